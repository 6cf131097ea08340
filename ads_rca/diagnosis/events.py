"""The run's critical event: what a verdict explains when nothing says the ego collided.

Why: a real drive rarely crashes; its users triage hard brakes, emergency stops and near
misses, and a recording of one has no collision source at all. The rules of both modes are
written around one frame (the collision) and one partner; here an event stands in for the
collision: a collision when the run knows one, else the time the user gave
(``event_time_s``), else the events found in the recording (an emergency / MRM state, a
near miss to a perceived or real object, a hard brake). Every event found is listed with its
time; the verdict explains one, and says which (docs/real-drives.md "Events").

An explained event travels in the run's metadata (``raw["critical_event"]``, so a log
folder, the player's metadata message and the live aggregator carry it) with
``collision_frame`` set to its frame: the rules, windows and outputs that read the collision
frame read the event's, and every output says it was an event, never a collision.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ads_rca.diagnosis.critical_event import (
    EMERGENCY,
    EMERGENCY_KEY,
    EVENT_KEY,
    GIVEN,
    HARD_BRAKE,
    NEAR_MISS,
    PRIORITY,
    START_OFFSET_KEY,
    CriticalEvent,
    explained_event,
)
from ads_rca.diagnosis.perceived import EGO_ID, is_perceived
from ads_rca.foundation.geometry import box_signed_distance
from ads_rca.model import RunLog, RunMetadata, frame_number
from ads_rca.oracles.base import ego_at
from ads_rca.params import Params

#: The ego's deceleration is taken over at least this span (ms), centred on the frame, so one
#: noisy speed sample is not a hard brake.
DECEL_SPAN_MS = 200


def emergency_onsets(log: RunLog) -> list[int]:
    """The timestamps an emergency state began at (well-formed entries only)."""
    value = log.metadata.raw.get(EMERGENCY_KEY)
    if not isinstance(value, list):
        return []
    return [v for v in value if isinstance(v, int) and not isinstance(v, bool)]


def start_offset_ms(log: RunLog) -> int:
    """ms from the recording's first message to frame 0 (0 for a log folder)."""
    value = log.metadata.raw.get(START_OFFSET_KEY, 0)
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        return 0
    return max(int(value), 0)


def seconds_of(log: RunLog, timestamp_ms: int) -> float:
    """A frame timestamp as seconds from the recording's first message."""
    return (timestamp_ms + start_offset_ms(log)) / 1000.0


def frame_of_time(log: RunLog, time_s: float) -> int | None:
    """The analysed timestamp nearest ``time_s`` (seconds from the recording's first
    message), if it lies within the run (half a frame either side); else None."""
    frames = log.unique_frames
    if not frames:
        return None
    target = time_s * 1000.0 - start_offset_ms(log)
    half = log.frame_ms / 2
    if target < frames[0] - half or target > frames[-1] + half:
        return None
    return min(frames, key=lambda ts: (abs(ts - target), -ts))


# -- finding events ---------------------------------------------------------------------------


def find_events(
    log: RunLog, params: Params, emergencies: Sequence[int] = ()
) -> list[CriticalEvent]:
    """Every event the recording shows, in time order: ``emergencies`` (timestamps at which
    an emergency / MRM state began), near misses and hard brakes (each a run of frames
    beyond its threshold, listed at its first frame)."""
    found = [
        _event(log, EMERGENCY, ts, "the stack's emergency (MRM) state began") for ts in emergencies
    ]
    found.extend(near_misses(log, params))
    found.extend(hard_brakes(log, params))
    return sorted(found, key=lambda e: (e.timestamp_ms, PRIORITY.index(e.kind)))


def _event(log: RunLog, kind: str, ts: int, what: str) -> CriticalEvent:
    return CriticalEvent(kind, ts, int(frame_number(ts, log.frame_ms)), seconds_of(log, ts), what)


def hard_brakes(log: RunLog, params: Params) -> list[CriticalEvent]:
    """The first frame of each run of frames where the ego decelerates at ``event_decel`` or
    more (speeds of the ego pose, differenced over :data:`DECEL_SPAN_MS`)."""
    stamps = [
        ts for ts in log.unique_frames if ts in log.pose and math.isfinite(log.pose[ts].speed)
    ]
    if len(stamps) < 3:
        return []
    t = np.asarray(stamps, dtype=np.float64) / 1000.0
    v = np.asarray([log.pose[ts].speed for ts in stamps], dtype=np.float64)
    reach = max(1, math.ceil(DECEL_SPAN_MS / 2 / max(log.frame_ms, 1)))
    lo = np.clip(np.arange(len(t)) - reach, 0, len(t) - 1)
    hi = np.clip(np.arange(len(t)) + reach, 0, len(t) - 1)
    span = t[hi] - t[lo]
    with np.errstate(invalid="ignore", divide="ignore"):
        decel = np.where(span > 0, (v[lo] - v[hi]) / span, np.nan)
    beyond = decel >= params.event_decel
    events = []
    for i in np.flatnonzero(beyond & ~np.concatenate(([False], beyond[:-1]))):
        run = i
        while run + 1 < len(beyond) and beyond[run + 1]:
            run += 1
        peak = float(np.nanmax(decel[i : run + 1]))
        what = f"ego deceleration {peak:.1f} m/s² (peak) >= event_decel {params.event_decel:g} m/s²"
        events.append(_event(log, HARD_BRAKE, stamps[i], what))
    return events


def near_misses(log: RunLog, params: Params) -> list[CriticalEvent]:
    """The first frame of each run of frames where an object's box comes within
    ``event_clearance`` of the ego's, or would within ``event_ttc_s`` at both keeping their
    velocity (the objects' from their last frame; the ego's from its pose)."""
    ego_id = (
        EGO_ID
        if is_perceived(log)
        else next(
            (ego_at(log, ts) for ts in log.unique_frames if ts in log.actors and ts in log.pose),
            None,
        )
    )
    extents = log.actor_extents
    if ego_id is None or ego_id not in extents:
        return []
    stamps = [ts for ts in log.unique_frames if ts in log.actors]
    close: list[tuple[int, str, float, float]] = []
    previous: dict[str, np.ndarray] = {}
    prev_ts: int | None = None
    for ts in stamps:
        frame = log.actors[ts]
        now = {a: frame.location[r, :2] for r, a in enumerate(frame.ids)}
        row = {a: r for r, a in enumerate(frame.ids)}
        if ego_id in row:
            gap, ttc, other = _closest(log, params, ts, frame, row, now, previous, prev_ts, ego_id)
            if other is not None:
                close.append((ts, other, gap, ttc))
        previous, prev_ts = now, ts
    events: list[CriticalEvent] = []
    last_ts: int | None = None
    for ts, other, gap, ttc in close:
        starts = last_ts is None or ts - last_ts > log.frame_ms * 1.5
        last_ts = ts
        if starts:
            parts = [f"clearance {gap:.2f} m to {other}"]
            if math.isfinite(ttc):
                parts.append(f"time to collision {ttc:.2f} s")
            what = (
                f"{', '.join(parts)} (event_clearance {params.event_clearance:g} m, "
                f"event_ttc_s {params.event_ttc_s:g} s)"
            )
            events.append(_event(log, NEAR_MISS, ts, what))
    return events


def threat_at(log: RunLog, params: Params, ts: int) -> tuple[float, float, str] | None:
    """At ``ts`` alone (no later frame: a live monitor has none yet): (clearance, time to
    collision, actor) of the object nearest a near miss with the ego by ``event_clearance``
    or ``event_ttc_s``, each kept at its velocity from its last frame (None when none, or
    the ego is not among the actors)."""
    frame = log.actors.get(ts)
    if frame is None:
        return None
    ego_id = EGO_ID if is_perceived(log) else ego_at(log, ts)
    row = {a: r for r, a in enumerate(frame.ids)}
    if ego_id is None or ego_id not in row or ego_id not in log.actor_extents:
        return None
    prev_ts = max((s for s in log.actors if s < ts), default=None)
    previous = (
        {a: log.actors[prev_ts].location[r, :2] for r, a in enumerate(log.actors[prev_ts].ids)}
        if prev_ts is not None
        else {}
    )
    now = {a: frame.location[r, :2] for r, a in enumerate(frame.ids)}
    gap, ttc, other = _closest(log, params, ts, frame, row, now, previous, prev_ts, ego_id)
    return None if other is None else (gap, ttc, other)


def _closest(
    log: RunLog,
    params: Params,
    ts: int,
    frame: Any,
    row: Mapping[str, int],
    now: Mapping[str, np.ndarray],
    previous: Mapping[str, np.ndarray],
    prev_ts: int | None,
    ego_id: str,
) -> tuple[float, float, str | None]:
    """The object nearest a near miss at ts: (clearance, time to collision, its id), or
    (nan, nan, None) when none is within the thresholds."""
    extents = log.actor_extents
    others = [a for a in frame.ids if a != ego_id and a in extents]
    if not others:
        return math.nan, math.nan, None
    dt = (ts - prev_ts) / 1000.0 if prev_ts is not None else 0.0
    ego_row = row[ego_id]
    ego_xy = frame.location[ego_row, :2]
    ego_yaw = frame.rotation[ego_row, 2]
    pose = log.pose.get(ts)
    if pose is not None and math.isfinite(pose.speed):
        heading = math.radians(pose.yaw)
        ego_v = np.array([math.cos(heading), math.sin(heading)]) * pose.speed
    else:
        ego_v = np.zeros(2)
    centres = np.array([now[a] for a in others])
    velocity = np.array(
        [(now[a] - previous[a]) / dt if dt > 0 and a in previous else np.zeros(2) for a in others]
    )
    yaws = np.array([frame.rotation[row[a], 2] for a in others])
    half = np.array([extents[a][:2] for a in others])
    ego_half = extents[ego_id][:2]
    steps = max(round(params.event_ttc_s * 1000 / max(log.frame_ms, 1)), 0)
    times = np.arange(steps + 1) * log.frame_ms / 1000.0
    n, k = len(others), len(times)
    ego_c = np.repeat((ego_xy + times[:, None] * ego_v)[None, :, :], n, axis=0)
    other_c = centres[:, None, :] + times[None, :, None] * velocity[:, None, :]
    with np.errstate(invalid="ignore", over="ignore"):
        dist = box_signed_distance(
            ego_c.reshape(-1, 2),
            np.broadcast_to(ego_half, (n * k, 2)),
            np.full(n * k, ego_yaw),
            other_c.reshape(-1, 2),
            np.repeat(half, k, axis=0),
            np.repeat(yaws, k),
        ).reshape(n, k)
    gap = dist[:, 0]
    hit = dist <= 0.0
    # An object first seen at ts has no velocity yet: taken as standing, a moving one would
    # be a near miss by time to collision it never was; only its clearance counts.
    moving_known = np.array([dt > 0 and a in previous for a in others])
    ttc = np.where(hit.any(axis=1) & moving_known, times[np.argmax(hit, axis=1)], np.inf)
    near = (gap < params.event_clearance) | (ttc <= params.event_ttc_s)
    near &= np.isfinite(gap)
    if not near.any():
        return math.nan, math.nan, None
    best = int(np.argmin(np.where(near, gap, np.inf)))
    return float(gap[best]), float(ttc[best]), others[best]


# -- choosing and applying --------------------------------------------------------------------


@dataclass(frozen=True)
class EventChoice:
    """The event a verdict explains (None: none found) and every event listed."""

    explained: CriticalEvent | None
    found: tuple[CriticalEvent, ...]
    #: Why no event was explained, or why the one given could not be (empty otherwise).
    note: str = ""


#: Why a run of snapshots (an atmaCup table: each row its own scene) has no critical event.
SNAPSHOTS_NOTE = "no critical event: its frames are independent snapshots, not one drive"


def choose_event(
    log: RunLog, params: Params, collision_state: str, emergencies: Sequence[int] = ()
) -> EventChoice:
    """The event to explain: the collision when the run knows one (nothing else is looked
    for), else the time given (``event_time_s`` >= 0), else, when nothing says whether the
    ego collided, the first found of the kind first in :data:`PRIORITY`. A run of snapshots
    has none (neither a time nor a deceleration runs through unrelated scenes). A run whose
    collision source says it did not collide is judged as before unless a time is given
    (its "no fault found (no collision)" stands on that source)."""
    if collision_state == "yes":
        return EventChoice(None, ())
    if collision_state == "no" and params.event_time_s < 0:
        return EventChoice(None, ())  # its collision source says none: judged as before
    if log.ego_snapshots is not None:  # rows of unrelated scenes: no time runs through them
        return EventChoice(None, (), SNAPSHOTS_NOTE)
    found = tuple(find_events(log, params, emergencies))
    if params.event_time_s >= 0:
        ts = frame_of_time(log, params.event_time_s)
        if ts is None:
            return EventChoice(
                None,
                found,
                f"event_time_s {params.event_time_s:g} s is outside the run's frames",
            )
        given = replace(
            _event(log, GIVEN, ts, f"event_time_s {params.event_time_s:g} s"),
            collision=collision_state,
        )
        return EventChoice(given, found)
    for kind in PRIORITY:
        of_kind = [e for e in found if e.kind == kind]
        if of_kind:
            return EventChoice(replace(of_kind[0], collision=collision_state), found)
    return EventChoice(None, found, "no critical event found")


def with_event(log: RunLog, event: CriticalEvent) -> RunLog:
    """``log`` whose verdict explains ``event``: its frame stands in for the collision frame
    and the event travels in the metadata (a new RunLog; the records are shared)."""
    metadata = replace(
        log.metadata,
        collision_frame=event.frame,
        raw={**log.metadata.raw, EVENT_KEY: event.to_dict()},
    )
    return replace(log, metadata=metadata)


def events_document(found: Sequence[CriticalEvent]) -> list[dict[str, Any]]:
    """The events found, for the verdict JSON."""
    return [e.to_dict() for e in found]


#: Where the events looked for travel in a prepared run's metadata: the player prepares the
#: run it plays (:func:`ads_rca.diagnosis.engine.prepared_run`), so the live verdict lists
#: the events ``diagnose`` lists and explains the same one.
CHOICE_KEY = "events_looked_for"


def with_choice(log: RunLog, choice: EventChoice | None) -> RunLog:
    """``log`` carrying ``choice`` (the events looked for) in its metadata; as it is for None."""
    if choice is None:
        return log
    document = {"found": events_document(choice.found), "note": choice.note}
    return replace(
        log, metadata=replace(log.metadata, raw={**log.metadata.raw, CHOICE_KEY: document})
    )


def choice_of(metadata: RunMetadata) -> EventChoice | None:
    """The events looked for that a prepared run's metadata carries (None: it carries none;
    a malformed entry is left out, as :meth:`CriticalEvent.from_dict` leaves it)."""
    document = metadata.raw.get(CHOICE_KEY)
    if not isinstance(document, Mapping):
        return None
    listed = document.get("found")
    found = [CriticalEvent.from_dict(d) for d in listed] if isinstance(listed, list) else []
    note = document.get("note")
    return EventChoice(
        explained_event(metadata),
        tuple(e for e in found if e is not None),
        note if isinstance(note, str) else "",
    )
