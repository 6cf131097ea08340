"""Reader for ADS running-log folders (the seed format), with the reference tool's rules.

Reading rules (rca-semantics.md, "Reading a log folder"): every ``*.json`` file of a folder
is read whatever its prefix (dot-files and other extensions ignored); its timestamp is the
decimal integer between the last ``-`` of its name and the next ``.``; when two files of a
folder map to one timestamp, the one listed last (directory order) wins; the analysed frames
are one per ``actors/`` file, ascending, duplicates kept.

Nothing here raises on bad data: a missing folder, an unreadable or invalid JSON file, a
file name without a timestamp, a wrong value... each becomes a Problem and the rest of the
log still loads. Only a path that is not a log folder at all raises InputError.

Hostile files too: only regular files of at most ``max_file_mb`` are read (FIFOs, devices,
symlinks to them are reported, see :mod:`ads_rca.foundation.files`); JSON nested deeper than the
parsers can read (1024 levels) is reported as invalid, never a RecursionError; and what the
reader keeps as raw JSON (``metadata.json``, box extras) may nest at most
:data:`MAX_KEPT_DEPTH` levels, so that writing it again (convert, the live graph) cannot
overflow either.
"""

from __future__ import annotations

import itertools
import json
import math
import os
from collections.abc import Callable, Iterable, Sequence
from dataclasses import replace
from operator import itemgetter
from pathlib import Path
from typing import Any

import orjson

from ads_rca.errors import InputError
from ads_rca.foundation.files import DEFAULT_MAX_FILE_MB, Unreadable, max_bytes, read_regular
from ads_rca.foundation.progress import Progress, advancer, tracked
from ads_rca.foundation.workers import can_fork, collector_paused, map_forked
from ads_rca.model import (
    ALL_FOLDERS,
    FOLDERS,
    INPUTS_KEY,
    MAX_FRAME,
    MAX_TIMESTAMP_MS,
    OPTIONAL_FOLDERS,
    InputStatus,
    Predictions,
    Record,
    RunLog,
    RunMetadata,
    read_inputs,
)
from ads_rca.problems import IGNORED, KEPT_VALUE, SKIPPED_FILE, USED_DEFAULT, Problem, ProblemLog
from ads_rca.sources.errors import InvalidJson
from ads_rca.sources.log.packing import Handed, Packer, reading_prefix, sweep_shared, unpack
from ads_rca.sources.log.records import (
    as_float,
    parse_actors,
    parse_boxes,
    parse_control,
    parse_objects_3d,
    parse_plan,
    parse_pose,
    parse_predictions,
    prediction_parts,
    show_value,
)
from ads_rca.sources.log.validate import validate_run_log
from ads_rca.sources.openlane.annotation import parse_lanes, parse_predicted_lanes

DEFAULT_TPF_MS = 50
#: Deepest nesting of what the reader keeps as raw JSON (``metadata.json``, box extras).
#: Far beyond any real log (records nest 4 levels), and below every writer of it: orjson
#: writes at most 255 levels (convert and the live graph write both again); json.dumps and
#: repr stop near Python's recursion limit (1000). Whole documents are bounded by the
#: parsers themselves: orjson reads 1024 levels, the reference's json.loads about 995.
MAX_KEPT_DEPTH = 200
_BOX_KEYS = frozenset(("bounding_box",))
Job = tuple[str, int, str]  # folder, timestamp, file name
#: Logs with fewer files than this are read in this process: forking and collecting
#: workers costs more than it saves.
PARALLEL_MIN_FILES = 1000
#: Chunks of files per worker: results come back in order, so the parent rebuilds one
#: chunk's records while the workers parse the next.
CHUNKS_PER_WORKER = 4
#: The most files in one chunk (a long log gets more chunks): a chunk comes back as one
#: pipe message, and both ends pay more per byte the larger it is (each read of the pipe's
#: 64 KiB asks for a buffer the size of the rest of the message). A 10,000-frame, 50-actor
#: log in 8 chunks of 50 MB took 1.04 s of the parent's system time and 1.72 s of the
#: workers'; in 35 chunks of 13 MB 0.69 and 1.16 s.
MAX_CHUNK_FILES = 2000

#: A folder's parser: decoded JSON document, file, problems, timestamp -> record or None.
Parser = Callable[[Any, str, ProblemLog, int], Record | None]
PARSERS: dict[str, Parser] = {
    "pose": parse_pose,
    "actors": parse_actors,
    "bboxes": parse_boxes,
    "bboxes_gt": parse_boxes,
    "predictions": parse_predictions,
    "predictions_with_perception": parse_predictions,
    "waypoint": parse_plan,
    "detections_3d": parse_objects_3d,
    "tracks_3d": parse_objects_3d,
    "control": parse_control,
    "lanes": parse_lanes,
    "lanes_predicted": parse_predicted_lanes,
}


def timestamp_of(file_name: str) -> int | None:
    """Milliseconds encoded in a log file name, or None when it has none.

    The text between the last ``-`` and the next ``.``: ``actors-050.json`` is 50,
    ``actors-3800.bak.json`` is 3800, ``actors.json`` has none.
    """
    _head, dash, tail = file_name.rpartition("-")
    if not dash:
        return None
    text = tail.split(".", 1)[0]
    if not text.isascii() or not text.isdigit():
        return None
    return int(text)


def is_log_file(file_name: str) -> bool:
    return file_name.endswith(".json") and not file_name.startswith(".")


def decode_json(data: bytes) -> Any:
    """Strict JSON first (fast); Python's json for the NaN/Infinity literals it also accepts.

    Raises InvalidJson for invalid JSON, nesting deeper than the parser reads included.
    """
    try:
        return orjson.loads(data)
    except orjson.JSONDecodeError as error:
        if "depth limit" in str(error):
            raise InvalidJson("nested too deep: more than 1024 levels") from None
    try:
        return json.loads(data)
    except RecursionError:
        raise InvalidJson("nested too deep for the parser") from None
    except ValueError as error:  # UnicodeDecodeError included
        raise InvalidJson(str(error)) from None


def kept_too_deep(folder: str, document: object, text: bytes | Unreadable | None = None) -> bool:
    """True when the raw JSON the reader keeps of ``document`` nests over MAX_KEPT_DEPTH.

    ``metadata.json`` is kept whole; of a boxes file, each box's fields but the corners
    (which become numbers or a reported NaN). Other folders keep numbers only.
    ``text``, the boxes file's JSON text when at hand, spares the walk over every box's
    fields when it has no more than MAX_KEPT_DEPTH brackets: each level opens with one
    (two counts in C: 1.0 instead of 3.9 µs for a file of 9 boxes, 4 instead of 18 for 44).
    """
    if folder == "metadata":
        return _deeper_than(document, MAX_KEPT_DEPTH)
    if folder not in ("bboxes", "bboxes_gt") or not isinstance(document, list):
        return False
    if isinstance(text, bytes) and text.count(b"[") + text.count(b"{") <= MAX_KEPT_DEPTH:
        return False
    return any(
        isinstance(value, dict | list) and _deeper_than(value, MAX_KEPT_DEPTH - 2)
        for box in document
        if isinstance(box, dict)
        for key, value in box.items()
        if key not in _BOX_KEYS
    )


def _too_deep_kept() -> str:
    return f"invalid JSON (nested too deep: more than {MAX_KEPT_DEPTH} levels)"


def _deeper_than(document: Any, limit: int) -> bool:
    """True when arrays/objects nest more than ``limit`` levels (iterative: no recursion)."""
    stack: list[tuple[Any, int]] = [(document, 1)]
    while stack:
        value, depth = stack.pop()
        children = value.values() if isinstance(value, dict) else value
        if depth > limit:
            return True
        stack.extend((c, depth + 1) for c in children if isinstance(c, dict | list))
    return False


@collector_paused()  # reading allocates millions of objects, none in cycles (workers too)
def read_run_log(
    path: str | os.PathLike[str],
    max_file_mb: float = DEFAULT_MAX_FILE_MB,
    progress: Progress | None = None,
    workers: int = 1,
) -> RunLog:
    """Load a running-log folder. Raises InputError only when ``path`` is no log folder.

    ``max_file_mb``: files larger than this are reported and skipped, not read.
    ``progress`` sees each file as it is read (most of the loading time).
    ``workers`` > 1 reads and parses the files of a long log in that many forked processes
    (CPU-bound: threads do not help): each parses chunks of every n-th file and sends
    their records back packed (:mod:`.packing`) with their problems' file positions, so the
    log and its problems are the same as read here.
    """
    root = Path(path)
    limit = check_max_file_mb(max_file_mb)
    if not root.exists():
        raise InputError(f"{root}: no such log folder")
    if not root.is_dir():
        raise InputError(f"{root}: not a folder (a running log is a folder of JSON files)")
    problems = ProblemLog()
    irregular: set[str] = set()  # files not listed as regular: read with the full check
    listings = {folder: _list_folder(root, folder, problems, irregular) for folder in FOLDERS}
    if not (root / "metadata.json").exists() and not listings["actors"]:
        raise InputError(f"{root}: not an ADS running log (no metadata.json, no actors/ files)")
    for folder in OPTIONAL_FOLDERS:  # our extension: absent means none, and says nothing
        if (root / folder).is_dir():
            listings[folder] = _list_folder(root, folder, problems, irregular)

    # Only the winning file of each timestamp is read (the others are reported by validate).
    files = {folder: {ts: name for ts, name in listing} for folder, listing in listings.items()}
    jobs = [
        (folder, ts, name) for folder in ALL_FOLDERS for ts, name in files.get(folder, {}).items()
    ]
    records: dict[str, dict[int, Record]] = {folder: {} for folder in ALL_FOLDERS}
    if workers > 1 and len(jobs) >= PARALLEL_MIN_FILES and can_fork():
        parsed, found = _parse_in_workers(
            str(root), jobs, limit, progress, workers, frozenset(irregular)
        )
    else:
        parsed, found = _parse_files(str(root), jobs, limit, frozenset(irregular), progress)
    problems.extend(found)
    for folder, ts, record in parsed:
        records[folder][ts] = record
    records = {folder: dict(sorted(r.items())) for folder, r in records.items()}
    actors_listing = [ts for ts, _ in listings["actors"]]
    metadata = read_metadata(root / "metadata.json", actors_listing, problems, limit)
    inputs, issues = read_inputs(metadata.raw)
    for name, issue in issues:
        problems.add("metadata.json", name, issue, IGNORED, "warning")
    log = RunLog.from_folders(
        metadata,
        tuple(sorted(actors_listing)),
        records,
        problems=problems,
        source=str(root),
        files=files,
        inputs=inputs,
    )
    validate_run_log(log, listings, missing_folders=[f for f in FOLDERS if not (root / f).is_dir()])
    return log


def read_predictions_folder(
    directory: str | os.PathLike[str], max_file_mb: float = DEFAULT_MAX_FILE_MB
) -> tuple[dict[int, Predictions], ProblemLog]:
    """A folder of prediction files in the seed format (``predictions-<ms>.json``, the
    running-log reader's naming and parsing rules): a predictor's output given beside a run
    that has none (``--predictions``). InputError only when it is no folder."""
    root = Path(directory)
    limit = check_max_file_mb(max_file_mb)
    if not root.is_dir():
        raise InputError(f"{root}: no such folder of prediction files")
    problems = ProblemLog()
    out: dict[int, Predictions] = {}
    for ts, name in sorted(dict(_list_folder(root.parent, root.name, problems)).items()):
        file = f"{root.name}/{name}"
        document = decode_file(read_regular(root / name, limit), file, problems, ts)
        if document is UNUSABLE:
            continue
        record = parse_predictions(document, file, problems, ts)
        if record is not None:
            out[ts] = record
    return out, problems


def with_predictions(log: RunLog, directory: str, max_file_mb: float) -> RunLog:
    """``log`` (which had no predictions) with a predictor's prediction files
    (:func:`read_predictions_folder`), their problems reported, and the capability record
    saying where they came from: the sources taking ``--predictions`` call it after reading."""
    found, problems = read_predictions_folder(directory, max_file_mb)
    log.predictions.update(found)
    log.problems.extend(problems)
    log.inputs["predictions"] = InputStatus(
        "real",
        os.fspath(directory),
        "a predictor's output given with --predictions: not judged by the verdict rules, "
        "scored against the realised future (ids are actor ids)",
    )
    raw = dict(log.metadata.raw)
    raw[INPUTS_KEY] = {name: s.to_dict() for name, s in log.inputs.items()}
    log.metadata = replace(log.metadata, raw=raw)
    return log


def check_max_file_mb(max_file_mb: float) -> int:
    """The byte cap of ``max_file_mb``; InputError unless it is a positive number."""
    if not (isinstance(max_file_mb, int | float) and math.isfinite(max_file_mb)) or (
        max_file_mb <= 0
    ):
        raise InputError(f"max_file_mb must be a positive number of MB, not {max_file_mb!r}")
    return max_bytes(max_file_mb)


def _list_folder(
    root: Path, folder: str, problems: ProblemLog, irregular: set[str] | None = None
) -> list[tuple[int, str]]:
    """(timestamp, file name) of each log file, in directory-listing order. ``irregular``
    gets ``folder/name`` of each listed as no regular file or as a symlink (the entry's
    type: no system call where the file system gives it), which are read with the full
    check (:func:`~ads_rca.foundation.files.read_regular`)."""
    directory = root / folder
    if not directory.is_dir():
        problems.add(f"{folder}/", "", "folder missing", "checks that need it are skipped")
        return []
    try:
        with os.scandir(directory) as entries:
            listed = [(entry.name, entry.is_file(follow_symlinks=False)) for entry in entries]
    except OSError as error:
        problems.add(f"{folder}/", "", f"cannot list: {error.strerror}", SKIPPED_FILE)
        return []
    if irregular is not None:
        irregular.update(f"{folder}/{name}" for name, regular in listed if not regular)
    listing: list[tuple[int, str]] = []
    for name, _regular in listed:
        if not is_log_file(name):
            continue
        ts = timestamp_of(name)
        if ts is None:
            problems.add(
                f"{folder}/{name}", "file name", "no timestamp after the last '-'", IGNORED
            )
            continue
        if ts > MAX_TIMESTAMP_MS:
            problems.add(
                f"{folder}/{name}",
                "file name",
                f"timestamp past the largest read ({MAX_TIMESTAMP_MS} ms)",
                IGNORED,
            )
            continue
        listing.append((ts, name))
    return listing


def _parse_files(
    root: str,
    jobs: Sequence[Job],
    limit: int,
    irregular: frozenset[str],
    progress: Progress | None = None,
    owners: list[int] | None = None,
    packer: Packer | None = None,
) -> tuple[list[tuple[str, int, Record]], list[Problem]]:
    """Read (at most ``limit`` bytes a file), decode and parse files in ``jobs`` order; the
    problems found on the way. ``owners``, when given, gets each problem's job position.
    With a ``packer`` the records go there instead (none is returned), a clean predictions
    file without making its tracks (a tenth of a large log's reading: dozens of tracks a
    file, each an object to make and to take apart again)."""
    problems = ProblemLog()
    parsed: list[tuple[str, int, Record]] = []
    base = os.path.join(root, "")  # paths as text: no Path object a file
    for position, (folder, ts, name) in enumerate(tracked(jobs, progress)):
        before = len(problems)
        file = f"{folder}/{name}"
        data = read_regular(base + file, limit, file not in irregular)
        document = decode_file(data, file, problems, ts)
        too_deep = document is not UNUSABLE and kept_too_deep(folder, document, data)
        del data  # the text is not needed while parsing (a large file's text is megabytes)
        if document is UNUSABLE:
            pass
        elif too_deep:
            problems.add(file, "", _too_deep_kept(), SKIPPED_FILE, timestamp_ms=ts)
        else:
            parse = PARSERS[folder]
            if (
                packer is not None
                and parse is parse_predictions
                and (parts := prediction_parts(document)) is not None
            ):
                packer.add_predictions(folder, ts, *parts)
            elif (record := parse(document, file, problems, ts)) is None:
                pass
            elif packer is not None:
                packer.add(folder, ts, record)
            else:
                parsed.append((folder, ts, record))
        if owners is not None:
            owners.extend([position] * (len(problems) - before))
    return parsed, list(problems)


# The forked readers' work (set just before forking, cleared after): root, jobs, limit, the
# files listed as no regular file, the number of chunks and the prefix of the reading's
# shared-memory files.
_SHARED_JOBS: tuple[str, list[Job], int, frozenset[str], int, str] | None = None


def _parse_in_workers(
    root: str,
    jobs: list[Job],
    limit: int,
    progress: Progress | None,
    workers: int,
    irregular: frozenset[str],
) -> tuple[list[tuple[str, int, Record]], list[Problem]]:
    """:func:`_parse_files` in forked workers, the same records and problems in the same
    order as read here.

    Chunk ``c`` of ``n`` takes jobs ``c, c + n, c + 2n...``, so every chunk holds the same mix
    of folders and costs the same: a predictions file costs ten times a pose file, and
    contiguous chunks of the folder-by-folder jobs left one worker parsing predictions
    alone while the other waited. The problems come back with their job's position and are
    put back in job order (stably: one file's problems keep theirs).
    """
    global _SHARED_JOBS  # noqa: PLW0603 - inherited by the forked workers, never written there
    count = chunk_count(len(jobs), workers)
    advance = advancer(jobs, progress)
    parsed: list[tuple[str, int, Record]] = []
    found: list[tuple[int, Problem]] = []
    prefix = reading_prefix()
    _SHARED_JOBS = (root, jobs, limit, irregular, count, prefix)
    try:
        for chunk, (packed, problems, owners) in enumerate(
            map_forked(_parse_chunk, range(count), workers)
        ):
            parsed.extend(unpack(packed))
            found.extend(zip([chunk + count * i for i in owners], problems, strict=True))
            advance(len(range(chunk, len(jobs), count)))
    finally:
        _SHARED_JOBS = None
        sweep_shared(prefix)  # chunks written but never received (an interrupted reading)
    found.sort(key=itemgetter(0))
    return parsed, [problem for _, problem in found]


def chunk_count(files: int, workers: int) -> int:
    """How many chunks ``workers`` read ``files`` in: :data:`CHUNKS_PER_WORKER` each, more
    when a chunk would hold over :data:`MAX_CHUNK_FILES`, never more than the files."""
    return min(files, max(workers * CHUNKS_PER_WORKER, -(-files // MAX_CHUNK_FILES)))


def _parse_chunk(chunk: int) -> tuple[Handed, list[Problem], list[int]]:
    """In a worker: parse every ``count``-th shared job from ``chunk`` on; its records
    packed, its problems and each problem's position in the chunk."""
    assert _SHARED_JOBS is not None
    root, jobs, limit, irregular, count, prefix = _SHARED_JOBS
    owners: list[int] = []
    packer = Packer()
    _, problems = _parse_files(
        root, jobs[chunk::count], limit, irregular, owners=owners, packer=packer
    )
    return packer.handed(prefix), problems, owners


#: What :func:`decode_file` returns for a file it reported as unusable.
UNUSABLE = object()


def decode_file(data: bytes | Unreadable, file: str, problems: ProblemLog, ts: int | None) -> Any:
    """The JSON document in ``data`` (as :func:`~ads_rca.foundation.files.read_regular` gave it), or
    :data:`UNUSABLE` with the reason reported: unreadable, empty or invalid JSON."""
    if isinstance(data, Unreadable):
        problems.add(file, "", data.issue, SKIPPED_FILE, timestamp_ms=ts)
        return UNUSABLE
    if not data.strip():
        problems.add(file, "", "empty file", SKIPPED_FILE, timestamp_ms=ts)
        return UNUSABLE
    try:
        return decode_json(data)
    except InvalidJson as error:
        detail = str(error).splitlines()[0]
        issue = f"invalid JSON ({detail})"
        problems.add(file, "", issue, SKIPPED_FILE, timestamp_ms=ts)
        return UNUSABLE


def read_metadata(
    path: Path,
    actors_timestamps: Iterable[int],
    problems: ProblemLog,
    limit: int = max_bytes(DEFAULT_MAX_FILE_MB),
) -> RunMetadata:
    """``metadata.json``; every missing or bad field gets a reported default.

    Defaults: the frame period is inferred from the actors timestamps (their most common
    step, else 50 ms), camera at the origin, no collision, and as many frames as the last
    actors timestamp covers. A number given as a string (``"64"``) or a boolean is used
    as the number and reported; a collision frame past the last actors file is reported.
    """
    file = "metadata.json"
    timestamps = sorted(set(actors_timestamps))
    document: Any = {}
    data = read_regular(path, limit) if path.exists() else None
    if data is None:
        problems.add(file, "", "missing", USED_DEFAULT)
    else:
        decoded = decode_file(data, file, problems, None)
        if decoded is not UNUSABLE and kept_too_deep("metadata", decoded):
            problems.add(file, "", _too_deep_kept(), USED_DEFAULT)
        elif decoded is not UNUSABLE:
            document = decoded
    if not isinstance(document, dict):
        problems.add(file, "", "expected an object", USED_DEFAULT)
        document = {}

    defaulted: set[str] = set()

    def field(name: str, value: Any, default: float, integral: bool) -> float:
        if value is None:
            if data is not None:
                problems.add(file, name, "missing", f"{USED_DEFAULT}: {default:g}")
            defaulted.add(name)
            return default
        shown = show_value(value)
        try:
            number = as_float(value)
        except (TypeError, ValueError):
            problems.add(file, name, f"{shown} is not a number", f"{USED_DEFAULT}: {default:g}")
            defaulted.add(name)
            return default
        if not math.isfinite(number) or (integral and not number.is_integer()):
            problems.add(file, name, f"{shown} is not an integer", f"{USED_DEFAULT}: {default:g}")
            defaulted.add(name)
            return default
        if isinstance(value, str | bool):
            kind = "a string" if isinstance(value, str) else "a boolean"
            problems.add(
                file, name, f"{shown} is {kind}, not a number", f"{KEPT_VALUE}: {number:g}"
            )
        return number

    frame_ms = int(
        field(
            "timesteps_per_frame",
            document.get("timesteps_per_frame"),
            _infer_frame_ms(timestamps),
            True,
        )
    )
    if frame_ms <= 0 or frame_ms > MAX_TIMESTAMP_MS:
        issue = (
            "is not positive" if frame_ms <= 0 else f"is past the largest read ({MAX_TIMESTAMP_MS})"
        )
        problems.add(file, "timesteps_per_frame", f"{frame_ms} {issue}", USED_DEFAULT)
        frame_ms = _infer_frame_ms(timestamps)
    elif "timesteps_per_frame" not in defaulted and len(timestamps) > 1:
        _check_step(file, frame_ms, timestamps, problems)
    camera_loc = _camera_loc(document, file, problems)
    collision = int(field("collision_frame", document.get("collision_frame"), -1, True))
    if abs(collision) > MAX_FRAME:  # judges as the absurd frame did (see MAX_FRAME)
        collision = MAX_FRAME if collision > 0 else -MAX_FRAME
        problems.add(
            file,
            "collision_frame",
            f"{show_value(document.get('collision_frame'))} is past the largest frame read",
            f"{USED_DEFAULT}: {collision}",
        )
    if collision < -1:
        problems.add(
            file,
            "collision_frame",
            f"frame {collision} is before the run (only -1 means no collision: the reference "
            "counts every failure as in the window, corrected finds no collision)",
            KEPT_VALUE,
        )
    if timestamps and collision * frame_ms > timestamps[-1]:
        problems.add(
            file,
            "collision_frame",
            f"frame {collision} ({collision * frame_ms} ms) is past the last actors file "
            f"({timestamps[-1]} ms)",
            KEPT_VALUE,
        )
    last_frame = (timestamps[-1] // frame_ms) if timestamps else 0
    total = int(field("total_frames", document.get("total_frames"), last_frame, True))
    if not 0 <= total <= MAX_FRAME:
        problems.add(
            file,
            "total_frames",
            f"{show_value(document.get('total_frames'))} is not 0 to {MAX_FRAME}",
            f"{USED_DEFAULT}: {last_frame}",
        )
        total = last_frame
    elif "total_frames" not in defaulted and timestamps:
        _check_total(file, total, frame_ms, timestamps[-1], problems)
    known = "collision_frame" not in defaulted  # else -1 stands in: the collision is unknown
    return RunMetadata(frame_ms, camera_loc, collision, total, raw=document, collision_known=known)


def _check_step(file: str, frame_ms: int, timestamps: list[int], problems: ProblemLog) -> None:
    """A ``timesteps_per_frame`` that is not the actors timestamps' step (their most common
    one, what a missing value defaults to) numbers every frame and places the collision and
    the effect window wrongly: an input problem; the value is kept, as the reference does."""
    step = _infer_frame_ms(timestamps)
    if step != frame_ms:
        problems.add(
            file,
            "timesteps_per_frame",
            f"{frame_ms} ms, but the actors timestamps step by {step} ms (their most common step)",
            KEPT_VALUE,
        )


def _check_total(file: str, total: int, frame_ms: int, last_ms: int, problems: ProblemLog) -> None:
    """A ``total_frames`` more than one frame from the last actors file's frame (one off
    is either counting convention: frames from 0 or from 1) disagrees with the data; the
    reference looks ahead up to it, so it is kept and reported."""
    last = last_ms // frame_ms
    if abs(total - last) > 1:
        problems.add(
            file,
            "total_frames",
            f"{total}, but the last actors file is frame {last} ({last_ms} ms): more than one "
            "frame apart",
            KEPT_VALUE,
            "warning",
        )


def _camera_loc(
    document: dict[str, Any], file: str, problems: ProblemLog
) -> tuple[float, float, float]:
    name = "ego_config.camera.camera_loc"
    value: Any = document
    for key in ("ego_config", "camera", "camera_loc"):
        value = value.get(key) if isinstance(value, dict) else None
    try:
        x, y, z = (as_float(v) for v in value)
        if all(math.isfinite(v) for v in (x, y, z)):
            return (x, y, z)
    except (TypeError, ValueError):
        pass
    if document:
        problems.add(
            file,
            name,
            f"{show_value(value)} is not [x, y, z] in metres",
            f"{USED_DEFAULT}: [0, 0, 0]",
        )
    return (0.0, 0.0, 0.0)


def _infer_frame_ms(timestamps: list[int]) -> int:
    steps = [b - a for a, b in itertools.pairwise(timestamps) if b > a]
    if not steps:
        return DEFAULT_TPF_MS
    return max(set(steps), key=steps.count)
