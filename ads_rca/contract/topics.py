"""The topic table: every topic the player sends, in one place, and what derives from it.

One row per topic (:data:`TABLE`): its key, the kind of record it carries (a
:class:`~ads_rca.contract.codec.Codec`: message type, object and CDR conversions, marker
style), its QoS and, for a per-frame data topic, the log folder. The folder ↔ topic maps,
the type names, the QoS map and the whole-frame conversions on both paths
(:func:`frame_messages`, :func:`frame_payloads`, :func:`message_to_record`,
:func:`decode_record`, :func:`stamp_ms`) are computed from it, so adding a topic of an
existing kind is one row, and no other module names a data topic
(``test/test_codec_table.py``). Nodes, the assembler, the tests and the docs take topic
names from here so that the contract (docs/topics.md) cannot drift between publisher and
subscribers. The player publishes a folder's records on its topic and lists the keys it
sent in each ``run/frame`` marker; monitors and the assembler map the keys back to folders
with :data:`TOPIC_FOLDERS`. Topic keys are the names relative to the ``topic_namespace``
parameter; ``/clock`` is absolute, as ROS wants it.

No ROS import at module level: message types are named here as text and
:func:`message_types` imports the classes on first use; QoS is described with plain data and
:func:`qos_profile` builds the rclpy profile where a node needs it.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from functools import cache
from typing import TYPE_CHECKING, Any

from ads_rca.contract import codec
from ads_rca.contract.codec import Codec
from ads_rca.contract.convert import MarkerStyle
from ads_rca.contract.errors import UnknownTopic
from ads_rca.model import RunLog
from ads_rca.sources.carla.annotations import annotations_from_document

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
OBJECTS_3D = "perception/objects_3d"
TRACKS_3D = "perception/tracks_3d"
CONTROL_COMMAND = "control/command"
#: Map perception (an OpenLane-V2 segment): the ground truth's and a model's lane graphs.
LANES = "map/lanes"
LANES_PREDICTED = "map/lanes_predicted"
#: A run's annotations (a CARLA run's events), each sent with the tick it falls on.
ANNOTATIONS = "run/annotations"
#: A snapshot table's row's future ego paths (realised, predicted), sent with its frame
#: (``ads_rca.contract.ego_paths``).
EGO_PATHS = "run/ego_paths"
FRAME = "run/frame"
STATUS = "player/status"
CLOCK = "/clock"

# The camera for 3D viewers (ads_rca/contract/camera.py): sent once per run, latched, after
# run/metadata. Kept out of the TABLE (which every player, recorder and assembler imports
# the classes of): tf2_msgs has no wheel, so the player sends /tf_static only where it is
# installed, and CameraInfo only when the log gives the intrinsics.
TF_STATIC = "/tf_static"
CAMERA_INFO = "camera/camera_info"
CAMERA_TYPE_NAMES: dict[str, str] = {
    TF_STATIC: "tf2_msgs/msg/TFMessage",
    CAMERA_INFO: "sensor_msgs/msg/CameraInfo",
}


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


@dataclass(frozen=True, slots=True)
class Topic:
    """One row of the table: a topic key, the kind of record it carries and how.

    ``folder``: the log folder (a name in :data:`ads_rca.model.ALL_FOLDERS`) whose records a
    per-frame data topic carries, stamped with their log time; None for the player's own
    topics. ``optional``: the topic is advertised only for a log that has its records
    (:func:`advertised`): the folder is one of :data:`ads_rca.model.OPTIONAL_FOLDERS`, or,
    without a folder, the records are the run's annotations; so a running log without them
    sends and records exactly what it did before they existed."""

    key: str
    codec: Codec[Any]
    qos: QoSSpec = DATA_QOS
    folder: str | None = None
    optional: bool = False


#: THE topic table: every topic the player sends, in publishing order (the data topics in
#: :data:`ads_rca.model.ALL_FOLDERS` order). Everything below derives from it.
TABLE: tuple[Topic, ...] = (
    Topic(METADATA, codec.TEXT, LATCHED_QOS),
    Topic(ODOMETRY, codec.POSE, folder="pose"),
    Topic(ACTORS, codec.actors(MarkerStyle("actors", (0.2, 0.6, 1.0))), folder="actors"),
    Topic(
        DETECTIONS,
        codec.boxes(MarkerStyle("detections", (1.0, 0.5, 0.0))),
        folder="bboxes",
    ),
    Topic(
        GROUND_TRUTH,
        codec.boxes(MarkerStyle("ground_truth", (0.0, 1.0, 0.0))),
        folder="bboxes_gt",
    ),
    Topic(
        PREDICTION_RAW,
        codec.predictions(MarkerStyle("predictions", (1.0, 0.0, 1.0))),
        folder="predictions",
    ),
    Topic(
        PREDICTION_WITH_PERCEPTION,
        codec.predictions(MarkerStyle("predictions_with_perception", (0.0, 1.0, 1.0))),
        folder="predictions_with_perception",
    ),
    Topic(TRAJECTORY, codec.PLAN, folder="waypoint"),
    Topic(
        OBJECTS_3D,
        codec.objects(MarkerStyle("objects_3d", (1.0, 0.8, 0.0))),
        folder="detections_3d",
        optional=True,
    ),
    Topic(
        TRACKS_3D,
        codec.objects(MarkerStyle("tracks_3d", (0.6, 0.2, 1.0))),
        folder="tracks_3d",
        optional=True,
    ),
    Topic(CONTROL_COMMAND, codec.CONTROL, folder="control", optional=True),
    Topic(
        LANES,
        codec.lanes(MarkerStyle("lanes", (1.0, 1.0, 1.0))),
        folder="lanes",
        optional=True,
    ),
    Topic(
        LANES_PREDICTED,
        codec.lanes(MarkerStyle("lanes_predicted", (1.0, 0.3, 0.3))),
        folder="lanes_predicted",
        optional=True,
    ),
    Topic(ANNOTATIONS, codec.TEXT, optional=True),
    Topic(EGO_PATHS, codec.TEXT, optional=True),
    Topic(FRAME, codec.TEXT),
    Topic(STATUS, codec.TEXT, LATCHED_QOS),
    Topic(CLOCK, codec.CLOCK),
)

#: Topic key → its row.
TOPICS: dict[str, Topic] = {topic.key: topic for topic in TABLE}
ALL_TOPICS: tuple[str, ...] = tuple(TOPICS)
#: The per-frame data topics' rows, in :data:`ads_rca.model.ALL_FOLDERS` order.
DATA: tuple[Topic, ...] = tuple(topic for topic in TABLE if topic.folder is not None)
DATA_TOPICS: tuple[str, ...] = tuple(topic.key for topic in DATA)
#: The player's JSON topics (metadata, frame markers, status): std_msgs/String text.
TEXT_TOPICS: frozenset[str] = frozenset(t.key for t in TABLE if t.codec is codec.TEXT)
#: Log folder → the data topic key that carries it, and back.
FOLDER_TOPICS: dict[str, str] = {str(topic.folder): topic.key for topic in DATA}
TOPIC_FOLDERS: dict[str, str] = {topic: folder for folder, topic in FOLDER_TOPICS.items()}
#: Message type of every topic key, as its ROS name (``package/msg/Type``).
MESSAGE_TYPE_NAMES: dict[str, str] = {topic.key: topic.codec.type_name for topic in TABLE}
QOS: dict[str, QoSSpec] = {topic.key: topic.qos for topic in TABLE} | {
    topic: LATCHED_QOS for topic in CAMERA_TYPE_NAMES
}


def advertised(log: RunLog) -> tuple[str, ...]:
    """The topic keys a player of ``log`` advertises (and a bag of it declares): every key
    but the optional data topics whose folder the log has no record in, the annotations of
    a run that has none, and the ego paths of a run that is no snapshot table."""
    return tuple(topic.key for topic in TABLE if not topic.optional or _carries(log, topic))


def _carries(log: RunLog, topic: Topic) -> bool:
    if topic.key == EGO_PATHS:
        return log.ego_snapshots is not None
    if topic.folder is None:  # the annotations
        return bool(annotations_from_document(log.metadata.raw))
    return bool(log.folder(topic.folder))


@cache
def message_types() -> dict[str, type[Any]]:
    """Message class of every topic key (imported here, on first use, not at module import)."""
    out: dict[str, type[Any]] = {}
    for key, name in MESSAGE_TYPE_NAMES.items():
        package, _, cls = name.split("/")
        out[key] = getattr(importlib.import_module(f"{package}.msg"), cls)
    return out


# --- whole frames, both paths ------------------------------------------------------------------


def frame_messages(log: RunLog, timestamp_ms: int) -> dict[str, Any]:
    """Every data message object of one timestamp, keyed by topic key, in ALL_FOLDERS order.

    A folder with no record at ``timestamp_ms`` contributes no message."""
    out: dict[str, Any] = {}
    for topic in DATA:
        record = log.folder(str(topic.folder)).get(timestamp_ms)
        if record is not None:
            out[topic.key] = topic.codec.build(record, timestamp_ms, log.frame_ms)
    return out


def frame_payloads(log: RunLog, timestamp_ms: int) -> dict[str, bytes]:
    """The CDR bytes of :func:`frame_messages` (the fast path), byte for byte what rclpy
    serialises from the objects."""
    out: dict[str, bytes] = {}
    for topic in DATA:
        record = log.folder(str(topic.folder)).get(timestamp_ms)
        if record is not None:
            out[topic.key] = topic.codec.encode(record, timestamp_ms, log.frame_ms)
    return out


def _data(key: str) -> Topic:
    topic = TOPICS.get(key)
    if topic is None or topic.folder is None:
        raise UnknownTopic(f"not a data topic: {key!r}")
    return topic


def message_to_record(key: str, msg: Any, timesteps_per_frame: int) -> Any:
    """The model record a data message object carries (inverse of :func:`frame_messages`)."""
    return _data(key).codec.read(msg, timesteps_per_frame)


def decode_record(key: str, data: bytes, timesteps_per_frame: int) -> Any:
    """The model record a data message's CDR bytes carry; CdrError for bytes that are not a
    well-formed message of the topic."""
    return _data(key).codec.decode(data, timesteps_per_frame)


def stamp_ms(key: str, data: bytes) -> int:
    """Log time of a data message's CDR bytes (NoStamp: a MarkerArray without markers)."""
    stamp = _data(key).codec.stamp
    if stamp is None:
        raise UnknownTopic(f"topic {key!r} carries no stamp")
    return stamp(data)


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
