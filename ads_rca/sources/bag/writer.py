"""Writes a RunLog as a rosbag2 bag (MCAP or sqlite3) without running ROS.

The bag holds exactly what a recorder would capture while the ``player`` plays the log with
default parameters: ``run/metadata``, ``player/status`` (playing), then per tick ``/clock``,
the tick's data messages and its ``run/frame`` marker, and finally the ``finished`` status.
So a converted bag and a recorded one read back the same way (bag_reader.py), and a bag
player replaying it drives every contract subscriber. Messages are built by the player's own
converters (ads_rca.contract.convert / playback) and serialised by :mod:`ads_rca.contract.rosmsg`
(rosbags, CDR identical to rclpy's). Bag log times are the records' log times.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, TypedDict

from ads_rca.contract import rosmsg, topics
from ads_rca.contract.convert import clock_message, string_message
from ads_rca.contract.ego_paths import ego_path_document
from ads_rca.contract.jsontext import dumps_json
from ads_rca.contract.playback import (
    FINISHED,
    PLAYING,
    annotation_message,
    annotations_by_tick,
    dropped_plan_keys,
    frame_marker,
    metadata_message,
    published_names,
    status_message,
    timeline,
)
from ads_rca.errors import ConfigError
from ads_rca.model import RunLog
from ads_rca.sources.bag.mcap_writer import McapBagWriter, qos_dict, qos_yaml

if TYPE_CHECKING:
    from typing import Unpack  # Python 3.11; annotations only (the package runs on 3.10)

    from rosbags.interfaces import Connection

STORAGES = ("mcap", "sqlite3")
_NS_PER_MS = 1_000_000


class BagSink(Protocol):
    """What both storages offer: topics, serialised messages, close."""

    def add_topic(self, name: str, msg_type: str, qos_profiles: str = "") -> None: ...

    def write(self, topic: str, log_time_ns: int, data: bytes) -> None: ...

    def close(self) -> None: ...


class Sqlite3BagWriter:
    """rosbag2 sqlite3 storage through rosbags' writer (v9 metadata, type hashes)."""

    def __init__(self, out_dir: str | os.PathLike[str]) -> None:
        from rosbags.rosbag2 import StoragePlugin, Writer

        self._writer = Writer(Path(out_dir), version=9, storage_plugin=StoragePlugin.SQLITE3)
        self._writer.open()
        self._connections: dict[str, Connection] = {}

    def add_topic(self, name: str, msg_type: str, qos_profiles: str = "") -> None:
        from rosbags.rosbag2.metadata import parse_qos

        if name in self._connections:
            return
        self._connections[name] = self._writer.add_connection(
            name,
            rosmsg.ensure_type(msg_type),
            msgdef=rosmsg.message_definition(msg_type),
            rihs01=rosmsg.type_hash(msg_type),
            offered_qos_profiles=parse_qos(qos_profiles) if qos_profiles else (),
        )

    def write(self, topic: str, log_time_ns: int, data: bytes) -> None:
        self._writer.write(self._connections[topic], log_time_ns, data)

    def close(self) -> None:
        self._writer.close()


class McapOptions(TypedDict, total=False):
    """The keyword options of :class:`McapBagWriter` (ignored by sqlite3)."""

    chunk_size: int
    compression: str
    fsync: bool


def open_bag_writer(
    out_dir: str | os.PathLike[str], storage: str = "mcap", **options: Unpack[McapOptions]
) -> BagSink:
    """A writer for a new bag directory in ``storage`` (``mcap`` options: chunk_size,
    compression, fsync)."""
    if storage == "mcap":
        return McapBagWriter(out_dir, **options)
    if storage == "sqlite3":
        return Sqlite3BagWriter(out_dir)
    raise ConfigError(f"storage must be one of {STORAGES}, got {storage!r}")


def contract_qos_yaml(key: str) -> str:
    """The player's offered QoS of a topic key, as rosbag2 stores it."""
    spec = topics.QOS[key]
    return qos_yaml([qos_dict(spec.reliable, spec.latched, spec.depth)])


def playback_messages(log: RunLog) -> Iterator[tuple[str, int, Any]]:
    """(topic key, log time ns, message) in the order the player sends them (defaults)."""
    ticks = timeline(log)
    first = max(0, ticks[0].stamp_ms * _NS_PER_MS) if ticks else 0
    playback = {"start_frame": 0, "stop_frame": -1, "ticks": len(ticks)}
    yield topics.METADATA, first, metadata_message(log, playback=playback)
    extra = {"problems": len(log.problems), "loops": 0, "source": log.source}
    yield topics.STATUS, first, status_message(PLAYING, 0, **extra, elapsed_s=0.0)
    last = first
    annotations = annotations_by_tick(log, ticks)
    for position, tick in enumerate(ticks):
        last = max(last, tick.stamp_ms * _NS_PER_MS)
        yield topics.CLOCK, last, clock_message(tick.stamp_ms)
        messages = topics.frame_messages(log, tick.stamp_ms)
        for key, msg in messages.items():
            yield key, last, msg
        for annotation in annotations.get(position, ()):
            yield topics.ANNOTATIONS, last, annotation_message(annotation)
        marker_extra: dict[str, object] = {}
        if dropped := dropped_plan_keys(log, tick.stamp_ms):
            marker_extra["dropped_plan_keys"] = dropped
        paths = ego_path_document(log, tick.stamp_ms)
        if paths is not None:
            yield topics.EGO_PATHS, last, string_message(dumps_json(paths))
            marker_extra["snapshot"] = paths["id"]
        names = [topics.CLOCK, *published_names(messages)]
        yield topics.FRAME, last, frame_marker(tick, names, log.frame_ms, **marker_extra)
    yield topics.STATUS, last, status_message(FINISHED, len(ticks), **extra, elapsed_s=0.0)


def write_bag(
    log: RunLog,
    out_dir: str | os.PathLike[str],
    storage: str = "mcap",
    namespace: str = topics.DEFAULT_NAMESPACE,
    **options: Unpack[McapOptions],
) -> dict[str, int]:
    """Write ``log`` as a bag directory; return the message count per topic name."""
    sink = open_bag_writer(out_dir, storage, **options)
    names = topics.topic_names(namespace)
    counts: dict[str, int] = {}
    try:
        for key in topics.advertised(log):
            sink.add_topic(
                names[key], rosmsg.type_name(topics.message_types()[key]), contract_qos_yaml(key)
            )
        for key, log_time, msg in playback_messages(log):
            sink.write(names[key], log_time, rosmsg.serialize(msg))
            counts[names[key]] = counts.get(names[key], 0) + 1
    finally:
        sink.close()
    return counts
