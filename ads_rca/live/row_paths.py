"""A planning monitor's snapshot rows' paths, and when a row is scored again.

Why: a snapshot table's row (``RunLog.ego_snapshots``) is scored frame by frame by the
planning module's not-judged result (its scorer's ``frame_scores``). The player sends
the row's paths on ``run/ego_paths`` with its frame, and a live trajectory-prediction model
(any node of the run, in its own process) may send its own ``predicted`` path for the row.
A model answers after it heard the frame, so its path often comes after the monitor judged
the row with the player's path (or with none): without a rule the model was scored only in
the aggregator's verdict, never frame by frame.

The rule (:class:`RowPaths`):

- a message for a row not yet judged is merged into the held row
  (:func:`~ads_rca.contract.ego_paths.merged`: each path from the later message where it has
  one), and the frame waits for its row as for a record;
- the planning result of a judged row is remembered (the last :data:`REMEMBERED_ROWS`) with
  the paths it scored; a later message for it is merged the same way and, when the merged row
  differs from the scored one (a path or the ID), the row is due: its planning result is
  published again with ``revision`` + 1, and the aggregator and recorder keep the highest
  revision of a frame (``live.results.ResultStore``), so the last word on a row is its
  latest paths, as the aggregator's verdict merges them;
- what cannot be used is refused with :class:`~ads_rca.contract.errors.MalformedMessage`
  (the node skips it and says so): a row older than every frame the window holds and not
  remembered (never played, or judged too long ago), a new row beyond :attr:`RowPaths.max_held`
  rows held, a change for a row already scored again :data:`MAX_RESCORES` times (a flood of
  messages for one stamp cannot grow memory or the results published). A message that
  changes nothing is taken silently.

Pure Python: no rclpy (``MonitorCore`` asks it; the re-score itself is the engine's oracle
on a one-row view, in ``live.window``).
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from ads_rca.contract.ego_paths import EgoPathRow, merged
from ads_rca.contract.errors import MalformedMessage
from ads_rca.foundation.geometry import FloatArray
from ads_rca.live.results import LiveResult

#: Judged rows remembered for a later path (a model answering within this many rows).
REMEMBERED_ROWS = 4096
#: Times one row's planning result is published again for later paths.
MAX_RESCORES = 16
#: Rows held before they are judged, at most (a legitimate player sends one row a frame).
MAX_HELD_ROWS = 4096
#: The incomplete reason of a frame judged without its row's paths (``window`` writes it).
NO_PATHS = "no ego_paths record"


@dataclass
class JudgedRow:
    """A judged row: its latest planning result and the paths it is to score."""

    result: LiveResult
    paths: EgoPathRow | None
    rescores: int = 0


def _same_path(a: FloatArray | None, b: FloatArray | None) -> bool:
    if a is None or b is None:
        return a is b
    return bool(np.array_equal(a, b, equal_nan=True))


def same_row(a: EgoPathRow | None, b: EgoPathRow | None) -> bool:
    """Whether two rows score the same (their ID and both paths)."""
    if a is None or b is None:
        return a is b
    return (
        a.ident == b.ident
        and _same_path(a.realised, b.realised)
        and _same_path(a.predicted, b.predicted)
    )


class RowPaths:
    """The rows held for frames to come and the judged rows remembered (module docstring)."""

    def __init__(
        self,
        max_held: int = MAX_HELD_ROWS,
        remembered: int = REMEMBERED_ROWS,
        max_rescores: int = MAX_RESCORES,
    ) -> None:
        self.max_held = max_held
        self.remembered = remembered
        self.max_rescores = max_rescores
        #: Rows of frames not judged yet (or never to be: trimmed with the window).
        self.held: dict[int, EgoPathRow] = {}
        #: Judged rows, oldest first.
        self.judged: OrderedDict[int, JudgedRow] = OrderedDict()
        self._due: dict[int, None] = {}  # an ordered set of stamps

    def __len__(self) -> int:
        return len(self.held) + len(self.judged)

    def add(self, row: EgoPathRow, floor: int | None) -> bool:
        """One message; True when it makes a judged row due for a new result. ``floor``:
        the oldest stamp the window holds (None: none yet). MalformedMessage when refused."""
        stamp = row.stamp_ms
        judged = self.judged.get(stamp)
        if judged is not None:
            new = merged(judged.paths, row)
            if same_row(new, judged.paths):
                judged.paths = new
                return False
            if judged.rescores >= self.max_rescores:
                raise MalformedMessage(
                    f"run/ego_paths: the row at {stamp} ms was scored again "
                    f"{self.max_rescores} times already; its later paths are skipped"
                )
            judged.paths = new
            self._due[stamp] = None
            return True
        if floor is not None and stamp < floor:
            raise MalformedMessage(
                f"run/ego_paths: no row at {stamp} ms is held (not played, or judged more "
                f"than {self.remembered} rows ago)"
            )
        if stamp not in self.held and len(self.held) >= self.max_held:
            raise MalformedMessage(
                f"run/ego_paths: {self.max_held} rows are held already; the row at "
                f"{stamp} ms is skipped"
            )
        self.held[stamp] = merged(self.held.get(stamp), row)
        return False

    def has(self, stamp: int) -> bool:
        """Whether the row at ``stamp`` has paths (held or judged)."""
        judged = self.judged.get(stamp)
        return stamp in self.held or (judged is not None and judged.paths is not None)

    def rows(self, stamps: Iterable[int]) -> dict[int, EgoPathRow]:
        """The rows of ``stamps`` that have paths (for a window's view)."""
        out: dict[int, EgoPathRow] = {}
        for stamp in stamps:
            judged = self.judged.get(stamp)
            row = self.held.get(stamp) if judged is None else judged.paths
            if row is not None:
                out[stamp] = row
        return out

    def judged_row(self, result: LiveResult) -> None:
        """A row's planning result was published (first judged, or judged again on a
        collision: its paths were the latest then, so nothing is due)."""
        stamp = result.stamp_ms
        known = self.judged.pop(stamp, None)
        paths = self.held.pop(stamp, None)
        if known is not None:
            paths = known.paths if paths is None else merged(known.paths, paths)
        self.judged[stamp] = JudgedRow(result, paths, known.rescores if known else 0)
        self._due.pop(stamp, None)
        while len(self.judged) > self.remembered:
            old, _ = self.judged.popitem(last=False)
            self._due.pop(old, None)

    def due(self) -> list[JudgedRow]:
        """The judged rows whose paths changed since their last result (then none is)."""
        out = [self.judged[s] for s in self._due if s in self.judged]
        self._due.clear()
        return out

    def rescored(self, result: LiveResult) -> None:
        """A due row's new result was published."""
        judged = self.judged[result.stamp_ms]
        judged.result = result
        judged.rescores += 1

    def forget_before(self, floor: int) -> None:
        """Held rows older than every frame the window holds (never to be judged)."""
        for stamp in [s for s in self.held if s < floor]:
            del self.held[stamp]


def rescored_incomplete(incomplete: tuple[str, ...], paths: EgoPathRow | None) -> tuple[str, ...]:
    """A re-scored row's incomplete reasons: no longer "no ego_paths record" once its
    realised path came (what the player's message carries)."""
    if paths is None or paths.realised is None:
        return incomplete
    return tuple(i for i in incomplete if i != NO_PATHS)


__all__ = [
    "MAX_HELD_ROWS",
    "MAX_RESCORES",
    "NO_PATHS",
    "REMEMBERED_ROWS",
    "JudgedRow",
    "RowPaths",
    "rescored_incomplete",
    "same_row",
]
