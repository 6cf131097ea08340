"""Prediction scoring: a predictor's tracks against the realised future of the actors.

A run whose prediction module cannot be judged by the verdict rules (a dataset's run: no
predictions on ground truth, no plan) may still carry a predictor's output (``diagnose
--predictions DIR``, or a stack's predictions): each predicted track whose id is an actor's is
scored against where that actor really went, with the usual trajectory-prediction figures:

- a track's step key k is k + 1 frames ahead, anchored at the ego pose at ts and rotated by
  its yaw (docs/semantics-corrected.md, the prediction frame); keys k < ``prediction_window``;
- a step is scored where the actor has a position k + 1 frames later, at or before the
  collision frame when there is one (what follows a crash is no future to predict; the
  live graph's view also ends there);
- ADE: the mean distance over a track's scored steps; FDE: the distance at its last scored
  step; a miss: FDE above :data:`MISS_M` (2 m);
- per frame: how many tracks were scored (``scored_ids``), how many ids are no actor of the
  frame (``unmatched_ids``), mean ADE, mean FDE and the miss rate over the scored tracks, and
  the same per actor type (``by_type``; the types the run's metadata gives,
  :data:`ACTOR_TYPES_KEY`, else ``unknown``);
- over the run (:func:`run_scores`): the same, every scored (track, frame) counted once.

Pure numpy per frame; the same function scores offline and in the live prediction monitor.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from ads_rca.diagnosis.scoring import FrameScores, Scorer
from ads_rca.diagnosis.verdict import FrameResults, Metric
from ads_rca.foundation.geometry import ego_to_world
from ads_rca.foundation.text import metres, short
from ads_rca.model import RunLog
from ads_rca.params import Params

#: A track whose final displacement error exceeds this (m) missed.
MISS_M = 2.0
#: Key of the metadata document mapping actor ids to their types (written by a reader whose
#: dataset types its agents).
ACTOR_TYPES_KEY = "actor_types"
UNKNOWN_TYPE = "unknown"
#: Key of the verdict JSON holding the run's scores.
SCORES_KEY = "prediction_scores"


def frame_scores(log: RunLog, ts: int, window: int) -> dict[str, Metric]:
    """The scores of the raw predictions at ``ts`` ({} when there are none to score)."""
    tracks, pose, actors = log.predictions.get(ts), log.pose.get(ts), log.actors.get(ts)
    if not tracks or pose is None or actors is None:
        return {}
    frame_ms = log.frame_ms
    meta = log.metadata
    last_ms = meta.collision_frame * frame_ms if meta.has_collision else None
    ids = [i for i in tracks if i in actors.index]
    unmatched = len(tracks) - len(ids)
    per_track: list[tuple[str, float, float]] = []  # (id, ADE, FDE)
    for actor_id in ids:
        track = tracks[actor_id]
        usable = (track.steps >= 0) & (track.steps < window)
        steps, offsets = track.steps[usable], track.offsets[usable]
        if steps.size == 0:
            continue
        real = np.full((steps.size, 2), np.nan)
        for n, step in enumerate(steps.tolist()):
            stamp = ts + (step + 1) * frame_ms
            if last_ms is not None and stamp > last_ms:
                continue
            later = log.actors.get(stamp)
            row = later.index.get(actor_id) if later is not None else None
            if row is not None:
                real[n] = later.location[row, 0:2]  # type: ignore[union-attr]
        predicted = ego_to_world(offsets[:, 0:2], pose.xy, pose.yaw)
        error = np.hypot(*(predicted - real).T)
        scored = np.isfinite(error)
        if not scored.any():
            continue
        order = np.argsort(steps[scored], kind="stable")
        errors = error[scored][order]
        per_track.append((actor_id, float(errors.mean()), float(errors[-1])))
    types = _actor_types(log)
    out: dict[str, Metric] = {"unmatched_ids": unmatched, **_summary(per_track)}
    kinds = sorted({types.get(i, UNKNOWN_TYPE) for i, _, _ in per_track})
    out["by_type"] = {
        kind: _summary([t for t in per_track if types.get(t[0], UNKNOWN_TYPE) == kind])
        for kind in kinds
    }
    return out


def _summary(per_track: list[tuple[str, float, float]]) -> dict[str, Metric]:
    if not per_track:
        return {"scored_ids": 0, "ade": None, "fde": None, "miss_rate": None}
    ade = np.array([a for _, a, _ in per_track])
    fde = np.array([f for _, _, f in per_track])
    return {
        "scored_ids": len(per_track),
        "ade": float(ade.mean()),
        "fde": float(fde.mean()),
        "miss_rate": float((fde > MISS_M).mean()),
    }


def _actor_types(log: RunLog) -> Mapping[str, str]:
    listed = log.metadata.raw.get(ACTOR_TYPES_KEY)
    if not isinstance(listed, Mapping):
        return {}
    return {str(k): v for k, v in listed.items() if isinstance(v, str)}


def run_scores(frames: Iterable[FrameResults]) -> dict[str, Any]:
    """The run's scores from its frames' prediction results ({} when nothing was scored):
    each figure the mean over every scored (track, frame), overall and per type."""
    totals: dict[str, list[float]] = {}

    def add(kind: str, summary: Mapping[str, Any]) -> None:
        count = summary.get("scored_ids")
        if not isinstance(count, int) or count <= 0:
            return
        row = totals.setdefault(kind, [0.0, 0.0, 0.0, 0.0])
        row[0] += count
        for n, key in enumerate(("ade", "fde", "miss_rate"), start=1):
            value = summary.get(key)
            row[n] += float(value) * count if isinstance(value, int | float) else 0.0

    for frame in frames:
        result = frame.results.get("prediction")
        if result is None or not isinstance(result.metrics.get("scored_ids"), int):
            continue
        add("", result.metrics)
        by_type = result.metrics.get("by_type")
        for kind, summary in (by_type if isinstance(by_type, dict) else {}).items():
            if isinstance(summary, dict):
                add(kind, summary)
    if "" not in totals:
        return {}

    def figures(row: list[float]) -> dict[str, Any]:
        count = row[0]
        return {
            "scored": int(count),
            "ade": row[1] / count,
            "fde": row[2] / count,
            "miss_rate": row[3] / count,
        }

    return {
        **figures(totals.pop("")),
        "miss_threshold_m": MISS_M,
        "by_type": {kind: figures(row) for kind, row in sorted(totals.items())},
    }


class PredictionScorer(Scorer):
    """The prediction module's scorer (``SCORER``): each not-judged frame's tracks, the run's
    figures, their summary and live status lines."""

    keys = (SCORES_KEY,)

    def document(
        self, log: RunLog, frames: Sequence[FrameResults], semantics: str
    ) -> dict[str, Any]:
        scores = run_scores(frames)
        return {SCORES_KEY: scores} if scores else {}

    def summary_lines(self, document: Mapping[str, Any], shown: int) -> list[str]:
        scores = document.get(SCORES_KEY)
        if not (isinstance(scores, dict) and scores.get("scored")):
            return []
        lines = [
            f"prediction scores ({scores['scored']} tracks against the realised future): "
            + _score_text(scores)
        ]
        by_type = scores.get("by_type")
        for kind, row in (by_type if isinstance(by_type, dict) else {}).items():
            if isinstance(row, dict):
                lines.append(f"  {kind}: {row.get('scored')} tracks, {_score_text(row)}")
        return lines

    def frame_scores(
        self, log: RunLog, timestamp_ms: int, params: Params, kept: dict[str, Any]
    ) -> FrameScores:
        return FrameScores(frame_scores(log, timestamp_ms, params.prediction_window), {})

    def status_text(self, metrics: Mapping[str, Metric]) -> str | None:
        if not metrics.get("scored_ids"):
            return None
        return (
            f"{metrics['scored_ids']} predictions scored "
            f"(ADE {metres(metrics.get('ade'))}, FDE {metres(metrics.get('fde'))})"
        )


def _score_text(row: Mapping[str, Any]) -> str:
    return (
        f"ADE {short(row.get('ade'))} m, FDE {short(row.get('fde'))} m, "
        f"miss rate {short(row.get('miss_rate'))} (FDE > {MISS_M:g} m)"
    )


SCORER = PredictionScorer()
