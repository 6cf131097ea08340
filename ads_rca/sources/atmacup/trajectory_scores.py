"""Ego-trajectory scoring: a model's predicted future ego paths against the realised ones,
as atmaCup #18 scored its submissions, and with the usual displacement errors.

A table of snapshots (``ads_rca.sources.atmacup.snapshots``) gives, per row, where the ego really
was
at t + 0.5 … 3.0 s and, with a submission, where a model said it would be:

- ``mae``: the competition's metric, the mean of |realised − predicted| over all 18 values
  (x, y, z at six horizons) of every scored row, flat (z counts as x and y do; the table's
  y mirrored changes no absolute difference);
- per row: ADE, the mean over the six horizons of the 3-D Euclidean distance between the
  realised and predicted points (3-D because the competition scores z too), FDE, that
  distance at 3.0 s, and the row's own MAE (``per_row``, every scored row);
- per horizon (0.5 … 3.0 s): the mean distance and the MAE over the scored rows; per axis,
  the MAE;
- the :data:`WORST_ROWS` rows of the largest ADE, with their IDs (bounded text), worst
  first, ties in table order.

A row is scored when all 36 of its values (realised and predicted) are finite numbers
within ±``MAX_PATH_VALUE`` (the readers report larger ones as input problems: their
differences would overflow); rows lacking either are counted (``no_truth``,
``no_prediction``), not guessed. A test
table has no realised paths: nothing is scored, and the document says why.

Pure numpy over all rows at once (43,000 rows in a few milliseconds).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from ads_rca.diagnosis.scoring import FrameScores, Scorer
from ads_rca.diagnosis.verdict import FrameResults, Metric
from ads_rca.foundation.text import metres, precise, short, shown_id
from ads_rca.model import RunLog
from ads_rca.params import Params
from ads_rca.sources.atmacup.snapshots import HORIZONS_S, MAX_PATH_VALUE, EgoSnapshots

#: Key of the verdict JSON holding the scores.
TRAJECTORY_SCORES_KEY = "trajectory_scores"
#: How many of the worst rows are listed.
WORST_ROWS = 10
#: The longest row ID shown.
MAX_ID = 80


def _bounded(text: str) -> str:
    return text if len(text) <= MAX_ID else text[: MAX_ID - 1] + "…"


def trajectory_scores(snapshots: EgoSnapshots, worst: int = WORST_ROWS) -> dict[str, Any]:
    """The scores of ``snapshots``' predicted paths (see the module docstring)."""
    realised, predicted = snapshots.realised, snapshots.predicted
    truth = _usable(realised)
    guess = _usable(predicted)
    scored = truth & guess
    out: dict[str, Any] = {
        "rows": len(snapshots),
        "submission": snapshots.submission,
        "with_truth": int(truth.sum()),
        "with_prediction": int(guess.sum()),
        "scored": int(scored.sum()),
        "no_truth": int((~truth).sum()),
        "no_prediction": int((truth & ~guess).sum()),
        "horizons_s": list(HORIZONS_S),
        "distance": "3-D Euclidean (x, y, z), metres",
    }
    if not snapshots.submission:
        out["note"] = "no submission given (--submission FILE): nothing to score"
        return out
    if not scored.any():
        if not truth.any():
            why = " (a test table has no targets: score against a train table's rows)"
        elif not guess.any():
            why = ": the submission gives no usable predicted path (see the input problems)"
        else:
            why = ""
        out["note"] = f"no row has both a realised and a predicted path{why}"
        return out
    error = realised[scored] - predicted[scored]  # (S, 6, 3)
    absolute = np.abs(error)
    distance = np.sqrt((error**2).sum(axis=2))  # (S, 6)
    ade = distance.mean(axis=1)
    fde = distance[:, -1]
    row_mae = absolute.reshape(len(ade), -1).mean(axis=1)
    ids = [snapshots.ids[n] for n in np.flatnonzero(scored).tolist()]
    frames = (snapshots.timestamps[scored]).tolist()
    order = np.argsort(-ade, kind="stable")[:worst]
    out.update(
        {
            "mae": float(absolute.mean()),
            "ade": float(ade.mean()),
            "fde": float(fde.mean()),
            "mae_by_axis": {axis: float(absolute[:, :, n].mean()) for n, axis in enumerate("xyz")},
            "by_horizon": [
                {
                    "horizon_s": horizon,
                    "distance": float(distance[:, n].mean()),
                    "mae": float(absolute[:, n, :].mean()),
                }
                for n, horizon in enumerate(HORIZONS_S)
            ],
            "worst_rows": [
                {
                    "id": _bounded(ids[n]),
                    "timestamp_ms": int(frames[n]),
                    "ade": float(ade[n]),
                    "fde": float(fde[n]),
                    "mae": float(row_mae[n]),
                }
                for n in order.tolist()
            ],
            "per_row": {
                "ids": [_bounded(i) for i in ids],
                "ade": ade.tolist(),
                "fde": fde.tolist(),
                "mae": row_mae.tolist(),
            },
        }
    )
    return out


def _usable(paths: npt.NDArray[np.float64]) -> npt.NDArray[np.bool_]:
    """Per row: every value a finite number that can be computed with."""
    with np.errstate(invalid="ignore"):
        fits = np.abs(paths) <= MAX_PATH_VALUE  # NaN compares False
    usable: npt.NDArray[np.bool_] = np.asarray(fits.all(axis=(1, 2)), dtype=bool)
    return usable


def frame_scores(log: RunLog, timestamp_ms: int) -> dict[str, float | str]:
    """One frame's row scored (the planning module's metrics where the verdict rules cannot
    judge planning, offline and on the live monitor): its ID and its ADE, FDE and MAE as in
    ``per_row``; {} when the frame is no row with both paths."""
    snapshots = log.ego_snapshots
    row = snapshots.row_at(timestamp_ms) if snapshots is not None else None
    if snapshots is None or row is None:
        return {}
    realised, predicted = snapshots.realised[row], snapshots.predicted[row]
    if not (_usable(realised[None]).all() and _usable(predicted[None]).all()):
        return {}
    error = realised - predicted
    distance = np.sqrt((error**2).sum(axis=1))
    return {
        "row_id": _bounded(snapshots.ids[row]),
        "trajectory_ade": float(distance.mean()),
        "trajectory_fde": float(distance[-1]),
        "trajectory_mae": float(np.abs(error).mean()),
    }


def trajectory_lines(scores: object, shown: int = 10) -> list[str]:
    """The summary's lines of a snapshot table's ego-trajectory scores (:func:`trajectory_scores`):
    the competition's MAE, ADE and FDE, per horizon, the worst rows; or why nothing was
    scored."""
    if not isinstance(scores, dict):
        return []
    head = f"trajectory scores ({scores.get('scored')} of {scores.get('rows')} rows scored"
    if not scores.get("scored"):
        return [f"{head}): {scores.get('note', 'nothing scored')}"]
    figures = [scores.get(name) for name in ("mae", "ade", "fde")]
    if not all(isinstance(v, float) and math.isfinite(v) for v in figures):
        return [
            f"{head}; {scores.get('no_truth')} without a realised path, "
            f"{scores.get('no_prediction')} without a prediction): MAE, ADE, FDE: not "
            "computed (a figure is no finite number)"
        ]
    lines = [
        f"{head}; {scores.get('no_truth')} without a realised path, "
        f"{scores.get('no_prediction')} without a prediction): MAE {precise(scores.get('mae'))} "
        f"(the competition's, over x, y, z), ADE {short(scores.get('ade'))} m, "
        f"FDE {short(scores.get('fde'))} m (3-D)"
    ]
    horizons = scores.get("by_horizon")
    if isinstance(horizons, list):
        lines.append(
            "  by horizon (mean distance): "
            + ", ".join(
                f"{short(h.get('horizon_s'))} s {short(h.get('distance'))} m"
                for h in horizons
                if isinstance(h, dict)
            )
        )
    worst = scores.get("worst_rows")
    if isinstance(worst, list) and worst:
        lines.append("  worst rows by ADE:")
        lines.extend(
            f"    {row.get('id')}: ADE {short(row.get('ade'))} m, FDE "
            f"{short(row.get('fde'))} m, MAE {short(row.get('mae'))}"
            for row in worst[:shown]
            if isinstance(row, dict)
        )
    return lines


class TrajectoryScorer(Scorer):
    """The planning module's scorer for a table of snapshots (``SCORER``): each row's
    predicted ego path, the table's scores, their summary and live status lines."""

    keys = (TRAJECTORY_SCORES_KEY,)

    def document(
        self, log: RunLog, frames: Sequence[FrameResults], semantics: str
    ) -> dict[str, Any]:
        if log.ego_snapshots is None:
            return {}
        return {TRAJECTORY_SCORES_KEY: trajectory_scores(log.ego_snapshots)}

    def summary_lines(self, document: Mapping[str, Any], shown: int) -> list[str]:
        return trajectory_lines(document.get(TRAJECTORY_SCORES_KEY), shown)

    def frame_scores(
        self, log: RunLog, timestamp_ms: int, params: Params, kept: dict[str, Any]
    ) -> FrameScores:
        return FrameScores(dict(frame_scores(log, timestamp_ms)), {})

    def status_text(self, metrics: Mapping[str, Metric]) -> str | None:
        if "trajectory_ade" not in metrics:
            return None
        return (
            f"row {shown_id(str(metrics.get('row_id')))}: predicted path scored (ADE "
            f"{metres(metrics.get('trajectory_ade'))}, FDE "
            f"{metres(metrics.get('trajectory_fde'))})"
        )


SCORER = TrajectoryScorer()

__all__ = [
    "SCORER",
    "TRAJECTORY_SCORES_KEY",
    "WORST_ROWS",
    "frame_scores",
    "trajectory_lines",
    "trajectory_scores",
]
