"""A run written as a rosbag2 recording of a real stack: fixtures for the recording readers.

Real stacks do not publish this project's contract topics: the CARLA ROS bridge publishes
ground truth as ``derived_object_msgs`` and collisions as ``carla_msgs``, Autoware its
perception, prediction, planning and control in its own types, detectors ``vision_msgs``.
To test the readers of such recordings on runs whose truth is known, a synthesised
:class:`~ads_rca.model.RunLog` is written here exactly as such a stack would have recorded
it: the inverse of the profiles' decoders (docs/recordings.md, "Writing recordings").

The types come from the ``.msg`` files shipped in ``ads_rca/synth/msgs`` (the stacks' own
published text) on top of rosbags' Kilted store, and each topic's stored definition is
that text, concatenated as rosbag2 does (the type's file, then each dependency after a
``MSG:`` separator, depth first), so a bag carries its types as a real recording does.
Geometry goes through :mod:`ads_rca.sources.bag.profiles.frames` (CARLA world → ROS ``map``). Header
stamps and log times are the frame timestamps after :data:`EPOCH_NS`, so no reader can
rely on time starting at zero.
"""

from __future__ import annotations

import json
import math
import os
import sqlite3
import uuid
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from ads_rca.capabilities import input_status, present
from ads_rca.contract.rosmsg import referenced_types
from ads_rca.errors import ConfigError
from ads_rca.model import Boxes, ControlCommand, EgoPose, Objects3D, Plan, RunLog, Track
from ads_rca.sources.bag.profiles.frames import (
    carla_rpy_to_quaternion,
    carla_to_map_xyz,
    rpy_to_quaternion,
    world_to_body,
)
from ads_rca.sources.bag.profiles.profile import load_profile
from ads_rca.sources.bag.writer import STORAGES
from ads_rca.sources.errors import OutputExists
from ads_rca.synth.errors import SynthesisError
from ads_rca.synth.geometry import FloatArray, to_world

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

#: The profiles a synthesised run can be written in (``ads_rca``, this project's own
#: contract, is :func:`ads_rca.sources.bag.writer.write_bag`).
PROFILES = ("carla-autoware", "vision_msgs")
#: Header stamp of timestamp 0 ms: 2023-11-14, a realistic wall-clock epoch.
EPOCH_NS = 1_700_000_000 * 1_000_000_000
#: Where the stacks' ``.msg`` files live: ``<package>/msg/<Type>.msg``.
MSG_DIR = Path(__file__).resolve().parent / "msgs"
#: The CARLA bridge's role name of the ego vehicle (its topics' namespace, odometry child).
EGO_ROLE = "ego_vehicle"
_AUTOWARE_PERCEPTION = "autoware_perception_msgs/msg/"
#: Keys of the bag's ``metadata.yaml`` ``custom_data``.
CUSTOM_SYNTHESIS = "ads_rca.synthesis"
CUSTOM_ACTOR_IDS = "ads_rca.actor_ids"
CUSTOM_CAMERA = "ads_rca.camera_loc"

_SEPARATOR = "=" * 80 + "\n"
_NS_PER_MS = 1_000_000


def profile_topics(profile: str) -> dict[str, tuple[str, str]]:
    """Model input → (topic, type) of a built-in profile: what the reader expects is what
    the writer writes (one table, ``ads_rca/sources/bag/profiles/builtin/<profile>.yaml``)."""
    return {name: (spec.topic, spec.type) for name, spec in load_profile(profile).inputs.items()}


#: Autoware's ObjectClassification labels by constant name; other names (CARLA's
#: ``vehicle``, ``walker``) through :data:`_LABEL_ALIASES`, anything else is UNKNOWN.
AUTOWARE_LABELS = {
    "UNKNOWN": 0,
    "CAR": 1,
    "TRUCK": 2,
    "BUS": 3,
    "TRAILER": 4,
    "MOTORCYCLE": 5,
    "BICYCLE": 6,
    "PEDESTRIAN": 7,
}
_LABEL_ALIASES = {"VEHICLE": "CAR", "WALKER": "PEDESTRIAN", "BIKE": "BICYCLE"}
#: Tracked-object uuids: uuid5 of the id text in this namespace (stable across runs).
_UUID_NAMESPACE = uuid.UUID("5d0f7e4c-1b9a-4c55-9d6e-ad5ca0000016")


# --- types and definitions -----------------------------------------------------------------


@cache
def _msg_files() -> dict[str, Path]:
    """``pkg/msg/Type`` → its shipped ``.msg`` file."""
    return {
        f"{path.parent.parent.name}/msg/{path.stem}": path
        for path in sorted(MSG_DIR.glob("*/msg/*.msg"))
    }


@cache
def typestore() -> Typestore:
    """rosbags' Kilted store plus every shipped stack type (a store of its own: the
    contract's process-wide store is left as it is)."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_KILTED)
    types = {}
    for name, path in _msg_files().items():
        types.update(get_types_from_msg(path.read_text(encoding="utf-8"), name))
    store.register(types)
    return store


def _dependencies(store: Typestore, name: str) -> list[str]:
    """The message types ``name``'s fields name, in field order, each once."""
    return list(dict.fromkeys(referenced_types(store.fielddefs[name][1])))


def _own_text(store: Typestore, name: str) -> str:
    """One type's own definition text: the shipped file verbatim, else the store's."""
    path = _msg_files().get(name)
    if path is not None:
        return path.read_text(encoding="utf-8")
    text, _ = store.generate_msgdef(name, ros_version=2)
    return text.split("\n" + _SEPARATOR, 1)[0].rstrip("\n") + "\n"


def message_definition(name: str) -> str:
    """The ``ros2msg`` text a recording stores for ``name``: its own text, then each
    dependency (``MSG: pkg/Type``) depth first, each once, as rosbag2 concatenates them."""
    store = typestore()
    seen = {name}
    parts: list[str] = []

    def add(current: str) -> None:
        parts.append(_own_text(store, current))
        for dep in _dependencies(store, current):
            if dep not in seen:
                seen.add(dep)
                package, _, short = dep.split("/")
                parts.append(f"{_SEPARATOR}MSG: {package}/{short}\n")
                add(dep)

    add(name)
    return "".join(parts)


# --- ids -------------------------------------------------------------------------------------


def actor_numbers(log: RunLog) -> dict[str, int]:
    """Each actor id (and the collision partner) → the uint32 the bridge's messages carry.

    Ids that are canonical uint32 decimals keep their value; any other id gets the next
    number above the largest of those, in order of first appearance (deterministic)."""
    ids = list(dict.fromkeys(i for ts in sorted(log.actors) for i in log.actors[ts].ids))
    partner = _partner(log)
    if partner is not None and partner not in ids:
        ids.append(partner)
    numbers = {i: int(i) for i in ids if _is_uint32(i)}
    following = max(numbers.values(), default=0) + 1
    for actor_id in ids:
        if actor_id not in numbers:
            numbers[actor_id] = following
            following += 1
    return numbers


def _is_uint32(text: str) -> bool:
    return text.isascii() and text.isdigit() and str(int(text)) == text and int(text) < 2**32


def _partner(log: RunLog) -> str | None:
    synthesis = log.metadata.raw.get("synthesis")
    partner = synthesis.get("partner_id") if isinstance(synthesis, Mapping) else None
    return None if partner is None else str(partner)


def object_uuid(object_id: str) -> bytes:
    """The 16-byte ``unique_identifier_msgs/UUID`` of a tracked object id (uuid5: stable)."""
    return uuid.uuid5(_UUID_NAMESPACE, object_id).bytes


def stamp_ns(timestamp_ms: int) -> int:
    """Header stamp (and log time) of a frame timestamp."""
    return EPOCH_NS + timestamp_ms * _NS_PER_MS


def autoware_label(label: str) -> int:
    """Autoware's classification constant for a label text (UNKNOWN when none fits)."""
    name = label.upper()
    return AUTOWARE_LABELS.get(_LABEL_ALIASES.get(name, name), AUTOWARE_LABELS["UNKNOWN"])


def _probability(value: float) -> float:
    """A score or existence probability; an unknown one (NaN) is written as 1.0."""
    return 1.0 if math.isnan(value) else float(value)


# --- message building ------------------------------------------------------------------------


class MessageBuilder:
    """Builds rosbags message objects of the store's types (short names for the nested
    geometry every message repeats); the test fixtures' writers of other stacks' bags
    build on it."""

    def __init__(self, store: Typestore) -> None:
        self.types = store.types

    def new(self, name: str, **fields: Any) -> Any:
        return self.types[name](**fields)

    def time(self, ns: int) -> Any:
        return self.new("builtin_interfaces/msg/Time", sec=ns // 10**9, nanosec=ns % 10**9)

    def duration(self, ns: int) -> Any:
        return self.new("builtin_interfaces/msg/Duration", sec=ns // 10**9, nanosec=ns % 10**9)

    def header(self, ns: int, frame_id: str = "map") -> Any:
        return self.new("std_msgs/msg/Header", stamp=self.time(ns), frame_id=frame_id)

    def vector3(self, v: FloatArray | Sequence[float]) -> Any:
        return self.new("geometry_msgs/msg/Vector3", x=float(v[0]), y=float(v[1]), z=float(v[2]))

    def poses(self, xyz: FloatArray, quaternions: FloatArray) -> list[Any]:
        """One Pose per row of positions (N, 3) and quaternions (N, 4): the hot path of
        predicted paths and trajectories, so the rows become Python floats at once."""
        point = self.types["geometry_msgs/msg/Point"]
        quaternion = self.types["geometry_msgs/msg/Quaternion"]
        pose = self.types["geometry_msgs/msg/Pose"]
        return [
            pose(position=point(*p), orientation=quaternion(*q))
            for p, q in zip(xyz.tolist(), quaternions.tolist(), strict=True)
        ]

    def pose(self, xyz: npt.ArrayLike, quaternion: npt.ArrayLike) -> Any:
        return self.poses(np.reshape(xyz, (1, 3)), np.reshape(quaternion, (1, 4)))[0]

    def pose_cov(self, pose: Any) -> Any:
        return self.new("geometry_msgs/msg/PoseWithCovariance", pose=pose, covariance=np.zeros(36))

    def twist(self, linear: FloatArray) -> Any:
        return self.new(
            "geometry_msgs/msg/Twist",
            linear=self.vector3(linear),
            angular=self.vector3(np.zeros(3)),
        )

    def twist_cov(self, linear: FloatArray) -> Any:
        return self.new(
            "geometry_msgs/msg/TwistWithCovariance",
            twist=self.twist(linear),
            covariance=np.zeros(36),
        )

    def accel_cov(self) -> Any:
        zero = self.vector3(np.zeros(3))
        accel = self.new("geometry_msgs/msg/Accel", linear=zero, angular=zero)
        return self.new(
            "geometry_msgs/msg/AccelWithCovariance", accel=accel, covariance=np.zeros(36)
        )

    def polygon(self) -> Any:
        return self.new("geometry_msgs/msg/Polygon", points=[])

    def uuid(self, object_id: str) -> Any:
        data = np.frombuffer(object_uuid(object_id), dtype=np.uint8).copy()
        return self.new("unique_identifier_msgs/msg/UUID", uuid=data)

    def classification(self, label: str) -> list[Any]:
        return [
            self.new(
                _AUTOWARE_PERCEPTION + "ObjectClassification",
                label=autoware_label(label),
                probability=1.0,
            )
        ]

    def shape(self, half_extent: FloatArray) -> Any:
        return self.new(
            _AUTOWARE_PERCEPTION + "Shape",
            type=0,  # BOUNDING_BOX: dimensions are full length, width, height
            footprint=self.polygon(),
            dimensions=self.vector3(2.0 * np.nan_to_num(half_extent)),
        )


class _MapObjects:
    """Objects3D rows in the ``map`` frame: positions, orientations, body-frame velocities."""

    def __init__(self, objects: Objects3D) -> None:
        n = len(objects)
        self.position = carla_to_map_xyz(objects.location)
        rpy = np.zeros((n, 3))
        rpy[:, 2] = objects.yaw
        self.quaternion = carla_rpy_to_quaternion(rpy)
        self.yaw = -np.radians(objects.yaw)
        self.has_velocity = np.asarray(np.isfinite(objects.velocity).all(axis=1), dtype=np.bool_)
        world = carla_to_map_xyz(np.nan_to_num(objects.velocity))
        self.body_velocity = world_to_body(world, self.yaw)


@dataclass(frozen=True)
class _Tracked:
    """What a predicted object takes from its track of the same frame."""

    location: FloatArray  # CARLA world
    yaw_map: float
    body_velocity: FloatArray
    extent: FloatArray
    label: str
    score: float


def _tracked(tracks: Objects3D | None) -> dict[str, _Tracked]:
    """Each track id's state (the first row of a repeated id)."""
    if tracks is None:
        return {}
    frame = _MapObjects(tracks)
    return {
        object_id: _Tracked(
            tracks.location[row],
            float(frame.yaw[row]),
            frame.body_velocity[row],
            tracks.extent[row],
            tracks.labels[row],
            float(tracks.score[row]),
        )
        for row, object_id in reversed(list(enumerate(tracks.ids)))
    }


def _yaw_quaternion(yaw_map: FloatArray) -> FloatArray:
    zeros = np.zeros_like(yaw_map)
    return rpy_to_quaternion(zeros, zeros, yaw_map)


def path_headings(points_map: FloatArray, initial: float) -> FloatArray:
    """Map yaw along a polyline: each point faces the next (the last keeps the previous
    heading); a point that does not move keeps the heading before it, ``initial`` first."""
    n = len(points_map)
    if n < 2:
        return np.full(n, initial)
    step = np.diff(points_map[:, :2], axis=0)  # segment i: point i → i + 1
    moved = np.hypot(step[:, 0], step[:, 1]) > 1e-9
    # Each segment's last moving segment at or before it (-1: none yet).
    last_moved = np.maximum.accumulate(np.where(moved, np.arange(n - 1), -1))
    segment = last_moved[np.minimum(np.arange(n), n - 2)]
    out: FloatArray = np.where(
        segment >= 0, np.arctan2(step[:, 1], step[:, 0])[np.maximum(segment, 0)], initial
    )
    return out


class _Writer:
    """One recording: the messages of each model input, per frame, for one profile."""

    def __init__(self, log: RunLog, profile: str) -> None:
        self.log = log
        self.profile = profile
        self.m = MessageBuilder(typestore())
        self.numbers = actor_numbers(log)
        self.frame_step_ns = log.frame_ms * _NS_PER_MS

    # Each builder gives the input's message at one timestamp, or None.

    def clock(self, ts: int) -> Any:
        return self.m.new("rosgraph_msgs/msg/Clock", clock=self.m.time(stamp_ns(ts)))

    def ego(self, ts: int) -> Any:
        pose = self.log.pose.get(ts)
        return None if pose is None else self._odometry(ts, pose)

    def _odometry(self, ts: int, pose: EgoPose) -> Any:
        m = self.m
        xyz = carla_to_map_xyz([pose.x, pose.y, pose.z])
        quaternion = carla_rpy_to_quaternion([pose.roll, pose.pitch, pose.yaw])
        return m.new(
            "nav_msgs/msg/Odometry",
            header=m.header(stamp_ns(ts)),
            child_frame_id=EGO_ROLE,
            pose=m.pose_cov(m.pose(xyz, quaternion)),
            # The body frame (child_frame_id): the speed is along the ego's x axis.
            twist=m.twist_cov(np.array([pose.speed, 0.0, 0.0])),
        )

    def actors(self, ts: int) -> Any:
        actors = self.log.actors.get(ts)
        if actors is None:
            return None
        m = self.m
        stamp = stamp_ns(ts)
        xyz = carla_to_map_xyz(actors.location)
        poses = m.poses(xyz, carla_rpy_to_quaternion(actors.rotation))
        dimensions = 2.0 * np.nan_to_num(actors.extent)
        zero = m.vector3(np.zeros(3))
        objects = [
            m.new(
                "derived_object_msgs/msg/Object",
                header=m.header(stamp),
                id=self.numbers[actor_id],
                detection_level=1,  # OBJECT_TRACKED: the simulator's ground truth
                object_classified=False,
                pose=poses[row],
                twist=m.twist(np.zeros(3)),
                accel=m.new("geometry_msgs/msg/Accel", linear=zero, angular=zero),
                polygon=m.polygon(),
                shape=m.new(
                    "shape_msgs/msg/SolidPrimitive",
                    type=1,  # BOX
                    dimensions=dimensions[row].copy(),
                    polygon=m.polygon(),
                ),
                classification=0,
                classification_certainty=0,
                classification_age=0,
            )
            for row, actor_id in enumerate(actors.ids)
        ]
        return m.new("derived_object_msgs/msg/ObjectArray", header=m.header(stamp), objects=objects)

    def collision(self, ts: int) -> Any:
        meta = self.log.metadata
        if not meta.has_collision or ts != meta.collision_frame * self.log.frame_ms:
            return None
        partner = _partner(self.log)
        return self.m.new(
            "carla_msgs/msg/CarlaCollisionEvent",
            header=self.m.header(stamp_ns(ts), EGO_ROLE),
            other_actor_id=0 if partner is None else self.numbers[partner],
            normal_impulse=self.m.vector3(np.zeros(3)),
        )

    def detections_3d(self, ts: int) -> Any:
        objects = self.log.detections_3d.get(ts)
        if objects is None:
            return None
        if self.profile == "vision_msgs":
            return self._detection_3d_array(ts, objects)
        m = self.m
        frame = _MapObjects(objects)
        detected = [
            m.new(
                _AUTOWARE_PERCEPTION + "DetectedObject",
                existence_probability=_probability(objects.score[row]),
                classification=m.classification(objects.labels[row]),
                kinematics=m.new(
                    _AUTOWARE_PERCEPTION + "DetectedObjectKinematics",
                    pose_with_covariance=m.pose_cov(
                        m.pose(frame.position[row], frame.quaternion[row])
                    ),
                    has_position_covariance=False,
                    orientation_availability=2,  # AVAILABLE
                    twist_with_covariance=m.twist_cov(frame.body_velocity[row]),
                    has_twist=bool(frame.has_velocity[row]),
                    has_twist_covariance=False,
                ),
                shape=m.shape(objects.extent[row]),
            )
            for row in range(len(objects))
        ]
        return m.new(
            _AUTOWARE_PERCEPTION + "DetectedObjects",
            header=m.header(stamp_ns(ts)),
            objects=detected,
        )

    def tracked_objects(self, ts: int) -> Any:
        objects = self.log.tracks_3d.get(ts)
        if objects is None:
            return None
        m = self.m
        frame = _MapObjects(objects)
        tracked = [
            m.new(
                _AUTOWARE_PERCEPTION + "TrackedObject",
                object_id=m.uuid(object_id),
                existence_probability=_probability(objects.score[row]),
                classification=m.classification(objects.labels[row]),
                kinematics=m.new(
                    _AUTOWARE_PERCEPTION + "TrackedObjectKinematics",
                    pose_with_covariance=m.pose_cov(
                        m.pose(frame.position[row], frame.quaternion[row])
                    ),
                    twist_with_covariance=m.twist_cov(frame.body_velocity[row]),
                    acceleration_with_covariance=m.accel_cov(),
                    orientation_availability=2,  # AVAILABLE
                    is_stationary=False,
                ),
                shape=m.shape(objects.extent[row]),
            )
            for row, object_id in enumerate(objects.ids)
        ]
        return m.new(
            _AUTOWARE_PERCEPTION + "TrackedObjects", header=m.header(stamp_ns(ts)), objects=tracked
        )

    def predictions(self, ts: int) -> Any:
        predictions = self.log.predictions.get(ts)
        if predictions is None:
            return None
        pose = self.log.pose.get(ts)
        if pose is None:
            raise SynthesisError(
                f"predictions at {ts} ms cannot be written in the map frame: no ego pose then"
            )
        tracked = _tracked(self.log.tracks_3d.get(ts))
        objects = [
            self._predicted(ts, pose, object_id, track, tracked.get(object_id))
            for object_id, track in predictions.items()
        ]
        return self.m.new(
            _AUTOWARE_PERCEPTION + "PredictedObjects",
            header=self.m.header(stamp_ns(ts)),
            objects=objects,
        )

    def _predicted(
        self, ts: int, pose: EgoPose, object_id: str, track: Track, known: _Tracked | None
    ) -> Any:
        m = self.m
        points = predicted_points(track.keys, track.offsets, pose)
        if known is not None:
            start = known.location
        elif len(points) >= 2:
            start = 2.0 * points[0] - points[1]  # key "0" minus one step
        else:
            start = points[0] if len(points) else np.array([pose.x, pose.y, pose.z])
        path_map = carla_to_map_xyz(np.vstack([start[None, :], points]))
        if known is None:  # untracked: moving along the path's first step
            step = float(np.linalg.norm(path_map[1, :2] - path_map[0, :2])) if len(points) else 0.0
            velocity = np.array([step / (self.frame_step_ns / 1e9), 0.0, 0.0])
            extent = self._actor_extent(ts, object_id)
            known = _Tracked(start, 0.0, velocity, extent, "", math.nan)
        quaternions = _yaw_quaternion(path_headings(path_map, known.yaw_map))
        poses = m.poses(path_map, quaternions)
        paths = [
            m.new(
                _AUTOWARE_PERCEPTION + "PredictedPath",
                path=poses,
                time_step=m.duration(self.frame_step_ns),
                confidence=1.0,
            )
        ]
        kinematics = m.new(
            _AUTOWARE_PERCEPTION + "PredictedObjectKinematics",
            initial_pose_with_covariance=m.pose_cov(poses[0]),
            initial_twist_with_covariance=m.twist_cov(known.body_velocity),
            initial_acceleration_with_covariance=m.accel_cov(),
            predicted_paths=paths if len(points) else [],
        )
        return m.new(
            _AUTOWARE_PERCEPTION + "PredictedObject",
            object_id=m.uuid(object_id),
            existence_probability=_probability(known.score),
            classification=m.classification(known.label),
            kinematics=kinematics,
            shape=m.shape(known.extent),
        )

    def _actor_extent(self, ts: int, object_id: str) -> FloatArray:
        """An object's ground-truth half extent when its id is an actor's, else zeros."""
        actors = self.log.actors.get(ts)
        if actors is not None and object_id in actors.index:
            extent: FloatArray = actors.extent[actors.index[object_id]]
            return extent
        return np.zeros(3)

    def plan(self, ts: int) -> Any:
        plan = self.log.waypoints.get(ts)
        return None if plan is None else self._trajectory(ts, plan)

    def _trajectory(self, ts: int, plan: Plan) -> Any:
        m = self.m
        pose = self.log.pose.get(ts)
        z = pose.z if pose is not None else 0.0
        carla = np.column_stack([plan.xy, np.full(len(plan), z)])
        xyz = carla_to_map_xyz(carla)
        initial = float(-np.radians(pose.yaw)) if pose is not None else 0.0
        poses = m.poses(xyz, _yaw_quaternion(path_headings(xyz, initial)))
        points = [
            m.new(
                "autoware_planning_msgs/msg/TrajectoryPoint",
                time_from_start=m.duration(i * self.frame_step_ns),
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
        return m.new(
            "autoware_planning_msgs/msg/Trajectory", header=m.header(stamp_ns(ts)), points=points
        )

    def control(self, ts: int) -> Any:
        command = self.log.controls.get(ts)
        return None if command is None else self._control(ts, command)

    def _control(self, ts: int, command: ControlCommand) -> Any:
        m = self.m
        stamp = m.time(stamp_ns(ts))
        steer = 0.0 if math.isnan(command.steer) else -math.radians(command.steer)
        acceleration = command.acceleration
        lateral = m.new(
            "autoware_control_msgs/msg/Lateral",
            stamp=stamp,
            control_time=stamp,
            steering_tire_angle=steer,  # ROS: positive turns left; CARLA's steer right
            steering_tire_rotation_rate=0.0,
            is_defined_steering_tire_rotation_rate=False,
        )
        longitudinal = m.new(
            "autoware_control_msgs/msg/Longitudinal",
            stamp=stamp,
            control_time=stamp,
            velocity=0.0 if math.isnan(command.speed) else command.speed,
            acceleration=0.0 if math.isnan(acceleration) else acceleration,
            jerk=0.0,
            is_defined_acceleration=not math.isnan(acceleration),
            is_defined_jerk=False,
        )
        return m.new(
            "autoware_control_msgs/msg/Control",
            stamp=stamp,
            control_time=stamp,
            lateral=lateral,
            longitudinal=longitudinal,
        )

    def detections_2d(self, ts: int) -> Any:
        boxes = self.log.bboxes.get(ts)
        return None if boxes is None else self._detection_2d_array(ts, boxes)

    def ground_truth_2d(self, ts: int) -> Any:
        boxes = self.log.bboxes_gt.get(ts)
        return None if boxes is None else self._detection_2d_array(ts, boxes)

    def _hypothesis(self, extras: Mapping[str, Any], pose: Any) -> Any:
        label = extras.get("label")
        score = extras.get("score")
        if not isinstance(score, (int, float)) or isinstance(score, bool):
            score = math.nan
        hypothesis = self.m.new(
            "vision_msgs/msg/ObjectHypothesis",
            class_id="" if label is None else str(label),
            score=_probability(float(score)),
        )
        return self.m.new(
            "vision_msgs/msg/ObjectHypothesisWithPose",
            hypothesis=hypothesis,
            pose=self.m.pose_cov(pose),
        )

    def _detection_2d_array(self, ts: int, boxes: Boxes) -> Any:
        m = self.m
        header = m.header(stamp_ns(ts), "camera")
        no_pose = m.pose(np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]))
        centre = (boxes.corners[:, :2] + boxes.corners[:, 2:]) / 2.0
        size = boxes.corners[:, 2:] - boxes.corners[:, :2]
        detections = [
            m.new(
                "vision_msgs/msg/Detection2D",
                header=header,
                results=[self._hypothesis(boxes.extras[row], no_pose)],
                bbox=m.new(
                    "vision_msgs/msg/BoundingBox2D",
                    center=m.new(
                        "vision_msgs/msg/Pose2D",
                        position=m.new(
                            "vision_msgs/msg/Point2D",
                            x=float(centre[row, 0]),
                            y=float(centre[row, 1]),
                        ),
                        theta=0.0,
                    ),
                    size_x=float(size[row, 0]),
                    size_y=float(size[row, 1]),
                ),
                id=box_id,
            )
            for row, box_id in enumerate(boxes.ids)
        ]
        return m.new("vision_msgs/msg/Detection2DArray", header=header, detections=detections)

    def _detection_3d_array(self, ts: int, objects: Objects3D) -> Any:
        m = self.m
        header = m.header(stamp_ns(ts))
        frame = _MapObjects(objects)
        detections = []
        for row, object_id in enumerate(objects.ids):
            pose = m.pose(frame.position[row], frame.quaternion[row])
            extras = {"label": objects.labels[row], "score": float(objects.score[row])}
            detections.append(
                m.new(
                    "vision_msgs/msg/Detection3D",
                    header=header,
                    results=[self._hypothesis(extras, pose)],
                    bbox=m.new(
                        "vision_msgs/msg/BoundingBox3D",
                        center=pose,
                        size=m.vector3(2.0 * np.nan_to_num(objects.extent[row])),
                    ),
                    id=object_id,
                )
            )
        return m.new("vision_msgs/msg/Detection3DArray", header=header, detections=detections)

    def builders(self) -> dict[str, Callable[[int], Any]]:
        """Input name → its builder, for the inputs of this profile."""
        return {name: getattr(self, name) for name in profile_topics(self.profile)}

    def messages(self) -> Iterator[tuple[str, int, Any]]:
        """(input, log time ns, message) per frame, ascending; inputs in profile order."""
        builders = self.builders()
        log = self.log
        stamps = set(log.frames)
        for records in _held(log).values():
            stamps.update(records)
        if log.metadata.has_collision:
            stamps.add(log.metadata.collision_frame * log.frame_ms)
        for ts in sorted(stamps):
            for name, build in builders.items():
                message = build(ts)
                if message is not None:
                    yield name, stamp_ns(ts), message


def predicted_points(keys: tuple[str, ...], offsets: FloatArray, pose: EgoPose) -> FloatArray:
    """The CARLA world points (K, 3) of prediction keys "0", "1", ... in the ego body frame
    at ``pose``; the path ends at the first missing key (a path has no gaps)."""
    rows = {key: row for row, key in reversed(list(enumerate(keys)))}
    ordered = []
    for step in range(len(keys)):
        if str(step) not in rows:
            break
        ordered.append(rows[str(step)])
    body = offsets[ordered] if ordered else np.zeros((0, 3))
    xy = to_world(body[:, :2], np.array([pose.x, pose.y]), math.radians(pose.yaw))
    out: FloatArray = np.column_stack([xy, pose.z + body[:, 2]])
    return out


# --- the bag ---------------------------------------------------------------------------------


def topics_written(log: RunLog, profile: str) -> dict[str, tuple[str, str]]:
    """The (topic, type) per input a recording of ``log`` has: every input the log holds,
    the clock, and the collision topic even without a collision (the bridge offers it) when
    the run's collision is known. A run whose collision is unknown (no collision frame in
    its metadata, no collision input) gets no collision topic: read back, it is unknown
    still, where an empty topic would say "no collision" (docs/verdicts.md)."""
    held = _held(log)
    known = present(input_status(log)["collision"])
    return {
        name: spec
        for name, spec in profile_topics(profile).items()
        if name == "clock" or (known if name == "collision" else bool(held[name]))
    }


def _held(log: RunLog) -> dict[str, Mapping[int, object]]:
    """Each model input's records in ``log`` (the clock and collision are not records)."""
    return {
        "ego": log.pose,
        "actors": log.actors,
        "detections_2d": log.bboxes,
        "ground_truth_2d": log.bboxes_gt,
        "detections_3d": log.detections_3d,
        "tracked_objects": log.tracks_3d,
        "predictions": log.predictions,
        "plan": log.waypoints,
        "control": log.controls,
    }


def write_recording(
    log: RunLog,
    path: str | os.PathLike[str],
    profile: str = "carla-autoware",
    storage: str = "mcap",
    definitions: bool = True,
) -> dict[str, int]:
    """Write ``log`` as a rosbag2 bag directory ``path`` recorded from a ``profile`` stack;
    return the message count per topic.

    ``definitions=False`` leaves the sqlite3 ``message_definitions`` table empty, as in
    bags of rosbag2 before Iron (only sqlite3 has such bags). ``metadata.yaml``'s
    ``custom_data`` keeps the synthesis label, the actor id → uint32 map and the camera
    mounting, which the messages cannot carry.
    """
    from rosbags.rosbag2 import StoragePlugin, Writer, WriterError

    if profile not in PROFILES:
        raise ConfigError(f"profile must be one of {PROFILES}, got {profile!r}")
    if storage not in STORAGES:
        raise ConfigError(f"storage must be one of {STORAGES}, got {storage!r}")
    if not definitions and storage != "sqlite3":
        raise ConfigError("a bag without message definitions can only be sqlite3")
    root = Path(path)
    if root.is_dir() and not any(root.iterdir()):
        root.rmdir()  # rosbags creates the folder itself
    if os.path.lexists(root):
        raise OutputExists(f"{root} exists and is not an empty folder")
    writer = _Writer(log, profile)
    store = typestore()
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    bag = Writer(root, version=9, storage_plugin=plugin)
    counts: dict[str, int] = {}
    try:
        bag.open()
    except WriterError as error:
        raise OutputExists(f"{root}: {error}") from None
    try:
        connections = {}
        for name, (topic, msgtype) in topics_written(log, profile).items():
            connections[name] = bag.add_connection(
                topic,
                msgtype,
                msgdef=message_definition(msgtype),
                rihs01=store.hash_rihs01(msgtype),
            )
            counts[topic] = 0
        for name, log_time, message in writer.messages():
            connection = connections[name]
            bag.write(connection, log_time, store.serialize_cdr(message, connection.msgtype))
            counts[connection.topic] += 1
        for key, value in _custom_data(log, writer.numbers).items():
            bag.set_custom_data(key, value)
    finally:
        bag.close()
    if not definitions:
        _drop_definitions(root)
    return counts


def _custom_data(log: RunLog, numbers: Mapping[str, int]) -> dict[str, str]:
    renumbered = {i: n for i, n in numbers.items() if not _is_uint32(i)}
    out = {
        CUSTOM_ACTOR_IDS: json.dumps(renumbered, sort_keys=True),
        CUSTOM_CAMERA: json.dumps(list(log.metadata.camera_loc)),
    }
    synthesis = log.metadata.raw.get("synthesis")
    if synthesis is not None:
        out[CUSTOM_SYNTHESIS] = json.dumps(synthesis, sort_keys=True)
    return out


def _drop_definitions(root: Path) -> None:
    """Empty the sqlite3 ``message_definitions`` table of a closed bag."""
    for db3 in sorted(root.glob("*.db3")):
        with sqlite3.connect(db3) as connection:
            connection.execute("DELETE FROM message_definitions")
        connection.close()


__all__ = [
    "EPOCH_NS",
    "PROFILES",
    "actor_numbers",
    "message_definition",
    "object_uuid",
    "profile_topics",
    "stamp_ns",
    "write_recording",
]
