"""Bags shaped like a real Autoware vehicle's recording, written from a synthesised run.

No recording of a real drive can be shipped, so the tests write their own from a
:class:`~ads_rca.model.RunLog` whose truth is known, the way ``ros2 bag record`` on an
Autoware vehicle keeps it: localisation (``/localization/kinematic_state``) and the
vehicle's velocity report at 50 Hz, perception, prediction and planning at 10 Hz, control
at the run's own rate, the fail-safe (MRM) state at 10 Hz (NORMAL, then MRM_OPERATING /
EMERGENCY_STOP from ``emergency_at_ms``), hundreds of other topics declared with no message,
no ground truth and no collision topic. Options: the legacy ``autoware_auto_*_msgs`` types
instead of the current ones, no tracking topic, and the storage: ``mcap`` or ``sqlite3``
(rosbag2 Iron and later: definitions stored) or ``humble`` (rosbag2 before Iron: a sqlite3
file of schema 3 with no ``message_definitions`` table and a version 5 metadata.yaml).

Each object's PredictedObject carries its track's state (pose with the track's yaw, twist
in the object's own frame, shape, class, existence probability), as Autoware's prediction
copies it from the tracker, and its predicted path (the track now, then the run's
predicted points; one per frame period). Geometry goes through the profiles' own frame
conversion (CARLA world → ROS ``map``); stamps are the frame times after the synthesised
recordings' epoch, log times 2 ms later.
"""

from __future__ import annotations

import math
import sqlite3
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt
import yaml
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from ads_rca.model import ControlCommand, EgoPose, Objects3D, Plan, RunLog
from ads_rca.sources.bag.message_types import shipped, shipped_files
from ads_rca.sources.bag.profiles.frames import (
    carla_rpy_to_quaternion,
    carla_to_map_xyz,
    rpy_to_quaternion,
    world_to_body,
)
from ads_rca.synth.recording import (
    EPOCH_NS,
    MSG_DIR,
    MessageBuilder,
    autoware_label,
    object_uuid,
    path_headings,
    predicted_points,
)

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore


STORAGES = ("mcap", "sqlite3", "humble")
#: Rates of a real vehicle: localisation and the velocity report, perception and the rest.
EGO_HZ = 50
OBJECTS_HZ = 10
MRM_HZ = 10
#: Log time after the header stamp: what the recorder's latency adds.
LOG_DELAY_NS = 2_000_000
_NS_PER_MS = 1_000_000
_SEPARATOR = "=" * 80 + "\n"
_QOS = (
    "- history: 1\n  depth: 1\n  reliability: 1\n  durability: 2\n  deadline:\n    sec: "
    "9223372036\n    nsec: 854775807\n  lifespan:\n    sec: 9223372036\n    nsec: 854775807\n"
    "  liveliness: 1\n  liveliness_lease_duration:\n    sec: 9223372036\n    nsec: 854775807\n"
    "  avoid_ros_namespace_conventions: false"
)

#: Each input → (topic, current type, legacy type).
TOPICS = {
    "ego": ("/localization/kinematic_state", "nav_msgs/msg/Odometry", "nav_msgs/msg/Odometry"),
    "detections_3d": (
        "/perception/object_recognition/detection/objects",
        "autoware_perception_msgs/msg/DetectedObjects",
        "autoware_auto_perception_msgs/msg/DetectedObjects",
    ),
    "tracked_objects": (
        "/perception/object_recognition/tracking/objects",
        "autoware_perception_msgs/msg/TrackedObjects",
        "autoware_auto_perception_msgs/msg/TrackedObjects",
    ),
    "predictions": (
        "/perception/object_recognition/objects",
        "autoware_perception_msgs/msg/PredictedObjects",
        "autoware_auto_perception_msgs/msg/PredictedObjects",
    ),
    "plan": (
        "/planning/scenario_planning/trajectory",
        "autoware_planning_msgs/msg/Trajectory",
        "autoware_auto_planning_msgs/msg/Trajectory",
    ),
    "control": (
        "/control/command/control_cmd",
        "autoware_control_msgs/msg/Control",
        "autoware_auto_control_msgs/msg/AckermannControlCommand",
    ),
    "vehicle_velocity": (
        "/vehicle/status/velocity_status",
        "autoware_vehicle_msgs/msg/VelocityReport",
        "autoware_auto_vehicle_msgs/msg/VelocityReport",
    ),
    "mrm_state": (
        "/system/fail_safe/mrm_state",
        "autoware_adapi_v1_msgs/msg/MrmState",
        "autoware_adapi_v1_msgs/msg/MrmState",
    ),
}
#: Where the idle topics live (each gets numbered debug topics) and the standard types
#: they are declared with.
_IDLE_PREFIXES = (
    "/sensing/lidar/top",
    "/sensing/lidar/left",
    "/sensing/camera/front",
    "/sensing/imu",
    "/sensing/gnss",
    "/localization/pose_estimator",
    "/localization/pose_twist_fusion_filter",
    "/perception/obstacle_segmentation",
    "/perception/object_recognition/detection/centerpoint",
    "/perception/traffic_light_recognition",
    "/planning/scenario_planning/lane_driving/behavior_planning",
    "/planning/scenario_planning/lane_driving/motion_planning",
    "/control/trajectory_follower",
    "/system/diagnostics",
    "/vehicle/status",
)
_IDLE_TYPES = (
    "sensor_msgs/msg/PointCloud2",
    "visualization_msgs/msg/MarkerArray",
    "diagnostic_msgs/msg/DiagnosticArray",
    "geometry_msgs/msg/PoseWithCovarianceStamped",
    "std_msgs/msg/Float32",
    "nav_msgs/msg/Path",
    "sensor_msgs/msg/Imu",
    "tf2_msgs/msg/TFMessage",
)


@dataclass(frozen=True)
class AutowareBagOptions:
    """What the recording holds and how it is stored (see the module docstring)."""

    legacy: bool = False
    storage: str = "mcap"
    tracking: bool = True
    idle_topics: int = 320
    #: ms on the run's clock from which the MRM state is MRM_OPERATING (None: NORMAL
    #: throughout); ``mrm``: whether the topic is recorded at all.
    emergency_at_ms: int | None = None
    mrm: bool = True


@dataclass
class AutowareBag:
    """A written recording: where, each input's (topic, type), the message count per
    topic, and the run's clock of the objects' frames (ms)."""

    path: Path
    topics: dict[str, tuple[str, str]]
    counts: dict[str, int] = field(default_factory=dict)
    object_frames: tuple[int, ...] = ()


def stamp_ns(timestamp_ms: float) -> int:
    """Header stamp of a time on the run's clock (ms)."""
    return EPOCH_NS + round(timestamp_ms * _NS_PER_MS)


# --- types -------------------------------------------------------------------------------------


@cache
def typestore() -> Typestore:
    """Kilted's standard types, the stacks' current types (the synthesiser's ``.msg``
    files) and the legacy ones shipped with the reader."""
    store = get_typestore(Stores.ROS2_KILTED)
    types = {}
    for path in sorted(MSG_DIR.glob("*/msg/*.msg")):
        name = f"{path.parent.parent.name}/msg/{path.stem}"
        types.update(get_types_from_msg(path.read_text(encoding="utf-8"), name))
    for name in shipped_files():
        found = shipped(name)
        assert found is not None
        types[name] = found
    store.register(types)
    return store


def definition(name: str) -> str:
    """The text rosbag2 (Iron and later) stores for a type: a ``.msg``-defined type's own
    text then each dependency (``MSG: pkg/Type``); an IDL-defined one (the legacy packages)
    as ``ros2idl``, its own file then each shipped dependency's (``IDL: pkg/msg/Type``)."""
    files = shipped_files()
    if files.get(name, Path()).suffix == ".idl":
        parts = [name, *(d for d in _closure(name) if files.get(d, Path()).suffix == ".idl")]
        return "".join(
            f"{_SEPARATOR}IDL: {part}\n{files[part].read_text(encoding='utf-8')}" for part in parts
        )
    text, _digest = typestore().generate_msgdef(name, ros_version=2)
    return text


def _closure(name: str) -> list[str]:
    """The message types ``name`` contains, depth first, each once."""
    store = typestore()
    seen: list[str] = []

    def visit(current: str) -> None:
        for _field, (kind, detail) in store.fielddefs[current][1]:
            inner = detail if kind == 2 else detail[0][1] if kind in (3, 4) else None
            if isinstance(inner, str) and inner not in seen:
                seen.append(inner)
                visit(inner)

    visit(name)
    return seen


# --- messages ----------------------------------------------------------------------------------


class _Messages(MessageBuilder):
    """Message objects of the store's types, current or legacy."""

    def __init__(self, legacy: bool) -> None:
        super().__init__(typestore())
        self.legacy = legacy
        self.perception = (
            "autoware_auto_perception_msgs/msg/" if legacy else "autoware_perception_msgs/msg/"
        )
        self.planning = (
            "autoware_auto_planning_msgs/msg/" if legacy else "autoware_planning_msgs/msg/"
        )

    def with_covariance(self, kind: str, value: Any, name: str) -> Any:
        return self.new(
            f"geometry_msgs/msg/{kind}WithCovariance", **{name: value}, covariance=np.zeros(36)
        )

    def twist(self, linear: Any) -> Any:
        twist = self.new(
            "geometry_msgs/msg/Twist", linear=self.vector3(linear), angular=self.vector3((0, 0, 0))
        )
        return self.with_covariance("Twist", twist, "twist")

    def accel(self) -> Any:
        zero = self.vector3((0, 0, 0))
        return self.with_covariance(
            "Accel", self.new("geometry_msgs/msg/Accel", linear=zero, angular=zero), "accel"
        )

    def shape(self, half_extent: Any) -> Any:
        return self.new(
            self.perception + "Shape",
            type=0,
            footprint=self.new("geometry_msgs/msg/Polygon", points=[]),
            dimensions=self.vector3(2.0 * np.nan_to_num(half_extent)),
        )

    def classification(self, label: str) -> list[Any]:
        return [
            self.new(
                self.perception + "ObjectClassification",
                label=autoware_label(label),
                probability=1.0,
            )
        ]

    def uuid(self, object_id: str) -> Any:
        data = np.frombuffer(object_uuid(object_id), dtype=np.uint8).copy()
        return self.new("unique_identifier_msgs/msg/UUID", uuid=data)


class _MapObjects:
    """Objects3D rows in ``map``: poses, yaws, body-frame velocities."""

    def __init__(self, m: _Messages, objects: Objects3D) -> None:
        n = len(objects)
        rpy = np.zeros((n, 3))
        rpy[:, 2] = objects.yaw
        self.yaw = -np.radians(objects.yaw)
        self.poses = m.poses(carla_to_map_xyz(objects.location), carla_rpy_to_quaternion(rpy))
        world = carla_to_map_xyz(np.nan_to_num(objects.velocity))
        self.body_velocity = world_to_body(world, self.yaw)
        self.has_velocity: npt.NDArray[np.bool_] = np.asarray(
            np.isfinite(objects.velocity).all(axis=1), dtype=np.bool_
        )


def _score(value: float) -> float:
    return 1.0 if math.isnan(value) else float(value)


class _Recording:
    """The messages of one recording, in time order."""

    def __init__(self, log: RunLog, options: AutowareBagOptions) -> None:
        self.log = log
        self.options = options
        self.m = _Messages(options.legacy)
        self.end_ms = max(log.frames) if log.frames else 0

    def type_of(self, name: str) -> str:
        _topic, current, legacy = TOPICS[name]
        return legacy if self.options.legacy else current

    def inputs(self) -> list[str]:
        out = ["ego", "detections_3d", "tracked_objects", "predictions", "plan", "control"]
        out.append("vehicle_velocity")
        if not self.options.tracking:
            out.remove("tracked_objects")
        if self.options.mrm:
            out.append("mrm_state")
        return out

    def object_frames(self) -> tuple[int, ...]:
        step = 1000 // OBJECTS_HZ
        return tuple(ts for ts in self.log.unique_frames if ts % step == 0)

    def messages(self) -> Iterator[tuple[str, int, Any]]:
        """(input, stamp ns, message), stamp order."""
        out: list[tuple[str, int, Any]] = []
        wanted = set(self.inputs())
        for t_ms in np.arange(0, self.end_ms + 1e-9, 1000 / EGO_HZ):
            pose = self.ego_at(float(t_ms))
            if pose is not None:
                out.append(("ego", stamp_ns(t_ms), self.odometry(float(t_ms), pose)))
                out.append(("vehicle_velocity", stamp_ns(t_ms), self.velocity(float(t_ms), pose)))
        for ts in self.object_frames():
            for name in ("detections_3d", "tracked_objects", "predictions", "plan"):
                message = getattr(self, name)(ts)
                if name in wanted and message is not None:
                    out.append((name, stamp_ns(ts), message))
        for ts in self.log.unique_frames:
            command = self.log.controls.get(ts)
            if command is not None:
                out.append(("control", stamp_ns(ts), self.control(ts, command)))
        if self.options.mrm:
            out.extend(
                ("mrm_state", stamp_ns(t_ms), self.mrm(t_ms))
                for t_ms in range(0, self.end_ms + 1, 1000 // MRM_HZ)
            )
        out.sort(key=lambda entry: entry[1])
        yield from out

    # -- each input

    def ego_at(self, t_ms: float) -> EgoPose | None:
        """The run's ego pose at ``t_ms``, linear between its frames (yaw unwrapped)."""
        stamps = sorted(self.log.pose)
        if not stamps or t_ms < stamps[0] or t_ms > stamps[-1]:
            return None
        i = int(np.searchsorted(stamps, t_ms))
        if stamps[i] == t_ms or i == 0:
            return self.log.pose[stamps[i]]
        a, b = self.log.pose[stamps[i - 1]], self.log.pose[stamps[i]]
        w = (t_ms - stamps[i - 1]) / (stamps[i] - stamps[i - 1])
        turn = (b.yaw - a.yaw + 180.0) % 360.0 - 180.0

        def mix(x: float, y: float) -> float:
            return x + (y - x) * w

        return EgoPose(
            mix(a.x, b.x),
            mix(a.y, b.y),
            mix(a.z, b.z),
            mix(a.roll, b.roll),
            mix(a.pitch, b.pitch),
            a.yaw + turn * w,
            mix(a.speed, b.speed),
        )

    def odometry(self, t_ms: float, pose: EgoPose) -> Any:
        m = self.m
        xyz = carla_to_map_xyz([[pose.x, pose.y, pose.z]])
        quaternion = carla_rpy_to_quaternion([[pose.roll, pose.pitch, pose.yaw]])
        return m.new(
            "nav_msgs/msg/Odometry",
            header=m.header(stamp_ns(t_ms)),
            child_frame_id="base_link",
            pose=m.with_covariance("Pose", m.poses(xyz, quaternion)[0], "pose"),
            twist=m.twist((pose.speed, 0.0, 0.0)),
        )

    def velocity(self, t_ms: float, pose: EgoPose) -> Any:
        return self.m.new(
            self.type_of("vehicle_velocity"),
            header=self.m.header(stamp_ns(t_ms), "base_link"),
            longitudinal_velocity=float(pose.speed),
            lateral_velocity=0.0,
            heading_rate=0.0,
        )

    def detections_3d(self, ts: int) -> Any:
        objects = self.log.detections_3d.get(ts)
        if objects is None:
            return None
        m = self.m
        frame = _MapObjects(m, objects)
        detected = [
            m.new(
                m.perception + "DetectedObject",
                existence_probability=_score(objects.score[row]),
                classification=m.classification(objects.labels[row]),
                kinematics=m.new(
                    m.perception + "DetectedObjectKinematics",
                    pose_with_covariance=m.with_covariance("Pose", frame.poses[row], "pose"),
                    has_position_covariance=False,
                    orientation_availability=2,
                    twist_with_covariance=m.twist(frame.body_velocity[row]),
                    has_twist=bool(frame.has_velocity[row]),
                    has_twist_covariance=False,
                ),
                shape=m.shape(objects.extent[row]),
            )
            for row in range(len(objects))
        ]
        return m.new(
            m.perception + "DetectedObjects", header=m.header(stamp_ns(ts)), objects=detected
        )

    def tracked_objects(self, ts: int) -> Any:
        objects = self.log.tracks_3d.get(ts)
        if objects is None:
            return None
        m = self.m
        frame = _MapObjects(m, objects)
        tracked = [
            m.new(
                m.perception + "TrackedObject",
                object_id=m.uuid(object_id),
                existence_probability=_score(objects.score[row]),
                classification=m.classification(objects.labels[row]),
                kinematics=m.new(
                    m.perception + "TrackedObjectKinematics",
                    pose_with_covariance=m.with_covariance("Pose", frame.poses[row], "pose"),
                    twist_with_covariance=m.twist(frame.body_velocity[row]),
                    acceleration_with_covariance=m.accel(),
                    orientation_availability=2,
                    is_stationary=False,
                ),
                shape=m.shape(objects.extent[row]),
            )
            for row, object_id in enumerate(objects.ids)
        ]
        return m.new(
            m.perception + "TrackedObjects", header=m.header(stamp_ns(ts)), objects=tracked
        )

    def predictions(self, ts: int) -> Any:
        """One PredictedObject per track of the frame: the track's state, and its path when
        the run predicts it (the track now, then the run's points)."""
        objects = self.log.tracks_3d.get(ts)
        pose = self.log.pose.get(ts)
        if objects is None or pose is None:
            return None
        m = self.m
        frame = _MapObjects(m, objects)
        predicted = self.log.predictions.get(ts, {})
        step_ns = self.log.frame_ms * _NS_PER_MS
        out = []
        for row, object_id in enumerate(objects.ids):
            paths = []
            track = predicted.get(object_id)
            if track is not None:
                points = predicted_points(track.keys, track.offsets, pose)
                path_map = carla_to_map_xyz(np.vstack([objects.location[row][None, :], points]))
                zeros = np.zeros(len(path_map))
                headings = path_headings(path_map, float(frame.yaw[row]))
                quaternions = rpy_to_quaternion(zeros, zeros, headings)
                paths.append(
                    m.new(
                        m.perception + "PredictedPath",
                        path=m.poses(path_map, quaternions),
                        time_step=m.duration(step_ns),
                        confidence=1.0,
                    )
                )
            kinematics = m.new(
                m.perception + "PredictedObjectKinematics",
                initial_pose_with_covariance=m.with_covariance("Pose", frame.poses[row], "pose"),
                initial_twist_with_covariance=m.twist(frame.body_velocity[row]),
                initial_acceleration_with_covariance=m.accel(),
                predicted_paths=paths,
            )
            out.append(
                m.new(
                    m.perception + "PredictedObject",
                    object_id=m.uuid(object_id),
                    existence_probability=_score(objects.score[row]),
                    classification=m.classification(objects.labels[row]),
                    kinematics=kinematics,
                    shape=m.shape(objects.extent[row]),
                )
            )
        return m.new(m.perception + "PredictedObjects", header=m.header(stamp_ns(ts)), objects=out)

    def plan(self, ts: int) -> Any:
        plan = self.log.waypoints.get(ts)
        return None if plan is None else self.trajectory(ts, plan)

    def trajectory(self, ts: int, plan: Plan) -> Any:
        m = self.m
        pose = self.log.pose.get(ts)
        z = pose.z if pose is not None else 0.0
        xyz = carla_to_map_xyz(np.column_stack([plan.xy, np.full(len(plan), z)]))
        initial = float(-np.radians(pose.yaw)) if pose is not None else 0.0
        zeros = np.zeros(len(plan))
        poses = m.poses(xyz, rpy_to_quaternion(zeros, zeros, path_headings(xyz, initial)))
        step_ns = self.log.frame_ms * _NS_PER_MS
        point = self.types_point()
        points = [
            point(
                time_from_start=m.duration(i * step_ns),
                pose=poses[i],
                longitudinal_velocity_mps=float(plan.speed[i]),
                lateral_velocity_mps=0.0,
                acceleration_mps2=0.0,
                heading_rate_rps=0.0,
                front_wheel_angle_rad=0.0,
                rear_wheel_angle_rad=0.0,
            )
            for i in range(len(plan))
        ]
        return m.new(m.planning + "Trajectory", header=m.header(stamp_ns(ts)), points=points)

    def types_point(self) -> Any:
        return self.m.types[self.m.planning + "TrajectoryPoint"]

    def control(self, ts: int, command: ControlCommand) -> Any:
        m = self.m
        stamp = m.time(stamp_ns(ts))
        steer = 0.0 if math.isnan(command.steer) else -math.radians(command.steer)
        speed = 0.0 if math.isnan(command.speed) else command.speed
        acceleration = 0.0 if math.isnan(command.acceleration) else command.acceleration
        if self.options.legacy:
            package = "autoware_auto_control_msgs/msg/"
            lateral = m.new(
                package + "AckermannLateralCommand",
                stamp=stamp,
                steering_tire_angle=steer,
                steering_tire_rotation_rate=0.0,
            )
            longitudinal = m.new(
                package + "LongitudinalCommand",
                stamp=stamp,
                speed=speed,
                acceleration=acceleration,
                jerk=0.0,
            )
            return m.new(
                package + "AckermannControlCommand",
                stamp=stamp,
                lateral=lateral,
                longitudinal=longitudinal,
            )
        package = "autoware_control_msgs/msg/"
        lateral = m.new(
            package + "Lateral",
            stamp=stamp,
            control_time=stamp,
            steering_tire_angle=steer,
            steering_tire_rotation_rate=0.0,
            is_defined_steering_tire_rotation_rate=False,
        )
        longitudinal = m.new(
            package + "Longitudinal",
            stamp=stamp,
            control_time=stamp,
            velocity=speed,
            acceleration=acceleration,
            jerk=0.0,
            is_defined_acceleration=True,
            is_defined_jerk=False,
        )
        return m.new(
            package + "Control",
            stamp=stamp,
            control_time=stamp,
            lateral=lateral,
            longitudinal=longitudinal,
        )

    def mrm(self, t_ms: int) -> Any:
        at = self.options.emergency_at_ms
        emergency = at is not None and t_ms >= at
        return self.m.new(
            "autoware_adapi_v1_msgs/msg/MrmState",
            stamp=self.m.time(stamp_ns(t_ms)),
            state=2 if emergency else 1,  # MRM_OPERATING, NORMAL
            behavior=2 if emergency else 1,  # EMERGENCY_STOP, NONE
        )


def idle_topics(count: int) -> dict[str, str]:
    """``count`` topic names (→ a standard type) a vehicle declares and this run never sent."""
    out = {}
    for i in range(count):
        prefix = _IDLE_PREFIXES[i % len(_IDLE_PREFIXES)]
        out[f"{prefix}/debug/topic_{i:03d}"] = _IDLE_TYPES[i % len(_IDLE_TYPES)]
    return out


def write_autoware_bag(
    log: RunLog, path: str | Path, options: AutowareBagOptions | None = None
) -> AutowareBag:
    """``log`` recorded at ``path`` (a new directory) as an Autoware vehicle records it."""
    options = options or AutowareBagOptions()
    if options.storage not in STORAGES:
        raise ValueError(f"storage must be one of {STORAGES}, got {options.storage!r}")
    recording = _Recording(log, options)
    root = Path(path)
    topics = {name: (TOPICS[name][0], recording.type_of(name)) for name in recording.inputs()}
    declared = {topic: msgtype for topic, msgtype in topics.values()}
    declared.update(idle_topics(options.idle_topics))
    store = typestore()
    entries = [
        (topics[name][0], log_ns + LOG_DELAY_NS, bytes(store.serialize_cdr(msg, topics[name][1])))
        for name, log_ns, msg in recording.messages()
    ]
    if options.storage == "humble":
        _write_humble(root, declared, entries)
    else:
        _write_rosbags(root, declared, entries, options.storage)
    counts = {topic: 0 for topic in declared}
    for topic, _time, _data in entries:
        counts[topic] += 1
    return AutowareBag(root, topics, counts, recording.object_frames())


def _write_rosbags(
    root: Path, declared: Mapping[str, str], entries: list[tuple[str, int, bytes]], storage: str
) -> None:
    """rosbag2 Iron and later (definitions and type hashes stored), with rosbags' writer."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    store = typestore()
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    with Writer(root, version=9, storage_plugin=plugin) as writer:
        connections = {
            topic: writer.add_connection(
                topic, msgtype, msgdef=definition(msgtype), rihs01=store.hash_rihs01(msgtype)
            )
            for topic, msgtype in declared.items()
        }
        for topic, log_ns, data in entries:
            writer.write(connections[topic], log_ns, data)


def _write_humble(
    root: Path, declared: Mapping[str, str], entries: list[tuple[str, int, bytes]]
) -> None:
    """rosbag2 before Iron: sqlite3 schema 3 (no ``message_definitions`` table, no type
    hashes), ``metadata.yaml`` version 5."""
    root.mkdir(parents=True)
    name = f"{root.name}_0.db3"
    ids = {topic: row + 1 for row, topic in enumerate(declared)}
    database = sqlite3.connect(root / name)
    with database:
        database.executescript(
            "CREATE TABLE schema(schema_version INTEGER PRIMARY KEY,ros_distro TEXT NOT NULL);"
            "CREATE TABLE metadata(id INTEGER PRIMARY KEY,metadata_version INTEGER NOT NULL,"
            "metadata TEXT NOT NULL);"
            "CREATE TABLE topics(id INTEGER PRIMARY KEY,name TEXT NOT NULL,type TEXT NOT NULL,"
            "serialization_format TEXT NOT NULL,offered_qos_profiles TEXT NOT NULL);"
            "CREATE TABLE messages(id INTEGER PRIMARY KEY,topic_id INTEGER NOT NULL,"
            "timestamp INTEGER NOT NULL, data BLOB NOT NULL);"
            "CREATE INDEX timestamp_idx ON messages (timestamp ASC);"
            "INSERT INTO schema VALUES (3, 'humble');"
        )
        database.executemany(
            "INSERT INTO topics VALUES (?, ?, ?, 'cdr', ?)",
            [(ids[topic], topic, msgtype, _QOS) for topic, msgtype in declared.items()],
        )
        database.executemany(
            "INSERT INTO messages (topic_id, timestamp, data) VALUES (?, ?, ?)",
            [(ids[topic], log_ns, data) for topic, log_ns, data in entries],
        )
    start = min((e[1] for e in entries), default=0)
    end = max((e[1] for e in entries), default=0)
    counts = {topic: 0 for topic in declared}
    for topic, _time, _data in entries:
        counts[topic] += 1
    info = {
        "version": 5,
        "storage_identifier": "sqlite3",
        "duration": {"nanoseconds": end - start},
        "starting_time": {"nanoseconds_since_epoch": start},
        "message_count": len(entries),
        "topics_with_message_count": [
            {
                "topic_metadata": {
                    "name": topic,
                    "type": msgtype,
                    "serialization_format": "cdr",
                    "offered_qos_profiles": _QOS,
                },
                "message_count": counts[topic],
            }
            for topic, msgtype in declared.items()
        ],
        "compression_format": "",
        "compression_mode": "",
        "relative_file_paths": [name],
        "files": [
            {
                "path": name,
                "starting_time": {"nanoseconds_since_epoch": start},
                "duration": {"nanoseconds": end - start},
                "message_count": len(entries),
            }
        ],
    }
    text = yaml.safe_dump({"rosbag2_bagfile_information": info}, sort_keys=False)
    with database:
        database.execute("INSERT INTO metadata VALUES (1, 5, ?)", (text,))
    database.close()
    (root / "metadata.yaml").write_text(text, encoding="utf-8")


__all__ = [
    "STORAGES",
    "TOPICS",
    "AutowareBag",
    "AutowareBagOptions",
    "definition",
    "idle_topics",
    "stamp_ns",
    "typestore",
    "write_autoware_bag",
]
