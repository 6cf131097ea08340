"""The one bounded cache the oracles use: least recently used, with compute-on-miss.

Why: oracles memoise parsed layouts and per-timestamp views so the four of them (and
overlapping horizons) build each thing once, but a live monitor runs for hours, so every
cache must be bounded. One class instead of a hand-rolled dict per use.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable
from typing import Generic, TypeVar

K = TypeVar("K")
V = TypeVar("V")

#: Default size: enough for the corrected control horizon's plans plus slack.
CACHE_SIZE = 64


class LRU(Generic[K, V]):
    """A small least-recently-used cache with a compute-on-miss accessor."""

    def __init__(self, size: int = CACHE_SIZE) -> None:
        self._data: OrderedDict[K, V] = OrderedDict()
        self._size = size

    def lookup(self, key: K) -> V | None:
        """The cached value, or None (no computation)."""
        if key in self._data:
            self._data.move_to_end(key)
            return self._data[key]
        return None

    def put(self, key: K, value: V) -> None:
        self._data[key] = value
        self._data.move_to_end(key)
        if len(self._data) > self._size:
            self._data.popitem(last=False)

    def get(self, key: K, compute: Callable[[], V]) -> V:
        if key in self._data:
            self._data.move_to_end(key)
            return self._data[key]
        value = compute()
        self.put(key, value)
        return value

    def __len__(self) -> int:
        return len(self._data)
