"""Perception judged without ground truth: what a run's own tracks show of it.

Why: when the stack's tracks stand in for the world (:mod:`ads_rca.diagnosis.perceived`),
perception cannot be compared with itself; rule 2b would find every track matched and call
perception sound. Some of perception's failures still leave marks in what it perceived, and
these are judged (each frame's result says which mark it found, and against what):

- **late sight**: the partner was first perceived, inside the effect window, closer to the
  ego than the ego could stop from (v²/(2 ``max_decel``) + v ``actuator_delay`` +
  ``safety_margin``): the ego then had to react to an object it should have seen earlier;
- **lost track**: an object tracked within ``event_clearance`` + the stopping distance of
  the ego, ahead of it, vanished inside the effect window and is not perceived again before
  the frame judged (the tracker dropped something it should have kept);
- **inconsistent track**: the partner's perceived velocity disagrees with its own perceived
  motion over the next ``prediction_window`` frames by more than ``perc3d_velocity_error``
  (a tracker reporting a braking car as cruising), or its position jumps between two frames
  by more than its speed explains plus ``pred_abs_threshold``;
- **untracked detection**: for ``min_persistence`` frames up to the one judged, the detector
  saw an object ahead of the ego within its stopping distance that no track is within
  ``perc3d_match_distance`` of (the tracker dropped or had not yet confirmed what the
  detector saw: the planner, reading tracks, did not know it).

A frame with none of these marks is not evidence that perception was right: the module is
"partly judged (no ground truth ...)" in every output, and a verdict that finds no failing
module says perception is suspected (docs/real-drives.md).
"""

from __future__ import annotations

import math

import numpy as np

from ads_rca.diagnosis.perceived import EGO_ID
from ads_rca.foundation.geometry import box_signed_distance
from ads_rca.oracles.base import Metric, OracleResult, RunContext
from ads_rca.oracles.corrected.context import (
    CacheName,
    CorrectedContext,
    corrected_context,
    window_frames,
)

#: How the module's status reads when the run has no ground truth.
STATUS = (
    "partly judged (no ground truth: only late sight, lost tracks, track consistency and "
    "untracked detections; perception suspected unless another module failed)"
)
#: What the results were judged against.
AGAINST = "the stack's own tracks (no ground truth)"
THRESHOLDS = (
    "max_decel",
    "actuator_delay",
    "safety_margin",
    "event_clearance",
    "perc3d_velocity_error",
    "pred_abs_threshold",
    "prediction_window",
    "perc3d_match_distance",
    "min_persistence",
)
SIGHTINGS: CacheName[dict[str, tuple[int, int]]] = CacheName("sightings")


def sightings(judging: CorrectedContext) -> dict[str, tuple[int, int]]:
    """Every perceived object's first and last timestamp in the run (run-wide, once)."""

    def build() -> dict[str, tuple[int, int]]:
        out: dict[str, tuple[int, int]] = {}
        for ts in sorted(judging.log.actors):
            for actor_id in judging.log.actors[ts].ids:
                first, _ = out.get(actor_id, (ts, ts))
                out[actor_id] = (first, ts)
        return out

    return judging.cache(SIGHTINGS).get(-1, build)


def _window_ms(judging: CorrectedContext) -> int:
    """The effect window's span (ms): how far back a mark counts."""
    return window_frames(judging.params, judging.frame_ms) * judging.frame_ms


def _stopping_distance(judging: CorrectedContext, ts: int) -> float:
    pose = judging.log.pose.get(ts)
    v = pose.speed if pose is not None and math.isfinite(pose.speed) else 0.0
    p = judging.params
    return v * v / (2 * p.max_decel) + v * p.actuator_delay + p.safety_margin


def _ego_xy_yaw(judging: CorrectedContext, ts: int) -> tuple[np.ndarray, float] | None:
    frame = judging.log.actors.get(ts)
    if frame is None or EGO_ID not in frame.index:
        return None
    row = frame.index[EGO_ID]
    return frame.location[row, :2], math.radians(float(frame.rotation[row, 2]))


def _distance(judging: CorrectedContext, actor_id: str, ts: int) -> float:
    """Centre distance minus both half lengths' worth of box (a cheap, conservative gap)."""
    frame = judging.log.actors.get(ts)
    ego = _ego_xy_yaw(judging, ts)
    if frame is None or ego is None or actor_id not in frame.index:
        return math.nan
    row = frame.index[actor_id]
    gap = float(np.hypot(*(frame.location[row, :2] - ego[0])))
    return gap - float(frame.extent[row, 0]) - float(frame.extent[frame.index[EGO_ID], 0])


def late_sight(judging: CorrectedContext, ts: int, partner: str) -> dict[str, Metric] | None:
    """The partner's first sighting, when it was inside the window before ts and too close."""
    first, _ = sightings(judging).get(partner, (None, None))
    if first is None or first > ts or ts - first > _window_ms(judging):
        return None
    distance = _distance(judging, partner, first)
    stop = _stopping_distance(judging, first)
    if not (distance < stop):
        return None
    return {
        "late_sight_ms": first,
        "late_sight_distance": distance,
        "stopping_distance": stop,
    }


def lost_tracks(judging: CorrectedContext, ts: int) -> list[str]:
    """Objects whose track ended inside the window before ts and that, kept moving at their
    last perceived velocity, come within ``safety_margin`` of the ego's realised boxes over
    the next ``prediction_window`` frames: the ego drives into where a dropped object would
    be (an object merely out of sight, driving on, is not one)."""
    lost: list[str] = []
    for actor_id, (first, last) in sightings(judging).items():
        if actor_id == EGO_ID or last >= ts or ts - last > _window_ms(judging) or first == last:
            continue
        gap = _extrapolated_gap(judging, actor_id, last, ts)
        if gap < judging.params.safety_margin:
            lost.append(actor_id)
    return lost


def _velocity(judging: CorrectedContext, actor_id: str, ts: int) -> np.ndarray:
    """An object's perceived world velocity (x, y) at ts: its track's, else its motion over
    the frame before."""
    tracks = judging.log.tracks_3d.get(ts)
    if tracks is not None and actor_id in tracks.ids:
        v = tracks.velocity[tracks.ids.index(actor_id), :2]
        if np.isfinite(v).all():
            return np.asarray(v, dtype=np.float64)
    log = judging.log
    before = [t for t in log.unique_frames if t < ts and t in log.actors]
    if before and actor_id in log.actors[before[-1]].index:
        prev = log.actors[before[-1]]
        here = log.actors[ts]
        dt = (ts - before[-1]) / 1000.0
        return (
            here.location[here.index[actor_id], :2] - prev.location[prev.index[actor_id], :2]
        ) / dt
    return np.zeros(2)


def _extrapolated_gap(judging: CorrectedContext, actor_id: str, last: int, ts: int) -> float:
    """The least box distance between the ego's realised boxes at ts .. ts + W frames and
    the object moved on from its last sighting at its last velocity (inf when none)."""
    log = judging.log
    frame = log.actors[last]
    row = frame.index[actor_id]
    velocity = _velocity(judging, actor_id, last)
    stamps = [
        ts + i * judging.frame_ms
        for i in range(judging.window + 1)
        if ts + i * judging.frame_ms in log.actors
        and EGO_ID in log.actors[ts + i * judging.frame_ms].index
    ]
    if not stamps:
        return math.inf
    ego_rows = [log.actors[t].index[EGO_ID] for t in stamps]
    ego_c = np.array([log.actors[t].location[r, :2] for t, r in zip(stamps, ego_rows, strict=True)])
    ego_yaw = np.array(
        [log.actors[t].rotation[r, 2] for t, r in zip(stamps, ego_rows, strict=True)]
    )
    ego_half = log.actors[stamps[0]].extent[ego_rows[0], :2]
    dt = (np.asarray(stamps, dtype=np.float64) - last) / 1000.0
    centres = frame.location[row, :2] + dt[:, None] * velocity
    n = len(stamps)
    with np.errstate(invalid="ignore", over="ignore"):
        dist = box_signed_distance(
            ego_c,
            np.broadcast_to(ego_half, (n, 2)),
            ego_yaw,
            centres,
            np.broadcast_to(frame.extent[row, :2], (n, 2)),
            np.full(n, frame.rotation[row, 2]),
        )
    finite = dist[np.isfinite(dist)]
    return float(finite.min()) if finite.size else math.inf


def inconsistency(judging: CorrectedContext, ts: int, partner: str) -> dict[str, Metric] | None:
    """The partner's track disagreeing with itself at ts (velocity or position)."""
    log = judging.log
    tracks = log.tracks_3d.get(ts)
    frame = log.actors.get(ts)
    if tracks is None or frame is None or partner not in frame.index:
        return None
    p = judging.params
    here = frame.location[frame.index[partner], :2]
    found: dict[str, Metric] = {}
    row = tracks.ids.index(partner) if partner in tracks.ids else None
    velocity = tracks.velocity[row, :2] if row is not None else np.full(2, np.nan)
    moved = _central_velocity(judging, partner, ts)
    if moved is not None and np.isfinite(velocity).all():
        error = float(np.hypot(*(velocity - moved)))
        if error > p.perc3d_velocity_error:
            found["velocity_inconsistency"] = error
    before = ts - judging.frame_ms
    if before in log.actors and partner in log.actors[before].index:
        prev = log.actors[before].location[log.actors[before].index[partner], :2]
        speed = float(np.hypot(*velocity)) if np.isfinite(velocity).all() else 0.0
        jump = float(np.hypot(*(here - prev))) - speed * judging.frame_ms / 1000.0
        if jump > p.pred_abs_threshold + p.perc3d_velocity_error * judging.frame_ms / 1000.0:
            found["position_jump"] = jump
    return found or None


#: Frames either side of ts over which an object's own motion gives its velocity (a central
#: difference: exact under constant acceleration, so a braking car is not "inconsistent").
MOTION_REACH = 2


def _central_velocity(judging: CorrectedContext, actor_id: str, ts: int) -> np.ndarray | None:
    """An object's velocity from its perceived positions :data:`MOTION_REACH` frames before
    and after ts (the nearest reach both sides have; None without one)."""
    log = judging.log
    for k in range(MOTION_REACH, 0, -1):
        a, b = ts - k * judging.frame_ms, ts + k * judging.frame_ms
        if a in log.actors and b in log.actors:
            fa, fb = log.actors[a], log.actors[b]
            if actor_id in fa.index and actor_id in fb.index:
                moved = fb.location[fb.index[actor_id], :2] - fa.location[fa.index[actor_id], :2]
                return np.asarray(moved / ((b - a) / 1000.0), dtype=np.float64)
    return None


def untracked_detections(judging: CorrectedContext, ts: int) -> tuple[int, float] | None:
    """(how many, the nearest's gap in m) of the detections at ts ahead of the ego within
    its stopping distance that no track is within ``perc3d_match_distance`` of, when each of
    the ``min_persistence`` frames up to ts has such a detection (None otherwise)."""
    p = judging.params
    found: tuple[int, float] | None = None
    for k in range(max(p.min_persistence, 1)):
        at = ts - k * judging.frame_ms
        unmatched = _untracked_at(judging, at)
        if not unmatched:
            return None
        if k == 0:
            found = (len(unmatched), min(unmatched))
    return found


def _untracked_at(judging: CorrectedContext, ts: int) -> list[float]:
    """Gaps (m) to the ego of the detections at ts ahead of it, within its stopping
    distance, that no track (the world's actors but the ego) is near."""
    log = judging.log
    detections, frame = log.detections_3d.get(ts), log.actors.get(ts)
    ego = _ego_xy_yaw(judging, ts)
    if detections is None or frame is None or ego is None or not len(detections.ids):
        return []
    centre, yaw = ego
    ego_length = float(frame.extent[frame.index[EGO_ID], 0])
    tracked = np.array(
        [frame.location[r, :2] for a, r in frame.index.items() if a != EGO_ID], dtype=np.float64
    ).reshape(-1, 2)
    stop = _stopping_distance(judging, ts)
    heading = np.array([math.cos(yaw), math.sin(yaw)])
    gaps: list[float] = []
    for row in range(len(detections.ids)):
        xy = np.asarray(detections.location[row, :2], dtype=np.float64)
        if not np.isfinite(xy).all():
            continue
        offset = xy - centre
        gap = float(np.hypot(*offset)) - float(detections.extent[row, 0]) - ego_length
        if float(offset @ heading) <= 0 or not (gap < stop):
            continue
        near = np.hypot(*(tracked - xy).T) if len(tracked) else np.empty(0)
        if not (near <= judging.params.perc3d_match_distance).any():
            gaps.append(gap)
    return gaps


def perception_without_truth(ctx: RunContext, ts: int) -> OracleResult:
    """Perception at ts, by the marks its failures leave in the run's own tracks."""
    judging = corrected_context(ctx)
    thresholds = judging.reported(THRESHOLDS)
    metrics: dict[str, Metric] = {"check": "without ground truth", "against": AGAINST}
    if ts not in judging.log.actors:
        return OracleResult("perception", ts, False, metrics, thresholds, skipped="no tracks")
    partner = judging.partner_at(ts)
    marks: list[str] = []
    if partner is not None:
        sight = late_sight(judging, ts, partner)
        if sight is not None:
            metrics.update(sight)
            marks.append("late sight")
        track = inconsistency(judging, ts, partner)
        if track is not None:
            metrics.update(track)
            marks.append("inconsistent track")
    untracked = untracked_detections(judging, ts)
    if untracked is not None:
        metrics["untracked_detections"], metrics["untracked_detection_gap"] = untracked
        marks.append("untracked detection")
    lost = lost_tracks(judging, ts)
    if lost:
        metrics["lost_tracks"] = list[Metric](lost[:8])
        marks.append("lost track")
    metrics["marks"] = list[Metric](marks)
    ids = (partner,) if partner is not None else ()
    return OracleResult("perception", ts, bool(marks), metrics, thresholds, ids)
