"""The noise-floor rule: each module's error floor, read from the run itself before the effect
window.

Why: a real stack is noisy. Localisation drifts by decimetres and a camera's 3-D position is
off by a metre at 20 m, so errors at or over the fixed thresholds (``understate_min``,
``pred_abs_threshold``, ``control_lateral_threshold``) are the stack's ordinary state, not a
fault. A module is blamed only when its error stands out from what the same module did on
the same run before: the floor.

The floor frames of ts are the log's timestamps u with ts − (G + L)·frame_ms ≤ u < ts − G·frame_ms:
G = W (the effect window), so no frame of a window frame's floor lies in the
window, and L = round(``noise_floor_s`` · 1000 / frame_ms). Only earlier frames are read, so a
live monitor judges exactly as the offline run does (it keeps them, :meth:`rejudge_history`).

* Perception, the 3-D perception rule's velocity and prediction: every floor frame gives one
  *sample* per actor (its error at u, the same measure the rule applies to the partner at ts;
  cached per u, independent of who the partner is). The floor is the median over the floor
  frames of the median over the actors other than the partner (basis ``others``). With fewer
  than ``noise_floor_min_frames`` such frames (an empty scene), it is the partner's own robust
  spread, 1.4826 × the median absolute deviation of its samples (basis ``partner``: a bias the
  partner carried throughout adds nothing, its jitter does). With fewer than that too (a short
  run), the floor is 0 (basis ``none``): the fixed thresholds alone, as on a noise-free run.
* Control: the robust sigma of the differences of consecutive floor steps' innovations
  (differencing removes a steady tracking offset, which is not noise).

The rules add ``noise_floor_factor`` × the floor to their fixed thresholds, and the 3-D
perception rule pairs a partner the match left alone with a free perceived object within the
match distance plus that allowance (:func:`partner_row`): noise moved the box, it was not missed.
docs/semantics-corrected.md ("Noise floors") has the precise readings.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from itertools import pairwise

import numpy as np

from ads_rca.foundation.geometry import FloatArray
from ads_rca.model import Track
from ads_rca.oracles.corrected.boxes import step_order
from ads_rca.oracles.corrected.context import (
    CacheName,
    CorrectedContext,
    floor_span,
    window_frames,
)
from ads_rca.oracles.corrected.links import raw_links
from ads_rca.oracles.corrected.match3d import frame_match, uses_3d
from ads_rca.params import Params

#: 1.4826 × MAD estimates a normal distribution's standard deviation.
MAD_SIGMA = 1.4826
BASIS_OTHERS = "others"
BASIS_PARTNER = "partner"
BASIS_NONE = "none"
BASIS_STEPS = "steps"

#: Samples per actor at one timestamp.
Samples = dict[str, float]


@dataclass(frozen=True)
class Floor:
    """A module's error floor at ts, and what it was read from."""

    value: float  # metres (control: per step, m/s or m)
    frames: int  # floor frames (or differences) it was read from
    basis: str  # BASIS_OTHERS | BASIS_PARTNER | BASIS_NONE (control: BASIS_STEPS)

    def metrics(self, prefix: str) -> dict[str, float | int | str]:
        return {
            f"{prefix}_floor": self.value,
            f"{prefix}_floor_frames": self.frames,
            f"{prefix}_floor_basis": self.basis,
        }


NO_FLOOR = Floor(0.0, 0, BASIS_NONE)
PERCEPTION_SAMPLES: CacheName[Samples] = CacheName("perception_samples")
PREDICTION_SAMPLES: CacheName[Samples] = CacheName("prediction_samples")


def floor_frames(judging: CorrectedContext, ts: int) -> list[int]:
    """The log's timestamps u with ts − (G + L)·frame_ms ≤ u < ts − G·frame_ms (ascending)."""
    frame_ms = judging.frame_ms
    span, gap = floor_reach(judging.params, frame_ms)
    first, end = ts - span * frame_ms, ts - gap * frame_ms
    grid = frame_grid(judging)
    if grid is not None:  # every frame_ms from lo to hi: the range's grid points inside it
        lo, hi = grid
        return (
            []
            if (first - lo) % frame_ms
            else list(range(max(first, lo), min(end, hi + frame_ms), frame_ms))
        )
    frames = judging.frame_set()
    return [u for u in range(first, end, frame_ms) if u in frames]


#: The parameters and frame period last asked, and their (W + L, W).
_REACH: list[tuple[Params, int, tuple[int, int]]] = []


def floor_reach(params: Params, frame_ms: int) -> tuple[int, int]:
    """(W + L, W) in frames: the floor frames of ts lie from ts − (W + L)·frame_ms to before
    ts − W·frame_ms (remembered for the last parameters: every frame asks)."""
    if _REACH and _REACH[0][0] is params and _REACH[0][1] == frame_ms:
        return _REACH[0][2]
    reach = (floor_span(params, frame_ms), window_frames(params, frame_ms))
    _REACH[:] = [(params, frame_ms, reach)]
    return reach


#: The frames tuple last checked and its first and last frame if it is a grid.
FRAME_GRID: CacheName[tuple[tuple[int, ...], tuple[int, int] | None]] = CacheName("frame_grid")


def frame_grid(judging: CorrectedContext) -> tuple[int, int] | None:
    """The log's first and last frame when its frames are every frame_ms from one to the other,
    each once (a run without gaps: floor frames are then a range), else None; checked once
    per frames tuple (a live window's frames change)."""
    frames = judging.log.frames
    cache = judging.cache(FRAME_GRID)
    found = cache.lookup(0)
    if found is None or found[0] is not frames:
        frame_ms = judging.frame_ms
        grid = bool(frames) and all(b - a == frame_ms for a, b in pairwise(frames))
        found = (frames, (frames[0], frames[-1]) if grid else None)
        cache.put(0, found)
    return found[1]


def median(values: Sequence[float] | FloatArray) -> float:
    """The median (a stable sort, so equal values keep their order: the one picked is
    the plain-Python reading's)."""
    return _middle(np.sort(np.asarray(values, dtype=np.float64), kind="stable"))


def list_median(values: list[float]) -> float:
    """:func:`median` of a short list, sorted in plain Python (a numpy call costs more
    than sorting ten values): the same stable order without NaN, so the same value."""
    if any(map(math.isnan, values)):  # NaN: numpy's order (last) is not Python's
        return median(values)
    return _middle(sorted(values))


def _middle(ordered: Sequence[float] | FloatArray) -> float:
    """The median of values already sorted (at least one)."""
    mid = len(ordered) // 2
    return float(ordered[mid] if len(ordered) % 2 else 0.5 * (ordered[mid - 1] + ordered[mid]))


def robust_sigma(values: Sequence[float] | FloatArray) -> float:
    """1.4826 × the median absolute deviation (0 for no values)."""
    if len(values) == 0:
        return 0.0
    spread = np.asarray(values, dtype=np.float64)
    return MAD_SIGMA * median(np.abs(spread - median(spread)))


def list_robust_sigma(values: list[float]) -> float:
    """:func:`robust_sigma` of a short list in plain Python (a numpy call costs more than
    its arithmetic): the same sorts and IEEE operations, so the same value; a list with a
    NaN or an infinity goes to numpy (whose NaN order Python's sort does not share)."""
    if not values:
        return 0.0
    if not all(map(math.isfinite, values)):
        return robust_sigma(values)
    centre = _middle(sorted(values))
    return MAD_SIGMA * _middle(sorted([abs(v - centre) for v in values]))


def robust_sigmas(rows: FloatArray) -> FloatArray:
    """:func:`robust_sigma` of each row along the last axis (the same sorts and IEEE
    operations, so the same values)."""
    centre = _medians(np.sort(rows, axis=-1, kind="stable"))
    spread = np.sort(np.abs(rows - centre[..., None]), axis=-1, kind="stable")
    return MAD_SIGMA * _medians(spread)


def _medians(ordered: FloatArray) -> FloatArray:
    """The median of each sorted row (last axis, at least one value)."""
    mid = ordered.shape[-1] // 2
    if ordered.shape[-1] % 2:
        return ordered[..., mid]
    return 0.5 * (ordered[..., mid - 1] + ordered[..., mid])


def actor_floor(
    judging: CorrectedContext, ts: int, sampler: Callable[[CorrectedContext, int], Samples]
) -> Floor:
    """The floor at ts from per-actor samples (others' median level, else the partner's
    own spread, else none); cached per timestamp and partner."""
    partner = judging.partner_at(ts)
    cache = judging.cache(_names(sampler)[0])
    found = cache.lookup(ts)
    if found is None or found[0] != partner:
        found = (partner, _actor_floor(judging, ts, sampler, partner))
        cache.put(ts, found)
    return found[1]


#: One floor frame's reduction for one partner: the others' median level (None without
#: others) and the partner's own sample (None without one).
Level = tuple[float | None, float | None]

#: The floor and level cache names of each sampler, by its name (made once, not per call).
_NAMES: dict[str, tuple[CacheName[tuple[str | None, Floor]], CacheName[Level]]] = {}


def _names(
    sampler: Callable[[CorrectedContext, int], Samples],
) -> tuple[CacheName[tuple[str | None, Floor]], CacheName[Level]]:
    name = sampler.__name__
    found = _NAMES.get(name)
    if found is None:
        found = _NAMES[name] = (CacheName(f"floor:{name}"), CacheName(f"level:{name}"))
    return found


def _actor_floor(
    judging: CorrectedContext,
    ts: int,
    sampler: Callable[[CorrectedContext, int], Samples],
    partner: str | None,
) -> Floor:
    slide = judging.slide(_names(sampler)[1])
    reduced = slide.read(
        floor_frames(judging, ts), lambda u: frame_level(sampler(judging, u), partner), partner
    )
    levels = [level for level, _ in reduced if level is not None]
    minimum = max(int(judging.params.noise_floor_min_frames), 1)
    if len(levels) >= minimum:
        return Floor(list_median(levels), len(levels), BASIS_OTHERS)
    own = [sample for _, sample in reduced if sample is not None]
    if len(own) >= minimum:
        return Floor(list_robust_sigma(own), len(own), BASIS_PARTNER)
    return NO_FLOOR


def frame_level(samples: Samples, partner: str | None) -> Level:
    """One floor frame's part of the floor: the median of the actors other than the
    partner (None without any) and the partner's own sample (None without one)."""
    others = [v for a, v in samples.items() if a != partner]
    own = None if partner is None else samples.get(partner)
    return list_median(others) if others else None, own


def perception_floor(judging: CorrectedContext, ts: int) -> Floor:
    """Perception's displacement floor at ts (m)."""
    return actor_floor(judging, ts, perception_samples)


def velocity_floor(judging: CorrectedContext, ts: int) -> Floor:
    """The 3-D perception rule's velocity-error floor at ts (m/s)."""
    return actor_floor(judging, ts, velocity_samples)


# -- samples --------------------------------------------------------------------------------
def perception_samples(judging: CorrectedContext, u: int) -> Samples:
    """Perception's error per actor at u (cached): the 2-D perception rule's raw displacement
    (each actor's linked raw prediction against its prediction on truth, max over the horizon)
    or the 3-D perception rule's (each matched actor's perceived against its real box, both at
    constant velocity)."""
    return judging.cache(PERCEPTION_SAMPLES).get(u, lambda: _perception_samples(judging, u))


def _perception_samples(judging: CorrectedContext, u: int) -> Samples:
    if uses_3d(judging):
        return _perception3d_samples(judging, u)
    raw, on_truth = judging.log.predictions.get(u), judging.log.predictions_with_perception.get(u)
    if raw is None or on_truth is None:
        return {}
    links = raw_links(raw, on_truth, judging.ego_id)
    if not links:
        return {}
    actors = list(links)
    raw_tracks, on_truth_tracks = [raw[links[a]] for a in actors], [on_truth[a] for a in actors]
    keys = raw_tracks[0].keys
    if all(t.keys == keys for t in raw_tracks) and all(t.keys == keys for t in on_truth_tracks):
        return _shared_keys_displacements(actors, raw_tracks, on_truth_tracks, keys, judging.window)
    out: Samples = {}
    for actor, a, b in zip(actors, raw_tracks, on_truth_tracks, strict=True):
        error = _offset_displacement(a, b, judging.window)
        if math.isfinite(error):
            out[actor] = error
    return out


def _shared_keys_displacements(
    actors: list[str],
    raw_tracks: list[Track],
    on_truth_tracks: list[Track],
    keys: tuple[str, ...],
    window: int,
) -> Samples:
    """:func:`_offset_displacement` of every linked pair at once when all tracks have the
    same keys (the usual case: their shared steps are all steps): the same distances, and
    each row's largest non-NaN one, kept where finite."""
    rows, _ = step_order(keys, window)
    if rows.size == 0:
        return {}
    diff = np.array([t.offsets for t in raw_tracks])[:, rows, :2]
    diff -= np.array([t.offsets for t in on_truth_tracks])[:, rows, :2]
    dist = np.hypot(diff[..., 0], diff[..., 1])
    some = np.isfinite(dist).any(axis=1).tolist()
    top = np.where(np.isnan(dist), -np.inf, dist).max(axis=1).tolist()
    return {a: v for a, v, k in zip(actors, top, some, strict=True) if k and math.isfinite(v)}


def _offset_displacement(a: Track, b: Track, window: int) -> float:
    """Max over the shared steps 0..W−1 of the distance between two tracks' offsets (the
    same pose anchors both, so this is their world displacement); NaN when none shared."""
    rows_a, steps_a = step_order(a.keys, window)
    rows_b, steps_b = step_order(b.keys, window)
    shared, ia, ib = np.intersect1d(steps_a, steps_b, return_indices=True)
    if shared.size == 0:
        return math.nan
    diff = a.offsets[rows_a[ia], :2] - b.offsets[rows_b[ib], :2]
    dist = np.hypot(diff[:, 0], diff[:, 1])
    return float(np.nanmax(dist)) if np.isfinite(dist).any() else math.nan


def _perception3d_samples(judging: CorrectedContext, u: int) -> Samples:
    offsets = perceived_offsets(judging, u)
    t = np.array([1, judging.window])  # the offset is linear in time: its max is at an end
    return {a: float(np.hypot(*off[t].T).max()) for a, off in offsets.items()}


def velocity_samples(judging: CorrectedContext, u: int) -> Samples:
    """The 3-D perception rule's velocity error |perceived − real| (m/s) of every matched
    in-range actor at u (the perceived velocity standing in for itself when unknown gives 0)."""
    dt = judging.frame_ms / 1000.0
    return {
        a: float(np.hypot(*(off[1] - off[0]))) / dt
        for a, off in perceived_offsets(judging, u).items()
    }


PERCEIVED_OFFSETS: CacheName[dict[str, np.ndarray]] = CacheName("perceived_offsets")


def perceived_offsets(judging: CorrectedContext, u: int) -> dict[str, np.ndarray]:
    """The 3-D perception rule's state error of every matched in-range actor at u (cached):
    perceived − real centre at indices 0..W, both moved at constant velocity (the perceived
    velocity, else the real one); actors with a NaN error are left out."""
    return judging.cache(PERCEIVED_OFFSETS).get(u, lambda: _perceived_offsets(judging, u))


def _perceived_offsets(judging: CorrectedContext, u: int) -> dict[str, np.ndarray]:
    match = frame_match(judging, u)
    if match is None or match.rows.size == 0:
        return {}
    ids = [match.actor_ids[c] for c in match.cols.tolist()]
    states = judging.states_over(
        judging.gids(ids), [u - judging.frame_ms, u, u + judging.frame_ms]
    )[:, :, :2]
    dt = judging.frame_ms / 1000.0
    ahead = (states[:, 2] - states[:, 1]) / dt
    behind = (states[:, 1] - states[:, 0]) / dt
    ahead_known = np.asarray(np.isfinite(ahead).all(axis=1), dtype=bool)
    real_v = np.where(ahead_known[:, None], ahead, behind)
    seen_v = match.objects.velocity[match.rows, :2]
    seen_known = np.asarray(np.isfinite(seen_v).all(axis=1), dtype=bool)
    seen_v = np.where(seen_known[:, None], seen_v, real_v)
    dp = match.objects.location[match.rows, :2] - match.actor_center[match.cols]
    t = judging.seconds(np.arange(judging.window + 1))
    moved = dp[:, None, :] + t[None, :, None] * (seen_v - real_v)[:, None, :]  # (N, W + 1, 2)
    keep = match.actor_in_range[match.cols] & np.isfinite(moved).all(axis=(1, 2))
    return {a: moved[n] for n, a in enumerate(ids) if keep[n]}


def partner_row(judging: CorrectedContext, ts: int, actor_id: str) -> tuple[int | None, bool]:
    """The perceived object row that stands for ``actor_id`` at ts, and whether only the
    noise allowance paired them: the 3-D match; else (the noise-floor rule) the nearest
    in-range object no actor matched whose centre lies within ``perc3d_match_distance`` plus the
    allowance
    (``noise_floor_factor`` × the perception floor) of the actor's; else None."""
    match = frame_match(judging, ts)
    if match is None or actor_id not in match.actor_ids:
        return None, False
    row = match.object_of(actor_id)
    if row is not None:
        return row, False
    p = judging.params
    reach = p.perc3d_match_distance + p.noise_floor_factor * perception_floor(judging, ts).value
    free = np.ones(len(match.objects.ids), dtype=bool)
    free[match.rows] = False
    free &= match.object_in_range
    if not free.any():
        return None, False
    col = match.actor_ids.index(actor_id)
    d = np.hypot(*(match.objects.location[:, :2] - match.actor_center[col]).T)
    d = np.where(free & np.isfinite(d), d, np.inf)
    nearest = int(np.argmin(d))
    return (nearest, True) if d[nearest] <= reach else (None, False)


def partner_object(judging: CorrectedContext, ts: int, actor_id: str) -> str | None:
    """The id of :func:`partner_row`'s object (the actor's raw track when tracked objects
    share their ids with the predictions)."""
    row, _ = partner_row(judging, ts, actor_id)
    match = frame_match(judging, ts)
    return None if row is None or match is None else match.objects.ids[row]


def step_floor(values: Sequence[float], minimum: int) -> Floor:
    """Control's floor from consecutive steps' innovations: the robust sigma of their
    differences (at least ``minimum`` differences, else none)."""
    with np.errstate(invalid="ignore"):  # inf − inf: a NaN difference, dropped next
        diffs = np.diff(np.asarray(values, dtype=np.float64))
    diffs = diffs[np.isfinite(diffs)]
    if len(diffs) < max(minimum, 1):
        return NO_FLOOR
    return Floor(robust_sigma(diffs), len(diffs), BASIS_STEPS)
