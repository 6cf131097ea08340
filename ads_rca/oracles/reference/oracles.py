"""The four module oracles exactly as the reference tool computes them, quirks included.

Why this module exists: users compare our counts with published results of the reference
tool (rca-semantics.md, "The four oracles"), so ``reference`` mode must reproduce its
per-frame decisions on every log it completes: greedy box matching with NaN means,
prediction anchored at the FUTURE ego pose, the planning link rule and tolerances, and the
control oracle with its inverted helper. Where the reference would stop with a traceback
("Where the reference crashes") we report the input problem through ``ctx.report`` and
skip that check for that frame (``failed=False``, ``skipped`` set); the ORDER in which the
reference reads its inputs decides which problem that is, and whether a failure found
earlier in that order still stands.

Speed: each oracle is vectorised within a frame (every key of every track at once, every
plan index x linked track pair at once) and then reduced to the reference's sequential
outcome by taking the first "event" (a crash or a failure) in the reference's visiting
order. Arrays are 1-D (x and y apart) because row gathers of (K, 2) arrays and numpy
reductions (``any``, ``min``) cost several times an element-wise operation at these sizes;
first events are found with ``argmax`` on boolean masks. Look-ups across time (ego pose
and actor locations at future timestamps) go through per-log tables built once, on first
use, and cached per :class:`RunLog` (build a log completely before judging it). Key
layouts, which repeat from frame to frame, are parsed once.
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from ads_rca.foundation.geometry import BLOCK_PAIRS, overlap_blocks
from ads_rca.model import Boxes, Plan, Predictions, RunLog, Track
from ads_rca.oracles.base import Metric, Module, OracleResult, RunContext
from ads_rca.oracles.cache import LRU
from ads_rca.oracles.frame_iou import IOU_BATCH, FrameIoU, batched_iou
from ads_rca.problems import DROPPED_RECORD

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

#: Constants of the reference that are not parameters.
PRED_DISTANCE_GATE_M = 4.0
LINK_DISTANCE_M = 100.0
CONTROL_MOVE_GATE_M = 0.6
CONTROL_STEP_MIN_M = 0.5
CONTROL_SCORE_MAX = 0.1
IOU_DECIMALS = 4

#: Clamp for absurd integer step keys (keeps int64 arithmetic exact and the outcome the
#: same: a huge positive step is beyond the horizon, a huge negative one finds no pose).
_STEP_CLAMP = 10**12
#: Loader action for a value that was missing or not a number (the reference crashes).
_READ_AS_NAN = "read as NaN"
#: What the reference does on the inputs we report.
_STOPS = "the reference stops here"
#: The parameters each oracle's results report in ``thresholds``, in that order (the mode's
#: ``Semantics.reported``); an oracle adds its constants after them.
REPORTED: dict[Module, tuple[str, ...]] = {
    "perception": ("perc_score_threshold",),
    "prediction": ("pred_score_threshold",),
    "planning": ("planning_toleration_future_step", "planning_toleration"),
    "controller": (),
}
#: Bound of each parse cache (logs repeat a handful of layouts).
_CACHE_SIZE = 256


# =========================================================================== helpers


def _skip(
    ctx: RunContext,
    module: Module,
    ts: int,
    file: str,
    field_name: str,
    issue: str,
    thresholds: dict[str, float],
) -> OracleResult:
    """Report the input problem that would crash the reference and skip this check."""
    ctx.report(file, field_name, f"{issue} ({_STOPS})", ts)
    where = f"{file}: {field_name}" if field_name else file
    skipped = f"{where}: {issue}"
    return OracleResult(
        module, ts, False, thresholds=thresholds, skipped=skipped, missing_input=True
    )


def _first(mask: BoolArray) -> int:
    """Index of the first True, or -1 (argmax: no reduction machinery)."""
    if not mask.size:
        return -1
    i = int(mask.argmax())
    return i if mask[i] else -1


def _parse_step(key: str) -> int | None:
    """``int(key)`` as Python reads it (the reference's conversion: " 3", "0_1"), else None."""
    try:
        return max(-_STEP_CLAMP, min(_STEP_CLAMP, int(key)))
    except ValueError:
        return None


_STEPS: LRU[tuple[str, ...], tuple[IntArray, BoolArray]] = LRU(_CACHE_SIZE)


def _parse_steps(keys: tuple[str, ...]) -> tuple[IntArray, BoolArray]:
    """Integer value of each key (0 where not an integer) and which keys are integers."""
    found = _STEPS.lookup(keys)
    if found is None:
        values = [_parse_step(k) for k in keys]
        ok = np.array([v is not None for v in values], dtype=np.bool_)
        found = (np.array([v or 0 for v in values], dtype=np.int64), ok)
        _STEPS.put(keys, found)
    return found


@dataclass(frozen=True, eq=False)
class _PlanPairs:
    """Raw keys that name a plan key, sorted in the planning oracle's visiting order."""

    key: IntArray  # (P,) row in the raw layout
    row: IntArray  # (P,) plan row (file order)
    track: IntArray  # (P,) raw track
    step: IntArray  # (P,) integer value of the plan key (0 where not an integer)
    #: (P,) judged unless beyond the horizon: i != 0, before the first non-integer key.
    reachable: BoolArray
    bad_row: int  # the first non-integer plan key (a crash when reached), or -1


@dataclass(frozen=True, eq=False)
class _Layout:
    """The keys of a predictions record, track after track (shared by equal records)."""

    keys: tuple[str, ...]
    track_of: IntArray  # (K,) track of each key
    steps: IntArray  # (K,) integer value of each key (0 where not an integer)
    int_ok: BoolArray  # (K,)
    all_int: bool
    zero_rows: IntArray  # (tracks,) row of each track's step "0" (identical string), -1
    all_zero: bool
    #: plan keys -> the pairs of a plan with these keys.
    plan_pairs: LRU[tuple[str, ...], _PlanPairs] = field(default_factory=lambda: LRU(16))


_LAYOUTS: LRU[tuple[tuple[str, ...], ...], _Layout] = LRU(_CACHE_SIZE)


def _layout(key_tuples: tuple[tuple[str, ...], ...]) -> _Layout:
    found = _LAYOUTS.lookup(key_tuples)
    if found is None:
        keys = tuple(k for keys in key_tuples for k in keys)
        steps, int_ok = _parse_steps(keys)
        zero_rows: list[int] = []
        start = 0
        for track_keys in key_tuples:
            zero_rows.append(start + track_keys.index("0") if "0" in track_keys else -1)
            start += len(track_keys)
        lengths = [len(keys) for keys in key_tuples]
        track_of = np.repeat(np.arange(len(key_tuples), dtype=np.int64), lengths)
        found = _Layout(
            keys,
            track_of,
            steps,
            int_ok,
            bool(int_ok.all()),
            np.array(zero_rows, dtype=np.int64),
            -1 not in zero_rows,
        )
        _LAYOUTS.put(key_tuples, found)
    return found


class _Flat:
    """One predictions record laid end to end: ids and tracks in file order, all keys.

    A plain class with slots, not a dataclass: two are made a frame (the predictions on
    truth and the raw ones), and a frozen dataclass's ``__init__`` (``object.__setattr__``
    a field) costs four times as much (0.66 against 0.15 us for five fields)."""

    __slots__ = ("ids", "layout", "tracks", "x", "y")

    def __init__(
        self,
        ids: tuple[str, ...],
        tracks: tuple[Track, ...],
        layout: _Layout,
        x: FloatArray,
        y: FloatArray,
    ) -> None:
        self.ids = ids
        self.tracks = tracks
        self.layout = layout
        self.x = x  # (K,) offsets x
        self.y = y  # (K,) offsets y


#: The last few flattened records: prediction and planning share the frame's record of
#: predictions on truth.
#: Keyed by the record's identity; the entry holds the record, so its id is not reused.
_FLAT_CACHE: LRU[int, tuple[Predictions, _Flat]] = LRU(4)


def _flatten(preds: Predictions) -> _Flat:
    cached = _FLAT_CACHE.lookup(id(preds))
    if cached is not None and cached[0] is preds:
        return cached[1]
    tracks = tuple(preds.values())
    layout = _layout(tuple(t.keys for t in tracks))
    if layout.keys:
        # x and y as the two rows of one copy (each contiguous): one copy, not two
        x, y = np.concatenate([t.offsets for t in tracks])[:, :2].T.copy()
    else:
        x = y = np.zeros(0, dtype=np.float64)
    flat = _Flat(tuple(preds), tracks, layout, x, y)
    _FLAT_CACHE.put(id(preds), (preds, flat))
    return flat


# =========================================================================== time tables


@dataclass(frozen=True, eq=False)
class _Tables:
    """Per-log look-up tables across time (built once per RunLog, on first use).

    Every table ends with a sentinel entry (NaN / absent) that missing look-ups point to,
    so gathers never need masking: pose row ``n_pose``, actor row ``n_times``, actor
    column ``n_cols - 1``.
    """

    frame_ms: int
    pose_times: IntArray  # (T,) sorted
    pose_x: FloatArray  # (T + 1,)
    pose_y: FloatArray
    actor_times: IntArray  # (U,) sorted
    actor_cols: dict[str, int]  # actor id -> column
    n_cols: int  # A + 1
    actor_x: FloatArray  # ((U + 1) * (A + 1),) raveled by (time row, column)
    actor_y: FloatArray
    actor_present: BoolArray
    ext_x: FloatArray  # (A + 1,) first-appearance half extents, NaN: none
    ext_y: FloatArray
    #: Frame grid (on-grid timestamps): slot 0 and F + 1 are sentinels, slot i frame f0+i-1.
    grid_f0: int
    pose_slot: IntArray  # (F + 2,) pose row, or the sentinel
    actor_slot: IntArray  # (F + 2,) actor time row, or the sentinel
    #: file -> fields the loader read as NaN (missing / not a number: the reference crashes).
    nan_fields: dict[str, set[str]]
    #: files in which the loader dropped a record (the reference crashes on them).
    dropped: set[str]

    def rows_at(self, ts: int, steps: IntArray) -> tuple[IntArray, IntArray]:
        """Pose row and actor time row at ts + steps * frame_ms (the sentinels where absent)."""
        n_pose, n_times = len(self.pose_times), len(self.actor_times)
        if ts % self.frame_ms == 0 and self.pose_slot.size:
            idx = steps + (ts // self.frame_ms - self.grid_f0 + 1)
            np.maximum(idx, 0, out=idx)
            np.minimum(idx, self.pose_slot.size - 1, out=idx)
            return self.pose_slot[idx], self.actor_slot[idx]
        tk = steps * self.frame_ms
        tk += ts
        return _search(self.pose_times, tk, n_pose), _search(self.actor_times, tk, n_times)

    def pose_present(self, row: IntArray) -> BoolArray:
        present: BoolArray = row != len(self.pose_times)
        return present


def _search(times: IntArray, query: IntArray, sentinel: int) -> IntArray:
    if not times.size:
        return np.full(query.shape, sentinel, dtype=np.int64)
    idx = np.searchsorted(times, query)
    np.minimum(idx, times.size - 1, out=idx)
    return np.where(times[idx] == query, idx, sentinel)


_TABLES: weakref.WeakKeyDictionary[RunLog, _Tables] = weakref.WeakKeyDictionary()


def _tables(log: RunLog) -> _Tables:
    cached = _TABLES.get(log)
    if cached is None:
        cached = _build_tables(log)
        _TABLES[log] = cached
    return cached


def _build_tables(log: RunLog) -> _Tables:
    frame_ms = log.frame_ms
    pose_times = sorted(log.pose)
    pose_x = np.array([log.pose[t].x for t in pose_times] + [math.nan], dtype=np.float64)
    pose_y = np.array([log.pose[t].y for t in pose_times] + [math.nan], dtype=np.float64)
    actor_times = sorted(log.actors)
    cols: dict[str, int] = {}
    groups = _frames_by_ids(log, actor_times)
    for ids, _rows in groups:
        for actor_id in ids:
            cols.setdefault(actor_id, len(cols))
    shape = (len(actor_times) + 1, len(cols) + 1)
    actor_x, actor_y = np.full(shape, np.nan), np.full(shape, np.nan)
    present = np.zeros(shape, dtype=np.bool_)
    for _ids, rows in groups:
        index = log.actors[actor_times[rows[0]]].index  # the first row of each id
        if not index:
            continue
        dst = np.array([cols[a] for a in index], dtype=np.int64)
        src = np.array(list(index.values()), dtype=np.int64)
        location = np.stack([log.actors[actor_times[u]].location for u in rows])
        frames = np.array(rows, dtype=np.int64)[:, None]
        actor_x[frames, dst] = location[:, src, 0]
        actor_y[frames, dst] = location[:, src, 1]
        present[frames, dst] = True
    ext_x, ext_y = np.full(len(cols) + 1, np.nan), np.full(len(cols) + 1, np.nan)
    for actor_id, ext in log.actor_extents.items():
        ext_x[cols[actor_id]], ext_y[cols[actor_id]] = ext[0], ext[1]
    f0, pose_slot, actor_slot = _grid(frame_ms, pose_times, actor_times)
    nan_fields: dict[str, set[str]] = {}
    dropped: set[str] = set()
    for problem in log.problems:
        if problem.action == _READ_AS_NAN:
            nan_fields.setdefault(problem.file, set()).add(problem.field)
        elif problem.action == DROPPED_RECORD:
            dropped.add(problem.file)
    return _Tables(
        frame_ms,
        np.array(pose_times, dtype=np.int64),
        pose_x,
        pose_y,
        np.array(actor_times, dtype=np.int64),
        cols,
        len(cols) + 1,
        actor_x.ravel(),
        actor_y.ravel(),
        present.ravel(),
        ext_x,
        ext_y,
        f0,
        pose_slot,
        actor_slot,
        nan_fields,
        dropped,
    )


def _frames_by_ids(log: RunLog, times: list[int]) -> list[tuple[tuple[str, ...], list[int]]]:
    """The frames (positions in ``times``) of each ids tuple, in order of first use, so
    that the tables take one array operation a group instead of one a frame (a run lists
    the same actors in the same order frame after frame). Tuples are grouped by value:
    the reader's workers share one tuple among a chunk's frames, a log read in one
    process has a tuple a frame."""
    groups: dict[tuple[str, ...], tuple[tuple[str, ...], list[int]]] = {}
    for u, t in enumerate(times):
        ids = log.actors[t].ids
        group = groups.get(ids)
        if group is None:
            groups[ids] = (ids, [u])
        else:
            group[1].append(u)
    return list(groups.values())


def _grid(
    frame_ms: int, pose_times: list[int], actor_times: list[int]
) -> tuple[int, IntArray, IntArray]:
    """Row per frame of the on-grid timestamps (empty when there are none or too sparse)."""
    frames = [t // frame_ms for t in (*pose_times, *actor_times) if t % frame_ms == 0]
    empty = np.zeros(0, dtype=np.int64)
    if not frames:
        return 0, empty, empty
    f0, f1 = min(frames), max(frames)
    if f1 - f0 > 10 * len(frames) + 10_000:
        return 0, empty, empty  # stray far timestamps: search instead
    pose_slot = np.full(f1 - f0 + 3, len(pose_times), dtype=np.int64)
    actor_slot = np.full(f1 - f0 + 3, len(actor_times), dtype=np.int64)
    for row, t in enumerate(pose_times):
        if t % frame_ms == 0:
            pose_slot[t // frame_ms - f0 + 1] = row
    for row, t in enumerate(actor_times):
        if t % frame_ms == 0:
            actor_slot[t // frame_ms - f0 + 1] = row
    return f0, pose_slot, actor_slot


def _rotate(x: FloatArray, y: FloatArray, yaw_deg: float) -> tuple[FloatArray, FloatArray]:
    """R(yaw) (x, y) = (x cos - y sin, x sin + y cos), yaw in degrees."""
    theta = math.radians(yaw_deg)
    c, s = math.cos(theta), math.sin(theta)
    return x * c - y * s, x * s + y * c


def _norm(x: FloatArray, y: FloatArray) -> FloatArray:
    """sqrt(x * x + y * y)."""
    out: FloatArray = x * x
    out += y * y
    return np.sqrt(out, out=out)


# =========================================================================== perception


def _match_scores(a: FloatArray, b: FloatArray) -> FloatArray:
    """IoU (N, M) where it can match (> 0), else 0.

    The float operations of :func:`ads_rca.foundation.geometry.axis_aligned_iou` (corners normalised
    by min/max, union = area_a + area_b - intersection). A zero-area box has intersection
    0, so IoU 0 (or 0/0 = NaN when both are empty); NaN coordinates give NaN; neither is
    > 0, so neither can match: the masks axis_aligned_iou applies change no match. Dense over
    the boxes given: :func:`greedy_match` calls it on bounded blocks.
    """
    ax1, ax2 = np.minimum(a[:, 0], a[:, 2]), np.maximum(a[:, 0], a[:, 2])
    ay1, ay2 = np.minimum(a[:, 1], a[:, 3]), np.maximum(a[:, 1], a[:, 3])
    bx1, bx2 = np.minimum(b[:, 0], b[:, 2]), np.maximum(b[:, 0], b[:, 2])
    by1, by2 = np.minimum(b[:, 1], b[:, 3]), np.maximum(b[:, 1], b[:, 3])
    iw = np.minimum(ax2[:, None], bx2)
    iw -= np.maximum(ax1[:, None], bx1)
    np.maximum(iw, 0.0, out=iw)
    ih = np.minimum(ay2[:, None], by2)
    ih -= np.maximum(ay1[:, None], by1)
    np.maximum(ih, 0.0, out=ih)
    iw *= ih  # intersection
    union = ((ax2 - ax1) * (ay2 - ay1))[:, None] + (bx2 - bx1) * (by2 - by1)
    union -= iw
    with np.errstate(invalid="ignore", divide="ignore"):
        np.divide(iw, union, out=union)
    iou: FloatArray = np.fmax(union, 0.0, out=union)  # NaN (and 0) never match
    return iou


#: Each frame's match scores (a batch of frames at once), with the box records they were
#: computed from.
_SCORES: LRU[int, FrameIoU] = LRU(2 * IOU_BATCH)


def frame_match_scores(log: RunLog, ts: int, det: Boxes, gt: Boxes) -> FloatArray | None:
    """The frame's match scores, as :func:`greedy_match` takes them, or None where the
    frame is too large (or empty) to batch.

    Why: a frame's hundred pairs cost fifteen numpy calls in :func:`_match_scores`; scored
    with the frames that follow (:func:`~ads_rca.oracles.frame_iou.batched_iou`), they cost
    a fraction of that. Those are the IoUs with NaN coordinates scored 0: every IoU above 0
    is :func:`_match_scores`' to the bit (the same operations in the same order), and where
    that one is NaN or 0 these are 0, so no NaN comes first in a row and the matches are
    the same (test_oracles_reference_batched_scores.py).
    """
    return batched_iou(log, _SCORES, ts, det, gt)


def greedy_match(
    det: FloatArray,
    gt: FloatArray,
    max_pairs: int = BLOCK_PAIRS,
    scores: FloatArray | None = None,
) -> tuple[list[int], list[int], FloatArray]:
    """The reference's greedy matching: detection rows, gt rows and raw IoUs of the matches.

    For each detection in order, the unused gt box with the largest IoU strictly above 0;
    ties keep the earlier gt; NaN IoUs never match. Block by block of detections (at most
    ``max_pairs`` scores at once, only gt boxes whose extent touches the block's: see
    :func:`~ads_rca.foundation.geometry.overlap_blocks`), so memory stays linear in the boxes.
    Used gt boxes score 0 in later blocks, which leaves every other row's first maximum where
    it was. Vectorised: when every detection's best gt in a block is distinct, that IS the
    greedy answer; otherwise rows are resolved in order, recomputing only those whose best
    was taken. ``scores``: the frame's :func:`_match_scores` where already computed
    (:func:`frame_match_scores`; read, never written).
    """
    n, m = len(det), len(gt)
    if n == 0 or m == 0:
        return [], [], np.zeros(0)
    used = np.zeros(m, dtype=np.bool_)
    if n * m <= max_pairs:  # the common case: one block, nothing to prune
        if scores is None:
            scores = _match_scores(det, gt)
        rows, chosen, top = _greedy_block(scores, used)
        return rows.tolist(), chosen.tolist(), top
    out_rows: list[int] = []
    cols: list[int] = []
    values: list[float] = []
    for start, stop, keep in overlap_blocks(det, gt, max_pairs):
        block_gt = gt if len(keep) == m else gt[keep]
        scores = _match_scores(det[start:stop], block_gt)
        taken = used[keep]
        if taken.any():
            scores[:, taken] = 0.0
        block_rows, block_cols, block_values = _greedy_block(scores, taken)
        chosen = keep[block_cols]
        used[chosen] = True
        out_rows.extend((block_rows + start).tolist())
        cols.extend(chosen.tolist())
        values.extend(block_values.tolist())
    return out_rows, cols, np.array(values, dtype=np.float64)


def _greedy_block(
    scores: FloatArray, used: npt.NDArray[np.bool_]
) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp], FloatArray]:
    """Greedy matching of one block's rows in order (``scores`` of used columns are 0)."""
    n, m = scores.shape
    best = scores.argmax(axis=1)  # the first maximum: ties keep the earlier gt
    top = scores.ravel()[best + np.arange(0, n * m, m)]
    rows = (top > 0).nonzero()[0]
    chosen = best[rows]
    if np.count_nonzero(np.bincount(chosen, minlength=m) > 1) == 0:
        return rows, chosen, top[rows]
    out_rows: list[int] = []
    cols: list[int] = []
    values: list[float] = []
    used = used.copy()
    top_list = top.tolist()
    for i, first_choice in zip(rows.tolist(), chosen.tolist(), strict=True):
        j, value = first_choice, top_list[i]
        if used[j]:
            row = np.where(used, 0.0, scores[i])
            j = int(row.argmax())
            value = float(row[j])
            if not value > 0:
                continue
        used[j] = True
        out_rows.append(i)
        cols.append(j)
        values.append(value)
    return np.array(out_rows, dtype=np.intp), np.array(cols, dtype=np.intp), np.array(values)


def round4(values: FloatArray) -> FloatArray:
    """``round(v, 4)`` of each value, exactly as Python rounds (correctly, half-even).

    rint(v * 1e4) / 1e4 is Python's result unless v * 1e4 lies within rounding error of a
    half-integer; those few values are rounded by Python itself.
    """
    scaled = values * 10.0**IOU_DECIMALS
    near = np.rint(scaled)
    out = near / 10.0**IOU_DECIMALS
    near -= scaled
    for i in (np.abs(near) > 0.5 - 1e-6).nonzero()[0].tolist():
        out[i] = round(float(values[i]), IOU_DECIMALS)
    return out


def perception(ctx: RunContext, ts: int) -> OracleResult:
    """Mean IoU of greedily matched detections; failure iff it is below the threshold."""
    log = ctx.log
    thr = ctx.params.perc_score_threshold
    det, gt = log.bboxes.get(ts), log.bboxes_gt.get(ts)
    if det is None or gt is None:
        missing = [name for name, boxes in (("bboxes", det), ("bboxes_gt", gt)) if boxes is None]
        for name in missing:
            ctx.report(log.file_of(name, ts), "", f"file missing ({_STOPS})", ts)
        skipped = f"{log.file_of(missing[0], ts)}: file missing"
        thresholds = ctx.params.values(REPORTED["perception"])
        return OracleResult(
            "perception", ts, False, thresholds=thresholds, skipped=skipped, missing_input=True
        )
    dropped = _tables(log).dropped
    if dropped:
        for name in ("bboxes", "bboxes_gt"):
            file = log.file_of(name, ts)
            if file in dropped:
                issue = "a box without an id or without two points"
                thresholds = ctx.params.values(REPORTED["perception"])
                return _skip(ctx, "perception", ts, file, "bounding_box", issue, thresholds)
    return judge_perception(det, gt, ts, thr, frame_match_scores(log, ts, det, gt))


def judge_perception(
    det: Boxes, gt: Boxes, ts: int, thr: float, scores: FloatArray | None = None
) -> OracleResult:
    """The reference perception oracle on two box records (no input checks); ``scores``:
    their match scores where already computed (:func:`frame_match_scores`)."""
    rows, cols, raw = greedy_match(det.corners, gt.corners, scores=scores)
    rounded = round4(raw)
    n = len(rows)
    # np.mean's arithmetic (pairwise sum, then one division); no match at all: NaN.
    mean = float(np.add.reduce(rounded)) / n if n else math.nan
    gt_ids = tuple([gt.ids[j] for j in cols])
    metrics: dict[str, Metric] = {
        "mean_iou": mean,
        "ious": rounded.tolist(),
        "n_matched": n,
        "det_ids": [det.ids[i] for i in rows],
    }
    failed = mean < thr  # NaN never fails
    return OracleResult("perception", ts, failed, metrics, {"perc_score_threshold": thr}, gt_ids)


# =========================================================================== prediction


def prediction(ctx: RunContext, ts: int) -> OracleResult:
    """First step of a non-ego track predicted on truth whose error/distance ratio reaches
    the threshold.

    Anchored at the ego pose at tk (the FUTURE pose: the reference's quirk) with the ego yaw
    at ts. Every key of every track is judged at once; the frame's outcome is its first
    event in file order: a crash (non-integer key, pose or actor missing at tk, pose
    missing at ts) or a failing step.
    """
    log = ctx.log
    thr = ctx.params.pred_score_threshold
    thresholds = {
        **ctx.params.values(REPORTED["prediction"]),
        "distance_gate_m": PRED_DISTANCE_GATE_M,
    }
    on_truth = log.predictions_with_perception.get(ts)
    if on_truth is None:
        file = log.file_of("predictions_with_perception", ts)
        return _skip(ctx, "prediction", ts, file, "", "file missing", thresholds)
    if not on_truth:  # no track, no step: nothing judged, nothing read
        return OracleResult("prediction", ts, False, {"n_steps": 0}, thresholds)
    flat = _flatten(on_truth)
    layout = flat.layout
    tables = _tables(log)
    steps = layout.steps
    tk = steps * log.frame_ms
    tk += ts
    judged = tk < log.metadata.end_ms
    crash = None if layout.all_int else ~layout.int_ok
    if crash is not None:
        judged &= layout.int_ok
    if ctx.ego_id in on_truth:  # the ego's own entry is never read
        not_ego = layout.track_of != flat.ids.index(ctx.ego_id)
        judged &= not_ego
        if crash is not None:
            crash &= not_ego
    ego_now = log.pose.get(ts)
    if ego_now is None:
        crash = judged if crash is None else crash | judged
        fail = crash
        error = dis = ratio = np.zeros(0)
    else:
        pose_row, actor_row = tables.rows_at(ts, steps)
        cols, sentinel = tables.actor_cols, tables.n_cols - 1
        col = np.array([cols.get(pid, sentinel) for pid in flat.ids], dtype=np.int64)
        cell = actor_row * tables.n_cols
        cell += col[layout.track_of]
        missing = ~tables.actor_present[cell]
        missing |= pose_row == len(tables.pose_times)
        missing &= judged
        crash = missing if crash is None else crash | missing
        # P = anchor + R(yaw_ts) (x, y), anchor = ego pose at tk; A = actor at tk.
        px, py = tables.pose_x[pose_row], tables.pose_y[pose_row]
        ax, ay = tables.actor_x[cell], tables.actor_y[cell]
        rx, ry = _rotate(flat.x, flat.y, ego_now.yaw)
        rx += px  # P
        rx -= ax
        ry += py
        ry -= ay
        error = _norm(rx, ry)  # |P - A|
        dis = _norm(px - ax, py - ay)  # |anchor - A|
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = error / dis  # float semantics: x/0 = inf, 0/0 = NaN
        fail = ratio >= thr
        fail &= dis < PRED_DISTANCE_GATE_M
        fail &= judged
    first = _first(crash | fail)
    if first < 0:
        n_steps = int(np.count_nonzero(judged))
        return OracleResult("prediction", ts, False, {"n_steps": n_steps}, thresholds)
    pid, key = flat.ids[int(layout.track_of[first])], layout.keys[first]
    if crash[first]:
        return _prediction_crash(ctx, ts, pid, key, int(tk[first]), thresholds)
    metrics: dict[str, Metric] = {
        "obstacle_id": pid,
        "key": key,
        "error": float(error[first]),
        "dis": float(dis[first]),
        "ratio": float(ratio[first]),
    }
    return OracleResult("prediction", ts, True, metrics, thresholds, (pid,))


def _prediction_crash(
    ctx: RunContext, ts: int, pid: str, key: str, tk: int, thresholds: dict[str, float]
) -> OracleResult:
    """The input problem at the step where the reference stops, in its reading order."""
    log = ctx.log
    if _parse_step(key) is None:
        file = log.file_of("predictions_with_perception", ts)
        issue = "step key is not an integer"
        return _skip(ctx, "prediction", ts, file, f"{pid}.{key}", issue, thresholds)
    if tk not in log.pose:
        file = log.file_of("pose", tk)
        return _skip(ctx, "prediction", ts, file, "", "pose missing", thresholds)
    if ts not in log.pose:
        file = log.file_of("pose", ts)
        return _skip(ctx, "prediction", ts, file, "yaw", "pose missing", thresholds)
    file = log.file_of("actors", tk)
    if tk not in log.actors:
        return _skip(ctx, "prediction", ts, file, "", "file missing", thresholds)
    issue = "actor missing (needed by a prediction step)"
    return _skip(ctx, "prediction", ts, file, pid, issue, thresholds)


# =========================================================================== planning


def planning(ctx: RunContext, ts: int) -> OracleResult:
    """First plan point whose box gap to a linked raw prediction is below the tolerance."""
    log, params = ctx.log, ctx.params
    thresholds = {k: float(v) for k, v in params.values(REPORTED["planning"]).items()}
    thresholds["link_distance_m"] = LINK_DISTANCE_M
    # 1. The ego yaw at ts and plan["0"] are read first.
    pose = log.pose.get(ts)
    if pose is None:
        return _skip(
            ctx, "planning", ts, log.file_of("pose", ts), "yaw", "pose missing", thresholds
        )
    plan = log.waypoints.get(ts)
    if plan is None or len(plan) == 0 or "0" not in plan.index:
        file = log.file_of("waypoint", ts)
        if plan is None:
            return _skip(ctx, "planning", ts, file, "", "file missing", thresholds)
        if len(plan) == 0:
            return _skip(ctx, "planning", ts, file, "", "empty plan", thresholds)
        return _skip(ctx, "planning", ts, file, "0", "plan has no point 0", thresholds)
    # 2. No raw predictions: nothing to collide with.
    raw = log.predictions.get(ts)
    if not raw:
        return OracleResult("planning", ts, False, {"links": {}}, thresholds)
    # 3. Link each raw id to an id on truth.
    on_truth = log.predictions_with_perception.get(ts)
    if on_truth is None:
        file = log.file_of("predictions_with_perception", ts)
        return _skip(ctx, "planning", ts, file, "", "file missing", thresholds)
    raw_flat = _flatten(raw)
    links = _link(ctx, ts, raw_flat, _flatten(on_truth), thresholds)
    if isinstance(links, OracleResult):
        return links
    # Even with nothing linked the plan keys are still visited (a non-integer one stops).
    return _judge_plan(ctx, ts, pose.yaw, plan, raw_flat, links, thresholds)


@dataclass(frozen=True, eq=False)
class _Links:
    """For each raw track (file order): linked or not, its half extents; the links."""

    linked: BoolArray  # (R,)
    ext_x: FloatArray  # (R,) garbage where not linked
    ext_y: FloatArray
    actor_ids: dict[str, str]  # raw id -> linked id on truth, in raw file order


def _link(
    ctx: RunContext, ts: int, raw: _Flat, on_truth: _Flat, thresholds: dict[str, float]
) -> _Links | OracleResult:
    """Each raw id's nearest non-ego id on truth by unrotated step "0" (< 100 m, earlier wins)."""
    log = ctx.log
    n_raw, n_on_truth = len(raw.ids), len(on_truth.ids)
    ego = on_truth.ids.index(ctx.ego_id) if ctx.ego_id in on_truth.ids else -1
    if n_on_truth - (ego >= 0) == 0:  # no candidate: every raw id is ignored, nothing is read
        nan = np.full(n_raw, np.nan)
        return _Links(np.zeros(n_raw, dtype=np.bool_), nan, nan, {})
    candidates = np.array([c for c in range(n_on_truth) if c != ego], dtype=np.int64)
    raw0, cand0 = raw.layout.zero_rows, on_truth.layout.zero_rows[candidates]
    if not (raw.layout.all_zero and (on_truth.layout.all_zero or _first(cand0 < 0) < 0)):
        # Read order: raw id 1's step "0", then every candidate's, then raw ids 2, 3 ...
        order = [("predictions", raw.ids[0], int(raw0[0]))]
        order += [
            ("predictions_with_perception", on_truth.ids[c], r)
            for c, r in zip(candidates.tolist(), cand0.tolist(), strict=True)
        ]
        order += [("predictions", rid, r) for rid, r in zip(raw.ids, raw0.tolist(), strict=True)]
        folder, obstacle_id, _ = next(item for item in order if item[2] < 0)
        file = log.file_of(folder, ts)
        return _skip(ctx, "planning", ts, file, obstacle_id, 'no step "0"', thresholds)
    dx = raw.x[raw0][:, None] - on_truth.x[cand0]  # (R, C)
    dy = raw.y[raw0][:, None] - on_truth.y[cand0]
    dist = _norm(dx, dy)
    dist[~(dist < LINK_DISTANCE_M)] = np.inf  # NaN never links
    nearest = dist.argmin(axis=1)  # the first minimum: the earlier id wins ties
    linked = dist.ravel()[nearest + np.arange(0, dist.size, dist.shape[1])] < np.inf
    tables = _tables(log)
    cols, sentinel = tables.actor_cols, tables.n_cols - 1
    cand_ids = [on_truth.ids[c] for c in candidates.tolist()]
    cand_col = np.array([cols.get(a, sentinel) for a in cand_ids], dtype=np.int64)
    col = cand_col[nearest]
    col[~linked] = sentinel
    ext_x, ext_y = tables.ext_x[col], tables.ext_y[col]
    no_extent = _first(linked & np.isnan(ext_x))  # read in raw file order
    if no_extent >= 0:
        actor_id = cand_ids[int(nearest[no_extent])]
        issue = "no extent for the actor a raw prediction links to"
        return _skip(ctx, "planning", ts, "actors/", f"{actor_id}.extent", issue, thresholds)
    actor_ids = {
        raw_id: cand_ids[k]
        for raw_id, k, ok in zip(raw.ids, nearest.tolist(), linked.tolist(), strict=True)
        if ok
    }
    return _Links(linked, ext_x, ext_y, actor_ids)


def _plan_pairs(layout: _Layout, plan: Plan) -> _PlanPairs:
    """Raw keys equal (as strings) to a plan key, by plan row then raw track (cached)."""
    found = layout.plan_pairs.lookup(plan.keys)
    if found is None:
        index = plan.index
        plan_row = np.array([index.get(k, -1) for k in layout.keys], dtype=np.int64)
        key = plan_row.__ge__(0).nonzero()[0]
        order = np.lexsort((layout.track_of[key], plan_row[key]))
        key = key[order]
        row = plan_row[key]
        steps, int_ok = _parse_steps(plan.keys)
        bad_row = _first(~int_ok)
        reachable = steps[row] != 0
        if bad_row >= 0:
            reachable &= row < bad_row
        found = _PlanPairs(key, row, layout.track_of[key], steps[row], reachable, bad_row)
        layout.plan_pairs.put(plan.keys, found)
    return found


def _judge_plan(
    ctx: RunContext,
    ts: int,
    yaw: float,
    plan: Plan,
    raw: _Flat,
    links: _Links,
    thresholds: dict[str, float],
) -> OracleResult:
    """All (plan index, linked track) pairs at once; the first event in visiting order.

    Visiting order: plan rows in file order, within a row the linked raw ids in file order.
    Events: a non-integer plan key (a crash, at its row, before its pairs), the first
    judged pair when the ego has no extent (a crash), a colliding pair (a failure).
    """
    log, params = ctx.log, ctx.params
    pairs = _plan_pairs(raw.layout, plan)
    bad_row = pairs.bad_row
    if not links.actor_ids:  # no pair is judged: only a non-integer plan key stops
        if bad_row >= 0:
            file, issue = log.file_of("waypoint", ts), "plan key is not an integer"
            return _skip(ctx, "planning", ts, file, plan.keys[bad_row], issue, thresholds)
        return OracleResult("planning", ts, False, {"links": {}}, thresholds)
    # Linked, i != 0, before any non-integer key, ts + i * frame_ms <= total_frames * frame_ms.
    step = pairs.step
    judged = links.linked[pairs.track]
    judged &= pairs.reachable
    judged &= step <= (log.metadata.end_ms - ts) // log.frame_ms
    ego_ext = log.actor_extents.get(ctx.ego_id) if ctx.ego_id is not None else None
    fail_at = -1
    gap_x = gap_y = tol = np.zeros(0)
    if ego_ext is None:
        fail_at = _first(judged)  # the first judged pair reads the ego's extent: a crash
        crash_row = int(pairs.row[fail_at]) if fail_at >= 0 else bad_row
        if crash_row >= 0 and (bad_row < 0 or crash_row < bad_row):
            field_name = f"{ctx.ego_id}.extent"
            issue = "the ego has no extent"
            return _skip(ctx, "planning", ts, "actors/", field_name, issue, thresholds)
    else:
        # Q = plan["0"] + R(yaw_ts) (x_i, y_i); W = plan point i.
        anchor = plan.xy[plan.index["0"]].tolist()
        qx, qy = _rotate(raw.x[pairs.key], raw.y[pairs.key], yaw)
        qx += anchor[0]
        qy += anchor[1]
        cam_x, cam_y = log.metadata.camera_loc[0], log.metadata.camera_loc[1]
        track = pairs.track
        gap_x = np.abs(plan.xy[:, 0][pairs.row] - qx)
        gap_x -= (links.ext_x[track] + ego_ext[0]) - cam_x
        gap_y = np.abs(plan.xy[:, 1][pairs.row] - qy)
        gap_y -= (links.ext_y[track] + ego_ext[1]) - cam_y
        near = step < params.planning_toleration_future_step
        tol = np.where(near, 0.0, -params.planning_toleration)
        fail = gap_x < tol
        fail &= gap_y < tol
        fail &= judged
        fail_at = _first(fail)
    if bad_row >= 0 and (fail_at < 0 or bad_row <= pairs.row[fail_at]):
        file, issue = log.file_of("waypoint", ts), "plan key is not an integer"
        return _skip(ctx, "planning", ts, file, plan.keys[bad_row], issue, thresholds)
    link_summary: dict[str, Metric] = dict(links.actor_ids)
    if fail_at < 0:
        return OracleResult("planning", ts, False, {"links": link_summary}, thresholds)
    n, raw_id = int(pairs.row[fail_at]), raw.ids[int(pairs.track[fail_at])]
    actor_id = links.actor_ids[raw_id]
    metrics: dict[str, Metric] = {
        "index": int(_parse_steps(plan.keys)[0][n]),
        "key": plan.keys[n],
        "raw_id": raw_id,
        "linked_id": actor_id,
        "gap_x": float(gap_x[fail_at]),
        "gap_y": float(gap_y[fail_at]),
        "tol": float(tol[fail_at]),
        "links": link_summary,
    }
    return OracleResult("planning", ts, True, metrics, thresholds, (raw_id, actor_id))


# =========================================================================== control


def _control_score(a: float, b: float) -> float:
    """The reference's per-axis helper: 1 when the planned step is short or tracked well.

    Note the inversion the reference applies at the call site: a failure is declared
    UNLESS both scores are below 0.1, so good tracking (score 1) is a failure.
    """
    if abs(b) < CONTROL_STEP_MIN_M:
        return 1.0
    if abs(a - b) < CONTROL_STEP_MIN_M:
        return 1.0
    return abs(a - b) / abs(b)


_CONTROL_THRESHOLDS = {
    "move_gate_m": CONTROL_MOVE_GATE_M,
    "step_min_m": CONTROL_STEP_MIN_M,
    "score_max": CONTROL_SCORE_MAX,
}


def control(ctx: RunContext, ts: int) -> OracleResult:
    """Planned step (plan["1"] - pose[ts]) against the actual step, the reference's way."""
    log = ctx.log
    frame_ms = log.frame_ms
    thresholds = dict(_CONTROL_THRESHOLDS)
    plan = log.waypoints.get(ts)
    if plan is None:
        file = log.file_of("waypoint", ts)
        return _skip(ctx, "controller", ts, file, "", "file missing", thresholds)
    if len(plan) == 0:
        # The reference never gets here (planning stopped on the empty plan); no failure.
        return OracleResult(  # the reference has crashed in planning on it already
            "controller", ts, False, thresholds=thresholds, skipped="empty plan", missing_input=True
        )
    if ts + frame_ms > log.metadata.end_ms:
        return OracleResult("controller", ts, False, {"beyond_end": True}, thresholds)
    row = plan.index.get("1")
    if row is None:
        file = log.file_of("waypoint", ts)
        return _skip(ctx, "controller", ts, file, "1", "plan has no point 1", thresholds)
    now, nxt = log.pose.get(ts), log.pose.get(ts + frame_ms)
    if now is None or nxt is None:
        file = log.file_of("pose", ts if now is None else ts + frame_ms)
        return _skip(ctx, "controller", ts, file, "", "pose missing", thresholds)
    px, py = plan.xy[row].tolist()
    bx, by = px - now.x, py - now.y  # planned step
    ax, ay = nxt.x - now.x, nxt.y - now.y  # actual step
    if math.isnan(ax + ay + bx + by):
        bad = _unreadable_control_input(ctx, ts)
        if bad is not None:
            issue = "missing or not a number"
            return _skip(ctx, "controller", ts, bad[0], bad[1], issue, thresholds)
    metrics: dict[str, Metric] = {"a": [ax, ay], "b": [bx, by]}
    if abs(ax) < CONTROL_MOVE_GATE_M and abs(ay) < CONTROL_MOVE_GATE_M:
        return OracleResult("controller", ts, False, metrics, thresholds)
    sx, sy = _control_score(ax, bx), _control_score(ay, by)
    metrics["s_x"], metrics["s_y"] = sx, sy
    failed = not (sx < CONTROL_SCORE_MAX and sy < CONTROL_SCORE_MAX)
    return OracleResult("controller", ts, failed, metrics, thresholds)


def _unreadable_control_input(ctx: RunContext, ts: int) -> tuple[str, str] | None:
    """The first control input the loader could not read (the reference crashes on it).

    A NaN the file really contained (a "nan" string) is data the reference computes with;
    only values the loader reported missing or not a number stop it.
    """
    log = ctx.log
    nan_fields = _tables(log).nan_fields
    for folder, t, names in (
        ("waypoint", ts, ("1.x", "1.y")),
        ("pose", ts, ("x", "y")),
        ("pose", ts + log.frame_ms, ("x", "y")),
    ):
        file = log.file_of(folder, t)
        for name in names:
            if name in nan_fields.get(file, ()):
                return file, name
    return None


# =========================================================================== registry

#: The reference oracles in pipeline order (module names as the reference spells them).
ORACLES: dict[Module, Callable[[RunContext, int], OracleResult]] = {
    "perception": perception,
    "prediction": prediction,
    "planning": planning,
    "controller": control,
}
