"""The synthesiser's noise level K: K = 1 is the default to the byte, K = 10 scales
perception noise tenfold and adds a drifting localisation error that only the stack's own
records carry, and ``ads-rca synth --noise`` / ``bench/accuracy.py --noise`` expose it."""

from __future__ import annotations

import filecmp
import json
import subprocess
import sys
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from ads_rca.cli import main
from ads_rca.model import RunLog
from ads_rca.sources.log.writer import write_run_log
from ads_rca.synth import Noise, SynthesisError, SynthesisSummary, synthesise, synthesise_run
from ads_rca.synth.geometry import FloatArray, to_world

REPO = Path(__file__).resolve().parent.parent
SCENARIO, FAULT, SEED = "cut_in", "planning", 3


@cache
def _run(noise: float | Noise) -> tuple[RunLog, SynthesisSummary]:
    return synthesise_run(SCENARIO, FAULT, SEED, noise)


def _same_tree(a: Path, b: Path) -> bool:
    cmp = filecmp.dircmp(a, b)
    if cmp.left_only or cmp.right_only or cmp.funny_files:
        return False
    _, mismatch, errors = filecmp.cmpfiles(a, b, cmp.common_files, shallow=False)
    return not mismatch and not errors and all(_same_tree(a / d, b / d) for d in cmp.common_dirs)


def _ego_error(log: RunLog, ego: str) -> FloatArray:
    """Logged pose minus the ego's ground-truth actor entry, per frame (frames, 2)."""
    rows = []
    for ts in log.frames:
        actors = log.actors[ts]
        row = actors.ids.index(ego)
        rows.append(log.pose[ts].xy - actors.location[row, :2])
    return np.array(rows)


def _track_errors(log: RunLog, ego: str, low: float = 15.0, high: float = 25.0) -> FloatArray:
    """Track position (localisation error removed) minus the nearest actor's, for actors
    ``low``..``high`` m from the ego (the nearest within 3 m: the tracker's gate)."""
    localisation = _ego_error(log, ego)
    errors = []
    for k, ts in enumerate(log.frames):
        actors = log.actors[ts]
        row = actors.ids.index(ego)
        others = np.delete(actors.location[:, :2], row, axis=0)
        for location in log.tracks_3d[ts].location[:, :2] - localisation[k]:
            gap = np.hypot(*(others - location).T)
            nearest = int(np.argmin(gap))
            distance = float(np.hypot(*(others[nearest] - actors.location[row, :2])))
            if low <= distance <= high and gap[nearest] < 3.0:
                errors.append(location - others[nearest])
    return np.array(errors)


def _box_jitter(log: RunLog) -> FloatArray:
    """Each detected box's corner error as a fraction of its (nearest) ground-truth box."""
    errors = []
    for ts in log.frames:
        gt = log.bboxes_gt[ts].corners
        if not len(gt):
            continue
        for corners in log.bboxes[ts].corners:
            nearest = int(np.argmin(np.abs(gt - corners).sum(axis=1)))
            box = gt[nearest]
            size = np.array([box[2] - box[0], box[3] - box[1]])
            errors.append((corners - box) / np.concatenate([size, size]))
    return np.array(errors)


def test_level_one_writes_the_default_bytes(tmp_path: Path) -> None:
    default = write_run_log(synthesise(SCENARIO, FAULT, SEED), tmp_path / "default")
    level_one = write_run_log(synthesise(SCENARIO, FAULT, SEED, 1.0), tmp_path / "one")
    assert _same_tree(default, level_one)
    assert "noise" not in json.loads((level_one / "metadata.json").read_text())["synthesis"]


def test_level_ten_localisation_drifts_and_ground_truth_keeps_none() -> None:
    log, summary = _run(10.0)
    error = _ego_error(log, summary["ego_id"])
    std = error.std(axis=0)
    assert np.all((std >= 0.12) & (std <= 0.5)), std
    assert np.all(np.abs(np.diff(error, axis=0)).max(axis=0) > 0.0)  # it drifts
    assert summary["noise"] == 10.0
    # At K = 1 the pose is the ego's actor entry (which is stored as float32).
    log_1, summary_1 = _run(1.0)
    for ts in log_1.frames:
        actors = log_1.actors[ts]
        row = actors.ids.index(summary_1["ego_id"])
        pose = log_1.pose[ts].xy.astype(np.float32).astype(np.float64)
        assert np.array_equal(pose, actors.location[row, :2])


def test_level_ten_scales_perceived_positions_and_box_jitter_tenfold() -> None:
    log_1, summary_1 = _run(1.0)
    log_10, summary_10 = _run(10.0)
    tracks_1 = _track_errors(log_1, summary_1["ego_id"])
    tracks_10 = _track_errors(log_10, summary_10["ego_id"])
    assert len(tracks_1) > 20 and len(tracks_10) > 20
    assert 5.0 < tracks_10.std() / tracks_1.std() < 20.0
    assert 5.0 < _box_jitter(log_10).std() / _box_jitter(log_1).std() < 20.0


def test_localisation_error_moves_only_the_stacks_own_records() -> None:
    """The same K = 10 run with and without localisation error: the loop is the same, and
    exactly the pose, plan, 3-D objects and the frame of the ground-truth predictions move."""
    on, _ = _run(10.0)
    off, _ = _run(Noise(10.0, localisation=False))
    assert on.frames == off.frames
    for ts in on.frames:
        shift = on.pose[ts].xy - off.pose[ts].xy
        assert np.hypot(*shift) > 0.0
        assert np.array_equal(on.actors[ts].location, off.actors[ts].location)
        assert np.array_equal(on.bboxes[ts].corners, off.bboxes[ts].corners)
        assert np.array_equal(on.bboxes_gt[ts].corners, off.bboxes_gt[ts].corners)
        np.testing.assert_allclose(on.waypoints[ts].xy, off.waypoints[ts].xy + shift, atol=1e-9)
        for kind in ("tracks_3d", "detections_3d"):
            a, b = getattr(on, kind)[ts], getattr(off, kind)[ts]
            assert a.ids == b.ids
            np.testing.assert_allclose(a.location[:, :2], b.location[:, :2] + shift, atol=1e-9)
        # Raw predictions: the same body-frame offsets (positions and pose shift together).
        assert on.predictions[ts].keys() == off.predictions[ts].keys()
        for track_id, track in on.predictions[ts].items():
            assert np.array_equal(track.offsets, off.predictions[ts][track_id].offsets)
        # Ground-truth predictions mapped back with the logged pose land on the truth (the
        # run without localisation error logs the true pose).
        for actor_id, track in on.predictions_with_perception[ts].items():
            truth = off.predictions_with_perception[ts][actor_id].offsets[:, :2]
            yaw = np.radians(on.pose[ts].yaw)
            np.testing.assert_allclose(
                to_world(track.offsets[:, :2], on.pose[ts].xy, yaw),
                to_world(truth, off.pose[ts].xy, yaw),
                atol=1e-9,
            )


@pytest.mark.parametrize("value", ["-1", "nan", "inf", "21", "abc"])
def test_cli_refuses_a_bad_noise_level_in_one_line(
    value: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    assert main(["synth", str(out), "--scenario", "cut_in", "--noise", value]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and "--noise" in lines[0], captured.err
    assert "Traceback" not in captured.err and not out.exists()


def test_api_refuses_a_bad_noise_level() -> None:
    with pytest.raises(SynthesisError, match="noise"):
        synthesise(SCENARIO, FAULT, SEED, float("nan"))


def test_cli_writes_the_noise_level(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    argv = ["synth", str(out), "--scenario", SCENARIO, "--fault", FAULT, "--seed", str(SEED)]
    assert main([*argv, "--noise", "10"]) == 0
    capsys.readouterr()
    synthesis = json.loads((out / "metadata.json").read_text())["synthesis"]
    assert synthesis["noise"] == 10.0


def test_bench_prints_accuracy_per_fault_and_noise_level() -> None:
    argv = [sys.executable, str(REPO / "bench" / "accuracy.py"), "1", "--scenarios", "cut_in"]
    argv += ["--faults", "none,planning", "--noise", "1,10"]
    result = subprocess.run(argv, capture_output=True, text=True, check=True, cwd=REPO)
    lines = result.stdout.splitlines()
    assert "=== noise level 1 ===" in lines and "=== noise level 10 ===" in lines
    assert lines.count("skipped: 0") == 2
    table = lines.index("fault kind × noise level (accuracy)")
    assert lines[table + 1].split() == ["fault", "\\", "noise", "1", "10"]
    assert [line.split()[0] for line in lines[table + 2 :]] == [
        "none",
        "planning",
        "overall",
        "skipped",
    ]
    assert lines[-1].split() == ["skipped", "0", "0"]
    assert sum(line.startswith("injected \\ primary") for line in lines) == 2
