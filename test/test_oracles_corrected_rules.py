"""The `corrected` oracles and attribution on hand-computed fixtures (no ROS).

Logs are built in code: an ego "E" and a partner "P" (half extents 2 × 1 m) on trajectories
sampled every 50 ms; by default the plan is the ego's realised future (exact tracking), both
prediction files are the partner's exact future written relative to the ego pose at ts (key
k = k + 1 frames ahead), and the partner is in view and detected. Each test then breaks one
thing and checks the rule that judges it. Property tests compare the vectorised box
distance and clearance with slow straightforward implementations (shapely, pure-Python SAT).
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable
from dataclasses import dataclass, replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import Polygon

from ads_rca.diagnosis.verdict import (
    BASIS_FALLBACK,
    BASIS_JUDGED,
    NO_COLLISION,
    NO_MODULE_FAILED,
    FrameResults,
    json_safe,
)
from ads_rca.foundation.geometry import (
    box_corners,
    box_signed_distance,
    polyline_nearest,
    signed_lateral_offset,
    world_to_ego,
)
from ads_rca.model import Actors, Boxes, EgoPose, Plan, RunLog, RunMetadata, Track
from ads_rca.oracles.base import MODULES, Metric, Module, OracleResult, RunContext
from ads_rca.oracles.corrected import ORACLES, attribute_corrected
from ads_rca.oracles.corrected.boxes import Series, build_plan
from ads_rca.oracles.corrected.clearance import clearances, partner_view
from ads_rca.oracles.corrected.context import corrected_context, floor_span
from ads_rca.params import make_params

TPF = 50
DT = TPF / 1000.0
EGO, PARTNER, TRACK = "E", "P", "T7"
HALF = np.array([2.0, 1.0])
GT_BOX = (100.0, 100.0, 200.0, 200.0)
HORIZON = 15


# --------------------------------------------------------------------------- fixtures
@dataclass
class Traj:
    """Positions (F, 2), yaw (F,) in degrees and speed (F,) at frames 0..F-1."""

    xy: np.ndarray
    yaw: np.ndarray
    speed: np.ndarray


def straight(x0: float, v: float, frames: int, y: float = 0.0, decel: float = 0.0) -> Traj:
    """Along +x from x0 at speed v, decelerating at ``decel`` to a stop."""
    t = np.arange(frames) * DT
    tau = np.minimum(t, v / decel) if decel > 0 else t
    x = x0 + v * tau - 0.5 * decel * tau**2
    speed = np.maximum(v - decel * t, 0.0)
    return Traj(np.column_stack((x, np.full(frames, y))), np.zeros(frames), speed)


def rotated(traj: Traj, deg: float, origin: tuple[float, float] = (0.0, 0.0)) -> Traj:
    th = math.radians(deg)
    r = np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])
    xy = (traj.xy - origin) @ r.T + origin
    return Traj(xy, traj.yaw + deg, traj.speed)


def plan_along(traj: Traj, f: int, horizon: int = HORIZON) -> Plan:
    """The realised future from frame f as a plan (exact tracking)."""
    idx = np.minimum(np.arange(f, f + horizon + 1), len(traj.speed) - 1)
    return Plan(tuple(str(i) for i in range(horizon + 1)), traj.xy[idx], traj.speed[idx])


def plan_from_pose(
    pose: EgoPose, v0: float, decel: float, horizon: int = HORIZON, lateral: float = 0.0
) -> Plan:
    """From the pose along its heading at v0 decelerating at ``decel``; optional lateral."""
    t = np.arange(horizon + 1) * DT
    tau = np.minimum(t, v0 / decel) if decel > 0 else t
    s = v0 * tau - 0.5 * decel * tau**2
    th = math.radians(pose.yaw)
    fwd, left = np.array([math.cos(th), math.sin(th)]), np.array([-math.sin(th), math.cos(th)])
    xy = np.array([pose.x, pose.y]) + s[:, None] * fwd + (lateral * t)[:, None] * left
    return Plan(tuple(str(i) for i in range(horizon + 1)), xy, np.maximum(v0 - decel * t, 0.0))


def track_of(
    traj: Traj, f: int, pose: EgoPose, horizon: int = HORIZON, shift: np.ndarray | None = None
) -> Track:
    """Exact prediction of ``traj`` from frame f, relative to the pose at f (key k -> f+k+1)."""
    idx = np.minimum(np.arange(f + 1, f + horizon + 1), len(traj.speed) - 1)
    world = traj.xy[idx] + (0.0 if shift is None else shift)
    off = world_to_ego(world, np.array([pose.x, pose.y]), pose.yaw)
    return Track(tuple(str(k) for k in range(horizon)), np.column_stack((off, np.zeros(horizon))))


def build_log(
    ego: Traj,
    partner: Traj,
    last: int,
    cf: int,
    others: dict[str, tuple[Traj, np.ndarray]] | None = None,
    pose_offset: tuple[float, float] = (0.0, 0.0),
) -> RunLog:
    """Frames 1..last with exact plans, predictions and perception (see module docstring)."""
    frames = tuple(f * TPF for f in range(1, last + 1))
    log = RunLog(RunMetadata(TPF, (1.3, 0.0, 1.8), cf, last), frames)
    extra = others or {}
    for f in range(1, last + 1):
        ts = f * TPF
        pose = EgoPose(
            float(ego.xy[f, 0] + pose_offset[0]),
            float(ego.xy[f, 1] + pose_offset[1]),
            0.0,
            0.0,
            0.0,
            float(ego.yaw[f]),
            float(ego.speed[f]),
        )
        log.pose[ts] = pose
        ids = [EGO, PARTNER, *extra]
        trajs = [ego, partner, *(t for t, _ in extra.values())]
        halves = [HALF, HALF, *(h for _, h in extra.values())]
        loc = np.array([[t.xy[f, 0], t.xy[f, 1], 0.0] for t in trajs])
        rot = np.array([[0.0, 0.0, t.yaw[f]] for t in trajs])
        ext = np.array([[h[0], h[1], 0.8] for h in halves])
        log.actors[ts] = Actors(tuple(ids), loc, rot, ext)
        log.bboxes_gt[ts] = Boxes((PARTNER,), np.array([GT_BOX]), ({},))
        log.bboxes[ts] = Boxes(("d0",), np.array([GT_BOX]), ({},))
        on_truth = {PARTNER: track_of(partner, f, pose)}
        for name, (traj, _) in extra.items():
            on_truth[name] = track_of(traj, f, pose)
        log.predictions_with_perception[ts] = on_truth
        log.predictions[ts] = {TRACK: track_of(partner, f, pose)}
        log.waypoints[ts] = plan_along(ego, f)
    return log


def head_on_log() -> RunLog:
    """Ego at 10 m/s from x=0 into a stationary partner at x=30; contact from frame 53.

    Real conflict (c_gt < 0.5) from frame 42 on (plan box 10 reaches x = 26 there).
    """
    ego = straight(0.0, 10.0, 80)
    partner = straight(30.0, 0.0, 80)
    return build_log(ego, partner, 53, 53)


def context(log: RunLog, **overrides: float) -> RunContext:
    return RunContext.create(log, make_params("corrected", overrides))


def run(log: RunLog, module: Module, ts: int, **overrides: float) -> OracleResult:
    return ORACLES[module](context(log, **overrides), ts)


def judged_frames(log: RunLog, ctx: RunContext) -> list[FrameResults]:
    """Every frame of ``log`` judged by the four oracles, as the engine judges them."""
    frames = []
    for ts in log.unique_frames:
        frame = FrameResults(ts, ts // TPF)
        frame.results = {m: ORACLES[m](ctx, ts) for m in MODULES}
        frames.append(frame)
    return frames


def value(result: OracleResult, key: str) -> float:
    """A numeric metric of a result."""
    number = result.metrics[key]
    assert isinstance(number, int | float)
    return float(number)


# --------------------------------------------------------------------------- partner
def test_partner_is_deepest_overlap_not_nearest_centre() -> None:
    # A car 0.5 m ahead (centre 6.5 m away) and a truck whose corner cuts into the ego
    # (centre 7.3 m away): the truck is the partner.
    frames = 3
    ego = straight(0.0, 0.0, frames)
    ahead = straight(6.5, 0.0, frames)
    truck = Traj(np.tile([-7.0, 2.0], (frames, 1)), np.full(frames, -10.0), np.zeros(frames))
    truck_half = np.array([6.0, 1.2])
    log = build_log(ego, ahead, 2, 2, others={"truck": (truck, truck_half)})
    assert box_signed_distance(np.zeros(2), HALF, 0.0, truck.xy[0], truck_half, -10.0)[0] < 0
    assert np.hypot(*truck.xy[0]) > 6.5
    assert corrected_context(context(log)).partner_id == "truck"


def test_partner_tie_goes_to_earlier_actor_and_missing_file_uses_earlier_frame() -> None:
    frames = 4
    ego = straight(0.0, 0.0, frames)
    front = straight(5.0, 0.0, frames)
    back = straight(-5.0, 0.0, frames)
    log = build_log(ego, front, 3, 3, others={"back": (back, HALF)})
    assert corrected_context(context(log)).partner_id == PARTNER
    # Without the actors file at the collision frame: the latest earlier frame, reported.
    log2 = build_log(ego, back, 3, 3, others={"front": (front, HALF)})
    del log2.actors[3 * TPF]
    ctx = context(log2)
    assert corrected_context(ctx).partner_id == PARTNER
    assert any("collision_frame" in p.issue for p in ctx.problems)


# --------------------------------------------------------------------------- prediction
CONFLICT_TS, CALM_TS = 42 * TPF, 20 * TPF  # c_gt = 0.0 and 10.5 in head_on_log


def _shifted(log: RunLog, ts: int, shift: np.ndarray, folder: str = "on_truth") -> None:
    """Replace the partner's prediction at ts by the exact one plus ``shift`` (K, 2)."""
    partner = Traj(
        np.array([log.actors[t].location[1, :2] for t in sorted(log.actors)]),
        np.zeros(len(log.actors)),
        np.zeros(len(log.actors)),
    )
    # Frame f is row f - 1 here; track_of indexes by frame, so pad one row in front.
    padded = Traj(np.vstack((partner.xy[:1], partner.xy)), partner.yaw, partner.speed)
    track = track_of(padded, ts // TPF, log.pose[ts], shift=shift)
    if folder == "on_truth":
        log.predictions_with_perception[ts][PARTNER] = track
    else:
        log.predictions[ts][TRACK] = track


def _ramp(per_step: float, axis: int = 0) -> np.ndarray:
    shift = np.zeros((HORIZON, 2))
    shift[:, axis] = per_step * np.arange(1, HORIZON + 1)
    return shift


@pytest.mark.parametrize("yaw", [0.0, 30.0, -135.0])
def test_exact_predictions_relative_to_pose_are_not_flagged(yaw: float) -> None:
    # A moving partner, a rotated world, and the pose 3 cm off the ego's actor location.
    ego = rotated(straight(0.0, 10.0, 80), yaw)
    partner = rotated(straight(25.0, 2.0, 80), yaw)
    log = build_log(ego, partner, 53, 53, pose_offset=(0.03, -0.02))
    ctx = context(log)
    for f in range(20, 53):
        result = ORACLES["prediction"](ctx, f * TPF)
        assert not result.failed, f
        assert value(result, "displacement_error") < 0.05
        assert value(result, "ade") < 0.05
    assert any(ORACLES["prediction"](ctx, f * TPF).metrics["real_conflict"] for f in range(40, 53))


def test_optimistic_prediction_error_during_conflict_fails() -> None:
    log = head_on_log()
    _shifted(log, CONFLICT_TS, _ramp(0.5))  # predicted to drive away at 10 m/s
    result = run(log, "prediction", CONFLICT_TS)
    assert result.failed
    assert result.metrics["c_gt"] == pytest.approx(0.0)
    assert result.metrics["c_pwp"] == pytest.approx(5.0)
    assert result.metrics["displacement_error"] == pytest.approx(5.0)
    assert result.metrics["unconditioned"] is True


def test_pessimistic_prediction_error_is_reported_not_blamed() -> None:
    log = head_on_log()
    _shifted(log, CONFLICT_TS, _ramp(-0.5))  # predicted to come towards the ego
    result = run(log, "prediction", CONFLICT_TS)
    assert not result.failed
    assert result.metrics["pessimistic"] is True
    assert result.metrics["displacement_error"] == pytest.approx(5.0)
    assert result.metrics["unconditioned"] is True  # the fallback test still sees it


@pytest.mark.parametrize(("shift", "failed"), [(0.45, True), (0.35, False)])
def test_prediction_that_hides_the_conflict_fails_below_the_displacement_threshold(
    shift: float, failed: bool
) -> None:
    # Partner at 30.1: c_gt = 0.1 at frame 42; a constant 0.45 m optimistic offset gives the
    # clearance on truth 0.55 >= margin (hidden) with e = 0.45 < 0.5; 0.35 m neither hides nor
    # exceeds.
    log = build_log(straight(0.0, 10.0, 80), straight(30.1, 0.0, 80), 53, 53)
    ts = 42 * TPF
    _shifted(log, ts, np.tile([shift, 0.0], (HORIZON, 1)))
    result = run(log, "prediction", ts)
    assert result.metrics["c_gt"] == pytest.approx(0.1)
    assert result.metrics["c_pwp"] == pytest.approx(0.1 + shift)
    assert result.failed is failed


def test_partner_in_view_but_absent_from_predictions_on_truth_fails_only_during_conflict() -> None:
    log = head_on_log()
    for ts in (CONFLICT_TS, CALM_TS):
        del log.predictions_with_perception[ts][PARTNER]
    ctx = context(log)
    assert ORACLES["prediction"](ctx, CONFLICT_TS).failed
    calm = ORACLES["prediction"](ctx, CALM_TS)
    assert not calm.failed
    assert calm.metrics["unconditioned"] is True


def test_prediction_metrics_ade_fde_miss_rate() -> None:
    log = head_on_log()
    _shifted(log, CALM_TS, _ramp(0.25))  # error 0.25 k+1: ADE 1.375 (10 keys), FDE 2.5
    result = run(log, "prediction", CALM_TS)
    assert result.metrics["ade"] == pytest.approx(0.25 * 5.5)
    assert result.metrics["fde"] == pytest.approx(2.5)
    assert result.metrics["miss_rate"] == pytest.approx(1.0)
    assert result.metrics["missed_actors"] == [PARTNER]


def _constant(x: float, y: float = 0.0) -> Track:
    return Track(tuple(str(k) for k in range(HORIZON)), np.tile([x, y, 0.0], (HORIZON, 1)))


def test_raw_linking_rule() -> None:
    # At CALM_TS the partner's step 0 on truth is 20 m ahead; Q's is 40 m. Raw A (20.5) and B
    # (19.8) both link to the partner, B is nearer its step 0; C links to Q; D is 100 m or
    # more from every step 0 on truth and links to nothing.
    log = head_on_log()
    log.predictions_with_perception[CALM_TS]["Q"] = _constant(40.0)
    log.predictions[CALM_TS] = {
        "A": _constant(20.5),
        "D": _constant(140.0),
        "B": _constant(19.8),
        "C": _constant(39.0),
    }
    view = partner_view(corrected_context(context(log)), CALM_TS)
    assert view.raw_id == "B"
    assert view.raw_displacement == pytest.approx(0.2)
    log.predictions[CALM_TS] = {"D": _constant(140.0), "C": _constant(39.0)}
    assert partner_view(corrected_context(context(log)), CALM_TS).raw is None


# --------------------------------------------------------------------------- perception
def test_hungarian_matching_metrics() -> None:
    # Greedy would give D1 -> G2 (IoU 0.667) and leave D2 unmatched; Hungarian matches
    # D1-G1 (70/130) and D2-G2 (90/110). G3 is missed outright; D3 is a false positive.
    log = head_on_log()
    gt = Boxes(
        ("G1", "G2", "G3"),
        np.array([[0, 0, 100, 100], [50, 0, 150, 100], [500, 0, 600, 100]], float),
        ({}, {}, {}),
    )
    det = Boxes(
        ("D1", "D2", "D3"),
        np.array([[30, 0, 130, 100], [160, 100, 60, 0], [1000, 0, 1100, 100]], float),
        ({}, {}, {}),
    )
    log.bboxes_gt[CALM_TS], log.bboxes[CALM_TS] = gt, det
    m = run(log, "perception", CALM_TS).metrics
    assert m["matched"] == 2
    assert m["precision"] == pytest.approx(2 / 3)
    assert m["recall"] == pytest.approx(2 / 3)
    assert m["mean_iou"] == pytest.approx((70 / 130 + 90 / 110) / 2)
    assert m["missed"] == {"G3": 0.0}
    assert m["false_positives"] == ["D3"]


def _undetected(log: RunLog, ts: int) -> None:
    log.bboxes[ts] = Boxes((), np.zeros((0, 4)), ())


def test_missed_partner_not_reaching_the_planner_fails_during_conflict_only() -> None:
    log = head_on_log()
    for ts in (CONFLICT_TS, CALM_TS):
        _undetected(log, ts)
        log.predictions[ts] = {}
    ctx = context(log)
    conflict = ORACLES["perception"](ctx, CONFLICT_TS)
    assert conflict.failed
    assert conflict.metrics["planner_input_degraded"] is True
    assert conflict.metrics["missed"] == {PARTNER: 0.0}
    calm = ORACLES["perception"](ctx, CALM_TS)
    assert not calm.failed
    assert calm.metrics["unconditioned"] is True
    planning = ORACLES["planning"](ctx, CONFLICT_TS)  # the partner is not in its inputs
    assert not planning.failed
    assert planning.metrics["partner_in_planner_inputs"] is False


def test_dropout_bridged_by_tracking_is_not_blamed() -> None:
    log = head_on_log()
    _undetected(log, CONFLICT_TS)  # the raw track still predicts the partner exactly
    result = run(log, "perception", CONFLICT_TS)
    assert result.metrics["partner_matched"] is False
    assert result.metrics["real_conflict"] is True
    assert not result.failed


@pytest.mark.parametrize(("per_step", "failed"), [(0.5, True), (-0.5, False)])
def test_missed_partner_with_displaced_raw_track(per_step: float, failed: bool) -> None:
    log = head_on_log()
    _undetected(log, CONFLICT_TS)
    _shifted(log, CONFLICT_TS, _ramp(per_step), folder="raw")
    assert run(log, "perception", CONFLICT_TS).failed is failed


# --------------------------------------------------------------------------- planning
def test_plan_into_predicted_partner_fails_when_braking_would_have_avoided() -> None:
    log = head_on_log()
    ctx = context(log)
    early = ORACLES["planning"](ctx, 42 * TPF)
    assert early.failed
    assert early.metrics["c_plan"] == pytest.approx(0.0)
    assert early.metrics["braking_clearance"] == pytest.approx(1.0)
    late = ORACLES["planning"](ctx, 45 * TPF)  # unavoidable by then: braking hits too
    assert not late.failed
    assert value(late, "braking_clearance") < 0


def test_plan_unsafe_only_against_ground_truth_is_not_a_planning_failure() -> None:
    log = head_on_log()
    ts = 42 * TPF
    _shifted(log, ts, np.tile([5.0, 0.0], (HORIZON, 1)), folder="raw")
    result = run(log, "planning", ts)
    assert not result.failed
    assert result.metrics["c_plan"] == pytest.approx(5.0)
    assert result.metrics["c_gt"] == pytest.approx(0.0)


@pytest.mark.parametrize(("decel", "failed"), [(7.6, False), (5.0, True)])
def test_braking_at_the_limit_is_exempt(decel: float, failed: bool) -> None:
    # Partner rear at 6.25 m ahead of the ego centre. Braking at 7.6 m/s² (within 0.5 of
    # the limit) ends 0.2 m short: unsafe but at the limit. At 5 m/s² it overlaps, while
    # braking at 8 m/s² keeps 0.25 m: a safer plan existed.
    log = build_log(straight(-0.5, 10.0, 40), straight(8.25, 0.0, 40), 12, 12)
    ts = TPF
    log.waypoints[ts] = plan_from_pose(log.pose[ts], 10.0, decel)
    result = run(log, "planning", ts)
    assert result.metrics["c_plan"] == pytest.approx(0.2 if decel == 7.6 else -0.125)
    assert result.metrics["braking_clearance"] == pytest.approx(0.25)
    assert result.metrics["braking_at_limit"] is (not failed)
    assert result.failed is failed


# --------------------------------------------------------------------------- control
@pytest.mark.parametrize("speed", [0.3, 10.0, 40.0])
def test_exact_tracking_never_fires(speed: float) -> None:
    log = build_log(straight(0.0, speed, 200), straight(500.0, 0.0, 200), 60, 60)
    ctx = context(log)
    for f in range(1, 50):
        result = ORACLES["controller"](ctx, f * TPF)
        assert not result.failed
        assert result.metrics["tracking_failure"] is False
        assert abs(value(result, "sum_speed_innovation")) < 1e-9


def _under_braking_log(partner_x: float) -> RunLog:
    """Realised 10 m/s while every plan brakes at 4 m/s² (index-1 speed 9.8)."""
    log = build_log(straight(0.0, 10.0, 80), straight(partner_x, 0.0, 80), 30, 30)
    for ts, pose in log.pose.items():
        log.waypoints[ts] = plan_from_pose(pose, 10.0, 4.0)
    return log


@pytest.mark.parametrize(("partner_x", "failed"), [(100.0, True), (-100.0, False)])
def test_faster_than_planned_fires_toward_partner_ahead_only(
    partner_x: float, failed: bool
) -> None:
    result = run(_under_braking_log(partner_x), "controller", 5 * TPF)
    assert result.metrics["sum_speed_innovation"] == pytest.approx(2.0)
    assert result.metrics["speed_threshold"] == pytest.approx(1.0)
    assert result.metrics["tracking_failure"] is True
    assert result.failed is failed


@pytest.mark.parametrize(("partner_y", "failed"), [(5.0, True), (-5.0, False)])
def test_lateral_drift_fires_toward_partner_side_only(partner_y: float, failed: bool) -> None:
    frames = 80
    ego = straight(0.0, 10.0, frames)
    ego.xy[:, 1] = np.arange(frames) * DT * 1.0  # drifts +y at 1 m/s
    log = build_log(ego, straight(20.0, 0.0, frames, y=partner_y), 30, 30)
    for ts, pose in log.pose.items():
        log.waypoints[ts] = plan_from_pose(pose, 10.0, 0.0)
    result = run(log, "controller", 5 * TPF)
    assert result.metrics["sum_lateral_innovation"] == pytest.approx(0.5)
    assert abs(value(result, "sum_speed_innovation")) < 1e-9
    assert result.failed is failed


def test_signed_lateral_offset_sign_follows_ego_y_axis() -> None:
    line = np.array([[[0.0, 0.0], [10.0, 0.0]]])
    assert signed_lateral_offset(np.array([[5.0, 0.3]]), line, np.array([0.0]))[0] == 0.3
    assert signed_lateral_offset(np.array([[5.0, -0.3]]), line, np.array([0.0]))[0] == -0.3
    vertical = np.array([[[0.0, 0.0], [0.0, 10.0]]])  # heading +y: ego y axis is -x
    assert signed_lateral_offset(np.array([[-0.2, 5.0]]), vertical, np.array([90.0]))[0] == (
        pytest.approx(0.2)
    )


# --------------------------------------------------------------------------- attribution
def _frames(
    cf: int,
    failing: dict[Module, Iterable[int]],
    unconditioned: dict[Module, Iterable[int]] | None = None,
    last: int | None = None,
    conflict: Iterable[int] = (),
    plan_clearance: dict[int, float] | None = None,
) -> tuple[list[FrameResults], RunContext]:
    """Fake per-frame results for frames 1..last with the given failing frames (and
    ``real_conflict`` true at the ``conflict`` frames; planning's ``c_plan`` where
    ``plan_clearance`` gives one)."""
    end = last if last is not None else max(cf, 1)
    log = build_log(straight(0.0, 0.0, end + 2), straight(3.0, 0.0, end + 2), end, cf)
    ctx = context(log)
    fail = {m: set(v) for m, v in failing.items()}
    uncond = {m: set(v) for m, v in (unconditioned or {}).items()}
    conflicts = set(conflict)
    frames = []
    for f in range(1, end + 1):
        frame = FrameResults(f * TPF, f)
        for m in MODULES:
            metrics: dict[str, Metric] = {
                "unconditioned": f in uncond.get(m, set()),
                "real_conflict": f in conflicts,
            }
            if m == "planning" and plan_clearance and f in plan_clearance:
                metrics["c_plan"] = plan_clearance[f]
            frame.results[m] = OracleResult(m, f * TPF, f in fail.get(m, set()), metrics)
        frames.append(frame)
    return frames, ctx


def test_window_and_persistence_runs() -> None:
    # Window [10, 30] (W = 20 frames at 20 Hz). Perception: a lone frame (not counted) and a
    # 2-run; controller: a 2-run (not counted, needs 3); planning: one frame (counts).
    frames, ctx = _frames(
        30,
        {
            "perception": [5, 6, 20, 24, 25],
            "controller": [26, 27],
            "planning": [28],
        },
    )
    a = attribute_corrected(frames, ctx)
    p = a.modules["perception"]
    assert (p.collision, p.safe, p.first_failure_frame) == (2, 3, 24)
    c = a.modules["controller"]
    assert (c.collision, c.safe, c.first_failure_frame) == (0, 2, 26)
    assert a.modules["planning"].collision == 1
    assert a.root_causes == ["perception", "planning"]
    assert a.primary_root_cause == "perception"
    assert a.contributing == ["planning"]
    assert a.attribution_basis == BASIS_JUDGED
    assert a.partner_id == PARTNER
    evidence = a.modules["perception"].evidence
    assert evidence is not None
    assert evidence["first_failing_frame"] == 24
    assert evidence["runs"] == [[24, 25]]


@pytest.mark.parametrize(
    ("upstream", "upstream_from", "primary"),
    [
        ("prediction", 25, "controller"),  # a turning partner's arc, after the controller
        ("perception", 24, "controller"),
        ("prediction", 22, "prediction"),  # the same frame: not after
        ("prediction", 20, "prediction"),
    ],
)
def test_an_upstream_failure_after_control_is_contributing(
    upstream: Module, upstream_from: int, primary: str
) -> None:
    """Issue 40 (third-party world): a controller fault at an intersection, the stack's
    constant-acceleration prediction of the turning partner failing ten frames later. The
    ego was already off its plan: what came after is a consequence (rule 7)."""
    frames, ctx = _frames(
        30, {"controller": range(22, 30), upstream: range(upstream_from, upstream_from + 4)}
    )
    a = attribute_corrected(frames, ctx)
    assert a.root_causes == [upstream, "controller"]
    assert a.primary_root_cause == primary


@pytest.mark.parametrize(("planning_from", "primary"), [(24, "controller"), (20, "planning")])
def test_planning_after_control_is_contributing(planning_from: int, primary: str) -> None:
    frames, ctx = _frames(
        30, {"controller": [22, 23, 24, 25], "planning": range(planning_from, 29)}
    )
    a = attribute_corrected(frames, ctx)
    assert a.root_causes == ["planning", "controller"]
    assert a.primary_root_cause == primary
    assert a.contributing == [m for m in ("planning", "controller") if m != primary]


@pytest.mark.parametrize(
    ("prediction", "conflict", "primary"),
    [
        # Judged right in a real conflict where planning began, never failing after:
        # the planner failed on a correct prediction.
        ([20, 21], range(18, 31), "planning"),
        ([20, 21], range(18, 22), "prediction"),  # not judged in a conflict at 22
        ([20, 21, 22], range(18, 31), "prediction"),  # still failing when planning began
        ([20, 21, 28], range(18, 31), "prediction"),  # a later failing frame, even uncounted
    ],
)
def test_a_prediction_that_recovered_before_planning_failed_is_contributing(
    prediction: list[int], conflict: range, primary: str
) -> None:
    frames, ctx = _frames(
        30, {"prediction": prediction, "planning": range(22, 29)}, conflict=conflict
    )
    a = attribute_corrected(frames, ctx)
    assert a.root_causes == ["prediction", "planning"]
    assert a.primary_root_cause == primary
    assert a.contributing == [m for m in ("prediction", "planning") if m != primary]


#: The planner's own inputs show the conflict (c_plan below the 0.5 m margin) or do not.
SHOWN, HIDDEN = 0.1, 2.0


@pytest.mark.parametrize(
    ("upstream", "failing", "clearances", "primary"),
    [
        # A sharp lane change: the stack's prediction misses by a metre at frames 22-24
        # while the planner, shown the car (c_plan below the margin), ignores it.
        ("prediction", [22, 23, 24], {f: SHOWN for f in range(22, 29)}, "planning"),
        # The same with the prediction failing first, at frames 20-21, where the plan
        # looked safe on it: the planner was misled there.
        (
            "prediction",
            [20, 21, 22],
            {20: HIDDEN, 21: HIDDEN, **{f: SHOWN for f in range(22, 29)}},
            "prediction",
        ),
        # Perception noise (ten times today's) during a planning fault: shown, not misled.
        ("perception", [21, 22, 23], {f: SHOWN for f in range(18, 29)}, "planning"),
        # A missed partner: absent from the planner's inputs (no c_plan): misled.
        ("perception", [20, 21, 22], {f: SHOWN for f in range(23, 29)}, "perception"),
        # An upstream failure that begins after planning's has nothing to mislead before it.
        ("prediction", [25, 26], {f: SHOWN for f in range(22, 29)}, "planning"),
    ],
)
def test_an_upstream_failure_must_have_misled_the_planner(
    upstream: Module, failing: list[int], clearances: dict[int, float], primary: str
) -> None:
    """Issue 40 item 2 (rule 7): perception and prediction are primary over planning only
    if, at one of their counted frames up to planning's first, the planner's inputs hid
    the threat (no c_plan below the margin there)."""
    frames, ctx = _frames(
        30,
        {upstream: failing, "planning": range(22, 29)},
        plan_clearance=clearances,
    )
    a = attribute_corrected(frames, ctx)
    assert a.root_causes == [upstream, "planning"]
    assert a.primary_root_cause == primary
    assert a.contributing == [m for m in (upstream, "planning") if m != primary]


def test_a_recovered_prediction_before_planning_after_control_leaves_control() -> None:
    frames, ctx = _frames(
        30,
        {"prediction": [18, 19], "controller": [21, 22, 23], "planning": range(24, 29)},
        conflict=range(18, 31),
    )
    a = attribute_corrected(frames, ctx)
    assert a.primary_root_cause == "controller"
    assert a.contributing == ["prediction", "planning"]


def test_fallback_to_unconditioned_tests() -> None:
    frames, ctx = _frames(
        30,
        {"perception": [27]},  # judged, but a single frame: not counted
        unconditioned={"perception": [27], "prediction": [20, 21, 22]},
    )
    a = attribute_corrected(frames, ctx)
    assert a.primary_root_cause == "prediction"
    assert a.attribution_basis == BASIS_FALLBACK
    assert a.reason is None
    evidence = a.modules["prediction"].evidence
    assert evidence is not None and evidence["basis"] == BASIS_FALLBACK
    assert a.modules["prediction"].collision == 0  # counts stay the judged ones


def test_no_fault_found_with_reason() -> None:
    frames, ctx = _frames(-1, {"perception": [3, 4, 5]}, last=10)
    a = attribute_corrected(frames, ctx)
    assert (a.primary_root_cause, a.reason) == (None, NO_COLLISION)
    assert a.modules["perception"].safe == 3
    frames, ctx = _frames(30, {"planning": [3]}, unconditioned={"perception": [25]})
    a = attribute_corrected(frames, ctx)
    assert (a.primary_root_cause, a.reason, a.root_causes) == (None, NO_MODULE_FAILED, [])
    assert a.modules["planning"].safe == 1


def test_nan_metrics_are_null_in_json() -> None:
    log = head_on_log()
    log.bboxes[CALM_TS] = Boxes((), np.zeros((0, 4)), ())
    log.bboxes_gt[CALM_TS] = Boxes((), np.zeros((0, 4)), ())
    result = run(log, "perception", CALM_TS)
    assert math.isnan(value(result, "precision"))
    text = json.dumps(json_safe(result.metrics), allow_nan=False)
    assert json.loads(text)["precision"] is None


def test_missing_input_is_reported_and_check_skipped() -> None:
    log = head_on_log()
    del log.bboxes[CALM_TS]
    ctx = context(log)
    result = ORACLES["perception"](ctx, CALM_TS)
    assert (result.failed, result.skipped) == (False, "missing bboxes")
    assert [p.file for p in ctx.problems] == [f"bboxes/bboxes-{CALM_TS}.json"]


@pytest.mark.parametrize(
    ("vanishes", "primary"),
    [
        (36, "perception"),
        # Over its 15 steps the plan runs into the partner from frame 37, braking still
        # keeping clear (rule 4 over the plan's horizon): a planner that saw it there and
        # kept going failed before perception lost it.
        (38, "planning"),
    ],
)
def test_engine_style_run_over_a_whole_log(vanishes: int, primary: str) -> None:
    log = head_on_log()
    for f in range(vanishes, 54):  # the partner vanishes from detection and tracking
        _undetected(log, f * TPF)
        log.predictions[f * TPF] = {}
    ctx = context(log)
    a = attribute_corrected(judged_frames(log, ctx), ctx)
    assert a.root_causes == ["perception", *(["planning"] if primary == "planning" else [])]
    assert a.primary_root_cause == primary
    assert json.dumps(json_safe(a.modules["perception"].evidence), allow_nan=False)


# --------------------------------------------------------------------------- properties
def _slow_signed_distance(
    ca: tuple[float, float], ha: tuple[float, float], ya: float,
    cb: tuple[float, float], hb: tuple[float, float], yb: float,
) -> float:  # fmt: skip
    """Shapely distance when apart; pure-Python SAT penetration depth when overlapping."""
    pa = [tuple(p) for p in box_corners(np.array(ca), np.array(ha), np.array(ya))[0]]
    pb = [tuple(p) for p in box_corners(np.array(cb), np.array(hb), np.array(yb))[0]]
    poly_a, poly_b = Polygon(pa), Polygon(pb)
    if not poly_a.intersects(poly_b):
        return float(poly_a.distance(poly_b))
    depth = math.inf
    for poly in (pa, pb):
        for n in range(4):
            ex, ey = poly[(n + 1) % 4][0] - poly[n][0], poly[(n + 1) % 4][1] - poly[n][1]
            norm = math.hypot(ex, ey)
            ax, ay = -ey / norm, ex / norm
            proj_a = [x * ax + y * ay for x, y in pa]
            proj_b = [x * ax + y * ay for x, y in pb]
            overlap = min(max(proj_a) - min(proj_b), max(proj_b) - min(proj_a))
            depth = min(depth, overlap)
    return -depth


coord = st.floats(-8.0, 8.0, allow_nan=False, allow_subnormal=False)
grid = st.integers(-80, 80).map(lambda v: v / 10)  # polylines: no degenerate tiny segments
half = st.floats(0.2, 4.0, allow_nan=False)
angle = st.floats(-180.0, 180.0, allow_nan=False)
box = st.tuples(st.tuples(coord, coord), st.tuples(half, half), angle)


@settings(max_examples=150, deadline=None)
@given(a=box, b=box)
def test_box_signed_distance_matches_slow_version(
    a: tuple[tuple[float, float], tuple[float, float], float],
    b: tuple[tuple[float, float], tuple[float, float], float],
) -> None:
    fast = box_signed_distance(
        np.array(a[0]), np.array(a[1]), np.array(a[2]), np.array(b[0]), np.array(b[1]), b[2]
    )[0]
    assert fast == pytest.approx(_slow_signed_distance(*a, *b), abs=1e-7)


@settings(max_examples=40, deadline=None)
@given(
    plan=st.lists(st.one_of(st.none(), box), min_size=11, max_size=11),
    other=st.lists(st.one_of(st.none(), box), min_size=11, max_size=11),
)
def test_clearance_matches_slow_version(
    plan: list[tuple[tuple[float, float], tuple[float, float], float] | None],
    other: list[tuple[tuple[float, float], tuple[float, float], float] | None],
) -> None:
    def series(boxes: list[tuple[tuple[float, float], tuple[float, float], float] | None],
               half_xy: tuple[float, float]) -> Series:  # fmt: skip
        center = np.array([b[0] if b else (np.nan, np.nan) for b in boxes])
        yaw = np.array([b[2] if b else np.nan for b in boxes])
        return Series(center, yaw, np.array(half_xy))

    ego_half, other_half = (2.0, 1.0), (1.5, 0.7)
    fast = clearances(series(plan, ego_half), [series(other, other_half)], 10)[0]
    slow = [
        (_slow_signed_distance(p[0], ego_half, p[2], o[0], other_half, o[2]), i)
        for i, (p, o) in enumerate(zip(plan, other, strict=True))
        if i >= 1 and p is not None and o is not None
    ]
    if not slow:
        assert not fast.defined and math.isnan(fast.value)
        assert not fast.value < 0.5 and not fast.value >= 0.5  # comparisons are false
        return
    value = min(d for d, _ in slow)
    assert fast.value == pytest.approx(value, abs=1e-7)
    assert fast.per_index[fast.index] == pytest.approx(value, abs=1e-7)
    # The earliest index of the minimum (near-ties within rounding count as ties).
    assert fast.index in [i for d, i in slow if d <= value + 1e-7]
    assert all(d > value + 1e-10 for d, i in slow if i < fast.index)


def test_params_replace_keeps_thresholds_in_results() -> None:
    log = head_on_log()
    ctx = RunContext.create(log, replace(make_params("corrected"), safety_margin=-5.0))
    result = ORACLES["planning"](ctx, CONFLICT_TS)
    assert result.thresholds["safety_margin"] == -5.0
    assert not result.failed  # c_plan = 0 is not below -5


# --------------------------------------------------------------------------- robustness
def test_oracles_read_only_a_bounded_window() -> None:
    # Same results from the full log and from a log holding only ts − (W + L) … ts + 10
    # frames (the noise floors' frames, the prediction window and control horizon) plus the
    # actors file at the collision frame.
    full = head_on_log()
    for f in (42, 43, 44):  # something to find: the partner vanishes from the planner
        _undetected(full, f * TPF)
        full.predictions[f * TPF] = {}
    ts = 42 * TPF
    keep = range(ts - floor_span(make_params("corrected"), TPF) * TPF, ts + 10 * TPF + 1)
    part = RunLog(full.metadata, tuple(t for t in full.frames if t in keep))
    for name in ("pose", "actors", "bboxes", "bboxes_gt", "predictions", "waypoint"):
        part.folder(name).update({t: v for t, v in full.folder(name).items() if t in keep})
    on_truth = full.predictions_with_perception
    part.predictions_with_perception.update({t: v for t, v in on_truth.items() if t in keep})
    part.actors[53 * TPF] = full.actors[53 * TPF]
    for module in MODULES:
        a, b = run(full, module, ts), run(part, module, ts)
        assert a.failed == b.failed, module
        assert json_safe(a.metrics) == json_safe(b.metrics), module
    assert run(full, "perception", ts).failed


def test_bad_logs_never_raise() -> None:
    from logfactory import make_log  # the shared corner-case factory (test/logfactory.py)

    for seed in range(4):
        log = make_log(20, 7, seed, duplicate_frame=True, orphan_stamps=True)
        ctx = context(log)
        frames = []
        for ts in log.unique_frames:
            frame = FrameResults(ts, ts / TPF)
            frame.results = {m: ORACLES[m](ctx, ts) for m in MODULES}
            frames.append(frame)
        attribution = attribute_corrected(frames, ctx)
        assert attribution.reason == NO_MODULE_FAILED
        metrics = [r.metrics for f in frames for r in f.results.values()]
        json.dumps(json_safe(metrics), allow_nan=False)
        assert list(ctx.problems)


@settings(max_examples=60, deadline=None)
@given(
    points=st.lists(st.tuples(grid, grid), min_size=1, max_size=6),
    p=st.tuples(grid, grid),
    yaw=angle,
)
def test_plan_lateral_offset_matches_vectorised_helper(
    points: list[tuple[float, float]], p: tuple[float, float], yaw: float
) -> None:
    pose = EgoPose(0.0, 0.0, 0.0, 0.0, 0.0, yaw, 0.0)
    xy = np.array(points)
    plan = Plan(tuple(str(i) for i in range(len(xy))), xy, np.zeros(len(xy)))
    data = build_plan(plan, pose, HALF, 10)
    assert data is not None
    fast = data.lateral_offset(p[0], p[1], yaw)
    slow = signed_lateral_offset(np.array([p]), xy[None, :, :], np.array([yaw]))[0]
    assert abs(fast) == pytest.approx(abs(slow), abs=1e-9)
    q = polyline_nearest(np.array([p]), xy[None, :, :])[0][0]
    th = math.radians(yaw)
    if abs(-math.sin(th) * (p[0] - q[0]) + math.cos(th) * (p[1] - q[1])) > 1e-6:
        assert fast == pytest.approx(slow, abs=1e-9)  # the sign, where it is well defined
    brute = min(_segment_distances(p, xy))
    assert abs(fast) == pytest.approx(brute, abs=1e-9)


def _segment_distances(p: tuple[float, float], xy: np.ndarray) -> list[float]:
    """Distances from p to each segment (or the single point) of a polyline, via shapely."""
    from shapely.geometry import LineString, Point

    if len(xy) == 1:
        return [Point(p).distance(Point(xy[0]))]
    return [Point(p).distance(LineString(xy[n : n + 2])) for n in range(len(xy) - 1)]
