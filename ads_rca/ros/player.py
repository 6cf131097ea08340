"""``player`` node: plays a running-log folder onto the topic contract, frame by frame.

A thin shell: the data logic (conversion, timeline, markers) lives in convert.py and
playback.py. Timing follows log time: a wall timer ticks every frame_ms/rate and sends every
stamp that is due; at rate 0 frames go in batches of ``ack_every``, each batch once every
subscriber acknowledged the previous one (``wait_for_all_acked``), so nothing is dropped.
Bad input is one logged line and exit status 2; reader problems are logged one per line
and counted in the status. The camera (``/tf_static``, ``camera/camera_info``) is sent once,
latched, at start (:mod:`ads_rca.contract.camera`).
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path
from typing import Any

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.logging import get_logger
from rclpy.node import Node
from rclpy.subscription import RCLError
from sensor_msgs.msg import CameraInfo
from std_msgs.msg import String

from ads_rca.contract import live_topics, topics
from ads_rca.contract.camera import camera_intrinsics, camera_mount
from ads_rca.contract.cdr import encode_clock, encode_string, encode_tf_message
from ads_rca.contract.convert import camera_info_message, clock_message
from ads_rca.contract.ego_paths import ego_path_document
from ads_rca.contract.jsontext import dumps_json
from ads_rca.contract.playback import (
    FINISHED,
    PLAYING,
    Tick,
    annotation_message,
    annotations_by_tick,
    dropped_plan_keys,
    frame_marker,
    metadata_message,
    published_names,
    select,
    status_message,
    timeline,
)
from ads_rca.diagnosis.engine import prepared_run
from ads_rca.errors import AdsRcaError, ConfigError, InputError
from ads_rca.foundation.files import DEFAULT_MAX_FILE_MB
from ads_rca.foundation.text import printable
from ads_rca.live.runid import checked_run_id, new_run_id
from ads_rca.model import RunLog
from ads_rca.oracles.semantics import EVENT_PARAMETERS
from ads_rca.params import DEFAULT_SEMANTICS, Params, make_params
from ads_rca.paramspec import MAX_FILE_MB, RATE, SECONDS, SPECS, Range
from ads_rca.ros.nodemain import (
    ignore_stop_signals,
    keep_running,
    make_executor,
    start_process,
    wait_for_acks,
)
from ads_rca.ros.nodeparams import (
    NodeParameter,
    command_line_overrides,
    declare_node_parameters,
    log_in_force,
)
from ads_rca.sources.bag.options import BagOptions
from ads_rca.sources.bag.profiles import BUILTIN_PROFILES, DEFAULT_PROFILE
from ads_rca.sources.formats import AUTO, SOURCE_PARAMS, SourceOptions
from ads_rca.sources.registry import FORMATS, no_frame_message

#: A tick may carry a few extra stamps; 40 frames stay far below the 100-message history.
MAX_ACK_EVERY = 40
#: The largest frame index a parameter can name.
MAX_FRAME = 2**31 - 1

#: Every parameter: (default, description[, range]); declared by
#: ``nodeparams.declare_node_parameters``, which checks the ranges.
PARAMETERS: dict[str, NodeParameter] = {
    "log_path": (
        "",
        "Running-log folder, rosbag2 bag (dir, .mcap, .db3), CARLA experiment-client run "
        "folder or DLP scene to play (required).",
    ),
    "format": (
        AUTO,
        f"The input's format: {', '.join(FORMATS)} ({AUTO}: told by the path; docs/formats.md).",
    ),
    "ego_agent": (
        "",
        "A DLP scene has no ego: the agent to take as one, by token or by number in token "
        "order ('' = the longest-lived moving car).",
    ),
    "predictions": (
        "",
        "A folder of a predictor's prediction files to score against a CARLA run's or DLP "
        "scene's realised future ('' = none).",
    ),
    "submission": (
        "",
        "An atmaCup #18 submission CSV: predicted ego paths to score against the table's "
        "realised ones ('' = none).",
    ),
    "derived_collision": (
        False,
        "A CARLA run or DLP scene records no collision: take the first frame where the ego's "
        "box overlaps another's as one, flagged derived.",
    ),
    "bag_remap": ("", "Topic remapping YAML for a bag whose topic names differ ('' = none)."),
    "profile": (
        DEFAULT_PROFILE,
        "Which topics and types of a bag carry the model's inputs: a built-in profile "
        f"({', '.join(BUILTIN_PROFILES)}) or a profile YAML path (docs/recordings.md).",
    ),
    "msg_path": (
        "",
        "Directories of .msg files for message types a bag does not define, separated by "
        f"{os.pathsep!r} ('' = none).",
    ),
    "rate": (
        1.0,
        "Playback speed vs log time; 0 = as fast as subscribers acknowledge.",
        RATE,
    ),
    "max_file_mb": (
        DEFAULT_MAX_FILE_MB,
        "Log files larger than this many MB are reported and skipped, not read.",
        MAX_FILE_MB,
    ),
    "start_frame": (
        0,
        "Index of the first analysed frame to play.",
        Range(0, MAX_FRAME, integer=True),
    ),
    "stop_frame": (
        -1,
        "Index of the last analysed frame to play (inclusive); -1 = the end.",
        Range(-1, MAX_FRAME, integer=True),
    ),
    "loop": (False, "Start again from start_frame after the last frame."),
    "publish_clock": (True, "Publish /clock with each frame's log time before its data."),
    "topic_namespace": (topics.DEFAULT_NAMESPACE, "Namespace of every contract topic."),
    "wait_for_subscribers": (
        0,
        "Wait for this many subscribers on run/frame before playing.",
        Range(0, 1000, integer=True),
    ),
    "wait_timeout_s": (
        10.0,
        "Longest wait for subscribers / acknowledgements, in seconds.",
        SECONDS,
    ),
    "exit_on_end": (True, "After 'finished', wait for all acks, then exit with status 0."),
    "ack_every": (
        20,
        "At rate 0: frames sent between waits for acknowledgements (1 to 40; the publishers "
        "keep 100 messages, so a batch never overwrites an unacknowledged one).",
        Range(1, MAX_ACK_EVERY, integer=True),
    ),
    "run_id": (
        "",
        "Identity of this run, carried by every JSON message ('' = a new random one); "
        "monitors, aggregator and recorder of another run ignore this one.",
    ),
    "fast_publish": (
        True,
        "Publish per-frame messages as CDR bytes built by ads_rca.contract.cdr (byte-identical, "
        "~20x faster) instead of rclpy message objects.",
    ),
}


#: The critical event's parameters (docs/real-drives.md "Events"): the player plays the run
#: as ``diagnose`` judges it, its event in the collision's place (same names, same ranges).
def _event_parameter(name: str) -> NodeParameter:
    effect, bounds = SPECS[name].effect_in(DEFAULT_SEMANTICS), SPECS[name].range
    assert isinstance(bounds, Range)  # every event parameter is a number
    return getattr(Params(), name), f"{effect[:1].upper()}{effect[1:]}.", bounds


EVENT_NODE_PARAMETERS: dict[str, NodeParameter] = {
    name: _event_parameter(name) for name in EVENT_PARAMETERS
}


class Player(Node):
    """Publishes one RunLog on the contract topics."""

    def __init__(self) -> None:
        super().__init__("player", parameter_overrides=command_line_overrides("player"))
        self._values = declare_node_parameters(self, {**PARAMETERS, **EVENT_NODE_PARAMETERS})
        self.rate = float(self._param("rate"))
        self.start_frame = int(self._param("start_frame"))
        self.stop_frame = int(self._param("stop_frame"))
        self.loop = bool(self._param("loop"))
        self.publish_clock = bool(self._param("publish_clock"))
        self.wait_count = int(self._param("wait_for_subscribers"))
        self.wait_timeout = float(self._param("wait_timeout_s"))
        self.exit_on_end = bool(self._param("exit_on_end"))
        self.fast_publish = bool(self._param("fast_publish"))
        self.ack_every = int(self._param("ack_every"))
        namespace = str(self._param("topic_namespace"))
        given_run = checked_run_id(str(self._param("run_id")))
        self.run_id = given_run or new_run_id()
        self.max_file_mb = float(self._param("max_file_mb"))
        self.log = self._load(str(self._param("log_path")), self._bag_options())
        self.ticks = select(timeline(self.log), self.start_frame, self.stop_frame)
        self.annotations = annotations_by_tick(self.log, self.ticks)
        if not self.ticks:
            self.get_logger().warning(
                f"frames {self.start_frame}..{self.stop_frame} select nothing "
                f"(the log has {len(self.log.frames)} analysed frames)"
            )
        self.pubs = {
            key: self.create_publisher(
                topics.message_types()[key],
                topics.topic_name(key, namespace),
                topics.qos_profile(key),
            )
            for key in topics.advertised(self.log)
            if key != topics.CLOCK or self.publish_clock
        }
        # Nodes given our run id subscribe here: counted before playing, they are ours
        # (run/frame also counts the subscribers of any other run on this namespace).
        self.ready_pub = (
            self.create_publisher(
                String, topics.topic_name(live_topics.ready_key(given_run), namespace), 1
            )
            if given_run
            else None
        )
        self.frames_published = 0
        self.loops = 0
        self.done = False
        self._position = 0
        self._wall0 = 0.0
        self.metadata = metadata_message(
            self.log,
            playback={
                "start_frame": self.start_frame,
                "stop_frame": self.stop_frame,
                "ticks": len(self.ticks),
            },
            run=self.run_id,
        )
        self.pubs[topics.METADATA].publish(self.metadata)
        self.get_logger().info(f"run {self.run_id}")
        self.camera_pubs = self._publish_camera(namespace)
        log_in_force(self, self._values)

    def _publish_camera(self, namespace: str) -> list[Any]:
        """The camera for 3D viewers, once, latched (docs/topics.md "The camera"):
        ``/tf_static`` where tf2_msgs is installed, CameraInfo where the log gives the
        intrinsics. Returns the publishers, which must live for late joiners."""
        stamp_ms = self.log.frames[0] if self.log.frames else 0
        logger = self.get_logger()
        pubs = []
        try:
            mount = camera_mount(self.log.metadata)
            from tf2_msgs.msg import TFMessage
        except ValueError as error:
            logger.warning(f"no {topics.TF_STATIC}: {printable(str(error))}")
        except ImportError:
            logger.info(f"tf2_msgs is not installed: {topics.TF_STATIC} not published")
        else:
            qos = topics.qos_profile(topics.TF_STATIC)
            pubs.append(self.create_publisher(TFMessage, topics.TF_STATIC, qos))
            pubs[-1].publish(encode_tf_message(stamp_ms, [mount]))
            logger.info(f"{topics.TF_STATIC}: {mount.parent} -> {mount.child} {mount.translation}")
        try:
            intrinsics = camera_intrinsics(self.log.metadata)
        except ValueError as error:
            logger.warning(f"no {topics.CAMERA_INFO}: {printable(str(error))}")
            return pubs
        if intrinsics is not None:
            name = topics.topic_name(topics.CAMERA_INFO, namespace)
            qos = topics.qos_profile(topics.CAMERA_INFO)
            pubs.append(self.create_publisher(CameraInfo, name, qos))
            pubs[-1].publish(camera_info_message(intrinsics, stamp_ms))
            logger.info(
                f"{topics.CAMERA_INFO}: {intrinsics.width}x{intrinsics.height} px, "
                f"focal {intrinsics.fx:.1f} px"
            )
        return pubs

    def _param(self, name: str) -> Any:
        return self._values[name]

    def _bag_options(self) -> BagOptions:
        """``profile``, ``bag_remap`` and ``msg_path``, each checked (one line naming it)."""
        remap = str(self._param("bag_remap"))
        if remap and not Path(remap).is_file():
            raise ConfigError(f"parameter bag_remap: {remap}: no such remapping file")
        dirs = tuple(d for d in str(self._param("msg_path")).split(os.pathsep) if d)
        for directory in dirs:
            if not Path(directory).is_dir():
                raise ConfigError(f"parameter msg_path: {directory}: no such directory")
        profile = str(self._param("profile")) or DEFAULT_PROFILE
        return BagOptions(profile, remap or None, dirs)

    def _load(self, log_path: str, bag: BagOptions) -> RunLog:
        from ads_rca.sources.registry import open_run

        if not log_path:
            raise ConfigError("parameter log_path is required (a running-log folder)")
        if not Path(log_path).exists():
            raise ConfigError(f"{log_path}: no such log folder")
        source = SourceOptions.from_values({k: self._param(k) for k in SOURCE_PARAMS})
        log = open_run(log_path, max_file_mb=self.max_file_mb, bag=bag, source=source)
        # Without ground truth its tracks are the world; without a collision, its critical
        # event stands in: the monitors judge what diagnose judges.
        events = make_params(DEFAULT_SEMANTICS, {n: self._param(n) for n in EVENT_NODE_PARAMETERS})
        log = prepared_run(log, events)
        for problem in log.problems:
            self.get_logger().warning(str(problem))
        if not log.frames:  # nothing to play: refused as diagnose refuses it
            raise InputError(no_frame_message(log_path, log, source.source_format, bag))
        self.get_logger().info(
            printable(
                f"{log_path}: {len(log.frames)} analysed frames, frame_ms {log.frame_ms} ms, "
                f"{len(log.problems)} problems"
            )
        )
        return log

    # --- waiting ------------------------------------------------------------------------

    def wait_for_subscribers(self) -> bool:
        """Until ``wait_count`` subscribers match run/frame (then, briefly, every data topic)."""
        if self.wait_count <= 0:
            return True
        deadline = time.monotonic() + self.wait_timeout
        frame_pub = self.pubs[topics.FRAME]
        ours = self.ready_pub if self.ready_pub is not None else frame_pub
        while keep_running() and (
            ours.get_subscription_count() < self.wait_count
            or frame_pub.get_subscription_count() < self.wait_count
        ):
            if time.monotonic() > deadline:
                self.get_logger().warning(
                    f"only {ours.get_subscription_count()} of {self.wait_count} "
                    f"subscribers after {self.wait_timeout} s; playing anyway"
                )
                return False
            time.sleep(0.01)
        # Endpoints of one participant are discovered together; allow stragglers a moment.
        grace = min(deadline, time.monotonic() + 2.0)
        data = [p for key, p in self.pubs.items() if not topics.QOS[key].latched]
        while (
            keep_running()
            and time.monotonic() < grace
            and any(p.get_subscription_count() < self.wait_count for p in data)
        ):
            time.sleep(0.01)
        return True

    def wait_for_acks(self) -> bool:
        """Every subscriber acknowledged every message (False after ``wait_timeout_s`` or on
        a stop signal)."""
        return wait_for_acks(self.pubs.values(), self.wait_timeout)

    # --- playing ------------------------------------------------------------------------

    def start(self) -> None:
        self._wall0 = time.monotonic()
        self.pubs[topics.STATUS].publish(self._status(PLAYING))
        period = 0.0 if self.rate == 0 else self.log.frame_ms / 1000.0 / self.rate
        self.create_timer(max(period, 0.0), self._on_timer)

    def _status(self, state: str) -> Any:
        return status_message(
            state,
            self.frames_published,
            problems=len(self.log.problems),
            loops=self.loops,
            source=self.log.source,
            elapsed_s=round(time.monotonic() - self._wall0, 6),
            run=self.run_id,
        )

    def _on_timer(self) -> None:
        if self.done:
            return
        if self.rate == 0:
            # A batch of frames, then wait for every acknowledgement: the batch stays well
            # inside the publishers' history (DATA_QOS depth), so nothing is overwritten.
            for _ in range(self.ack_every):
                self._publish_tick(self.ticks[self._position] if self.ticks else None)
                if self.done or not self.ticks:
                    break
            if not self.wait_for_acks():
                self.get_logger().warning("subscribers did not acknowledge within the timeout")
        else:
            while not self.done and self.ticks and self._due(self.ticks[self._position]):
                self._publish_tick(self.ticks[self._position])
        if not self.ticks:
            self._finish()

    def _due(self, tick: Tick) -> bool:
        """Log time has reached ``tick`` (log time runs at ``rate`` from the first tick)."""
        elapsed_ms = (time.monotonic() - self._wall0) * 1000.0 * self.rate
        return tick.stamp_ms <= self.ticks[0].stamp_ms + elapsed_ms

    def _publish_tick(self, tick: Tick | None) -> None:
        if tick is None:
            return
        fast = self.fast_publish
        if self.publish_clock:
            stamp = tick.stamp_ms
            self.pubs[topics.CLOCK].publish(encode_clock(stamp) if fast else clock_message(stamp))
        # Same topics, order and bytes either way; the fast path skips rclpy message objects.
        messages: dict[str, Any] = (
            topics.frame_payloads(self.log, tick.stamp_ms)
            if fast
            else topics.frame_messages(self.log, tick.stamp_ms)
        )
        for key, msg in messages.items():
            self.pubs[key].publish(msg)
        for annotation in self.annotations.get(self._position, ()):
            note = annotation_message(annotation, run=self.run_id)
            self.pubs[topics.ANNOTATIONS].publish(encode_string(note.data) if fast else note)
        extra: dict[str, Any] = {"run": self.run_id}
        if dropped := dropped_plan_keys(self.log, tick.stamp_ms):
            extra["dropped_plan_keys"] = dropped
        paths = ego_path_document(self.log, tick.stamp_ms)
        if paths is not None:  # a snapshot table's row: its paths, and the frame marked so
            text = dumps_json({**paths, "run": self.run_id})
            self.pubs[topics.EGO_PATHS].publish(encode_string(text) if fast else String(data=text))
            extra["snapshot"] = paths["id"]
        names = published_names(messages)
        if self.publish_clock:
            names.insert(0, topics.CLOCK)
        marker = frame_marker(tick, names, self.log.frame_ms, **extra)
        self.pubs[topics.FRAME].publish(encode_string(marker.data) if fast else marker)
        self.frames_published += 1
        self._position += 1
        if self._position >= len(self.ticks):
            if self.loop:
                self._position = 0
                self.loops += 1
                self._wall0 = time.monotonic()
            else:
                self._finish()

    def _finish(self) -> None:
        self.done = True
        self.pubs[topics.STATUS].publish(self._status(FINISHED))
        self.get_logger().info(f"finished: {self.frames_published} frames published")


def main(args: list[str] | None = None) -> int:
    if not start_process("player", args):
        return 2
    node: Player | None = None
    try:
        try:
            node = Player()
        except AdsRcaError as error:  # a parameter or the log cannot be used
            get_logger("player").error(printable(error))
            return 2
        executor = make_executor()
        executor.add_node(node)
        node.wait_for_subscribers()
        if keep_running():
            node.start()
        while keep_running() and not (node.done and node.exit_on_end):
            executor.spin_once(timeout_sec=0.1)
        if keep_running() and not node.wait_for_acks():
            node.get_logger().warning("not every message was acknowledged before exit")
        return 0
    except (KeyboardInterrupt, ExternalShutdownException):
        return 0
    except RCLError:
        if rclpy.ok():
            raise
        return 0  # SIGINT/SIGTERM shut the context down in the middle of a call
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
        ignore_stop_signals()


if __name__ == "__main__":
    sys.exit(main())
