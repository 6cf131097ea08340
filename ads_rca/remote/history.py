"""The bounded history a dashboard that connects late asks for: ``frames?since=N``.

Frames are kept by frame index, newest last, at most ``capacity`` of them; the verdict and
the status are kept apart (one each, never evicted). A selector's ``since`` is parsed
strictly: a whole number ≥ -1, anything else refused in one line naming the parameter.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Mapping
from typing import Any

from ads_rca.errors import ConfigError

#: ``since`` values beyond this are refused (a frame index is far smaller).
MAX_SINCE = 10**12


def parse_since(parameters: Mapping[str, str]) -> int:
    """The ``since`` of a query's parameters (-1, everything, when absent)."""
    text = parameters.get("since")
    if text is None or text == "":
        return -1
    stripped = text.strip()
    if not stripped.lstrip("-").isdigit() or len(stripped) > 14:
        raise ConfigError(f"query parameter since: {text[:40]!r} is not a whole number")
    value = int(stripped)
    if not -1 <= value <= MAX_SINCE:
        raise ConfigError(f"query parameter since: {value} is out of range [-1, {MAX_SINCE}]")
    return value


class History:
    """The latest frames (by index), the verdict and the status."""

    def __init__(self, capacity: int) -> None:
        if capacity < 1:
            raise ConfigError(f"history capacity: {capacity} must be at least 1")
        self.capacity = capacity
        self._frames: OrderedDict[int, dict[str, Any]] = OrderedDict()
        self.verdict: dict[str, Any] | None = None
        self.status: dict[str, Any] | None = None
        self.evicted = 0

    def add_frame(self, index: int, document: dict[str, Any]) -> None:
        """Keep frame ``index`` (a re-judged frame replaces its earlier document)."""
        self._frames.pop(index, None)
        self._frames[index] = document
        while len(self._frames) > self.capacity:
            self._frames.popitem(last=False)
            self.evicted += 1

    def frame(self, index: int) -> dict[str, Any] | None:
        """The kept document of frame ``index``, if any."""
        return self._frames.get(index)

    def since(self, index: int) -> list[dict[str, Any]]:
        """Frames with an index above ``index``, oldest first."""
        return [doc for n, doc in sorted(self._frames.items()) if n > index]

    def __len__(self) -> int:
        return len(self._frames)
