"""The 2-D perception rule: perception is blamed only when a missed partner degraded what the
planner saw.

Every frame reports the standard detection metrics from an optimal one-to-one (Hungarian)
matching of detections to ground-truth boxes with IoU >= ``perc_match_iou``: precision,
recall, mean matched IoU, missed gt ids with their best IoU (0 = missed outright, else
mislocated) and false positives. A failure needs three things at once: the partner is in
view (has a gt box) but unmatched; a real conflict (c_gt < ``safety_margin``); and the
planner's input about the partner is degraded (no raw prediction links to it, or its raw
boxes understate the danger relative to the reference boxes by more than
``understate_min`` while being displaced beyond the threshold or hiding the conflict).
A dropout that tracking bridges never reaches the planner, so it is not blamed.
"""

from __future__ import annotations

import math

import numpy as np

from ads_rca.foundation.geometry import FloatArray, axis_aligned_iou, overlap_blocks
from ads_rca.model import Boxes
from ads_rca.oracles.base import Metric, OracleResult, RunContext
from ads_rca.oracles.corrected.assignment import best_matching
from ads_rca.oracles.corrected.clearance import PartnerView, partner_view
from ads_rca.oracles.corrected.common import (
    REPORTED,
    clearance_metrics,
    missing_inputs,
    missing_skip,
    num,
)
from ads_rca.oracles.corrected.context import CacheName, CorrectedContext, corrected_context
from ads_rca.oracles.corrected.floors import perception_floor
from ads_rca.oracles.corrected.match3d import uses_3d
from ads_rca.oracles.corrected.perception3d import perception3d
from ads_rca.oracles.frame_iou import FrameIoU, batched_iou

#: Frames with at most this many detection x gt pairs are matched on the whole IoU matrix.
DENSE_PAIRS = 1 << 18
FRAME_IOUS: CacheName[FrameIoU] = CacheName("frame_ious")


def frame_iou(judging: CorrectedContext, ts: int, det: Boxes, gt: Boxes) -> FloatArray | None:
    """The IoU matrix of ``det`` x ``gt`` at ts (NaN coordinates score 0), batched with the
    frames after it (:func:`~ads_rca.oracles.frame_iou.batched_iou`), or None where the frame
    is too large (more than ``BATCH_PAIRS`` pairs: :func:`match_boxes` scores it) or empty."""
    return batched_iou(judging.log, judging.cache(FRAME_IOUS), ts, det, gt)


def match_boxes(
    detections: FloatArray,
    gts: FloatArray,
    threshold: float,
    dense_pairs: int = DENSE_PAIRS,
    iou: FloatArray | None = None,
) -> tuple[np.ndarray, np.ndarray, FloatArray, FloatArray]:
    """Hungarian matching with IoU >= threshold.

    Returns matched detection rows (ascending), matched gt rows, their IoUs, and each gt
    box's best IoU over all detections (NaN coordinates score 0). ``iou``: the whole IoU
    matrix (NaN coordinates scored 0) where it is already computed (:func:`frame_iou`).

    Up to ``dense_pairs`` pairs, one assignment on the whole matrix. Beyond, memory stays
    linear: IoUs are computed block by block (only boxes whose extents touch), only the
    eligible pairs are kept, and each connected group of them is assigned on its own. The
    optimum is the same (ineligible pairs cost 0, so groups do not interact); where several
    matchings are exactly equally good, the one chosen may differ from the whole matrix's.
    """
    n, m = len(detections), len(gts)
    if n == 0 or m == 0:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty, np.zeros(0), np.zeros(m)
    if iou is not None or n * m <= dense_pairs or not threshold > 0:  # (<= 0: all eligible)
        if iou is None:
            iou = axis_aligned_iou(detections, gts, nan_score=0.0)  # never infinite
        rows, cols = best_matching(iou >= threshold, iou)
        return rows, cols, iou[rows, cols], np.maximum.reduce(iou, axis=0)
    best = np.zeros(m)
    pair_rows, pair_cols, pair_iou = [], [], []
    for start, stop, keep in overlap_blocks(detections, gts):
        iou = np.nan_to_num(axis_aligned_iou(detections[start:stop], gts[keep]), nan=0.0)
        best[keep] = np.maximum(best[keep], iou.max(axis=0))
        r, c = np.nonzero(iou >= threshold)
        pair_rows.append(r + start)
        pair_cols.append(keep[c])
        pair_iou.append(iou[r, c])
    rows, cols, ious = _assign_groups(
        np.concatenate([np.zeros(0, np.intp), *pair_rows]),
        np.concatenate([np.zeros(0, np.intp), *pair_cols]),
        np.concatenate([np.zeros(0), *pair_iou]),
        n,
        m,
    )
    return rows, cols, ious, best


def _assign_groups(
    rows: np.ndarray, cols: np.ndarray, iou: FloatArray, n: int, m: int
) -> tuple[np.ndarray, np.ndarray, FloatArray]:
    """Optimal assignment of the eligible pairs (row, col, iou), one connected group at a
    time; matched rows ascending, with their columns and IoUs."""
    from scipy.optimize import linear_sum_assignment  # only for crowds (0.4 s to import)
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    graph = coo_matrix((np.ones(len(rows)), (rows, cols + n)), shape=(n + m, n + m))
    _count, label = connected_components(graph, directed=False)
    group = label[rows]
    order = np.lexsort((cols, rows, group))  # by group, then row, then column
    rows, cols, iou, group = rows[order], cols[order], iou[order], group[order]
    bounds = np.flatnonzero(np.diff(group)) + 1
    out_rows: list[np.ndarray] = []
    out_cols: list[np.ndarray] = []
    out_iou: list[FloatArray] = []
    for g_rows, g_cols, g_iou in zip(
        np.split(rows, bounds), np.split(cols, bounds), np.split(iou, bounds), strict=True
    ):
        if len(g_rows) == 1:  # one eligible pair, shared with no other: it is matched
            out_rows.append(g_rows)
            out_cols.append(g_cols)
            out_iou.append(g_iou)
            continue
        row_ids, r = np.unique(g_rows, return_inverse=True)
        col_ids, c = np.unique(g_cols, return_inverse=True)
        cost = np.zeros((len(row_ids), len(col_ids)))
        cost[r, c] = -g_iou
        a, b = linear_sum_assignment(cost)
        take = cost[a, b] < 0
        out_rows.append(row_ids[a[take]])
        out_cols.append(col_ids[b[take]])
        out_iou.append(-cost[a[take], b[take]])
    all_rows = np.concatenate([np.zeros(0, np.intp), *out_rows])
    order = np.argsort(all_rows, kind="stable")
    all_cols = np.concatenate([np.zeros(0, np.intp), *out_cols])
    all_iou = np.concatenate([np.zeros(0), *out_iou])
    return all_rows[order], all_cols[order], all_iou[order]


def detection_metrics(
    det: Boxes, gt: Boxes, threshold: float, iou: FloatArray | None = None
) -> tuple[dict[str, Metric], set[str]]:
    """Precision, recall, mean matched IoU, missed gt ids (best IoU), false positives;
    and the matched gt ids (``iou``: as :func:`match_boxes` takes it)."""
    rows, cols, ious, best = match_boxes(det.corners, gt.corners, threshold, iou=iou)
    n_det, n_gt, n_match = len(det), len(gt), len(rows)
    # a frame has about ten boxes a side: Python sets beat numpy masks at that size
    matched_rows, matched_cols = set(rows.tolist()), set(cols.tolist())
    best_list = best.tolist()
    metrics: dict[str, Metric] = {
        "detections": n_det,
        "gt_boxes": n_gt,
        "matched": n_match,
        "precision": n_match / n_det if n_det else math.nan,
        "recall": n_match / n_gt if n_gt else math.nan,
        # ndarray.mean's own steps: the summation numpy uses, then one division
        "mean_iou": float(np.add.reduce(ious)) / n_match if n_match else math.nan,
        "missed": {gt.ids[c]: round(best_list[c], 4) for c in range(n_gt) if c not in matched_cols},
        "false_positives": [det.ids[r] for r in range(n_det) if r not in matched_rows],
    }
    return metrics, {gt.ids[c] for c in matched_cols}


def degraded(judging: CorrectedContext, view: PartnerView, allowance: float = 0.0) -> bool:
    """The planner's input about the partner is degraded (the 2-D perception rule's third
    condition), by more than the noise ``allowance`` (the noise-floor rule) on the fixed
    thresholds."""
    if view.raw is None:
        return True
    understated = view.c_raw.value - view.c_ref.value > judging.params.understate_min + allowance
    # an error within the noise floor hides nothing: the stack's ordinary state
    hidden = view.c_raw.value >= judging.params.safety_margin and (
        allowance == 0 or view.raw_displacement > allowance
    )
    return bool(understated and (displaced(view, allowance) or hidden))


def displaced(view: PartnerView, allowance: float) -> bool:
    """The raw boxes are displaced from the reference beyond the threshold plus the noise
    allowance (False for NaN)."""
    return bool(view.raw_displacement > view.threshold + allowance)


def perception(ctx: RunContext, ts: int) -> OracleResult:
    """The 2-D perception rule at ts, with the standard detection metrics (the 3-D perception
    rule for 3-D logs)."""
    judging = corrected_context(ctx)
    if uses_3d(judging):
        return perception3d(ctx, ts)
    p = judging.params
    thresholds = judging.reported(REPORTED["perception"])
    absent = missing_inputs(judging, ts, ("bboxes", "bboxes_gt"), "perception check")
    if absent:
        return missing_skip("perception", ts, absent, thresholds=thresholds)
    det, gt = judging.log.bboxes[ts], judging.log.bboxes_gt[ts]
    metrics, matched_gt = detection_metrics(
        det, gt, p.perc_match_iou, frame_iou(judging, ts, det, gt)
    )
    partner = judging.partner_at(ts)
    in_view = partner is not None and partner in gt.ids
    unmatched = partner is not None and in_view and partner not in matched_gt
    best = metrics["missed"]
    partner_best = best.get(partner) if partner is not None and isinstance(best, dict) else None
    metrics.update(
        partner_in_view=in_view,
        partner_matched=in_view and not unmatched,
        partner_best_iou=partner_best,
        unconditioned=unmatched,
    )
    ids = (partner,) if partner is not None else ()
    if not unmatched:
        return OracleResult("perception", ts, False, metrics, thresholds, ids)
    needed = ("pose", "waypoint", "predictions", "predictions_with_perception")
    absent = missing_inputs(judging, ts, needed, "perception degradation check")
    if absent:
        return missing_skip("perception", ts, absent, metrics, thresholds)
    view = partner_view(judging, ts)
    floor = perception_floor(judging, ts)
    allowance = p.noise_floor_factor * floor.value
    is_degraded = degraded(judging, view, allowance)
    metrics.update(
        # the fallback's test is the error alone: missed by the planner, or displaced
        unconditioned=bool(view.raw is None or displaced(view, allowance)),
        **floor.metrics("perception"),
        noise_allowance=allowance,
        real_conflict=view.real_conflict,
        planner_input_degraded=is_degraded,
        raw_linked=view.raw is not None,
        raw_displacement=num(view.raw_displacement),
        displacement_threshold=view.threshold,
        **clearance_metrics("c_gt", view.c_gt),
        **clearance_metrics("c_raw", view.c_raw),
        **clearance_metrics("c_ref", view.c_ref),
    )
    failed = bool(view.real_conflict and is_degraded)
    if view.raw_id is not None:
        ids = (*ids, view.raw_id)
    return OracleResult("perception", ts, failed, metrics, thresholds, ids)
