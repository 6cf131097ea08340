"""Stack mode's front end: a stack's messages into a monitor core, frame by frame.

The player announces frames and the run's metadata; a stack does neither. :class:`StackFeed`
does it from the stack's own topics: each message's stamp is read on arrival, the
:class:`~ads_rca.live.stamp_sync.StampSync` groups the inputs into frames of the reference
input's header stamps, and each released frame goes to the
:class:`~ads_rca.live.window.MonitorCore` as the player's would: its records, re-keyed to the
frame's stamp, then its marker (index ``round(stamp / period)``), with the inputs that did
not come marked missing. The metadata comes from the parameters (:class:`StackConfig`),
its period given or measured. A collision (``run/collision``) closes the frames before it
once the sync has released the frame at the collision (or ``input_timeout_s`` after the
collision was heard). Run facts that can be checked live are checked: an ``ego_id`` that
never appears among the actors, a measured period far from ``timesteps_per_frame``.

Episodes (:mod:`ads_rca.live.episodes`): reference stamps going back by more than
``episode_rewind_s`` begin a new episode with a fresh core, stamp sync and decoders (the
frames, windows, partner and collisions of the old one are never seen by the new one). The
old episode ends: for ``input_timeout_s`` its late messages still reach it and it is
judged as they come, then its held frames are released, its collision closed,
and it is judged to its end; :meth:`StackFeed.poll` returns its results. Every result
carries its episode's number.

The reference input is guarded (:mod:`ads_rca.live.stack_guard`, issue 43): only its first
writer is taken, a NaN/inf pose never makes a frame, a forward jump is confirmed only when
another input moved on too, and what was refused is counted over every episode
(:attr:`StackFeed.guard`, for the monitors' heartbeat). Pure: no rclpy; the monitor node
is a thin shell over it.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from ads_rca.contract.errors import MalformedMessage, NoStamp
from ads_rca.contract.stack_layouts import Decoder
from ads_rca.live.episodes import NEW, NEXT, PREVIOUS, EpisodeClock, ForwardJumps
from ads_rca.live.results import FrameMarker, LiveResult
from ads_rca.live.stack_config import StackConfig, period_to_frame_ms
from ads_rca.live.stack_guard import StackGuard, pose_problem
from ads_rca.live.stamp_sync import StampSync, SyncedFrame
from ads_rca.live.window import MonitorCore
from ads_rca.model import OPTIONAL_FOLDERS, Actors, Record

#: Frames with actors after which an ``ego_id`` never seen among them is reported.
EGO_CHECK_FRAMES = 20
#: A measured period further than this (relative) from ``timesteps_per_frame`` is reported.
PERIOD_TOLERANCE = 0.1

#: Called with (folder, error text) for a message that could not be read.
SkipReport = Callable[[str, str], None]


@dataclass
class _Episode:
    """One episode's own state: its window, its stamp sync, its decoders (a PoseStamped's
    speed reads the pose before it) and the stamp its frame numbers count from."""

    number: int
    core: MonitorCore
    sync: StampSync[Any]
    decoders: dict[str, Decoder]
    origin_ms: int | None = None
    ended_at: float | None = None  #: when a later episode began


class StackFeed:
    """Feed :meth:`add` every stack message and call :meth:`poll` on a timer; judge and
    publish :attr:`core` (the current episode's) and what :meth:`poll` returns."""

    def __init__(
        self,
        config: StackConfig,
        core: MonitorCore,
        skipped: SkipReport,
        reference_topic: str = "",
    ) -> None:
        self.config = config
        self.skipped = skipped
        folders = {*core.folders, config.reference}
        self.settings = config.sync_settings(folders)
        #: What was refused on the inputs, over every episode (live/stack_guard.py).
        self.guard = StackGuard(reference_topic or config.reference)
        self.expected = (config.reference, *self.settings.inputs)
        #: The judged modules' inputs the stack does not provide (their results say so).
        #: A stack's inputs are the seed format's folders; the optional ones of recordings
        #: (3-D objects, control) are not stack inputs, so never awaited.
        self.unprovided = tuple(
            f for f in core.folders if f not in config.inputs and f not in OPTIONAL_FOLDERS
        )
        #: Run facts found wrong while running (one line each), for /diagnostics.
        self.fact_problems: list[str] = []
        #: One line per episode begun or ended, for the node to log (taken by the node).
        self.news: list[str] = []
        self._frames_with_actors = 0
        self._ego_seen = not config.ego_id
        self._period_checked = False
        self._sync_said = ""  # the sync's counts as last said
        self.clock = EpisodeClock(config.episode_rewind_s * 1000.0)
        # A jump is confirmed by the other inputs moving on too (when there are any).
        self.jumps = ForwardJumps(config.stamp_jump_s * 1000.0, bool(self.settings.inputs))
        self.episode = self._episode(1, core)
        #: The episode before, while its late messages still come (None: none).
        self.ending: _Episode | None = None
        #: Inputs and collisions of an episode whose first reference stamp has not come
        #: yet (DDS does not order topics): (folder, payload, arrival) and (frame, arrival).
        self._ahead: deque[tuple[str, Any, float]] = deque(maxlen=config.max_pending_frames)
        self._collisions_ahead: list[tuple[int, float]] = []
        self._retired: list[LiveResult] = []

    @property
    def core(self) -> MonitorCore:
        """The current episode's window (the one to poll and publish)."""
        return self.episode.core

    @property
    def sync(self) -> StampSync[Any]:
        return self.episode.sync

    @property
    def decoders(self) -> dict[str, Decoder]:
        return self.episode.decoders

    def _episode(self, number: int, core: MonitorCore) -> _Episode:
        """Episode ``number`` on ``core``, set up from the parameters."""
        config = self.config
        core.episode = number
        core.derived = config.derived()
        if config.ego_id:
            core.ego_id, core.ego_resolved = config.ego_id, True
        if config.timesteps_per_frame:
            core.set_metadata(config.metadata(config.timesteps_per_frame), 0.0)
            core.last_input = None  # no input yet: the stack may start much later
        decoders = {f: Decoder(f, config.inputs[f].layout.name) for f in self.expected}
        return _Episode(number, core, StampSync(self.settings), decoders)

    def add(self, folder: str, payload: Any, now: float, writer: bytes | None = None) -> bool:
        """One received message of ``folder``'s topic (``now``: monotonic seconds;
        ``writer``: its publisher GID, None when unknown). False when it was refused as
        another writer's on the reference topic (the node may find the locked writer gone:
        :meth:`~ads_rca.live.stack_guard.WriterLock.release`, then add it again)."""
        reference = folder == self.config.reference
        if reference and not self.guard.lock.accept(writer):
            return False  # before it is read: a flood of them costs little
        decoder = self.decoders[folder]
        try:
            stamp = decoder.stamp_ms(payload)
            numbers = decoder.pose_numbers(payload) if reference else None
        except NoStamp:  # an empty MarkerArray: nothing seen, nothing to judge
            return True
        except MalformedMessage as error:
            self.skipped(folder, str(error))
            return True
        if reference:
            problem = pose_problem(numbers) if numbers is not None else None
            # A NaN pose makes no frame of its own; on the stream's grid its frame is
            # still the stack's, judged incomplete (its pose record reported missing).
            if problem is not None and not self.sync.on_grid(stamp):
                self.guard.malformed += 1
                self.skipped(folder, problem)
                return True
            if self.jumps.check(stamp, self.clock.newest_ms) == "skipped":
                self.sync.counts.implausible += 1  # a clock glitch must not move the grid
                self.guard.implausible += 1
                return True
            place = self.clock.reference(stamp)
            if place == NEW:
                self._begin(stamp, now)
        else:
            self.jumps.other(stamp, self.clock.newest_ms)
            place = self.clock.place(stamp)
            if place == NEXT and self.sync.is_late(stamp):  # the next episode's, maybe
                self._ahead.append((folder, payload, now))
                return True
        episode = self.ending if place == PREVIOUS else self.episode
        if episode is None:
            self.sync.counts.ended_episode += 1
            return True
        episode.core.last_input = now
        sync = episode.sync
        late, late_reference, crowded = sync.counts.late, sync.late_reference, sync.counts.crowded
        frames = sync.add(folder, stamp, payload, now)
        lost = sync.late_reference - late_reference
        self.guard.count_late(lost, sync.counts.late - late - lost, now)
        self.guard.crowded += sync.counts.crowded - crowded
        self._feed(episode, frames, now)
        return True

    def set_collision(self, frame: int, now: float) -> bool:
        """A collision heard: the current episode's, unless its frame lies more than the
        bound before this episode's stamps (an episode whose data are not here yet: it
        waits for it). Never the ending episode's: a stack announces a collision after its
        frame's data, so one stamped ahead of the data judged so far is this episode's, its
        data still queued; True when held frames are judged again."""
        frame_ms = self._frame_ms()
        if frame_ms and self.clock.place(frame * frame_ms) == NEXT:
            self._collisions_ahead.append((frame, now))
            return False
        return self.core.set_collision(frame, now)

    def poll(self, now: float) -> list[LiveResult]:
        """Release what timed out; close the frames before a collision once all are in.
        Returns the last results of an episode that ended (publish them before the
        current core's)."""
        ending = self.ending
        if ending is not None:
            self._feed(ending, ending.sync.poll(now), now)
            self._close_collision(ending, now)
            self._retired.extend(ending.core.poll(now))
            if now - (ending.ended_at or now) >= self.config.input_timeout_s:
                self._retire(now)
        self._expire_ahead(now)
        episode = self.episode
        self._feed(episode, episode.sync.poll(now), now)
        self._close_collision(episode, now)
        out, self._retired = self._retired, []
        return out

    def _close_collision(self, episode: _Episode, now: float) -> None:
        """Close the frames before the collision once its frame was released (or
        ``input_timeout_s`` after it was heard, when no frame before it is held)."""
        core, sync = episode.core, episode.sync
        if core.collision_frame < 0 or core.horizon_closed or core.metadata is None:
            return
        cf_ms = core.collision_frame * core.metadata.timesteps_per_frame
        released = sync.released_ms
        slop = sync.slop_ms
        waited = core.collision_at is not None and now - core.collision_at >= (
            self.config.input_timeout_s
        )
        first_held = sync.first_held_ms
        held_before = first_held is not None and first_held <= cf_ms + slop
        # Waited long enough, but a frame before the collision still held is still to come.
        if (released is not None and released >= cf_ms - slop) or (waited and not held_before):
            core.close_horizon()

    def sync_news(self) -> str | None:
        """One line when the stamp sync dropped or released early more than last said
        (late, duplicate, unmatched messages; frames released incomplete); else None."""
        said = self.sync.counts.text()
        if self.episode.number > 1 and said:
            said = f"(episode {self.episode.number}) {said}"
        if said == self._sync_said:
            return None
        self._sync_said = said
        return f"stamp sync so far: {said}"

    def flush(self, now: float) -> None:
        """Release every held frame (the node is stopping, or a test's run ended); an
        ending episode is judged to its end (its results: the next :meth:`poll`)."""
        if self.ending is not None:
            self._retire(now)
        self._feed(self.episode, self.sync.flush(), now)

    # --- episodes ------------------------------------------------------------------------

    def _begin(self, stamp: int, now: float) -> None:
        """The reference stamp ``stamp`` went back: a new episode, on a fresh core."""
        if self.ending is not None:
            self._retire(now)
        ended = self.ending = self.episode
        ended.ended_at = now
        old = ended.core
        core = MonitorCore(
            old.modules,
            old.params,
            old.settings,
            stack=True,
            judge_without_collision=old.judge_without_collision,
        )
        core.run, core.session, core.tracebacks = old.run, old.session, old.tracebacks
        self.episode = self._episode(self.clock.number, core)
        previous = self.clock.previous_ms
        self.news.append(
            f"episode {self.episode.number} began: the {self.config.reference} stamps went "
            f"back from {previous} ms to {stamp} ms; episode {ended.number} ends"
        )
        ahead, self._ahead = list(self._ahead), deque(maxlen=self._ahead.maxlen)
        for folder, payload, arrived in ahead:
            self.add(folder, payload, arrived)
        collisions, self._collisions_ahead = self._collisions_ahead, []
        for frame, heard in collisions:
            self.set_collision(frame, heard)

    def _retire(self, now: float) -> None:
        """The ending episode takes nothing more: its held frames released, its collision
        closed (nothing more will come), judged to its end; its results for :meth:`poll`."""
        ending, self.ending = self.ending, None
        assert ending is not None
        self.clock.close_previous()
        self._feed(ending, ending.sync.flush(), now)
        core = ending.core
        if core.collision_frame >= 0:
            core.close_horizon()
        core.set_finished(now)
        self._retired.extend(core.poll(now))
        counts = ending.sync.counts.text()
        self.news.append(
            f"episode {ending.number} closed: {core.stats.evaluated} frames judged"
            + (f"; its stamp sync: {counts}" if counts else "")
        )

    def _expire_ahead(self, now: float) -> None:
        """What waited ``input_timeout_s`` for an episode that did not begin: messages are
        late (dropped, counted), collisions go to the current episode."""
        timeout = self.config.input_timeout_s
        while self._ahead and now - self._ahead[0][2] >= timeout:
            self._ahead.popleft()
            self.sync.counts.late += 1
            self.guard.count_late(0, 1, now)
        due = [c for c in self._collisions_ahead if now - c[1] >= timeout]
        self._collisions_ahead = [c for c in self._collisions_ahead if now - c[1] < timeout]
        for frame, heard in due:
            self.core.set_collision(frame, heard)

    def _frame_ms(self) -> int | None:
        """The current episode's frame period (ms), once known."""
        metadata = self.core.metadata
        if metadata is not None:
            return metadata.timesteps_per_frame
        period = self.sync.period_ms
        return period_to_frame_ms(period) if period is not None else None

    # --- frames into the core ----------------------------------------------------------

    def _feed(self, episode: _Episode, frames: list[SyncedFrame[Any]], now: float) -> None:
        if not frames:
            return
        core, sync = episode.core, episode.sync
        if core.metadata is None:
            assert sync.period_ms is not None  # nothing is released before it is known
            core.set_metadata(self.config.metadata(period_to_frame_ms(sync.period_ms)), now)
        self._check_period(sync)
        assert core.metadata is not None
        frame_ms = core.metadata.timesteps_per_frame
        period = sync.period_ms or float(frame_ms)
        wanted = frozenset((*self.expected, *self.unprovided))
        for frame in frames:
            for folder, payload in frame.inputs.items():
                try:
                    record = episode.decoders[folder].record(payload, frame_ms)
                except MalformedMessage as error:
                    self.skipped(folder, str(error))
                    continue
                core.add_record(folder, frame.stamp_ms, record, now)
                if folder == "actors":
                    self._check_ego(record)
            if episode.origin_ms is None:
                episode.origin_ms = frame.stamp_ms
            index = round((frame.stamp_ms - episode.origin_ms) / period)
            # Its wait (and the verdict's latency) counts from its reference's arrival, the
            # time the sync held it for its inputs included.
            core.add_marker(FrameMarker(index, frame.stamp_ms, wanted), now, frame.arrived_s)

    def _check_ego(self, record: Record) -> None:
        if self._ego_seen or not isinstance(record, Actors):
            return
        if self.config.ego_id in record.index:
            self._ego_seen = True
            return
        self._frames_with_actors += 1
        if self._frames_with_actors == EGO_CHECK_FRAMES:
            self.fact_problems.append(
                f"ego_id {self.config.ego_id!r} is not among the actors of the first "
                f"{EGO_CHECK_FRAMES} frames"
            )

    def _check_period(self, sync: StampSync[Any]) -> None:
        given, measured = self.config.timesteps_per_frame, sync.measured_ms
        if self._period_checked or not given or measured is None:
            return
        self._period_checked = True
        if abs(measured - given) > PERIOD_TOLERANCE * given:
            self.fact_problems.append(
                f"timesteps_per_frame is {given} ms but the reference input's stamps are "
                f"{measured:g} ms apart"
            )
