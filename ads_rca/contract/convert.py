"""Model records ↔ ROS message objects, both ways, one pair of functions per kind of record.

Pure functions (message packages, imported where a message is built; no rclpy) so the
conversion can be tested without DDS and reused by the player, the bag writer and the
assembler. Which topic carries which kind, in which marker namespace and colour, is the
topic table's business (:mod:`ads_rca.contract.topics`), not this module's.

Geometry goes from the log's CARLA world frame (left-handed, degrees) to ROS REP-103
(right-handed, radians, quaternions) exactly as the CARLA ROS bridge does: (x, y, z) →
(x, −y, z), roll → roll, pitch → −pitch, yaw → −yaw. Positions round-trip exactly (negation
is exact); angles come back through the quaternion to ~1e-12 degrees, wrapped to
(−180, 180]. Quaternion math runs in numpy over a whole frame. See docs/topics.md for the
contract and its limits.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from ads_rca.contract.errors import MalformedMessage, NoStamp
from ads_rca.contract.jsontext import dumps_json, loads_json
from ads_rca.foundation.text import short_repr
from ads_rca.model import (
    Actors,
    Boxes,
    ControlCommand,
    EgoPose,
    FloatArray,
    Objects3D,
    Plan,
    Predictions,
    Track,
)
from ads_rca.sources.openlane.lanes import LaneGraph

if TYPE_CHECKING:
    from builtin_interfaces.msg import Duration, Time
    from geometry_msgs.msg import Point, Quaternion
    from nav_msgs.msg import Odometry
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import CameraInfo, JointState
    from std_msgs.msg import ColorRGBA, Header, String
    from trajectory_msgs.msg import MultiDOFJointTrajectory
    from visualization_msgs.msg import Marker, MarkerArray

    from ads_rca.contract.camera import Intrinsics

INT32_MAX = 2**31 - 1
_NS_PER_MS = 1_000_000

#: Frame ids: the world (poses, actors, plans), the ego body (prediction offsets), the image
#: (boxes in pixels).
WORLD_FRAME = "map"
EGO_FRAME = "base_link"
IMAGE_FRAME = "camera_image"


@dataclass(frozen=True, slots=True)
class MarkerStyle:
    """How a MarkerArray topic draws its records: marker namespace and colour (r, g, b).

    Two topics of one kind (detections and ground truth) differ only in this."""

    ns: str
    color: tuple[float, float, float]


# --- time ---------------------------------------------------------------------------------


def to_time(timestamp_ms: int) -> Time:
    """Log milliseconds → builtin_interfaces/Time (floor division keeps negatives exact)."""
    from builtin_interfaces.msg import Time

    sec, ms = divmod(int(timestamp_ms), 1000)
    return Time(sec=sec, nanosec=ms * _NS_PER_MS)


def from_time(stamp: Time) -> int:
    """builtin_interfaces/Time → log milliseconds."""
    return int(stamp.sec) * 1000 + int(stamp.nanosec) // _NS_PER_MS


def to_duration(ms: int) -> Duration:
    from builtin_interfaces.msg import Duration

    sec, rest = divmod(int(ms), 1000)
    return Duration(sec=sec, nanosec=rest * _NS_PER_MS)


def from_duration(duration: Duration) -> int:
    return int(duration.sec) * 1000 + int(duration.nanosec) // _NS_PER_MS


def header(timestamp_ms: int, frame_id: str) -> Header:
    from std_msgs.msg import Header

    return Header(stamp=to_time(timestamp_ms), frame_id=frame_id)


# --- rotations (vectorised) ---------------------------------------------------------------


def carla_rpy_to_quaternions(rpy_deg: FloatArray) -> FloatArray:
    """(N, 3) CARLA roll, pitch, yaw in degrees → (N, 4) ROS quaternions (x, y, z, w).

    ROS angles are roll, −pitch, −yaw (radians); the quaternion is that of the static-axes
    x-y-z Euler rotation (``tf_transformations.quaternion_from_euler``), as the CARLA bridge.
    """
    rpy = np.radians(np.asarray(rpy_deg, dtype=np.float64).reshape(-1, 3))
    half = 0.5 * rpy * np.array([1.0, -1.0, -1.0])
    c, s = np.cos(half), np.sin(half)
    cr, cp, cy = c[:, 0], c[:, 1], c[:, 2]
    sr, sp, sy = s[:, 0], s[:, 1], s[:, 2]
    return np.stack(
        (
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
            cr * cp * cy + sr * sp * sy,
        ),
        axis=1,
    )


def quaternions_to_carla_rpy(quaternions: FloatArray) -> FloatArray:
    """(N, 4) ROS quaternions (x, y, z, w) → (N, 3) CARLA roll, pitch, yaw in degrees.

    The inverse of :func:`carla_rpy_to_quaternions` for pitch within ±90°; angles come back
    wrapped to (−180, 180]. Pitch uses atan2 with |cos pitch| so it stays accurate near ±90°.
    """
    q = np.asarray(quaternions, dtype=np.float64).reshape(-1, 4)
    x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    # A stack's (or a hostile topic's) quaternion may hold any double: overflow gives NaN
    # angles, judged as such, and no numpy warning on the node's stderr.
    with np.errstate(over="ignore", invalid="ignore"):
        sin_r_cos_p = 2.0 * (w * x + y * z)
        cos_r_cos_p = 1.0 - 2.0 * (x * x + y * y)
        roll = np.arctan2(sin_r_cos_p, cos_r_cos_p)
        pitch = np.arctan2(2.0 * (w * y - z * x), np.hypot(sin_r_cos_p, cos_r_cos_p))
        yaw = np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    degrees: FloatArray = np.degrees(np.stack((roll, -pitch, -yaw), axis=1))
    return degrees


def _quaternion(q: Sequence[float]) -> Quaternion:
    from geometry_msgs.msg import Quaternion

    return Quaternion(x=q[0], y=q[1], z=q[2], w=q[3])


def _point(x: float, y: float, z: float) -> Point:
    from geometry_msgs.msg import Point

    return Point(x=x, y=y, z=z)


# --- pose ---------------------------------------------------------------------------------


def pose_to_odometry(pose: EgoPose, timestamp_ms: int) -> Odometry:
    """Ego pose → nav_msgs/Odometry in ``map``, speed as body-frame linear x."""
    from geometry_msgs.msg import Pose
    from nav_msgs.msg import Odometry

    q = carla_rpy_to_quaternions(np.array([pose.roll, pose.pitch, pose.yaw]))[0].tolist()
    msg = Odometry(header=header(timestamp_ms, WORLD_FRAME), child_frame_id=EGO_FRAME)
    msg.pose.pose = Pose(position=_point(pose.x, -pose.y, pose.z), orientation=_quaternion(q))
    msg.twist.twist.linear.x = float(pose.speed)
    return msg


def odometry_to_pose(msg: Odometry) -> EgoPose:
    p, o = msg.pose.pose.position, msg.pose.pose.orientation
    roll, pitch, yaw = quaternions_to_carla_rpy(np.array([o.x, o.y, o.z, o.w]))[0].tolist()
    return EgoPose(
        x=p.x, y=-p.y, z=p.z, roll=roll, pitch=pitch, yaw=yaw, speed=msg.twist.twist.linear.x
    )


# --- actors -------------------------------------------------------------------------------


def marker_id(actor_id: str) -> int:
    """int32 marker id of an actor: the id itself when it is a canonical int ≥ 0 in int32,
    else a stable negative number from crc32 (so it cannot collide with numeric ids)."""
    if actor_id.isascii() and actor_id.isdigit() and str(int(actor_id)) == actor_id:
        value = int(actor_id)
        if value <= INT32_MAX:
            return value
    return -(zlib.crc32(actor_id.encode("utf-8")) & INT32_MAX) - 1


def _delete_all(timestamp_ms: int, frame_id: str, ns: str) -> Marker:
    from visualization_msgs.msg import Marker

    return Marker(header=header(timestamp_ms, frame_id), ns=ns, action=Marker.DELETEALL)


def _color(style: MarkerStyle) -> ColorRGBA:
    from std_msgs.msg import ColorRGBA

    r, g, b = style.color
    return ColorRGBA(r=r, g=g, b=b, a=1.0)


def actors_to_markers(actors: Actors, timestamp_ms: int, style: MarkerStyle) -> MarkerArray:
    """Actors → DELETEALL + one CUBE per actor (file order), full size, pose in ``map``."""
    from geometry_msgs.msg import Pose, Vector3
    from visualization_msgs.msg import Marker, MarkerArray

    ns = style.ns
    head = header(timestamp_ms, WORLD_FRAME)
    color = _color(style)
    quats = carla_rpy_to_quaternions(actors.rotation).tolist()
    locs = (actors.location * np.array([1.0, -1.0, 1.0])).tolist()
    sizes = (2.0 * actors.extent).tolist()
    markers = [_delete_all(timestamp_ms, WORLD_FRAME, ns)]
    for actor_id, loc, q, size in zip(actors.ids, locs, quats, sizes, strict=True):
        markers.append(
            Marker(
                header=head,
                ns=ns,
                id=marker_id(actor_id),
                type=Marker.CUBE,
                action=Marker.ADD,
                pose=Pose(position=_point(*loc), orientation=_quaternion(q)),
                scale=Vector3(x=size[0], y=size[1], z=size[2]),
                color=color,
                text=actor_id,
            )
        )
    return MarkerArray(markers=markers)


def _added(msg: MarkerArray) -> list[Marker]:
    from visualization_msgs.msg import Marker

    return [m for m in msg.markers if m.action != Marker.DELETEALL]


def markers_to_actors(msg: MarkerArray) -> Actors:
    markers = _added(msg)
    n = len(markers)
    location = np.empty((n, 3))
    quats = np.empty((n, 4))
    extent = np.empty((n, 3))
    for row, m in enumerate(markers):
        p, o, s = m.pose.position, m.pose.orientation, m.scale
        location[row] = (p.x, -p.y, p.z)
        quats[row] = (o.x, o.y, o.z, o.w)
        extent[row] = (s.x, s.y, s.z)
    return Actors(
        ids=tuple(m.text for m in markers),
        location=location,
        rotation=quaternions_to_carla_rpy(quats),
        extent=extent / 2.0,
    )


# --- 3-D objects ----------------------------------------------------------------------------

#: CARLA ↔ ROS for positions and velocities, both ways: y is negated.
FLIP_Y = np.array([1.0, -1.0, 1.0])


def objects_rpy(objects: Objects3D) -> FloatArray:
    """(N, 3) roll, pitch, yaw of 3-D objects (roll and pitch 0: a stack's boxes are upright)."""
    rpy = np.zeros((len(objects.ids), 3))
    rpy[:, 2] = np.reshape(objects.yaw, -1)
    return rpy


def object_text(object_id: str, label: str, score: float, yaw: float, velocity: list[float]) -> str:
    """A 3-D object marker's ``text``: what a CUBE cannot carry, in ``map`` convention (the
    yaw in degrees, so it comes back exactly)."""
    return dumps_json(
        {"id": object_id, "label": label, "score": score, "yaw_deg": -yaw, "velocity": velocity}
    )


def object_texts(objects: Objects3D) -> list[str]:
    """Every object's marker ``text`` (row order)."""
    velocity = (np.reshape(objects.velocity, (-1, 3)) * FLIP_Y).tolist()
    return [
        object_text(*fields)
        for fields in zip(
            objects.ids,
            objects.labels,
            np.reshape(objects.score, -1).tolist(),
            np.reshape(objects.yaw, -1).tolist(),
            velocity,
            strict=True,
        )
    ]


def objects_to_markers(objects: Objects3D, timestamp_ms: int, style: MarkerStyle) -> MarkerArray:
    """3-D objects → DELETEALL + one CUBE per object (row order, id = row), full size, in
    ``map``; id, label, score, exact yaw and velocity in ``text`` (docs/topics.md)."""
    from geometry_msgs.msg import Pose, Vector3
    from visualization_msgs.msg import Marker, MarkerArray

    ns = style.ns
    head = header(timestamp_ms, WORLD_FRAME)
    color = _color(style)
    quats = carla_rpy_to_quaternions(objects_rpy(objects)).tolist()
    locs = (np.reshape(objects.location, (-1, 3)) * FLIP_Y).tolist()
    sizes = (2.0 * np.reshape(objects.extent, (-1, 3))).tolist()
    markers = [_delete_all(timestamp_ms, WORLD_FRAME, ns)]
    for index, (loc, q, size, text) in enumerate(
        zip(locs, quats, sizes, object_texts(objects), strict=True)
    ):
        markers.append(
            Marker(
                header=head,
                ns=ns,
                id=index,
                type=Marker.CUBE,
                action=Marker.ADD,
                pose=Pose(position=_point(*loc), orientation=_quaternion(q)),
                scale=Vector3(x=size[0], y=size[1], z=size[2]),
                color=color,
                text=text,
            )
        )
    return MarkerArray(markers=markers)


def objects_from_fields(
    marker_ids: Sequence[int], poses: FloatArray, scales: FloatArray, texts: Sequence[str]
) -> Objects3D:
    """Objects3D from its markers' ids, poses (N, 7: position, quaternion), scales (N, 3)
    and texts: the reading both paths share. MalformedMessage for a text that is not the
    object's (a velocity that is not 3 numbers, a label or id that is not text ...)."""
    n = len(texts)
    yaw = quaternions_to_carla_rpy(np.reshape(poses[:, 3:7], (-1, 4)))[:, 2]
    velocity = np.full((n, 3), math.nan)
    score = np.full(n, math.nan)
    ids: list[str] = []
    labels: list[str] = []
    for row, (marker, text) in enumerate(zip(marker_ids, texts, strict=True)):
        document = marker_document(text)
        object_id = document.get("id", str(marker))
        label = document.get("label", "")
        if not isinstance(object_id, str) or not isinstance(label, str):
            raise MalformedMessage(f"3-D object marker {row}: id and label must be text")
        ids.append(object_id)
        labels.append(label)
        if "yaw_deg" in document:
            yaw[row] = -_number(document["yaw_deg"], row, "yaw_deg")
        if document.get("score") is not None:
            score[row] = _number(document["score"], row, "score")
        listed = document.get("velocity")
        if listed is not None:
            if not isinstance(listed, list) or len(listed) != 3:
                raise MalformedMessage(f"3-D object marker {row}: velocity is not [vx, vy, vz]")
            velocity[row] = [math.nan if v is None else _number(v, row, "velocity") for v in listed]
    location = np.array(poses[:, 0:3], dtype=np.float64).reshape(-1, 3) * FLIP_Y
    return Objects3D(
        ids=tuple(ids),
        location=location,
        yaw=yaw,
        extent=np.array(scales, dtype=np.float64).reshape(-1, 3) / 2.0,
        velocity=velocity * FLIP_Y,
        score=score,
        labels=tuple(labels),
    )


def _number(value: object, row: int, key: str) -> float:
    """A JSON number of a marker text (bool is not one)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise MalformedMessage(f"3-D object marker {row}: {key} is not a number")
    return float(value)


def markers_to_objects(msg: MarkerArray) -> Objects3D:
    markers = _added(msg)
    poses = np.empty((len(markers), 7))
    scales = np.empty((len(markers), 3))
    for row, m in enumerate(markers):
        p, o, s = m.pose.position, m.pose.orientation, m.scale
        poses[row] = (p.x, p.y, p.z, o.x, o.y, o.z, o.w)
        scales[row] = (s.x, s.y, s.z)
    return objects_from_fields([m.id for m in markers], poses, scales, [m.text for m in markers])


# --- control commands -------------------------------------------------------------------------

#: ``control/command``'s JointState names, in order.
CONTROL_NAMES = ("steering_tire_angle_deg", "acceleration", "speed")


def control_positions(command: ControlCommand) -> list[float]:
    """The JointState positions of a command: steering in degrees with the ROS sign (+ left,
    the negated CARLA sign: exact), acceleration and target speed as they are."""
    return [-float(command.steer), float(command.acceleration), float(command.speed)]


def control_to_joint_state(command: ControlCommand, timestamp_ms: int) -> JointState:
    from sensor_msgs.msg import JointState

    return JointState(
        header=header(timestamp_ms, ""),
        name=list(CONTROL_NAMES),
        position=control_positions(command),
    )


def control_from_fields(names: Sequence[str], positions: Sequence[float]) -> ControlCommand:
    """A command from JointState names and positions (values by name; a name absent: NaN)."""
    if len(positions) < len(names):
        raise MalformedMessage(f"joint state has {len(names)} names, {len(positions)} positions")
    value: dict[str, float] = {}
    for name, position in zip(names, positions, strict=False):
        value.setdefault(name, float(position))
    steer, acceleration, speed = (value.get(name, math.nan) for name in CONTROL_NAMES)
    return ControlCommand(steer=-steer, acceleration=acceleration, speed=speed)


def joint_state_to_control(msg: JointState) -> ControlCommand:
    return control_from_fields(list(msg.name), list(msg.position))


# --- boxes --------------------------------------------------------------------------------


def boxes_to_markers(boxes: Boxes, timestamp_ms: int, style: MarkerStyle) -> MarkerArray:
    """Boxes → DELETEALL + one closed LINE_STRIP per box in pixels (``camera_image``).

    points[0] and points[2] are the two corners as written; ``text`` is JSON of the id and
    every extra key (label, score ...), in file order.
    """
    from visualization_msgs.msg import MarkerArray

    ns = style.ns
    head = header(timestamp_ms, IMAGE_FRAME)
    color = _color(style)
    markers = [_delete_all(timestamp_ms, IMAGE_FRAME, ns)]
    for index, (box_id, (x1, y1, x2, y2), extras) in enumerate(
        zip(boxes.ids, boxes.corners.tolist(), boxes.extras, strict=True)
    ):
        p1 = _point(x1, y1, 0.0)
        corners = [p1, _point(x2, y1, 0.0), _point(x2, y2, 0.0), _point(x1, y2, 0.0), p1]
        text = dumps_json({"id": box_id, **extras})
        markers.append(_line_strip(head, ns, index, 2.0, color, corners, text))
    return MarkerArray(markers=markers)


def _line_strip(
    head: Header, ns: str, index: int, width: float, color: Any, points: list[Point], text: str
) -> Marker:
    """An ADD LINE_STRIP marker (boxes and predictions are both drawn as these)."""
    from geometry_msgs.msg import Pose, Quaternion, Vector3
    from visualization_msgs.msg import Marker

    return Marker(
        header=head,
        ns=ns,
        id=index,
        type=Marker.LINE_STRIP,
        action=Marker.ADD,
        pose=Pose(orientation=Quaternion(w=1.0)),
        scale=Vector3(x=width),
        color=color,
        points=points,
        text=text,
    )


def marker_document(text: str) -> dict[str, Any]:
    """The JSON object of a marker's ``text`` ({} when empty); MalformedMessage (JsonTextError
    for text that is no JSON) when it is not one: the marker's message cannot be used."""
    document = loads_json(text) if text else {}
    if not isinstance(document, dict):
        raise MalformedMessage(f"marker text is not a JSON object: {type(document).__name__}")
    return document


def check_box_points(count: int) -> None:
    """A box marker carries its two corners as points 0 and 2."""
    if count < 3:
        raise MalformedMessage(f"a box marker has {count} points, its corners need 3")


def track_keys(document: dict[str, Any], points: int) -> tuple[str, ...]:
    """A prediction marker's step keys: one per point (its text's ``keys``, else 0..n-1)."""
    listed = document.get("keys")
    if listed is None:
        return tuple(map(str, range(points)))
    if not isinstance(listed, list) or len(listed) != points:
        raise MalformedMessage(f"prediction marker keys do not match its {points} points")
    return tuple(map(str, listed))


def markers_to_boxes(msg: MarkerArray) -> Boxes:
    markers = _added(msg)
    corners = np.empty((len(markers), 4))
    ids: list[str] = []
    extras: list[dict[str, Any]] = []
    for row, m in enumerate(markers):
        check_box_points(len(m.points))
        p1, p2 = m.points[0], m.points[2]
        corners[row] = (p1.x, p1.y, p2.x, p2.y)
        document = marker_document(m.text)
        ids.append(str(document.pop("id", m.id)))
        extras.append(document)
    return Boxes(ids=tuple(ids), corners=corners, extras=tuple(extras))


# --- predictions --------------------------------------------------------------------------


def predictions_to_markers(
    predictions: Predictions, timestamp_ms: int, style: MarkerStyle
) -> MarkerArray:
    """Predictions → DELETEALL + one LINE_STRIP per obstacle of ego-frame offsets (``base_link``).

    ``text`` is JSON {"id", "keys"}: the obstacle id and its step keys as written.
    """
    from visualization_msgs.msg import MarkerArray

    ns = style.ns
    head = header(timestamp_ms, EGO_FRAME)
    color = _color(style)
    markers = [_delete_all(timestamp_ms, EGO_FRAME, ns)]
    for index, (obstacle_id, track) in enumerate(predictions.items()):
        offsets = (track.offsets * np.array([1.0, -1.0, 1.0])).tolist()
        text = dumps_json({"id": obstacle_id, "keys": list(track.keys)})
        points = [_point(*o) for o in offsets]
        markers.append(_line_strip(head, ns, index, 0.2, color, points, text))
    return MarkerArray(markers=markers)


def markers_to_predictions(msg: MarkerArray) -> Predictions:
    out: Predictions = {}
    for m in _added(msg):
        document = marker_document(m.text)
        keys = track_keys(document, len(m.points))
        offsets = np.array([(p.x, -p.y, p.z) for p in m.points], dtype=np.float64).reshape(-1, 3)
        out.setdefault(str(document.get("id", m.id)), Track(keys=keys, offsets=offsets))
    return out


# --- lane graphs (map perception) ---------------------------------------------------------

#: A lane centerline's line width (m); the traffic elements' labels: height (m) and where
#: they stack above the ego (z of the first, then one step up each).
LANE_WIDTH = 0.3
LABEL_HEIGHT = 0.5
LABEL_BASE_Z = 3.0
LABEL_STEP_Z = 0.6
#: visualization_msgs/Marker.TEXT_VIEW_FACING (the traffic elements' labels).
TEXT_VIEW_FACING = 9


def lane_marker_texts(graph: LaneGraph) -> list[str]:
    """Every lane's marker ``text``, then every traffic element's (docs/topics.md): JSON
    {"lane", "score", "next", "elements"} with lane i's rows of the two adjacency matrices,
    and {"element", "box", "category", "attribute", "score"}."""
    lanes = [
        dumps_json({"lane": ident, "score": score, "next": following, "elements": governed})
        for ident, score, following, governed in zip(
            graph.lane_ids,
            graph.lane_scores.tolist(),
            graph.lane_lane.tolist(),
            graph.lane_element.tolist(),
            strict=True,
        )
    ]
    elements = [
        dumps_json(
            {"element": ident, "box": box, "category": category, "attribute": attribute}
            | {"score": score}
        )
        for ident, box, category, attribute, score in graph.element_rows()
    ]
    return lanes + elements


def label_heights(count: int) -> FloatArray:
    """z of each traffic element's label (stacked above the ego)."""
    out: FloatArray = LABEL_BASE_Z + LABEL_STEP_Z * np.arange(count, dtype=np.float64)
    return out


def lanes_to_markers(graph: LaneGraph, timestamp_ms: int, style: MarkerStyle) -> MarkerArray:
    """A lane graph → DELETEALL + one LINE_STRIP per lane centerline (``base_link``, REP-103:
    y flipped back to the left) + one TEXT_VIEW_FACING label per traffic element, stacked
    above the ego (the elements are image boxes: ``perception/ground_truth`` draws them).
    Marker ids: lanes 0…n−1, elements n…; ``text`` as :func:`lane_marker_texts`."""
    from geometry_msgs.msg import Pose, Quaternion, Vector3
    from visualization_msgs.msg import Marker, MarkerArray

    ns = style.ns
    head = header(timestamp_ms, EGO_FRAME)
    color = _color(style)
    texts = lane_marker_texts(graph)
    markers = [_delete_all(timestamp_ms, EGO_FRAME, ns)]
    for index, lane in enumerate(graph.lanes):
        points = [_point(*p) for p in (lane * FLIP_Y).tolist()]
        markers.append(_line_strip(head, ns, index, LANE_WIDTH, color, points, texts[index]))
    n = graph.lane_count
    for row, z in enumerate(label_heights(graph.element_count).tolist()):
        markers.append(
            Marker(
                header=head,
                ns=ns,
                id=n + row,
                type=TEXT_VIEW_FACING,
                action=Marker.ADD,
                pose=Pose(position=_point(0.0, 0.0, z), orientation=Quaternion(w=1.0)),
                scale=Vector3(z=LABEL_HEIGHT),
                color=color,
                text=texts[n + row],
            )
        )
    return MarkerArray(markers=markers)


def markers_to_lanes(msg: MarkerArray) -> LaneGraph:
    """The inverse of :func:`lanes_to_markers`."""
    return lane_graph_of(
        [
            (m.text, np.array([(p.x, p.y, p.z) for p in m.points], dtype=np.float64))
            for m in _added(msg)
        ]
    )


def lane_graph_of(markers: Sequence[tuple[str, FloatArray]]) -> LaneGraph:
    """A lane graph from its markers' (text, (P, 3) points in REP-103); MalformedMessage for
    markers that are not one (a text of neither kind, rows of the wrong length)."""
    lanes: list[dict[str, Any]] = []
    elements: list[dict[str, Any]] = []
    points: list[FloatArray] = []
    for text, pts in markers:
        document = marker_document(text)
        if "lane" in document:
            lanes.append(document)
            points.append(np.reshape(pts, (-1, 3)) * FLIP_Y)
        elif "element" in document:
            elements.append(document)
        else:
            raise MalformedMessage("a lanes marker that is neither a lane nor an element")
    n, k = len(lanes), len(elements)
    return LaneGraph(
        lane_ids=_marker_ids(lanes, "lane"),
        lanes=tuple(points),
        lane_scores=_marker_numbers(lanes, "score", ()),
        element_ids=_marker_ids(elements, "element"),
        element_boxes=_marker_numbers(elements, "box", (4,)),
        element_category=_marker_numbers(elements, "category", (), np.int64),
        element_attribute=_marker_numbers(elements, "attribute", (), np.int64),
        element_scores=_marker_numbers(elements, "score", ()),
        lane_lane=_marker_numbers(lanes, "next", (n,)),
        lane_element=_marker_numbers(lanes, "elements", (k,)),
    )


def _marker_ids(documents: Sequence[dict[str, Any]], key: str) -> tuple[str, ...]:
    """Each lanes marker's ``key`` id as text; MalformedMessage where one is no text or
    integer."""
    ids = tuple(document.get(key) for document in documents)
    for value in ids:
        if not isinstance(value, (str, int)) or isinstance(value, bool):
            raise MalformedMessage(f"a lanes marker's {key} id is {short_repr(value)}")
    return tuple(map(str, ids))


def _marker_numbers(
    documents: Sequence[dict[str, Any]],
    key: str,
    shape: tuple[int, ...],
    dtype: type[np.float64] | type[np.int64] = np.float64,
) -> npt.NDArray[Any]:
    """Each lanes marker's ``key``: a number (``shape`` ()) or a list of ``shape[0]``
    numbers (integers for int64), stacked; MalformedMessage where one is not."""
    integral = dtype is np.int64
    rows = [document.get(key) for document in documents]
    for value in rows:
        values = [value] if not shape else value if isinstance(value, list) else None
        if (
            values is None
            or len(values) != (shape[0] if shape else 1)
            or not all(_in_range(v, integral) for v in values)
        ):
            wanted = f"{shape[0]} numbers" if shape else "an integer" if integral else "a number"
            raise MalformedMessage(f"a lanes marker's {key} is not {wanted}: {short_repr(value)}")
    return np.array(rows, dtype=dtype).reshape(len(rows), *shape)


def _in_range(value: object, integral: bool) -> bool:
    """A JSON number that fits its column (an int64 for integers, a double else)."""
    if isinstance(value, bool):
        return False
    if isinstance(value, int):
        return -(2**63) <= value < 2**63
    return isinstance(value, float) and not integral


# --- plan ---------------------------------------------------------------------------------


def step_ms(timesteps_per_frame: int) -> int:
    """Milliseconds per plan step (1 if the metadata's frame period is not positive)."""
    return timesteps_per_frame if timesteps_per_frame > 0 else 1


def carried_plan_rows(plan: Plan) -> list[int]:
    """Rows whose key is a canonical integer (``str(int(k)) == k``): the ones a trajectory
    point can carry through ``time_from_start``. Others are dropped by the converter."""
    return [row for row, key in enumerate(plan.keys) if _canonical_int(key)]


def _canonical_int(text: str) -> bool:
    try:
        return str(int(text)) == text
    except ValueError:
        return False


def plan_to_trajectory(
    plan: Plan, timestamp_ms: int, timesteps_per_frame: int
) -> MultiDOFJointTrajectory:
    """Plan → MultiDOFJointTrajectory in ``map``: one point per integer key, file order.

    translation (x, −y, 0), identity rotation, linear.x = speed, time_from_start = key × frame_ms.
    """
    from geometry_msgs.msg import Quaternion, Transform, Twist, Vector3
    from trajectory_msgs.msg import MultiDOFJointTrajectory, MultiDOFJointTrajectoryPoint

    step = step_ms(timesteps_per_frame)
    xy, speed = plan.xy.tolist(), plan.speed.tolist()
    points = []
    for row in carried_plan_rows(plan):
        x, y = xy[row]
        points.append(
            MultiDOFJointTrajectoryPoint(
                transforms=[Transform(translation=Vector3(x=x, y=-y), rotation=Quaternion(w=1.0))],
                velocities=[Twist(linear=Vector3(x=speed[row]))],
                time_from_start=to_duration(int(plan.keys[row]) * step),
            )
        )
    return MultiDOFJointTrajectory(
        header=header(timestamp_ms, WORLD_FRAME), joint_names=["ego"], points=points
    )


def trajectory_to_plan(msg: MultiDOFJointTrajectory, timesteps_per_frame: int) -> Plan:
    step = step_ms(timesteps_per_frame)
    n = len(msg.points)
    xy = np.empty((n, 2))
    speed = np.empty(n)
    keys: list[str] = []
    for row, point in enumerate(msg.points):
        t = point.transforms[0].translation
        xy[row] = (t.x, -t.y)
        speed[row] = point.velocities[0].linear.x if point.velocities else math.nan
        keys.append(str(from_duration(point.time_from_start) // step))
    return Plan(keys=tuple(keys), xy=xy, speed=speed)


# --- the camera -----------------------------------------------------------------------------


def camera_info_message(intrinsics: Intrinsics, timestamp_ms: int) -> CameraInfo:
    """sensor_msgs/CameraInfo of a distortion-free pinhole (``plumb_bob``, D all zero,
    R identity), in ``camera_image`` (ads_rca/contract/camera.py)."""
    from sensor_msgs.msg import CameraInfo

    return CameraInfo(
        header=header(timestamp_ms, IMAGE_FRAME),
        height=intrinsics.height,
        width=intrinsics.width,
        distortion_model="plumb_bob",
        d=[0.0] * 5,
        k=list(intrinsics.k),
        r=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        p=list(intrinsics.p),
    )


# --- control messages and stamps ------------------------------------------------------------


def string_message(text: str) -> String:
    """std_msgs/String (the JSON topics: metadata, frame markers, status)."""
    from std_msgs.msg import String

    return String(data=text)


def string_text(msg: String) -> str:
    return str(msg.data)


def clock_message(timestamp_ms: int) -> Clock:
    """rosgraph_msgs/Clock of a log time."""
    from rosgraph_msgs.msg import Clock

    return Clock(clock=to_time(timestamp_ms))


def clock_ms(msg: Clock) -> int:
    return from_time(msg.clock)


def message_stamp_ms(msg: Any) -> int:
    """Log time of a data message: its header stamp (a MarkerArray's first marker's);
    NoStamp for a MarkerArray without markers."""
    from visualization_msgs.msg import MarkerArray

    if isinstance(msg, MarkerArray):
        if not msg.markers:
            raise NoStamp("empty MarkerArray carries no stamp")
        return from_time(msg.markers[0].header.stamp)
    return from_time(msg.header.stamp)
