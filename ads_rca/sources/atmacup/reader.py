"""Reader for atmaCup #18's driving table: ``train_features.csv`` or
``test_features.csv``, ``traffic_lights/{ID}.json`` beside it, optionally a submission.

Each row of the table is one moment of a Japanese drive (ID = ``{scene}_{deciseconds}``):
the CAN state of the car, the traffic lights a detector found in its camera image and, in
the train table, where the car really was 0.5 … 3.0 s later. The rows are **independent
snapshots** (a scene's rows are mostly ten seconds apart), so (docs/formats.md "atmaCup
#18 tables" has the whole mapping):

- frames: one per usable row, in file order, :data:`TPF_MS` (100 ms, the table's unit of
  time) apart: frame n at 100·n ms. Consecutive frames are NOT a time series; the metadata
  says so (``snapshots: true``, ``frame_layout``), and every row's ID is kept;
- the ego: at the origin of its own frame at every row (the table's frame is the ego's),
  speed ``vEgo``; the other CAN fields, the realised future path (``x_i, −y_i, z_i``: the
  table's right-handed frame mirrored) and a submission's predicted path are the run's
  :class:`~ads_rca.sources.atmacup.snapshots.EgoSnapshots`;
- 2-D detections: the row's traffic lights (``bboxes``: id = ``index``, label = ``class``,
  corners in pixels of the 128 × 64 image, as given); an empty list is a frame with no
  detection, a missing file a frame without the record;
- nothing else: no other road users, no ground truth boxes, no plan, no collision.

Columns are found by their header names only. Bad input is reported as the running-log
reader does, one line per column and kind (how many rows, the first named): a cell that is
no number is NaN, a row whose ID is not ``{letters and digits}_{digits}`` or repeats an
earlier one is skipped, a traffic-light file that is no list of detections is skipped, a
detection without four finite corners dropped.
"""

from __future__ import annotations

import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ads_rca.capabilities import source_statuses
from ads_rca.errors import InputError
from ads_rca.foundation.files import DEFAULT_MAX_FILE_MB, read_regular
from ads_rca.foundation.geometry import FloatArray
from ads_rca.foundation.text import printable
from ads_rca.model import (
    INPUTS_KEY,
    Actors,
    Boxes,
    EgoPose,
    InputStatus,
    Record,
    RunLog,
    RunMetadata,
)
from ads_rca.problems import DROPPED_RECORD, SKIPPED_FILE, SKIPPED_FRAME, ProblemLog
from ads_rca.sources.atmacup import TABLE_FILES
from ads_rca.sources.atmacup.snapshots import (
    BOOLEAN_COLUMNS,
    HORIZONS_S,
    MAX_PATH_VALUE,
    TARGET_COLUMNS,
    VEHICLE_COLUMNS,
    EgoSnapshots,
)
from ads_rca.sources.csv_table import (
    CsvTable,
    booleans,
    numbers,
    read_csv_table,
    shown,
    unknown_columns,
)
from ads_rca.sources.formats import SourceOptions
from ads_rca.sources.log.reader import UNUSABLE, check_max_file_mb, decode_file
from ads_rca.sources.log.records import json_number

FORMAT_NAME = "atmacup"
LIGHTS_FOLDER = "traffic_lights"
#: Milliseconds between the frames of consecutive rows (the table's unit: deciseconds).
TPF_MS = 100
#: A row ID: the scene (letters and digits) and the deciseconds since its start.
ID_PATTERN = re.compile(r"[0-9A-Za-z]{1,64}_[0-9]{1,9}")
ID_COLUMN = "ID"
#: The ego's actor id: the only actor of every frame (the table has no other road users).
EGO_ID = "ego"
GEAR_COLUMN = "gearShifter"
GEARS = ("drive", "park", "reverse", "neutral")
#: The largest traffic-light index kept as the detection's id.
MAX_INDEX = 999_999
LIGHT_CLASSES = ("green", "yellow", "red", "straight", "left", "right", "empty", "other")
#: Every column the reader uses.
KNOWN_COLUMNS = (ID_COLUMN, *VEHICLE_COLUMNS, GEAR_COLUMN, *TARGET_COLUMNS)
#: The camera's height above the ground (m), from the data description.
CAMERA_HEIGHT_M = 1.22
#: The camera (the data description): 128 × 64 px, intrinsics, its height.
CAMERA = {
    "width_px": 128,
    "height_px": 64,
    "intrinsics": [[226.16438356, 0.0, 63.62426614], [0.0, 224.82352941, 11.76], [0.0, 0.0, 1.0]],
    "height_m": CAMERA_HEIGHT_M,
}
SOURCE_FRAME = (
    "atmaCup ego frame at each row's moment (right-handed: x forward, y left, z up, origin "
    "at the ego) mirrored into the model's: y' = -y; traffic-light boxes in image pixels as given"
)
FRAME_LAYOUT = (
    f"one frame per usable row in file order, {TPF_MS} ms apart (frame n at {TPF_MS}*n ms); "
    "rows are independent snapshots: consecutive frames are not a time series"
)


def table_file(path: str | os.PathLike[str]) -> Path:
    """The table CSV at ``path``: the file itself, or the one of :data:`TABLE_FILES` a
    folder holds; InputError when a folder holds neither or both."""
    given = Path(path)
    if not given.is_dir():
        return given
    found = [given / name for name in TABLE_FILES if os.path.lexists(given / name)]
    if len(found) != 1:
        which = "both" if found else "neither"
        raise InputError(
            f"{given}: holds {which} of {' and '.join(TABLE_FILES)}: give the table file"
        )
    return found[0]


@dataclass(frozen=True)
class Rows:
    """The table's usable rows: their positions among the data rows and their IDs."""

    positions: np.ndarray[Any, np.dtype[np.int64]]
    ids: tuple[str, ...]
    #: Per data row, whether it is one of them.
    used: np.ndarray[Any, np.dtype[np.bool_]]


def read_atmacup_table(
    path: str | os.PathLike[str],
    max_file_mb: float = DEFAULT_MAX_FILE_MB,
    source: SourceOptions | None = None,
) -> RunLog:
    """Load an atmaCup #18 table (see the module docstring); ``source.submission`` names a
    submission CSV whose predicted paths are put beside the realised ones."""
    source = source or SourceOptions()
    limit = check_max_file_mb(max_file_mb)
    file = table_file(path)
    problems = ProblemLog()
    name = file.name
    table = read_csv_table(str(file), name, limit, problems)
    if not table.has(ID_COLUMN):
        raise InputError(f"{file}: no {ID_COLUMN} column: not an atmaCup table")
    unknown_columns(table, KNOWN_COLUMNS, problems)
    labels = _labels(table)
    rows = _usable_rows(table, labels, problems)
    if not rows.ids:
        raise InputError(f"{file}: {_no_rows(table, problems)}")
    vehicle = _vehicle(table, labels, rows, problems)
    gear = _gears(table, labels, rows, problems)
    realised = _targets(table, labels, rows, problems)
    timestamps = np.arange(len(rows.ids), dtype=np.int64) * TPF_MS
    predicted = np.full((len(rows.ids), len(HORIZONS_S), 3), np.nan)
    submission_info: dict[str, Any] = {}
    if source.submission:
        from ads_rca.sources.atmacup.submission import read_submission

        predicted, submission_info = read_submission(
            source.submission, rows.ids, rows.positions, len(table), limit, problems
        )
    lights_dir = file.parent / LIGHTS_FOLDER
    lights = _lights(lights_dir, rows.ids, timestamps, limit, problems)
    snapshots = EgoSnapshots(
        rows.ids,
        timestamps,
        rows.positions,
        realised,
        predicted,
        vehicle,
        gear,
        os.fspath(source.submission) if source.submission else "",
    )
    speeds = vehicle["vEgo"].tolist()
    frames = tuple(timestamps.tolist())
    pose: dict[int, Record] = {
        ts: EgoPose(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, speed)
        for ts, speed in zip(frames, speeds, strict=True)
    }
    alone = Actors((EGO_ID,), np.zeros((1, 3)), np.zeros((1, 3)), np.full((1, 3), np.nan))
    actors: dict[int, Record] = dict.fromkeys(frames, alone)  # one shared, immutable record
    raw: dict[str, Any] = {
        "source_format": FORMAT_NAME,
        "timesteps_per_frame": TPF_MS,
        "collision_frame": -1,
        "total_frames": len(frames),
        "snapshots": True,
        "frame_layout": FRAME_LAYOUT,
        "source_frame": SOURCE_FRAME,
        "table": {
            "file": name,
            "data_rows": len(table),
            "rows": len(frames),
            "scenes": len({i.rpartition("_")[0] for i in rows.ids}),
            "realised_paths": int(np.isfinite(realised).all(axis=(1, 2)).sum()),
            "traffic_light_files": len(lights) if lights is not None else 0,
        },
        "camera": CAMERA,
    }
    if submission_info:
        raw["submission"] = submission_info
    inputs = _capabilities(name, lights is not None, snapshots)
    raw[INPUTS_KEY] = {key: status.to_dict() for key, status in inputs.items()}
    metadata = RunMetadata(TPF_MS, (0.0, 0.0, CAMERA_HEIGHT_M), -1, len(frames), raw)
    log = RunLog.from_folders(
        metadata,
        frames,
        {"pose": pose, "actors": actors, "bboxes": dict(lights or {})},
        problems=problems,
        source=str(file),
        inputs=inputs,
    )
    log.ego_snapshots = snapshots
    return log


def _labels(table: CsvTable) -> list[str]:
    """How a problem names each data row: its ID when it is one, else its position."""
    return [
        f"row {ident}" if ID_PATTERN.fullmatch(ident) else f"data row {n + 1}"
        for n, ident in enumerate(table.cells(ID_COLUMN))
    ]


def _usable_rows(table: CsvTable, labels: Sequence[str], problems: ProblemLog) -> Rows:
    """Rows with a well-formed ID seen for the first time (the others reported, skipped)."""
    seen: set[str] = set()
    keep: list[int] = []
    malformed: list[int] = []
    repeated: list[int] = []
    for n, (ident, short) in enumerate(
        zip(table.cells(ID_COLUMN), table.short.tolist(), strict=True)
    ):
        if short:
            continue  # reported with the row's field count
        if not ID_PATTERN.fullmatch(ident):
            malformed.append(n)
        elif ident in seen:
            repeated.append(n)
        else:
            seen.add(ident)
            keep.append(n)
    if malformed:
        cell = table.cells(ID_COLUMN)[malformed[0]]
        problems.add(
            table.name,
            ID_COLUMN,
            f"{len(malformed)} rows: not an ID {{scene}}_{{deciseconds}} (the first: "
            f"{labels[malformed[0]]}, {shown(cell)!r})",
            SKIPPED_FRAME,
        )
    if repeated:
        problems.add(
            table.name,
            ID_COLUMN,
            f"{len(repeated)} rows repeat an earlier row's ID (the first: {labels[repeated[0]]})",
            "the first row kept",
        )
    cells = table.cells(ID_COLUMN)
    used = np.zeros(len(table), dtype=bool)
    used[keep] = True
    return Rows(np.asarray(keep, dtype=np.int64), tuple(cells[n] for n in keep), used)


def _no_rows(table: CsvTable, problems: ProblemLog) -> str:
    """Why a table gives no usable row, in words (its header alone, or every row unusable:
    the last error said about the table), escaped for one line."""
    if not len(table):
        return "no data rows: the table holds its header alone"
    said = [p for p in problems if p.file == table.name and p.severity == "error"]
    why = f" ({said[-1].field}: {said[-1].issue})" if said else ""
    return printable(f"{ID_COLUMN}: none of its {len(table)} data rows is usable{why}")


def _vehicle(
    table: CsvTable, labels: Sequence[str], rows: Rows, problems: ProblemLog
) -> dict[str, FloatArray]:
    """Each CAN column at the usable rows; a missing column is NaN throughout (reported)."""
    out: dict[str, FloatArray] = {}
    missing = [c for c in VEHICLE_COLUMNS if not table.has(c)]
    if missing:
        problems.add(
            table.name,
            ", ".join(missing),
            "missing columns",
            "read as NaN" + (" (the ego's speed too)" if "vEgo" in missing else ""),
        )
    for column in VEHICLE_COLUMNS:
        if column in missing:
            out[column] = np.full(len(rows.ids), np.nan)
            continue
        read = booleans if column in BOOLEAN_COLUMNS else numbers
        out[column] = read(table, column, labels, problems, rows.used)[rows.positions]
    return out


def _gears(
    table: CsvTable, labels: Sequence[str], rows: Rows, problems: ProblemLog
) -> tuple[str, ...]:
    """The gear lever per usable row: one of :data:`GEARS`, else ``unknown`` (reported)."""
    if not table.has(GEAR_COLUMN):
        problems.add(table.name, GEAR_COLUMN, "missing column", "gear unknown")
        return ("unknown",) * len(rows.ids)
    cells = table.cells(GEAR_COLUMN)
    texts = [cells[n].strip().lower() for n in rows.positions.tolist()]
    bad = [n for n, t in zip(rows.positions.tolist(), texts, strict=True) if t not in GEARS]
    if bad:
        problems.add(
            table.name,
            GEAR_COLUMN,
            f"{len(bad)} rows: not one of {', '.join(GEARS)} (the first: {labels[bad[0]]}, "
            f"{shown(cells[bad[0]])!r})",
            "gear unknown",
        )
    return tuple(t if t in GEARS else "unknown" for t in texts)


def _targets(
    table: CsvTable, labels: Sequence[str], rows: Rows, problems: ProblemLog
) -> FloatArray:
    """The realised paths, (rows, 6, 3), y mirrored; NaN where the table has none (a test
    table: no target columns at all, not a problem)."""
    out = np.full((len(rows.ids), len(HORIZONS_S), 3), np.nan)
    present = [c for c in TARGET_COLUMNS if table.has(c)]
    if not present:
        return out
    if len(present) < len(TARGET_COLUMNS):
        missing = [c for c in TARGET_COLUMNS if not table.has(c)]
        problems.add(
            table.name,
            ", ".join(missing),
            "missing target columns",
            "those coordinates unknown: the rows' paths are not scored",
        )
    flat = out.reshape(len(rows.ids), len(TARGET_COLUMNS))
    for n, column in enumerate(TARGET_COLUMNS):
        if table.has(column):
            read = numbers(table, column, labels, problems, rows.used, MAX_PATH_VALUE)
            flat[:, n] = read[rows.positions]
    out[:, :, 1] = 0.0 - out[:, :, 1]  # right-handed y (left) -> the model's (right); no -0.0
    return out


# --- traffic lights --------------------------------------------------------------------------


def _lights(
    folder: Path,
    ids: Sequence[str],
    timestamps: np.ndarray[Any, np.dtype[np.int64]],
    limit: int,
    problems: ProblemLog,
) -> dict[int, Boxes] | None:
    """Each row's traffic lights as 2-D detections (None without a ``traffic_lights``
    folder). Problems are counted per kind, one line each (the first file named)."""
    if not folder.is_dir():
        return None
    try:
        present = set(os.listdir(folder))
    except OSError as error:
        problems.add(LIGHTS_FOLDER, "", f"cannot list: {error.strerror}", SKIPPED_FILE)
        return None
    issues: dict[tuple[str, str], list[str]] = {}
    out: dict[int, Boxes] = {}
    missing = 0
    directory = os.fspath(folder)  # text paths: a Path per file cost a third of the time
    for ident, stamp in zip(ids, timestamps.tolist(), strict=True):
        file = f"{ident}.json"
        if file not in present:
            missing += 1
            continue
        where = f"{LIGHTS_FOLDER}/{file}"
        quiet = ProblemLog()  # decode_file's line, folded into the counts below
        document = decode_file(
            read_regular(os.path.join(directory, file), limit), where, quiet, None
        )
        if document is UNUSABLE:
            _note(issues, "", next(iter(quiet)).issue.split(" (")[0], where)
            continue
        boxes = _boxes(document, where, issues)
        if boxes is not None:
            out[stamp] = boxes
    for (field, issue), files in issues.items():
        action = SKIPPED_FILE if not field else DROPPED_RECORD
        problems.add(files[0], field, f"{issue} ({len(files)} files; this one the first)", action)
    if missing:
        problems.add(
            LIGHTS_FOLDER,
            "",
            f"{missing} rows have no traffic-light file (the first: "
            f"{ids[_first_missing(ids, present)]})",
            "no detections record for those frames",
            "warning",
        )
    return out


def _first_missing(ids: Sequence[str], present: set[str]) -> int:
    return next(n for n, ident in enumerate(ids) if f"{ident}.json" not in present)


def _boxes(document: Any, where: str, issues: dict[tuple[str, str], list[str]]) -> Boxes | None:
    """One file's detections; None when it is not a list (counted)."""
    if not isinstance(document, list):
        _note(issues, "", "not a list of detections", where)
        return None
    if not document:
        return NO_BOXES
    ids: list[str] = []
    corners: list[list[float]] = []
    extras: list[Mapping[str, Any]] = []
    for n, entry in enumerate(document):
        bbox = entry.get("bbox") if isinstance(entry, dict) else None
        values = [json_number(v) for v in bbox] if isinstance(bbox, list) and len(bbox) == 4 else []
        if len(values) != 4 or not np.isfinite(values).all():
            _note(issues, "bbox", "not four finite numbers", where)
            continue
        index = entry.get("index")
        number = json_number(index)  # 10**400 too: past the float range, infinite
        if not (number.is_integer() and 0 <= number <= MAX_INDEX):
            _note(issues, "index", "not an integer 0 to 999999: the list position used", where)
            index = n
        kind = entry.get("class")
        if kind not in LIGHT_CLASSES:
            _note(issues, "class", f"not one of {', '.join(LIGHT_CLASSES)}: read as other", where)
            kind = "other"
        ids.append(str(int(index)))
        corners.append(values)
        extras.append({"label": kind})
    return Boxes(tuple(ids), np.asarray(corners, dtype=np.float64).reshape(-1, 4), tuple(extras))


#: The record of a frame that saw no traffic light (one, shared: records are immutable).
NO_BOXES = Boxes((), np.zeros((0, 4)), ())


def _note(issues: dict[tuple[str, str], list[str]], field: str, issue: str, where: str) -> None:
    """Count ``where`` once for this kind of defect (a file with several counts once)."""
    files = issues.setdefault((field, issue), [])
    if not files or files[-1] != where:
        files.append(where)


# --- capability record -----------------------------------------------------------------------


def _capabilities(name: str, lights: bool, snapshots: EgoSnapshots) -> dict[str, InputStatus]:
    given = {
        "ego": InputStatus(
            "real",
            name,
            "vEgo; the pose is the origin of each row's own frame (the table's frame is the "
            "ego's); rows are independent snapshots",
        ),
        "actors": InputStatus(
            "derived",
            name,
            f"the ego alone (id {EGO_ID}, at the origin, size unknown): the table holds no "
            "other road users",
        ),
        "detections_2d": (
            InputStatus(
                "real", LIGHTS_FOLDER, "traffic lights only (a detector's output, no confidence)"
            )
            if lights
            else InputStatus("absent", "", f"no {LIGHTS_FOLDER} folder beside the table")
        ),
        "ground_truth_2d": InputStatus(
            "absent", "", "the traffic lights are a detector's output: no ground truth"
        ),
        "plan": InputStatus(
            "absent",
            "",
            "the table holds no plan; a submission's predicted ego path is scored against the "
            "realised one (trajectory_scores), not judged as a plan (rows are snapshots)"
            + (f": {snapshots.submission}" if snapshots.submission else ""),
        ),
        "control": InputStatus(
            "absent",
            "",
            "the CAN state (acceleration, steering, pedals, gear, blinkers) is measured, not "
            "commanded: kept per row in the run's ego snapshots",
        ),
        "collision": InputStatus("absent", "", "naturalistic driving: no collision recorded"),
        "clock": InputStatus("absent", "", "a table has no clock"),
    }
    return source_statuses(given, "an atmaCup table holds no")


__all__ = ["FORMAT_NAME", "TABLE_FILES", "TPF_MS", "read_atmacup_table", "table_file"]
