"""Detector and tracker: the perception module of the simulated stack.

The detector turns the camera's gt boxes into detections with relative (scale-free) corner
noise, occasional misses of background objects, and its own per-frame ids (every σ comes
from :class:`~ads_rca.synth.noise.Noise`, the run's noise level). Alongside each box it
reports a perceived 3-D position whose error is a slowly varying bias (like a depth estimate),
so velocities derived from it stay realistic. The tracker (α-β-γ filter per
object) keeps its own track ids, bridges short dropouts by coasting and drops a track after
``MAX_COAST`` missed frames. Both are vectorised over actors: state arrays are indexed by
actor row, which stands for the association a real tracker would do by gating.

Each detection also carries the object's size and, only if the detector measured one, a
velocity. The tracker's shape estimate is the noise-free detected size (an idealised shape
filter: the planner sees true shapes unless perception is faulty); a measured velocity
replaces the filter's velocity and acceleration, as a tracker fed with a velocity sensor
would. The fault-free detector measures none (velocities come from the filter only).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ads_rca.synth.camera import HEIGHT, WIDTH
from ads_rca.synth.geometry import FloatArray
from ads_rca.synth.noise import DEFAULT_NOISE, Noise

# Re-exported: the perceived position's σ, as the 3-D checks of the tests read it.
from ads_rca.synth.noise import POSITION_NOISE as POSITION_NOISE  # noqa: PLC0414
from ads_rca.synth.noise import RANGE_NOISE as RANGE_NOISE  # noqa: PLC0414

DT = 0.05
MISS_PROBABILITY = 0.03  # background objects only
BIAS_CORRELATION = 0.95
MAX_COAST = 2  # frames a track survives without detections
CONFIRM_AGE = 8  # frames before a track is published (filter settled)
GATE = 3.0  # m: a measurement further than this from the track starts a new track
ALPHA, BETA, GAMMA = 0.6, 0.25, 0.02
MAX_ACCEL = 8.0


@dataclass
class Detections:
    """One frame of detector output (rows = detected actors, sorted by image x)."""

    rows: np.ndarray  # actor rows (hidden truth, never written)
    ids: tuple[str, ...]
    corners: FloatArray  # (D, 4)
    position: FloatArray  # (D, 2) perceived world position
    yaw: FloatArray  # (D,) perceived heading, radians
    size: FloatArray  # (D, 3) perceived half extents, without per-frame noise
    velocity: FloatArray  # (D, 2) measured world velocity; NaN: not measured


class Detector:
    """Noisy detector; draws the same random numbers every frame whatever it sees."""

    def __init__(
        self,
        rng: np.random.Generator,
        n_actors: int,
        never_miss: int,
        noise: Noise = DEFAULT_NOISE,
    ) -> None:
        self._rng = rng
        self._noise = noise
        self._never_miss = never_miss
        self._bias = rng.standard_normal((n_actors, 2))

    def detect(
        self,
        gt: FloatArray,
        in_view: np.ndarray,
        xy: FloatArray,
        yaw: FloatArray,
        ego_xy: FloatArray,
        suppressed: np.ndarray,
        extent: FloatArray,
    ) -> Detections:
        n = gt.shape[0]
        rng = self._rng
        box_noise = rng.standard_normal((n, 4))
        miss = np.less(rng.random(n), MISS_PROBABILITY)
        white = rng.standard_normal((n, 2))
        yaw_noise = rng.standard_normal((n,)) * self._noise.yaw
        rho = BIAS_CORRELATION
        self._bias = rho * self._bias + np.sqrt(1 - rho * rho) * white
        if 0 <= self._never_miss < n:
            miss[self._never_miss] = False
        seen = in_view & ~miss & ~suppressed
        rows = np.flatnonzero(seen)
        size = np.stack([gt[:, 2] - gt[:, 0], gt[:, 3] - gt[:, 1]], axis=1)[rows]
        jitter = box_noise[rows] * self._noise.box
        corners = gt[rows] + jitter * np.concatenate([size, size], axis=1)
        corners[:, [0, 2]] = np.clip(corners[:, [0, 2]], 0, WIDTH - 1)
        corners[:, [1, 3]] = np.clip(corners[:, [1, 3]], 0, HEIGHT - 1)
        rng_m = np.hypot(*(xy[rows] - ego_xy).T)
        sigma = self._noise.position(rng_m)
        position = xy[rows] + self._bias[rows] * sigma[:, None]
        order = np.argsort(corners[:, 0], kind="stable")
        return Detections(
            rows=rows[order],
            ids=tuple(str(i) for i in range(rows.size)),
            corners=corners[order],
            position=position[order],
            yaw=(yaw[rows] + yaw_noise[rows])[order],
            size=extent[rows][order],
            velocity=np.full((rows.size, 2), np.nan),
        )


class Tracker:
    """α-β-γ tracks with their own ids, one slot per actor row."""

    def __init__(self, n_actors: int, first_id: int) -> None:
        self.track_id = np.full(n_actors, -1, dtype=np.int64)
        self.pos = np.zeros((n_actors, 2))
        self.vel = np.zeros((n_actors, 2))
        self.acc = np.zeros((n_actors, 2))
        self.yaw = np.zeros(n_actors)
        self.extent = np.zeros((n_actors, 3))
        self.age = np.zeros(n_actors, dtype=np.int64)
        self.missed = np.zeros(n_actors, dtype=np.int64)
        self._next_id = first_id

    def update(self, det: Detections) -> None:
        n = self.track_id.size
        measured = np.zeros(n, dtype=bool)
        measured[det.rows] = True
        z = np.zeros((n, 2))
        z[det.rows] = det.position
        z_yaw = np.zeros(n)
        z_yaw[det.rows] = det.yaw
        z_size = np.zeros((n, 3))
        z_size[det.rows] = det.size
        z_vel = np.full((n, 2), np.nan)
        z_vel[det.rows] = det.velocity
        alive = self.track_id >= 0
        pred_pos = self.pos + self.vel * DT + 0.5 * self.acc * DT * DT
        pred_vel = self.vel + self.acc * DT
        residual = z - pred_pos
        far = np.hypot(residual[:, 0], residual[:, 1]) > GATE
        update = alive & measured & ~far
        coast = alive & ~measured
        new = measured & (~alive | far)
        # Existing tracks: filter or coast.
        self.pos = np.where(alive[:, None], pred_pos, self.pos)
        self.vel = np.where(alive[:, None], pred_vel, self.vel)
        u = update[:, None]
        self.pos = np.where(u, self.pos + ALPHA * residual, self.pos)
        self.vel = np.where(u, self.vel + (BETA / DT) * residual, self.vel)
        acc = self.acc + (2 * GAMMA / (DT * DT)) * residual
        norm = np.maximum(np.hypot(acc[:, 0], acc[:, 1]) / MAX_ACCEL, 1.0)
        self.acc = np.where(u, acc / norm[:, None], self.acc)
        self.yaw = np.where(update, z_yaw, self.yaw)
        self.extent = np.where(u, z_size, self.extent)
        self.age = np.where(alive, self.age + 1, self.age)
        self.missed = np.where(update, 0, np.where(coast, self.missed + 1, self.missed))
        dropped = coast & (self.missed > MAX_COAST)
        self.track_id[dropped] = -1
        # New tracks, ids in row order (deterministic).
        new_rows = np.flatnonzero(new)
        if new_rows.size:
            self.track_id[new_rows] = np.arange(self._next_id, self._next_id + new_rows.size)
            self._next_id += int(new_rows.size)
            self.pos[new_rows] = z[new_rows]
            self.vel[new_rows] = 0.0
            self.acc[new_rows] = 0.0
            self.yaw[new_rows] = z_yaw[new_rows]
            self.extent[new_rows] = z_size[new_rows]
            self.age[new_rows] = 1
            self.missed[new_rows] = 0
        fused = measured & np.isfinite(z_vel).all(axis=1)
        self.vel[fused] = z_vel[fused]
        self.acc[fused] = 0.0

    def published(self) -> np.ndarray:
        """Rows of confirmed tracks, ordered by track id."""
        rows = np.flatnonzero((self.track_id >= 0) & (self.age >= CONFIRM_AGE))
        return rows[np.argsort(self.track_id[rows], kind="stable")]
