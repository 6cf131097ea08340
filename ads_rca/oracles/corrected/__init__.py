"""The `corrected` semantics: the four oracles judged on clearance, and the attribution.

``ORACLES`` maps each module to its per-frame oracle ``(ctx, ts) -> OracleResult`` (the
same signature as the reference oracles); ``attribute_corrected`` turns the per-frame
results into the verdict (rules 6–7 of docs/semantics-corrected.md).
"""

from __future__ import annotations

from collections.abc import Callable

from ads_rca.oracles.base import Module, OracleResult, RunContext
from ads_rca.oracles.corrected.attribution import attribute_corrected
from ads_rca.oracles.corrected.control import control
from ads_rca.oracles.corrected.perception import perception
from ads_rca.oracles.corrected.planning import planning
from ads_rca.oracles.corrected.prediction import prediction

ORACLES: dict[Module, Callable[[RunContext, int], OracleResult]] = {
    "perception": perception,
    "prediction": prediction,
    "planning": planning,
    "controller": control,
}

__all__ = ["ORACLES", "attribute_corrected"]
