"""Messages a node had to skip: counted per topic, said in the log without flooding it.

Anyone on the domain can publish on the contract's topics, so a subscriber meets bytes that
are not a message of the topic's type, JSON it cannot read, or a document missing what it
needs. Such a message is skipped (never half-used, never a dead node) and said: the first
one on a topic at once, later ones at most once per ``period_s`` per topic with how many
were skipped since. The counts go in the node's heartbeat status. Pure: no rclpy.
"""

from __future__ import annotations

from collections import Counter

from ads_rca.foundation.text import printable


class SkippedMessages:
    """Per-topic counts of skipped messages, and the log lines due (rate-limited)."""

    def __init__(self, period_s: float = 10.0) -> None:
        self.period_s = period_s
        self.counts: Counter[str] = Counter()
        self._unsaid: Counter[str] = Counter()
        self._said_at: dict[str, float] = {}

    def note(self, topic: str, reason: object, now: float) -> str | None:
        """Count one skipped message; the line to log now, or None (said recently)."""
        self.counts[topic] += 1
        self._unsaid[topic] += 1
        said = self._said_at.get(topic)
        if said is not None and now - said < self.period_s:
            return None
        self._said_at[topic] = now
        count = self._unsaid.pop(topic)
        more = "" if count == 1 else f" ({count} since the last report)"
        return f"malformed message on {topic} skipped{more}: {printable(reason)}"

    @property
    def total(self) -> int:
        return sum(self.counts.values())
