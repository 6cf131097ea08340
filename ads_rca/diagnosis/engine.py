"""The root-cause engine: run the mode's four oracles over a log and attribute the crash.

One function, :func:`diagnose`, serves ``ads-rca diagnose``, the replay and (frame by frame,
through the same oracles) the live monitor nodes, so they cannot disagree. Everything that
depends on the mode (oracles, analysed frames, ego, window, attribution) is asked of its
:class:`~ads_rca.oracles.semantics.Semantics`.
"""

from __future__ import annotations

import traceback
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np

from ads_rca import __version__
from ads_rca.capabilities import input_status, present
from ads_rca.diagnosis.conclusion import Conclusion, collision_state, conclude
from ads_rca.diagnosis.critical_event import collision_frame_of, explained_event
from ads_rca.diagnosis.events import (
    EventChoice,
    choice_of,
    choose_event,
    emergency_onsets,
    with_choice,
    with_event,
)
from ads_rca.diagnosis.perceived import perceived_world, reference_of
from ads_rca.diagnosis.verdict import Attribution, FrameResults, json_safe
from ads_rca.foundation.indented_json import RenderedList
from ads_rca.foundation.progress import advancer
from ads_rca.foundation.workers import can_fork, collector_paused, map_forked
from ads_rca.model import RunLog, frame_number
from ads_rca.oracles.base import MODULES, Module, OracleResult, RunContext
from ads_rca.oracles.semantics import Oracle, Semantics, semantics_for
from ads_rca.params import Params
from ads_rca.problems import Problem, ProblemLog
from ads_rca.sources.registry import scored_entries


def evaluate_frame(ctx: RunContext, oracles: Mapping[Module, Oracle], ts: int) -> FrameResults:
    """All oracles at one frame. An oracle never raises on bad input (it reports it), so an
    exception is a bug in our code: that module's result says ``internal_error`` (never an
    input problem) and its first traceback is kept on ``ctx`` for the command to print;
    the other modules are still judged (docs/verdicts.md).

    Numbers from a log may be as large as a double goes (1.7e308): their products and
    differences overflow to infinity and NaN, which every rule judges as its semantics
    say, so numpy's warnings about it (lines of our code on stderr) are not printed.
    """
    results: dict[Module, OracleResult] = {}
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        for module, oracle in oracles.items():
            try:
                results[module] = oracle(ctx, ts)
            except Exception as error:
                results[module] = internal_error_result(ctx, module, ts, error)
    return FrameResults(ts, frame_number(ts, ctx.frame_ms), results)


def internal_error_result(
    ctx: RunContext, module: Module, ts: int, error: Exception
) -> OracleResult:
    """The result of an oracle that raised at ts: not judged, the error named, its first
    traceback per module kept on ``ctx`` (:attr:`RunContext.tracebacks`)."""
    text = f"{type(error).__name__}: {error}"
    ctx.tracebacks.setdefault(module, "".join(traceback.format_exception(error)))
    return OracleResult(
        module, ts, failed=False, skipped=f"internal error ({text})", internal_error=text
    )


@dataclass
class Diagnosis:
    """Everything ``diagnose`` found: per-frame results, the attribution, the problems."""

    log: RunLog
    ctx: RunContext
    frames: list[FrameResults]
    attribution: Attribution
    #: The frames' part of the verdict JSON, made while they were judged (``diagnose(...,
    #: render_frames=True)`` with workers): :meth:`to_json` puts it in place of the list.
    rendered_frames: RenderedList | None = None
    #: Why a live verdict came before all its results (each a reason it is inconclusive).
    incomplete: Sequence[str] = ()
    #: The events looked for when the run knew no collision (None: it knew one).
    events: EventChoice | None = None

    @property
    def params(self) -> Params:
        return self.ctx.params

    @property
    def semantics(self) -> Semantics:
        return semantics_for(self.params)

    @property
    def window_frames(self) -> int:
        """W: the effect window's length in frames (the mode's rule)."""
        return self.semantics.window_frames(self.params, self.log.frame_ms)

    @property
    def problems(self) -> ProblemLog:
        """Input problems: the reader's, then those found while judging."""
        return ProblemLog([*self.log.problems, *self.ctx.problems])

    @cached_property
    def conclusion(self) -> Conclusion:
        """What the evidence lets the verdict claim (docs/verdicts.md)."""
        return conclude(
            self.semantics, self.params, self.log, self.frames, self.incomplete, self.events
        )

    @property
    def verdict_text(self) -> str:
        return self.conclusion.verdict_text(self.attribution)

    @collector_paused()  # a new dict or list for every value of every frame, in no cycle
    def to_json(self, include_frames: bool = True) -> dict[str, Any]:
        """The machine contract of ``ads-rca diagnose --json`` (see ads_rca.diagnosis.verdict)."""
        a = self.attribution
        conclusion = self.conclusion
        document: dict[str, Any] = {
            "tool": "ads_rca",
            "version": __version__,
            "source": self.log.source,
            "semantics": self.params.semantics,
            "thresholds": self.semantics.used(self.params),
            "collision_frame": collision_frame_of(self.log.metadata),
            "reference": reference_of(self.log),
            "window_frames": self.window_frames,
            "effect_window": self.semantics.effect_window(self.params, self.log.frame_ms),
            "ego_id": self.ctx.ego_id,
            "modules_judged": conclusion.modules,
            "partner_id": a.partner_id,
            "modules": {
                m: {
                    "collision": a.modules[m].collision,
                    "safe": a.modules[m].safe,
                    "first_failure_frame": a.modules[m].first_failure_frame,
                }
                for m in MODULES
            },
            "root_causes": list(a.root_causes),
            "primary_root_cause": a.primary_root_cause,
            "contributing": list(a.contributing),
            "attribution_basis": a.attribution_basis,
            "reason": conclusion.reason(a),
            "verdict": conclusion.verdict_text(a),
            **conclusion.to_document(),
            "evidence": {
                m: a.modules[m].evidence for m in MODULES if a.modules[m].evidence is not None
            },
            "frames": self._frames_json() if include_frames else [],
            "input_problems": [p.to_dict() for p in self.problems],
        }
        # The figures the run's data gives beside the verdict, when it gives any.
        document.update(scored_entries(self.log, self.frames, self.params.semantics))
        return dict(json_safe(document))

    def _frames_json(self) -> list[dict[str, Any]] | RenderedList:
        """The frames' part of the document: as made while judging when it was."""
        rendered = self.rendered_frames
        if rendered is not None and len(rendered) == len(self.frames):
            return rendered
        return [frame_json(f) for f in self.frames]


def frame_json(frame: FrameResults) -> dict[str, Any]:
    out: dict[str, Any] = {"frame": frame.frame, "timestamp_ms": frame.timestamp_ms}
    for module, result in frame.results.items():
        out[module] = {
            "failed": result.failed,
            **({"skipped": result.skipped} if result.skipped else {}),
            **({"missing_input": True} if result.missing_input else {}),
            **({"internal_error": result.internal_error} if result.internal_error else {}),
            **({"ids": list(result.ids)} if result.ids else {}),
            **result.metrics,
        }
    return out


#: Logs shorter than this are judged in-process (a worker costs ~50 ms to fork and collect).
PARALLEL_MIN_FRAMES = 400


def diagnose(
    log: RunLog,
    params: Params,
    progress: Callable[[Iterable[int]], Iterable[int]] | None = None,
    workers: int = 1,
    render_frames: bool = False,
) -> Diagnosis:
    """Judge every analysed frame with the mode's oracles, then attribute the crash.

    ``progress`` may wrap the timestamp iterable (a progress bar). ``workers`` > 1 judges
    slices of frames in forked processes (the oracles are pure per-frame functions, and a
    fork shares the loaded log without copying it); results are the same, in frame order.
    ``render_frames``: the verdict JSON will be written: with workers, the frames' text is
    made as their slices come back (:attr:`Diagnosis.rendered_frames`).
    """
    semantics = semantics_for(params)
    log, events = explained_run(log, params)
    ctx = RunContext.create(log, params)
    oracles = semantics.judging_oracles(log)
    timestamps = semantics.analysed_frames(log)
    rendered = None
    if workers > 1 and len(timestamps) >= PARALLEL_MIN_FRAMES and can_fork():
        rendered = RenderedList("frames") if render_frames else None
        frames = _judge_in_workers(ctx, oracles, timestamps, workers, progress, rendered)
    else:
        stamps: Iterable[int] = progress(timestamps) if progress is not None else timestamps
        frames = [evaluate_frame(ctx, oracles, ts) for ts in stamps]
    return Diagnosis(log, ctx, frames, semantics.attribute(frames, ctx), rendered, events=events)


def explained_run(log: RunLog, params: Params) -> tuple[RunLog, EventChoice | None]:
    """The run as its verdict judges it: the stack's tracks as its world when it has no
    ground truth (:mod:`.perceived`), and, when it knows no collision, the critical event
    its verdict explains (:mod:`.events`) in the collision's place. A run already prepared
    (:func:`prepared_run`: its event or the events looked for in its metadata) is returned as
    it is, with the events it carries."""
    log = perceived_world(log)
    prepared = choice_of(log.metadata)
    if prepared is not None or explained_event(log.metadata) is not None:
        return log, prepared
    state = collision_state(log, present(input_status(log)["collision"]))
    choice = choose_event(log, params, state, emergency_onsets(log))
    if choice.explained is None:
        return log, choice if state == "unknown" or choice.note else None
    return with_event(log, choice.explained), choice


def prepared_run(log: RunLog, params: Params) -> RunLog:
    """The run as :func:`explained_run` makes it, the events looked for in its metadata: what
    the player plays, so the monitors judge the world and the event ``diagnose`` judges and
    the aggregator's verdict lists the same events."""
    log, choice = explained_run(log, params)
    return with_choice(log, choice)


# The forked workers read the run and its timestamps from here (set just before forking,
# cleared after): a slice sent to a worker is two integers.
_SHARED: tuple[RunContext, Mapping[Module, Oracle], tuple[int, ...]] | None = None


def _judge_slice(
    bounds: tuple[int, int],
) -> tuple[list[FrameResults], list[Problem], dict[Module, str]]:
    """In a worker: judge one slice; return its results, the problems it reported and the
    tracebacks of the oracles that raised."""
    assert _SHARED is not None
    ctx, oracles, timestamps = _SHARED
    start, stop = bounds
    before = len(ctx.problems)
    frames = [evaluate_frame(ctx, oracles, ts) for ts in timestamps[start:stop]]
    return frames, list(ctx.problems)[before:], dict(ctx.tracebacks)


def _judge_in_workers(
    ctx: RunContext,
    oracles: Mapping[Module, Oracle],
    timestamps: tuple[int, ...],
    workers: int,
    progress: Callable[[Iterable[int]], Iterable[int]] | None,
    rendered: RenderedList | None,
) -> list[FrameResults]:
    """The frames judged in slices by forked workers; each slice's text made into
    ``rendered`` (when given) while the workers judge the next."""
    global _SHARED  # noqa: PLW0603 - inherited by the forked workers, never written there
    chunk = max(50, len(timestamps) // (workers * 8))
    slices = [(i, min(i + chunk, len(timestamps))) for i in range(0, len(timestamps), chunk)]
    advance = advancer(timestamps, progress)
    frames: list[FrameResults] = []
    _SHARED = (ctx, oracles, timestamps)
    try:
        for (start, stop), (judged, problems, tracebacks) in zip(
            slices, map_forked(_judge_slice, slices, workers), strict=True
        ):
            frames.extend(judged)
            ctx.merge(problems)
            for module, text in tracebacks.items():
                ctx.tracebacks.setdefault(module, text)
            if rendered is not None:
                rendered.extend([frame_json(f) for f in judged])
            advance(stop - start)
    finally:
        _SHARED = None
    return frames
