"""The test stack (test/stack_publisher.py) sends a run as a stack does, over real DDS.

The publisher and a plain rclpy subscriber (test/stack_probe.py) run as separate processes;
what arrives is checked against the log itself: every record of every folder exactly once
(except the drops, which the publisher names), header stamps = log stamp + that topic's
fixed offset (the reference not offset), /clock = the frame stamps, the collision document
once, after the collision frame's data, and nothing of the player's on the graph.
"""

from __future__ import annotations

import itertools
import json
import subprocess
import sys
from collections import Counter
from pathlib import Path
from typing import Any

import pytest
import yaml
from conftest import RosEnv
from rosrun import wait_for
from stack_publisher import (
    CARLA_TOPICS,
    REFERENCE,
    Schedule,
    load_run,
    make_schedule,
    parse_args,
    topic_offsets,
)

from ads_rca.contract import live_topics, topics
from ads_rca.contract.jsontext import loads_json
from ads_rca.live.results import collision_frame
from ads_rca.live.runid import RunFilter
from ads_rca.live.stack_config import STACK_PARAMETERS
from ads_rca.model import FOLDERS
from ads_rca.ros.aggregator import PARAMETERS as AGGREGATOR_PARAMETERS
from ads_rca.ros.launcher import Launcher
from ads_rca.sources.log.writer import write_run_log
from ads_rca.synth import synthesise

HERE = Path(__file__).resolve().parent
PUBLISHER = HERE / "stack_publisher.py"
PROBE = HERE / "stack_probe.py"
CONFIG = HERE.parent / "config"
SYNTH = ("cut_in", "perception", 1)
#: What a player sends and a stack does not.
PLAYER_ONLY = (topics.FRAME, topics.METADATA, topics.STATUS)


def run_stack(ros_env: RosEnv, tmp: Path, *options: str) -> tuple[dict[str, Any], dict[str, Any]]:
    """Probe and publisher as processes; (the probe's record, the publisher's summary)."""
    argv = ["--synth", ":".join(map(str, SYNTH)), "--namespace", ros_env.namespace, *options]
    schedule = make_schedule(synthesise(*SYNTH), parse_args(argv))
    spec = tmp / "probe.json"
    stop = tmp / "stop"
    out = tmp / "record.json"
    spec.write_text(
        json.dumps({"topics": schedule.topic_types, "stop_file": str(stop), "timeout_s": 90})
    )
    with Launcher(ros_env.env, echo=sys.stderr) as launcher:
        probe = launcher.start("probe", [sys.executable, str(PROBE), str(spec), str(out)])
        wait_for(lambda: "probe ready" in probe.output, 20.0, "the probe")
        publisher = launcher.start("stack", [sys.executable, str(PUBLISHER), *argv])
        assert publisher.wait(90.0) == 0, publisher.output
        stop.touch()
        assert probe.wait(30.0) == 0, probe.output
    [summary] = [json.loads(line) for line in publisher.lines if line.startswith("{")]
    return json.loads(out.read_text()), summary


@pytest.mark.parametrize("layout", ["contract", "carla"])
def test_a_synthesised_crash_arrives_as_a_stack_sends_it(
    ros_env: RosEnv, tmp_path: Path, layout: str
) -> None:
    log = synthesise(*SYNTH)
    options = ["--layout", layout, "--seed", "3", "--drop", "bboxes:0.05", "--jitter-ms", "80"]
    if layout == "carla":
        options += ["--rate", "4"]  # paced by log time (the contract run goes at rate 0)
    record, summary = run_stack(ros_env, tmp_path, *options)
    messages = record["messages"]
    offsets = {folder: int(v) for folder, v in summary["offsets_ms"].items()}
    assert offsets == topic_offsets(3, 20)
    assert offsets[REFERENCE] == 0
    assert all(-20 <= v <= 20 for v in offsets.values()) and len(set(offsets.values())) > 2
    dropped = summary["dropped"]
    assert list(dropped) == ["bboxes"] and len(dropped["bboxes"]) == round(0.05 * len(log.frames))
    if layout == "contract":
        names = {f: topics.topic_name(topics.FOLDER_TOPICS[f], ros_env.namespace) for f in FOLDERS}
    else:
        names = dict(CARLA_TOPICS)
    folder_of = {name: folder for folder, name in names.items()}
    by_topic: dict[str, list[int]] = {}
    for row in messages:
        assert len(set(row["stamps"])) <= 1  # a MarkerArray's markers share one stamp
        by_topic.setdefault(row["topic"], []).append(row["stamps"][0] if row["stamps"] else -1)
    for folder in FOLDERS:
        got = sorted(stamp - offsets[folder] for stamp in by_topic[names[folder]])
        assert got == sorted(set(log.folder(folder)) - set(dropped.get(folder, [])))
    assert sorted(by_topic[topics.CLOCK]) == list(log.unique_frames)
    collision = topics.topic_name(live_topics.COLLISION, ros_env.namespace)
    [document] = [row for row in messages if row["topic"] == collision]
    assert loads_json(document["text"]) == {"frame": 103, "stamp_ms": 5150}
    assert collision_frame(loads_json(document["text"]), RunFilter()) == 103
    data = [r for r in messages if r["topic"] in folder_of]
    log_stamp = [r["stamps"][0] - offsets[folder_of[r["topic"]]] for r in data]
    assert max(log_stamp) == 5150 == log.frames[-1]
    assert all(r["received_ns"] < document["received_ns"] for r in data)
    counts = Counter(row["topic"] for row in messages)
    assert counts == Counter({t: n for t, n in summary["sent"].items()})
    assert sum(counts.values()) == 7 * 103 - len(dropped["bboxes"]) + 103 + 1
    graph = set(record["graph"])
    assert set(names.values()) <= graph
    assert not graph & {topics.topic_name(k, ros_env.namespace) for k in PLAYER_ONLY}
    arrival = [r["stamps"][0] for r in messages if r["topic"] == names[REFERENCE]]
    assert arrival != sorted(arrival)  # jitter above the period reorders frames


def sent(schedule: Schedule) -> list[tuple[float, str, int]]:
    return [(out.due_ms, out.topic, out.header_stamp_ms) for out in schedule.messages]


def test_the_schedule_follows_the_seed_and_the_jitter_stays_within_its_frame() -> None:
    log = synthesise(*SYNTH)
    settings = parse_args(["--synth", "cut_in:perception:1", "--seed", "2"])
    schedule = make_schedule(log, settings)
    assert sent(schedule) == sent(make_schedule(log, settings))
    other = parse_args(["--synth", "cut_in:perception:1", "--seed", "3"])
    assert schedule.offsets_ms != make_schedule(log, other).offsets_ms
    first = log.frames[0]
    data = [out for out in schedule.messages if out.folder is not None]
    delays = [out.due_ms - (out.log_stamp_ms - first) for out in data]
    assert min(delays) >= 0 and max(delays) <= 30
    # A 30 ms jitter under a 50 ms period: frames keep their order, topics within one do not.
    assert [out.log_stamp_ms for out in data] == sorted(out.log_stamp_ms for out in data)
    order = [out.folder for out in data if out.log_stamp_ms == first]
    assert sorted(order, key=FOLDERS.index) == list(FOLDERS) != order
    clocks = [i for i, out in enumerate(schedule.messages) if out.topic == topics.CLOCK]
    assert [schedule.messages[i + 1].log_stamp_ms for i in clocks] == list(log.frames)
    assert schedule.messages[-1].topic == topics.topic_name(live_topics.COLLISION)
    elsewhere = parse_args(["--synth", "cut_in:perception:1", "--collision-topic", "/crash"])
    assert make_schedule(log, elsewhere).messages[-1].topic == "/crash"


def test_a_log_folder_is_sent_as_the_synthesised_run_it_was_written_from(
    tmp_path: Path,
) -> None:
    folder = write_run_log(synthesise(*SYNTH), tmp_path / "log")
    options = ["--layout", "carla", "--seed", "5", "--drop", "waypoint:0.1"]
    synthesised = parse_args(["--synth", "cut_in:perception:1", *options])
    logged = parse_args(["--log", str(folder), *options])
    expected = make_schedule(synthesise(*SYNTH), synthesised)
    schedule = make_schedule(load_run(logged), logged)
    assert sent(schedule) == sent(expected)
    assert schedule.dropped == expected.dropped and len(schedule.dropped["waypoint"]) == 10


def run_publisher(ros_env: RosEnv, *options: str) -> subprocess.CompletedProcess[str]:
    """The publisher alone, its stdout and stderr apart."""
    argv = [sys.executable, str(PUBLISHER), *options]
    return subprocess.run(
        argv, env=ros_env.env, capture_output=True, text=True, timeout=60, check=False
    )


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (
            ["--synth", "cut_in:perception"],
            "stack_publisher: --synth 'cut_in:perception': expected SCENARIO:FAULT:SEED",
        ),
        (
            ["--synth", "cut_in:brakes:1"],
            "stack_publisher: --synth 'cut_in:brakes:1': fault must be one of none, perception, "
            "prediction, planning, controller",
        ),
        (
            ["--log", "/nonexistent/log"],
            "stack_publisher: --log /nonexistent/log: no such log folder",
        ),
        (
            ["--synth", "cut_in:none:1", "--drop", "bboxes:1.5"],
            "stack_publisher: --drop 'bboxes:1.5': fraction '1.5' is not a number in [0, 1]",
        ),
        (
            ["--synth", "cut_in:none:1", "--drop", "radar:0.1"],
            "stack_publisher: --drop 'radar:0.1': folder must be one of " + ", ".join(FOLDERS),
        ),
        (
            ["--synth", "cut_in:none:1", "--wait-collision-subscribers", "-1"],
            "stack_publisher: --wait-collision-subscribers must be >= 0, not -1",
        ),
        (
            ["--synth", "cut_in:none:1", "--rate", "-1"],
            "stack_publisher: argument --rate: --rate must be a number >= 0.0, not '-1'",
        ),
    ],
)
def test_bad_options_are_one_line_and_exit_2(
    ros_env: RosEnv, options: list[str], message: str
) -> None:
    done = run_publisher(ros_env, *options)
    assert (done.returncode, done.stdout, done.stderr) == (2, "", message + "\n")


#: What the stack files set for every node, and for the aggregator only.
SHARED_KEYS = set(STACK_PARAMETERS) - {"inputs_best_effort"} | {"topic_namespace"}
AGGREGATOR_KEYS = {"collision_topic", "detect_collisions"}
LAYOUT_OF = {"contract": {}, "carla": {"actors": "carla_markers", "waypoint": "path"}}


def flatten(values: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """A params file's nested keys as ROS names them (``inputs.pose.topic``)."""
    out: dict[str, Any] = {}
    for key, value in values.items():
        if isinstance(value, dict):
            out |= flatten(value, f"{prefix}{key}.")
        else:
            out[f"{prefix}{key}"] = value
    return out


@pytest.mark.parametrize("layout", ["contract", "carla"])
def test_the_stack_config_file_describes_the_test_stacks_layout(layout: str) -> None:
    path = CONFIG / f"stack_{layout}.yaml"
    document = yaml.safe_load(path.read_text())
    values = flatten(document["/**"]["ros__parameters"])
    assert set(values) == SHARED_KEYS
    aggregator = document["/**/aggregator"]["ros__parameters"]
    assert set(aggregator) == AGGREGATOR_KEYS
    assert set(aggregator) <= set(AGGREGATOR_PARAMETERS)
    if layout == "contract":
        names = {f: topics.topic_name(topics.FOLDER_TOPICS[f]) for f in FOLDERS}
    else:
        names = dict(CARLA_TOPICS)
    assert {f: values[f"inputs.{f}.topic"] for f in FOLDERS} == names
    layouts = {f: LAYOUT_OF[layout].get(f, "contract") for f in FOLDERS}
    assert {f: values[f"inputs.{f}.layout"] for f in FOLDERS} == layouts
    metadata = synthesise(*SYNTH).metadata
    camera = tuple(values[f"camera_loc.{axis}"] for axis in "xyz")
    assert camera == metadata.camera_loc == (1.3, 0.0, 1.8)
    assert values["timesteps_per_frame"] == metadata.timesteps_per_frame == 50
    assert aggregator["collision_topic"] == topics.topic_name(live_topics.COLLISION)
    lines = path.read_text().splitlines()
    for before, line in itertools.pairwise(lines):
        if (
            line.strip()
            and not line.lstrip().startswith("#")
            and line.startswith("    ")
            and (line.strip() != "ros__parameters:")
        ):
            assert before.lstrip().startswith("#"), f"{path.name}: {line.strip()} has no comment"


@pytest.mark.slow
def test_without_its_subscribers_the_stack_gives_up_in_one_line(ros_env: RosEnv) -> None:
    done = run_publisher(ros_env, "--synth", "cut_in:none:1", "--namespace", ros_env.namespace)
    assert (done.returncode, done.stdout) == (1, "")
    [line] = done.stderr.splitlines()
    assert "[ERROR]" in line and "only 0 of 1 subscribers after 10.0 s on " in line
    assert line.endswith(topics.topic_name(live_topics.COLLISION, ros_env.namespace))
