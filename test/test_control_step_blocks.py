"""Control steps read a block of frames at a time give bit for bit the step each frame's
own plan gives, and leave every step that reports a problem to the single-step path."""

from __future__ import annotations

import math
import random

import numpy as np

from ads_rca.model import EgoPose, Plan, RunLog, RunMetadata
from ads_rca.oracles.base import RunContext
from ads_rca.oracles.corrected.context import corrected_context
from ads_rca.oracles.corrected.control import BLOCK, Step, _control_step, step_block
from ads_rca.params import make_params

TPF = 50


def bits(step: Step) -> tuple[str, str, str]:
    """A step's three values as exact hex (NaN equals NaN)."""
    return (float.hex(step.speed), float.hex(step.lateral), float.hex(step.decel))


def hostile_log(seed: int) -> RunLog:
    """Random plans (shuffled and repeated keys, no step 0 or 1, one point, repeated points,
    NaN points, a non-integer key, an empty plan) and poses (random yaws, NaN, gaps)."""
    rng = random.Random(seed)
    log = RunLog(metadata=RunMetadata(TPF, (1.3, 0.0, 1.8), -1, 3 * BLOCK), frames=())
    for f in range(3 * BLOCK + 1):
        t = f * TPF
        if rng.random() < 0.9:
            x = math.nan if rng.random() < 0.03 else rng.uniform(-50.0, 50.0)
            log.pose[t] = EgoPose(x, rng.uniform(-50, 50), 0, 0, 0, rng.uniform(-360, 360), 3.0)
        n = rng.choice((0, 1, 2, 5, 5, 5, 8))
        keys = [str(k) for k in range(n)]
        if n and rng.random() < 0.2:
            keys[rng.randrange(n)] = rng.choice(("0", "1", "7", "x", "1.5", "40"))
        if rng.random() < 0.3:
            rng.shuffle(keys)
        xy = np.array([[rng.uniform(-60, 60), rng.uniform(-60, 60)] for _ in keys]).reshape(-1, 2)
        if n > 2 and rng.random() < 0.2:
            xy[1] = xy[0]  # a zero-length segment
        if n and rng.random() < 0.05:
            xy[rng.randrange(n), rng.randrange(2)] = math.nan
        speed = np.array([rng.uniform(0, 20) for _ in keys])
        if rng.random() < 0.95:
            log.waypoints[t] = Plan(tuple(keys), xy, speed)
    return log


def test_a_block_of_steps_is_each_frames_own_step_bit_for_bit() -> None:
    # 40 random logs x 96 frames: every frame's block step equals the single-step reading
    # of a fresh context, and a block leaves a frame out exactly when that reading reports
    # a problem or finds an input missing
    checked = 0
    for seed in range(40):
        log = hostile_log(seed)
        params = make_params("corrected")
        block_cc = corrected_context(RunContext(log, params))
        for start in range(0, 3 * BLOCK * TPF, BLOCK * TPF):
            block = step_block(block_cc, start)
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
        assert not block_cc.ctx.problems  # reading a block reports nothing
    assert checked > 1000  # the blocks did most of the work
