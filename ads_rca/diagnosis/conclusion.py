"""Whether a verdict may conclude, and what it then says (docs/verdicts.md).

Why one module: a diagnosis tool's worst answer is a false "no fault found". Every output
(the summary, the verdict JSON, ``/diagnostics``, batch rows, ``watch``, the dashboard)
renders the verdict decided here from the same evidence: which modules the run's inputs let
be judged, which raised in our own code, which frames of the effect window were judged on
full inputs, whether the collision is known, and (live) what never arrived. Without all of
it the verdict is inconclusive and says why; it never turns into "no fault found".
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from itertools import pairwise

from ads_rca.capabilities import JUDGED, NOT_JUDGED, input_status, present
from ads_rca.diagnosis.critical_event import CriticalEvent, explained_event
from ads_rca.diagnosis.events import EventChoice
from ads_rca.diagnosis.perceived import is_perceived
from ads_rca.diagnosis.verdict import (
    COLLISION_UNKNOWN,
    INCONCLUSIVE,
    MODULES,
    NO_CRITICAL_EVENT,
    PERCEPTION_SUSPECTED,
    Attribution,
    FrameResults,
    Module,
)
from ads_rca.model import RunLog, frame_number
from ads_rca.oracles.semantics import Semantics
from ads_rca.params import Params

#: ``collision`` of the verdict JSON: a collision frame is known, the run is known to have
#: none, or nothing says (no collision source).
COLLISION_YES = "yes"
COLLISION_NO = "no"
COLLISION_UNKNOWN_STATE = "unknown"
#: How a module's status starts when it was judged on only some frames of the window.
PARTLY_JUDGED = "partly judged"
#: Frames a reason lists before it says how many more there are.
SHOWN_FRAMES = 8


@dataclass(frozen=True)
class InternalError:
    """Our own code raised while judging a module: the first error, where, how often."""

    module: Module
    error: str
    first_frame: int | float
    first_ms: int
    frames: int

    @property
    def status(self) -> str:
        """The module's status in every output."""
        return f"{NOT_JUDGED}: internal error ({self.error}) at frame {self.first_frame}"

    def to_dict(self) -> dict[str, object]:
        return {
            "module": self.module,
            "error": self.error,
            "first_frame": self.first_frame,
            "first_ms": self.first_ms,
            "frames": self.frames,
        }


@dataclass(frozen=True)
class Conclusion:
    """What the evidence lets the verdict claim."""

    #: :data:`COLLISION_YES`, :data:`COLLISION_NO` or :data:`COLLISION_UNKNOWN_STATE`.
    collision: str
    #: Per module: ``judged``, ``not judged (no <input>)``, ``partly judged (...)`` or
    #: ``not judged: internal error (...) at frame N``.
    modules: dict[Module, str]
    #: Why the verdict is inconclusive, in words (empty: conclusive).
    reasons: tuple[str, ...]
    internal_errors: tuple[InternalError, ...] = ()
    #: The event (not a collision) the verdict explains, if one stood in for the collision.
    event: CriticalEvent | None = None
    #: The events looked for when the run knew no collision (None: it knew one).
    events: EventChoice | None = None
    #: Modules suspected for want of a judgement (without ground truth: perception).
    suspected: tuple[Module, ...] = ()

    @property
    def conclusive(self) -> bool:
        return not self.reasons

    @property
    def explains_nothing(self) -> bool:
        """No collision known and no critical event found or given."""
        return self.collision != COLLISION_YES and self.event is None and self.events is not None

    def reason(self, attribution: Attribution) -> str | None:
        """``reason`` of the JSON: why no root cause was named (None: one was)."""
        if attribution.primary_root_cause is not None:
            return None
        if self.suspected and self.event is not None:
            return PERCEPTION_SUSPECTED
        if self.collision == COLLISION_UNKNOWN_STATE:
            return COLLISION_UNKNOWN
        return attribution.reason if self.conclusive else INCONCLUSIVE

    def verdict_text(self, attribution: Attribution) -> str:
        """The verdict in words (docs/verdicts.md "The verdict")."""
        primary = attribution.primary_root_cause
        why = "; ".join(self.reasons)
        explains = f" [explains {self.event.label}]" if self.event is not None else ""
        if primary is None:
            if self.explains_nothing and self.collision != COLLISION_NO:
                judged = ", ".join(f"{m} {self.modules.get(m, JUDGED)}" for m in MODULES)
                return f"inconclusive: {why}; modules: {judged}"
            if self.suspected and self.event is not None:
                return (
                    f"{', '.join(self.suspected)} suspected (no module failed against what the "
                    f"stack perceived; without ground truth it cannot be judged); "
                    f"inconclusive: {why}{explains}"
                )
            text = f"inconclusive: {why}" if why else f"no fault found ({attribution.reason})"
            return text + explains
        contributing = attribution.contributing
        text = f"{primary} (contributing: {', '.join(contributing)})" if contributing else primary
        return (f"{text}; inconclusive: {why}" if why else text) + explains

    def to_document(self) -> dict[str, object]:
        """The verdict JSON's keys for it."""
        document: dict[str, object] = {
            "conclusive": self.conclusive,
            "why_inconclusive": list(self.reasons),
            "collision": self.collision,
            "internal_errors": [e.to_dict() for e in self.internal_errors],
        }
        if self.events is not None or self.event is not None:
            document["event"] = self.event.to_dict() if self.event is not None else None
            document["events_found"] = (
                [e.to_dict() for e in self.events.found] if self.events is not None else []
            )
        if self.suspected:
            document["suspected"] = list(self.suspected)
        return document


def conclude(
    semantics: Semantics,
    params: Params,
    log: RunLog,
    frames: Sequence[FrameResults],
    incomplete: Iterable[str] = (),
    events: EventChoice | None = None,
) -> Conclusion:
    """The conclusion from a run's inputs and judged frames (``log.frames``: the frames the
    run holds; ``log.metadata.collision_frame``: the collision, or the event standing in for
    it, being explained). ``incomplete``: why a live verdict came before all its results
    (each one a reason); ``events``: the events looked for (the run knew no collision)."""
    statuses = input_status(log)
    modules: dict[Module, str] = dict(semantics.judged(log))
    errors = internal_errors(frames)
    for error in errors:
        modules[error.module] = error.status
    event = explained_event(log.metadata)
    if event is not None:
        collision = event.collision
    else:
        collision = collision_state(log, present(statuses["collision"]))
    reasons: list[str] = []
    if collision == COLLISION_UNKNOWN_STATE:  # an event explained does not say it
        why = statuses["collision"].reason or "the run has no collision source"
        reasons.append(f"collision unknown ({why})")
        if events is not None and event is None:
            reasons.append(events.note or NO_CRITICAL_EVENT)
    missing: list[str] = []
    if collision == COLLISION_YES or event is not None:
        window = _window(semantics, params, log)
        modules.update(_partly_judged(frames, window, modules))
        missing = _missing_frames(log, window)
    reasons.extend(f"{m} {modules[m]}" for m in MODULES if modules.get(m, JUDGED) != JUDGED)
    reasons.extend(missing)
    reasons.extend(incomplete)
    suspected: tuple[Module, ...] = ()
    if is_perceived(log) and modules.get("perception", JUDGED) != JUDGED:
        suspected = ("perception",)
    return Conclusion(collision, modules, tuple(reasons), tuple(errors), event, events, suspected)


def collision_state(log: RunLog, source_present: bool) -> str:
    """``yes`` for a collision frame (one before the run included: the reference counts it),
    ``no`` when the run's collision source says none, ``unknown`` without one."""
    if log.metadata.collision_frame != -1:
        return COLLISION_YES
    return COLLISION_NO if source_present else COLLISION_UNKNOWN_STATE


def internal_errors(frames: Iterable[FrameResults]) -> list[InternalError]:
    """Per module that raised, its first error, in pipeline order."""
    first: dict[Module, tuple[str, int | float, int]] = {}
    counts: dict[Module, int] = {}
    for frame in frames:
        for module, result in frame.results.items():
            if result.internal_error is None:
                continue
            counts[module] = counts.get(module, 0) + 1
            first.setdefault(module, (result.internal_error, frame.frame, frame.timestamp_ms))
    return [InternalError(m, *first[m], counts[m]) for m in MODULES if m in first]


@dataclass(frozen=True)
class _Window:
    """The effect window up to the collision: its bounds (ms) and frame period."""

    start_ms: int
    end_ms: int
    frame_ms: int


def _window(semantics: Semantics, params: Params, log: RunLog) -> _Window:
    frame_ms = log.frame_ms
    end = log.metadata.collision_frame * frame_ms
    return _Window(end - semantics.window_frames(params, frame_ms) * frame_ms, end, frame_ms)


def _partly_judged(
    frames: Sequence[FrameResults], window: _Window, modules: Mapping[Module, str]
) -> dict[Module, str]:
    """Per judged module whose check lacked an input inside the window: its status."""
    unique = list(
        {
            f.timestamp_ms: f
            for f in reversed(frames)  # a duplicated stamp: its first judgement
            if window.start_ms <= f.timestamp_ms <= window.end_ms
        }.values()
    )
    unique.sort(key=lambda f: f.timestamp_ms)
    out: dict[Module, str] = {}
    for module in MODULES:
        if modules.get(module, JUDGED) != JUDGED:
            continue
        gaps = [f for f in unique if _lacked(f, module)]
        if gaps:
            first = gaps[0].results.get(module)
            why = "no result" if first is None else first.skipped or "an input missing"
            out[module] = (
                f"{PARTLY_JUDGED} ({len(gaps)} of {len(unique)} window frames: {why} at "
                f"{frames_text([f.frame for f in gaps])})"
            )
    return out


def _lacked(frame: FrameResults, module: Module) -> bool:
    result = frame.results.get(module)
    return result is None or result.missing_input


def _missing_frames(log: RunLog, window: _Window) -> list[str]:
    """The reason naming the frames of the window the run does not hold (none: [])."""
    if not any(window.start_ms <= ts <= window.end_ms for ts in log.frames):
        return ["no frame of the effect window is in the run"] if log.frames else []
    missing = missing_window_frames(log.frames, window.start_ms, window.end_ms, window.frame_ms)
    if not missing:
        return []
    verb = "is" if len(missing) == 1 else "are"
    return [f"{frames_text(missing)} of the effect window {verb} missing from the run"]


def missing_window_frames(
    frames_ms: Iterable[int], start_ms: int, end_ms: int, frame_ms: int
) -> list[int | float]:
    """Frame numbers in [``start_ms``, ``end_ms``] that ``frames_ms`` lacks: between two
    frames it holds (the last one before the window counts: a run that began earlier and
    lost the window's first frames lost them), or after its last one up to ``end_ms``.
    Before its first frame the run had not begun. The live aggregator names the frames a
    stack's monitors never judged with it."""
    stamps = sorted(set(frames_ms))
    held = [ts for ts in stamps if start_ms <= ts <= end_ms]
    if not held:
        return []
    earlier = [ts for ts in stamps if ts < start_ms][-1:]
    missing: list[int | float] = []
    for before, after in pairwise([*earlier, *held]):
        gap = round((after - before) / frame_ms) - 1
        stamps_between = (before + k * frame_ms for k in range(1, gap + 1))
        missing.extend(frame_number(ts, frame_ms) for ts in stamps_between if ts >= start_ms)
    after_last = round((end_ms - held[-1]) / frame_ms)
    missing.extend(
        frame_number(held[-1] + k * frame_ms, frame_ms) for k in range(1, after_last + 1)
    )
    return missing


def frames_text(frames: Sequence[int | float]) -> str:
    """``frame 70``, ``70, 71`` or the first few and ``(+N)``."""
    shown = ", ".join(str(f) for f in frames[:SHOWN_FRAMES])
    more = f" (+{len(frames) - SHOWN_FRAMES})" if len(frames) > SHOWN_FRAMES else ""
    return f"frame {shown}" if len(frames) == 1 else f"frames {shown}{more}"
