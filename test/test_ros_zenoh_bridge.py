"""The Zenoh bridge over real DDS and real Zenoh sessions on loopback, every part its own process.

- ``ads-rca replay --zenoh``: a listener process with no rclpy import receives every frame's
  result of every module and the verdict, identical to what the replay and ``diagnose``
  say; the raw CDR samples decode with rosbags into the original messages; a dashboard
  that connects after the verdict gets it, and the frames it missed, from the queryables;
  with the default linger, ``watch`` started after the replay printed its verdict gets it,
  and Ctrl-C during the linger loses nothing (status 0, JSON and bag complete);
- the bridge node on its own survives its Zenoh peer going away and coming back, counts a
  malformed result instead of forwarding it, and stops cleanly (exit 0, session closed)
  on SIGINT and on SIGTERM;
- bad parameters and options are one line and exit 2, before any session opens.
"""

from __future__ import annotations

import base64
import json
import re
import signal
import socket
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest
from headless import chromium, wait_for_connection
from logcompare import assert_logs_equal
from loopback import free_port
from rosbags.typesys import Stores, get_typestore
from rosrun import listener, rows, wait_for
from verdicts import failed_flags, verdict_keys

from ads_rca.contract.live_topics import metrics_qos
from ads_rca.diagnosis.engine import diagnose
from ads_rca.foundation import strictjson
from ads_rca.oracles.base import MODULES
from ads_rca.params import make_params
from ads_rca.ros.launcher import ManagedProcess, ros_args
from ads_rca.sources.bag.reader import read_bag
from ads_rca.sources.log.reader import read_run_log

if TYPE_CHECKING:
    from conftest import RosEnv

pytestmark = pytest.mark.timeout(180)

TYPESTORE = get_typestore(Stores.ROS2_KILTED)


@pytest.mark.slow
def test_replay_over_zenoh_gives_every_result_the_verdict_and_late_catch_up(
    ros_env: RosEnv, tmp_path: Path, log_dirs: Callable[[str, str], Path]
) -> None:
    log_dir = log_dirs("cut_in", "perception")
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    live_rows, late_rows = tmp_path / "live.jsonl", tmp_path / "late.jsonl"
    end_rows = tmp_path / "end.jsonl"
    remote = listener(ros_env.env, live_rows, "--connect", endpoint, "--until-verdict")
    out = tmp_path / "verdict.json"
    argv = [sys.executable, "-m", "ads_rca.cli", "replay", str(log_dir), "--json", str(out)]
    argv += ["--domain-id", str(ros_env.domain_id), "--namespace", ros_env.namespace]
    argv += ["--zenoh", "--zenoh-listen", endpoint, "--zenoh-prefix", "car1"]
    argv += ["--rate-modules", "0", "--zenoh-linger", "20", "--timeout", "90"]
    replay = ManagedProcess("replay", argv, ros_env.env)
    try:
        assert remote.wait(120) == 0, remote.output
        # Late: the verdict is out; the bridge lingers and answers the queryables.
        late = listener(
            ros_env.env,
            late_rows,
            *("--connect", endpoint, "--timeout", "3"),
            *("--query", "car1/ads_rca/verdict", "--query", "car1/ads_rca/frames?since=40"),
        )
        assert late.wait(60) == 0, late.output
        # Until the bridge ends: its last heartbeat says it stopped, the verdict out or not.
        ending = listener(ros_env.env, end_rows, "--connect", endpoint, "--timeout", "60")
        assert replay.wait(120) == 0, replay.output
        ending.signal(signal.SIGTERM)
        ending.wait(10)
    finally:
        replay.stop()
    heartbeats = [r for r in rows(end_rows) if r.get("key") == "car1/ads_rca/status.json"]
    assert heartbeats and strictjson.loads(heartbeats[-1]["text"])["state"] == "stopped"
    live = json.loads(out.read_text())
    offline = diagnose(read_run_log(log_dir), make_params("corrected")).to_json()
    received = rows(live_rows)
    assert received[-1] == {"end": True, "rclpy_loaded": False}
    frames = len(live["frames"])

    # Every module's result of every frame, and the verdict: the replay's document.
    results: dict[str, dict[int, dict[str, Any]]] = {m: {} for m in MODULES}
    verdicts = []
    for row in received[:-1]:
        if row["key"].startswith("car1/ads_rca/modules/"):
            document = strictjson.loads(row["text"])
            results[document["module"]][document["index"]] = document
        elif row["key"] == "car1/ads_rca/verdict.json":
            verdicts.append(json.loads(row["text"]))  # strict form: NaN never equals NaN
    for module in MODULES:
        assert sorted(results[module]) == list(range(frames)), module
        flags = [results[module][i]["failed"] for i in range(frames)]
        assert flags == [f[module]["failed"] for f in live["frames"]], module
    assert len(verdicts) == 1
    assert sorted(k for k in {*live, *verdicts[0]} if verdicts[0].get(k) != live.get(k)) == []
    assert failed_flags(verdicts[0]) == failed_flags(offline)
    assert verdict_keys(verdicts[0])["primary_root_cause"] == offline["primary_root_cause"]

    # Raw CDR under the zenoh-bridge-ros2dds keys decodes into the original messages.
    ns = ros_env.namespace.strip("/")
    raw = {r["key"]: r for r in received[:-1] if "b64" in r}
    verdict_raw = raw[f"car1/{ns}/verdict"]
    assert verdict_raw["encoding"] == "application/cdr;diagnostic_msgs/msg/DiagnosticArray"
    array: Any = TYPESTORE.deserialize_cdr(
        base64.b64decode(verdict_raw["b64"]), "diagnostic_msgs/msg/DiagnosticArray"
    )
    assert offline["primary_root_cause"] in array.status[0].message
    text: Any = TYPESTORE.deserialize_cdr(
        base64.b64decode(raw[f"car1/{ns}/verdict/json"]["b64"]), "std_msgs/msg/String"
    )
    assert json.loads(text.data) == live
    metrics = [r for r in received[:-1] if r["key"] == f"car1/{ns}/metrics/planning"]
    strings: list[Any] = [
        TYPESTORE.deserialize_cdr(base64.b64decode(r["b64"]), "std_msgs/msg/String")
        for r in metrics
    ]
    texts = [message.data for message in strings]
    # Each frame's final result, after the provisional ones the replay showed as it played.
    assert sum(not json.loads(t).get("provisional") for t in texts) == frames
    last: Any = TYPESTORE.deserialize_cdr(
        base64.b64decode(metrics[-1]["b64"]), "std_msgs/msg/String"
    )
    assert json.loads(last.data) == json.loads(strictjson.dumps(results["planning"][frames - 1]))

    # The late dashboard: the verdict and the frames after 40 from the queryables.
    replies = {r["key"]: r for r in rows(late_rows) if r.get("reply")}
    assert json.loads(replies["car1/ads_rca/verdict"]["text"]) == live
    history = strictjson.loads(replies["car1/ads_rca/frames"]["text"])
    assert [f["index"] for f in history["frames"]] == list(range(41, frames))
    assert set(history["frames"][-1]["modules"]) == set(MODULES)


@pytest.mark.slow
def test_watch_started_after_the_verdict_gets_it_and_ctrl_c_in_the_linger_loses_nothing(
    ros_env: RosEnv, tmp_path: Path, log_dirs: Callable[[str, str], Path]
) -> None:
    """``replay --zenoh`` with the default linger (30 s): every output is written and every
    other node stopped before the bridge lingers, so ``watch`` started after the replay
    printed its verdict gets it, and Ctrl-C then ends the replay with the run's status (0),
    the JSON as printed and the recording finalised. Before, the bridge was gone 2 s after
    the verdict and such a ``watch`` timed out (exit 3)."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    log_dir = log_dirs("cut_in", "perception")
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    out, bag = tmp_path / "verdict.json", tmp_path / "bag"
    argv = [sys.executable, "-m", "ads_rca.cli", "replay", str(log_dir), "--json", str(out)]
    argv += ["--record", str(bag), "--domain-id", str(ros_env.domain_id)]
    argv += ["--namespace", ros_env.namespace, "--zenoh", "--zenoh-listen", endpoint]
    replay = ManagedProcess("replay", [*argv, "--timeout", "90"], ros_env.env)
    watch_argv = [sys.executable, "-m", "ads_rca.cli", "watch", "--json", "--exit-on-verdict"]
    watch_argv += ["--timeout", "20", "--connect", endpoint]
    watch: ManagedProcess | None = None
    try:

        def serving() -> str | None:
            return next((x for x in list(replay.lines) if "late dashboards on" in x), None)

        line = wait_for(serving, 90, "the replay to serve late dashboards")
        assert f"on {endpoint} for 30 s" in line, replay.output
        assert out.is_file() and (bag / "verdict.json").is_file()
        watch = ManagedProcess("watch", watch_argv, ros_env.env)
        assert watch.wait(60) == 0, watch.output
        assert replay.returncode is None, replay.output  # still lingering
        replay.signal(signal.SIGINT)
        assert replay.wait(30) == 0, replay.output
    finally:
        for process in (watch, replay):
            if process is not None:
                process.stop()
    printed = json.loads(out.read_text())
    assert f"verdict: {printed['verdict']}  [{printed['attribution_basis']}]" in replay.lines
    assert json.loads((bag / "verdict.json").read_text()) == printed
    assert "stopped by SIGINT while serving late dashboards" in replay.output
    final = [json.loads(x) for x in watch.output.splitlines() if x.startswith("{")][-1]
    assert final["kind"] == "final"
    assert final["primary_root_cause"] == printed["primary_root_cause"] is not None
    # The recording is finalised (summary and metadata), its verdict the one printed, and
    # it rebuilds the log that was played.
    assert (bag / "metadata.yaml").is_file()
    with next(bag.glob("*.mcap")).open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        topic = f"{ros_env.namespace}/verdict/json"
        recorded = [m.data for _s, _c, _r, m in reader.iter_decoded_messages(topics=[topic])]
    assert summary is not None and summary.statistics is not None
    assert summary.statistics.message_count > 0
    assert [json.loads(text) for text in recorded] == [printed]
    assert_logs_equal(read_run_log(log_dir), read_bag(bag))


def bridge_process(ros_env: RosEnv, name: str, **params: Any) -> ManagedProcess:
    values = {"topic_namespace": ros_env.namespace, "heartbeat_s": 0.2, **params}
    argv = [sys.executable, "-m", "ads_rca.ros.zenoh_bridge", *ros_args(values)]
    return ManagedProcess(name, argv, ros_env.env)


@pytest.mark.parametrize("stop", [signal.SIGINT, signal.SIGTERM])
def test_bridge_survives_its_peer_going_away_and_stops_cleanly(
    ros_env: RosEnv, tmp_path: Path, stop: signal.Signals
) -> None:
    import rclpy
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from std_msgs.msg import String

    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    peer_rows = [tmp_path / "peer1.jsonl", tmp_path / "peer2.jsonl"]
    peer = listener(ros_env.env, peer_rows[0], "--listen", endpoint, "--timeout", "60")
    bridge = bridge_process(
        ros_env,
        "bridge",
        zenoh_connect=(endpoint,),
        zenoh_listen=(f"tcp/127.0.0.1:{free_port()}",),
        zenoh_prefix="car1",
        bridge_topics=("chatter", "metrics/perception"),
    )
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node("talker", context=context)
    qos = QoSProfile(
        depth=10, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE
    )
    chatter = node.create_publisher(String, f"{ros_env.namespace}/chatter", qos)
    results = node.create_publisher(  # as a monitor publishes: latched for late readers
        String, f"{ros_env.namespace}/metrics/perception", metrics_qos()
    )
    sent = iter(range(10_000))

    def seen(path: Path, count: int = 1) -> bool:
        chatter.publish(String(data=f"hello {next(sent)}"))
        time.sleep(0.05)
        found = [r for r in rows(path)[:-1] if r.get("key") == "car1" + chatter.topic_name]
        return len(found) >= count

    try:
        wait_for(lambda: seen(peer_rows[0]), 30, "the first peer to get samples")
        results.publish(String(data="not a result {"))
        peer.signal(signal.SIGTERM)
        assert peer.wait(10) == 0, peer.output
        for _ in range(20):  # the peer is gone: the bridge keeps going
            chatter.publish(String(data="nobody listens"))
        time.sleep(0.5)
        assert bridge.returncode is None, bridge.output
        again = listener(ros_env.env, peer_rows[1], "--listen", endpoint, "--timeout", "60")
        wait_for(lambda: seen(peer_rows[1], 3), 30, "the bridge to reach the new peer")

        def status() -> dict[str, Any] | None:
            for row in reversed(rows(peer_rows[1])[:-1]):
                if row.get("key") == "car1/ads_rca/status.json":
                    found: dict[str, Any] = strictjson.loads(row["text"])
                    return found
            return None

        report = wait_for(status, 10, "a status heartbeat")
        assert report["malformed"] == 1 and "result" in report["last_problem"]
        started = time.monotonic()
        bridge.signal(stop)
        assert bridge.wait(10) == 0, bridge.output
        assert time.monotonic() - started < 5
        assert "Traceback" not in bridge.output
        assert "bridged" in bridge.output

        # Its last heartbeat says it stopped (it said "verdict" when it had forwarded one).
        def last_state() -> object:
            found = [r for r in rows(peer_rows[1]) if r.get("key") == "car1/ads_rca/status.json"]
            return found and strictjson.loads(found[-1]["text"]).get("state") == "stopped"

        wait_for(last_state, 10, "a last heartbeat saying stopped")
        again.signal(signal.SIGTERM)
        assert again.wait(10) == 0, again.output
    finally:
        node.destroy_node()
        rclpy.shutdown(context=context)
        for process in (bridge, peer):
            process.stop()


@pytest.mark.parametrize(
    ("params", "message"),
    [
        (
            {"zenoh_listen": ("tcp/0.0.0.0:7447",)},
            "not on loopback; give -p zenoh_allow_remote:=true",
        ),
        ({"zenoh_listen": ("http://x",)}, "is not PROTOCOL/HOST:PORT"),
        ({"zenoh_mode": "router"}, "is not one of peer, client"),
        ({"zenoh_mode": "client"}, "give at least one connect endpoint"),
        ({"zenoh_prefix": "car/*/x"}, "chunk '*'"),
        ({"bridge_topics": ("a b",)}, "chunk 'a b'"),
        ({"rate_modules": -1.0}, "rate_modules: -1 is out of range"),
        ({"history_frames": 0}, "history_frames: 0 is out of range"),
        ({"linger_s": -1.0}, "linger_s: -1 is out of range [0, inf] s"),
        ({"linger_s": "soon"}, "linger_s: 'soon' is not a number"),
        ({"zenoh_listen": ("tcp/127.0.0.1:{busy}",)}, "cannot open the Zenoh session"),
    ],
)
def test_bad_bridge_parameters_are_one_line_and_exit_2(
    ros_env: RosEnv, params: dict[str, Any], message: str
) -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        values = {
            k: tuple(x.format(busy=port) for x in v) if isinstance(v, tuple) else v
            for k, v in params.items()
        }
        bridge = bridge_process(ros_env, "bridge", **values)
        assert bridge.wait(30) == 2, bridge.output
    errors = [line for line in bridge.output.splitlines() if "ERROR" in line]
    assert len(errors) == 1 and message in errors[0], bridge.output
    assert "Traceback" not in bridge.output


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (["--zenoh-listen", "tcp/192.0.2.1:7447"], "not on loopback; give --zenoh-allow-remote"),
        (["--zenoh-connect", "tcp/127.0.0.1:99999"], "out of range"),
        (["--zenoh-prefix", "a/$x"], "chunk '$x'"),
        (["--rate-modules", "nan"], "rate_modules"),
        (["--zenoh-linger", "-1"], "zenoh_linger"),
        (["--zenoh-linger=-inf"], "zenoh_linger: -inf is out of range [0, inf] s"),
        (["--zenoh-linger", "nan"], "zenoh_linger: nan is out of range"),
        (["--zenoh-linger", "soon"], "zenoh_linger: 'soon' is not a number"),
        (["--zenoh-linger", ""], "zenoh_linger: '' is not a number"),
    ],
)
def test_bad_replay_zenoh_options_are_one_line_before_any_node(
    ros_env: RosEnv, log_dirs: Callable[[str, str], Path], options: list[str], message: str
) -> None:
    argv = [sys.executable, "-m", "ads_rca.cli", "replay", str(log_dirs("cut_in", "none"))]
    argv += ["--domain-id", str(ros_env.domain_id), "--zenoh", *options]
    replay = ManagedProcess("replay", argv, ros_env.env)
    assert replay.wait(30) == 2, replay.output
    lines = [line for line in replay.output.splitlines() if line.strip()]
    assert len(lines) == 1 and message in lines[0], replay.output


@contextmanager
def watch_and_replay(
    ros_env: RosEnv, log_dir: Path, options: Sequence[str] = (), endpoint: str = ""
) -> Iterator[tuple[ManagedProcess, ManagedProcess]]:
    """``watch --json --exit-on-verdict`` started first, then ``replay --zenoh`` of
    ``log_dir`` (with ``options``) on ``endpoint`` (a free port by default); after the
    block, ``watch`` must end with status 0, and the replay too once Ctrl-C ended its
    bridge's linger (both are stopped however the block ends)."""
    endpoint = endpoint or f"tcp/127.0.0.1:{free_port()}"
    watch_argv = [sys.executable, "-m", "ads_rca.cli", "watch", "--connect", endpoint]
    watch = ManagedProcess("watch", [*watch_argv, "--json", "--exit-on-verdict"], ros_env.env)
    argv = [sys.executable, "-m", "ads_rca.cli", "replay", str(log_dir), *options]
    argv += ["--domain-id", str(ros_env.domain_id), "--namespace", ros_env.namespace]
    argv += ["--zenoh", "--zenoh-listen", endpoint, "--zenoh-linger", "10", "--timeout", "90"]
    replay = ManagedProcess("replay", argv, ros_env.env)
    try:
        yield watch, replay
        assert watch.wait(120) == 0, watch.output
        # The replay's outputs are written before its bridge lingers: end the linger.
        wait_for(lambda: "late dashboards on" in replay.output, 60, "the replay's linger")
        replay.signal(signal.SIGINT)
        assert replay.wait(60) == 0, replay.output
    finally:
        for process in (watch, replay):
            process.stop()


@pytest.mark.slow
def test_watch_started_before_a_rate_limited_replay_ends_with_every_frame_counted(
    ros_env: RosEnv, tmp_path: Path, log_dirs: Callable[[str, str], Path]
) -> None:
    """The bridge's default rate limits send a few of each module's results live; once the
    verdict is in, ``watch`` fetches the rest from the frame history before its final
    digest, so its counts are the run's."""
    log_dir = log_dirs("cut_in", "perception")
    with watch_and_replay(ros_env, log_dir) as (watch, _replay):
        pass  # until both end
    events = [json.loads(line) for line in watch.output.splitlines() if line.startswith("{")]
    live = [e for e in events if e["kind"] == "module"]
    final = assert_final_digest_is_diagnoses(events, log_dir)
    assert len(live) < 4 * (final["last_index"] + 1)  # rate-limited live
    assert final["semantics"] == "corrected"
    for module in MODULES:  # the blamed module is said so, never "ok"
        blamed = module == final["primary_root_cause"]
        states = ("root cause",) if blamed else ("ok", "failing", "skipped")
        assert final["modules"][module]["state"] in states, module


def assert_final_digest_is_diagnoses(events: list[dict[str, Any]], log_dir: Path) -> Any:
    """``watch --json``'s final digest: diagnose's root cause, and each module's frames
    judged and failed counted once each (a frame judged again is not counted twice)."""
    final = next(e for e in events if e["kind"] == "final")
    offline = diagnose(read_run_log(log_dir), make_params("corrected")).to_json()
    assert final["primary_root_cause"] == offline["primary_root_cause"]
    frames = len(offline["frames"])
    for module in MODULES:
        failed = sum(bool(f[module]["failed"]) for f in offline["frames"])
        counts = {k: final["modules"][module][k] for k in ("judged", "failed_frames")}
        assert counts == {"judged": frames, "failed_frames": failed}, module
    return final


def test_the_bridge_starts_from_its_config_file(ros_env: RosEnv) -> None:
    """rcl's own params-file parser reads config/zenoh_bridge.yaml (it refuses what plain
    YAML accepts, e.g. an empty list or an unquoted endpoint in a flow list)."""
    config = Path(__file__).resolve().parents[1] / "config" / "zenoh_bridge.yaml"
    endpoint = f'["tcp/127.0.0.1:{free_port()}"]'
    argv = [sys.executable, "-m", "ads_rca.ros.zenoh_bridge", "--ros-args"]
    argv += ["--params-file", str(config), "-p", f"zenoh_listen:={endpoint}"]
    bridge = ManagedProcess("bridge", argv, ros_env.env)
    try:
        wait_for(lambda: "parameters in force" in bridge.output, 30, "the bridge to start")
        assert "rate_modules=20.0" in bridge.output and "history_frames=2000" in bridge.output
        bridge.signal(signal.SIGINT)
        assert bridge.wait(10) == 0, bridge.output
    finally:
        bridge.stop()


@pytest.mark.parametrize("typed", ["inf", ".inf"])
def test_the_bridge_takes_an_endless_linger(ros_env: RosEnv, typed: str) -> None:
    """``linger_s`` inf (as typed, or as ``replay --zenoh-linger inf`` passes it): serve
    late dashboards until stopped, which still ends the bridge cleanly."""
    argv = [sys.executable, "-m", "ads_rca.ros.zenoh_bridge", "--ros-args"]
    argv += ["-p", "exit_after_verdict:=true", "-p", f"linger_s:={typed}"]
    argv += ["-p", f'zenoh_listen:=["tcp/127.0.0.1:{free_port()}"]']
    bridge = ManagedProcess("bridge", argv, ros_env.env)
    try:
        wait_for(lambda: "parameters in force" in bridge.output, 30, "the bridge to start")
        assert "linger_s=inf" in bridge.output
        bridge.signal(signal.SIGINT)
        assert bridge.wait(10) == 0, bridge.output
    finally:
        bridge.stop()


def test_results_reach_watch_and_the_page_while_a_replay_plays_at_log_rate(
    ros_env: RosEnv, tmp_path: Path, log_dirs: Callable[[str, str], Path]
) -> None:
    """A replay in `corrected` at log rate: the monitors judge each frame provisionally as
    it plays (the partner is read at the collision frame, the run's last), so results reach
    Zenoh, ``watch --json`` and the dashboard's page in chromium before the verdict, marked
    provisional; the final digest is diagnose's and the page ends on the verdict. Before,
    every result came within 0.2 s at the end."""
    log_dir = log_dirs("cut_in", "perception")
    out = tmp_path / "verdict.json"
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    options = ["--rate", "1", "--json", str(out), "--rate-modules", "0"]
    board = ManagedProcess(
        "dashboard",
        [sys.executable, "-m", "ads_rca.cli", "dashboard", "--port", "0", "--connect", endpoint],
        ros_env.env,
    )
    try:
        wait_for(lambda: "http://" in board.output, 30.0, "the dashboard's URL")
        url = re.search(r"http://\S+/", board.output)
        assert url is not None
        with (
            chromium() as browser,
            watch_and_replay(ros_env, log_dir, options, endpoint) as (
                watch,
                replay,
            ),
        ):
            page = browser.new_page()
            page.goto(url.group(0))

            def provisional_heard() -> bool:
                for line in list(watch.lines):
                    if line.startswith("{") and json.loads(line).get("kind") == "module":
                        document = json.loads(line).get("result") or {}
                        if document.get("provisional") is True:
                            return True
                return False

            wait_for(provisional_heard, 60.0, "a provisional result on watch --json")
            page.wait_for_function(
                """() => Array.from(document.querySelectorAll('#modules .status'))
                         .some((cell) => cell.textContent.endsWith('(provisional)'))""",
                timeout=60_000,
            )
            wait_for_connection(page, "live", 10_000, f"dashboard: {board.output}")
            assert not out.exists() and replay.returncode is None  # still playing
            primary = json.dumps(diagnose_primary(log_dir))
            page.wait_for_function(
                f"() => document.getElementById('verdict-primary').textContent === {primary}",
                timeout=90_000,
            )
            page.close()
    finally:
        board.stop()
    events = [json.loads(line) for line in watch.output.splitlines() if line.startswith("{")]
    assert_final_digest_is_diagnoses(events, log_dir)


def diagnose_primary(log_dir: Path) -> str:
    """The primary root cause ``diagnose`` names for ``log_dir``."""
    offline = diagnose(read_run_log(log_dir), make_params("corrected")).to_json()
    return str(offline["primary_root_cause"])


def test_a_busy_zenoh_port_is_refused_in_one_line_before_any_node(
    ros_env: RosEnv, log_dirs: Callable[[str, str], Path]
) -> None:
    """Another replay's bridge holds the port: the second replay's bridge could not listen,
    and the replay exited 1 after 17 s with no verdict. Now it is refused at once, naming
    the endpoint and the option to give."""
    port = free_port()
    with socket.socket() as holder:
        holder.bind(("127.0.0.1", port))
        holder.listen()
        argv = [sys.executable, "-m", "ads_rca.cli", "replay", str(log_dirs("cut_in", "none"))]
        argv += ["--domain-id", str(ros_env.domain_id), "--zenoh"]
        argv += ["--zenoh-listen", f"tcp/127.0.0.1:{port}"]
        replay = ManagedProcess("replay", argv, ros_env.env)
        assert replay.wait(30) == 2, replay.output
    lines = [line for line in replay.output.splitlines() if line.strip()]
    assert len(lines) == 1, replay.output
    assert f"tcp/127.0.0.1:{port}: in use" in lines[0] and "give --zenoh-listen" in lines[0]
