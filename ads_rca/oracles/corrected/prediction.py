"""The prediction rule: prediction is judged on the predictions on truth
(``predictions_with_perception``: correct perception given).

Predictions are anchored at the ego pose at ts and rotated by its yaw; key k is k + 1
frames ahead (the prediction frame), so exact predictions are never flagged. A failure needs a
real conflict (c_gt < ``safety_margin``) that the prediction made look safer than it was:
c_on_truth (the clearance of the partner's boxes predicted on truth, reported as ``c_pwp``)
− c_gt > ``understate_min``, and either the partner's displacement error e (max over
the horizon of |predicted − real|) exceeds the threshold or the prediction hid the conflict
(c_on_truth >= ``safety_margin``). Pessimistic errors are reported in the metrics, never blamed.
The partner in view but absent from the predictions on truth during a real conflict also fails.

Every frame also reports ADE, FDE and the miss rate (FDE > 2 m) over all predicted actors.
"""

from __future__ import annotations

import math

import numpy as np

from ads_rca.foundation.geometry import FloatArray, ego_to_world
from ads_rca.model import EgoPose, Predictions
from ads_rca.oracles.base import Metric, OracleResult, RunContext
from ads_rca.oracles.corrected.boxes import Series, step_order
from ads_rca.oracles.corrected.clearance import (
    Clearance,
    PartnerView,
    displacement,
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
from ads_rca.oracles.corrected.context import CacheName, CorrectedContext, corrected_context
from ads_rca.oracles.corrected.floors import Samples, actor_floor, perceived_offsets
from ads_rca.oracles.corrected.match3d import frame_match, raw_without_predictions_on_truth
from ads_rca.oracles.corrected.perception3d import PartnerPerception, partner_perception

#: A final displacement error above this is a miss (the usual motion-forecasting metric).
MISS_DISTANCE = 2.0


def displacement_metrics(
    judging: CorrectedContext, ids: list[str], err: FloatArray
) -> dict[str, Metric]:
    """ADE, FDE per actor and overall, and the miss rate, from :func:`errors`' distances."""
    w = judging.window
    out: dict[str, Metric] = {
        "ade": math.nan,
        "fde": math.nan,
        "miss_rate": math.nan,
        "missed_actors": [],
        "ade_per_actor": {},
        "fde_per_actor": {},
    }
    if not ids:
        return out
    finite = np.isfinite(err)
    count = finite.sum(axis=1)
    has = count > 0
    ade = np.where(has, np.where(finite, err, 0.0).sum(axis=1) / np.maximum(count, 1), np.nan)
    last = w - 1 - finite[:, ::-1].argmax(axis=1)
    fde = np.where(has, err[np.arange(len(ids)), last], np.nan)
    fdes: list[float] = fde.tolist()
    n = int(np.count_nonzero(has))
    if n:
        # a mean is the sum over the count (what ndarray.mean computes, without its wrapper)
        out["ade"] = float(ade[has].sum()) / n
        out["fde"] = float(fde[has].sum()) / n
        missed: list[Metric] = [a for a, v in zip(ids, fdes, strict=True) if v > MISS_DISTANCE]
        out["miss_rate"] = len(missed) / n
        out["missed_actors"] = missed
    out["ade_per_actor"] = dict(zip(ids, ade.tolist(), strict=True))
    out["fde_per_actor"] = dict(zip(ids, fdes, strict=True))
    return out


def errors(
    judging: CorrectedContext,
    ts: int,
    tracks_by_actor: Predictions,
    pose: EgoPose,
    offsets: dict[str, FloatArray] | None = None,
) -> tuple[list[str], FloatArray]:
    """Non-ego actor ids and their |predicted − reference| centre distance (A, W) at
    indices 1..W (NaN where undefined): the reference is the real position, moved by
    ``offsets[actor]`` (indices 0..W) where given."""
    w, frame_ms = judging.window, judging.frame_ms
    ids = [a for a in tracks_by_actor if a != judging.ego_id]
    if not ids:
        return [], np.zeros((0, w))
    tracks = [tracks_by_actor[a] for a in ids]
    keys = tracks[0].keys
    anchor = np.array([pose.x, pose.y])
    predicted = np.full((len(ids), w, 2), np.nan)
    if all(t.keys == keys for t in tracks):  # the usual case: one key set, stack at once
        order, k = step_order(keys, w)
        if order.size:
            stacked = np.array([t.offsets for t in tracks])[:, order, :2]
            predicted[:, k] = ego_to_world(stacked, anchor, pose.yaw)
    else:
        for n, track in enumerate(tracks):
            order, k = step_order(track.keys, w)
            if order.size:
                predicted[n, k] = ego_to_world(track.offsets[order, :2], anchor, pose.yaw)
    real = judging.locations_over(judging.gids(ids), [ts + (j + 1) * frame_ms for j in range(w)])
    if offsets is not None:
        shift = np.array([offsets.get(a, np.full((w + 1, 2), np.nan))[1:] for a in ids])
        real = real + shift
    diff = predicted - real
    return ids, np.hypot(diff[..., 0], diff[..., 1])


ERRORS_ON_TRUTH: CacheName[tuple[list[str], FloatArray]] = CacheName("errors_on_truth")


def errors_on_truth(judging: CorrectedContext, ts: int) -> tuple[list[str], FloatArray]:
    """:func:`errors` of the predictions on truth at ts (cached: the frame's metrics and,
    later, its noise-floor samples read it); the caller has checked that the predictions on
    truth and the pose exist."""
    return judging.cache(ERRORS_ON_TRUTH).get(
        ts,
        lambda: errors(
            judging, ts, judging.log.predictions_with_perception[ts], judging.log.pose[ts]
        ),
    )


def prediction_samples(judging: CorrectedContext, u: int) -> Samples:
    """Prediction's error per actor at u, the noise-floor rule's samples (cached): e, the max
    over the horizon of |predicted − real| centre, of every non-ego actor's track predicted on
    truth; without predictions on truth (the 3-D perception rule's reading), of every raw
    track the 3-D match paired, against reality as perceived."""
    return judging.cache(PREDICTION_SAMPLES).get(u, lambda: _carried_samples(judging, u))


def _carried_samples(judging: CorrectedContext, u: int) -> Samples:
    """The samples at u, carried from the run's last context that read the same records
    (a live monitor's views overlap on every floor frame but the newest); on truth only:
    the raw reading's samples also depend on the perception match."""
    if judging.ctx.carried is None or raw_without_predictions_on_truth(judging):
        return _prediction_samples(judging, u)
    log, frame_ms = judging.log, judging.frame_ms
    sources = (
        judging.params,
        judging.ego_id,
        frame_ms,
        judging.window,
        log.pose.get(u),
        log.predictions_with_perception.get(u),
        *[log.actors.get(u + j * frame_ms) for j in range(1, judging.window + 1)],
    )
    return judging.carried(PREDICTION_SAMPLES, u, sources, lambda: _prediction_samples(judging, u))


def _prediction_samples(judging: CorrectedContext, u: int) -> Samples:
    pose = judging.log.pose.get(u)
    if pose is None:
        return {}
    if raw_without_predictions_on_truth(judging):
        raw = judging.log.predictions.get(u)
        if raw is None:
            return {}
        ids, err = errors(
            judging, u, by_actor(judging, u, raw), pose, perceived_offsets(judging, u)
        )
    else:
        if u not in judging.log.predictions_with_perception:
            return {}
        ids, err = errors_on_truth(judging, u)
    if not ids:  # no actor predicted (most frames of a quiet run): no array calls
        return {}
    finite: list[bool] = np.asarray(np.isfinite(err).any(axis=1), dtype=bool).tolist()
    e = np.where(np.isfinite(err), err, -np.inf).max(axis=1)
    return {a: float(v) for a, v, k in zip(ids, e.tolist(), finite, strict=True) if k}


PREDICTION_SAMPLES: CacheName[Samples] = CacheName("prediction_samples")


def judge(
    judging: CorrectedContext,
    c_pred: Clearance,
    c_gt: Clearance,
    e: float,
    view: PartnerView,
    allowance: float,
) -> tuple[bool, bool, bool, bool]:
    """The prediction rule's tests on a predicted clearance and displacement error, each fixed
    threshold raised by the noise ``allowance`` (the noise-floor rule): (e over the threshold,
    understated by more than understate_min, conflict hidden, judged failing)."""
    p = judging.params
    e_over = e > view.threshold + allowance
    understated = c_pred.value - c_gt.value > p.understate_min + allowance
    # an error within the noise floor hides nothing: the stack's ordinary state
    hidden = c_pred.value >= p.safety_margin and (allowance == 0 or e > allowance)
    return e_over, understated, hidden, understated and (e_over or hidden)


def by_actor(judging: CorrectedContext, ts: int, raw: Predictions) -> Predictions:
    """The raw tracks the 3-D perception rule matched to an actor at ts, keyed by that actor
    (file order)."""
    match = frame_match(judging, ts)
    if match is None:
        return {}
    actor_of = {
        match.objects.ids[r]: match.actor_ids[c]
        for r, c in zip(match.rows.tolist(), match.cols.tolist(), strict=True)
    }
    return {actor_of[i]: track for i, track in raw.items() if i in actor_of}


def prediction(ctx: RunContext, ts: int) -> OracleResult:
    """The prediction rule at ts, with ADE/FDE/miss rate."""
    judging = corrected_context(ctx)
    p = judging.params
    thresholds = {**judging.reported(REPORTED["prediction"]), "miss_distance": MISS_DISTANCE}
    if raw_without_predictions_on_truth(judging):
        return raw_prediction(judging, ts, thresholds)
    absent = missing_inputs(
        judging, ts, ("pose", "predictions_with_perception"), "prediction check"
    )
    if absent:
        return missing_skip("prediction", ts, absent, thresholds=thresholds)
    metrics = displacement_metrics(judging, *errors_on_truth(judging, ts))
    partner = judging.partner_at(ts)
    if partner is None:
        metrics["unconditioned"] = False
        return OracleResult("prediction", ts, False, metrics, thresholds)
    view = partner_view(judging, ts)
    thresholds["displacement_threshold"] = view.threshold
    absent_from_predictions_on_truth = bool(view.in_view) and view.in_predictions_on_truth is False
    floor = actor_floor(judging, ts, prediction_samples)
    allowance = p.noise_floor_factor * floor.value
    e_over, understated, hidden, judged = judge(
        judging, view.c_on_truth, view.c_gt, view.e_on_truth, view, allowance
    )
    metrics.update(
        **floor.metrics("prediction"),
        noise_allowance=allowance,
        partner_in_view=view.in_view,
        partner_in_pwp=view.in_predictions_on_truth,
        displacement_error=num(view.e_on_truth),
        displacement_threshold=view.threshold,
        partner_travelled=num(view.travelled),
        real_conflict=view.real_conflict,
        understated=bool(understated),
        conflict_hidden=bool(hidden),
        pessimistic=bool(view.c_on_truth.value < view.c_gt.value),
        unconditioned=bool(e_over or absent_from_predictions_on_truth),
        **clearance_metrics("c_gt", view.c_gt),
        **clearance_metrics("c_pwp", view.c_on_truth),
    )
    failed = bool(view.real_conflict and (judged or absent_from_predictions_on_truth))
    reason = None
    if ts not in judging.log.waypoints:
        judging.missing("waypoint", ts, "prediction check needs the plan for clearances")
        reason = "missing waypoint"
    return OracleResult(
        "prediction", ts, failed, metrics, thresholds, (partner,), reason, reason is not None
    )


def raw_prediction(
    judging: CorrectedContext, ts: int, thresholds: dict[str, float]
) -> OracleResult:
    """The prediction rule without predictions on ground truth (the 3-D perception rule's
    reading): the partner's raw track, linked by the 3-D match, judged only where the partner
    was perceived correctly at ts, against reality as perceived (:func:`perceived_reality`), so
    that it answers for its own model as the predictions on truth would."""
    absent = missing_inputs(judging, ts, ("pose", "predictions"), "prediction check (raw)")
    if absent:
        return missing_skip("prediction", ts, absent, thresholds=thresholds)
    pose = judging.log.pose[ts]
    raw = by_actor(judging, ts, judging.log.predictions[ts])
    metrics = displacement_metrics(judging, *errors(judging, ts, raw, pose))
    metrics["basis"] = "raw"
    if judging.partner_at(ts) is None:
        metrics["unconditioned"] = False
        return OracleResult("prediction", ts, False, metrics, thresholds)
    seen = partner_perception(judging, ts)
    if seen is None or not seen.correct:
        why = "perception of the partner not correct at ts"
        return skipped("prediction", ts, why, metrics, thresholds)
    view = partner_view(judging, ts)
    if view.raw is None:
        return skipped("prediction", ts, "no raw prediction of the partner", metrics, thresholds)
    thresholds["displacement_threshold"] = view.threshold
    ref, c_ref = perceived_reality(judging, ts, view, seen)
    e = displacement(view.raw, ref)
    floor = actor_floor(judging, ts, prediction_samples)
    allowance = judging.params.noise_floor_factor * floor.value
    e_over, understated, hidden, judged = judge(judging, view.c_raw, c_ref, e, view, allowance)
    metrics.update(
        **floor.metrics("prediction"),
        noise_allowance=allowance,
        partner_in_view=seen.in_range,
        partner_in_raw=True,
        raw_id=view.raw_id,
        displacement_error=num(e),
        displacement_threshold=view.threshold,
        partner_travelled=num(view.travelled),
        real_conflict=view.real_conflict,
        understated=bool(understated),
        conflict_hidden=bool(hidden),
        pessimistic=bool(view.c_raw.value < view.c_gt.value),
        unconditioned=bool(e_over),
        **clearance_metrics("c_gt", view.c_gt),
        **clearance_metrics("c_ref", c_ref),
        **clearance_metrics("c_raw", view.c_raw),
    )
    failed = bool(view.real_conflict and judged)
    reason = None
    if ts not in judging.log.waypoints:
        judging.missing("waypoint", ts, "prediction check needs the plan for clearances")
        reason = "missing waypoint"
    ids = (seen.partner_id,) if view.raw_id is None else (seen.partner_id, view.raw_id)
    return OracleResult("prediction", ts, failed, metrics, thresholds, ids, reason)


def perceived_reality(
    judging: CorrectedContext, ts: int, view: PartnerView, seen: PartnerPerception
) -> tuple[Series | None, Clearance]:
    """The reference of a raw prediction: the partner's real boxes moved by the state error
    perception made at ts (and the 3-D perception rule accepted), so prediction answers only
    for its own model, as a prediction on ground truth would."""
    if view.real is None or seen.offset is None:
        return view.real, view.c_gt
    ref = Series(view.real.center + seen.offset, view.real.yaw, view.real.half)
    plan = judging.plan(ts)
    (c_ref,) = pair_clearances([(plan.boxes if plan else None, ref)], judging.window)
    return ref, c_ref
