"""OpenLane-V2 scores of a run: each frame's figures and the segment's so far, one function
for ``diagnose`` and the live perception monitor.

An OpenLane-V2 segment with a model's results (``--predictions``) gives nothing the verdict
rules can judge (no actors, no plan), but its lane graphs can be scored with the benchmark's
own figures (:mod:`ads_rca.sources.openlane.scores`). Where the perception module is not judged and
the mode scores predictions (``corrected``; ``reference`` reproduces the reference tool and
scores nothing), its per-frame result carries:

- ``openlane_frame``: the figures of that frame alone (DET_l, DET_t, TOP_ll, TOP_lt, OLS as
  :meth:`~ads_rca.sources.openlane.scores.OpenLaneScores.to_dict`);
- ``openlane_segment``: the figures of every scored frame up to and including it (the
  segment so far), pooled from the frames' kept :class:`~ads_rca.sources.openlane.scores.FrameMatch`
  (:class:`LaneMatches`: a frame is matched once, never again);
- ``openlane_inputs``: which side the frame held.

The run's figures (:func:`run_scores`, the verdict JSON's :data:`OPENLANE_SCORES_KEY`) are
the latest scored frame's segment figures, so ``diagnose`` and the live aggregator, which
only holds the frames' results, give the same numbers, with :data:`RULES` saying what
produced them.

Which frames are scored: a frame with a predicted lane graph, and a frame with ground truth
but no prediction when the run says a model's results were given (the OpenLane-V2 reader's
metadata ``segment.predicted_frames`` > 0; it travels in ``run/metadata`` and a converted
log's metadata.json): the reader reads a frame without a usable result as nothing
predicted, so its ground truth counts as missed (false negatives; its links on unmatched
lanes as wrong), as the benchmark counts a frame a model left out. A prediction without
ground truth is scored too (only false positives). A run without a model's results, and a
frame with neither graph or two empty ones (nothing to find, nothing to miss: it would add
nothing but its count), score nothing.

Pure; the live monitor gives each context its own persistent :class:`LaneMatches`, the
engine one per run (a forked worker matches the frames before its slice once, itself).
"""

from __future__ import annotations

import math
from bisect import bisect_right
from collections.abc import Iterable, Mapping, Sequence
from typing import Any, cast

from ads_rca.diagnosis.scoring import FrameScores, Scorer
from ads_rca.diagnosis.verdict import FrameResults, Metric
from ads_rca.model import RunLog, RunMetadata
from ads_rca.params import Params
from ads_rca.sources.openlane.lanes import LaneGraph
from ads_rca.sources.openlane.scores import (
    ELEMENT_IOU_DISTANCE,
    GT_POINT_INTERVAL,
    LANE_THRESHOLDS_M,
    LINK_CONFIDENCE,
    RELAX_FLOOR,
    RELAX_PER_M,
    FrameMatch,
    match_frame,
    scores_from,
)

#: Key of the verdict JSON holding the segment's figures.
OPENLANE_SCORES_KEY = "openlane_scores"
#: Keys of the perception result's metrics.
FRAME_KEY = "openlane_frame"
SEGMENT_KEY = "openlane_segment"
INPUTS_KEY = "openlane_inputs"
#: What ``openlane_inputs`` says.
BOTH = "ground truth and prediction"
TRUTH_ONLY = "ground truth only: nothing predicted"
PREDICTION_ONLY = "prediction only: no ground truth"
#: The rules that produced the figures (the verdict JSON's ``rules``).
RULES: dict[str, Metric] = {
    "ground_truth_points": f"every {GT_POINT_INTERVAL}th (the devkit's val/test collection)",
    "lane_frechet_thresholds_m": list(LANE_THRESHOLDS_M),
    "lane_relaxation": f"max({RELAX_FLOOR}, 1 - {RELAX_PER_M} * d_nearest_m)",
    "element_iou_above": round(1.0 - ELEMENT_IOU_DISTANCE, 6),
    "link_confidence_above": LINK_CONFIDENCE,
    "ap": "11-point interpolated, frames pooled",
    "matching": "greedy by confidence, each prediction to its nearest ground truth",
    "empty_sets": "null (undefined), not the devkit's 1.0 per empty class / 0.0 topology",
    "frames_scored": "every frame with a prediction; ground truth without one as missed",
    "reference": "docs/openlane-metrics.md",
}
#: The perception result's thresholds (numbers only, as every oracle's).
THRESHOLDS: dict[str, float] = {
    **{f"openlane_lane_m_{n}": t for n, t in enumerate(LANE_THRESHOLDS_M, start=1)},
    "openlane_element_iou": round(1.0 - ELEMENT_IOU_DISTANCE, 6),
    "openlane_link_confidence": LINK_CONFIDENCE,
}


def model_given(metadata: RunMetadata) -> bool:
    """The run's metadata says a model's results were read (``segment.predicted_frames``)."""
    segment = metadata.raw.get("segment")
    count = segment.get("predicted_frames") if isinstance(segment, Mapping) else None
    return isinstance(count, int) and not isinstance(count, bool) and count > 0


def scored_pair(log: RunLog, ts: int) -> tuple[LaneGraph, LaneGraph, str] | None:
    """(ground truth, prediction, which side was held) to score at ``ts``; None if none
    (neither graph, or both without a lane or an element: nothing to find or to miss)."""
    gt, pred = log.lanes.get(ts), log.lanes_predicted.get(ts)
    if _empty(gt) and _empty(pred):
        return None
    if pred is not None:
        return (gt, pred, BOTH) if gt is not None else (LaneGraph.empty(), pred, PREDICTION_ONLY)
    if gt is not None and model_given(log.metadata):
        return gt, LaneGraph.empty(), TRUTH_ONLY
    return None


def _empty(graph: LaneGraph | None) -> bool:
    return graph is None or (graph.lane_count == 0 and graph.element_count == 0)


class LaneMatches:
    """The scored frames' matches by stamp, kept for the segment figures (a frame is matched
    once). Grows by one small record per scored frame: a segment's worth."""

    def __init__(self) -> None:
        self.by_stamp: dict[int, FrameMatch] = {}
        #: Stamps already looked at (scored or not).
        self._seen: set[int] = set()

    def add(self, log: RunLog, ts: int) -> str | None:
        """Match ``ts`` if it was not yet; which side it held (None: nothing to score)."""
        pair = scored_pair(log, ts)
        if ts not in self._seen:
            self._seen.add(ts)
            if pair is not None:
                self.by_stamp[ts] = match_frame(pair[0], pair[1])
        return pair[2] if pair is not None else None

    def upto(self, ts: int) -> list[FrameMatch]:
        """The kept matches of frames at or before ``ts``, in stamp order."""
        return [self.by_stamp[s] for s in sorted(self.by_stamp) if s <= ts]

    @classmethod
    def kept_in(cls, kept: dict[str, Any]) -> LaneMatches:
        """The run's matches in the scorer's state ``kept`` (new on its first frame)."""
        found = kept.setdefault("matches", cls())
        assert isinstance(found, cls)
        return found


def frame_scores(log: RunLog, ts: int, matches: LaneMatches) -> dict[str, Metric]:
    """The figures of frame ``ts`` and of the segment up to it ({} when ``ts`` has nothing to
    score). Frames of ``log`` before ``ts`` not matched yet (a forked worker's slice) are
    matched first, so the segment figures never depend on who judged which frame."""
    if not log.lanes and not log.lanes_predicted:
        return {}
    stamps = log.frames  # ascending
    for earlier in stamps[: bisect_right(stamps, ts)]:
        if earlier != ts:
            matches.add(log, earlier)
    held = matches.add(log, ts)
    if held is None or ts not in matches.by_stamp:
        return {}
    return {
        INPUTS_KEY: held,
        FRAME_KEY: cast("Metric", scores_from([matches.by_stamp[ts]]).to_dict()),
        SEGMENT_KEY: cast("Metric", scores_from(matches.upto(ts)).to_dict()),
    }


#: The headline figures, in the order texts give them.
HEADLINE: tuple[tuple[str, str], ...] = (
    ("ols", "OLS"),
    ("det_l", "DET_l"),
    ("det_t", "DET_t"),
    ("top_ll", "TOP_ll"),
    ("top_lt", "TOP_lt"),
)


def figure(value: object) -> str:
    """A figure for a line of text: 3 decimals, ``-`` when undefined or not a number."""
    if isinstance(value, bool) or not isinstance(value, int | float) or math.isnan(value):
        return "-"
    return f"{value:.3f}"


def figures_text(scores: object) -> str:
    """``OLS 0.783, DET_l 1.000, DET_t 0.500, TOP_ll 1.000, TOP_lt 0.400`` of a
    :meth:`~ads_rca.sources.openlane.scores.OpenLaneScores.to_dict` (``-`` where undefined)."""
    found = scores if isinstance(scores, Mapping) else {}
    return ", ".join(f"{name} {figure(found.get(key))}" for key, name in HEADLINE)


def summary_lines(scores: object) -> list[str]:
    """The summary's lines for the verdict JSON's :data:`OPENLANE_SCORES_KEY` ([] if none)."""
    if not isinstance(scores, Mapping) or not scores:
        return []
    det_l = scores.get("det_l_ap")
    det_t = scores.get("det_t_ap")
    per_threshold = ", ".join(
        f"{key} m {figure(v)}" for key, v in (det_l.items() if isinstance(det_l, Mapping) else ())
    )
    per_class = ", ".join(
        f"{key} {figure(v)}" for key, v in (det_t.items() if isinstance(det_t, Mapping) else ())
    )
    lines = [
        f"OpenLane-V2 scores ({scores.get('frames')} frames, semantics "
        f"{scores.get('semantics')}): {figures_text(scores)}",
        f"  lanes {scores.get('gt_lanes')} true / {scores.get('pred_lanes')} predicted, traffic "
        f"elements {scores.get('gt_elements')} / {scores.get('pred_elements')}; DET_l AP: "
        f"{per_threshold or '-'}; DET_t AP: {per_class or '-'}",
    ]
    dropped = [
        f"{scores.get(k)} {k.replace('_', ' ')}"
        for k in ("dropped_lanes", "dropped_elements", "unscored")
        if scores.get(k)
    ]
    if dropped:
        lines.append(f"  left out as unusable: {', '.join(dropped)}")
    lines.append(
        f"  rules: Fréchet below {', '.join(f'{t:g}' for t in LANE_THRESHOLDS_M)} m, IoU above "
        f"{THRESHOLDS['openlane_element_iou']:g}, links above {LINK_CONFIDENCE:g}; '-' is "
        "undefined (nothing true or predicted); docs/openlane-metrics.md"
    )
    return lines


def run_scores(frames: Iterable[FrameResults], semantics: str) -> dict[str, Any]:
    """The segment's figures: the latest scored frame's ``openlane_segment`` (every scored
    frame pooled), with the semantics and rules that produced them; {} when none scored."""
    latest: tuple[int, Mapping[str, Any]] | None = None
    for frame in frames:
        result = frame.results.get("perception")
        segment = result.metrics.get(SEGMENT_KEY) if result is not None else None
        if isinstance(segment, Mapping) and (latest is None or frame.timestamp_ms >= latest[0]):
            latest = (frame.timestamp_ms, segment)
    if latest is None:
        return {}
    rules = {key: list(v) if isinstance(v, list) else v for key, v in RULES.items()}
    return {**latest[1], "semantics": semantics, "rules": rules}


def _frames(count: object) -> str:
    if not isinstance(count, int) or isinstance(count, bool):
        return "- frames"
    return f"{count} frame" + ("" if count == 1 else "s")


class LaneScorer(Scorer):
    """The perception module's scorer for a segment's lane graphs (``SCORER``): each
    not-judged frame's figures and the segment's so far, the segment's figures, their
    summary and live status lines."""

    keys = (OPENLANE_SCORES_KEY,)

    def document(
        self, log: RunLog, frames: Sequence[FrameResults], semantics: str
    ) -> dict[str, Any]:
        lanes = run_scores(frames, semantics)
        return {OPENLANE_SCORES_KEY: lanes} if lanes else {}

    def summary_lines(self, document: Mapping[str, Any], shown: int) -> list[str]:
        return summary_lines(document.get(OPENLANE_SCORES_KEY))

    def frame_scores(
        self, log: RunLog, timestamp_ms: int, params: Params, kept: dict[str, Any]
    ) -> FrameScores:
        if not log.lanes and not log.lanes_predicted:
            return FrameScores({}, {})
        metrics = frame_scores(log, timestamp_ms, LaneMatches.kept_in(kept))
        return FrameScores(metrics, dict(THRESHOLDS) if metrics else {})

    def status_text(self, metrics: Mapping[str, Metric]) -> str | None:
        if FRAME_KEY not in metrics:
            return None
        segment = metrics.get(SEGMENT_KEY)
        frames = segment.get("frames") if isinstance(segment, Mapping) else None
        return (
            f"OpenLane-V2 {figures_text(metrics[FRAME_KEY])} (frame) / "
            f"{figures_text(segment)} (segment so far, {_frames(frames)})"
        )


SCORER = LaneScorer()

__all__ = [
    "FRAME_KEY",
    "INPUTS_KEY",
    "OPENLANE_SCORES_KEY",
    "RULES",
    "SCORER",
    "SEGMENT_KEY",
    "THRESHOLDS",
    "LaneMatches",
    "figure",
    "figures_text",
    "frame_scores",
    "model_given",
    "run_scores",
    "scored_pair",
    "summary_lines",
]
