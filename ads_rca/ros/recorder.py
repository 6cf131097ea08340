"""``recorder`` node: records the contract topics (and more) into a rosbag2 MCAP bag.

``ros2 bag record`` is not available here, and the replay/demo graphs need a recording that
survives a crash of the stack. A thin shell over
:class:`ads_rca.sources.bag.mcap_writer.McapBagWriter`:
raw subscriptions hand the serialised bytes straight to the writer (no deserialisation,
log time = reception time, publish time = the sender's timestamp), with lossless QoS
(RELIABLE + KEEP_ALL, latched topics TRANSIENT_LOCAL) so a player at rate 0 waits for us.

Which topics: ``topics`` (names; relative ones are under ``topic_namespace``), or by default
every contract topic, the graph's own outputs (monitor metrics, verdicts, ``/diagnostics``:
subscribed from the start, so a short run's results are not over before discovery finds
them) and anything else published under the namespace, found by polling the graph.
SIGINT/SIGTERM stop the node, drain what DDS already delivered and finalise the bag
(summary + metadata.yaml); a SIGKILL loses at most the chunk being filled (``chunk_size``
bytes or ``flush_period_s`` seconds). With ``stop_on_finished`` the node also stops by
itself once the player said ``finished`` and every message its frame markers announced is
in the bag.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Any

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.logging import get_logger
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message
from std_msgs.msg import String

from ads_rca.contract import live_topics, rosmsg, topics
from ads_rca.contract.assembler import RunLogAssembler
from ads_rca.contract.errors import UnknownMessageType
from ads_rca.contract.jsontext import loads_json
from ads_rca.errors import AdsRcaError, ConfigError
from ads_rca.live.diagnostics import status_runs
from ads_rca.live.runid import checked_run_id, document_run, writer_prefix
from ads_rca.paramspec import SECONDS, Range
from ads_rca.ros.env import ros_distro
from ads_rca.ros.nodemain import (
    ignore_stop_signals,
    keep_running,
    start_process,
    stop_requested,
    subscribe_ready_once_matched,
)
from ads_rca.ros.nodeparams import (
    NodeParameter,
    command_line_overrides,
    declare_node_parameters,
    log_in_force,
)
from ads_rca.ros.qos_match import offered_qos
from ads_rca.sources.bag.mcap_writer import (
    COMPRESSIONS,
    DEFAULT_CHUNK_SIZE,
    McapBagWriter,
    qos_yaml,
)
from ads_rca.sources.bag.writer import contract_qos_yaml

PARAMETERS: dict[str, NodeParameter] = {
    "output": ("", "Bag directory to create (required; must be new or empty)."),
    "topics": ([], "Topics to record ([] = contract + /diagnostics + namespace topics)."),
    "topic_namespace": (topics.DEFAULT_NAMESPACE, "Namespace of the contract topics."),
    "discover": (True, "Poll the graph for more topics to record (default topic set)."),
    "compression": ("zstd", "Chunk compression: zstd, lz4 or none."),
    "chunk_size": (
        DEFAULT_CHUNK_SIZE,
        "Bytes per chunk; each full chunk goes to disk.",
        Range(1024, 1 << 30, integer=True, unit="bytes"),
    ),
    "flush_period_s": (
        1.0,
        "Also end the current chunk this often (0 = only when full).",
        SECONDS,
    ),
    "stop_on_finished": (False, "Stop once the player finished and all it announced is in."),
    "max_duration_s": (
        0.0,
        "Stop after this many seconds (0 = never).",
        Range(0.0, 604_800.0, unit="s"),
    ),
    "run_id": ("", "Record only this run ('' = everything); see ads_rca.live.runid."),
    "graph_wait_s": (
        0.0,
        "With run_id: be counted by the run's player only once the graph's outputs "
        "(monitor results, verdict, /diagnostics) each have a publisher, at most this long "
        "(0 = at once).",
        SECONDS,
    ),
}
_IGNORED = {"/rosout", "/parameter_events"}
_STRING_TYPE = "std_msgs/msg/String"
_DIAGNOSTICS_TYPE = "diagnostic_msgs/msg/DiagnosticArray"
#: Messages held at most while their sender's run is not known yet (then: not recorded).
MAX_HELD = 100_000


class RunMembership:
    """Which senders belong to the run being recorded (``run_id``), learnt per participant.

    A participant is ours once one of its messages names our run (the ``run`` field of a
    JSON String, ``live.run`` of a verdict, the ``run`` key of a diagnostic status) and
    foreign once one names another. Until then its messages are held, in order, and
    written when it turns out ours (so the bag keeps every message of the run, log times
    unchanged); held messages of a participant never identified are not recorded. Where
    the rmw gives no participant prefix, each message is judged on its own.
    """

    def __init__(self, run_id: str) -> None:
        self.run = run_id
        self.ours: set[bytes] = set()
        self.foreign: set[bytes] = set()
        self.held: dict[bytes, list[tuple[Any, ...]]] = {}
        self.held_count = 0
        self.skipped = 0

    def sort(self, msg_type: str, data: bytes, info: Any, item: tuple[Any, ...]) -> list[Any]:
        """The messages to write now (``item`` and any held ones it releases)."""
        prefix = writer_prefix(info)
        if prefix is not None and prefix in self.ours:
            return [item]
        if prefix is not None and prefix in self.foreign:
            self.skipped += 1
            return []
        run = _named_run(msg_type, data)
        if run is None:
            if prefix is None:
                return [item]
            if self.held_count >= MAX_HELD:
                self.skipped += 1
                return []
            self.held.setdefault(prefix, []).append(item)
            self.held_count += 1
            return []
        released = self.held.pop(prefix, []) if prefix is not None else []
        self.held_count -= len(released)
        if run != self.run:
            if prefix is not None:
                self.foreign.add(prefix)
            self.skipped += 1 + len(released)
            return []
        if prefix is not None:
            self.ours.add(prefix)
        return [*released, item]


def _named_run(msg_type: str, data: bytes) -> str | None:
    """The run a String (JSON) or DiagnosticArray message names, if any."""
    if msg_type == _DIAGNOSTICS_TYPE:
        return next((run for _name, run in status_runs(data) if run), None)
    if msg_type != _STRING_TYPE:
        return None
    try:
        document = loads_json(deserialize_message(data, String).data)
    except (ValueError, TypeError):
        return None
    if not isinstance(document, dict):
        return None
    live = document.get("live")
    return document_run(document) or (document_run(live) if isinstance(live, dict) else None)


def _duration(nanoseconds: int) -> dict[str, int]:
    sec, nsec = divmod(int(nanoseconds), 10**9)
    return {"sec": sec, "nsec": nsec}


def _offered_qos(info: list[Any]) -> str:
    """rosbag2 YAML of the publishers' QoS profiles."""
    profiles = [
        {
            "history": "keep_all" if p.history == HistoryPolicy.KEEP_ALL else "keep_last",
            "depth": int(p.depth),
            "reliability": "reliable"
            if p.reliability == ReliabilityPolicy.RELIABLE
            else "best_effort",
            "durability": "transient_local"
            if p.durability == DurabilityPolicy.TRANSIENT_LOCAL
            else "volatile",
            **{
                name: _duration(getattr(p, name).nanoseconds)
                for name in ("deadline", "lifespan", "liveliness_lease_duration")
            },
            "liveliness": "automatic",
            "avoid_ros_namespace_conventions": False,
        }
        for p in (endpoint.qos_profile for endpoint in info)
    ]
    return qos_yaml(profiles)


class Recorder(Node):
    """Subscribes (raw) to the topics to record and writes every message to the bag."""

    def __init__(self) -> None:
        super().__init__("recorder", parameter_overrides=command_line_overrides("recorder"))
        self._values = declare_node_parameters(self, PARAMETERS)
        output = str(self._param("output"))
        if not output:
            raise ConfigError("parameter output is required (a bag directory to create)")
        out = Path(output)
        if out.exists() and (not out.is_dir() or any(out.iterdir())):
            raise ConfigError(f"{output}: exists and is not an empty directory")
        compression = str(self._param("compression"))
        if compression not in COMPRESSIONS:
            raise ConfigError(f"compression must be one of {sorted(COMPRESSIONS)}")
        self.namespace = str(self._param("topic_namespace"))
        self.names = topics.topic_names(self.namespace)
        self.keys = {name: key for key, name in self.names.items()}
        requested = [str(t) for t in self._param("topics") or [] if str(t)]
        self.explicit = {topics.topic_name(t, self.namespace) for t in requested}
        self.discover = bool(self._param("discover"))
        self.stop_on_finished = bool(self._param("stop_on_finished"))
        self.max_duration = float(self._param("max_duration_s"))
        self.writer = McapBagWriter(
            out,
            chunk_size=int(self._param("chunk_size")),
            compression=compression,
            ros_distro=ros_distro(),
        )
        self.writer.set_custom_data("recorded_by", "ads_rca recorder")
        self.progress = RunLogAssembler()  # only counts and the String topics
        run_id = checked_run_id(str(self._param("run_id")))
        self.membership = RunMembership(run_id) if run_id else None
        self.subs: dict[str, Any] = {}
        self.started = time.monotonic()
        for key, name in self.names.items():
            if not self.explicit or name in self.explicit:
                self._subscribe(name, rosmsg.type_name(topics.message_types()[key]))
        self.graph_qos: dict[str, QoSProfile] = {}
        for name, (msg_type, qos) in live_topics.graph_topics(self.namespace).items():
            if name in self.explicit if self.explicit else self.discover:
                self.graph_qos[name] = qos()
                self._subscribe(name, msg_type)
        outputs = {name: self.subs[name] for name in self.graph_qos}
        wait = float(self._param("graph_wait_s"))
        subscribe_ready_once_matched(self, self.namespace, run_id, outputs, wait)
        if self.discover or self.explicit - set(self.subs):
            self._discover()
            self.create_timer(0.5, self._discover)
        period = float(self._param("flush_period_s"))
        if period > 0:
            self.create_timer(period, self.writer.flush)
        self.get_logger().info(f"recording {len(self.subs)} topics to {out}")
        log_in_force(self, self._values)

    def _param(self, name: str) -> Any:
        return self._values[name]

    # --- topics -------------------------------------------------------------------------

    def _wanted(self, name: str) -> bool:
        if name in self.subs or name in _IGNORED:
            return False
        if f"/{live_topics.READY_PREFIX}" in name:
            return False  # another run's ready topic: subscribing would count as its node
        if self.explicit:
            return name in self.explicit
        prefix = topics.normalise_namespace(self.namespace) + "/"
        outside = name in (live_topics.DIAGNOSTICS, topics.TF_STATIC)
        return self.discover and (outside or name.startswith(prefix))

    def _discover(self) -> None:
        for name, types in self.get_topic_names_and_types():
            if self._wanted(name) and len(types) == 1:
                self._subscribe(name, types[0])

    def _qos(self, name: str) -> QoSProfile:
        key = self.keys.get(name)
        if key is not None:
            return topics.qos_profile(key, keep_all=True)
        if name in self.graph_qos:
            return self.graph_qos[name]
        return offered_qos(self, name, keep_all=True)

    def _subscribe(self, name: str, msg_type: str) -> None:
        msg_type = rosmsg.normalise_type(msg_type)
        try:
            cls = rosmsg.message_class(msg_type)
        except (ImportError, AttributeError):
            self.get_logger().warning(f"{name}: type {msg_type} is not installed; not recorded")
            self.subs[name] = None
            return
        self.subs[name] = self.create_subscription(
            cls, name, self._callback(name, msg_type), self._qos(name), raw=True
        )

    def _register(self, name: str, msg_type: str) -> None:
        key = self.keys.get(name)
        info = self.get_publishers_info_by_topic(name)
        offered = _offered_qos(info) if info else (contract_qos_yaml(key) if key else "")
        try:
            self.writer.add_topic(name, msg_type, offered)
        except UnknownMessageType:  # no definition installed: still record, schema-less text
            self.writer.add_topic(name, msg_type, offered, topic_type_hash="", definition="")

    def _callback(self, name: str, msg_type: str) -> Any:
        def on_message(data: bytes, info: Any) -> None:
            received = int(info["received_timestamp"]) or time.time_ns()
            source = int(info["source_timestamp"]) or received
            item = (name, msg_type, data, received, source)
            if self.membership is None:
                self._record(*item)
                return
            for held in self.membership.sort(msg_type, data, info, item):
                self._record(*held)

        return on_message

    def _record(self, name: str, msg_type: str, data: bytes, received: int, source: int) -> None:
        if not self.writer.has_topic(name):
            self._register(name, msg_type)
        self.writer.write(name, received, data, publish_time_ns=source)
        key = self.keys.get(name)
        if key is None:
            return
        if key in topics.TEXT_TOPICS:
            self.progress.add(key, deserialize_message(data, String))
        else:
            self.progress.received[key] += 1

    # --- stopping -----------------------------------------------------------------------

    def done(self) -> bool:
        if self.max_duration > 0 and time.monotonic() - self.started > self.max_duration:
            return True
        return self.stop_on_finished and self.progress.complete()

    def summary(self) -> str:
        counts = self.writer.counts()
        rows = ", ".join(f"{name}: {n}" for name, n in sorted(counts.items()))
        text = f"{self.writer.message_count} messages in {self.writer.path} ({rows})"
        runs = self.membership
        if runs is not None and (runs.skipped or runs.held_count):
            text += (
                f"; not recorded: {runs.skipped} messages of other runs, {runs.held_count} "
                "from senders that never named a run"
            )
        return text


def _drain(executor: SingleThreadedExecutor, node: Recorder) -> None:
    """Take what DDS already delivered (until 0.3 s pass with nothing new, at most 3 s;
    a second stop signal ends it at once)."""
    deadline = time.monotonic() + 3.0
    quiet_since = time.monotonic()
    count = node.writer.message_count
    while time.monotonic() < deadline and time.monotonic() - quiet_since < 0.3:
        if stop_requested() > 1:
            return
        executor.spin_once(timeout_sec=0.05)
        if node.writer.message_count != count:
            count = node.writer.message_count
            quiet_since = time.monotonic()


def main(args: list[str] | None = None) -> int:
    # A stop signal only sets a flag (nodemain): rclpy's handlers would shut the context
    # down at once, losing samples DDS already holds for us; the loop drains them first.
    if not start_process("recorder", args):
        return 2
    node: Recorder | None = None
    try:
        try:
            node = Recorder()
        except AdsRcaError as error:  # a parameter or the output folder cannot be used
            get_logger("recorder").error(str(error))
            return 2
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        while keep_running() and not node.done():
            executor.spin_once(timeout_sec=0.1)
        _drain(executor, node)
        return 0
    except (KeyboardInterrupt, ExternalShutdownException):
        return 0
    finally:
        if node is not None:
            node.writer.close()
            print(node.summary(), flush=True)
            node.destroy_node()
        rclpy.try_shutdown()
        ignore_stop_signals()


if __name__ == "__main__":
    sys.exit(main())
