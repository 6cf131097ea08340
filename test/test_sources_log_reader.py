"""The running-log reader: the spec's reading rules, and every kind of bad input.

Each bad-input test checks the reported problem (file, field, action) AND that the rest of
the log still loads.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from ads_rca.errors import InputError
from ads_rca.model import FOLDERS
from ads_rca.problems import Problem
from ads_rca.sources.log import reader as log_reader
from ads_rca.sources.log.reader import read_run_log, timestamp_of
from ads_rca.sources.log.writer import write_run_log

TPF = 50


def _write(path: Path, document: Any) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(document))


def make_log(root: Path, frames: int = 5) -> Path:
    """A small valid log: ego '10' driving along x, one car '20' ahead, frames 1..frames."""
    _write(
        root / "metadata.json",
        {
            "timesteps_per_frame": TPF,
            "ego_config": {"camera": {"camera_loc": [1.3, 0.0, 1.8]}},
            "collision_frame": -1,
            "total_frames": frames,
        },
    )
    for f in range(1, frames + 1):
        ts = f * TPF
        ego_x = 0.5 * f
        _write(
            root / f"pose/pose-{ts}.json",
            {
                "x": str(ego_x),
                "y": "2.0",
                "z": "0.0",
                "pitch": "0",
                "yaw": "0.5",
                "roll": "0",
                "timestamp": str(ts),
                "speed": "10.0",
            },
        )
        actor = {
            "extent": {"x": 2.4, "y": 1.0, "z": 0.75},
            "rotation": {"pitch": 0.0, "roll": 0.0, "yaw": 0.5},
        }
        _write(
            root / f"actors/actors-{ts}.json",
            {
                "10": {**actor, "location": {"x": ego_x, "y": 2.0, "z": 0.0}},
                "20": {**actor, "location": {"x": ego_x + 20, "y": 2.0, "z": 0.0}},
            },
        )
        box = {"id": 20, "bounding_box": [[900, 500], [1020, 580]]}
        _write(root / f"bboxes_gt/bboxes_gt-{ts}.json", [box])
        _write(root / f"bboxes/bboxes-{ts}.json", [{**box, "id": 0, "label": "car"}])
        track = {str(k): {"x": 20.0 - 0.1 * k, "y": 0.0, "z": 0.0} for k in range(10)}
        _write(root / f"predictions/predictions-{ts}.json", {"7": track})
        _write(root / f"predictions_with_perception/predictions-{ts}.json", {"20": track})
        plan = {str(i): {"x": ego_x + 0.5 * i, "y": 2.0, "speed": 10.0} for i in range(10)}
        _write(root / f"waypoint/waypoints-{ts}.json", plan)
    return root


def problems_about(problems: Any, file_part: str) -> list[Problem]:
    return [p for p in problems if file_part in p.file]


@pytest.fixture
def log_dir(tmp_path: Path) -> Path:
    return make_log(tmp_path / "log")


def test_valid_log_loads_without_problems(log_dir: Path) -> None:
    log = read_run_log(log_dir)
    assert list(log.problems) == []
    assert log.frames == (50, 100, 150, 200, 250)
    assert log.pose[100].x == 1.0 and log.pose[100].yaw == 0.5
    assert log.actors[50].ids == ("10", "20")
    np.testing.assert_array_equal(log.actors[50].extent[1], [2.4, 1.0, 0.75])
    assert log.bboxes[50].ids == ("0",) and log.bboxes[50].extras == ({"label": "car"},)
    assert log.bboxes_gt[50].corners.tolist() == [[900, 500, 1020, 580]]
    assert log.predictions[50]["7"].keys[:3] == ("0", "1", "2")
    assert log.waypoints[50].point("3") is not None
    assert log.metadata.camera_loc == (1.3, 0.0, 1.8)


def test_written_log_reads_back_identically(log_dir: Path, tmp_path: Path) -> None:
    log = read_run_log(log_dir)
    again = read_run_log(write_run_log(log, tmp_path / "copy"))
    assert again.frames == log.frames and list(again.problems) == []
    for ts in log.frames:
        assert again.pose[ts] == log.pose[ts]
        np.testing.assert_array_equal(again.actors[ts].location, log.actors[ts].location)
        assert again.bboxes[ts].extras == log.bboxes[ts].extras
        np.testing.assert_array_equal(again.waypoints[ts].xy, log.waypoints[ts].xy)
        assert again.predictions[ts]["7"].keys == log.predictions[ts]["7"].keys


@pytest.mark.parametrize(
    ("name", "expected"),
    [
        ("actors-50.json", 50),
        ("actors-050.json", 50),
        ("actors-3800.bak.json", 3800),
        ("any-prefix-100.json", 100),
        ("actors.json", None),
        ("actors-12a.json", None),
        ("actors-.json", None),
    ],
)
def test_timestamp_is_the_integer_after_the_last_dash(name: str, expected: int | None) -> None:
    assert timestamp_of(name) == expected


def test_dot_files_and_other_extensions_are_ignored_and_bad_names_reported(log_dir: Path) -> None:
    (log_dir / "actors/.hidden-300.json").write_text("{}")
    (log_dir / "actors/actors-300.txt").write_text("{}")
    (log_dir / "actors/actors.json").write_text("{}")
    log = read_run_log(log_dir)
    assert 300 not in log.frames
    [problem] = log.problems
    assert problem.file == "actors/actors.json" and problem.field == "file name"


def test_missing_log_folder_is_an_input_error(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="no such log folder"):
        read_run_log(tmp_path / "nope")


def test_cli_reports_missing_folder_in_one_line_without_traceback(tmp_path: Path) -> None:
    result = subprocess.run(
        [sys.executable, "-m", "ads_rca.cli", "inspect", str(tmp_path / "nope")],
        capture_output=True,
        text=True,
        check=False,
    )
    assert result.returncode == 2
    assert result.stderr.strip().count("\n") == 0
    assert "no such log folder" in result.stderr and "Traceback" not in result.stderr


def test_missing_subfolder_is_reported_once_and_the_rest_loads(log_dir: Path) -> None:
    for file in (log_dir / "bboxes").iterdir():
        file.unlink()
    (log_dir / "bboxes").rmdir()
    log = read_run_log(log_dir)
    [problem] = log.problems
    assert problem.file == "bboxes/" and problem.issue == "folder missing"
    assert len(log.frames) == 5 and len(log.bboxes_gt) == 5 and log.bboxes == {}


def test_missing_file_for_a_frame_is_reported_with_its_timestamp(log_dir: Path) -> None:
    (log_dir / "bboxes_gt/bboxes_gt-100.json").unlink()
    (log_dir / "bboxes_gt/bboxes_gt-150.json").unlink()
    log = read_run_log(log_dir)
    [problem] = log.problems
    assert problem.file == "bboxes_gt/" and "100-150 ms (2 frames)" in problem.issue
    assert sorted(log.bboxes_gt) == [50, 200, 250]


@pytest.mark.parametrize("content", ['{"x": "1.0", "y": ', "", "not json at all", "[1, 2"])
def test_truncated_or_invalid_json_skips_that_file_only(log_dir: Path, content: str) -> None:
    (log_dir / "pose/pose-150.json").write_text(content)
    log = read_run_log(log_dir)
    [problem] = log.problems
    assert problem.file == "pose/pose-150.json" and problem.action == "file skipped"
    assert "JSON" in problem.issue or "empty" in problem.issue
    assert sorted(log.pose) == [50, 100, 200, 250] and len(log.frames) == 5


def test_string_that_is_not_a_number_reads_as_nan_and_names_the_field(log_dir: Path) -> None:
    pose = json.loads((log_dir / "pose/pose-100.json").read_text())
    pose["yaw"] = "north"
    (log_dir / "pose/pose-100.json").write_text(json.dumps(pose))
    actors = json.loads((log_dir / "actors/actors-150.json").read_text())
    actors["20"]["location"]["x"] = "far"
    (log_dir / "actors/actors-150.json").write_text(json.dumps(actors))
    log = read_run_log(log_dir)
    by_file = {p.file: p for p in log.problems}
    assert by_file["pose/pose-100.json"].field == "yaw"
    assert "'north' is not a number" in by_file["pose/pose-100.json"].issue
    assert by_file["actors/actors-150.json"].field == "20.location.x"
    assert math.isnan(log.pose[100].yaw) and log.pose[100].x == 1.0
    assert math.isnan(log.actors[150].location[1, 0]) and log.actors[150].location[0, 0] == 1.5


def test_a_list_in_place_of_every_number_is_reported_not_read_as_more_rows(
    log_dir: Path,
) -> None:
    # Every number of a file a pair [a, b]: the whole-file array is then one dimension
    # deeper but still a multiple of its width (2 actors x 9 numbers x 2 = 36 = 4 rows of
    # 9), and used to be read as twice the rows, ids and numbers out of step.
    actors = json.loads((log_dir / "actors/actors-100.json").read_text())
    for actor in actors.values():
        for part in ("location", "rotation", "extent"):
            actor[part] = {axis: [1.0, 2.0] for axis in actor[part]}
    (log_dir / "actors/actors-100.json").write_text(json.dumps(actors))
    track = {str(k): {"x": [1.0, 2.0], "y": [3.0, 4.0], "z": [5.0, 6.0]} for k in range(3)}
    _write(log_dir / "predictions/predictions-100.json", {"7": track})
    plan = {str(i): {"x": [1.0, 2.0], "y": [3.0, 4.0], "speed": [5.0, 6.0]} for i in range(2)}
    _write(log_dir / "waypoint/waypoints-100.json", plan)
    log = read_run_log(log_dir)
    assert log.actors[100].location.shape == (2, 3)
    assert np.isnan(log.actors[100].location).all() and np.isnan(log.actors[100].extent).all()
    assert log.predictions[100]["7"].offsets.shape == (3, 3)
    assert np.isnan(log.predictions[100]["7"].offsets).all()
    assert log.waypoints[100].xy.shape == (2, 2) and np.isnan(log.waypoints[100].speed).all()
    issues = {(p.file, p.field): p.issue for p in log.problems}
    # 2 actors x 9 fields, 3 steps x 3 fields, 2 points x 3 fields: 18 + 9 + 6 reports.
    assert len(issues) == 33
    assert issues[("actors/actors-100.json", "20.rotation.yaw")] == "[1.0, 2.0] is not a number"
    assert issues[("predictions/predictions-100.json", "7.2.z")] == "[5.0, 6.0] is not a number"
    assert issues[("waypoint/waypoints-100.json", "1.speed")] == "[5.0, 6.0] is not a number"


def test_numbers_given_as_strings_are_accepted_everywhere(log_dir: Path) -> None:
    plan = json.loads((log_dir / "waypoint/waypoints-50.json").read_text())
    plan["1"]["x"] = "0.75"
    (log_dir / "waypoint/waypoints-50.json").write_text(json.dumps(plan))
    log = read_run_log(log_dir)
    assert list(log.problems) == [] and log.waypoints[50].xy[1, 0] == 0.75


def test_nan_and_infinity_are_kept_and_reported(log_dir: Path) -> None:
    text = (log_dir / "predictions_with_perception/predictions-100.json").read_text()
    text = text.replace('"x": 19.9', '"x": NaN', 1).replace('"y": 0.0', '"y": Infinity', 1)
    (log_dir / "predictions_with_perception/predictions-100.json").write_text(text)
    log = read_run_log(log_dir)
    fields = sorted(p.field for p in log.problems)
    assert fields == ["20.0.y", "20.1.x"]
    assert all(p.action == "value kept" and p.severity == "warning" for p in log.problems)
    offsets = log.predictions_with_perception[100]["20"].offsets
    assert math.isnan(offsets[1, 0]) and math.isinf(offsets[0, 1]) and offsets[2, 0] == 19.8


def test_duplicated_timestamps_keep_the_last_listed_file_and_analyse_twice(log_dir: Path) -> None:
    actors = json.loads((log_dir / "actors/actors-100.json").read_text())
    actors["20"]["location"]["x"] = 99.0
    (log_dir / "actors/actors-0100.json").write_text(json.dumps(actors))
    log = read_run_log(log_dir)
    assert log.frames == (50, 100, 100, 150, 200, 250)
    assert log.unique_frames == (50, 100, 150, 200, 250)
    listing = [n for n in os.listdir(log_dir / "actors") if timestamp_of(n) == 100]
    expected_x = 99.0 if listing[-1] == "actors-0100.json" else 20.0 + 1.0
    assert log.actors[100].location[1, 0] == expected_x
    [problem] = log.problems
    assert problem.field == "timestamp" and "analysed twice" in problem.action


def test_gap_in_timestamps_is_reported(log_dir: Path) -> None:
    for folder in FOLDERS:
        for file in (log_dir / folder).glob("*-150.json"):
            file.unlink()
    log = read_run_log(log_dir)
    [problem] = log.problems
    assert "gap: no frame between 100 and 200 ms (1 missing)" in problem.issue
    assert log.frames == (50, 100, 200, 250)


def test_id_that_appears_nowhere_else_is_reported(log_dir: Path) -> None:
    _write(
        log_dir / "bboxes_gt/bboxes_gt-100.json", [{"id": 404, "bounding_box": [[1, 2], [3, 4]]}]
    )
    log = read_run_log(log_dir)
    [problem] = log.problems
    assert (
        problem.file == "bboxes_gt/bboxes_gt-100.json" and "'404' is not an actor" in problem.issue
    )
    assert log.bboxes_gt[100].ids == ("404",)


@pytest.mark.parametrize("workers", [1, 2])
def test_unknown_ids_are_counted_frame_by_frame_when_frames_repeat_them(
    tmp_path: Path, workers: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The check remembers the unknown ids of each (box ids, actors) pair, as most frames
    repeat one: a frame with the same boxes but other actors is judged on its own."""
    log_dir = make_log(tmp_path / "log", frames=8)
    for f in range(1, 9):
        box = {"bounding_box": [[1, 2], [3, 4]]}
        _write(
            log_dir / f"bboxes_gt/bboxes_gt-{f * TPF}.json",
            [{**box, "id": "ghost"}, {**box, "id": 20}, {**box, "id": "ghost"}],
        )
    actors = json.loads((log_dir / "actors/actors-150.json").read_text())
    for ts in (150, 300):  # the car '20' is not in these two frames
        _write(log_dir / f"actors/actors-{ts}.json", {"10": actors["10"]})
    monkeypatch.setattr(log_reader, "PARALLEL_MIN_FILES", 1)
    issues = [
        (p.file, p.issue)
        for p in read_run_log(log_dir, workers=workers).problems
        if "is not an actor" in p.issue
    ]
    assert issues == [
        ("bboxes_gt/bboxes_gt-50.json", "id 'ghost' is not an actor in the same frame (8 frames)"),
        ("bboxes_gt/bboxes_gt-150.json", "id '20' is not an actor in the same frame (2 frames)"),
        (
            "predictions_with_perception/predictions-150.json",
            "id '20' is not an actor in the same frame (2 frames)",
        ),
    ]


def test_unknown_ids_are_reported_in_file_order_whatever_the_hash_seed(log_dir: Path) -> None:
    ids = [f"ghost_{i}" for i in range(12)]
    _write(
        log_dir / "bboxes_gt/bboxes_gt-100.json",
        [{"id": i, "bounding_box": [[1, 2], [3, 4]]} for i in ids],
    )
    script = (
        "import json, sys; from ads_rca.sources.log.reader import read_run_log; "
        "print(json.dumps([p.issue for p in read_run_log(sys.argv[1]).problems]))"
    )
    outputs = {
        subprocess.run(
            [sys.executable, "-c", script, str(log_dir)],
            env={**os.environ, "PYTHONHASHSEED": str(seed)},
            capture_output=True,
            text=True,
            check=True,
        ).stdout
        for seed in (0, 1, 2, 3)
    }
    assert len(outputs) == 1
    [issues] = [json.loads(text) for text in outputs]
    assert [i.split("'")[1] for i in issues] == ids


def test_empty_records_load_as_empty(log_dir: Path) -> None:
    _write(log_dir / "predictions/predictions-100.json", {})
    _write(log_dir / "predictions_with_perception/predictions-100.json", {"20": {}})
    _write(log_dir / "bboxes/bboxes-100.json", [])
    log = read_run_log(log_dir)
    assert list(log.problems) == []
    assert log.predictions[100] == {} and len(log.bboxes[100]) == 0
    assert log.predictions_with_perception[100]["20"].offsets.shape == (0, 3)


def test_empty_plan_is_reported(log_dir: Path) -> None:
    _write(log_dir / "waypoint/waypoints-200.json", {})
    log = read_run_log(log_dir)
    [problem] = log.problems
    assert problem.file == "waypoint/waypoints-200.json" and "empty plan" in problem.issue
    assert len(log.waypoints[200]) == 0 and len(log.waypoints[250]) == 10


@pytest.mark.parametrize(
    ("box", "field", "issue"),
    [
        ({"bounding_box": [[1, 2], [3, 4]]}, "[0].id", "missing"),
        ({"id": 1, "bounding_box": [[1, 2]]}, "[0].bounding_box", "needs exactly two points"),
        ({"id": 1, "bounding_box": [[1, 2], [3]]}, "[0].bounding_box", "a point is not [x, y]"),
    ],
)
def test_malformed_box_is_dropped(
    log_dir: Path, box: dict[str, Any], field: str, issue: str
) -> None:
    good = {"id": 5, "bounding_box": [[10, 20], [30, 40]]}
    _write(log_dir / "bboxes/bboxes-100.json", [box, good])
    log = read_run_log(log_dir)
    [problem] = log.problems
    assert (problem.field, problem.issue, problem.action) == (field, issue, "record dropped")
    assert log.bboxes[100].ids == ("5",)


def test_actor_without_extent_where_it_first_appears(log_dir: Path) -> None:
    actors = json.loads((log_dir / "actors/actors-50.json").read_text())
    del actors["20"]["extent"]
    (log_dir / "actors/actors-50.json").write_text(json.dumps(actors))
    log = read_run_log(log_dir)
    [problem] = log.problems
    assert problem.field == "20.extent" and problem.action == "used its next known extent"
    np.testing.assert_array_equal(log.actor_extents["20"], [2.4, 1.0, 0.75])


def test_actor_without_location_is_dropped(log_dir: Path) -> None:
    actors = json.loads((log_dir / "actors/actors-100.json").read_text())
    del actors["20"]["location"]
    (log_dir / "actors/actors-100.json").write_text(json.dumps(actors))
    log = read_run_log(log_dir)
    dropped, *consequences = log.problems
    assert (dropped.field, dropped.action) == ("20.location", "record dropped")
    assert log.actors[100].ids == ("10",) and log.actors[150].ids == ("10", "20")
    # The boxes and predictions that name the dropped actor in that frame are reported too.
    assert {p.file for p in consequences} == {
        "bboxes_gt/bboxes_gt-100.json",
        "predictions_with_perception/predictions-100.json",
    }


def test_wrong_document_type_skips_the_file(log_dir: Path) -> None:
    _write(log_dir / "predictions/predictions-100.json", [1, 2, 3])
    log = read_run_log(log_dir)
    [problem] = log.problems
    assert problem.action == "file skipped" and "expected an object" in problem.issue
    assert 100 not in log.predictions and 150 in log.predictions


def test_missing_metadata_uses_reported_defaults(log_dir: Path) -> None:
    (log_dir / "metadata.json").unlink()
    log = read_run_log(log_dir)
    [problem] = log.problems
    assert problem.file == "metadata.json" and problem.issue == "missing"
    assert (
        log.frame_ms == 50 and log.metadata.collision_frame == -1 and log.metadata.total_frames == 5
    )


def test_bad_metadata_fields_use_reported_defaults(log_dir: Path) -> None:
    _write(
        log_dir / "metadata.json",
        {"timesteps_per_frame": "50", "collision_frame": "soon", "total_frames": 5},
    )
    log = read_run_log(log_dir)
    fields = {p.field for p in log.problems}
    # "50" is used as 50 and reported; "soon" falls back to the default.
    assert fields == {"timesteps_per_frame", "collision_frame", "ego_config.camera.camera_loc"}
    assert log.frame_ms == 50 and log.metadata.collision_frame == -1


def test_cli_inspect_lists_problems_one_line_each(log_dir: Path) -> None:
    (log_dir / "pose/pose-150.json").write_text("{")
    _write(log_dir / "waypoint/waypoints-200.json", {})
    result = subprocess.run(
        [sys.executable, "-m", "ads_rca.cli", "inspect", str(log_dir)],
        capture_output=True,
        text=True,
        check=True,
    )
    assert "problems: 2" in result.stdout
    assert "error: pose/pose-150.json: invalid JSON" in result.stdout
    assert "Traceback" not in result.stdout + result.stderr
