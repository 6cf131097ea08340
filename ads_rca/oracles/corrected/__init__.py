"""The `corrected` semantics: the four oracles judged on clearance, and the attribution.

``SEMANTICS`` is what the engine and the live nodes ask (:class:`~ads_rca.oracles.semantics.
Semantics`). ``ORACLES`` maps each module to its per-frame oracle ``(ctx, ts) ->
OracleResult`` (the same signature as the reference oracles); ``attribute_corrected`` turns
the per-frame results into the verdict (docs/semantics-corrected.md,
"Window" and "Attribution").
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

from ads_rca.diagnosis.verdict import Attribution, FrameResults
from ads_rca.model import FOLDERS, Record
from ads_rca.oracles.base import Module, OracleResult, RunContext, earliest_ego
from ads_rca.oracles.corrected.attribution import attribute_corrected
from ads_rca.oracles.corrected.common import REPORTED
from ads_rca.oracles.corrected.context import (
    corrected_context,
    floor_span,
    window_frames,
    window_terms,
)
from ads_rca.oracles.corrected.control import control
from ads_rca.oracles.corrected.perception import perception
from ads_rca.oracles.corrected.perception_without_truth import STATUS as NO_TRUTH_STATUS
from ads_rca.oracles.corrected.perception_without_truth import perception_without_truth
from ads_rca.oracles.corrected.planning import planning
from ads_rca.oracles.corrected.prediction import prediction
from ads_rca.oracles.corrected.threat import most_threatening
from ads_rca.oracles.semantics import EVENT_PARAMETERS, Headline, Oracle, Semantics
from ads_rca.params import Params

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
    scores_predictions = True  # its look-ahead and folders cover the scoring
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
        "perception_check",
        "perception_3d_source",
        "perc3d_match_iou",
        "perc3d_match_distance",
        "perc3d_small_area",
        "perc3d_range",
        "perc3d_velocity_error",
        "noise_floor_s",
        "noise_floor_min_frames",
        "noise_floor_factor",
        *EVENT_PARAMETERS,
    )
    reported = REPORTED
    without_truth: Mapping[Module, tuple[str, Oracle]] = {
        "perception": (NO_TRUTH_STATUS, perception_without_truth)
    }
    requires: Mapping[Module, tuple[tuple[str, ...], ...]] = {
        # Every rule measures clearances against the ego's plan boxes; without predictions
        # on ground truth, the 3-D match links the stack's predictions to the partner.
        "perception": (
            (
                "actors",
                "ego",
                "plan",
                "detections_2d",
                "ground_truth_2d",
                "predictions",
                "predictions_gt",
            ),
            ("actors", "ego", "plan", "tracked_objects"),
            ("actors", "ego", "plan", "detections_3d"),
        ),
        "prediction": (
            ("actors", "ego", "plan", "predictions_gt"),
            ("actors", "ego", "plan", "predictions", "tracked_objects"),
        ),
        "planning": (
            ("actors", "ego", "plan", "predictions", "predictions_gt"),
            ("actors", "ego", "plan", "predictions", "tracked_objects"),
        ),
        "controller": (("actors", "ego", "plan"),),
    }
    rules: Mapping[Module, str] = {
        "perception": "the partner unmatched in a real conflict while the planner's view of "
        "it is degraded (3-D: missed, or seen safer by understate_min, displaced or hiding "
        "the conflict, or moving so over the stack's plan)",
        "prediction": "the partner's clearance overstated by more than understate_min in a "
        "real conflict",
        "planning": "plan clearance below safety_margin against its own inputs where braking "
        "would have kept clear",
        "controller": "summed speed or lateral tracking error over control_horizon above its "
        "threshold, toward the partner",
    }
    count_columns = ("counted", "other")
    count_legend = (
        "counted: failing frames in persistent runs inside the effect window; "
        "other: the other failing frames (JSON collision / safe)"
    )
    headline: Mapping[Module, Sequence[Headline]] = {
        # what the 2-D perception rule judges: the partner's real clearance while it is
        # unmatched, and what the planner was told (c_raw), not the overall recall
        "perception": [
            Headline(
                ("c_gt", "c_raw"),
                "clearance to the partner",
                "m",
                threshold="safety_margin",
                gates={
                    "c_gt": (("partner_in_view", False), ("partner_matched", True)),
                    "c_raw": (
                        ("partner_in_view", False),
                        ("partner_matched", True),
                        ("raw_linked", False),
                    ),
                },
                band=("unconditioned", "partner in view but unmatched"),
                partner=True,
            ),
            Headline(("mean_iou",), "mean matched IoU", "1", threshold="perc_match_iou"),
        ],
        "prediction": [
            Headline(
                ("displacement_error",),
                "partner's predicted displacement error",
                "m",
                limit="displacement_threshold",
                gates={
                    "displacement_error": (("partner_in_view", False), ("partner_in_pwp", False))
                },
                partner=True,
            ),
            Headline(("ade",), "average displacement error", "m"),
        ],
        "planning": [
            Headline(
                ("c_plan", "c_gt"),
                "clearance to the partner",
                "m",
                threshold="safety_margin",
                gates={"c_plan": (("partner_in_planner_inputs", False),)},
                partner=True,
            ),
            Headline(
                ("plan_realised_error_mean", "plan_realised_error_max"),
                "plan vs realised position",
                "m",
            ),
        ],
        "controller": [
            Headline(
                ("sum_speed_innovation",),
                "summed speed innovation",
                "m/s",
                limit="speed_threshold",
                both_signs=True,
            ),
        ],
    }

    def find_ego(self, ctx: RunContext) -> str | None:
        """The earliest analysed frame's ego, tolerant of a localisation error: the actor
        within 0.5 m of the pose per axis, else the nearest within 2 m."""
        return earliest_ego(ctx, tolerant=True)

    def folders(self, module: Module) -> tuple[str, ...]:
        """Every folder of a running log, and for the partner-reading rules the 3-D
        objects of a recording (the 3-D perception rule, and the 3-D link of prediction and
        planning); perception also an OpenLane-V2 segment's lane graphs, which its not-judged
        result scores (:mod:`ads_rca.sources.openlane.run_scores`)."""
        if module == "controller":
            return FOLDERS
        lanes = ("lanes", "lanes_predicted") if module == "perception" else ()
        return (*FOLDERS, "detections_3d", "tracks_3d", *lanes)

    def attribute(self, frames: Sequence[FrameResults], ctx: RunContext) -> Attribution:
        return attribute_corrected(frames, ctx)

    def window_frames(self, params: Params, frame_ms: int) -> int:
        return window_frames(params, frame_ms)

    def window_terms(self, params: Params, frame_ms: int) -> dict[str, int]:
        return window_terms(params, frame_ms)

    def window_rule(self, params: Params, frame_ms: int) -> str:
        terms = window_terms(params, frame_ms)
        return (
            f"max(effect_time_window {terms['effect_time_window']}, "
            f"round(window_s {params.window_s:g} s / {frame_ms} ms) {terms['window_s']})"
        )

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

    def rejudge_history(self, params: Params, frame_ms: int) -> int:
        """The effect window, the floor frames its first frame reads (the noise-floor rule),
        the control horizon, and some slack: a live window keeps their records, so a re-judged
        frame reads what the offline run read."""
        span = floor_span(params, frame_ms)
        return window_frames(params, frame_ms) + span + params.control_horizon + 5

    def partner_id(self, ctx: RunContext) -> str | None:
        return corrected_context(ctx).partner_id

    def judge_without_collision(self, ctx: RunContext) -> None:
        """Before a collision, the most threatening actor is the partner (:mod:`.threat`)."""
        corrected_context(ctx).judge_without_collision(most_threatening)

    def judge_against(self, ctx: RunContext, actor: str) -> None:
        corrected_context(ctx).judge_without_collision(lambda _judging, _ts: actor)

    def partner_at(self, ctx: RunContext, ts: int) -> str | None:
        return corrected_context(ctx).partner_at(ts)


SEMANTICS = CorrectedSemantics()

__all__ = ["ORACLES", "SEMANTICS", "CorrectedSemantics", "attribute_corrected"]
