"""Motion prediction: constant acceleration (with stop) from a state, in the ego body frame.

The same predictor serves both prediction files: fed with the tracker's state it writes
``predictions/`` (keyed by track id, what the planner sees); fed with finite differences of
the ground-truth history it writes ``predictions_with_perception/`` (keyed by actor id, the
prediction "given correct perception"). Key k is k+1 frames ahead; offsets are in the ego
body frame at ts (x forward, y right). Braking is extrapolated to a stop, never to reversing,
so a lead car braking at constant deceleration is predicted exactly.
"""

from __future__ import annotations

import numpy as np

from ads_rca.synth.geometry import FloatArray

DT = 0.05


def predict_positions(pos: FloatArray, vel: FloatArray, acc: FloatArray, steps: int) -> FloatArray:
    """World positions (M, steps, 2) at 1..steps frames ahead under constant acceleration.

    Where the acceleration opposes the velocity the motion stops when the speed along the
    initial direction reaches zero.
    """
    t = np.arange(1, steps + 1) * DT  # (K,)
    vv = vel[:, 0] * vel[:, 0] + vel[:, 1] * vel[:, 1]
    av = acc[:, 0] * vel[:, 0] + acc[:, 1] * vel[:, 1]
    braking = (av < 0.0) & (vv > 1e-6)
    t_stop = np.where(braking, -vv / np.where(braking, av, -1.0), np.inf)
    te = np.minimum(t[None, :], t_stop[:, None])  # (M, K)
    positions: FloatArray = (
        pos[:, None, :]
        + vel[:, None, :] * te[..., None]
        + 0.5 * acc[:, None, :] * (te**2)[..., None]
    )
    return positions


def state_from_history(history: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Position, velocity and acceleration (each (N, 2)) from positions at t-2, t-1, t (3, N, 2).

    Exact for trajectories that are quadratic in time over the last two frames.
    """
    d1 = (history[2] - history[1]) / DT
    d0 = (history[1] - history[0]) / DT
    acc = (d1 - d0) / DT
    return history[2], d1 + acc * (DT / 2), acc


def wrong_model(
    model: str,
    pos: FloatArray,
    vel: FloatArray,
    acc: FloatArray,
    stale_position: FloatArray,
    stale_velocity: FloatArray,
    road: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The optimistic wrong motion models a prediction fault substitutes (pos, vel, accel).

    ``stale``: the velocity from before the partner's manoeuvre, no acceleration (a braking
    lead predicted to keep going). ``keep_lane``: the partner predicted to follow the road
    at its lateral position from before the manoeuvre (a cutting-in car predicted to stay
    in its lane, a crossing pedestrian to stay on the sidewalk). ``frozen``: standing still
    (oncoming traffic predicted not to arrive).
    """
    if model == "stale":
        return pos, np.broadcast_to(stale_velocity, vel.shape).copy(), np.zeros_like(acc)
    if model == "keep_lane":
        normal = np.array([-road[1], road[0]])
        lateral = (pos - stale_position) @ normal
        along_v = (vel @ road)[:, None] * road
        along_a = (acc @ road)[:, None] * road
        return pos - lateral[:, None] * normal, along_v, along_a
    if model == "frozen":
        return pos, np.zeros_like(vel), np.zeros_like(acc)
    raise ValueError(f"unknown prediction fault model {model!r}")
