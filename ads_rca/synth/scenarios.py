"""Scenario families, each drawn from a seed: speeds, gaps, timing, heading, background.

Every family scripts one partner whose manoeuvre, left unanswered, hits the ego: a
fault-free ego notices it and brakes (a near miss); a faulty one does not. Scenes are
built in a local road frame (ego lane along +x, y to the right, lanes 3.5 m apart) and
rotated by a random heading. ``cruise`` is a long, conflict-free drive with many actors,
for benchmarks.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ads_rca.synth.geometry import FloatArray
from ads_rca.synth.world import (
    CAR_EXTENTS,
    PAD,
    PEDESTRIAN,
    PEDESTRIAN_EXTENT,
    VEHICLE,
    Path,
    Scene,
    left_turn_path,
    straight_path,
    transform_points,
    yaw_from_motion,
)

DT = 0.05
LANE = 3.5
SCENARIOS = ("cut_in", "lead_braking", "pedestrian_crossing", "left_turn", "cruise")
DEFAULT_FRAMES = {"cut_in": 200, "lead_braking": 200, "pedestrian_crossing": 200, "left_turn": 240}


def _times(frames: int) -> FloatArray:
    return (np.arange(frames + PAD + 1, dtype=np.float64) - PAD) * DT


def _brake_x(t: FloatArray, x0: float, v: float, t_brake: float, decel: float) -> FloatArray:
    """Position along a lane: constant speed, then constant deceleration to a stop."""
    tau = np.clip(t - t_brake, 0.0, v / decel)
    x: FloatArray = x0 + v * np.minimum(t, t_brake) + v * tau - 0.5 * decel * tau * tau
    return x


class _Builder:
    """Collects actors in the local road frame, then places the scene in the world."""

    def __init__(self, rng: np.random.Generator, name: str, frames: int) -> None:
        self.rng = rng
        self.name = name
        self.frames = frames
        self.t = _times(frames)
        self.xy: list[FloatArray] = []
        self.kinds: list[str] = []
        self.extents: list[FloatArray] = []
        self.yaw0: list[float] = []

    def car(self) -> FloatArray:
        extents: FloatArray = CAR_EXTENTS[self.rng.integers(0, len(CAR_EXTENTS))]
        return extents

    def add(self, xy: FloatArray, kind: str, extent: FloatArray, yaw0: float) -> int:
        self.xy.append(xy)
        self.kinds.append(kind)
        self.extents.append(extent)
        self.yaw0.append(yaw0)
        return len(self.xy) - 1

    def background(self, count: int, ego_speed: float, left_side: bool = True) -> None:
        """Vehicles in lanes two or more away from the ego's, pedestrians on sidewalks."""
        rng, t = self.rng, self.t
        lanes = [2 * LANE, 3 * LANE] + ([-2 * LANE, -3 * LANE] if left_side else [])
        sidewalks = [9.0] + ([-9.5] if left_side else [])
        for _ in range(count):
            if rng.random() < 0.65:
                y = lanes[rng.integers(0, len(lanes))] + rng.normal(0, 0.15)
                direction = 1.0 if y > 0 else -1.0
                speed = 0.0 if rng.random() < 0.2 else rng.uniform(0.5, 1.2) * ego_speed
                x = rng.uniform(-20, 160) + direction * speed * t
                self.add(
                    np.stack([x, np.full_like(t, y)], -1),
                    VEHICLE,
                    self.car(),
                    0.0 if direction > 0 else np.pi,
                )
            else:
                y = sidewalks[rng.integers(0, len(sidewalks))] + rng.uniform(-0.8, 0.8)
                speed = rng.choice([0.0, rng.uniform(0.8, 1.6)]) * rng.choice([-1.0, 1.0])
                x = rng.uniform(0, 120) + speed * t
                self.add(
                    np.stack([x, np.full_like(t, y)], -1),
                    PEDESTRIAN,
                    PEDESTRIAN_EXTENT,
                    0.0 if speed >= 0 else np.pi,
                )

    def scene(
        self,
        path_points: FloatArray,
        ego_speed: float,
        desired_speed: float,
        partner: int,
        trigger_frame: int,
        model: str,
    ) -> Scene:
        rng = self.rng
        rotation = float(rng.uniform(-np.pi, np.pi))
        offset = rng.uniform(-300.0, 300.0, size=2)
        n = len(self.xy)
        order = rng.permutation(n)  # the partner is not always the first actor in the files
        local = np.stack(self.xy, axis=1)[:, order]
        xy = transform_points(local, rotation, offset)
        yaw = yaw_from_motion(xy, np.asarray(self.yaw0)[order] + rotation)
        ids = rng.choice(np.arange(100, 10000), size=n + 1, replace=False)
        return Scene(
            name=self.name,
            frames=self.frames,
            path=Path.from_points(path_points).transformed(rotation, offset),
            ego_id=str(ids[0]),
            ego_extent=CAR_EXTENTS[0].copy(),
            ego_speed=ego_speed,
            desired_speed=desired_speed,
            actor_ids=tuple(str(i) for i in ids[1:]),
            kinds=tuple(self.kinds[k] for k in order),
            extent=np.stack(self.extents)[order],
            xy=xy,
            yaw=yaw,
            partner=-1 if partner < 0 else int(np.flatnonzero(order == partner)[0]),
            trigger_frame=trigger_frame,
            prediction_fault_model=model,
            road_direction=np.array([np.cos(rotation), np.sin(rotation)]),
        )


def lead_braking(rng: np.random.Generator, frames: int, actors: int) -> Scene:
    """The lead car in the ego's lane brakes hard to a stop."""
    b = _Builder(rng, "lead_braking", frames)
    v = rng.uniform(9.0, 15.0)
    gap = rng.uniform(10.0, 18.0)
    ext = b.car()
    trigger = int(rng.integers(30, 50))
    x = _brake_x(b.t, gap + CAR_EXTENTS[0][0] + ext[0], v, trigger * DT, rng.uniform(4.5, 7.0))
    partner = b.add(np.stack([x, np.zeros_like(x)], -1), VEHICLE, ext, 0.0)
    b.background(actors, v)
    return b.scene(straight_path(v * frames * DT + 100), v, v, partner, trigger, "stale")


def cut_in(rng: np.random.Generator, frames: int, actors: int) -> Scene:
    """A slower car in the next lane changes into the ego's lane just ahead of it."""
    b = _Builder(rng, "cut_in", frames)
    v_e = rng.uniform(11.0, 16.0)
    v_p = v_e - rng.uniform(3.0, 6.0)
    side = float(rng.choice([-1.0, 1.0]))
    trigger = int(rng.integers(30, 45))
    duration = rng.uniform(2.5, 3.5)
    gap = rng.uniform(5.0, 12.0)
    ext = b.car()
    x_trigger = v_e * trigger * DT + gap + CAR_EXTENTS[0][0] + ext[0]
    x = x_trigger + v_p * (b.t - trigger * DT)
    tau = np.clip((b.t - trigger * DT) / duration, 0.0, 1.0)
    y = side * LANE * (1.0 - (tau - np.sin(2 * np.pi * tau) / (2 * np.pi)))
    partner = b.add(np.stack([x, y], -1), VEHICLE, ext, 0.0)
    b.background(actors, v_e)
    return b.scene(straight_path(v_e * frames * DT + 100), v_e, v_e, partner, trigger, "keep_lane")


def pedestrian_crossing(rng: np.random.Generator, frames: int, actors: int) -> Scene:
    """A pedestrian steps off the sidewalk and crosses in front of the ego."""
    b = _Builder(rng, "pedestrian_crossing", frames)
    v_e = rng.uniform(9.0, 14.0)
    side = float(rng.choice([-1.0, 1.0]))
    y0 = side * rng.uniform(5.0, 7.0)
    v_p = rng.uniform(1.2, 2.0)
    accel = 1.5
    trigger = int(rng.integers(25, 45))
    t_ramp = v_p / accel
    dist_ramp = 0.5 * accel * t_ramp**2
    tau = np.clip(b.t - trigger * DT, 0.0, None)
    walked = np.where(tau < t_ramp, 0.5 * accel * tau**2, dist_ramp + v_p * (tau - t_ramp))
    y = y0 - side * walked
    t_reach = t_ramp + (abs(y0) - dist_ramp) / v_p  # when it reaches the lane centre
    arrive = trigger * DT + t_reach + rng.uniform(-0.3, 0.2)
    x_ped = v_e * arrive + CAR_EXTENTS[0][0] + PEDESTRIAN_EXTENT[0]
    partner = b.add(
        np.stack([np.full_like(y, x_ped), y], -1), PEDESTRIAN, PEDESTRIAN_EXTENT, -side * np.pi / 2
    )
    b.background(actors, v_e)
    return b.scene(straight_path(v_e * frames * DT + 100), v_e, v_e, partner, trigger, "keep_lane")


def left_turn(rng: np.random.Generator, frames: int, actors: int) -> Scene:
    """The ego turns left across the oncoming lane as an oncoming car arrives."""
    b = _Builder(rng, "left_turn", frames)
    v_e = rng.uniform(6.0, 9.0)
    approach = rng.uniform(30.0, 45.0)
    radius = rng.uniform(9.0, 13.0)
    v_p = rng.uniform(9.0, 14.0)
    phi = np.arccos(1.0 - LANE / radius)
    x_conflict = approach + radius * np.sin(phi)
    t_conflict = (approach + radius * phi) / v_e + rng.uniform(-0.25, 0.25)
    x0 = x_conflict + v_p * t_conflict
    ext = b.car()
    x = x0 - v_p * b.t
    partner = b.add(np.stack([x, np.full_like(x, -LANE)], -1), VEHICLE, ext, np.pi)
    b.background(actors, v_e, left_side=False)
    trigger = 1
    path = left_turn_path(approach, radius, v_e * frames * DT + 60)
    return b.scene(path, v_e, v_e, partner, trigger, "frozen")


def cruise(rng: np.random.Generator, frames: int, actors: int) -> Scene:
    """A long conflict-free drive among traffic and pedestrians that stays around the ego."""
    b = _Builder(rng, "cruise", frames)
    v_e = rng.uniform(10.0, 14.0)
    span = 100.0
    lanes = np.array([LANE, -LANE, 2 * LANE, -2 * LANE])
    kinds = rng.random(actors) < 0.7
    for vehicle in kinds:
        if vehicle:
            y = lanes[rng.integers(0, lanes.size)]
            v = v_e * rng.uniform(0.8, 1.2) if y > 0 else -rng.uniform(8.0, 15.0)
            extent, kind = b.car(), VEHICLE
        else:
            y = float(rng.choice([-1.0, 1.0])) * rng.uniform(9.0, 11.0)
            v = float(rng.choice([-1.0, 1.0])) * rng.uniform(0.8, 1.6)
            extent, kind = PEDESTRIAN_EXTENT, PEDESTRIAN
        rel = rng.uniform(-span, span) + (v - v_e) * b.t
        rel = (rel + span) % (2 * span) - span
        x = v_e * b.t + rel
        b.add(np.stack([x, np.full_like(x, y)], -1), kind, extent, 0.0 if v >= 0 else np.pi)
    return b.scene(straight_path(v_e * frames * DT + 300), v_e, v_e, -1, 0, "stale")


BUILDERS: dict[str, Callable[[np.random.Generator, int, int], Scene]] = {
    "cut_in": cut_in,
    "lead_braking": lead_braking,
    "pedestrian_crossing": pedestrian_crossing,
    "left_turn": left_turn,
    "cruise": cruise,
}
