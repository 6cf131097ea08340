"""Clearance, the common currency of the `corrected` rules, and the partner's view at ts.

Clearance c(X) at ts is the minimum over horizon indices i = 1..``prediction_window`` (where
both boxes exist) of the signed edge-to-edge distance between the ego's plan box i and X's
box i; negative is penetration. A clearance with no such index is undefined (NaN), so
every comparison with it is false, which is exactly the spec's reading.

:class:`PartnerView` gathers, once per timestamp, everything perception, prediction and
planning ask about the partner: its real boxes, its boxes predicted on truth (the predictions
on truth, ``predictions_with_perception``: the stack's predictor given ground-truth perception)
and its raw boxes (the planner's ``predictions``, linked by the reference's rule; without any
predictions on truth in the log, the track the 3-D match paired with the partner), the three
clearances, displacement errors and the displacement threshold.
"""

from __future__ import annotations

import math
import operator
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import numpy.typing as npt

from ads_rca.foundation.geometry import (
    FloatArray,
    box_signed_distance,
    half_rows,
    signed_distance_rows,
)
from ads_rca.model import Predictions
from ads_rca.oracles.cache import CACHE_SIZE
from ads_rca.oracles.corrected.boxes import PlanData, Series, all_steps, braking_boxes
from ads_rca.oracles.corrected.context import CacheName, CorrectedContext
from ads_rca.oracles.corrected.floors import partner_object
from ads_rca.oracles.corrected.links import raw_links
from ads_rca.oracles.corrected.match3d import raw_without_predictions_on_truth

NAN = float("nan")
#: Clearances this close count as equal when choosing the earliest index of the minimum.
TIE_TOLERANCE = 1e-9


@dataclass(frozen=True)
class Clearance:
    """A clearance and where it is reached (``index`` -1 and NaN when undefined)."""

    value: float
    index: int
    per_index: FloatArray  # (W + 1,) signed distance per index, NaN where undefined

    @property
    def defined(self) -> bool:
        return self.index >= 0


@lru_cache(maxsize=8)
def undefined_clearance(window: int) -> Clearance:
    """The undefined clearance (one shared instance per window: its array is read-only)."""
    per_index = np.full(window + 1, np.nan)
    per_index.flags.writeable = False
    return Clearance(NAN, -1, per_index)


def clearances(
    plan: Series | None, others: Sequence[Series | None], window: int
) -> list[Clearance]:
    """c(X) for each X in ``others`` against the plan boxes, in one vectorised call."""
    return pair_clearances([(plan, other) for other in others], window)


def pair_clearances(
    pairs: Sequence[tuple[Series | None, Series | None]], window: int
) -> list[Clearance]:
    """The clearance of each (ego boxes, other boxes) pair, all in one vectorised call.

    Indices where either box is missing give NaN distances, ignored by the minimum. A pair
    given twice (the same two series, e.g. the reference that is the real boxes) is
    measured once.
    """
    undefined = undefined_clearance(window)
    rows: dict[tuple[int, int], int] = {}
    given: list[tuple[Series, Series]] = []
    row_of: list[int] = []
    for a, b in pairs:
        if a is None or b is None or window < 1:
            row_of.append(-1)
            continue
        row = rows.setdefault((id(a), id(b)), len(given))
        if row == len(given):
            given.append((a, b))
        row_of.append(row)
    if not given:
        return [undefined] * len(pairs)
    dist = _pair_distances(given, window)
    low, first = lowest(dist)
    per = np.empty((len(given), window + 1))
    per[:, 0] = np.nan
    per[:, 1:] = dist
    found = [
        Clearance(value, index + 1, per[row]) if math.isfinite(value) else undefined
        for row, (value, index) in enumerate(zip(low.tolist(), first.tolist(), strict=True))
    ]
    return [undefined if row < 0 else found[row] for row in row_of]


def _pair_distances(pairs: list[tuple[Series, Series]], window: int) -> FloatArray:
    """Signed distances (N, W) of N pairs of series at indices 1..W (NaN where a box is
    missing): every pair's boxes in one row, one distance call."""
    if len(pairs) == 1:
        ((a, b),) = pairs
        a_center, a_yaw, b_center, b_yaw = a.center[1:], a.yaw[1:], b.center[1:], b.yaw[1:]
    else:
        a_center = np.concatenate([a.center[1:] for a, _ in pairs])
        a_yaw = np.concatenate([a.yaw[1:] for a, _ in pairs])
        b_center = np.concatenate([b.center[1:] for _, b in pairs])
        b_yaw = np.concatenate([b.yaw[1:] for _, b in pairs])
    halves = _halves(tuple((*a.half.tolist(), *b.half.tolist()) for a, b in pairs), window)
    return signed_distance_rows(a_center, a_yaw, b_center, b_yaw, halves).reshape(
        len(pairs), window
    )


@lru_cache(maxsize=64)
def _halves(pairs: tuple[tuple[float, ...], ...], window: int) -> FloatArray:
    """The pairs' half extents (each pair's A x, y and B x, y) repeated over their W
    indices, as the distance takes them (memoised: the ego's and the partner's extents are
    the same every frame; read-only)."""
    out = np.repeat(half_rows(np.array(pairs, dtype=np.float64)), window, axis=1)
    out.flags.writeable = False
    return out


def index_distances(
    a_center: FloatArray,
    a_half: FloatArray,
    a_yaw: FloatArray,
    b_center: FloatArray,
    b_half: FloatArray,
    b_yaw: FloatArray,
) -> FloatArray:
    """Signed distances (N, W) between N pairs of box series at indices 1..W: centres
    (N, W + 1, 2), half extents (N, 2), yaws (N, W + 1); NaN where a box is missing."""
    count, window = a_center.shape[0], a_center.shape[1] - 1
    return box_signed_distance(
        a_center[:, 1:].reshape(-1, 2),
        np.repeat(a_half, window, axis=0),
        a_yaw[:, 1:].reshape(-1),
        b_center[:, 1:].reshape(-1, 2),
        np.repeat(b_half, window, axis=0),
        b_yaw[:, 1:].reshape(-1),
    ).reshape(count, window)


def lowest(dist: FloatArray) -> tuple[FloatArray, npt.NDArray[np.int64]]:
    """Per row of ``dist`` (N, W), the minimum over defined indices (inf if none) and the
    earliest column reaching it (within :data:`TIE_TOLERANCE`)."""
    masked = np.fmin(dist, np.inf)  # NaN -> inf, every other value as it is
    low = masked.min(axis=1)
    first = (masked <= (low + TIE_TOLERANCE)[:, None]).argmax(axis=1)
    return low, first


def displacement(a: Series | None, b: Series | None) -> float:
    """Max over i = 1..W (both present) of the centre distance between two series; NaN if none."""
    if a is None or b is None:
        return NAN
    both = a.present & b.present
    both[0] = False  # a fresh array
    if not both.any():
        return NAN
    d = a.center[both] - b.center[both]
    return float(np.hypot(d[:, 0], d[:, 1]).max())


def path_length(real: Series | None) -> float:
    """Path length of the real positions at ts, ts + frame_ms, …, ts + W·frame_ms (present ones)."""
    if real is None:
        return NAN
    pts = real.center[real.present]
    if len(pts) < 2:
        return 0.0 if len(pts) == 1 else NAN
    step = pts[1:] - pts[:-1]
    return float(np.hypot(step[:, 0], step[:, 1]).sum())


def path_lengths(series: list[Series]) -> list[float | None]:
    """:func:`path_length` of each series with a box at every index, in one array (the same
    differences and distances; each row summed as one series is); None for the others."""
    if len(series) < 2:
        return [None] * len(series)
    center = np.array([s.center for s in series])
    yaw = np.array([s.yaw for s in series])
    whole = np.isfinite(center).all(axis=(1, 2)) & np.isfinite(yaw).all(axis=1)
    if center.shape[1] < 2 or not whole.any():
        return [None] * len(series)
    step = center[:, 1:] - center[:, :-1]
    total = np.hypot(step[..., 0], step[..., 1]).sum(axis=1).tolist()
    return [t if w else None for t, w in zip(total, whole.tolist(), strict=True)]


def displacement_threshold(judging: CorrectedContext, travelled: float) -> float:
    """max(pred_abs_threshold, pred_score_threshold × distance travelled over the horizon)."""
    p = judging.params
    scaled = p.pred_score_threshold * travelled if math.isfinite(travelled) else 0.0
    return float(max(p.pred_abs_threshold, scaled))


@dataclass(frozen=True)
class PartnerView:
    """What the partner-dependent rules need at one timestamp."""

    partner_id: str | None
    plan: PlanData | None
    real: Series | None
    on_truth: Series | None
    raw: Series | None
    raw_id: str | None
    ref: Series | None
    c_gt: Clearance
    c_on_truth: Clearance
    c_raw: Clearance
    c_ref: Clearance
    c_brake: Clearance  # the plan's path braking at max_decel from v0, vs the raw boxes
    e_on_truth: float  # max |predicted on truth − real| of the partner over the horizon
    raw_displacement: float  # max |raw − reference| over the horizon
    travelled: float
    threshold: float  # displacement threshold
    in_view: bool | None  # partner has a gt box (None: no bboxes_gt file)
    in_predictions_on_truth: bool | None  # partner in predictions_with_perception (None: no file)
    raw_file: bool  # the predictions file exists
    real_conflict: bool


PARTNER_VIEW: CacheName[PartnerView] = CacheName("partner_view")


def partner_view(judging: CorrectedContext, ts: int) -> PartnerView:
    """The partner's view at ts (cached per timestamp, rebuilt should the partner at ts
    change: a collision announced after a provisional partner was judged)."""
    cache = judging.cache(PARTNER_VIEW)
    view = cache.lookup(ts)
    if view is None or view.partner_id != judging.partner_at(ts):
        view = _build_view(judging, ts)
        cache.put(ts, view)
    return view


def _build_view(judging: CorrectedContext, ts: int) -> PartnerView:
    log, w = judging.log, judging.window
    partner = judging.partner_at(ts)
    plan = judging.plan(ts)
    pose = log.pose.get(ts)
    gt = log.bboxes_gt.get(ts)
    on_truth_file = log.predictions_with_perception.get(ts)
    raw_file = log.predictions.get(ts)
    in_view = None if gt is None or partner is None else partner in gt.ids
    in_predictions_on_truth = (
        None if on_truth_file is None or partner is None else partner in on_truth_file
    )
    real = on_truth = raw = None
    raw_id = None
    measured = None if partner is None or plan is None else _measured(judging, ts, partner, plan)
    travelled = None if measured is None else measured[2]
    if partner is not None:
        real = measured[0] if measured is not None else judging.real_series(partner, ts)
        if pose is not None and on_truth_file is not None and partner in on_truth_file:
            on_truth = judging.predicted_series(on_truth_file[partner], pose, partner, ts)
            if raw_file is not None:
                raw_id = link_raw(judging, ts, raw_file, on_truth_file, partner)
                if raw_id is not None:
                    raw = judging.predicted_series(raw_file[raw_id], pose, partner, ts)
        elif (
            pose is not None and raw_file is not None and raw_without_predictions_on_truth(judging)
        ):
            raw_id = partner_object(judging, ts, partner)  # the 3-D match stands in for the link
            if raw_id is not None and raw_id in raw_file:
                raw = judging.predicted_series(raw_file[raw_id], pose, partner, ts)
            else:
                raw_id = None
    ref = _reference(on_truth, real)
    ego = plan.boxes if plan else None
    brake = None
    if plan is not None and raw is not None and pose is not None:
        p = judging.params
        brake = braking_boxes(
            plan, pose.yaw, plan.speed_of(0), p.max_decel, judging.frame_ms / 1000.0, w
        )
    c_gt = undefined_clearance(w)
    if measured is not None:
        c_gt = measured[1]
    elif plan is not None and real is not None and partner is not None:
        c_gt = _ground_truth(judging, ts, partner, plan, real)
    # without predictions on truth the reference is the real boxes: c_ref is c_gt
    same = ref is real
    pairs = [(ego, on_truth), (ego, raw), (None if same else ego, ref), (brake, raw)]
    c_on_truth, c_raw, c_ref, c_brake = pair_clearances(pairs, w)
    if same:
        c_ref = c_gt
    if travelled is None:
        travelled = path_length(real)
    return PartnerView(
        partner_id=partner,
        plan=plan,
        real=real,
        on_truth=on_truth,
        raw=raw,
        raw_id=raw_id,
        ref=ref,
        c_gt=c_gt,
        c_on_truth=c_on_truth,
        c_raw=c_raw,
        c_ref=c_ref,
        c_brake=c_brake,
        e_on_truth=displacement(on_truth, real),
        raw_displacement=displacement(raw, ref),
        travelled=travelled,
        threshold=displacement_threshold(judging, travelled),
        in_view=in_view,
        in_predictions_on_truth=in_predictions_on_truth,
        raw_file=raw_file is not None,
        real_conflict=bool(c_gt.value < judging.params.safety_margin),
    )


#: c_gt by timestamp, with the plan and real boxes it was measured on, what those real
#: boxes were read from (:meth:`CorrectedContext.real_sources`) and their path length (None
#: where the batch left it to :func:`path_length`).
GROUND_TRUTH: CacheName[tuple[PlanData, Series, Clearance, tuple[object, ...], float | None]] = (
    CacheName("c_gt")
)


#: Frames after ts whose c_gt is measured with it (at least W): a batch costs a few dozen
#: numpy calls whatever its length, so a longer one costs less per frame; half the plans
#: cache (:data:`~ads_rca.oracles.cache.CACHE_SIZE`), so that its plans are still there
#: when their frames are judged. Like control's step blocks, a batch reads the plans and
#: poses present when it is made (a live monitor judges each window on a new context).
BATCH_AHEAD = CACHE_SIZE // 2


def _measured(
    judging: CorrectedContext, ts: int, partner: str, plan: PlanData
) -> tuple[Series, Clearance, float | None] | None:
    """The real boxes, c_gt and path length a batch measured at ts, if on this very plan and on
    the records a fresh read of the real boxes would read (the same objects), so the frame
    neither rebuilds nor compares its real boxes; kept as ts's real series."""
    found = judging.cache(GROUND_TRUTH).lookup(ts)
    if found is None or found[0] is not plan:
        return None
    sources = judging.real_sources(partner, ts)
    if len(sources) != len(found[3]) or not all(map(operator.is_, sources, found[3])):
        return None
    judging.keep_real_series(partner, ts, found[1])
    return found[1], found[2], found[4]


def _ground_truth(
    judging: CorrectedContext, ts: int, partner: str, plan: PlanData, real: Series
) -> Clearance:
    """c_gt at ts. With a collision partner (the same every frame), measured in one call
    with the :data:`BATCH_AHEAD` frames after it (W if longer) and kept per frame with the
    plan and real boxes it was measured on: a frame takes it only for that very plan and the
    same real boxes (a frame read again since, in a live window, is measured afresh). A batch
    stops at a frame without a plan or pose, already measured, or whose plan has a key that
    is no step (building it reports that, which stays with the frame judged)."""
    cache = judging.cache(GROUND_TRUTH)
    found = cache.lookup(ts)
    if found is not None and found[0] is plan and _same_boxes(found[1], real):
        return found[2]
    batch = [(ts, plan, real)]
    log = judging.log
    if log.metadata.collision_frame >= 0 and judging.frame_ms > 0:
        ahead: list[int] = []
        for k in range(1, max(judging.window, BATCH_AHEAD) + 1):
            u = ts + k * judging.frame_ms
            waypoints = log.waypoints.get(u)
            if waypoints is None or u not in log.pose or cache.lookup(u) is not None:
                break
            if not all_steps(waypoints.keys):
                break
            ahead.append(u)
        judging.plans_ahead(ahead)
        # the real boxes from the batch's previous ones, kept only with this c_gt (they read
        # frames past ts's horizon, which a frame judged later reads for itself)
        run = judging.real_series_run(partner, ts, real, len(ahead))
        for u, seen in zip(ahead, run, strict=False):
            later = judging.plan(u)
            if later is None:
                break
            batch.append((u, later, seen))
    measured = pair_clearances([(p.boxes, r) for _, p, r in batch], judging.window)
    lengths = path_lengths([r for _, _, r in batch])
    for (u, p, r), c, length in zip(batch, measured, lengths, strict=True):
        cache.put(u, (p, r, c, judging.real_sources(partner, u), length))
    return measured[0]


def _same_boxes(a: Series, b: Series) -> bool:
    return a is b or (
        a.center.tobytes() == b.center.tobytes()
        and a.yaw.tobytes() == b.yaw.tobytes()
        and a.half.tobytes() == b.half.tobytes()
    )


def _reference(on_truth: Series | None, real: Series | None) -> Series | None:
    """The boxes predicted on truth, with the real boxes at indices where there is none."""
    if on_truth is None:
        return real
    if real is None:
        return on_truth
    fill = ~on_truth.present
    center, yaw = on_truth.center.copy(), on_truth.yaw.copy()
    center[fill], yaw[fill] = real.center[fill], real.yaw[fill]
    return Series(center, yaw, on_truth.half)


def link_raw(
    judging: CorrectedContext, ts: int, raw: Predictions, on_truth: Predictions, partner: str
) -> str | None:
    """The raw id linked to the partner by the reference's linking rule.

    Each raw id links to the id on truth (file order, ego skipped) with the smallest distance
    between the unrotated step-"0" offsets, strictly below 100 m, earlier id on ties. If
    several raw ids link to the partner: the one nearest the partner's step "0" on truth.
    """
    if (
        partner == judging.ego_id
        or partner not in on_truth
        or on_truth[partner].offset("0") is None
    ):
        return None
    if any(track.offset("0") is None for track in raw.values()):
        judging.ctx.report(
            judging.log.file_of("predictions", ts), "step 0", "a raw id has no step 0; ignored", ts
        )
    return raw_links(raw, on_truth, judging.ego_id).get(partner)
