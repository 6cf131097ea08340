"""``best_matching`` is SciPy's assignment, with SciPy left unimported where no pairs compete."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
from scipy.optimize import linear_sum_assignment

from ads_rca.oracles.corrected.assignment import best_matching


def scipy_matching(eligible: np.ndarray, score: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    rows, cols = linear_sum_assignment(np.where(eligible, -score, 0.0))
    keep = eligible[rows, cols]
    return rows[keep], cols[keep]


def test_the_same_matching_as_scipy_on_random_matrices() -> None:
    """Sparse (the fast path), dense (conflicts), tied and zero scores, empty and
    rectangular matrices: the same rows and columns, in the same order."""
    rng = np.random.default_rng(18)
    fast = 0
    for case in range(3000):
        n, m = rng.integers(0, 9, size=2)
        density = (0.05, 0.2, 0.6, 1.0)[case % 4]
        eligible = rng.random((n, m)) < density
        score = rng.random((n, m))
        if case % 5 == 0:
            score = np.round(score, 1)  # ties
        if case % 7 == 0:
            score[rng.random((n, m)) < 0.2] = 0.0  # an eligible pair worth nothing
        want = scipy_matching(eligible, score)
        got = best_matching(eligible, score)
        assert [a.tolist() for a in got] == [a.tolist() for a in want], case
        rows, cols = np.nonzero(eligible)
        fast += np.unique(rows).size == rows.size and np.unique(cols).size == cols.size
    assert fast > 500  # the fast path was exercised, and so was the solver


def test_no_scipy_import_where_no_pairs_compete() -> None:
    code = (
        "import sys, numpy as np\n"
        "from ads_rca.oracles.corrected.perception import match_boxes\n"
        "boxes = np.array([[0, 0, 1, 1], [5, 5, 6, 6]], float)\n"
        "rows, cols, ious, best = match_boxes(boxes, boxes[::-1].copy(), 0.5)\n"
        "assert rows.tolist() == [0, 1] and cols.tolist() == [1, 0], (rows, cols)\n"
        "print('scipy.optimize' in sys.modules)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "False"
