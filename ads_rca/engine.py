"""The root-cause engine: run the mode's four oracles over a log and attribute the crash.

One function, :func:`diagnose`, serves ``ads-rca diagnose``, the replay and (frame by frame,
through the same oracles) the live monitor nodes, so they cannot disagree.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from ads_rca import __version__
from ads_rca.model import RunLog
from ads_rca.oracles.base import MODULES, Module, OracleResult, RunContext
from ads_rca.params import Params
from ads_rca.problems import CHECK_SKIPPED, ProblemLog
from ads_rca.verdict import Attribution, FrameResults, attribute_reference, frame_number, json_safe

Oracle = Callable[[RunContext, int], OracleResult]


def oracles_for(params: Params) -> dict[Module, Oracle]:
    """The mode's oracles, in pipeline order."""
    if params.semantics == "reference":
        from ads_rca.oracles.reference import ORACLES
    else:
        from ads_rca.oracles.corrected import ORACLES
    return dict(ORACLES)


def attribute(frames: Sequence[FrameResults], ctx: RunContext) -> Attribution:
    if ctx.params.semantics == "reference":
        return attribute_reference(frames, ctx)
    from ads_rca.oracles.corrected import attribute_corrected

    return attribute_corrected(frames, ctx)


def analysed_timestamps(log: RunLog, params: Params) -> tuple[int, ...]:
    """reference analyses a duplicated timestamp once per file; corrected once."""
    return log.frames if params.semantics == "reference" else log.unique_frames


def evaluate_frame(ctx: RunContext, oracles: dict[Module, Oracle], ts: int) -> FrameResults:
    """All oracles at one frame. An unexpected error in one oracle is reported, not raised."""
    results: dict[Module, OracleResult] = {}
    for module, oracle in oracles.items():
        try:
            results[module] = oracle(ctx, ts)
        except Exception as error:
            issue = f"{module} check failed on this frame: {type(error).__name__}: {error}"
            ctx.problems.add(
                ctx.log.file_of("actors", ts), module, issue, CHECK_SKIPPED, "error", ts
            )
            results[module] = OracleResult(module, ts, failed=False, skipped=issue)
    return FrameResults(ts, frame_number(ts, ctx.tpf), results)


@dataclass
class Diagnosis:
    """Everything ``diagnose`` found: per-frame results, the attribution, the problems."""

    log: RunLog
    ctx: RunContext
    frames: list[FrameResults]
    attribution: Attribution

    @property
    def params(self) -> Params:
        return self.ctx.params

    @property
    def problems(self) -> ProblemLog:
        """Input problems: the reader's, then those found while judging."""
        return ProblemLog([*self.log.problems, *self.ctx.problems])

    @property
    def verdict_text(self) -> str:
        a = self.attribution
        if a.primary_root_cause is None:
            return f"no fault found ({a.reason})"
        extra = f" (contributing: {', '.join(a.contributing)})" if a.contributing else ""
        return f"{a.primary_root_cause}{extra}"

    def to_json(self, include_frames: bool = True) -> dict[str, Any]:
        """The machine contract of ``ads-rca diagnose --json`` (see ads_rca.verdict)."""
        a = self.attribution
        document: dict[str, Any] = {
            "tool": "ads_rca",
            "version": __version__,
            "source": self.log.source,
            "semantics": self.params.semantics,
            "thresholds": self.params.used(),
            "collision_frame": self.log.metadata.collision_frame,
            "window_frames": self.params.window_frames(self.log.tpf),
            "ego_id": self.ctx.ego_id,
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
            "reason": a.reason,
            "verdict": self.verdict_text,
            "evidence": {
                m: a.modules[m].evidence for m in MODULES if a.modules[m].evidence is not None
            },
            "frames": [frame_json(f) for f in self.frames] if include_frames else [],
            "input_problems": [p.to_dict() for p in self.problems],
        }
        return dict(json_safe(document))


def frame_json(frame: FrameResults) -> dict[str, Any]:
    out: dict[str, Any] = {"frame": frame.frame, "timestamp_ms": frame.timestamp_ms}
    for module, result in frame.results.items():
        out[module] = {
            "failed": result.failed,
            **({"skipped": result.skipped} if result.skipped else {}),
            **({"ids": list(result.ids)} if result.ids else {}),
            **result.metrics,
        }
    return out


def diagnose(
    log: RunLog, params: Params, progress: Callable[[Iterable[int]], Iterable[int]] | None = None
) -> Diagnosis:
    """Judge every analysed frame with the mode's oracles, then attribute the crash.

    ``progress`` may wrap the timestamp iterable (a progress bar).
    """
    ctx = RunContext.create(log, params)
    oracles = oracles_for(params)
    timestamps: Iterable[int] = analysed_timestamps(log, params)
    if progress is not None:
        timestamps = progress(timestamps)
    frames = [evaluate_frame(ctx, oracles, ts) for ts in timestamps]
    return Diagnosis(log, ctx, frames, attribute(frames, ctx))
