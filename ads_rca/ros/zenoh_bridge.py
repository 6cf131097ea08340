"""``zenoh_bridge`` node: the graph's results on Eclipse Zenoh, for dashboards without ROS.

It subscribes (raw, no deserialisation) to a list of topics, by default the graph's results
(``metrics/<module>`` and their ``/values``, ``verdict``, ``verdict/json``,
``/diagnostics``, ``run/collision``, ``run/metadata``, ``player/status``), and publishes:

- every message's CDR bytes under its zenoh-bridge-ros2dds key (the ROS name without the
  leading slash, under ``zenoh_prefix``), encoding ``application/cdr`` with the ROS type as
  its schema, so a remote ``zenoh-bridge-ros2dds`` or a plain Zenoh subscriber decodes it;
- the dashboards' JSON under ``<zenoh_prefix>/ads_rca/...`` (per-module results, the
  verdict, a status heartbeat), with queryables for a dashboard that connects late.

The JSON side is :class:`~ads_rca.remote.state.RemoteState` behind a
:class:`~ads_rca.remote.publisher.ZenohPublisher`; this node only moves bytes. The Zenoh
session is loopback-only unless ``zenoh_allow_remote`` (docs/remote.md) and is closed on
every exit path (SIGINT and SIGTERM included: ``run_node`` calls :meth:`ZenohBridge.close`).
Once the verdict went out it logs :data:`~ads_rca.ros.graph.BRIDGE_FORWARDED` (``replay``
stops the rest of its graph only then). With ``exit_after_verdict`` it stops ``linger_s``
seconds later (``ads-rca replay --zenoh``: 30 s; ``inf``: not before it is stopped),
answering late dashboards' queries until then.
"""

from __future__ import annotations

import math
import time
from typing import Any

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile

from ads_rca.contract import live_topics, rosmsg, topics
from ads_rca.contract.cdr_decode import decode_string
from ads_rca.contract.errors import DOCUMENT_ERRORS, MalformedMessage
from ads_rca.errors import AdsRcaError, ConfigError
from ads_rca.foundation import quick_exit
from ads_rca.live.runid import checked_run_id
from ads_rca.oracles.base import MODULES
from ads_rca.paramspec import LINGER, RATE, SECONDS, Range
from ads_rca.remote.config import DEFAULT_ENDPOINT
from ads_rca.remote.keys import ros_key
from ads_rca.remote.publisher import ZenohPublisher
from ads_rca.remote.rate import RateLimiter
from ads_rca.remote.state import RemoteState
from ads_rca.ros.graph import BRIDGE_FORWARDED
from ads_rca.ros.nodemain import run_node, subscribe_ready_once_matched
from ads_rca.ros.nodeparams import (
    NodeParameter,
    command_line_overrides,
    declare_node_parameters,
    log_in_force,
)
from ads_rca.ros.qos_match import offered_qos

#: How often rate-limited samples are flushed (s).
FLUSH_PERIOD_S = 0.1
#: How often the graph is polled for the types of requested topics not yet seen (s).
DISCOVERY_PERIOD_S = 0.5
#: What decoding a String message's text may raise.
TEXT_ERRORS: tuple[type[Exception], ...] = (MalformedMessage, *DOCUMENT_ERRORS)
HISTORY = Range(1, 1_000_000, integer=True, unit="frames")

PARAMETERS: dict[str, NodeParameter] = {
    "topic_namespace": (topics.DEFAULT_NAMESPACE, "Namespace of the graph's topics."),
    "bridge_topics": (
        [],
        "Topics to forward (relative names under topic_namespace; [] = the graph's results, "
        "verdict, /diagnostics, run/collision, run/metadata and player/status).",
    ),
    "zenoh_mode": ("peer", "Zenoh session mode: peer or client."),
    "zenoh_listen": ([DEFAULT_ENDPOINT], "Zenoh endpoints to listen on (peer mode)."),
    "zenoh_connect": ([], "Zenoh endpoints to connect to (a router, or a peer)."),
    "zenoh_prefix": ("", "Key prefix of every sample ('' = none), e.g. the vehicle or run."),
    "zenoh_allow_remote": (
        False,
        "Allow endpoints on other interfaces than loopback (configure Zenoh TLS and access "
        "control then).",
    ),
    "rate_modules": (
        20.0,
        "Most JSON samples per second on each module's key (0 = every result; the newest "
        "pending one is sent when the interval ends, the frame history keeps them all).",
        RATE,
    ),
    "rate_raw": (
        0.0,
        "Most raw CDR samples per second per topic (0 = every message; latched topics such "
        "as the verdict are never limited).",
        RATE,
    ),
    "history_frames": (2000, "Frames kept for frames?since=N queries.", HISTORY),
    "heartbeat_s": (1.0, "Period of the status heartbeat (0 = none).", SECONDS),
    "run_id": ("", "Forward only this run's results and verdict ('' = any run)."),
    "exit_after_verdict": (False, "Exit (status 0) linger_s after forwarding the verdict."),
    "linger_s": (
        0.0,
        "With exit_after_verdict: keep answering queries this long (.inf: until stopped).",
        LINGER,
    ),
    "graph_wait_s": (
        0.0,
        "With run_id: be counted by the run's player only once the graph's outputs it "
        "bridges (monitor results, verdict, /diagnostics) each have a publisher, at most "
        "this long (0 = at once).",
        SECONDS,
    ),
}


def default_topics(namespace: str) -> dict[str, tuple[str, QoSProfile]]:
    """The graph's outputs and the player's run topics: full name → (type, reader QoS)."""
    out = {name: (kind, qos()) for name, (kind, qos) in live_topics.graph_topics(namespace).items()}
    out[topics.topic_name(live_topics.COLLISION, namespace)] = (
        "std_msgs/msg/String",
        live_topics.latched_qos(),
    )
    for key in (topics.METADATA, topics.STATUS):
        out[topics.topic_name(key, namespace)] = (
            rosmsg.type_name(topics.message_types()[key]),
            topics.qos_profile(key),
        )
    return out


class ZenohBridge(Node):
    """Raw subscriptions in, Zenoh samples out (see the module doc)."""

    def __init__(self) -> None:
        super().__init__("zenoh_bridge", parameter_overrides=command_line_overrides("zenoh_bridge"))
        p = declare_node_parameters(self, PARAMETERS)
        self.values = p
        ns = str(p["topic_namespace"])
        self.prefix = str(p["zenoh_prefix"])
        run_id = checked_run_id(str(p["run_id"]))
        state = RemoteState(
            self.prefix,
            int(p["history_frames"]),
            {"modules": float(p["rate_modules"])},
            run=run_id,
        )
        known = default_topics(ns)
        requested = [str(t) for t in p["bridge_topics"] or [] if str(t)]
        names = [topics.topic_name(t, ns) for t in requested] or list(known)
        self.raw_keys = {name: ros_key(name, self.prefix) for name in names}  # checks names
        self.json_topics = {topics.topic_name(live_topics.metrics_key(m), ns): m for m in MODULES}
        self.verdict_topic = topics.topic_name(live_topics.VERDICT_JSON, ns)
        latched = {
            self.raw_keys[n] for n, (_, q) in known.items() if n in self.raw_keys and _latched(q)
        }
        rate_raw = float(p["rate_raw"])
        self.raw_limiter: RateLimiter[tuple[bytes, str]] = RateLimiter(
            {key: rate_raw for key in self.raw_keys.values()}, frozenset(latched)
        )
        self.zenoh = ZenohPublisher(
            state,
            str(p["zenoh_mode"]),
            [str(e) for e in p["zenoh_listen"] or [] if str(e)],
            [str(e) for e in p["zenoh_connect"] or [] if str(e)],
            bool(p["zenoh_allow_remote"]),
        )
        self.exit_after_verdict = bool(p["exit_after_verdict"])
        self.linger_s = float(p["linger_s"])
        self.verdict_at: float | None = None
        #: The verdict went out and ``linger_s`` passed (with ``exit_after_verdict``).
        self.finished = False
        self.subs: dict[str, Any] = {}
        self.pending = {n: known[n] for n in names if n in known}
        self.unknown = [n for n in names if n not in known]
        for name, (msg_type, qos) in self.pending.items():
            self._subscribe(name, msg_type, qos)
        if self.unknown:
            self._discover()
            self.create_timer(DISCOVERY_PERIOD_S, self._discover)
        outputs = live_topics.graph_topics(ns)
        subscribe_ready_once_matched(
            self,
            ns,
            run_id,
            {name: sub for name, sub in self.subs.items() if name in outputs},
            float(p["graph_wait_s"]),
        )
        if run_id:  # a graph member: the player waits for our run/frame subscription too
            frame_type = rosmsg.message_class(
                rosmsg.type_name(topics.message_types()[topics.FRAME])
            )
            self.create_subscription(
                frame_type,
                topics.topic_name(topics.FRAME, ns),
                _ignore,
                topics.qos_profile(topics.FRAME),
                raw=True,
            )
        self.heartbeat_s = float(p["heartbeat_s"])
        self.next_heartbeat = time.monotonic()
        self.create_timer(FLUSH_PERIOD_S, self._tick)
        # Last: nothing after it may fail, or the open session would hang the exit.
        try:
            self.zenoh.open()
        except Exception as error:  # zenoh.ZError: the endpoint is taken, unreachable ...
            raise ConfigError(f"cannot open the Zenoh session: {error}") from None
        log_in_force(self, p)

    def _subscribe(self, name: str, msg_type: str, qos: QoSProfile) -> None:
        try:
            cls = rosmsg.message_class(rosmsg.normalise_type(msg_type))
        except (ImportError, AttributeError):
            self.get_logger().warning(f"{name}: type {msg_type} is not installed; not bridged")
            self.subs[name] = None
            return
        self.subs[name] = self.create_subscription(
            cls, name, self._callback(name, rosmsg.normalise_type(msg_type)), qos, raw=True
        )

    def _discover(self) -> None:
        """Subscribe to requested topics outside the graph's own once a publisher names
        their type."""
        for name, types in self.get_topic_names_and_types():
            if name in self.unknown and name not in self.subs and len(types) == 1:
                self._subscribe(name, types[0], offered_qos(self, name, depth=100))

    def _callback(self, name: str, msg_type: str) -> Any:
        key = self.raw_keys[name]
        module = self.json_topics.get(name)
        verdict = name == self.verdict_topic

        def on_message(data: bytes) -> None:
            now = time.monotonic()
            for out_key, (payload, kind) in self.raw_limiter.offer(key, (data, msg_type), now):
                self.zenoh.put_raw(out_key, payload, kind)
            if module is None and not verdict:
                return
            try:
                text = decode_string(data)
            except TEXT_ERRORS:
                text = "\x00"  # counted as malformed by the state, never forwarded
            if verdict:
                self.zenoh.on_verdict(text)
            else:
                self.zenoh.on_result(text)
            self._note_verdict(now)

        return on_message

    def _note_verdict(self, now: float) -> None:
        """When the verdict went out (it waits for the results it counts: RemoteState),
        said once: the graph's other nodes may stop then."""
        if self.zenoh.state.verdict is not None and self.verdict_at is None:
            self.verdict_at = now
            serving = ""
            if self.exit_after_verdict:
                serving = "; serving late dashboards " + (
                    "until stopped" if math.isinf(self.linger_s) else f"for {self.linger_s:g} s"
                )
            self.get_logger().info(BRIDGE_FORWARDED + serving)

    def _tick(self) -> None:
        now = time.monotonic()
        for key, (payload, kind) in self.raw_limiter.flush(now):
            self.zenoh.put_raw(key, payload, kind)
        heartbeat = self.heartbeat_s > 0 and now >= self.next_heartbeat
        if heartbeat:
            self.next_heartbeat = now + self.heartbeat_s
        self.zenoh.tick(heartbeat)
        self._note_verdict(now)
        if (
            self.exit_after_verdict
            and self.verdict_at is not None
            and now - self.verdict_at >= self.linger_s
        ):
            self.finished = True

    def close(self) -> None:
        """Everything pending and the final status out, then the session closed."""
        try:
            for key, (payload, kind) in self.raw_limiter.flush(time.monotonic(), force=True):
                self.zenoh.put_raw(key, payload, kind)
            self.zenoh.finish("stopped")  # a verdict is its own key: the bridge is gone
        finally:
            self.zenoh.close()
        state = self.zenoh.state
        self.get_logger().info(
            f"bridged {self.zenoh.raw_puts} CDR and {self.zenoh.puts} JSON samples; "
            f"{state.malformed} malformed, {state.other_runs} of other runs"
        )


def _ignore(data: bytes) -> None:
    """Frame markers are not bridged: the subscription only makes the player wait for us."""


def _latched(qos: QoSProfile) -> bool:
    return qos.durability == DurabilityPolicy.TRANSIENT_LOCAL and qos.depth == 1


def main(args: list[str] | None = None) -> int:
    return run_node("zenoh_bridge", ZenohBridge, args, (AdsRcaError,))


def entry() -> None:
    """The node as a program: it ends without finalizing the interpreter once its Zenoh
    session is closed (:mod:`ads_rca.foundation.quick_exit`)."""
    quick_exit.run_program(main)


if __name__ == "__main__":
    entry()
