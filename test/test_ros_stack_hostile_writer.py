"""Stack mode over real DDS with a hostile second writer on the reference topic (issue 43).

The ``monitors`` and ``aggregator`` nodes, each its own process, run from
``config/stack_carla.yaml`` beside test/independent_stack.py (the real stack, at half log
rate); 15 frames into its run, test/hostile_publisher.py, another process, publishes on
the ego odometry topic: three messages stamped with the wall clock (56 years
ahead of the simulated stamps), 40 NaN poses stamped between the stack's frames, and a
flood at about 4,000 messages a second. Before, that moved the frame grid: every later
real message was dropped as late or thousands of flood frames were judged, while the
monitors' heartbeat stayed OK. Now the topic is locked to its first writer: the hostile
messages are counted and skipped, every frame of the real stack is judged, the verdict is
``diagnose``'s, and the heartbeat says WARN "second publisher on <topic>: N messages
ignored". In process: test_live_stack_guard.py.
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path
from typing import Any

import pytest
from conftest import RosEnv
from rosrun import wait_for
from stackgraph import crash, offline, start_judges

from ads_rca.oracles.base import MODULES
from ads_rca.ros.graph import AGGREGATOR, GROUP, MONITOR
from ads_rca.ros.launcher import Launcher, ParamValue, ros_args
from ads_rca.sources.log.writer import write_run_log

pytestmark = pytest.mark.timeout(240)

HERE = Path(__file__).resolve().parent
STACK = HERE / "independent_stack.py"
HOSTILE = HERE / "hostile_publisher.py"
CARLA = HERE.parent / "config" / "stack_carla.yaml"
ODOMETRY = "/carla/ego_vehicle/odometry"
CASE = ("lead_braking", "prediction")  # collision at frame 78
HEARTBEATS = {f"ads_rca/{m}/monitor" for m in MODULES}


def jsonl(path: Path) -> list[dict[str, Any]]:
    text = path.read_text() if path.exists() else ""
    return [json.loads(line) for line in text.splitlines() if line.strip()]


def test_a_second_writer_on_the_reference_topic_is_ignored_and_said(
    ros_env: RosEnv, tmp_path: Path
) -> None:
    log = crash(*CASE)
    folder = write_run_log(log, tmp_path / "_".join(CASE))
    diag, metrics = tmp_path / "diag.jsonl", tmp_path / "metrics.jsonl"
    shared: dict[str, ParamValue] = {
        "topic_namespace": ros_env.namespace,
        "semantics": "corrected",
        "input_timeout_s": 1.0,
    }
    aggregator_params = {
        **shared,
        "collision_topic": "",
        "verdict_json": str(tmp_path / "verdict.json"),
        "metrics_log": str(metrics),
    }
    python = sys.executable
    with Launcher(ros_env.env, echo=sys.stderr) as launcher:
        probe, monitors, aggregator = start_judges(
            launcher,
            diag,
            [python, "-m", MONITOR, GROUP, *ros_args(shared, CARLA)],
            [python, "-m", AGGREGATOR, *ros_args(aggregator_params, CARLA)],
        )
        # The real stack is the first writer: the attack begins after 15 of its frames.
        hostile = launcher.start("hostile", [python, str(HOSTILE), "--topic", ODOMETRY])
        real = ["--log", str(folder), "--seed", "3", "--rate", "0.5"]
        stack = launcher.start(
            "stack", [python, str(STACK), "--namespace", ros_env.namespace, *real]
        )
        assert hostile.wait(60.0) == 0, hostile.output
        assert stack.wait(120.0) == 0, stack.output
        wait_for(lambda: list(tmp_path.glob("verdict*.json")), 60.0, "the verdict")
        outputs = {"monitors": monitors.output, "aggregator": aggregator.output}
        for process in (aggregator, monitors, probe):
            process.stop(timeout=10.0)
    [attack] = [json.loads(line) for line in hostile.lines if line.startswith("{")]
    statuses = jsonl(diag)
    beats = [s for s in statuses if s["name"] in HEARTBEATS]
    said = [s for s in beats if f"second publisher on {ODOMETRY}: " in s["message"]]
    sync = [line for line in outputs["monitors"].splitlines() if "stamp sync so far" in line]
    facts = (attack, sync[-3:], beats[-1]["message"] if beats else None)

    [verdict] = [json.loads(p.read_text()) for p in sorted(tmp_path.glob("verdict*.json"))]
    want = offline(*CASE, "corrected").to_json()
    assert verdict["live"]["complete"] is True, (verdict["live"], facts)
    assert verdict["collision_frame"] == 78, facts
    for key in ("partner_id", "primary_root_cause", "verdict"):
        assert verdict[key] == want[key], (key, facts)
    # Every frame of the real stack judged, none of the hostile's.
    controller = {r["stamp_ms"] for r in jsonl(metrics) if r["module"] == "controller"}
    cf_ms = 78 * log.frame_ms
    assert controller == {s for s in log.unique_frames if s <= cf_ms}, facts
    # Never OK while refusing: WARN with the count, and no frame dropped as late.
    assert said, facts
    assert {s["level"] for s in said} == {1}, facts
    found = [re.search(r"second publisher on \S+: (\d+)", s["message"]) for s in said]
    counts = [int(match[1]) for match in found if match is not None]
    assert len(counts) == len(said), facts
    assert 3 <= max(counts) <= attack["total"], (counts, facts)
    last = said[-1]["values"]
    assert int(last["ignored_other_writers"]) == max(counts)
    assert int(last["late_reference"]) == 0, facts
    assert "stack inputs refused: second publisher on" in outputs["monitors"]
