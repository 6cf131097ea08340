"""The simulated world: the ego's path, the scripted actors and the scene transform.

Non-ego actors do not react to the ego, so their whole trajectories are computed up front
as arrays (frames × actors); only the ego is simulated in closed loop. Scenarios are built
in a local road frame (ego lane along +x, y to the right as in CARLA) and the whole scene
is then rotated by a random heading and shifted, so roads are not axis-aligned.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ads_rca.synth.geometry import FloatArray

#: Actor kinds, written as detection labels.
#: Warm-up frames before frame 0 in trajectory arrays (the gt predictor needs history).
PAD = 2
VEHICLE = "vehicle"
PEDESTRIAN = "pedestrian"

#: Half extents (x, y, z) of the car models the synthesiser draws from.
CAR_EXTENTS = np.array(
    [
        [2.4508416652679443, 1.0641621351242065, 0.7553732395172119],
        [2.3958897590637207, 1.081725001335144, 0.744159996509552],
        [2.2763495445251465, 1.0060961246490479, 0.7660311460494995],
        [2.5133883953094482, 1.0757731199264526, 0.8209919929504395],
    ]
)
PEDESTRIAN_EXTENT = np.array([0.25, 0.25, 0.9])


@dataclass(frozen=True)
class Path:
    """A dense polyline with arc length: where the ego drives (world frame)."""

    xy: FloatArray  # (P, 2)
    s: FloatArray  # (P,) cumulative arc length
    yaw: FloatArray  # (P,) heading of each point, radians

    @classmethod
    def from_points(cls, xy: FloatArray) -> Path:
        seg = np.diff(xy, axis=0)
        length = np.hypot(seg[:, 0], seg[:, 1])
        s = np.concatenate([[0.0], np.cumsum(length)])
        heading = np.arctan2(seg[:, 1], seg[:, 0])
        yaw = np.unwrap(np.concatenate([heading, heading[-1:]]))
        return cls(xy=xy, s=s, yaw=yaw)

    def at(self, s: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Positions (..., 2) and headings (..., rad) at arc lengths ``s`` (clamped)."""
        s = np.clip(s, 0.0, self.s[-1])
        x = np.interp(s, self.s, self.xy[:, 0])
        y = np.interp(s, self.s, self.xy[:, 1])
        return np.stack([x, y], axis=-1), np.interp(s, self.s, self.yaw)

    def transformed(self, rotation: float, offset: FloatArray) -> Path:
        return Path(
            xy=transform_points(self.xy, rotation, offset), s=self.s, yaw=self.yaw + rotation
        )


def transform_points(xy: FloatArray, rotation: float, offset: FloatArray) -> FloatArray:
    """Rotate local road-frame points by ``rotation`` (rad) and shift by ``offset``."""
    c, s = np.cos(rotation), np.sin(rotation)
    return np.stack(
        [offset[0] + xy[..., 0] * c - xy[..., 1] * s, offset[1] + xy[..., 0] * s + xy[..., 1] * c],
        axis=-1,
    )


def straight_path(length: float, step: float = 0.5) -> FloatArray:
    """Local points of a straight road along +x from the origin."""
    x = np.arange(0.0, length + step, step)
    return np.stack([x, np.zeros_like(x)], axis=-1)


def left_turn_path(
    approach: float, radius: float, exit_length: float, step: float = 0.5
) -> FloatArray:
    """Local points: straight along +x, a quarter circle to the left (−y), then along −y."""
    straight = straight_path(approach, step)
    n_arc = max(int(radius * np.pi / 2 / step), 8)
    angle = np.linspace(0.0, np.pi / 2, n_arc)[1:]
    arc = np.stack([approach + radius * np.sin(angle), -radius * (1 - np.cos(angle))], axis=-1)
    tail_y = -radius - np.arange(step, exit_length + step, step)
    tail = np.stack([np.full_like(tail_y, approach + radius), tail_y], axis=-1)
    return np.concatenate([straight, arc, tail])


def yaw_from_motion(xy: FloatArray, initial_yaw: FloatArray) -> FloatArray:
    """Headings (T, N) along each actor's motion; standing actors keep their last heading."""
    step = np.diff(xy, axis=0)
    moving = np.hypot(step[..., 0], step[..., 1]) > 1e-4
    heading = np.arctan2(step[..., 1], step[..., 0])
    yaw = np.empty(xy.shape[:2])
    yaw[0] = initial_yaw
    for t in range(1, xy.shape[0]):  # once per scene, not per simulated frame
        yaw[t] = np.where(moving[t - 1], heading[t - 1], yaw[t - 1])
    yaw[0] = np.where(moving[0], heading[0], initial_yaw)
    return yaw


@dataclass
class Scene:
    """A scenario instance: everything the closed loop needs, in the world frame.

    ``xy``/``yaw`` hold every non-ego actor at frames 0..frames (index = frame number).
    """

    name: str
    frames: int
    path: Path
    ego_id: str
    ego_extent: FloatArray  # (3,)
    ego_speed: float  # initial speed, m/s
    desired_speed: float
    actor_ids: tuple[str, ...]
    kinds: tuple[str, ...]
    extent: FloatArray  # (N, 3)
    xy: FloatArray  # (frames + 1, N, 2)
    yaw: FloatArray  # (frames + 1, N) radians
    partner: int = -1  # index of the scripted conflict partner; -1 for none
    trigger_frame: int = 0  # when the partner's conflicting behaviour starts
    #: Which optimistic wrong motion model a prediction fault uses for this partner.
    prediction_fault_model: str = "stale"
    #: Unit vector of the ego's road direction (world), for the "mirror" model.
    road_direction: FloatArray = field(default_factory=lambda: np.array([1.0, 0.0]))
    info: dict[str, float] = field(default_factory=dict)
