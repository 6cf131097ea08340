"""One table drives every topic of the contract.

``contract/topics.py``'s ``TABLE`` gives each topic its kind of record (a ``Codec``: type,
object conversions, CDR encoder, decoder, stamp reader), QoS and log folder; the folder maps,
the type names and the whole-frame conversions of both paths derive from it. Checked here:
every row round-trips record → message object → record and record → CDR bytes → record,
the bytes equal rclpy's serialisation of the object (non-padding bytes, test/cdrlayout.py),
and no other module names a topic: adding a topic is one row, nothing else to keep in step.
"""

from __future__ import annotations

import ast
from pathlib import Path
from typing import Any

import pytest
from cdrlayout import differences
from logcompare import assert_logs_equal
from logfactory import add_3d
from rclpy.serialization import serialize_message

import ads_rca
from ads_rca.contract import codec, rosmsg, topics
from ads_rca.contract.convert import message_stamp_ms
from ads_rca.model import ALL_FOLDERS, OPTIONAL_FOLDERS, RunLog
from ads_rca.synth import synthesise

PACKAGE = Path(ads_rca.__file__).resolve().parent
ROOT = PACKAGE.parent
#: The codec modules sit below the table: they convert kinds of record, never name a topic.
CODEC_MODULES = ("convert.py", "cdr.py", "cdr_decode.py", "codec.py")


@pytest.fixture(scope="module")
def log() -> RunLog:
    return add_3d(synthesise("cut_in", "perception", 3))


def _one(log: RunLog, folder: str, stamp: int, record: Any) -> RunLog:
    """A run holding only ``record`` (so assert_logs_equal compares exactly that record)."""
    return RunLog.from_folders(log.metadata, (stamp,), {folder: {stamp: record}})


def _check_row(topic: topics.Topic, record: Any, stamp: int, frame_ms: int) -> tuple[Any, Any]:
    """Both paths of one row on one record: the object is the table's type, our bytes are
    rclpy's bytes of it; returns the record read back from the object and from the bytes."""
    msg = topic.codec.build(record, stamp, frame_ms)
    assert type(msg) is topics.message_types()[topic.key]
    assert rosmsg.type_name(type(msg)) == topic.codec.type_name
    data = topic.codec.encode(record, stamp, frame_ms)
    assert differences(data, serialize_message(msg), msg) == []
    return topic.codec.read(msg, frame_ms), topic.codec.decode(data, frame_ms)


def test_every_data_topic_round_trips_on_both_paths_byte_equal_to_rclpy(log: RunLog) -> None:
    for topic in topics.DATA:
        assert topic.folder is not None and topic.codec.stamp is not None
        stamps = sorted(log.folder(topic.folder))[::15]
        assert stamps, topic.key
        for stamp in stamps:
            record = log.folder(topic.folder)[stamp]
            from_object, from_bytes = _check_row(topic, record, stamp, log.frame_ms)
            data = topic.codec.encode(record, stamp, log.frame_ms)
            msg = topic.codec.build(record, stamp, log.frame_ms)
            assert topic.codec.stamp(data) == message_stamp_ms(msg) == stamp
            assert topics.stamp_ms(topic.key, data) == stamp
            expected = _one(log, topic.folder, stamp, record)
            assert_logs_equal(expected, _one(log, topic.folder, stamp, from_object))
            assert_logs_equal(expected, _one(log, topic.folder, stamp, from_bytes))


def test_the_player_topics_round_trip_their_text_and_time() -> None:
    others = [topic for topic in topics.TABLE if topic.folder is None]
    # A new kind of row must come with a case here.
    assert {id(topic.codec) for topic in others} <= {id(codec.TEXT), id(codec.CLOCK)}
    for topic in others:
        values: list[Any] = (
            ['{"state": "playing", "é": "\\u202e"}', "", "x" * 7]
            if topic.codec is codec.TEXT
            else [0, 1050, -1, 2**40]
        )
        for value in values:
            assert _check_row(topic, value, 0, 50) == (value, value)


def test_the_maps_derive_from_the_table() -> None:
    assert tuple(topic.key for topic in topics.TABLE) == topics.ALL_TOPICS
    assert len(set(topics.ALL_TOPICS)) == len(topics.TABLE)
    assert tuple(topics.FOLDER_TOPICS) == ALL_FOLDERS  # data topics in the folders' order
    assert tuple(topics.FOLDER_TOPICS.values()) == topics.DATA_TOPICS
    assert {topics.FOLDER_TOPICS[f]: f for f in ALL_FOLDERS} == topics.TOPIC_FOLDERS
    optional_data = tuple(str(t.folder) for t in topics.TABLE if t.optional and t.folder)
    assert optional_data == OPTIONAL_FOLDERS
    optional_text = [t.key for t in topics.TABLE if t.optional and not t.folder]
    assert optional_text == [topics.ANNOTATIONS, topics.EGO_PATHS]
    text = {topics.METADATA, topics.ANNOTATIONS, topics.EGO_PATHS, topics.FRAME, topics.STATUS}
    assert text == topics.TEXT_TOPICS
    for topic in topics.TABLE:
        assert topics.MESSAGE_TYPE_NAMES[topic.key] == topic.codec.type_name
        assert topics.QOS[topic.key] is topic.qos
    with pytest.raises(ValueError, match="not a data topic"):
        topics.decode_record(topics.FRAME, b"", 50)


def _python_files() -> list[Path]:
    return sorted(PACKAGE.rglob("*.py")) + sorted((ROOT / "launch_scripts").glob("*.py"))


def test_no_other_module_names_a_topic() -> None:
    """Topic keys are spelled only in topics.py; the data topics' constants are used only
    there (the nodes may name the player's own topics: they treat those specially)."""
    table = PACKAGE / "contract" / "topics.py"
    # "actors" is also a folder's name: its spelling elsewhere is the folder.
    spelled = set(topics.ALL_TOPICS) - set(ALL_FOLDERS)
    data_names = {
        name
        for name, value in vars(topics).items()
        if name.isupper() and isinstance(value, str) and value in topics.DATA_TOPICS
    }
    assert len(data_names) == len(topics.DATA_TOPICS)
    found: list[str] = []
    for path in _python_files():
        if path == table:
            continue
        where = path.relative_to(ROOT)
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Constant) and node.value in spelled:
                found.append(f"{where}:{node.lineno}: {node.value!r}")
            elif isinstance(node, ast.Attribute) and node.attr in data_names:
                found.append(f"{where}:{node.lineno}: .{node.attr}")
            elif isinstance(node, ast.ImportFrom) and node.module == "ads_rca.contract.topics":
                found.extend(
                    f"{where}:{node.lineno}: import {a.name}"
                    for a in node.names
                    if a.name in data_names
                )
    assert found == []


def test_the_codec_modules_sit_below_the_table() -> None:
    for name in CODEC_MODULES:
        path = PACKAGE / "contract" / name
        imported: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                imported.update(alias.name for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.module:
                imported.add(node.module)
                imported.update(f"{node.module}.{alias.name}" for alias in node.names)
        assert "ads_rca.contract.topics" not in imported, name
