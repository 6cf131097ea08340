"""Small helpers the four `corrected` oracles share: result building and input checks."""

from __future__ import annotations

import math
from collections.abc import Iterable

from ads_rca.oracles.base import Metric, Module, OracleResult
from ads_rca.oracles.corrected.clearance import Clearance
from ads_rca.oracles.corrected.context import CorrectedContext

#: The noise-floor rule's parameters every module with a floor reports.
FLOOR_PARAMETERS = ("noise_floor_s", "noise_floor_min_frames", "noise_floor_factor")

#: The parameters each oracle's results report in ``thresholds``, in that order (the mode's
#: ``Semantics.reported``); an oracle adds its constants and derived values after them.
REPORTED: dict[Module, tuple[str, ...]] = {
    "perception": (
        "perc_match_iou",
        "safety_margin",
        "understate_min",
        "pred_abs_threshold",
        "pred_score_threshold",
        *FLOOR_PARAMETERS,
    ),
    "prediction": (
        "safety_margin",
        "understate_min",
        "pred_abs_threshold",
        "pred_score_threshold",
        *FLOOR_PARAMETERS,
    ),
    "planning": ("safety_margin", "max_decel", "decel_tolerance", "standstill_speed"),
    "controller": (
        "control_speed_threshold",
        "actuator_delay",
        "control_lateral_threshold",
        "control_horizon",
        *FLOOR_PARAMETERS,
    ),
}


def num(value: float | None) -> float:
    """A plain float (NaN for None), so metrics stay JSON-friendly via json_safe."""
    return math.nan if value is None else float(value)


def clearance_metrics(prefix: str, c: Clearance) -> dict[str, Metric]:
    """``<prefix>`` value and ``<prefix>_index`` (the earliest index of the minimum)."""
    return {prefix: num(c.value), f"{prefix}_index": c.index if c.defined else None}


def missing_inputs(
    judging: CorrectedContext, ts: int, folders: Iterable[str], why: str
) -> list[str]:
    """The folders with no record at ts among ``folders``; each is reported as a problem."""
    absent = [f for f in folders if ts not in judging.folders[f]]
    for folder in absent:
        judging.missing(folder, ts, why)
    return absent


def skipped(
    module: Module,
    ts: int,
    reason: str,
    metrics: dict[str, Metric] | None = None,
    thresholds: dict[str, float] | None = None,
    missing_input: bool = False,
) -> OracleResult:
    """A result whose check could not run (no failure); ``missing_input``: because an input
    the run should hold at ts is missing (reported), not because the rule has nothing to
    judge there."""
    return OracleResult(
        module,
        ts,
        False,
        dict(metrics or {}),
        dict(thresholds or {}),
        (),
        skipped=reason,
        missing_input=missing_input,
    )


def missing_skip(
    module: Module,
    ts: int,
    absent: Iterable[str],
    metrics: dict[str, Metric] | None = None,
    thresholds: dict[str, float] | None = None,
) -> OracleResult:
    """A check that could not run because the run lacks ``absent`` (folders) at ts: a
    frame not judged on full inputs (:attr:`OracleResult.missing_input`)."""
    return skipped(module, ts, f"missing {', '.join(absent)}", metrics, thresholds, True)
