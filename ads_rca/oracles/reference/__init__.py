"""The `reference` semantics: the reference tool's oracles and verdict, quirks included.

``SEMANTICS`` is what the engine and the live nodes ask (:class:`~ads_rca.oracles.semantics.
Semantics`); the oracles are in :mod:`.oracles`, the attribution in :mod:`.attribution`
(docs/semantics-reference.md).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from ads_rca.diagnosis.verdict import Attribution, FrameResults
from ads_rca.model import Record
from ads_rca.oracles.base import EGO_ID_TIMESTAMP_MS, Module, RunContext, earliest_ego, ego_at
from ads_rca.oracles.reference.attribution import attribute_reference
from ads_rca.oracles.reference.oracles import (
    ORACLES,
    REPORTED,
    control,
    greedy_match,
    perception,
    planning,
    prediction,
)
from ads_rca.oracles.semantics import EVENT_PARAMETERS, Headline, Semantics
from ads_rca.params import Params

#: The folders each reference oracle reads.
FOLDERS_READ: dict[Module, tuple[str, ...]] = {
    "perception": ("bboxes", "bboxes_gt"),
    "prediction": ("pose", "actors", "predictions_with_perception"),
    "planning": ("pose", "actors", "predictions", "predictions_with_perception", "waypoint"),
    "controller": ("pose", "waypoint"),
}
#: The reference oracles that read the ego's identity.
EGO_MODULES: tuple[Module, ...] = ("prediction", "planning")


class ReferenceSemantics(Semantics):
    """Every file's frame judged (duplicates too), the ego read at 50 ms, the reference's
    counts; results never depend on the collision partner."""

    name = "reference"
    oracles = ORACLES
    analyses_duplicates = True
    uses_partner = False
    parameters = (
        "effect_time_window",
        "perc_score_threshold",
        "pred_score_threshold",
        "planning_toleration_future_step",
        "planning_toleration",
        *EVENT_PARAMETERS,
    )
    reported = REPORTED
    window_counts = "frames after collision_frame - {w}, with no upper bound"
    requires: Mapping[Module, tuple[tuple[str, ...], ...]] = {
        "perception": (("detections_2d", "ground_truth_2d"),),
        "prediction": (("ego", "actors", "predictions_gt"),),
        "planning": (("ego", "plan", "predictions", "predictions_gt"),),
        "controller": (("ego", "plan"),),
    }
    rules: Mapping[Module, str] = {
        "perception": "mean IoU of the matched detections below perc_score_threshold; missed "
        "objects never count",
        "prediction": "position error at least pred_score_threshold times the distance, for actors "
        "within 4 m",
        "planning": "a plan point inside a raw prediction's extents (both gaps below the "
        "tolerance)",
        "controller": "the ego's step against the planned step per axis: any move fails where "
        "an axis's planned step is under 0.5 m",
    }
    headline: Mapping[Module, Sequence[Headline]] = {
        "perception": [
            Headline(("mean_iou",), "mean IoU of greedy matches", "1", "perc_score_threshold")
        ],
        # the reference reports these only at failing frames
        "prediction": [
            Headline(("ratio",), "error / distance ratio", "1", "pred_score_threshold"),
            Headline(("n_steps",), "prediction steps judged", "1"),
        ],
        "planning": [Headline(("gap_y", "gap_x"), "gap to the linked obstacle", "m")],
        "controller": [Headline(("s_x", "s_y"), "control score", "1")],
    }

    def attribute(self, frames: Sequence[FrameResults], ctx: RunContext) -> Attribution:
        return attribute_reference(frames, ctx)

    def find_ego(self, ctx: RunContext) -> str | None:
        """At exactly 50 ms; where that actors file or pose is missing, or no actor
        qualifies, the earliest analysed frame with both files (reported)."""
        log = ctx.log
        found = ego_at(log, EGO_ID_TIMESTAMP_MS)
        if found is not None:
            return found
        missing = [
            f"{name}/"
            for name, folder in (("actors", log.actors), ("pose", log.pose))
            if EGO_ID_TIMESTAMP_MS not in folder
        ]
        issue = (
            f"no {' or '.join(missing)} file at 50 ms"
            if missing
            else "no actor within 0.5 m of the pose at 50 ms"
        )
        ctx.report(
            log.file_of("actors", EGO_ID_TIMESTAMP_MS),
            "ego id",
            f"{issue} (the reference stops here; used the earliest frame)",
            EGO_ID_TIMESTAMP_MS,
        )
        return earliest_ego(ctx)

    def folders(self, module: Module) -> tuple[str, ...]:
        return FOLDERS_READ[module]

    def reads_ego(self, module: Module) -> bool:
        return module in EGO_MODULES

    def lookahead_frames(
        self,
        module: Module,
        params: Params,
        records: Mapping[str, Mapping[int, Record]],
        stamp_ms: int,
        cap: int,
    ) -> int:
        """Control reads the next frame; prediction as far ahead as its step keys go
        (capped); perception and planning read their own frame only."""
        if module == "controller":
            return 1
        if module != "prediction":
            return 0
        longest = 0
        tracks = records["predictions_with_perception"].get(stamp_ms)
        for track in (tracks if isinstance(tracks, dict) else {}).values():
            steps = track.steps
            if steps.size:
                longest = max(longest, int(steps.max()))
        return min(longest, cap)


SEMANTICS = ReferenceSemantics()

__all__ = [
    "ORACLES",
    "SEMANTICS",
    "ReferenceSemantics",
    "attribute_reference",
    "control",
    "greedy_match",
    "perception",
    "planning",
    "prediction",
]
