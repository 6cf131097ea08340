"""Stack mode's guard on the reference input: one writer, finite poses, what was refused.

Why (issue 43): stack mode takes any local publisher (the run-id filter covers a player's
run only), and the reference input's header stamps make the frame grid. A second process
publishing on the ego odometry topic (three messages stamped far ahead, a stream of NaN
poses, a flood of 4,000 messages a second) moved the grid: every later real message was
dropped as late (130-386 in the tester's runs) or thousands of its frames were judged,
while ``/diagnostics`` stayed OK. So:

- **One writer.** The reference topic is locked to the first writer heard (its publisher
  GID from the MessageInfo); messages of any other writer are counted and skipped before
  they are read. The lock passes on only when the locked writer has left the graph (a
  stack restarted as a new process), said by the node (:meth:`WriterLock.release`).
- **Malformed poses.** A reference pose with a NaN or infinite number is refused (counted,
  never a frame).
- What the stamp sync and the forward-jump rule refuse (:mod:`ads_rca.live.stamp_sync`,
  :class:`ads_rca.live.episodes.ForwardJumps`) is counted here too, over every episode.
- **Said.** :meth:`StackGuard.report` gives a level and one line for the monitors'
  heartbeat: WARN naming what was refused, ERROR while the real stream's frames are being
  dropped as late (it is then not judged), OK only when nothing was.

Pure: no rclpy (the MessageInfo is a plain dict); the monitor node calls it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from ads_rca.live import diagnostics as diag

#: Reference messages dropped as late within this many seconds make the report an ERROR
#: (the real stream's frames are being lost now); older ones a WARN.
LATE_RECENT_S = 5.0


def writer_gid(info: Mapping[str, Any] | None) -> bytes | None:
    """The publisher GID of a subscription's MessageInfo (None: the rmw gave none)."""
    gid = info.get("publisher_gid") if info else None
    data = gid.get("data") if isinstance(gid, Mapping) else None
    return bytes(data) if isinstance(data, bytes | bytearray) and data else None


def gid_text(gid: bytes) -> str:
    """A writer as the log names it: its GID in hex, dot-separated in fours."""
    hexed = gid.hex()
    return ".".join(hexed[i : i + 8] for i in range(0, len(hexed), 8))


@dataclass
class WriterLock:
    """The first writer heard is the only one taken (see the module docstring)."""

    writer: bytes | None = None
    #: Messages skipped, per other writer.
    ignored: dict[bytes, int] = field(default_factory=dict)

    def accept(self, writer: bytes | None) -> bool:
        """A message of ``writer``: True when it is the locked writer (locking onto it if
        none yet) or unknown (an rmw without GIDs: nothing to tell writers apart by)."""
        if writer is None:
            return True
        if self.writer is None:
            self.writer = writer
        if writer == self.writer:
            return True
        self.ignored[writer] = self.ignored.get(writer, 0) + 1
        return False

    def release(self) -> None:
        """The locked writer left the graph: the next writer heard is locked."""
        self.writer = None

    @property
    def total_ignored(self) -> int:
        return sum(self.ignored.values())


def pose_problem(numbers: Mapping[str, float]) -> str | None:
    """Why a reference pose cannot define a frame (a NaN or infinite number), else None."""
    bad = [name for name, value in numbers.items() if not math.isfinite(value)]
    if not bad:
        return None
    return f"pose not finite ({', '.join(bad)}): it cannot define a frame; skipped"


@dataclass
class StackGuard:
    """What stack mode refused on its inputs, over every episode, and the report of it."""

    topic: str  #: the reference topic, as reports name it
    lock: WriterLock = field(default_factory=WriterLock)
    malformed: int = 0  #: reference messages refused as malformed (non-finite pose)
    implausible: int = 0  #: reference stamps implausibly far ahead, skipped
    crowded: int = 0  #: reference stamps too close to a frame (a flood), skipped
    late_reference: int = 0  #: reference messages dropped as late (their frames lost)
    late_inputs: int = 0  #: other inputs' messages dropped as late
    #: When a reference message was last dropped as late (monotonic s).
    late_at: float | None = None

    def count_late(self, reference: int, inputs: int, now: float) -> None:
        """Late messages the stamp sync just dropped."""
        if reference:
            self.late_reference += reference
            self.late_at = now
        self.late_inputs += inputs

    def lines(self) -> list[str]:
        """What was refused, one clause each (empty: nothing)."""
        out = []
        if self.lock.ignored:
            writers = len(self.lock.ignored)
            who = "second publisher" if writers == 1 else f"{writers} other publishers"
            out.append(f"{who} on {self.topic}: {self.lock.total_ignored} messages ignored")
        if self.late_reference:
            out.append(
                f"{self.late_reference} {self.topic} messages dropped as late "
                "(their frames not judged)"
            )
        if self.late_inputs:
            out.append(f"{self.late_inputs} input messages dropped as late")
        if self.malformed:
            out.append(f"{self.malformed} malformed {self.topic} messages skipped (NaN/inf pose)")
        if self.implausible:
            out.append(f"{self.implausible} {self.topic} stamps implausibly far ahead skipped")
        if self.crowded:
            out.append(
                f"{self.crowded} {self.topic} stamps closer than half a frame to another "
                "(a flood) skipped"
            )
        return out

    def report(self, now: float) -> tuple[int, str, dict[str, int]]:
        """The level (OK, WARN, or ERROR while reference messages are being dropped as
        late), one line ('' when OK) and the counts, for the heartbeat."""
        lines = self.lines()
        values = {
            "ignored_other_writers": self.lock.total_ignored,
            "late_reference": self.late_reference,
            "late_inputs": self.late_inputs,
            "malformed_reference": self.malformed,
            "implausible_stamps": self.implausible,
            "flood_stamps": self.crowded,
        }
        if not lines:
            return diag.OK, "", values
        recent = self.late_at is not None and now - self.late_at < LATE_RECENT_S
        return (diag.ERROR if recent else diag.WARN), "; ".join(lines), values


__all__ = ["LATE_RECENT_S", "StackGuard", "WriterLock", "gid_text", "pose_problem", "writer_gid"]
