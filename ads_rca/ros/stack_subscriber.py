"""Stack mode's subscriptions: a running stack's own topics into a monitor unit.

The thin rclpy shell of :class:`~ads_rca.live.stack_feed.StackFeed`: one subscription per
input the stack provides, of the type its layout names (CDR bytes for our contract's types,
message objects for the others), the collision topic, and a timer that releases what timed
out and judges what became ready (and the last frames of an episode that ended: the stamps
went back, :mod:`ads_rca.live.episodes`). On ``/diagnostics`` it says what the stack does
not give:
a module whose inputs the stack does not provide, or stopped providing, is STALE with the
reason (never OK), and a run fact found wrong (an ``ego_id`` never among the actors) is a
WARN status ``ads_rca/run_facts``. The reference topic's callback reads the MessageInfo:
its messages are taken from one writer only (:mod:`ads_rca.live.stack_guard`), passed on
when that writer left the graph; what was refused is logged and on every heartbeat.
"""

from __future__ import annotations

import importlib
import time
from collections import deque
from typing import TYPE_CHECKING, Any

from std_msgs.msg import String

from ads_rca.contract import live_topics, topics
from ads_rca.contract.errors import MalformedMessage
from ads_rca.contract.playback import read_document
from ads_rca.live import diagnostics as diag
from ads_rca.live.results import collision_frame
from ads_rca.live.runid import RunFilter
from ads_rca.live.stack_config import StackConfig
from ads_rca.live.stack_feed import StackFeed
from ads_rca.live.stack_guard import gid_text, writer_gid
from ads_rca.ros.diagnostics import array as diagnostic_array
from ads_rca.ros.qos_match import any_durability

if TYPE_CHECKING:
    from collections.abc import Callable

    from rclpy.node import Node
    from rclpy.qos import QoSProfile
    from rclpy.subscription import Subscription

    from ads_rca.ros.monitor import MonitorUnit

#: Status name of the run facts checked live.
FACTS_STATUS = "ads_rca/run_facts"


def message_class(type_name: str) -> type[Any]:
    """``package/msg/Type`` → the class (imported on first use)."""
    package, _, name = type_name.split("/")
    cls: type[Any] = getattr(importlib.import_module(f"{package}.msg"), name)
    return cls


#: A stack input's reader history. KEEP_LAST, so a slow monitor never slows the stack (no
#: back-pressure on its writers); deep, so a monitor held up (a loaded machine, a long
#: judgement) loses nothing it was sent: 1000 messages is 50 s of a 20 Hz topic. A reader
#: 100 deep lost a frame's messages in a CI run: DDS had acknowledged them.
STACK_READER_DEPTH = 1000
#: The reference topic's reader history: DDS keeps one history for every writer of a topic,
#: so another writer's flood (4,000 messages a second, issue 43) pushed the stack's own
#: messages out of a 1000-deep one on a loaded machine before the writer lock saw them.
#: Odometry is small (10,000 of them: about 7 MB); another reference input keeps the
#: default depth.
REFERENCE_READER_DEPTH = 10_000


def stack_qos(best_effort: bool, depth: int = STACK_READER_DEPTH) -> QoSProfile:
    """A stack's topics: KEEP_LAST ``depth``, reliable unless its publishers are best
    effort."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=depth,
        reliability=ReliabilityPolicy.BEST_EFFORT if best_effort else ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.VOLATILE,
    )


#: Stack mode auto: messages kept while deciding (the first frames of a stack's run).
MAX_WAITING = 10_000
#: How long after stack mode began an input's topic with no publisher is given up on, and
#: how often it is asked: DDS discovery on one machine takes up to ~2.5 s (environment.md),
#: longer under load. A publisher found later has its input awaited again (a companion
#: node, such as a predictor, may start after the stack).
DISCOVERY_GRACE_S = 3.0
PUBLISHER_CHECK_S = 0.5
#: The reference topic's writer lock passes on only when its writer is gone from the graph
#: and silent this long (the graph may lag a writer just heard); another writer's message
#: asks the graph at most this often (a flood of them must not).
WRITER_GONE_S = 0.5
WRITER_CHECK_S = 0.2


class StackSubscriber:
    """Subscribes ``node`` to the stack's inputs for ``unit`` (see the module docstring).

    ``decide`` (``stack_mode`` auto): until it returns True, asked on each message of the
    frame-defining input, messages are only kept (at most :data:`MAX_WAITING`); then stack
    mode starts with them. Subscribing from the start means no message is lost to the
    discovery of new subscriptions when a stack is found. :meth:`close` if it never is.
    """

    def __init__(
        self,
        node: Node,
        unit: MonitorUnit,
        config: StackConfig,
        decide: Callable[[], bool] | None = None,
    ) -> None:
        self.node = node
        self.unit = unit
        self.config = config
        self.decide = decide
        self.feed: StackFeed | None = None
        self.runs = RunFilter("")
        self.waiting: deque[tuple[str, Any, float, bytes | None]] = deque(maxlen=MAX_WAITING)
        self._writer_heard_at = 0.0  # the locked reference writer's last message
        self._writer_checked_at = 0.0
        self._guard_said = ""
        self._facts_said = 0
        self._facts_at = 0.0
        self._sync_at = 0.0
        self._started_at: float | None = None
        self._publishers_at = 0.0
        qos = stack_qos(config.best_effort)
        reference_qos = stack_qos(config.best_effort, REFERENCE_READER_DEPTH)
        folders = {*unit.core.folders, config.reference}
        self.topics = config.input_topics(folders)
        self.subscriptions = [
            node.create_subscription(
                message_class(config.inputs[folder].layout.type_name),
                topic,
                self._callback(folder),
                reference_qos if folder == config.reference == "pose" else qos,
                raw=config.inputs[folder].layout.raw,
            )
            for folder, topic in self.topics.items()
        ]
        if decide is None:
            self._start()

    def _start(self) -> None:
        """Stack mode from now on: the feed, the collision topic, the poll timer."""
        config, unit = self.config, self.unit
        feed = self.feed = StackFeed(config, unit.core, self._skip, self.topics[config.reference])
        for node in unit.nodes.values():
            node.guard = feed.guard  # the heartbeat says what it refused
        namespace = next(iter(unit.nodes.values())).namespace
        self.subscriptions.extend(
            listen_for_collisions(
                self.node, unit, namespace, self.runs, self._skip, collide=self._collide
            )
        )
        self.node.create_timer(unit.poll_period, self._poll)
        self.node.get_logger().info(
            "stack mode: frames from "
            f"{self.topics[config.reference]} stamps; inputs "
            + ", ".join(f"{f}={t}" for f, t in self.topics.items())
            + (f"; not provided: {', '.join(feed.unprovided)}" if feed.unprovided else "")
        )
        while self.waiting:
            folder, msg, now, writer = self.waiting.popleft()
            self._add(folder, msg, now, writer)

    def close(self) -> None:
        """Not a stack's run after all: unsubscribe, forget what was kept."""
        for sub in self.subscriptions:
            self.node.destroy_subscription(sub)
        self.subscriptions.clear()
        self.waiting.clear()
        self.decide = None

    def _callback(self, folder: str) -> Any:
        reference = folder == self.config.reference

        def on_message(msg: Any, info: Any) -> None:
            now = time.monotonic()
            writer = writer_gid(info) if reference else None
            if self.feed is not None:
                self._add(folder, msg, now, writer)
                if self.feed.core is not self.unit.core:  # a new episode began
                    self._follow()
                return
            self.waiting.append((folder, msg, now, writer))
            if reference and self.decide is not None and self.decide():
                self._start()

        if reference:  # the writer lock reads the MessageInfo
            return on_message
        return lambda msg: on_message(msg, None)

    def _add(self, folder: str, msg: Any, now: float, writer: bytes | None) -> None:
        """One message into the feed; the reference topic's from another writer than the
        locked one is skipped, unless the locked one has left the graph (a stack restarted
        as a new process): then the lock passes to this writer."""
        assert self.feed is not None
        if self.feed.add(folder, msg, now, writer):
            if folder == self.config.reference and writer is not None:
                self._writer_heard_at = now
            return
        if now - self._writer_checked_at >= WRITER_CHECK_S:
            self._writer_checked_at = now
            if self._release_gone_writer(now) and self.feed.add(folder, msg, now, writer):
                self._writer_heard_at = now

    def _release_gone_writer(self, now: float) -> bool:
        """Release the reference topic's writer lock when its writer is no longer among the
        topic's publishers and has been silent :data:`WRITER_GONE_S`; True if released."""
        assert self.feed is not None
        lock = self.feed.guard.lock
        if lock.writer is None or now - self._writer_heard_at < WRITER_GONE_S:
            return False
        topic = self.topics[self.config.reference]
        present = {bytes(p.endpoint_gid) for p in self.node.get_publishers_info_by_topic(topic)}
        if lock.writer in present:
            return False
        self.node.get_logger().info(
            f"the writer of {topic} ({gid_text(lock.writer)}) left the graph: the next one "
            "heard is taken"
        )
        lock.release()
        return True

    def _collide(self, frame: int, now: float) -> bool:
        """A collision heard: judged up to it at once, not at the next poll (the verdict
        waits for it); True when held frames are judged again. A repeat, or a flood of
        announcements, polls no more often than the timer would (a quarter period apart)."""
        assert self.feed is not None
        before = self.feed.core.collision_frame
        again = self.feed.set_collision(frame, now)
        changed = again or self.feed.core.collision_frame != before
        if changed and now - self.unit.last_poll >= self.unit.poll_period / 4:
            self._poll()
        return again

    def _poll(self) -> None:
        assert self.feed is not None
        now = time.monotonic()
        ended = self.feed.poll(now)  # an ended episode's last results: before the new one's
        self._follow()
        self.unit.publish(ended)
        self.unit.poll()
        self._say_facts()
        if now - self._publishers_at >= PUBLISHER_CHECK_S:
            self._publishers_at = now
            self._give_up_unpublished(now)
        if now - self._sync_at >= 1.0:  # what the sync dropped: at most a line a second
            self._sync_at = now
            news = self.feed.sync_news()
            if news is not None:
                self.node.get_logger().warning(news)
            self._say_guard()

    def _say_guard(self) -> None:
        """What the guard refused, a warning when it changed (the heartbeat says it too)."""
        assert self.feed is not None
        guard = self.feed.guard
        said = "; ".join(guard.lines())
        if said == self._guard_said:
            return
        self._guard_said = said
        writers = ", ".join(gid_text(w) for w in guard.lock.ignored)
        locked = gid_text(guard.lock.writer) if guard.lock.writer is not None else "none"
        who = f" (taken: {locked}; ignored: {writers})" if writers else ""
        self.node.get_logger().warning(f"stack inputs refused: {said}{who}")

    def _give_up_unpublished(self, now: float) -> None:
        """The inputs whose topic has no publisher :data:`DISCOVERY_GRACE_S` after stack
        mode began: the stack runs without them, so frames stop waiting for them (the
        modules that read them say so); a message of one brings it back."""
        if self._started_at is None:
            self._started_at = now
        if self.feed is None or now - self._started_at < DISCOVERY_GRACE_S:
            return
        published = {
            folder: self.node.count_publishers(self.topics[folder]) > 0
            for folder in self.feed.settings.inputs
        }
        self.feed.sync.give_up([f for f, yes in published.items() if not yes])
        self.feed.sync.resume([f for f, yes in published.items() if yes])

    def _follow(self) -> None:
        """The unit judges the current episode's core; what the feed says of episodes is
        logged."""
        assert self.feed is not None
        if self.feed.core is not self.unit.core:
            self.unit.use_core(self.feed.core)
        for line in self.feed.news:
            self.node.get_logger().info(line)
        self.feed.news.clear()

    def _skip(self, folder: str, error: str) -> None:
        topic = self.config.inputs[folder].topic if folder in self.config.inputs else folder
        line = self.unit.skipped.note(topic, error, time.monotonic())
        if line is not None:
            self.node.get_logger().warning(line)

    def _say_facts(self) -> None:
        """Each run fact found wrong: a warning once, a WARN status every second after."""
        problems = self.feed.fact_problems if self.feed is not None else []
        now = time.monotonic()
        if not problems or (len(problems) == self._facts_said and now - self._facts_at < 1.0):
            return
        self._facts_at = now
        for line in problems[self._facts_said :]:
            self.node.get_logger().warning(f"run fact: {line}")
        self._facts_said = len(problems)
        first = next(iter(self.unit.nodes.values()))
        status = diag.simple_status(
            FACTS_STATUS, diag.WARN, "; ".join(problems), first.hardware_id, {}
        )
        pub = first.diag_pub
        pub.publish(diagnostic_array(self.node.get_clock().now().to_msg(), [status]))


def listen_for_collisions(
    node: Node,
    unit: MonitorUnit,
    namespace: str,
    runs: RunFilter,
    skip: Callable[[str, str], None],
    collide: Callable[[int, float], bool] | None = None,
) -> list[Subscription[String]]:
    """Subscribe to ``run/collision``, latched or volatile publishers alike: each collision
    goes to ``collide`` (stack mode: the feed, which finds its episode), else the unit's core
    (which judges the held frames again, said once); an unreadable document is skipped and
    said."""

    def on_collision(msg: String) -> None:
        try:
            frame = collision_frame(read_document(msg), runs)
        except MalformedMessage as error:
            skip(live_topics.COLLISION, str(error))
            return
        if frame is None:
            return
        now = time.monotonic()
        if collide(frame, now) if collide is not None else unit.core.set_collision(frame, now):
            unit.logger.info(f"collision at frame {frame}: judging held frames again")

    name = topics.topic_name(live_topics.COLLISION, namespace)
    return any_durability(node, String, name, on_collision)


__all__ = ["FACTS_STATUS", "StackSubscriber", "listen_for_collisions"]
