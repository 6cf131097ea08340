"""A run with no collision source has its collision "unknown" in every output
(docs/verdicts.md): never "no collision in this run", never "no fault found".

The runs: a CARLA+Autoware crash recording (written by our synthesiser) read through a
profile without its collision input, and through a ground-truth-only profile (ego and
actors: a vehicle's own recording); a log folder whose ``metadata.json`` has no
``collision_frame``. The outputs: ``diagnose`` (text, JSON, HTML report), ``inspect``,
``convert`` round trips (log folder → stack recording → diagnose; recording → log folder →
diagnose; log folder → contract bag → log folder) and ``replay`` through the live graph.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest
from commandline import run_cli

from ads_rca.ros.launcher import ManagedProcess
from ads_rca.sources.bag.profiles.profile import builtin_path
from ads_rca.sources.log.writer import write_run_log
from ads_rca.synth import synthesise
from ads_rca.synth.recording import write_recording

if TYPE_CHECKING:
    from conftest import RosEnv

CARLA = "carla-autoware"
#: A ground-truth-only profile: the ego and the other road users, no module output.
GROUND_TRUTH = """\
profile: ground_truth
reference: actors
inputs:
  ego: {topic: /carla/ego_vehicle/odometry, type: nav_msgs/msg/Odometry, frame: map}
  actors: {topic: /carla/objects, type: derived_object_msgs/msg/ObjectArray, frame: map}
metadata:
  camera_loc: [1.5, 0.0, 2.4]
"""
#: What an output with an unknown collision may never say ("collision unknown (no
#: collision source)" is fine).
NEVER = ("no collision in this run", "(no collision)", "no fault found")


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The crash as a recording and two profiles without a collision input; the crash as a
    log folder whose metadata.json lost its collision_frame."""
    root = tmp_path_factory.mktemp("unknown")
    crash = synthesise("lead_braking", "planning", 1)
    write_recording(crash, root / "bag", CARLA, "mcap")
    text = builtin_path(CARLA).read_text(encoding="utf-8")
    no_collision = "\n".join(x for x in text.splitlines() if "collision:" not in x)
    (root / "no_collision.yaml").write_text(no_collision + "\n", encoding="utf-8")
    (root / "ground_truth.yaml").write_text(GROUND_TRUTH, encoding="utf-8")
    folder = write_run_log(crash, root / "log")
    metadata = json.loads((folder / "metadata.json").read_text())
    del metadata["collision_frame"]
    (folder / "metadata.json").write_text(json.dumps(metadata))
    return {
        "bag": root / "bag",
        "no_collision": root / "no_collision.yaml",
        "ground_truth": root / "ground_truth.yaml",
        "log": folder,
    }


def source_args(runs: dict[str, Path], case: str) -> list[str]:
    """The input and its options of each case."""
    if case == "log":
        return [str(runs["log"])]
    return [str(runs["bag"]), "--profile", str(runs[case])]


def assert_unknown(document: dict[str, Any], text: str) -> None:
    """A verdict whose collision is unknown, and its text."""
    assert document["collision"] == "unknown"
    assert document["conclusive"] is False
    assert any(r.startswith("collision unknown") for r in document["why_inconclusive"])
    assert document["reason"] in ("collision unknown", None)
    assert "collision unknown" in text
    assert not [x for x in NEVER if x in text or x in document["verdict"]], text


CASES = ["no_collision", "ground_truth", "log"]


@pytest.mark.parametrize("semantics", ["corrected", "reference"])
@pytest.mark.parametrize("case", CASES)
def test_diagnose_says_collision_unknown(
    runs: dict[str, Path], tmp_path: Path, case: str, semantics: str
) -> None:
    out, report = tmp_path / "v.json", tmp_path / "r.html"
    done = run_cli(
        "diagnose",
        *source_args(runs, case),
        "--semantics",
        semantics,
        "--json",
        str(out),
        "--report",
        str(report),
    )
    assert done.returncode == 0, done.stderr
    assert_unknown(json.loads(out.read_text()), done.stdout)
    page = report.read_text()
    assert "collision unknown" in page and not [x for x in NEVER if x in page]


@pytest.mark.parametrize("case", CASES)
def test_inspect_says_collision_unknown(runs: dict[str, Path], case: str) -> None:
    """Not ``collision frame -1``, which reads as none."""
    done = run_cli("inspect", *source_args(runs, case))
    assert done.returncode == 0, done.stderr
    first = done.stdout.splitlines()[0]
    assert "collision unknown" in first and "collision frame" not in first, first
    info = json.loads(run_cli("inspect", *source_args(runs, case), "--json").stdout)
    assert info["collision"] == "unknown" and info["inputs"]["collision"]["state"] == "absent"
    known = json.loads(run_cli("inspect", str(runs["bag"]), "--profile", CARLA, "--json").stdout)
    assert known["collision"] == "yes"


def test_a_log_with_unknown_collision_written_as_a_stack_recording_stays_unknown(
    runs: dict[str, Path], tmp_path: Path
) -> None:
    """An empty collision topic would say nothing collided: it is not written."""
    bag, out = tmp_path / "bag", tmp_path / "v.json"
    assert run_cli("convert", str(runs["log"]), str(bag), "--profile", CARLA).returncode == 0
    done = run_cli("diagnose", str(bag), "--profile", CARLA, "--json", str(out))
    assert done.returncode == 0, done.stderr
    assert_unknown(json.loads(out.read_text()), done.stdout)


@pytest.mark.parametrize(
    "first", [["--profile", "no_collision"], []], ids=["recording", "log_via_contract_bag"]
)
def test_convert_round_trips_keep_the_collision_unknown(
    runs: dict[str, Path], tmp_path: Path, first: list[str]
) -> None:
    """A recording read without a collision input, written as a log folder; a log folder
    written as a contract bag and back: each folder diagnosed says unknown."""
    if first:
        source = [str(runs["bag"]), first[0], str(runs[first[1]])]
    else:
        assert run_cli("convert", str(runs["log"]), str(tmp_path / "b.mcap")).returncode == 0
        source = [str(tmp_path / "b.mcap")]
    folder, out = tmp_path / "folder", tmp_path / "v.json"
    done = run_cli("convert", *source, str(folder))
    assert done.returncode == 0, done.stderr
    done = run_cli("diagnose", str(folder), "--json", str(out))
    assert done.returncode == 0, done.stderr
    assert_unknown(json.loads(out.read_text()), done.stdout)


@pytest.mark.parametrize("case", ["no_collision", "log"])
def test_replay_says_collision_unknown(
    ros_env: RosEnv, runs: dict[str, Path], tmp_path: Path, case: str
) -> None:
    """The player sends the run metadata (no collision_frame, or model_inputs saying the
    collision is absent); the aggregator's verdict says unknown."""
    out = tmp_path / "v.json"
    argv = [sys.executable, "-m", "ads_rca.cli", "replay", *source_args(runs, case)]
    argv += ["--json", str(out), "--domain-id", str(ros_env.domain_id), "--timeout", "90"]
    replay = ManagedProcess("replay", argv, ros_env.env)
    assert replay.wait(120) == 0, replay.output
    document = json.loads(out.read_text())
    assert document["live"]["complete"], document["live"]
    assert_unknown(document, replay.output)
