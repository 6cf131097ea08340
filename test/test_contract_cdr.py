"""The fast CDR path (ads_rca.contract.cdr / cdr_decode) against rclpy and convert.py.

Byte equality: our bytes must equal ``rclpy.serialization.serialize_message`` of the message
convert.py builds on every non-padding byte, with zero padding (rclpy leaves its padding
uninitialised; test/cdrlayout.py finds the padding from the type definitions, not from our
encoder). Over DDS, where Fast DDS zeroes the padding of message objects, the bytes a raw
subscriber receives must be identical in full. Decoding must give exactly convert's records.
"""

from __future__ import annotations

import subprocess
import sys
import time
from typing import TYPE_CHECKING, Any

import numpy as np
import pytest
from cdrlayout import differences
from hypothesis import given, settings
from hypothesis import strategies as st
from logcompare import assert_logs_equal
from logfactory import add_3d, awkward_log, make_log
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import String
from visualization_msgs.msg import MarkerArray

from ads_rca.contract import cdr, convert, playback, topics
from ads_rca.contract.assembler import RunLogAssembler
from ads_rca.contract.cdr_decode import decode_clock, decode_string
from ads_rca.contract.topics import decode_record, stamp_ms
from ads_rca.live import diagnostics as diag
from ads_rca.model import (
    OPTIONAL_FOLDERS,
    Actors,
    Boxes,
    ControlCommand,
    EgoPose,
    RunLog,
)
from ads_rca.ros.diagnostics import array as diagnostic_array

if TYPE_CHECKING:
    from conftest import RosEnv

TPF = 50


def assert_bytes_match(ours: bytes, msg: Any) -> None:
    problems = differences(ours, serialize_message(msg), msg)
    assert not problems, problems


def assert_records_equal(a: Any, b: Any) -> None:
    """Bit-exact equality of two model records (arrays by bytes, so NaN signs count too)."""
    assert type(a) is type(b)
    if isinstance(a, dict):
        assert list(a) == list(b)
        for key in a:
            assert_records_equal(a[key], b[key])
        return
    if isinstance(a, EgoPose | ControlCommand):  # floats only: compared by their bits
        assert np.array(list(_fields(a))).tobytes() == np.array(list(_fields(b))).tobytes()
        return
    for name in a.__dataclass_fields__:
        x, y = getattr(a, name), getattr(b, name)
        if isinstance(x, np.ndarray):
            assert x.shape == y.shape and x.tobytes() == y.tobytes(), (name, x, y)
        elif name == "lanes":  # a lane graph's tuple of (P, 3) arrays
            assert [(a.shape, a.tobytes()) for a in x] == [(b.shape, b.tobytes()) for b in y]
        elif name == "extras":
            assert [list(e.items()) for e in x] == [list(e.items()) for e in y]
        else:
            assert x == y, (name, x, y)


def _fields(record: EgoPose | ControlCommand) -> tuple[float, ...]:
    return tuple(getattr(record, name) for name in record.__dataclass_fields__)


def check_log(log: RunLog, every: int = 1) -> int:
    """Every tick's (or every ``every``-th tick's) payloads vs convert + rclpy; decoders vs
    convert's rebuild. Returns the number of messages checked."""
    checked = 0
    for tick in playback.timeline(log)[::every]:
        ts = tick.stamp_ms
        fast = topics.frame_payloads(log, ts)
        slow = topics.frame_messages(log, ts)
        assert list(fast) == list(slow)
        for key, msg in slow.items():
            assert_bytes_match(fast[key], msg)
            expected = topics.message_to_record(key, msg, log.frame_ms)
            assert_records_equal(decode_record(key, fast[key], log.frame_ms), expected)
            rclpy_bytes = serialize_message(msg)
            assert_records_equal(decode_record(key, rclpy_bytes, log.frame_ms), expected)
            assert stamp_ms(key, fast[key]) == convert.message_stamp_ms(msg)
            checked += 1
        assert_bytes_match(cdr.encode_clock(ts), convert.clock_message(ts))
    return checked


@pytest.mark.parametrize(
    ("scenario", "fault"),
    [("cruise", "none"), ("cut_in", "perception"), ("pedestrian_crossing", "prediction")],
)
def test_synthesised_logs_encode_byte_for_byte(scenario: str, fault: str) -> None:
    from ads_rca.synth import synthesise

    options = {"frames": 30, "actors": 8} if scenario == "cruise" else {}
    log = synthesise(scenario, fault, 3, horizon=12, **options)
    assert check_log(log, every=1 if scenario == "cruise" else 4) > 100


@pytest.mark.parametrize("seed", [0, 1])
def test_factory_logs_encode_byte_for_byte(seed: int) -> None:
    log = make_log(14, 11, seed, duplicate_frame=True, orphan_stamps=True)
    assert check_log(log) > 50


def test_3d_objects_and_control_commands_encode_byte_for_byte_and_decode_exactly() -> None:
    log = add_3d(make_log(14, 11, 4, duplicate_frame=True, orphan_stamps=True), 4)
    optional = {t.key for t in topics.DATA if t.optional}
    sent = [key for t in playback.timeline(log) for key in topics.frame_payloads(log, t.stamp_ms)]
    assert {key: sent.count(key) for key in optional} == {
        topics.OBJECTS_3D: 13,
        topics.TRACKS_3D: 7,
        topics.CONTROL_COMMAND: 12,  # the duplicated frame's again, and a records-only one
        topics.LANES: 12,  # 3 frames in 4, the duplicated frame's again
        topics.LANES_PREDICTED: 5,  # every third frame
    }
    assert check_log(log) > 120


def test_awkward_values_encode_byte_for_byte() -> None:
    assert check_log(awkward_log()) >= 12


@settings(max_examples=60, deadline=None)
@given(
    ids=st.lists(st.text(max_size=9), max_size=6),
    text=st.text(max_size=40),
    stamp=st.integers(-(2**40), 2**40),
)
def test_unicode_strings_of_every_length_keep_alignment(
    ids: list[str], text: str, stamp: int
) -> None:
    ids = [i.replace("\x00", "") for i in ids]  # a C string cannot hold NUL
    text = text.replace("\x00", "")
    n = len(ids)
    rng = np.random.default_rng(n)
    actors = Actors(tuple(ids), rng.normal(size=(n, 3)), rng.normal(size=(n, 3)), np.ones((n, 3)))
    actor_codec = topics.TOPICS[topics.ACTORS].codec
    msg = actor_codec.build(actors, stamp, TPF)
    ours = actor_codec.encode(actors, stamp, TPF)
    assert_bytes_match(ours, msg)
    assert_records_equal(decode_record(topics.ACTORS, ours, TPF), convert.markers_to_actors(msg))
    boxes = Boxes(tuple(ids), rng.normal(size=(n, 4)), tuple({text: i} for i in ids))
    box_codec = topics.TOPICS[topics.DETECTIONS].codec
    box_msg = box_codec.build(boxes, stamp, TPF)
    assert_bytes_match(box_codec.encode(boxes, stamp, TPF), box_msg)
    string = String(data=text)
    assert_bytes_match(cdr.encode_string(text), string)
    assert decode_string(serialize_message(string)) == text
    assert decode_clock(cdr.encode_clock(stamp)) == stamp


@settings(max_examples=60, deadline=None)
@given(
    statuses=st.lists(
        st.tuples(
            st.integers(0, 3),
            st.text(max_size=12),
            st.text(max_size=7),
            st.lists(st.tuples(st.text(max_size=6), st.text(max_size=9)), max_size=5),
        ),
        max_size=4,
    ),
    stamp_ns=st.integers(0, 2**62),
)
def test_diagnostic_arrays_encode_byte_for_byte(
    statuses: list[tuple[int, str, str, list[tuple[str, str]]]], stamp_ns: int
) -> None:
    """Monitors publish DiagnosticArray bytes from diag.encode_array; rclpy must agree."""
    from builtin_interfaces.msg import Time

    def clean(text: str) -> str:
        return text.replace("\x00", "")

    built = [
        diag.Status(level, clean(name), clean(msg), "hw", [(clean(k), clean(v)) for k, v in kv])
        for level, name, msg, kv in statuses
    ]
    sec, nanosec = divmod(stamp_ns, 10**9)
    msg = diagnostic_array(Time(sec=sec % 2**31, nanosec=nanosec), built)
    ours = diag.encode_array((sec % 2**31) * 10**9 + nanosec, built)
    assert_bytes_match(ours, msg)
    assert diag.status_names(ours) == [s.name for s in built]
    assert isinstance(diag.status_names(ours[: len(ours) // 2]), list)  # truncated: no raise


def test_decoder_walks_every_marker_field() -> None:
    """A MarkerArray from another publisher, with colors, texture, uv, mesh ... all set."""
    from std_msgs.msg import ColorRGBA
    from visualization_msgs.msg import MeshFile, UVCoordinate

    boxes = make_log(2, 4, 5).bboxes_gt[TPF]
    msg = topics.TOPICS[topics.GROUND_TRUTH].codec.build(boxes, TPF, TPF)
    for i, m in enumerate(msg.markers[1:]):
        m.colors = [ColorRGBA(r=0.5)] * (i + 1)
        m.texture_resource = "embedded://" + "t" * i
        m.texture.header.frame_id = "cam" * i
        m.texture.format = "png"
        m.texture.data = bytes(range(i * 3 + 1))
        m.uv_coordinates = [UVCoordinate(u=0.1, v=0.2)] * i
        m.mesh_resource = "package://m" + "x" * i
        m.mesh_file = MeshFile(filename="f" * (i + 2), data=bytes(i + 5))
        m.mesh_use_embedded_materials = True
        m.frame_locked = True
    data = serialize_message(msg)
    assert_records_equal(
        decode_record(topics.GROUND_TRUTH, data, TPF), convert.markers_to_boxes(msg)
    )


def test_assembler_add_raw_rebuilds_the_log_like_add() -> None:
    log = add_3d(make_log(12, 6, 2, duplicate_frame=True, orphan_stamps=True), 2)
    by_bytes, by_objects, mixed = RunLogAssembler(), RunLogAssembler(), RunLogAssembler()
    sent: list[tuple[str, Any, bytes]] = [
        (topics.METADATA, playback.metadata_message(log), b""),
        (topics.STATUS, playback.status_message(playback.PLAYING, 0), b""),
    ]
    ticks = playback.timeline(log)
    for tick in ticks:
        fast = topics.frame_payloads(log, tick.stamp_ms)
        slow = topics.frame_messages(log, tick.stamp_ms)
        sent.append((topics.CLOCK, convert.clock_message(tick.stamp_ms), b""))
        sent += [(key, slow[key], fast[key]) for key in slow]
        marker = playback.frame_marker(tick, playback.published_names(fast), TPF)
        sent.append((topics.FRAME, marker, b""))
    sent.append((topics.STATUS, playback.status_message(playback.FINISHED, len(ticks)), b""))
    for n, (key, msg, data) in enumerate(sent):
        raw = data or serialize_message(msg)
        by_bytes.add_raw(key, raw)
        by_objects.add(key, msg)
        if n % 2:
            mixed.add_raw(key, raw)
        else:
            mixed.add(key, deserialize_message(raw, topics.message_types()[key]))
    assert by_bytes.complete() and mixed.complete()
    assert by_bytes.received == by_objects.received
    for assembler in (by_bytes, mixed):
        rebuilt = assembler.build()
        assert_logs_equal(log, rebuilt)
        reference = by_objects.build()
        for folder in ("pose", "actors", "bboxes", "predictions", "waypoint", *OPTIONAL_FOLDERS):
            for ts, record in reference.folder(folder).items():
                assert_records_equal(rebuilt.folder(folder)[ts], record)


def test_empty_marker_array_has_no_stamp() -> None:
    assembler = RunLogAssembler()
    assembler.add_raw(topics.ACTORS, serialize_message(MarkerArray()))
    assert assembler.received[topics.ACTORS] == 1
    with pytest.raises(ValueError):
        stamp_ms(topics.ACTORS, cdr.ENCAPSULATION + bytes(4))
    with pytest.raises(ValueError):
        decode_string(b"\x00\x00\x00\x00\x01\x00\x00\x00\x00")  # big-endian: not read


def test_encoder_modules_do_not_import_rclpy() -> None:
    code = (
        "import sys, ads_rca.contract.cdr, ads_rca.contract.cdr_decode; "
        "assert 'rclpy' not in sys.modules, 'rclpy imported'"
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=60)


@pytest.mark.timeout(60)
def test_subscribers_receive_identical_bytes_over_dds(ros_env: RosEnv) -> None:
    """Object publisher vs bytes publisher, raw subscribers: the very same bytes arrive."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    log = make_log(4, 9, 4)
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = rclpy.create_node("cdr_equality", context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        got: dict[str, list[bytes]] = {"objects": [], "bytes": []}
        pubs = {}
        for kind, received in got.items():
            for key in (*topics.DATA_TOPICS, topics.CLOCK):
                name = f"{ros_env.namespace}/{kind}/{key.strip('/')}"
                pubs[kind, key] = node.create_publisher(topics.message_types()[key], name, 100)
                node.create_subscription(
                    topics.message_types()[key], name, received.append, 100, raw=True
                )
        deadline = time.monotonic() + 15
        while any(p.get_subscription_count() < 1 for p in pubs.values()):
            assert time.monotonic() < deadline, "no discovery"
            time.sleep(0.02)
        expected = 0
        for tick in playback.timeline(log):
            ts = tick.stamp_ms
            slow = {topics.CLOCK: convert.clock_message(ts), **topics.frame_messages(log, ts)}
            fast = {topics.CLOCK: cdr.encode_clock(ts), **topics.frame_payloads(log, ts)}
            for key, msg in slow.items():
                pubs["objects", key].publish(msg)
                pubs["bytes", key].publish(fast[key])
                expected += 1
        deadline = time.monotonic() + 20
        while min(len(v) for v in got.values()) < expected and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        assert len(got["objects"]) == len(got["bytes"]) == expected
        assert sorted(got["objects"]) == sorted(got["bytes"])
    finally:
        rclpy.try_shutdown(context=context)


@pytest.mark.timeout(120)
@pytest.mark.parametrize(("fast_publish", "fast_decode"), [(False, True), (True, False)])
def test_fast_and_object_paths_interoperate_across_processes(
    ros_env: RosEnv, tmp_path: Any, fast_publish: bool, fast_decode: bool
) -> None:
    from rosrun import run_pair

    from ads_rca.sources.log.reader import read_run_log
    from ads_rca.sources.log.writer import write_run_log

    log_dir = write_run_log(make_log(10, 7, 9, duplicate_frame=True), tmp_path / "log")
    out = tmp_path / "rebuilt"
    ns = ros_env.namespace
    result = run_pair(
        ros_env.env,
        tmp_path,
        {
            "log_path": str(log_dir),
            "rate": 0.0,
            "topic_namespace": ns,
            "fast_publish": fast_publish,
        },
        {
            "topic_namespace": ns,
            "output_json": True,
            "output_dir": str(out),
            "fast_decode": fast_decode,
        },
    )
    assert result.player_code == 0 and result.summary_code == 0, result.summary_output
    assert result.summary["complete"], result.summary
    assert_logs_equal(read_run_log(log_dir), read_run_log(out))
