"""The verdict: per-module counts, root causes, and the JSON contract of ``diagnose --json``.

The contract (stable; later tools parse it)::

    {"semantics", "thresholds", "collision_frame", "modules": {module: {"collision",
     "safe", "first_failure_frame"}}, "root_causes", "primary_root_cause", "frames",
     "input_problems", ...}

plus, additively, ``contributing``, ``attribution_basis``, ``reason`` (why no fault was
found), ``evidence`` per blamed module, ``partner_id`` and ``ego_id``. NaN and infinity are
written as null, each named in the top-level ``"$nonfinite"`` map (JSON Pointer → "nan",
"inf" or "-inf"; :mod:`ads_rca.strictjson`), so the document is strict JSON.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from ads_rca.oracles.base import MODULES, Metric, Module, OracleResult, RunContext
from ads_rca.strictjson import to_strict

#: ``attribution_basis`` values.
BASIS_REFERENCE = "reference counts"
BASIS_JUDGED = "judged failures in the window"
BASIS_FALLBACK = "consequence beyond the judged horizon"

NO_COLLISION = "no collision"
NO_MODULE_FAILED = "no module failed"


@dataclass
class ModuleVerdict:
    """One module's failures: in the effect window (``collision``) and outside (``safe``)."""

    collision: int = 0
    safe: int = 0
    first_failure_frame: int | float | None = None
    evidence: dict[str, Metric] | None = None


@dataclass
class Attribution:
    modules: dict[Module, ModuleVerdict]
    root_causes: list[Module]
    primary_root_cause: Module | None
    contributing: list[Module]
    attribution_basis: str
    #: Why no fault was found (NO_COLLISION or NO_MODULE_FAILED), else None.
    reason: str | None = None
    partner_id: str | None = None


@dataclass
class FrameResults:
    """The four oracles' results at one analysed frame."""

    timestamp_ms: int
    frame: int | float
    results: dict[Module, OracleResult] = field(default_factory=dict)


def frame_number(timestamp_ms: int, tpf: int) -> int | float:
    """Frame index of a timestamp: an int on the frame grid, else a float."""
    return timestamp_ms // tpf if timestamp_ms % tpf == 0 else timestamp_ms / tpf


def attribute_reference(frames: Sequence[FrameResults], ctx: RunContext) -> Attribution:
    """The reference verdict: count failures in and before the (unbounded) window.

    A failure at ts counts as ``collision`` when a collision happened and
    ts > (collision_frame - effect_time_window) * tpf, with no upper bound; else ``safe``.
    Root causes are the modules with any ``collision`` count, in pipeline order.
    """
    collision_frame = ctx.log.metadata.collision_frame
    tpf = ctx.tpf
    start_ms = (collision_frame - ctx.params.effect_time_window) * tpf
    modules = {m: ModuleVerdict() for m in MODULES}
    for frame in frames:
        for module, result in frame.results.items():
            if not result.failed:
                continue
            verdict = modules[module]
            if collision_frame >= 0 and frame.timestamp_ms > start_ms:
                verdict.collision += 1
                if verdict.first_failure_frame is None:
                    verdict.first_failure_frame = frame.frame
            else:
                verdict.safe += 1
    for module in MODULES:  # modules that only failed outside the window: first failure at all
        verdict = modules[module]
        if verdict.first_failure_frame is None and verdict.safe:
            verdict.first_failure_frame = next(
                f.frame for f in frames if module in f.results and f.results[module].failed
            )
    root_causes = [m for m in MODULES if modules[m].collision > 0]
    reason = None
    if not root_causes:
        reason = NO_COLLISION if collision_frame < 0 else NO_MODULE_FAILED
    return Attribution(
        modules=modules,
        root_causes=root_causes,
        primary_root_cause=root_causes[0] if root_causes else None,
        contributing=root_causes[1:],
        attribution_basis=BASIS_REFERENCE,
        reason=reason,
    )


def json_safe(value: Any) -> Any:
    """Strict-JSON-ready data for the contract: :func:`ads_rca.strictjson.to_strict`."""
    return to_strict(value)
