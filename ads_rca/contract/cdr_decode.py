"""CDR bytes of the contract's messages → model records, without rclpy message objects.

Why: deserialising into rclpy objects and walking them (:func:`convert.message_to_record`)
costs as much as building them; a subscriber that only wants the model reads the few fields
it needs straight from the bytes (struct for headers, numpy for point runs) and skips the
rest. The semantics mirror convert.py exactly: the same CARLA ← ROS conversions through the
same numpy functions, DELETEALL markers ignored, ids and keys from the JSON ``text``.

Any publisher's bytes are accepted, not only the fast encoder's: every Marker field is
walked (colors, texture, uv_coordinates, mesh_file ...), whatever it holds. Only the
little-endian representation (encapsulation ``00 01``) is read; that is what ROS 2 sends on
every supported platform. Pure: no rclpy import.

The bytes are untrusted: anyone on the domain can publish on the contract's topics. Every
decoder either returns a record or raises :class:`~ads_rca.contract.errors.CdrError` (a
MalformedMessage), never another exception, and never allocates for a count it has not
checked against the bytes that remain (``count × smallest element ≤ remaining``): a sequence
count of 2**32 - 1 is refused, not allocated. A MarkerArray without markers is not
malformed: :func:`marker_array_stamp_ms` raises :class:`~ads_rca.contract.errors.NoStamp` for
it. Which topic uses which decoder is the topic table's (:mod:`ads_rca.contract.topics`).
"""

from __future__ import annotations

import functools
import math
import struct
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ParamSpec, TypeVar

import numpy as np

from ads_rca.contract.cdr import HEADER_SIZE, MESH_WHEN_EMPTY, MIDDLE_WHEN_EMPTY
from ads_rca.contract.convert import (
    check_box_points,
    control_from_fields,
    lane_graph_of,
    marker_document,
    objects_from_fields,
    quaternions_to_carla_rpy,
    step_ms,
    track_keys,
)
from ads_rca.contract.errors import CdrError, MalformedMessage, NoStamp
from ads_rca.model import (
    Actors,
    Boxes,
    ControlCommand,
    EgoPose,
    Objects3D,
    Plan,
    Predictions,
    Track,
)
from ads_rca.sources.openlane.lanes import LaneGraph

_P = ParamSpec("_P")
_R = TypeVar("_R")

_NS_PER_MS = 1_000_000
_U32 = struct.Struct("<I")
_STAMP = struct.Struct("<iI")
_F64 = struct.Struct("<d")
_F64_3 = struct.Struct("<3d")
_F64_7 = struct.Struct("<7d")
_DELETEALL = 3
#: Marker pose (7 float64), scale (3 float64), color (4 float32), lifetime, frame_locked.
_FIXED_AFTER_POSE = 56 + 24 + 16 + 8 + 1
_NOT_CDR = "not a little-endian CDR message (encapsulation 00 01)"
#: Fewest bytes a Marker can take (every string and sequence empty, no alignment counted):
#: stamp, frame_id, ns, id/type/action, pose..frame_locked, points, colors,
#: texture_resource, texture (stamp, frame_id, format, data), uv, text, mesh_resource,
#: mesh_file (filename, data), mesh_use_embedded_materials.
MIN_MARKER_BYTES = 8 + 4 + 4 + 12 + _FIXED_AFTER_POSE + 4 + 4 + 4 + 16 + 4 + 4 + 4 + 4 + 4 + 1
#: Fewest bytes of a MultiDOFJointTrajectoryPoint: three sequence counts and a Duration.
MIN_TRAJECTORY_POINT_BYTES = 4 + 4 + 4 + 8


class _Unnamed(CdrError):
    """A CdrError whose text is only the reason: the decoder that meets it names itself
    (``malformed odometry: ...``), as for the low-level errors below."""


#: What reading past the end, a wrong UTF-8 string, a marker text that is no record's or a
#: value no record can hold raises inside the decoders; :func:`_typed` turns each into a
#: CdrError naming the decoder.
_LOW_LEVEL = (
    MalformedMessage,
    struct.error,
    IndexError,
    KeyError,
    TypeError,
    AttributeError,
    OverflowError,
    MemoryError,
    ValueError,
)


def _typed(decoder: Callable[_P, _R]) -> Callable[_P, _R]:
    """``decoder`` raising :class:`CdrError` (or :class:`NoStamp`) for every bad payload."""
    name = decoder.__name__
    what = name.removeprefix("decode_") if name.startswith("decode_") else "message"

    @functools.wraps(decoder)
    def checked(*args: _P.args, **kwargs: _P.kwargs) -> _R:
        try:
            return decoder(*args, **kwargs)
        except (CdrError, NoStamp) as error:
            if not isinstance(error, _Unnamed):
                raise
            detail = str(error)
        except _LOW_LEVEL as error:
            detail = str(error) or type(error).__name__
        raise CdrError(f"malformed {what}: {detail}") from None

    return checked


def check_count(count: int, element_bytes: int, remaining: int, what: str) -> None:
    """Refuse a sequence count the remaining bytes cannot hold (before allocating for it)."""
    if count * element_bytes > remaining:
        raise CdrError(
            f"{what}: {count} elements need at least {count * element_bytes} bytes, "
            f"{remaining} remain"
        )


class CdrReader:
    """Reads CDR fields from a payload, aligning each relative to the payload start."""

    __slots__ = ("data", "position")

    def __init__(self, data: bytes) -> None:
        if len(data) < HEADER_SIZE or data[1] != 1:
            raise _Unnamed(_NOT_CDR)
        self.data = memoryview(data)[HEADER_SIZE:]
        self.position = 0

    def align(self, alignment: int) -> None:
        self.position += -self.position % alignment

    def unpack(self, layout: struct.Struct, alignment: int) -> tuple[Any, ...]:
        self.align(alignment)
        values = layout.unpack_from(self.data, self.position)
        self.position += layout.size
        return values

    def u32(self) -> int:
        self.align(4)
        (value,) = _U32.unpack_from(self.data, self.position)
        self.position += 4
        return int(value)

    def remaining(self) -> int:
        return len(self.data) - self.position

    def string(self) -> str:
        size = self.u32()
        start = self.position
        self.position += size
        if self.position > len(self.data):
            raise CdrError(f"a string claims {size} bytes, {len(self.data) - start} remain")
        return bytes(self.data[start : start + max(size - 1, 0)]).decode()

    def check_end(self, what: str) -> None:
        """Every field read lay inside the payload (skips only move the position)."""
        if self.position > len(self.data):
            raise CdrError(
                f"{what} truncated: {self.position} bytes walked, {len(self.data)} present"
            )

    def skip_string(self) -> None:
        size = self.u32()  # not ``position += u32()``: that would read position first
        self.position += size

    def skip_sequence(self, element_size: int, alignment: int) -> None:
        count = self.u32()
        if count:
            self.align(alignment)
            self.position += count * element_size

    def stamp_ms(self) -> int:
        """A builtin_interfaces/Time as log milliseconds (:func:`convert.from_time`)."""
        sec, nanosec = self.unpack(_STAMP, 4)
        return int(sec) * 1000 + int(nanosec) // _NS_PER_MS

    def skip_header(self) -> None:
        """std_msgs/Header: stamp (4-aligned) and frame_id."""
        self.align(4)
        self.position += 8
        self.skip_string()


# --- small messages -----------------------------------------------------------------------


@_typed
def decode_string(data: bytes) -> str:
    """std_msgs/String → its text."""
    return CdrReader(data).string()


@_typed
def decode_clock(data: bytes) -> int:
    """rosgraph_msgs/Clock → log milliseconds."""
    return CdrReader(data).stamp_ms()


@_typed
def header_stamp_ms(data: bytes) -> int:
    """Log time of a message that starts with a std_msgs/Header (Odometry, trajectory)."""
    return CdrReader(data).stamp_ms()


@_typed
def marker_array_stamp_ms(data: bytes) -> int:
    """Log time of a MarkerArray: its first marker's header stamp
    (:func:`convert.message_stamp_ms`). Raises NoStamp for a MarkerArray without markers."""
    reader = CdrReader(data)
    if reader.u32() == 0:
        raise NoStamp("empty MarkerArray carries no stamp")
    return reader.stamp_ms()


@_typed
def decode_odometry(data: bytes) -> EgoPose:
    """nav_msgs/Odometry → EgoPose (:func:`convert.odometry_to_pose`)."""
    r = CdrReader(data)
    r.skip_header()
    r.skip_string()  # child_frame_id
    x, y, z, qx, qy, qz, qw = r.unpack(_F64_7, 8)
    r.position += 36 * 8  # covariance
    (speed,) = r.unpack(_F64, 8)
    roll, pitch, yaw = quaternions_to_carla_rpy(np.array([qx, qy, qz, qw]))[0].tolist()
    return EgoPose(x=x, y=-y, z=z, roll=roll, pitch=pitch, yaw=yaw, speed=speed)


# --- MarkerArray --------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class MarkerFields:
    """What the decoders use of the ADD markers of a MarkerArray (DELETEALL dropped)."""

    ids: list[int]
    poses: np.ndarray  # (N, 7) position x, y, z, orientation x, y, z, w
    scales: np.ndarray  # (N, 3)
    points: list[np.ndarray]  # (K, 3) each
    texts: list[str]
    #: Each kept marker's type, action and header frame, when asked (``kinds``), else empty.
    types: list[int]
    actions: list[int]
    frames: list[str]


@_typed
def read_markers(data: bytes, kinds: bool = False) -> MarkerFields:
    """Walk every field of every Marker; keep id, pose, scale, points and text of the markers
    whose action is not DELETEALL (as convert.py's ``_added``), and with ``kinds`` their type,
    action and header frame too (a layout of markers other than ours filters on them).

    The hot path of every subscriber (~250 markers a frame at 50 actors), so the walk is one
    flat loop on local offsets (no reader method calls), and pose and scale are gathered for
    all markers at once with numpy at the offsets found.
    """
    if len(data) < HEADER_SIZE or data[1] != 1:
        raise _Unnamed(_NOT_CDR)
    view = memoryview(data)[HEADER_SIZE:]
    u32 = _U32.unpack_from
    ita = _ITA.unpack_from
    keep: list[int] = []  # offset of the pose of each kept marker
    ids: list[int] = []
    spans: list[tuple[int, int]] = []
    texts: list[str] = []
    types: list[int] = []
    actions: list[int] = []
    frames: list[str] = []
    (n,) = u32(view, 0)
    pos = 4
    check_count(n, MIN_MARKER_BYTES, len(view) - pos, "MarkerArray")
    for _ in range(n):
        pos += -pos % 4 + 8  # header.stamp
        (frame_size,) = u32(view, pos)  # header.frame_id (4-aligned after the stamp)
        frame_at = pos + 4
        pos = frame_at + frame_size
        pos += -pos % 4
        pos += 4 + u32(view, pos)[0]  # ns
        pos += -pos % 4
        marker_id, _type, action = ita(view, pos)
        pos += 12
        pos += -pos % 8
        at = pos
        pos += _FIXED_AFTER_POSE  # pose, scale, color, lifetime, frame_locked
        pos += -pos % 4
        (count,) = u32(view, pos)
        pos += 4
        if count:
            pos += -pos % 8
        start = pos
        pos += 24 * count
        pos += -pos % 4
        if view[pos : pos + _EMPTY_MIDDLE_SIZE] == _EMPTY_MIDDLE:
            pos += _EMPTY_MIDDLE_SIZE  # no colors, texture or uv (what our player sends)
        else:
            pos += 4 + 16 * u32(view, pos)[0]  # colors
            pos += 4 + u32(view, pos)[0]  # texture_resource
            pos += -pos % 4 + 8  # texture.header.stamp
            pos += 4 + u32(view, pos)[0]  # texture.header.frame_id
            pos += -pos % 4
            pos += 4 + u32(view, pos)[0]  # texture.format
            pos += -pos % 4
            pos += 4 + u32(view, pos)[0]  # texture.data
            pos += -pos % 4
            pos += 4 + 8 * u32(view, pos)[0]  # uv_coordinates
        (size,) = u32(view, pos)  # text (4-aligned after uv)
        text_at = pos + 4
        pos = text_at + size
        pos += -pos % 4
        if view[pos : pos + _EMPTY_MESH_SIZE] == _EMPTY_MESH:
            pos += _EMPTY_MESH_SIZE
        else:
            pos += 4 + u32(view, pos)[0]  # mesh_resource
            pos += -pos % 4
            pos += 4 + u32(view, pos)[0]  # mesh_file.filename
            pos += -pos % 4
            pos += 4 + u32(view, pos)[0]  # mesh_file.data
        pos += 1  # mesh_use_embedded_materials
        if action == _DELETEALL:
            continue
        keep.append(at)
        ids.append(int(marker_id))
        spans.append((start, count))
        texts.append(bytes(view[text_at : text_at + max(size - 1, 0)]).decode())
        if kinds:
            types.append(_type)
            actions.append(action)
            frames.append(bytes(view[frame_at : frame_at + max(frame_size - 1, 0)]).decode())
    if pos > len(view):
        raise CdrError(f"MarkerArray truncated: {pos} bytes walked, {len(view)} present")
    raw = np.frombuffer(view, dtype=np.uint8)
    fixed = raw[np.asarray(keep, dtype=np.intp)[:, None] + _POSE_SCALE_BYTES]
    values = fixed.view("<f8").reshape(len(keep), 10).astype(np.float64)
    return MarkerFields(
        ids=ids,
        poses=values[:, :7],
        scales=values[:, 7:],
        points=[
            np.frombuffer(view, "<f8", 3 * c, at).reshape(c, 3) if c else np.empty((0, 3))
            for at, c in spans
        ],
        texts=texts,
        types=types,
        actions=actions,
        frames=frames,
    )


#: The bytes between ``points`` and ``text`` when colors, texture and uv are all empty (from
#: a 4-aligned offset), and between ``text`` and ``mesh_use_embedded_materials`` when the
#: mesh fields are: a marker that matches skips ~20 field reads (same result either way).
_EMPTY_MIDDLE = MIDDLE_WHEN_EMPTY
_EMPTY_MIDDLE_SIZE = len(_EMPTY_MIDDLE)
_EMPTY_MESH = MESH_WHEN_EMPTY
_EMPTY_MESH_SIZE = len(_EMPTY_MESH)
#: Byte offsets of pose (7 float64) and scale (3 float64) from a marker's pose offset.
_POSE_SCALE_BYTES = np.arange(80, dtype=np.intp)
_ITA = struct.Struct("<3i")


@_typed
def decode_actors(data: bytes) -> Actors:
    """``actors`` MarkerArray → Actors (:func:`convert.markers_to_actors`)."""
    m = read_markers(data)
    location = m.poses[:, 0:3].copy()
    location[:, 1] = -location[:, 1]
    return Actors(
        ids=tuple(m.texts),
        location=location,
        rotation=quaternions_to_carla_rpy(m.poses[:, 3:7].copy()),
        extent=m.scales / 2.0,
    )


@_typed
def decode_objects(data: bytes) -> Objects3D:
    """``perception/objects_3d`` or ``tracks_3d`` MarkerArray → Objects3D
    (:func:`convert.markers_to_objects`)."""
    m = read_markers(data)
    return objects_from_fields(m.ids, m.poses, m.scales, m.texts)


@_typed
def decode_boxes(data: bytes) -> Boxes:
    """``perception/*`` MarkerArray → Boxes (:func:`convert.markers_to_boxes`)."""
    m = read_markers(data)
    corners = np.empty((len(m.texts), 4))
    ids: list[str] = []
    extras: list[dict[str, Any]] = []
    for row, (marker_id, pts, text) in enumerate(zip(m.ids, m.points, m.texts, strict=True)):
        check_box_points(len(pts))
        corners[row] = (pts[0, 0], pts[0, 1], pts[2, 0], pts[2, 1])
        document = marker_document(text)
        ids.append(str(document.pop("id", marker_id)))
        extras.append(document)
    return Boxes(ids=tuple(ids), corners=corners, extras=tuple(extras))


@_typed
def decode_predictions(data: bytes) -> Predictions:
    """``prediction/*`` MarkerArray → Predictions (:func:`convert.markers_to_predictions`)."""
    m = read_markers(data)
    out: Predictions = {}
    for marker_id, pts, text in zip(m.ids, m.points, m.texts, strict=True):
        document = marker_document(text)
        keys = track_keys(document, len(pts))
        offsets = pts.copy()
        offsets[:, 1] = -offsets[:, 1]
        out.setdefault(str(document.get("id", marker_id)), Track(keys=keys, offsets=offsets))
    return out


@_typed
def decode_lanes(data: bytes) -> LaneGraph:
    """``map/lanes*`` MarkerArray → LaneGraph (:func:`convert.markers_to_lanes`)."""
    m = read_markers(data)
    return lane_graph_of(list(zip(m.texts, m.points, strict=True)))


# --- trajectory ---------------------------------------------------------------------------


@_typed
def decode_trajectory(data: bytes, timesteps_per_frame: int) -> Plan:
    """MultiDOFJointTrajectory → Plan (:func:`convert.trajectory_to_plan`)."""
    step = step_ms(timesteps_per_frame)
    r = CdrReader(data)
    r.skip_header()
    names = r.u32()
    check_count(names, 4, r.remaining(), "joint_names")
    for _ in range(names):
        r.skip_string()
    n = r.u32()
    check_count(n, MIN_TRAJECTORY_POINT_BYTES, r.remaining(), "trajectory points")
    xy = np.empty((n, 2))
    speed = np.empty(n)
    keys: list[str] = []
    for row in range(n):
        transforms = r.u32()
        if not transforms:
            raise CdrError(f"trajectory point {row} has no transform")
        x, y, _z = r.unpack(_F64_3, 8)
        r.position += (transforms * 7 - 3) * 8
        xy[row] = (x, -y)
        velocities = r.u32()
        if velocities:
            (speed[row],) = r.unpack(_F64, 8)
            r.position += (velocities * 6 - 1) * 8
        else:
            speed[row] = math.nan
        r.skip_sequence(48, 8)  # accelerations
        keys.append(str(r.stamp_ms() // step))
    r.check_end("MultiDOFJointTrajectory")
    return Plan(keys=tuple(keys), xy=xy, speed=speed)


@_typed
def decode_control(data: bytes) -> ControlCommand:
    """``control/command`` sensor_msgs/JointState → ControlCommand
    (:func:`convert.joint_state_to_control`): names and positions; velocity, effort unread."""
    r = CdrReader(data)
    r.skip_header()
    count = r.u32()
    check_count(count, 4, r.remaining(), "joint state names")
    names = [r.string() for _ in range(count)]
    positions = r.u32()
    check_count(positions, 8, r.remaining(), "joint state positions")
    values: list[float] = []
    if positions:
        r.align(8)
        values = np.frombuffer(r.data, "<f8", positions, r.position).tolist()
        r.position += 8 * positions
    r.check_end("JointState")
    return control_from_fields(names, values)
