"""OpenLane-V2's metrics on frames worked out by hand (ads_rca.sources.openlane.scores)."""

from __future__ import annotations

import functools
import json
import math
from collections.abc import Iterable, Sequence
from fractions import Fraction
from typing import Any

import numpy as np
import pytest

from ads_rca.sources.openlane.lanes import LaneGraph
from ads_rca.sources.openlane.scores import (
    UNMATCHED_LINK,
    average_precision,
    frechet_distance,
    frechet_matrix,
    greedy_match,
    iou_matrix,
    lane_distance_matrix,
    match_frame,
    relaxation_factors,
    score_frames,
    scores_from,
    vertex_link_ap,
)

RED, GREEN = 1, 2


def evaluate_frames(pairs: Iterable[tuple[LaneGraph, LaneGraph]], **options: Any) -> Any:
    """The devkit's ``evaluate()`` on a ground truth already collected: the hand-made lanes
    here are scored as given (``point_interval`` 1), the collection step is tested apart."""
    return score_frames(pairs, point_interval=1, **options)


def evaluate_frame(gt: LaneGraph, pred: LaneGraph) -> Any:
    """:func:`evaluate_frames`'s match of one frame."""
    return match_frame(gt, pred, point_interval=1)


def line(x0: float, x1: float, y: float = 0.0, points: int = 3) -> np.ndarray:
    """A straight lane along x at lateral offset y (z = 0)."""
    xs = np.linspace(x0, x1, points)
    return np.stack([xs, np.full(points, y), np.zeros(points)], axis=1)


def graph(
    lanes: Sequence[np.ndarray],
    scores: Sequence[float] | None = None,
    boxes: Sequence[Sequence[float]] = (),
    attributes: Sequence[int] = (),
    element_scores: Sequence[float] | None = None,
    lane_lane: np.ndarray | None = None,
    lane_element: np.ndarray | Sequence[Sequence[float]] | None = None,
) -> LaneGraph:
    n, k = len(lanes), len(boxes)
    return LaneGraph(
        lane_ids=tuple(str(i) for i in range(n)),
        lanes=tuple(np.asarray(lane, dtype=np.float64) for lane in lanes),
        lane_scores=np.full(n, np.nan) if scores is None else np.asarray(scores, float),
        element_ids=tuple(f"e{i}" for i in range(k)),
        element_boxes=np.asarray(boxes, dtype=np.float64).reshape(k, 4),
        element_category=np.ones(k, dtype=np.int64),
        element_attribute=np.asarray(attributes, dtype=np.int64).reshape(k),
        element_scores=(
            np.full(k, np.nan) if element_scores is None else np.asarray(element_scores, float)
        ),
        lane_lane=np.zeros((n, n)) if lane_lane is None else np.asarray(lane_lane, float),
        lane_element=(
            np.zeros((n, k)) if lane_element is None else np.asarray(lane_element, float)
        ),
    )


# A 3-lane fork: L0 (0..10 m) runs into L1 (10..20 m, straight) and L2 (10..20 m, to y = 5).
FORK = (line(0, 10), line(10, 20), np.array([[10.0, 0, 0], [15, 2.5, 0], [20, 5, 0]]))
FORK_LINKS = np.array([[0, 1, 1], [0, 0, 0], [0, 0, 0]], dtype=float)  # 0 -> 1, 0 -> 2
# E0 a red light over L1, E1 a green light over L2 (image pixels).
BOXES = ((0, 0, 10, 10), (20, 0, 30, 10))
FORK_ELEMENTS = np.array([[0, 0], [1, 0], [0, 1]], dtype=float)


def fork_truth() -> LaneGraph:
    return graph(
        FORK, boxes=BOXES, attributes=(RED, GREEN), lane_lane=FORK_LINKS, lane_element=FORK_ELEMENTS
    )


# ---------------------------------------------------------------------------------------------
# distances


def test_frechet_of_parallel_lanes_is_their_offset() -> None:
    assert frechet_distance(line(0, 10), line(0, 10, y=1.5)) == pytest.approx(1.5)


def test_frechet_of_a_reversed_lane_is_its_length() -> None:
    # both couplings' ends pair (0,0,0) with (10,0,0): 10 m, and the diagonal coupling
    # reaches no more
    assert frechet_distance(line(0, 10), line(0, 10)[::-1]) == pytest.approx(10.0)


def test_frechet_of_lanes_with_different_point_counts() -> None:
    # a: (0,0,0) (10,0,0); b: (0,1,0) (5,1,0) (10,1,0). b's middle point pairs with a's
    # first or last point: sqrt(5^2 + 1^2) = sqrt(26) either way
    two = line(0, 10, y=0.0, points=2)
    assert frechet_distance(two, line(0, 10, y=1.0)) == pytest.approx(math.sqrt(26))
    assert frechet_distance(line(0, 10, y=1.0), two) == pytest.approx(math.sqrt(26))


def slow_frechet(a: np.ndarray, b: np.ndarray) -> float:
    """Eiter and Mannila's recursion, transcribed."""

    @functools.cache
    def c(i: int, j: int) -> float:
        d = float(np.linalg.norm(a[i] - b[j]))
        if i == 0 and j == 0:
            return d
        if i == 0:
            return max(c(0, j - 1), d)
        if j == 0:
            return max(c(i - 1, 0), d)
        return max(min(c(i - 1, j), c(i - 1, j - 1), c(i, j - 1)), d)

    return c(len(a) - 1, len(b) - 1)


def test_vectorised_frechet_equals_the_recursion_on_random_polylines() -> None:
    rng = np.random.default_rng(20)
    a = [rng.normal(size=(int(rng.integers(1, 9)), 3)) * 4 for _ in range(9)]
    b = [rng.normal(size=(int(rng.integers(1, 9)), 3)) * 4 for _ in range(11)]
    expected = np.array([[slow_frechet(x, y) for y in b] for x in a])
    np.testing.assert_allclose(frechet_matrix(a, b), expected, rtol=1e-12)
    # the scorer's cut-off skips only pairs at or beyond it
    relaxed = expected * relaxation_factors(a)[:, None]
    ranked = np.sort(relaxed, axis=None)
    cutoff = float(ranked[49] + ranked[50]) / 2  # between two distances, so no tie
    cut = lane_distance_matrix(a, b, cutoff=cutoff)
    near = relaxed < cutoff
    assert 0 < near.sum() < near.size
    np.testing.assert_allclose(cut[near], relaxed[near], rtol=1e-12)
    assert (cut[~near] >= cutoff).all()


def test_relaxation_scales_a_lane_by_its_nearest_point() -> None:
    # nearest points 0, 40 and 150 m: 1, 1 - 0.005 * 40 = 0.8, max(0.5, 0.25) = 0.5
    lanes = [line(0, 10), line(40, 50), line(150, 160)]
    np.testing.assert_allclose(relaxation_factors(lanes), [1.0, 0.8, 0.5])
    far = lane_distance_matrix([line(150, 160)], [line(150, 160, y=1.5)])
    assert far[0, 0] == pytest.approx(0.75)  # 1.5 m * 0.5


def test_iou_of_boxes_worked_by_hand() -> None:
    a = np.array([[0, 0, 10, 10.0]])
    b = np.array([[5, 0, 15, 10.0], [20, 20, 30, 30.0], [3, 3, 3, 3.0]])
    # overlap 5 x 10 = 50, union 100 + 100 - 50 = 150; disjoint; a point inside: 0 / 100
    np.testing.assert_allclose(iou_matrix(a, b), [[1 / 3, 0.0, 0.0]])
    # two points: no union, IoU 0 (the devkit divides 0 by 0)
    assert iou_matrix(np.array([[1, 1, 1, 1.0]]), np.array([[1, 1, 1, 1.0]]))[0, 0] == 0.0


# ---------------------------------------------------------------------------------------------
# matching and AP


def test_greedy_takes_only_the_nearest_ground_truth() -> None:
    # prediction 1 is within 2 m of ground truth 1, but its nearest is ground truth 0, already
    # taken by prediction 0: a false positive (the devkit does not fall back)
    distance = np.array([[0.5, 1.0], [2.5, 1.9]])
    assert greedy_match(distance, np.array([0.9, 0.8]), 2.0).tolist() == [0, -1]


def test_average_precision_eleven_points() -> None:
    # ranked TP, FP, TP of 2 ground truths: precisions 1, 1/2, 2/3 at recalls 1/2, 1/2, 1;
    # levels 0..0.5 reach precision 1, levels 0.6..1 only 2/3: (6 * 1 + 5 * 2/3) / 11 = 28/33
    tp = np.array([True, False, True])
    assert average_precision(tp, np.array([0.9, 0.8, 0.7]), 2) == pytest.approx(28 / 33)
    # the same but the false positive first: 2/3 at every level
    assert average_precision(tp, np.array([0.8, 0.9, 0.7]), 2) == pytest.approx(2 / 3)
    assert average_precision(np.zeros(2, bool), np.array([0.5, 0.4]), 0) == 0.0
    assert average_precision(np.zeros(0, bool), np.zeros(0), 3) == 0.0
    assert math.isnan(average_precision(np.zeros(0, bool), np.zeros(0), 0))


def slow_ap(tp: list[bool], gt: int) -> float:
    """11-point AP with exact fractions, transcribed from its definition."""
    hits, curve = 0, []
    for rank, hit in enumerate(tp, start=1):
        hits += hit
        curve.append((Fraction(hits, gt), Fraction(hits, rank)))
    levels = [max((p for r, p in curve if r >= Fraction(k, 10)), default=0) for k in range(11)]
    return float(sum(levels, Fraction(0)) / 11)


def test_average_precision_equals_its_definition_on_random_rankings() -> None:
    rng = np.random.default_rng(7)
    for _ in range(200):
        size, gt = int(rng.integers(1, 15)), int(rng.integers(1, 12))
        tp = rng.random(size) < 0.5
        tp[np.flatnonzero(tp)[gt:]] = False  # never more hits than ground truths
        confidence = np.sort(rng.random(size))[::-1]
        expected = slow_ap(tp.tolist(), gt)
        assert average_precision(tp, confidence, gt) == pytest.approx(expected, abs=1e-12)


def slow_vertex_ap(truth: np.ndarray, confidence: np.ndarray) -> float:
    predicted = [j for j in np.argsort(-confidence, kind="stable") if confidence[j] > 0.5]
    if not truth.any() and not predicted:
        return 1.0
    if not truth.any() or not predicted:
        return 0.0
    hits, total = 0, 0.0
    for rank, j in enumerate(predicted, start=1):
        if truth[j]:
            hits += 1
            total += hits / rank
    return total / int(truth.sum())


def test_vertex_link_ap_equals_its_definition_on_random_graphs() -> None:
    rng = np.random.default_rng(3)
    truth = rng.random((40, 7)) < 0.3
    confidence = np.round(rng.random((40, 7)), 1)  # ties included
    expected = [slow_vertex_ap(t, c) for t, c in zip(truth, confidence, strict=True)]
    np.testing.assert_allclose(vertex_link_ap(truth, confidence), expected, rtol=1e-12)


# ---------------------------------------------------------------------------------------------
# whole frames


def test_a_perfect_prediction_scores_one_everywhere() -> None:
    pred = graph(
        FORK,
        scores=(0.9, 0.8, 0.7),
        boxes=BOXES,
        attributes=(RED, GREEN),
        element_scores=(0.9, 0.8),
        lane_lane=FORK_LINKS,
        lane_element=FORK_ELEMENTS,
    )
    s = evaluate_frames([(fork_truth(), pred)])
    assert (s.det_l, s.det_t, s.top_ll, s.top_lt, s.ols) == (1.0, 1.0, 1.0, 1.0, 1.0)
    assert s.det_l_ap == {1.0: 1.0, 2.0: 1.0, 3.0: 1.0}
    assert s.det_t_ap == {"red": 1.0, "green": 1.0}


def test_a_lane_shifted_1_5_m_counts_at_2_and_3_m_only() -> None:
    # Fréchet 1.5 m, relaxation 1 (the lane starts at the ego): a miss at 1 m (AP 0), a hit
    # at 2 and 3 m (AP 1): DET_l = 2/3. TOP_ll at 1 m: the ground-truth lane is unmatched,
    # so its self-link is set to the opposite of the truth (a link at 0.5 + eps): out and in
    # APs 0; at 2 and 3 m no link either side: 1 and 1. (0 + 0 + 4 * 1) / 6 = 2/3
    s = evaluate_frames([(graph([line(0, 10)]), graph([line(0, 10, y=1.5)], scores=[0.9]))])
    assert s.det_l_ap == {1.0: 0.0, 2.0: 1.0, 3.0: 1.0}
    assert s.det_l == pytest.approx(2 / 3)
    assert s.top_ll == pytest.approx(2 / 3)
    # no traffic element anywhere: DET_t and TOP_lt undefined, so OLS too
    assert math.isnan(s.det_t) and math.isnan(s.top_lt) and math.isnan(s.ols)
    assert s.det_t_ap == {}


def test_devkit_empty_scores_empty_classes_one_and_empty_topology_zero() -> None:
    # as above, but the devkit's values: 13 empty attributes at AP 1, TOP_lt 0
    pairs = [(graph([line(0, 10)]), graph([line(0, 10, y=1.5)], scores=[0.9]))]
    s = evaluate_frames(pairs, devkit_empty=True)
    assert s.det_t == 1.0 and len(s.det_t_ap) == 13 and s.top_lt == 0.0
    assert s.ols == pytest.approx((2 / 3 + 1 + math.sqrt(2 / 3) + 0) / 4)


def test_a_far_lane_is_relaxed() -> None:
    # nearest point 150 m: factor 0.5, so 1.5 m off counts as 0.75 m: a hit at every threshold
    s = evaluate_frames([(graph([line(150, 160)]), graph([line(150, 160, y=1.5)], scores=[0.9]))])
    assert s.det_l == 1.0


def test_greedy_matching_follows_confidence_not_distance() -> None:
    # A (1.5 m off, 0.9) and B (0.2 m off, 0.6) both nearest the one lane. At 1 m A misses,
    # B takes the lane: ranked FP, TP, precision 0 then 1/2 at recall 1: AP 1/2. At 2 and
    # 3 m A takes it first and B is a false positive: ranked TP, FP: AP 1.
    truth = graph([line(0, 10)])
    pred = graph([line(0, 10, y=1.5), line(0, 10, y=0.2)], scores=[0.9, 0.6])
    s = evaluate_frames([(truth, pred)])
    assert s.det_l_ap == {1.0: 0.5, 2.0: 1.0, 3.0: 1.0}
    assert s.det_l == pytest.approx(5 / 6)


def test_a_second_prediction_does_not_fall_back_to_its_second_nearest_lane() -> None:
    # ground truth at y = 0 (relaxation 1) and y = 3 (nearest 3 m: 0.985). P0 (y = 0.5) and
    # P1 (y = 1.0) are both nearest the first (P1: 1.0 against 2 * 0.985 = 1.97); P0 ranks
    # first and takes it; P1 is a false positive although 1.97 < 2 m. Ranked TP, FP of 2
    # ground truths at every threshold: recall 1/2 at most: (6 * 1 + 5 * 0) / 11 = 6/11
    truth = graph([line(0, 10), line(0, 10, y=3.0)])
    pred = graph([line(0, 10, y=0.5), line(0, 10, y=1.0)], scores=[0.9, 0.8])
    s = evaluate_frames([(truth, pred)])
    assert s.det_l == pytest.approx(6 / 11)


def test_a_false_positive_ranked_between_hits_lowers_ap_as_worked() -> None:
    # two lanes found (0.9 and 0.7) and a lane 20 m away at 0.8: ranked TP, FP, TP:
    # AP 28/33 at every threshold (see test_average_precision_eleven_points)
    truth = graph([line(0, 10), line(0, 10, y=10.0)])
    pred = graph([line(0, 10), line(0, 10, y=-20.0), line(0, 10, y=10.0)], scores=[0.9, 0.8, 0.7])
    assert evaluate_frames([(truth, pred)]).det_l == pytest.approx(28 / 33)
    without = graph([line(0, 10), line(0, 10, y=10.0)], scores=[0.9, 0.7])
    assert evaluate_frames([(truth, without)]).det_l == 1.0


def test_det_t_averages_two_attributes() -> None:
    # Q0 red on E0: IoU 1. Q1 green at (25, 0, 35, 10) against E1 (20, 0, 30, 10): overlap
    # 50, union 150, IoU 1/3 > 0.25: a hit. Q2 "red" exactly on the green light E1 at 0.95:
    # the only red ground truth is E0, IoU 0: a red false positive. Red ranked FP, TP of
    # one: AP 1/2; green AP 1; DET_t = 3/4.
    truth = graph([], boxes=BOXES, attributes=(RED, GREEN))
    pred = graph(
        [],
        boxes=((0, 0, 10, 10), (25, 0, 35, 10), (20, 0, 30, 10)),
        attributes=(RED, GREEN, RED),
        element_scores=(0.9, 0.8, 0.95),
    )
    s = evaluate_frames([(truth, pred)])
    assert s.det_t_ap == {"red": 0.5, "green": 1.0}
    assert s.det_t == pytest.approx(0.75)


def test_an_iou_of_exactly_a_quarter_does_not_match() -> None:
    # (26, 0, 36, 10) against (20, 0, 30, 10): overlap 40, union 160: IoU 0.25, distance 0.75,
    # not below 0.75
    truth = graph([], boxes=BOXES[1:], attributes=(GREEN,))
    pred = graph([], boxes=((26, 0, 36, 10),), attributes=(GREEN,), element_scores=(0.9,))
    assert evaluate_frames([(truth, pred)]).det_t == 0.0


def test_topology_with_one_wrong_link() -> None:
    # Geometry and elements perfect. Lanes: predicted 0 -> 1 (0.9) and 1 -> 2 (0.8) instead
    # of 0 -> 2 (0.3, below 0.5). Out-rows: L0 true {1, 2}, predicted {1}: 1 / 2; L1 true {},
    # predicted {2}: 0; L2 neither: 1. In-columns: L0 neither: 1; L1 true {0}, predicted {0}:
    # 1; L2 true {0}, predicted {1}: 0. (0.5 + 0 + 1 + 1 + 1 + 0) / 6 = 7/12 at each threshold.
    # Lane-element: predicted L1-E0 (0.9), L2-E0 (0.7) instead of L2-E1 (0.4). Lanes: L0
    # neither 1, L1 {E0}/{E0} 1, L2 {E1}/{E0} 0; elements: E0 {L1} ranked L1, L2: 1; E1
    # {L2}/{} 0. (1 + 1 + 0 + 1 + 0) / 5 = 3/5.
    links = np.array([[0, 0.9, 0.3], [0, 0, 0.8], [0, 0, 0]])
    elements = np.array([[0, 0], [0.9, 0], [0.7, 0.4]])
    pred = graph(
        FORK,
        scores=(0.9, 0.8, 0.7),
        boxes=BOXES,
        attributes=(RED, GREEN),
        element_scores=(0.9, 0.8),
        lane_lane=links,
        lane_element=elements,
    )
    s = evaluate_frames([(fork_truth(), pred)])
    assert (s.det_l, s.det_t) == (1.0, 1.0)
    assert s.top_ll == pytest.approx(7 / 12)
    assert s.top_lt == pytest.approx(3 / 5)
    assert s.ols == pytest.approx((1 + 1 + math.sqrt(7 / 12) + math.sqrt(3 / 5)) / 4)


def test_links_of_unmatched_predicted_lanes_are_not_looked_at() -> None:
    # a false-positive lane far away with a confident link from the found lane: the link has
    # no ground-truth vertex to land on, so topology stays perfect
    pred = graph(
        [line(0, 10), line(0, 10, y=30.0)],
        scores=[0.9, 0.8],
        lane_lane=np.array([[0, 0.9], [0.9, 0]]),
    )
    s = evaluate_frames([(graph([line(0, 10)]), pred)])
    assert s.top_ll == 1.0


def test_a_segment_pools_its_frames_before_ap() -> None:
    # frame 1: a hit at 0.6; frame 2: a false positive at 0.9 and its lane missed. Pooled:
    # ranked FP, TP of 2 ground truths: precision 1/2 at recall 1/2: (6 * 1/2) / 11 = 3/11,
    # not the mean of the frames' APs (1 and 0).
    one = (graph([line(0, 10)]), graph([line(0, 10)], scores=[0.6]))
    two = (graph([line(0, 10)]), graph([line(0, 10, y=-20.0)], scores=[0.9]))
    matches = [evaluate_frame(*one), evaluate_frame(*two)]
    assert scores_from(matches[:1]).det_l == 1.0
    assert scores_from(matches[1:]).det_l == 0.0
    pooled = scores_from(matches)
    assert pooled.det_l == pytest.approx(3 / 11) and pooled.frames == 2
    assert evaluate_frames([one, two]).det_l == pooled.det_l


# ---------------------------------------------------------------------------------------------
# hostile frames


def test_no_frames_and_empty_frames_are_undefined() -> None:
    for s in (evaluate_frames([]), evaluate_frames([(LaneGraph.empty(), LaneGraph.empty())])):
        assert all(math.isnan(v) for v in (s.det_l, s.det_t, s.top_ll, s.top_lt, s.ols))
        doc = s.to_dict()
        assert doc["ols"] is None and doc["det_l_ap"] == {"1": None, "2": None, "3": None}
        json.dumps(doc, allow_nan=False)
    devkit = evaluate_frames([(LaneGraph.empty(), LaneGraph.empty())], devkit_empty=True)
    # DET_l 1, DET_t 1, TOP_ll 0, TOP_lt 0: (1 + 1 + 0 + 0) / 4
    assert devkit.ols == pytest.approx(0.5)


def test_ground_truth_without_any_prediction_scores_zero() -> None:
    s = evaluate_frames([(fork_truth(), LaneGraph.empty())])
    # every vertex unmatched: every per-vertex AP 0
    assert (s.det_l, s.det_t, s.top_ll, s.top_lt, s.ols) == (0.0, 0.0, 0.0, 0.0, 0.0)


def test_predictions_without_ground_truth_are_false_positives_and_no_topology() -> None:
    s = evaluate_frames([(LaneGraph.empty(), graph([line(0, 10)], scores=[0.9]))])
    assert s.det_l == 0.0 and math.isnan(s.top_ll) and s.pred_lanes == 1


def test_lanes_with_non_finite_or_no_points_are_dropped_and_counted() -> None:
    bad = line(0, 10, y=5.0)
    bad[1, 2] = np.nan
    # ground truth: the good lane, a NaN lane and a link between them (dropped with it)
    truth = graph([line(0, 10), bad], lane_lane=np.array([[0, 1], [0, 0]]))
    flat = np.zeros((0, 3))
    planar = line(0, 10)[:, :2]
    pred = graph([line(0, 10), flat, planar, np.full((3, 3), np.inf)], scores=[0.9] * 4)
    s = evaluate_frames([(truth, pred)])
    assert s.dropped_lanes == 4 and s.gt_lanes == 1 and s.pred_lanes == 1
    assert (s.det_l, s.top_ll) == (1.0, 1.0)


def test_bad_boxes_are_dropped_and_counted() -> None:
    truth = graph([], boxes=BOXES, attributes=(RED, GREEN))
    pred = graph(
        [],
        boxes=((0, 0, 10, 10), (30, 0, 20, 10), (np.nan, 0, 1, 1)),
        attributes=(RED, GREEN, GREEN),
        element_scores=(0.9, 0.9, 0.9),
    )
    s = evaluate_frames([(truth, pred)])
    # the inverted and the NaN box dropped: red found (1), green missed (0)
    assert s.dropped_elements == 2 and s.det_t_ap == {"red": 1.0, "green": 0.0}


def test_a_prediction_without_confidences_ranks_in_list_order() -> None:
    # no confidence at all: ranked as listed, FP then TP: AP 1/2 at every threshold
    truth = graph([line(0, 10)])
    s = evaluate_frames([(truth, graph([line(0, 10, y=-20.0), line(0, 10)]))])
    assert s.det_l == pytest.approx(0.5) and s.unscored == 2
    # a stated confidence ranks before a missing one: TP then FP, AP 1
    mixed = graph([line(0, 10, y=-20.0), line(0, 10)], scores=[np.nan, 0.1])
    assert evaluate_frames([(truth, mixed)]).det_l == 1.0


def test_a_nan_link_between_matched_lanes_counts_as_wrong() -> None:
    # the devkit fills every NaN entry with the opposite of the truth: 0 -> 1 true but NaN is
    # a miss; the NaN self-links become false links at 0.5 + eps
    truth = graph([line(0, 10), line(10, 20)], lane_lane=np.array([[0, 1], [0, 0]]))
    pred = graph([line(0, 10), line(10, 20)], scores=[0.9, 0.8], lane_lane=np.full((2, 2), np.nan))
    # rows: L0 true {1}, predicted {0} (self): 0; L1 true {}, predicted {1}: 0; columns the
    # same: 0
    assert evaluate_frames([(truth, pred)]).top_ll == 0.0
    assert UNMATCHED_LINK > 0.5


def test_mismatched_shapes_are_refused_by_the_graph() -> None:
    with pytest.raises(ValueError, match="lane_lane"):
        graph([line(0, 10)], lane_lane=np.zeros((2, 2)))


def test_an_element_of_no_known_attribute_counts_for_no_class_but_links() -> None:
    # attribute 20 is none of the 13: DET_t has no class to judge (NaN), but the element is
    # matched (IoU 1) for the topology: lane row {E0}/{E0} 1, element column {L0}/{L0} 1
    truth = graph([line(0, 10)], boxes=BOXES[:1], attributes=(20,), lane_element=[[1.0]])
    pred = graph(
        [line(0, 10)],
        scores=[0.9],
        boxes=BOXES[:1],
        attributes=(20,),
        element_scores=(0.9,),
        lane_element=[[0.9]],
    )
    s = evaluate_frames([(truth, pred)])
    assert math.isnan(s.det_t) and s.det_t_ap == {} and s.top_lt == 1.0
