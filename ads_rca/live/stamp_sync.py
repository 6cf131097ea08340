"""Frames from header stamps: a stack's topics grouped into frames with no player marker.

Why this exists: beside a real stack (stack mode) nobody announces frames. A
stack stamps each message with the time of the data it was computed from, a few ms apart
per topic (camera detections, predictions and plans come later than the odometry), and
DDS delivers them late, out of order or twice. :class:`StampSync` turns that stream into
frames:

- **Frames** are the header stamps of one reference topic (default the ego odometry).
- **Period** from ``timesteps_per_frame`` (``period_ms``), else measured: the median of the
  positive differences of the first ``measure_stamps`` reference stamps (sorted, so
  reordering and a dropped stamp do not move it).
- **Association**: every other input goes to the held frame whose stamp is nearest within
  ``sync_slop_ms`` (default half a period; a tie goes to the earlier frame); of several
  messages of one topic for one frame, the nearest (then the earlier stamp) is used and
  the others are counted ``unmatched``.
- **Release**, in stamp order: a frame is released complete when every expected input is
  in; or, ``input_timeout_s`` of monotonic time after its reference arrived, with what
  arrived, its missing topics named. Nothing is released early before ``measure_stamps``
  reference stamps were seen (the start settles, the period is measured); a frame more than
  1.5 periods after the last released one (a gap: the frame between may still come,
  reordered) waits for it until its own timeout.
- **Inputs never heard**: an input no message has come on is given up once a frame timed
  out waiting for it, or once the node finds no publisher of its topic
  (:meth:`StampSync.give_up`): later frames no longer wait for it (released ``absent``, the
  input named missing, so the modules that read it say so), until a message of it comes.
  A monitor that joined a stack running without one input lags one ``input_timeout_s`` at
  most, not every frame.
- **Late, duplicate**: a message whose nearest frame was already released (the newest
  released frame, or older) is dropped and counted ``late``; a second message with a stamp
  already held on its topic is dropped (the first kept) and counted ``duplicates``.
- **A flood**: once the period is known, a reference stamp less than half a period from a
  held or released frame's stamp (not equal to it: a duplicate) is dropped and counted
  ``crowded``: at most two frames a period, so thousands of messages a second on the
  reference topic cannot each become a frame and starve the real ones (issue 43).
- **Bounded memory**: at most ``max_pending_frames`` frames and as many messages per topic
  are held; past that the oldest frame is released (incomplete if it is) and counted
  ``overflow``, the oldest message dropped and counted ``dropped``.

Per message the work is a binary search over the held stamps (no pass over the data);
messages are held per topic in two parallel sorted lists, so what a release makes stale is
cut with one slice. Pure: no rclpy; :mod:`ads_rca.live.stack_feed` feeds the monitors through it.
"""

from __future__ import annotations

import bisect
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Generic, Literal, TypeVar

import numpy as np

from ads_rca.contract.topics import FOLDER_TOPICS
from ads_rca.errors import ConfigError

P = TypeVar("P")

#: The default reference: the topic that carries the ego pose (the ego odometry).
EGO_POSE_TOPIC = FOLDER_TOPICS["pose"]

#: Why a frame was released.
Reason = Literal["complete", "absent", "timeout", "overflow", "flush"]

#: A head frame after a gap of more than this many periods waits for the frame in between.
GAP_PERIODS = 1.5


@dataclass(frozen=True, slots=True)
class SyncSettings:
    """The parameters of stamp synchronisation (node parameters in stack mode)."""

    inputs: tuple[str, ...]  #: every expected topic but the reference
    reference: str = EGO_POSE_TOPIC
    period_ms: float | None = None  #: None: measured from the reference stamps
    sync_slop_ms: float | None = None  #: None: half a period
    input_timeout_s: float = 5.0
    max_pending_frames: int = 1200
    measure_stamps: int = 5

    def __post_init__(self) -> None:
        if self.reference in self.inputs:
            raise ConfigError(f"inputs: the reference topic {self.reference!r} is listed too")
        if len(set(self.inputs)) != len(self.inputs):
            raise ConfigError(f"inputs: a topic is listed twice in {list(self.inputs)}")
        positive = {
            "period_ms": self.period_ms,
            "sync_slop_ms": self.sync_slop_ms,
            "input_timeout_s": self.input_timeout_s,
        }
        for name, value in positive.items():
            if value is not None and not (np.isfinite(value) and value > 0):
                raise ConfigError(f"{name} must be a positive number, not {value!r}")
        for name, count, least in (
            ("max_pending_frames", self.max_pending_frames, 1),
            ("measure_stamps", self.measure_stamps, 2),
        ):
            if count < least:
                raise ConfigError(f"{name} must be at least {least}, not {count}")


@dataclass(frozen=True, slots=True)
class SyncedFrame(Generic[P]):
    """One released frame: its stamp, each input's payload and stamp, the topics missing."""

    stamp_ms: int
    inputs: dict[str, P]
    stamps: dict[str, int]
    missing: tuple[str, ...]
    reason: Reason
    #: When its reference message arrived (monotonic s): the frame's wait counts from it.
    arrived_s: float = 0.0

    @property
    def complete(self) -> bool:
        return not self.missing


@dataclass
class SyncCounts:
    """What was dropped or released early, for the node to report."""

    late: int = 0
    duplicates: int = 0
    unmatched: int = 0
    overflow: int = 0  #: frames released early because too many were held
    dropped: int = 0  #: messages dropped because too many were held on their topic
    incomplete: int = 0
    #: messages of an episode that had ended (stack mode's episodes, live/episodes.py)
    ended_episode: int = 0
    #: reference stamps implausibly far ahead, skipped (live/episodes.py ForwardJumps)
    implausible: int = 0
    #: reference stamps less than half a period from a frame's (a flood), skipped
    crowded: int = 0

    def text(self) -> str:
        """The non-zero counts, one line ('' when nothing was dropped)."""
        return ", ".join(f"{n} {COUNT_LABELS[name]}" for name, n in vars(self).items() if n)


#: What each of :class:`SyncCounts` counts, as the monitor node says it.
COUNT_LABELS = {
    "late": "late messages",
    "duplicates": "duplicate messages",
    "unmatched": "unmatched messages",
    "overflow": "frames released early (too many held)",
    "dropped": "messages dropped (too many held)",
    "incomplete": "frames released incomplete",
    "ended_episode": "messages of an ended episode dropped",
    "implausible": "reference stamps implausibly far ahead skipped",
    "crowded": "reference stamps within half a period of a frame skipped (a flood)",
}


@dataclass
class _Held(Generic[P]):
    """One topic's held messages: stamps ascending, payloads in the same order."""

    stamps: list[int] = field(default_factory=list)
    payloads: list[P] = field(default_factory=list)

    def add(self, stamp: int, payload: P) -> bool:
        """Insert; False (nothing inserted) when the stamp is already held."""
        at = bisect.bisect_left(self.stamps, stamp)
        if at < len(self.stamps) and self.stamps[at] == stamp:
            return False
        self.stamps.insert(at, stamp)
        self.payloads.insert(at, payload)
        return True

    def cut_through(self, stamp: float) -> int:
        """Drop every message stamped at or before ``stamp``; how many."""
        end = bisect.bisect_right(self.stamps, stamp)
        del self.stamps[:end], self.payloads[:end]
        return end

    def take(self, at: int) -> tuple[int, P]:
        return self.stamps.pop(at), self.payloads.pop(at)


def measure_period(stamps: Iterable[int]) -> float | None:
    """The median of the positive differences of the sorted stamps (None without any)."""
    ordered = np.unique(np.fromiter(stamps, dtype=np.int64))
    steps = np.diff(ordered)
    return float(np.median(steps)) if steps.size else None


def _nearest(stamps: list[int], target: int) -> int:
    """Index of the stamp nearest to ``target`` (the earlier on a tie; a handful of
    candidates: the messages of one topic within the slop of one frame)."""
    return int(np.argmin(np.abs(np.asarray(stamps, dtype=np.int64) - target)))


class StampSync(Generic[P]):
    """Feed every message with :meth:`add`, call :meth:`poll` on a timer; both return the
    frames released, in stamp order. :meth:`flush` releases what is held (end of run)."""

    def __init__(self, settings: SyncSettings) -> None:
        self.settings = settings
        self.period_ms = settings.period_ms
        #: The period measured from the first ``measure_stamps`` reference stamps (also when
        #: one is given: a stack's user checks it against the parameter).
        self.measured_ms: float | None = None
        self.counts = SyncCounts()
        self.released_ms: int | None = None  #: the newest released frame's stamp
        #: Reference messages dropped as late (their frames lost), of ``counts.late``.
        self.late_reference = 0
        self._frames = _Held[tuple[P, float]]()  # reference stamp -> (payload, arrival)
        self._held = {topic: _Held[P]() for topic in settings.inputs}
        self._seen: list[int] = []  # the first reference stamps, to measure the period
        self._heard: set[str] = set()  # inputs any message came on
        #: Inputs given up on (never heard; a frame timed out on them, or no publisher):
        #: frames do not wait for them until one of their messages comes.
        self.absent: set[str] = set()

    # --- feeding ---------------------------------------------------------------------

    def add(self, topic: str, stamp_ms: int, payload: P, now_s: float) -> list[SyncedFrame[P]]:
        """One message (``now_s``: monotonic arrival time); the frames it releases."""
        if topic == self.settings.reference:
            self._add_reference(stamp_ms, payload, now_s)
        elif topic in self._held:
            self._add_input(topic, stamp_ms, payload)
        else:
            raise ConfigError(f"topic {topic!r} is not an input of the stamp sync")
        return self.poll(now_s)

    def _add_reference(self, stamp: int, payload: P, now_s: float) -> None:
        if self.released_ms is not None and stamp <= self.released_ms:
            self.counts.late += 1
            self.late_reference += 1
            return
        if self._crowded(stamp):
            self.counts.crowded += 1
            return
        if not self._frames.add(stamp, (payload, now_s)):
            self.counts.duplicates += 1
            return
        if len(self._seen) < self.settings.measure_stamps:
            self._seen.append(stamp)
            if len(self._seen) == self.settings.measure_stamps:
                self.measured_ms = measure_period(self._seen)
                if self.period_ms is None:
                    self.period_ms = self.measured_ms

    def _crowded(self, stamp: int) -> bool:
        """Whether ``stamp`` lies less than half a period from a held or released frame's
        stamp but is not that stamp (a duplicate): a frame rate far above the period's
        (a flood on the reference topic) would otherwise make a frame of every message and
        starve the real ones. Frames are at most two a period; until the period is known,
        nothing is crowded."""
        if self.period_ms is None:
            return False
        half = self.period_ms / 2
        frames = self._frames.stamps
        at = bisect.bisect_left(frames, stamp)
        near = [frames[i] for i in (at - 1, at) if 0 <= i < len(frames)]
        if self.released_ms is not None:
            near.append(self.released_ms)
        return any(0 < abs(stamp - other) < half for other in near)

    def on_grid(self, stamp: int) -> bool:
        """Whether ``stamp`` is where the stream's next frames fall: the period is known and
        the stamp lies within a tenth of a period of the newest frame's stamp plus a whole
        number of periods (a stamp between two frames is not)."""
        frames = self._frames.stamps
        anchor = frames[-1] if frames else self.released_ms
        if self.period_ms is None or anchor is None:
            return False
        phase = (stamp - anchor) / self.period_ms
        return abs(phase - round(phase)) * self.period_ms <= self.period_ms / 10

    def _add_input(self, topic: str, stamp: int, payload: P) -> None:
        self._heard.add(topic)
        self.absent.discard(topic)
        if self.is_late(stamp):
            self.counts.late += 1
            return
        held = self._held[topic]
        if not held.add(stamp, payload):
            self.counts.duplicates += 1
            return
        if len(held.stamps) > self.settings.max_pending_frames:
            held.take(0)
            self.counts.dropped += 1

    def is_late(self, stamp: int) -> bool:
        """Whether the frame nearest to ``stamp`` was already released (a message of
        another input stamped so is dropped as late)."""
        last = self.released_ms
        if last is None or stamp > last + self.slop_ms:
            return False
        if stamp <= last:
            return True
        frames = self._frames.stamps
        return not frames or frames[0] - stamp >= stamp - last

    # --- releasing -------------------------------------------------------------------

    @property
    def slop_ms(self) -> float:
        """The association window (0 until the period is known, when none is set)."""
        if self.settings.sync_slop_ms is not None:
            return self.settings.sync_slop_ms
        return self.period_ms / 2 if self.period_ms is not None else 0.0

    def poll(self, now_s: float) -> list[SyncedFrame[P]]:
        """The frames releasable at ``now_s``, in stamp order."""
        out: list[SyncedFrame[P]] = []
        while self._frames.stamps:
            head = self._frames.stamps[0]
            arrived = self._frames.payloads[0][1]
            picks = self._picks(head)
            awaited = [t for t in self._held if t not in picks and t not in self.absent]
            if not awaited and self._may_release_early(head):
                reason: Reason = "complete" if len(picks) == len(self._held) else "absent"
            elif now_s - arrived >= self.settings.input_timeout_s:
                reason = "timeout"
                self.give_up(awaited)
            elif len(self._frames.stamps) > self.settings.max_pending_frames:
                self.counts.overflow += 1
                reason = "overflow"
            else:
                break
            out.append(self._release(picks, reason))
        return out

    def give_up(self, topics: Iterable[str]) -> None:
        """Stop waiting for those of ``topics`` that never had a message (the node found no
        publisher of them, or a frame timed out on them)."""
        self.absent.update(t for t in topics if t in self._held and t not in self._heard)

    def resume(self, topics: Iterable[str]) -> None:
        """Wait again for those of ``topics`` given up on (a publisher of them was found)."""
        self.absent.difference_update(topics)

    def flush(self) -> list[SyncedFrame[P]]:
        """Release every held frame with what arrived (the end of a run)."""
        out: list[SyncedFrame[P]] = []
        while self._frames.stamps:
            picks = self._picks(self._frames.stamps[0])
            reason: Reason = "complete" if len(picks) == len(self._held) else "flush"
            out.append(self._release(picks, reason))
        return out

    def _may_release_early(self, head: int) -> bool:
        """A complete head goes at once unless a frame before it may still arrive."""
        if len(self._seen) < self.settings.measure_stamps or self.period_ms is None:
            return False
        last = self.released_ms
        return last is None or head - last <= GAP_PERIODS * self.period_ms

    def _picks(self, head: int) -> dict[str, int]:
        """Per input topic, the index of the held message associated with ``head``."""
        slop = self.slop_ms
        frames = self._frames.stamps
        # Messages nearer to the next frame belong to it (a tie to the earlier frame).
        upper = min(head + slop, (head + frames[1]) / 2) if len(frames) > 1 else head + slop
        picks: dict[str, int] = {}
        for topic, held in self._held.items():
            lo = bisect.bisect_left(held.stamps, head - slop)
            hi = bisect.bisect_right(held.stamps, upper)
            if lo < hi:
                picks[topic] = lo + _nearest(held.stamps[lo:hi], head)
        return picks

    def _release(self, picks: dict[str, int], reason: Reason) -> SyncedFrame[P]:
        """Release the head frame with ``picks``; drop what can no longer match a frame."""
        head, (payload, arrived) = self._frames.take(0)
        inputs = {self.settings.reference: payload}
        stamps = {self.settings.reference: head}
        for topic, at in picks.items():
            stamps[topic], inputs[topic] = self._held[topic].take(at)
        self.released_ms = head
        # Held messages nearer to this frame than to the next held one are now late.
        frames = self._frames.stamps
        stale = (head + frames[0]) / 2 if frames else head + self.slop_ms
        for held in self._held.values():
            self.counts.unmatched += held.cut_through(min(stale, head + self.slop_ms))
        missing = tuple(t for t in self.settings.inputs if t not in picks)
        self.counts.incomplete += bool(missing)
        return SyncedFrame(head, inputs, stamps, missing, reason, arrived)

    # --- state -----------------------------------------------------------------------

    @property
    def first_held_ms(self) -> int | None:
        """The oldest held frame's stamp (None: none held)."""
        return self._frames.stamps[0] if self._frames.stamps else None

    @property
    def held_frames(self) -> int:
        return len(self._frames.stamps)

    @property
    def held_messages(self) -> int:
        return sum(len(held.stamps) for held in self._held.values())
