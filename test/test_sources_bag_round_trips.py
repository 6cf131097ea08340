"""Bags without a recorder: CDR parity with rclpy, the MCAP layout, convert round trips,
crash tolerance of the writer, and the player playing bags (also a stack's, remapped)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING

import pytest
import yaml
from logcompare import assert_logs_equal
from logfactory import make_log
from rosrun import run_pair

from ads_rca.cli import main as cli
from ads_rca.contract import rosmsg, topics
from ads_rca.contract.playback import metadata_message
from ads_rca.contract.topics import frame_messages
from ads_rca.sources.bag.mcap_writer import McapBagWriter
from ads_rca.sources.bag.reader import is_bag, iter_mcap_stream, read_bag
from ads_rca.sources.bag.writer import contract_qos_yaml, playback_messages, write_bag
from ads_rca.sources.log.reader import read_run_log
from ads_rca.sources.log.writer import write_run_log
from ads_rca.sources.registry import open_run

if TYPE_CHECKING:
    from conftest import RosEnv

pytestmark = pytest.mark.timeout(120)


@pytest.fixture(scope="module")
def log_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    log = make_log(16, 6, 5, duplicate_frame=True, orphan_stamps=True)
    return write_run_log(log, tmp_path_factory.mktemp("bags") / "log")


def test_cdr_matches_rclpy_both_ways(log_dir: Path) -> None:
    from rclpy.serialization import deserialize_message, serialize_message

    log = read_run_log(log_dir)
    messages = [metadata_message(log)]
    for ts in log.frames[:4]:
        messages += list(frame_messages(log, ts).values())
    store = rosmsg.typestore()
    for msg in messages:
        name = rosmsg.type_name(type(msg))
        ours, theirs = rosmsg.serialize(msg), serialize_message(msg)
        # rclpy leaves CDR padding bytes uninitialised: compare after a canonical re-encode.
        assert len(ours) == len(theirs)
        assert ours == bytes(store.serialize_cdr(store.deserialize_cdr(theirs, name), name))
        assert rosmsg.serialize(deserialize_message(ours, type(msg))) == ours
        assert rosmsg.serialize(rosmsg.deserialize(ours, name)) == ours
    for key, cls in topics.message_types().items():  # rosbags' Kilted hashes are rclpy's
        assert rosmsg.type_hash(rosmsg.type_name(cls)).startswith("RIHS01_"), key


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_convert_round_trips(log_dir: Path, tmp_path: Path, storage: str) -> None:
    bag, back = tmp_path / "bag", tmp_path / "back"
    assert cli(["convert", str(log_dir), str(bag), "--storage", storage]) == 0
    assert is_bag(bag) and (bag / "metadata.yaml").is_file()
    assert cli(["convert", str(bag), str(back)]) == 0
    original = read_run_log(log_dir)
    assert_logs_equal(original, read_run_log(back))
    assert read_run_log(back).frames == original.frames  # duplicates and order kept
    assert cli(["convert", str(bag), str(back)]) == 2  # never overwrites


def test_a_bag_keeps_the_logs_reader_problems(tmp_path: Path) -> None:
    """Values the reader read as NaN stay reported in the bag, so it is judged the same."""
    from synthlogs import write_log_with_unreadable_values

    from ads_rca.diagnosis.engine import diagnose
    from ads_rca.params import make_params

    log_dir = write_log_with_unreadable_values(tmp_path / "log")
    assert cli(["convert", str(log_dir), str(tmp_path / "bag")]) == 0
    original, bag = read_run_log(log_dir), read_bag(tmp_path / "bag")
    assert list(bag.problems) == list(original.problems)
    for semantics in ("reference", "corrected"):
        params = make_params(semantics)
        assert (
            diagnose(bag, params).to_json()["frames"]
            == (diagnose(original, params).to_json()["frames"])
        )


def test_mcap_layout_is_rosbag2s(log_dir: Path, tmp_path: Path) -> None:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from rosbags.highlevel import AnyReader

    bag = tmp_path / "run"
    counts = write_bag(read_run_log(log_dir), bag, chunk_size=8192)
    assert sorted(p.name for p in bag.iterdir()) == ["metadata.yaml", "run_0.mcap"]
    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["version"] == 9 and info["storage_identifier"] == "mcap"
    assert info["relative_file_paths"] == ["run_0.mcap"]
    assert info["message_count"] == sum(counts.values())
    with (bag / "run_0.mcap").open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        assert summary.statistics.message_count == sum(counts.values())
        assert summary.statistics.chunk_count > 1
        for schema in summary.schemas.values():
            assert schema.encoding == "ros2msg" and schema.name.count("/msg/") == 1
            assert schema.data.decode() == rosmsg.message_definition(schema.name)
        for channel in summary.channels.values():
            schema_name = summary.schemas[channel.schema_id].name
            assert channel.message_encoding == "cdr"
            assert channel.metadata["topic_type_hash"] == rosmsg.type_hash(schema_name)
            key = next(k for k in topics.ALL_TOPICS if channel.topic.endswith(k))
            assert channel.metadata["offered_qos_profiles"] == contract_qos_yaml(key)
        records = list(reader.iter_metadata())
        assert [r.name for r in records] == ["rosbag2"]
        assert yaml.safe_load(records[0].metadata["serialized_metadata"]) == info
        decoded = sum(1 for _ in reader.iter_decoded_messages())
    assert decoded == sum(counts.values())
    with AnyReader([bag]) as any_reader:
        assert {c.topic: c.msgcount for c in any_reader.connections} == counts
        for conn, _ts, raw in any_reader.messages():
            any_reader.deserialize(raw, conn.msgtype)


def test_killed_writer_leaves_complete_chunks_readable(log_dir: Path, tmp_path: Path) -> None:
    log = read_run_log(log_dir)
    bag = tmp_path / "killed"
    writer = McapBagWriter(bag, chunk_size=4096)
    name = topics.topic_name(topics.ACTORS)
    writer.add_topic(name, "visualization_msgs/msg/MarkerArray")
    written = 0
    for key, log_time, msg in playback_messages(log):
        if key == topics.ACTORS:
            writer.write(name, log_time, rosmsg.serialize(msg))
            written += 1
    flushed = writer.chunks_flushed
    assert flushed >= 2
    # No close(): what a SIGKILL leaves (the chunk being filled never reached the file).
    assert not (bag / "metadata.yaml").exists() and is_bag(bag)
    streamed = list(iter_mcap_stream(bag / "killed_0.mcap"))
    assert 0 < len(streamed) <= written
    assert all(m.topic == name for m in streamed)
    for m in streamed:
        rosmsg.deserialize(m.data, m.msg_type)
    writer.close()  # and once closed, everything is there
    assert len(list(iter_mcap_stream(bag / "killed_0.mcap"))) == written


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_player_plays_a_bag(ros_env: RosEnv, tmp_path: Path, log_dir: Path, storage: str) -> None:
    bag, out, ns = tmp_path / "bag", tmp_path / "rebuilt", ros_env.namespace
    write_bag(read_run_log(log_dir), bag, storage)
    source = bag if storage == "mcap" else next(bag.glob("*.db3"))  # dir and bare file
    result = run_pair(
        ros_env.env,
        tmp_path,
        {"log_path": str(source), "rate": 0.0, "topic_namespace": ns},
        {"topic_namespace": ns, "output_json": True, "output_dir": str(out)},
    )
    assert result.player_code == 0, result.player_output
    assert result.summary_code == 0 and result.summary["complete"], result.summary_output
    assert_logs_equal(read_run_log(log_dir), read_run_log(out))


def _stack_bag(log_dir: Path, bag: Path) -> dict[str, object]:
    """A stack's bag: its own topic names, data topics only (no markers, no metadata)."""
    names = {
        topics.ODOMETRY: "/carla/hero/odometry",
        topics.ACTORS: "/stack/tracking/objects_markers",
        topics.DETECTIONS: "/stack/perception/boxes_2d",
        topics.GROUND_TRUTH: "/carla/hero/gt_boxes_2d",
        topics.PREDICTION_RAW: "/stack/prediction/markers",
        topics.PREDICTION_WITH_PERCEPTION: "/stack/prediction/fused_markers",
        topics.TRAJECTORY: "/stack/planning/trajectory",
    }
    log = read_run_log(log_dir)
    with McapBagWriter(bag) as writer:
        for key, their in names.items():
            writer.add_topic(their, rosmsg.type_name(topics.message_types()[key]))
        for key, log_time, msg in playback_messages(log):
            if key in names:
                writer.write(names[key], log_time, rosmsg.serialize(msg))
    return {**{their: key for key, their in names.items()}, "metadata": log.metadata.to_dict()}


def test_stack_bag_plays_through_a_remapping(ros_env: RosEnv, tmp_path: Path) -> None:
    log = make_log(12, 5, 9, orphan_stamps=True)  # frames = actors stamps (no duplicates)
    log_dir = write_run_log(log, tmp_path / "log")
    bag, remap = tmp_path / "stack_bag", tmp_path / "remap.yaml"
    remap.write_text(yaml.safe_dump(_stack_bag(log_dir, bag)))
    original = read_run_log(log_dir)
    assert_logs_equal(original, open_run(bag, remap=remap))
    with pytest.raises(Exception, match="run/metadata"):
        read_bag(bag)  # no contract names, no metadata: one clear error
    out, ns = tmp_path / "rebuilt", ros_env.namespace
    result = run_pair(
        ros_env.env,
        tmp_path,
        {"log_path": str(bag), "bag_remap": str(remap), "rate": 0.0, "topic_namespace": ns},
        {"topic_namespace": ns, "output_json": True, "output_dir": str(out)},
    )
    assert result.player_code == 0, result.player_output
    assert result.summary_code == 0, result.summary_output
    assert_logs_equal(original, read_run_log(out))


def test_convert_bad_input_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert cli(["convert", str(tmp_path / "nope"), str(tmp_path / "out")]) == 2
    broken = tmp_path / "broken.mcap"
    broken.write_bytes(b"not an mcap")
    assert cli(["convert", str(broken), str(tmp_path / "out2")]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and err.count("error:") == 2, err
    print(err, file=sys.stderr)
