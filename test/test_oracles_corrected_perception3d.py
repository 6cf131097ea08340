"""The 3-D perception rule and prediction / planning without predictions on truth, on
hand-built logs.

Logs are built in code like a recording of a real stack: ground-truth actors, ego pose, an
exact plan, the partner as a tracked object (id "T7") and the stack's own prediction of
that track, no image boxes and no predictions on ground truth. The ego "E" (half extents
2 × 1 m) drives along +x; each test breaks what the stack perceived at one frame and checks
the number the 3-D perception rule computes by hand. The bird's-eye IoU is also compared with
shapely.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely

from ads_rca.diagnosis.engine import diagnose, evaluate_frame
from ads_rca.errors import ConfigError
from ads_rca.foundation.geometry import FloatArray, bev_iou, box_corners, world_to_ego
from ads_rca.model import Actors, Boxes, EgoPose, Objects3D, Plan, RunLog, RunMetadata, Track
from ads_rca.oracles.base import Module, OracleResult, RunContext
from ads_rca.oracles.corrected import ORACLES
from ads_rca.oracles.corrected.match3d import match_objects
from ads_rca.params import make_params

TPF = 50
DT = TPF / 1000.0
EGO, PARTNER, TRACK = "E", "P", "T7"
EGO_HALF = (2.0, 1.0)
CAR_HALF = (2.0, 1.0)
HORIZON = 15


def scene(
    ego_v: float,
    partner_xy: tuple[float, float],
    partner_v: float,
    last: int,
    partner_half: tuple[float, float] = CAR_HALF,
) -> RunLog:
    """Frames 1..last: the ego from x = 0 at ``ego_v``, the partner from ``partner_xy`` at
    ``partner_v`` along x, both heading 0°; a plan equal to the ego's future, the partner
    perceived exactly (tracked object T7 with its velocity) and predicted exactly by the
    stack; collision at ``last``."""
    frames = tuple(f * TPF for f in range(1, last + 1))
    log = RunLog(RunMetadata(TPF, (1.3, 0.0, 1.8), last, last), frames)
    span = np.arange(last + HORIZON + 2) * DT
    ego = np.column_stack((ego_v * span, np.zeros_like(span)))
    partner = np.column_stack((partner_xy[0] + partner_v * span, np.full_like(span, partner_xy[1])))
    for f in range(1, last + 1):
        ts = f * TPF
        pose = EgoPose(float(ego[f, 0]), 0.0, 0.0, 0.0, 0.0, 0.0, ego_v)
        log.pose[ts] = pose
        log.actors[ts] = Actors(
            (EGO, PARTNER),
            np.array([[ego[f, 0], 0.0, 0.0], [partner[f, 0], partner[f, 1], 0.0]]),
            np.zeros((2, 3)),
            np.array([[*EGO_HALF, 0.8], [*partner_half, 0.8]]),
        )
        keys = tuple(str(i) for i in range(HORIZON + 1))
        log.waypoints[ts] = Plan(keys, ego[f : f + HORIZON + 1], np.full(HORIZON + 1, ego_v))
        log.tracks_3d[ts] = objects(partner[f], partner_half, (partner_v, 0.0))
        future = world_to_ego(partner[f + 1 : f + HORIZON + 1], pose.xy, 0.0)
        offsets = np.column_stack((future, np.zeros(HORIZON)))
        log.predictions[ts] = {TRACK: Track(keys[:HORIZON], offsets)}
    return log


def objects(
    xy: FloatArray | tuple[float, float],
    half: tuple[float, float],
    velocity: tuple[float, float],
    yaw: float = 0.0,
    ids: tuple[str, ...] = (TRACK,),
) -> Objects3D:
    """One perceived object (NaN velocity components stay unknown)."""
    return Objects3D(
        ids,
        np.array([[xy[0], xy[1], 0.0]]),
        np.array([yaw]),
        np.array([[*half, 0.8]]),
        np.array([[velocity[0], velocity[1], 0.0]]),
        np.array([0.9]),
        ("CAR",),
    )


def no_objects() -> Objects3D:
    return Objects3D((), np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)),
                     np.zeros(0), ())  # fmt: skip


def run(log: RunLog, module: Module, ts: int, **overrides: float | str) -> OracleResult:
    return ORACLES[module](RunContext.create(log, make_params("corrected", overrides)), ts)


def number(result: OracleResult, key: str) -> float:
    value = result.metrics[key]
    assert isinstance(value, int | float), (key, value)
    return float(value)


#: Head-on: the ego at 10 m/s into a standing car at x = 30. At frame 42 (ego x = 21) the
#: plan box 10 (x = 26, front 28) touches the car's rear (28): c_gt = c_true = 0.
CONFLICT = 42 * TPF


def head_on() -> RunLog:
    return scene(10.0, (30.0, 0.0), 0.0, 53)


# --------------------------------------------------------------------------- geometry
def test_bev_iou_of_hand_computed_pairs() -> None:
    # A 2 x 2 square and itself turned 45°: the intersection is the octagon of inradius 1,
    # area 8(√2 − 1); IoU = (√2 − 1) / (2 − √2) = 1/√2.
    iou = bev_iou(np.zeros((1, 2)), [[1.0, 1.0]], [0.0], np.zeros((1, 2)), [[1.0, 1.0]], [45.0])
    assert iou[0, 0] == pytest.approx(1 / math.sqrt(2), abs=1e-12)
    # Two 4 x 2 cars turned 30°, one 2 m ahead of the other along its heading:
    # intersection 2 x 2 = 4, union 8 + 8 − 4: IoU 1/3. Identical boxes: 1. Apart: 0.
    ahead = 2.0 * np.array([math.cos(math.radians(30)), math.sin(math.radians(30))])
    iou = bev_iou(
        np.array([[5.0, 5.0]]),
        [[2.0, 1.0]],
        [30.0],
        np.array([[5.0, 5.0], 5.0 + ahead, [50.0, 0.0]]),
        [[2.0, 1.0]] * 3,
        [30.0, 30.0, 30.0],
    )
    assert iou[0] == pytest.approx([1.0, 1 / 3, 0.0], abs=1e-12)
    # NaN and zero-area boxes never match.
    iou = bev_iou([[0.0, 0.0]], [[1.0, 1.0]], [0.0], [[np.nan, 0.0], [0.0, 0.0]],
                  [[1.0, 1.0], [0.0, 1.0]], [0.0, 0.0])  # fmt: skip
    assert iou.tolist() == [[0.0, 0.0]]


@pytest.mark.parametrize("seed", range(5))
def test_bev_iou_equals_shapely_on_random_boxes(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n, m = 30, 25
    ca, cb = rng.uniform(-4, 4, (n, 2)), rng.uniform(-4, 4, (m, 2))
    ha, hb = rng.uniform(0.1, 3.0, (n, 2)), rng.uniform(0.1, 3.0, (m, 2))
    ya, yb = rng.uniform(-180, 180, n), rng.uniform(-180, 180, m)
    ours = bev_iou(ca, ha, ya, cb, hb, yb)
    pa = shapely.polygons(box_corners(ca, ha, ya))
    pb = shapely.polygons(box_corners(cb, hb, yb))
    inter = shapely.area(shapely.intersection(pa[:, None], pb[None, :]))
    union = shapely.area(pa)[:, None] + shapely.area(pb)[None, :] - inter
    assert (ours > 0).sum() > n * m // 4  # the boxes do overlap: the test can fail
    np.testing.assert_allclose(ours, inter / union, rtol=0, atol=1e-9)


# --------------------------------------------------------------------------- matching
def test_a_pedestrian_is_matched_by_distance_when_iou_cannot() -> None:
    params = make_params("corrected")
    ped = (np.array([[10.0, 0.0]]), np.array([[0.3, 0.3]]), np.zeros(1))
    seen = (np.array([[10.7, 0.0]]), np.array([[0.3, 0.3]]), np.zeros(1))
    rows, cols, iou, best = match_objects(seen, ped, params)
    assert (rows.tolist(), cols.tolist(), iou.tolist(), best.tolist()) == ([0], [0], [0.0], [0.0])
    # 0.7 m is beyond a 0.5 m match distance; a car is never matched by distance.
    strict = make_params("corrected", {"perc3d_match_distance": 0.5})
    assert match_objects(seen, ped, strict)[0].size == 0
    car = (np.array([[10.0, 0.0]]), np.array([[2.0, 1.0]]), np.zeros(1))
    car_seen = (np.array([[13.9, 0.0]]), np.array([[2.0, 1.0]]), np.zeros(1))
    assert match_objects(car_seen, car, params)[0].size == 0  # IoU 0.1/7.9 < 0.3
    no_yaw = (seen[0], seen[1], np.array([np.nan]))
    assert match_objects(no_yaw, ped, params)[0].size == 0  # NaN never matches


def test_an_iou_match_is_preferred_to_a_distance_match() -> None:
    # Two perceived objects near one small actor: the overlapping one is matched even though
    # the other is within the match distance too.
    params = make_params("corrected")
    actor = (np.array([[0.0, 0.0]]), np.array([[0.5, 0.5]]), np.zeros(1))
    seen = (np.array([[0.9, 0.0], [0.1, 0.0]]), np.array([[0.5, 0.5]] * 2), np.zeros(2))
    rows, cols, iou, _ = match_objects(seen, actor, params)
    assert rows.tolist() == [1] and cols.tolist() == [0]
    assert iou[0] == pytest.approx(0.9 / 1.1)


def test_metrics_count_in_range_objects_only() -> None:
    log = head_on()
    ts = CONFLICT
    # A far actor (200 m: beyond perc3d_range 80) and a false positive near the ego.
    actors = log.actors[ts]
    log.actors[ts] = Actors(
        (*actors.ids, "far"),
        np.vstack((actors.location, [[221.0, 0.0, 0.0]])),
        np.zeros((3, 3)),
        np.vstack((actors.extent, [[2.0, 1.0, 0.8]])),
    )
    real = log.tracks_3d[ts]
    ghost = objects((21.0, 10.0), CAR_HALF, (0.0, 0.0), ids=("ghost",))
    log.tracks_3d[ts] = Objects3D(
        (TRACK, "ghost"),
        np.vstack((real.location, ghost.location)),
        np.concatenate((real.yaw, [12.0])),
        np.vstack((real.extent, ghost.extent)),
        np.vstack((real.velocity, ghost.velocity)),
        np.array([0.9, 0.4]),
        ("CAR", "CAR"),
    )
    result = run(log, "perception", ts)
    m = result.metrics
    assert (m["check"], m["source"]) == ("3d", "tracked")
    assert (m["detections"], m["gt_objects"], m["matched"]) == (2, 1, 1)
    assert (m["precision"], m["recall"], m["mean_iou"]) == (0.5, 1.0, 1.0)
    assert m["missed"] == {} and m["false_positives"] == ["ghost"]
    assert (m["mean_position_error"], m["mean_yaw_error"]) == (0.0, 0.0)
    assert not result.failed
    assert result.thresholds == {
        "perc3d_match_iou": 0.3,
        "perc3d_match_distance": 1.0,
        "perc3d_small_area": 2.0,
        "perc3d_range": 80.0,
        "perc3d_velocity_error": 1.5,
        "safety_margin": 0.5,
        "understate_min": 0.3,
        "pred_abs_threshold": 0.5,
        "pred_score_threshold": 0.1,
        "noise_floor_s": 3.0,
        "noise_floor_min_frames": 5,
        "noise_floor_factor": 1.5,
    }


# --------------------------------------------------------------- the 3-D perception rule
def test_exact_perception_never_fails() -> None:
    log = head_on()
    ctx = RunContext.create(log, make_params("corrected"))
    for f in range(20, 53):
        result = ORACLES["perception"](ctx, f * TPF)
        assert result.skipped is None and not result.failed, f
        assert result.metrics["partner_matched"] is True
    result = ORACLES["perception"](ctx, CONFLICT)
    assert result.metrics["real_conflict"] is True
    for key in ("c_gt", "c_true", "c_perc"):
        assert number(result, key) == pytest.approx(0.0), key


def test_a_missed_partner_in_a_real_conflict_fails() -> None:
    log = head_on()
    log.tracks_3d[CONFLICT] = no_objects()
    result = run(log, "perception", CONFLICT)
    assert result.failed
    m = result.metrics
    assert (m["partner_in_range"], m["partner_matched"], m["unconditioned"]) == (True, False, True)
    assert m["missed"] == {PARTNER: 0.0}
    assert number(result, "c_gt") == pytest.approx(0.0)
    assert result.ids == (PARTNER,)
    # Far from the conflict (frame 20: c_gt = 11 m) the same miss is not blamed, only
    # flagged unconditioned; and out of sensing range it is not perception's fault at all.
    calm = 20 * TPF
    log.tracks_3d[calm] = no_objects()
    assert not run(log, "perception", calm).failed
    assert run(log, "perception", calm).metrics["unconditioned"] is True
    far = run(log, "perception", CONFLICT, perc3d_range=5.0)
    assert not far.failed and far.metrics["partner_in_range"] is False


def test_a_bus_seen_1_5_m_away_from_the_ego_path_fails_by_the_clearance_difference() -> None:
    # A bus (half 6 x 1.5) at y = 2: it overlaps the ego's lane by 0.5 m; its rear is at
    # x = 28, touched by plan box 10 at frame 42 (c_true = 0). Seen 1.5 m further left
    # (y = 3.5) it clears the lane by 1 m: c_perc = 1.0, IoU 18/54 = 1/3 (still matched).
    log = scene(10.0, (34.0, 2.0), 0.0, 53, partner_half=(6.0, 1.5))
    log.tracks_3d[CONFLICT] = objects((34.0, 3.5), (6.0, 1.5), (0.0, 0.0))
    result = run(log, "perception", CONFLICT)
    m = result.metrics
    assert result.failed
    assert m["partner_matched"] is True and m["overstated"] is True
    assert m["mean_iou"] == pytest.approx(1 / 3)
    assert number(result, "c_true") == pytest.approx(0.0)
    assert number(result, "c_perc") == pytest.approx(1.0)
    assert number(result, "partner_position_error") == pytest.approx(1.5)
    assert result.ids == (PARTNER, TRACK)


def test_a_car_seen_0_1_m_away_does_not_fail() -> None:
    log = head_on()
    log.tracks_3d[CONFLICT] = objects((30.1, 0.0), CAR_HALF, (0.0, 0.0))
    result = run(log, "perception", CONFLICT)
    assert not result.failed
    assert result.metrics["overstated"] is False and result.metrics["unconditioned"] is False
    assert number(result, "c_perc") - number(result, "c_true") == pytest.approx(0.1)


@pytest.mark.parametrize(("seen_x", "overstated"), [(30.4, False), (30.6, True)])
def test_a_safer_looking_partner_must_be_displaced_or_hide_the_conflict(
    seen_x: float, overstated: bool
) -> None:
    # Seen 0.4 m further away: c_perc − c_true = 0.4 ≥ understate_min, but displaced by
    # 0.4 m (threshold max(0.5, 0.1 × 0 m travelled) = 0.5) and c_perc 0.4 < safety_margin
    # still shows the conflict: not overstated (the 2-D perception rule's test). Seen 0.6 m
    # away: displaced.
    log = head_on()
    log.tracks_3d[CONFLICT] = objects((seen_x, 0.0), CAR_HALF, (0.0, 0.0))
    result = run(log, "perception", CONFLICT)
    assert number(result, "c_perc") - number(result, "c_true") == pytest.approx(seen_x - 30.0)
    assert number(result, "partner_displacement") == pytest.approx(seen_x - 30.0)
    assert number(result, "displacement_threshold") == pytest.approx(0.5)
    assert result.metrics["overstated"] is overstated
    assert result.failed is overstated


def test_a_shrunk_box_fails_through_its_extent() -> None:
    # The car seen 2 m long instead of 4 (same centre): its rear appears 1 m later.
    log = head_on()
    log.tracks_3d[CONFLICT] = objects((30.0, 0.0), (1.0, 1.0), (0.0, 0.0))
    result = run(log, "perception", CONFLICT)
    assert result.failed
    assert result.metrics["partner_extent_error"] == [-2.0, 0.0]
    assert number(result, "c_perc") == pytest.approx(1.0)


def test_an_approaching_car_seen_slower_fails_by_its_velocity() -> None:
    # The ego stands at x = 0; a car comes toward it at 5 m/s from x = 6.5: over the 0.5 s
    # horizon its rear reaches x = 2.0, the ego's front (c_true = 0). Seen at 1 m/s, its
    # rear stops at 4.0: c_perc = 2.0.
    ts = 10 * TPF
    log = scene(0.0, (6.5 + 5.0 * 10 * DT, 0.0), -5.0, 30)
    assert log.actors[ts].location[1, 0] == pytest.approx(6.5)
    log.tracks_3d[ts] = objects((6.5, 0.0), CAR_HALF, (-1.0, 0.0))
    result = run(log, "perception", ts)
    assert result.failed
    assert number(result, "partner_velocity_error") == pytest.approx(4.0)
    assert number(result, "c_true") == pytest.approx(0.0, abs=1e-9)
    assert number(result, "c_perc") == pytest.approx(2.0)
    # The same box with no velocity at all (a detector) is judged on position and extent.
    log.tracks_3d[ts] = objects((6.5, 0.0), CAR_HALF, (math.nan, math.nan))
    unknown = run(log, "perception", ts)
    assert not unknown.failed and math.isnan(number(unknown, "partner_velocity_error"))


#: A pedestrian (half extents 0.3 m) 11.3 m ahead of the ego (10 m/s), at the edge of its
#: path (y = -1, the ego's side at -1), stepping in at 1.6 m/s; the stack plans 30 steps.
WALKER_HALF = (0.3, 0.3)
STEP_IN = 1.6


def crossing(perceived_vy: float, real_vy: float = STEP_IN, last: int = 60) -> RunLog:
    """The pedestrian's real motion across the path and, at frame 10, its perceived
    velocity; the plan at frame 10 runs 30 steps (1.5 s) ahead."""
    ts = 10 * TPF
    log = scene(10.0, (16.3, -1.0), 0.0, last, partner_half=WALKER_HALF)
    for f in range(1, last + 1):
        log.actors[f * TPF].location[1, 1] = -1.0 + real_vy * (f - 10) * DT
    steps = np.arange(31)
    ego = np.column_stack((5.0 + 0.5 * steps, np.zeros(31)))
    log.waypoints[ts] = Plan(tuple(str(i) for i in steps), ego, np.full(31, 10.0))
    log.tracks_3d[ts] = objects((16.3, -1.0), WALKER_HALF, (0.0, perceived_vy))
    return log


def test_a_pedestrian_seen_walking_back_misleads_over_the_stacks_plan() -> None:
    # Over the judged 0.5 s both propagations stay level with the ego's side (c_true: the
    # 4 m gap ahead; c_perc: that gap beside a 0.5 m lateral one, 0.03 m more). Over the
    # plan's 1.5 s the real walker is in the ego's path when the ego arrives (i = 18:
    # contact, then overlap); the perceived one is 1.6·0.05·i − 0.3 m beside it while the
    # ego passes (i = 18..27), least 1.14 m at i = 18.
    ts = 10 * TPF
    log = crossing(-STEP_IN)
    result = run(log, "perception", ts)
    assert number(result, "partner_velocity_error") == pytest.approx(3.2)
    assert number(result, "c_true") == pytest.approx(4.0)
    assert number(result, "c_perc") == pytest.approx(math.hypot(4.0, 0.5))
    assert result.metrics["overstated"] is False and result.metrics["real_conflict"] is False
    assert result.metrics["misled"] is True and result.metrics["misled_horizon"] == 30
    assert number(result, "misled_c_perc") == pytest.approx(1.14)
    assert number(result, "misled_c_true") < 0.0
    # No real conflict within the window yet: not a failure, but unconditioned (what the
    # fallback of attribution finds), and the stack's prediction is not judged from it.
    assert not result.failed and result.metrics["unconditioned"] is True
    assert "perc3d_velocity_error" in result.thresholds
    assert run(log, "prediction", ts).skipped == "perception of the partner not correct at ts"


def test_a_velocity_error_that_makes_the_partner_look_closer_never_fails() -> None:
    # Really walking back, perceived stepping in: pessimistic, not misleading, so never a
    # failure; still a wrong input (unconditioned, as the prediction rule's error test), and
    # the stack's prediction from it is not judged.
    log = crossing(STEP_IN, real_vy=-STEP_IN)
    result = run(log, "perception", 10 * TPF)
    assert number(result, "partner_velocity_error") == pytest.approx(3.2)
    assert number(result, "misled_c_perc") < number(result, "misled_c_true")
    assert result.metrics["misled"] is False and result.metrics["velocity_wrong"] is True
    assert result.metrics["unconditioned"] is True and not result.failed
    assert run(log, "prediction", 10 * TPF).skipped == "perception of the partner not correct at ts"


def test_the_velocity_test_runs_only_above_its_threshold() -> None:
    ts = 10 * TPF
    small = run(crossing(STEP_IN - 1.2), "perception", ts)  # 1.2 m/s off: below 1.5
    assert "misled_horizon" not in small.metrics and small.metrics["misled"] is False
    assert small.metrics["velocity_wrong"] is False and small.metrics["unconditioned"] is False
    lowered = run(crossing(STEP_IN - 1.2), "perception", ts, perc3d_velocity_error=1.0)
    assert lowered.metrics["misled_horizon"] == 30
    unknown = run(crossing(math.nan), "perception", ts)  # a detector without velocities
    assert "misled_horizon" not in unknown.metrics and unknown.metrics["misled"] is False


def stepping_in_at_frame_10(perceived_vy: float) -> RunLog:
    """The pedestrian of :func:`crossing` standing until frame 10 and stepping in after it:
    at frame 10 the next frame's velocity is 1.6 m/s, the last frame's 0."""
    log = crossing(perceived_vy)
    for f in range(1, 61):
        log.actors[f * TPF].location[1, 1] = -1.0 + STEP_IN * max(f - 10, 0) * DT
    return log


def test_a_tracker_that_has_not_seen_a_step_yet_is_not_wrong() -> None:
    """The real velocity at ts looks one frame ahead; a tracker at ts has seen the motion
    up to ts only. A walker setting off at frame 10, still tracked standing there, is 1.6
    m/s off the next frame's velocity and right about the last one: the change across ts
    (1.6 m/s) raises the limit, so this is no velocity error (it was, misleading, before)."""
    result = run(stepping_in_at_frame_10(0.0), "perception", 10 * TPF)
    assert number(result, "partner_velocity_error") == pytest.approx(STEP_IN)
    assert result.metrics["velocity_wrong"] is False and result.metrics["misled"] is False
    assert result.metrics["unconditioned"] is False
    assert number(result, "partner_velocity_change") == pytest.approx(STEP_IN)


def test_a_velocity_wrong_beyond_the_change_across_ts_still_misleads() -> None:
    """Seen walking back as it sets off: 3.2 m/s off, past 1.5 + the 1.6 m/s change."""
    result = run(stepping_in_at_frame_10(-STEP_IN), "perception", 10 * TPF)
    assert number(result, "partner_velocity_error") == pytest.approx(2 * STEP_IN)
    assert result.metrics["velocity_wrong"] is True and result.metrics["misled"] is True


def test_on_steady_motion_the_change_across_ts_is_nothing() -> None:
    result = run(crossing(-STEP_IN), "perception", 10 * TPF)
    assert number(result, "partner_velocity_change") == pytest.approx(0.0, abs=1e-9)
    assert result.metrics["velocity_wrong"] is True


@pytest.mark.parametrize("damage", ["absent the frame before", "NaN", "1e308 the frame after"])
def test_a_change_across_ts_that_cannot_be_read_allows_nothing(damage: str) -> None:
    """The change is read from the partner's real positions around ts, which a log writes:
    a frame without the partner, a NaN or a position whose difference overflows gives 0
    (the fixed limit and the floor alone), never a NaN or infinite limit that no error
    could exceed."""
    log = stepping_in_at_frame_10(-STEP_IN)
    actors = log.actors[(9 if damage != "1e308 the frame after" else 11) * TPF]
    if damage == "absent the frame before":
        log.actors[9 * TPF] = Actors(
            actors.ids[:1], actors.location[:1], actors.rotation[:1], actors.extent[:1]
        )
    else:
        actors.location[1, 0] = math.nan if damage == "NaN" else 1e308
    result = evaluate_frame(
        RunContext.create(log, make_params("corrected")), ORACLES, 10 * TPF
    ).results["perception"]
    assert result.internal_error is None
    change = result.metrics.get("partner_velocity_change")
    assert change is None or change == 0.0


def test_a_plan_naming_a_huge_step_is_looked_at_for_ten_seconds_only() -> None:
    ts = 10 * TPF
    log = crossing(-STEP_IN)
    plan = log.waypoints[ts]
    keys = (*plan.keys[:-1], str(10**12))
    log.waypoints[ts] = Plan(keys, plan.xy, plan.speed)
    result = run(log, "perception", ts)
    assert result.metrics["misled_horizon"] == 200  # 10 s at 50 ms
    assert result.metrics["misled"] is True


def test_a_reversed_heading_is_a_180_degree_error() -> None:
    log = head_on()
    log.tracks_3d[CONFLICT] = objects((30.0, 0.0), CAR_HALF, (0.0, 0.0), yaw=180.0)
    result = run(log, "perception", CONFLICT)
    assert number(result, "partner_yaw_error") == 180.0
    assert number(result, "mean_iou") == pytest.approx(1.0)
    assert not result.failed


# --------------------------------------------------------------------------- selection
def test_perception_check_chooses_the_rule() -> None:
    log = head_on()
    assert run(log, "perception", CONFLICT).metrics["check"] == "3d"
    two_d = run(log, "perception", CONFLICT, perception_check="2d")
    assert two_d.skipped == "missing bboxes, bboxes_gt"
    detected = run(log, "perception", CONFLICT, perception_3d_source="detected")
    assert detected.skipped == "missing detections_3d"
    with pytest.raises(ConfigError, match=r"perception_check: '4d' is not one of auto \| 2d"):
        make_params("corrected", {"perception_check": "4d"})
    # With image boxes and their ground truth too, auto keeps the 2-D perception rule (2-D
    # logs unchanged).
    box = Boxes((PARTNER,), np.array([[100.0, 100.0, 200.0, 200.0]]), ({},))
    log.bboxes[CONFLICT], log.bboxes_gt[CONFLICT] = box, box
    both = run(log, "perception", CONFLICT)
    assert "check" not in both.metrics and both.metrics["partner_matched"] is True
    assert run(log, "perception", CONFLICT, perception_check="3d").metrics["check"] == "3d"


# ------------------------------------------------------------------- no predictions on truth
def test_prediction_without_predictions_on_truth_is_judged_on_the_linked_raw_track() -> None:
    log = head_on()
    exact = run(log, "prediction", CONFLICT)
    assert not exact.failed and exact.skipped is None
    assert exact.metrics["basis"] == "raw" and exact.metrics["raw_id"] == TRACK
    assert number(exact, "displacement_error") == pytest.approx(0.0, abs=1e-9)
    assert number(exact, "ade") == pytest.approx(0.0, abs=1e-9)
    # The stack predicts the standing car to drive away at 10 m/s: c_raw = 5 m.
    offsets = log.predictions[CONFLICT][TRACK].offsets.copy()
    offsets[:, 0] += 0.5 * np.arange(1, HORIZON + 1)
    log.predictions[CONFLICT] = {TRACK: Track(log.predictions[CONFLICT][TRACK].keys, offsets)}
    wrong = run(log, "prediction", CONFLICT)
    assert wrong.failed
    assert number(wrong, "c_raw") == pytest.approx(5.0)
    assert number(wrong, "displacement_error") == pytest.approx(5.0)


def test_a_raw_prediction_answers_for_its_model_not_for_perceptions_accepted_error() -> None:
    # The standing car perceived 0.4 m further (the 3-D perception rule accepts it:
    # c_perc − c_true = 0.4 but displaced 0.4 ≤ 0.5 and c_perc 0.4 < safety_margin): the stack
    # predicts it exactly from there. The reference is reality moved by that perception error,
    # so the prediction's own error is 0 and c_ref = c_raw = 0.4 (c_gt = 0).
    log = head_on()
    log.tracks_3d[CONFLICT] = objects((30.4, 0.0), CAR_HALF, (0.0, 0.0))
    track = log.predictions[CONFLICT][TRACK]
    moved = track.offsets.copy()
    moved[:, 0] += 0.4
    log.predictions[CONFLICT] = {TRACK: Track(track.keys, moved)}
    assert run(log, "perception", CONFLICT).metrics["overstated"] is False
    exact = run(log, "prediction", CONFLICT)
    assert number(exact, "displacement_error") == pytest.approx(0.0, abs=1e-9)
    assert number(exact, "c_ref") == pytest.approx(0.4)
    assert number(exact, "c_raw") == pytest.approx(0.4)
    assert number(exact, "c_gt") == pytest.approx(0.0, abs=1e-9)
    assert not exact.failed
    # Its own model error on top (predicted driving away at 2 m/s) is measured from there.
    moved[:, 0] += 0.1 * np.arange(1, HORIZON + 1)
    log.predictions[CONFLICT] = {TRACK: Track(track.keys, moved)}
    wrong = run(log, "prediction", CONFLICT)
    assert number(wrong, "displacement_error") == pytest.approx(1.0)
    assert number(wrong, "c_raw") == pytest.approx(1.4)
    assert wrong.failed  # understated by 1.0 from c_ref, displaced 1.0 > 0.5


def test_prediction_is_not_judged_where_perception_of_the_partner_was_wrong() -> None:
    log = head_on()
    log.tracks_3d[CONFLICT] = no_objects()
    assert run(log, "prediction", CONFLICT).skipped == "perception of the partner not correct at ts"
    log.tracks_3d[CONFLICT] = objects((31.5, 0.0), CAR_HALF, (0.0, 0.0))  # matched, overstated
    assert run(log, "prediction", CONFLICT).skipped == "perception of the partner not correct at ts"


def test_planning_without_predictions_on_truth_links_the_raw_track_through_the_3d_match() -> None:
    log = head_on()
    result = run(log, "planning", CONFLICT)
    assert result.skipped is None
    assert result.metrics["partner_in_planner_inputs"] is True
    assert result.ids == (PARTNER, TRACK)
    assert number(result, "c_plan") == pytest.approx(0.0)
    log.tracks_3d[CONFLICT] = no_objects()  # no match: the planner did not have the partner
    missed = run(log, "planning", CONFLICT)
    assert missed.metrics["partner_in_planner_inputs"] is False and not missed.failed


def test_a_partner_missed_for_the_last_second_is_blamed_on_perception() -> None:
    log = head_on()
    for f in range(33, 54):
        log.tracks_3d[f * TPF] = no_objects()
    found = diagnose(log, make_params("corrected"))
    assert list(found.problems) == []
    assert found.attribution.primary_root_cause == "perception"
    evidence = found.attribution.modules["perception"].evidence
    assert evidence is not None and evidence["ids"] == [PARTNER]
    # Perceived all along, the car was in the planner's inputs (linked through the 3-D
    # match) and the plan drove into it where braking would have kept clear: planning.
    exact = diagnose(head_on(), make_params("corrected"))
    assert list(exact.problems) == []
    assert exact.attribution.root_causes == ["planning"]
