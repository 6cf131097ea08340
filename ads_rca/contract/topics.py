"""Topic keys and which log folder each data topic carries: one table, no ROS import.

Topic keys are names relative to the ``topic_namespace`` parameter (docs/topics.md). The
player publishes a folder's records on its topic and lists the keys it sent in each
``run/frame`` marker; monitors and the assembler map the keys back to folders with
:data:`TOPIC_FOLDERS`. Message types and QoS are in :mod:`ads_rca.ros.topics`.
"""

from __future__ import annotations

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
