"""``aggregator`` node: the four monitors' results in, the verdict out (once, latched).

A thin shell over :class:`~ads_rca.live.aggregate.AggregatorCore`, which attributes with the
engine's own ``attribute`` and renders the ``diagnose --json`` contract. Publishes the
verdict on ``verdict`` (DiagnosticArray, ERROR naming the primary root cause, evidence as
key/values) and ``verdict/json`` (String), both latched, writes it to ``verdict_json``, and
logs the one-line verdict. It also watches the monitors' heartbeats: a monitor silent for
``stale_timeout_s`` while the run goes on is reported STALE on ``/diagnostics`` under its
module's status name (a dead process cannot report itself).

Stack mode keeps each episode apart (:mod:`ads_rca.live.episodes`): results are keyed by
the episode the monitors numbered, a verdict says its episode (``live.episode``), and an
episode that ended is reported on ``/diagnostics`` (status ``ads_rca/episode``).

``metrics_log`` (optional) receives every result as it arrives, one JSON line each, for the
determinism test and the benchmark.

With ``exit_after_verdict`` the node ends once the verdict is out: it waits until every
subscriber (the recorder among them) acknowledged the verdict messages, then exits 0, which
is how ``rca_graph.launch.py`` knows the run is over and stops the rest of the graph.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import Any, TextIO

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from std_msgs.msg import String

from ads_rca.contract import live_topics, topics
from ads_rca.contract.assembler import run_metadata
from ads_rca.contract.ego_paths import read_ego_path
from ads_rca.contract.errors import MalformedMessage
from ads_rca.contract.jsontext import loads_json
from ads_rca.contract.malformed import SkippedMessages
from ads_rca.contract.playback import (
    FINISHED,
    read_document,
    read_input_problems,
)
from ads_rca.diagnosis.summary import window_text
from ads_rca.errors import AdsRcaError
from ads_rca.foundation.indented_json import dumps_indented
from ads_rca.live import diagnostics as diag
from ads_rca.live.aggregate import AggregatorCore, VerdictOutcome
from ads_rca.live.collision_feed import CollisionFeed, collision_document
from ads_rca.live.episodes import EpisodeAggregator, EpisodeReport
from ads_rca.live.results import FrameMarker, LiveResult, collision_frame
from ads_rca.live.runid import RUN_KEY, RunFilter, checked_run_id
from ads_rca.live.stack_config import STACK_PARAMETERS, StackConfig
from ads_rca.oracles.base import MODULES, Module
from ads_rca.oracles.semantics import semantics_for
from ads_rca.paramspec import SECONDS
from ads_rca.ros.diagnostics import array as diagnostic_array
from ads_rca.ros.nodemain import run_node, subscribe_ready, wait_for_acks
from ads_rca.ros.nodeparams import (
    NodeParameter,
    command_line_overrides,
    declare_engine_parameters,
    declare_node_parameters,
    log_in_force,
)
from ads_rca.ros.qos_match import any_durability

PARAMETERS: dict[str, NodeParameter] = {
    "topic_namespace": (topics.DEFAULT_NAMESPACE, "Namespace of the contract topics."),
    "hardware_id": ("ads_rca", "hardware_id of the diagnostic statuses."),
    "verdict_json": ("", "Write the verdict JSON here ('' = no file)."),
    "metrics_log": ("", "Append every received result as a JSON line here ('' = none)."),
    "verdict_timeout_s": (
        10.0,
        "After the horizon, publish anyway after this long without results (stack mode: "
        "input_timeout_s + this long after the collision).",
        SECONDS,
    ),
    "stall_timeout_s": (
        20.0,
        "Before the horizon, publish anyway after this long without input.",
        SECONDS,
    ),
    "stale_timeout_s": (2.0, "A monitor silent this long is reported STALE.", SECONDS),
    "run_id": (
        "",
        "Attribute only this run ('' = the first run heard of); see ads_rca.live.runid.",
    ),
    "exit_after_verdict": (
        False,
        "Exit (status 0) once every subscriber acknowledged the published verdict.",
    ),
    "ack_timeout_s": (
        10.0,
        "With exit_after_verdict: longest wait for those acknowledgements.",
        SECONDS,
    ),
    "input_timeout_s": (
        5.0,
        "Stack mode, detect_collisions: a frame missing its pose or actors is given up on "
        "after this long.",
        SECONDS,
    ),
    "collision_topic": (
        "",
        "Stack mode: a topic announcing collisions (std_msgs/String, the run/collision "
        "document); '' = run/collision only. Forwarded to run/collision for the monitors.",
    ),
    "detect_collisions": (
        False,
        "Stack mode: detect collisions from ground truth (ego and actor boxes overlapping), "
        "published on run/collision flagged derived.",
    ),
}
_REPORTER = "aggregator"
#: Status name of the episodes (stack mode: an episode ended, a later one began).
EPISODE_STATUS = "ads_rca/episode"


class Aggregator(Node):
    """Collects results, publishes the verdict once."""

    def __init__(self) -> None:
        super().__init__("aggregator", parameter_overrides=command_line_overrides("aggregator"))
        self.params = declare_engine_parameters(self)
        p = declare_node_parameters(self, {**PARAMETERS, **STACK_PARAMETERS}, self.params)
        self.hardware_id = str(p["hardware_id"])
        self.verdict_json = str(p["verdict_json"])
        self.exit_after_verdict = bool(p["exit_after_verdict"])
        self.ack_timeout = float(p["ack_timeout_s"])
        #: The verdict is out and ``exit_after_verdict``: run_node stops spinning.
        self.finished = False
        self.stale_timeout = float(p["stale_timeout_s"])
        self.runs = RunFilter(checked_run_id(str(p["run_id"])))
        self.skipped = SkippedMessages()
        ns = self.namespace = str(p["topic_namespace"])
        self.stack_config = StackConfig.from_values(p, ns, float(p["input_timeout_s"]))
        self.timeouts = (float(p["verdict_timeout_s"]), float(p["stall_timeout_s"]))
        stack = self.stack_config if self.stack_config.mode == "stack" else None
        self.episodes = self._episodes(stack)
        self.verdicts_published = 0
        self._metrics_log: TextIO | None = None
        if p["metrics_log"]:
            path = Path(str(p["metrics_log"]))
            path.parent.mkdir(parents=True, exist_ok=True)
            # Line-buffered: a reader (a test, a tail -f) sees each result as it arrives.
            self._metrics_log = path.open("w", encoding="utf-8", buffering=1)
        self.heard: dict[Module, float] = {}
        #: Monitors a result was received from: the first one of each is said, so a log
        #: shows whether the aggregator hears the graph at all.
        self.results_from: set[Module] = set()
        self.run_started: float | None = None
        for module in MODULES:
            self.create_subscription(
                String,
                topics.topic_name(live_topics.metrics_key(module), ns),
                self._on_result,
                live_topics.metrics_qos(subscriber=True),
            )
        self.create_subscription(
            String,
            topics.topic_name(topics.EGO_PATHS, ns),
            self._on_ego_path,
            topics.qos_profile(topics.EGO_PATHS, keep_all=True),
        )
        for key in (topics.FRAME, topics.METADATA, topics.STATUS):
            self.create_subscription(
                String,
                topics.topic_name(key, ns),
                self._callback(key),
                topics.qos_profile(key, keep_all=True),
            )
        collision_topic = topics.topic_name(live_topics.COLLISION, ns)
        any_durability(self, String, collision_topic, self._on_collision)
        #: Collisions from elsewhere (a mapped topic, detection) go on run/collision too.
        self.collision_pub = self.create_publisher(
            String, collision_topic, live_topics.latched_qos()
        )
        mapped = str(p["collision_topic"])
        if mapped and mapped != collision_topic:
            any_durability(self, String, mapped, self._on_mapped_collision)
        self.detection: CollisionFeed | None = None
        if bool(p["detect_collisions"]):
            self._subscribe_detection()
        subscribe_ready(self, ns, str(p["run_id"]))
        # Raw: only the status names are read (heartbeats), not 4 full statuses a frame.
        self.create_subscription(
            DiagnosticArray,
            live_topics.DIAGNOSTICS,
            self._on_diagnostics,
            live_topics.diagnostics_qos(),
            raw=True,
        )
        self._heartbeats = {diag.heartbeat_name(m): m for m in MODULES}
        latched = live_topics.latched_qos()
        self.verdict_pub = self.create_publisher(
            DiagnosticArray, topics.topic_name(live_topics.VERDICT, ns), latched
        )
        self.json_pub = self.create_publisher(
            String, topics.topic_name(live_topics.VERDICT_JSON, ns), latched
        )
        self.diag_pub = self.create_publisher(
            DiagnosticArray, live_topics.DIAGNOSTICS, live_topics.diagnostics_qos()
        )
        self.create_timer(0.02, self._poll)
        self.create_timer(0.5, self._watch_monitors)
        #: Stack mode: the last episode that ended (said on /diagnostics every second).
        self.episode_report: EpisodeReport | None = None
        self.create_timer(1.0, self._say_episode)
        log_in_force(self, p, self.params)

    def _episodes(self, stack: StackConfig | None) -> EpisodeAggregator:
        """One core per episode (a player's run: one core)."""
        return EpisodeAggregator(
            lambda: AggregatorCore(self.params, *self.timeouts, stack=stack),
            stack is not None,
            grace_s=self.timeouts[0],
        )

    @property
    def core(self) -> AggregatorCore:
        """The current episode's core (a player's run has one)."""
        return self.episodes.current

    # --- inputs ----------------------------------------------------------------------

    def _callback(self, key: str) -> Any:
        def on_message(msg: String) -> None:
            now = time.monotonic()
            try:
                document = read_document(msg)
                marker = FrameMarker.from_document(document) if key == topics.FRAME else None
            except MalformedMessage as error:
                self._skip(key, error, now)
                return
            if not self.runs.accept(document):
                return  # another run's player
            if marker is not None:
                self.core.add_marker(marker, now)
            elif key == topics.STATUS:
                if document.get("state") == FINISHED:
                    published = document.get("frames_published")
                    self.core.set_finished(now, published if isinstance(published, int) else None)
            else:
                try:
                    metadata = run_metadata(document)
                except MalformedMessage as error:
                    self._skip(key, error, now)
                    return
                self.core.set_metadata(
                    metadata,
                    str(document.get("source", "")),
                    now,
                    read_input_problems(document),
                )
                frame_ms = metadata.timesteps_per_frame
                if frame_ms > 0:  # the window in frames needs the run's frame period
                    window = semantics_for(self.params).effect_window(self.params, frame_ms)
                    self.get_logger().info(f"{frame_ms} ms per frame, {window_text(window)}")

        return on_message

    def _on_ego_path(self, msg: String) -> None:
        """A snapshot row's paths (``run/ego_paths``): kept for the verdict's scores."""
        try:
            document = read_document(msg)
            row = read_ego_path(document)
        except MalformedMessage as error:
            self._skip(topics.EGO_PATHS, error, time.monotonic())
            return
        if self.runs.accept(document):
            try:
                self.core.add_ego_path(row)
            except MalformedMessage as error:  # beyond the rows held (live.aggregate)
                self._skip(topics.EGO_PATHS, error, time.monotonic())

    def _subscribe_detection(self) -> None:
        from ads_rca.ros.stack_subscriber import message_class, stack_qos

        def skip(folder: str, error: str) -> None:
            topic = self.stack_config.inputs[folder].topic
            self._skip(topic, f"collision detection: {error}", time.monotonic())

        feed = self.detection = CollisionFeed(self.stack_config, skip)
        for folder, topic in feed.topics.items():
            layout = self.stack_config.inputs[folder].layout

            def on_message(msg: Any, folder: str = folder) -> None:
                self._detected(feed.add(folder, msg, time.monotonic()))

            self.create_subscription(
                message_class(layout.type_name),
                topic,
                on_message,
                stack_qos(self.stack_config.best_effort),
                raw=layout.raw,
            )

    def _detected(self, collisions: list[Any]) -> None:
        for collision in collisions:
            document = collision_document(collision)
            self.get_logger().info(
                f"collision {collision.number} detected at frame {document['frame']} "
                f"(ego box overlaps actor {document['actor_id']!r} by {collision.depth_m:.2f} m)"
            )
            self._stack_mode()
            self.episodes.set_collision(int(document["frame"]), time.monotonic(), derived=True)
            self.collision_pub.publish(String(data=json.dumps(document)))

    def _stack_mode(self) -> None:
        """``stack_mode`` auto: results judged on a stack's frames (they carry the frame
        period) or a stack's collision, with no player heard: the aggregator follows."""
        if self.core.stack or self.core.metadata is not None or self.stack_config.mode == "player":
            return
        self.get_logger().info("no player on the graph: stack mode")
        self.episodes = self._episodes(self.stack_config)

    def _on_result(self, msg: String) -> None:
        now = time.monotonic()
        try:
            document = loads_json(msg.data)
            result = LiveResult.from_document(document)
        except MalformedMessage as error:
            reason = error.__cause__ or error  # the reader's own error, as always said
            self._skip("metrics", f"unreadable monitor result: {reason!r}", now)
            return
        if not self.runs.accept(document):
            return  # a monitor judging another run
        self.heard[result.module] = now
        if result.module not in self.results_from:
            self.results_from.add(result.module)
            self.get_logger().info(f"first result from the {result.module} monitor")
        if result.frame_ms > 0:
            self._stack_mode()
        before = self.episodes.cores.get(result.episode)
        known = before.collision_frame if before is not None else -1
        core = self.episodes.add_result(result, now)
        if core is None:
            self._skip("metrics", f"a result of episode {result.episode}, already closed", now)
        elif core.collision_frame != known and core.collision_source == "monitors":
            self.get_logger().info(
                f"collision at frame {core.collision_frame} taken from the "
                f"{result.module} monitor's result (its event was not heard here)"
            )
        if self._metrics_log is not None:
            self._metrics_log.write(msg.data + "\n")
        self._poll()

    def _skip(self, key: str, error: object, now: float) -> None:
        """A message that cannot be read: counted, and said (at most every few seconds)."""
        line = self.skipped.note(topics.topic_name(key, self.namespace), error, now)
        if line is not None:
            self.get_logger().warning(line)

    def _on_collision(self, msg: String, forward: bool = False) -> None:
        """``run/collision`` or, ``forward``, a stack's own collision topic (then forwarded
        to run/collision for the monitors)."""
        try:
            frame = collision_frame(read_document(msg), self.runs)
        except MalformedMessage as error:
            self._skip(live_topics.COLLISION, error, time.monotonic())
            return
        if frame is None:
            return
        self._stack_mode()  # a collision and no player heard: a stack's run
        if frame != self.core.collision_frame:  # said once: a graph without a verdict shows it
            self.get_logger().info(f"collision announced at frame {frame}")
        self.episodes.set_collision(frame, time.monotonic())
        if forward:
            self.collision_pub.publish(String(data=json.dumps({"frame": frame})))

    def _on_mapped_collision(self, msg: String) -> None:
        self._on_collision(msg, forward=True)

    def _on_diagnostics(self, data: bytes) -> None:
        now = time.monotonic()
        for name, run in diag.status_runs(data):
            module = self._heartbeats.get(name)
            if module is not None and self.runs.accept_run(run):
                self.heard[module] = now

    # --- outputs ---------------------------------------------------------------------

    def _watch_monitors(self) -> None:
        """STALE for each monitor not heard from while the run goes on."""
        core = self.core
        if core.outcome is not None or core.metadata is None or not core.markers_received:
            return  # judged only while the run is under way
        now = time.monotonic()
        if self.run_started is None:
            self.run_started = now
        statuses = []
        for module in MODULES:
            silent = now - max(self.heard.get(module, self.run_started), self.run_started)
            if silent >= self.stale_timeout:
                statuses.append(
                    diag.simple_status(
                        diag.status_name(module),
                        diag.STALE,
                        f"{module} monitor silent for {silent:.1f} s",
                        self.hardware_id,
                        {
                            "reported_by": _REPORTER,
                            "silent_s": round(silent, 3),
                            RUN_KEY: self.runs.run or "",
                        },
                    )
                )
        if statuses:
            self.diag_pub.publish(diagnostic_array(self.get_clock().now().to_msg(), statuses))

    def _poll(self) -> None:
        now = time.monotonic()
        if self.detection is not None:
            self._detected(self.detection.poll(now))
        for event in self.episodes.poll(now):
            if isinstance(event, EpisodeReport):
                self._publish_episode(event)
            else:
                self._publish(event)

    def _publish_episode(self, report: EpisodeReport) -> None:
        """An episode ended (a later one began): said in the log and on /diagnostics."""
        self.episode_report = report
        self.get_logger().info(report.text())
        self._say_episode()

    def _say_episode(self) -> None:
        """Stack mode, once results came: the episode judged and, once one ended, what it
        held, on /diagnostics at once and every second (a late subscriber, or a diagnostics
        aggregator that marks a status not repeated stale, still sees it)."""
        episodes = self.episodes
        if not episodes.stack or episodes.current.last_input is None:
            return
        report = self.episode_report
        values: dict[str, object] = {"episode": episodes.number, RUN_KEY: self.runs.run or ""}
        if report is not None:
            ended = report.to_document()
            values |= {f"ended.{k}": v for k, v in ended.items() if k != "next_episode"}
        text = report.text() if report is not None else f"episode {episodes.number}"
        status = diag.simple_status(EPISODE_STATUS, diag.OK, text, self.hardware_id, values)
        self.diag_pub.publish(diagnostic_array(self.get_clock().now().to_msg(), [status]))

    def _publish(self, outcome: VerdictOutcome) -> None:
        document = outcome.document
        document["live"][RUN_KEY] = self.runs.run or ""
        text = dumps_indented(document)
        stamp = self.get_clock().now().to_msg()
        self.verdict_pub.publish(
            diagnostic_array(stamp, [diag.verdict_status(document, self.hardware_id)])
        )
        self.json_pub.publish(String(data=text))
        self.diag_pub.publish(
            diagnostic_array(stamp, [diag.verdict_status(document, self.hardware_id)])
        )
        self.verdicts_published += 1
        if self.verdict_json:
            path = numbered(Path(self.verdict_json), self.verdicts_published)
            path.parent.mkdir(parents=True, exist_ok=True)
            partial = path.with_name(path.name + ".partial")
            partial.write_text(text + "\n")
            partial.replace(path)
        state = (
            "complete"
            if outcome.complete
            else "INCOMPLETE: " + "; ".join(document["live"]["why_incomplete"])
        )
        live = document["live"]
        which = (
            f" (episode {live['episode']}, collision {live['collision_number']})"
            if "episode" in live
            else ""
        )
        self.get_logger().info(
            f"verdict{which}: {document['verdict']} [{document['attribution_basis']}] "
            f"latency {document['verdict_latency_s']:.3f} s, {state}"
        )
        if self._metrics_log is not None:
            self._metrics_log.flush()
        self.finished = self.exit_after_verdict

    def close(self) -> None:
        if self.finished:
            publishers = (self.verdict_pub, self.json_pub, self.diag_pub)
            if not wait_for_acks(publishers, self.ack_timeout):
                self.get_logger().warning(
                    f"verdict not acknowledged by every subscriber within {self.ack_timeout} s"
                )
        if self._metrics_log is not None:
            self._metrics_log.close()
            self._metrics_log = None


def numbered(path: Path, number: int) -> Path:
    """Verdict N's file: the path for the first, ``name.N.json`` for the later ones."""
    return path if number == 1 else path.with_name(f"{path.stem}.{number}{path.suffix}")


def main(args: list[str] | None = None) -> int:
    return run_node("aggregator", Aggregator, args, (AdsRcaError, OSError))


if __name__ == "__main__":
    sys.exit(main())
