"""The safety and comfort figures a CARLA experiment-client run reports about itself.

The client scores each run with collision count, minimum time-to-collision, hard-brake count
and jerk RMS (its ``metrics/naturalness.py``); ``diagnose`` shows the same figures for a run
read from its telemetry, with the client's definitions, so a user can compare:

- accelerations: the change of the world velocity between ticks, projected on the current
  forward (longitudinal) and right (lateral) axes, over ``dt``; 0 on the first tick;
- jerk: the change of those accelerations over ``dt`` (from 0 before the first tick);
- hard brake: a tick with longitudinal acceleration below −4 m/s²;
- time-to-collision: per tick, the lead vehicle is the nearest vehicle 1 m to 50 m away whose
  direction is within ~45° of the ego's forward axis (cosine at least 0.7); TTC = its
  distance / (ego speed − its speed) when that closing speed exceeds 0.1 m/s;
- collisions: the client counts its collision sensor's events, which the telemetry does not
  hold; here an episode is a run of consecutive ticks in which the ego's box overlaps one
  actor's box (blueprint extents, assumed), so the count is *derived* and says so.

Pure numpy over all ticks and actor rows at once (no per-tick loop).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from ads_rca.diagnosis.scoring import Scorer
from ads_rca.foundation.geometry import FloatArray, box_signed_distance, ego_to_world, world_to_ego
from ads_rca.foundation.text import short
from ads_rca.sources.carla.annotations import ANNOTATIONS_KEY, annotations_from_document

if TYPE_CHECKING:
    from ads_rca.diagnosis.verdict import FrameResults
    from ads_rca.model import RunLog

HARD_BRAKE_MS2 = -4.0
LEAD_MIN_M = 1.0
LEAD_MAX_M = 50.0
LEAD_MIN_COSINE = 0.7
CLOSING_MIN_MS = 0.1

#: Keys of the figures, in output order (``run_figures`` of the verdict JSON).
FIGURE_KEYS = (
    "collision_count",
    "min_ttc_s",
    "hard_brake_count",
    "jerk_rms_longitudinal",
    "jerk_rms_lateral",
    "accel_rms_longitudinal",
    "accel_rms_lateral",
)

BASIS = (
    "the CARLA experiment client's definitions; collision_count is derived from box "
    "overlaps with assumed blueprint extents (the client counts collision-sensor events)"
)


@dataclass(frozen=True)
class EgoTrack:
    """The ego on every tick: CARLA world position and yaw (degrees), speed, and the body
    velocity (x forward, y LEFT as the telemetry writes it; NaN where not recorded)."""

    xy: FloatArray  # (T, 2)
    yaw: FloatArray  # (T,)
    speed: FloatArray  # (T,)
    body_velocity: FloatArray  # (T, 2)
    half: FloatArray  # (2,) half length, half width


@dataclass(frozen=True)
class ActorRows:
    """Every actor on every tick, one row each: its tick, a per-actor number, CARLA world
    position and yaw, half extents, speed and whether it is a vehicle."""

    tick: npt.NDArray[np.int64]  # (K,)
    actor: npt.NDArray[np.int64]  # (K,)
    xy: FloatArray  # (K, 2)
    yaw: FloatArray  # (K,)
    half: FloatArray  # (K, 2)
    speed: FloatArray  # (K,)
    vehicle: npt.NDArray[np.bool_]  # (K,)


def world_velocity(ego: EgoTrack) -> FloatArray:
    """The body velocity in the CARLA world frame (left-handed: y right), (T, 2); speed
    along the heading where the body velocity is not recorded."""
    vx, vy_left = ego.body_velocity[:, 0], ego.body_velocity[:, 1]
    missing = ~(np.isfinite(vx) & np.isfinite(vy_left))
    body = np.stack([np.where(missing, ego.speed, vx), np.where(missing, 0.0, -vy_left)], -1)
    return ego_to_world(body, np.zeros(2), ego.yaw)  # y right, as the world's


def accelerations(ego: EgoTrack, dt: float) -> tuple[FloatArray, FloatArray]:
    """Longitudinal and lateral acceleration per tick (0 on the first)."""
    velocity = world_velocity(ego)
    change = np.zeros_like(velocity)
    change[1:] = np.diff(velocity, axis=0)
    along, across = (world_to_ego(change, np.zeros(2), ego.yaw) / dt).T
    return along, across


def overlaps(ego: EgoTrack, rows: ActorRows) -> npt.NDArray[np.bool_]:
    """Whether each actor row's box overlaps the ego's box on its tick (penetration > 0)."""
    if rows.tick.size == 0:
        return np.zeros(0, dtype=bool)
    distance = box_signed_distance(
        ego.xy[rows.tick], ego.half, ego.yaw[rows.tick], rows.xy, rows.half, rows.yaw
    )
    return np.asarray(distance < 0.0)


def overlap_episodes(rows: ActorRows, hit: npt.NDArray[np.bool_]) -> int:
    """Runs of consecutive ticks in which one actor overlaps the ego."""
    if not hit.any():
        return 0
    order = np.lexsort((rows.tick[hit], rows.actor[hit]))
    actor, tick = rows.actor[hit][order], rows.tick[hit][order]
    continues = (actor[1:] == actor[:-1]) & (tick[1:] == tick[:-1] + 1)
    return int(actor.size - np.count_nonzero(continues))


def min_time_to_collision(ego: EgoTrack, rows: ActorRows) -> float:
    """The smallest TTC to the lead vehicle over the run; NaN when never closing on one."""
    tick = rows.tick
    if tick.size == 0:
        return float("nan")
    offset = rows.xy - ego.xy[tick]
    distance = np.hypot(offset[:, 0], offset[:, 1])
    ahead_m = world_to_ego(rows.xy, ego.xy[tick], ego.yaw[tick])[:, 0]
    with np.errstate(invalid="ignore", divide="ignore"):
        cosine = ahead_m / distance
    ahead = (
        rows.vehicle
        & (distance >= LEAD_MIN_M)
        & (distance < LEAD_MAX_M)
        & (cosine >= LEAD_MIN_COSINE)
    )
    if not ahead.any():
        return float("nan")
    candidates = np.flatnonzero(ahead)
    order = candidates[np.lexsort((distance[candidates], tick[candidates]))]
    _, first = np.unique(tick[order], return_index=True)
    lead = order[first]
    closing = ego.speed[tick[lead]] - rows.speed[lead]
    closing_fast = closing > CLOSING_MIN_MS
    if not closing_fast.any():
        return float("nan")
    return float(np.min(distance[lead][closing_fast] / closing[closing_fast]))


def _rms(values: FloatArray) -> float:
    finite = values[np.isfinite(values)]
    return float(np.sqrt(np.mean(finite * finite))) if finite.size else float("nan")


def run_figures(
    ego: EgoTrack, rows: ActorRows, dt: float, actors_recorded: bool = True
) -> dict[str, Any]:
    """The figures of :data:`FIGURE_KEYS` (NaN where a run cannot give one: a run that
    records no actors at all, ``telemetry.csv``, has an unknown collision count, not 0)."""
    along, across = accelerations(ego, dt)
    jerk_along = np.diff(along, prepend=0.0) / dt
    jerk_across = np.diff(across, prepend=0.0) / dt
    collisions = overlap_episodes(rows, overlaps(ego, rows)) if actors_recorded else math.nan
    return {
        "collision_count": collisions,
        "min_ttc_s": min_time_to_collision(ego, rows),
        "hard_brake_count": int(np.count_nonzero(along < HARD_BRAKE_MS2)),
        "jerk_rms_longitudinal": _rms(jerk_along),
        "jerk_rms_lateral": _rms(jerk_across),
        "accel_rms_longitudinal": _rms(along),
        "accel_rms_lateral": _rms(across),
    }


#: Key of the metadata document (and of the verdict JSON) holding a run's figures.
FIGURES_KEY = "run_figures"


def figures_from_document(document: Mapping[str, Any]) -> dict[str, Any]:
    """The figures a metadata document carries under :data:`FIGURES_KEY`, each a finite
    number or null, with the basis they were computed on; {} when it carries none (a
    document may come from a topic: anything else is left out)."""
    listed = document.get(FIGURES_KEY)
    if not isinstance(listed, Mapping):
        return {}
    out: dict[str, Any] = {"basis": BASIS}
    for key in FIGURE_KEYS:
        value = listed.get(key)
        usable = (
            isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
        )
        out[key] = value if usable else None
    return out


class RunNotes(Scorer):
    """What a run says about itself (``SCORER``): its annotations (events, never collisions)
    and its own figures, both read back from its metadata, bounded and checked."""

    keys = (ANNOTATIONS_KEY, FIGURES_KEY)

    def document(
        self, log: RunLog, frames: Sequence[FrameResults], semantics: str
    ) -> dict[str, Any]:
        out: dict[str, Any] = {}
        annotations = annotations_from_document(log.metadata.raw)
        if annotations:
            out[ANNOTATIONS_KEY] = [a.to_dict() for a in annotations]
        figures = figures_from_document(log.metadata.raw)
        if figures:
            out[FIGURES_KEY] = figures
        return out

    def summary_lines(self, document: Mapping[str, Any], shown: int) -> list[str]:
        lines: list[str] = []
        figures = figures_from_document(document)
        if figures:
            values = ", ".join(f"{k}={short(figures[k])}" for k in FIGURE_KEYS)
            lines.append(f"run figures: {values}")
        annotations = annotations_from_document(document)
        if annotations:
            lines.append(f"annotations ({len(annotations)}; events, not collisions):")
            lines.extend(f"  {a.line()}" for a in annotations[:shown])
            if len(annotations) > shown:
                lines.append(f"  ... {len(annotations) - shown} more")
        return lines


SCORER = RunNotes()
