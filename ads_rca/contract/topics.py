"""The topic contract in one place: names, message types and QoS of everything the player sends.

Nodes, the assembler, the tests and the docs all take topic names from here so that the
contract (docs/topics.md) cannot drift between publisher and subscribers. The player
publishes a folder's records on its topic and lists the keys it sent in each ``run/frame``
marker; monitors and the assembler map the keys back to folders with :data:`TOPIC_FOLDERS`.
Topic keys are the names relative to the ``topic_namespace`` parameter; ``/clock`` is
absolute, as ROS wants it.
No ROS import at module level: message types are named here as text and
:func:`message_types` imports the classes on first use; QoS is described with plain data and
:func:`qos_profile` builds the rclpy profile where a node needs it.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from functools import cache
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from rclpy.qos import QoSProfile

DEFAULT_NAMESPACE = "/ads_rca"

# Topic keys (relative names).
METADATA = "run/metadata"
ODOMETRY = "ego/odometry"
ACTORS = "actors"
DETECTIONS = "perception/detections"
GROUND_TRUTH = "perception/ground_truth"
PREDICTION_RAW = "prediction/raw"
PREDICTION_WITH_PERCEPTION = "prediction/with_perception"
TRAJECTORY = "planning/trajectory"
FRAME = "run/frame"
STATUS = "player/status"
CLOCK = "/clock"

#: Per-frame data topics, keyed by the log folder they carry (in :data:`ads_rca.model.FOLDERS`
#: order). Their messages are stamped with the frame's log time.
FOLDER_TOPICS: dict[str, str] = {
    "pose": ODOMETRY,
    "actors": ACTORS,
    "bboxes": DETECTIONS,
    "bboxes_gt": GROUND_TRUTH,
    "predictions": PREDICTION_RAW,
    "predictions_with_perception": PREDICTION_WITH_PERCEPTION,
    "waypoint": TRAJECTORY,
}
#: Data topic key → the log folder it carries.
TOPIC_FOLDERS: dict[str, str] = {topic: folder for folder, topic in FOLDER_TOPICS.items()}
DATA_TOPICS: tuple[str, ...] = tuple(FOLDER_TOPICS.values())


#: Message type of every topic key, as its ROS name (``package/msg/Type``).
MESSAGE_TYPE_NAMES: dict[str, str] = {
    METADATA: "std_msgs/msg/String",
    ODOMETRY: "nav_msgs/msg/Odometry",
    ACTORS: "visualization_msgs/msg/MarkerArray",
    DETECTIONS: "visualization_msgs/msg/MarkerArray",
    GROUND_TRUTH: "visualization_msgs/msg/MarkerArray",
    PREDICTION_RAW: "visualization_msgs/msg/MarkerArray",
    PREDICTION_WITH_PERCEPTION: "visualization_msgs/msg/MarkerArray",
    TRAJECTORY: "trajectory_msgs/msg/MultiDOFJointTrajectory",
    FRAME: "std_msgs/msg/String",
    STATUS: "std_msgs/msg/String",
    CLOCK: "rosgraph_msgs/msg/Clock",
}
ALL_TOPICS: tuple[str, ...] = tuple(MESSAGE_TYPE_NAMES)

# The camera for 3D viewers (ads_rca/contract/camera.py): sent once per run, latched, after
# run/metadata. Kept out of ALL_TOPICS (which every player, recorder and assembler imports
# the classes of): tf2_msgs has no wheel, so the player sends /tf_static only where it is
# installed, and CameraInfo only when the log gives the intrinsics.
TF_STATIC = "/tf_static"
CAMERA_INFO = "camera/camera_info"
CAMERA_TYPE_NAMES: dict[str, str] = {
    TF_STATIC: "tf2_msgs/msg/TFMessage",
    CAMERA_INFO: "sensor_msgs/msg/CameraInfo",
}


@cache
def message_types() -> dict[str, type[Any]]:
    """Message class of every topic key (imported here, on first use, not at module import)."""
    out: dict[str, type[Any]] = {}
    for key, name in MESSAGE_TYPE_NAMES.items():
        package, _, cls = name.split("/")
        out[key] = getattr(importlib.import_module(f"{package}.msg"), cls)
    return out


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
} | {topic: LATCHED_QOS for topic in CAMERA_TYPE_NAMES}


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
