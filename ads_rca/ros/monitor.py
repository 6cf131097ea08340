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
from ads_rca.oracles.base import Module
from ads_rca.ros import diagnostics as diag
from ads_rca.ros import live_topics, topics
from ads_rca.ros.assembler import metadata_from_document
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

PARAMETERS: dict[str, tuple[Any, str]] = {
    "topic_namespace": (topics.DEFAULT_NAMESPACE, "Namespace of the contract topics."),
    "hardware_id": ("ads_rca", "hardware_id of the diagnostic statuses."),
    "stale_timeout_s": (2.0, "STALE on /diagnostics after this long without input."),
    "input_timeout_s": (5.0, "Judge with what arrived after this long without input."),
    "heartbeat_s": (0.5, "Period of the monitor heartbeat status."),
    "max_lookahead_frames": (100, "Longest look-ahead waited for (reference prediction keys)."),
    "max_pending_frames": (1200, "Frames held at most before judging anyway (marked)."),
    "history_frames": (0, "Judged frames kept for a late collision (0 = automatic)."),
    "publish_diagnostics": (True, "Publish one /diagnostics status per judged frame."),
}


class Monitor(Node):
    """Judges one module's frames as they complete."""

    def __init__(self, node_name: str, module: Module) -> None:
        super().__init__(node_name)
        self.module = module
        self.params = declare_engine_parameters(self)
        p = declare_node_parameters(self, PARAMETERS)
        self.hardware_id = str(p["hardware_id"])
        self.stale_timeout = float(p["stale_timeout_s"])
        self.publish_diagnostics = bool(p["publish_diagnostics"])
        settings = WindowSettings(
            max_lookahead_frames=int(p["max_lookahead_frames"]),
            input_timeout_s=float(p["input_timeout_s"]),
            max_pending_frames=int(p["max_pending_frames"]),
            history_frames=int(p["history_frames"]),
        )
        self.core = MonitorCore(module, self.params, settings)
        namespace = str(p["topic_namespace"])
        self._queued: list[tuple[str, Any, float]] = []
        self._stale_since_report = False
        self.started = time.monotonic()
        folders = module_folders(self.params.semantics, module)
        lossless = [k for k, f in topics.TOPIC_FOLDERS.items() if f in folders]
        # Data topics arrive as CDR bytes and are decoded straight into model records
        # (ads_rca.ros.cdr_decode): building rclpy message objects costs ~10 ms a frame.
        for key in (*lossless, topics.FRAME, topics.METADATA, topics.STATUS):
            self.create_subscription(
                topics.MESSAGE_TYPES[key],
                topics.topic_name(key, namespace),
                self._callback(key),
                topics.qos_profile(key, keep_all=True),
                raw=key in lossless,
            )
        self.create_subscription(
            String,
            topics.topic_name(live_topics.COLLISION, namespace),
            self._on_collision,
            live_topics.latched_qos(),
        )
        self.metrics_pub = self.create_publisher(
            String,
            topics.topic_name(live_topics.metrics_key(module), namespace),
            live_topics.metrics_qos(),
        )
        self.diag_pub = self.create_publisher(
            DiagnosticArray, live_topics.DIAGNOSTICS, live_topics.diagnostics_qos()
        )
        self.create_timer(0.02, self._poll)
        self.create_timer(float(p["heartbeat_s"]), self._heartbeat)
        self.get_logger().info(
            f"{module} monitor, semantics {self.params.semantics}, session {self.core.session}"
        )

    # --- inputs ----------------------------------------------------------------------

    def _callback(self, key: str) -> Any:
        def on_message(msg: Any) -> None:
            now = time.monotonic()
            if key == topics.METADATA:
                self._on_metadata(msg, now)
            elif key == topics.FRAME:
                self.core.add_marker(FrameMarker.from_document(read_document(msg)), now)
                self._poll()
            elif key == topics.STATUS:
                status = read_document(msg)
                if status.get("state") == FINISHED:
                    self.core.set_finished(now, _count(status.get("frames_published")))
            elif self.core.metadata is None:
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
            self.get_logger().error(f"unusable run/metadata: {error!r}")
            return
        self.core.set_metadata(metadata, now)
        queued, self._queued = self._queued, []
        for key, data, arrived in queued:
            self._add_data(key, data, arrived)

    def _add_data(self, key: str, data: bytes, now: float) -> None:
        assert self.core.metadata is not None
        try:
            stamp = stamp_ms(key, data)
        except ValueError:  # a MarkerArray without markers carries no stamp
            return
        record = decode_record(key, data, self.core.metadata.timesteps_per_frame)
        self.core.add_record(topics.TOPIC_FOLDERS[key], stamp, record, now)

    def _on_collision(self, msg: String) -> None:
        frame = read_document(msg).get("frame")
        if isinstance(frame, int) and self.core.set_collision(frame, time.monotonic()):
            self.get_logger().info(f"collision at frame {frame}: judging held frames again")

    # --- outputs ---------------------------------------------------------------------

    def _poll(self) -> None:
        for result in self.core.poll(time.monotonic()):
            self._publish(result)

    def _publish(self, result: LiveResult) -> None:
        self.metrics_pub.publish(String(data=dumps_json(result.to_document())))
        if self.publish_diagnostics:
            status = diag.result_status(result, self.params.semantics, self.hardware_id)
            self.diag_pub.publish(diag.array(self.get_clock().now().to_msg(), [status]))

    def _heartbeat(self) -> None:
        now = time.monotonic()
        core = self.core
        last = core.last_input if core.last_input is not None else self.started
        silent = now - last
        statuses = [
            diag.simple_status(
                f"{diag.status_name(self.module)}/monitor",
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


def _count(value: object) -> int | None:
    return value if isinstance(value, int) else None


def run(node_name: str, args: list[str] | None = None) -> int:
    return run_node(node_name, lambda: Monitor(node_name, MONITORS[node_name]), args)


def perception_main(args: list[str] | None = None) -> int:
    return run("perception_monitor", args)


def prediction_main(args: list[str] | None = None) -> int:
    return run("prediction_monitor", args)


def planning_main(args: list[str] | None = None) -> int:
    return run("planning_monitor", args)


def control_main(args: list[str] | None = None) -> int:
    return run("control_monitor", args)


if __name__ == "__main__":
    # python -m ads_rca.ros.monitor <node_name> [--ros-args ...]
    name = sys.argv[1] if len(sys.argv) > 1 and sys.argv[1] in MONITORS else ""
    if not name:
        print(f"usage: python -m ads_rca.ros.monitor {{{','.join(MONITORS)}}} [--ros-args ...]")
        sys.exit(2)
    sys.exit(run(name, [sys.argv[0], *sys.argv[2:]]))
