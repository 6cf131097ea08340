"""Monitor results as labelled numbers, so plotting tools can draw them.

The ``metrics/<module>`` topics carry JSON, which neither Foxglove nor PlotJuggler plots.
Each result is therefore also sent as a row of numbers with a label each (the monitor puts
it in a ``sensor_msgs/JointState``: ``name`` = labels, ``position`` = values; see
docs/topics.md for why that type). Tools address a value by its position (Foxglove's
``.position[6]``) or by its label (PlotJuggler's ``/values/c_gt/position``), so positions
must not move:

- first :data:`HEAD` (``frame``, and ``failed``/``skipped``/``incomplete`` as 0/1, and the
  ``revision``), then the mode's headline metrics of the module (``Semantics.headline``,
  the ones the HTML report plots), always at the same positions for a mode and module;
- then every other top-level numeric metric in the order the monitor first meets it. A
  layout only grows: a label keeps its position for the monitor's life, and a frame without
  that metric has NaN there.

Numbers are the JSON's values: floats and ints as float64 (exact below 2**53), booleans as
1/0, ``null`` (a metric with no value) as NaN. Strings, lists and maps (per-actor values)
are left to the JSON: their keys would grow the layout with every actor id.
Pure data, no rclpy.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from ads_rca.live.results import LiveResult

#: The labels every layout starts with.
HEAD: tuple[str, ...] = ("frame", "failed", "skipped", "incomplete", "revision")


def number(value: object) -> float | None:
    """A metric as a plottable number, or None when it is not a number (text, list, map)."""
    if value is None:
        return math.nan
    if isinstance(value, bool):
        return 1.0 if value else 0.0
    if isinstance(value, int | float):
        return float(value)
    return None


class NumericLayout:
    """The labels of one module's rows, fixed head first, only ever appended to."""

    def __init__(self, headline: Sequence[str] = ()) -> None:
        self.labels: list[str] = []
        self._position: dict[str, int] = {}
        for label in (*HEAD, *headline):
            self._add(label)

    def _add(self, label: str) -> int:
        position = self._position.get(label)
        if position is None:
            position = self._position[label] = len(self.labels)
            self.labels.append(label)
        return position

    def row(self, live: LiveResult) -> list[float]:
        """The result's values, one per label (the layout grows first if need be)."""
        r = live.result
        head = (live.frame, r.failed, bool(r.skipped), bool(live.incomplete), live.revision)
        values: dict[str, float] = {k: float(v) for k, v in zip(HEAD, head, strict=True)}
        for key, value in r.metrics.items():
            if key not in values and (x := number(value)) is not None:
                values[key] = x
        if len(values) > len(self.labels) or not values.keys() <= self._position.keys():
            for key in values:
                self._add(key)
        row = [math.nan] * len(self.labels)
        position = self._position
        for key, x in values.items():
            row[position[key]] = x
        return row
