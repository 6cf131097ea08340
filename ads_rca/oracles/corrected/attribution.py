"""Attribution over the effect window: which module caused the crash, from the per-frame
`corrected` results.

Window: frames [collision_frame − W, collision_frame] with W = :func:`window_frames`.
A module's failing frames in the window count only in runs of at least its persistence
(perception and prediction ``min_persistence``, planning ``planning_min_persistence``,
control ``control_min_persistence``); runs are maximal runs of consecutive analysed frames
inside the window. The primary root cause is the most upstream module with counted failures,
except that a failure whose first counted frame is strictly after the controller's is
contributing, not primary (the ego was already off its plan: the planner plans from the
state the controller delivered, and what perception and prediction then get wrong
follows); so is a prediction failure that had ended where planning's counted failure
begins, prediction judged right there in a real conflict (the planner then failed on a
correct prediction with a safer plan at hand); and so is a perception or prediction
failure that never misled the planner before planning's counted failure began (the
planner's own inputs, within W or over the plan's own horizon, showed the conflict at each
of its frames: :func:`_misled`). With a
collision but no counted failure, the unconditioned tests of perception and prediction
(``metrics["unconditioned"]``) are used the same way, and the basis says so.
Otherwise "no fault found" with its reason. Each blamed module carries its evidence.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from ads_rca.diagnosis.verdict import (
    BASIS_FALLBACK,
    BASIS_JUDGED,
    NO_COLLISION,
    NO_MODULE_FAILED,
    Attribution,
    FrameResults,
    ModuleVerdict,
)
from ads_rca.oracles.base import MODULES, Metric, Module, OracleResult, RunContext
from ads_rca.oracles.corrected.context import corrected_context, window_frames
from ads_rca.params import Params

#: Modules with an unconditioned test, for the fallback (pipeline order).
FALLBACK_MODULES: tuple[Module, ...] = ("perception", "prediction")
#: Modules whose failure reaches the planner through its inputs (:func:`_misled`).
UPSTREAM_OF_PLANNING: tuple[Module, ...] = ("perception", "prediction")
#: The plan's clearances against its own inputs: over W, and over the plan's own horizon
#: (reported where below the margin).
PLAN_CLEARANCES = ("c_plan", "c_plan_horizon")


def persistence(params: Params, module: Module) -> int:
    """The minimum run length of counted failures for a module."""
    if module == "planning":
        return params.planning_min_persistence
    if module == "controller":
        return params.control_min_persistence
    return params.min_persistence


def counted_runs(flags: Sequence[bool], min_length: int) -> list[tuple[int, int]]:
    """Maximal runs [start, end] (inclusive positions) of True of at least ``min_length``."""
    runs: list[tuple[int, int]] = []
    start = -1
    for n, flag in enumerate([*flags, False]):
        if flag and start < 0:
            start = n
        elif not flag and start >= 0:
            if n - start >= max(min_length, 1):
                runs.append((start, n - 1))
            start = -1
    return runs


def _failed(frame: FrameResults, module: Module) -> bool:
    result = frame.results.get(module)
    return bool(result is not None and result.failed)


def _unconditioned(frame: FrameResults, module: Module) -> bool:
    result = frame.results.get(module)
    return bool(result is not None and result.metrics.get("unconditioned") is True)


def _evidence(
    window: Sequence[FrameResults],
    runs: list[tuple[int, int]],
    module: Module,
    basis: str,
) -> dict[str, Metric]:
    first = window[runs[0][0]]
    result: OracleResult | None = first.results.get(module)
    return {
        "basis": basis,
        "first_failing_frame": first.frame,
        "first_failing_ms": first.timestamp_ms,
        "counted_frames": sum(end - start + 1 for start, end in runs),
        "runs": [[window[s].frame, window[e].frame] for s, e in runs],
        "metrics": dict(result.metrics) if result else {},
        "thresholds": dict(result.thresholds) if result else {},
        "ids": list(result.ids) if result else [],
    }


def attribute_corrected(frames: Sequence[FrameResults], ctx: RunContext) -> Attribution:
    """The `corrected` verdict over the analysed frames' oracle results."""
    params, frame_ms = ctx.params, ctx.frame_ms
    collision_frame = ctx.log.metadata.collision_frame
    ordered = sorted({f.timestamp_ms: f for f in reversed(frames)}.values(), key=_ts)
    partner = corrected_context(ctx).partner_id if collision_frame >= 0 else None
    if collision_frame >= 0:
        start, end = (
            (collision_frame - window_frames(params, frame_ms)) * frame_ms,
            collision_frame * frame_ms,
        )
        window = [f for f in ordered if start <= f.timestamp_ms <= end]
    else:
        window = []
    modules = {m: ModuleVerdict() for m in MODULES}
    judged: dict[Module, list[tuple[int, int]]] = {}
    for module in MODULES:
        runs = counted_runs([_failed(f, module) for f in window], persistence(params, module))
        verdict = modules[module]
        total = sum(_failed(f, module) for f in ordered)
        verdict.collision = sum(e - s + 1 for s, e in runs)
        verdict.safe = total - verdict.collision
        if runs:
            judged[module] = runs
            verdict.first_failure_frame = window[runs[0][0]].frame
        elif total:
            verdict.first_failure_frame = next(f.frame for f in ordered if _failed(f, module))
    basis, runs_by_module = BASIS_JUDGED, judged
    if not judged and collision_frame >= 0:
        fallback = {
            m: runs
            for m in FALLBACK_MODULES
            if (
                runs := counted_runs([_unconditioned(f, m) for f in window], persistence(params, m))
            )
        }
        if fallback:
            basis, runs_by_module = BASIS_FALLBACK, fallback
    root_causes = [m for m in MODULES if m in runs_by_module]
    first = {m: runs[0][0] for m, runs in runs_by_module.items()}
    recovered = "planning" in first and _recovered(window, first["planning"])
    harmless = {
        m
        for m in UPSTREAM_OF_PLANNING
        if m in runs_by_module
        and "planning" in first
        and not _misled(window, runs_by_module[m], first["planning"], params.safety_margin)
    }
    primary = _primary(root_causes, first, recovered, harmless)
    for module in root_causes:
        modules[module].evidence = _evidence(window, runs_by_module[module], module, basis)
    reason = None
    if primary is None:
        reason = NO_COLLISION if collision_frame < 0 else NO_MODULE_FAILED
    return Attribution(
        modules=modules,
        root_causes=root_causes,
        primary_root_cause=primary,
        contributing=[m for m in root_causes if m != primary],
        attribution_basis=basis,
        reason=reason,
        partner_id=partner,
    )


def _ts(frame: FrameResults) -> int:
    return frame.timestamp_ms


def _recovered(window: Sequence[FrameResults], planning_start: int) -> bool:
    """Whether prediction was judged right, in a real conflict, where planning's counted
    failure begins (window position), and never failed from there on."""
    result = window[planning_start].results.get("prediction")
    judged_right = (
        result is not None
        and not result.failed
        and result.skipped is None
        and result.metrics.get("real_conflict") is True
    )
    return judged_right and not any(_failed(f, "prediction") for f in window[planning_start:])


def _misled(
    window: Sequence[FrameResults],
    runs: list[tuple[int, int]],
    planning_start: int,
    margin: float,
) -> bool:
    """Whether an upstream module's counted failure hid the threat from the planner at one
    of its frames up to planning's first counted frame (window positions): planning there
    has no clearance below ``margin`` against its own inputs (the partner absent from them,
    a plan clear of what it was given within W and over its horizon, or planning not
    judged: not knowing is misled)."""
    for start, end in runs:
        for position in range(start, min(end, planning_start) + 1):
            if not _plan_saw_threat(window[position].results.get("planning"), margin):
                return True
    return False


def _plan_saw_threat(result: OracleResult | None, margin: float) -> bool:
    """Planning judged the frame and its plan's clearance against its own inputs (the
    partner's raw boxes), over W or over the plan's own horizon, was below ``margin``: the
    planner was shown the conflict."""
    if result is None or result.skipped is not None:
        return False
    return any(_below(result.metrics.get(name), margin) for name in PLAN_CLEARANCES)


def _below(clearance: Metric | None, margin: float) -> bool:
    return (
        isinstance(clearance, int | float)
        and not isinstance(clearance, bool)
        and math.isfinite(clearance)
        and clearance < margin
    )


def _primary(
    root_causes: list[Module],
    first: dict[Module, int],
    prediction_recovered: bool,
    harmless: set[Module],
) -> Module | None:
    """Most upstream, skipping a module that began strictly after the controller (the ego
    was already off its plan), prediction when it had recovered before planning failed, and
    an upstream module that never misled the planner (``harmless``)."""
    for module in root_causes:
        if module in harmless:
            continue
        if (
            module != "controller"
            and "controller" in root_causes
            and first[module] > first["controller"]
        ):
            continue  # the ego was already off its plan: a consequence
        if module == "prediction" and prediction_recovered:
            continue
        return module
    return None
