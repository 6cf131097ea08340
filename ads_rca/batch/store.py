"""A batch's output folder, written as the runs finish.

``OUT/runs/<run_id>.json``
    the verdict JSON of each diagnosed run (``diagnose --json``'s bytes), written atomically
    (:mod:`ads_rca.foundation.atomic_write`: a temporary file, synced, renamed);
``OUT/results.csv``
    one row per finished run (:data:`~ads_rca.batch.rows.COLUMNS`), appended with one
    unbuffered write as each run finishes: the record of what is done. A row is appended
    only after its JSON is in place, so an interrupted batch (Ctrl-C, a kill, a power cut)
    loses no finished run; at worst the last line is cut short, and ``--resume`` drops it
    and redoes that run. A row that cannot be written whole (a full disk) is cut off again
    (the file truncated to its rows before it);
``OUT/results.parquet``
    the same rows with typed columns, rewritten atomically every :data:`PARQUET_EVERY` rows
    or :data:`PARQUET_SECONDS` seconds (no sooner than :data:`PARQUET_PAUSE` times the
    last rewrite's time after it) and at the end.

A write that fails (a full disk) raises :class:`StoreError`, one line naming the file and
saying how many finished runs are kept: every row and file written before stays whole.
``--resume`` reads ``results.csv`` back: its run ids are skipped, its rows kept.
"""

from __future__ import annotations

import contextlib
import csv
import io
import os
import time
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

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
from ads_rca.foundation.atomic_write import replace_bytes, replacing_binary
from ads_rca.foundation.text import printable

CSV_NAME = "results.csv"
PARQUET_NAME = "results.parquet"
RUNS_DIR = "runs"
PARQUET_EVERY = 200
PARQUET_SECONDS = 30.0
#: A rewrite of the Parquet file waits this many times as long as the last one took: each
#: rewrites every row (~2 s at 100k rows), so every 200 rows would make the batch's cost
#: grow with the square of its size; this keeps rewrites to a tenth of the time at most.
PARQUET_PAUSE = 9.0


class StoreError(InputError):
    """A file of the output folder could not be written (a full disk): one line; what was
    written before it is whole."""


class ResultStore:
    """The output folder ``out`` (see the module docstring); ``resume`` keeps its rows."""

    def __init__(self, out: Path, resume: bool = False) -> None:
        self.out = out
        self.rows: dict[str, Row] = {}
        self.failed = False
        self._csv: int | None = None
        csv_path = out / CSV_NAME
        with self.writing(out):
            (out / RUNS_DIR).mkdir(parents=True, exist_ok=True)
            if resume and csv_path.exists():
                for row in read_csv(csv_path):
                    self.rows[row["run_id"]] = row
                self._rewrite_csv()  # without a line cut short by an interrupted batch
            else:
                replace_bytes(csv_path, _csv_text([]).encode("utf-8"))
            self._csv = os.open(csv_path, os.O_WRONLY | os.O_APPEND | os.O_CLOEXEC)
            self._csv_size = os.fstat(self._csv).st_size
        self._unsaved = 0
        self._saved_at = time.monotonic()
        self._next_save = self._saved_at

    @property
    def done(self) -> set[str]:
        """Run ids with a row (skipped by ``--resume``)."""
        return set(self.rows)

    def add(self, row: Row, document: bytes | None) -> None:
        """Record one finished run: its JSON first, then its row (one write)."""
        row = storable(row)
        if document is not None:
            json_path = self.out / RUNS_DIR / f"{row['run_id']}.json"
            with self.writing(json_path):
                replace_bytes(json_path, document)
        buffer = io.StringIO()
        csv.writer(buffer).writerow([to_text(name, row[name]) for name in COLUMNS])
        with self.writing(self.out / CSV_NAME):
            self._append(buffer.getvalue().encode("utf-8"))
        self.rows[row["run_id"]] = row
        self._unsaved += 1
        now = time.monotonic()
        due = self._unsaved >= PARQUET_EVERY or now - self._saved_at > PARQUET_SECONDS
        if due and now >= self._next_save:
            self.save_parquet()

    def save_parquet(self) -> None:
        path = self.out / PARQUET_NAME
        started = time.monotonic()
        with self.writing(path):
            write_parquet(path, self.rows.values())
        self._unsaved = 0
        self._saved_at = time.monotonic()
        self._next_save = self._saved_at + PARQUET_PAUSE * (self._saved_at - started)

    def close(self) -> None:
        """Flush everything: the CSV closed, the Parquet file written with every row. After
        a failed write (already raised) only what can still be written is: no second error."""
        if self._csv is None:
            return
        fd, self._csv = self._csv, None
        os.close(fd)
        failed = self.failed
        try:
            self.save_parquet()
        except StoreError:
            if not failed:
                raise

    def _append(self, data: bytes) -> None:
        """``data`` at the end of the CSV, whole or not at all (cut off again on failure)."""
        assert self._csv is not None
        view = memoryview(data)
        try:
            while view:
                view = view[os.write(self._csv, view) :]
        except OSError:
            with contextlib.suppress(OSError):
                os.ftruncate(self._csv, self._csv_size)
            raise
        self._csv_size += len(data)

    @contextlib.contextmanager
    def writing(self, path: Path) -> Iterator[None]:
        """An ``OSError`` writing ``path`` as a :class:`StoreError` (one line)."""
        try:
            yield
        except OSError as error:
            self.failed = True
            why = error.strerror or str(error)
            raise StoreError(
                f"--out {printable(path)}: cannot write ({why}); the {len(self.rows)} finished "
                "runs written before are kept (--resume continues the batch)"
            ) from None

    def _rewrite_csv(self) -> None:
        replace_bytes(self.out / CSV_NAME, _csv_text(self.rows.values()).encode("utf-8"))


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
    with replacing_binary(path) as out:
        pq.write_table(table, out)


def read_parquet(path: Path) -> list[dict[str, Any]]:
    import pyarrow.parquet as pq

    return list(pq.read_table(path).to_pylist())
