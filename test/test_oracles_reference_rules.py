"""Hand-computed tests of the reference oracles (rca-semantics.md, "The four oracles").

Every expected number below is worked out in a comment next to it. The quirks of the
reference are tested as quirks: they are what users reproduce published results with.
Property tests check the vectorised perception and prediction against slow, literal,
pure-Python transcriptions of the spec on random inputs (NaN, zero areas, ties).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from oraclefixtures import CAR, LogBuilder, context, make_boxes

from ads_rca.model import RunLog
from ads_rca.oracles import reference
from ads_rca.oracles.base import MODULES, OracleResult, RunContext
from ads_rca.oracles.reference import ORACLES, control, perception, planning, prediction
from ads_rca.params import make_params
from ads_rca.problems import DROPPED_RECORD

TS = 100  # the judged frame in most tests (frame 2 at 50 ms per frame)


def problems_of(ctx: RunContext) -> list[tuple[str, str]]:
    return [(p.file, p.field) for p in ctx.problems]


def assert_skipped(result: OracleResult) -> None:
    assert result.failed is False
    assert result.skipped


def test_registry_is_in_pipeline_order() -> None:
    assert tuple(ORACLES) == MODULES
    assert ORACLES["controller"] is control


# ============================================================================ perception


def perception_log(det: Any, gt: Any, ts: int = TS) -> RunLog:
    b = LogBuilder().frame(ts).pose(50, 0, 0).actor(50, "ego", 0, 0)
    return b.boxes(ts, det, gt).build()


def judge_perception(det: Any, gt: Any, **params: Any) -> OracleResult:
    log = perception_log(det, gt)
    return perception(context(log, **params), TS)


def test_perfect_box_next_to_missed_object_scores_one() -> None:
    # gt "2" is never detected; the reference ignores missed objects: mean IoU = 1.0.
    result = judge_perception(
        [("d0", (0, 0, 10, 10))], [("1", (0, 0, 10, 10)), ("2", (50, 50, 60, 60))]
    )
    assert not result.failed
    assert result.metrics["mean_iou"] == 1.0
    assert result.metrics["n_matched"] == 1
    assert result.ids == ("1",)


def test_partial_overlap_is_rounded_and_fails() -> None:
    # inter = 5 x 10 = 50, union = 100 + 100 - 50 = 150: IoU 1/3, recorded 0.3333 < 0.5.
    result = judge_perception([("d", (0, 0, 10, 10))], [("g", (5, 0, 15, 10))])
    assert result.failed
    assert result.metrics["ious"] == [0.3333]
    assert result.metrics["mean_iou"] == 0.3333
    assert result.thresholds == {"perc_score_threshold": 0.5}


def test_rounding_happens_before_the_threshold() -> None:
    # IoU = 0.49996 (a 1 x 0.49996 box inside a unit box) rounds to 0.5: not < 0.5.
    result = judge_perception([("d", (0, 0, 1, 0.49996))], [("g", (0, 0, 1, 1))])
    assert result.metrics["ious"] == [0.5]
    assert not result.failed


def test_threshold_is_strict() -> None:
    # inter 50, union 100: exactly 0.5, not a failure.
    assert not judge_perception([("d", (0, 0, 10, 5))], [("g", (0, 0, 10, 10))]).failed


def test_tiny_overlap_matches_and_records_zero() -> None:
    # Selection uses the raw IoU (4e-5 > 0 matches), the record is rounded (0.0): failure.
    result = judge_perception([("d", (0, 0, 1, 0.00004))], [("g", (0, 0, 1, 1))])
    assert result.metrics["ious"] == [0.0]
    assert result.failed


def test_greedy_in_detection_order_second_detection_takes_next_gt() -> None:
    # d1 and d2 are the same box. d1 takes A (IoU 1). d2 finds A used and takes B:
    # inter 8 x 10 = 80, union 100 + 100 - 80 = 120: 0.6667. Mean (1 + 0.6667) / 2.
    result = judge_perception(
        [("d1", (0, 0, 10, 10)), ("d2", (0, 0, 10, 10))],
        [("A", (0, 0, 10, 10)), ("B", (2, 0, 12, 10))],
    )
    assert result.metrics["ious"] == [1.0, 0.6667]
    assert result.metrics["mean_iou"] == pytest.approx(0.83335)
    assert result.ids == ("A", "B")
    assert result.metrics["det_ids"] == ["d1", "d2"]


def test_greedy_is_order_dependent_not_optimal() -> None:
    # d_low overlaps A with IoU 0.6, d_high with 0.9; only one can have A.
    a = ("A", (0, 0, 10, 10))
    d_low, d_high = ("lo", (0, 0, 10, 6)), ("hi", (0, 0, 10, 9))
    first_low = judge_perception([d_low, d_high], [a], perc_score_threshold=0.7)
    first_high = judge_perception([d_high, d_low], [a], perc_score_threshold=0.7)
    assert first_low.metrics["ious"] == [0.6] and first_low.failed
    assert first_high.metrics["ious"] == [0.9] and not first_high.failed


def test_ties_keep_the_earlier_gt() -> None:
    result = judge_perception(
        [("d", (0, 0, 10, 10))], [("x", (0, 0, 10, 10)), ("y", (0, 0, 10, 10))]
    )
    assert result.ids == ("x",)


def test_corner_order_is_normalised() -> None:
    result = judge_perception([("d", (10, 10, 0, 0))], [("g", (0, 10, 10, 0))])
    assert result.metrics["ious"] == [1.0]


def test_greedy_with_nan_boxes() -> None:
    # The NaN detection matches nothing; the NaN gt is never taken; d2 takes "ok" (IoU 1).
    nan = math.nan
    result = judge_perception(
        [("d1", (nan, 0, 10, 10)), ("d2", (0, 0, 10, 10))],
        [("bad", (0, 0, nan, 10)), ("ok", (0, 0, 10, 10))],
    )
    assert result.metrics["ious"] == [1.0]
    assert result.ids == ("ok",)


def test_no_match_at_all_is_nan_and_not_a_failure() -> None:
    for det, gt in (
        ([("d", (math.nan, 0, 1, 1))], [("g", (0, 0, 1, 1))]),  # NaN
        ([("d", (5, 5, 5, 10))], [("g", (0, 0, 10, 10))]),  # zero-area detection
        ([("d", (0, 0, 10, 10))], [("g", (0, 0, 10, 0))]),  # zero-area gt
        ([("d", (0, 0, 1, 1))], [("g", (2, 2, 3, 3))]),  # disjoint
        ([], [("g", (0, 0, 1, 1))]),  # no detection
        ([("d", (0, 0, 1, 1))], []),  # no gt
    ):
        result = judge_perception(det, gt)
        assert not result.failed
        mean_iou = result.metrics["mean_iou"]
        assert isinstance(mean_iou, float) and math.isnan(mean_iou)
        assert result.metrics["n_matched"] == 0


def test_perception_missing_file_is_reported_and_skipped() -> None:
    log = perception_log(None, [("g", (0, 0, 1, 1))])
    ctx = context(log)
    result = perception(ctx, TS)
    assert_skipped(result)
    assert problems_of(ctx) == [("bboxes/bboxes-100.json", "")]


def test_perception_dropped_box_record_skips_the_frame() -> None:
    # The loader dropped a box without an id (the reference stops on it): skip the check.
    log = perception_log([("d", (0, 0, 10, 10))], [("g", (5, 0, 15, 10))])
    log.problems.add("bboxes_gt/bboxes_gt-100.json", "[1].id", "missing", DROPPED_RECORD)
    ctx = context(log)
    assert_skipped(perception(ctx, TS))
    assert ("bboxes_gt/bboxes_gt-100.json", "bounding_box") in problems_of(ctx)


# ============================================================================ prediction


def moving_ego(b: LogBuilder, speed: float = 1.0, until: int = 1000) -> LogBuilder:
    """Ego at (speed * f, 0), yaw 0, at every frame f; actor "7" parked at (5, 2)."""
    for ts in range(0, until + 1, 50):
        f = ts // 50
        b.pose(ts, speed * f, 0).actor(ts, "ego", speed * f, 0).actor(ts, "7", 5, 2)
    return b


def test_prediction_anchored_at_the_future_ego_flags_exact_offsets_when_ego_moves() -> None:
    # At ts = 100 the ego is at (2, 0); "7" is parked at (5, 2). Offsets written exactly,
    # relative to the ego AT ts: (3, 2) for every step. The reference anchors step k at the
    # ego pose at tk = 100 + 50k, i.e. (2 + k, 0):
    #   k = 0: P = (5, 2) = A, error 0, ratio 0: passes.
    #   k = 1: P = (6, 2), error 1; dis = |(3, 0) - (5, 2)| = sqrt(8) < 4; 1/sqrt(8) = 0.354
    #          >= 0.1: failure.
    # The ego's own entry (listed first, absurd offsets) is skipped.
    b = moving_ego(LogBuilder()).frame(TS)
    b.on_truth(TS, {"ego": {"0": (99, 99)}, "7": {"0": (3, 2), "1": (3, 2), "2": (3, 2)}})
    ctx = context(b.build())
    assert ctx.ego_id == "ego"
    result = prediction(ctx, TS)
    assert result.failed
    assert result.metrics["obstacle_id"] == "7"
    assert result.metrics["key"] == "1"
    assert result.metrics["error"] == 1.0
    assert result.metrics["dis"] == math.sqrt(8)
    assert result.metrics["ratio"] == 1 / math.sqrt(8)
    assert result.ids == ("7",)


def test_prediction_same_offsets_pass_when_ego_stands_still() -> None:
    b = moving_ego(LogBuilder(), speed=0.0).frame(TS)
    # Ego at (0, 0) throughout: exact offsets are (5, 2); error 0 at every step.
    b.on_truth(TS, {"7": {"0": (5, 2), "1": (5, 2), "2": (5, 2)}})
    assert not prediction(context(b.build()), TS).failed


def test_prediction_offsets_relative_to_future_ego_pass() -> None:
    # What the reference expects: A - ego(tk) = (3 - k, 2).
    b = moving_ego(LogBuilder()).frame(TS)
    b.on_truth(TS, {"7": {"0": (3, 2), "1": (2, 2), "2": (1, 2)}})
    result = prediction(context(b.build()), TS)
    assert not result.failed
    assert result.metrics["n_steps"] == 3


def test_prediction_rotates_by_the_yaw_at_ts_not_at_tk() -> None:
    # Ego at the origin, yaw 90 at ts and 0 at tk. Body offset (3, 0) at yaw 90 is the
    # world point (0, 3) where "7" is: exact with the yaw at ts. With the yaw at tk it
    # would be (3, 0): error sqrt(18), dis 3, a failure.
    b = LogBuilder().frame(TS).pose(50, 0, 0).actor(50, "ego", 0, 0)
    b.pose(TS, 0, 0, yaw=90).pose(150, 0, 0, yaw=0)
    for ts in (50, TS, 150):
        b.actor(ts, "ego", 0, 0).actor(ts, "7", 0, 3)
    b.on_truth(TS, {"7": {"0": (3, 0), "1": (3, 0)}})
    assert not prediction(context(b.build()), TS).failed


def dis_zero_log(offset: tuple[float, float]) -> RunLog:
    """Ego parked at the origin; "7" exactly at the ego's position at tk = 150."""
    b = LogBuilder().frame(TS)
    for ts in (50, TS, 150):
        b.pose(ts, 0, 0).actor(ts, "ego", 0, 0).actor(ts, "7", 0, 0)
    return b.on_truth(TS, {"7": {"1": offset}}).build()


def test_prediction_dis_zero_with_error_is_infinite_ratio_failure() -> None:
    # error 0.5, dis 0: 0.5 / 0 = +inf >= 0.1.
    result = prediction(context(dis_zero_log((0.5, 0))), TS)
    assert result.failed
    assert result.metrics["ratio"] == math.inf
    assert result.metrics["dis"] == 0.0


def test_prediction_dis_zero_without_error_is_nan_and_passes() -> None:
    # error 0, dis 0: 0 / 0 = NaN, and NaN >= 0.1 is false.
    assert not prediction(context(dis_zero_log((0, 0))), TS).failed


def test_prediction_distance_gate() -> None:
    # "7" 10 m away (>= 4 m): never judged, however wrong the prediction.
    b = LogBuilder().frame(TS)
    for ts in (50, TS, 150):
        b.pose(ts, 0, 0).actor(ts, "ego", 0, 0).actor(ts, "7", 10, 0)
    b.on_truth(TS, {"7": {"1": (-50, 30)}})
    assert not prediction(context(b.build()), TS).failed


def test_prediction_nan_offset_passes() -> None:
    b = moving_ego(LogBuilder()).frame(TS)
    b.on_truth(TS, {"7": {"0": (math.nan, 2), "1": (3, math.nan)}})
    assert not prediction(context(b.build()), TS).failed


def test_prediction_first_failure_in_file_order() -> None:
    # Both ids fail; "9" comes first in the file (then its keys in file order: "2" then "1").
    b = moving_ego(LogBuilder()).frame(TS)
    for ts in range(0, 1001, 50):
        b.actor(ts, "9", 5, 2).actor(ts, "3", 5, 2)
    b.on_truth(TS, {"9": {"0": (3, 2), "2": (3, 2), "1": (3, 2)}, "3": {"0": (9, 9)}})
    result = prediction(context(b.build()), TS)
    assert (result.metrics["obstacle_id"], result.metrics["key"]) == ("9", "2")
    # k = 2: P = (4 + 3, 2), error 2; dis = |(4, 0) - (5, 2)| = sqrt(5).
    assert result.metrics["error"] == 2.0
    assert result.metrics["dis"] == math.sqrt(5)


def test_prediction_horizon_excludes_tk_at_the_end() -> None:
    # total_frames 3: end 150 ms. Step 1 (tk 150) is not < 150: never read, so its
    # missing pose and actor do not matter.
    b = LogBuilder(total_frames=3).frame(TS)
    for ts in (50, TS):
        b.pose(ts, 0, 0).actor(ts, "ego", 0, 0).actor(ts, "7", 1, 0)
    b.on_truth(TS, {"7": {"0": (1, 0), "1": (40, 40)}})
    ctx = context(b.build())
    result = prediction(ctx, TS)
    assert not result.failed and result.skipped is None
    assert result.metrics["n_steps"] == 1
    assert not ctx.problems


def test_prediction_failure_before_a_crash_stands() -> None:
    # Step "1" fails (see the first prediction test) before the non-integer key is read.
    b = moving_ego(LogBuilder()).frame(TS)
    b.on_truth(TS, {"7": {"0": (3, 2), "1": (3, 2), "x": (0, 0)}, "8": {"1": (0, 0)}})
    ctx = context(b.build())
    result = prediction(ctx, TS)
    assert result.failed and result.skipped is None
    assert not ctx.problems


@pytest.mark.parametrize(
    ("mutate", "problem"),
    [
        # A non-integer key before any failure.
        (lambda b: b.on_truth(TS, {"7": {"0": (3, 2), "1.0": (3, 2)}}),
         ("predictions_with_perception/predictions-100.json", "7.1.0")),
        # The ego pose at tk = 150 is missing.
        (lambda b: b.log.pose.pop(150), ("pose/pose-150.json", "")),
        # The actors file at tk = 150 is missing.
        (lambda b: b.no_actors_file(150), ("actors/actors-150.json", "")),
        # "7" is not in the actors file at tk = 150.
        (lambda b: b._actors[150].pop("7"), ("actors/actors-150.json", "7")),
        # The file of predictions on truth itself is missing.
        (lambda b: b.log.predictions_with_perception.pop(TS),
         ("predictions_with_perception/predictions-100.json", "")),
    ],
)  # fmt: skip
def test_prediction_crash_cases_are_reported_and_skipped(mutate: Any, problem: Any) -> None:
    b = moving_ego(LogBuilder()).frame(TS, 200)
    # Offsets relative to the future ego: every step passes when the data is there.
    b.on_truth(TS, {"7": {"0": (3, 2), "1": (2, 2)}})
    b.on_truth(200, {"7": {"0": (1, 2), "1": (0, 2)}})
    mutate(b)
    ctx = context(b.build())
    result = prediction(ctx, TS)
    assert_skipped(result)
    assert problems_of(ctx) == [problem]
    # The next frame is still evaluated (and passes).
    later = prediction(ctx, 200)
    assert not later.failed and later.skipped is None


def test_prediction_missing_pose_at_ts() -> None:
    b = moving_ego(LogBuilder()).frame(TS)
    b.on_truth(TS, {"7": {"1": (2, 2)}})
    b.log.pose.pop(TS)
    ctx = context(b.build())
    assert_skipped(prediction(ctx, TS))
    assert problems_of(ctx) == [("pose/pose-100.json", "yaw")]


def test_prediction_off_grid_frame_looks_up_exact_timestamps() -> None:
    # ts = 125 (off the 50 ms grid): step 1 is 175 ms, found by exact timestamp. Ego parked
    # at the origin, "7" at (1, 0) at 175: offset (0, 0) gives error = dis = 1: failure.
    b = LogBuilder().frame(125).pose(50, 0, 0).actor(50, "ego", 0, 0)
    b.pose(125, 0, 0).pose(175, 0, 0).actor(175, "ego", 0, 0).actor(175, "7", 1, 0)
    b.on_truth(125, {"7": {"1": (0, 0)}})
    result = prediction(context(b.build()), 125)
    assert result.failed and result.metrics["ratio"] == 1.0


def test_prediction_negative_key_reads_the_past() -> None:
    # Key "-1" at ts 100 is tk = 50 < end: judged against the ego and "7" at 50 ms.
    b = LogBuilder().frame(TS).pose(50, 0, 0).actor(50, "ego", 0, 0).actor(50, "7", 1, 0)
    b.pose(TS, 0, 0).on_truth(TS, {"7": {"-1": (0, 0)}})
    assert prediction(context(b.build()), TS).failed


def test_prediction_only_ego_is_nothing_to_judge() -> None:
    b = moving_ego(LogBuilder()).frame(TS).on_truth(TS, {"ego": {"0": (99, 0)}})
    result = prediction(context(b.build()), TS)
    assert not result.failed and result.skipped is None


# ============================================================================ planning


def planning_builder(
    raw: Mapping[str, Mapping[str, tuple[float, float]]],
    on_truth: Mapping[str, Mapping[str, tuple[float, float]]] | None = None,
    total_frames: int = 20,
    yaw: float = 0.0,
    other_ext: tuple[float, float, float] = CAR,
) -> LogBuilder:
    """Ego (a car) at the origin at ts = 100; plan points i at (i, 0); actor "car".

    Combined half sizes minus the camera offset (camera_loc (1.3, 0, 1.8)):
    x: 2.4 + 2.4 - 1.3 = 3.5, y: 1.0 + 1.0 - 0.0 = 2.0 (for a car partner).
    """
    b = LogBuilder(total_frames=total_frames).frame(TS)
    b.pose(50, 0, 0).actor(50, "ego", 0, 0).actor(50, "car", 50, 50, ext=other_ext)
    b.pose(TS, 0, 0, yaw=yaw)
    b.plan(TS, {str(i): (float(i), 0.0) for i in range(6)})
    b.on_truth(
        TS, on_truth if on_truth is not None else {"ego": {"0": (0, 0)}, "car": {"0": (10, 0)}}
    )
    return b.raw(TS, raw)


def ahead(*indices: int, dx: float = 2.0) -> dict[str, tuple[float, float]]:
    """A raw track with step "0" at (10, 0) and step i at plan point i + (dx, 0)."""
    return {"0": (10.0, 0.0)} | {str(i): (i + dx, 0.0) for i in indices}


def judge_planning(b: LogBuilder) -> tuple[OracleResult, RunContext]:
    ctx = context(b.build())
    return planning(ctx, TS), ctx


def test_planning_car_overlap_at_index_one_or_two_is_a_collision() -> None:
    # Q_2 - W_2 = (2, 0): gap_x = 2 - 3.5 = -1.5, gap_y = 0 - 2.0 = -2.0; tol 0 below
    # index 3: both gaps < 0, a collision at index 2.
    result, _ = judge_planning(planning_builder({"r": ahead(2)}))
    assert result.failed
    assert result.metrics == {
        "index": 2,
        "key": "2",
        "raw_id": "r",
        "linked_id": "car",
        "gap_x": -1.5,
        "gap_y": -2.0,
        "tol": 0.0,
        "links": {"r": "car"},
    }
    assert result.ids == ("r", "car")


def test_planning_car_overlap_from_index_three_is_tolerated() -> None:
    # tol = -2.0 from index 3 on. gap_x = -1.5 is not < -2; even an exact overlap
    # (gap_x -3.5) fails the y test: gap_y = |dy| - 2.0 >= -2.0 is never < -2.0, so two
    # cars of half width 1.0 can never collide at index 3+.
    for raw in (ahead(3, 4, 5), ahead(3, 4, 5, dx=0.0)):
        result, _ = judge_planning(planning_builder({"r": raw}))
        assert not result.failed


def test_planning_wide_partner_collides_beyond_tolerance() -> None:
    # A truck (half width 1.5): y gap |0| - 2.5 = -2.5 < -2, x gap -3.5 < -2 at index 3.
    result, _ = judge_planning(planning_builder({"r": ahead(3, dx=0.0)}, other_ext=(2.4, 1.5, 1.0)))
    assert result.failed
    assert (result.metrics["index"], result.metrics["tol"]) == (3, -2.0)
    assert result.metrics["gap_y"] == -2.5


def test_planning_horizon_is_inclusive_at_the_end() -> None:
    truck = (2.4, 1.5, 1.0)
    # end = 5 x 50 = 250 ms: 100 + 3 x 50 = 250 <= 250, judged.
    result, _ = judge_planning(
        planning_builder({"r": ahead(3, dx=0.0)}, total_frames=5, other_ext=truck)
    )
    assert result.failed
    # end = 200 ms: index 3 lies beyond.
    result, _ = judge_planning(
        planning_builder({"r": ahead(3, dx=0.0)}, total_frames=4, other_ext=truck)
    )
    assert not result.failed


def test_planning_first_collision_in_plan_order_then_raw_order() -> None:
    # Both raw ids collide at index 1 and 2; plan index 1 comes first, and within it "r2"
    # (first in the raw file).
    result, _ = judge_planning(planning_builder({"r2": ahead(2, 1), "r1": ahead(1, 2)}))
    assert (result.metrics["key"], result.metrics["raw_id"]) == ("1", "r2")


def test_planning_keys_match_only_as_identical_strings() -> None:
    raw = {"0": (10.0, 0.0), "01": (3.0, 0.0)}  # "01" is not plan key "1"
    result, _ = judge_planning(planning_builder({"r": raw}))
    assert not result.failed


def test_planning_rotates_raw_offsets_by_the_ego_yaw() -> None:
    # yaw 90: R (x, y) = (-y, x). Offset (0, -3) lands at (3, 0) = W_1 + (2, 0): collision.
    # Unrotated it would be (0, -3): gap_y = 3 - 2 = 1, no collision.
    raw = {"0": (10.0, 0.0), "1": (0.0, -3.0)}
    result, _ = judge_planning(planning_builder({"r": raw}, yaw=90.0))
    assert result.failed
    assert result.metrics["gap_x"] == pytest.approx(-1.5)


def test_planning_anchor_is_plan_zero_not_the_pose() -> None:
    b = planning_builder({"r": ahead(1)})
    b.pose(TS, 100.0, 100.0)  # only the yaw of the pose is used
    result, _ = judge_planning(b)
    assert result.failed


def test_planning_link_skips_the_ego_and_takes_the_nearest() -> None:
    # The ego's step "0" coincides with the raw one; it is skipped. "car" (d = 2) wins.
    on_truth = {"ego": {"0": (10, 0)}, "far": {"0": (30, 0)}, "car": {"0": (12, 0)}}
    b = planning_builder({"r": ahead(1)}, on_truth=on_truth).actor(50, "far", 0, 90)
    result, _ = judge_planning(b)
    assert result.metrics["links"] == {"r": "car"}


def test_planning_link_tie_goes_to_the_earlier_id() -> None:
    # "ped" and "car" are both 1 m from the raw step "0". The earlier id wins. Linked to
    # the pedestrian (half 0.3): gap_x = 2 - (0.3 + 2.4 - 1.3) = 0.6, no collision.
    on_truth = {"ped": {"0": (11, 0)}, "car": {"0": (9, 0)}}
    b = planning_builder({"r": ahead(1)}, on_truth=on_truth).actor(
        50, "ped", 70, 70, ext=(0.3, 0.3, 1)
    )
    result, _ = judge_planning(b)
    assert result.metrics["links"] == {"r": "ped"} and not result.failed
    swapped = {"car": {"0": (9, 0)}, "ped": {"0": (11, 0)}}
    b = planning_builder({"r": ahead(1)}, on_truth=swapped).actor(
        50, "ped", 70, 70, ext=(0.3, 0.3, 1)
    )
    result, _ = judge_planning(b)
    assert result.metrics["links"] == {"r": "car"} and result.failed


def test_planning_link_distance_is_strictly_below_100() -> None:
    # Raw step "0" at (10, 0); the candidate at (110, 0) is exactly 100 m away: ignored.
    result, ctx = judge_planning(
        planning_builder({"r": ahead(1)}, on_truth={"car": {"0": (110, 0)}})
    )
    assert not result.failed and result.metrics["links"] == {}
    assert not ctx.problems
    result, _ = judge_planning(
        planning_builder({"r": ahead(1)}, on_truth={"car": {"0": (109.9, 0)}})
    )
    assert result.failed


def test_planning_without_raw_predictions_passes() -> None:
    for drop_file in (False, True):
        b = planning_builder({})
        if drop_file:
            b.log.predictions.pop(TS)
        result, ctx = judge_planning(b)
        assert not result.failed and result.skipped is None
        assert not ctx.problems


def test_planning_no_candidate_ignores_raw_ids_without_reading_them() -> None:
    # Only the ego in the predictions on truth: nothing to link, so the raw id's missing
    # step "0" is never read.
    result, ctx = judge_planning(
        planning_builder({"r": {"1": (3, 0)}}, on_truth={"ego": {"0": (0, 0)}})
    )
    assert not result.failed and result.skipped is None
    assert not ctx.problems


def drop_pose(b: LogBuilder) -> LogBuilder:
    b.log.pose.pop(TS)
    return b


@pytest.mark.parametrize(
    ("mutate", "problem"),
    [
        # The yaw and plan["0"] are read before the raw predictions: even with no raw.
        (lambda b: (drop_pose(b), b.raw(TS, {})), ("pose/pose-100.json", "yaw")),
        (lambda b: (b.plan(TS, {"1": (1, 0)}), b.raw(TS, {})),
         ("waypoint/waypoints-100.json", "0")),
        (lambda b: b.plan(TS, {}), ("waypoint/waypoints-100.json", "")),
        (lambda b: b.log.waypoints.pop(TS), ("waypoint/waypoints-100.json", "")),
        # Linking needs every step "0": the raw id's, and every candidate's.
        (lambda b: b.raw(TS, {"r": {"1": (3, 0)}}), ("predictions/predictions-100.json", "r")),
        (lambda b: b.on_truth(TS, {"car": {"0": (10, 0)}, "x": {"1": (0, 0)}}),
         ("predictions_with_perception/predictions-100.json", "x")),
        (lambda b: b.log.predictions_with_perception.pop(TS),
         ("predictions_with_perception/predictions-100.json", "")),
        # A non-integer plan key reached before the collision (index 1 is after it).
        (lambda b: b.plan(TS, {"0": (0, 0), "one": (1, 0), "1": (1, 0)}),
         ("waypoint/waypoints-100.json", "one")),
        # Nothing links (only the ego on truth), but the plan keys are still visited.
        (lambda b: (b.on_truth(TS, {"ego": {"0": (0, 0)}}), b.plan(TS, {"0": (0, 0), "x": (1, 0)})),
         ("waypoint/waypoints-100.json", "x")),
        # The linked actor has no extent anywhere.
        (lambda b: b.on_truth(TS, {"ghost": {"0": (10, 0)}}), ("actors/", "ghost.extent")),
    ],
)  # fmt: skip
def test_planning_crash_cases_are_reported_and_skipped(mutate: Any, problem: Any) -> None:
    b = planning_builder({"r": ahead(1)})
    mutate(b)
    result, ctx = judge_planning(b)
    assert_skipped(result)
    assert problems_of(ctx) == [problem]


def test_planning_non_integer_key_after_the_collision_is_never_read() -> None:
    b = planning_builder({"r": ahead(1)})
    b.plan(TS, {"0": (0, 0), "1": (1, 0), "one": (1, 0)})
    result, ctx = judge_planning(b)
    assert result.failed and not ctx.problems


def test_planning_ego_without_extent() -> None:
    b = planning_builder({"r": ahead(1)})
    b.actor(50, "ego", 0, 0, ext=(math.nan, math.nan, math.nan))
    result, ctx = judge_planning(b)
    assert_skipped(result)
    assert problems_of(ctx) == [("actors/", "ego.extent")]


# ============================================================================ control


def control_log(a: tuple[float, float], b: tuple[float, float], total_frames: int = 20) -> RunLog:
    """Pose at the origin at ts; actual step ``a`` (pose at ts + 50); planned step ``b``."""
    lb = LogBuilder(total_frames=total_frames).frame(TS).pose(50, 0, 0).actor(50, "ego", 0, 0)
    lb.pose(TS, 0, 0).pose(150, *a)
    return lb.plan(TS, {"0": (0, 0), "1": b}).build()


def judge_control(a: tuple[float, float], b: tuple[float, float]) -> OracleResult:
    return control(context(control_log(a, b)), TS)


def test_control_fires_on_exact_tracking_above_12_m_s() -> None:
    # 12 m/s at 50 ms per frame is 0.6 m per step. Exact tracking: a = b = (0.6, 0).
    # |a_x| = 0.6 is not < 0.6, so the step is judged. x: |b_x| >= 0.5 and |a_x - b_x| = 0
    # < 0.5 gives s_x = 1; y: |b_y| = 0 < 0.5 gives s_y = 1. The reference declares a
    # failure UNLESS s_x < 0.1 and s_y < 0.1 (its helper returns 1 for "good" and it
    # inverts it here), so perfect tracking is a failure. Whenever |b| >= 0.5 and
    # |a - b| < 0.5, s = 1 and the frame fails.
    result = judge_control((0.6, 0.0), (0.6, 0.0))
    assert result.failed
    assert result.metrics == {"a": [0.6, 0.0], "b": [0.6, 0.0], "s_x": 1.0, "s_y": 1.0}


def test_control_below_the_movement_gate_never_fails() -> None:
    # 11.8 m/s: 0.59 m per step on both axes, below 0.6: no failure whatever the plan.
    assert not judge_control((0.59, 0.59), (30.0, -30.0)).failed


def test_control_passes_only_when_both_ratios_are_small() -> None:
    # b = (10, 10), a = (10.6, 10.6): |a - b| = 0.6 >= 0.5, s = 0.6 / 10 = 0.06 < 0.1.
    result = judge_control((10.6, 10.6), (10.0, 10.0))
    assert not result.failed
    assert result.metrics["s_x"] == pytest.approx(0.06)
    # a_x = 12: s_x = 2 / 10 = 0.2: failure.
    result = judge_control((12.0, 10.6), (10.0, 10.0))
    assert result.failed and result.metrics["s_x"] == pytest.approx(0.2)


def test_control_short_planned_step_scores_one() -> None:
    # |b_x| = 0.4 < 0.5: s_x = 1 however far the car actually went.
    result = judge_control((1.0, 0.0), (0.4, 0.0))
    assert result.failed and result.metrics["s_x"] == 1.0


def test_control_after_the_end_passes() -> None:
    # total_frames 2: end 100 ms; ts + 50 > 100. No pose at 150 needed.
    lb = LogBuilder(total_frames=2).frame(TS).pose(50, 0, 0).actor(50, "ego", 0, 0)
    log = lb.pose(TS, 0, 0).plan(TS, {"0": (0, 0), "1": (5, 0)}).build()
    ctx = context(log)
    result = control(ctx, TS)
    assert not result.failed and result.skipped is None and not ctx.problems


def test_control_empty_plan_passes() -> None:
    log = control_log((1, 0), (1, 0))
    log.waypoints[TS] = log.waypoints[TS].__class__((), np.zeros((0, 2)), np.zeros(0))
    ctx = context(log)
    result = control(ctx, TS)
    assert not result.failed and result.skipped == "empty plan"


@pytest.mark.parametrize(
    ("mutate", "problem"),
    [
        (lambda log: log.waypoints.pop(TS), ("waypoint/waypoints-100.json", "")),
        (lambda log: log.pose.pop(150), ("pose/pose-150.json", "")),
        (lambda log: log.pose.pop(TS), ("pose/pose-100.json", "")),
    ],
)
def test_control_crash_cases_are_reported_and_skipped(mutate: Any, problem: Any) -> None:
    log = control_log((5, 0), (1, 0))
    mutate(log)
    ctx = context(log)
    assert_skipped(control(ctx, TS))
    assert problem in problems_of(ctx)


def test_control_plan_without_point_one() -> None:
    lb = LogBuilder().frame(TS).pose(50, 0, 0).actor(50, "ego", 0, 0).pose(TS, 0, 0)
    log = lb.pose(150, 5, 0).plan(TS, {"0": (0, 0), "2": (1, 0)}).build()
    ctx = context(log)
    assert_skipped(control(ctx, TS))
    assert problems_of(ctx) == [("waypoint/waypoints-100.json", "1")]


def test_control_nan_in_the_file_is_computed_with_unreadable_value_is_skipped() -> None:
    # A genuine "nan" (the reference floats it): every comparison is false, s = NaN, and
    # "not (NaN < 0.1)" is a failure.
    log = control_log((math.nan, 0.0), (1.0, 0.0))
    assert control(context(log), TS).failed
    # The same NaN where the loader could not read the value: the reference stops.
    log = control_log((math.nan, 0.0), (1.0, 0.0))
    log.problems.add("pose/pose-150.json", "x", "'abc' is not a number", "read as NaN")
    ctx = context(log)
    assert_skipped(control(ctx, TS))
    assert problems_of(ctx) == [("pose/pose-150.json", "x")]


# ============================================================================ all four


def test_crash_in_one_frame_leaves_the_other_frames_evaluated() -> None:
    # Frames 100, 150, 200; the bboxes file at 150 is missing, so is the pose at 150
    # (prediction and control at 100 need it for step 1; every oracle at 150 but
    # perception needs it too).
    b = moving_ego(LogBuilder()).frame(100, 150, 200)
    for ts in (100, 150, 200):
        b.boxes(ts, [("d", (0, 0, 10, 10))], [("g", (5, 0, 15, 10))])  # IoU 1/3: failure
        b.on_truth(ts, {"7": {"1": (0, 0)}})
        b.raw(ts, {})
        f = ts // 50
        b.plan(ts, {"0": (f, 0), "1": (f + 1, 0)})  # exact tracking at 20 m/s: failure
    b.log.bboxes.pop(150)
    b.log.pose.pop(150)
    ctx = context(b.build())
    results = {ts: {m: ORACLES[m](ctx, ts) for m in MODULES} for ts in (100, 150, 200)}
    failed = {ts: [m for m, r in res.items() if r.failed] for ts, res in results.items()}
    skipped = {ts: [m for m, r in res.items() if r.skipped] for ts, res in results.items()}
    assert skipped == {
        100: ["prediction", "controller"],  # pose at 150: prediction step 1, control's a
        150: ["perception", "prediction", "planning", "controller"],  # pose / yaw at 150
        200: [],
    }
    # At 200 everything is there. Prediction: step 1 anchored at the ego at 250, (5, 0),
    # offset (0, 0), "7" at (5, 2): error = dis = 2, ratio 1: a failure. Control: a = b =
    # (1, 0): exact tracking at 20 m/s, a failure.
    assert failed == {
        100: ["perception"],
        150: [],
        200: ["perception", "prediction", "controller"],
    }
    assert set(problems_of(ctx)) == {
        ("pose/pose-150.json", ""),
        ("bboxes/bboxes-150.json", ""),
        ("pose/pose-150.json", "yaw"),
    }


# ============================================================================ properties


def slow_iou(a: list[float], b: list[float]) -> float:
    """IoU written out by hand, with the same float operations as the vectorised one."""
    if any(math.isnan(v) for v in a + b):
        return math.nan
    ax1, ax2 = min(a[0], a[2]), max(a[0], a[2])
    ay1, ay2 = min(a[1], a[3]), max(a[1], a[3])
    bx1, bx2 = min(b[0], b[2]), max(b[0], b[2])
    by1, by2 = min(b[1], b[3]), max(b[1], b[3])
    area_a = (ax2 - ax1) * (ay2 - ay1)
    area_b = (bx2 - bx1) * (by2 - by1)
    if area_a <= 0 or area_b <= 0:
        return 0.0
    iw = max(min(ax2, bx2) - max(ax1, bx1), 0.0)
    ih = max(min(ay2, by2) - max(ay1, by1), 0.0)
    inter = iw * ih
    union = area_a + area_b - inter
    return inter / union if union > 0 else 0.0


def slow_perception(det: list[list[float]], gt: list[list[float]], thr: float) -> tuple[Any, ...]:
    """The spec's greedy matching, one detection and one gt at a time."""
    used: set[int] = set()
    ious: list[float] = []
    rows: list[int] = []
    for d in det:
        best, best_j = 0.0, -1
        for j, g in enumerate(gt):
            if j in used:
                continue
            value = slow_iou(d, g)
            if value > best:  # strict: ties keep the earlier gt; NaN never wins
                best, best_j = value, j
        if best_j >= 0:
            used.add(best_j)
            rows.append(best_j)
            ious.append(round(best, 4))
    mean = float(np.mean(ious)) if ious else math.nan
    return (mean < thr, ious, rows)


coord = st.one_of(
    st.integers(0, 6).map(float),
    st.sampled_from([math.nan, 2.5, 0.5]),
)
box = st.lists(coord, min_size=4, max_size=4)


@settings(max_examples=400, deadline=None)
@given(st.lists(box, max_size=7), st.lists(box, max_size=7), st.sampled_from([0.3, 0.5, 0.7]))
def test_perception_matches_slow_greedy(
    det: list[list[float]], gt: list[list[float]], thr: float
) -> None:
    det_items = [(f"d{i}", c) for i, c in enumerate(det)]
    gt_items = [(str(j), c) for j, c in enumerate(gt)]
    result = judge_perception(det_items, gt_items, perc_score_threshold=thr)
    failed, ious, rows = slow_perception(det, gt, thr)
    assert result.failed == failed
    assert result.metrics["ious"] == ious
    assert result.ids == tuple(str(j) for j in rows)
    _, cols, _ = reference.greedy_match(make_boxes(det_items).corners, make_boxes(gt_items).corners)
    assert cols == rows


def slow_prediction(log: RunLog, ego_id: str, ts: int, thr: float) -> tuple[Any, ...]:
    """The spec's prediction oracle, one id and one key at a time; "crash" where it stops."""
    frame_ms, end = log.frame_ms, log.metadata.end_ms
    on_truth = log.predictions_with_perception.get(ts)
    if on_truth is None:
        return ("crash",)
    for pid, track in on_truth.items():
        if pid == ego_id:
            continue
        for row, key in enumerate(track.keys):
            try:
                k = int(key)
            except ValueError:
                return ("crash",)
            tk = ts + k * frame_ms
            if not tk < end:
                continue
            anchor, now, actors = log.pose.get(tk), log.pose.get(ts), log.actors.get(tk)
            if anchor is None or now is None or actors is None or pid not in actors.index:
                return ("crash",)
            ax, ay = (float(v) for v in actors.location[actors.index[pid], :2])
            x, y = float(track.offsets[row, 0]), float(track.offsets[row, 1])
            c, s = math.cos(math.radians(now.yaw)), math.sin(math.radians(now.yaw))
            px, py = anchor.x + (x * c - y * s), anchor.y + (x * s + y * c)
            error = math.sqrt((px - ax) * (px - ax) + (py - ay) * (py - ay))
            dis = math.sqrt((anchor.x - ax) * (anchor.x - ax) + (anchor.y - ay) * (anchor.y - ay))
            if dis == 0:
                ratio = math.nan if error == 0 or math.isnan(error) else math.inf
            else:
                ratio = error / dis
            if dis < 4 and ratio >= thr:
                return ("fail", pid, key, error, dis, ratio)
    return ("pass",)


small = st.one_of(st.integers(-2, 3).map(float), st.just(math.nan))
key_strategy = st.sampled_from(["0", "1", "2", "3", "-1", "x", "05", "9"])


@st.composite
def prediction_logs(draw: st.DrawFn) -> tuple[RunLog, float, int]:
    """Tiny random logs; the judged frame is on the 50 ms grid or off it (125 ms)."""
    ts_judged = draw(st.sampled_from([TS, 125]))
    b = LogBuilder(total_frames=draw(st.integers(2, 6))).frame(ts_judged)
    ids = ["ego", "1", "2", "3"]
    for ts in range(0, 401, 25):
        if ts == ts_judged or draw(st.booleans()) or draw(st.booleans()):
            yaw = draw(st.sampled_from([0.0, 90.0, 30.0, math.nan]))
            b.pose(ts, draw(small), draw(small), yaw=yaw)
        if draw(st.integers(0, 5)) > 0:
            for actor_id in ids:
                if draw(st.integers(0, 5)) > 0:
                    b.actor(ts, actor_id, draw(small), draw(small))
    if draw(st.integers(0, 9)) > 0:
        tracks: dict[str, dict[str, tuple[float, float]]] = {}
        for actor_id in draw(st.permutations(ids)):
            if draw(st.booleans()):
                keys = draw(st.lists(key_strategy, max_size=4, unique=True))
                tracks[actor_id] = {k: (draw(small), draw(small)) for k in keys}
        b.on_truth(ts_judged, tracks)
    return b.build(), draw(st.sampled_from([0.1, 0.5])), ts_judged


@pytest.mark.slow
@settings(max_examples=500, deadline=None)
@given(prediction_logs())
def test_prediction_matches_slow_sequential(case: tuple[RunLog, float, int]) -> None:
    log, thr, ts = case
    ctx = RunContext(log, make_params("reference", {"pred_score_threshold": thr}), ego_id="ego")
    result = prediction(ctx, ts)
    expected = slow_prediction(log, "ego", ts, thr)
    if expected[0] == "crash":
        assert result.skipped and not result.failed
        assert len(ctx.problems) == 1
        return
    assert result.skipped is None
    assert result.failed == (expected[0] == "fail")
    if result.failed:
        m = result.metrics
        got = ("fail", m["obstacle_id"], m["key"], m["error"], m["dis"], m["ratio"])
        assert got[:3] == expected[:3]
        for g, e in zip(got[3:], expected[3:], strict=True):
            nan_g = isinstance(g, float) and math.isnan(g)
            assert g == e or (nan_g and isinstance(e, float) and math.isnan(e))


def slow_planning(log: RunLog, ego: str, ts: int) -> tuple[Any, ...]:
    """The spec's planning oracle written out literally; "crash" where the reference stops."""
    frame_ms, end, cam = log.frame_ms, log.metadata.end_ms, log.metadata.camera_loc
    pose, plan = log.pose.get(ts), log.waypoints.get(ts)
    if pose is None or plan is None or len(plan) == 0 or plan.point("0") is None:
        return ("crash",)
    raw = log.predictions.get(ts)
    if not raw:
        return ("pass",)
    on_truth = log.predictions_with_perception.get(ts)
    if on_truth is None:
        return ("crash",)
    links: dict[str, tuple[str, Any]] = {}
    for raw_id, raw_track in raw.items():
        best, best_id = 100.0, None
        for pid, track in on_truth.items():
            if pid == ego:
                continue
            r0, p0 = raw_track.offset("0"), track.offset("0")
            if r0 is None or p0 is None:
                return ("crash",)
            dx, dy = float(r0[0]) - float(p0[0]), float(r0[1]) - float(p0[1])
            d = math.sqrt(dx * dx + dy * dy)
            if d < best:
                best, best_id = d, pid
        if best_id is None:
            continue
        ext = log.actor_extents.get(best_id)
        if ext is None:
            return ("crash",)
        links[raw_id] = (best_id, ext)
    anchor = plan.point("0")
    assert anchor is not None
    c, s = math.cos(math.radians(pose.yaw)), math.sin(math.radians(pose.yaw))
    for n, key in enumerate(plan.keys):
        try:
            i = int(key)
        except ValueError:
            return ("crash",)
        if i == 0 or ts + i * frame_ms > end:
            continue
        for raw_id, (pid, ext) in links.items():
            offset = raw[raw_id].offset(key)
            if offset is None:
                continue
            ego_ext = log.actor_extents.get(ego)
            if ego_ext is None:
                return ("crash",)
            x, y = float(offset[0]), float(offset[1])
            qx, qy = float(anchor[0]) + (x * c - y * s), float(anchor[1]) + (x * s + y * c)
            wx, wy = float(plan.xy[n, 0]), float(plan.xy[n, 1])
            gx = abs(wx - qx) - ((float(ext[0]) + float(ego_ext[0])) - cam[0])
            gy = abs(wy - qy) - ((float(ext[1]) + float(ego_ext[1])) - cam[1])
            tol = 0.0 if i < 3 else -2.0
            if gx < tol and gy < tol:
                return ("fail", key, raw_id, pid, gx, gy, tol)
    return ("pass",)


plan_key = st.sampled_from(["0", "1", "2", "3", "4", "01", "-1", "x"])
coord_m = st.one_of(st.sampled_from([0.0, 1.0, 2.0, 3.0, 4.0, 120.0, -2.0]), st.just(math.nan))


@st.composite
def planning_logs(draw: st.DrawFn) -> RunLog:
    b = LogBuilder(total_frames=draw(st.integers(2, 8)), camera_loc=(1.3, 0.2, 1.8)).frame(TS)
    if draw(st.integers(0, 9)):
        b.pose(TS, 0.0, 0.0, yaw=draw(st.sampled_from([0.0, 90.0, 30.0])))
    ids = ["ego", "1", "2", "3"]
    for actor_id in ids:
        if draw(st.integers(0, 5)):
            ext = draw(st.sampled_from([(2.4, 1.0, 0.7), (0.3, 0.3, 1.0), (2.4, 1.6, 1.0)]))
            b.actor(50, actor_id, 90.0, 90.0, ext=ext)
    if draw(st.integers(0, 9)):
        keys = draw(st.lists(plan_key, max_size=6, unique=True))
        if draw(st.integers(0, 5)):
            keys = ["0", *[k for k in keys if k != "0"]]
        b.plan(TS, {k: (draw(coord_m), draw(coord_m)) for k in keys})

    def tracks(id_pool: list[str]) -> dict[str, dict[str, tuple[float, float]]]:
        out: dict[str, dict[str, tuple[float, float]]] = {}
        for obstacle_id in draw(st.permutations(id_pool)):
            if draw(st.booleans()):
                keys = draw(st.lists(plan_key, max_size=5, unique=True))
                if draw(st.integers(0, 4)):
                    keys = ["0", *[k for k in keys if k != "0"]]
                out[obstacle_id] = {k: (draw(coord_m), draw(coord_m)) for k in keys}
        return out

    if draw(st.integers(0, 9)):
        b.raw(TS, tracks(["r1", "r2", "r3"]))
    if draw(st.integers(0, 9)):
        b.on_truth(TS, tracks([*ids, "ghost"]))
    return b.build()


@settings(max_examples=600, deadline=None)
@given(planning_logs())
def test_planning_matches_slow_sequential(log: RunLog) -> None:
    ctx = RunContext(log, make_params("reference"), ego_id="ego")
    result = planning(ctx, TS)
    expected = slow_planning(log, "ego", TS)
    if expected[0] == "crash":
        assert result.skipped and not result.failed
        assert len(ctx.problems) == 1
        return
    assert result.skipped is None
    assert result.failed == (expected[0] == "fail")
    if result.failed:
        m = result.metrics
        got = ("fail", m["key"], m["raw_id"], m["linked_id"], m["gap_x"], m["gap_y"], m["tol"])
        assert got == expected
