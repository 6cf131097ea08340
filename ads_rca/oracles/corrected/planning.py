"""The planning rule: planning is judged against its own inputs (the raw predictions), with
feasibility.

If the partner is not in the planner's inputs (no raw prediction links to it), planning is
not at fault: that is an upstream failure. Otherwise c_plan is the clearance of the plan
against the partner's raw boxes, reached at i*. Planning fails when c_plan <
``safety_margin``, the plan was not already braking at the limit, and a safer plan existed:
the same path driven from v0 braking at ``max_decel`` to a stop keeps clearance > 0 against
the same raw boxes at every index (``boxes.braking_boxes``, computed with the partner's view).
A plan unsafe only against ground truth is not a planning failure.

The same test also runs over the plan's own horizon (:func:`over_plan_horizon`), not only
the ``prediction_window`` every clearance looks ahead, against the partner's raw boxes at the
extent the planner was given (:func:`perceived_half`): a planner that drops a partner its
inputs show in its path a second ahead would otherwise be judged only once braking no longer
helps (issue 40, item 3). Metrics also give clearances and times to collision against
predictions and ground truth, and the plan-vs-realised ego displacement error.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import numpy.typing as npt

from ads_rca.foundation.geometry import FloatArray, ego_to_world
from ads_rca.model import EgoPose, Plan, Track
from ads_rca.oracles.base import Metric, OracleResult, RunContext
from ads_rca.oracles.corrected.boxes import PlanData, braking_boxes, build_plan, step_order
from ads_rca.oracles.corrected.clearance import (
    Clearance,
    PartnerView,
    pair_clearances,
    partner_view,
)
from ads_rca.oracles.corrected.common import (
    REPORTED,
    clearance_metrics,
    missing_inputs,
    missing_skip,
    num,
    skipped,
)
from ads_rca.oracles.corrected.context import CorrectedContext, corrected_context
from ads_rca.oracles.corrected.match3d import raw_without_predictions_on_truth

#: The folders the planning rule needs to link the planner's inputs to the partner (the
#: predictions on truth: the link; without them in the log, the 3-D match links them and only
#: the predictions are needed).
PLANNER_INPUTS = ("predictions", "predictions_with_perception")


def time_to_collision(judging: CorrectedContext, c: Clearance) -> float:
    """Seconds to the first horizon index with contact (distance <= 0); NaN if none."""
    if not c.value <= 0.0:  # the least distance is not contact (or there is none)
        return math.nan
    contact = np.flatnonzero(c.per_index <= 0.0)
    return float(judging.seconds(int(contact[0]))) if contact.size else math.nan


def realised_error(judging: CorrectedContext, ts: int, plan: PlanData) -> dict[str, Metric]:
    """Plan point i vs the realised pose at ts + i·frame_ms, i = 1..W: mean, max and last."""
    poses = judging.log.pose
    after = [poses.get(ts + i * judging.frame_ms) for i in range(1, judging.window + 1)]
    real = np.array([_NOWHERE if p is None else (p.x, p.y) for p in after], dtype=np.float64)
    diff = plan.boxes.center[1:] - real
    err = np.hypot(diff[:, 0], diff[:, 1])
    err = err[np.isfinite(err)]
    if err.size == 0:
        return {"plan_realised_error_mean": math.nan, "plan_realised_error_max": math.nan}
    return {
        # the sum over the count: what ndarray.mean computes; the reductions ndarray.sum and
        # .max call, without their wrappers
        "plan_realised_error_mean": float(np.add.reduce(err)) / err.size,
        "plan_realised_error_max": float(np.maximum.reduce(err)),
    }


_NOWHERE = (math.nan, math.nan)


def perceived_half(
    judging: CorrectedContext, ts: int, raw_id: str, partner: str
) -> FloatArray | None:
    """The partner's half extent (x, y) as the planner was given it: its tracked object's
    (the raw id's) at ts where the log has one, else the real one (None without either)."""
    tracked = judging.log.tracks_3d.get(ts)
    if tracked is not None and raw_id in tracked.ids:
        half = tracked.extent[tracked.ids.index(raw_id), :2].astype(np.float64)
        if np.isfinite(half).all():
            return half
    extent = judging.log.actor_extents.get(partner)
    return None if extent is None else np.asarray(extent[:2], dtype=np.float64)


def _within_reach(plan: Plan, pose: EgoPose, track: Track, horizon: int, reach: float) -> bool:
    """Whether the plan's point and the track's predicted centre come closer than ``reach``
    at some index 1..``horizon``."""
    plan_rows, track_rows = _same_indices(plan.keys, track.keys, horizon)
    if plan_rows.size == 0:
        return False
    anchor = np.array([pose.x, pose.y])
    predicted = ego_to_world(track.offsets[track_rows, :2], anchor, pose.yaw)
    gap = plan.xy[plan_rows] - predicted
    return bool((gap[:, 0] * gap[:, 0] + gap[:, 1] * gap[:, 1] < reach * reach).any())


@lru_cache(maxsize=64)
def _same_indices(
    plan_keys: tuple[str, ...], track_keys: tuple[str, ...], horizon: int
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """The plan's and the track's rows at the indices 1..``horizon`` both have (plan step s
    is index s, track key k index k + 1); memoised: a run's plans and tracks share keys."""
    plan_rows, plan_index = step_order(plan_keys, horizon + 1)
    track_rows, track_steps = step_order(track_keys, horizon)
    index, at_plan, at_track = np.intersect1d(plan_index, track_steps + 1, return_indices=True)
    ahead = index >= 1
    return plan_rows[at_plan[ahead]], track_rows[at_track[ahead]]


@dataclass(frozen=True)
class PlanTest:
    """Rule 4's test of a plan against the partner's raw boxes over some horizon: the
    clearance (reached at i*), whether the plan was braking at the limit there, and the
    clearance of the braking alternative."""

    clearance: Clearance
    v0: float
    t_star: float
    v_star: float
    limit: float  # the speed braking at the limit reaches at i*
    not_at_limit: bool
    braking: float  # the braking alternative's clearance

    @property
    def horizon(self) -> int:
        """The last index the clearance looked at."""
        return int(self.clearance.per_index.size) - 1

    def failed(self, margin: float) -> bool:
        """Unsafe against its own inputs, not braking at the limit, a safer plan at hand."""
        return bool(self.clearance.value < margin and self.not_at_limit and self.braking > 0.0)


def plan_test(
    judging: CorrectedContext, plan: PlanData, raw: Clearance, brake: Clearance
) -> PlanTest:
    """The test of ``plan`` given its clearance ``raw`` against the partner's raw boxes and
    the braking alternative's ``brake`` (``raw`` defined)."""
    p = judging.params
    t_star = float(judging.seconds(raw.index))
    v0 = plan.speed_of(0)
    v_star = float(plan.speed_at[raw.index])
    limit = max(0.0, v0 - (p.max_decel - p.decel_tolerance) * t_star) + p.standstill_speed
    not_at_limit = bool(v_star > limit and v0 >= p.standstill_speed)
    return PlanTest(raw, v0, t_star, v_star, limit, not_at_limit, brake.value)


def over_plan_horizon(judging: CorrectedContext, ts: int, view: PartnerView) -> PlanTest | None:
    """The test over the plan's own horizon H (its last step, at most ``PLAN_HORIZON_MAX_S``):
    the plan, the braking alternative and the partner's raw boxes over indices 1..H. None
    where H is not beyond W (the W test says it all) or a box series cannot be built."""
    log = judging.log
    plan, pose, raw = log.waypoints.get(ts), log.pose.get(ts), log.predictions.get(ts)
    if plan is None or pose is None or raw is None or view.raw_id not in raw:
        return None
    horizon = judging.plan_horizon(plan)
    partner, track = view.partner_id, raw[view.raw_id]
    assert partner is not None  # a raw id links to a partner
    half = perceived_half(judging, ts, view.raw_id, partner)
    if horizon <= judging.window or half is None:
        return None
    # Circumscribed circles further apart than the margin at every index: the test cannot
    # fail, nor report a clearance below the margin; skip it (most frames of a run).
    reach = judging.params.safety_margin + math.hypot(*half) + math.hypot(*judging.ego_half)
    if not _within_reach(plan, pose, track, horizon, reach):
        return None
    built = build_plan(plan, pose, judging.ego_half, horizon)
    boxes = judging.predicted_series(track, pose, partner, ts, horizon, half)
    if built is None or boxes is None:
        return None
    dt, decel = judging.frame_ms / 1000.0, judging.params.max_decel
    brake = braking_boxes(built, pose.yaw, built.speed_of(0), decel, dt, horizon)
    c_raw, c_brake = pair_clearances([(built.boxes, boxes), (brake, boxes)], horizon)
    return plan_test(judging, built, c_raw, c_brake) if c_raw.defined else None


def planning(ctx: RunContext, ts: int) -> OracleResult:
    """The planning rule at ts, with clearance, TTC and plan-vs-realised metrics."""
    judging = corrected_context(ctx)
    p = judging.params
    thresholds = judging.reported(REPORTED["planning"])
    absent = missing_inputs(judging, ts, ("pose", "waypoint"), "planning check")
    plan = None if absent else judging.plan(ts)
    if plan is None:
        reason = f"missing {', '.join(absent)}" if absent else "empty plan"
        if not absent:
            judging.ctx.report(
                judging.log.file_of("waypoint", ts), "", "plan has no usable point", ts
            )
        return skipped("planning", ts, reason, thresholds=thresholds, missing_input=True)
    metrics: dict[str, Metric] = realised_error(judging, ts, plan)
    partner = judging.partner_at(ts)
    if partner is None:
        return OracleResult("planning", ts, False, metrics, thresholds)
    needed = ("predictions",) if raw_without_predictions_on_truth(judging) else PLANNER_INPUTS
    absent = missing_inputs(judging, ts, needed, "planning check (planner inputs)")
    if absent:
        return missing_skip("planning", ts, absent, metrics, thresholds)
    view = partner_view(judging, ts)
    metrics.update(
        partner_in_planner_inputs=view.raw is not None,
        **clearance_metrics("c_plan", view.c_raw),
        **clearance_metrics("c_gt", view.c_gt),
        ttc_pred=time_to_collision(judging, view.c_raw),
        ttc_gt=time_to_collision(judging, view.c_gt),
    )
    ids = (partner,) if view.raw_id is None else (partner, view.raw_id)
    if view.raw is None or not view.c_raw.defined:
        return OracleResult("planning", ts, False, metrics, thresholds, ids)
    within = plan_test(judging, plan, view.c_raw, view.c_brake)
    metrics.update(
        v0=num(within.v0),
        speed_at_i_star=num(within.v_star),
        braking_limit_speed=within.limit,
        plan_decel=(within.v0 - within.v_star) / within.t_star if within.t_star > 0 else math.nan,
        braking_at_limit=not within.not_at_limit,
        braking_clearance=num(within.braking),
        safer_plan_existed=bool(within.braking > 0.0),
    )
    failed = within.failed(p.safety_margin)
    ahead = over_plan_horizon(judging, ts, view)
    if ahead is not None and ahead.clearance.value < p.safety_margin:
        # reported only where it can matter: elsewhere the output stays as before
        metrics.update(
            **clearance_metrics("c_plan_horizon", ahead.clearance),
            plan_horizon=ahead.horizon,
            horizon_braking_at_limit=not ahead.not_at_limit,
            horizon_braking_clearance=num(ahead.braking),
            horizon_failed=ahead.failed(p.safety_margin),
        )
        failed = failed or ahead.failed(p.safety_margin)
    return OracleResult("planning", ts, failed, metrics, thresholds, ids)
