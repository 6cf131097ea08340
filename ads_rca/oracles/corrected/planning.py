"""The planning rule: planning is judged against its own inputs (the raw predictions), with
feasibility.

If the partner is not in the planner's inputs (no raw prediction links to it), planning is
not at fault: that is an upstream failure. Otherwise c_plan is the clearance of the plan
against the partner's raw boxes, reached at i*. Planning fails when c_plan <
``safety_margin``, the plan was not already braking at the limit, and a safer plan existed:
the same path driven from v0 braking at ``max_decel`` to a stop keeps clearance > 0 against
the same raw boxes at every index (``boxes.braking_boxes``, computed with the partner's view).
A plan unsafe only against ground truth is not a planning failure. Metrics also give
clearances and times to collision against predictions and ground truth, and the
plan-vs-realised ego displacement error.
"""

from __future__ import annotations

import math

import numpy as np

from ads_rca.oracles.base import Metric, OracleResult, RunContext
from ads_rca.oracles.corrected.boxes import PlanData
from ads_rca.oracles.corrected.clearance import Clearance, partner_view
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
        # the sum over the count: what ndarray.mean computes, without its wrapper
        "plan_realised_error_mean": float(err.sum()) / err.size,
        "plan_realised_error_max": float(err.max()),
    }


_NOWHERE = (math.nan, math.nan)


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
    i_star = view.c_raw.index
    t_star = float(judging.seconds(i_star))
    v0 = plan.speed_of(0)
    v_star = float(plan.speed_at[i_star])
    limit = max(0.0, v0 - (p.max_decel - p.decel_tolerance) * t_star) + p.standstill_speed
    not_at_limit = bool(v_star > limit and v0 >= p.standstill_speed)
    brake = view.c_brake.value
    safer_exists = bool(brake > 0.0)
    unsafe = bool(view.c_raw.value < p.safety_margin)
    metrics.update(
        v0=num(v0),
        speed_at_i_star=num(v_star),
        braking_limit_speed=limit,
        plan_decel=(v0 - v_star) / t_star if t_star > 0 else math.nan,
        braking_at_limit=not not_at_limit,
        braking_clearance=num(brake),
        safer_plan_existed=safer_exists,
    )
    failed = unsafe and not_at_limit and safer_exists
    return OracleResult("planning", ts, failed, metrics, thresholds, ids)
