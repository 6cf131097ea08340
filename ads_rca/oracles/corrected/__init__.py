"""The `corrected` semantics: the four oracles judged on clearance, and the attribution.

``SEMANTICS`` is what the engine and the live nodes ask (:class:`~ads_rca.oracles.semantics.
Semantics`). ``ORACLES`` maps each module to its per-frame oracle ``(ctx, ts) ->
OracleResult`` (the same signature as the reference oracles); ``attribute_corrected`` turns
the per-frame results into the verdict (rules 6–7 of docs/semantics-corrected.md).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

from ads_rca.model import Record
from ads_rca.oracles.base import Module, OracleResult, RunContext
from ads_rca.oracles.corrected.attribution import attribute_corrected, window_frames
from ads_rca.oracles.corrected.common import REPORTED
from ads_rca.oracles.corrected.context import corrected_context
from ads_rca.oracles.corrected.control import control
from ads_rca.oracles.corrected.perception import perception
from ads_rca.oracles.corrected.planning import planning
from ads_rca.oracles.corrected.prediction import prediction
from ads_rca.oracles.semantics import Semantics
from ads_rca.params import Params
from ads_rca.verdict import Attribution, FrameResults

ORACLES: dict[Module, Callable[[RunContext, int], OracleResult]] = {
    "perception": perception,
    "prediction": prediction,
    "planning": planning,
    "controller": control,
}


class CorrectedSemantics(Semantics):
    """A duplicated timestamp judged once; the ego from the earliest frame; every oracle
    reads every folder (they share one context) and the collision partner."""

    name = "corrected"
    oracles = ORACLES
    analyses_duplicates = False
    uses_partner = True
    parameters = (
        "effect_time_window",
        "window_s",
        "perc_match_iou",
        "prediction_window",
        "safety_margin",
        "understate_min",
        "pred_abs_threshold",
        "pred_score_threshold",
        "max_decel",
        "decel_tolerance",
        "standstill_speed",
        "control_horizon",
        "control_speed_threshold",
        "actuator_delay",
        "control_lateral_threshold",
        "min_persistence",
        "control_min_persistence",
        "planning_min_persistence",
        "heading_min_step",
    )
    reported = REPORTED
    headline: Mapping[Module, Sequence[tuple[str, str | None]]] = {
        "perception": [("recall", None), ("mean_iou", "perc_match_iou")],
        "prediction": [("displacement_error", None), ("ade", None)],
        "planning": [("c_plan", "safety_margin"), ("c_gt", "safety_margin")],
        "controller": [("sum_speed_innovation", "control_speed_threshold")],
    }

    def attribute(self, frames: Sequence[FrameResults], ctx: RunContext) -> Attribution:
        return attribute_corrected(frames, ctx)

    def window_frames(self, params: Params, tpf_ms: int) -> int:
        return window_frames(params, tpf_ms)

    def lookahead_frames(
        self,
        module: Module,
        params: Params,
        records: Mapping[str, Mapping[int, Record]],
        stamp_ms: int,
        cap: int,
    ) -> int:
        """The clearance horizon and the control horizon (at least the next frame), for
        every module: they share one context."""
        return max(params.prediction_window, params.control_horizon, 1)

    def rejudge_history(self, params: Params, tpf_ms: int) -> int:
        """The effect window plus the control horizon, and some slack."""
        return window_frames(params, tpf_ms) + params.control_horizon + 5

    def partner_id(self, ctx: RunContext) -> str | None:
        return corrected_context(ctx).partner_id


SEMANTICS = CorrectedSemantics()

__all__ = ["ORACLES", "SEMANTICS", "CorrectedSemantics", "attribute_corrected"]
