"""A dashboard's Zenoh side: subscribe to the runs' JSON, ask the queryables what was missed.

Used by ``ads-rca watch`` and ``ads-rca dashboard``; no rclpy. Zenoh calls back on its own
threads, so samples are handed over through a queue and the caller drains it into its
:class:`~ads_rca.remote.view.DashboardModel` on its own thread (:meth:`RemoteClient.drain`).
The session is closed on every exit path (a process that exits with an open session holding
a subscriber hangs: use it as a context manager or call :meth:`close`).

:class:`RemoteLinks` keeps one session per endpoint, so each endpoint's state is known
and shown (one client session with two endpoints reaches only one of them), opens the
ones whose peer is not up yet, opens afresh a session that reached nobody for
:data:`REOPEN_AFTER_S` (recovery never rests on Zenoh's own reconnection, whatever the
outage's length), and asks the queryables again whenever a link (re)connects.
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial
from typing import Any

from ads_rca.foundation.text import printable
from ads_rca.remote.config import DEFAULT_ENDPOINT, session_config
from ads_rca.remote.keys import DASHBOARD_ROOT, SAMPLE_SUFFIX, check_prefix
from ads_rca.remote.session import SessionOwner, close_session, open_session
from ads_rca.remote.view import payload_limit

#: Samples waiting for the caller beyond this many, or these many bytes, are dropped (and
#: counted): a stalled UI, or a peer putting large samples, must not grow memory without
#: bound.
QUEUE_LIMIT = 100_000
QUEUE_BYTES = 256 * 1024 * 1024
#: Seconds between attempts to open a session whose peer does not answer.
RETRY_S = 0.5
#: A session that has reached no peer or router this long is closed and opened afresh.
REOPEN_AFTER_S = 30.0
#: Seconds between two looks at the links (and checks for a catch-up to run).
LINK_PERIOD_S = 0.25
#: A link's states.
CONNECTED, CONNECTING, DISCONNECTED = "connected", "connecting", "not connected"


def root_expression(prefix: str | None) -> str:
    """The key expression of every dashboard key of ``prefix`` (None: of every run)."""
    if prefix is None:
        return f"**/{DASHBOARD_ROOT}"
    base = check_prefix(prefix)
    return f"{base}/{DASHBOARD_ROOT}" if base else DASHBOARD_ROOT


class SampleQueue(queue.Queue[tuple[str, bytes]]):
    """Samples (key, payload) for the caller, bounded in count (:data:`QUEUE_LIMIT`) and
    in bytes (:data:`QUEUE_BYTES`)."""

    def __init__(self, limit: int = QUEUE_LIMIT, max_bytes: int = QUEUE_BYTES) -> None:
        super().__init__(limit)
        self.max_bytes = max_bytes
        self.bytes = 0

    def offer(self, item: tuple[str, bytes]) -> bool:
        """Queue ``item`` unless that would pass either bound; whether it was queued."""
        with self.mutex:
            if self.bytes + len(item[1]) > self.max_bytes:
                return False
        try:
            self.put_nowait(item)
        except queue.Full:
            return False
        return True

    def drain(self, limit: int) -> list[tuple[str, bytes]]:
        """What is queued (at most ``limit``), oldest first, without waiting."""
        out: list[tuple[str, bytes]] = []
        while len(out) < limit:
            try:
                out.append(self.get_nowait())
            except queue.Empty:
                break
        return out

    def _put(self, item: tuple[str, bytes]) -> None:  # under the queue's mutex
        self.queue.append(item)
        self.bytes += len(item[1])

    def _get(self) -> tuple[str, bytes]:  # under the queue's mutex
        item: tuple[str, bytes] = self.queue.popleft()
        self.bytes -= len(item[1])
        return item


class RemoteClient(SessionOwner):
    """A Zenoh session subscribed to ``<prefix>/ads_rca/**`` (every prefix by default)."""

    def __init__(
        self,
        connect: Sequence[str] = (DEFAULT_ENDPOINT,),
        prefix: str | None = None,
        mode: str = "client",
        listen: Sequence[str] = (),
        allow_remote: bool = False,
        samples: SampleQueue | None = None,
    ) -> None:
        self.config_text = session_config(mode, listen, connect, allow_remote)
        self.root = root_expression(prefix)
        #: Where samples and replies go (several clients may share one).
        self.samples = samples or SampleQueue()
        #: Called on Zenoh's thread after each sample is queued (None: nothing).
        self.on_sample: Callable[[], None] | None = None
        self.dropped = 0
        #: Of :attr:`dropped`, those refused for their size (``view.payload_limit``).
        self.oversize = 0
        self._lock = threading.Lock()
        self._session: Any = None
        self._subscriber: Any = None

    def open(self) -> RemoteClient:
        self._session = open_session(self.config_text)
        try:
            # Only the JSON samples: raw CDR keys of the graph's namespace share the root.
            self._subscriber = self._session.declare_subscriber(
                f"{self.root}/**/$*{SAMPLE_SUFFIX}", self._on_sample
            )
        except BaseException:
            self.close()
            raise
        return self

    def _on_sample(self, sample: Any) -> None:  # on a zenoh thread
        self._offer(str(sample.key_expr), sample.payload)
        if self.on_sample is not None:
            self.on_sample()

    def _offer(self, key: str, payload: Any) -> None:
        """Queue a sample's key and bytes; one over its key's size limit is counted and
        dropped before it is copied out of Zenoh's buffer, and so is one that would take
        the queue past :data:`QUEUE_BYTES`."""
        if len(payload) > payload_limit(key):
            with self._lock:
                self.oversize += 1
                self.dropped += 1
            return
        data = payload if isinstance(payload, bytes) else payload.to_bytes()
        if not self.samples.offer((key, data)):
            with self._lock:
                self.dropped += 1

    def catch_up(self, since: int = -1, timeout: float = 2.0) -> int:
        """Ask every run's queryables for its status, its verdict and the frames after
        ``since``; the replies join the sample queue. Returns how many replies came."""
        if self._session is None:
            raise RuntimeError("catch_up before open")
        count = 0
        for selector in (
            f"{self.root}/status",
            f"{self.root}/frames?since={int(since)}",
            f"{self.root}/verdict",
        ):
            for reply in self._session.get(selector, timeout=timeout):
                if reply.ok is not None:
                    self._offer(str(reply.ok.key_expr), reply.ok.payload)
                    count += 1
        return count

    def drain(self, limit: int = 10_000) -> list[tuple[str, bytes]]:
        """Samples received since the last call (at most ``limit``), oldest first."""
        return self.samples.drain(limit)

    def connected(self) -> bool:
        """The session reaches a peer or a router right now."""
        session = self._session
        if session is None:
            return False
        info = session.info
        return bool(list(info.peers_zid()) or list(info.routers_zid()))

    def close(self) -> None:
        """Undeclare and close; safe to call twice."""
        subscriber, self._subscriber = self._subscriber, None
        session, self._session = self._session, None
        close_session(session, [] if subscriber is None else [subscriber])


def one_line(error: BaseException) -> str:
    """Zenoh's error text without its source location, on one line."""
    text = str(error).split(" at /", 1)[0].strip() or type(error).__name__
    return printable(text)[:160]


@dataclass
class Link:
    """One endpoint's session and what is known of it."""

    endpoint: str
    client: RemoteClient
    opened: bool = False
    connected: bool = False
    #: Why the session could not open or was dropped ("" when none).
    error: str = ""
    #: Wall-clock time of the last change of :attr:`state` (0: none yet).
    since: float = 0.0
    #: Sessions opened afresh after reaching nobody for :data:`REOPEN_AFTER_S`.
    reopened: int = 0
    _next_open: float = 0.0
    _reached: float = 0.0

    @property
    def state(self) -> str:
        if self.connected:
            return CONNECTED
        return DISCONNECTED if self.opened or self.since else CONNECTING

    def open(self, tick: float) -> None:
        """Open the session now (Zenoh's error when it cannot)."""
        self.client.open()
        self.opened, self._reached = True, tick

    def maintain(self, tick: float, wall: float) -> bool:
        """Open the session if due, note whether it reaches anyone, open it afresh when it
        has not for :data:`REOPEN_AFTER_S`. True when it has just connected."""
        before = self.state
        if not self.opened and tick >= self._next_open:
            try:
                self.open(tick)
            except Exception as error:  # zenoh.ZError: the peer is not listening (yet)
                self.error = one_line(error)
                self._next_open = tick + RETRY_S
        connected = self.opened and self.client.connected()
        if connected:
            self._reached, self.error = tick, ""
        elif self.opened and tick - self._reached > REOPEN_AFTER_S:
            self.client.close()
            self.opened, self.reopened, self._next_open = False, self.reopened + 1, tick
            self.error = f"reached nobody for {REOPEN_AFTER_S:g} s: opening a new session"
        self.connected = connected
        if self.state != before:
            self.since = wall
        return connected and before != CONNECTED

    def describe(self) -> dict[str, Any]:
        """The link as the dashboards show it (strict JSON)."""
        return {
            "endpoint": self.endpoint,
            "state": self.state,
            "since": self.since,
            "error": self.error,
            "reopened": self.reopened,
        }


class RemoteLinks:
    """One :class:`RemoteClient` per endpoint, all feeding one queue, looked after on a
    thread of their own (opened, reopened, caught up: a query waits for its replies, the
    caller's loop must not)."""

    def __init__(
        self,
        connect: Sequence[str] = (DEFAULT_ENDPOINT,),
        prefix: str | None = None,
        mode: str = "client",
        allow_remote: bool = False,
        catch_up_timeout: float = 2.0,
        wall: Callable[[], float] = time.time,
    ) -> None:
        self.samples = SampleQueue()
        # Every endpoint is checked here (ConfigError: one line) before anything opens.
        self.links = [
            Link(
                endpoint,
                RemoteClient(
                    (endpoint,), prefix, mode, allow_remote=allow_remote, samples=self.samples
                ),
            )
            for endpoint in dict.fromkeys(connect)
        ]
        for link in self.links:
            link.client.on_sample = partial(self._heard, link)
        self.catch_up_timeout = catch_up_timeout
        self.wall = wall
        #: When the last finished catch-up began (monotonic; its replies are queued).
        self.caught_up = 0.0
        #: The last catch-up's error ("" when it worked).
        self.catch_up_error = ""
        self._lock = threading.Lock()
        self._wanted = threading.Event()
        #: Set to look at the links before the period ends.
        self._look = threading.Event()
        self._stopping = threading.Event()
        self._thread: threading.Thread | None = None

    @property
    def endpoints(self) -> tuple[str, ...]:
        return tuple(link.endpoint for link in self.links)

    @property
    def dropped(self) -> int:
        return sum(link.client.dropped for link in self.links)

    def open_now(self) -> None:
        """Try every session once on this thread: an error that is not "the peer is not
        up" (a peer session opens without one) reaches the caller."""
        tick = time.monotonic()
        with self._lock:
            for link in self.links:
                link.open(tick)

    def start(self) -> RemoteLinks:
        self._thread = threading.Thread(target=self._run, name="zenoh-links", daemon=True)
        self._thread.start()
        return self

    def request_catch_up(self) -> None:
        """Ask every connected link's queryables again, on the links' thread."""
        self._wanted.set()

    def _heard(self, link: Link) -> None:
        """A sample came through ``link`` (on a Zenoh thread). Not marked connected yet (it
        connected since the last look): look now, not at the period's end, so that no
        dashboard says "not connected" beside results that came through it."""
        if not link.connected:
            self._look.set()

    def states(self) -> list[dict[str, Any]]:
        return [link.describe() for link in self.links]

    def any_connected(self) -> bool:
        return any(link.connected for link in self.links)

    def drain(self, limit: int = 10_000) -> list[tuple[str, bytes]]:
        """Samples and replies of every link since the last call, oldest first."""
        return self.samples.drain(limit)

    def _run(self) -> None:
        while not self._stopping.is_set():
            tick = time.monotonic()
            with self._lock:
                if self._stopping.is_set():
                    break
                arrived = [link.maintain(tick, self.wall()) for link in self.links]
            if any(arrived) or self._wanted.is_set():
                self._wanted.clear()
                # Begun after the request it answers was seen (``Watcher.settled``).
                self._catch_up(time.monotonic())
            self._look.wait(LINK_PERIOD_S)
            self._look.clear()

    def _catch_up(self, began: float) -> None:
        error = ""
        for link in self.links:
            if not link.connected or self._stopping.is_set():
                continue
            try:
                link.client.catch_up(timeout=self.catch_up_timeout)
            except Exception as failure:  # the session closing under it, or the peer gone
                error = f"{link.endpoint}: {one_line(failure)}"
        self.catch_up_error = error
        self.caught_up = began

    def close(self) -> None:
        """Stop the thread (a query in progress ends with its session) and close every
        session; safe to call twice."""
        self._stopping.set()
        self._look.set()
        for link in self.links:
            link.client.close()
        if self._thread is not None:
            self._thread.join(self.catch_up_timeout + RETRY_S + 1.0)
            self._thread = None
        with self._lock:
            for link in self.links:
                link.client.close()
                link.opened = link.connected = False
