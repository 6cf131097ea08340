"""The best one-to-one matching of eligible pairs, without SciPy where none compete.

Why: matching detections to ground truth is an assignment problem (Hungarian), solved by
SciPy's ``linear_sum_assignment``; on most frames no two eligible pairs share a row or a
column. Then every eligible pair is in the optimum (each scores > 0, an ineligible pair 0,
and none excludes another), so it is the answer: the same rows and columns the solver
returns. Where pairs do compete, the solver is loaded once (:func:`solver`).
"""

from __future__ import annotations

import functools
import importlib.machinery
import importlib.util
import os
from collections.abc import Callable

import numpy as np

from ads_rca.model import FloatArray

Solver = Callable[[FloatArray], tuple[np.ndarray, np.ndarray]]


def best_matching(eligible: np.ndarray, score: FloatArray) -> tuple[np.ndarray, np.ndarray]:
    """The matched (rows ascending, columns) maximising the summed ``score`` over the
    ``eligible`` pairs (boolean matrix); an ineligible pair is never matched."""
    # more pairs than rows or than columns: some share one (and the test below would fail)
    if np.count_nonzero(eligible) <= min(eligible.shape):
        return _unshared(eligible, score)
    return _solved(eligible, score)


def _unshared(eligible: np.ndarray, score: FloatArray) -> tuple[np.ndarray, np.ndarray]:
    """The eligible pairs themselves where none shares a row or a column with another and
    each scores > 0 (then they are the optimum), else the solver's matching."""
    rows, cols = np.nonzero(eligible)  # row-major: rows ascending
    # pairs are few (about one a box): Python sets test them faster than np.unique
    row_list, col_list = rows.tolist(), cols.tolist()
    if (
        len(set(row_list)) == len(row_list)
        and len(set(col_list)) == len(col_list)
        and all(value > 0 for value in score[rows, cols].tolist())  # False for NaN
    ):
        return rows, cols
    return _solved(eligible, score)


def _solved(eligible: np.ndarray, score: FloatArray) -> tuple[np.ndarray, np.ndarray]:
    """The solver's optimal matching, ineligible pairs dropped."""
    rows, cols = solver()(np.where(eligible, -score, 0.0))
    keep = eligible[rows, cols]
    return rows[keep], cols[keep]


@functools.cache
def solver() -> Solver:
    """SciPy's ``linear_sum_assignment``, loaded alone.

    Why: ``import scipy.optimize`` imports the whole package (about 0.3 s, paid by every
    worker judging a long run) for this one function, which SciPy builds as an extension
    module of its own (``scipy/optimize/_lsap``): that module is loaded from where SciPy
    is installed, without the package around it. The same C function, so the same
    matchings. Where SciPy is laid out otherwise, the public import.
    """
    found = importlib.util.find_spec("scipy")
    folder = os.path.join(os.path.dirname(found.origin or ""), "optimize") if found else ""
    for suffix in importlib.machinery.EXTENSION_SUFFIXES:
        path = os.path.join(folder, "_lsap" + suffix)
        if folder and os.path.isfile(path):
            loader = importlib.machinery.ExtensionFileLoader("scipy.optimize._lsap", path)
            spec = importlib.util.spec_from_file_location(loader.name, path, loader=loader)
            if spec is not None:
                module = importlib.util.module_from_spec(spec)
                loader.exec_module(module)
                function: Solver = module.linear_sum_assignment
                return function
    from scipy.optimize import linear_sum_assignment

    public: Solver = linear_sum_assignment
    return public
