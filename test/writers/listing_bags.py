"""Bags shaped like real recordings for the listing tests (``inspect BAG`` with no profile).

A real vehicle's bag from 2023-2024 is a rosbag2 sqlite3 file recorded before ROS 2 Iron:
schema 3, a ``topics`` table without type hashes, no ``message_definitions`` table, often no
``metadata.yaml`` (a recorder killed, a copy of the ``.db3`` alone); hundreds of declared
topics most of which never got a message; Autoware's legacy ``autoware_auto_*`` types.
:func:`write_bag` writes such bags with rosbags' writer (MCAP too) and reshapes the sqlite
file as rosbag2 Humble left it. A message's bytes are real CDR only where a test reads them
(:func:`odometry`); a listing never decodes, so elsewhere they are opaque.
"""

from __future__ import annotations

import sqlite3
import struct
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cache
from pathlib import Path

from profilebags import build, header
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore

#: A plausible epoch: nothing may rely on time starting at zero.
EPOCH_NS = 1_700_000_000_000_000_000
#: rosbags wants a type hash; a recording before Iron has none worth checking.
NO_HASH = "RIHS01_" + "0" * 64

LEGACY_PERCEPTION = {
    "/perception/object_recognition/detection/objects": (
        "autoware_auto_perception_msgs/msg/DetectedObjects"
    ),
    "/perception/object_recognition/tracking/objects": (
        "autoware_auto_perception_msgs/msg/TrackedObjects"
    ),
    "/perception/object_recognition/objects": "autoware_auto_perception_msgs/msg/PredictedObjects",
}


@dataclass(frozen=True)
class TopicSpec:
    """One declared topic: its type, its messages' log times, and their bytes (``data``:
    per log time; default 8 opaque bytes)."""

    name: str
    type: str
    times_ns: tuple[int, ...] = ()
    data: Callable[[int], bytes] | None = None


def every(hz: float, seconds: float, start_ns: int = EPOCH_NS) -> tuple[int, ...]:
    """Log times at ``hz`` for ``seconds`` from ``start_ns``."""
    step = int(1e9 / hz)
    return tuple(start_ns + i * step for i in range(round(hz * seconds)))


@cache
def kilted() -> Typestore:
    return get_typestore(Stores.ROS2_KILTED)


def odometry(time_ns: int) -> bytes:
    """A real nav_msgs/msg/Odometry (CDR) stamped at ``time_ns``, the ego moving along x."""
    store = kilted()
    seconds = (time_ns - EPOCH_NS) / 1e9
    message = build(
        store,
        "nav_msgs/msg/Odometry",
        {
            "header": header(time_ns),
            "child_frame_id": "base_link",
            "pose": {"pose": {"position": {"x": 5.0 * seconds}, "orientation": {"w": 1.0}}},
            "twist": {"twist": {"linear": {"x": 5.0}}},
        },
    )
    return bytes(store.serialize_cdr(message, "nav_msgs/msg/Odometry"))


def write_bag(
    path: Path,
    topics: Sequence[TopicSpec],
    storage: str = "sqlite3",
    pre_iron: bool = False,
    metadata_yaml: bool = True,
) -> Path:
    """A bag of ``topics`` at ``path`` (rosbags' writer; standard types with their Kilted
    definitions, others with none). ``pre_iron``: the sqlite3 file as rosbag2 Humble wrote
    it (schema 3, no ``message_definitions`` table, no type hashes)."""
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    store = kilted()
    with Writer(path, version=8, storage_plugin=plugin) as writer:
        connections = {}
        for spec in topics:
            known = spec.type in store.fielddefs
            definition = store.generate_msgdef(spec.type, ros_version=2)[0] if known else ""
            connections[spec.name] = writer.add_connection(
                spec.name,
                spec.type,
                msgdef=definition,
                rihs01=store.hash_rihs01(spec.type) if known else NO_HASH,
            )
        timeline = sorted(
            ((t, spec) for spec in topics for t in spec.times_ns), key=lambda item: item[0]
        )
        for time_ns, spec in timeline:
            data = spec.data(time_ns) if spec.data is not None else b"\x00\x01\x00\x00opaque"
            writer.write(connections[spec.name], time_ns, data)
    if pre_iron:
        humble_shape(storage_file(path))
    if not metadata_yaml:
        (path / "metadata.yaml").unlink()
    return path


def storage_file(bag: Path) -> Path:
    """The one storage file of a bag written here."""
    (found,) = [p for p in bag.iterdir() if p.suffix in (".db3", ".mcap")]
    return found


def humble_shape(db3: Path) -> None:
    """A sqlite3 bag reshaped as rosbag2 before Iron wrote it."""
    with sqlite3.connect(db3) as connection:
        connection.execute("DROP TABLE message_definitions")
        connection.execute("ALTER TABLE topics DROP COLUMN type_description_hash")
        connection.execute("UPDATE schema SET schema_version = 3, ros_distro = 'humble'")
    connection.close()


def vehicle_topics(declared: int = 320, seconds: float = 2.0) -> list[TopicSpec]:
    """A real vehicle's recording: localisation at 50 Hz (real Odometry), planning at
    10 Hz and control at 30 Hz in the legacy types, perception declared in the legacy
    types but without a message (it did not run), one topic with a single message, and
    ``declared`` topics in all (the rest sensors and debug topics never published)."""
    topics = [
        TopicSpec(
            "/localization/kinematic_state",
            "nav_msgs/msg/Odometry",
            every(50, seconds),
            odometry,
        ),
        TopicSpec(
            "/planning/scenario_planning/trajectory",
            "autoware_auto_planning_msgs/msg/Trajectory",
            every(10, seconds),
        ),
        TopicSpec(
            "/control/command/control_cmd",
            "autoware_auto_control_msgs/msg/AckermannControlCommand",
            every(30, seconds),
        ),
        TopicSpec("/autoware/state", "autoware_auto_system_msgs/msg/AutowareState", (EPOCH_NS,)),
        *(TopicSpec(name, msg_type) for name, msg_type in LEGACY_PERCEPTION.items()),
    ]
    kinds = (
        ("/sensing/lidar/{}/pointcloud", "sensor_msgs/msg/PointCloud2"),
        ("/sensing/camera/{}/image_raw", "sensor_msgs/msg/Image"),
        ("/planning/debug/{}", "tier4_debug_msgs/msg/Float64Stamped"),
        ("/perception/debug/{}/markers", "visualization_msgs/msg/MarkerArray"),
    )
    for i in range(declared - len(topics)):
        pattern, msg_type = kinds[i % len(kinds)]
        topics.append(TopicSpec(pattern.format(i), msg_type))
    return topics


def without_summary(mcap: Path) -> None:
    """An MCAP file rewritten as a recorder that keeps no summary leaves it: the data
    section, then a footer whose summary start is 0 (every record before the data end
    kept as written)."""
    data = mcap.read_bytes()
    pos = 8  # the magic
    while True:
        opcode, length = struct.unpack_from("<BQ", data, pos)
        pos += 9 + length
        if opcode == 0x0F:  # data end
            break
    footer = struct.pack("<BQQQI", 0x02, 20, 0, 0, 0)
    mcap.write_bytes(data[:pos] + footer + data[:8])
