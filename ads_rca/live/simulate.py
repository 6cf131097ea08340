"""The live graph without DDS: a log played through four monitor cores and the aggregator.

Why: it runs the exact scheduling the nodes run (same classes, same order of events as the
player sends them) in one process, so tests and benchmarks can check the window logic
against ``diagnose`` quickly and deterministically, and try what DDS makes hard to stage
(a topic that stops, a collision announced late). Records go in as model objects: the
message conversion is tested separately (docs/topics.md).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from ads_rca.live.aggregate import AggregatorCore, VerdictOutcome
from ads_rca.live.results import FrameMarker, LiveResult
from ads_rca.live.window import MonitorCore, WindowSettings
from ads_rca.model import ALL_FOLDERS, FOLDERS, RunLog
from ads_rca.oracles.base import MODULES, Module
from ads_rca.params import Params

if TYPE_CHECKING:
    from ads_rca.live.episodes import EpisodeReport
    from ads_rca.live.stack_config import StackConfig
    from ads_rca.live.stack_feed import SkipReport, StackFeed

#: (folder, stamp_ms) -> deliver this record? (to simulate a topic that stops)
Filter = Callable[[str, int], bool]


@dataclass
class LiveRun:
    """What the simulated graph produced."""

    results: dict[Module, list[LiveResult]] = field(default_factory=dict)
    outcome: VerdictOutcome | None = None
    monitors: dict[Module, MonitorCore] = field(default_factory=dict)
    max_held_records: dict[Module, int] = field(default_factory=dict)
    #: Stack mode: every verdict, in order, and the feed (its sync's counts).
    verdicts: list[VerdictOutcome] = field(default_factory=list)
    feed: StackFeed | None = None
    #: Stack mode: each episode that ended (a later one began), in order.
    episodes: list[EpisodeReport] = field(default_factory=list)
    #: The results a monitor node publishes after the others of their poll
    #: (:meth:`MonitorCore.poll_in_order`).
    deferred: list[LiveResult] = field(default_factory=list)


def run_live(
    log: RunLog,
    params: Params,
    settings: WindowSettings | None = None,
    deliver: Filter | None = None,
    metadata_collision: bool = True,
    collision_event_after: int | None = None,
    clock_step_s: float = 0.001,
    drain_s: float = 60.0,
    shared: bool = False,
    judge_without_collision: bool = False,
) -> LiveRun:
    """Play ``log`` (its timeline, as the player does) through the live cores.

    ``metadata_collision`` False hides the collision frame from the metadata (a live stack)
    and announces it as an event after the frame with index ``collision_event_after`` (or at
    the end). After the last frame the clock advances until the verdict (at most ``drain_s``
    seconds of simulated time), so timeouts fire as they would. ``shared``: one core judges
    the four modules (the ``monitors`` process) instead of one core each.
    ``judge_without_collision``: the cores judge frames before the collision against the
    mode's provisional partner (stack mode).
    """
    from ads_rca.contract.playback import timeline

    clock = [0.0]

    def now() -> float:
        clock[0] += clock_step_s
        return clock[0]

    metadata = log.metadata
    if log.inputs:  # a recording's inputs reach the monitors in run/metadata's document
        metadata = replace(metadata, raw=log.metadata_document())
    if not metadata_collision:
        metadata = replace(metadata, collision_frame=-1)
    if shared:
        one = MonitorCore(MODULES, params, settings, judge_without_collision)
        monitors = {m: one for m in MODULES}
    else:
        monitors = {m: MonitorCore(m, params, settings, judge_without_collision) for m in MODULES}
    cores = list({id(core): core for core in monitors.values()}.values())
    aggregator = AggregatorCore(params)
    run = LiveRun(results={m: [] for m in MODULES}, monitors=monitors)

    def pump() -> None:
        for core in cores:
            deciding, later = core.poll_in_order(now())
            run.deferred.extend(later)
            # As the node publishes: what the verdict waits for first, the rest after.
            for part in (deciding, later):
                for result in part:
                    run.results[result.module].append(result)
                    aggregator.add_result(result, now())
                if run.outcome is None and part:
                    run.outcome = aggregator.poll(now())
            for module in core.modules:
                run.max_held_records[module] = max(
                    run.max_held_records.get(module, 0), core.held_records()
                )
        if run.outcome is None:
            run.outcome = aggregator.poll(now())

    for core in cores:  # the player's metadata message carries the reader's problems
        core.set_metadata(metadata, now(), log.problems)
    aggregator.set_metadata(metadata, log.source, now(), log.problems)
    announced = False
    for tick in timeline(log):
        folders = set()
        for folder in ALL_FOLDERS:
            record = log.folder(folder).get(tick.stamp_ms)
            if record is None:
                continue
            folders.add(folder)
            if deliver is not None and not deliver(folder, tick.stamp_ms):
                continue
            for core in cores:
                core.add_record(folder, tick.stamp_ms, record, now())
        marker = FrameMarker(tick.index, tick.stamp_ms, frozenset(folders), tick.duplicate)
        for core in cores:
            core.add_marker(marker, now())
        aggregator.add_marker(marker, now())
        pump()
        if (
            not announced
            and collision_event_after is not None
            and tick.index is not None
            and tick.index >= collision_event_after
            and log.metadata.collision_frame >= 0
        ):
            announce(cores, aggregator, log.metadata.collision_frame, now())
            announced = True
            pump()
    if not metadata_collision and not announced and log.metadata.collision_frame >= 0:
        announce(cores, aggregator, log.metadata.collision_frame, now())
    for core in cores:
        core.set_finished(now())
    aggregator.set_finished(now())
    deadline = clock[0] + drain_s
    while run.outcome is None and clock[0] < deadline:
        pump()
        clock[0] += 0.05
    return run


def announce(
    cores: list[MonitorCore], aggregator: AggregatorCore | None, frame: int, at: float
) -> None:
    """The collision event, as the monitors and (unless None) the aggregator hear it."""
    for core in cores:
        core.set_collision(frame, at)
    if aggregator is not None:
        aggregator.set_collision(frame, at)


# --- stack mode ------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class StackMessage:
    """One message as a stack sends it: its arrival time, input and payload (CDR bytes, or
    the message object for a layout read as objects, as :class:`StackFeed` takes it)."""

    arrival_s: float
    folder: str
    stamp_ms: int
    payload: Any


@dataclass
class StackStream:
    """A log as a stack publishes it, in arrival order, and what was left out."""

    messages: list[StackMessage]
    offsets_ms: dict[str, int]
    dropped: dict[str, list[int]]  # folder -> log stamps of the dropped messages
    collision_s: float | None  # arrival of the collision announcement (None: no crash)


def stack_stream(
    log: RunLog,
    seed: int = 0,
    max_offset_ms: int = 20,
    jitter_ms: float = 30.0,
    drop: dict[str, float] | None = None,
    reference: str = "pose",
) -> StackStream:
    """The contract messages of ``log`` stamped and delivered as a stack does:
    each input but the reference stamped at its frame's time plus a fixed per-input offset in
    [-max_offset_ms, max_offset_ms], each message arriving up to ``jitter_ms`` after its
    frame's time (so inputs and frames reorder), ``drop`` {folder: fraction} of an input's
    messages left out (deterministic from ``seed``), the collision announced after the last
    message of the collision frame."""
    from ads_rca.contract import topics

    rng = np.random.default_rng(seed)
    offsets = {
        f: 0 if f == reference else int(rng.integers(-max_offset_ms, max_offset_ms + 1))
        for f in FOLDERS
    }
    dropped: dict[str, list[int]] = {}
    messages: list[StackMessage] = []
    for topic in topics.DATA:
        if topic.optional:  # a stack's inputs are the running log's folders (stack_config)
            continue
        folder = str(topic.folder)
        stamps = sorted(log.folder(folder))
        fraction = (drop or {}).get(folder, 0.0)
        count = round(fraction * len(stamps))
        gone = set(rng.choice(stamps, size=count, replace=False).tolist()) if count else set()
        dropped[folder] = sorted(gone)
        for stamp in stamps:
            if stamp in gone:
                continue
            record = log.folder(folder)[stamp]
            payload = topic.codec.encode(record, stamp + offsets[folder], log.frame_ms)
            arrival = (stamp + float(rng.uniform(0.0, jitter_ms))) / 1000.0
            messages.append(StackMessage(arrival, folder, stamp + offsets[folder], payload))
    messages.sort(key=lambda m: m.arrival_s)
    collision_s = None
    if log.metadata.collision_frame >= 0:
        cf_ms = log.metadata.collision_frame * log.frame_ms
        collision_s = (
            max((m.arrival_s for m in messages if m.stamp_ms <= cf_ms + max_offset_ms), default=0.0)
            + 0.001
        )
    return StackStream(messages, offsets, dropped, collision_s)


def run_stack(
    log: RunLog,
    params: Params,
    stream: StackStream,
    config: StackConfig,
    settings: WindowSettings | None = None,
    drain_s: float = 60.0,
    collisions: Sequence[tuple[float, int]] | None = None,
    skipped: SkipReport | None = None,
    aggregator_hears: bool = True,
    warned: Callable[[MonitorCore], None] | None = None,
    writer: Callable[[StackMessage], bytes | None] | None = None,
) -> LiveRun:
    """Play ``stream`` through stack mode's cores: one :class:`MonitorCore` for the four
    modules fed by a :class:`StackFeed`, and the aggregator, on simulated time (the
    messages' arrival times). ``collisions``: the announcements, (arrival s, frame), by
    default the log's collision when the stream says (a run can collide several times);
    ``skipped`` hears of every message that could not be read; not ``aggregator_hears``:
    the announcements reach the monitors only (the aggregator matched the latched event
    too late); ``warned``: called with the core after each collision warning check, before
    it judges ahead (a test can name another actor as the threat); ``writer``: each
    message's publisher GID (None: unknown, as without it)."""
    from ads_rca.live.episodes import EpisodeAggregator, EpisodeReport
    from ads_rca.live.stack_feed import StackFeed

    core = MonitorCore(MODULES, params, settings, stack=True)
    feed = StackFeed(config, core, skipped or (lambda folder, error: None))
    aggregator = EpisodeAggregator(lambda: AggregatorCore(params, stack=config), stack=True)
    run = LiveRun(results={m: [] for m in MODULES}, monitors={m: core for m in MODULES})
    run.feed = feed

    def pump(now: float) -> None:
        ended = feed.poll(now)  # an ended episode's last results, then the current one's
        deciding, later = feed.core.poll_in_order(now)
        run.deferred.extend(later)
        for result in ended + deciding + later:
            run.results[result.module].append(result)
            aggregator.add_result(result, now)
        feed.core.collision_warnings()  # as the monitors node polls
        if warned is not None:
            warned(feed.core)
        feed.core.prepare()
        for module in core.modules:
            run.max_held_records[module] = max(
                run.max_held_records.get(module, 0), feed.core.held_records()
            )
        for event in aggregator.poll(now):
            if isinstance(event, EpisodeReport):
                run.episodes.append(event)
                continue
            run.verdicts.append(event)
            run.outcome = run.outcome or event

    if collisions is None:
        collisions = []
        if stream.collision_s is not None:
            collisions = [(stream.collision_s, log.metadata.collision_frame)]
    due = deque(sorted(collisions))

    def collide(frame: int, at: float) -> None:
        feed.set_collision(frame, at)
        if aggregator_hears:
            aggregator.set_collision(frame, at)

    now = 0.0
    for message in stream.messages:
        now = message.arrival_s
        while due and now >= due[0][0]:
            at, frame = due.popleft()
            collide(frame, at)
        if message.folder in feed.decoders:
            gid = writer(message) if writer is not None else None
            feed.add(message.folder, message.payload, now, gid)
        pump(now)
    for at, frame in due:
        now = max(now, at)
        collide(frame, now)
    deadline = now + drain_s
    while now < deadline and (
        len(run.verdicts) < len(collisions) or feed.core.pending or feed.ending is not None
    ):
        now += 0.05
        pump(now)
    return run


def stack_episodes(
    logs: Sequence[RunLog], gap_s: float = 1.0, **stream: Any
) -> tuple[StackStream, list[tuple[float, int]]]:
    """Several runs sent one after the other as one stack does when its simulator restarts:
    each run's own stamps (so they go back at each new episode), its messages arriving
    ``gap_s`` after the previous run's last message or collision announcement (negative:
    its first messages overlap the previous run's last ones); ``stream``:
    :func:`stack_stream`'s options. The stream and the collision announcements (arrival s,
    frame), in order."""
    messages: list[StackMessage] = []
    collisions: list[tuple[float, int]] = []
    dropped: dict[str, list[int]] = {}
    offsets: dict[str, int] = {}
    start = 0.0
    for log in logs:
        one = stack_stream(log, **stream)
        shift = start - min((m.arrival_s for m in one.messages), default=0.0)
        messages += [replace(m, arrival_s=m.arrival_s + shift) for m in one.messages]
        if one.collision_s is not None:
            collisions.append((one.collision_s + shift, log.metadata.collision_frame))
        for folder, stamps in one.dropped.items():
            dropped.setdefault(folder, []).extend(stamps)
        offsets = one.offsets_ms
        start = max(m.arrival_s for m in messages) + gap_s
        if collisions:
            start = max(start, collisions[-1][0] + gap_s)
    messages.sort(key=lambda m: m.arrival_s)
    return StackStream(messages, offsets, dropped, None), collisions
