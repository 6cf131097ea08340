"""The 3-D perception rule: perception in 3-D, judged like the 2-D perception rule on what
the stack perceived of the partner.

Real stacks perceive objects as 3-D boxes (tracked objects, 3-D detections), not image boxes.
Every frame reports bird's-eye detection metrics from the match of :mod:`.match3d` (precision,
recall, IoU, position and heading errors, missed actors, false positives). A failure needs a
real conflict (c_gt < ``safety_margin``) with the partner in sensing range and either missed,
or perceived so that the clearance looked safer than it was by at least ``understate_min``
while displaced beyond the displacement threshold or hiding the conflict (the 2-D perception
rule's test): the real and the perceived partner are both moved at constant velocity from ts
(the real velocity from the ground truth over one frame, the perceived one as recorded) against
the ego's plan boxes, so only the errors of position, extent, heading and velocity at ts count,
not the partner's later manoeuvres (prediction's business). A velocity off by more than
``perc3d_velocity_error`` is also tested over the stack's whole plan, longer than the judged
window: optimistic there, it fails too (``misled``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ads_rca.foundation.geometry import FloatArray
from ads_rca.oracles.base import Metric, OracleResult, RunContext
from ads_rca.oracles.corrected.boxes import Series, build_plan
from ads_rca.oracles.corrected.clearance import (
    Clearance,
    displacement,
    displacement_threshold,
    pair_clearances,
    partner_view,
    path_length,
    undefined_clearance,
)
from ads_rca.oracles.corrected.common import (
    FLOOR_PARAMETERS,
    clearance_metrics,
    missing_inputs,
    missing_skip,
    num,
    skipped,
)
from ads_rca.oracles.corrected.context import (
    CacheName,
    CorrectedContext,
    corrected_context,
    ego_box,
)
from ads_rca.oracles.corrected.floors import (
    NO_FLOOR,
    Floor,
    partner_row,
    perception_floor,
    velocity_floor,
)
from ads_rca.oracles.corrected.match3d import Match3D, frame_match, source

#: The parameters the 3-D perception rule's results report in ``thresholds``, in that order.
REPORTED_3D = (
    "perc3d_match_iou",
    "perc3d_match_distance",
    "perc3d_small_area",
    "perc3d_range",
    "perc3d_velocity_error",
    "safety_margin",
    "understate_min",
    "pred_abs_threshold",
    "pred_score_threshold",
    *FLOOR_PARAMETERS,
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
    overstated: bool  # looked safer by understate_min, displaced or hiding the conflict
    displacement: float = math.nan  # max |perceived − real| centre over the window
    threshold: float = math.nan  # the displacement threshold
    velocity_wrong: bool = False  # velocity_error > perc3d_velocity_error
    misled: Misled | None = None  # the velocity test over the plan (None: not run)
    #: perceived − real centre at indices 0..W (both at constant velocity); None unmatched
    offset: FloatArray | None = None
    floor: Floor = NO_FLOOR  # the displacement noise floor (matched only)
    velocity_floor: Floor = NO_FLOOR  # the velocity-error noise floor (matched only)
    velocity_change: float = 0.0  # |the real velocity's change across ts| (matched only)
    allowance: float = 0.0  # noise_floor_factor × floor (m)
    by_allowance: bool = False  # paired with its object only within the noise allowance

    @property
    def matched(self) -> bool:
        return self.object_id is not None

    @property
    def misleading(self) -> bool:
        """A wrong velocity that made the partner look safer over the stack's plan."""
        return self.misled is not None and self.misled.optimistic

    @property
    def degraded(self) -> bool:
        """Missed, overstated, or moving as it does not: perception let the stack down."""
        return not self.matched or self.overstated or self.misleading

    @property
    def correct(self) -> bool:
        """Matched, not overstated, velocity right: prediction may be judged from it (a
        prediction that propagates a wrong perceived velocity is not prediction's error)."""
        return self.matched and not self.overstated and not self.velocity_wrong


@dataclass(frozen=True)
class Misled:
    """The velocity test: real and perceived partner at constant velocity over every step
    of the stack's plan (its own horizon, not only the judged window)."""

    horizon: int  # plan steps compared
    c_true: float
    c_perc: float
    optimistic: bool  # c_perc − c_true >= understate_min


NAN2 = (math.nan, math.nan)
PARTNER: CacheName[PartnerPerception | None] = CacheName("partner_perception")


def partner_perception(judging: CorrectedContext, ts: int) -> PartnerPerception | None:
    """The partner's perception at ts (cached per partner); None without a partner, or
    without a match at ts (no actors, perceived objects or ego position)."""
    cache = judging.cache(PARTNER)
    found = cache.lookup(ts)
    partner = judging.partner_at(ts)
    if found is None or found.partner_id != partner:
        found = _assess(judging, ts, partner)
        cache.put(ts, found)
    return found


def real_velocity(judging: CorrectedContext, actor_id: str, ts: int) -> FloatArray:
    """The actor's world velocity (2,) at ts: its displacement to ts + frame_ms over one frame
    (from ts − frame_ms when ts + frame_ms has none); NaN when neither."""
    now = judging.actor_state(actor_id, ts)
    dt = judging.frame_ms / 1000.0
    if now is None:
        return np.full(2, np.nan)
    later = judging.actor_state(actor_id, ts + judging.frame_ms)
    if later is not None:
        return np.asarray((later[0] - now[0]) / dt, dtype=np.float64)
    earlier = judging.actor_state(actor_id, ts - judging.frame_ms)
    if earlier is not None:
        return np.asarray((now[0] - earlier[0]) / dt, dtype=np.float64)
    return np.full(2, np.nan)


def velocity_change(judging: CorrectedContext, actor_id: str, ts: int) -> float:
    """How much the actor's real velocity changes across ts: |v(ts → ts + tpf) − v(ts − tpf →
    ts)| (m/s), 0 where either is unknown. :func:`real_velocity` looks one frame ahead, which
    a tracker at ts has not seen: an error within this change is any tracker's lag."""
    states = [judging.actor_state(actor_id, ts + k * judging.frame_ms) for k in (-1, 0, 1)]
    if any(state is None for state in states):
        return 0.0
    before, now, after = (state[0] for state in states if state is not None)
    change = float(np.hypot(*(after - 2.0 * now + before))) / (judging.frame_ms / 1000.0)
    return change if math.isfinite(change) else 0.0


@dataclass(frozen=True)
class Motion:
    """A box at ts moving at constant velocity: how the 3-D perception rule propagates both
    the real and the perceived partner, so only their states at ts differ."""

    center: FloatArray  # (2,) world metres
    velocity: FloatArray  # (2,) m/s
    yaw: float  # degrees
    half: FloatArray  # (2,) half extents

    def boxes(self, judging: CorrectedContext, horizon: int) -> Series:
        """Boxes at indices 0..``horizon`` (index i is i frames after ts)."""
        t = judging.seconds(np.arange(horizon + 1))
        moved = self.center[None, :] + t[:, None] * self.velocity[None, :]
        return Series(moved, np.full(len(t), self.yaw), self.half)


def _assess(judging: CorrectedContext, ts: int, partner: str | None) -> PartnerPerception | None:
    match = frame_match(judging, ts)
    if partner is None or match is None:
        return None
    if partner not in match.actor_ids:
        none = undefined_clearance(judging.window)
        return PartnerPerception(
            partner, False, None, math.nan, math.nan, NAN2, math.nan, none, none, False
        )
    col = match.actor_ids.index(partner)
    row, by_allowance = partner_row(judging, ts, partner)
    velocity = real_velocity(judging, partner, ts)
    real = Motion(
        match.actor_center[col], velocity, float(match.actor_yaw[col]), match.actor_half[col]
    )
    plan = judging.plan(ts)
    ego = plan.boxes if plan else None
    in_range = bool(match.actor_in_range[col])
    if row is None:
        (c_true,) = pair_clearances([(ego, real.boxes(judging, judging.window))], judging.window)
        none = undefined_clearance(judging.window)
        return PartnerPerception(
            partner, in_range, None, math.nan, math.nan, NAN2, math.nan, c_true, none, False
        )
    objects = match.objects
    o_velocity = objects.velocity[row, :2]
    known = bool(np.isfinite(o_velocity).all())
    seen = Motion(
        objects.location[row, :2],
        o_velocity if known else velocity,
        float(objects.yaw[row]),
        objects.extent[row, :2],
    )
    real_boxes, seen_boxes = (
        real.boxes(judging, judging.window),
        seen.boxes(judging, judging.window),
    )
    c_true, c_perc = pair_clearances([(ego, real_boxes), (ego, seen_boxes)], judging.window)
    displaced = displacement(seen_boxes, real_boxes)
    threshold = displacement_threshold(judging, path_length(real_boxes))
    p = judging.params
    floor, v_floor = perception_floor(judging, ts), velocity_floor(judging, ts)
    allowance = p.noise_floor_factor * floor.value  # the noise-floor rule
    hidden = c_perc.value >= p.safety_margin > c_true.value  # the error hid the conflict
    overstated = c_perc.value - c_true.value >= p.understate_min + allowance and (
        displaced > threshold + allowance or hidden
    )
    size = 2.0 * (seen.half - real.half)
    velocity_error = float(np.hypot(*(o_velocity - velocity))) if known else math.nan
    change = velocity_change(judging, partner, ts)
    v_limit = p.perc3d_velocity_error + p.noise_floor_factor * v_floor.value + change
    velocity_wrong = velocity_error > v_limit  # False for NaN
    misled = _misled(judging, ts, real, seen, allowance) if velocity_wrong else None
    return PartnerPerception(
        partner_id=partner,
        in_range=in_range,
        object_id=objects.ids[row],
        position_error=float(np.hypot(*(seen.center - real.center))),
        yaw_error=float(yaw_error(seen.yaw, real.yaw)),
        extent_error=(float(size[0]), float(size[1])),
        velocity_error=velocity_error,
        c_true=c_true,
        c_perc=c_perc,
        overstated=bool(overstated),
        displacement=displaced,
        threshold=threshold,
        velocity_wrong=velocity_wrong,
        misled=misled,
        offset=seen_boxes.center - real_boxes.center,
        floor=floor,
        velocity_floor=v_floor,
        velocity_change=change,
        allowance=allowance,
        by_allowance=by_allowance,
    )


def _misled(
    judging: CorrectedContext, ts: int, real: Motion, seen: Motion, allowance: float
) -> Misled | None:
    """The velocity test at ts over every step of the stack's plan at ts (at most
    ``PLAN_HORIZON_MAX_S``), optimistic by ``understate_min`` plus the noise ``allowance``; None
    without a plan with a step beyond 0 or a pose at ts."""
    plan, pose = judging.log.waypoints.get(ts), judging.log.pose.get(ts)
    if plan is None or pose is None:
        return None
    horizon = judging.plan_horizon(plan)
    built = build_plan(plan, pose, judging.ego_half, horizon) if horizon >= 1 else None
    if built is None:
        return None
    c_true, c_perc = pair_clearances(
        [(built.boxes, real.boxes(judging, horizon)), (built.boxes, seen.boxes(judging, horizon))],
        horizon,
    )
    optimistic = bool(c_perc.value - c_true.value >= judging.params.understate_min + allowance)
    return Misled(horizon, c_true.value, c_perc.value, optimistic)


def _not_matched(judging: CorrectedContext, ts: int, thresholds: dict[str, float]) -> OracleResult:
    """The 3-D perception rule cannot run at ts: say which input is missing (reported once
    per file)."""
    name, frames = source(judging)
    field = "tracks_3d" if name == "tracked" else "detections_3d"
    missing = True
    if ts not in frames:
        why = f"missing {field}"
        missing = judging.in_log(ts)
        if missing:
            judging.ctx.report(field, "", "missing (3-D perception check)", ts)
    elif ts not in judging.log.actors:
        why = "missing actors"
    elif ego_box(judging, ts) is None:
        why = "no ego position"
        judging.ctx.report(
            judging.log.file_of("actors", ts), "ego", "no ego box (3-D perception)", ts
        )
    else:
        why, missing = "no match", False
    return skipped("perception", ts, why, thresholds=thresholds, missing_input=missing)


def perception3d(ctx: RunContext, ts: int) -> OracleResult:
    """The 3-D perception rule at ts, with the bird's-eye detection metrics."""
    judging = corrected_context(ctx)
    thresholds = judging.reported(REPORTED_3D)
    match = frame_match(judging, ts)
    if match is None:
        return _not_matched(judging, ts, thresholds)
    metrics: dict[str, Metric] = {"check": "3d", "source": match.source}
    metrics.update(object_metrics(match))
    seen = partner_perception(judging, ts)
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
        partner_displacement=num(seen.displacement),
        displacement_threshold=num(seen.threshold),
    )
    if seen.matched:
        metrics.update(
            **seen.floor.metrics("perception"),
            **seen.velocity_floor.metrics("velocity"),
            partner_velocity_change=seen.velocity_change,
            noise_allowance=seen.allowance,
            partner_paired_by_allowance=seen.by_allowance,
        )
    ids = (partner,) if seen.object_id is None else (partner, seen.object_id)
    if seen.misled is not None:
        metrics.update(
            misled_horizon=seen.misled.horizon,
            misled_c_true=num(seen.misled.c_true),
            misled_c_perc=num(seen.misled.c_perc),
        )
    metrics["velocity_wrong"] = seen.velocity_wrong
    metrics["misled"] = seen.misleading
    degraded = seen.in_range and seen.degraded
    # The fallback's test is the error alone, as the prediction rule's (e above the threshold).
    metrics["unconditioned"] = bool(degraded or (seen.in_range and seen.velocity_wrong))
    if not seen.in_range:
        return OracleResult("perception", ts, False, metrics, thresholds, ids)
    absent = missing_inputs(judging, ts, ("pose", "waypoint"), "3-D perception check (clearances)")
    if absent:
        return missing_skip("perception", ts, absent, metrics, thresholds)
    view = partner_view(judging, ts)
    metrics.update(
        real_conflict=view.real_conflict,
        overstated=seen.overstated,
        **clearance_metrics("c_gt", view.c_gt),
        **clearance_metrics("c_true", seen.c_true),
        **clearance_metrics("c_perc", seen.c_perc),
    )
    failed = bool(view.real_conflict and degraded)
    return OracleResult("perception", ts, failed, metrics, thresholds, ids)
