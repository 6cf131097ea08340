"""``ads-rca inspect BAG`` with no profile, as a user runs it: any rosbag2 bag listed (every
topic with its type, messages, rate and span), each built-in profile's fit and the one to
use, ``--json`` carrying the same, ``--write-profile FILE`` (never over an existing file
without ``--force``), and hostile bags: one line and exit 2 for a file that is no bag,
escaped and cut names, no traceback.

Real bags written with rosbags' writer (``writers/listing_bags.py``); the command run in
process (``cli``) where its output is all a test reads, as a child process for exit
statuses and stderr.
"""

from __future__ import annotations

import json
import shutil
import sqlite3
import time
from pathlib import Path

import pytest
import yaml
from commandline import assert_clean, convert_example, run_cli
from writers.listing_bags import (
    TopicSpec,
    every,
    odometry,
    storage_file,
    vehicle_topics,
    without_summary,
    write_bag,
)

from ads_rca.cli import main as cli
from ads_rca.commands.inspect_cmd import MAX_LINE_CHARS
from ads_rca.sources.bag.profiles.profile import load_profile
from ads_rca.synth.recording import MSG_DIR


def strict(text: str) -> object:
    """JSON that holds no NaN or Infinity literal."""

    def refuse(constant: str) -> object:
        raise AssertionError(f"non-finite JSON literal {constant}")

    return json.loads(text, parse_constant=refuse)


@pytest.fixture(scope="module")
def vehicle(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A real vehicle's pre-Iron sqlite3 bag: 320 declared topics, no metadata.yaml."""
    folder = tmp_path_factory.mktemp("vehicle")
    return write_bag(folder / "drive", vehicle_topics(320), pre_iron=True, metadata_yaml=False)


def test_a_vehicle_bag_lists_with_no_profile(
    vehicle: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    started = time.perf_counter()
    assert cli(["inspect", str(vehicle)]) == 0
    elapsed = time.perf_counter() - started
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith(f"bag: {vehicle}: 1 storage file(s) (drive.db3; no metadata.yaml)")
    assert "messages: 181 on 4 of 320 declared topics" in lines
    assert "topics: 320 (316 without messages)" in lines
    rows = {line.split()[0]: line.split()[1:] for line in lines if line.startswith("  /")}
    assert len(rows) == 320
    assert rows["/localization/kinematic_state"] == [
        "nav_msgs/msg/Odometry",
        "100",
        "50.00",
        "Hz",
        "1.980",
        "s",
    ]
    assert rows["/autoware/state"][1:] == ["1", "-", "0.000", "s"]  # one message: no rate
    assert rows["/perception/object_recognition/objects"] == [
        "autoware_auto_perception_msgs/msg/PredictedObjects",
        "0",
        "-",
        "-",
    ]
    assert any(line.startswith("definitions: the bag stores none") for line in lines)
    assert any(line.startswith("recommended: ") for line in lines)
    assert lines[-1] == "problems: 0"
    assert elapsed < 2.0, elapsed


def test_json_carries_the_same_listing(vehicle: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert cli(["inspect", str(vehicle), "--json"]) == 0
    document = strict(capsys.readouterr().out)
    assert isinstance(document, dict)
    assert document["source"] == str(vehicle)
    assert document["bag"]["files"] == ["drive.db3"] and document["bag"]["messages"] == 181
    assert document["bag"]["stores_definitions"] is False
    topics = {t["name"]: t for t in document["topics"]}
    assert len(topics) == 320
    assert topics["/autoware/state"]["rate_hz"] is None
    assert topics["/localization/kinematic_state"]["rate_hz"] == pytest.approx(50.0)
    assert topics["/localization/kinematic_state"]["definition"] == "standard"
    assert {p["profile"] for p in document["profiles"]} >= {"ads_rca", "carla-autoware"}
    assert set(document["recommendation"]) == {"profile", "reason", "lacking", "by_type"}
    assert document["problems"] == []


@pytest.fixture(scope="module")
def own_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """This project's own bag: the bundled example converted (sqlite3)."""
    return convert_example(tmp_path_factory.mktemp("own") / "bag", "--storage", "sqlite3")


def test_this_projects_own_bag_is_still_read(
    own_bag: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = own_bag
    capsys.readouterr()
    assert cli(["inspect", str(bag)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert "analysed frames" in lines[0]
    assert "recommended: --profile ads_rca (" in "\n".join(lines)
    assert any(line.startswith("  /ads_rca/run/metadata ") for line in lines)
    assert (
        "corrected: perception judged; prediction judged; planning judged; controller judged"
        in (lines)
    )


def test_this_projects_bag_with_a_damaged_run_is_still_listed(
    own_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = Path(shutil.copytree(own_bag, tmp_path / "bag"))
    with sqlite3.connect(storage_file(bag)) as db:
        db.execute(
            "UPDATE messages SET data = x'0001000005000000' WHERE topic_id = "
            "(SELECT id FROM topics WHERE name = '/ads_rca/run/metadata')"
        )
    capsys.readouterr()
    assert cli(["inspect", str(bag)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith(f"bag: {bag}: ") and "topics: 11 (0 without messages)" in lines
    assert lines[-2] == "problems: 1"
    assert "the bag has no run/metadata message" in lines[-1]
    assert lines[-1].endswith("(the run is not read)") and "add --profile" not in lines[-1]


def test_an_mcap_without_summary_lists_from_a_scan(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = write_bag(tmp_path / "bag", vehicle_topics(30), "mcap", metadata_yaml=False)
    assert cli(["inspect", str(bag), "--json"]) == 0
    summarised = strict(capsys.readouterr().out)
    without_summary(storage_file(bag))
    assert cli(["inspect", str(bag), "--json"]) == 0
    scanned = strict(capsys.readouterr().out)
    assert isinstance(summarised, dict) and isinstance(scanned, dict)
    assert scanned["topics"] == summarised["topics"]
    assert scanned["bag"]["listed_by"] == ["a scan of every record (no usable MCAP summary)"]


def test_hostile_names_are_escaped_and_cut(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    forged, long_name = "/x\x1b[2J\nverdict: planning", "/y" * 5000
    topics = [
        TopicSpec(forged, "acme_msgs/msg/A\x1bB", every(10, 1)),
        TopicSpec(long_name, "acme_msgs/msg/" + "L" * 10_000, (1,)),
    ]
    bag = write_bag(tmp_path / "bag", topics, metadata_yaml=False)
    assert cli(["inspect", str(bag)]) == 0
    out = capsys.readouterr().out
    assert "\x1b" not in out and "\nverdict: planning" not in out
    assert all(len(line) <= MAX_LINE_CHARS for line in out.splitlines())
    assert max(len(line) for line in out.splitlines()) < 400
    assert "/x\\x1b[2J\\x0averdict: planning" in out
    assert cli(["inspect", str(bag), "--json"]) == 0
    document = strict(capsys.readouterr().out)
    assert isinstance(document, dict)
    assert {t["name"] for t in document["topics"]} == {forged, long_name}  # exact


@pytest.mark.parametrize("content", [b"", b"SQLite format 3\x00" + b"\xff" * 4000, b"x" * 9000])
def test_a_corrupt_db3_is_one_line_naming_it(tmp_path: Path, content: bytes) -> None:
    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / "rosbag2_2023_05_08-16_32_17_0.db3").write_bytes(content)
    done = run_cli("inspect", str(bag))
    assert_clean(done, 2)
    assert done.stderr.count("\n") == 1, done.stderr
    assert f"{bag / 'rosbag2_2023_05_08-16_32_17_0.db3'}: " in done.stderr


def test_write_profile_writes_a_loadable_profile_and_never_overwrites(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    topics = [
        TopicSpec("/my/odom", "nav_msgs/msg/Odometry", every(20, 1), odometry),
        TopicSpec("/my/plan", "autoware_planning_msgs/msg/Trajectory", every(10, 1)),
        TopicSpec("/my/empty", "autoware_perception_msgs/msg/TrackedObjects"),
    ]
    bag = write_bag(tmp_path / "bag", topics, metadata_yaml=False)
    target = tmp_path / "profiles" / "my stack.yaml"
    assert cli(["inspect", str(bag), "--write-profile", str(target)]) == 0
    out = capsys.readouterr().out
    assert f"profile written: {target} (maps ego, plan;" in out
    profile = load_profile(target)
    assert profile.name == "my-stack" and profile.reference == "ego"
    assert {i: s.topic for i, s in profile.inputs.items()} == {
        "ego": "/my/odom",
        "plan": "/my/plan",
    }
    written = target.read_text()
    done = run_cli("inspect", str(bag), "--write-profile", str(target))
    assert_clean(done, 2)
    assert done.stderr.count("\n") == 1 and "exists (--force replaces it)" in done.stderr
    target.write_text("# my edits\n" + written)
    assert cli(["inspect", str(bag), "--write-profile", str(target), "--force", "--json"]) == 0
    document = strict(capsys.readouterr().out)
    assert isinstance(document, dict)
    assert document["written_profile"] == {
        "path": str(target),
        "inputs": {"ego": "/my/odom", "plan": "/my/plan"},
    }
    assert target.read_text() == written
    assert [p.name for p in target.parent.iterdir()] == [target.name]  # no temporary left
    # Read with it: the plan's type is defined nowhere in the bag (--msg-path gives it) and
    # its messages are opaque bytes, so only the ego's 20 real messages make frames.
    read = run_cli("inspect", str(bag), "--profile", str(target), "--msg-path", str(MSG_DIR))
    assert_clean(read)
    assert read.stdout.splitlines()[0].endswith("total_frames 20")
    assert "inputs found: ego" in read.stdout.splitlines()


def test_write_profile_refusals_are_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = write_bag(tmp_path / "bag", [TopicSpec("/s", "std_msgs/msg/String", every(1, 3))])
    log = tmp_path / "log"
    log.mkdir()
    target = tmp_path / "p.yaml"
    for argv, said in (
        ([str(bag), "--write-profile", str(target)], "no profile can be started"),
        ([str(bag), "--force"], "--force: only with --write-profile FILE"),
        ([str(bag), "--write-profile", str(tmp_path)], "is a directory"),
        ([str(log), "--write-profile", str(target)], f"--write-profile: {log} is not a bag"),
    ):
        assert cli(["inspect", *argv]) == 2, argv
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and said in err, err
    assert not target.exists()


def test_a_profile_fit_names_what_is_missing(
    vehicle: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The vehicle's perception topics are declared, never published: no profile maps them
    and the starting profile leaves them out, whatever types the profiles accept."""
    target = tmp_path / "v.yaml"
    assert cli(["inspect", str(vehicle), "--json", "--write-profile", str(target)]) == 0
    document = strict(capsys.readouterr().out)
    assert isinstance(document, dict)
    perception = ("detections_3d", "tracked_objects", "predictions")
    for fit in document["profiles"]:
        for name in perception:
            if name in fit["inputs"]:
                assert not fit["inputs"][name]["mapped"] and fit["inputs"][name]["count"] == 0
                assert fit["inputs"][name]["why"], fit
    (carla,) = [f for f in document["profiles"] if f["profile"] == "carla-autoware"]
    assert carla["refused"].startswith("no message to time the frames by: actors")
    written = yaml.safe_load(target.read_text())
    assert written["inputs"]["ego"]["topic"] == "/localization/kinematic_state"
    assert not set(perception) & set(written["inputs"])  # declared, never published
