"""Parsing one decoded JSON document of each folder into a model record.

Every function takes the decoded document, the file's name (for problem reports) and the
:class:`~ads_rca.problems.ProblemLog`, and returns the record or None (file unusable).
Each tries a fast path that converts a whole file with numpy in one go; only when that
fails (a missing key, a string that is not a number, NaN) does it walk the document value
by value to say exactly which field was wrong.

Rules (the same for every folder of the seed format): a number may be given as a string
(pose values always are); a value that is not a number, or is missing, is read as NaN and
reported, so the checks that use it pass; a record without the structure it needs (a box
without an id or without exactly two points, an actor without a location) is dropped and
reported. The optional folders (``detections_3d/``, ``tracks_3d/``, ``control/``: our own
extension, docs/topics.md) are strict instead: JSON numbers only, ``null`` where a value
may be unknown; anything else is reported and the file skipped.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable, Mapping, Sequence
from itertools import accumulate, chain
from operator import itemgetter
from typing import Any, TypeVar

import numpy as np

from ads_rca.model import (
    Actors,
    Boxes,
    ControlCommand,
    EgoPose,
    FloatArray,
    Objects3D,
    Plan,
    Predictions,
    Track,
)
from ads_rca.problems import DROPPED_RECORD, KEPT_VALUE, SKIPPED_FILE, USED_DEFAULT, ProblemLog
from ads_rca.sources.errors import StrictFileError

_R = TypeVar("_R")

POSE_FIELDS = ("x", "y", "z", "roll", "pitch", "yaw", "speed")
_NUMERIC_KINDS = "fiub"
#: Exact types of a strict JSON number, and of one that may be unknown (null).
_NUMBER_TYPES: frozenset[type] = frozenset((int, float))
_MAYBE_NUMBER_TYPES: frozenset[type] = frozenset((int, float, type(None)))
#: A 3-D point's numbers, in a C loop.
_STEP_XYZ = itemgetter("x", "y", "z")
#: A prediction step's or a plan point's numbers one at a time, each mapped over every
#: step or point of a file (a predictions file holds thousands of steps).
_X, _Y, _Z, _SPEED = itemgetter("x"), itemgetter("y"), itemgetter("z"), itemgetter("speed")
#: A box's corners and id.
_BOUNDING_BOX, _ID = itemgetter("bounding_box"), itemgetter("id")
#: A 3-D object's parts.
_LOCATION, _EXTENT, _YAW = itemgetter("location"), itemgetter("extent"), itemgetter("yaw")
_ROTATION = itemgetter("rotation")
_NO_VELOCITY = (None, None, None)
#: A pose's fields, in a C loop.
_POSE_VALUES = itemgetter(*POSE_FIELDS)


class FieldReader:
    """Reads numbers out of one file, reporting each bad value once with its field path.

    ``text_numbers_reported``: a number written as text (``"12.5"``) or a boolean is read
    and reported (formats whose writers never do that); the seed format's reference reads
    them silently, so its reader does too.
    """

    def __init__(
        self,
        file: str,
        problems: ProblemLog,
        timestamp_ms: int | None,
        text_numbers_reported: bool = False,
    ) -> None:
        self.file = file
        self.problems = problems
        self.timestamp_ms = timestamp_ms
        self.text_numbers_reported = text_numbers_reported

    def report(self, field: str, issue: str, action: str, severity: str = "error") -> None:
        self.problems.add(
            self.file,
            field,
            issue,
            action,
            "warning" if severity == "warning" else "error",
            self.timestamp_ms,
        )

    def number(self, container: Any, key: Any, field: str, default: float = math.nan) -> float:
        """``container[key]`` as a float; NaN (or ``default``) and a report when unusable."""
        try:
            value = container[key]
        except (KeyError, IndexError, TypeError):
            action = USED_DEFAULT if not math.isnan(default) else "read as NaN"
            self.report(field, "missing", action, "warning")
            return default
        try:
            number = as_float(value)
        except (TypeError, ValueError):
            self.report(field, f"{show_value(value)} is not a number", "read as NaN")
            return math.nan
        if not math.isfinite(number):
            self.report(field, f"{show_value(value)} is not finite", KEPT_VALUE, "warning")
        elif self.text_numbers_reported and isinstance(value, str | bool):
            kind = "text" if isinstance(value, str) else "a boolean"
            self.report(
                field, f"{show_value(value)} is {kind}, not a number", KEPT_VALUE, "warning"
            )
        return number


def parse_pose(document: Any, file: str, problems: ProblemLog, ts: int) -> EgoPose | None:
    fast = _pose_fast(document)
    if fast is not None:
        return fast
    return pose_walked(document, FieldReader(file, problems, ts))


def pose_walked(document: Any, reader: FieldReader) -> EgoPose | None:
    """A pose file read field by field, each problem reported: what :func:`_pose_fast`
    gives on a file it takes (a test holds them equal on hostile values)."""
    if not isinstance(document, Mapping):
        reader.report("", f"expected an object, found {_type(document)}", SKIPPED_FILE)
        return None
    values = [reader.number(document, name, name) for name in POSE_FIELDS]
    return EgoPose(*values)


def _pose_fast(document: Any) -> EgoPose | None:
    """The pose when every field is there and reads as a finite number (the seed format
    writes them as text), else None: :func:`parse_pose` then reads it field by field, each
    problem reported. ``float`` of each value is what :meth:`FieldReader.number` reads
    (a third of its time: no reader, no call a field)."""
    try:
        values = list(map(float, _POSE_VALUES(document)))
    except (KeyError, TypeError, ValueError, OverflowError):
        return None
    if not all(map(math.isfinite, values)):
        return None
    return EgoPose(*values)


def parse_actors(document: Any, file: str, problems: ProblemLog, ts: int) -> Actors | None:
    if isinstance(document, Mapping) and (fast := _actors_fast(document)) is not None:
        return fast  # (no reader made: a clean file reports nothing)
    reader = FieldReader(file, problems, ts)
    if not isinstance(document, Mapping):
        reader.report("", f"expected an object, found {_type(document)}", SKIPPED_FILE)
        return None
    ids: list[str] = []
    rows: list[list[float]] = []
    for actor_id, actor in document.items():
        where = f"{actor_id}"
        if not isinstance(actor, Mapping):
            reader.report(where, f"expected an object, found {_type(actor)}", DROPPED_RECORD)
            continue
        location = actor.get("location")
        if not isinstance(location, Mapping) or "x" not in location or "y" not in location:
            reader.report(f"{where}.location", "missing", DROPPED_RECORD)
            continue
        loc = [
            reader.number(location, "x", f"{where}.location.x"),
            reader.number(location, "y", f"{where}.location.y"),
            reader.number(location, "z", f"{where}.location.z", 0.0),
        ]
        rotation = actor.get("rotation")
        if rotation is None:
            reader.report(f"{where}.rotation", "missing", "read as 0", "warning")
            rot = [0.0, 0.0, 0.0]
        else:
            rot = [
                reader.number(rotation, axis, f"{where}.rotation.{axis}", 0.0)
                for axis in ("roll", "pitch", "yaw")
            ]
        extent = actor.get("extent")
        # A missing extent is only a problem where the actor first appears (checked later).
        ext = (
            [reader.number(extent, a, f"{where}.extent.{a}") for a in ("x", "y", "z")]
            if extent is not None
            else [math.nan] * 3
        )
        ids.append(str(actor_id))
        rows.append(loc + rot + ext)
    table = np.array(rows, dtype=np.float64).reshape(-1, 9)
    return Actors(tuple(ids), table[:, 0:3].copy(), table[:, 3:6].copy(), table[:, 6:9].copy())


def _actors_fast(document: Mapping[str, Any]) -> Actors | None:
    """Whole-file conversion when every actor is complete and numeric, else None.

    The nine numbers of every actor go end to end into one flat list (a 1-D list is
    converted by numpy faster than rows of tuples: 30 instead of 42 us for 50 actors), in
    the order of the table's columns: location, rotation (roll, pitch, yaw), extent."""
    flat: list[Any] = []
    try:
        for actor in document.values():
            loc, rot, ext = actor["location"], actor["rotation"], actor["extent"]
            flat += (
                loc["x"],
                loc["y"],
                loc["z"],
                rot["roll"],
                rot["pitch"],
                rot["yaw"],
                ext["x"],
                ext["y"],
                ext["z"],
            )
        table = np.array(flat)
    except (KeyError, TypeError, ValueError, AttributeError):
        return None
    if not _clean(table, 9):
        return None
    table = table.astype(np.float64).reshape(-1, 9)
    ids = tuple(str(k) for k in document)
    return Actors(ids, table[:, 0:3].copy(), table[:, 3:6].copy(), table[:, 6:9].copy())


def parse_boxes(document: Any, file: str, problems: ProblemLog, ts: int) -> Boxes | None:
    if isinstance(document, list) and (fast := _boxes_fast(document)) is not None:
        return fast
    reader = FieldReader(file, problems, ts)
    if not isinstance(document, list):
        reader.report("", f"expected a list of boxes, found {_type(document)}", SKIPPED_FILE)
        return None
    return boxes_walked(document, reader)


def boxes_walked(document: list[Any], reader: FieldReader) -> Boxes:
    """A boxes file read box by box, each problem reported: what :func:`_boxes_fast` gives
    on a file it takes (a test holds them equal on hostile values)."""
    ids: list[str] = []
    corners: list[list[float]] = []
    extras: list[Mapping[str, Any]] = []
    for position, box in enumerate(document):
        where = f"[{position}]"
        if not isinstance(box, Mapping):
            reader.report(where, f"expected an object, found {_type(box)}", DROPPED_RECORD)
            continue
        if "id" not in box or box["id"] is None:
            reader.report(f"{where}.id", "missing", DROPPED_RECORD)
            continue
        points = box.get("bounding_box")
        if not isinstance(points, list) or len(points) != 2:
            reader.report(f"{where}.bounding_box", "needs exactly two points", DROPPED_RECORD)
            continue
        if not all(isinstance(p, list) and len(p) == 2 for p in points):
            reader.report(f"{where}.bounding_box", "a point is not [x, y]", DROPPED_RECORD)
            continue
        coords = [
            reader.number(points[i], j, f"{where}.bounding_box[{i}][{j}]")
            for i in (0, 1)
            for j in (0, 1)
        ]
        ids.append(_box_id(box["id"]))
        corners.append(coords)
        extras.append({k: v for k, v in box.items() if k not in ("id", "bounding_box")})
    array = np.array(corners, dtype=np.float64).reshape(-1, 4)
    return Boxes(tuple(ids), array, tuple(extras))


def _boxes_fast(document: list[Any]) -> Boxes | None:
    """Whole-file conversion when every box has an id and two points of two finite numbers
    each, else None. Every box's and every point's length is 2 (counted in C loops), so
    the numbers end to end through :func:`finite_floats` are the (N, 4) corners."""
    try:
        corners = list(map(_BOUNDING_BOX, document))
        points = list(chain.from_iterable(corners))
        if not {*map(len, corners), *map(len, points)} <= {2}:
            return None
        numbers = finite_floats(list(chain.from_iterable(points)))
        raw_ids = list(map(_ID, document))
        extras = tuple(map(_box_extras, document))
    except (KeyError, TypeError, AttributeError):
        return None
    if numbers is None or None in raw_ids:
        return None
    return Boxes(tuple(map(_box_id, raw_ids)), numbers.reshape(-1, 4), extras)


def _box_extras(box: dict[str, Any]) -> dict[str, Any]:
    """A box's other keys in file order: a copy less two keys (a C copy, not a loop), or a
    new empty dict when it has none (a copy emptied keeps its table: 3000 boxes' worth
    is more than test_memory's headroom)."""
    if len(box) == 2:  # only id and bounding_box, both read before
        return {}
    extras = box.copy()
    del extras["id"], extras["bounding_box"]
    return extras


def parse_predictions(
    document: Any, file: str, problems: ProblemLog, ts: int
) -> Predictions | None:
    if isinstance(document, Mapping) and (fast := _predictions_fast(document)) is not None:
        return fast
    reader = FieldReader(file, problems, ts)
    if not isinstance(document, Mapping):
        reader.report("", f"expected an object, found {_type(document)}", SKIPPED_FILE)
        return None
    out: Predictions = {}
    for obstacle_id, steps in document.items():
        if not isinstance(steps, Mapping):
            reader.report(
                f"{obstacle_id}", f"expected an object, found {_type(steps)}", DROPPED_RECORD
            )
            continue
        out[str(obstacle_id)] = _track(steps, f"{obstacle_id}", reader)
    return out


#: A clean predictions file in pieces: obstacle ids, each track's step keys (file order),
#: and every step's offsets end to end, (K, 3).
PredictionParts = tuple[tuple[str, ...], list[tuple[str, ...]], FloatArray]


def prediction_parts(document: Any) -> PredictionParts | None:
    """All tracks of a predictions file in one array conversion, or None unless every step
    of every track has numeric, finite x, y and z (then :func:`parse_predictions` says
    what is wrong). A reader process packs these pieces without making the tracks. The
    numbers are read a key at a time (:func:`finite_columns`), then copied into rows."""
    if not isinstance(document, Mapping):
        return None
    if not document:  # no track (every frame of a quiet run): no array calls
        return (), [], _NO_OFFSETS
    try:
        tracks = list(document.values())
        steps = list(chain.from_iterable(map(dict.values, tracks)))
        columns = finite_columns(steps, _X, _Y, _Z)
        keys = [tuple(track) for track in tracks]
    except (KeyError, TypeError, AttributeError):
        return None
    if columns is None:
        return None
    return tuple(map(str, document)), keys, columns.T.copy()


def _predictions_fast(document: Mapping[str, Any]) -> Predictions | None:
    """All tracks of a file in one array conversion (:func:`prediction_parts`), then split
    (views, no copies)."""
    parts = prediction_parts(document)
    if parts is None:
        return None
    ids, keys, flat = parts
    return dict(zip(ids, map(Track.of, keys, track_offsets(flat, keys)), strict=True))


def track_offsets(flat: FloatArray, keys: Sequence[tuple[str, ...]]) -> list[FloatArray]:
    """Each track's (K, 3) offsets, views of ``flat`` (every track's rows end to end, in
    ``keys``' order): when every track has the same keys by iterating one (tracks, K, 3)
    view, a third of the cost of slicing each."""
    count = len(keys)
    if count and keys.count(keys[0]) == count:
        return list(flat.reshape(count, len(keys[0]), 3))
    ends = accumulate(map(len, keys))
    return [flat[end - len(k) : end] for k, end in zip(keys, ends, strict=True)]


def _track(steps: Mapping[str, Any], where: str, reader: FieldReader) -> Track:
    keys = tuple(str(k) for k in steps)
    rows = [
        [
            reader.number(step, "x", f"{where}.{key}.x"),
            reader.number(step, "y", f"{where}.{key}.y"),
            reader.number(step, "z", f"{where}.{key}.z", 0.0),
        ]
        for key, step in steps.items()
    ]
    return Track(keys, np.array(rows, dtype=np.float64).reshape(-1, 3))


def parse_plan(document: Any, file: str, problems: ProblemLog, ts: int) -> Plan | None:
    if not isinstance(document, Mapping):
        FieldReader(file, problems, ts).report(
            "", f"expected an object, found {_type(document)}", SKIPPED_FILE
        )
        return None
    keys = tuple(str(k) for k in document)
    try:
        columns = finite_columns(list(document.values()), _X, _Y, _SPEED)
        if columns is not None:
            return Plan(keys, columns[:2].T.copy(), columns[2].copy())
    except (KeyError, TypeError, AttributeError):
        pass
    reader = FieldReader(file, problems, ts)
    rows = [
        [
            reader.number(point, "x", f"{key}.x"),
            reader.number(point, "y", f"{key}.y"),
            reader.number(point, "speed", f"{key}.speed"),
        ]
        for key, point in document.items()
    ]
    table = np.array(rows, dtype=np.float64).reshape(-1, 3)
    return Plan(keys, table[:, :2].copy(), table[:, 2].copy())


def _strict_number(container: Any, key: str, where: str, unknown: bool = False) -> float:
    """``container[key]``, a finite JSON number (``null`` or absent → NaN when ``unknown``
    values are allowed); StrictFileError otherwise."""
    field = f"{where}.{key}" if where else key
    if not isinstance(container, Mapping):
        raise StrictFileError(where, f"expected an object, found {_type(container)}")
    value = container.get(key)
    if value is None:
        if unknown:
            return math.nan
        raise StrictFileError(field, "missing" if key not in container else "null is not a number")
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise StrictFileError(field, f"{show_value(value)} is not a number")
    number = as_float(value)
    if not math.isfinite(number):
        raise StrictFileError(field, f"{show_value(value)} is not a finite number")
    return number


def _strict_file(
    parse: Callable[[Any], _R],
) -> Callable[[Any, str, ProblemLog, int], _R | None]:
    """A strict parser reporting its StrictFileError as one problem, the file skipped."""

    def checked(document: Any, file: str, problems: ProblemLog, ts: int) -> _R | None:
        try:
            return parse(document)
        except StrictFileError as error:
            FieldReader(file, problems, ts).report(error.field, error.issue, SKIPPED_FILE)
            return None

    checked.__name__ = parse.__name__
    checked.__doc__ = parse.__doc__
    return checked


def _objects_3d(document: Any) -> Objects3D:
    if not isinstance(document, Mapping):
        raise StrictFileError("", f"expected an object, found {_type(document)}")
    fast = _objects_3d_fast(document)
    if fast is not None:
        return fast
    rows: list[list[float]] = []
    labels: list[str] = []
    for object_id, entry in document.items():
        where = str(object_id)
        if not isinstance(entry, Mapping):
            raise StrictFileError(where, f"expected an object, found {_type(entry)}")
        location = entry.get("location")
        extent = entry.get("extent")
        velocity = entry.get("velocity")
        row = [_strict_number(location, a, f"{where}.location") for a in "xyz"]
        row.append(_strict_number(entry.get("rotation"), "yaw", f"{where}.rotation"))
        row += [_strict_number(extent, a, f"{where}.extent") for a in "xyz"]
        if velocity is None:
            row += [math.nan] * 3
        else:
            row += [_strict_number(velocity, a, f"{where}.velocity", unknown=True) for a in "xyz"]
        row.append(_strict_number(entry, "score", where, unknown=True))
        label = entry.get("label", "")
        if not isinstance(label, str):
            raise StrictFileError(f"{where}.label", f"{show_value(label)} is not text")
        rows.append(row)
        labels.append(label)
    table = np.array(rows, dtype=np.float64).reshape(-1, 11)
    return Objects3D(
        ids=tuple(str(k) for k in document),
        location=table[:, 0:3].copy(),
        yaw=table[:, 3].copy(),
        extent=table[:, 4:7].copy(),
        velocity=table[:, 7:10].copy(),
        score=table[:, 10].copy(),
        labels=tuple(labels),
    )


def _objects_3d_fast(document: Mapping[str, Any]) -> Objects3D | None:
    """A whole file converted a column at a time when every value is as the strict rules
    want (finite JSON numbers, null or absent only where a value may be unknown, text
    labels), else None (then :func:`_objects_3d` names the first bad value). A value's
    type is checked by its exact type: a boolean, which numpy would read as 1 or 0, is none
    of them."""
    try:
        entries = list(document.values())
        known = list(
            chain(
                chain.from_iterable(map(_STEP_XYZ, map(_LOCATION, entries))),
                map(_YAW, map(_ROTATION, entries)),
                chain.from_iterable(map(_STEP_XYZ, map(_EXTENT, entries))),
            )
        )
        velocities = [entry.get("velocity") for entry in entries]
        unknown = [
            value
            for velocity in velocities
            for value in (
                _NO_VELOCITY
                if velocity is None
                else (velocity.get("x"), velocity.get("y"), velocity.get("z"))
            )
        ]
        unknown.extend(entry.get("score") for entry in entries)
        labels = tuple(entry.get("label", "") for entry in entries)
        if not (
            set(map(type, known)) <= _NUMBER_TYPES
            and set(map(type, unknown)) <= _MAYBE_NUMBER_TYPES
            and set(map(type, labels)) <= {str}
        ):
            return None
        numbers = np.array(known, dtype=np.float64)
        maybe = np.array(unknown, dtype=np.float64)  # None is NaN
    except (KeyError, TypeError, ValueError, AttributeError, OverflowError):
        return None
    finite = np.isfinite(maybe)
    if not np.isfinite(numbers).all() or int(finite.sum()) != len(unknown) - unknown.count(None):
        return None  # a non-finite number, or a value of the unknown ones
    count = len(entries)
    maybe[~finite] = math.nan  # the NaN the strict reader gives an unknown value
    return Objects3D(  # each column its own array, as the strict reader makes them
        ids=tuple(str(k) for k in document),
        location=numbers[: 3 * count].reshape(-1, 3).copy(),
        yaw=numbers[3 * count : 4 * count].copy(),
        extent=numbers[4 * count :].reshape(-1, 3).copy(),
        velocity=maybe[: 3 * count].reshape(-1, 3).copy(),
        score=maybe[3 * count :].copy(),
        labels=labels,
    )


def _control(document: Any) -> ControlCommand:
    if not isinstance(document, Mapping):
        raise StrictFileError("", f"expected an object, found {_type(document)}")
    steer, acceleration, speed = (
        _strict_number(document, key, "", unknown=True)
        for key in ("steer", "acceleration", "speed")
    )
    return ControlCommand(steer=steer, acceleration=acceleration, speed=speed)


#: ``detections_3d/`` and ``tracks_3d/`` files: id → location, rotation.yaw, extent (finite
#: numbers), velocity, score (numbers or null), label (text).
parse_objects_3d = _strict_file(_objects_3d)
#: ``control/`` files: steer, acceleration, speed (numbers or null).
parse_control = _strict_file(_control)


#: The offsets of a predictions file without tracks (never written to: shared).
_NO_OFFSETS: FloatArray = np.zeros((0, 3))


def finite_columns(rows: list[Any], *columns: Callable[[Any], Any]) -> FloatArray | None:
    """Each of ``columns`` (a key's getter) read over every row, as a (columns, rows) array
    through :func:`finite_floats` (None where it refuses): one C loop a key, no tuple a row
    to chain (30 instead of 37 us for a predictions file of 300 steps). A row without the
    key raises KeyError, one that is no mapping TypeError or AttributeError."""
    numbers = finite_floats(list(chain.from_iterable(map(column, rows) for column in columns)))
    return None if numbers is None else numbers.reshape(len(columns), -1)


def finite_floats(values: list[Any]) -> FloatArray | None:
    """``values`` as a float64 array when every one is a number (an int, a float or a
    boolean: ``True`` is 1.0) and finite, else None (text, ``null``, a list, an integer
    past the float range, NaN or infinity: the caller's slow path reports it).

    :mod:`struct` packs a flat list straight into the array's buffer, to the same numbers
    as each ``float(value)`` (correctly rounded): twice as fast as ``array("d")``, whose C
    loop parses a format per item, and as ``np.array`` discovers it (6 instead of 13 and
    15 us for a predictions file's 900 numbers). It takes what ``np.array`` refuses in one
    case only: a finite integer outside numpy's 64-bit range (2**70), which the slow path
    reads as the same float without a report, so the record is the same either way."""
    numbers = np.empty(len(values))
    try:
        struct.pack_into(f"{len(values)}d", numbers.data, 0, *values)
    except struct.error:  # a value that is no number, or an integer past the float range
        return None
    if not np.isfinite(numbers).all():
        return None
    return numbers


def _clean(array: np.ndarray, width: int, ndim: int = 1) -> bool:
    """True when a fast-path array is numeric, finite, of the expected width and of
    ``ndim`` dimensions (a list of numbers in place of every number makes one more: a
    value that is not a number, to report)."""
    if array.size == 0:
        return True
    if array.dtype.kind not in _NUMERIC_KINDS or array.size % width or array.ndim != ndim:
        return False
    return bool(np.isfinite(array).all())


def is_json_number(value: object) -> bool:
    """An int or float of a parsed JSON document (a boolean is none)."""
    return isinstance(value, int | float) and not isinstance(value, bool)


def json_number(value: object) -> float:
    """A JSON number as a float (:func:`as_float`: past the float range infinite); NaN for
    anything else (text, booleans, lists...)."""
    return as_float(value) if is_json_number(value) else math.nan


def as_float(value: Any) -> float:
    """``float(value)``, but an integer past the float range is infinite (as ``1e999`` in
    JSON reads), not an OverflowError: JSON integers have no size limit."""
    try:
        return float(value)
    except OverflowError:
        return math.inf if value > 0 else -math.inf


def _box_id(value: object) -> str:
    """Box ids compare with actor ids (strings): integers and integral floats as digits."""
    if isinstance(value, float) and value.is_integer():
        return str(int(value))
    return str(value)


def show_value(value: object) -> str:
    """A short repr of a value for a problem message (at most 40 characters)."""
    try:
        text = repr(value)
    except RecursionError:  # a list nested ~1000 levels (the JSON parser reads 1024)
        return f"a {type(value).__name__} nested too deep"
    return text if len(text) <= 40 else text[:37] + "..."


def _type(value: object) -> str:
    names: dict[type, str] = {dict: "an object", list: "a list", str: "a string"}
    return names.get(type(value), type(value).__name__)
