"""The bounded caches the oracles use: least recently used, with compute-on-miss, and the
sliding run of values a floor reads.

Why: oracles memoise parsed layouts and per-timestamp views so the four of them (and
overlapping horizons) build each thing once, but a live monitor runs for hours, so every
cache must be bounded. One class instead of a hand-rolled dict per use; and for a floor,
which reads a value per frame of a window that slides by one frame per timestamp, one
that keeps the last window's values, so reading the next costs one new value, not a
lookup per frame. A live monitor judges each frame on a new view of its window, so it
also carries per-frame values from one view's context to the next, each with the records it
was computed from.
"""

from __future__ import annotations

from bisect import bisect_left
from collections import OrderedDict
from collections.abc import Callable
from typing import Generic, TypeVar

K = TypeVar("K")
V = TypeVar("V")

#: What a missing key reads as (None may be a cached value).
_ABSENT = object()

#: Default size: enough for the corrected control horizon's plans plus slack.
CACHE_SIZE = 64


class LRU(Generic[K, V]):
    """A small least-recently-used cache with a compute-on-miss accessor."""

    def __init__(self, size: int = CACHE_SIZE) -> None:
        self._data: OrderedDict[K, V] = OrderedDict()
        self._size = size

    def lookup(self, key: K) -> V | None:
        """The cached value, or None (no computation)."""
        data = self._data
        value = data.get(key, _ABSENT)
        if value is _ABSENT:
            return None
        data.move_to_end(key)
        return value  # type: ignore[return-value]

    def put(self, key: K, value: V) -> None:
        data = self._data
        if key in data:
            data.move_to_end(key)
        data[key] = value  # a new key goes last
        if len(data) > self._size:
            data.popitem(last=False)

    def get(self, key: K, compute: Callable[[], V]) -> V:
        data = self._data
        found = data.get(key, _ABSENT)
        if found is not _ABSENT:
            data.move_to_end(key)
            return found  # type: ignore[return-value]
        value = compute()
        self.put(key, value)
        return value

    def __len__(self) -> int:
        return len(self._data)

    def __contains__(self, key: object) -> bool:
        """Whether ``key`` is cached (its recency unchanged)."""
        return key in self._data


class Slide(Generic[V]):
    """The values of the last ascending run of keys read, reused where the next run overlaps
    it: a run that slides by one key computes one value. A value must be a function of its
    key (and ``tag``: values read under another tag are not reused)."""

    def __init__(self) -> None:
        self._keys: list[int] = []
        self._values: list[V] = []
        self._tag: object = None

    def read(self, keys: list[int], compute: Callable[[int], V], tag: object = None) -> list[V]:
        """The value of each of ``keys`` (ascending), computing only those not in the last
        run read (under the same tag)."""
        old = self._keys if tag == self._tag else []
        start = bisect_left(old, keys[0]) if keys else len(old)
        shared = len(old) - start
        if shared and old[start:] == keys[:shared]:
            values = self._values[start:] + [compute(k) for k in keys[shared:]]
        else:
            values = [compute(k) for k in keys]
        self._keys, self._values, self._tag = keys, values, tag
        return values


class Carry(Generic[K, V]):
    """Values kept from one context of a run to the next (a live monitor builds one per view
    of its window), each with the records it was computed from: a value is reused only
    while every one of them is the very same object, so a record that arrived since, or a
    view that lacks one, computes afresh. Bounded: least recently used."""

    def __init__(self, size: int = CACHE_SIZE) -> None:
        self._data: LRU[K, tuple[tuple[object, ...], V]] = LRU(size)

    def get(self, key: K, sources: tuple[object, ...], compute: Callable[[], V]) -> V:
        """The value kept for ``key`` if it was computed from ``sources`` (by identity),
        else ``compute()``, kept with them."""
        found = self._data.lookup(key)
        if found is not None:
            kept = found[0]
            if len(kept) == len(sources) and all(
                a is b for a, b in zip(kept, sources, strict=True)
            ):
                return found[1]
        value = compute()
        self._data.put(key, (sources, value))
        return value

    def __len__(self) -> int:
        return len(self._data)
