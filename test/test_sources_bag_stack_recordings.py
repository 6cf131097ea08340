"""Recordings of real stacks diagnosed with one command: a synthesised run written
as a CARLA ROS bridge + Autoware (or vision_msgs) stack would have recorded it, read back with
``--profile``, its types from the bag itself.

Real processes (the ``ads-rca`` console script) and real bags (rosbags' writer, MCAP and
sqlite3); hostile cases: a bag without type definitions, a profile naming a topic the bag
lacks, a profile whose type differs from the stored one, and bad options.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import pytest
from commandline import run_script
from verdicts import assert_close, failed_flags, verdict_keys

from ads_rca.diagnosis.engine import diagnose
from ads_rca.params import make_params
from ads_rca.ros.launcher import ManagedProcess
from ads_rca.sources.bag.options import BagOptions
from ads_rca.sources.bag.profiles.profile import builtin_path
from ads_rca.sources.registry import open_run
from ads_rca.synth import synthesise
from ads_rca.synth.recording import MSG_DIR, write_recording

if TYPE_CHECKING:
    from conftest import RosEnv

ADS_RCA = str(Path(sys.executable).with_name("ads-rca"))
CARLA = "carla-autoware"


def edited_profile(folder: Path, old: str, new: str) -> Path:
    """The built-in carla-autoware profile with the first ``old`` replaced by ``new``."""
    text = builtin_path(CARLA).read_text(encoding="utf-8").replace(old, new, 1)
    profile = folder / "edited.yaml"
    profile.write_text(text, encoding="utf-8")
    return profile


@pytest.fixture(scope="module")
def crash() -> object:
    return synthesise("lead_braking", "planning", 1)


@pytest.fixture(scope="module")
def bags(crash: object, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    out: dict[str, Path] = {}
    for profile in (CARLA, "vision_msgs"):
        for storage in ("mcap", "sqlite3"):
            path = tmp_path_factory.mktemp("bags") / f"{profile}_{storage}"
            write_recording(crash, path, profile, storage)  # type: ignore[arg-type]
            out[f"{profile}/{storage}"] = path
    old = tmp_path_factory.mktemp("bags") / "old_sqlite3"
    write_recording(crash, old, CARLA, "sqlite3", definitions=False)  # type: ignore[arg-type]
    out["old"] = old
    return out


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_a_carla_autoware_recording_is_diagnosed_with_one_command(
    bags: dict[str, Path], storage: str, tmp_path: Path
) -> None:
    verdict = tmp_path / "verdict.json"
    done = run_script(
        "diagnose", str(bags[f"{CARLA}/{storage}"]), "--profile", CARLA, "--json", str(verdict)
    )
    assert done.returncode == 0, done.stderr
    document = json.loads(verdict.read_text())
    assert document["primary_root_cause"] == "planning"
    assert document["modules_judged"] == dict.fromkeys(
        ("perception", "prediction", "planning", "controller"), "judged"
    )
    # The same run read in-process gives the same verdict: one reader, whatever the storage.
    log = open_run(bags[f"{CARLA}/{storage}"], bag=BagOptions(CARLA))
    assert diagnose(log, make_params("corrected")).to_json()["verdict"] == document["verdict"]


def test_reference_mode_says_what_it_cannot_judge_on_a_3d_stack(bags: dict[str, Path]) -> None:
    done = run_script(
        "diagnose", str(bags[f"{CARLA}/mcap"]), "--profile", CARLA, "--semantics", "reference"
    )
    assert done.returncode == 0, done.stderr
    assert (
        "perception           0      0  not judged (no detections_2d, ground_truth_2d)"
        in done.stdout
    )
    assert "prediction           0      0  not judged (no predictions_gt)" in done.stdout
    # The reference has no 3-D rule: with perception and prediction unjudged the verdict
    # names what was judged and why it cannot conclude (docs/verdicts.md).
    verdict = next(line for line in done.stdout.splitlines() if line.startswith("verdict: "))
    assert "inconclusive: perception not judged (no detections_2d, ground_truth_2d)" in verdict
    assert "no fault found" not in done.stdout


def test_inspect_lists_topics_inputs_and_the_modules_each_mode_can_judge(
    bags: dict[str, Path],
) -> None:
    done = run_script("inspect", str(bags[f"{CARLA}/sqlite3"]), "--profile", CARLA)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    frames = len(synthesise("lead_braking", "planning", 1).frames)
    rows = {tuple(line.split()[:3]) for line in lines if line.startswith("  /")}
    assert ("/carla/objects", "derived_object_msgs/msg/ObjectArray", str(frames)) in rows
    assert any(
        row[:2]
        == (
            "/perception/object_recognition/objects",
            "autoware_perception_msgs/msg/PredictedObjects",
        )
        for row in rows
    )
    assert "inputs missing: detections_2d, ground_truth_2d, predictions_gt" in lines
    assert (
        "reference: perception not judged (no detections_2d, ground_truth_2d); prediction not "
        "judged (no predictions_gt); planning not judged (no predictions_gt); controller judged"
    ) in lines
    assert (
        "corrected: perception judged; prediction judged; planning judged; controller judged"
        in lines
    )
    info = json.loads(
        run_script("inspect", str(bags[f"{CARLA}/sqlite3"]), "--profile", CARLA, "--json").stdout
    )
    assert info["inputs"]["tracked_objects"]["source"].startswith(
        "/perception/object_recognition/tracking/objects"
    )


def test_a_vision_msgs_recording_is_judged_on_its_2d_boxes(bags: dict[str, Path]) -> None:
    log = open_run(bags["vision_msgs/mcap"], bag=BagOptions("vision_msgs"))
    judged = diagnose(log, make_params("reference")).to_json()["modules_judged"]
    assert judged == {
        "perception": "judged",
        "prediction": "not judged (no predictions_gt)",
        "planning": "not judged (no plan, predictions, predictions_gt)",
        "controller": "not judged (no plan)",
    }


def test_a_bag_without_type_definitions_names_them_and_msg_path_supplies_them(
    bags: dict[str, Path],
) -> None:
    done = run_script("diagnose", str(bags["old"]), "--profile", CARLA)
    assert done.returncode == 2
    error = done.stderr.strip()
    assert "\n" not in error and "Traceback" not in error
    for missing in (
        "autoware_perception_msgs/msg/TrackedObjects",
        "autoware_planning_msgs/msg/Trajectory",
        "derived_object_msgs/msg/ObjectArray",
    ):
        assert missing in error
    assert "--msg-path" in error
    fixed = run_script("diagnose", str(bags["old"]), "--profile", CARLA, "--msg-path", str(MSG_DIR))
    assert fixed.returncode == 0, fixed.stderr
    assert "verdict: planning" in fixed.stdout


def test_a_profile_naming_a_topic_the_bag_lacks_leaves_that_input_absent(
    bags: dict[str, Path], tmp_path: Path
) -> None:
    profile = edited_profile(
        tmp_path, "/planning/scenario_planning/trajectory", "/planning/nowhere"
    )
    done = run_script("diagnose", str(bags[f"{CARLA}/mcap"]), "--profile", str(profile))
    assert done.returncode == 0, done.stderr
    assert "planning             0      0  not judged (no plan)" in done.stdout
    assert "/planning/nowhere" in done.stdout  # the problem names the topic


def test_a_profile_whose_type_differs_from_the_stored_one_is_said_once(
    bags: dict[str, Path], tmp_path: Path
) -> None:
    profile = edited_profile(
        tmp_path,
        "autoware_perception_msgs/msg/TrackedObjects",
        "autoware_perception_msgs/msg/DetectedObjects",
    )
    done = run_script("inspect", str(bags[f"{CARLA}/mcap"]), "--profile", str(profile))
    assert done.returncode == 0, done.stderr
    wrong = [
        line
        for line in done.stdout.splitlines()
        if "/perception/object_recognition/tracking/objects" in line
        and "TrackedObjects" in line
        and "DetectedObjects" in line
    ]
    assert len(wrong) == 1


@pytest.mark.parametrize(
    ("argv", "said"),
    [
        (["--profile", "autoware-nope"], "autoware-nope: no such profile"),
        (["--profile", CARLA, "--remap", "{remap}"], "--remap applies to the ads_rca profile"),
        (
            ["--profile", CARLA, "--msg-path", "/nonexistent/msgs"],
            "--msg-path /nonexistent/msgs: no such directory",
        ),
    ],
)
def test_bad_bag_options_are_one_line(
    bags: dict[str, Path], tmp_path: Path, argv: list[str], said: str
) -> None:
    remap = tmp_path / "remap.yaml"
    remap.write_text("/x: actors\n")
    argv = [a.replace("{remap}", str(remap)) for a in argv]
    for command in ("diagnose", "inspect", "convert"):
        extra = [str(tmp_path / f"out_{command}")] if command == "convert" else []
        done = run_script(command, str(bags[f"{CARLA}/mcap"]), *extra, *argv)
        assert done.returncode == 2, (command, done.stdout)
        assert said in done.stderr and done.stderr.count("\n") == 1, (command, done.stderr)


@pytest.mark.parametrize("profile", [CARLA, "vision_msgs"])
def test_a_stacks_recording_read_without_its_profile_names_the_profile(
    bags: dict[str, Path], profile: str
) -> None:
    done = run_script("diagnose", str(bags[f"{profile}/mcap"]))
    assert done.returncode == 2, done.stdout
    assert done.stderr.count("\n") == 1, done.stderr
    assert "the bag has no run/metadata message" in done.stderr
    assert done.stderr.rstrip().endswith(
        f"its topics are the {profile} profile's: add --profile {profile}"
    ), done.stderr
    listed = run_script("inspect", str(bags[f"{profile}/mcap"]))  # lists, and says the same
    assert listed.returncode == 0, listed.stderr
    assert f"recommended: --profile {profile} (" in listed.stdout


def test_convert_writes_a_log_folder_as_a_stacks_recording(tmp_path: Path) -> None:
    folder, bag = tmp_path / "run", tmp_path / "bag"
    made = run_script(
        "synth", str(folder), "--scenario", "lead_braking", "--fault", "planning", "--seed", "1"
    )
    assert made.returncode == 0, made.stderr
    done = run_script("convert", str(folder), str(bag), "--profile", CARLA, "--storage", "sqlite3")
    assert done.returncode == 0, done.stderr
    assert "as a carla-autoware stack records it" in done.stdout
    diagnosed = run_script("diagnose", str(bag), "--profile", CARLA)
    assert diagnosed.returncode == 0, diagnosed.stderr
    assert "controller           0      0" in diagnosed.stdout  # judged: ego, plan, actors
    refused = run_script(
        "convert", str(folder), str(tmp_path / "x"), "--profile", str(tmp_path / "p.yaml")
    )
    assert (
        refused.returncode == 2
        and "can be written as carla-autoware, vision_msgs" in refused.stderr
    )


@pytest.mark.parametrize("semantics", ["corrected", "reference"])
def test_replay_of_a_carla_autoware_recording_equals_diagnose(
    ros_env: RosEnv, bags: dict[str, Path], tmp_path: Path, semantics: str
) -> None:
    """The player reads the recording through the profile; the 3-D objects and the input
    statuses travel on the contract topics; the monitors judge what diagnose judges."""
    bag, out = bags[f"{CARLA}/sqlite3"], tmp_path / "verdict.json"
    argv = [sys.executable, "-m", "ads_rca.cli", "replay", str(bag), "--profile", CARLA]
    argv += ["--semantics", semantics, "--json", str(out)]
    argv += ["--domain-id", str(ros_env.domain_id), "--timeout", "90"]
    replay = ManagedProcess("replay", argv, ros_env.env)
    assert replay.wait(120) == 0, replay.output
    live = json.loads(out.read_text())
    log = open_run(bag, bag=BagOptions(CARLA))
    offline = diagnose(log, make_params(semantics)).to_json()
    assert live["live"]["complete"], live["live"]
    assert failed_flags(live) == failed_flags(offline)
    assert_close(verdict_keys(live), verdict_keys(offline))
    assert_close(live["frames"], offline["frames"])
    assert live["modules_judged"] == offline["modules_judged"]
