"""Lateral dynamics: a kinematic bicycle steered by pure pursuit along the ego's path.

Without it the ego rides its path exactly (our synthesised worlds, whose roads are straight
where the ego drives). With it the ego is a vehicle: its pose is integrated from a steering
angle that a pure-pursuit follower commands toward a point ``lookahead`` ahead on the path,
realised through a first-order steering lag. On a straight road it stays on the line; at a
curve's entry it lags and then cuts inside, so its pose leaves the plan by centimetres a step,
as a real path follower's does. That is the normal behaviour of a sound controller, which a
judge of control must not read as a fault (issue #40, item 1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ads_rca.synth.geometry import FloatArray
from ads_rca.synth.world import Path

#: Distance between the axles (m), as for the steering angle the commands record.
WHEELBASE = 2.9


@dataclass(frozen=True)
class PathFollower:
    """Pure pursuit on a kinematic bicycle. The lookahead distance is ``lookahead_time``
    seconds of travel, at least ``min_lookahead``; the steering reaches its command with the
    time constant ``steer_lag_s``, within ±``max_steer_deg``."""

    lookahead_time: float = 0.8
    min_lookahead: float = 5.0
    steer_lag_s: float = 0.15
    max_steer_deg: float = 35.0


@dataclass
class VehicleState:
    """Where the ego is (world frame), where it heads (rad), its steering angle (rad, the
    sign of its yaw rate) and its progress ``s`` along the path (its projection)."""

    xy: FloatArray
    yaw: float
    steer: float
    s: float


def start_state(path: Path, s: float) -> VehicleState:
    """The vehicle on its path at arc length ``s``, heading along it, wheels straight."""
    xy, yaw = path.at(np.asarray(s))
    return VehicleState(np.asarray(xy, dtype=float), float(yaw), 0.0, s)


def step(
    follower: PathFollower,
    path: Path,
    state: VehicleState,
    distance: float,
    speed: float,
    dt: float,
) -> VehicleState:
    """The state after travelling ``distance`` (m) in ``dt`` (s) at about ``speed`` (m/s):
    the steering moves toward pure pursuit's command, then the bicycle moves (midpoint
    heading), then the progress is the new pose's projection onto the path."""
    lookahead = max(follower.min_lookahead, follower.lookahead_time * speed)
    target, _ = path.at(np.asarray(state.s + lookahead))
    dx, dy = float(target[0] - state.xy[0]), float(target[1] - state.xy[1])
    alpha = math.atan2(dy, dx) - state.yaw
    command = math.atan2(2.0 * WHEELBASE * math.sin(alpha), math.hypot(dx, dy))
    limit = math.radians(follower.max_steer_deg)
    command = min(max(command, -limit), limit)
    steer = state.steer + (command - state.steer) * min(dt / follower.steer_lag_s, 1.0)
    turn = distance / WHEELBASE * math.tan(steer)
    heading = state.yaw + 0.5 * turn
    xy = state.xy + distance * np.array([math.cos(heading), math.sin(heading)])
    return VehicleState(xy, state.yaw + turn, steer, project(path, xy, state.s))


def project(path: Path, xy: FloatArray, near: float, window: float = 10.0) -> float:
    """The arc length of the point of ``path`` nearest ``xy``, searched within ``window`` m
    of ``near`` (the path may come back near itself further on)."""
    lo = int(np.searchsorted(path.s, near - window))
    hi = int(np.searchsorted(path.s, near + window)) + 1
    points, arc = path.xy[lo : hi + 1], path.s[lo : hi + 1]
    if len(points) < 2:
        return float(np.clip(near, 0.0, path.s[-1]))
    start, vec = points[:-1], np.diff(points, axis=0)
    length2 = np.maximum((vec * vec).sum(axis=1), 1e-12)
    t = np.clip(((xy - start) * vec).sum(axis=1) / length2, 0.0, 1.0)
    nearest = start + t[:, None] * vec
    j = int(np.argmin(((xy - nearest) ** 2).sum(axis=1)))
    return float(arc[j] + t[j] * (arc[j + 1] - arc[j]))
