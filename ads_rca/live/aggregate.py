"""The aggregator's core: collect the monitors' results and decide the verdict, once.

Why this shape: the verdict must be ``ads-rca diagnose``'s, so the aggregator never judges
anything itself. It gathers the four modules' per-frame results, keyed by analysed-frame
index (reference judges a duplicated timestamp twice; corrected once, the first index), and
when the verdict's horizon is covered it calls the mode's
:meth:`~ads_rca.oracles.semantics.Semantics.attribute` on them (as the engine does) and
renders :meth:`~ads_rca.diagnosis.engine.Diagnosis.to_json` (the ``diagnose --json`` contract) plus
a
``live`` section.

The horizon is the collision frame (from the run metadata, or a later collision event): the
frames at or before it decide the attribution. Without a collision it is the end of the run.
A module's result for a frame is *lost* when that module has already published results for
later frames (a monitor that was restarted lost its window): the verdict does not wait for
it, it is published marked incomplete with the lost frames listed. It also does not wait
forever: once the horizon is reached, after ``verdict_timeout_s`` without any new result;
before, after ``stall_timeout_s`` without any input once the run started; what is there is
then attributed and the verdict says why it is incomplete.

A snapshot table's run with a live model beside it (``run/ego_paths``): once any message
with a predicted path was heard, the verdict also waits, within the same
``verdict_timeout_s``, for a predicted path for every analysed row the player sent, so a
model answering as it hears each row is scored in the verdict even when its last answer
comes after the monitors' last results; a row still unanswered then is listed in why the
verdict is incomplete. Without any predicted path the verdict does not wait (no model).

Stack mode (``stack=True``, docs/live-graph.md): there are no frame markers. The frames are
the ones the monitors judged (re-indexed here by stamp, so monitor processes started at
different times agree), and a module is complete for collision N once its result marked
``closes_collision`` N arrived (a collision it did not hear itself, its latched event gone
before it matched, is taken from the first such result: ``collision_source`` "monitors").
A run can collide several times: the collisions are taken in order, a verdict each, numbered.
A stack-mode verdict is complete only when every frame of the effect window was judged on
full inputs: a window frame no monitor judged (its reference message lost, late, or the
stack down), a result judged without an input its module reads, or an input no frame of
the window had, each makes it incomplete, naming the frames by frame number; an input no
window frame had is absent in the verdict's inputs, so the modules needing it are "not
judged (no <input>)". One core serves one episode (:mod:`ads_rca.live.episodes`).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ads_rca.capabilities import INPUT_FIELDS, held_status
from ads_rca.contract.ego_paths import EgoPathRow, merged, snapshots_from_rows
from ads_rca.contract.errors import MalformedMessage
from ads_rca.diagnosis.conclusion import frames_text, missing_window_frames
from ads_rca.diagnosis.engine import Diagnosis, frame_json
from ads_rca.diagnosis.events import choice_of
from ads_rca.diagnosis.verdict import FrameResults, json_safe
from ads_rca.live.results import (
    Columns,
    FollowsRunEnd,
    FrameMarker,
    LiveResult,
    ResultStore,
    RunEnd,
)
from ads_rca.live.stack_config import StackConfig
from ads_rca.model import (
    FOLDER_FIELDS,
    FOLDERS,
    InputStatus,
    RunLog,
    RunMetadata,
    frame_number,
    read_inputs,
)
from ads_rca.oracles.base import MODULES, Module, OracleResult, RunContext
from ads_rca.oracles.semantics import semantics_for
from ads_rca.params import Params
from ads_rca.problems import Problem, ProblemLog, new_problems


@dataclass
class VerdictOutcome:
    """The verdict, ready to publish."""

    diagnosis: Diagnosis
    document: dict[str, Any]
    complete: bool
    why_incomplete: list[str] = field(default_factory=list)


@dataclass
class _Expected:
    index: int
    stamp_ms: int
    arrived: float


class AggregatorCore(FollowsRunEnd):
    """Feed markers, metadata and results; :meth:`poll` returns the verdict once."""

    def __init__(
        self,
        params: Params,
        verdict_timeout_s: float = 10.0,
        stall_timeout_s: float = 20.0,
        stack: StackConfig | None = None,
    ) -> None:
        self.params = params
        # The mode's modules are imported now, not while the verdict is due.
        self.semantics = semantics_for(params)
        self.verdict_timeout_s = verdict_timeout_s
        self.stall_timeout_s = stall_timeout_s
        self.metadata: RunMetadata | None = None
        self.source = ""
        self.collision_frame = -1
        self.collision_source = "none"
        #: Analysed frames announced by markers: stamp and arrival time per index.
        self.expected = Columns(stamp_ms=np.int64, arrived=np.float64)
        self.last_stamp: int | None = None
        self.end = RunEnd()
        #: Each module's latest result per index, spilled to disk (flat memory on long runs).
        self.results = ResultStore()
        self.progress: dict[Module, int] = {m: -1 for m in MODULES}
        self.problems: list[Problem] = []  # found while judging (from the results)
        self.input_problems: list[Problem] = []  # found by the player's reader
        self._seen_problems: set[tuple[str, str, str]] = set()
        self.ego_id: str | None = None
        self.partner_id: str | None = None
        self.last_input: float | None = None
        self.horizon_reached_at: float | None = None
        self.outcome: VerdictOutcome | None = None
        self.received: dict[Module, int] = {m: 0 for m in MODULES}
        #: (horizon, number of expected frames) -> index of the last required frame.
        self._last_required: tuple[int | None, int, int] = (None, -1, -1)
        #: Stack mode's run facts (None: a player's run).
        self.stack_config = stack
        self.stack = stack is not None
        #: What the run gives: a recording's input statuses (run metadata), else the
        #: folders the player's markers listed (a stack's: the inputs it provides).
        self.recorded_inputs: dict[str, InputStatus] = {}
        self.folders_sent: set[str] = set(stack.inputs) if stack is not None else set()
        if stack is not None and stack.timesteps_per_frame:
            self.set_metadata(stack.metadata(stack.timesteps_per_frame), "stack", 0.0)
        #: Stack mode: the number of the collision being decided (1, 2, ...), when it was
        #: heard, whether it was derived from ground truth, the later ones waiting.
        self.collision_number = 0
        self.collision_at: float | None = None
        self.collision_derived = False
        self._queued: deque[tuple[int, str, bool, float]] = deque()
        #: Stack mode: per module, the collision its last ``closes_collision`` result closed.
        self.closed: dict[Module, int] = {}
        self._origin_ms: int | None = None  # stack mode: the stamp of index STACK_MARGIN
        #: Every verdict given, in order (stack mode can give several).
        self.verdicts: list[VerdictOutcome] = []
        #: A snapshot table's rows' future ego paths (``run/ego_paths``), merged per stamp:
        #: scored at the verdict as ``diagnose`` scores the table.
        self.ego_paths: dict[int, EgoPathRow] = {}
        #: A predicted path was heard: a model is answering, the verdict waits for its rows.
        self.model_heard = False
        #: Stack mode: the episode this core judges (:mod:`ads_rca.live.episodes`), when
        #: a later one began (None: still running), the collision frames its results were
        #: judged with, and those it took (being decided, queued or decided).
        self.episode = 1
        self.ended_at: float | None = None
        self.collisions_judged: set[int] = set()
        self.collisions_taken: set[int] = set()

    # --- feeding ---------------------------------------------------------------------

    def set_metadata(
        self,
        metadata: RunMetadata,
        source: str,
        now: float,
        input_problems: Iterable[Problem] = (),
    ) -> None:
        """The run's metadata and the reader's problems (listed first in the verdict, as
        ``diagnose`` lists them)."""
        self.metadata, self.source = metadata, source
        self.input_problems = list(input_problems)
        self.recorded_inputs = read_inputs(metadata.raw)[0]
        if metadata.collision_frame >= 0 and self.collision_source != "event":
            self.collision_frame, self.collision_source = metadata.collision_frame, "metadata"
        self.last_input = now

    def set_collision(
        self, frame: int, now: float, derived: bool = False, source: str = "event"
    ) -> None:
        """A live collision event (wins over the metadata). In stack mode a collision after
        the one being decided waits for its verdict, then is decided in turn; ``source``
        says how it was heard (``event``, or ``monitors``: see :meth:`add_result`)."""
        self.last_input = now
        if not self.stack:
            self.collision_frame, self.collision_source = frame, source
            return
        known = [self.collision_frame, *(q[0] for q in self._queued)]
        if frame in known or frame < self.collision_frame:
            return
        self.collisions_taken.add(frame)
        if self.collision_frame >= 0 and self.outcome is None:
            self._queued.append((frame, source, derived, now))
            return
        self._start_collision(frame, source, derived, now)

    @property
    def deciding(self) -> bool:
        """Stack mode: a collision is heard and its verdict not given yet."""
        return (self.collision_frame >= 0 and self.outcome is None) or bool(self._queued)

    def decide_now(self, now: float, why: str) -> list[VerdictOutcome]:
        """Every collision still being decided, decided now on what arrived (its episode
        is closed), each verdict saying ``why`` it is incomplete."""
        out = []
        while self.metadata is not None and self.deciding:
            out.append(self._decide(now, [why]))
        return out

    def _start_collision(self, frame: int, source: str, derived: bool, now: float) -> None:
        self.collision_frame, self.collision_source = frame, source
        self.collision_derived, self.collision_at = derived, now
        self.collision_number += 1
        self.outcome, self.horizon_reached_at = None, None

    def add_marker(self, marker: FrameMarker, now: float) -> None:
        self.last_input = now
        self.last_stamp = marker.stamp_ms
        self.folders_sent |= marker.folders
        self.end.marker()
        if marker.index is None:
            return
        if self.semantics.analyses(marker.duplicate):
            index = marker.index
            if self.expected.accepts(index) and not self.expected.has(index):
                self.expected.set(index, stamp_ms=marker.stamp_ms, arrived=now)

    def add_ego_path(self, row: EgoPathRow) -> None:
        """One ``run/ego_paths`` message (the player's row, or a live model's prediction);
        MalformedMessage when it would be a row beyond :data:`MAX_ROWS` (only the rows of
        analysed frames are scored at the verdict: one of a stamp never played counts for
        nothing)."""
        if row.stamp_ms not in self.ego_paths and len(self.ego_paths) >= MAX_ROWS:
            raise MalformedMessage(
                f"run/ego_paths: {MAX_ROWS} rows are held already; the row at "
                f"{row.stamp_ms} ms is skipped"
            )
        self.ego_paths[row.stamp_ms] = merged(self.ego_paths.get(row.stamp_ms), row)
        self.model_heard = self.model_heard or row.predicted is not None

    def set_finished(self, now: float, frames_published: int | None = None) -> None:
        """The player's end; effective once ``frames_published`` markers arrived (DDS does
        not order the status after the last markers)."""
        self.last_input = now
        self.end.end(frames_published)

    def add_result(self, result: LiveResult, now: float) -> None:
        self.last_input = now
        if result.provisional:  # shown while the run plays; its final revision decides
            return
        if self.stack:
            result = self._stack_frame(result, now)
            if result.index < 0:
                return
        module = result.module
        self.received[module] += 1
        # put() keeps the highest revision; an absurd index is dropped and moves nothing.
        if self.results.put(result) or self.results.has(module, result.index):
            self.progress[module] = max(self.progress[module], result.index)
        self.problems.extend(new_problems(result.problems, self._seen_problems))
        if result.ego_id is not None and (self.ego_id is None or module == "prediction"):
            self.ego_id = result.ego_id
        if result.partner_id is not None and result.collision_frame == self.collision_frame:
            self.partner_id = result.partner_id
        if result.closes_collision >= 0:
            self.closed[module] = result.closes_collision
            if self.stack:
                # A monitor closed a collision this node never heard of (the latched event
                # was gone before we matched it): taken from the result, not waited for.
                self.set_collision(result.closes_collision, now, source="monitors")

    def _stack_frame(self, result: LiveResult, now: float) -> LiveResult:
        """Stack mode: the result re-indexed by its stamp, its frame registered as expected
        (index -1: a stamp too far before the first one heard)."""
        if self.metadata is None and self.stack_config is not None and result.frame_ms > 0:
            self.set_metadata(self.stack_config.metadata(result.frame_ms), "stack", now)
        if self.metadata is None:
            return replace(result, index=-1)
        frame_ms = self.metadata.timesteps_per_frame
        if self._origin_ms is None:
            self._origin_ms = result.stamp_ms - STACK_MARGIN * frame_ms
        index = round((result.stamp_ms - self._origin_ms) / frame_ms)
        if index < 0:
            return replace(result, index=-1)
        if self.expected.accepts(index) and not self.expected.has(index):
            self.expected.set(index, stamp_ms=result.stamp_ms, arrived=now)
        self.last_stamp = max(self.last_stamp or result.stamp_ms, result.stamp_ms)
        return replace(result, index=index)

    # --- deciding --------------------------------------------------------------------

    def horizon_ms(self) -> int | None:
        """Frames at or before this stamp decide the verdict (None: the whole run)."""
        if self.collision_frame < 0 or self.metadata is None:
            return None
        return self.collision_frame * self.metadata.timesteps_per_frame

    def horizon_reached(self) -> bool:
        horizon = self.horizon_ms()
        if self.stack:
            return horizon is not None and all(
                self.closed.get(m, -1) == self.collision_frame for m in MODULES
            )
        if self.finished:
            return True
        return horizon is not None and self.last_stamp is not None and self.last_stamp >= horizon

    def _required_indices(self) -> np.ndarray:
        """Indices of the expected frames at or before the horizon, ascending."""
        horizon = self.horizon_ms()
        indices = self.expected.indices()
        if horizon is not None:
            indices = indices[self.expected.columns["stamp_ms"][indices] <= horizon]
        return indices

    def required(self) -> list[_Expected]:
        stamps, arrived = self.expected.columns["stamp_ms"], self.expected.columns["arrived"]
        return [
            _Expected(int(i), int(stamps[i]), float(arrived[i]))
            for i in self._required_indices().tolist()
        ]

    def _failures_before(self, start_ms: int) -> list[FrameResults]:
        """Stack mode: the frames before the effect window as the attribution reads them,
        failures only (found in the stored columns, nothing read back), so a long run's
        verdict costs its failures, not its length. Their full results stay on the metrics
        topics; passing frames outside the window count for nothing in either mode."""
        assert self.metadata is not None
        frame_ms = self.metadata.timesteps_per_frame
        indices = self._required_indices()
        stamps = self.expected.columns["stamp_ms"][indices]
        before = indices[stamps < start_ms]
        failing: dict[int, dict[Module, OracleResult]] = {}
        for module in MODULES:
            for index in self.results.failed_among(module, before).tolist():
                stamp = int(self.expected.columns["stamp_ms"][index])
                failing.setdefault(index, {})[module] = OracleResult(
                    module, stamp, True, {}, {}, (), None
                )
        out = []
        for index in sorted(failing):
            stamp = int(self.expected.columns["stamp_ms"][index])
            out.append(FrameResults(stamp, frame_number(stamp, frame_ms), failing[index]))
        return out

    def _window_start_ms(self) -> int | None:
        horizon = self.horizon_ms()
        if horizon is None or self.metadata is None:
            return None
        w = self.semantics.window_frames(self.params, self.metadata.timesteps_per_frame)
        return horizon - w * self.metadata.timesteps_per_frame

    def _behind(self) -> bool:
        """Some module's results stop before the last required frame (so it is awaited).

        The cheap test run on every result: the full scan of :meth:`waiting_for` is
        O(frames) and would make a long run's catching-up quadratic.
        """
        horizon = self.horizon_ms()
        count = self.expected.count
        if horizon != self._last_required[0] or count != self._last_required[1]:
            indices = self._required_indices()
            last = int(indices[-1]) if indices.size else -1
            self._last_required = (horizon, count, last)
        last = self._last_required[2]
        return any(self.progress[m] < last for m in MODULES)

    def waiting_for(self) -> tuple[dict[Module, list[int]], dict[Module, list[int]]]:
        """Per module: required frames still awaited, and those lost (the module moved on)."""
        awaited: dict[Module, list[int]] = {m: [] for m in MODULES}
        lost: dict[Module, list[int]] = {m: [] for m in MODULES}
        # A result judged against another collision (partner) is stale inside the window.
        fresh_from = self._window_start_ms() if self.semantics.uses_partner else None
        for e in self.required():
            for m in MODULES:
                got = self.results.has(m, e.index)
                stale = (
                    got
                    and fresh_from is not None
                    and e.stamp_ms >= fresh_from
                    and self.results.collision_frame(m, e.index) != self.collision_frame
                )
                if got and not stale:
                    continue
                (lost if self.progress[m] > e.index and not stale else awaited)[m].append(e.index)
        return awaited, lost

    def poll(self, now: float) -> VerdictOutcome | None:
        """The verdict when it is due (returned once; None before and after)."""
        if self.outcome is not None or self.metadata is None:
            return None
        why: list[str] = []
        if self.stack and not self.horizon_reached():
            budget = self.stack_budget_s()
            if self.collision_at is None or now - self.collision_at < budget:
                return None
            open_modules = [m for m in MODULES if self.closed.get(m, -1) != self.collision_frame]
            why.append(
                f"timed out after {budget:g} s waiting for "
                f"{', '.join(open_modules)} to judge up to the collision"
            )
            return self._decide(now, why)
        if self.horizon_reached():
            if self.horizon_reached_at is None:
                self.horizon_reached_at = now
            progress = max(self.horizon_reached_at, self.last_input or 0.0)
            waiting = now - progress < self.verdict_timeout_s
            if waiting and self._behind():
                return None  # a module has not reached the last required frame yet
            awaited, lost = self.waiting_for()
            if any(awaited.values()):
                if waiting:
                    return None
                why.append(f"timed out waiting for results: {self._frames_text(awaited)}")
            if any(lost.values()):
                why.append(f"results lost (a monitor restarted): {self._frames_text(lost)}")
            unanswered = self._unanswered_rows()
            if unanswered:
                if waiting:
                    return None
                why.append(
                    "timed out waiting for the model's predicted paths: rows at "
                    f"{_first_few(unanswered)} ms"
                )
        else:
            if not self.markers_received:  # the run has not started: nothing stalls yet
                return None
            if self.last_input is None or now - self.last_input < self.stall_timeout_s:
                return None
            why.append(f"inputs stalled for {self.stall_timeout_s:g} s before the horizon")
        return self._decide(now, why)

    def _unanswered_rows(self) -> list[int]:
        """Stamps of the analysed rows the player sent that no predicted path covers yet,
        once a model answers (none before: a run without a model is not waited for)."""
        if not self.model_heard:
            return []
        rows = self._rows(self.required())
        return [
            stamp
            for stamp, got in rows.items()
            if got.realised is not None and got.predicted is None
        ]

    def _rows(self, required: list[_Expected]) -> dict[int, EgoPathRow]:
        """The snapshot rows of the verdict's frames (merged per stamp)."""
        return {
            e.stamp_ms: self.ego_paths[e.stamp_ms] for e in required if e.stamp_ms in self.ego_paths
        }

    def stack_budget_s(self) -> float:
        """Stack mode: how long after a collision the verdict waits for the monitors. A
        monitor may hold the collision frame ``input_timeout_s`` for its inputs before it
        judges up to it (docs/live-graph.md), so the wait is that plus ``verdict_timeout_s``:
        an input DDS delivers late makes the verdict late, not incomplete."""
        held = self.stack_config.input_timeout_s if self.stack_config is not None else 0.0
        return held + self.verdict_timeout_s

    def _decide(self, now: float, why: list[str]) -> VerdictOutcome:
        """The verdict (kept); in stack mode, the next queued collision starts."""
        outcome = self.outcome = self._verdict(now, why)
        self.verdicts.append(outcome)
        if self._queued:
            self._start_collision(*self._queued.popleft())
        return outcome

    def _latency(self, required: Sequence[_Expected], now: float) -> dict[str, Any]:
        """How long after the last frame the verdict decides on (the collision frame, or the
        last of its look-ahead) first reached the graph the verdict came: from the earliest
        of its arrival at a monitor (each result says when, on the machine's
        CLOCK_MONOTONIC, which its processes share) and what the aggregator saw of it first
        (its marker; beside a stack, its first result). ``verdict_latency_from`` says which."""
        if not required:
            return {"verdict_latency_s": 0.0, "verdict_latency_from": "no frame decided on"}
        decisive = required[-1]
        at_monitor = self.results.arrived(decisive.index)
        if at_monitor is not None and at_monitor <= decisive.arrived:
            start, source = at_monitor, "the collision frame's arrival at the monitors"
        else:
            seen = "its marker" if not self.stack else "its first result"
            start, source = decisive.arrived, f"the collision frame's arrival ({seen}) here"
        return {
            "verdict_latency_s": round(max(0.0, now - start), 6),
            "verdict_latency_from": source,
        }

    def frame_stamps(self) -> list[int]:
        """The stamps of every frame results came for, ascending."""
        indices = self.expected.indices()
        return [int(s) for s in self.expected.columns["stamp_ms"][indices]]

    def _frames_text(self, by_module: Mapping[Module, list[int]]) -> str:
        """``perception frames 70, 71`` per module: stack mode's indices are internal (a
        margin before the first stamp heard), so they are named by frame number."""
        if not self.stack or self.metadata is None:
            return _frames_text(by_module)
        frame_ms = self.metadata.timesteps_per_frame
        stamps = self.expected.columns["stamp_ms"]
        number = {
            i: frame_number(int(stamps[i]), frame_ms) for got in by_module.values() for i in got
        }
        return _frames_text({m: [number[i] for i in got] for m, got in by_module.items()})

    def _verdict(self, now: float, why: list[str]) -> VerdictOutcome:
        assert self.metadata is not None
        metadata = replace(self.metadata, collision_frame=self.collision_frame)
        frame_ms = metadata.timesteps_per_frame
        required = self.required()
        window_start = self._window_start_ms() if self.stack else None
        frames: list[FrameResults] = []
        if window_start is not None:
            frames = self._failures_before(window_start)
            required_full = [e for e in required if e.stamp_ms >= window_start]
        else:
            required_full = required
        for e in required_full:
            results = {m: self._result(m, e.index) for m in MODULES if self.results.has(m, e.index)}
            frames.append(FrameResults(e.stamp_ms, frame_number(e.stamp_ms, frame_ms), results))
        held = {FOLDER_FIELDS[f] for f in self.folders_sent if f in FOLDER_FIELDS}
        inputs = dict(self.recorded_inputs or held_status(held, metadata.collision_known))
        # Stack mode: only the effect window's frames decide whether the verdict is complete.
        among = np.array([e.index for e in required_full], dtype=np.int64)
        incomplete = self.results.incomplete(among if window_start is not None else None)
        unheard = self._unheard(among) if window_start is not None else {}
        inputs.update(unheard.values())
        why_incomplete = [
            *why,
            *(status.reason for _, status in unheard.values()),
            *([f"{len(incomplete)} results judged with incomplete inputs"] if incomplete else []),
        ]
        log = RunLog(
            metadata=metadata,
            frames=tuple(e.stamp_ms for e in required),
            source=self.source,
            problems=ProblemLog([*self.input_problems, *self.problems]),
            inputs=inputs,
            ego_snapshots=snapshots_from_rows(rows) if (rows := self._rows(required)) else None,
        )
        # The engine's attribution; its context reports nothing we keep (no records here).
        attribution = self.semantics.attribute(
            frames, RunContext(log, self.params, ego_id=self.ego_id)
        )
        if self.semantics.uses_partner:
            attribution.partner_id = self.partner_id if self.collision_frame >= 0 else None
        diagnosis = Diagnosis(
            log,
            RunContext(log, self.params, ego_id=self.ego_id),
            frames,
            attribution,
            incomplete=[f"incomplete: {reason}" for reason in why_incomplete],
            events=choice_of(metadata),
        )
        if window_start is not None:
            # Said by the conclusion too ("... missing from the run"): not passed to it.
            why_incomplete += self._never_judged(required, window_start)
        document = diagnosis.to_json(include_frames=window_start is None)
        if window_start is not None:  # the frames that decide: the effect window's
            document["frames"] = [
                json_safe(frame_json(f)) for f in frames if f.timestamp_ms >= window_start
            ]
        document.update(self._latency(required, now))
        complete = not why_incomplete
        document["live"] = {
            "complete": complete,
            "why_incomplete": why_incomplete,
            "collision_source": self.collision_source,
            **(
                {
                    "episode": self.episode,
                    "collision_number": self.collision_number,
                    "derived": self.collision_derived,
                }
                if self.stack
                else {}
            ),
            "frames_expected": len(required),
            "results_received": dict(self.received),
            "incomplete_results": [
                [m, frame_number(int(self.expected.columns["stamp_ms"][i]), frame_ms)]
                if self.expected.has(i)
                else [m, None]
                for m, i in incomplete[:50]
            ],
        }
        return VerdictOutcome(diagnosis, document, complete, why)

    def _result(self, module: Module, index: int) -> OracleResult:
        """A held result as the conclusion reads it: one the monitor judged without an
        input (or look-ahead) it reads lacked an input there (docs/verdicts.md)."""
        result = self.results.result(module, index)
        if self.results.is_incomplete(module, index) and not result.missing_input:
            return replace(result, missing_input=True)
        return result

    def _unheard(self, among: np.ndarray) -> dict[str, tuple[str, InputStatus]]:
        """Stack mode: the provided inputs no frame of the window had (every result of every
        module reading one was judged without it): folder -> (model input, its status)."""
        config = self.stack_config
        if config is None or not among.size:
            return {}
        input_of = {field_name: name for name, field_name in INPUT_FIELDS.items()}
        out: dict[str, tuple[str, InputStatus]] = {}
        for folder in FOLDERS:
            if folder not in config.inputs:
                continue
            bit = 1 << FOLDERS.index(folder)
            readers = [m for m in MODULES if folder in self.semantics.folders(m)]
            lacking = [self.results.lacking(m, among) for m in readers]
            held = [bits for bits in lacking if bits is not None]
            if held and all(bits & bit for bits in held):
                topic = config.inputs[folder].topic
                reason = f"no {folder} message on {topic} for any frame of the effect window"
                status = InputStatus("absent", topic, reason)
                out[folder] = (input_of[FOLDER_FIELDS[folder]], status)
        return out

    def _never_judged(self, required: list[_Expected], window_start: int) -> list[str]:
        """Stack mode: the window's frames no monitor judged (their reference message lost,
        dropped as late by the stamp sync, or the stack down), by frame number."""
        assert self.metadata is not None
        horizon = self.horizon_ms()
        if horizon is None:
            return []
        frame_ms = self.metadata.timesteps_per_frame
        stamps = [e.stamp_ms for e in required]
        if not any(window_start <= stamp <= horizon for stamp in stamps):
            return ["no frame of the effect window was judged"]
        missing = missing_window_frames(stamps, window_start, horizon, frame_ms)
        if not missing:
            return []
        return [
            f"{frames_text(missing)} of the effect window never judged (no frame released "
            "there: its reference message was lost, came late, or the stack was down)"
        ]


#: Stack mode: results this many frames before the first one heard are still placed.
STACK_MARGIN = 4096
#: Snapshot rows (``run/ego_paths`` stamps) held at most: a whole dataset split of snapshots
#: is some 43,000 rows; a flood of made-up stamps must not grow memory without end.
MAX_ROWS = 1 << 17


def _frames_text(by_module: Mapping[Module, Sequence[int | float]]) -> str:
    parts = []
    for module, indices in by_module.items():
        if indices:
            parts.append(f"{module} frames {_first_few(indices)}")
    return "; ".join(parts)


def _first_few(numbers: Sequence[int | float]) -> str:
    """``3, 5, 9`` or, beyond eight, the first eight and ``(+N)`` more."""
    more = f" (+{len(numbers) - 8})" if len(numbers) > 8 else ""
    return ", ".join(map(str, numbers[:8])) + more
