"""Per-key rate limits, so a slow link is not flooded and the latest state still arrives.

A key with a limit r (samples per second) sends at most one sample per 1/r s. A sample that
comes sooner is not lost outright: it replaces the key's pending sample, which :meth:`flush`
sends once the interval has passed, so a dashboard always ends on the newest value. Keys
named in ``never_dropped`` (the verdict and the status) bypass the limit.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Generic, TypeVar

from ads_rca.errors import ConfigError

P = TypeVar("P")


@dataclass
class RateLimiter(Generic[P]):
    """Limits by key (samples per second; absent or 0: unlimited)."""

    rates: Mapping[str, float]
    never_dropped: frozenset[str] = frozenset()
    _last: dict[str, float] = field(default_factory=dict)
    _pending: dict[str, P] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for key, rate in self.rates.items():
            if not (isinstance(rate, (int, float)) and math.isfinite(rate) and rate >= 0):
                raise ConfigError(f"rate limit of {key[:60]!r}: {rate!r} is not a rate >= 0")

    def _interval(self, key: str) -> float:
        rate = self.rates.get(key, 0.0)
        return 0.0 if key in self.never_dropped or rate <= 0 else 1.0 / rate

    def offer(self, key: str, payload: P, now: float) -> list[tuple[str, P]]:
        """What to send now for a new sample at time ``now`` (s): the sample itself, or
        nothing while the key's interval runs (it is then the key's pending sample)."""
        last = self._last.get(key)
        if last is None or now - last >= self._interval(key):
            self._last[key] = now
            self._pending.pop(key, None)
            return [(key, payload)]
        self._pending[key] = payload
        return []

    def flush(self, now: float, force: bool = False) -> list[tuple[str, P]]:
        """Pending samples whose interval has passed (all of them with ``force``: at the end
        of a run)."""
        due = [
            key
            for key in self._pending
            if force or now - self._last.get(key, -math.inf) >= self._interval(key)
        ]
        out = [(key, self._pending.pop(key)) for key in due]
        for key in due:
            self._last[key] = now
        return out

    def pending(self) -> Iterable[str]:
        return tuple(self._pending)
