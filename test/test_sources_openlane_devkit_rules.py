"""OpenLane-V2 scored as the official pipeline does (issue 39 items 1-3), on released-shaped
files: the ground truth's 201-point lanes thinned to every 20th point before matching (the
devkit's val/test ``collect(..., point_interval=20)``), traffic-element predictions in the
devkit baseline's format (no ``category``), confidences outside [0, 1] (ranked, as the
devkit uses them) and JSON booleans in predicted topology (numpy reads them as 1 and 0).

Figures worked out by hand here; ``test_sources_openlane_devkit_parity.py`` holds the
devkit's own numbers for data shaped like the released files.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from writers.openlane_segments import (
    LANES,
    RELEASED_POINTS,
    predicted_annotation,
    released_points,
    scored_points,
    write_openlane_predictions,
    write_openlane_segment,
)

from ads_rca.problems import ProblemLog
from ads_rca.sources.formats import SourceOptions
from ads_rca.sources.openlane.annotation import lane_graph
from ads_rca.sources.openlane.reader import read_openlane_segment
from ads_rca.sources.openlane.scores import GT_POINT_INTERVAL, match_frame, score_frames


def segment_scores(tmp_path: Path, result: dict[str, Any]) -> Any:
    """Every frame of the writer's segment given ``result``: the pooled figures, with the
    reader's problems."""
    segment = write_openlane_segment(tmp_path / "data", frames=3)
    folder = write_openlane_predictions(tmp_path / "pred", segment)
    for path in folder.glob("*.json"):
        path.write_text(json.dumps({"predictions": result}))
    log = read_openlane_segment(segment, source=SourceOptions(predictions=str(folder)))
    pairs = [(log.lanes[ts], log.lanes_predicted[ts]) for ts in log.frames]
    return score_frames(pairs, devkit_empty=True), log


def test_the_ground_truth_is_thinned_as_the_official_evaluation_collects_it() -> None:
    """A released lane of 201 points is scored on points 0, 20, ..., 200. A prediction of
    those 11 points matches at every threshold; scored against all 201 (as before) it is
    1 m away (halfway between two of its points) and misses at 1 m."""
    truth = released_points(LANES["A"])
    assert len(truth) == RELEASED_POINTS and GT_POINT_INTERVAL == 20
    problems = ProblemLog()
    gt = lane_graph({"lane_centerline": [{"id": 1, "points": truth}]}, "gt", "", problems, 0, False)
    prediction = {
        "lane_centerline": [{"id": 1, "points": scored_points(LANES["A"]), "confidence": 1}]
    }
    pred = lane_graph(prediction, "pred", "", problems, 0, True)
    assert scored_points(LANES["A"]) == truth[::20] and len(truth[::20]) == 11
    official = match_frame(gt, pred)
    assert official.lane_tp.tolist() == [[True], [True], [True]]
    as_given = match_frame(gt, pred, point_interval=1)
    assert as_given.lane_tp.tolist() == [[False], [True], [True]]
    assert score_frames([(gt, pred)]).det_l == 1.0
    with pytest.raises(ValueError, match="point_interval"):
        match_frame(gt, pred, point_interval=0)


def test_a_perfect_model_of_released_files_scores_one(tmp_path: Path) -> None:
    scores, log = segment_scores(tmp_path, predicted_annotation("perfect"))
    assert (scores.det_l, scores.det_t, scores.top_ll, scores.top_lt, scores.ols) == (1, 1, 1, 1, 1)
    assert [len(lane) for lane in log.lanes[log.frames[0]].lanes] == [201, 201, 201]


def test_elements_in_the_devkit_baseline_format_are_scored(tmp_path: Path) -> None:
    """``{id, attribute, points, confidence}``, no category (the baseline's output), and the
    tutorial's category 0: scored as the devkit does; another category is kept, reported."""
    result = predicted_annotation("perfect")
    for element in result["traffic_element"]:
        del element["category"]
    scores, log = segment_scores(tmp_path, result)
    assert scores.det_t == 1.0 and scores.ols == 1.0
    assert log.lanes_predicted[log.frames[0]].element_category.tolist() == [0, 0]
    assert not [p for p in map(str, log.problems) if "category" in p]
    result["traffic_element"][0]["category"] = 0
    result["traffic_element"][1]["category"] = 7
    scores, log = segment_scores(tmp_path / "again", result)
    assert scores.det_t == 1.0
    found = [p for p in map(str, log.problems) if "category" in p]
    assert found and all("7 is not 0, 1 or 2" in p and "read as unspecified" in p for p in found)


def test_confidences_outside_zero_to_one_rank_as_the_devkit_ranks_them(tmp_path: Path) -> None:
    """Logits: lane B predicted 1.5 m off at the highest score (4.0) ranks first and misses
    at 1 m, as it would at 0.99; every confidence in [0, 1] gives the same figures."""
    logits = predicted_annotation("perfect")
    for lane, score in zip(logits["lane_centerline"], (-2.0, 4.0, 0.5), strict=True):
        lane["confidence"] = score
    logits["lane_centerline"][1]["points"] = [
        [x, y + 1.5, z] for x, y, z in scored_points(LANES["B"])
    ]
    probabilities = json.loads(json.dumps(logits))
    for lane, score in zip(probabilities["lane_centerline"], (0.1, 0.99, 0.6), strict=True):
        lane["confidence"] = score
    from_logits, log = segment_scores(tmp_path / "logits", logits)
    from_probabilities, _ = segment_scores(tmp_path / "p", probabilities)
    assert from_logits.det_l == from_probabilities.det_l < 1.0
    assert from_logits.det_l_ap == from_probabilities.det_l_ap
    assert not [p for p in map(str, log.problems) if "confidence" in p]
    assert log.lanes_predicted[log.frames[0]].lane_scores.tolist() == [-2.0, 4.0, 0.5]


def test_boolean_and_unbounded_link_confidences_are_read_as_the_devkit_reads_them(
    tmp_path: Path,
) -> None:
    """``true``/``false`` links are 1 and 0 (they read as 0 before: TOP_ll 0); confidences
    past 1 are kept (not clipped), so they rank as given."""
    booleans = predicted_annotation("perfect")
    booleans["topology_lclc"] = [[bool(v > 0.5) for v in row] for row in booleans["topology_lclc"]]
    booleans["topology_lcte"] = [[bool(v > 0.5) for v in row] for row in booleans["topology_lcte"]]
    scores, log = segment_scores(tmp_path / "bool", booleans)
    graph = log.lanes_predicted[log.frames[0]]
    assert graph.lane_lane.tolist() == [[0, 0, 1], [0, 0, 0], [0, 0, 0]]
    assert scores.top_ll == 1.0 and scores.top_lt == 1.0
    assert not [p for p in map(str, log.problems) if "topology" in p]
    unbounded = predicted_annotation("perfect")
    unbounded["topology_lclc"] = [
        [7.5 if v > 0.5 else -3.0 for v in row] for row in unbounded["topology_lclc"]
    ]
    scores, log = segment_scores(tmp_path / "logit", unbounded)
    assert np.asarray(log.lanes_predicted[log.frames[0]].lane_lane).max() == 7.5
    assert scores.top_ll == 1.0
