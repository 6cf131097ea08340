"""Reads rosbag2 bags (MCAP or sqlite3) whose topics follow our contract back into a RunLog.

A bag recorded from the player (``recorder`` node), written by ``ads-rca convert``, or made
by a stack whose topics carry the contract's types under other names (mapped by a remapping
YAML, see docs/topics.md) is replayed into the same :class:`RunLogAssembler` the live
subscribers use, so a bag and a DDS stream rebuild the same log. Pure: rosbags reads the
storage, :mod:`ads_rca.io.rosmsg` turns CDR into message objects; no rclpy.

Accepted paths: a bag directory with ``metadata.yaml``; a directory holding one ``.mcap`` /
``.db3`` file (a recording whose writer was killed before writing ``metadata.yaml``); a bare
``.mcap`` or ``.db3`` file. An MCAP file without a summary (killed recorder) is read
up to its last complete chunk.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import yaml

from ads_rca.errors import InputError
from ads_rca.io import rosmsg
from ads_rca.model import RunLog
from ads_rca.ros import topics
from ads_rca.ros.assembler import RunLogAssembler

BAG_SUFFIXES = (".mcap", ".db3")


@dataclass(frozen=True)
class BagMessage:
    topic: str
    msg_type: str
    log_time_ns: int
    data: bytes


@dataclass(frozen=True)
class Remap:
    """Their topic name → our topic key; optional metadata.json document for bags without
    ``run/metadata``."""

    topics: dict[str, str] = field(default_factory=dict)
    metadata: dict[str, Any] | None = None


def load_remap(path: str | os.PathLike[str]) -> Remap:
    """A remapping YAML: ``{their_topic: our_topic_key, ..., metadata: {...}}``."""
    document = yaml.safe_load(Path(path).read_text(encoding="utf-8")) or {}
    if not isinstance(document, dict):
        raise InputError(f"{path}: a remapping file is a mapping of topic → topic key")
    metadata = document.pop("metadata", None)
    mapping: dict[str, str] = {}
    for theirs, ours in document.items():
        key = str(ours)
        if key not in topics.ALL_TOPICS:
            raise InputError(f"{path}: {ours!r} is not a contract topic key {topics.ALL_TOPICS}")
        mapping[str(theirs)] = key
    if metadata is not None and not isinstance(metadata, dict):
        raise InputError(f"{path}: 'metadata' must be a mapping (a metadata.json document)")
    return Remap(mapping, metadata)


# --- locating and iterating -------------------------------------------------------------


def _storage_files(directory: Path) -> list[Path]:
    return sorted(p for p in directory.iterdir() if p.suffix in BAG_SUFFIXES and p.is_file())


def is_bag(path: str | os.PathLike[str]) -> bool:
    """A bag directory (metadata.yaml, or one storage file) or a .mcap/.db3 file."""
    p = Path(path)
    if p.is_file():
        return p.suffix in BAG_SUFFIXES
    if p.is_dir():
        return (p / "metadata.yaml").is_file() or len(_storage_files(p)) == 1
    return False


def iter_bag(path: str | os.PathLike[str]) -> Iterator[BagMessage]:
    """Every message of a bag in log-time order (file order for a truncated MCAP)."""
    p = Path(path)
    if p.is_dir() and (p / "metadata.yaml").is_file():
        yield from _iter_rosbags_dir(p)
        return
    if p.is_dir():
        files = _storage_files(p)
        if len(files) != 1:
            raise InputError(f"{p}: not a bag (no metadata.yaml and no single .mcap/.db3)")
        p = files[0]
    if not p.is_file():
        raise InputError(f"{p}: no such bag")
    if p.suffix == ".mcap":
        yield from _iter_mcap_file(p)
    elif p.suffix == ".db3":
        yield from _iter_storage(p, "sqlite3")
    else:
        raise InputError(f"{p}: not a bag file (.mcap or .db3)")


def _iter_rosbags_dir(path: Path) -> Iterator[BagMessage]:
    from rosbags.rosbag2 import Reader

    with Reader(path) as reader:
        for conn, timestamp, data in reader.messages():
            yield BagMessage(conn.topic, conn.msgtype, timestamp, bytes(data))


def _iter_storage(path: Path, kind: str) -> Iterator[BagMessage]:
    from rosbags.rosbag2.storage_mcap import McapReader
    from rosbags.rosbag2.storage_sqlite3 import Sqlite3Reader

    storage: Any = McapReader(path) if kind == "mcap" else Sqlite3Reader(path)
    storage.open()
    try:
        for conn, timestamp, data in storage.messages(storage.connections):
            yield BagMessage(conn.topic, conn.msgtype, timestamp, bytes(data))
    finally:
        storage.close()


def _iter_mcap_file(path: Path) -> Iterator[BagMessage]:
    from rosbags.rosbag2.errors import ReaderError

    try:
        messages = list(_iter_storage(path, "mcap"))
    except (ReaderError, AssertionError, ValueError, OSError):
        messages = list(iter_mcap_stream(path))
    yield from messages


def iter_mcap_stream(path: str | os.PathLike[str]) -> Iterator[BagMessage]:
    """Stream-read an MCAP, stopping quietly at a truncated end (complete chunks only)."""
    from mcap.reader import NonSeekingReader

    with open(path, "rb") as stream:
        reader = NonSeekingReader(stream)
        iterator = reader.iter_messages(log_time_order=False)
        while True:
            try:
                schema, channel, message = next(iterator)
            except StopIteration:
                return
            except Exception:  # a truncated tail: end of the complete chunks
                return
            yield BagMessage(
                channel.topic,
                schema.name if schema is not None else "",
                message.log_time,
                bytes(message.data),
            )


def bag_topics(path: str | os.PathLike[str]) -> dict[str, str]:
    """Topic name → type of every topic a bag holds messages on."""
    out: dict[str, str] = {}
    for message in iter_bag(path):
        out.setdefault(message.topic, message.msg_type)
    return out


# --- rebuilding the log -------------------------------------------------------------------


def detect_namespace(names: list[str]) -> str:
    """The contract namespace a bag's topic names use (default when none matches)."""
    anchors = (topics.METADATA, topics.FRAME, topics.STATUS, *topics.DATA_TOPICS)
    votes: dict[str, int] = {}
    for name in names:
        for key in anchors:
            if name.endswith("/" + key):
                namespace = topics.normalise_namespace(name[: -len(key) - 1])
                votes[namespace] = votes.get(namespace, 0) + 1
    if not votes:
        return topics.DEFAULT_NAMESPACE
    return max(votes, key=lambda ns: votes[ns])


def topic_keys(
    names: list[str], remap: Remap | None = None, namespace: str | None = None
) -> dict[str, str]:
    """Bag topic name → contract key, by remapping or by the contract's names."""
    if remap is not None and remap.topics:
        return {name: key for name, key in remap.topics.items() if name in names}
    ns = detect_namespace(names) if namespace is None else namespace
    full = topics.topic_names(ns)
    return {full[key]: key for key in topics.ALL_TOPICS if full[key] in names}


def read_bag(
    path: str | os.PathLike[str],
    remap: Remap | str | os.PathLike[str] | None = None,
    namespace: str | None = None,
) -> RunLog:
    """Rebuild the RunLog a bag carries (see the module docstring for accepted paths)."""
    if remap is not None and not isinstance(remap, Remap):
        remap = load_remap(remap)
    from rosbags.rosbag2.errors import ReaderError

    try:
        messages = list(iter_bag(path))
    except (ReaderError, OSError) as error:
        raise InputError(f"{path}: cannot read the bag: {error}") from error
    keys = topic_keys(sorted({m.topic for m in messages}), remap, namespace)
    assembler = RunLogAssembler()
    for message in messages:
        key = keys.get(message.topic)
        if key is None:
            continue
        expected = rosmsg.type_name(topics.MESSAGE_TYPES[key])
        if rosmsg.normalise_type(message.msg_type) != expected:
            raise InputError(
                f"{path}: topic {message.topic} has type {message.msg_type}, "
                f"the contract's {key} is {expected}"
            )
        assembler.add(key, rosmsg.deserialize(message.data, expected))
    if assembler.metadata_document is None and remap is not None and remap.metadata:
        assembler.metadata_document = dict(remap.metadata)
    if assembler.metadata_document is None:
        raise InputError(
            f"{path}: the bag has no run/metadata message (map one, or give 'metadata' in "
            "the remapping file)"
        )
    log = assembler.build()
    if not assembler.markers:  # no frame markers (a stack's bag): actors stamps are frames
        log = replace(log, frames=tuple(sorted(log.actors)))
    return replace(log, source=str(path))
