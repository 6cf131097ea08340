"""The control rule: control is judged on tracking over a horizon, in the partner's direction.

For each step t = ts … ts + (``control_horizon`` − 1)·frame_ms the speed innovation is the
realised speed at t + frame_ms minus plan[t]'s index-1 speed, and the lateral innovation the
signed offset of the realised position at t + frame_ms from plan[t]'s polyline (sign of the
ego-frame y axis at t). Signed sums cancel noise; the sums stop at the first missing input.
Tracking fails when |Σ speed| exceeds max(``control_speed_threshold``, ``actuator_delay`` ×
the largest commanded deceleration) or |Σ lateral| exceeds ``control_lateral_threshold``.
It concerns the partner only when the deviation points toward it: faster than planned with
the partner ahead (slower with it behind), or drift to its side. There is no speed gate:
exact tracking never fires, and a real deviation fires at any speed.

Each frame's horizon adds one step, and a step costs a handful of numpy calls on a ~30-point
plan, so steps are read a block of frames at a time (one array pass over their plans), and only
a step that reports a problem is read on its own; so are the floors (the noise-floor rule): a
block of frames whose floor frames all have such steps costs two sorts. A block reads only
records present when it is made and lives in the context's caches, as every per-timestamp view
does (a live monitor judges each window on a new context).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import TypeVar, cast

import numpy as np

from ads_rca.foundation.geometry import FloatArray
from ads_rca.oracles.base import Metric, OracleResult, RunContext
from ads_rca.oracles.corrected.boxes import key_steps, signed_offset, step_order
from ads_rca.oracles.corrected.common import REPORTED, skipped
from ads_rca.oracles.corrected.context import (
    CacheName,
    CorrectedContext,
    corrected_context,
    floor_span,
    window_frames,
)
from ads_rca.oracles.corrected.floors import (
    BASIS_STEPS,
    NO_FLOOR,
    Floor,
    floor_frames,
    frame_grid,
    robust_sigmas,
    step_floor,
)

_T = TypeVar("_T")


@dataclass(frozen=True)
class Step:
    """One control step t: innovations realised at t + frame_ms against plan[t]."""

    speed: float  # realised speed at t + frame_ms − plan[t]'s step-1 speed
    lateral: float  # signed offset of pose[t + frame_ms] from plan[t]'s polyline
    decel: float  # commanded deceleration (step-0 − step-1 speed) / dt; NaN without step 0
    curve: float  # lateral acceleration plan[t] asks for: step-1 speed² × |curvature|


#: A step, or the first missing (folder, timestamp) it needs.
CONTROL_STEP: CacheName[Step | tuple[str, int]] = CacheName("control_step")

#: Frames whose steps are computed together (one array pass over their plans).
BLOCK = 32


@dataclass(frozen=True)
class StepBlock:
    """The steps at ``start`` + i·frame_ms, i < :data:`BLOCK`; None where the step cannot be
    read without a problem report (a missing input, a plan with no step 1 or a non-integer
    key): those take :func:`_control_step`'s path, which reports."""

    start: int
    steps: list[Step | None]


#: Step blocks by block number (timestamp // (BLOCK · frame_ms)).
STEP_BLOCKS: CacheName[StepBlock] = CacheName("control_step_blocks")


def control_step(judging: CorrectedContext, t: int) -> Step | tuple[str, int]:
    """The step at t, or the first missing input: from t's block of steps where it could
    be read silently, else on its own (cached: overlapping horizons share it)."""
    step = block_step(judging, t)
    return step if step is not None else _control_step(judging, t)


def block_step(judging: CorrectedContext, t: int) -> Step | None:
    """The step at t from its block, None where it must be read on its own (it reports a
    problem, t is off the frame grid, or no plan was built yet: the first build reports
    an ego without extent, and must come first)."""
    block = block_of(judging, t)
    return None if block is None else block.steps[(t - block.start) // judging.frame_ms]


def block_of(judging: CorrectedContext, t: int) -> StepBlock | None:
    """The block of steps t belongs to (None off the frame grid or before any plan build)."""
    frame_ms = judging.frame_ms
    if t % frame_ms:
        return None
    blocks = judging.cache(STEP_BLOCKS)
    number = t // (BLOCK * frame_ms)
    block = blocks.lookup(number)
    if block is None:
        if "ego_half" not in vars(judging):
            return None
        block = step_block(judging, number * BLOCK * frame_ms)
        blocks.put(number, block)
    return block


def step_block(judging: CorrectedContext, start: int) -> StepBlock:
    """The steps of the frames start + i·frame_ms, i < :data:`BLOCK`, in one pass per key layout:
    the same IEEE operations as :meth:`PlanData.lateral_offset`, so the same values."""
    frame_ms = judging.frame_ms
    pose, plans = judging.log.pose, judging.log.waypoints
    groups: dict[tuple[str, ...], list[int]] = {}
    for i in range(BLOCK):
        t = start + i * frame_ms
        plan = plans.get(t)
        if plan is not None and len(plan) and t in pose and t + frame_ms in pose:
            groups.setdefault(plan.keys, []).append(i)
    steps: list[Step | None] = [None] * BLOCK
    for keys, members in groups.items():
        values = key_steps(keys)
        times = [start + i * frame_ms for i in members]
        shapes = ((len(keys), 2), (len(keys),))
        if (values < 0).any() or any(
            (plans[t].xy.shape, plans[t].speed.shape) != shapes for t in times
        ):
            continue  # a non-integer key (the plan build reports it) or a malformed plan
        order, sorted_steps = step_order(keys, int(values.max()) + 1)
        rows = {step: row for row, step in enumerate(sorted_steps.tolist())}
        if 1 not in rows:
            continue
        before = [pose[t] for t in times]
        after = [pose[t + frame_ms] for t in times]
        # (np.array of same-shape arrays: np.stack's copy without its per-array Python work)
        xy = np.array([plans[t].xy for t in times])[:, order]
        lateral = _lateral_offsets(
            xy, np.array([[p.x, p.y] for p in after]), [p.yaw for p in before]
        )
        speed = np.array([plans[t].speed for t in times])[:, order]
        v1 = speed[:, rows[1]].tolist()
        v0 = speed[:, rows[0]].tolist() if 0 in rows else [math.nan] * len(times)
        curves = lateral_demands(xy[:, sorted_steps >= 1], speed[:, rows[1]])
        for n, i in enumerate(members):
            steps[i] = _step(
                after[n].speed - v1[n],
                lateral[n],
                (v0[n] - v1[n]) / (frame_ms / 1000.0),
                curves[n],
            )
    return StepBlock(start, steps)


def _step(speed: float, lateral: float, decel: float, curve: float) -> Step:
    """``Step(speed, lateral, decel, curve)`` (a block makes 32)."""
    return _made(Step, speed=speed, lateral=lateral, decel=decel, curve=curve)


#: Plan points from step 1 over which a plan's curvature is read (about 0.5 s at 20 Hz).
CURVATURE_POINTS = 11
#: Shorter segments (m) give no heading worth reading: a plan of a car at a standstill.
CURVATURE_MIN_SEGMENT = 0.1


def lateral_demands(ahead: FloatArray, speed_1: FloatArray) -> list[float]:
    """The lateral acceleration each plan asks for near its start: its step-1 speed² ×
    |curvature|, the curvature being the heading change from the segment of its first two
    points ``ahead`` (K, M, 2: from step 1, in step order) to the segment ending at its
    :data:`CURVATURE_POINTS`-th, over the distance between those segments' midpoints (0
    with fewer than three points, a segment shorter than :data:`CURVATURE_MIN_SEGMENT`, or
    a value that is not finite)."""
    points = ahead[:, :CURVATURE_POINTS]
    if points.shape[1] < 3:
        return [0.0] * len(ahead)
    first = points[:, 1] - points[:, 0]
    last = points[:, -1] - points[:, -2]
    turn = np.arctan2(last[:, 1], last[:, 0]) - np.arctan2(first[:, 1], first[:, 0])
    turn = (turn + math.pi) % (2.0 * math.pi) - math.pi
    gap = 0.5 * (points[:, -1] + points[:, -2] - points[:, 1] - points[:, 0])
    distance = np.hypot(gap[:, 0], gap[:, 1])
    with np.errstate(divide="ignore", invalid="ignore"):
        demand = speed_1 * speed_1 * np.abs(turn) / distance
    shortest = np.minimum(np.hypot(first[:, 0], first[:, 1]), np.hypot(last[:, 0], last[:, 1]))
    usable = np.isfinite(demand) & (distance > 0.0) & (shortest >= CURVATURE_MIN_SEGMENT)
    return cast("list[float]", np.where(usable, demand, 0.0).tolist())


def _made(cls: type[_T], **fields: object) -> _T:
    """The instance ``cls(**fields)`` makes, its fields put in its ``__dict__`` directly
    instead of by the frozen ``__init__``'s ``object.__setattr__`` per field."""
    made = object.__new__(cls)
    made.__dict__.update(fields)
    return made


def _lateral_offsets(xy: FloatArray, points: FloatArray, yaws: list[float]) -> list[float]:
    """:meth:`PlanData.lateral_offset` of ``points`` (K, 2) from the polylines ``xy``
    (K, M, 2), each signed by its yaw (deg)."""
    if xy.shape[1] == 1:
        start, vec, length2 = xy, np.zeros_like(xy), np.ones(xy.shape[:2])
    else:
        start, vec = xy[:, :-1], np.diff(xy, axis=1)
        length2 = vec[..., 0] * vec[..., 0] + vec[..., 1] * vec[..., 1]
        length2 = np.where(length2 > 0, length2, np.inf)
    px, py = points[:, :1] - start[..., 0], points[:, 1:] - start[..., 1]
    t = np.minimum(np.maximum((px * vec[..., 0] + py * vec[..., 1]) / length2, 0.0), 1.0)
    dx, dy = px - t * vec[..., 0], py - t * vec[..., 1]
    j = np.argmin(dx * dx + dy * dy, axis=1)
    rows = np.arange(len(j))
    return [
        signed_offset(ex, ey, yaw)
        for ex, ey, yaw in zip(dx[rows, j].tolist(), dy[rows, j].tolist(), yaws, strict=True)
    ]


def _control_step(judging: CorrectedContext, t: int) -> Step | tuple[str, int]:
    """The step at t read on its own (reporting what is missing), cached."""
    cache = judging.cache(CONTROL_STEP)
    found = cache.lookup(t)
    if found is not None:
        return found
    frame_ms = judging.frame_ms
    checks = (("pose", t), ("waypoint", t), ("pose", t + frame_ms))
    absent = [(folder, at) for folder, at in checks if at not in judging.folders[folder]]
    plan = None if absent else judging.plan(t)
    if plan is None or 1 not in plan.rows:
        if not absent:
            judging.ctx.report(judging.log.file_of("waypoint", t), "1", "plan has no step 1", t)
            return ("waypoint", t)
        for folder, at in absent:
            if judging.in_log(at):
                judging.missing(folder, at, "control tracking")
        return absent[0]
    before, after = judging.log.pose[t], judging.log.pose[t + frame_ms]
    v1 = plan.speed_of(1)
    lateral = plan.lateral_offset(after.x, after.y, before.yaw)
    (curve,) = lateral_demands(plan.xy[plan.steps >= 1][None], np.array([v1]))
    decel = (plan.speed_of(0) - v1) / (frame_ms / 1000.0)
    step = Step(after.speed - v1, lateral, decel, curve)
    cache.put(t, step)
    return step


@dataclass(frozen=True)
class FloorBlock:
    """The control floors at ``start`` + i·frame_ms, i < :data:`BLOCK`, read for the log's
    ``frames``; None where a floor frame is missing, its step is read on its own or a
    difference is not finite (:func:`_control_floors` reads those)."""

    start: int
    frames: tuple[int, ...]
    floors: list[tuple[Floor, Floor] | None]


#: Floor blocks by block number (timestamp // (BLOCK · frame_ms)).
FLOOR_BLOCKS: CacheName[FloorBlock] = CacheName("control_floor_blocks")


def control_floors(judging: CorrectedContext, ts: int) -> tuple[Floor, Floor]:
    """The noise-floor rule's speed and lateral floors at ts, from the control steps of its
    floor frames (those with every input; the robust sigma of consecutive steps' differences):
    from ts's block of floors where every floor frame has a silent step, else on its own."""
    frame_ms = judging.frame_ms
    if ts % frame_ms == 0 and "ego_half" in vars(judging):
        blocks = judging.cache(FLOOR_BLOCKS)
        number = ts // (BLOCK * frame_ms)
        block = blocks.lookup(number)
        if block is None or block.frames is not judging.log.frames:
            block = floor_block(judging, number * BLOCK * frame_ms)
            blocks.put(number, block)
        found = block.floors[(ts - block.start) // frame_ms]
        if found is not None:
            return found
    return _control_floors(judging, ts)


def floor_block(judging: CorrectedContext, start: int) -> FloorBlock:
    """The floors of a block of frames whose floor frames are all present with silent
    steps: consecutive floor frames, so each frame's differences are a window of one
    difference array, and all the robust sigmas are two sorts."""
    frame_ms = judging.frame_ms
    span = floor_span(judging.params, frame_ms)
    length = span - window_frames(judging.params, frame_ms)  # floor frames per frame (L)
    floors: list[tuple[Floor, Floor] | None] = [None] * BLOCK
    block = FloorBlock(start, judging.log.frames, floors)
    if length < 2:
        return block
    first = start - span * frame_ms
    found = _silent_steps(judging, first, BLOCK - 1 + length)
    values = np.array(
        [
            [math.nan if s is None else s.speed for s in found],
            [math.nan if s is None else s.lateral for s in found],
        ]
    )
    with np.errstate(invalid="ignore"):  # inf − inf: a NaN difference, not used
        diffs = np.diff(values, axis=1)
    windows = np.lib.stride_tricks.sliding_window_view(diffs, length - 1, axis=1)
    # Frame i reads steps i … i + L − 1 through differences i … i + L − 2; a missing step k
    # there (NaN) makes difference k − 1 or k (one is in that range as L >= 2) NaN: so the
    # frames whose every step is present are among those whose differences are all finite.
    use = np.flatnonzero(np.isfinite(windows).all(axis=(0, 2)))
    if use.size == 0:
        return block
    count = length - 1
    if count < max(int(judging.params.noise_floor_min_frames), 1):
        for i in use.tolist():
            floors[i] = (NO_FLOOR, NO_FLOOR)
        return block
    sigmas = robust_sigmas(windows[:, use]).tolist()
    for n, i in enumerate(use.tolist()):
        floors[i] = (_floor(sigmas[0][n], count), _floor(sigmas[1][n], count))
    return block


def _floor(value: float, frames: int) -> Floor:
    """``Floor(value, frames, BASIS_STEPS)`` (a block makes 64)."""
    return _made(Floor, value=value, frames=frames, basis=BASIS_STEPS)


def _silent_steps(judging: CorrectedContext, first: int, count: int) -> list[Step | None]:
    """The silent steps (:func:`block_step`) of the frames first + k·frame_ms, k < count, None
    where that frame is not in the log or its step is read on its own."""
    frame_ms = judging.frame_ms
    out: list[Step | None] = []
    while len(out) < count:
        u = first + len(out) * frame_ms
        block = block_of(judging, u)
        if block is None:
            out.append(None)
            continue
        i = (u - block.start) // frame_ms
        out.extend(block.steps[i : i + count - len(out)])
    grid = frame_grid(judging)
    if grid is not None and grid[0] % frame_ms == 0:  # frames every frame_ms from lo to hi (as u)
        lo, hi = grid
        return [s if lo <= first + k * frame_ms <= hi else None for k, s in enumerate(out)]
    frames = judging.frame_set()
    return [s if first + k * frame_ms in frames else None for k, s in enumerate(out)]


def _control_floors(judging: CorrectedContext, ts: int) -> tuple[Floor, Floor]:
    """:func:`control_floors` read on its own (sliding from the last one read)."""
    found = judging.slide(CONTROL_STEP).read(
        floor_frames(judging, ts), lambda u: control_step(judging, u)
    )
    steps = [s for s in found if isinstance(s, Step)]
    minimum = int(judging.params.noise_floor_min_frames)
    return (
        step_floor([s.speed for s in steps], minimum),
        step_floor([s.lateral for s in steps], minimum),
    )


#: Steps read from ts, why they stopped (None: the whole horizon) and whether the stop was
#: an input the run should hold (inside it), not the end of the recording.
Steps = tuple[list[Step], str | None, bool]


def _steps(judging: CorrectedContext, ts: int) -> Steps:
    """The usable steps from ts, stopping at the first missing input, and why it stopped."""
    frame_ms = judging.frame_ms
    horizon = max(int(judging.params.control_horizon), 0)
    block = block_of(judging, ts)
    if block is not None:  # the usual case: every step silent, sliced from one or two blocks
        i = (ts - block.start) // frame_ms
        silent = block.steps[i : i + horizon]
        if len(silent) < horizon:
            after = block_of(judging, block.start + BLOCK * frame_ms)
            if after is not None:
                silent = silent + after.steps[: horizon - len(silent)]
        # (an identity test: ``None in`` would call Step.__eq__ on every step)
        if len(silent) == horizon and all(step is not None for step in silent):
            return cast("list[Step]", silent), None, False
    return _steps_one_by_one(judging, ts, horizon)


def _steps_one_by_one(judging: CorrectedContext, ts: int, horizon: int) -> Steps:
    """:func:`_steps` where some step is read on its own (and may report a problem)."""
    steps: list[Step] = []
    frame_ms = judging.frame_ms
    block: StepBlock | None = None
    for j in range(horizon):
        t = ts + j * frame_ms
        if block is None or t - block.start >= BLOCK * frame_ms:  # a horizon spans two blocks
            block = block_of(judging, t)
        silent = None if block is None else block.steps[(t - block.start) // frame_ms]
        step = silent if silent is not None else _control_step(judging, t)
        if not isinstance(step, Step):
            return steps, f"missing {step[0]} at {step[1]} ms", judging.in_log(step[1])
        steps.append(step)
    return steps, None, False


def control(ctx: RunContext, ts: int) -> OracleResult:
    """The control rule at ts, with tracking-error metrics."""
    judging = corrected_context(ctx)
    p = judging.params
    thresholds: dict[str, float] = judging.reported(REPORTED["controller"])
    steps, stop, missing = _steps(judging, ts)
    if not steps:
        reason = stop or "no control step"
        return skipped("controller", ts, reason, thresholds=thresholds, missing_input=missing)
    speeds, laterals = [s.speed for s in steps], [s.lateral for s in steps]
    sum_v, sum_lat = exact_sum(speeds), exact_sum(laterals)
    decels = [s.decel for s in steps if math.isfinite(s.decel)]
    max_decel = max(decels) if decels else math.nan
    speed_floor, lateral_floor = control_floors(judging, ts)
    # noise floors: the summed noise of n steps grows as sqrt(n); 2 sigma of it is not a fault
    spread = p.noise_floor_factor * 2.0 * math.sqrt(len(steps))
    thr_v = max(p.control_speed_threshold, spread * speed_floor.value)
    if decels:
        thr_v = max(thr_v, p.actuator_delay * max_decel)
    # a path follower's lag on a curved plan (rule 5, "Curves")
    demands = [s.curve for s in steps]
    curve_allowance = p.actuator_delay * p.actuator_delay * exact_sum(demands)
    thr_lat = max(p.control_lateral_threshold, spread * lateral_floor.value) + curve_allowance
    thresholds["speed_threshold"] = thr_v
    thresholds["lateral_threshold"] = thr_lat
    speed_fail = abs(sum_v) > thr_v
    lateral_fail = abs(sum_lat) > thr_lat
    metrics: dict[str, Metric] = {
        "steps": len(steps),
        "stopped_at": stop,
        "sum_speed_innovation": sum_v,
        "sum_lateral_innovation": sum_lat,
        "speed_threshold": thr_v,
        "lateral_threshold": thr_lat,
        "curve_allowance": curve_allowance,
        "max_lateral_acceleration": max(demands),
        **speed_floor.metrics("speed"),
        **lateral_floor.metrics("lateral"),
        "max_commanded_decel": max_decel,
        "tracking_failure": bool(speed_fail or lateral_fail),
        "speed_tracking_error": exact_sum(map(abs, speeds)) / len(steps),
        "lateral_tracking_error": exact_sum(map(abs, laterals)) / len(steps),
        "first_step_speed_error": steps[0].speed,
        "first_step_lateral_error": steps[0].lateral,
    }
    partner = judging.partner_at(ts)
    state = judging.actor_state(partner, ts) if partner is not None else None
    if partner is None or state is None:
        metrics["toward_partner"] = None
        return OracleResult("controller", ts, False, metrics, thresholds, missing_input=missing)
    pose = judging.log.pose[ts]
    rx, ry = ego_offset(state[0], pose.x, pose.y, pose.yaw)
    toward = bool(
        (sum_v > thr_v and rx > 0)
        or (sum_v < -thr_v and rx < 0)
        or (lateral_fail and sum_lat * ry > 0)
    )
    metrics.update(partner_rx=float(rx), partner_ry=float(ry), toward_partner=toward)
    return OracleResult(
        "controller", ts, toward, metrics, thresholds, (partner,), missing_input=missing
    )


def exact_sum(values: Iterable[float]) -> float:
    """``math.fsum`` (signed sums cancel exactly), or where a partial sum passes the float
    range (a log's numbers may be as large as a double goes) what plain addition gives:
    ±infinity, or NaN when both signs overflow, which the rules judge as they say."""
    items = list(values)
    try:
        return math.fsum(items)
    except OverflowError:
        with np.errstate(over="ignore", invalid="ignore"):
            return float(np.sum(np.asarray(items, dtype=np.float64)))


def ego_offset(point: FloatArray, x: float, y: float, yaw_deg: float) -> tuple[float, float]:
    """:func:`~ads_rca.foundation.geometry.world_to_ego` of one world point (2,) from the pose
    (x, y, yaw): the same ufuncs and IEEE operations on scalars, so the same values,
    without the array calls that cost more than the arithmetic."""
    theta = np.deg2rad(yaw_deg)
    c, s = np.cos(theta), np.sin(theta)
    dx, dy = float(point[0]) - x, float(point[1]) - y
    return float(dx * c + dy * s), float(-dx * s + dy * c)
