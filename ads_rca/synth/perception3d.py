"""3-D perception output (detections and tracks as a real stack publishes them) and the
3-D perception faults that misperceive the partner so that it seems to clear the ego's path.

The detector's 3-D objects are its detections as the tracker receives them: the perceived
position (with the detector's slowly varying bias), heading, half extents with a per-frame
relative noise (``Noise.extent``, floored at half the size), a measured velocity (NaN: this
detector measures none, except the one a ``velocity`` fault makes up), a score falling with
range, and the class. The tracks are the tracker's published state, keyed by the track ids
the raw predictions use. Noise and scores come from their own generator, so the 2-D boxes,
predictions and plans are the same numbers whether or not 3-D output is made.

The faults act on the partner's detection before the tracker, so the tracker, the raw
predictions and the planner follow exactly as they would follow a real misperception:

- ``shifted``: its position moved sideways from the ego's path (the normal at the nearest
  path point ahead), by ``SHIFT_MIN`` more than it is, and at least until its box clears the
  ego's corridor by ``CLEARANCE``: a car in the ego's lane is perceived in the next lane. The
  shift grows by at most ``SHIFT_STEP`` a frame, so the track keeps its id (the gate is 3 m).
- ``shrunk``: its extent scaled by ``SHRINK`` toward its far side (the side away from the
  ego stays where it is), so its near side recedes by 1.4 half extents: 3.4 m for a car's
  length, 0.35 m for a pedestrian.
- ``velocity``: it reports a velocity (which the tracker takes) from the scene's optimistic
  wrong motion model: a braking lead at its speed from before braking, a cutting-in car or
  crossing pedestrian moving back out across the road (its motion across the road
  mirrored), oncoming traffic standing.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ads_rca.model import Objects3D
from ads_rca.synth.geometry import FloatArray
from ads_rca.synth.noise import DEFAULT_NOISE, Noise
from ads_rca.synth.perception import DT, Detections, Tracker
from ads_rca.synth.prediction import wrong_model
from ads_rca.synth.world import PEDESTRIAN, VEHICLE, Scene

SCORE_AT_ZERO = 0.95  # detection score at zero range, falling by SCORE_PER_METRE
SCORE_PER_METRE = 0.003
SCORE_NOISE = 0.03
SHIFT_MIN = 2.0  # m: a shifted partner is perceived at least this much further out
CLEARANCE = 1.5  # m between a shifted partner's box and the ego's corridor (> planner margin)
SHIFT_STEP = 1.5  # m a frame the shift may grow
SHRINK = 0.3  # a shrunk partner's extent, as a fraction of the true one
LOOKAHEAD = 120.0  # m of the ego's path searched for the point nearest the partner
#: Class names as Autoware's ObjectClassification constants spell them.
LABELS = {VEHICLE: "CAR", PEDESTRIAN: "PEDESTRIAN"}


@dataclass
class Misperception:
    """A perception fault's variant applied to the partner's detection, frame by frame."""

    scene: Scene
    stale_velocity: FloatArray  # the partner's velocity before its manoeuvre
    stale_position: FloatArray
    side: float = 0.0  # which side of the ego's path a shifted partner is moved to
    shift: FloatArray | None = None  # the shift applied at the last frame (world, m)

    def apply(
        self,
        det: Detections,
        variant: str,
        frame_index: int,
        ego_s: float,
        ego_xy: FloatArray,
        ego_speed: float,
    ) -> Detections:
        """``det`` with the partner misperceived as ``variant`` says ("" or "missed": as is)."""
        hit = np.flatnonzero(det.rows == self.scene.partner)
        if variant in ("", "missed") or hit.size == 0:
            return det
        scene, row, k = self.scene, self.scene.partner, int(hit[0])
        if variant == "shrunk":
            size, position = det.size.copy(), det.position.copy()
            position[k] += self._toward_far_side(frame_index, ego_xy, size[k])
            size[k] *= SHRINK
            return replace(det, size=size, position=position)
        if variant == "velocity":
            here, before = scene.xy[frame_index, row], scene.xy[frame_index - 1, row]
            true_velocity = ((here - before) / DT)[None, :]
            model = scene.prediction_fault_model
            velocity = det.velocity.copy()
            if model == "keep_lane":
                road = scene.road_direction
                along = float(true_velocity[0] @ road)
                across = true_velocity[0] - along * road
                if scene.kinds[row] == VEHICLE:
                    along = max(along, ego_speed)
                velocity[k] = along * road - across
            else:
                _, wrong, _ = wrong_model(
                    model,
                    here[None, :],
                    true_velocity,
                    np.zeros_like(true_velocity),
                    self.stale_position,
                    self.stale_velocity,
                    scene.road_direction,
                )
                velocity[k] = wrong[0]
            return replace(det, velocity=velocity)
        if variant == "shifted":
            position = det.position.copy()
            position[k] += self._shift(frame_index, ego_s)
            return replace(det, position=position)
        raise ValueError(f"unknown perception fault variant {variant!r}")

    def _toward_far_side(
        self, frame_index: int, ego_xy: FloatArray, half: FloatArray
    ) -> FloatArray:
        """How far the centre moves when the box shrinks keeping its side away from the ego."""
        row = self.scene.partner
        away = self.scene.xy[frame_index, row] - ego_xy
        away /= max(float(np.hypot(*away)), 1e-9)
        heading = self.scene.yaw[frame_index, row]
        along = abs(np.cos(heading) * away[0] + np.sin(heading) * away[1])
        across = np.sqrt(max(0.0, 1.0 - along * along))
        support = half[0] * along + half[1] * across
        moved: FloatArray = (1.0 - SHRINK) * support * away
        return moved

    def _shift(self, frame_index: int, ego_s: float) -> FloatArray:
        """This frame's shift of the partner (world): sideways from the ego's path."""
        scene, row = self.scene, self.scene.partner
        point = scene.xy[frame_index, row]
        path = scene.path
        ahead = np.flatnonzero((path.s >= ego_s) & (path.s <= ego_s + LOOKAHEAD))
        if ahead.size == 0:
            ahead = np.array([path.s.size - 1])
        nearest = int(ahead[np.argmin(np.hypot(*(path.xy[ahead] - point).T))])
        normal = np.array([-np.sin(path.yaw[nearest]), np.cos(path.yaw[nearest])])
        lateral = float((point - path.xy[nearest]) @ normal)
        if self.side == 0.0:
            self.side = 1.0 if lateral >= 0.0 else -1.0
        heading = scene.yaw[frame_index, row]
        along = abs(np.cos(heading) * normal[0] + np.sin(heading) * normal[1])
        across = np.sqrt(max(0.0, 1.0 - along * along))
        half = scene.extent[row, 0] * along + scene.extent[row, 1] * across
        clear = scene.ego_extent[1] + half + CLEARANCE
        outward = self.side * lateral
        wanted = (max(outward + SHIFT_MIN, clear) - outward) * self.side * normal
        previous = np.zeros(2) if self.shift is None else self.shift
        step = wanted - previous
        length = float(np.hypot(*step))
        if length > SHIFT_STEP:
            step *= SHIFT_STEP / length
        self.shift = previous + step
        return self.shift


class Output3D:
    """Turns each frame's detections and published tracks into :class:`Objects3D`."""

    def __init__(
        self, rng: np.random.Generator, kinds: tuple[str, ...], noise: Noise = DEFAULT_NOISE
    ) -> None:
        self._rng = rng
        self._noise = noise
        self._labels = tuple(LABELS[k] for k in kinds)

    def detections(self, det: Detections, ego_xy: FloatArray) -> Objects3D:
        """The detector's 3-D objects (ids as its 2-D boxes: one detection, both views).

        Draws the same random numbers every frame whatever is detected."""
        n = len(self._labels)
        size_noise = self._rng.standard_normal((n, 3))[det.rows]
        score_noise = self._rng.standard_normal(n)[det.rows]
        extent = det.size * np.maximum(1.0 + self._noise.extent * size_noise, 0.5)
        distance = np.hypot(*(det.position - ego_xy).T)
        score = SCORE_AT_ZERO - SCORE_PER_METRE * distance + SCORE_NOISE * score_noise
        velocity = _xyz(det.velocity)
        velocity[np.isnan(det.velocity[:, 0]), 2] = np.nan
        return Objects3D(
            ids=det.ids,
            location=_xyz(det.position),
            yaw=np.degrees(det.yaw),
            extent=extent,
            velocity=velocity,
            score=np.clip(score, 0.3, 1.0),
            labels=tuple(self._labels[r] for r in det.rows),
        )

    def tracks(self, tracker: Tracker, rows: np.ndarray) -> Objects3D:
        """The tracker's published tracks; the score is an existence probability that grows
        with the track's age and falls while it coasts."""
        existence = (1.0 - 0.5 ** np.minimum(tracker.age[rows], 30)) * 0.7 ** tracker.missed[rows]
        return Objects3D(
            ids=tuple(str(t) for t in tracker.track_id[rows]),
            location=_xyz(tracker.pos[rows]),
            yaw=np.degrees(tracker.yaw[rows]),
            extent=tracker.extent[rows].copy(),
            velocity=_xyz(tracker.vel[rows]),
            score=existence.astype(np.float64),
            labels=tuple(self._labels[r] for r in rows),
        )


def _xyz(xy: FloatArray) -> FloatArray:
    """(N, 2) → (N, 3) with z = 0: objects stand on the flat ground, as actors do."""
    out = np.zeros((xy.shape[0], 3))
    out[:, :2] = xy
    return out
