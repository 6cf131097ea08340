"""Real stacks' message types → model records: one pure function per ROS type.

Each decoder takes the message object rosbags deserialised with the bag's own definitions
(attribute access; numeric arrays are numpy arrays) and gives the model record it carries,
in the log's CARLA frame (:mod:`ads_rca.sources.bag.profiles.frames`). A recording nobody checked
can
hold anything, and its definitions are its own: a field may be missing, of another type, or
NaN. Every such value raises :class:`MalformedMessage` naming the field (``objects[3].shape.
dimensions.x: NaN``), so the reader skips that one message and says why; nothing is
half-used. Objects are read column by column (one ``attrgetter`` pass per field, then numpy),
so a message of 10^5 objects costs a few hundred milliseconds, not a loop of model records.

A field the message's definition does not have at all is told apart (:func:`missing_field`):
every message of that topic would fail alike, so the reader skips the topic in one line.

Conventions (docs/recordings.md): ``shape.dimensions`` and ``bbox.size`` are FULL sizes
(halved here); twists of Autoware objects are in the object's own frame (rotated by its
yaw); a Control's steering is ROS-signed (positive left), the model's CARLA-signed
(positive right). Autoware's legacy types (``autoware_auto_*_msgs``) are aliases of the
current ones (:data:`LEGACY_ALIASES`): the same decoder, but where a field's name differs.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from dataclasses import field as dataclass_field
from operator import attrgetter
from typing import Any, cast

import numpy as np
import numpy.typing as npt

from ads_rca.contract.errors import MalformedMessage
from ads_rca.contract.rosmsg import normalise_type
from ads_rca.model import Actors, Boxes, ControlCommand, EgoPose, Objects3D, VehicleVelocity
from ads_rca.sources.bag.profiles import frames

FloatArray = npt.NDArray[np.float64]

#: The frames a profile input can be given in: ROS ``map`` (converted) or ``carla`` (as is).
FRAMES = ("map", "carla")

#: Autoware's ObjectClassification labels by value (the constants' names).
AUTOWARE_LABELS = (
    "UNKNOWN",
    "CAR",
    "TRUCK",
    "BUS",
    "TRAILER",
    "MOTORCYCLE",
    "BICYCLE",
    "PEDESTRIAN",
    "ANIMAL",
    "HAZARD",
    "OVER_DRIVABLE",
    "UNDER_DRIVABLE",
)
_UUID_BYTES = 16


def _no_objects() -> Objects3D:
    """A message of no objects."""
    empty = np.zeros((0, 3))
    return Objects3D((), empty, np.zeros(0), empty, empty, np.zeros(0), ())


@dataclass(frozen=True, eq=False)
class PredictedPaths:
    """One PredictedObjects message in the world: per object, its chosen path's points
    (P, 3) in the CARLA frame and their spacing in seconds (point j is at j·step after the
    message's stamp). The reader turns them into :data:`ads_rca.model.Predictions` once the
    ego pose of the frame is known (offsets are in the ego's body frame).

    ``states`` are the objects as the message states them now (its own kinematics: initial
    pose and twist, shape, class, existence probability), the tracked objects a recording
    without a tracking topic still carries; or why they cannot be read (a NaN twist spoils
    them, not the paths)."""

    ids: tuple[str, ...]
    points: tuple[FloatArray, ...]
    step_s: tuple[float, ...]
    states: Objects3D | MalformedMessage = dataclass_field(default_factory=_no_objects)


@dataclass(frozen=True, eq=False)
class TimedPlan:
    """One Trajectory message in the world: its points (N, 2) in the CARLA frame, their
    speeds and their ``time_from_start`` in seconds. A real planner spaces its points by
    distance, not by the frame period, so the reader samples the model's plan (key i = i
    frames ahead) from these times once the period is known."""

    times_s: FloatArray
    xy: FloatArray
    speed: FloatArray


@dataclass(frozen=True, slots=True)
class CollisionEvent:
    """A collision the simulator reported: the other actor's id (as the actors' ids)."""

    other_actor_id: str


@dataclass(frozen=True, slots=True)
class FailSafeState:
    """The stack's fail-safe (MRM) state as one message states it, by the constants' names
    (a value no constant names: its number as text)."""

    state: str
    behavior: str


@dataclass(frozen=True)
class Decoder:
    """How one ROS type is read: the model inputs it can carry, its record, its stamp."""

    type_name: str
    inputs: frozenset[str]
    #: (message object, frame) → record; MalformedMessage for a value that cannot be used.
    decode: Callable[[Any, str], object]
    #: message object → its stamp in nanoseconds (MalformedMessage if unusable).
    stamp: Callable[[Any], int]
    #: A legacy type read as this current type (its decoder, with the fields that differ).
    alias_of: str | None = None


# --- field access -------------------------------------------------------------------------


class _NoSuchField(MalformedMessage):
    """A field the decoder reads is not in the message's definition: every message of the
    topic lacks it (:func:`missing_field` tells it from a bad value)."""

    def __init__(self, path: str) -> None:
        super().__init__(f"{path}: missing (the message's definition has no such field)")
        self.path = path


def missing_field(error: MalformedMessage) -> str | None:
    """The field (path from the message) a decoding error says the definition lacks; None
    when the error is a bad value of one message."""
    return error.path if isinstance(error, _NoSuchField) else None


def within(prefix: str, error: MalformedMessage) -> MalformedMessage:
    """``error`` said of a field inside ``prefix`` (``objects[3]``), of the same kind."""
    if isinstance(error, _NoSuchField):
        return _NoSuchField(f"{prefix}.{error.path}")
    return MalformedMessage(f"{prefix}.{error}")


def field(msg: Any, path: str) -> Any:
    """``msg.<path>`` (dotted), MalformedMessage naming the path when a field is missing."""
    try:
        return attrgetter(path)(msg)
    except AttributeError:
        raise _NoSuchField(path) from None


def number(msg: Any, path: str) -> float:
    """A finite number field (an int or float; bool and text refused)."""
    value = field(msg, path)
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise MalformedMessage(f"{path}: {type(value).__name__} {value!r:.40}, not a number")
    out = float(value)
    if not np.isfinite(out):
        raise MalformedMessage(f"{path}: {out}, not a finite number")
    return out


def text(msg: Any, path: str) -> str:
    value = field(msg, path)
    if not isinstance(value, str):
        raise MalformedMessage(f"{path}: {type(value).__name__}, not a string")
    return value


def sequence(msg: Any, path: str) -> Sequence[Any]:
    """A sequence field (a list of messages, or a numpy array)."""
    value = field(msg, path)
    if not isinstance(value, (list, tuple, np.ndarray)):
        raise MalformedMessage(f"{path}: {type(value).__name__}, not a sequence")
    return cast("Sequence[Any]", value)  # an ndarray indexes and measures like one


def stamp_ns(msg: Any, path: str = "header.stamp") -> int:
    """A builtin_interfaces/Time field in nanoseconds."""
    sec, nanosec = field(msg, f"{path}.sec"), field(msg, f"{path}.nanosec")
    for name, value in ((f"{path}.sec", sec), (f"{path}.nanosec", nanosec)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            raise MalformedMessage(f"{name}: {type(value).__name__}, not an integer")
    if not 0 <= nanosec < 1_000_000_000:
        raise MalformedMessage(f"{path}.nanosec: {nanosec} is not below 1e9")
    return int(sec) * 1_000_000_000 + int(nanosec)


def duration_s(msg: Any, path: str) -> float:
    """A builtin_interfaces/Duration field in seconds."""
    return stamp_ns(msg, path) / 1e9


def column(items: Sequence[Any], where: str, path: str) -> FloatArray:
    """``item.<path>`` of every item as a float array (N,), every value a finite number.

    ``where`` names the sequence (``objects``) for the error, which names the first bad
    item: ``objects[3].pose.position.x: NaN``."""
    getter = attrgetter(path)
    try:
        values = list(map(getter, items))
    except AttributeError:
        row = next(i for i, item in enumerate(items) if not _has(item, path))
        raise _NoSuchField(f"{where}[{row}].{path}") from None
    try:
        array = np.array(values) if values else np.zeros(0)
    except (ValueError, OverflowError):  # ragged sequences, integers past 64 bits
        array = np.zeros((0, 0))
    if array.dtype.kind not in "fiu" or array.ndim != 1:
        row = next((i for i, v in enumerate(values) if not _is_number(v)), 0)
        bad = values[row] if values else None
        raise MalformedMessage(
            f"{where}[{row}].{path}: {type(bad).__name__} {bad!r:.40}, not a number"
        )
    out = array.astype(np.float64)
    finite = np.isfinite(out)
    if not finite.all():
        row = int(np.argmin(finite))
        raise MalformedMessage(f"{where}[{row}].{path}: {out[row]}, not a finite number")
    return out


def _has(item: Any, path: str) -> bool:
    try:
        attrgetter(path)(item)
    except AttributeError:
        return False
    return True


def _is_number(value: object) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)


def vectors(items: Sequence[Any], where: str, path: str) -> FloatArray:
    """``item.<path>.x/.y/.z`` of every item as (N, 3)."""
    return np.stack([column(items, where, f"{path}.{axis}") for axis in "xyz"], axis=-1)


# --- geometry -----------------------------------------------------------------------------


def poses(items: Sequence[Any], where: str, path: str, frame: str) -> tuple[FloatArray, FloatArray]:
    """Positions (N, 3) and (roll, pitch, yaw) degrees (N, 3) in CARLA of geometry_msgs/Pose
    fields, given in ``frame``."""
    xyz = vectors(items, where, f"{path}.position")
    q = [column(items, where, f"{path}.orientation.{axis}") for axis in "xyzw"]
    norm = np.sqrt(sum(c * c for c in q))
    if (norm == 0).any():
        row = int(np.argmin(norm))
        raise MalformedMessage(f"{where}[{row}].{path}.orientation: zero quaternion")
    rpy = frames.quaternion_to_rpy(*q)
    if frame == "carla":
        return xyz, np.degrees(rpy)
    return frames.map_to_carla_xyz(xyz), frames.map_rpy_to_carla_deg(rpy)


def world_velocity(linear_body: FloatArray, yaw_deg_carla: FloatArray, frame: str) -> FloatArray:
    """Body-frame linear twists (N, 3) of bodies with CARLA yaw (degrees) → CARLA world m/s.

    The twist is in the body's own axes of the message's frame: map bodies turn by their map
    yaw (= −CARLA yaw) and then flip y; CARLA bodies turn by their CARLA yaw."""
    if frame == "carla":
        return frames.body_to_world(linear_body, np.radians(yaw_deg_carla))
    return frames.map_to_carla_xyz(frames.body_to_world(linear_body, -np.radians(yaw_deg_carla)))


def _one(msg: Any, path: str, frame: str) -> tuple[FloatArray, FloatArray]:
    """One Pose field's position and CARLA rpy degrees, with the field named in errors."""
    xyz, rpy = poses([msg], "msg", path, frame)
    return xyz[0], rpy[0]


def _strip_row(error: MalformedMessage) -> MalformedMessage:
    path = missing_field(error)
    if path is not None:
        return _NoSuchField(path.removeprefix("msg[0]."))
    return MalformedMessage(str(error).removeprefix("msg[0]."))


# --- decoders -----------------------------------------------------------------------------


def decode_odometry(msg: Any, frame: str) -> EgoPose:
    """nav_msgs/Odometry → the ego pose; speed = |twist.linear| (any frame: a norm)."""
    try:
        xyz, rpy = _one(msg, "pose.pose", frame)
        twist = vectors([msg], "msg", "twist.twist.linear")[0]
    except MalformedMessage as error:
        raise _strip_row(error) from None
    x, y, z = (float(v) for v in xyz)
    roll, pitch, yaw = (float(v) for v in rpy)
    return EgoPose(x, y, z, roll, pitch, yaw, float(np.linalg.norm(twist)))


def decode_object_array(msg: Any, frame: str) -> Actors:
    """derived_object_msgs/ObjectArray → ground-truth actors (id = str(uint32 id); half
    extents from ``shape.dimensions``, full sizes for a BOX; other shapes: taken anyway)."""
    objects = sequence(msg, "objects")
    ids = column(objects, "objects", "id")
    xyz, rpy = poses(objects, "objects", "pose", frame)
    return Actors(tuple(str(int(i)) for i in ids), xyz, rpy, _half_extents(objects))


def _half_extents(objects: Sequence[Any]) -> FloatArray:
    """Half sizes (N, 3) of every object's shape: all at once when every shape is a box of
    three finite sizes (the usual case), else object by object."""
    try:
        dims = np.array(list(map(attrgetter("shape.dimensions"), objects)))
    except (AttributeError, ValueError, OverflowError):  # said object by object below
        dims = np.zeros((0, 0))
    if dims.shape == (len(objects), 3) and dims.dtype.kind in "fiu" and np.isfinite(dims).all():
        half: FloatArray = dims.astype(np.float64) / 2.0
        return half
    return np.array([_half_extent(obj, row) for row, obj in enumerate(objects)]).reshape(-1, 3)


def _half_extent(obj: Any, row: int) -> FloatArray:
    """Half sizes (x, y, z) of a shape_msgs/SolidPrimitive's ``dimensions``: a BOX's three
    full sizes halved; a CYLINDER's or CONE's (height, radius) and a SPHERE's (radius)
    taken as the box around them; none given: NaN (unknown)."""
    dims = np.asarray(sequence(obj, "shape.dimensions"))
    if dims.dtype.kind in "fiu" and np.isfinite(dims).all():
        values = dims.astype(np.float64)
        if values.shape == (3,):
            out: FloatArray = values / 2.0
            return out
        if values.shape == (2,):
            return np.array([values[1], values[1], values[0] / 2.0])
        if values.shape == (1,):
            return np.repeat(values, 3)
        if values.shape == (0,):  # no size given: unknown, as a log's missing extent
            return np.full(3, np.nan)
    raise MalformedMessage(f"objects[{row}].shape.dimensions: {dims.tolist()!r:.60}")


def _uuid_hex(objects: Sequence[Any]) -> tuple[str, ...]:
    out = []
    for row, obj in enumerate(objects):
        raw = field(obj, "object_id.uuid")
        data = np.asarray(raw)
        if data.dtype.kind not in "iu" or data.shape != (_UUID_BYTES,):
            raise MalformedMessage(
                f"objects[{row}].object_id.uuid: {data.size} values, not {_UUID_BYTES} bytes"
            )
        out.append(bytes(data.astype(np.uint8).tolist()).hex())
    return tuple(out)


def _labels(objects: Sequence[Any]) -> tuple[str, ...]:
    """Each object's most probable Autoware class name (UNKNOWN when none is given)."""
    out = []
    for row, obj in enumerate(objects):
        classes = sequence(obj, "classification")
        best, best_p = 0, -np.inf
        for k, entry in enumerate(classes):
            where = f"objects[{row}].classification[{k}]"
            try:
                p, label = number(entry, "probability"), number(entry, "label")
            except MalformedMessage as error:
                raise within(where, error) from None
            if p > best_p:
                best, best_p = int(label), p
        out.append(AUTOWARE_LABELS[best] if 0 <= best < len(AUTOWARE_LABELS) else str(best))
    return tuple(out)


def _autoware_objects(
    objects: Sequence[Any], frame: str, ids: tuple[str, ...], has_twist: npt.NDArray[np.bool_]
) -> Objects3D:
    xyz, rpy = poses(objects, "objects", "kinematics.pose_with_covariance.pose", frame)
    dims = vectors(objects, "objects", "shape.dimensions")
    body = vectors(objects, "objects", "kinematics.twist_with_covariance.twist.linear")
    velocity = world_velocity(body, rpy[:, 2], frame)
    velocity[~has_twist] = np.nan
    return Objects3D(
        ids=ids,
        location=xyz,
        yaw=rpy[:, 2],
        extent=dims / 2.0,
        velocity=velocity,
        score=column(objects, "objects", "existence_probability"),
        labels=_labels(objects),
    )


def _flags(items: Sequence[Any], where: str, path: str) -> npt.NDArray[np.bool_]:
    """A bool field of every item."""
    out = np.zeros(len(items), dtype=bool)
    for row, item in enumerate(items):
        try:
            value = attrgetter(path)(item)
        except AttributeError:
            raise _NoSuchField(f"{where}[{row}].{path}") from None
        if not isinstance(value, (bool, np.bool_)):
            raise MalformedMessage(f"{where}[{row}].{path}: {type(value).__name__}, not a bool")
        out[row] = value
    return out


def decode_detected_objects(msg: Any, frame: str) -> Objects3D:
    """autoware DetectedObjects → 3-D detections (ids ``d<row>``; velocity NaN unless
    ``has_twist``)."""
    objects = sequence(msg, "objects")
    has_twist = _flags(objects, "objects", "kinematics.has_twist")
    ids = tuple(f"d{row}" for row in range(len(objects)))
    return _autoware_objects(objects, frame, ids, has_twist)


def decode_tracked_objects(msg: Any, frame: str) -> Objects3D:
    """autoware TrackedObjects → tracked objects (ids: the 16-byte uuid as 32 hex digits;
    a track always has a velocity)."""
    objects = sequence(msg, "objects")
    ids = _uuid_hex(objects)
    return _autoware_objects(objects, frame, ids, np.ones(len(objects), dtype=bool))


def _best_path(obj: Any, row: int) -> tuple[Any, str] | None:
    """An object's predicted path of highest confidence and its field name (None: none)."""
    where = f"objects[{row}].kinematics.predicted_paths"
    paths = sequence(obj, "kinematics.predicted_paths")
    if not len(paths):
        return None
    if len(paths) == 1:
        try:
            number(paths[0], "confidence")
        except MalformedMessage as error:
            raise within(f"{where}[0]", error) from None
        return paths[0], f"{where}[0]"
    best = int(np.argmax(column(paths, where, "confidence")))
    return paths[best], f"{where}[{best}]"


def decode_predicted_objects(msg: Any, frame: str) -> PredictedPaths:
    """autoware PredictedObjects → each object's most confident path in the world (the
    points of all paths read as one column)."""
    objects = sequence(msg, "objects")
    ids = _uuid_hex(objects)
    chosen = [_best_path(obj, row) for row, obj in enumerate(objects)]
    steps: list[float] = []
    point_lists: list[Sequence[Any]] = []
    for found in chosen:
        if found is None:
            steps.append(0.0)
            point_lists.append(())
            continue
        path, here = found
        try:
            step = duration_s(path, "time_step")
            points = sequence(path, "path")
        except MalformedMessage as error:
            raise within(here, error) from None
        if step <= 0 and len(points) > 1:
            raise MalformedMessage(f"{here}.time_step: {step} s is not positive")
        steps.append(step)
        point_lists.append(points)
    flat = [point for points in point_lists for point in points]
    try:
        xyz = vectors(flat, "path", "position") if flat else np.zeros((0, 3))
    except MalformedMessage:  # name the object's own field
        for found, points in zip(chosen, point_lists, strict=True):
            if found is not None and len(points):
                vectors(points, f"{found[1]}.path", "position")
        raise
    if frame != "carla":
        xyz = frames.map_to_carla_xyz(xyz)
    if not objects:
        return PredictedPaths((), (), ())
    bounds = np.cumsum([len(points) for points in point_lists], dtype=np.int64)[:-1]
    states: Objects3D | MalformedMessage
    try:
        states = _predicted_states(objects, frame, ids)
    except MalformedMessage as error:
        states = error
    return PredictedPaths(ids, tuple(np.split(xyz, bounds)), tuple(steps), states)


def _predicted_states(objects: Sequence[Any], frame: str, ids: tuple[str, ...]) -> Objects3D:
    """Predicted objects as they are now: ``initial_pose_with_covariance``, the body-frame
    ``initial_twist_with_covariance`` turned into the world by the object's yaw, the
    shape's full size halved, the class of highest probability, the existence probability
    (the kinematics Autoware's prediction copies from its tracker)."""
    kinematics = "kinematics.initial_pose_with_covariance.pose"
    xyz, rpy = poses(objects, "objects", kinematics, frame)
    body = vectors(objects, "objects", "kinematics.initial_twist_with_covariance.twist.linear")
    return Objects3D(
        ids=ids,
        location=xyz,
        yaw=rpy[:, 2],
        extent=vectors(objects, "objects", "shape.dimensions") / 2.0,
        velocity=world_velocity(body, rpy[:, 2], frame),
        score=column(objects, "objects", "existence_probability"),
        labels=_labels(objects),
    )


def decode_trajectory(msg: Any, frame: str) -> TimedPlan:
    """autoware Trajectory → its points in CARLA xy, longitudinal speeds and
    ``time_from_start`` (MalformedMessage when the times go backwards)."""
    points = sequence(msg, "points")
    xyz = vectors(points, "points", "pose.position") if len(points) else np.zeros((0, 3))
    if frame != "carla":
        xyz = frames.map_to_carla_xyz(xyz)
    speed = column(points, "points", "longitudinal_velocity_mps")
    times = np.array([duration_s(point, "time_from_start") for point in points], dtype=np.float64)
    if times.size and np.any(np.diff(times) < 0):
        row = int(np.argmax(np.diff(times) < 0)) + 1
        raise MalformedMessage(
            f"points[{row}].time_from_start: {times[row]:g} s, before the point ahead of it"
        )
    return TimedPlan(times, xyz[:, :2].copy(), speed)


def decode_control(msg: Any, frame: str) -> ControlCommand:
    """autoware Control → steering (ROS + left → CARLA + right, degrees), acceleration,
    target speed."""
    del frame  # a command has no frame
    return _command(msg, "longitudinal.velocity")


def decode_ackermann_control(msg: Any, frame: str) -> ControlCommand:
    """autoware_auto AckermannControlCommand → as Control (its target speed is
    ``longitudinal.speed``)."""
    del frame
    return _command(msg, "longitudinal.speed")


def _command(msg: Any, speed_path: str) -> ControlCommand:
    angle = number(msg, "lateral.steering_tire_angle")
    return ControlCommand(
        steer=-float(np.degrees(angle)),
        acceleration=number(msg, "longitudinal.acceleration"),
        speed=number(msg, speed_path),
    )


def decode_velocity_report(msg: Any, frame: str) -> VehicleVelocity:
    """autoware VelocityReport → the vehicle's own velocity in its axes: longitudinal m/s,
    lateral m/s and heading rate in degrees/s, CARLA-signed (ROS positive left and
    counter-clockwise → CARLA positive right and clockwise) unless given in ``carla``."""
    sign = 1.0 if frame == "carla" else -1.0
    return VehicleVelocity(
        longitudinal=number(msg, "longitudinal_velocity"),
        lateral=sign * number(msg, "lateral_velocity"),
        heading_rate=sign * float(np.degrees(number(msg, "heading_rate"))),
    )


#: autoware_adapi_v1_msgs/MrmState's constants by value.
MRM_STATES = ("UNKNOWN", "NORMAL", "MRM_OPERATING", "MRM_SUCCEEDED", "MRM_FAILED")
MRM_BEHAVIORS = ("UNKNOWN", "NONE", "EMERGENCY_STOP", "COMFORTABLE_STOP", "PULL_OVER")


def decode_mrm_state(msg: Any, frame: str) -> FailSafeState:
    """autoware_adapi_v1_msgs MrmState → the state and behaviour by name."""
    del frame
    return FailSafeState(
        _constant(msg, "state", MRM_STATES), _constant(msg, "behavior", MRM_BEHAVIORS)
    )


def _constant(msg: Any, path: str, names: tuple[str, ...]) -> str:
    value = field(msg, path)
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise MalformedMessage(f"{path}: {type(value).__name__} {value!r:.40}, not an integer")
    return names[int(value)] if 0 <= value < len(names) else str(int(value))


def decode_collision(msg: Any, frame: str) -> CollisionEvent:
    """carla_msgs CarlaCollisionEvent → the other actor's id."""
    del frame
    other = field(msg, "other_actor_id")
    if isinstance(other, bool) or not isinstance(other, (int, np.integer)):
        raise MalformedMessage(f"other_actor_id: {type(other).__name__}, not an integer")
    return CollisionEvent(str(int(other)))


def decode_clock(msg: Any, frame: str) -> None:
    """rosgraph_msgs/Clock carries only its time."""
    del msg, frame


def _hypotheses(detections: Sequence[Any]) -> tuple[list[str | None], FloatArray]:
    """The first hypothesis's class id and score of each detection (None / NaN: none)."""
    labels: list[str | None] = []
    scores = np.full(len(detections), np.nan)
    for row, det in enumerate(detections):
        results = sequence(det, "results")
        if len(results):
            where = f"detections[{row}].results[0]"
            try:
                labels.append(text(results[0], "hypothesis.class_id"))
                scores[row] = number(results[0], "hypothesis.score")
            except MalformedMessage as error:
                raise within(where, error) from None
        else:
            labels.append(None)
    return labels, scores


def _detection_ids(detections: Sequence[Any]) -> tuple[str, ...]:
    """Each Detection's ``id``; ``d<row>`` when empty."""
    out = []
    for row, det in enumerate(detections):
        try:
            ident = text(det, "id")
        except MalformedMessage as error:
            raise within(f"detections[{row}]", error) from None
        out.append(ident or f"d{row}")
    return tuple(out)


def decode_detection_2d_array(msg: Any, frame: str) -> Boxes:
    """vision_msgs Detection2DArray → image boxes (x1, y1, x2, y2) from centre ± size/2;
    extras: the first hypothesis's ``label`` and ``score``."""
    del frame  # image pixels
    detections = sequence(msg, "detections")
    cx = column(detections, "detections", "bbox.center.position.x")
    cy = column(detections, "detections", "bbox.center.position.y")
    sx = column(detections, "detections", "bbox.size_x") / 2.0
    sy = column(detections, "detections", "bbox.size_y") / 2.0
    labels, scores = _hypotheses(detections)
    extras = tuple(
        {} if label is None else {"label": label, "score": float(score)}
        for label, score in zip(labels, scores, strict=True)
    )
    corners = np.stack([cx - sx, cy - sy, cx + sx, cy + sy], axis=-1).reshape(-1, 4)
    return Boxes(_detection_ids(detections), corners, extras)


def decode_detection_3d_array(msg: Any, frame: str) -> Objects3D:
    """vision_msgs Detection3DArray → 3-D detections (bbox centre pose; size FULL → half;
    no velocity)."""
    detections = sequence(msg, "detections")
    xyz, rpy = poses(detections, "detections", "bbox.center", frame)
    size = vectors(detections, "detections", "bbox.size")
    labels, scores = _hypotheses(detections)
    return Objects3D(
        ids=_detection_ids(detections),
        location=xyz,
        yaw=rpy[:, 2],
        extent=size / 2.0,
        velocity=np.full((len(detections), 3), np.nan),
        score=scores,
        labels=tuple(label or "" for label in labels),
    )


def _header(msg: Any) -> int:
    return stamp_ns(msg, "header.stamp")


_OBJECTS_3D = frozenset({"detections_3d", "tracked_objects"})
_BOXES = frozenset({"detections_2d", "ground_truth_2d"})
_PREDICTIONS = frozenset({"predictions", "predictions_gt"})

#: THE decoder table: ROS type name → how it is read.
DECODERS: dict[str, Decoder] = {
    d.type_name: d
    for d in (
        Decoder("nav_msgs/msg/Odometry", frozenset({"ego"}), decode_odometry, _header),
        Decoder(
            "derived_object_msgs/msg/ObjectArray",
            frozenset({"actors"}),
            decode_object_array,
            _header,
        ),
        Decoder(
            "autoware_perception_msgs/msg/DetectedObjects",
            _OBJECTS_3D,
            decode_detected_objects,
            _header,
        ),
        Decoder(
            "autoware_perception_msgs/msg/TrackedObjects",
            _OBJECTS_3D,
            decode_tracked_objects,
            _header,
        ),
        Decoder(
            "autoware_perception_msgs/msg/PredictedObjects",
            _PREDICTIONS,
            decode_predicted_objects,
            _header,
        ),
        Decoder(
            "autoware_planning_msgs/msg/Trajectory", frozenset({"plan"}), decode_trajectory, _header
        ),
        Decoder(
            "autoware_control_msgs/msg/Control",
            frozenset({"control"}),
            decode_control,
            lambda msg: stamp_ns(msg, "stamp"),
        ),
        Decoder(
            "carla_msgs/msg/CarlaCollisionEvent",
            frozenset({"collision"}),
            decode_collision,
            _header,
        ),
        Decoder(
            "rosgraph_msgs/msg/Clock",
            frozenset({"clock"}),
            decode_clock,
            lambda msg: stamp_ns(msg, "clock"),
        ),
        Decoder("vision_msgs/msg/Detection2DArray", _BOXES, decode_detection_2d_array, _header),
        Decoder(
            "vision_msgs/msg/Detection3DArray", _OBJECTS_3D, decode_detection_3d_array, _header
        ),
        Decoder(
            "autoware_vehicle_msgs/msg/VelocityReport",
            frozenset({"vehicle_velocity"}),
            decode_velocity_report,
            _header,
        ),
        Decoder(
            "autoware_adapi_v1_msgs/msg/MrmState",
            frozenset({"mrm_state"}),
            decode_mrm_state,
            lambda msg: stamp_ns(msg, "stamp"),
        ),
    )
}

#: Autoware's legacy types (``autoware_auto_*_msgs``, recorded until 2024) → the current type
#: whose decoder reads them. Their fields carry the same names but for the control command's
#: target speed (``longitudinal.speed``, now ``longitudinal.velocity``); field order and
#: constants differ (the bytes are decoded by the legacy definition, the fields read by
#: name), and the legacy ObjectClassification stops at PEDESTRIAN (7).
LEGACY_ALIASES = {
    "autoware_auto_perception_msgs/msg/DetectedObjects": (
        "autoware_perception_msgs/msg/DetectedObjects"
    ),
    "autoware_auto_perception_msgs/msg/TrackedObjects": (
        "autoware_perception_msgs/msg/TrackedObjects"
    ),
    "autoware_auto_perception_msgs/msg/PredictedObjects": (
        "autoware_perception_msgs/msg/PredictedObjects"
    ),
    "autoware_auto_planning_msgs/msg/Trajectory": "autoware_planning_msgs/msg/Trajectory",
    "autoware_auto_control_msgs/msg/AckermannControlCommand": "autoware_control_msgs/msg/Control",
    "autoware_auto_vehicle_msgs/msg/VelocityReport": "autoware_vehicle_msgs/msg/VelocityReport",
}
#: The legacy types whose fields differ: their own decode function.
_LEGACY_DECODE: dict[str, Callable[[Any, str], object]] = {
    "autoware_auto_control_msgs/msg/AckermannControlCommand": decode_ackermann_control,
}
DECODERS.update(
    {
        legacy: Decoder(
            legacy,
            DECODERS[current].inputs,
            _LEGACY_DECODE.get(legacy, DECODERS[current].decode),
            DECODERS[current].stamp,
            alias_of=current,
        )
        for legacy, current in LEGACY_ALIASES.items()
    }
)


def aliases_of(type_name: str) -> tuple[str, ...]:
    """The types read by the same decoder as ``type_name`` (its legacy alias, or the
    current type it is an alias of), ``type_name`` itself not included."""
    name = normalise_type(type_name)
    current = LEGACY_ALIASES.get(name, name)
    family = [current, *(old for old, new in LEGACY_ALIASES.items() if new == current)]
    return tuple(t for t in family if t != name and (t in DECODERS))


def decoder_for(type_name: str) -> Decoder | None:
    """The decoder of a type given as ``pkg/msg/Type`` or ``pkg/Type``."""
    return DECODERS.get(normalise_type(type_name))
