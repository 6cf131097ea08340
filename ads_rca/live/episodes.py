"""Episodes in stack mode: a stack or simulator that restarts its clock begins a new run.

Why: beside a running stack nobody says that a run began again. When a simulator resets
(a new episode from stamp 0) or a stack restarts from an earlier time, the header stamps
jump back. Taken as one run, the new episode's frames were dropped as late (their stamps
were already released), or its crash was judged on the previous episode's data (another
partner) and called complete. So the reference input's header stamps are watched: going
back by more than ``episode_rewind_s`` begins a new episode, numbered 1, 2, ... Each node
keeps each episode's state apart (frames, windows, partner, collisions, stamp sync) and
closes the old one: its pending collision is still decided on its own data, then it is
forgotten. /clock is not read: the simulator's restart shows in the stamps it gives the
ego pose, and a stack stamping with wall time beside a simulated /clock would otherwise
begin an episode at every tick.

:class:`EpisodeClock` is the rule, for the monitors (:mod:`ads_rca.live.stack_feed`): per
message, which episode its stamp belongs to. DDS does not order topics, so a message of
the episode that just ended can come after the first of the new one (``PREVIOUS``: given to
the ending episode, never to the new one), and one of a new episode can come before the
reference stamp that begins it (``NEXT``: held until it does).

:class:`EpisodeAggregator` is the aggregator's side. The monitors number the episodes and
every result carries its number; the aggregator keeps one
:class:`~ads_rca.live.aggregate.AggregatorCore` per episode, keyed by that number, so a
result of the old episode that arrives after the new one began still goes to the old one.
A collision heard on ``run/collision`` names only a frame: it is given to the episode
whose monitors judged with it (their results carry its frame), so a new episode's crash
heard before any of its results is not taken for the old episode's. Pure: no rclpy.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Literal

from ads_rca.live.aggregate import AggregatorCore, VerdictOutcome
from ads_rca.live.results import LiveResult
from ads_rca.model import frame_number

#: Where a stamp belongs: this episode, a new one it begins (a reference stamp), the
#: episode before (a late message of it), or an episode not begun here yet.
Place = Literal["current", "new", "previous", "next"]
CURRENT: Place = "current"
NEW: Place = "new"
PREVIOUS: Place = "previous"
NEXT: Place = "next"


@dataclass
class EpisodeClock:
    """The episode rule over one stream of stamps (see the module docstring)."""

    rewind_ms: float  #: stamps going back by more than this begin an episode (0: never)
    number: int = 1
    newest_ms: int | None = None  #: this episode's newest reference stamp
    #: The episode before's newest reference stamp, while its late messages are taken.
    previous_ms: int | None = None

    def reference(self, stamp_ms: int) -> Place:
        """A reference stamp: ``NEW`` when it goes back by more than the bound (it begins
        the next episode), ``PREVIOUS`` for a late one of the episode before, else
        ``CURRENT`` (this episode's newest moves on)."""
        place = self.place(stamp_ms)
        if place == NEXT:
            self.previous_ms, self.newest_ms = self.newest_ms, stamp_ms
            self.number += 1
            return NEW
        if place == CURRENT and (self.newest_ms is None or stamp_ms > self.newest_ms):
            self.newest_ms = stamp_ms
        return place

    def place(self, stamp_ms: int) -> Place:
        """Any other stamp (an input's, a collision frame's), the clock unmoved: ``NEXT``
        when it is more than the bound before this episode's newest reference stamp,
        ``PREVIOUS`` when it lies more than the bound after it but within the previous
        episode's stamps, else ``CURRENT``."""
        newest, bound = self.newest_ms, self.rewind_ms
        if bound <= 0 or newest is None:
            return CURRENT
        if stamp_ms < newest - bound:
            return NEXT
        previous = self.previous_ms
        if previous is not None and newest + bound < stamp_ms <= previous + bound:
            return PREVIOUS
        return CURRENT

    def close_previous(self) -> None:
        """The episode before takes no more messages (theirs are dropped from now on)."""
        self.previous_ms = None


#: Reference stamps in a row, each near the one before, that confirm a forward jump.
JUMP_CONFIRM = 3
#: What :meth:`ForwardJumps.check` says of a reference stamp.
Jump = Literal["plausible", "skipped", "confirmed"]


@dataclass
class ForwardJumps:
    """Reference stamps implausibly far ahead (issue 41): one odometry message stamped
    2^32 s ahead moved the frame grid, and every later real message was dropped as late.
    A stamp more than ``jump_ms`` ahead of the newest accepted one is skipped and counted,
    unless it is the :data:`JUMP_CONFIRM`-th such stamp in a row, each within ``jump_ms``
    after the one before, and the stack's other inputs moved on too (with ``corroborate``:
    a message of another input stamped within ``jump_ms`` of the candidates, told by
    :meth:`other`): then the jump is real (a stack that moved its clock on), that stamp is
    taken and the grid follows it; the ones before it stay skipped. A plausible stamp in
    between discards the candidates. ``jump_ms`` 0: never skip.

    Why the other inputs (issue 43): three messages in a row stamped far ahead, a clock
    glitch of the odometry alone (wall time beside simulated time) or a forged writer,
    confirmed the jump and blinded the monitors for the rest of the run; a stack whose
    clock really moved on stamps its other topics ahead as well."""

    jump_ms: float
    #: Whether a confirmation needs another input stamped near the candidates.
    corroborate: bool = False
    #: The candidate jump's stamps so far.
    candidates: list[int] = field(default_factory=list)
    skipped: int = 0
    confirmed: int = 0
    #: The newest other input's stamp that lay more than ``jump_ms`` ahead (None: none).
    ahead_ms: int | None = None

    def check(self, stamp_ms: int, newest_ms: int | None) -> Jump:
        """``stamp_ms``, a reference stamp, against the episode's newest accepted one."""
        if self.jump_ms <= 0 or newest_ms is None or stamp_ms - newest_ms <= self.jump_ms:
            self.candidates.clear()
            return "plausible"
        last = self.candidates[-1] if self.candidates else None
        if last is not None and not 0 < stamp_ms - last <= self.jump_ms:
            self.candidates.clear()
        self.candidates.append(stamp_ms)
        moved = self.ahead_ms is not None and abs(self.ahead_ms - stamp_ms) <= self.jump_ms
        if len(self.candidates) < JUMP_CONFIRM or (self.corroborate and not moved):
            self.skipped += 1
            return "skipped"
        self.candidates.clear()
        self.ahead_ms = None
        self.confirmed += 1
        return "confirmed"

    def other(self, stamp_ms: int, newest_ms: int | None) -> None:
        """Another input's stamp: one more than ``jump_ms`` ahead of the newest reference
        stamp may confirm a jump of the reference stamps near it."""
        if self.jump_ms > 0 and newest_ms is not None and stamp_ms - newest_ms > self.jump_ms:
            self.ahead_ms = stamp_ms


# --- the aggregator's side -------------------------------------------------------------------


@dataclass(frozen=True)
class EpisodeReport:
    """An episode that ended because a later one began: what it held."""

    episode: int
    next_episode: int
    frames: int  #: frames judged
    first_frame: int | float | None
    last_frame: int | float | None
    collisions: int
    verdicts: int
    #: The collision still being decided when it ended (its verdict follows), else None.
    deciding: int | None

    def text(self) -> str:
        """One line for /diagnostics and the log."""
        span = (
            f"frames {self.first_frame} to {self.last_frame}" if self.frames else "no frame judged"
        )
        collisions = f"{self.collisions} collision{'' if self.collisions == 1 else 's'}"
        verdicts = f"{self.verdicts} verdict{'' if self.verdicts == 1 else 's'}"
        follows = (
            f"; the verdict on its collision at frame {self.deciding} follows"
            if self.deciding is not None
            else ""
        )
        return (
            f"episode {self.next_episode} began (the stamps went back); episode "
            f"{self.episode} ended: {span}, {collisions}, {verdicts}{follows}"
        )

    def to_document(self) -> dict[str, object]:
        """Every field by its name, in field order."""
        return asdict(self)

    @classmethod
    def of(cls, core: AggregatorCore, next_episode: int) -> EpisodeReport:
        stamps = core.frame_stamps()
        frame_ms = core.metadata.timesteps_per_frame if core.metadata is not None else 0
        first, last = (
            (frame_number(stamps[0], frame_ms), frame_number(stamps[-1], frame_ms))
            if stamps and frame_ms
            else (None, None)
        )
        deciding = core.collision_frame if core.deciding else None
        return cls(
            core.episode,
            next_episode,
            len(stamps),
            first,
            last,
            core.collision_number,
            len(core.verdicts),
            deciding,
        )


#: What :meth:`EpisodeAggregator.poll` gives: a verdict, or an episode that ended.
Event = VerdictOutcome | EpisodeReport
#: Ended episodes kept open for their late results; when one more ends, the oldest is
#: decided on what it has and closed.
OPEN_ENDED = 1


@dataclass
class _Heard:
    """A collision heard on ``run/collision``, not yet given to an episode."""

    frame: int
    at: float
    derived: bool
    source: str


@dataclass
class EpisodeAggregator:
    """The aggregator's cores, one per episode (see the module docstring). Without
    ``stack`` (a player's run) there is one core and everything goes to it."""

    make_core: Callable[[], AggregatorCore]
    stack: bool
    #: How long an ended episode stays open, once nothing is pending, for its late results.
    grace_s: float = 10.0
    number: int = 1
    cores: dict[int, AggregatorCore] = field(default_factory=dict)
    #: Results of an episode already closed (dropped, never given to another).
    dropped: int = 0
    _heard: list[_Heard] = field(default_factory=list)
    _events: list[Event] = field(default_factory=list)

    def __post_init__(self) -> None:
        if not self.cores:
            self.cores[self.number] = self.make_core()

    @property
    def current(self) -> AggregatorCore:
        return self.cores[self.number]

    def add_result(self, result: LiveResult, now: float) -> AggregatorCore | None:
        """One monitor result, to its episode's core (begun if it is a new one); the core,
        or None when that episode is already closed."""
        if not self.stack:
            self.current.add_result(result, now)
            return self.current
        if result.episode > self.number:
            self._begin(result.episode, now)
        core = self.cores.get(result.episode)
        if core is None:
            self.dropped += 1
            return None
        if result.collision_frame >= 0 and result.collision_frame not in core.collisions_judged:
            core.collisions_judged.add(result.collision_frame)
            self._bind(now)  # before the result: an event heard wins over the monitors'
        core.add_result(result, now)
        return core

    def set_collision(
        self, frame: int, now: float, derived: bool = False, source: str = "event"
    ) -> None:
        """A collision heard (``run/collision``, a stack's topic, detection): given to the
        episode whose monitors judge with it, or after :meth:`_wait_s` to the current one."""
        if not self.stack:
            self.current.set_collision(frame, now, derived, source)
            return
        if all(heard.frame != frame for heard in self._heard):
            self._heard.append(_Heard(frame, now, derived, source))
        self._bind(now)

    def poll(self, now: float) -> list[Event]:
        """Verdicts due and episodes ended, in order; closes ended episodes gone quiet."""
        self._bind(now)
        events, self._events = self._events, []
        for number in sorted(self.cores):
            outcome = self.cores[number].poll(now)
            if outcome is not None:
                events.append(outcome)
        for number, core in list(self.cores.items()):
            quiet = max(core.ended_at or now, core.last_input or 0.0)
            if number != self.number and not core.deciding and now - quiet >= self.grace_s:
                del self.cores[number]
        return events

    # --- inside ----------------------------------------------------------------------

    def _begin(self, number: int, now: float) -> None:
        """Episode ``number`` began: the current one ends (reported), a fresh core."""
        ended = self.current
        ended.ended_at = now
        self._events.append(EpisodeReport.of(ended, number))
        core = self.make_core()
        core.episode = number
        self.cores[number] = core
        self.number = number
        for old in sorted(self.cores)[: -1 - OPEN_ENDED]:
            why = f"episode {number} began before every result of episode {old} came"
            self._events.extend(self.cores.pop(old).decide_now(now, why))

    def _wait_s(self) -> float:
        """How long a heard collision waits for the monitors to say its episode: what a
        stack-mode verdict waits for them (beyond it, it is the current episode's)."""
        return self.current.stack_budget_s()

    def _bind(self, now: float) -> None:
        """Each heard collision to the newest episode whose results carry its frame and that
        has not taken it yet; one nobody judged with after :meth:`_wait_s`, to the current
        episode (a collision it already took is not taken twice)."""
        for heard in list(self._heard):
            target = next(
                (
                    self.cores[n]
                    for n in sorted(self.cores, reverse=True)
                    if heard.frame in self.cores[n].collisions_judged
                    and heard.frame not in self.cores[n].collisions_taken
                ),
                None,
            )
            if target is None:
                if now - heard.at < self._wait_s():
                    continue
                target = self.current
            target.set_collision(heard.frame, heard.at, heard.derived, heard.source)
            self._heard.remove(heard)
