"""Model records → CDR bytes of the contract's messages, without rclpy message objects.

Why: building rclpy message objects costs ~19 µs per Marker and ~1 µs per Point, so
:func:`ads_rca.contract.convert.frame_messages` plus serialisation takes 10-17 ms for a 50-actor
frame. Here the same messages are written straight as XCDR1 little-endian bytes (the 4-byte
encapsulation header ``00 01 00 00`` then the payload, alignment relative to the payload
start, strings as uint32 length incl. NUL + bytes + NUL, no trailing padding), which
``Publisher.publish(bytes)`` sends unchanged. Numbers go through exactly the numpy
operations convert.py applies (same quaternion function on the same arrays, the same
multiplications and negations), so every value bit, NaN sign included, is the same.
Padding bytes are zero, as Fast DDS sends them for message objects; ``serialize_message``
leaves them uninitialised, so only non-padding bytes are comparable with it (see the tests).

Pure: numpy, struct and the message-free helpers of convert.py; no rclpy import.
Decoders live in :mod:`ads_rca.contract.cdr_decode`; which topic uses which encoder, in
which marker style, is the topic table's (:mod:`ads_rca.contract.topics`).
"""

from __future__ import annotations

import struct
from functools import lru_cache
from typing import Any

import numpy as np

from ads_rca.contract.camera import StaticTransform
from ads_rca.contract.convert import (
    CONTROL_NAMES,
    EGO_FRAME,
    FLIP_Y,
    IMAGE_FRAME,
    LABEL_HEIGHT,
    LANE_WIDTH,
    TEXT_VIEW_FACING,
    WORLD_FRAME,
    MarkerStyle,
    carla_rpy_to_quaternions,
    carried_plan_rows,
    control_positions,
    label_heights,
    lane_marker_texts,
    marker_id,
    object_texts,
    objects_rpy,
    step_ms,
)
from ads_rca.contract.jsontext import dumps_json
from ads_rca.model import Actors, Boxes, ControlCommand, EgoPose, Objects3D, Plan, Predictions
from ads_rca.sources.openlane.lanes import LaneGraph

#: Encapsulation header: representation CDR_LE (0x0001), options 0.
ENCAPSULATION = b"\x00\x01\x00\x00"
HEADER_SIZE = len(ENCAPSULATION)

_NS_PER_MS = 1_000_000
_U32 = struct.Struct("<I")
_STAMP = struct.Struct("<iI")
_ZEROS = bytes(8)

#: Marker constants (visualization_msgs/Marker).
CUBE = 1
LINE_STRIP = 4
ADD = 0
DELETEALL = 3

#: One Marker's id, type, action, pose, scale, color, lifetime, frame_locked, the 3 bytes
#: that realign to 4, and the points count, packed. The 4 bytes of alignment before ``pose``
#: depend on where the marker starts and are inserted when the rows are laid out.
MARKER_FIXED = np.dtype(
    [
        ("ita", "<i4", (3,)),
        ("pose", "<f8", (7,)),
        ("scale", "<f8", (3,)),
        ("color", "<f4", (4,)),
        ("lifetime", "<i4", (2,)),
        ("frame_locked", "u1"),
        ("pad", "V3"),
        ("points", "<u4"),
    ]
)
_FIXED = MARKER_FIXED.itemsize  # 124
_POSE_AT = 12  # offset of the first float64 in a MARKER_FIXED row

#: Fields between ``points`` and ``text`` when all are empty (starts 8-aligned): colors [],
#: texture_resource "", texture (stamp 0, frame_id "", format "", data []), uv_coordinates [].
_EMPTY_STRING = b"\x01\x00\x00\x00\x00\x00\x00\x00"  # "" + 3 bytes to realign to 4
MIDDLE_WHEN_EMPTY = (
    _U32.pack(0) + _EMPTY_STRING + bytes(8) + _EMPTY_STRING + _EMPTY_STRING + bytes(4) + bytes(4)
)
#: After ``text`` (4-aligned): mesh_resource "", mesh_file (filename "", data []),
#: mesh_use_embedded_materials false, then 3 bytes to realign the next marker to 4.
#: ``_TAILS[(text length incl. NUL) % 4]`` also holds the text's NUL and its padding.
MESH_WHEN_EMPTY = _EMPTY_STRING + _EMPTY_STRING + _U32.pack(0)
_AFTER_TEXT = MESH_WHEN_EMPTY + b"\x00\x00\x00\x00"
_TAILS = tuple(b"\x00" + bytes(-r % 4) + _AFTER_TEXT for r in range(4))
_MARKER_GAP = 3  # a marker ends 1 past a 4-boundary; the next one starts aligned


def stamp_fields(timestamp_ms: int) -> tuple[int, int]:
    """Log milliseconds → (sec, nanosec), floor division as :func:`convert.to_time`."""
    sec, ms = divmod(int(timestamp_ms), 1000)
    return sec, ms * _NS_PER_MS


def cdr_string(text: str) -> bytes:
    """A CDR string (caller aligns to 4): uint32 length incl. NUL, UTF-8 bytes, NUL."""
    data = text.encode()
    return _U32.pack(len(data) + 1) + data + b"\x00"


def _pad(position: int, alignment: int) -> bytes:
    return _ZEROS[: -position % alignment]


class CdrWriter:
    """Appends CDR fields to a buffer, aligning each to its size relative to the payload.

    For the small, once-per-message parts (headers, odometry); the bulk of a MarkerArray
    is written from precomputed pieces in :func:`encode_marker_array`.
    """

    def __init__(self) -> None:
        self.buffer = bytearray(ENCAPSULATION)

    @property
    def position(self) -> int:
        """Offset from the payload start (what CDR alignment refers to)."""
        return len(self.buffer) - HEADER_SIZE

    def align(self, alignment: int) -> None:
        self.buffer += _pad(self.position, alignment)

    def pack(self, layout: struct.Struct, *values: Any, alignment: int) -> None:
        self.align(alignment)
        self.buffer += layout.pack(*values)

    def string(self, text: str) -> None:
        self.align(4)
        self.buffer += cdr_string(text)

    def u32(self, value: int) -> None:
        """A uint32 (also a sequence's length)."""
        self.pack(_U32, value, alignment=4)

    def stamp(self, sec: int, nanosec: int) -> None:
        """builtin_interfaces/Time."""
        self.pack(_STAMP, sec, nanosec, alignment=4)

    def header(self, timestamp_ms: int, frame_id: str) -> None:
        """std_msgs/Header: stamp (sec int32, nanosec uint32) and frame_id."""
        self.stamp(*stamp_fields(timestamp_ms))
        self.string(frame_id)

    def getvalue(self) -> bytes:
        return bytes(self.buffer)


# --- small messages -----------------------------------------------------------------------


def encode_string(text: str) -> bytes:
    """std_msgs/String."""
    return ENCAPSULATION + cdr_string(text)


def encode_clock(timestamp_ms: int) -> bytes:
    """rosgraph_msgs/Clock of a log time (as :func:`convert.clock_message`)."""
    return ENCAPSULATION + _STAMP.pack(*stamp_fields(timestamp_ms))


#: Odometry after child_frame_id: pose (position, orientation), covariance (zero), twist
#: (linear, angular), covariance (zero); struct's ``x`` pad bytes are zero.
_ODOMETRY_BODY = struct.Struct("<3d4d288x6d288x")


def encode_odometry(pose: EgoPose, timestamp_ms: int) -> bytes:
    """nav_msgs/Odometry as :func:`convert.pose_to_odometry` builds it."""
    q = carla_rpy_to_quaternions(np.array([pose.roll, pose.pitch, pose.yaw]))[0].tolist()
    w = CdrWriter()
    w.header(timestamp_ms, WORLD_FRAME)
    w.string(EGO_FRAME)
    twist = (float(pose.speed), 0.0, 0.0, 0.0, 0.0, 0.0)
    w.pack(_ODOMETRY_BODY, float(pose.x), -pose.y, float(pose.z), *q, *twist, alignment=8)
    return w.getvalue()


def float64_sequence(w: CdrWriter, values: Any) -> None:
    """A ``float64[]``: its count, then (8-aligned, only when there are any) the values."""
    array = np.asarray(values, dtype="<f8")
    w.u32(array.size)
    if array.size:
        w.align(8)
        w.buffer += array.tobytes()


def encode_joint_state(
    timestamp_ms: int, names: list[str], positions: list[float], frame_id: str = ""
) -> bytes:
    """sensor_msgs/JointState with ``name`` and ``position`` (velocity, effort empty): the
    labelled numbers of a monitor result (:mod:`ads_rca.live.numeric`)."""
    w = CdrWriter()
    w.stamp(*stamp_fields(timestamp_ms))
    w.buffer += _joint_state_names(frame_id, tuple(names))
    float64_sequence(w, positions)
    float64_sequence(w, ())  # velocity
    float64_sequence(w, ())  # effort
    return w.getvalue()


@lru_cache(maxsize=64)
def _joint_state_names(frame_id: str, names: tuple[str, ...]) -> bytes:
    """The bytes after the stamp up to the positions: the same for every row of a layout
    (the stamp is fixed-size, so their alignment is too)."""
    w = CdrWriter()
    w.stamp(0, 0)
    w.string(frame_id)
    w.u32(len(names))
    for name in names:
        w.string(name)
    return w.getvalue()[HEADER_SIZE + _STAMP.size :]


#: geometry_msgs/Transform: translation (Vector3) and rotation (Quaternion), 7 float64.
_TRANSFORM = struct.Struct("<7d")


def encode_tf_message(timestamp_ms: int, transforms: list[StaticTransform]) -> bytes:
    """tf2_msgs/TFMessage (``/tf_static``). Our own encoder: tf2_msgs has no wheel, so
    rclpy cannot serialise it here (bytes checked against rosbags' serialiser)."""
    w = CdrWriter()
    w.u32(len(transforms))
    for t in transforms:
        w.header(timestamp_ms, t.parent)
        w.string(t.child)
        w.pack(_TRANSFORM, *t.translation, *t.rotation, alignment=8)
    return w.getvalue()


# --- MarkerArray --------------------------------------------------------------------------


def _color(style: MarkerStyle) -> tuple[float, float, float, float]:
    r, g, b = style.color
    return (r, g, b, 1.0)


def encode_marker_array(
    timestamp_ms: int,
    frame_id: str,
    ns: str,
    fixed: np.ndarray,
    points: np.ndarray,
    texts: list[str],
) -> bytes:
    """DELETEALL + one marker per row of ``fixed`` (a MARKER_FIXED array, row 0 the DELETEALL
    marker, ``points`` field = point count), in the layout rclpy gives a MarkerArray.

    ``points`` is the (P, 3) float64 concatenation of every marker's points and ``texts`` each
    marker's ``text``. Every other Marker field (colors, texture, uv_coordinates, mesh ...) is
    empty, as convert.py sends. All markers share header and ns, so that prefix is built
    once. Why this is fast: a marker's layout only varies in the 4 bytes of alignment before
    ``pose``, and those depend only on the previous marker's text length (everything else
    between two texts is a multiple of 8 long), so numpy lays out every fixed part at once
    and the Python loop only joins three slices per marker.
    """
    head = _STAMP.pack(*stamp_fields(timestamp_ms)) + cdr_string(frame_id)
    head += _pad(len(head), 4) + cdr_string(ns)
    head += _pad(len(head), 4)
    n = len(texts)
    encoded = [t.encode() for t in texts]
    sizes = np.fromiter(map(len, encoded), dtype=np.int64, count=n) + 1
    # Marker i starts (mod 8) where marker i-1's padded text ends; marker 0 after the count.
    start = np.empty(n, dtype=np.int64)
    start[0] = 4
    start[1:] = (sizes[:-1] + 3) & 4
    pose_pad = (-(start + len(head) + _POSE_AT)) % 8
    width = len(head) + _FIXED + 4
    rows = np.zeros((n, width), dtype=np.uint8)
    rows[:, : len(head)] = np.frombuffer(head, dtype=np.uint8)
    fixed_u8 = fixed.view(np.uint8).reshape(n, _FIXED)
    rows[:, len(head) : len(head) + _POSE_AT] = fixed_u8[:, :_POSE_AT]
    body = len(head) + _POSE_AT
    padded = pose_pad != 0
    rows[~padded, body : body + _FIXED - _POSE_AT] = fixed_u8[~padded, _POSE_AT:]
    rows[padded, body + 4 :] = fixed_u8[padded, _POSE_AT:]
    row_blob = rows.tobytes()
    row_ends = (np.arange(n) * width + width - 4 + pose_pad).tolist()
    point_blob = np.ascontiguousarray(points, dtype="<f8").tobytes()
    point_ends = (np.cumsum(fixed["points"], dtype=np.int64) * 24).tolist()
    tails = [
        MIDDLE_WHEN_EMPTY + _U32.pack(size) + data + _TAILS[size & 3]
        for data, size in zip(encoded, sizes.tolist(), strict=True)
    ]
    tails[-1] = tails[-1][:-_MARKER_GAP]  # no padding after the last marker
    parts: list[bytes] = [ENCAPSULATION, _U32.pack(n)]
    row_at = point_at = 0
    for row_end, point_end, tail in zip(row_ends, point_ends, tails, strict=True):
        parts += (row_blob[row_at:row_end], point_blob[point_at:point_end], tail)
        row_at += width
        point_at = point_end
    return b"".join(parts)


def marker_rows(n: int, style: MarkerStyle, marker_type: int) -> np.ndarray:
    """MARKER_FIXED rows: 0 = DELETEALL (default pose, w 1), 1..n = ADD of ``marker_type`` in
    the style's colour with identity orientation (callers overwrite what differs)."""
    fixed = np.zeros(n + 1, MARKER_FIXED)
    fixed["ita"][0] = (0, 0, DELETEALL)
    fixed["pose"][:, 6] = 1.0
    fixed["ita"][1:, 1] = marker_type
    fixed["ita"][1:, 2] = ADD
    fixed["color"][1:] = _color(style)
    return fixed


@lru_cache(maxsize=65536)
def cached_marker_id(actor_id: str) -> int:
    """:func:`convert.marker_id`, memoised: actor ids repeat on every frame."""
    return marker_id(actor_id)


def encode_actors(actors: Actors, timestamp_ms: int, style: MarkerStyle) -> bytes:
    """Actors as :func:`convert.actors_to_markers` (CUBEs in ``map``, full size)."""
    n = len(actors.ids)
    fixed = marker_rows(n, style, CUBE)
    fixed["ita"][1:, 0] = [cached_marker_id(a) for a in actors.ids]
    body = fixed["pose"][1:]
    body[:, 0:3] = np.reshape(actors.location * np.array([1.0, -1.0, 1.0]), (-1, 3))
    body[:, 3:7] = carla_rpy_to_quaternions(actors.rotation)
    fixed["scale"][1:] = np.reshape(2.0 * actors.extent, (-1, 3))
    return encode_marker_array(
        timestamp_ms,
        WORLD_FRAME,
        style.ns,
        fixed,
        np.empty((0, 3)),
        ["", *actors.ids],
    )


def encode_objects(objects: Objects3D, timestamp_ms: int, style: MarkerStyle) -> bytes:
    """3-D objects as :func:`convert.objects_to_markers` (CUBEs in ``map``, full size)."""
    n = len(objects.ids)
    fixed = marker_rows(n, style, CUBE)
    fixed["ita"][1:, 0] = np.arange(n)
    body = fixed["pose"][1:]
    body[:, 0:3] = np.reshape(objects.location, (-1, 3)) * FLIP_Y
    body[:, 3:7] = carla_rpy_to_quaternions(objects_rpy(objects))
    fixed["scale"][1:] = 2.0 * np.reshape(objects.extent, (-1, 3))
    return encode_marker_array(
        timestamp_ms,
        WORLD_FRAME,
        style.ns,
        fixed,
        np.empty((0, 3)),
        ["", *object_texts(objects)],
    )


def encode_control(command: ControlCommand, timestamp_ms: int) -> bytes:
    """A control command as :func:`convert.control_to_joint_state`."""
    return encode_joint_state(timestamp_ms, list(CONTROL_NAMES), control_positions(command))


#: Corner columns (x1, y1, x2, y2) of the five points of a box's closed LINE_STRIP.
_BOX_X = np.array([0, 2, 2, 0, 0])
_BOX_Y = np.array([1, 1, 3, 3, 1])


def encode_boxes(boxes: Boxes, timestamp_ms: int, style: MarkerStyle) -> bytes:
    """Boxes as :func:`convert.boxes_to_markers` (pixels in ``camera_image``)."""
    n = len(boxes.ids)
    fixed = marker_rows(n, style, LINE_STRIP)
    fixed["ita"][1:, 0] = np.arange(n)
    fixed["scale"][1:, 0] = 2.0
    fixed["points"][1:] = 5
    corners = np.asarray(boxes.corners, dtype=np.float64).reshape(-1, 4)
    points = np.zeros((n, 5, 3))
    points[:, :, 0] = corners[:, _BOX_X]
    points[:, :, 1] = corners[:, _BOX_Y]
    texts = [
        dumps_json({"id": box_id, **extras})
        for box_id, extras in zip(boxes.ids, boxes.extras, strict=True)
    ]
    return encode_marker_array(
        timestamp_ms,
        IMAGE_FRAME,
        style.ns,
        fixed,
        points.reshape(-1, 3),
        ["", *texts],
    )


def encode_predictions(predictions: Predictions, timestamp_ms: int, style: MarkerStyle) -> bytes:
    """Predictions as :func:`convert.predictions_to_markers` (offsets in ``base_link``)."""
    n = len(predictions)
    fixed = marker_rows(n, style, LINE_STRIP)
    fixed["ita"][1:, 0] = np.arange(n)
    fixed["scale"][1:, 0] = 0.2
    offsets = [
        t.offsets if t.offsets.ndim == 2 else np.reshape(t.offsets, (-1, 3))
        for t in predictions.values()
    ]
    fixed["points"][1:] = [len(o) for o in offsets]
    points = np.concatenate(offsets) if offsets else np.empty((0, 3))
    texts = [
        dumps_json({"id": obstacle_id, "keys": list(track.keys)})
        for obstacle_id, track in predictions.items()
    ]
    return encode_marker_array(
        timestamp_ms,
        EGO_FRAME,
        style.ns,
        fixed,
        points * np.array([1.0, -1.0, 1.0]),
        ["", *texts],
    )


def encode_lanes(graph: LaneGraph, timestamp_ms: int, style: MarkerStyle) -> bytes:
    """A lane graph as :func:`convert.lanes_to_markers` (lanes in ``base_link``, element
    labels stacked above the ego)."""
    n, k = graph.lane_count, graph.element_count
    fixed = marker_rows(n + k, style, LINE_STRIP)
    fixed["ita"][1:, 0] = np.arange(n + k)
    fixed["ita"][n + 1 :, 1] = TEXT_VIEW_FACING
    fixed["scale"][1 : n + 1, 0] = LANE_WIDTH
    fixed["scale"][n + 1 :, 2] = LABEL_HEIGHT
    fixed["pose"][n + 1 :, 2] = label_heights(k)
    fixed["points"][1 : n + 1] = [len(lane) for lane in graph.lanes]
    points = np.concatenate(graph.lanes) * FLIP_Y if n else np.empty((0, 3))
    return encode_marker_array(
        timestamp_ms, EGO_FRAME, style.ns, fixed, points, ["", *lane_marker_texts(graph)]
    )


# --- trajectory ---------------------------------------------------------------------------

#: One MultiDOFJointTrajectoryPoint starting 4 past an 8-boundary: transforms [1 Transform],
#: velocities [1 Twist] (4 bytes of alignment before it), accelerations [], time_from_start.
#: Starting on an 8-boundary, 4 more bytes of alignment follow the transforms count.
TRAJECTORY_POINT = np.dtype(
    [
        ("transforms", "<u4"),
        ("transform", "<f8", (7,)),
        ("velocities", "<u4"),
        ("pad", "V4"),
        ("twist", "<f8", (6,)),
        ("accelerations", "<u4"),
        ("sec", "<i4"),
        ("nanosec", "<u4"),
    ]
)


@lru_cache(maxsize=4096)
def _carried_rows(keys: tuple[str, ...]) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """Rows a trajectory can carry and their key values (memoised: plans repeat keys)."""
    rows = carried_plan_rows(Plan(keys=keys, xy=np.empty((0, 2)), speed=np.empty(0)))
    return tuple(rows), tuple(int(keys[r]) for r in rows)


def encode_trajectory(plan: Plan, timestamp_ms: int, timesteps_per_frame: int) -> bytes:
    """A plan as :func:`convert.plan_to_trajectory`."""
    rows, steps = _carried_rows(tuple(plan.keys))
    step = step_ms(timesteps_per_frame)
    w = CdrWriter()
    w.header(timestamp_ms, WORLD_FRAME)
    w.pack(_U32, 1, alignment=4)
    w.string("ego")
    w.pack(_U32, len(rows), alignment=4)
    if not rows:
        return w.getvalue()
    index = list(rows)
    xy = np.asarray(plan.xy, dtype=np.float64).reshape(-1, 2)[index]
    points = np.zeros(len(rows), TRAJECTORY_POINT)
    points["transforms"] = 1
    points["transform"][:, 0] = xy[:, 0]
    points["transform"][:, 1] = -xy[:, 1]
    points["transform"][:, 6] = 1.0
    points["velocities"] = 1
    points["twist"][:, 0] = np.asarray(plan.speed, dtype=np.float64)[index]
    durations = [divmod(s * step, 1000) for s in steps]
    points["sec"] = [d[0] for d in durations]
    points["nanosec"] = [d[1] * _NS_PER_MS for d in durations]
    blob = points.tobytes()
    w.align(4)
    if w.position & 7 == 0:  # the first point's Transform needs 4 bytes of alignment
        w.buffer += blob[:4] + _ZEROS[:4]
        blob = blob[4:]
    w.buffer += blob
    return w.getvalue()
