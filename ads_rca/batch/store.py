"""A batch's output folder, written as the runs finish.

``OUT/runs/<run_id>.json``
    the verdict JSON of each diagnosed run (``diagnose --json``'s bytes), written atomically;
``OUT/results.csv``
    one row per finished run (:data:`~ads_rca.batch.rows.COLUMNS`), appended and flushed as
    each run finishes: the record of what is done. A row is appended only after its JSON is
    in place, so an interrupted batch (Ctrl-C, a kill, a power cut) loses no finished run;
    at worst the last line is cut short, and ``--resume`` drops it and redoes that run;
``OUT/results.parquet``
    the same rows with typed columns, rewritten atomically (a temporary file renamed) every
    :data:`PARQUET_EVERY` rows or :data:`PARQUET_SECONDS` seconds and at the end.

``--resume`` reads ``results.csv`` back: its run ids are skipped, its rows kept.
"""

from __future__ import annotations

import csv
import io
import os
import tempfile
import time
from collections.abc import Iterable
from pathlib import Path
from typing import Any, TextIO

from ads_rca.batch.rows import (
    BOOL,
    COLUMNS,
    FLOAT,
    INT,
    TYPES,
    Row,
    from_text,
    storable,
    to_text,
)
from ads_rca.errors import InputError
from ads_rca.foundation.text import printable

CSV_NAME = "results.csv"
PARQUET_NAME = "results.parquet"
RUNS_DIR = "runs"
PARQUET_EVERY = 200
PARQUET_SECONDS = 30.0


class ResultStore:
    """The output folder ``out`` (see the module docstring); ``resume`` keeps its rows."""

    def __init__(self, out: Path, resume: bool = False) -> None:
        self.out = out
        self.rows: dict[str, Row] = {}
        out.mkdir(parents=True, exist_ok=True)
        (out / RUNS_DIR).mkdir(exist_ok=True)
        csv_path = out / CSV_NAME
        if resume and csv_path.exists():
            for row in read_csv(csv_path):
                self.rows[row["run_id"]] = row
            self._rewrite_csv()  # without a line cut short by an interrupted batch
        else:
            _atomic_write(csv_path, _csv_text([]).encode("utf-8"))
        self._csv: TextIO | None = csv_path.open("a", encoding="utf-8", newline="")
        self._writer = csv.writer(self._csv)
        self._unsaved = 0
        self._saved_at = time.monotonic()

    @property
    def done(self) -> set[str]:
        """Run ids with a row (skipped by ``--resume``)."""
        return set(self.rows)

    def add(self, row: Row, document: bytes | None) -> None:
        """Record one finished run: its JSON first, then its row (flushed)."""
        row = storable(row)
        if document is not None:
            _atomic_write(self.out / RUNS_DIR / f"{row['run_id']}.json", document)
        assert self._csv is not None
        self._writer.writerow([to_text(name, row[name]) for name in COLUMNS])
        self._csv.flush()
        self.rows[row["run_id"]] = row
        self._unsaved += 1
        if self._unsaved >= PARQUET_EVERY or time.monotonic() - self._saved_at > PARQUET_SECONDS:
            self.save_parquet()

    def save_parquet(self) -> None:
        write_parquet(self.out / PARQUET_NAME, self.rows.values())
        self._unsaved = 0
        self._saved_at = time.monotonic()

    def close(self) -> None:
        """Flush everything: the CSV closed, the Parquet file written with every row."""
        if self._csv is not None:
            self._csv.close()
            self._csv = None
            self.save_parquet()

    def _rewrite_csv(self) -> None:
        _atomic_write(self.out / CSV_NAME, _csv_text(self.rows.values()).encode("utf-8"))


def read_csv(path: Path) -> list[Row]:
    """The complete rows of a batch's ``results.csv`` (a line cut short is dropped)."""
    try:
        with path.open(encoding="utf-8", newline="") as handle:
            text = handle.read()
    except (OSError, UnicodeDecodeError) as error:
        raise InputError(f"--resume {printable(path)}: cannot read ({error})") from None
    # A last line without its newline was cut short: that run is redone.
    text = text[: text.rfind("\n") + 1]
    reader = csv.reader(io.StringIO(text))
    header = next(reader, None)
    if header is None:
        return []
    if tuple(header) != COLUMNS:
        raise InputError(
            f"--resume {printable(path)}: not the results of this version of ads-rca batch "
            "(other columns)"
        )
    rows: list[Row] = []
    for cells in reader:
        if len(cells) != len(COLUMNS):  # zip below is then exact
            continue
        try:
            rows.append(
                {name: from_text(name, cell) for name, cell in zip(COLUMNS, cells, strict=True)}
            )
        except ValueError:
            continue
    return rows


def _csv_text(rows: Iterable[Row]) -> str:
    buffer = io.StringIO()
    writer = csv.writer(buffer)
    writer.writerow(COLUMNS)
    for row in rows:
        writer.writerow([to_text(name, row[name]) for name in COLUMNS])
    return buffer.getvalue()


def write_parquet(path: Path, rows: Iterable[Row]) -> None:
    """``rows`` as a Parquet file with :data:`COLUMNS`' types, replaced atomically."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    kinds = {INT: pa.int64(), FLOAT: pa.float64(), BOOL: pa.bool_()}
    schema = pa.schema([(name, kinds.get(TYPES[name], pa.string())) for name in COLUMNS])
    listed = list(rows)
    table = pa.table({name: [row[name] for row in listed] for name in COLUMNS}, schema=schema)
    fd, temporary = tempfile.mkstemp(prefix=".results.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        pq.write_table(table, temporary)
        os.replace(temporary, path)
    except BaseException:
        os.unlink(temporary)
        raise


def read_parquet(path: Path) -> list[dict[str, Any]]:
    import pyarrow.parquet as pq

    return list(pq.read_table(path).to_pylist())


def _atomic_write(path: Path, data: bytes) -> None:
    fd, temporary = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
        os.replace(temporary, path)
    except BaseException:
        if os.path.exists(temporary):
            os.unlink(temporary)
        raise
