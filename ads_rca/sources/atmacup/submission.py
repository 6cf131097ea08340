"""A submission to atmaCup #18: the predicted future ego path of every test row.

The competition's format is a CSV of the 18 columns ``x_0, y_0, z_0, …, x_5, y_5, z_5``
(the ego at t + 0.5 … 3.0 s in its right-handed frame at t), one row per table row in the
table's order, no ID column. A submission may also carry an ``ID`` column: its rows are
then matched to the table's by ID (IDs the table lacks and table rows it lacks are
reported), in any order. Without one, data row k is the table's data row k (a table row
the reader skipped takes its submission row with it, so the others stay aligned).

A submission that cannot be used at all (unreadable, no header, a target column missing)
is one line (InputError); a row whose values are not all finite numbers (or are too large
to compute with: beyond ±``MAX_PATH_VALUE``), too few or too many rows, IDs that match
nothing are reported, and the rest is scored.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from ads_rca.errors import InputError
from ads_rca.foundation.geometry import FloatArray
from ads_rca.problems import IGNORED, ProblemLog
from ads_rca.sources.atmacup.snapshots import HORIZONS_S, MAX_PATH_VALUE, TARGET_COLUMNS
from ads_rca.sources.csv_table import numbers, read_csv_table, shown, unknown_columns

ID_COLUMN = "ID"
NOT_SCORED = "those rows not scored"


def read_submission(
    path: str | os.PathLike[str],
    ids: Sequence[str],
    positions: npt.NDArray[np.int64],
    data_rows: int,
    limit: int,
    problems: ProblemLog,
) -> tuple[FloatArray, dict[str, Any]]:
    """The predicted paths of the table's usable rows (``ids``, at ``positions`` among its
    ``data_rows``), (rows, 6, 3) with y mirrored as the realised ones, NaN where the
    submission gives none; and what the metadata says about it (file, rows, how matched)."""
    name = Path(path).name
    table = read_csv_table(os.fspath(path), name, limit, problems, "submission")
    missing = [c for c in TARGET_COLUMNS if not table.has(c)]
    if missing:
        raise InputError(
            f"{path}: not a submission: no column {', '.join(missing[:3])}"
            + (f" and {len(missing) - 3} more" if len(missing) > 3 else "")
            + f" (expected the {len(TARGET_COLUMNS)} columns x_0, y_0, z_0 … z_5)"
        )
    unknown_columns(table, (ID_COLUMN, *TARGET_COLUMNS), problems)
    by_id = table.has(ID_COLUMN)
    labels = (
        [f"row {shown(i)}" for i in table.cells(ID_COLUMN)]
        if by_id
        else [f"data row {n + 1}" for n in range(len(table))]
    )
    values = np.stack(
        [numbers(table, c, labels, problems, bound=MAX_PATH_VALUE) for c in TARGET_COLUMNS],
        axis=1,
    )
    if by_id:
        source_rows = _match_ids(table.cells(ID_COLUMN), ids, name, problems)
    else:
        source_rows = _match_order(len(table), positions, data_rows, name, problems)
    out = np.full((len(ids), len(TARGET_COLUMNS)), np.nan)
    found = source_rows >= 0
    out[found] = values[source_rows[found]]
    paths = out.reshape(len(ids), len(HORIZONS_S), 3)
    paths[:, :, 1] = 0.0 - paths[:, :, 1]  # mirrored as the realised paths are
    info = {
        "file": name,
        "data_rows": len(table),
        "matched_by": "ID" if by_id else "row order",
        "matched_rows": int(found.sum()),
    }
    return paths, info


def _match_order(
    count: int,
    positions: npt.NDArray[np.int64],
    data_rows: int,
    name: str,
    problems: ProblemLog,
) -> npt.NDArray[np.int64]:
    """Submission row per usable table row, by position (-1 where it has none)."""
    if count < data_rows:
        problems.add(
            name,
            "",
            f"{count} rows for the table's {data_rows}: the last {data_rows - count} table rows "
            "have no prediction",
            NOT_SCORED,
        )
    elif count > data_rows:
        problems.add(
            name,
            "",
            f"{count} rows for the table's {data_rows}: the last {count - data_rows}",
            IGNORED,
        )
    out: npt.NDArray[np.int64] = np.where(positions < count, positions, -1)
    return out


def _match_ids(
    cells: Sequence[str], ids: Sequence[str], name: str, problems: ProblemLog
) -> npt.NDArray[np.int64]:
    """Submission row per usable table row, by ID (-1 where it has none)."""
    rows: dict[str, int] = {}
    repeated: list[int] = []
    for n, cell in enumerate(cells):
        ident = cell.strip()
        if ident in rows:
            repeated.append(n)
        else:
            rows[ident] = n
    if repeated:
        problems.add(
            name,
            ID_COLUMN,
            f"{len(repeated)} rows repeat an earlier row's ID (the first: data row "
            f"{repeated[0] + 1}, {shown(cells[repeated[0]])!r})",
            "the first row used",
        )
    known = set(ids)
    unknown = [i for i in rows if i not in known]
    if unknown:
        problems.add(
            name,
            ID_COLUMN,
            f"{len(unknown)} IDs are no row of the table (the first: {shown(unknown[0])!r})",
            IGNORED,
        )
    out = np.fromiter((rows.get(i, -1) for i in ids), dtype=np.int64, count=len(ids))
    lacking = np.flatnonzero(out < 0)
    if lacking.size:
        problems.add(
            name,
            ID_COLUMN,
            f"{lacking.size} table rows have no prediction (the first: {ids[int(lacking[0])]})",
            NOT_SCORED,
        )
    return out
