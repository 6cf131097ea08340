"""Messages name what the input is, and metadata that disagrees with the data is a problem.

- A run that yields no frame is refused in one line naming what exists for that input: a
  bag read through a stack's profile names the profile and its actors input (never "no
  readable actors/ file", a log folder's words), a bag of our contract its frame markers
  and actors; ``diagnose`` and the player (so ``replay``) say the same.
- ``metadata.json``'s ``timesteps_per_frame`` that is not the actors timestamps' step, and
  a ``total_frames`` more than one frame from the last actors file's frame, are input
  problems naming the file and field; the value is kept and the run still diagnosed. The
  synthesiser's logs (consistent metadata) get none.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import pytest
from commandline import run_cli

from ads_rca.ros.launcher import ManagedProcess
from ads_rca.sources.log.reader import read_run_log
from ads_rca.sources.log.writer import write_run_log
from ads_rca.synth import synthesise
from ads_rca.synth.recording import write_recording

if TYPE_CHECKING:
    from conftest import RosEnv

#: A profile whose ground truth is on a topic the bag lacks: its frames (the actors input's
#: messages) never come.
EGO_ONLY = """\
profile: ego_only
reference: ego
inputs:
  ego: {topic: /carla/ego_vehicle/odometry, type: nav_msgs/msg/Odometry, frame: map}
  actors: {topic: /nowhere/objects, type: derived_object_msgs/msg/ObjectArray, frame: map}
metadata:
  camera_loc: [1.5, 0.0, 2.4]
"""
EGO_ONLY_REFUSAL = (
    "no frame to analyse: the frames are the ego_only profile's actors messages, and its "
    "actors input gave none (/nowhere/objects (derived_object_msgs/msg/ObjectArray), topic "
    "/nowhere/objects not in the bag)"
)


@pytest.fixture(scope="module")
def ego_only_bag(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A carla-autoware recording and a profile that reads only its ego odometry."""
    root = tmp_path_factory.mktemp("ego_only")
    write_recording(synthesise("lead_braking", "planning", 1), root / "bag", "carla-autoware")
    (root / "ego_only.yaml").write_text(EGO_ONLY, encoding="utf-8")
    return root / "bag", root / "ego_only.yaml"


def test_a_bag_read_through_a_profile_without_frames_names_its_actors_input(
    ego_only_bag: tuple[Path, Path],
) -> None:
    bag, profile = ego_only_bag
    done = run_cli("diagnose", str(bag), "--profile", str(profile))
    assert done.returncode == 2, done.stdout
    assert EGO_ONLY_REFUSAL in done.stderr and "actors/ file" not in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and "Traceback" not in done.stderr


def test_a_batch_row_names_the_profile_s_actors_input_too(ego_only_bag: tuple[Path, Path]) -> None:
    from ads_rca.batch.work import Job, run_job
    from ads_rca.params import make_params
    from ads_rca.sources.bag.options import BagOptions

    bag, profile = ego_only_bag
    options = BagOptions(str(profile))
    job = Job("run", str(bag), make_params("corrected"), 100.0, options, timeout=60.0)
    outcome = run_job(job)
    assert outcome.json is None
    assert EGO_ONLY_REFUSAL in outcome.row["error"] and "actors/ file" not in outcome.row["error"]


def test_a_contract_bag_without_frames_names_its_markers_and_actors(tmp_path: Path) -> None:
    folder = tmp_path / "log"
    folder.mkdir()
    (folder / "metadata.json").write_text('{"timesteps_per_frame": 50, "collision_frame": -1}')
    bag = tmp_path / "empty.mcap"
    assert run_cli("convert", str(folder), str(bag)).returncode == 0
    done = run_cli("diagnose", str(bag))
    assert done.returncode == 2
    assert (
        f"{bag}: no frame to analyse: the bag has no run/frame marker and no actors message"
        in done.stderr
    )
    assert "actors/ file" not in done.stderr
    # A log folder is told about its own files, as before.
    done = run_cli("diagnose", str(folder))
    assert done.returncode == 2
    assert f"{folder}: no frame to analyse (no readable actors/ file)" in done.stderr


def test_replay_of_a_bag_without_frames_is_refused_by_the_player(
    ros_env: RosEnv, ego_only_bag: tuple[Path, Path]
) -> None:
    """Not a verdict over no frame: the player refuses the run as diagnose does."""
    bag, profile = ego_only_bag
    argv = [sys.executable, "-m", "ads_rca.cli", "replay", str(bag), "--profile", str(profile)]
    argv += ["--domain-id", str(ros_env.domain_id), "--timeout", "60"]
    replay = ManagedProcess("replay", argv, ros_env.env)
    assert replay.wait(90) == 2, replay.output
    line = next(x for x in replay.lines if "no verdict" in x)
    assert "player exited early (status 2)" in line and EGO_ONLY_REFUSAL in line
    assert "no fault found" not in replay.output and "no collision" not in replay.output


def _log_with_metadata(folder: Path, **fields: int) -> Path:
    """A synthesised crash (50 ms frames 1 to 78) with metadata.json fields replaced."""
    log_dir = write_run_log(synthesise("lead_braking", "planning", 1), folder)
    metadata = json.loads((log_dir / "metadata.json").read_text())
    metadata.update(fields)
    (log_dir / "metadata.json").write_text(json.dumps(metadata))
    return log_dir


def _metadata_problems(log_dir: Path) -> list[str]:
    return [str(p) for p in read_run_log(log_dir).problems if p.file == "metadata.json"]


def test_a_frame_period_other_than_the_timestamps_step_is_a_problem(tmp_path: Path) -> None:
    log_dir = _log_with_metadata(tmp_path / "log", timesteps_per_frame=100, collision_frame=39)
    found = _metadata_problems(log_dir)
    assert (
        "error: metadata.json: timesteps_per_frame: 100 ms, but the actors timestamps step "
        "by 50 ms (their most common step) (value kept)"
    ) in found, found
    out = tmp_path / "v.json"
    done = run_cli("diagnose", str(log_dir), "--json", str(out))  # diagnosed all the same
    assert done.returncode == 0, done.stderr
    document = json.loads(out.read_text())
    assert document["collision_frame"] == 39 and len(document["frames"]) == 78
    assert any(p["field"] == "timesteps_per_frame" for p in document["input_problems"])


@pytest.mark.parametrize(
    ("total", "reported"), [(200, True), (10, True), (80, True), (79, False), (77, False)]
)
def test_total_frames_far_from_the_last_frame_is_a_problem(
    tmp_path: Path, total: int, reported: bool
) -> None:
    """The last actors file is frame 78: one frame either way is a counting convention."""
    found = _metadata_problems(_log_with_metadata(tmp_path / "log", total_frames=total))
    expected = (
        f"warning: metadata.json: total_frames: {total}, but the last actors file is frame 78 "
        "(3900 ms): more than one frame apart (value kept)"
    )
    assert (expected in found) is reported, found
    assert len(found) == int(reported), found


def test_consistent_metadata_is_no_problem(tmp_path: Path) -> None:
    """The synthesiser's logs (test_diagnosis_golden_outputs pins every one) get no new problem."""
    assert _metadata_problems(_log_with_metadata(tmp_path / "log")) == []
