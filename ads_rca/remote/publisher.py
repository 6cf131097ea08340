"""The bridge's Zenoh side: a session that puts the state's samples and answers its queries.

No rclpy: the ``zenoh_bridge`` node feeds it from ROS subscriptions, and tests and benches
feed it directly. Every entry point takes the state lock, because the queryables answer on
a zenoh thread while the node puts from its executor thread. The session is closed on every
exit path (an open session with a queryable hangs the interpreter at exit).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

from ads_rca.errors import ConfigError
from ads_rca.remote.config import session_config
from ads_rca.remote.session import SessionOwner, close_session, open_session
from ads_rca.remote.state import Put, RemoteState


class ZenohPublisher(SessionOwner):
    """Puts JSON and raw CDR samples; answers ``verdict``, ``status`` and ``frames``."""

    def __init__(
        self,
        state: RemoteState,
        mode: str = "peer",
        listen: Sequence[str] = (),
        connect: Sequence[str] = (),
        allow_remote: bool = False,
        clock: Callable[[], float] = time.time,
        allow_option: str = "-p zenoh_allow_remote:=true",
    ) -> None:
        self.state = state
        self.config_text = session_config(mode, listen, connect, allow_remote, allow_option)
        self.clock = clock
        self.lock = threading.Lock()
        self.puts = 0
        self.raw_puts = 0
        self.queries = 0
        self.refused_queries = 0
        self._session: Any = None
        self._declared: list[Any] = []
        self._raw_publishers: dict[str, Any] = {}

    def open(self) -> ZenohPublisher:
        self._session = open_session(self.config_text)
        try:
            for key in self.state.queries.values():
                self._declared.append(self._session.declare_queryable(key, self._answerer(key)))
        except BaseException:
            self.close()
            raise
        return self

    def _answerer(self, key: str) -> Callable[[Any], None]:
        """The callback of ``key``'s queryable: a query's own key expression may be a
        wildcard (``**/ads_rca/verdict``), the reply names the key answered."""
        return lambda query: self._on_query(query, key)

    def _on_query(self, query: Any, key: str) -> None:  # on a zenoh thread
        try:
            parameters = dict(query.parameters)
            with self.lock:
                self.queries += 1
                text = self.state.answer(key, parameters, self.clock())
        except ConfigError as error:
            with self.lock:
                self.refused_queries += 1
            query.reply_err(str(error))
            return
        if text is not None:
            import zenoh

            query.reply(key, text, encoding=zenoh.Encoding.APPLICATION_JSON)

    def send(self, puts: list[Put]) -> None:
        """Put JSON samples (what the state's methods returned). Every put blocks rather
        than drops when the link is congested (Zenoh's default for puts is to drop): the
        rate limits, not the transport, decide what a slow link is spared."""
        session = self._session
        if session is None:
            return
        import zenoh

        for key, text in puts:
            session.put(
                key,
                text,
                encoding=zenoh.Encoding.APPLICATION_JSON,
                congestion_control=zenoh.CongestionControl.BLOCK,
            )
        self.puts += len(puts)

    def put_raw(self, key: str, payload: bytes, ros_type: str) -> None:
        """One raw CDR sample on a zenoh-bridge-ros2dds key (a declared publisher per key;
        encoding ``application/cdr`` with the ROS type as its schema)."""
        if self._session is None:
            return
        publisher = self._raw_publishers.get(key)
        if publisher is None:
            import zenoh

            encoding = zenoh.Encoding.APPLICATION_CDR.with_schema(ros_type)
            publisher = self._session.declare_publisher(
                key, encoding=encoding, congestion_control=zenoh.CongestionControl.BLOCK
            )
            self._raw_publishers[key] = publisher
        publisher.put(payload)
        self.raw_puts += 1

    def on_result(self, text: str | bytes) -> None:
        with self.lock:
            puts = self.state.on_result(text, self.clock())
        self.send(puts)

    def on_verdict(self, text: str | bytes) -> None:
        with self.lock:
            puts = self.state.on_verdict(text, self.clock())
        self.send(puts)

    def tick(self, heartbeat: bool, state: str = "running") -> None:
        """Send what the rate limits now allow, and the status when ``heartbeat``."""
        now = self.clock()
        with self.lock:
            puts = self.state.flush(now)
            if heartbeat:
                puts += self.state.heartbeat(now, state)
        self.send(puts)

    def finish(self, state: str = "stopped") -> None:
        """Everything pending, then the final status: before closing."""
        now = self.clock()
        with self.lock:
            puts = self.state.flush(now, force=True) + self.state.heartbeat(now, state)
        self.send(puts)

    def close(self) -> None:
        """Undeclare everything and close the session; safe to call twice."""
        declared, self._declared = self._declared, []
        publishers, self._raw_publishers = self._raw_publishers, {}
        session, self._session = self._session, None
        close_session(session, [*declared, *publishers.values()])
