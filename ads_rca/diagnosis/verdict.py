"""The verdict: per-frame results, per-module counts, root causes, the ``diagnose --json``
contract's types and JSON helpers.

The types only: each mode's attribution (which fills them) lives with its oracles
(``oracles/reference/attribution.py``, ``oracles/corrected/attribution.py``), so this
module imports nothing of :mod:`ads_rca.oracles` and the oracles may import it.

The contract (stable; later tools parse it)::

    {"semantics", "thresholds", "collision_frame", "modules": {module: {"collision",
     "safe", "first_failure_frame"}}, "root_causes", "primary_root_cause", "frames",
     "input_problems", ...}

plus, additively, ``contributing``, ``attribution_basis``, ``reason`` (why no root cause
was named), ``evidence`` per blamed module, ``partner_id``, ``ego_id``, ``modules_judged``
(per module ``judged``, ``not judged (no <input>)``, ``partly judged (...)`` or an internal
error) and what the evidence lets the verdict claim (:mod:`ads_rca.diagnosis.conclusion`,
docs/verdicts.md): ``conclusive``, ``why_inconclusive``, ``collision`` and
``internal_errors``.
NaN and infinity are written as null, each named in the top-level ``"$nonfinite"`` map
(JSON Pointer → "nan", "inf" or "-inf"; :mod:`ads_rca.foundation.strictjson`), so the document is
strict JSON.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

from ads_rca.foundation.strictjson import to_strict

Module = Literal["perception", "prediction", "planning", "controller"]
#: Pipeline order, upstream first (the reference's names).
MODULES: tuple[Module, ...] = ("perception", "prediction", "planning", "controller")

Metric = float | int | str | bool | None | list["Metric"] | dict[str, "Metric"]

#: ``attribution_basis`` values.
BASIS_REFERENCE = "reference counts"
BASIS_JUDGED = "judged failures in the window"
BASIS_FALLBACK = "consequence beyond the judged horizon"

NO_COLLISION = "no collision"
NO_MODULE_FAILED = "no module failed"
#: ``reason`` of a verdict that finds no root cause but may not say "no fault found"
#: (docs/verdicts.md): something it needed was not judged, or the collision is unknown.
INCONCLUSIVE = "inconclusive"
COLLISION_UNKNOWN = "collision unknown"
#: ``reason`` when the run knows no collision and no critical event was found or given.
NO_CRITICAL_EVENT = "no critical event found"
#: ``reason`` when, without ground truth, no module failed against what the stack perceived.
PERCEPTION_SUSPECTED = "perception suspected"


@dataclass(frozen=True)
class OracleResult:
    """One module judged at one frame."""

    module: Module
    timestamp_ms: int
    failed: bool
    metrics: dict[str, Metric] = field(default_factory=dict)
    thresholds: dict[str, float] = field(default_factory=dict)
    ids: tuple[str, ...] = ()
    #: Why the check could not run (missing input), else None.
    skipped: str | None = None
    #: The check lacked an input the run should hold at this frame (a missing or unreadable
    #: file or message, reported as an input problem): the frame is not judged on full
    #: inputs (docs/verdicts.md "partly judged").
    missing_input: bool = False
    #: Our own code raised while judging this frame: ``"<type>: <message>"`` (a bug, never
    #: an input problem; docs/verdicts.md "internal error").
    internal_error: str | None = None


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


def json_safe(value: object) -> Any:
    """Strict-JSON-ready data for the contract: :func:`ads_rca.foundation.strictjson.to_strict`."""
    return to_strict(value)
