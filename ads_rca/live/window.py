"""A monitor's bounded frame window: when a frame can be judged, and with which data.

Why this exists: the offline engine judges frame ts with the whole log at hand, but the
oracles only read ts and a few frames AFTER it (reference prediction as far as its step keys
go, control ts + 1 frame; corrected ``prediction_window`` / ``control_horizon`` frames), the
first-appearance extents of the actors, the ego's identity, and in `corrected` the collision
partner (actors at the collision frame). :class:`MonitorCore` keeps exactly that: per-folder
records for the frames not yet judged plus their look-ahead, the extents of every actor
ever seen, the ego id once found, and the records at the collision frame. A frame is judged,
in analysed-frame order, as soon as

- its own inputs are in (every topic its ``run/frame`` marker announced), and
- the look-ahead it reads has arrived (markers are in timeline order, so "every marker up to
  stamp S is complete" says the data up to S is final, gaps included), and
- the ego is known (reference reads it at 50 ms) and, in `corrected` with a collision, the
  data at the collision frame has arrived (the partner), or the run ended;

or, when inputs stall (nothing for ``input_timeout_s``) or the pending queue is full, with
what arrived, the result marked ``incomplete``. Each judgement runs the engine's own oracle
on a :class:`~ads_rca.model.RunLog` *view* of the window, so live and offline results are
the same function of the same data. Records older than what pending frames and the
re-evaluation history need are dropped: memory does not grow with run length.

A collision announced later (a live stack's collision topic) moves the frames still held
back to the queue (`corrected` only: reference results do not depend on the partner); they
are judged again and published with a higher ``revision``.

A snapshot table's row (``run/ego_paths``) that a live model gives a path for after its
frame was judged is scored again: its planning result alone is published with a higher
``revision`` (:mod:`ads_rca.live.row_paths` has the rule; the oracle runs on a one-row view,
as the planning result of such a row reads the row's paths only).

One core can judge several modules on one window (the ``monitors`` process): frames then
wait for the longest look-ahead among them, and the modules of a frame are judged on one
context, so the `corrected` oracles share their per-frame caches (clearances, plans) as
they do in ``ads-rca diagnose``. Results are the same as with one core per module.
"""

from __future__ import annotations

import time
import uuid
from collections import deque
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ads_rca.capabilities import JUDGED, complete, judged_modules
from ads_rca.contract.ego_paths import EgoPathRow, snapshots_from_rows
from ads_rca.diagnosis.engine import evaluate_frame
from ads_rca.diagnosis.events import threat_at
from ads_rca.diagnosis.perceived import perceived_reference
from ads_rca.live.diagnostics import CollisionWarning
from ads_rca.live.results import FollowsRunEnd, FrameMarker, LiveResult, RunEnd, no_record
from ads_rca.live.row_paths import JudgedRow, RowPaths, rescored_incomplete
from ads_rca.model import (
    Actors,
    FloatArray,
    InputStatus,
    Record,
    RunLog,
    RunMetadata,
    frame_number,
    read_inputs,
)
from ads_rca.oracles.base import MODULES, Module, RunContext
from ads_rca.oracles.semantics import semantics_for
from ads_rca.params import Params
from ads_rca.problems import Problem, ProblemLog, new_problems

#: A snapshot row's paths, awaited by the planning module like an input folder.
EGO_PATHS = "ego_paths"

#: What holds a frame in `corrected` while the collision frame (its partner) is to come.
PARTNER_UNKNOWN = "collision partner unknown (collision frame not received)"

#: Stack mode: the oracle time one :meth:`MonitorCore.prepare` call may spend judging held
#: frames ahead against a warned actor (a fifth of a 20 Hz stack's frame period).
PREPARE_BUDGET_S = 0.01


@dataclass
class _Entry:
    """A frame marker as the window tracks it."""

    marker: FrameMarker
    arrived: float
    settled: bool = False  # own inputs in, or given up on
    missing: tuple[str, ...] = ()
    revision: int = 0
    #: Its last results (one per module), and whether a collision announced since left
    #: their data as it was (no cut inside its look-ahead): then the results stand when
    #: the frame's partner did not change (:meth:`MonitorCore._kept_results`).
    results: list[LiveResult] = field(default_factory=list)
    data_unchanged: bool = False
    #: Results judged ahead against a warned actor (:meth:`MonitorCore.prepare`), and it.
    prepared: list[LiveResult] = field(default_factory=list)
    prepared_for: str | None = None
    #: Its results were published provisionally (judged before the partner was known).
    provisional: bool = False


@dataclass
class WindowSettings:
    """The node parameters the scheduling reads (besides the engine's)."""

    max_lookahead_frames: int = 100
    input_timeout_s: float = 5.0
    max_pending_frames: int = 1200
    #: Judged frames kept for a re-evaluation on a late collision (0 = automatic).
    history_frames: int = 0


@dataclass
class _Stats:
    evaluated: int = 0
    incomplete: int = 0
    #: Frames a collision sent back whose results stood (same partner, same data).
    kept: int = 0
    #: Frames judged provisionally, before the collision partner was known.
    provisional: int = 0
    #: Frames judged ahead against a warned actor, and the time it took.
    prepared: int = 0
    prepare_s: float = 0.0
    max_records: int = 0
    compute_s: list[float] = field(default_factory=list)


class MonitorCore(FollowsRunEnd):
    """The window and scheduler of one module (or several judged together); feed it, then
    :meth:`poll` for new results (one per module and frame, in frame order)."""

    def __init__(
        self,
        modules: Module | Sequence[Module],
        params: Params,
        settings: WindowSettings | None = None,
        stack: bool = False,
        judge_without_collision: bool = False,
    ) -> None:
        """``judge_without_collision`` (stack mode): before any collision, judge each frame
        against the mode's provisional partner (`corrected`: the most threatening actor)."""
        chosen: tuple[Module, ...] = (modules,) if isinstance(modules, str) else tuple(modules)
        self.modules = tuple(m for m in MODULES if m in chosen)  # pipeline order
        if not self.modules:
            raise ValueError("a monitor judges at least one module")
        self.params = params
        self.judge_without_collision = judge_without_collision or stack
        self.settings = settings or WindowSettings()
        self.semantics = semantics_for(params)
        self.oracles = {m: self.semantics.oracles[m] for m in self.modules}
        self.folders = self.semantics.module_folders(self.modules)
        #: Per module, the folders it reads: a result names only the missing ones of those
        #: (a shared window's frame lacking the 2-D boxes is not the controller's gap).
        self.reads = {m: frozenset(self.semantics.folders(m)) for m in self.modules}
        self.needs_ego = any(self.semantics.reads_ego(m) for m in self.modules)
        self.metadata: RunMetadata | None = None
        self.input_problems: tuple[Problem, ...] = ()
        self.inputs: dict[str, InputStatus] = {}
        self.collision_frame = -1
        self.records: dict[str, dict[int, Record]] = {f: {} for f in self.folders}
        self.first_extents: dict[str, FloatArray] = {}
        self.analysed: dict[int, int] = {}  # index -> stamp, for the frames held
        self._markers: deque[_Entry] = deque()  # not yet settled, timeline order
        self.pending: deque[_Entry] = deque()  # analysed frames to judge, in order
        self._judged: deque[_Entry] = deque()  # judged, kept for a re-evaluation
        self.complete_through: int | None = None  # every marker up to here settled
        self.end = RunEnd()
        self.last_input: float | None = None
        self.ego_id: str | None = None
        self.ego_resolved = not self.needs_ego
        self._reported: set[tuple[str, str, str]] = set()
        self.session = uuid.uuid4().hex[:8]
        self.run = ""  # the run being judged, stamped on every result (set by the shell)
        #: Stack mode: the episode judged, stamped on every result (set by the feed).
        self.episode = 1
        self.stats = _Stats()
        #: Stack mode (docs/live-graph.md): frames come whole from the stamp sync, a
        #: collision closes the frames up to it (look-ahead and view cut at the collision).
        self.stack = stack
        #: The last frame looked at for a collision warning (:meth:`collision_warnings`).
        self._warned_through = -1
        #: The actor of the latest collision warning, the likely partner (:meth:`prepare`),
        #: and the stamp it was warned of at.
        self.threat: str | None = None
        self.threat_ms = -1
        #: A module of this run is scored (its figures pool the run): nothing judged ahead.
        self.scored = False
        #: :meth:`prepare`'s context: its actor, and the last stamp its view holds whole.
        self._ahead: tuple[str, RunContext, int] | None = None
        #: Stack mode: no frame at or before the collision frame is still to come.
        self.horizon_closed = False
        self.collision_at: float | None = None
        #: What the stack's layouts derive rather than carry (said on every result).
        self.derived: tuple[str, ...] = ()
        #: A snapshot table's rows' paths (``run/ego_paths``), which the planning module's
        #: not-judged result scores: a snapshot frame waits for its row as for a record, and
        #: a judged row given a later path is scored again (:mod:`ads_rca.live.row_paths`).
        self.row_paths = RowPaths(max_held=2 * self.settings.max_pending_frames + 64)
        self.wants_paths = "planning" in self.modules and self.semantics.scores_predictions
        if self.wants_paths:
            self.reads["planning"] |= {EGO_PATHS}
        #: Planning is not judged by its rules on this run's inputs: its result of a row reads
        #: the row's paths only, so a later path re-scores it (set with the metadata).
        self.rescores_rows = False
        #: What each scorer keeps over the run's frames (a scorer's figures of the run so
        #: far pool every frame judged, in every window; :attr:`RunContext.scorer_state`).
        self.scorer_state: dict[str, Any] = {}
        #: Per module, the traceback of the first exception its oracle raised in any
        #: window (a bug in our code: the node logs it once; the result says which error).
        self.tracebacks: dict[Module, str] = {}
        #: What the oracles carry from one view's context to the next
        #: (:attr:`RunContext.carried`): a floor's samples of the frames views share.
        self.carried: dict[str, Any] = {}

    # --- feeding ---------------------------------------------------------------------

    def set_metadata(
        self, metadata: RunMetadata, now: float, input_problems: Iterable[Problem] = ()
    ) -> None:
        """The run's metadata, and the problems the player's reader found (oracles read
        them as ``RunLog.problems``, e.g. reference skips a value read as NaN)."""
        self.input_problems = tuple(input_problems)
        # A recording's inputs ride in its metadata document (model.INPUTS_KEY); unreadable
        # entries were said by the reader that wrote the document. A module they do not
        # allow is "not judged", as diagnose says.
        self.inputs = read_inputs(metadata.raw)[0]
        if self.inputs:
            chosen = self.semantics.oracles_for_inputs(
                complete(self.inputs), perceived=perceived_reference(metadata.raw)
            )
            self.oracles = {m: chosen[m] for m in self.modules}
            verdicts = judged_modules(self.semantics.requires, complete(self.inputs))
            self.rescores_rows = self.wants_paths and verdicts.get("planning") != JUDGED
        changed = self.metadata is None or metadata.collision_frame != self.metadata.collision_frame
        if changed and metadata.collision_frame >= 0:
            self.set_collision(metadata.collision_frame, now)
        self.metadata = metadata
        self._touch(now)

    def set_collision(self, frame: int, now: float) -> bool:
        """A collision at ``frame`` (from the metadata or a live collision topic).

        Returns True when held frames went back to the queue for a re-evaluation.
        """
        self._touch(now)
        if frame == self.collision_frame:
            return False
        previous, self.collision_frame = self.collision_frame, frame
        self.collision_at, self.horizon_closed = now, False
        self._ahead = None
        if self.semantics.uses_partner:
            again = list(self._judged)
            self._judged.clear()
            cuts = self._cuts(frame, previous)
            for entry in again:
                entry.data_unchanged = not any(self._reaches(entry, c) for c in cuts)
        elif self.stack and self._judged:
            # Judged before the run's end was known, a frame whose look-ahead may reach past
            # the collision read as if the run went on: judged again, the data ending there.
            # So was one judged on the data up to the previous collision: the run went on.
            cuts = self._cuts(frame, previous)
            again = [e for e in self._judged if any(self._reaches(e, c) for c in cuts)]
            taken = {id(e) for e in again}
            self._judged = deque(e for e in self._judged if id(e) not in taken)
            if not again and not self._pending_through(frame):
                # The aggregator hears a module is complete for this collision from the
                # result of its last frame before it (closes_collision): published again.
                again = [self._judged.pop()]
        else:
            return False
        for entry in reversed(again):
            entry.revision += 1
            self.pending.appendleft(entry)
        return bool(again)

    def _cuts(self, frame: int, previous: int) -> list[int]:
        """Stack mode: the stamps where the data of frames judged before collision
        ``frame`` was, or now is, cut (the new collision and the ``previous`` one)."""
        if not self.stack or self.metadata is None:
            return []
        return [c * self.metadata.timesteps_per_frame for c in (frame, previous) if c >= 0]

    def _reaches(self, entry: _Entry, cf_ms: int) -> bool:
        """Whether a judged frame's look-ahead reaches the collision (it read the run as
        going on past it)."""
        assert self.metadata is not None
        frame_ms = self.metadata.timesteps_per_frame
        stamp = entry.marker.stamp_ms
        return stamp + self._lookahead_frames(entry) * frame_ms >= cf_ms

    def _pending_through(self, frame: int) -> bool:
        """A frame at or before collision ``frame`` is still to be judged."""
        assert self.metadata is not None
        cf_ms = frame * self.metadata.timesteps_per_frame
        return bool(self.pending) and self.pending[0].marker.stamp_ms <= cf_ms

    def close_horizon(self) -> None:
        """Stack mode: every frame at or before the collision frame has been fed."""
        self.horizon_closed = True

    def _cut_ms(self, stamp_ms: int) -> int | None:
        """Stack mode: a frame at or before the collision is judged on the data up to it
        (as a crash log ends there), so its look-ahead and view stop there."""
        if not self.stack or self.collision_frame < 0 or self.metadata is None:
            return None
        cf_ms = self.collision_frame * self.metadata.timesteps_per_frame
        return cf_ms if stamp_ms <= cf_ms else None

    def add_record(self, folder: str, stamp_ms: int, record: Record, now: float) -> None:
        self._touch(now)
        if folder not in self.records:
            return
        self.records[folder].setdefault(stamp_ms, record)
        if folder == "actors" and isinstance(record, Actors):
            extent = record.extent
            for row, actor_id in enumerate(record.ids):
                if actor_id not in self.first_extents and not np.isnan(extent[row]).any():
                    self.first_extents[actor_id] = extent[row]
        self._settle(now)

    def add_ego_path(self, row: EgoPathRow, now: float) -> None:
        """One ``run/ego_paths`` message (the player's row, or a live model's path for it);
        MalformedMessage when it is refused (:class:`~ads_rca.live.row_paths.RowPaths`)."""
        self._touch(now)
        if self.wants_paths:
            self.row_paths.add(row, self._floor())
            self._settle(now)

    def add_marker(self, marker: FrameMarker, now: float, arrived: float | None = None) -> None:
        """One frame's marker; ``arrived``: when the frame first reached the node (stack
        mode: its reference message, before the sync held it for its inputs), else now."""
        self._touch(now)
        entry = _Entry(marker, now if arrived is None else arrived)
        self._markers.append(entry)
        self.end.marker()
        if marker.index is not None:
            self.analysed[marker.index] = marker.stamp_ms
            if self.semantics.analyses(marker.duplicate):
                self.pending.append(entry)
        self._settle(now)

    def set_finished(self, now: float, frames_published: int | None = None) -> None:
        """The player reached the end, after ``frames_published`` markers (see
        :class:`~ads_rca.live.results.RunEnd`; a monitor that joined late judges its last
        frames when inputs stall, marked incomplete)."""
        self._touch(now)
        self.end.end(frames_published)

    def _touch(self, now: float) -> None:
        self.last_input = now

    # --- scheduling ------------------------------------------------------------------

    def _settle(self, now: float) -> None:
        """Settle markers whose inputs are in (or timed out), in order; advance the front."""
        timeout = self.settings.input_timeout_s
        stalled = self.stalled(now)
        while self._markers:
            entry = self._markers[0]
            stamp = entry.marker.stamp_ms
            wanted = [f for f in self.folders if f in entry.marker.folders]
            missing = tuple(f for f in wanted if stamp not in self.records[f])
            if self.wants_paths and entry.marker.snapshot and not self.row_paths.has(stamp):
                missing += (EGO_PATHS,)
            if missing and not stalled and now - entry.arrived < timeout and not self.stack:
                break
            entry.settled, entry.missing = True, missing
            self.complete_through = stamp
            self._markers.popleft()

    def stalled(self, now: float) -> bool:
        """No input at all for ``input_timeout_s``."""
        return self.last_input is not None and now - self.last_input >= (
            self.settings.input_timeout_s
        )

    def _lookahead_frames(self, entry: _Entry) -> int:
        return self.semantics.modules_lookahead(
            self.modules,
            self.params,
            self.records,
            entry.marker.stamp_ms,
            self.settings.max_lookahead_frames,
        )

    def _through(self, stamp_ms: int) -> bool:
        """Every marker up to ``stamp_ms`` has settled (or the run is over and all did)."""
        if self.finished and not self._markers:
            return True
        cut = self._cut_ms(stamp_ms)
        if cut is not None and self.horizon_closed:
            return True
        return self.complete_through is not None and self.complete_through >= stamp_ms

    def _blockers(self, entry: _Entry) -> list[str]:
        """What the frame still waits for (empty: it can be judged)."""
        assert self.metadata is not None
        frame_ms = self.metadata.timesteps_per_frame
        stamp = entry.marker.stamp_ms
        out = []
        if not entry.settled:
            out.append("inputs not complete")
        ahead = stamp + self._lookahead_frames(entry) * frame_ms
        cut = self._cut_ms(stamp)
        if cut is not None:
            ahead = min(ahead, cut)
        if not self._through(ahead):
            out.append(f"look-ahead to {ahead} ms not received")
        if not self.ego_resolved and not self._through(self.semantics.ego_stamp_ms):
            out.append("ego not identified yet")
        if (
            self.semantics.uses_partner
            and self.collision_frame >= 0
            and not self._through(self.collision_frame * frame_ms)
        ):
            out.append(PARTNER_UNKNOWN)
        return out

    def poll(self, now: float | None = None) -> list[LiveResult]:
        """Judge every frame that became ready (in order); their results."""
        deciding, later = self.poll_in_order(now)
        return deciding + later

    def poll_in_order(self, now: float | None = None) -> tuple[list[LiveResult], list[LiveResult]]:
        """:meth:`poll`'s results in two parts: those to publish first, and those a node
        may publish after them, which decide no verdict (:meth:`_judge`)."""
        now = time.monotonic() if now is None else now
        if self.metadata is None:
            return [], []
        self._settle(now)
        judged, later = self._judge_ready(now)
        return judged + self._rescore(), later

    def _judge_ready(self, now: float) -> tuple[list[LiveResult], list[LiveResult]]:
        stalled = self.stalled(now)
        ready: list[tuple[_Entry, tuple[str, ...]]] = []
        waiting: list[_Entry] = []  # held for the partner alone: judged provisionally
        for entry in self.pending:
            blockers = self._blockers(entry)
            if blockers and not stalled:
                if len(self.pending) - len(ready) <= self.settings.max_pending_frames:
                    if blockers != [PARTNER_UNKNOWN] or self.stack:
                        break
                    if not entry.provisional:
                        waiting.append(entry)
                    continue
                blockers.append("pending queue full")
            ready.append((entry, tuple(blockers)))
        if not ready:
            return self._judge_provisionally(waiting, now), []
        results = self._judge(ready, now)
        for _ in ready:
            self._judged.append(self.pending.popleft())
        self._trim()
        return results

    def _judge_provisionally(self, entries: list[_Entry], now: float) -> list[LiveResult]:
        """`corrected`, a collision known whose frame has not come (a replay announces it
        in its metadata): judge frames otherwise ready against the most threatening actor,
        as stack mode does before a collision, and publish them marked ``provisional``, so a
        module's state shows while the run plays. They stay queued: once the partner is
        known each is judged for good with a higher revision, its provisional results kept
        where the actor was the partner (:meth:`_kept_results`)."""
        if not entries:
            return []
        ctx = self._context(self.view(collision_frame=-1))
        ctx.scorer_state = {}  # provisional: no run figures pool these results
        self.semantics.judge_without_collision(ctx)
        out: list[LiveResult] = []
        cuts = self._cuts(self.collision_frame, -1)
        for entry in entries:
            results = self._evaluate(ctx, entry, (), now, None, self._reported)
            entry.results = [replace(r, provisional=True, collision_frame=-1) for r in results]
            entry.provisional, entry.revision = True, entry.revision + 1
            # A scorer's figures pool the run so far: one scored apart is judged again.
            entry.data_unchanged = not ctx.scorer_state and not any(
                self._reaches(entry, c) for c in cuts
            )
            self.stats.provisional += 1
            out.extend(entry.results)
        return out

    # --- warning ---------------------------------------------------------------------

    def collision_warnings(self) -> list[CollisionWarning]:
        """Each frame come in since the last call, before any collision is known, whose
        actors kept at their velocity meet the ego within ``event_ttc_s`` (or are within
        ``event_clearance``): computed as the frame arrives, without the look-ahead the
        rules wait for (docs/live-graph.md "Collision warning"). A monitor that does not
        judge planning, or whose mode reads no actors, warns of nothing."""
        if (
            "planning" not in self.modules
            or self.collision_frame >= 0
            or self.metadata is None
            or "actors" not in self.records
            or "pose" not in self.records
        ):
            return []
        actors, poses = self.records["actors"], self.records["pose"]
        new = sorted(s for s in actors if s > self._warned_through and s in poses)
        if not new:
            return []
        self._warned_through = new[-1]
        log = self.view()
        out = []
        for ts in new:
            found = threat_at(log, self.params, ts)
            if found is not None:
                gap, ttc, actor = found
                frame = int(frame_number(ts, log.frame_ms))
                out.append(CollisionWarning(ts, frame, gap, ttc, actor))
        if out:
            self.threat, self.threat_ms = out[-1].actor, out[-1].stamp_ms
        return out

    def _threat_current(self) -> bool:
        """A warning within the last effect window of the frames come in (a collision
        later than that is not the one warned of)."""
        if self.threat is None or self.metadata is None or self.complete_through is None:
            return False
        frame_ms = self.metadata.timesteps_per_frame
        window = self.semantics.window_frames(self.params, frame_ms) * frame_ms
        return self.complete_through - self.threat_ms <= window

    # --- preparing a verdict ---------------------------------------------------------

    def prepare(self, budget_s: float = PREPARE_BUDGET_S) -> int:
        """Stack mode, a collision warned of (within the last effect window) and not yet
        come: judge held frames again against the warned actor, newest first, for at most
        ``budget_s`` of oracle time; the number of frames judged.

        Why: a collision sends every held frame back to be judged against its partner, and
        judging a whole window at once was most of the verdict's latency. Results judged
        ahead are kept on their frame, never published as they are: the collision uses them
        only when its partner is the warned actor and the frame's data did not change
        (:meth:`_kept_results`), where judging again would give the same results."""
        actor = self.threat
        if (
            actor is None
            or self.scored
            or not self._threat_current()
            or not self.stack
            or not self.semantics.uses_partner
            or self.collision_frame >= 0
            or self.metadata is None
        ):
            return 0
        todo = [
            e
            for e in reversed(self._judged)
            if e.prepared_for != actor and any(r.partner_id != actor for r in e.results)
        ]
        if not todo:
            return 0
        started = time.perf_counter()
        done = 0
        while todo and not self.scored and time.perf_counter() - started < budget_s:
            ctx, covered = self._ahead_context(actor, todo)
            if not covered:  # their look-ahead is not all in yet
                break
            for entry in covered:
                seen = set(self._reported)  # said when the results are used, not now
                entry.prepared = self._evaluate(ctx, entry, (), 0.0, None, seen)
                entry.prepared_for = actor
                if ctx.scorer_state:  # a scorer's figures pool the run so far: a module
                    entry.prepared_for = None  # scored apart is never used, and this
                    self.scored = True  # run's modules are scored: nothing judged ahead
                    break
                todo.remove(entry)
                done += 1
                if time.perf_counter() - started >= budget_s:
                    break
        self.stats.prepared += done
        self.stats.prepare_s += time.perf_counter() - started
        return done

    def _ahead_context(self, actor: str, todo: list[_Entry]) -> tuple[RunContext, list[_Entry]]:
        """A context judging against ``actor``, and the frames of ``todo`` whose look-ahead
        its view holds. One context serves many calls (its caches are what make judging
        ahead cheap): a new one is built only when it covers none of ``todo``."""
        assert self.metadata is not None
        frame_ms = self.metadata.timesteps_per_frame

        def covered(through: int) -> list[_Entry]:
            return [
                e
                for e in todo
                if e.marker.stamp_ms + self._lookahead_frames(e) * frame_ms <= through
            ]

        if self._ahead is not None and self._ahead[0] == actor:
            found = covered(self._ahead[2])
            if found:
                return self._ahead[1], found
        ctx = self._context(self.view())
        ctx.scorer_state = {}  # judged ahead: no run figures pool these results
        self.semantics.judge_against(ctx, actor)
        through = self.complete_through if self.complete_through is not None else -1
        self._ahead = (actor, ctx, through)
        return ctx, covered(through)

    # --- judging ---------------------------------------------------------------------

    def view(self, cut_ms: int | None = None, collision_frame: int | None = None) -> RunLog:
        """The window as a RunLog (records shared, dicts copied: tables are per view);
        ``cut_ms``: nothing stamped after it (stack mode, a frame before the collision);
        ``collision_frame``: in place of the known one (-1: judged as if none was known)."""
        assert self.metadata is not None
        if collision_frame is None:
            collision_frame = self.collision_frame
        metadata = replace(self.metadata, collision_frame=collision_frame)
        frames = tuple(self.analysed[i] for i in sorted(self.analysed))
        records = self.records
        if cut_ms is not None:  # the run's data ends at the collision, as a crash log's
            metadata = replace(metadata, total_frames=cut_ms // metadata.timesteps_per_frame)
            frames = tuple(s for s in frames if s <= cut_ms)
            records = {
                folder: {s: r for s, r in by_stamp.items() if s <= cut_ms}
                for folder, by_stamp in records.items()
            }
        return RunLog.from_folders(
            metadata,
            frames,
            records,
            source="live",
            first_extents=dict(self.first_extents),
            problems=ProblemLog(self.input_problems),
            inputs=dict(self.inputs),
            ego_snapshots=snapshots_from_rows(rows)
            if (rows := self.row_paths.rows(frames))
            else None,
        )

    def _context(self, log: RunLog) -> RunContext:
        if self.ego_resolved:
            ctx = RunContext(log, self.params, ego_id=self.ego_id)
        else:
            ctx = RunContext.create(log, self.params)
            self.ego_id, self.ego_resolved = ctx.ego_id, True
        ctx.scorer_state = self.scorer_state  # the run so far: every judged frame's
        ctx.tracebacks = self.tracebacks  # the first per module, of every window
        ctx.carried = self.carried  # per-frame values its views share (floor samples)
        if self.judge_without_collision and self.collision_frame < 0:
            self.semantics.judge_without_collision(ctx)
        return ctx

    def _judge(
        self, ready: list[tuple[_Entry, tuple[str, ...]]], now: float
    ) -> tuple[list[LiveResult], list[LiveResult]]:
        """Judge ``ready`` in order, on one view per cut (stack mode: frames up to the
        collision see no data after it); the results, and those that may come last.

        Results kept as published before, of frames before the effect window, come last:
        they changed only in the collision they name, and the verdict reads nothing else of
        them (which frames failed), so the aggregator hears the results that decide it
        first. Results judged ahead (:meth:`prepare`) were never published: they are not
        deferred."""
        out: list[LiveResult] = []
        later: list[LiveResult] = []
        groups: dict[int | None, list[tuple[_Entry, tuple[str, ...]]]] = {}
        for item in ready:
            groups.setdefault(self._cut_ms(item[0].marker.stamp_ms), []).append(item)
        for cut, group in groups.items():
            out.extend(self._judge_on(self.view(cut), group, now, later))
        del self.stats.compute_s[:-10000]
        return out, later

    def _window_start_ms(self) -> int | None:
        """The first stamp of the collision's effect window (None: no collision)."""
        if self.collision_frame < 0 or self.metadata is None:
            return None
        frame_ms = self.metadata.timesteps_per_frame
        w = self.semantics.window_frames(self.params, frame_ms)
        return (self.collision_frame - w) * frame_ms

    def _closing_stamp(self) -> int | None:
        """Stack mode: the frame whose result tells the aggregator this monitor is complete
        for the current collision (its last frame at or before it), once it is known."""
        if not self.stack or self.collision_frame < 0 or self.metadata is None:
            return None
        cf_ms = self.collision_frame * self.metadata.timesteps_per_frame
        if not self._through(cf_ms):
            return None
        before = [s for s in self.analysed.values() if s <= cf_ms]
        return max(before) if before else None

    def _missing(self, entry: _Entry, module: Module) -> tuple[str, ...]:
        """Why ``module``'s result of the frame lacks inputs: the folders it reads that did
        not come (and a snapshot row's paths, for planning)."""
        reads = self.reads[module]
        return tuple(no_record(f) for f in entry.missing if f in reads)

    def _judge_on(
        self,
        log: RunLog,
        ready: list[tuple[_Entry, tuple[str, ...]]],
        now: float,
        later: list[LiveResult],
    ) -> list[LiveResult]:
        """The results of ``ready`` on ``log``; kept ones before the effect window go to
        ``later`` (:meth:`_judge`)."""
        ctx = self._context(log)
        closing = self._closing_stamp()
        window_start = self._window_start_ms()
        out: list[LiveResult] = []
        for entry, blockers in ready:
            stamp = entry.marker.stamp_ms
            kept = self._kept_results(entry, blockers, self._partner(ctx, stamp))
            # The final results published before stand: only the collision they name
            # changes (provisional ones never reached a verdict: not these).
            unchanged = bool(kept) and kept is entry.results and not kept[0].provisional
            entry.data_unchanged, entry.prepared, entry.prepared_for = False, [], None
            if kept:
                self.stats.kept += 1
                entry.results = [
                    replace(
                        r,
                        provisional=False,
                        collision_frame=self.collision_frame,
                        revision=entry.revision,
                        problems=tuple(new_problems(r.problems, self._reported)),
                        compute_s=0.0,
                        wait_s=max(0.0, now - entry.arrived),
                        closes_collision=self.collision_frame if stamp == closing else -1,
                    )
                    for r in kept
                ]
            else:
                self.stats.evaluated += 1
                self.stats.incomplete += bool(blockers or entry.missing)
                entry.results = self._evaluate(ctx, entry, blockers, now, closing, self._reported)
                self.stats.compute_s.extend(r.compute_s for r in entry.results)
            early = unchanged and window_start is not None and stamp < window_start
            (later if early else out).extend(entry.results)
            if self.rescores_rows and entry.marker.snapshot:
                self.row_paths.judged_row(next(r for r in entry.results if r.module == "planning"))
        return out

    def _evaluate(
        self,
        ctx: RunContext,
        entry: _Entry,
        blockers: tuple[str, ...],
        now: float,
        closing: int | None,
        reported: set[tuple[str, str, str]],
    ) -> list[LiveResult]:
        """The frame's result of each module on ``ctx`` (the problems not in ``reported``)."""
        stamp = entry.marker.stamp_ms
        partner = self._partner(ctx, stamp)
        frame_ms = ctx.log.frame_ms
        out = []
        for module, oracle in self.oracles.items():
            started = time.perf_counter()
            result = evaluate_frame(ctx, {module: oracle}, stamp).results[module]
            spent = time.perf_counter() - started
            out.append(
                LiveResult(
                    index=int(entry.marker.index or 0),
                    result=result,
                    frame=frame_number(stamp, frame_ms),
                    collision_frame=self.collision_frame,
                    incomplete=blockers + self._missing(entry, module),
                    revision=entry.revision,
                    ego_id=ctx.ego_id,
                    partner_id=partner,
                    problems=tuple(new_problems(ctx.problems, reported)),
                    compute_s=spent,
                    wait_s=max(0.0, now - entry.arrived),
                    arrived_s=entry.arrived,
                    session=self.session,
                    run=self.run,
                    closes_collision=self.collision_frame if stamp == closing else -1,
                    frame_ms=frame_ms if self.stack else 0,
                    episode=self.episode,
                    extra={"derived": list(self.derived)} if self.derived else {},
                )
            )
        return out

    def _kept_results(
        self, entry: _Entry, blockers: tuple[str, ...], partner: str | None
    ) -> list[LiveResult]:
        """The results a frame sent back by a collision keeps (empty: judge it again).

        Why: a `corrected` result reads the frame's data and its partner only. A frame
        judged before the collision against the provisional partner (the most threatening
        actor), whose look-ahead ends before the collision, is judged on the same data
        against the same actor when the collision partner is that actor: its result stands,
        and only the collision it was judged with changes; so for results judged ahead
        against the partner (:meth:`prepare`). Re-judging the held window at the collision
        was most of the verdict's latency (docs/live-graph.md "Verdict latency")."""
        if not entry.data_unchanged or blockers or entry.missing or self.rescores_rows:
            return []
        previous = entry.prepared if entry.prepared_for == partner else entry.results
        if len(previous) != len(self.oracles) or any(
            r.partner_id != partner
            or partner is None
            or r.incomplete
            or r.result.internal_error
            or r.result.missing_input
            for r in previous
        ):
            return []
        return previous

    def _rescore(self) -> list[LiveResult]:
        """The planning result, again with ``revision`` + 1, of each judged row a later
        ``run/ego_paths`` message changed (:mod:`ads_rca.live.row_paths`)."""
        out = []
        for judged in self.row_paths.due():
            result = self._row_result(judged)
            self.row_paths.rescored(result)
            # A later re-judge goes higher still (set_collision adds 1 to a judged frame's;
            # a frame already queued again is published after this result).
            for entry in self._judged:
                if entry.marker.stamp_ms == result.stamp_ms:
                    entry.revision = max(entry.revision, result.revision)
            for entry in self.pending:
                if entry.marker.stamp_ms == result.stamp_ms:
                    entry.revision = max(entry.revision, result.revision + 1)
            out.append(result)
        return out

    def _row_result(self, judged: JudgedRow) -> LiveResult:
        """The planning oracle on a one-row view: the row's result reads its paths only."""
        assert self.metadata is not None
        last = judged.result
        stamp = last.stamp_ms
        log = RunLog.from_folders(
            replace(self.metadata, collision_frame=self.collision_frame),
            (stamp,),
            {folder: {} for folder in self.folders},
            source="live",
            problems=ProblemLog(self.input_problems),
            inputs=dict(self.inputs),
            ego_snapshots=snapshots_from_rows({stamp: judged.paths}) if judged.paths else None,
        )
        ctx = RunContext(log, self.params, ego_id=last.ego_id)
        ctx.tracebacks = self.tracebacks
        started = time.perf_counter()
        result = evaluate_frame(ctx, {"planning": self.oracles["planning"]}, stamp).results
        spent = time.perf_counter() - started
        return replace(
            last,
            result=result["planning"],
            incomplete=rescored_incomplete(last.incomplete, judged.paths),
            revision=last.revision + 1,
            problems=tuple(new_problems(ctx.problems, self._reported)),
            compute_s=spent,
            wait_s=0.0,
        )

    def _partner(self, ctx: RunContext, stamp_ms: int) -> str | None:
        """The partner the frame was judged against (None where the mode has none)."""
        return self.semantics.partner_at(ctx, stamp_ms)

    # --- forgetting ------------------------------------------------------------------

    def history_frames(self) -> int:
        """Judged frames kept for a re-evaluation (none where results do not depend on the
        partner; else the setting, or the mode's own count)."""
        if not self.semantics.uses_partner or self.metadata is None:
            # Stack mode: the frames a collision may make judged again (their look-ahead).
            return self.settings.max_lookahead_frames + 1 if self.stack else 0
        if self.settings.history_frames > 0:
            return self.settings.history_frames
        return self.semantics.rejudge_history(self.params, self.metadata.timesteps_per_frame)

    def _trim(self) -> None:
        """Forget what no pending frame, re-evaluation or the collision partner will read."""
        assert self.metadata is not None
        keep = self.history_frames()
        while len(self._judged) > keep:
            self._judged.popleft()
        floor = self._floor()
        if floor is None:
            return
        pinned = self._pinned_stamp()
        for by_stamp in self.records.values():
            for stamp in [s for s in by_stamp if s < floor]:
                if stamp != pinned:
                    del by_stamp[stamp]
        self.row_paths.forget_before(floor)
        for index in [i for i, s in self.analysed.items() if s < floor]:
            if self.analysed[index] != pinned:
                del self.analysed[index]
        size = sum(len(r) for r in self.records.values())
        self.stats.max_records = max(self.stats.max_records, size)

    def _floor(self) -> int | None:
        """The oldest stamp a held, pending or settling frame has (None: nothing yet)."""
        oldest = [q[0].marker.stamp_ms for q in (self._judged, self.pending) if q]
        if self._markers:
            oldest.append(self._markers[0].marker.stamp_ms)
        if oldest:
            return min(oldest)
        if self.complete_through is not None:  # everything settled so far was judged
            return self.complete_through + 1
        return None

    def _pinned_stamp(self) -> int | None:
        """The analysed frame the partner is read at: the latest one <= the collision frame."""
        if not self.semantics.uses_partner or self.collision_frame < 0 or self.metadata is None:
            return None
        cf_ms = self.collision_frame * self.metadata.timesteps_per_frame
        candidates = [s for s in self.analysed.values() if s <= cf_ms]
        return max(candidates) if candidates else None

    def held_records(self) -> int:
        return sum(len(r) for r in self.records.values())
