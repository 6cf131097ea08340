"""The best one-to-one matching of eligible pairs, without SciPy where none compete.

Why: matching detections to ground truth is an assignment problem (Hungarian), solved by
SciPy's ``linear_sum_assignment``; but importing ``scipy.optimize`` costs about 0.4 s, more
than judging a long run's perception, and on most frames no two eligible pairs share a row
or a column. Then every eligible pair is in the optimum (each scores > 0, an ineligible
pair 0, and none excludes another), so it is the answer: the same rows and columns the
solver returns. SciPy is imported, once, only for a frame where pairs do compete.
"""

from __future__ import annotations

import numpy as np

from ads_rca.model import FloatArray


def best_matching(eligible: np.ndarray, score: FloatArray) -> tuple[np.ndarray, np.ndarray]:
    """The matched (rows ascending, columns) maximising the summed ``score`` over the
    ``eligible`` pairs (boolean matrix); an ineligible pair is never matched."""
    rows, cols = np.nonzero(eligible)  # row-major: rows ascending
    if (
        np.unique(rows).size == rows.size
        and np.unique(cols).size == cols.size
        and bool((score[rows, cols] > 0).all())
    ):
        return rows, cols
    from scipy.optimize import linear_sum_assignment

    rows, cols = linear_sum_assignment(np.where(eligible, -score, 0.0))
    keep = eligible[rows, cols]
    return rows[keep], cols[keep]
