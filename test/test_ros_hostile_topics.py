"""Hostile messages on the contract's topics: anyone on the domain can publish.

- Every CDR decoder of the live path (``ads_rca.contract.cdr_decode``), fed real payloads (the
  project's own encoder on the example log) cut at every length, with absurd counts written
  over every 4-byte field and with random bytes flipped: a record, or ``CdrError``; nothing
  else, and no allocation for a count the message cannot hold (checked under an
  address-space limit, where allocating for it fails).
- JSON texts nested past the parsers' limit: one typed error (``JsonTextError``), never a
  RecursionError; in a bag, a Problem naming the message.
- Over real DDS: a real ``monitors`` process, fed a run by this test process (its player),
  gets malformed messages from the run's own participant (skipped, said once in its log,
  counted in its heartbeat, the rest judged) and from a foreign participant (dropped by the
  run filter before any decoding).
"""

from __future__ import annotations

import json
import random
import shutil
import struct
import subprocess
import sys
import textwrap
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest
from commandline import convert_example

from ads_rca.contract import cdr, cdr_decode, live_topics, playback, rosmsg, topics
from ads_rca.contract.errors import CdrError, JsonTextError, MalformedMessage, NoStamp
from ads_rca.contract.jsontext import loads_json
from ads_rca.contract.malformed import SkippedMessages
from ads_rca.errors import InputError
from ads_rca.live import diagnostics as diag
from ads_rca.ros.graph import GROUP, MONITORS
from ads_rca.ros.launcher import ManagedProcess, ParamValue, ros_args
from ads_rca.sources.bag.mcap_writer import McapBagWriter
from ads_rca.sources.bag.reader import iter_mcap_stream, read_bag
from ads_rca.sources.log.reader import read_run_log

if TYPE_CHECKING:
    from conftest import RosEnv

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "cut_in_perception"
ABSURD = (2**32 - 1, 2**31, 10**8, 65_537)


def real_payloads() -> dict[str, list[bytes]]:
    """Topic key → payloads the encoder makes from the example log (a few frames each)."""
    log = read_run_log(EXAMPLE)
    out: dict[str, list[bytes]] = {}
    for stamp in log.frames[::20]:
        for key, data in topics.frame_payloads(log, stamp).items():
            out.setdefault(key, []).append(data)
    out[topics.CLOCK] = [cdr.encode_clock(log.frames[3])]
    out[topics.METADATA] = [cdr.encode_string(playback.metadata_message(log).data)]
    return out


def decoders(key: str) -> list[Any]:
    """Every decoder the live path applies to a payload of ``key``."""
    if key == topics.CLOCK:
        return [cdr_decode.decode_clock]
    if key == topics.METADATA:
        return [cdr_decode.decode_string]
    out: list[Callable[[bytes], object]] = [
        lambda data: topics.stamp_ms(key, data),
        lambda data: topics.decode_record(key, data, 50),
    ]
    if key not in (topics.ODOMETRY, topics.TRAJECTORY):
        out.append(cdr_decode.read_markers)
    return out


def mutations(data: bytes, rng: random.Random) -> list[bytes]:
    """Cuts (every length up to 600 bytes, then spread), an absurd u32 over every aligned
    4-byte field (the counts and lengths among them), and random flips."""
    cuts = list(range(len(data))) if len(data) <= 600 else rng.sample(range(len(data)), 600)
    out = [data[:n] for n in cuts]
    for at in range(4, len(data) - 3, 4):
        value = ABSURD[(at // 4) % len(ABSURD)]
        out.append(data[:at] + struct.pack("<I", value) + data[at + 4 :])
    for _ in range(300):
        damaged = bytearray(data)
        for _ in range(rng.randrange(1, 12)):
            damaged[rng.randrange(len(damaged))] = rng.randrange(256)
        out.append(bytes(damaged))
    return out


def test_every_decoder_gives_a_record_or_one_typed_error() -> None:
    """... and prints nothing: damaged doubles (1e308 quaternions) overflow to NaN angles
    without a numpy warning on the node's stderr."""
    rng = random.Random(12)
    outcomes = {"record": 0, "refused": 0}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for key, payloads in real_payloads().items():
            for data in payloads[:2]:
                for damaged in mutations(data, rng):
                    for decode in decoders(key):
                        try:
                            decode(damaged)
                        except (CdrError, NoStamp):
                            outcomes["refused"] += 1
                        else:
                            outcomes["record"] += 1
                assert diag.status_runs(data[: len(data) // 2]) == []  # never raises
    assert outcomes["record"] > 1000 and outcomes["refused"] > 1000, outcomes
    assert [str(w.message) for w in caught] == []


def _count_offsets() -> dict[str, tuple[bytes, int]]:
    """A real payload and the byte offset of its top-level sequence count, per decoder."""
    payloads = real_payloads()
    trajectory = payloads[topics.TRAJECTORY][0]
    reader = cdr_decode.CdrReader(trajectory)
    reader.skip_header()
    for _ in range(reader.u32()):  # joint names; the points count follows
        reader.skip_string()
    return {
        topics.TRAJECTORY: (trajectory, cdr.HEADER_SIZE + reader.position),
        topics.ACTORS: (payloads[topics.ACTORS][0], cdr.HEADER_SIZE),
        topics.DETECTIONS: (payloads[topics.DETECTIONS][0], cdr.HEADER_SIZE),
    }


def test_absurd_counts_are_refused_before_allocating(tmp_path: Path) -> None:
    """In a process limited to 1.5 GB of address space: a trajectory of 2**31 points (48 GB
    if allocated) and a MarkerArray of 2**32 - 1 markers are refused as CdrError."""
    cases = []
    for key, (data, at) in _count_offsets().items():
        for count in (2**31, 2**32 - 1, 10**8):
            patched = data[:at] + struct.pack("<I", count) + data[at + 4 :]
            cases.append((key, patched.hex()))
    (tmp_path / "cases.json").write_text(json.dumps(cases))
    script = textwrap.dedent(
        """
        import json, resource, sys
        resource.setrlimit(resource.RLIMIT_AS, (3 << 29, 3 << 29))
        from ads_rca.contract.cdr_decode import CdrError
        from ads_rca.contract.topics import decode_record
        for key, data in json.load(open(sys.argv[1])):
            try:
                decode_record(key, bytes.fromhex(data), 50)
            except CdrError as error:
                print("refused", key, error)
            else:
                print("decoded", key)
        """
    )
    done = subprocess.run(
        [sys.executable, "-c", script, str(tmp_path / "cases.json")],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr
    lines = done.stdout.splitlines()
    assert len(lines) == len(cases) and all(line.startswith("refused") for line in lines), lines
    assert all("need at least" in line for line in lines), lines


def test_a_cut_string_is_refused_not_shortened() -> None:
    whole = cdr.encode_string("hello world")
    assert cdr_decode.decode_string(whole) == "hello world"
    with pytest.raises(CdrError, match="a string claims 12 bytes"):
        cdr_decode.decode_string(whole[:-3])


def _with_markers(payloads: list[bytes]) -> Any:
    """The first of ``payloads`` holding a marker besides the DELETEALL, as an object."""
    for data in payloads:
        msg = rosmsg.deserialize(data, "visualization_msgs/msg/MarkerArray")
        if len(msg.markers) > 1:
            return msg
    raise AssertionError("no MarkerArray with markers")


def test_marker_text_that_is_not_a_box_document_is_refused() -> None:
    """Text JSON that is a list, a box with fewer than 3 points, prediction keys that do
    not match the points: CdrError (these raised AttributeError / IndexError)."""
    payloads = real_payloads()
    for key, text in (
        (topics.DETECTIONS, "[1, 2]"),
        (topics.DETECTIONS, '{"id": ' * 1500),
        (topics.PREDICTION_RAW, '{"id": "a", "keys": ["1"]}'),
        (topics.PREDICTION_RAW, '{"id": "a", "keys": 7}'),
    ):
        msg = _with_markers(payloads[key])
        msg.markers[1].text = text
        data = rosmsg.serialize(msg, "visualization_msgs/msg/MarkerArray")
        with pytest.raises(CdrError):
            topics.decode_record(key, data, 50)
    msg = _with_markers(payloads[topics.DETECTIONS])
    msg.markers[1].points = msg.markers[1].points[:2]
    with pytest.raises(CdrError, match="corners need 3"):
        topics.decode_record(
            topics.DETECTIONS, rosmsg.serialize(msg, "visualization_msgs/msg/MarkerArray"), 50
        )


# --- deep JSON ------------------------------------------------------------------------------


@pytest.mark.parametrize("depth", [1025, 5000, 200_000])
@pytest.mark.parametrize("shape", ["[", '{"a":'])
@pytest.mark.parametrize("extra", ["", "NaN", "12345678901234567890"])
def test_deep_json_is_one_typed_error(depth: int, shape: str, extra: str) -> None:
    """Past orjson's 1024 levels the json module overflowed the stack (RecursionError)."""
    closing = "]" if shape == "[" else "}"
    text = shape * depth + (extra or "0") + closing * depth
    with pytest.raises(JsonTextError, match="nested too deep"):
        loads_json(text)
    assert loads_json(shape * 900 + "0" + closing * 900) is not None  # what orjson reads


def _bag_with(tmp_path: Path, replace: dict[str, Any]) -> Path:
    """The example log as a bag, with the first message of each topic key in ``replace``
    swapped for replace[key](its rclpy-free message object) serialised again."""
    source = convert_example(tmp_path / "source", "--compression", "none")
    bag = tmp_path / "bag"
    done: set[str] = set()
    with McapBagWriter(bag, compression="none") as writer:
        for message in iter_mcap_stream(next(source.glob("*.mcap"))):
            if not writer.has_topic(message.topic):
                writer.add_topic(message.topic, message.msg_type)
            data = message.data
            key = next((k for k in replace if message.topic.endswith("/" + k)), None)
            if key is not None and key not in done:
                msg = rosmsg.deserialize(data, message.msg_type)
                if replace[key](msg):
                    done.add(key)
                    data = rosmsg.serialize(msg, message.msg_type)
            writer.write(message.topic, message.log_time_ns, data)
    assert done == set(replace)
    return bag


def deep(depth: int = 3000) -> str:
    return '{"a":' * depth + "1" + "}" * depth


def _set_text(text: str) -> Any:
    def change(msg: Any) -> bool:
        if len(msg.markers) < 2:
            return False
        msg.markers[1].text = text
        return True

    return change


def test_deep_or_wrong_json_in_a_bag_is_a_problem(tmp_path: Path) -> None:
    """Marker text nested 3000 levels, or a list where a box document belongs: that message
    is skipped and named; the rest of the bag is read and diagnosed."""
    bag = _bag_with(
        tmp_path,
        {topics.DETECTIONS: _set_text(deep()), topics.GROUND_TRUTH: _set_text("[1]")},
    )
    log = read_bag(bag)
    skipped = {
        p.field.rsplit("/", 2)[-2] + "/" + p.field.rsplit("/", 1)[-1]: p for p in log.problems
    }
    assert "nested too deep" in skipped[topics.DETECTIONS].issue, skipped
    assert "not a JSON object" in skipped[topics.GROUND_TRUTH].issue, skipped
    assert len(log.frames) == 81
    done = subprocess.run(
        [sys.executable, "-m", "ads_rca.cli", "diagnose", str(bag), "--workers", "1"],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr
    assert "verdict: perception" in done.stdout and "nested too deep" in done.stdout


def test_deep_json_as_the_only_run_metadata_is_one_line(tmp_path: Path) -> None:
    def replace(msg: Any) -> bool:
        msg.data = deep()
        return True

    bag = _bag_with(tmp_path, {topics.METADATA: replace})
    with pytest.raises(InputError, match="nested too deep") as error:
        read_bag(bag)
    assert "\n" not in str(error.value)


def test_skipped_messages_are_said_once_then_rate_limited() -> None:
    skipped = SkippedMessages(period_s=10.0)
    assert skipped.note("/a", "bad\nverdict: planning", 0.0) == (
        "malformed message on /a skipped: bad\\x0averdict: planning"
    )
    assert skipped.note("/a", "bad", 1.0) is None and skipped.note("/a", "bad", 2.0) is None
    assert skipped.note("/b", "other", 2.0) is not None  # per topic
    assert (
        skipped.note("/a", "bad", 10.5)
        == "malformed message on /a skipped (3 since the last report): bad"
    )
    assert skipped.total == 5 and skipped.counts["/a"] == 4


# --- over DDS -------------------------------------------------------------------------------


def _patched_count(key: str, count: int = 2**31) -> bytes:
    data, at = _count_offsets()[key]
    return data[:at] + struct.pack("<I", count) + data[at + 4 :]


FOREIGN = """
import sys, time, rclpy
from ads_rca.contract import topics
rclpy.init()
node = rclpy.create_node("foreign")
pub = node.create_publisher(
    topics.message_types()[topics.DETECTIONS],
    topics.topic_name(topics.DETECTIONS, sys.argv[1]),
    topics.qos_profile(topics.DETECTIONS),
)
data = bytes.fromhex(sys.argv[2])
deadline = time.monotonic() + 60
while time.monotonic() < deadline:
    if pub.get_subscription_count():
        pub.publish(data)
        print("sent", flush=True)
    time.sleep(0.05)
"""


@pytest.mark.timeout(300)
def test_monitors_skip_and_report_malformed_messages_and_judge_the_rest(ros_env: RosEnv) -> None:
    """This process plays the example log to a real ``monitors`` process, with a trajectory
    of 2**31 points, a MarkerArray of 2**31 markers, run/frame texts that are not JSON or
    nest 5000 levels slipped in from the same participant (the run's own player); another
    process floods the detections topic with a hostile MarkerArray (a foreign participant,
    dropped before decoding). The monitors stay up, say each bad topic, and judge every
    frame."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile
    from std_msgs.msg import String

    ns = ros_env.namespace
    log = read_run_log(EXAMPLE)
    params: dict[str, ParamValue] = {
        "topic_namespace": ns,
        "publish_diagnostics": False,
        "heartbeat_s": 0.2,
    }
    monitors = ManagedProcess(
        "monitors",
        [sys.executable, "-m", "ads_rca.ros.monitor", GROUP, *ros_args(params)],
        ros_env.env,
        echo=sys.stderr,
    )
    foreign = ManagedProcess(
        "foreign",
        [sys.executable, "-c", FOREIGN, ns, _patched_count(topics.DETECTIONS).hex()],
        ros_env.env,
    )
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = rclpy.create_node("hostile_player", context=context)
        sent = topics.advertised(log)  # the example has no 3-D objects or control topics
        data_keys = [key for key in topics.DATA_TOPICS if key in sent]
        keys = (topics.METADATA, topics.FRAME, topics.STATUS, *data_keys)
        pubs = {
            key: node.create_publisher(
                topics.message_types()[key], topics.topic_name(key, ns), topics.qos_profile(key)
            )
            for key in keys
        }
        results: list[dict[str, Any]] = []
        heartbeat: dict[str, str] = {}
        for module in MONITORS.values():
            node.create_subscription(
                String,
                topics.topic_name(live_topics.metrics_key(module), ns),
                lambda msg: results.append(json.loads(msg.data)),
                live_topics.metrics_qos(subscriber=True),
            )

        def on_diagnostics(msg: Any) -> None:
            for status in msg.status:
                if status.name == diag.heartbeat_name("perception"):
                    heartbeat.update({kv.key: kv.value for kv in status.values})

        node.create_subscription(
            DiagnosticArray,
            live_topics.DIAGNOSTICS,
            on_diagnostics,
            QoSProfile(depth=100),
        )

        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)

        def spin(seconds: float) -> None:
            end = time.monotonic() + seconds
            while True:
                executor.spin_once(timeout_sec=0.01)
                if time.monotonic() >= end:
                    return

        deadline = time.monotonic() + 30
        while any(pubs[k].get_subscription_count() < 1 for k in keys):
            assert time.monotonic() < deadline, monitors.output
            spin(0.05)
        # The flood goes on while the run plays: wait until the foreign process (a slow
        # start under load) has matched the monitors and sends.
        deadline = time.monotonic() + 60
        while "sent" not in foreign.output:
            assert time.monotonic() < deadline, foreign.output
            spin(0.05)
        run = "hostile-test-run"
        pubs[topics.METADATA].publish(playback.metadata_message(log, run=run))
        hostile_frame = 10
        ticks = playback.timeline(log)[:30]
        for tick in ticks:
            payloads = topics.frame_payloads(log, tick.stamp_ms)
            if tick.index == hostile_frame:  # before the real messages of this stamp
                pubs[topics.ACTORS].publish(_patched_count(topics.ACTORS))
                pubs[topics.TRAJECTORY].publish(_patched_count(topics.TRAJECTORY))
                for text in (
                    "not json",
                    deep(5000),
                    json.dumps({"run": run, "stamp_ms": []}),
                ):
                    pubs[topics.FRAME].publish(String(data=text))
            for key, data in payloads.items():
                pubs[key].publish(data)
            published = playback.published_names(payloads)
            pubs[topics.FRAME].publish(
                playback.frame_marker(tick, published, log.frame_ms, run=run)
            )
            for pub in pubs.values():
                pub.wait_for_all_acked()
            spin(0.0)
        finished = playback.status_message(playback.FINISHED, len(ticks), run=run)
        pubs[topics.STATUS].publish(finished)
        expected = sum(tick.index is not None for tick in ticks) * len(MONITORS)
        deadline = time.monotonic() + 90
        while (len(results) < expected or not heartbeat) and time.monotonic() < deadline:
            assert monitors.returncode is None, monitors.output
            spin(0.1)
        spin(1.0)
        assert monitors.returncode is None, monitors.output  # alive
        assert "sent" in foreign.output  # the foreign process did publish
    finally:
        rclpy.try_shutdown(context=context)
        foreign.stop()
        monitors.stop()
    output = monitors.output
    assert "Traceback" not in output, output
    for key in (topics.ACTORS, topics.TRAJECTORY, topics.FRAME):
        said = [line for line in output.splitlines() if f"malformed message on {ns}/{key} " in line]
        assert said, output
    assert f"{ns}/{topics.DETECTIONS}" not in output  # foreign: dropped, never decoded
    assert "need at least" in output  # a count refused before allocating
    judged = {(r["module"], r["index"]) for r in results}
    assert len(judged) == expected, (len(judged), expected)
    assert int(heartbeat["skipped_messages"]) >= 5, heartbeat


def test_the_assembler_leaves_undecodable_bytes_out_as_a_problem() -> None:
    """``add_raw`` keeps data as bytes (stamp read only); a message cut after its stamp is
    left out of ``build()`` and said, the rest of the log is built (topic_summary's path)."""
    from ads_rca.contract.assembler import RunLogAssembler

    log = read_run_log(EXAMPLE)
    assembler = RunLogAssembler()
    assembler.add_raw(topics.METADATA, cdr.encode_string(playback.metadata_message(log).data))
    stamp = log.frames[5]
    for key, data in topics.frame_payloads(log, stamp).items():
        assembler.add_raw(key, data[:-40] if key == topics.ACTORS else data)
    for key, data in topics.frame_payloads(log, log.frames[6]).items():
        assembler.add_raw(key, data)
    with pytest.raises(CdrError):
        assembler.add_raw(topics.METADATA, b"\x00\x01\x00\x00\xff\xff\xff\x7f")
    rebuilt = assembler.build()
    assert stamp not in rebuilt.actors and log.frames[6] in rebuilt.actors
    (problem,) = [p for p in rebuilt.problems if p.action == "message skipped"]
    assert problem.file == topics.ACTORS and problem.timestamp_ms == stamp


def test_the_aggregator_skips_malformed_results_and_says_so_once(ros_env: RosEnv) -> None:
    """A real ``aggregator`` process gets 40 monitor results that are not results (not JSON,
    nested 5000 levels, a list, a document missing its fields) and bad run/frame texts: it
    stays up, logs one rate-limited line per topic, never a traceback, never a line each."""
    import rclpy
    from std_msgs.msg import String

    ns = ros_env.namespace
    log = read_run_log(EXAMPLE)
    aggregator = ManagedProcess(
        "aggregator",
        [sys.executable, "-m", "ads_rca.ros.aggregator", *ros_args({"topic_namespace": ns})],
        ros_env.env,
        echo=sys.stderr,
    )
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = rclpy.create_node("hostile_monitor", context=context)
        metrics = node.create_publisher(
            String,
            topics.topic_name(live_topics.metrics_key("perception"), ns),
            live_topics.metrics_qos(),
        )
        frames = node.create_publisher(
            String, topics.topic_name(topics.FRAME, ns), topics.qos_profile(topics.FRAME)
        )
        metadata = node.create_publisher(
            String, topics.topic_name(topics.METADATA, ns), topics.qos_profile(topics.METADATA)
        )
        deadline = time.monotonic() + 30
        while min(p.get_subscription_count() for p in (metrics, frames, metadata)) < 1:
            assert time.monotonic() < deadline, aggregator.output
            time.sleep(0.05)
        metadata.publish(playback.metadata_message(log, run="hostile-aggregator-run"))
        bad = ["not json", deep(5000), "[1, 2]", json.dumps({"module": "perception"})]
        for i in range(40):
            metrics.publish(String(data=bad[i % len(bad)]))
            frames.publish(String(data=bad[i % len(bad)]))
        for pub in (metrics, frames, metadata):
            pub.wait_for_all_acked()
        deadline = time.monotonic() + 30
        while "on " + ns + "/metrics" not in aggregator.output and time.monotonic() < deadline:
            time.sleep(0.1)
        time.sleep(1.0)
        assert aggregator.returncode is None, aggregator.output  # alive
    finally:
        rclpy.try_shutdown(context=context)
        aggregator.stop()
    output = aggregator.output
    assert "Traceback" not in output, output
    for key in ("metrics", topics.FRAME):
        said = [line for line in output.splitlines() if f"malformed message on {ns}/{key} " in line]
        assert len(said) == 1, output  # 40 bad messages, one line (rate-limited)


_RESULT = {"module": "perception", "stamp_ms": 1000, "failed": False, "index": 3, "frame": 3}
_HOSTILE_NUMBERS: list[tuple[str, Any]] = [
    (field, value)
    for field in (
        "index",
        "stamp_ms",
        "collision_frame",
        "closes_collision",
        "revision",
        "frame_ms",
    )
    for value in (10**30, 2**63, -(2**63) - 1, True, "12", 2.5, 1e300)
]


@pytest.mark.parametrize(("field", "value"), _HOSTILE_NUMBERS)
def test_absurd_numbers_in_a_result_are_one_malformed_message(field: str, value: Any) -> None:
    """A result whose integers are past int64, past any frame or stamp, booleans, strings or
    fractions is refused as malformed, naming the field. It used to pass, then overflow the
    aggregator's int64 columns inside its callback (a traceback that ended the node), or,
    as a collision a monitor closed, hold every later verdict back."""
    from stacksettings import config

    from ads_rca.contract.errors import MalformedMessage
    from ads_rca.live.aggregate import AggregatorCore
    from ads_rca.live.results import LiveResult
    from ads_rca.params import make_params

    with pytest.raises(MalformedMessage, match=field):
        LiveResult.from_document({**_RESULT, "frame_ms": 50, field: value})
    # What is accepted is used without an error, in both kinds of run.
    for run in (None, config()):  # a player's run, and a stack's (test_live_stack_mode's facts)
        core = AggregatorCore(make_params("corrected"), stack=run)
        edge = {"closes_collision": 2**42, "collision_frame": -(2**42), "revision": 2**42}
        for document in (_RESULT, {**_RESULT, "frame_ms": 50, **edge}):
            core.add_result(LiveResult.from_document(document), 1.0)
        core.poll(2.0)
        core.poll(1000.0)


@pytest.mark.parametrize("value", [10**30, 2**42 + 1, -(2**63) - 1])
def test_absurd_marker_and_collision_frames_are_malformed(value: int) -> None:
    from ads_rca.contract.errors import MalformedMessage
    from ads_rca.live.results import FrameMarker, collision_frame
    from ads_rca.live.runid import RunFilter

    for document in ({"index": value, "stamp_ms": 0}, {"index": 1, "stamp_ms": value * 1000}):
        with pytest.raises(MalformedMessage):
            FrameMarker.from_document(document)
    if value > 0:
        with pytest.raises(MalformedMessage, match="collision frame"):
            collision_frame({"frame": value}, RunFilter(""))
    assert collision_frame({"frame": 2**42}, RunFilter("")) == 2**42  # model.MAX_FRAME


@pytest.mark.parametrize(
    ("key", "value", "named"),
    [
        ("timesteps_per_frame", 0, "timesteps_per_frame 0 is outside"),
        ("timesteps_per_frame", 10**30, "timesteps_per_frame"),
        ("collision_frame", 10**30, "collision_frame"),
        ("collision_frame", "12", "collision_frame is not an integer"),
        ("total_frames", -1, "total_frames -1 is outside"),
    ],
)
def test_run_metadata_with_numbers_no_reader_gives_is_malformed(
    key: str, value: Any, named: str
) -> None:
    """A ``run/metadata`` (or a recording's) whose frame period is 0 divided by zero in the
    aggregator, inside its callback; numbers the reader never gives are one malformed
    message instead, naming the field."""
    from ads_rca.contract.assembler import run_metadata
    from ads_rca.contract.errors import MalformedMessage

    log = read_run_log(EXAMPLE)
    document = playback.read_document(playback.metadata_message(log))
    document[playback.METADATA_DOCUMENT_KEY][key] = value
    with pytest.raises(MalformedMessage, match=named):
        run_metadata(document)


def test_a_log_with_an_absurd_collision_frame_replays_to_diagnoses_verdict(
    ros_env: RosEnv, tmp_path: Path
) -> None:
    """metadata.json says the collision is at frame 10**300: the reader clamps it (and says
    so), the live graph carries it, and the verdict is diagnose's. The aggregator used to
    die on it (OverflowError in its result callback) and the replay gave no verdict."""
    from verdicts import assert_close, failed_flags, verdict_keys

    from ads_rca.diagnosis.engine import diagnose
    from ads_rca.params import make_params

    log_dir = Path(shutil.copytree(EXAMPLE, tmp_path / "log"))
    metadata = json.loads((log_dir / "metadata.json").read_text())
    metadata["collision_frame"] = 10**300
    (log_dir / "metadata.json").write_text(json.dumps(metadata))
    out = tmp_path / "verdict.json"
    argv = [sys.executable, "-m", "ads_rca.cli", "replay", str(log_dir), "--json", str(out)]
    argv += ["--domain-id", str(ros_env.domain_id), "--timeout", "90"]
    replay = ManagedProcess("replay", argv, ros_env.env)
    assert replay.wait(150) == 0, replay.output
    assert "Traceback" not in replay.output
    live = json.loads(out.read_text())
    offline = diagnose(read_run_log(log_dir), make_params("corrected")).to_json()
    assert live["live"]["complete"], live["live"]
    assert live["collision_frame"] == offline["collision_frame"] > 10**12
    assert failed_flags(live) == failed_flags(offline)
    assert_close(verdict_keys(live), verdict_keys(offline))


def _lane_markers(tmp_path: Path) -> Any:
    """A synthesised OpenLane-V2 segment's first ground-truth lane graph as a MarkerArray."""
    from writers.openlane_segments import write_openlane_segment

    from ads_rca.sources.registry import open_run

    log = open_run(write_openlane_segment(tmp_path))
    data = topics.frame_payloads(log, log.frames[0])[topics.LANES]
    return rosmsg.deserialize(data, "visualization_msgs/msg/MarkerArray")


@pytest.mark.parametrize(
    "row, text",
    [
        (1, '{"lane": [1], "score": 0.5, "next": [0, 0, 0], "elements": [0, 0]}'),
        (1, '{"lane": true, "score": 0.5, "next": [0, 0, 0], "elements": [0, 0]}'),
        (1, '{"lane": "a", "score": "0.5", "next": [0, 0, 0], "elements": [0, 0]}'),
        (1, '{"lane": "a", "score": 0.5, "next": [0, 0], "elements": [0, 0]}'),
        (1, '{"lane": "a", "score": 0.5, "next": 7, "elements": [0, 0]}'),
        (1, '{"lane": "a", "next": [0, 0, 0], "elements": [0, 0]}'),
        (1, '{"lane": "a", "score": 0.5, "next": [0, 0, 0], "elements": [0, 0, true]}'),
        (4, '{"element": "e", "box": [1, 2, 3], "category": 1, "attribute": 0, "score": 1}'),
        (4, '{"element": "e", "box": [1, 2, 3, 4], "category": 1.5, "attribute": 0}'),
        (
            4,
            '{"element": "e", "box": [1, 2, 3, 4], "category": 2, "attribute": 1' + "0" * 19 + "}",
        ),
        (4, '{"element": {}, "box": [1, 2, 3, 4], "category": 2, "attribute": 0, "score": 1}'),
        (4, '{"neither": 1}'),
    ],
)
def test_lane_marker_texts_that_are_no_lane_graph_are_refused(
    tmp_path: Path, row: int, text: str
) -> None:
    """A lanes marker's text with a wrong type, length or range in any field: one typed
    error on both paths (objects and CDR bytes), never a KeyError, TypeError or
    OverflowError of the decoder (rows 1-3 are the lanes, 4-5 the elements)."""
    msg = _lane_markers(tmp_path)
    assert len(msg.markers) == 6, "the synthesised graph: 3 lanes and 2 elements"
    msg.markers[row].text = text
    with pytest.raises(MalformedMessage):
        topics.message_to_record(topics.LANES, msg, 500)
    data = rosmsg.serialize(msg, "visualization_msgs/msg/MarkerArray")
    with pytest.raises(CdrError):
        topics.decode_record(topics.LANES, data, 500)


def test_lane_markers_round_trip_unchanged(tmp_path: Path) -> None:
    msg = _lane_markers(tmp_path)
    data = rosmsg.serialize(msg, "visualization_msgs/msg/MarkerArray")
    by_object = topics.message_to_record(topics.LANES, msg, 500)
    by_bytes = topics.decode_record(topics.LANES, data, 500)
    for graph in (by_object, by_bytes):
        assert graph.lane_lane.shape == (3, 3) and graph.lane_element.shape == (3, 2)
    assert by_object.lane_ids == by_bytes.lane_ids
    assert (by_object.lane_lane == by_bytes.lane_lane).all()
