"""Rule 2b: perception in 3-D, judged like rule 2 on what the stack perceived of the partner.

Real stacks perceive objects as 3-D boxes (tracked objects, 3-D detections), not image
boxes. Every frame reports bird's-eye detection metrics from the match of :mod:`.match3d`
(precision, recall, IoU, position and heading errors, missed actors, false positives). A
failure needs a real conflict (c_gt < ``safety_margin``) with the partner in sensing range
and either missed, or perceived so that the clearance looked safer than it was by at least
``understate_min``: the real and the perceived partner are both moved at constant velocity
from ts (the real velocity from the ground truth over one frame, the perceived one as
recorded) against the ego's plan boxes, so only the errors of position, extent, heading
and velocity at ts count, not the partner's later manoeuvres (prediction's business).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ads_rca.geometry import FloatArray
from ads_rca.oracles.base import Metric, OracleResult, RunContext
from ads_rca.oracles.corrected.boxes import Series
from ads_rca.oracles.corrected.clearance import (
    Clearance,
    pair_clearances,
    partner_view,
    undefined_clearance,
)
from ads_rca.oracles.corrected.common import clearance_metrics, missing_inputs, num, skipped
from ads_rca.oracles.corrected.context import (
    CacheName,
    CorrectedContext,
    corrected_context,
    ego_box,
)
from ads_rca.oracles.corrected.match3d import Match3D, frame_match, source

#: The parameters rule 2b's results report in ``thresholds``, in that order.
REPORTED_3D = (
    "perc3d_match_iou",
    "perc3d_match_distance",
    "perc3d_small_area",
    "perc3d_range",
    "safety_margin",
    "understate_min",
)


def yaw_error(a: FloatArray | float, b: FloatArray | float) -> FloatArray:
    """|a − b| in degrees wrapped to [0, 180]: a reversed heading is a 180° error (it
    misleads prediction although the box looks the same)."""
    diff = np.abs((np.asarray(a, dtype=np.float64) - b + 180.0) % 360.0 - 180.0)
    return np.asarray(diff, dtype=np.float64)


def object_metrics(match: Match3D) -> dict[str, Metric]:
    """Precision, recall, mean IoU, position and heading errors over the in-range pairs,
    missed in-range actors (their best IoU) and in-range false positives."""
    objects = match.objects
    in_range = match.actor_in_range[match.cols]
    rows, cols, iou = match.rows[in_range], match.cols[in_range], match.iou[in_range]
    n_obj = int(match.object_in_range.sum())
    n_gt = int(match.actor_in_range.sum())
    free_obj = match.object_in_range.copy()
    free_obj[match.rows] = False
    free_gt = match.actor_in_range.copy()
    free_gt[match.cols] = False
    offset = objects.location[rows, :2] - match.actor_center[cols]
    position = np.hypot(offset[:, 0], offset[:, 1])
    heading = yaw_error(objects.yaw[rows], match.actor_yaw[cols])
    matched_objects = int(match.object_in_range[match.rows].sum())
    best = match.best.tolist()
    return {
        "detections": n_obj,
        "gt_objects": n_gt,
        "matched": len(rows),
        "precision": matched_objects / n_obj if n_obj else math.nan,
        "recall": len(rows) / n_gt if n_gt else math.nan,
        "mean_iou": float(iou.mean()) if len(rows) else math.nan,
        "mean_position_error": float(position.mean()) if len(rows) else math.nan,
        "mean_yaw_error": float(heading.mean()) if len(rows) else math.nan,
        "missed": {match.actor_ids[c]: round(best[c], 4) for c in np.flatnonzero(free_gt)},
        "false_positives": [objects.ids[r] for r in np.flatnonzero(free_obj)],
    }


@dataclass(frozen=True)
class PartnerPerception:
    """How the stack perceived the partner at ts, and what that did to the clearance."""

    partner_id: str
    in_range: bool
    object_id: str | None  # the matched perceived object
    position_error: float
    yaw_error: float
    extent_error: tuple[float, float]  # perceived − real full length, width (m)
    velocity_error: float  # |perceived − real| world velocity (NaN when unknown)
    c_true: Clearance
    c_perc: Clearance
    overstated: bool  # c_perc − c_true >= understate_min

    @property
    def matched(self) -> bool:
        return self.object_id is not None

    @property
    def correct(self) -> bool:
        """Matched and not overstated: prediction may be judged from this perception."""
        return self.matched and not self.overstated


NAN2 = (math.nan, math.nan)
PARTNER: CacheName[PartnerPerception | None] = CacheName("partner_perception")


def partner_perception(cc: CorrectedContext, ts: int) -> PartnerPerception | None:
    """The partner's perception at ts (cached per partner); None without a partner, or
    without a match at ts (no actors, perceived objects or ego position)."""
    cache = cc.cache(PARTNER)
    found = cache.lookup(ts)
    partner = cc.partner_at(ts)
    if found is None or found.partner_id != partner:
        found = _assess(cc, ts, partner)
        cache.put(ts, found)
    return found


def real_velocity(cc: CorrectedContext, actor_id: str, ts: int) -> FloatArray:
    """The actor's world velocity (2,) at ts: its displacement to ts + tpf over one frame
    (from ts − tpf when ts + tpf has none); NaN when neither."""
    now = cc.actor_state(actor_id, ts)
    dt = cc.tpf / 1000.0
    if now is None:
        return np.full(2, np.nan)
    later = cc.actor_state(actor_id, ts + cc.tpf)
    if later is not None:
        return np.asarray((later[0] - now[0]) / dt, dtype=np.float64)
    earlier = cc.actor_state(actor_id, ts - cc.tpf)
    if earlier is not None:
        return np.asarray((now[0] - earlier[0]) / dt, dtype=np.float64)
    return np.full(2, np.nan)


def moving_boxes(
    center: FloatArray, velocity: FloatArray, yaw: float, half: FloatArray, cc: CorrectedContext
) -> Series:
    """Boxes at indices 0..W of a box moving at constant velocity from ``center``."""
    t = cc.seconds(np.arange(cc.window + 1))
    return Series(center[None, :] + t[:, None] * velocity[None, :], np.full(len(t), yaw), half)


def _assess(cc: CorrectedContext, ts: int, partner: str | None) -> PartnerPerception | None:
    match = frame_match(cc, ts)
    if partner is None or match is None:
        return None
    if partner not in match.actor_ids:
        none = undefined_clearance(cc.window)
        return PartnerPerception(
            partner, False, None, math.nan, math.nan, NAN2, math.nan, none, none, False
        )
    col = match.actor_ids.index(partner)
    row = match.object_of(partner)
    center, half, yaw = match.actor_center[col], match.actor_half[col], match.actor_yaw[col]
    velocity = real_velocity(cc, partner, ts)
    plan = cc.plan(ts)
    true_boxes = moving_boxes(center, velocity, float(yaw), half, cc)
    if row is None:
        (c_true,) = pair_clearances([(plan.boxes if plan else None, true_boxes)], cc.window)
        return PartnerPerception(
            partner,
            bool(match.actor_in_range[col]),
            None,
            math.nan,
            math.nan,
            NAN2,
            math.nan,
            c_true,
            undefined_clearance(cc.window),
            False,
        )
    objects = match.objects
    o_center, o_half = objects.location[row, :2], objects.extent[row, :2]
    o_yaw, o_velocity = float(objects.yaw[row]), objects.velocity[row, :2]
    known = bool(np.isfinite(o_velocity).all())
    seen_boxes = moving_boxes(o_center, o_velocity if known else velocity, o_yaw, o_half, cc)
    ego = plan.boxes if plan else None
    c_true, c_perc = pair_clearances([(ego, true_boxes), (ego, seen_boxes)], cc.window)
    size = 2.0 * (o_half - half)
    return PartnerPerception(
        partner_id=partner,
        in_range=bool(match.actor_in_range[col]),
        object_id=objects.ids[row],
        position_error=float(np.hypot(*(o_center - center))),
        yaw_error=float(yaw_error(o_yaw, yaw)),
        extent_error=(float(size[0]), float(size[1])),
        velocity_error=float(np.hypot(*(o_velocity - velocity))) if known else math.nan,
        c_true=c_true,
        c_perc=c_perc,
        overstated=bool(c_perc.value - c_true.value >= cc.params.understate_min),
    )


def _not_matched(cc: CorrectedContext, ts: int, thresholds: dict[str, float]) -> OracleResult:
    """Rule 2b cannot run at ts: say which input is missing (reported once per file)."""
    name, frames = source(cc)
    field = "tracks_3d" if name == "tracked" else "detections_3d"
    if ts not in frames:
        why = f"missing {field}"
        if cc.in_log(ts):
            cc.ctx.report(field, "", "missing (3-D perception check)", ts)
    elif ts not in cc.log.actors:
        why = "missing actors"
    elif ego_box(cc, ts) is None:
        why = "no ego position"
        cc.ctx.report(cc.log.file_of("actors", ts), "ego", "no ego box (3-D perception)", ts)
    else:
        why = "no match"
    return skipped("perception", ts, why, thresholds=thresholds)


def perception3d(ctx: RunContext, ts: int) -> OracleResult:
    """Rule 2b at ts, with the bird's-eye detection metrics."""
    cc = corrected_context(ctx)
    p = cc.params
    thresholds = p.values(REPORTED_3D)
    match = frame_match(cc, ts)
    if match is None:
        return _not_matched(cc, ts, thresholds)
    metrics: dict[str, Metric] = {"check": "3d", "source": match.source}
    metrics.update(object_metrics(match))
    seen = partner_perception(cc, ts)
    if seen is None:
        metrics["unconditioned"] = False
        return OracleResult("perception", ts, False, metrics, thresholds)
    partner = seen.partner_id
    metrics.update(
        partner_in_range=seen.in_range,
        partner_matched=seen.matched,
        partner_object=seen.object_id,
        partner_position_error=num(seen.position_error),
        partner_yaw_error=num(seen.yaw_error),
        partner_extent_error=list(seen.extent_error),
        partner_velocity_error=num(seen.velocity_error),
    )
    ids = (partner,) if seen.object_id is None else (partner, seen.object_id)
    degraded = seen.in_range and (not seen.matched or seen.overstated)
    metrics["unconditioned"] = bool(degraded)
    if not seen.in_range:
        return OracleResult("perception", ts, False, metrics, thresholds, ids)
    absent = missing_inputs(cc, ts, ("pose", "waypoint"), "3-D perception check (clearances)")
    if absent:
        return skipped("perception", ts, f"missing {', '.join(absent)}", metrics, thresholds)
    view = partner_view(cc, ts)
    metrics.update(
        real_conflict=view.real_conflict,
        overstated=seen.overstated,
        **clearance_metrics("c_gt", view.c_gt),
        **clearance_metrics("c_true", seen.c_true),
        **clearance_metrics("c_perc", seen.c_perc),
    )
    failed = bool(view.real_conflict and degraded)
    return OracleResult("perception", ts, failed, metrics, thresholds, ids)
