"""Monitor nodes: one module's oracle judged live, frame by frame, on the player's topics.

``perception_monitor``, ``prediction_monitor``, ``planning_monitor`` and ``control_monitor``
are this one class with a different module. A thin shell over
:class:`~ads_rca.live.window.MonitorCore`, which decides when a frame can be judged and
runs the engine's own oracle on it: this node only converts messages, calls it, and
publishes each result on ``/diagnostics`` (status ``ads_rca/<module>``) and, losslessly, on
``metrics/<module>`` for the aggregator. A heartbeat ``ads_rca/<module>/monitor`` tells the
aggregator the node is alive; ``ads_rca/<module>`` goes STALE when inputs stop (no message
for ``stale_timeout_s`` before the player said ``finished``).

Subscriptions use the lossless QoS of the contract (RELIABLE + KEEP_ALL) so a player at rate
0 waits for us. Data that arrives before the (latched) metadata is queued: converting a
trajectory needs the frame period.

Inputs live in :class:`MonitorInputs`, which subscribes once and feeds one or more monitors:
each monitor process has its own, and the ``monitors`` executable runs the four monitor
nodes in one process behind one :class:`MonitorInputs`, so every message is received and
decoded once instead of four times (decoding is most of a monitor's work). Each node keeps
its own window, results and publishers either way, so results are the same.
"""

from __future__ import annotations

import sys
import time
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from std_msgs.msg import String

from ads_rca.live.results import FrameMarker, LiveResult
from ads_rca.live.window import MonitorCore, WindowSettings, module_folders
from ads_rca.model import RunMetadata
from ads_rca.oracles.base import Module
from ads_rca.ros import diagnostics as diag
from ads_rca.ros import live_topics, topics
from ads_rca.ros.assembler import metadata_from_document
from ads_rca.ros.cdr import encode_string
from ads_rca.ros.cdr_decode import decode_record, stamp_ms
from ads_rca.ros.jsontext import dumps_json
from ads_rca.ros.nodemain import run_node
from ads_rca.ros.nodeparams import declare_engine_parameters, declare_node_parameters
from ads_rca.ros.playback import FINISHED, METADATA_DOCUMENT_KEY, read_document

#: Node name → module it judges.
MONITORS: dict[str, Module] = {
    "perception_monitor": "perception",
    "prediction_monitor": "prediction",
    "planning_monitor": "planning",
    "control_monitor": "controller",
}

#: The executable that runs all four monitors in one process.
GROUP = "monitors"

PARAMETERS: dict[str, tuple[Any, str]] = {
    "topic_namespace": (topics.DEFAULT_NAMESPACE, "Namespace of the contract topics."),
    "hardware_id": ("ads_rca", "hardware_id of the diagnostic statuses."),
    "stale_timeout_s": (2.0, "STALE on /diagnostics after this long without input."),
    "input_timeout_s": (5.0, "Judge with what arrived after this long without input."),
    "heartbeat_s": (0.5, "Period of the monitor heartbeat status."),
    "poll_period_s": (
        0.02,
        "Judge ready frames at least this often; a frame marker judges at once unless the "
        "last judgement is more recent (so a backlog is judged in batches).",
    ),
    "max_lookahead_frames": (100, "Longest look-ahead waited for (reference prediction keys)."),
    "max_pending_frames": (1200, "Frames held at most before judging anyway (marked)."),
    "history_frames": (0, "Judged frames kept for a late collision (0 = automatic)."),
    "publish_diagnostics": (True, "Publish one /diagnostics status per judged frame."),
}


class Monitor(Node):
    """Judges one module's frames as they complete (fed by a :class:`MonitorInputs`)."""

    def __init__(self, node_name: str, module: Module, own_inputs: bool = True) -> None:
        super().__init__(node_name)
        self.module = module
        self.params = declare_engine_parameters(self)
        p = declare_node_parameters(self, PARAMETERS)
        self.hardware_id = str(p["hardware_id"])
        self.stale_timeout = float(p["stale_timeout_s"])
        self.publish_diagnostics = bool(p["publish_diagnostics"])
        self.namespace = str(p["topic_namespace"])
        settings = WindowSettings(
            max_lookahead_frames=int(p["max_lookahead_frames"]),
            input_timeout_s=float(p["input_timeout_s"]),
            max_pending_frames=int(p["max_pending_frames"]),
            history_frames=int(p["history_frames"]),
        )
        self.core = MonitorCore(module, self.params, settings)
        self._stale_since_report = False
        self.started = time.monotonic()
        self.metrics_pub = self.create_publisher(
            String,
            topics.topic_name(live_topics.metrics_key(module), self.namespace),
            live_topics.metrics_qos(),
        )
        self.diag_pub = self.create_publisher(
            DiagnosticArray, live_topics.DIAGNOSTICS, live_topics.diagnostics_qos()
        )
        self.poll_period = float(p["poll_period_s"])
        self.last_poll = 0.0
        self.create_timer(self.poll_period, self.poll)
        self.create_timer(float(p["heartbeat_s"]), self._heartbeat)
        self.inputs = MonitorInputs(self, [self]) if own_inputs else None
        self.get_logger().info(
            f"{module} monitor, semantics {self.params.semantics}, session {self.core.session}"
        )

    # --- outputs ---------------------------------------------------------------------

    def poll(self) -> None:
        """Publish the results of every frame that became ready."""
        self.last_poll = now = time.monotonic()
        for result in self.core.poll(now):
            self._publish(result)

    def _publish(self, result: LiveResult) -> None:
        # CDR bytes straight from our encoders: rclpy message objects cost more than judging.
        self.metrics_pub.publish(encode_string(dumps_json(result.to_document())))
        if self.publish_diagnostics:
            status = diag.result_status(result, self.params.semantics, self.hardware_id)
            self.diag_pub.publish(diag.encode_array(self.get_clock().now().nanoseconds, [status]))

    def _heartbeat(self) -> None:
        now = time.monotonic()
        core = self.core
        last = core.last_input if core.last_input is not None else self.started
        silent = now - last
        statuses = [
            diag.simple_status(
                diag.heartbeat_name(self.module),
                diag.OK,
                f"judged {core.stats.evaluated}, pending {len(core.pending)}",
                self.hardware_id,
                {
                    "session": core.session,
                    "judged": core.stats.evaluated,
                    "incomplete": core.stats.incomplete,
                    "pending": len(core.pending),
                    "held_records": core.held_records(),
                    "finished": core.finished,
                },
            )
        ]
        if silent >= self.stale_timeout and not core.finished:
            statuses.append(
                diag.simple_status(
                    diag.status_name(self.module),
                    diag.STALE,
                    f"no input for {silent:.1f} s",
                    self.hardware_id,
                    {"silent_s": round(silent, 3), "pending": len(core.pending)},
                )
            )
            if not self._stale_since_report:
                self.get_logger().warning(f"inputs stale: nothing for {silent:.1f} s")
            self._stale_since_report = True
        else:
            self._stale_since_report = False
        self.diag_pub.publish(diag.array(self.get_clock().now().to_msg(), statuses))


class MonitorInputs:
    """The contract subscriptions of one process, feeding every monitor in it.

    Subscribes (on ``node``) to the topics any of ``monitors`` reads, decodes each data
    message once and hands the record to each monitor that reads its folder; markers,
    metadata, the player's status and a live collision go to all of them.
    """

    def __init__(self, node: Node, monitors: list[Monitor]) -> None:
        self.node = node
        self.monitors = monitors
        self._queued: list[tuple[str, bytes, float]] = []
        self._metadata: RunMetadata | None = None
        semantics = monitors[0].params.semantics
        wanted = {f for m in monitors for f in module_folders(semantics, m.module)}
        lossless = [k for k, f in topics.TOPIC_FOLDERS.items() if f in wanted]
        namespace = monitors[0].namespace
        # Data topics arrive as CDR bytes and are decoded straight into model records
        # (ads_rca.ros.cdr_decode): building rclpy message objects costs ~10 ms a frame.
        for key in (*lossless, topics.FRAME, topics.METADATA, topics.STATUS):
            node.create_subscription(
                topics.MESSAGE_TYPES[key],
                topics.topic_name(key, namespace),
                self._callback(key),
                topics.qos_profile(key, keep_all=True),
                raw=key in lossless,
            )
        node.create_subscription(
            String,
            topics.topic_name(live_topics.COLLISION, namespace),
            self._on_collision,
            live_topics.latched_qos(),
        )

    def _callback(self, key: str) -> Any:
        def on_message(msg: Any) -> None:
            now = time.monotonic()
            if key == topics.METADATA:
                self._on_metadata(msg, now)
            elif key == topics.FRAME:
                marker = FrameMarker.from_document(read_document(msg))
                for monitor in self.monitors:
                    monitor.core.add_marker(marker, now)
                    # Judging has a fixed cost per batch (the window's view and context):
                    # while markers stream in faster than poll_period_s, the timer batches.
                    if now - monitor.last_poll >= monitor.poll_period:
                        monitor.poll()
            elif key == topics.STATUS:
                status = read_document(msg)
                if status.get("state") == FINISHED:
                    for monitor in self.monitors:
                        monitor.core.set_finished(now, _count(status.get("frames_published")))
            elif self._metadata is None:
                self._queued.append((key, msg, now))
            else:
                self._add_data(key, msg, now)

        return on_message

    def _on_metadata(self, msg: String, now: float) -> None:
        document = read_document(msg)
        exact = document.get(METADATA_DOCUMENT_KEY)
        try:
            metadata = metadata_from_document(exact if isinstance(exact, dict) else document)
        except (KeyError, TypeError, ValueError) as error:
            self.node.get_logger().error(f"unusable run/metadata: {error!r}")
            return
        self._metadata = metadata
        for monitor in self.monitors:
            monitor.core.set_metadata(metadata, now)
        queued, self._queued = self._queued, []
        for key, data, arrived in queued:
            self._add_data(key, data, arrived)

    def _add_data(self, key: str, data: bytes, now: float) -> None:
        assert self._metadata is not None
        try:
            stamp = stamp_ms(key, data)
        except ValueError:  # a MarkerArray without markers carries no stamp
            return
        record = decode_record(key, data, self._metadata.timesteps_per_frame)
        folder = topics.TOPIC_FOLDERS[key]
        for monitor in self.monitors:
            monitor.core.add_record(folder, stamp, record, now)

    def _on_collision(self, msg: String) -> None:
        frame = read_document(msg).get("frame")
        if not isinstance(frame, int):
            return
        for monitor in self.monitors:
            if monitor.core.set_collision(frame, time.monotonic()):
                monitor.get_logger().info(f"collision at frame {frame}: judging held frames again")


def _count(value: object) -> int | None:
    return value if isinstance(value, int) else None


def run(node_name: str, args: list[str] | None = None) -> int:
    return run_node(node_name, lambda: Monitor(node_name, MONITORS[node_name]), args)


def build_group() -> list[Node]:
    """The four monitor nodes of one process, behind one set of subscriptions."""
    monitors = [Monitor(name, module, own_inputs=False) for name, module in MONITORS.items()]
    MonitorInputs(monitors[0], monitors)
    return list(monitors)


def perception_main(args: list[str] | None = None) -> int:
    return run("perception_monitor", args)


def prediction_main(args: list[str] | None = None) -> int:
    return run("prediction_monitor", args)


def planning_main(args: list[str] | None = None) -> int:
    return run("planning_monitor", args)


def control_main(args: list[str] | None = None) -> int:
    return run("control_monitor", args)


def group_main(args: list[str] | None = None) -> int:
    """``monitors``: all four monitor nodes in one process (inputs decoded once)."""
    return run_node(GROUP, build_group, args)


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
