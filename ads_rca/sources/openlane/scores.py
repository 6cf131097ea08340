"""OpenLane-V2's benchmark metrics (DET_l, DET_t, TOP_ll, TOP_lt, OLS) as a pure scorer.

A map-perception model's output (a :class:`~ads_rca.sources.openlane.lanes.LaneGraph` per frame) is
judged
against the ground truth with the benchmark's own figures, so a number here means what it
means on the OpenLane-V2 leaderboard. The rules follow the official devkit
(OpenDriveLab/OpenLane-V2, ``openlanev2/centerline/evaluation/evaluate.py`` and
``distance.py`` as of v2.1.0, the "v1.1/v2.1" topology metrics of its issue #76); the code is
ours, vectorised with numpy. docs/openlane-metrics.md states every rule with its source.

- Lane distance: the discrete Fréchet distance of the two 3-D polylines as given (no
  resampling; direction matters, a reversed lane is far), multiplied by the ground-truth
  lane's relaxation ``max(0.5, 1 - 0.005 * d)``, d its point nearest the ego (m) (devkit
  ``pairwise(..., relax=True)``). The devkit skips pairs whose Chamfer distance is 3 m or
  more (Chamfer <= Fréchet, so they cannot match); we skip those whose first or last points
  are 3 m or more apart (another lower bound, cheaper): neither changes a match.
- Element distance: ``1 - IoU`` of the (x1, y1, x2, y2) image boxes.
- Matching, per frame and threshold: predictions in descending confidence; each one looks
  only at its NEAREST ground truth (first on ties) and is a true positive iff that distance
  is below the threshold (strict) and no earlier prediction took it; otherwise a false
  positive (it does not fall back to its second nearest; devkit ``_tpfp``). Lanes at 1, 2 and
  3 m; elements at IoU distance < 0.75 (IoU > 0.25).
- AP over a set of frames: every frame's true/false positives ranked together by confidence;
  11-point interpolated AP: the mean over recall levels r = 0, 0.1, ..., 1 of the highest
  precision at recall >= r (0 if never reached) (devkit ``_AP``, ``_pr_curve``).
- DET_l: the mean of the three thresholds' APs. DET_t: per attribute (0..12 of
  :data:`~ads_rca.sources.openlane.lanes.ELEMENT_ATTRIBUTES`) ground truth and predictions of that
  attribute
  only, then the mean over attributes. Elements of any other attribute count for no class.
- TOP_ll, TOP_lt: per frame with ground-truth lanes (TOP_lt: and elements), per lane
  threshold, the prediction's links are carried onto the ground truth's vertices through that
  threshold's lane matching (TOP_lt: and the all-attribute element matching); every entry
  with a vertex left unmatched is set to the opposite of the truth at confidence
  ``0.5 + eps(float32)``: a missing true link, a present false one. A link is predicted iff
  its confidence > 0.5. Per vertex and direction (TOP_ll: out-links = rows, in-links =
  columns; TOP_lt: each lane over elements, each element over lanes) the link-prediction AP
  ``sum(precision at each true link in confidence order) / |true links|``: 1 when the vertex
  has neither true nor predicted links, 0 when only one side has any. TOP is the mean over
  all those per-vertex values of every frame and threshold (devkit ``_mAP_topology_lclc``,
  ``_mAP_topology_lcte``, ``_AP_directerd``, ``_AP_undirecterd``,
  ``_average_precision_per_vertex``); unmatched predicted lanes' links are not looked at.
- OLS = mean(DET_l, DET_t, sqrt(TOP_ll), sqrt(TOP_lt)).

Where we differ, on purpose (``devkit_empty=True`` restores the devkit's empty-set values):

- Empty sets: the devkit scores a class with neither ground truth nor predictions 1.0 (so a
  frame without traffic elements gets DET_t 1.0 from 13 empty attributes) and a topology
  with no frame to judge 0.0. Here both are NaN (undefined): DET_t averages the attributes
  that have ground truth or predictions; OLS is NaN when any of its four parts is. A class
  with predictions and no ground truth is 0.0 in both (only false positives).
- Ties: equal confidences are ranked in frame then list order (stable sorts; the devkit's
  quicksort leaves large tied arrays in an unspecified order).
- Recall levels are compared exactly (``10 * tp >= k * n_gt`` in integers). The devkit
  compares float32 recalls with ``np.arange(0, 1.001, 0.1)``: with the numpy it pins (< 1.24)
  the comparison runs in float32 and agrees; under numpy 2 it runs in float64 and a recall of
  exactly 0.7 misses the 0.7 level (10 lanes, 7 found: AP 7/11 there, 8/11 here).
- Unusable input, which the devkit would crash on or score as NaN: a lane with no point,
  not (P, 3), or with a non-finite coordinate, and an element whose box is non-finite or
  inverted (x2 < x1 or y2 < y1) are dropped (with their adjacency rows and columns) and
  counted in ``dropped_lanes`` / ``dropped_elements``. A prediction whose confidence is not
  finite ranks after every scored prediction (in list order) and is counted in
  ``unscored``. A ground-truth link is a finite non-zero entry; a non-finite predicted link
  confidence between matched vertices is the opposite of the truth, as the devkit fills its
  NaNs. Boxes of zero union have IoU 0.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from ads_rca.sources.openlane.lanes import ELEMENT_ATTRIBUTES, LaneGraph

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

#: Fréchet thresholds of DET_l and of the topology's lane matching (m).
LANE_THRESHOLDS_M = (1.0, 2.0, 3.0)
#: A traffic element matches below this IoU distance (1 - IoU), i.e. at IoU > 0.25.
ELEMENT_IOU_DISTANCE = 0.75
#: A link is predicted iff its confidence exceeds this.
LINK_CONFIDENCE = 0.5
#: The official val/test evaluation scores ground-truth lanes thinned to every 20th point
#: (the devkit's ``collect(..., point_interval=20)``, run when its ground truth is
#: gathered): a released lane's 201 points become 11. 1 scores the points as given (what
#: ``evaluate()`` does with a ground truth already collected).
GT_POINT_INTERVAL = 20
#: A ground-truth lane's distances are scaled by max(RELAX_FLOOR, 1 - RELAX_PER_M * d).
RELAX_PER_M = 5e-3
RELAX_FLOOR = 0.5
#: The confidence given to the opposite of the truth where a vertex is unmatched.
UNMATCHED_LINK = 0.5 + float(np.finfo(np.float32).eps)
#: Recall levels of the 11-point interpolated AP, in tenths.
_RECALL_TENTHS = np.arange(11)
#: Cells (pairs x points x points) per chunk of the Fréchet dynamic programme.
_CHUNK_CELLS = 1 << 21


# ---------------------------------------------------------------------------------------------
# distances


def frechet_matrix(a: Sequence[FloatArray], b: Sequence[FloatArray]) -> FloatArray:
    """Discrete Fréchet distance of every polyline of ``a`` to every one of ``b``: (len a, len b).

    Each polyline is (P, D) points in order (D the same for all).
    """
    rows, cols = np.divmod(np.arange(len(a) * len(b), dtype=np.int64), max(1, len(b)))
    return frechet_pairs(a, b, rows, cols).reshape(len(a), len(b))


def frechet_distance(a: FloatArray, b: FloatArray) -> float:
    """Discrete Fréchet distance of two polylines ((P, D) and (Q, D) points)."""
    return float(frechet_matrix([a], [b])[0, 0])


def frechet_pairs(
    a: Sequence[FloatArray], b: Sequence[FloatArray], rows: IntArray, cols: IntArray
) -> FloatArray:
    """Fréchet distance of ``a[rows[k]]`` to ``b[cols[k]]`` for each k.

    Pairs of equal point counts (P, Q) are computed together: the dynamic programme runs
    over the anti-diagonals of the (P, Q) grid, vectorised over the pairs and the cells of a
    diagonal, in chunks that bound memory.
    """
    out = np.full(rows.size, np.nan)
    if rows.size == 0:
        return out
    stack_a, at_a, len_a = _stacked(a)
    stack_b, at_b, len_b = _stacked(b)
    shapes = np.stack([len_a[rows], len_b[cols]], axis=1)
    for p, q in np.unique(shapes, axis=0).tolist():
        group = np.flatnonzero((shapes[:, 0] == p) & (shapes[:, 1] == q))
        step = max(1, _CHUNK_CELLS // (p * q))
        for start in range(0, group.size, step):
            k = group[start : start + step]
            out[k] = _frechet_same_shape(stack_a[p][at_a[rows[k]]], stack_b[q][at_b[cols[k]]])
    return out


def _stacked(
    lines: Sequence[FloatArray],
) -> tuple[dict[int, FloatArray], IntArray, IntArray]:
    """Polylines stacked by point count; each line's row in its stack and its count."""
    lengths = np.array([len(line) for line in lines], dtype=np.int64)
    at = np.zeros(lengths.size, dtype=np.int64)
    stacks: dict[int, FloatArray] = {}
    for n in np.unique(lengths).tolist():
        members = np.flatnonzero(lengths == n)
        at[members] = np.arange(members.size)
        stacks[n] = np.stack([np.asarray(lines[i], dtype=np.float64) for i in members.tolist()])
    return stacks, at, lengths


def _frechet_same_shape(pa: FloatArray, pb: FloatArray) -> FloatArray:
    """Fréchet distances of (N, P, D) against (N, Q, D) polylines, pair by pair: (N,)."""
    n, p, q = pa.shape[0], pa.shape[1], pb.shape[1]
    # d[s, t, k]: distance of point s of pair k's first line to point t of its second
    d = np.linalg.norm(pa.transpose(1, 0, 2)[:, None] - pb.transpose(1, 0, 2)[None], axis=-1)
    # c[s + 1, t + 1, k]: the best coupling's cost up to (s, t); row and column 0 are +inf
    # borders, and c[0, 0] = 0 starts the recursion
    c = np.full((p + 1, q + 1, n), np.inf)
    c[0, 0] = 0.0
    for diagonal in range(p + q - 1):
        s = np.arange(max(0, diagonal - q + 1), min(diagonal, p - 1) + 1)
        t = diagonal - s
        before = np.minimum(np.minimum(c[s, t + 1], c[s + 1, t]), c[s, t])
        c[s + 1, t + 1] = np.maximum(d[s, t], before)
    return c[p, q]


def relaxation_factors(lanes: Sequence[FloatArray]) -> FloatArray:
    """Each ground-truth lane's distance factor: max(0.5, 1 - 0.005 * its nearest point's range)."""
    if not lanes:
        return np.zeros(0)
    nearest = np.array([float(np.linalg.norm(lane, axis=1).min()) for lane in lanes])
    return np.maximum(RELAX_FLOOR, 1.0 - RELAX_PER_M * nearest)


def lane_distance_matrix(
    gt: Sequence[FloatArray], pred: Sequence[FloatArray], cutoff: float = math.inf
) -> FloatArray:
    """The devkit's lane distance: Fréchet scaled by the ground-truth lane's relaxation.

    Pairs whose scaled distance cannot be below ``cutoff`` are +inf without computing it
    (their first points and their last points are coupled, so either gap bounds it below).
    """
    out = np.full((len(gt), len(pred)), np.inf)
    if not gt or not pred:
        return out
    relax = relaxation_factors(gt)
    first_a = np.stack([lane[0] for lane in gt])
    first_b = np.stack([lane[0] for lane in pred])
    last_a = np.stack([lane[-1] for lane in gt])
    last_b = np.stack([lane[-1] for lane in pred])
    bound = np.maximum(
        np.linalg.norm(first_a[:, None] - first_b[None], axis=-1),
        np.linalg.norm(last_a[:, None] - last_b[None], axis=-1),
    )
    rows, cols = np.nonzero(bound * relax[:, None] < cutoff)
    out[rows, cols] = frechet_pairs(gt, pred, rows, cols) * relax[rows]
    return out


def iou_matrix(a: FloatArray, b: FloatArray) -> FloatArray:
    """IoU of every (x1, y1, x2, y2) box of ``a`` (n, 4) with every one of ``b`` (m, 4).

    0 where the union has no area.
    """
    a = np.asarray(a, dtype=np.float64).reshape(-1, 4)
    b = np.asarray(b, dtype=np.float64).reshape(-1, 4)
    lo = np.maximum(a[:, None, 0:2], b[None, :, 0:2])
    hi = np.minimum(a[:, None, 2:4], b[None, :, 2:4])
    inter = np.prod(np.clip(hi - lo, 0.0, None), axis=-1)
    area_a = np.prod(a[:, 2:4] - a[:, 0:2], axis=1)
    area_b = np.prod(b[:, 2:4] - b[:, 0:2], axis=1)
    union = area_a[:, None] + area_b[None, :] - inter
    with np.errstate(divide="ignore", invalid="ignore"):
        iou = np.where(union > 0, inter / union, 0.0)
    return np.asarray(iou, dtype=np.float64)


# ---------------------------------------------------------------------------------------------
# matching and AP


def rank_order(confidence: FloatArray) -> IntArray:
    """Indices in descending confidence, ties and non-finite last in list order (stable)."""
    key = np.where(np.isfinite(confidence), -confidence, np.inf)
    return np.argsort(key, kind="stable").astype(np.int64)


def greedy_match(distance: FloatArray, confidence: FloatArray, threshold: float) -> IntArray:
    """The devkit's greedy matching of one frame: for each prediction the ground truth it took.

    ``distance`` is (G, P); the result (P,) holds a ground-truth index, or -1 for a false
    positive. Each prediction, in :func:`rank_order`, takes its nearest ground truth if the
    distance is below ``threshold`` and no earlier prediction took it.
    """
    g, p = distance.shape
    match = np.full(p, -1, dtype=np.int64)
    if g == 0 or p == 0:
        return match
    finite = np.where(np.isnan(distance), np.inf, distance)
    nearest = np.argmin(finite, axis=0)
    near = finite[nearest, np.arange(p)]
    order = rank_order(confidence)
    eligible = order[near[order] < threshold]
    _, first = np.unique(nearest[eligible], return_index=True)
    winners = eligible[first]
    match[winners] = nearest[winners]
    return match


def average_precision(tp: BoolArray, confidence: FloatArray, gt_count: int) -> float:
    """11-point interpolated AP of predictions pooled over frames (NaN if nothing to rank).

    ``tp`` and ``confidence`` are per prediction; ``gt_count`` the ground truths they could
    match. 0.0 when there are predictions but no ground truth, or ground truth but none found.
    """
    if tp.size == 0 and gt_count == 0:
        return math.nan
    if tp.size == 0:
        return 0.0
    hits = np.cumsum(tp[rank_order(confidence)].astype(np.int64))
    precision = hits / np.arange(1, hits.size + 1)
    # best precision from each rank on (recall never falls along the ranking)
    best_after = np.maximum.accumulate(precision[::-1])[::-1]
    first = np.searchsorted(10 * hits, _RECALL_TENTHS * gt_count, side="left")
    reached = first < hits.size
    return float(np.where(reached, best_after[np.minimum(first, hits.size - 1)], 0.0).mean())


def vertex_link_ap(truth: BoolArray, confidence: FloatArray) -> FloatArray:
    """Link-prediction AP of each row: true links ``truth`` (V, C), link confidences (V, C).

    Links with confidence > 0.5 are predicted and ranked; a row's AP is the sum of the
    precisions at its true links over its true-link count; 1 with neither true nor predicted
    links, 0 with only one of them.
    """
    v, c = truth.shape
    if v == 0:
        return np.zeros(0)
    predicted = np.where(np.isfinite(confidence), confidence, -np.inf) > LINK_CONFIDENCE
    key = np.where(predicted, -confidence, np.inf)
    order = np.argsort(key, axis=1, kind="stable")
    ranked_pred = np.take_along_axis(predicted, order, axis=1)
    ranked_hit = np.take_along_axis(truth, order, axis=1) & ranked_pred
    precision = np.cumsum(ranked_hit, axis=1) / np.arange(1, c + 1)
    n_true = truth.sum(axis=1)
    n_pred = predicted.sum(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        ap = np.where(n_true > 0, (precision * ranked_hit).sum(axis=1) / n_true, 0.0)
    ap = np.where((n_true == 0) | (n_pred == 0), 0.0, ap)
    return np.asarray(np.where((n_true == 0) & (n_pred == 0), 1.0, ap), dtype=np.float64)


def _links_on_truth(
    truth: BoolArray, pred: FloatArray, rows: IntArray, cols: IntArray
) -> FloatArray:
    """The predicted link matrix on the truth's vertices.

    ``rows[g]`` / ``cols[g]``: the prediction matched to ground-truth row / column g, or -1.
    Entries with an unmatched vertex, or a non-finite predicted confidence, are the opposite
    of the truth at :data:`UNMATCHED_LINK` (the devkit fills every NaN so).
    """
    out = np.full(truth.shape, np.nan)
    r = np.flatnonzero(rows >= 0)
    k = np.flatnonzero(cols >= 0)
    if r.size and k.size:
        out[np.ix_(r, k)] = pred[np.ix_(rows[r], cols[k])]
    return np.where(np.isfinite(out), out, np.where(truth, 0.0, UNMATCHED_LINK))


def _inverse(match: IntArray, gt_count: int) -> IntArray:
    """Per ground truth, the prediction that took it (-1 if none)."""
    inverse = np.full(gt_count, -1, dtype=np.int64)
    taken = np.flatnonzero(match >= 0)
    inverse[match[taken]] = taken
    return inverse


# ---------------------------------------------------------------------------------------------
# frames


@dataclass(frozen=True, eq=False)
class FrameMatch:
    """One frame's matches, what :func:`scores_from` pools over any set of frames."""

    gt_lanes: int
    lane_confidence: FloatArray  # (P,)
    lane_tp: BoolArray  # (thresholds, P)
    element_attribute: IntArray  # (Q,) predicted elements' attributes
    element_confidence: FloatArray  # (Q,)
    element_tp: BoolArray  # (Q,) matched within its own attribute
    gt_attribute_counts: IntArray  # (attributes,)
    top_ll: FloatArray  # per-vertex link APs of every threshold (empty if not judged)
    top_lt: FloatArray
    top_ll_judged: bool
    top_lt_judged: bool
    gt_elements: int
    dropped_lanes: int
    dropped_elements: int
    unscored: int


@dataclass(frozen=True, eq=False)
class _Usable:
    lanes: tuple[FloatArray, ...]
    lane_confidence: FloatArray
    boxes: FloatArray
    attribute: IntArray
    element_confidence: FloatArray
    lane_lane: FloatArray
    lane_element: FloatArray
    dropped_lanes: int
    dropped_elements: int


def _usable(graph: LaneGraph, point_interval: int = 1) -> _Usable:
    """The graph's scorable part: lanes of finite (P, 3) points (every ``point_interval``-th
    kept, the first included), boxes finite and not inverted; their links."""
    keep_l = np.array(
        [
            lane.ndim == 2
            and lane.shape[0] > 0
            and lane.shape[1] == 3
            and bool(np.isfinite(lane).all())
            for lane in graph.lanes
        ],
        dtype=bool,
    )
    boxes = graph.element_boxes
    keep_e = np.isfinite(boxes).all(axis=1) & (boxes[:, 2] >= boxes[:, 0])
    keep_e &= boxes[:, 3] >= boxes[:, 1]
    li, ei = np.flatnonzero(keep_l), np.flatnonzero(keep_e)
    return _Usable(
        lanes=tuple(np.asarray(graph.lanes[i], dtype=np.float64)[::point_interval] for i in li),
        lane_confidence=np.asarray(graph.lane_scores, dtype=np.float64)[li],
        boxes=boxes[ei],
        attribute=graph.element_attribute[ei],
        element_confidence=np.asarray(graph.element_scores, dtype=np.float64)[ei],
        lane_lane=graph.lane_lane[np.ix_(li, li)],
        lane_element=graph.lane_element[np.ix_(li, ei)],
        dropped_lanes=int(keep_l.size - li.size),
        dropped_elements=int(keep_e.size - ei.size),
    )


def _truth(adjacency: FloatArray) -> BoolArray:
    return np.asarray(np.isfinite(adjacency) & (adjacency != 0), dtype=np.bool_)


def match_frame(
    gt: LaneGraph, pred: LaneGraph, point_interval: int = GT_POINT_INTERVAL
) -> FrameMatch:
    """One frame's ground truth against a prediction: every match the metrics need. The
    ground truth's lanes are thinned as the official evaluation collects them
    (:data:`GT_POINT_INTERVAL`); the prediction's points are scored as given."""
    if (
        isinstance(point_interval, bool)
        or not isinstance(point_interval, int)
        or point_interval < 1
    ):
        raise ValueError(f"point_interval: a whole number >= 1, not {point_interval!r}")
    g, p = _usable(gt, point_interval), _usable(pred)
    n_gt, n_gte = len(g.lanes), g.attribute.size
    lane_dist = lane_distance_matrix(g.lanes, p.lanes, cutoff=max(LANE_THRESHOLDS_M))
    lane_match = [greedy_match(lane_dist, p.lane_confidence, t) for t in LANE_THRESHOLDS_M]
    box_dist = 1.0 - iou_matrix(g.boxes, p.boxes)
    element_tp = np.zeros(p.attribute.size, dtype=bool)
    for a in range(len(ELEMENT_ATTRIBUTES)):
        gi, pi = np.flatnonzero(g.attribute == a), np.flatnonzero(p.attribute == a)
        if pi.size:
            sub = box_dist[np.ix_(gi, pi)]
            hit = greedy_match(sub, p.element_confidence[pi], ELEMENT_IOU_DISTANCE) >= 0
            element_tp[pi] = hit
    counts = np.bincount(
        g.attribute[(g.attribute >= 0) & (g.attribute < len(ELEMENT_ATTRIBUTES))],
        minlength=len(ELEMENT_ATTRIBUTES),
    ).astype(np.int64)
    ll_truth, lt_truth = _truth(g.lane_lane), _truth(g.lane_element)
    top_ll: list[FloatArray] = []
    top_lt: list[FloatArray] = []
    element_rows = _inverse(
        greedy_match(box_dist, p.element_confidence, ELEMENT_IOU_DISTANCE), n_gte
    )
    for match in lane_match:
        lane_rows = _inverse(match, n_gt)
        if n_gt:
            links = _links_on_truth(ll_truth, p.lane_lane, lane_rows, lane_rows)
            top_ll += [vertex_link_ap(ll_truth, links), vertex_link_ap(ll_truth.T, links.T)]
        if n_gt and n_gte:
            links = _links_on_truth(lt_truth, p.lane_element, lane_rows, element_rows)
            top_lt += [vertex_link_ap(lt_truth, links), vertex_link_ap(lt_truth.T, links.T)]
    return FrameMatch(
        gt_lanes=n_gt,
        lane_confidence=p.lane_confidence,
        lane_tp=np.stack([m >= 0 for m in lane_match]).reshape(len(LANE_THRESHOLDS_M), -1),
        element_attribute=p.attribute.astype(np.int64),
        element_confidence=p.element_confidence,
        element_tp=element_tp,
        gt_attribute_counts=counts,
        top_ll=np.concatenate(top_ll) if top_ll else np.zeros(0),
        top_lt=np.concatenate(top_lt) if top_lt else np.zeros(0),
        top_ll_judged=n_gt > 0,
        top_lt_judged=n_gt > 0 and n_gte > 0,
        gt_elements=n_gte,
        dropped_lanes=g.dropped_lanes + p.dropped_lanes,
        dropped_elements=g.dropped_elements + p.dropped_elements,
        unscored=int((~np.isfinite(p.lane_confidence)).sum())
        + int((~np.isfinite(p.element_confidence)).sum()),
    )


# ---------------------------------------------------------------------------------------------
# scores


@dataclass(frozen=True)
class OpenLaneScores:
    """OpenLane-V2's figures over a set of frames (one frame, a segment, a split).

    NaN is undefined (see the module docstring); ``det_l_ap`` maps each Fréchet threshold
    (m) to its AP, ``det_t_ap`` each attribute with ground truth or predictions to its AP.
    """

    frames: int
    det_l: float
    det_t: float
    top_ll: float
    top_lt: float
    ols: float
    det_l_ap: dict[float, float] = field(default_factory=dict)
    det_t_ap: dict[str, float] = field(default_factory=dict)
    gt_lanes: int = 0
    pred_lanes: int = 0
    gt_elements: int = 0
    pred_elements: int = 0
    dropped_lanes: int = 0
    dropped_elements: int = 0
    unscored: int = 0

    def to_dict(self) -> dict[str, object]:
        """JSON-ready: NaN as None, thresholds as text keys."""
        return {
            "frames": self.frames,
            "det_l": _json_float(self.det_l),
            "det_t": _json_float(self.det_t),
            "top_ll": _json_float(self.top_ll),
            "top_lt": _json_float(self.top_lt),
            "ols": _json_float(self.ols),
            "det_l_ap": {f"{t:g}": _json_float(v) for t, v in self.det_l_ap.items()},
            "det_t_ap": {k: _json_float(v) for k, v in self.det_t_ap.items()},
            "gt_lanes": self.gt_lanes,
            "pred_lanes": self.pred_lanes,
            "gt_elements": self.gt_elements,
            "pred_elements": self.pred_elements,
            "dropped_lanes": self.dropped_lanes,
            "dropped_elements": self.dropped_elements,
            "unscored": self.unscored,
        }


def _json_float(value: float) -> float | None:
    return value if math.isfinite(value) else None


def _mean(values: Sequence[float]) -> float:
    finite = [v for v in values if not math.isnan(v)]
    return float(np.mean(finite)) if finite else math.nan


def scores_from(matches: Sequence[FrameMatch], *, devkit_empty: bool = False) -> OpenLaneScores:
    """Pool frames' matches into the benchmark's figures.

    ``devkit_empty``: score empty classes and topologies as the devkit does (1.0 for a class
    with neither ground truth nor predictions, averaging all 13 attributes; 0.0 for a topology
    with no frame to judge) instead of NaN.
    """
    vacuous = 1.0 if devkit_empty else math.nan
    lane_conf = np.concatenate([m.lane_confidence for m in matches] or [np.zeros(0)])
    lane_tp = np.concatenate(
        [m.lane_tp for m in matches] or [np.zeros((len(LANE_THRESHOLDS_M), 0), dtype=bool)],
        axis=1,
    )
    gt_lanes = sum(m.gt_lanes for m in matches)
    det_l_ap: dict[float, float] = {}
    for row, t in enumerate(LANE_THRESHOLDS_M):
        ap = average_precision(lane_tp[row], lane_conf, gt_lanes)
        det_l_ap[t] = vacuous if math.isnan(ap) else ap
    det_l = _mean(list(det_l_ap.values()))

    attr = np.concatenate([m.element_attribute for m in matches] or [np.zeros(0, np.int64)])
    conf = np.concatenate([m.element_confidence for m in matches] or [np.zeros(0)])
    tp = np.concatenate([m.element_tp for m in matches] or [np.zeros(0, dtype=bool)])
    gt_counts = np.sum(
        [m.gt_attribute_counts for m in matches] or [np.zeros(len(ELEMENT_ATTRIBUTES), np.int64)],
        axis=0,
    )
    det_t_ap: dict[str, float] = {}
    for a, name in enumerate(ELEMENT_ATTRIBUTES):
        mine = attr == a
        ap = average_precision(tp[mine], conf[mine], int(gt_counts[a]))
        if math.isnan(ap) and devkit_empty:
            ap = 1.0
        if not math.isnan(ap):
            det_t_ap[name] = ap
    det_t = _mean(list(det_t_ap.values()))

    empty_top = 0.0 if devkit_empty else math.nan
    ll = [m.top_ll for m in matches if m.top_ll_judged]
    lt = [m.top_lt for m in matches if m.top_lt_judged]
    top_ll = float(np.concatenate(ll).mean()) if ll else empty_top
    top_lt = float(np.concatenate(lt).mean()) if lt else empty_top
    parts = (det_l, det_t, math.sqrt(top_ll), math.sqrt(top_lt))
    ols = math.nan if any(math.isnan(x) for x in parts) else float(np.mean(parts))
    return OpenLaneScores(
        frames=len(matches),
        det_l=det_l,
        det_t=det_t,
        top_ll=top_ll,
        top_lt=top_lt,
        ols=ols,
        det_l_ap=det_l_ap,
        det_t_ap=det_t_ap,
        gt_lanes=gt_lanes,
        pred_lanes=int(lane_conf.size),
        gt_elements=sum(m.gt_elements for m in matches),
        pred_elements=int(attr.size),
        dropped_lanes=sum(m.dropped_lanes for m in matches),
        dropped_elements=sum(m.dropped_elements for m in matches),
        unscored=sum(m.unscored for m in matches),
    )


def score_frames(
    pairs: Iterable[tuple[LaneGraph, LaneGraph]],
    *,
    devkit_empty: bool = False,
    point_interval: int = GT_POINT_INTERVAL,
) -> OpenLaneScores:
    """OpenLane-V2's figures of (ground truth, prediction) frames: one frame, a segment, a
    split; the ground truth's lanes thinned as the official val/test evaluation does
    (``point_interval``, :data:`GT_POINT_INTERVAL`)."""
    matches = [match_frame(gt, pred, point_interval) for gt, pred in pairs]
    return scores_from(matches, devkit_empty=devkit_empty)
