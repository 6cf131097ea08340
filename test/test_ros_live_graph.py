"""The live node graph over real DDS: every node its own process, on the test's own domain.

- ``ads-rca replay`` gives ``ads-rca diagnose``'s verdict and per-frame flags, for every
  scenario and every fault kind, in both semantics modes;
- a monitor killed (SIGKILL) mid-run is reported STALE, recovers when restarted, and the
  aggregator still publishes a verdict (marked incomplete, lost frames listed);
- a stalled input (the player killed mid-run) is reported STALE and the verdict comes after
  the stall timeout instead of never;
- three replays of one log give identical metric streams and verdicts.
"""

from __future__ import annotations

import itertools
import json
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest
from rosrun import jsonl, start_probe, wait_for
from synthlogs import CASES, write_log_with_unreadable_values
from verdicts import assert_close, failed_flags, verdict_keys

from ads_rca.diagnosis.engine import diagnose
from ads_rca.oracles.base import MODULES
from ads_rca.params import make_params
from ads_rca.ros.graph import MONITORS_SEPARATE, Graph, GraphSpec
from ads_rca.ros.launcher import ManagedProcess, ros_args
from ads_rca.sources.log.reader import read_run_log

if TYPE_CHECKING:
    from conftest import RosEnv

pytestmark = pytest.mark.timeout(180)

STALE = 3


@pytest.mark.parametrize("semantics", ["reference", "corrected"])
@pytest.mark.parametrize("case", CASES, ids=["-".join(c) for c in CASES])
def test_replay_gives_the_diagnose_verdict(
    ros_env: RosEnv,
    tmp_path: Path,
    log_dirs: Callable[[str, str], Path],
    case: tuple[str, str],
    semantics: str,
) -> None:
    log_dir = log_dirs(*case)
    out = tmp_path / "verdict.json"
    argv = [sys.executable, "-m", "ads_rca.cli", "replay", str(log_dir), "--semantics", semantics]
    argv += ["--json", str(out), "--domain-id", str(ros_env.domain_id), "--timeout", "90"]
    started = time.monotonic()
    replay = ManagedProcess("replay", argv, ros_env.env)
    assert replay.wait(120) == 0, replay.output
    elapsed = time.monotonic() - started
    live = json.loads(out.read_text())
    offline = diagnose(read_run_log(log_dir), make_params(semantics)).to_json()
    assert live["live"]["complete"], live["live"]
    assert failed_flags(live) == failed_flags(offline)
    assert_close(verdict_keys(live), verdict_keys(offline))  # evidence metrics: floats
    assert_close(live["frames"], offline["frames"])
    # From the last decided frame's first arrival in the graph (one machine's
    # CLOCK_MONOTONIC) to the verdict: a later instant, inside the replay's lifetime.
    assert live["verdict_latency_from"].startswith("the collision frame's arrival")
    assert 0 < live["verdict_latency_s"] < elapsed
    assert f"verdict: {offline['verdict']}" in replay.output


def test_replay_with_one_process_per_monitor_gives_the_same_verdict(
    ros_env: RosEnv, tmp_path: Path, log_dirs: Callable[[str, str], Path]
) -> None:
    """``--monitors separate``: the layout a monitor can be restarted in, same verdict."""
    log_dir = log_dirs("cut_in", "planning")
    out = tmp_path / "verdict.json"
    argv = [sys.executable, "-m", "ads_rca.cli", "replay", str(log_dir), "--monitors", "separate"]
    argv += ["--json", str(out), "--domain-id", str(ros_env.domain_id), "--timeout", "90"]
    replay = ManagedProcess("replay", argv, ros_env.env)
    assert replay.wait(120) == 0, replay.output
    live = json.loads(out.read_text())
    offline = diagnose(read_run_log(log_dir), make_params("corrected")).to_json()
    assert live["live"]["complete"], live["live"]
    assert failed_flags(live) == failed_flags(offline)
    assert_close(verdict_keys(live), verdict_keys(offline))


def test_replay_of_a_log_with_unreadable_values_equals_diagnose(
    ros_env: RosEnv, tmp_path: Path
) -> None:
    """Reader problems cross DDS in run/metadata: the live judging skips what diagnose skips."""
    log_dir = write_log_with_unreadable_values(tmp_path / "log")
    out = tmp_path / "verdict.json"
    argv = [sys.executable, "-m", "ads_rca.cli", "replay", str(log_dir), "--semantics"]
    argv += ["reference", "--json", str(out), "--domain-id", str(ros_env.domain_id)]
    replay = ManagedProcess("replay", [*argv, "--timeout", "90"], ros_env.env)
    assert replay.wait(120) == 0, replay.output
    live = json.loads(out.read_text())
    offline = diagnose(read_run_log(log_dir), make_params("reference")).to_json()
    assert_close(live["frames"], offline["frames"])
    assert live["input_problems"] == offline["input_problems"]
    assert any(p["action"] == "read as NaN" for p in live["input_problems"])


def test_replay_stops_at_once_when_a_node_fails(ros_env: RosEnv, tmp_path: Path) -> None:
    """A player that cannot start ends the replay with its error, not after --timeout."""
    not_a_log = tmp_path / "not_a_log"
    not_a_log.mkdir()
    argv = [sys.executable, "-m", "ads_rca.cli", "replay", str(not_a_log), "--timeout", "600"]
    replay = ManagedProcess("replay", [*argv, "--domain-id", str(ros_env.domain_id)], ros_env.env)
    assert replay.wait(120) == 2, replay.output
    line = next(x for x in replay.lines if "no verdict" in x)
    assert "player exited early (status 2)" in line
    assert f"{not_a_log}: not an ADS running log" in line


@pytest.mark.slow
def test_monitor_killed_and_restarted_goes_stale_recovers_and_a_verdict_comes(
    ros_env: RosEnv, tmp_path: Path, log_dirs: Callable[[str, str], Path]
) -> None:

    log_dir = log_dirs("pedestrian_crossing", "planning")
    params = make_params("reference")
    metrics = tmp_path / "metrics.jsonl"
    spec = GraphSpec(
        log_dir,
        params,
        tmp_path / "verdict.json",
        namespace=ros_env.namespace,
        rate=0.6,
        metrics_log=metrics,
        aggregator_params={"stale_timeout_s": 1.0},
        monitors=MONITORS_SEPARATE,  # one monitor is killed on its own
    )
    diagnostics = tmp_path / "diagnostics.jsonl"
    probe = start_probe(ros_env, diagnostics)
    try:
        with Graph(spec, ros_env.env) as graph:
            graph.start()
            wait_for(
                lambda: sum(r["module"] == "controller" for r in jsonl(metrics)) >= 5,
                60,
                "controller results",
            )
            victim = graph.processes["controller_monitor"]
            victim.process.kill()
            victim.wait(10)
            killed_at = time.monotonic()
            stale = wait_for(
                lambda: [
                    r
                    for r in jsonl(diagnostics)
                    if r["name"] == "ads_rca/controller"
                    and r["level"] == STALE
                    and r["t"] > killed_at
                ],
                20,
                "a STALE controller status",
            )
            assert stale[0]["values"]["reported_by"] == "aggregator"
            graph.restart("controller_monitor")
            document = graph.wait_verdict(90, fail_fast=False)
            assert document is not None, graph.processes["aggregator"].output
            graph.stop()
    finally:
        probe.stop()
    rows = jsonl(diagnostics)
    first_stale = stale[0]["t"]
    recovered = [
        r
        for r in rows
        if r["name"] == "ads_rca/controller" and r["level"] != STALE and r["t"] > first_stale
    ]
    assert recovered, "no controller status after the restart"
    # Diagnostics tools key statuses by name: never two of one name in an array.
    names = [(r["array"], r["name"]) for r in rows]
    assert len(names) == len(set(names))
    # One status per judged batch: its latest frame, and how many were judged since the
    # previous status, so the statuses account for every judged frame exactly.
    statuses = [
        (int(r["values"]["index"]), int(r["values"]["judged_since_last"]))
        for r in rows
        if r["name"] == "ads_rca/perception" and "index" in r["values"]
    ]
    judged = [r["index"] for r in jsonl(metrics) if r["module"] == "perception"]
    assert judged == sorted(set(judged))  # reference: each frame judged once, in order
    # /diagnostics is volatile: the probe sees what was sent once discovery matched it to
    # the monitor (up to ~2.5 s, environment.md), which may be after the first frames.
    assert len(statuses) >= 2
    positions = [judged.index(index) for index, _count in statuses]
    assert positions[0] + 1 >= statuses[0][1]
    assert [b - a for a, b in itertools.pairwise(positions)] == [n for _i, n in statuses[1:]]
    offline = diagnose(read_run_log(log_dir), params).to_json()
    assert document["primary_root_cause"] == offline["primary_root_cause"]
    assert document["live"]["complete"] is False
    reasons = document["live"]["why_incomplete"]
    assert any("lost" in why and "controller" in why for why in reasons), document["live"]
    sessions = {r["session"] for r in jsonl(metrics) if r["module"] == "controller"}
    assert len(sessions) == 2  # results from before and after the restart


@pytest.mark.slow
def test_stalled_input_is_reported_and_not_waited_on_forever(
    ros_env: RosEnv, tmp_path: Path, log_dirs: Callable[[str, str], Path]
) -> None:
    log_dir = log_dirs("lead_braking", "prediction")
    spec = GraphSpec(
        log_dir,
        make_params("corrected"),
        tmp_path / "verdict.json",
        namespace=ros_env.namespace,
        rate=1.0,
        monitor_params={"stale_timeout_s": 1.0, "input_timeout_s": 1.5},
        aggregator_params={"stall_timeout_s": 3.0},
    )
    diagnostics = tmp_path / "diagnostics.jsonl"
    probe = start_probe(ros_env, diagnostics)
    try:
        with Graph(spec, ros_env.env) as graph:
            graph.start()

            def pending() -> int:
                beats = [r for r in jsonl(diagnostics) if r["name"] == "ads_rca/controller/monitor"]
                return int(beats[-1]["values"]["pending"]) if beats else 0

            wait_for(lambda: pending() >= 15, 60, "frames held by the monitors")
            graph.processes["player"].process.kill()  # inputs stop mid-run
            stopped = time.monotonic()
            document = graph.wait_verdict(60, fail_fast=False)
            assert document is not None, graph.processes["aggregator"].output
            took = time.monotonic() - stopped
            graph.stop()
    finally:
        probe.stop()
    assert took < 30
    live = document["live"]
    assert live["complete"] is False
    assert any("stalled" in why for why in live["why_incomplete"]), live
    assert document["frames"], (document["live"], document["modules"])
    stale = [
        r
        for r in jsonl(diagnostics)
        if r["level"] == STALE and r["name"] in {f"ads_rca/{m}" for m in MODULES}
    ]
    assert any("no input" in r["message"] for r in stale), "monitors did not report STALE"


def _stream(path: Path) -> dict[str, list[dict[str, Any]]]:
    # run: each replay's own id; revision: 1 where the frame was first judged provisionally
    volatile = {"compute_s", "wait_s", "arrived_s", "session", "run", "revision"}
    out: dict[str, list[dict[str, Any]]] = {m: [] for m in MODULES}
    for row in jsonl(path):  # the final results: which frames were judged provisionally
        if not row.get("provisional"):  # first depends on when the collision frame came
            out[row["module"]].append({k: v for k, v in row.items() if k not in volatile})
    return out


@pytest.mark.slow
def test_three_replays_give_identical_metric_streams_and_verdicts(
    ros_env: RosEnv, tmp_path: Path, log_dirs: Callable[[str, str], Path]
) -> None:
    log_dir = log_dirs("lead_braking", "prediction")
    streams, verdicts = [], []
    for run in range(3):
        spec = GraphSpec(
            log_dir,
            make_params("corrected"),
            tmp_path / f"verdict{run}.json",
            namespace=f"{ros_env.namespace}_{run}",
            metrics_log=tmp_path / f"metrics{run}.jsonl",
        )
        with Graph(spec, ros_env.env) as graph:
            graph.start()
            document = graph.wait_verdict(90)
            assert document is not None, graph.processes["aggregator"].output
            graph.stop()
        document.pop("verdict_latency_s")
        document.pop("verdict_latency_from")  # which node saw the frame first: a race
        assert document["live"].pop("run") == spec.run_id
        verdicts.append(document)
        streams.append(_stream(tmp_path / f"metrics{run}.jsonl"))
    assert all(len(streams[0][m]) == len(read_run_log(log_dir).frames) for m in MODULES)
    assert streams[0] == streams[1] == streams[2]
    assert verdicts[0] == verdicts[1] == verdicts[2]


def test_monitor_accepts_a_params_file(ros_env: RosEnv, tmp_path: Path) -> None:
    """``--params-file config/rca_reference.yaml`` sets the mode, like ``diagnose --config``."""
    config = Path(__file__).parents[1] / "config" / "rca_reference.yaml"
    argv = [sys.executable, "-m", "ads_rca.ros.monitor", "planning_monitor"]
    argv += ros_args({"effect_time_window": 7}, config)
    node = ManagedProcess("planning_monitor", argv, ros_env.env)
    try:
        wait_for(lambda: "semantics reference" in node.output, 20, "the monitor to start")
    finally:
        assert node.stop() == 0


def test_monitors_process_refuses_nodes_with_different_parameters(ros_env: RosEnv) -> None:
    """The four nodes of ``monitors`` share one window: per-node engine values are refused."""
    argv = [sys.executable, "-m", "ads_rca.ros.monitor", "monitors", "--ros-args"]
    argv += ["-p", "perception_monitor:effect_time_window:=7"]
    node = ManagedProcess("monitors", argv, ros_env.env)
    assert node.wait(60) == 2, node.output
    errors = [line for line in node.lines if "[ERROR]" in line]
    assert len(errors) == 1, node.output
    assert "parameters differ (params)" in errors[0]
    assert "Traceback" not in node.output
