"""Monitor nodes: each module's oracle judged live, frame by frame, on the player's topics.

``perception_monitor``, ``prediction_monitor``, ``planning_monitor`` and ``controller_monitor``
are this one class with a different module (node name = ``<module>_monitor``). A thin shell over
:class:`~ads_rca.live.window.MonitorCore`, which decides when a frame can be judged and
runs the engine's own oracles on it: the shell only decodes messages, calls it, and
publishes each result losslessly on ``metrics/<module>`` for the aggregator (and as labelled
numbers on ``metrics/<module>/values`` for plotting tools), and each judged batch's latest
frame on ``/diagnostics`` (status ``ads_rca/<module>``). A heartbeat
``ads_rca/<module>/monitor`` tells the aggregator the node is alive; ``ads_rca/<module>``
goes STALE when inputs stop (no message for ``stale_timeout_s`` before the player said
``finished``).

Subscriptions use the lossless QoS of the contract (RELIABLE + KEEP_ALL) so a player at rate
0 waits for us. Data that arrives before the (latched) metadata is queued (at most 64 MiB,
:mod:`ads_rca.live.early_queue`): converting a trajectory needs the frame period.

Three pieces: a :class:`Monitor` node per module (its publishers, heartbeat and STALE
status), a :class:`MonitorUnit` (one window, ``MonitorCore``, judging one or more modules,
and the nodes its results go to) and :class:`MonitorInputs` (the subscriptions of a process,
feeding its unit). A ``*_monitor`` process is one node, one unit, one set of inputs. The
``monitors`` executable runs the four nodes in one process on one unit: every message is
received and decoded once instead of four times (decoding was most of a monitor's work) and
a frame's four modules are judged on one context, sharing its caches as ``ads-rca
diagnose`` does. Results are the same either way (tested).
"""

from __future__ import annotations

import sys
import time
from dataclasses import replace
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from ads_rca.contract import live_topics, topics
from ads_rca.contract.assembler import run_metadata
from ads_rca.contract.cdr import encode_joint_state, encode_string
from ads_rca.contract.ego_paths import read_ego_path
from ads_rca.contract.errors import CdrError, MalformedMessage, NoStamp
from ads_rca.contract.jsontext import dumps_json
from ads_rca.contract.malformed import SkippedMessages
from ads_rca.contract.playback import (
    FINISHED,
    read_document,
    read_input_problems,
)
from ads_rca.errors import InputError
from ads_rca.live import diagnostics as diag
from ads_rca.live.early_queue import EarlyQueue
from ads_rca.live.numeric import NumericLayout
from ads_rca.live.results import FrameMarker, LiveResult
from ads_rca.live.runid import RUN_KEY, RunFilter, checked_run_id
from ads_rca.live.stack_config import STACK_PARAMETERS, StackConfig
from ads_rca.live.stack_guard import StackGuard
from ads_rca.live.window import MonitorCore, WindowSettings
from ads_rca.model import RunMetadata
from ads_rca.oracles.base import Module
from ads_rca.oracles.semantics import semantics_for
from ads_rca.paramspec import SECONDS, Range
from ads_rca.ros.diagnostics import array as diagnostic_array
from ads_rca.ros.graph import GROUP, MONITORS
from ads_rca.ros.nodemain import run_node, subscribe_ready, wait_for_acks
from ads_rca.ros.nodeparams import (
    NodeParameter,
    command_line_overrides,
    declare_engine_parameters,
    declare_node_parameters,
    log_in_force,
)
from ads_rca.ros.stack_subscriber import StackSubscriber, listen_for_collisions

#: Longest a stopping monitor waits for its subscribers to acknowledge its last results.
CLOSE_FLUSH_S = 3.0

PARAMETERS: dict[str, NodeParameter] = {
    "topic_namespace": (topics.DEFAULT_NAMESPACE, "Namespace of the contract topics."),
    "hardware_id": ("ads_rca", "hardware_id of the diagnostic statuses."),
    "stale_timeout_s": (2.0, "STALE on /diagnostics after this long without input.", SECONDS),
    "input_timeout_s": (5.0, "Judge with what arrived after this long without input.", SECONDS),
    "heartbeat_s": (0.5, "Period of the monitor heartbeat status.", Range(0.01, 60.0, unit="s")),
    "poll_period_s": (
        0.02,
        "Judge ready frames at least this often; a frame marker judges at once unless the "
        "last judgement is more recent (so a backlog is judged in batches).",
        Range(0.001, 10.0, unit="s"),
    ),
    "max_lookahead_frames": (
        100,
        "Longest look-ahead waited for (reference prediction keys).",
        Range(0, 100_000, integer=True, unit="frames"),
    ),
    "max_pending_frames": (
        1200,
        "Frames held at most before judging anyway (marked).",
        Range(1, 1_000_000, integer=True, unit="frames"),
    ),
    "history_frames": (
        0,
        "Judged frames kept for a late collision (0 = automatic).",
        Range(0, 1_000_000, integer=True, unit="frames"),
    ),
    "publish_diagnostics": (
        True,
        "Publish on /diagnostics one status per judged batch: its latest frame, with the "
        "counts judged and failed since the previous status.",
    ),
    "run_id": ("", "Judge only this run ('' = the first run heard of); see ads_rca.live.runid."),
}


class Monitor(Node):
    """One module's node: declares the parameters, publishes its results and heartbeat."""

    def __init__(self, node_name: str, module: Module) -> None:
        super().__init__(node_name, parameter_overrides=command_line_overrides(node_name))
        self.module = module
        self.params = declare_engine_parameters(self)
        p = declare_node_parameters(self, {**PARAMETERS, **STACK_PARAMETERS}, self.params)
        self.hardware_id = str(p["hardware_id"])
        self.stale_timeout = float(p["stale_timeout_s"])
        self.publish_diagnostics = bool(p["publish_diagnostics"])
        self.namespace = str(p["topic_namespace"])
        self.run_id = checked_run_id(str(p["run_id"]))
        self.poll_period = float(p["poll_period_s"])
        self.settings = WindowSettings(
            max_lookahead_frames=int(p["max_lookahead_frames"]),
            input_timeout_s=float(p["input_timeout_s"]),
            max_pending_frames=int(p["max_pending_frames"]),
            history_frames=int(p["history_frames"]),
        )
        self.stack_config = StackConfig.from_values(
            p,
            self.namespace,
            self.settings.input_timeout_s,
            self.settings.max_pending_frames,
        )
        #: Stack mode's inputs the stack does not provide that this module reads.
        self.unprovided = tuple(
            f
            for f in semantics_for(self.params).folders(module)
            if f in self.stack_config.not_provided
        )
        self.core: MonitorCore | None = None  # set by the unit that judges this module
        #: Stack mode: what was refused on the stack's inputs (set by its subscriber).
        self.guard: StackGuard | None = None
        self.skipped = SkippedMessages()  # shared with the unit's inputs
        self._stale_since_report = False
        self.started = time.monotonic()
        self.metrics_pub = self.create_publisher(
            String,
            topics.topic_name(live_topics.metrics_key(module), self.namespace),
            live_topics.metrics_qos(),
        )
        self.values_pub = self.create_publisher(
            JointState,
            topics.topic_name(live_topics.values_key(module), self.namespace),
            live_topics.metrics_qos(),
        )
        headline = semantics_for(self.params).headline.get(module, ())
        self.layout = NumericLayout([key for entry in headline for key in entry.keys])
        self.diag_pub = self.create_publisher(
            DiagnosticArray, live_topics.DIAGNOSTICS, live_topics.diagnostics_qos()
        )
        self.create_timer(float(p["heartbeat_s"]), self._heartbeat)
        log_in_force(self, p, self.params)

    def close(self) -> None:
        """Before the node goes (run_node calls this): every subscriber has the results
        published, at most :data:`CLOSE_FLUSH_S` (a second stop signal ends the wait).
        Samples not yet acknowledged go with their publisher: in CI a recorder stopped just
        after this monitor lacked a replay's last 13 planning ``values``."""
        wait_for_acks([self.metrics_pub, self.values_pub], CLOSE_FLUSH_S, signals_allowed=1)

    def publish(self, results: list[LiveResult]) -> None:
        """Each result on the metrics topic (JSON) and its ``values`` topic (numbers); the
        batch as one status on ``/diagnostics``.

        CDR bytes straight from our encoders: rclpy message objects cost more than judging.
        Diagnostics tools key statuses by name, so the batch is one status (its latest
        frame, :func:`~ads_rca.ros.diagnostics.batch_status`), not one per frame.
        """
        for result in results:
            self.metrics_pub.publish(encode_string(dumps_json(result.to_document())))
            row = self.layout.row(result)
            self.values_pub.publish(encode_joint_state(result.stamp_ms, self.layout.labels, row))
        if self.publish_diagnostics and results:
            status = diag.batch_status(results, self.params.semantics, self.hardware_id)
            status = self._stale_if_inputs_missing(status, results[-1])
            self.diag_pub.publish(diag.encode_array(self.get_clock().now().nanoseconds, [status]))

    def _stale_if_inputs_missing(self, status: diag.Status, latest: LiveResult) -> diag.Status:
        """Stack mode: a frame judged without an input this module reads is STALE, with the
        inputs named (a stack that stopped publishing one is never OK)."""
        core = self.core
        if core is None or not core.stack:
            return status
        reads = set(semantics_for(self.params).folders(self.module))
        missing = [f for f in latest.missing_folders if f in reads]
        if not missing:
            return status
        text = f"frame {latest.frame}: not judged on full inputs: no {', '.join(missing)} input"
        return replace(status, level=diag.STALE, message=text)

    def _heartbeat(self) -> None:
        core = self.core
        if core is None:
            return
        now = time.monotonic()
        last = core.last_input if core.last_input is not None else self.started
        silent = now - last
        # Stack mode: never OK while the stack's inputs are refused or its frames lost.
        level, refused, counts = (
            self.guard.report(now) if self.guard is not None else (diag.OK, "", {})
        )
        statuses = [
            diag.simple_status(
                diag.heartbeat_name(self.module),
                level,
                f"judged {core.stats.evaluated}, pending {len(core.pending)}"
                + (f"; {refused}" if refused else ""),
                self.hardware_id,
                {
                    RUN_KEY: core.run,
                    "session": core.session,
                    "judged": core.stats.evaluated,
                    "incomplete": core.stats.incomplete,
                    "pending": len(core.pending),
                    "held_records": core.held_records(),
                    "finished": core.finished,
                    "skipped_messages": self.skipped.total,
                    **({"episode": core.episode} if core.stack else {}),
                    **counts,
                },
            )
        ]
        if core.stack and self.unprovided:
            statuses.append(
                diag.simple_status(
                    diag.status_name(self.module),
                    diag.STALE,
                    "not judged on full inputs: the stack provides no "
                    + ", ".join(self.unprovided),
                    self.hardware_id,
                    {"not_provided": ", ".join(self.unprovided)},
                )
            )
        elif silent >= self.stale_timeout and not core.finished:
            statuses.append(
                diag.simple_status(
                    diag.status_name(self.module),
                    diag.STALE,
                    f"no input for {silent:.1f} s",
                    self.hardware_id,
                    {
                        "silent_s": round(silent, 3),
                        "pending": len(core.pending),
                        RUN_KEY: core.run,
                    },
                )
            )
            if not self._stale_since_report:
                self.get_logger().warning(f"inputs stale: nothing for {silent:.1f} s")
            self._stale_since_report = True
        else:
            self._stale_since_report = False
        self.diag_pub.publish(diagnostic_array(self.get_clock().now().to_msg(), statuses))


class MonitorUnit:
    """One window judging the modules of ``nodes``; results go to each module's node.

    Judging has a fixed cost per batch (the window's view and context), so :meth:`on_marker`
    judges at once only if the last judgement is at least ``poll_period_s`` old; otherwise
    the ``poll_period_s`` timer judges everything that became ready in one batch.
    """

    def __init__(self, nodes: list[Monitor], stack: bool = False) -> None:
        first = nodes[0]
        for node in nodes[1:]:
            _check_same_settings(first, node)
        self.nodes = {node.module: node for node in nodes}
        self.core = MonitorCore(tuple(self.nodes), first.params, first.settings, stack=stack)
        self.skipped = SkippedMessages()
        for node in nodes:
            node.core = self.core
            node.skipped = self.skipped
        self.logger = first.get_logger()
        self.logged_errors: set[Module] = set()  # modules whose traceback was logged
        self.poll_period = first.poll_period
        self.last_poll = 0.0
        first.create_timer(self.poll_period, self.poll)
        modules = ", ".join(self.core.modules)
        self.logger.info(
            f"judging {modules}, semantics {first.params.semantics}, session {self.core.session}"
        )

    def poll(self) -> None:
        """Publish the results of every frame that became ready, then the collision warning
        of the frames that came in (before any collision: docs/live-graph.md)."""
        self.last_poll = now = time.monotonic()
        deciding, later = self.core.poll_in_order(now)
        self.publish(deciding)  # what the verdict waits for, first
        self.publish(later)
        planning = self.nodes.get("planning")
        said = planning is not None and planning.publish_diagnostics
        if not (said or self.core.stack):
            return
        warnings = self.core.collision_warnings()  # stack mode: the threat judged ahead
        if planning is not None and said:
            threshold = planning.params.event_ttc_s
            warning = diag.collision_warning(
                warnings, threshold, planning.hardware_id, self.core.run
            )
            if warning is not None:
                stamp = planning.get_clock().now().nanoseconds
                planning.diag_pub.publish(diag.encode_array(stamp, [warning]))
        self.core.prepare()  # stack mode, a collision warned of: judge ahead against it

    def publish(self, results: list[LiveResult]) -> None:
        """Each module's results on its node (one /diagnostics status per module)."""
        by_module: dict[Module, list[LiveResult]] = {}
        for result in results:
            by_module.setdefault(result.module, []).append(result)
        for module, batch in by_module.items():
            self.nodes[module].publish(batch)
        self._log_internal_errors()

    def _log_internal_errors(self) -> None:
        """Each module whose oracle raised: its first traceback, once, on its node's log (a
        bug in ads_rca; its results and /diagnostics name the error at every frame)."""
        for module, text in self.core.tracebacks.items():
            if module not in self.logged_errors:
                self.logged_errors.add(module)
                self.nodes[module].get_logger().error(
                    f"{diag.internal_error_head(module)}; this is a bug in ads_rca, not in the "
                    f"input: please report it with this traceback:\n{text.rstrip()}"
                )

    def use_core(self, core: MonitorCore) -> None:
        """Judge ``core`` from now on (stack mode: a new episode's window)."""
        self.core = core
        for node in self.nodes.values():
            node.core = core

    def on_marker(self, now: float) -> None:
        if now - self.last_poll >= self.poll_period:
            self.poll()


def _check_same_settings(first: Monitor, other: Monitor) -> None:
    """Nodes judged on one window must agree on every engine and window parameter."""
    differ = [
        name
        for name in ("params", "settings", "namespace", "poll_period", "run_id", "stack_config")
        if getattr(first, name) != getattr(other, name)
    ]
    if differ:
        raise InputError(
            f"{first.get_name()} and {other.get_name()} share one window in this process but "
            f"their parameters differ ({', '.join(differ)}); give both the same values or run "
            "one process per monitor"
        )


class MonitorInputs:
    """The contract subscriptions of one process, feeding its monitor unit.

    Subscribes (on ``node``) to the topics the unit's modules read and decodes each data
    message once into a model record; markers, metadata, the player's status and a live
    collision are handed over as they come. Messages of another run are dropped
    (:class:`~ads_rca.live.runid.RunFilter`: the run field of JSON messages, the writer's
    participant for data), so callbacks take the MessageInfo too. A message that cannot be
    read (bytes that are not its type, JSON that is not a document of the contract) is
    skipped and said (:class:`~ads_rca.contract.malformed.SkippedMessages`); a data message is
    only decoded once its writer is known to be the run's player.
    """

    def __init__(self, node: Node, unit: MonitorUnit) -> None:
        self.node = node
        self.unit = unit
        core = unit.core
        self._queued: EarlyQueue[Any] = EarlyQueue()
        self._metadata: RunMetadata | None = None
        first = next(iter(unit.nodes.values()))
        self.runs = RunFilter(first.run_id)
        core.run = first.run_id
        self._greeted = False  # "judging run" said on the run's first accepted message
        lossless = [k for k, f in topics.TOPIC_FOLDERS.items() if f in core.folders]
        namespace = self.node_namespace = first.namespace
        # Data topics arrive as CDR bytes and are decoded straight into model records
        # (ads_rca.contract.cdr_decode): building rclpy message objects costs ~10 ms a frame.
        self.subscriptions: list[Any] = []
        paths = (topics.EGO_PATHS,) if core.wants_paths else ()
        for key in (*lossless, topics.FRAME, topics.METADATA, topics.STATUS, *paths):
            sub = node.create_subscription(
                topics.message_types()[key],
                topics.topic_name(key, namespace),
                self._callback(key),
                topics.qos_profile(key, keep_all=True),
                raw=key in lossless,
            )
            self.subscriptions.append(sub)
        self.subscriptions.extend(
            listen_for_collisions(
                node,
                unit,
                namespace,
                self.runs,
                lambda key, error: self._skip(key, error, time.monotonic()),
            )
        )
        subscribe_ready(node, namespace, first.run_id)

    @property
    def has_metadata(self) -> bool:
        return self._metadata is not None

    def stop(self) -> None:
        """Unsubscribe and forget what was queued (stack mode took over)."""
        for sub in self.subscriptions:
            self.node.destroy_subscription(sub)
        self.subscriptions.clear()
        self._queued.drain()

    def _callback(self, key: str) -> Any:
        core = self.unit.core
        player = key in topics.TEXT_TOPICS

        def on_message(msg: Any, info: Any) -> None:
            now = time.monotonic()
            if player:
                try:
                    document = read_document(msg)
                except MalformedMessage as error:
                    self._skip(key, error, now)
                    return
                # Anyone on the run may send a row's paths (a live model): not the player.
                if not self._ours(document, info, player=key != topics.EGO_PATHS):
                    return
                if key == topics.METADATA:
                    self._on_metadata(document, now)
                elif key == topics.FRAME:
                    try:
                        marker = FrameMarker.from_document(document)
                    except MalformedMessage as error:
                        self._skip(key, error, now)
                        return
                    core.add_marker(marker, now)
                    self.unit.on_marker(now)
                elif key == topics.EGO_PATHS:
                    try:  # refused by the reader, or by the rows' bounds (live.row_paths)
                        core.add_ego_path(read_ego_path(document), now)
                    except MalformedMessage as error:
                        self._skip(key, error, now)
                elif document.get("state") == FINISHED:
                    core.set_finished(now, _count(document.get("frames_published")))
            elif self._metadata is None:
                if self._queued.add(key, msg, info, now):
                    self._skip(key, self._queued.overflow_reason(), now)
            elif self.runs.accept_data(info):
                self._add_data(key, msg, now)

        return on_message

    def _ours(self, document: dict[str, Any], info: Any, player: bool = True) -> bool:
        """A message of our run (the first one locks the run; the first of the ``player``'s
        its participant)."""
        if not self.runs.accept(document, info, player=player):
            return False
        if not self._greeted and self.runs.run is not None:
            self._greeted = True
            self.unit.core.run = self.runs.run
            self.node.get_logger().info(f"judging run {self.runs.run}")
        return True

    def _on_metadata(self, document: dict[str, Any], now: float) -> None:
        try:
            metadata = run_metadata(document)
        except MalformedMessage as error:
            self.node.get_logger().error(str(error))
            return
        self._metadata = metadata
        self.unit.core.set_metadata(metadata, now, read_input_problems(document))
        for key, data, info, arrived in self._queued.drain():
            if self.runs.accept_data(info):
                self._add_data(key, data, arrived)

    def _add_data(self, key: str, data: bytes, now: float) -> None:
        assert self._metadata is not None
        try:
            stamp = topics.stamp_ms(key, data)
            record = topics.decode_record(key, data, self._metadata.timesteps_per_frame)
        except NoStamp:  # a MarkerArray without markers carries no stamp
            return
        except CdrError as error:
            self._skip(key, error, now)
            return
        self.unit.core.add_record(topics.TOPIC_FOLDERS[key], stamp, record, now)

    def _skip(self, key: str, error: object, now: float) -> None:
        """A message that cannot be read: counted, and said (at most every few seconds)."""
        name = topics.topic_name(key, self.node_namespace)
        line = self.unit.skipped.note(name, error, now)
        if line is not None:
            self.node.get_logger().warning(line)


class AutoStack:
    """``stack_mode`` auto: the player's inputs and, kept aside, the stack's, until a message
    of the frame-defining input arrives: while nobody publishes ``run/metadata`` it makes
    this a stack's run (stack mode for good, with what was kept); once the player's
    metadata is in, the stack's subscriptions go.

    Why a message and not a delay: a player's metadata writer is discovered with its data
    writers (one participant), so a reference message with no metadata publisher known is a
    stack's, however slow discovery is.
    """

    def __init__(self, node: Node, unit: MonitorUnit, inputs: MonitorInputs) -> None:
        self.node, self.unit, self.inputs = node, unit, inputs
        first = next(iter(unit.nodes.values()))
        self.metadata_topic = topics.topic_name(topics.METADATA, first.namespace)
        self.stack = StackSubscriber(node, unit, first.stack_config, decide=self._decide)

    def _decide(self) -> bool:
        if self.inputs.has_metadata:  # a player's run
            self.stack.close()
            return False
        if self.node.count_publishers(self.metadata_topic) > 0:
            return False
        self.node.get_logger().info(
            f"no player on the graph (nobody publishes {self.metadata_topic}): stack mode"
        )
        self.inputs.stop()
        self.unit.core.stack = self.unit.core.judge_without_collision = True
        return True


def build_monitors(names: list[str]) -> list[Node]:
    """The monitor nodes ``names`` on one window, with the inputs of this process: the
    player's, the stack's (``stack_mode`` on) or the player's until a stack shows (auto)."""
    nodes = [Monitor(name, MONITORS[name]) for name in names]
    mode = nodes[0].stack_config.mode
    unit = MonitorUnit(nodes, stack=mode == "stack")
    if mode == "stack":
        StackSubscriber(nodes[0], unit, nodes[0].stack_config)
        return list(nodes)
    inputs = MonitorInputs(nodes[0], unit)
    if mode == "auto":
        AutoStack(nodes[0], unit, inputs)
    return list(nodes)


def _count(value: object) -> int | None:
    return value if isinstance(value, int) else None


def run(node_name: str, args: list[str] | None = None) -> int:
    return run_node(node_name, lambda: build_monitors([node_name]), args, message_info=True)


def perception_main(args: list[str] | None = None) -> int:
    return run("perception_monitor", args)


def prediction_main(args: list[str] | None = None) -> int:
    return run("prediction_monitor", args)


def planning_main(args: list[str] | None = None) -> int:
    return run("planning_monitor", args)


def controller_main(args: list[str] | None = None) -> int:
    return run("controller_monitor", args)


def group_main(args: list[str] | None = None) -> int:
    """``monitors``: all four monitor nodes in one process (inputs decoded once)."""
    return run_node(GROUP, lambda: build_monitors(list(MONITORS)), args, message_info=True)


if __name__ == "__main__":
    # python -m ads_rca.ros.monitor {<node_name>|monitors} [--ros-args ...]
    name = sys.argv[1] if len(sys.argv) > 1 else ""
    if name == GROUP:
        sys.exit(group_main([sys.argv[0], *sys.argv[2:]]))
    if name not in MONITORS:
        names = ",".join([*MONITORS, GROUP])
        print(f"usage: python -m ads_rca.ros.monitor {{{names}}} [--ros-args ...]")
        sys.exit(2)
    sys.exit(run(name, [sys.argv[0], *sys.argv[2:]]))
