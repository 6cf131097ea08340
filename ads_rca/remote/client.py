"""A dashboard's Zenoh side: subscribe to the runs' JSON, ask the queryables what was missed.

Used by ``ads-rca watch`` and ``ads-rca dashboard``; no rclpy. Zenoh calls back on its own
threads, so samples are handed over through a queue and the caller drains it into its
:class:`~ads_rca.remote.view.DashboardModel` on its own thread (:meth:`RemoteClient.drain`).
The session is closed on every exit path (a process that exits with an open session holding
a subscriber hangs: use it as a context manager or call :meth:`close`).
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Sequence
from typing import Any

from ads_rca.remote.config import DEFAULT_ENDPOINT, session_config
from ads_rca.remote.keys import DASHBOARD_ROOT, SAMPLE_SUFFIX, check_prefix
from ads_rca.remote.session import SessionOwner, close_session

#: Samples waiting for the caller beyond this are dropped (and counted): a stalled UI must
#: not grow memory without bound.
QUEUE_LIMIT = 100_000


def root_expression(prefix: str | None) -> str:
    """The key expression of every dashboard key of ``prefix`` (None: of every run)."""
    if prefix is None:
        return f"**/{DASHBOARD_ROOT}"
    base = check_prefix(prefix)
    return f"{base}/{DASHBOARD_ROOT}" if base else DASHBOARD_ROOT


class RemoteClient(SessionOwner):
    """A Zenoh session subscribed to ``<prefix>/ads_rca/**`` (every prefix by default)."""

    def __init__(
        self,
        connect: Sequence[str] = (DEFAULT_ENDPOINT,),
        prefix: str | None = None,
        mode: str = "client",
        listen: Sequence[str] = (),
        allow_remote: bool = False,
    ) -> None:
        self.config_text = session_config(mode, listen, connect, allow_remote)
        self.root = root_expression(prefix)
        self.samples: queue.Queue[tuple[str, bytes]] = queue.Queue(QUEUE_LIMIT)
        self.dropped = 0
        self._lock = threading.Lock()
        self._session: Any = None
        self._subscriber: Any = None

    def open(self) -> RemoteClient:
        import zenoh

        self._session = zenoh.open(zenoh.Config.from_json5(self.config_text))
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
        self._offer(str(sample.key_expr), sample.payload.to_bytes())

    def _offer(self, key: str, payload: bytes) -> None:
        try:
            self.samples.put_nowait((key, payload))
        except queue.Full:
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
                    self._offer(str(reply.ok.key_expr), reply.ok.payload.to_bytes())
                    count += 1
        return count

    def drain(self, limit: int = 10_000) -> list[tuple[str, bytes]]:
        """Samples received since the last call (at most ``limit``), oldest first."""
        out: list[tuple[str, bytes]] = []
        while len(out) < limit:
            try:
                out.append(self.samples.get_nowait())
            except queue.Empty:
                break
        return out

    def close(self) -> None:
        """Undeclare and close; safe to call twice."""
        subscriber, self._subscriber = self._subscriber, None
        session, self._session = self._session, None
        close_session(session, [] if subscriber is None else [subscriber])
