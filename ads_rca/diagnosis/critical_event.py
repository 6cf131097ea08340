"""The critical event a verdict explains, as it travels with a run.

Why apart from :mod:`ads_rca.diagnosis.events` (which finds and chooses events): the rules
read which event stands in for the collision, and a recording's reader writes the keys the
finding reads, both from below the oracles' layer. Only data and its reading live here.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from ads_rca.model import RunMetadata

#: Where the explained event travels in the run's metadata.
EVENT_KEY = "critical_event"
#: ms from the recording's first message to frame 0 (a recording's reader sets it; a log
#: folder starts at its first frame): ``--event-time`` counts from that first message.
START_OFFSET_KEY = "first_message_offset_ms"

COLLISION = "collision"
GIVEN = "given"
EMERGENCY = "emergency"
NEAR_MISS = "near_miss"
HARD_BRAKE = "hard_brake"
#: Which event a verdict explains when several are found: the first kind here, then the
#: earliest of that kind.
PRIORITY = (COLLISION, GIVEN, EMERGENCY, NEAR_MISS, HARD_BRAKE)
KIND_WORDS = {
    COLLISION: "collision",
    GIVEN: "event given",
    EMERGENCY: "emergency state",
    NEAR_MISS: "near miss",
    HARD_BRAKE: "hard brake",
}


@dataclass(frozen=True)
class CriticalEvent:
    """One event: its kind, where it is on the run's frame clock, and what it was."""

    kind: str
    timestamp_ms: int
    frame: int
    time_s: float  # seconds from the recording's first message
    what: str  # in words, with the threshold that made it an event
    #: The run's own collision state (``yes``, ``no``, ``unknown``) when this stood in for it.
    collision: str = "unknown"

    @property
    def label(self) -> str:
        """``hard brake at 12.40 s (frame 124)``."""
        return f"{KIND_WORDS[self.kind]} at {self.time_s:.2f} s (frame {self.frame})"

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "timestamp_ms": self.timestamp_ms,
            "frame": self.frame,
            "time_s": self.time_s,
            "what": self.what,
            "collision": self.collision,
        }

    @classmethod
    def from_dict(cls, document: object) -> CriticalEvent | None:
        """The event a metadata document carries; None when it carries none or one that is
        not well formed (it then explains nothing: the run is judged as its collision
        source says)."""
        if not isinstance(document, Mapping):
            return None
        kind, stamp, frame = (
            document.get("kind"),
            document.get("timestamp_ms"),
            document.get("frame"),
        )
        time_s, what = document.get("time_s"), document.get("what", "")
        collision = document.get("collision", "unknown")
        if not isinstance(stamp, int) or not isinstance(frame, int):
            return None
        if (
            kind not in KIND_WORDS
            or not _whole(stamp)
            or not _whole(frame)
            or not isinstance(time_s, int | float)
            or isinstance(time_s, bool)
            or not math.isfinite(time_s)
            or not isinstance(what, str)
            or collision not in ("yes", "no", "unknown")
        ):
            return None
        return cls(str(kind), int(stamp), int(frame), float(time_s), what, str(collision))


def _whole(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value >= 0


def explained_event(metadata: RunMetadata) -> CriticalEvent | None:
    """The event (not a collision) a run's verdict explains; None: its collision, if any."""
    event = CriticalEvent.from_dict(metadata.raw.get(EVENT_KEY))
    if event is None or event.kind == COLLISION:
        return None
    frame_ms = metadata.timesteps_per_frame
    if abs(event.timestamp_ms - metadata.collision_frame * frame_ms) >= max(frame_ms, 1):
        return None  # the frame it stood in for was changed since: not this run's event
    return event


def collision_frame_of(metadata: RunMetadata) -> int:
    """The run's collision frame as its source gave it (-1 when an event stands in)."""
    return -1 if explained_event(metadata) is not None else metadata.collision_frame


#: Timestamps (ms, the frames' clock) at which the stack entered an emergency / MRM state:
#: a recording's reader lists them in the metadata when the run carries that state.
EMERGENCY_KEY = "emergency_onsets_ms"
