"""The topic contract in one place: names, message types and QoS of everything the player sends.

Nodes, the assembler, the tests and the docs all take topic names from here so that the
contract (docs/topics.md) cannot drift between publisher and subscribers. The keys and the
folder ↔ topic table are :mod:`ads_rca.contract.topics` (pure, re-exported here).
Topic keys are the names relative to the ``topic_namespace`` parameter; ``/clock`` is
absolute, as ROS wants it.
QoS is described with plain data so this module imports no rclpy; :func:`qos_profile` builds
the rclpy profile where a node needs it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from nav_msgs.msg import Odometry
from rosgraph_msgs.msg import Clock
from std_msgs.msg import String
from trajectory_msgs.msg import MultiDOFJointTrajectory
from visualization_msgs.msg import MarkerArray

from ads_rca.contract.topics import (
    ACTORS,
    CLOCK,
    DATA_TOPICS,
    DEFAULT_NAMESPACE,
    DETECTIONS,
    FOLDER_TOPICS,
    FRAME,
    GROUND_TRUTH,
    METADATA,
    ODOMETRY,
    PREDICTION_RAW,
    PREDICTION_WITH_PERCEPTION,
    STATUS,
    TOPIC_FOLDERS,
    TRAJECTORY,
)

if TYPE_CHECKING:
    from rclpy.qos import QoSProfile

#: The keys and folder table come from :mod:`ads_rca.contract.topics` (re-exported).
__all__ = [
    "ACTORS",
    "ALL_TOPICS",
    "CLOCK",
    "DATA_QOS",
    "DATA_TOPICS",
    "DEFAULT_NAMESPACE",
    "DETECTIONS",
    "EGO_FRAME",
    "FOLDER_TOPICS",
    "FRAME",
    "GROUND_TRUTH",
    "IMAGE_FRAME",
    "LATCHED_QOS",
    "LATCHED_READER_DEPTH",
    "MESSAGE_TYPES",
    "METADATA",
    "ODOMETRY",
    "PREDICTION_RAW",
    "PREDICTION_WITH_PERCEPTION",
    "QOS",
    "STATUS",
    "TOPIC_FOLDERS",
    "TRAJECTORY",
    "WORLD_FRAME",
    "QoSSpec",
    "normalise_namespace",
    "qos_profile",
    "topic_name",
    "topic_names",
]


#: Message type of every topic key.
MESSAGE_TYPES: dict[str, type[Any]] = {
    METADATA: String,
    ODOMETRY: Odometry,
    ACTORS: MarkerArray,
    DETECTIONS: MarkerArray,
    GROUND_TRUTH: MarkerArray,
    PREDICTION_RAW: MarkerArray,
    PREDICTION_WITH_PERCEPTION: MarkerArray,
    TRAJECTORY: MultiDOFJointTrajectory,
    FRAME: String,
    STATUS: String,
    CLOCK: Clock,
}
ALL_TOPICS: tuple[str, ...] = tuple(MESSAGE_TYPES)

# Frame ids.
WORLD_FRAME = "map"
EGO_FRAME = "base_link"
IMAGE_FRAME = "camera_image"


@dataclass(frozen=True, slots=True)
class QoSSpec:
    """A QoS profile as plain data (so the contract can be read without rclpy)."""

    depth: int
    reliable: bool = True
    latched: bool = False  # TRANSIENT_LOCAL durability

    def describe(self) -> str:
        reliability = "RELIABLE" if self.reliable else "BEST_EFFORT"
        durability = "TRANSIENT_LOCAL" if self.latched else "VOLATILE"
        return f"{reliability}, {durability}, KEEP_LAST {self.depth}"


DATA_QOS = QoSSpec(depth=100)
LATCHED_QOS = QoSSpec(depth=1, latched=True)
#: History depth of a lossless reader of a latched topic (see :func:`qos_profile`).
LATCHED_READER_DEPTH = 100

QOS: dict[str, QoSSpec] = {
    topic: (LATCHED_QOS if topic in (METADATA, STATUS) else DATA_QOS) for topic in ALL_TOPICS
}


def normalise_namespace(namespace: str) -> str:
    """``ads_rca/``, ``/ads_rca`` → ``/ads_rca``; empty or ``/`` → ``""`` (root)."""
    stripped = namespace.strip().strip("/")
    return f"/{stripped}" if stripped else ""


def topic_name(key: str, namespace: str = DEFAULT_NAMESPACE) -> str:
    """Full name of a topic key under ``namespace`` (absolute keys are returned unchanged)."""
    if key.startswith("/"):
        return key
    return f"{normalise_namespace(namespace)}/{key}"


def topic_names(namespace: str = DEFAULT_NAMESPACE) -> dict[str, str]:
    """Every topic key → its full name."""
    return {key: topic_name(key, namespace) for key in ALL_TOPICS}


def qos_profile(key: str, depth: int | None = None, keep_all: bool = False) -> QoSProfile:
    """The rclpy QoS profile of a topic key (``depth`` overrides the contract's history depth).

    ``keep_all``: for subscribers that must lose nothing (recorder, monitors, summary). A
    reliable KEEP_ALL reader withholds its acknowledgements while its queue is full, so a
    player pacing itself on acknowledgements (rate 0) waits instead of overwriting samples
    the reader has not taken yet. Latched topics stay KEEP_LAST (a late joiner gets the
    writer's last sample), but such a reader keeps :data:`LATCHED_READER_DEPTH` samples:
    its history is shared by every writer of the topic (keyless types have one instance),
    so with depth 1 another run's player sending its metadata just after ours would
    overwrite ours before the callback took it.
    """
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    spec = QOS[key]
    if depth is None:
        depth = LATCHED_READER_DEPTH if keep_all and spec.latched else spec.depth
    return QoSProfile(
        history=HistoryPolicy.KEEP_ALL
        if keep_all and not spec.latched
        else HistoryPolicy.KEEP_LAST,
        depth=depth,
        reliability=(
            ReliabilityPolicy.RELIABLE if spec.reliable else ReliabilityPolicy.BEST_EFFORT
        ),
        durability=(
            DurabilityPolicy.TRANSIENT_LOCAL if spec.latched else DurabilityPolicy.VOLATILE
        ),
    )
