"""Collisions derived from ground truth: the ego's box overlapping an actor's box.

A stack publishes no collision frame, so stack mode can detect it from
what the simulator reports. The ego box is built as the oracles build it: centre and yaw
from the ego pose, half extent from the ego actor's record; every other actor's box is its
location, yaw and half extent in the same record. A pair collides when the signed distance
of :func:`ads_rca.foundation.geometry.box_signed_distance` (the corrected oracles' clearance) is
below
zero, which is the synthesiser's rule too (its separating-axis gap is that distance's
negative branch), so a synthesised crash is detected at its logged collision frame.

A contact lasting several frames is one collision; the same actor after a frame apart
(distance ≥ 0) is a new one. A frame where an actor's distance cannot be computed (NaN
pose, extent or yaw; the actor absent) neither starts nor ends a contact, so hostile
values never detect. Pure: numpy only, vectorised over the actors of a frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ads_rca.errors import ConfigError
from ads_rca.foundation.geometry import FloatArray, box_signed_distance
from ads_rca.model import Actors, EgoPose, RunLog, frame_number
from ads_rca.oracles.base import ego_row

__all__ = ["Collision", "CollisionDetector", "detect_collisions"]


@dataclass(frozen=True, slots=True)
class Collision:
    """One numbered collision: where it began and with whom."""

    number: int  # 1, 2, ... in onset order (deepest first within one frame)
    timestamp_ms: int
    frame: int | float  # model.frame_number of the onset stamp
    actor_id: str
    depth_m: float  # penetration depth at the onset (positive)


class CollisionDetector:
    """Streamed detection: feed frames in stamp order, get the collisions they begin.

    ``ego_id`` names the ego actor (a parameter in stack mode); without it the ego is the
    actor matching the first pose by the oracles' ego rule (:func:`oracles.base.ego_row`),
    then kept. ``ego_half`` overrides the ego's half extent (x, y) in metres; otherwise the
    first finite one of the ego's records is used and kept.
    """

    def __init__(
        self, frame_ms: int, ego_id: str | None = None, ego_half: FloatArray | None = None
    ) -> None:
        if frame_ms <= 0:
            raise ConfigError(f"collision detector: frame_ms must be positive, got {frame_ms}")
        self.frame_ms = frame_ms
        self.ego_id = ego_id
        self.ego_half: FloatArray | None = None
        if ego_half is not None:
            self.ego_half = _usable_half(np.asarray(ego_half, dtype=np.float64).reshape(1, 2))[0]
        self.collisions: list[Collision] = []
        self.ignored_frames = 0  # frames not after the previous one, left out
        self._contacts: set[str] = set()
        self._last_ts: int | None = None

    @property
    def in_contact(self) -> frozenset[str]:
        """Actors whose contact with the ego is ongoing."""
        return frozenset(self._contacts)

    def update(self, ts: int, pose: EgoPose | None, actors: Actors | None) -> list[Collision]:
        """The collisions that begin at ``ts`` (deepest first); [] for a stale stamp."""
        if self._last_ts is not None and ts <= self._last_ts:
            self.ignored_frames += 1
            return []
        self._last_ts = ts
        if actors is None or len(actors) == 0:
            return []
        ids = np.asarray(actors.ids, dtype=object)
        ego = self._ego_rows(ids, actors, pose)
        if ego is None:
            return []
        ego_xy, ego_yaw, ego_half = ego
        others = np.flatnonzero(ids != self.ego_id)
        if others.size == 0:
            return []
        half = _usable_half(actors.extent[others, :2])
        with np.errstate(invalid="ignore", over="ignore"):
            dist = box_signed_distance(
                ego_xy,
                ego_half,
                ego_yaw,
                actors.location[others, :2],
                half,
                actors.rotation[others, 2],
            )
        return self._advance(ts, ids[others], dist)

    def _ego_rows(
        self, ids: npt.NDArray[np.object_], actors: Actors, pose: EgoPose | None
    ) -> tuple[FloatArray, float, FloatArray] | None:
        """The ego box's centre, yaw and half extent at this frame, or None if unknown."""
        if self.ego_id is None and pose is not None:
            row = ego_row(actors, pose)
            if row is not None:
                self.ego_id = actors.ids[row]
        if self.ego_id is None:
            return None
        rows = np.flatnonzero(ids == self.ego_id)
        if self.ego_half is None and rows.size:
            candidate = _usable_half(actors.extent[rows[:1], :2])[0]
            if np.isfinite(candidate).all():
                self.ego_half = candidate
        if self.ego_half is None:
            return None
        if pose is not None:
            return np.array([pose.x, pose.y]), pose.yaw, self.ego_half
        if rows.size:  # no pose this frame: the ego actor's own record
            r = int(rows[0])
            return actors.location[r, :2], float(actors.rotation[r, 2]), self.ego_half
        return None

    def _advance(self, ts: int, ids: npt.NDArray[np.object_], dist: FloatArray) -> list[Collision]:
        """Update the contacts from this frame's distances; the new contacts, numbered."""
        inside = np.flatnonzero(dist < 0.0)
        for actor_id in list(self._contacts):  # ongoing contacts only, a handful at most
            if (dist[ids == actor_id] >= 0.0).any():
                self._contacts.discard(actor_id)
        order = inside[np.argsort(dist[inside], kind="stable")]
        found: list[Collision] = []
        for r in order.tolist():  # only the overlapping actors, a handful at most
            actor_id = str(ids[r])
            if actor_id in self._contacts:
                continue
            self._contacts.add(actor_id)
            number = len(self.collisions) + 1
            collision = Collision(
                number, ts, frame_number(ts, self.frame_ms), actor_id, float(-dist[r])
            )
            self.collisions.append(collision)
            found.append(collision)
        return found


def _usable_half(half: FloatArray) -> FloatArray:
    """Half extents (N, 2) with non-finite or negative rows made NaN (never a box)."""
    half = np.asarray(half, dtype=np.float64)
    bad = ~np.isfinite(half) | (half < 0.0)
    return np.where(bad.any(axis=1, keepdims=True), np.nan, half)


def detect_collisions(
    log: RunLog, ego_id: str | None = None, ego_half: FloatArray | None = None
) -> list[Collision]:
    """Every collision of a whole log, numbered, by streaming its analysed frames."""
    detector = CollisionDetector(log.frame_ms, ego_id, ego_half)
    for ts in sorted(log.unique_frames):
        detector.update(ts, log.pose.get(ts), log.actors.get(ts))
    return detector.collisions
