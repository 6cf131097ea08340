"""The synthesiser: deterministic, complete logs, crashes only with a fault, faults confined."""

from __future__ import annotations

import filecmp
import json
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from ads_rca.model import FOLDERS, RunLog
from ads_rca.sources.log.writer import write_run_log
from ads_rca.synth import (
    FAULTS,
    SCENARIOS,
    SynthesisError,
    SynthesisSummary,
    synthesise,
    synthesise_run,
)
from ads_rca.synth.camera import CX, project_boxes
from ads_rca.synth.geometry import sat_gap
from ads_rca.synth.scenarios import BUILDERS

CRASH_SCENARIOS = [s for s in SCENARIOS if s != "cruise"]
SEED = 5


@cache
def _run(scenario: str, fault: str) -> tuple[RunLog, SynthesisSummary]:
    return synthesise_run(scenario, fault, SEED)


def _dir_equal(a: Path, b: Path) -> bool:
    cmp = filecmp.dircmp(a, b)
    if cmp.left_only or cmp.right_only or cmp.funny_files:
        return False
    _, mismatch, errors = filecmp.cmpfiles(a, b, cmp.common_files, shallow=False)
    return not mismatch and not errors and all(_dir_equal(a / d, b / d) for d in cmp.common_dirs)


def test_same_seed_writes_byte_identical_folders(tmp_path: Path) -> None:
    first = write_run_log(synthesise("lead_braking", "controller", SEED), tmp_path / "a")
    second = write_run_log(synthesise("lead_braking", "controller", SEED), tmp_path / "b")
    assert _dir_equal(first, second)


def test_different_seeds_give_different_scenes() -> None:
    a = BUILDERS["cut_in"](np.random.default_rng(1), 100, 3)
    b = BUILDERS["cut_in"](np.random.default_rng(2), 100, 3)
    assert not np.allclose(a.path.xy[0], b.path.xy[0])
    assert a.desired_speed != b.desired_speed


@pytest.mark.parametrize("scenario", CRASH_SCENARIOS)
@pytest.mark.parametrize("fault", FAULTS)
def test_every_scenario_and_fault_writes_a_complete_running_log(
    scenario: str, fault: str, tmp_path: Path
) -> None:
    log, summary = _run(scenario, fault)
    root = write_run_log(log, tmp_path / "log")
    meta = json.loads((root / "metadata.json").read_text())
    assert meta["timesteps_per_frame"] == 50
    assert meta["ego_config"]["camera"]["camera_loc"] == [1.3, 0.0, 1.8]
    total = meta["total_frames"]
    for folder in FOLDERS:
        names = sorted(p.name for p in (root / folder).iterdir())
        assert len(names) == total, folder
    pose = json.loads((root / "pose" / "pose-50.json").read_text())
    assert all(isinstance(v, str) for v in pose.values())
    assert pose["timestamp"] == "50"
    float(pose["yaw"])
    actors = json.loads((root / "actors" / "actors-50.json").read_text())
    first_id, first = next(iter(actors.items()))
    assert first_id == summary["ego_id"]
    assert abs(first["location"]["x"] - float(pose["x"])) < 0.05
    assert abs(first["location"]["y"] - float(pose["y"])) < 0.05
    plan = json.loads((root / "waypoint" / "waypoints-50.json").read_text())
    assert abs(plan["0"]["x"] - float(pose["x"])) < 1e-6
    gt = json.loads((root / "bboxes_gt" / "bboxes_gt-50.json").read_text())
    assert {str(b["id"]) for b in gt} <= set(actors)


@pytest.mark.parametrize("scenario", CRASH_SCENARIOS)
@pytest.mark.parametrize("fault", FAULTS[1:])
def test_faulty_log_ends_at_a_collision_with_the_partner_and_its_twin_does_not(
    scenario: str, fault: str
) -> None:
    log, summary = _run(scenario, fault)
    twin, _ = _run(scenario, "none")
    collision = log.metadata.collision_frame
    assert collision > summary["fault_onset_frame"] > 0
    assert log.metadata.total_frames == collision
    assert max(log.frames) == collision * 50
    assert twin.metadata.collision_frame == -1
    assert _ego_partner_gap(log, collision, summary) < 0.0
    assert _ego_partner_gap(log, collision - 1, summary) >= 0.0


def _ego_partner_gap(log: RunLog, frame: int, summary: SynthesisSummary) -> float:
    ts = frame * 50
    actors, pose = log.actors[ts], log.pose[ts]
    ego = log.actor_extents[summary["ego_id"]]
    partner = summary["partner_id"]
    assert partner is not None  # every crash scenario has one
    row = actors.index[partner]
    return float(
        sat_gap(
            pose.xy,
            np.radians(pose.yaw),
            ego[:2],
            actors.location[row, :2],
            np.radians(actors.rotation[row, 2]),
            actors.extent[row, :2],
        )
    )


def _same_boxes(a: RunLog, b: RunLog, ts: int) -> bool:
    return a.bboxes[ts].ids == b.bboxes[ts].ids and np.array_equal(
        a.bboxes[ts].corners, b.bboxes[ts].corners
    )


def _same_predictions(a: RunLog, b: RunLog, ts: int) -> bool:
    pa, pb = a.predictions[ts], b.predictions[ts]
    return list(pa) == list(pb) and all(np.array_equal(pa[k].offsets, pb[k].offsets) for k in pa)


@pytest.mark.parametrize("scenario", CRASH_SCENARIOS)
def test_a_control_fault_leaves_perception_prediction_and_planning_untouched_until_onset(
    scenario: str,
) -> None:
    log, summary = _run(scenario, "controller")
    twin, _ = _run(scenario, "none")
    onset = summary["fault_onset_frame"]
    for frame in range(1, onset + 1):
        ts = frame * 50
        assert _same_boxes(log, twin, ts)
        assert _same_predictions(log, twin, ts)
        assert np.array_equal(log.waypoints[ts].xy, twin.waypoints[ts].xy)
    # The first pose after the onset is where control departs from the plan.
    ts = (onset + 1) * 50
    assert log.pose[ts].speed >= twin.pose[ts].speed


@pytest.mark.parametrize("scenario", CRASH_SCENARIOS)
def test_a_perception_fault_drops_the_partner_from_detections_only(scenario: str) -> None:
    log, summary = _run(scenario, "perception")
    twin, _ = _run(scenario, "none")
    onset = summary["fault_onset_frame"]
    for frame in range(1, onset):
        assert _same_boxes(log, twin, frame * 50)
    ts = (onset + 1) * 50
    assert len(log.bboxes[ts]) < len(twin.bboxes[ts])
    assert list(log.predictions_with_perception[onset * 50]) == list(
        twin.predictions_with_perception[onset * 50]
    )


def test_a_prediction_fault_changes_the_partner_in_both_prediction_files() -> None:
    log, summary = _run("lead_braking", "prediction")
    twin, _ = _run("lead_braking", "none")
    ts = (summary["fault_onset_frame"] + 2) * 50
    partner = summary["partner_id"]
    assert partner is not None
    assert _same_boxes(log, twin, ts)
    assert not np.allclose(
        log.predictions_with_perception[ts][partner].offsets,
        twin.predictions_with_perception[ts][partner].offsets,
    )
    changed = [k for k in log.predictions[ts] if k in twin.predictions[ts]]
    assert any(
        not np.allclose(log.predictions[ts][k].offsets, twin.predictions[ts][k].offsets)
        for k in changed
    )


def test_an_actor_straight_ahead_projects_near_the_image_centre_column() -> None:
    boxes, in_view = project_boxes(
        np.array([10.0, 5.0]),
        np.radians(30.0),
        (1.3, 0.0, 1.8),
        np.array([[10.0 + 20 * np.cos(np.radians(30.0)), 5.0 + 20 * np.sin(np.radians(30.0))]]),
        np.array([np.radians(30.0)]),
        np.array([[2.4, 1.0, 0.75]]),
    )
    assert in_view[0]
    centre = 0.5 * (boxes[0, 0] + boxes[0, 2])
    assert abs(centre - CX) < 2.0
    assert boxes[0, 3] > 539.5  # its bottom is below the horizon (the camera is above it)


def test_an_actor_to_the_right_projects_right_of_centre_and_one_behind_is_not_in_view() -> None:
    boxes, in_view = project_boxes(
        np.zeros(2),
        0.0,
        (1.3, 0.0, 1.8),
        np.array([[20.0, 4.0], [-20.0, 0.0]]),
        np.zeros(2),
        np.array([[2.4, 1.0, 0.75], [2.4, 1.0, 0.75]]),
    )
    assert in_view[0] and not in_view[1]
    assert boxes[0, 0] > CX


def test_cruise_is_long_and_collision_free() -> None:
    log = synthesise("cruise", "none", 1, frames=300, actors=30)
    assert log.metadata.collision_frame == -1
    assert log.metadata.total_frames == 300
    assert len(log.actors[50]) == 31


def test_bad_arguments_raise_a_synthesis_error() -> None:
    with pytest.raises(SynthesisError):
        synthesise("cruise", "controller", 1)
    with pytest.raises(SynthesisError):
        synthesise("no_such_scenario", "none", 1)
