"""``best_matching`` is SciPy's assignment, with SciPy left unimported where no pairs compete
and its solver loaded alone (not ``scipy.optimize``) where they do."""

from __future__ import annotations

import importlib.util
import subprocess
import sys

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

from ads_rca.oracles.corrected import assignment
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


def test_competing_pairs_load_the_solver_alone() -> None:
    """Detections each overlapping two gt boxes: the solver decides, without the 0.3 s
    import of ``scipy.optimize`` (or of any other SciPy module); importing the package
    afterwards still works."""
    code = (
        "import sys, numpy as np\n"
        "from ads_rca.oracles.corrected.perception import match_boxes\n"
        "gts = np.array([[0, 0, 10, 10], [1, 0, 11, 10], [2, 0, 12, 10]], float)\n"
        "dets = np.array([[0.5, 0, 10.5, 10], [1.5, 0, 11.5, 10]], float)\n"
        "rows, cols, ious, best = match_boxes(dets, gts, 0.5)\n"
        "print(rows.tolist(), cols.tolist())\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] == 'scipy'))\n"
        "from scipy.optimize import linear_sum_assignment\n"  # the package still imports
        "print(linear_sum_assignment(-np.eye(2))[1].tolist())\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    matched, modules, later = done.stdout.strip().splitlines()
    gts = np.array([[0, 0, 10, 10], [1, 0, 11, 10], [2, 0, 12, 10]], float)
    dets = np.array([[0.5, 0, 10.5, 10], [1.5, 0, 11.5, 10]], float)
    from ads_rca.foundation.geometry import axis_aligned_iou

    iou = axis_aligned_iou(dets, gts)
    want = scipy_matching(iou >= 0.5, iou)
    assert matched == f"{want[0].tolist()} {want[1].tolist()}"
    assert modules == "['scipy.optimize._lsap']"  # the extension alone
    assert later == "[0, 1]"


def test_the_solver_falls_back_to_the_public_import(monkeypatch: pytest.MonkeyPatch) -> None:
    """Where SciPy's extension is not where this version keeps it: ``scipy.optimize``."""
    assignment.solver.cache_clear()
    monkeypatch.setattr(importlib.util, "find_spec", lambda name: None)
    try:
        assert assignment.solver() is linear_sum_assignment
    finally:
        assignment.solver.cache_clear()
    assert assignment.solver().__name__ == "linear_sum_assignment"
