"""The dashboard's TCP connections: bounded in number, and a request that never completes
is closed.

Why: aiohttp holds every connection a peer opens for as long as the peer likes, and a
request whose headers come a byte at a time is waited for until its keep-alive runs out
(an hour). 1,100 such half-open requests at the common ``ulimit -n 1024`` took the process
past its file descriptors: every accept failed (EMFILE, with tracebacks) and the dashboard
was unreachable until they stopped. Here each accepted connection goes through
:class:`GuardedProtocol`: past :attr:`ConnectionGuard.max_total` open connections, or
:attr:`ConnectionGuard.max_per_peer` from one address, it is closed at once; one that has
not completed a request within :attr:`ConnectionGuard.request_timeout_s` is closed. The
bounds follow the process's open-file limit, so accepting never runs out of descriptors.
Refusals are counted and said at most once per :data:`SAY_EVERY_S`, never one line each.
"""

from __future__ import annotations

import asyncio
import logging
import resource
import time
from dataclasses import dataclass, field
from typing import Any

#: Most connections kept open at once, whatever the open-file limit allows.
MAX_CONNECTIONS = 512
#: Seconds a connection may take to send a complete request.
REQUEST_TIMEOUT_S = 10.0
#: Least seconds between two log lines about refused connections.
SAY_EVERY_S = 10.0

LOG = logging.getLogger("ads_rca.dashboard")


def connection_bounds(limit: int = MAX_CONNECTIONS) -> tuple[int, int]:
    """(most connections, most from one address): at most half the open-file limit (the
    rest for the Zenoh sessions, the static files, the interpreter), and half of that from
    one address."""
    soft, _hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    total = limit if soft == resource.RLIM_INFINITY else max(8, min(limit, soft // 2))
    return total, max(4, total // 2)


@dataclass
class ConnectionGuard:
    """Open connections by address, and those that have not completed a request yet."""

    max_total: int
    max_per_peer: int
    request_timeout_s: float = REQUEST_TIMEOUT_S
    by_peer: dict[str, int] = field(default_factory=dict)
    waiting: set[Any] = field(default_factory=set)
    refused: int = 0
    timed_out: int = 0
    _said_at: float = -SAY_EVERY_S
    _said: tuple[int, int] = (0, 0)

    @property
    def total(self) -> int:
        return sum(self.by_peer.values())

    def admit(self, peer: str, transport: Any) -> bool:
        """Whether a new connection from ``peer`` may stay open (counted if so)."""
        if self.total >= self.max_total or self.by_peer.get(peer, 0) >= self.max_per_peer:
            self.refused += 1
            self._say()
            return False
        self.by_peer[peer] = self.by_peer.get(peer, 0) + 1
        self.waiting.add(transport)
        return True

    def started(self, transport: Any) -> None:
        """A request came complete on ``transport`` (the app's middleware says so)."""
        self.waiting.discard(transport)

    def release(self, peer: str, transport: Any) -> None:
        self.waiting.discard(transport)
        left = self.by_peer.get(peer, 0) - 1
        if left > 0:
            self.by_peer[peer] = left
        else:
            self.by_peer.pop(peer, None)

    def expire(self, transport: Any) -> None:
        """Close ``transport`` if it still has not completed a request."""
        if transport in self.waiting and not transport.is_closing():
            self.timed_out += 1
            transport.close()
            self._say()

    def _say(self) -> None:
        now = time.monotonic()
        counts = (self.refused, self.timed_out)
        if now - self._said_at >= SAY_EVERY_S and counts != self._said:
            self._said_at, self._said = now, counts
            LOG.warning(
                "ads-rca dashboard: %d connections refused over the limit (%d in all, %d per "
                "address), %d closed for not sending a request within %g s",
                self.refused,
                self.max_total,
                self.max_per_peer,
                self.timed_out,
                self.request_timeout_s,
            )


class GuardedProtocol(asyncio.Protocol):
    """aiohttp's protocol for one connection, behind :class:`ConnectionGuard`."""

    def __init__(self, inner: asyncio.Protocol, guard: ConnectionGuard) -> None:
        self.inner, self.guard = inner, guard
        self.peer = ""
        self.admitted = False
        self.transport: asyncio.BaseTransport | None = None
        self._timer: asyncio.TimerHandle | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        name = transport.get_extra_info("peername")
        self.peer = str(name[0]) if isinstance(name, tuple) and name else "?"
        self.transport = transport
        if not self.guard.admit(self.peer, transport):
            if isinstance(transport, asyncio.Transport):
                transport.abort()
            else:
                transport.close()
            return
        self.admitted = True
        loop = asyncio.get_running_loop()
        self._timer = loop.call_later(self.guard.request_timeout_s, self.guard.expire, transport)
        self.inner.connection_made(transport)

    def data_received(self, data: bytes) -> None:
        if self.admitted:
            self.inner.data_received(data)

    def eof_received(self) -> bool | None:
        return self.inner.eof_received() if self.admitted else None

    def pause_writing(self) -> None:
        if self.admitted:
            self.inner.pause_writing()

    def resume_writing(self) -> None:
        if self.admitted:
            self.inner.resume_writing()

    def connection_lost(self, exc: Exception | None) -> None:
        if self._timer is not None:
            self._timer.cancel()
        if self.admitted:
            self.guard.release(self.peer, self.transport)
            self.inner.connection_lost(exc)
