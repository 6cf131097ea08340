"""Runs keep apart, and replay leaves nothing behind.

- two ``ads-rca replay`` of different logs at once on ONE domain and ONE namespace each give
  their own ``diagnose`` verdict; a graph's aggregator, monitors and recorder ignore a
  foreign player playing another log next to it;
- ``replay`` takes ROS_DOMAIN_ID from the environment, and otherwise a domain whose RTPS
  ports nobody holds;
- SIGTERM, SIGINT, SIGHUP or SIGKILL to ``replay`` mid-run: within a bounded wait no node
  process remains and no ``ads_rca_replay_*`` folder is left in its TMPDIR;
- a launcher killed with SIGKILL takes its nodes with it (parent-death signal, no reaper);
- SIGINT or SIGTERM to a player is a clean exit, no traceback.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import pytest
from rosrun import wait_for
from synthlogs import synth
from verdicts import assert_close, failed_flags, verdict_keys

from ads_rca.contract import topics
from ads_rca.diagnosis.engine import diagnose
from ads_rca.live import diagnostics as diag
from ads_rca.live.runid import RunFilter, writer_prefix
from ads_rca.params import make_params
from ads_rca.ros.domains import domains_in_use, free_domain_id
from ads_rca.ros.graph import Graph, GraphSpec
from ads_rca.ros.launcher import ManagedProcess, node_command
from ads_rca.sources.log.reader import read_run_log
from ads_rca.sources.log.writer import write_run_log
from ads_rca.sources.registry import open_run

if TYPE_CHECKING:
    from conftest import RosEnv

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "cut_in_perception"
pytestmark = pytest.mark.timeout(240)


def ours_on_domain(domain_id: int) -> list[int]:
    """Live processes of this package (besides us) on ``domain_id``, found through /proc."""
    marker = f"ROS_DOMAIN_ID={domain_id}".encode()
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        try:
            environ = (entry / "environ").read_bytes().split(b"\0")
            cmdline = (entry / "cmdline").read_bytes()
            state = (entry / "stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            continue
        if state != "Z" and marker in environ and b"ads_rca" in cmdline:
            found.append(int(entry.name))
    return found


def kill_leftovers(domain_id: int) -> None:
    for pid in ours_on_domain(domain_id):
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)


def matches_diagnose(document: dict[str, Any], log_dir: Path, output: str = "") -> None:
    offline = diagnose(read_run_log(log_dir), make_params("corrected")).to_json()
    assert document["live"]["complete"], (document["live"], output)
    assert document["verdict"] == offline["verdict"]
    assert failed_flags(document) == failed_flags(offline)
    assert_close(verdict_keys(document), verdict_keys(offline))


# --- runs keep apart ----------------------------------------------------------------------


def test_two_replays_on_one_domain_and_namespace_give_their_own_verdicts(
    ros_env: RosEnv, tmp_path: Path, log_dirs: Callable[[str, str], Path]
) -> None:
    logs = [log_dirs("cut_in", "perception"), log_dirs("lead_braking", "prediction")]
    replays = []
    for n, log_dir in enumerate(logs):
        argv = [sys.executable, "-m", "ads_rca.cli", "replay", str(log_dir)]
        argv += ["--json", str(tmp_path / f"v{n}.json"), "--timeout", "120", "--verbose"]
        # Same domain (the test's, from the environment), same (default) namespace.
        replays.append(ManagedProcess(f"replay{n}", argv, ros_env.env))
    try:
        for replay in replays:
            assert replay.wait(180) == 0, replay.output
            assert f"ROS_DOMAIN_ID={ros_env.domain_id} (from ROS_DOMAIN_ID)" in replay.output
    finally:
        for replay in replays:
            replay.stop()
    verdicts = [json.loads((tmp_path / f"v{n}.json").read_text()) for n in range(2)]
    assert verdicts[0]["verdict"] != verdicts[1]["verdict"]  # the test can tell them apart
    for document, log_dir, replay in zip(verdicts, logs, replays, strict=True):
        matches_diagnose(document, log_dir, replay.output)
    assert verdicts[0]["live"]["run"] != verdicts[1]["live"]["run"]


@pytest.mark.slow
def test_graph_ignores_a_foreign_player_on_its_namespace(
    ros_env: RosEnv, tmp_path: Path, log_dirs: Callable[[str, str], Path]
) -> None:
    """Aggregator, monitors and recorder of one run next to a player of another log."""
    ours, theirs = log_dirs("pedestrian_crossing", "planning"), log_dirs("left_turn", "controller")
    ns = ros_env.namespace
    foreign_argv = node_command(
        "ads_rca.ros.player",
        {"log_path": str(theirs), "rate": 0.0, "topic_namespace": ns, "loop": True},
    )
    foreign = ManagedProcess("foreign", foreign_argv, ros_env.env)
    bag = tmp_path / "bag"
    spec = GraphSpec(
        ours,
        make_params("corrected"),
        tmp_path / "verdict.json",
        namespace=ns,
        record=bag,
        metrics_log=tmp_path / "metrics.jsonl",
    )
    try:
        with Graph(spec, ros_env.env) as graph:
            graph.start()
            document = graph.wait_verdict(120)
            assert document is not None, graph.processes["aggregator"].output
            graph.stop()
    finally:
        foreign.stop()
    matches_diagnose(document, ours)
    assert document["live"]["run"] == spec.run_id
    rows = [json.loads(line) for line in (tmp_path / "metrics.jsonl").read_text().splitlines()]
    assert rows and {row["run"] for row in rows} == {spec.run_id}
    # The bag holds our run only: its log, one metadata message naming our run.
    recorded = open_run(bag)
    assert recorded.frames == read_run_log(ours).frames
    from rosbags.highlevel import AnyReader

    with AnyReader([bag]) as reader:
        metadata = [
            # rosbags types a message as object; this topic's is a std_msgs/String
            json.loads(cast(Any, reader.deserialize(raw, c.msgtype)).data)
            for c, _t, raw in reader.messages()
            if c.topic == topics.topic_name(topics.METADATA, ns)
        ]
    assert metadata and {m["run"] for m in metadata} == {spec.run_id}


def test_run_filter_locks_onto_one_run_and_its_player(tmp_path: Path) -> None:
    def info(prefix: bytes, entity: bytes = b"\0\0\x13\x03") -> dict[str, Any]:
        gid = {"implementation_identifier": "rmw_fastrtps_cpp", "data": prefix + entity}
        return {"publisher_gid": gid}

    a, b = b"A" * 12, b"B" * 12
    runs = RunFilter()
    assert runs.accept({"index": 0})  # nothing named yet: taken as before
    assert runs.accept({"run": "one"}, info(a), player=True) and runs.run == "one"
    assert not runs.accept({"run": "two"}, info(b), player=True)
    assert not runs.accept({"index": 1})  # once locked, a message naming no run is not ours
    assert runs.accept_data(info(a, b"\0\0\x14\x03")) and not runs.accept_data(info(b))
    assert runs.accept_run("one") and not runs.accept_run("") and not runs.accept_run("two")
    given = RunFilter("two")
    assert not given.accept({"run": "one"}, info(a), player=True)
    assert given.accept({"run": "two"}, info(b), player=True) and given.player == b
    # An rmw whose GIDs do not carry the participant: no data filtering (documented).
    assert writer_prefix({"publisher_gid": {"implementation_identifier": "rmw_zenoh_cpp"}}) is None
    statuses = [
        diag.simple_status("ads_rca/planning/monitor", diag.OK, "", "h", {"run": "one"}),
        diag.simple_status("ads_rca/planning", diag.OK, "", "h", {}),
    ]
    assert diag.status_runs(diag.encode_array(0, statuses)) == [
        ("ads_rca/planning/monitor", "one"),
        ("ads_rca/planning", ""),
    ]


def test_a_free_domain_has_no_participant(ros_env: RosEnv, tmp_path: Path) -> None:
    """A domain with a participant on it (a waiting player) is never picked."""
    waiting = ManagedProcess(
        "holder",
        node_command(
            "ads_rca.ros.player",
            {
                "log_path": str(write_run_log(synth("cut_in", "perception"), tmp_path / "log")),
                "wait_for_subscribers": 1,
                "wait_timeout_s": 60.0,
            },
        ),
        ros_env.env,
    )
    try:
        wait_for(lambda: ros_env.domain_id in domains_in_use(), 30, "the holder's ports")
        picked = free_domain_id(start=ros_env.domain_id)
        assert picked is not None and picked != ros_env.domain_id
        assert picked not in domains_in_use()
        assert free_domain_id(in_use=set(range(0, 233))) is None
    finally:
        waiting.stop()


# --- replay leaves nothing behind ---------------------------------------------------------


@pytest.mark.parametrize("sig", ["SIGTERM", "SIGINT", "SIGHUP", "SIGKILL"])
def test_a_stopped_replay_leaves_no_process_and_no_folder(
    ros_env: RosEnv, tmp_path: Path, log_dirs: Callable[[str, str], Path], sig: str
) -> None:
    private = tmp_path / "tmp"
    private.mkdir()
    env = {**ros_env.env, "TMPDIR": str(private)}
    argv = [sys.executable, "-m", "ads_rca.cli", "replay", str(log_dirs("cut_in", "perception"))]
    domain = ros_env.domain_id
    argv += ["--rate", "0.2", "--verbose", "--timeout", "120", "--domain-id", str(domain)]
    replay = ManagedProcess("replay", argv, env)
    try:
        # Mid-run: the player has loaded the log and the other nodes are up.
        wait_for(lambda: "[player]" in replay.output, 60, "the player to start")
        wait_for(lambda: len(ours_on_domain(domain)) >= 3, 30, "the nodes")
        assert list(private.glob("ads_rca_replay_*")), "no work folder to check"
        replay.process.send_signal(getattr(signal, sig))
        code = replay.wait(60)
        assert code is not None, "replay did not exit"
        if sig != "SIGKILL":
            assert code == 128 + getattr(signal, sig), replay.output
            assert "Traceback" not in replay.output, replay.output
        wait_for(lambda: not ours_on_domain(domain), 40, f"no node left after {sig}")
        wait_for(lambda: not list(private.glob("ads_rca_replay_*")), 20, "the folder removed")
    finally:
        replay.stop()
        kill_leftovers(domain)


def test_nodes_die_with_a_killed_launcher(ros_env: RosEnv, tmp_path: Path) -> None:
    """No reaper here: the parent-death signal alone stops the node."""
    script = (
        "import sys, time\n"
        "from ads_rca.ros.launcher import Launcher, node_command\n"
        "launcher = Launcher()\n"
        "launcher.start('aggregator', node_command('ads_rca.ros.aggregator'))\n"
        "print('started', flush=True)\n"
        "time.sleep(120)\n"
    )
    parent = ManagedProcess("parent", [sys.executable, "-c", script], ros_env.env)
    try:
        wait_for(lambda: "started" in parent.output, 30, "the launcher")
        wait_for(
            lambda: any(b"aggregator" in _cmdline(p) for p in ours_on_domain(ros_env.domain_id)),
            30,
            "the aggregator",
        )
        parent.process.send_signal(signal.SIGKILL)
        parent.wait(10)
        wait_for(lambda: not ours_on_domain(ros_env.domain_id), 30, "the orphaned aggregator gone")
    finally:
        parent.stop()
        kill_leftovers(ros_env.domain_id)


def _cmdline(pid: int) -> bytes:
    try:
        return (Path("/proc") / str(pid) / "cmdline").read_bytes()
    except OSError:
        return b""


@pytest.mark.parametrize("sig", ["SIGINT", "SIGTERM"])
def test_a_stop_signal_ends_a_player_cleanly(ros_env: RosEnv, tmp_path: Path, sig: str) -> None:
    """SIGTERM (what replay's escalation and the parent-death signal send) shuts rclpy's
    context down under the player's feet: it used to end in an RCLError traceback."""
    log_dir = write_run_log(synth("cut_in", "perception"), tmp_path / "log")
    argv = node_command(
        "ads_rca.ros.player",
        {"log_path": str(log_dir), "wait_for_subscribers": 1, "wait_timeout_s": 60.0},
    )
    player = ManagedProcess("player", argv, ros_env.env)
    try:
        wait_for(lambda: "analysed frames" in player.output, 60, "the player waiting")
        player.process.send_signal(getattr(signal, sig))
        assert player.wait(20) == 0, player.output
        assert "Traceback" not in player.output, player.output
    finally:
        player.stop()


@pytest.mark.parametrize(
    ("run_id", "said"),
    [
        ("x/../y z!", "run_id must be 1 to 64 letters"),  # valid YAML, not a topic name
        ("y\x1b[2J", "bad ROS arguments"),  # rcl cannot parse it at all
    ],
)
@pytest.mark.parametrize(
    "node", ["ads_rca.ros.player", "ads_rca.ros.aggregator", "ads_rca.ros.recorder", "monitors"]
)
def test_a_hostile_run_id_is_one_line_and_exit_2(
    ros_env: RosEnv, tmp_path: Path, node: str, run_id: str, said: str
) -> None:
    """``run_id`` becomes part of a topic name (``run/ready_<id>``): a hostile one is refused
    at start in one line (escaped), never an rclpy traceback."""
    from ads_rca.ros.graph import GROUP
    from ads_rca.ros.launcher import ros_args

    params: dict[str, Any] = {"run_id": run_id, "topic_namespace": ros_env.namespace}
    if node == "ads_rca.ros.player":
        params["log_path"] = str(EXAMPLE)
    if node == "ads_rca.ros.recorder":
        params["output"] = str(tmp_path / "bag")
    argv = [sys.executable, "-m", node, *ros_args(params)]
    if node == "monitors":
        argv = [sys.executable, "-m", "ads_rca.ros.monitor", GROUP, *ros_args(params)]
    process = ManagedProcess(node, argv, ros_env.env)
    code = process.wait(60)
    output = process.output
    process.stop()
    assert code == 2, output
    assert "Traceback" not in output and "\x1b[" not in output.replace("\\x1b", ""), output
    assert said in output, output
