"""A CSV file read by its header's column names, its columns converted a column at a time.

Dataset tables (a competition's features, a submission) are tens of thousands of rows: each
column is parsed by numpy in one call, and only a column holding something that is no
number is walked value by value (to find which). A defect becomes one problem per column
and kind (how many rows, the first named), never one per row: a column of text in a big
table is one line, not forty thousand.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ads_rca.errors import InputError
from ads_rca.foundation.files import Unreadable, read_regular
from ads_rca.foundation.geometry import FloatArray
from ads_rca.problems import DROPPED_RECORD, IGNORED, ProblemLog

#: The longest column name or cell text shown in a problem.
MAX_TEXT = 64
#: The texts a boolean column may hold (compared lower-cased, stripped).
TRUE_TEXTS = frozenset({"true", "1", "1.0"})
FALSE_TEXTS = frozenset({"false", "0", "0.0"})


def shown(text: str) -> str:
    """A cell or column name for a problem line: at most :data:`MAX_TEXT` characters."""
    return text if len(text) <= MAX_TEXT else text[: MAX_TEXT - 1] + "…"


@dataclass(frozen=True)
class CsvTable:
    """A CSV file's header and data rows (every row as long as the header: a row of
    another length is kept as empty cells and flagged in ``short``, so row positions hold)."""

    name: str
    header: tuple[str, ...]
    #: Column name -> its position (the first, should a name repeat).
    index: Mapping[str, int]
    #: The cells column by column (``columns[i][row]``).
    columns: tuple[tuple[str, ...], ...]
    #: Rows whose field count was not the header's (their cells read as empty).
    short: npt.NDArray[np.bool_]

    def __len__(self) -> int:
        return len(self.short)

    def has(self, column: str) -> bool:
        return column in self.index

    def cells(self, column: str) -> tuple[str, ...]:
        return self.columns[self.index[column]]


def read_csv_table(
    path: str, name: str, limit: int, problems: ProblemLog, what: str = "table"
) -> CsvTable:
    """The table in ``path`` (a regular file of at most ``limit`` bytes, UTF-8 text with a
    header row); InputError (one line) when it cannot be used at all. Rows of another field
    count than the header's and a cut or damaged tail are reported (``name`` is the file
    named in problems)."""
    data = read_regular(path, limit)
    if isinstance(data, Unreadable):
        raise InputError(f"{path}: {data.issue}")
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as error:
        raise InputError(f"{path}: not UTF-8 text ({error.reason} at byte {error.start})") from None
    reader = csv.reader(io.StringIO(text, newline=""))
    rows: list[list[str]] = []
    header: list[str] | None = None
    try:
        header = next(reader, None)
        rows.extend(reader)
    except csv.Error as error:
        if header is None:
            raise InputError(f"{path}: not a CSV {what} ({error})") from None
        problems.add(
            name,
            f"line {reader.line_num}",
            f"not CSV ({error}): the {len(rows)} rows before it kept",
            DROPPED_RECORD,
        )
    if header is None:
        raise InputError(f"{path}: empty file: no header row")
    header = [cell.strip() for cell in header]
    index: dict[str, int] = {}
    for position, column in enumerate(header):
        if column in index:
            problems.add(name, shown(column), "the column repeats", "the first kept", "warning")
            continue
        index[column] = position
    while rows and not any(cell.strip() for cell in rows[-1]):
        rows.pop()  # blank lines at the end
    width = len(header)
    short = np.fromiter((len(row) != width for row in rows), dtype=bool, count=len(rows))
    if short.any():
        first = int(np.argmax(short))
        problems.add(
            name,
            "",
            f"{int(short.sum())} rows do not have the header's {width} fields (the first: data "
            f"row {first + 1}, {len(rows[first])} fields)",
            DROPPED_RECORD,
        )
        empty = [""] * width
        rows = [empty if bad else row for row, bad in zip(rows, short.tolist(), strict=True)]
    columns = tuple(zip(*rows, strict=True)) if rows else tuple(() for _ in header)
    return CsvTable(name, tuple(header), index, columns, short)


def numbers(
    table: CsvTable,
    column: str,
    labels: Sequence[str],
    problems: ProblemLog,
    used: npt.NDArray[np.bool_] | None = None,
    bound: float = math.inf,
) -> FloatArray:
    """A column as floats; a cell that is no finite number is NaN, reported once for the
    column (how many, the first by its label in ``labels``) among the ``used`` rows (all by
    default); so is one beyond ±``bound`` (too large to compute with). Rows of the wrong
    length are NaN unreported (their own problem said so)."""
    cells = table.cells(column)
    try:
        values = np.array(cells, dtype=np.float64)
    except ValueError:
        values = np.array([_float(cell) for cell in cells], dtype=np.float64)
    judged = _judged(table, used)
    said = (table, column, labels, problems)
    _read_as_nan(said, values, ~np.isfinite(values) & judged, "not a finite number")
    _read_as_nan(
        said,
        values,
        np.isfinite(values) & (np.abs(values) > bound) & judged,
        f"beyond ±{bound:g}, too large to compute with",
    )
    return values


#: A column as its refusals name it: its table, its name, the rows' labels, where to say.
_Column = tuple[CsvTable, str, Sequence[str], ProblemLog]


def _judged(table: CsvTable, used: npt.NDArray[np.bool_] | None) -> npt.NDArray[np.bool_]:
    """The rows whose cells are judged: of the header's length, and ``used`` (all by
    default)."""
    judged: npt.NDArray[np.bool_] = ~table.short & (True if used is None else used)
    return judged


def _read_as_nan(
    column: _Column, values: FloatArray, rows: npt.NDArray[np.bool_], why: str
) -> None:
    """``rows`` of ``column`` read as NaN in ``values``, said once: how many, why, the first
    by its label."""
    if not rows.any():
        return
    table, name, labels, problems = column
    first = int(np.argmax(rows))
    problems.add(
        table.name,
        shown(name),
        f"{int(rows.sum())} rows: {why} (the first: {labels[first]}, "
        f"{shown(table.cells(name)[first])!r})",
        "read as NaN",
    )
    values[rows] = np.nan


def _float(cell: str) -> float:
    try:
        return float(cell)
    except ValueError:
        return float("nan")


def booleans(
    table: CsvTable,
    column: str,
    labels: Sequence[str],
    problems: ProblemLog,
    used: npt.NDArray[np.bool_] | None = None,
) -> FloatArray:
    """A column of True/False (any case, or 1/0) as 1.0 / 0.0; anything else NaN, reported
    once for the column (among the ``used`` rows)."""
    texts, inverse = np.unique(np.array(table.cells(column), dtype=str), return_inverse=True)
    lookup = np.array(
        [
            1.0
            if t.strip().lower() in TRUE_TEXTS
            else 0.0
            if t.strip().lower() in FALSE_TEXTS
            else np.nan
            for t in texts.tolist()
        ],
        dtype=np.float64,
    ).reshape(-1)
    values: FloatArray = lookup[inverse.reshape(-1)] if len(texts) else np.zeros(0)
    said = (table, column, labels, problems)
    _read_as_nan(said, values, np.isnan(values) & _judged(table, used), "not true or false")
    return values


def unknown_columns(table: CsvTable, known: Sequence[str], problems: ProblemLog) -> None:
    """One warning naming the columns the reader does not use (a pandas index, extra
    features)."""
    extra = [c for c in table.index if c not in known]
    if extra:
        names = ", ".join(shown(c) for c in extra[:5]) + (" …" if len(extra) > 5 else "")
        problems.add(table.name, "", f"{len(extra)} columns not read: {names}", IGNORED, "warning")
