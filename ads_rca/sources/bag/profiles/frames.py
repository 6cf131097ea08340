"""ROS ``map`` (REP-103: right-handed, z up, radians) ↔ the log's world frame (CARLA:
left-handed, z up, degrees), the conversion the CARLA ROS bridge applies.

The model keeps geometry in the CARLA frame (:mod:`ads_rca.model`), so every reader of a ROS
recording converts here and every writer of one converts back: x stays, y flips, z stays;
roll stays, pitch and yaw change sign. A velocity is a difference of positions, so it flips
like one. Twists that ROS messages give in a body frame (``child_frame_id``, an object's own
frame) are first turned into the map frame by the body's yaw. All functions are vectorised
over leading axes.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

#: Per-axis factors taking a map vector to CARLA and back (the conversion is its own inverse).
_FLIP_Y = np.array([1.0, -1.0, 1.0])


def map_to_carla_xyz(xyz: npt.ArrayLike) -> FloatArray:
    """Points or velocities (..., 3) in ROS map → CARLA world (y negated)."""
    out: FloatArray = np.asarray(xyz, dtype=np.float64) * _FLIP_Y
    return out


def carla_to_map_xyz(xyz: npt.ArrayLike) -> FloatArray:
    """Points or velocities (..., 3) in CARLA world → ROS map (y negated)."""
    return map_to_carla_xyz(xyz)


def quaternion_to_rpy(
    qx: npt.ArrayLike, qy: npt.ArrayLike, qz: npt.ArrayLike, qw: npt.ArrayLike
) -> FloatArray:
    """A unit quaternion's (roll, pitch, yaw) in radians, ZYX convention, shape (..., 3).

    The quaternion is normalised first (recorded ones drift from unit length); pitch is
    clipped at ±90° where rounding takes ``sin`` past 1."""
    q = np.stack(np.broadcast_arrays(qx, qy, qz, qw), axis=-1).astype(np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    roll = np.arctan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2.0 * (w * y - z * x), -1.0, 1.0))
    yaw = np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    out: FloatArray = np.stack([roll, pitch, yaw], axis=-1)
    return out


def rpy_to_quaternion(roll: npt.ArrayLike, pitch: npt.ArrayLike, yaw: npt.ArrayLike) -> FloatArray:
    """(qx, qy, qz, qw) of ZYX angles in radians, shape (..., 4)."""
    r, p, y = (np.asarray(a, dtype=np.float64) / 2.0 for a in (roll, pitch, yaw))
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    out: FloatArray = np.stack(
        [
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
            cr * cp * cy + sr * sp * sy,
        ],
        axis=-1,
    )
    return out


def map_rpy_to_carla_deg(rpy: npt.ArrayLike) -> FloatArray:
    """Map (roll, pitch, yaw) radians (..., 3) → CARLA (roll, pitch, yaw) degrees."""
    out: FloatArray = np.degrees(np.asarray(rpy, dtype=np.float64)) * np.array([1.0, -1.0, -1.0])
    return out


def carla_deg_to_map_rpy(rpy_deg: npt.ArrayLike) -> FloatArray:
    """CARLA (roll, pitch, yaw) degrees (..., 3) → map (roll, pitch, yaw) radians."""
    out: FloatArray = np.radians(np.asarray(rpy_deg, dtype=np.float64)) * np.array(
        [1.0, -1.0, -1.0]
    )
    return out


def quaternion_to_carla_rpy(
    qx: npt.ArrayLike, qy: npt.ArrayLike, qz: npt.ArrayLike, qw: npt.ArrayLike
) -> FloatArray:
    """A map-frame orientation quaternion → CARLA (roll, pitch, yaw) degrees (..., 3)."""
    return map_rpy_to_carla_deg(quaternion_to_rpy(qx, qy, qz, qw))


def carla_rpy_to_quaternion(rpy_deg: npt.ArrayLike) -> FloatArray:
    """CARLA (roll, pitch, yaw) degrees (..., 3) → the map-frame quaternion (..., 4)."""
    rpy = carla_deg_to_map_rpy(rpy_deg)
    return rpy_to_quaternion(rpy[..., 0], rpy[..., 1], rpy[..., 2])


def body_to_world(vector: npt.ArrayLike, yaw: npt.ArrayLike) -> FloatArray:
    """Vectors (..., 3) given in a body frame → the same frame's world axes, rotating about z
    by the body's ``yaw`` (radians, same convention as the vectors: map yaw for map-frame
    bodies). Roll and pitch are ignored: the model is planar."""
    v = np.asarray(vector, dtype=np.float64)
    c, s = np.cos(yaw), np.sin(yaw)
    out: FloatArray = np.stack(
        [c * v[..., 0] - s * v[..., 1], s * v[..., 0] + c * v[..., 1], v[..., 2]], axis=-1
    )
    return out


def world_to_body(vector: npt.ArrayLike, yaw: npt.ArrayLike) -> FloatArray:
    """The inverse of :func:`body_to_world`."""
    return body_to_world(vector, -np.asarray(yaw, dtype=np.float64))


__all__ = [
    "body_to_world",
    "carla_deg_to_map_rpy",
    "carla_rpy_to_quaternion",
    "carla_to_map_xyz",
    "map_rpy_to_carla_deg",
    "map_to_carla_xyz",
    "quaternion_to_carla_rpy",
    "quaternion_to_rpy",
    "rpy_to_quaternion",
    "world_to_body",
]
