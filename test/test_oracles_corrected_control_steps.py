"""Control steps and floors read a block of frames at a time give bit for bit what each
frame read on its own gives, and leave every step that reports a problem to the single-step
path (so the problems reported, and their order, are the same)."""

from __future__ import annotations

import math
import random

import numpy as np

from ads_rca.foundation.geometry import world_to_ego
from ads_rca.model import EgoPose, Plan, RunLog, RunMetadata
from ads_rca.oracles.base import RunContext
from ads_rca.oracles.corrected.context import corrected_context
from ads_rca.oracles.corrected.control import (
    BLOCK,
    FLOOR_BLOCKS,
    Step,
    _control_floors,
    _control_step,
    _steps,
    _steps_one_by_one,
    control_floors,
    ego_offset,
    step_block,
)
from ads_rca.oracles.corrected.floors import Floor
from ads_rca.params import make_params

TPF = 50


def bits(step: Step) -> tuple[str, str, str, str]:
    """A step's four values as exact hex (NaN equals NaN)."""
    values = (step.speed, step.lateral, step.decel, step.curve)
    return (float.hex(values[0]), float.hex(values[1]), float.hex(values[2]), float.hex(values[3]))


def hostile_log(seed: int, frames: int = 3 * BLOCK, rough: float = 1.0) -> RunLog:
    """Random plans (shuffled and repeated keys, no step 0 or 1, one point, repeated points,
    NaN points, a non-integer key, an empty plan) and poses (random yaws, NaN, infinite
    speed, gaps); ``rough`` scales how often an input is hostile."""
    rng = random.Random(seed)
    odd = rough * 0.2
    log = RunLog(metadata=RunMetadata(TPF, (1.3, 0.0, 1.8), -1, frames), frames=())
    for f in range(frames + 1):
        t = f * TPF
        if rng.random() > odd / 2:
            x = math.nan if rng.random() < odd / 6 else rng.uniform(-50.0, 50.0)
            yaw, v = rng.uniform(-360, 360), math.inf if rng.random() < odd / 6 else 3.0
            log.pose[t] = EgoPose(x, rng.uniform(-50, 50), 0, 0, 0, yaw, v)
        n = rng.choice((0, 1, 2, 5, 5, 5, 8)) if rng.random() < odd * 5 else 5
        keys = [str(k) for k in range(n)]
        if n and rng.random() < odd:
            keys[rng.randrange(n)] = rng.choice(("0", "1", "7", "x", "1.5", "40"))
        if rng.random() < odd * 1.5:
            rng.shuffle(keys)
        xy = np.array([[rng.uniform(-60, 60), rng.uniform(-60, 60)] for _ in keys]).reshape(-1, 2)
        if n > 2 and rng.random() < odd:
            xy[1] = xy[0]  # a zero-length segment
        if n and rng.random() < odd / 4:
            xy[rng.randrange(n), rng.randrange(2)] = math.nan
        speed = np.array([rng.uniform(0, 20) for _ in keys])
        if rng.random() > odd / 4:
            log.waypoints[t] = Plan(tuple(keys), xy, speed)
    log.frames = tuple(f * TPF for f in range(frames) if rng.random() > odd / 10)
    return log


def floor_bits(floors: tuple[Floor, Floor]) -> list[tuple[str, int, str]]:
    return [(float.hex(f.value), f.frames, f.basis) for f in floors]


def test_a_block_of_control_floors_is_each_frames_own_floor_bit_for_bit() -> None:
    # floors of 10 and 11 frames (9 and 10 differences: the odd and the even median) two
    # frames before ts, on random logs with gaps, missing inputs and infinite speeds: the
    # block reading and the single one agree on every floor and on the problems reported
    used = 0
    for seed in range(30):
        log = hostile_log(seed, 4 * BLOCK, 0.05 if seed % 3 else 1.0)
        floor_s = 0.5 if seed % 2 else 0.55
        params = make_params(
            "corrected",
            {"effect_time_window": 2, "window_s": 0.1, "noise_floor_s": floor_s},
        )
        fast = corrected_context(RunContext(log, params))
        slow = corrected_context(RunContext(log, params))
        for judging in (fast, slow):
            assert len(judging.ego_half) == 2  # the first plan build's report, in both
        for ts in log.frames:
            got, want = control_floors(fast, ts), _control_floors(slow, ts)
            assert floor_bits(got) == floor_bits(want), (seed, ts)
            block = fast.cache(FLOOR_BLOCKS).lookup(ts // (BLOCK * TPF))
            used += block is not None and block.floors[ts // TPF % BLOCK] is not None
        assert list(fast.ctx.problems) == list(slow.ctx.problems)
    assert used > 1000  # most floors were read by blocks


def test_a_block_of_steps_is_each_frames_own_step_bit_for_bit() -> None:
    # 40 random logs x 96 frames: every frame's block step equals the single-step reading
    # of a fresh context, and a block leaves a frame out exactly when that reading reports
    # a problem or finds an input missing
    checked = 0
    for seed in range(40):
        log = hostile_log(seed)
        params = make_params("corrected")
        block_judging = corrected_context(RunContext(log, params))
        for start in range(0, 3 * BLOCK * TPF, BLOCK * TPF):
            block = step_block(block_judging, start)
            for i, got in enumerate(block.steps):
                ctx = RunContext(log, params)
                want = _control_step(corrected_context(ctx), start + i * TPF)
                # (the ego's missing extent is reported by whichever plan build is first)
                found = [p for p in ctx.problems if p.field != "ego extent"]
                silent = isinstance(want, Step) and not found
                assert (got is not None) == silent, (seed, start + i * TPF)
                if got is not None:
                    assert isinstance(want, Step)
                    assert bits(got) == bits(want), (seed, start + i * TPF)
                    checked += 1
        assert not block_judging.ctx.problems  # reading a block reports nothing
    assert checked > 1000  # the blocks did most of the work


def test_the_partner_offset_is_world_to_egos_bit_for_bit() -> None:
    # random points, poses and yaws (multiples of 90 degrees, huge and NaN included): the
    # scalar reading gives world_to_ego's bits
    rng = np.random.default_rng(5)
    yaws = [0.0, 90.0, -180.0, 270.0, 1e6, math.nan]
    for case in range(5000):
        point = rng.normal(size=2) * 10.0 ** rng.integers(-2, 5)
        x, y = (rng.normal(size=2) * 10.0 ** rng.integers(-2, 5)).tolist()
        yaw = yaws[case % 6] if case % 3 == 0 else float(rng.uniform(-720, 720))
        want = world_to_ego(point, np.array([x, y]), yaw)
        got = ego_offset(point, x, y, yaw)
        assert np.array(got).tobytes() == np.asarray(want, dtype=np.float64).tobytes()


def test_a_horizon_sliced_from_blocks_is_the_one_by_one_reading() -> None:
    # 30 random logs x 128 frames (horizons of 1, 10 and 40 frames: within a block, across
    # two, longer than one): the steps _steps returns (sliced from one or two blocks where
    # every step is silent) are those the step-by-step loop of a fresh context returns, the
    # same objects' bits, the same stop, and the same problems in the same order
    sliced = 0
    for seed in range(30):
        log = hostile_log(seed, 4 * BLOCK, 0.05 if seed % 2 else 1.0)
        params = make_params("corrected", {"control_horizon": (1, 10, 40)[seed % 3]})
        horizon = int(params.control_horizon)
        fast = corrected_context(RunContext(log, params))
        slow = corrected_context(RunContext(log, params))
        for judging in (fast, slow):
            assert len(judging.ego_half) == 2  # the first plan build's report, in both
        for ts in log.frames:
            got, stop, missing = _steps(fast, ts)
            want, want_stop, want_missing = _steps_one_by_one(slow, ts, horizon)
            assert [bits(s) for s in got] == [bits(s) for s in want], (seed, ts)
            assert (stop, missing) == (want_stop, want_missing), (seed, ts)
            sliced += stop is None and len(got) == horizon
        assert list(fast.ctx.problems) == list(slow.ctx.problems), seed
    assert sliced > 1000  # most horizons were whole
