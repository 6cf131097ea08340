"""A rosbag2-compatible MCAP bag writer for already-serialised CDR messages (no rclpy).

Why not rosbags' writer: a recorder must survive being killed. This writer decides itself
when a chunk ends (every ``chunk_size`` bytes, or when :meth:`McapBagWriter.flush` is
called, e.g. by a timer) and hands each finished chunk, with its message indexes, to the
operating system at once, so a SIGKILL loses at most the chunk being filled: the file then
ends without a summary, and a streaming MCAP reader still reads every complete chunk.
:meth:`close` writes what rosbag2 writes: a ``rosbag2`` metadata record, the summary
(schemas, channels, statistics, chunk and metadata indexes) and ``metadata.yaml``.

Layout (as ``ros2 bag record -s mcap``): ``OUT/metadata.yaml`` + ``OUT/OUT_0.mcap``; profile
``ros2``; one ``ros2msg`` schema per type named ``pkg/msg/Type`` holding the concatenated
definition; one ``cdr`` channel per topic with metadata ``offered_qos_profiles`` (rosbag2 v9
YAML) and ``topic_type_hash`` (RIHS01). Chunks are zstd-compressed by default: CDR of marker
arrays is very repetitive (frame ids, namespaces, colours, padding), every rosbag2/MCAP reader
decodes zstd, and zstd's default level keeps up with a recorder; ``lz4`` and ``none`` are
available for CPU-starved recorders.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml
from mcap.writer import CompressionType, Writer

from ads_rca.contract.rosmsg import message_definition, type_hash
from ads_rca.errors import ConfigError
from ads_rca.sources.errors import OutputExists

#: rosbag2 metadata version written: Jazzy's and later rosbag2, rosbags and the mcap tools
#: read it; Humble's rosbag2 (metadata version 5) does not (it reads each topic's
#: ``offered_qos_profiles`` as a string, and version 9 writes a list).
BAG_VERSION = 9
#: The distribution whose message definitions and type hashes the contract's types carry
#: (rosbags' Kilted store): a bag written outside ROS (``ads-rca convert``) says this one;
#: the recorder says the distribution it runs on (``ads_rca.ros.env.ros_distro``).
TYPES_DISTRO = "kilted"
DEFAULT_CHUNK_SIZE = 1 << 20
COMPRESSIONS: dict[str, CompressionType] = {
    "zstd": CompressionType.ZSTD,
    "lz4": CompressionType.LZ4,
    "none": CompressionType.NONE,
}
#: RMW's "infinite" duration as rosbag2 writes it into QoS YAML.
_INFINITE = {"sec": 9223372036, "nsec": 854775807}
_RECORD_OVERHEAD = 31  # opcode, length, channel id, sequence, log and publish time


def qos_dict(
    reliable: bool = True, transient_local: bool = False, depth: int = 10, keep_all: bool = False
) -> dict[str, Any]:
    """One offered QoS profile in rosbag2's v9 form (names in lower case)."""
    return {
        "history": "keep_all" if keep_all else "keep_last",
        "depth": depth,
        "reliability": "reliable" if reliable else "best_effort",
        "durability": "transient_local" if transient_local else "volatile",
        "deadline": dict(_INFINITE),
        "lifespan": dict(_INFINITE),
        "liveliness": "automatic",
        "liveliness_lease_duration": dict(_INFINITE),
        "avoid_ros_namespace_conventions": False,
    }


def qos_yaml(profiles: list[dict[str, Any]]) -> str:
    """The ``offered_qos_profiles`` YAML text rosbag2 stores per channel."""
    if not profiles:
        return ""
    text: str = yaml.safe_dump(profiles, default_flow_style=False, sort_keys=False)
    return text.strip()


def bag_file_name(out_dir: str | os.PathLike[str], extension: str = "mcap") -> Path:
    """rosbag2's first file of a bag directory: ``OUT/OUT_0.<extension>``."""
    root = Path(out_dir)
    return root / f"{root.name}_0.{extension}"


@dataclass
class _Topic:
    channel_id: int
    name: str
    type: str
    qos: str
    hash: str
    count: int = 0
    sequence: int = 0


class McapBagWriter:
    """Writes one rosbag2 MCAP bag directory; topics first, then messages as bytes."""

    def __init__(
        self,
        out_dir: str | os.PathLike[str],
        *,
        chunk_size: int = DEFAULT_CHUNK_SIZE,
        compression: str = "zstd",
        fsync: bool = False,
        ros_distro: str = TYPES_DISTRO,
    ) -> None:
        if compression not in COMPRESSIONS:
            raise ConfigError(f"compression must be one of {sorted(COMPRESSIONS)}")
        self.root = Path(out_dir)
        if self.root.exists() and any(self.root.iterdir()):
            raise OutputExists(f"{self.root} exists and is not empty")
        self.root.mkdir(parents=True, exist_ok=True)
        self.path = bag_file_name(self.root)
        self.chunk_size = max(1, int(chunk_size))
        self.compression = compression
        self.fsync = fsync
        self.ros_distro = ros_distro
        self._stream = self.path.open("xb")
        # The library's own chunk limit is never reached: chunks end where we flush.
        self._mcap = Writer(self._stream, chunk_size=2**62, compression=COMPRESSIONS[compression])
        self._mcap.start(profile="ros2", library=f"ads_rca rosbag2-mcap ({ros_distro})")
        self._schemas: dict[str, int] = {}
        self._topics: dict[str, _Topic] = {}
        self._pending = 0
        self._start = 2**63 - 1
        self._end = 0
        self._custom: dict[str, str] = {}
        self.chunks_flushed = 0
        self.closed = False

    # --- topics -------------------------------------------------------------------------

    def add_topic(
        self,
        name: str,
        msg_type: str,
        qos_profiles: str = "",
        topic_type_hash: str | None = None,
        definition: str | None = None,
    ) -> None:
        """Register a topic (idempotent). ``msg_type`` is ``pkg/msg/Type``; the definition
        and hash default to the installed type's."""
        if name in self._topics:
            return
        digest = topic_type_hash if topic_type_hash is not None else type_hash(msg_type)
        schema_id = self._schemas.get(msg_type)
        if schema_id is None:
            text = definition if definition is not None else message_definition(msg_type)
            schema_id = self._mcap.register_schema(msg_type, "ros2msg", text.encode("utf-8"))
            self._schemas[msg_type] = schema_id
        metadata = {"offered_qos_profiles": qos_profiles, "topic_type_hash": digest}
        channel_id = self._mcap.register_channel(name, "cdr", schema_id, metadata)
        self._topics[name] = _Topic(channel_id, name, msg_type, qos_profiles, digest)

    def has_topic(self, name: str) -> bool:
        return name in self._topics

    # --- messages -----------------------------------------------------------------------

    def write(
        self, topic: str, log_time_ns: int, data: bytes, publish_time_ns: int | None = None
    ) -> None:
        """Append one serialised message (``topic`` must be registered)."""
        entry = self._topics[topic]
        self._mcap.add_message(
            entry.channel_id,
            log_time=log_time_ns,
            data=data,
            publish_time=log_time_ns if publish_time_ns is None else publish_time_ns,
            sequence=entry.sequence,
        )
        entry.sequence = (entry.sequence + 1) & 0xFFFFFFFF
        entry.count += 1
        self._start = min(self._start, log_time_ns)
        self._end = max(self._end, log_time_ns)
        self._pending += len(data) + _RECORD_OVERHEAD
        if self._pending >= self.chunk_size:
            self.flush()

    def flush(self) -> None:
        """End the current chunk (if it holds messages) and hand it to the OS."""
        if self._pending == 0:
            return
        self._mcap.flush()  # type: ignore[no-untyped-call]  # mcap's Writer.flush is unannotated
        if self.fsync:
            os.fsync(self._stream.fileno())
        self._pending = 0
        self.chunks_flushed += 1

    @property
    def message_count(self) -> int:
        return sum(t.count for t in self._topics.values())

    def counts(self) -> dict[str, int]:
        """Messages written per topic."""
        return {name: t.count for name, t in self._topics.items()}

    def set_custom_data(self, key: str, value: str) -> None:
        """A ``custom_data`` entry of the bag metadata."""
        self._custom[key] = value

    # --- closing ------------------------------------------------------------------------

    def metadata(self) -> dict[str, Any]:
        """The ``rosbag2_bagfile_information`` document (metadata.yaml and the MCAP record)."""
        count = self.message_count
        start = self._start if count else 0
        duration = self._end - self._start if count else 0
        return {
            "version": BAG_VERSION,
            "storage_identifier": "mcap",
            "duration": {"nanoseconds": duration},
            "starting_time": {"nanoseconds_since_epoch": start},
            "message_count": count,
            "topics_with_message_count": [
                {
                    "topic_metadata": {
                        "name": t.name,
                        "type": t.type,
                        "serialization_format": "cdr",
                        "offered_qos_profiles": yaml.safe_load(t.qos) if t.qos else [],
                        "type_description_hash": t.hash,
                    },
                    "message_count": t.count,
                }
                for t in self._topics.values()
            ],
            "compression_format": "",
            "compression_mode": "",
            "relative_file_paths": [self.path.name],
            "files": [
                {
                    "path": self.path.name,
                    "starting_time": {"nanoseconds_since_epoch": start},
                    "duration": {"nanoseconds": duration},
                    "message_count": count,
                }
            ],
            "custom_data": dict(self._custom) or None,
            "ros_distro": self.ros_distro,
        }

    def close(self) -> None:
        """Last chunk, ``rosbag2`` metadata record, summary, footer; then metadata.yaml."""
        if self.closed:
            return
        self.closed = True
        document = self.metadata()
        serialized = yaml.safe_dump(document, default_flow_style=False, sort_keys=False)
        self.flush()
        self._mcap.add_metadata(
            "rosbag2", {"serialized_metadata": serialized, "ROS_DISTRO": self.ros_distro}
        )
        self._mcap.finish()  # type: ignore[no-untyped-call]  # mcap's Writer.finish is unannotated
        self._stream.flush()
        os.fsync(self._stream.fileno())
        self._stream.close()
        write_metadata_yaml(self.root, document)

    def __enter__(self) -> McapBagWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def write_metadata_yaml(root: Path, document: dict[str, Any]) -> Path:
    """``metadata.yaml`` of a bag directory, replaced atomically."""
    path = root / "metadata.yaml"
    partial = root / "metadata.yaml.tmp"
    text = yaml.safe_dump(
        {"rosbag2_bagfile_information": document}, default_flow_style=False, sort_keys=False
    )
    partial.write_text(text, encoding="utf-8")
    partial.replace(path)
    return path
