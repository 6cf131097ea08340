"""Model records from inputs as driving stacks publish them (common_interfaces only).

A stack beside which the live graph runs does not publish our contract's messages: its ego
may be a bare ``geometry_msgs/PoseStamped`` (no speed), its plan a ``nav_msgs/Path`` (no
speeds), its ground truth the CUBE markers of the CARLA ROS bridge's ``/carla/markers``.
These pure functions turn such messages into the same model records convert.py gives for
ours, with the same CARLA ↔ REP-103 geometry (convert.py's, reused). Speeds a message does
not carry are derived from positions over stamps (distance / time of each interval) and
flagged so. Bad input (NaN, no or unsorted stamps, an empty path, a foreign frame) raises
:class:`~ads_rca.contract.errors.MalformedMessage`, never half-used. Odometry and
MultiDOFJointTrajectory are convert.py's ``odometry_to_pose`` / ``trajectory_to_plan``.
The builders (records → stack messages) are what a test stack publishes.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from ads_rca.contract.cdr_decode import read_markers
from ads_rca.contract.convert import (
    WORLD_FRAME,
    carla_rpy_to_quaternions,
    carried_plan_rows,
    from_time,
    header,
    odometry_to_pose,
    quaternions_to_carla_rpy,
    step_ms,
)
from ads_rca.contract.errors import MalformedMessage
from ads_rca.model import Actors, EgoPose, FloatArray, Plan

if TYPE_CHECKING:
    from builtin_interfaces.msg import Time
    from geometry_msgs.msg import Point, Pose, PoseStamped, Quaternion
    from nav_msgs.msg import Odometry, Path
    from visualization_msgs.msg import MarkerArray

IntArray = npt.NDArray[np.int64]
_NS_PER_S = 1_000_000_000


@dataclass(frozen=True, slots=True)
class StackPose:
    """An ego pose at its header stamp; ``speed_derived``: the speed was computed from
    successive poses, not measured (NaN for the first pose of a series)."""

    stamp_ms: int
    pose: EgoPose
    speed_derived: bool


# --- shared pieces --------------------------------------------------------------------------


def _stamp_ns(stamp: Time) -> int:
    return int(stamp.sec) * _NS_PER_S + int(stamp.nanosec)


def _check_frame(frame_id: str, world_frame: str, what: str) -> None:
    if frame_id != world_frame:
        raise MalformedMessage(f"{what} is in frame {frame_id!r}, expected {world_frame!r}")


def _xyz(v: Point | Quaternion) -> tuple[float, float, float]:
    return (v.x, v.y, v.z)


def _pose_arrays(poses: Sequence[Pose], what: str) -> tuple[FloatArray, FloatArray]:
    """(N, 3) CARLA positions and (N, 3) CARLA roll, pitch, yaw (degrees) of REP-103 poses;
    MalformedMessage for a non-finite value or a zero quaternion."""
    return _pose_rows(_pose_table(poses), what)


def _pose_table(poses: Sequence[Pose]) -> FloatArray:
    """Poses as (N, 7) rows: position x, y, z, orientation x, y, z, w."""
    return np.array(
        [(*_xyz(p.position), *_xyz(p.orientation), p.orientation.w) for p in poses],
        dtype=np.float64,
    ).reshape(-1, 7)


def _pose_rows(raw: FloatArray, what: str) -> tuple[FloatArray, FloatArray]:
    """:func:`_pose_arrays` of poses as :func:`_pose_table`'s rows."""
    bad = ~np.isfinite(raw).all(axis=1)
    if bad.any():
        raise MalformedMessage(f"{what}: pose {int(np.argmax(bad))} is not finite")
    quats = raw[:, 3:]
    norms = np.linalg.norm(quats, axis=1)
    if (norms < 1e-9).any():
        raise MalformedMessage(f"{what}: pose {int(np.argmax(norms < 1e-9))} has a zero quaternion")
    location = raw[:, :3] * np.array([1.0, -1.0, 1.0])
    return location, quaternions_to_carla_rpy(quats / norms[:, None])


def _increasing(stamps_ns: IntArray, what: str) -> None:
    steps = np.diff(stamps_ns)
    if (steps <= 0).any():
        row = int(np.argmax(steps <= 0)) + 1
        raise MalformedMessage(f"{what}: stamp {row} is not after the one before it")


def interval_speeds(location: FloatArray, stamps_ns: IntArray) -> FloatArray:
    """(N-1,) speed over each interval between successive positions (m/s): distance / time.

    Stamps must be strictly increasing (callers check). Over an interval where the speed
    changes this is its mean, not either end's speed."""
    distance = np.linalg.norm(np.diff(location, axis=0), axis=1)
    seconds = np.diff(stamps_ns).astype(np.float64) / _NS_PER_S
    speeds: FloatArray = distance / seconds
    return speeds


def point_speeds(location: FloatArray, stamps_ns: IntArray) -> FloatArray:
    """(N,) speed at each of a plan's points (m/s): the derivative of the distance travelled
    along the points over their stamps, second order (central differences inside, one-sided
    at the ends; numpy.gradient with non-uniform stamps).

    Why not each interval's mean (distance / time to the point before): under constant
    acceleration that is the speed half an interval earlier, 0.2 m/s too high at 8 m/s²
    and 20 Hz, and a braking plan looked safer than the one the planner made. Second-order
    differences are exact where the distance is quadratic in time (constant acceleration),
    so a Path of a logged plan gives back the logged speeds. Two points: their interval's
    speed for both; one: NaN. Stamps must be strictly increasing (callers check)."""
    if len(stamps_ns) < 2:
        return np.full(len(stamps_ns), math.nan)
    travelled = np.concatenate(
        ([0.0], np.cumsum(np.linalg.norm(np.diff(location, axis=0), axis=1)))
    )
    seconds = (stamps_ns - stamps_ns[0]).astype(np.float64) / _NS_PER_S
    speeds: FloatArray = np.gradient(travelled, seconds, edge_order=2 if len(stamps_ns) > 2 else 1)
    return speeds


# --- ego --------------------------------------------------------------------------------------


def odometry_stack_pose(msg: Odometry) -> StackPose:
    """nav_msgs/Odometry → StackPose (measured speed: convert.py's reading)."""
    return StackPose(from_time(msg.header.stamp), odometry_to_pose(msg), speed_derived=False)


def pose_stamped_series(
    msgs: Sequence[PoseStamped], world_frame: str = WORLD_FRAME
) -> list[StackPose]:
    """PoseStamped messages in stamp order → StackPose each, speed derived over the interval
    ending at that pose (NaN for the first). MalformedMessage for an empty series, a
    foreign frame, a non-finite pose or stamps that do not increase."""
    if not msgs:
        raise MalformedMessage("no PoseStamped to read")
    for msg in msgs:
        _check_frame(msg.header.frame_id, world_frame, "PoseStamped")
    stamps = np.array([_stamp_ns(m.header.stamp) for m in msgs], dtype=np.int64)
    _increasing(stamps, "PoseStamped series")
    location, rpy = _pose_arrays([m.pose for m in msgs], "PoseStamped")
    speed = np.concatenate(([math.nan], interval_speeds(location, stamps)))
    rows = np.column_stack((location, rpy, speed)).tolist()
    return [
        StackPose(from_time(m.header.stamp), EgoPose(*row), speed_derived=True)
        for m, row in zip(msgs, rows, strict=True)
    ]


def pose_stamped_pose(
    msg: PoseStamped, previous: PoseStamped | None, world_frame: str = WORLD_FRAME
) -> StackPose:
    """One PoseStamped as it arrives, speed from the last one accepted before it (``None``:
    NaN). The streaming form of :func:`pose_stamped_series` (same checks, same numbers); a
    gap (a dropped pose) gives the mean speed over the longer interval."""
    series = [msg] if previous is None else [previous, msg]
    return pose_stamped_series(series, world_frame)[-1]


def pose_stamped(pose: EgoPose, timestamp_ms: int, frame_id: str = WORLD_FRAME) -> PoseStamped:
    """EgoPose → geometry_msgs/PoseStamped (REP-103; the speed is not carried)."""
    from geometry_msgs.msg import PoseStamped

    return PoseStamped(
        header=header(timestamp_ms, frame_id),
        pose=_ros_pose((pose.x, pose.y, pose.z), (pose.roll, pose.pitch, pose.yaw)),
    )


def _ros_pose(location: Sequence[float], rpy_deg: Sequence[float]) -> Pose:
    from geometry_msgs.msg import Point, Pose, Quaternion

    x, y, z, w = carla_rpy_to_quaternions(np.array(rpy_deg))[0].tolist()
    lx, ly, lz = location
    return Pose(position=Point(x=lx, y=-ly, z=lz), orientation=Quaternion(x=x, y=y, z=z, w=w))


# --- plan -------------------------------------------------------------------------------------


def path_to_plan(msg: Path, timesteps_per_frame: int, world_frame: str = WORLD_FRAME) -> Plan:
    """nav_msgs/Path → Plan.

    Key of a point: its stamp after the header stamp in plan steps (``timesteps_per_frame``
    ms, rounded to the nearest step); xy from the REP-103 position; speed at the point from
    :func:`point_speeds` (NaN for a one-point path). MalformedMessage for an empty path, a
    foreign frame, a non-finite pose or stamps that do not increase."""
    if not msg.poses:
        raise MalformedMessage("nav_msgs/Path has no poses")
    _check_frame(msg.header.frame_id, world_frame, "Path")
    for pose in msg.poses:
        if pose.header.frame_id not in ("", world_frame):
            _check_frame(pose.header.frame_id, world_frame, "Path pose")
    stamps = np.array([_stamp_ns(p.header.stamp) for p in msg.poses], dtype=np.int64)
    _increasing(stamps, "Path")
    location, _ = _pose_arrays([p.pose for p in msg.poses], "Path")
    speed = point_speeds(location, stamps)
    step_ns = step_ms(timesteps_per_frame) * 1_000_000
    offset = stamps - _stamp_ns(msg.header.stamp)
    keys = np.floor_divide(offset + step_ns // 2, step_ns)
    return Plan(keys=tuple(map(str, keys.tolist())), xy=location[:, :2].copy(), speed=speed)


def plan_to_path(plan: Plan, timestamp_ms: int, timesteps_per_frame: int) -> Path:
    """Plan → nav_msgs/Path in ``map``: one pose per integer key (stamp = header stamp +
    key × frame_ms ms), position (x, −y, 0), identity orientation; the speeds are not carried."""
    from geometry_msgs.msg import PoseStamped
    from nav_msgs.msg import Path

    step = step_ms(timesteps_per_frame)
    xy = plan.xy.tolist()
    poses = [
        PoseStamped(
            header=header(timestamp_ms + int(plan.keys[row]) * step, WORLD_FRAME),
            pose=_ros_pose((*xy[row], 0.0), (0.0, 0.0, 0.0)),
        )
        for row in carried_plan_rows(plan)
    ]
    return Path(header=header(timestamp_ms, WORLD_FRAME), poses=poses)


# --- CARLA ROS bridge markers -------------------------------------------------------------------


def carla_markers_to_actors(msg: MarkerArray, world_frame: str = WORLD_FRAME) -> Actors:
    """CUBE markers as the CARLA ROS bridge publishes them on ``/carla/markers`` → Actors.

    The bridge sends one ADD CUBE per traffic participant (the ego included), in ``map``,
    ``id`` = the CARLA actor id, pose = the actor's transform in REP-103 (as convert.py),
    scale = full bounding-box size, no ``text``. Other markers (other types, DELETE) are not
    actors and are skipped. MalformedMessage for a cube in a foreign frame, a repeated id or
    a non-finite pose or size. :func:`decode_carla_markers` reads the same from CDR bytes."""
    from visualization_msgs.msg import Marker

    cubes = [m for m in msg.markers if m.type == Marker.CUBE and m.action == Marker.ADD]
    return _cubes_to_actors(
        [m.id for m in cubes],
        [m.header.frame_id for m in cubes],
        _pose_table([m.pose for m in cubes]),
        np.array([(m.scale.x, m.scale.y, m.scale.z) for m in cubes], dtype=np.float64),
        world_frame,
    )


#: visualization_msgs/Marker's CUBE type and ADD action.
_CUBE, _ADD = 1, 0


def decode_carla_markers(data: bytes, world_frame: str = WORLD_FRAME) -> Actors:
    """:func:`carla_markers_to_actors` of the MarkerArray's CDR bytes (a raw subscription):
    the same records and errors without building a message object per marker, which cost
    a monitor ~9 ms a frame at 50 actors. CdrError for bytes that are no MarkerArray."""
    m = read_markers(data, kinds=True)
    cubes = [
        n
        for n, (kind, action) in enumerate(zip(m.types, m.actions, strict=True))
        if kind == _CUBE and action == _ADD
    ]
    return _cubes_to_actors(
        [m.ids[n] for n in cubes],
        [m.frames[n] for n in cubes],
        m.poses[cubes],
        m.scales[cubes],
        world_frame,
    )


def _cubes_to_actors(
    ids: list[int], frames: list[str], poses: FloatArray, sizes: FloatArray, world_frame: str
) -> Actors:
    """Actors of CUBE markers' ids, header frames, (N, 7) poses and (N, 3) sizes, checked in
    :func:`carla_markers_to_actors`'s order."""
    for marker_id, frame in zip(ids, frames, strict=True):
        _check_frame(frame, world_frame, f"CARLA marker {marker_id}")
    names = tuple(str(i) for i in ids)
    if len(set(names)) != len(names):
        raise MalformedMessage("CARLA markers repeat an actor id")
    location, rotation = _pose_rows(poses, "CARLA markers")
    size = sizes.reshape(-1, 3)
    if not np.isfinite(size).all():
        raise MalformedMessage("CARLA markers: a cube size is not finite")
    return Actors(ids=names, location=location, rotation=rotation, extent=size / 2.0)


def actors_to_carla_markers(actors: Actors, timestamp_ms: int) -> MarkerArray:
    """Actors → MarkerArray as the CARLA ROS bridge sends it (ids must be integers)."""
    from geometry_msgs.msg import Vector3
    from std_msgs.msg import ColorRGBA
    from visualization_msgs.msg import Marker, MarkerArray

    head = header(timestamp_ms, WORLD_FRAME)
    markers = [
        Marker(
            header=head,
            id=int(actor_id),
            type=Marker.CUBE,
            action=Marker.ADD,
            pose=_ros_pose(loc, rpy),
            scale=Vector3(x=sx, y=sy, z=sz),
            color=ColorRGBA(b=255.0, a=0.3),
        )
        for actor_id, loc, rpy, (sx, sy, sz) in zip(
            actors.ids,
            actors.location.tolist(),
            actors.rotation.tolist(),
            (2.0 * actors.extent).tolist(),
            strict=True,
        )
    ]
    return MarkerArray(markers=markers)
