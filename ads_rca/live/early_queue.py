"""Data that arrives before the run's metadata, held in a queue bounded in bytes.

A monitor cannot decode a data message before it knows the run (its frame period, its
player), so such messages wait. Anyone on the domain can publish before any run starts:
without a bound, a flood before the metadata would grow the queue until memory runs out.
The queue keeps at most ``max_bytes`` of payload; past that the OLDEST messages are dropped
(a real player sends its metadata first, so what is dropped in a flood is stale) and
counted, for the node to say. Pure: no rclpy.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterator
from typing import Generic, TypeVar

#: Default bound: a few seconds of a busy run's data (50 actors, 20 Hz: ~50 kB a frame).
DEFAULT_MAX_BYTES = 64 << 20

Info = TypeVar("Info")


class EarlyQueue(Generic[Info]):
    """(topic key, payload, info, arrival) in arrival order, at most ``max_bytes`` of payload."""

    def __init__(self, max_bytes: int = DEFAULT_MAX_BYTES) -> None:
        self.max_bytes = max_bytes
        self.size = 0
        self.dropped = 0
        self._items: deque[tuple[str, bytes, Info, float]] = deque()

    def add(self, key: str, data: bytes, info: Info, arrived: float) -> int:
        """Queue one message; how many old ones were dropped to make room for it."""
        self._items.append((key, data, info, arrived))
        self.size += len(data)
        dropped = 0
        while self.size > self.max_bytes and self._items:
            _key, old, _info, _arrived = self._items.popleft()
            self.size -= len(old)
            dropped += 1
        self.dropped += dropped
        return dropped

    def overflow_reason(self) -> str:
        """Why messages were dropped, for the node's log."""
        return (
            f"no run metadata yet and more than {self.max_bytes >> 20} MiB of data queued: "
            f"{self.dropped} oldest messages dropped so far"
        )

    def drain(self) -> Iterator[tuple[str, bytes, Info, float]]:
        """Every queued message, oldest first; the queue is empty afterwards."""
        items, self._items, self.size = self._items, deque(), 0
        yield from items

    def __len__(self) -> int:
        return len(self._items)
