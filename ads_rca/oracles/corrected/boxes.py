"""Oriented boxes over the horizon: the ego's plan boxes and an actor's predicted boxes.

The `corrected` rules compare boxes index by index (index i = i frames after ts). This module
turns a plan or a predicted track into such a series (rules' "Geometry" section): keys are
read as integers, sorted, first occurrence kept; headings follow the path, keeping the
previous heading where the motion is too short to give one. Key parsing and ordering are
memoised per key tuple, since nearly every track and plan of a log has the same keys.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property, lru_cache

import numpy as np
import numpy.typing as npt

from ads_rca.foundation.geometry import FloatArray, along_polyline, ego_to_world
from ads_rca.model import EgoPose, Plan, Track, step_value
from ads_rca.oracles.cache import LRU

#: Plan headings from neighbouring points shorter than this keep the previous heading.
PLAN_HEADING_MIN_STEP = 1e-3

_KEY_STEPS_MAX = 256
_KEY_STEPS: LRU[tuple[str, ...], npt.NDArray[np.int64]] = LRU(_KEY_STEPS_MAX)


def key_steps(keys: tuple[str, ...]) -> npt.NDArray[np.int64]:
    """Integer value of each step key (-1 where not an integer), memoised per key tuple:
    nearly every track and plan of a log has the same keys."""
    found = _KEY_STEPS.lookup(keys)
    if found is None:
        found = np.array([step_value(k) for k in keys], dtype=np.int64)
        found.flags.writeable = False
        _KEY_STEPS.put(keys, found)
    return found


_ALL_STEPS: LRU[tuple[str, ...], bool] = LRU(_KEY_STEPS_MAX)


def all_steps(keys: tuple[str, ...]) -> bool:
    """Whether every key is an integer step (:func:`key_steps` has no -1), memoised per key
    tuple: asked of every plan, where the array test costs more than the lookup."""
    found = _ALL_STEPS.lookup(keys)
    if found is None:
        found = not bool((key_steps(keys) < 0).any())
        _ALL_STEPS.put(keys, found)
    return found


@dataclass(frozen=True)
class Series:
    """One object's oriented boxes at horizon indices 0..W (NaN rows where it has none)."""

    center: FloatArray  # (W + 1, 2) world metres
    yaw: FloatArray  # (W + 1,) degrees
    half: FloatArray  # (2,) half extents

    @cached_property
    def present(self) -> npt.NDArray[np.bool_]:
        """Indices with a box (read-only: shared by every user of the series)."""
        out = np.isfinite(self.center[:, 0]) & np.isfinite(self.center[:, 1])
        out &= np.isfinite(self.yaw)
        out.flags.writeable = False
        return out


@dataclass(frozen=True)
class PlanData:
    """One plan: its integer-step points in step order, speeds, and the ego's plan boxes."""

    steps: np.ndarray  # (M,) ascending, unique, >= 0
    xy: FloatArray  # (M, 2)
    speed: FloatArray  # (M,)
    boxes: Series  # ego plan boxes at indices 0..W
    speed_at: FloatArray  # (W + 1,) plan speed at index i (NaN where the plan has no step i)
    rows: dict[int, int] = field(default_factory=dict)  # step -> row

    def point(self, step: int) -> FloatArray | None:
        row = self.rows.get(step)
        return None if row is None else self.xy[row]

    def speed_of(self, step: int) -> float:
        row = self.rows.get(step)
        return float("nan") if row is None else float(self.speed[row])

    @cached_property
    def _segments(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Segment starts (S, 2), vectors (S, 2) and squared lengths (inf if zero)."""
        if len(self.xy) == 1:
            return self.xy, np.zeros((1, 2)), np.ones(1)
        start, vec = self.xy[:-1], np.diff(self.xy, axis=0)
        length2 = vec[:, 0] * vec[:, 0] + vec[:, 1] * vec[:, 1]
        return start, vec, np.where(length2 > 0, length2, np.inf)  # t = 0 on empty segments

    def lateral_offset(self, x: float, y: float, yaw_deg: float) -> float:
        """Distance from (x, y) to the nearest point q of the plan polyline, signed by
        (−sin ψ, cos ψ)·(p − q) with ψ = ``yaw_deg`` (the ego-frame y axis)."""
        start, vec, length2 = self._segments
        px, py = x - start[:, 0], y - start[:, 1]
        t = np.minimum(np.maximum((px * vec[:, 0] + py * vec[:, 1]) / length2, 0.0), 1.0)
        dx, dy = px - t * vec[:, 0], py - t * vec[:, 1]
        j = int(np.argmin(dx * dx + dy * dy))
        return signed_offset(float(dx[j]), float(dy[j]), yaw_deg)


def signed_offset(ex: float, ey: float, yaw_deg: float) -> float:
    """|(ex, ey)|, negative where (ex, ey) points to the right of heading ``yaw_deg``
    (the sign of (−sin ψ, cos ψ)·(ex, ey)): a lateral offset from its nearest point."""
    theta = math.radians(yaw_deg)
    side = -math.sin(theta) * ex + math.cos(theta) * ey
    distance = math.hypot(ex, ey)
    return -distance if side < 0 else distance


def forward_fill(values: FloatArray, valid: np.ndarray) -> FloatArray:
    """``values`` with invalid entries replaced by the last valid one (entry 0 must be valid)."""
    idx = np.where(valid, np.arange(len(values)), 0)
    np.maximum.accumulate(idx, out=idx)
    return values[idx]


def step_order(keys: tuple[str, ...], limit: int) -> tuple[np.ndarray, np.ndarray]:
    """Rows of the integer keys 0 <= k < limit in ascending step order (a repeated step keeps
    its first row), and those steps; memoised per key tuple."""
    memo_key = (keys, limit)
    found = _ORDER.lookup(memo_key)
    if found is None:
        steps = key_steps(keys)
        keep = np.flatnonzero((steps >= 0) & (steps < limit))
        order = keep[np.argsort(steps[keep], kind="stable")]
        k = steps[order]
        first = np.concatenate(([True], k[1:] != k[:-1])) if k.size else np.zeros(0, bool)
        found = (order[first], k[first])
        _ORDER.put(memo_key, found)
    return found


_ORDER: LRU[tuple[tuple[str, ...], int], tuple[np.ndarray, np.ndarray]] = LRU(_KEY_STEPS_MAX)
_NO_LIMIT = 1 << 62


@dataclass(frozen=True)
class _PlanLayout:
    """Where a plan's points go, the same for every plan with the same keys and window."""

    order: npt.NDArray[np.intp]  # rows of the integer steps >= 0, in step order
    steps: npt.NDArray[np.int64]  # those steps
    rows: dict[int, int]  # step -> row in that order (shared: read only)
    nxt: npt.NDArray[np.intp]  # heading neighbours of the first m sorted points
    prv: npt.NDArray[np.intp]
    from_zero: bool  # the first sorted step is 0 (its heading is the pose yaw)
    take: npt.NDArray[np.intp]  # the first m sorted points at horizon indices <= W
    index: npt.NDArray[np.int64]  # their horizon indices


def _plan_layout(keys: tuple[str, ...], window: int) -> _PlanLayout | None:
    """The layout of plans with ``keys`` (None without an integer step), memoised: nearly
    every plan of a log has the same keys, so only its values are new."""
    memo_key = (keys, window)
    found = _LAYOUTS.lookup(memo_key)
    if found is None:
        order, steps = step_order(keys, _NO_LIMIT)
        if order.size == 0:
            return None
        # Boxes need indices 0..W, hence headings of the first W + 1 sorted points at most
        # (their neighbours reach W + 2 points).
        m = min(len(order), window + 2)
        take = np.flatnonzero(steps[:m] <= window)
        found = _PlanLayout(
            order=order,
            steps=steps,
            rows={step: row for row, step in enumerate(steps.tolist())},
            nxt=np.minimum(np.arange(1, m + 1), len(order) - 1),
            prv=np.maximum(np.arange(-1, m - 1), 0),
            from_zero=bool(steps[0] == 0),
            take=take,
            index=steps[take],
        )
        _LAYOUTS.put(memo_key, found)
    return found


_LAYOUTS: LRU[tuple[tuple[str, ...], int], _PlanLayout | None] = LRU(_KEY_STEPS_MAX)


def build_plan(plan: Plan, pose: EgoPose, ego_half: FloatArray, window: int) -> PlanData | None:
    """Plan points in step order and the ego's plan boxes (heading along the path)."""
    layout = _plan_layout(plan.keys, window)
    if layout is None:
        return None
    xy = plan.xy[layout.order]
    speed = plan.speed[layout.order]
    # Heading along P[j+1] - P[j-1] (P[j] - P[j-1] at the last point; pose yaw at j = 0).
    vec = xy[layout.nxt] - xy[layout.prv]
    heading = np.rad2deg(np.arctan2(vec[:, 1], vec[:, 0]))
    valid = vec[:, 0] * vec[:, 0] + vec[:, 1] * vec[:, 1] >= PLAN_HEADING_MIN_STEP**2
    if layout.from_zero or not valid[0]:
        heading[0], valid[0] = pose.yaw, True
    if not valid.all():
        heading = forward_fill(heading, valid)
    center, yaw, speed_at = _nan_rows(window)
    take, index = layout.take, layout.index
    center[index], yaw[index], speed_at[index] = xy[take], heading[take], speed[take]
    boxes = Series(center, yaw, ego_half)
    return PlanData(layout.steps, xy, speed, boxes, speed_at, layout.rows)


def build_plans(
    plans: Sequence[Plan], poses: Sequence[EgoPose], ego_half: FloatArray, window: int
) -> list[PlanData | None]:
    """:func:`build_plan` of each (plan, pose), plans with the same keys and shapes (nearly
    every plan of a log) as rows of one array: the same elementwise operations, so the same
    values, in a few calls for the lot instead of a dozen per plan."""
    first = plans[0] if plans else None
    if (
        first is None
        or len(plans) == 1
        or not all(
            p.keys == first.keys
            and p.xy.shape == first.xy.shape
            and p.speed.shape == first.speed.shape
            and p.xy.dtype == first.xy.dtype == p.speed.dtype == first.speed.dtype
            for p in plans
        )
    ):
        return [build_plan(p, pose, ego_half, window) for p, pose in zip(plans, poses, strict=True)]
    layout = _plan_layout(first.keys, window)
    if layout is None:
        return [None] * len(plans)
    xy = np.array([p.xy for p in plans])[:, layout.order]
    speed = np.array([p.speed for p in plans])[:, layout.order]
    vec = xy[:, layout.nxt] - xy[:, layout.prv]
    heading = np.rad2deg(np.arctan2(vec[..., 1], vec[..., 0]))
    valid = vec[..., 0] * vec[..., 0] + vec[..., 1] * vec[..., 1] >= PLAN_HEADING_MIN_STEP**2
    yaws = np.array([pose.yaw for pose in poses], dtype=np.float64)
    use_pose = slice(None) if layout.from_zero else ~valid[:, 0]
    heading[use_pose, 0] = yaws[use_pose]
    valid[:, 0] = True
    for row in np.flatnonzero(~valid.all(axis=1)).tolist():
        heading[row] = forward_fill(heading[row], valid[row])
    count = len(plans)
    center = np.full((count, window + 1, 2), np.nan)
    yaw = np.full((count, window + 1), np.nan)
    speed_at = np.full((count, window + 1), np.nan)
    take, index = layout.take, layout.index
    center[:, index], yaw[:, index], speed_at[:, index] = (
        xy[:, take],
        heading[:, take],
        speed[:, take],
    )
    return [
        PlanData(
            layout.steps,
            xy[n],
            speed[n],
            Series(center[n], yaw[n], ego_half),
            speed_at[n],
            layout.rows,
        )
        for n in range(count)
    ]


def _nan_rows(window: int) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Fresh NaN arrays (W + 1, 2), (W + 1,) and (W + 1,): copies of a template."""
    center, yaw, speed_at = _nan_templates(window)
    return center.copy(), yaw.copy(), speed_at.copy()


@lru_cache(maxsize=16)
def _nan_templates(window: int) -> tuple[FloatArray, FloatArray, FloatArray]:
    return (
        np.full((window + 1, 2), np.nan),
        np.full(window + 1, np.nan),
        np.full(window + 1, np.nan),
    )


def build_predicted(
    track: Track,
    pose: EgoPose,
    state: tuple[FloatArray, float] | None,
    half: FloatArray,
    window: int,
    heading_min_step: float,
) -> Series:
    """Boxes of one predicted track: offset key k is k + 1 frames ahead (k < window only),
    anchored at the ego pose at ts and rotated by its yaw; heading from the predicted motion
    where a step is at least ``heading_min_step``, else the previous heading (initially the
    actor's yaw at ts, the step from its real location at ts)."""
    center = np.full((window + 1, 2), np.nan)
    yaw = np.full(window + 1, np.nan)
    order, k = step_order(track.keys, window)
    if order.size == 0:
        return Series(center, yaw, half)
    world = ego_to_world(track.offsets[order, :2], np.array([pose.x, pose.y]), pose.yaw)
    if state is not None:
        start, yaw0 = state
    else:  # the actor has no entry at ts: no step from it; start from the first motion
        start, yaw0 = world[0], float("nan")
    step = np.diff(world, axis=0, prepend=start[None, :])
    heading = np.empty(len(k) + 1)
    heading[0] = yaw0
    heading[1:] = np.rad2deg(np.arctan2(step[:, 1], step[:, 0]))
    valid = np.empty(len(k) + 1, dtype=bool)
    valid[0] = True
    valid[1:] = step[:, 0] * step[:, 0] + step[:, 1] * step[:, 1] >= heading_min_step**2
    if np.isnan(yaw0):
        moving = np.flatnonzero(valid[1:])
        heading[0] = heading[1 + moving[0]] if moving.size else 0.0
    if not valid.all():
        heading = forward_fill(heading, valid)
    center[k + 1] = world
    yaw[k + 1] = heading[1:]
    return Series(center, yaw, half)


def braking_boxes(
    plan: PlanData, yaw0: float, v0: float, decel: float, dt: float, window: int
) -> Series:
    """The ego's boxes at indices 0..W driving the plan's path from v0 braking at ``decel``
    to a stop: arc length s = v0·t − ½·a·t² (v0²/2a once stopped) from the first plan
    point, heading of the segment there (``yaw0`` where every segment has zero length)."""
    t = np.arange(window + 1) * dt
    v0 = max(v0, 0.0) if math.isfinite(v0) else 0.0
    if decel > 0:
        tau = np.minimum(t, v0 / decel)
        arc = v0 * tau - 0.5 * decel * tau * tau
    else:
        arc = v0 * t
    center, heading = along_polyline(plan.xy, arc)
    heading = np.where(np.isnan(heading), yaw0, heading)
    return Series(center, heading, plan.boxes.half)
