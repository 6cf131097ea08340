"""Parsed records packed for the trip from a reader process to the parent, and rebuilt.

Pickling the records themselves costs about as much as parsing them: a predictions file is a
dozen small arrays and objects, each pickled with a header of its own. Packed, a chunk of
files is one float64 array plus, per record, its ids and keys (equal key tuples are shared,
so each is pickled once a chunk) and where its numbers start. The parent rebuilds every
record as views of that one array: the same values, dtypes and shapes (each a contiguous
block, as the parsers make them). Kinds without arrays (control commands, lane graphs)
travel as they are.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np

from ads_rca.io.records import track_offsets
from ads_rca.model import Actors, Boxes, EgoPose, FloatArray, Objects3D, Plan, Record, Track

#: What one packed record says: folder, timestamp, kind, then the kind's fields.
Entry = tuple[Any, ...]
#: A chunk of records: their numbers end to end, and an entry per record.
Packed = tuple[FloatArray, list[Entry]]

_POSE, _ACTORS, _BOXES, _PREDICTIONS, _PLAN, _OBJECTS_3D, _AS_IS = range(7)
_POSE_WIDTH = 7


class Packer:
    """Collects records into one :data:`Packed` chunk."""

    def __init__(self) -> None:
        self._blocks: list[FloatArray] = []
        self._size = 0
        self._entries: list[Entry] = []
        self._shared: dict[tuple[str, ...], tuple[str, ...]] = {}

    def add(self, folder: str, ts: int, record: Record) -> None:
        entries = self._entries
        if isinstance(record, EgoPose):
            numbers = np.array(
                [record.x, record.y, record.z, record.roll, record.pitch, record.yaw, record.speed]
            )
            entries.append((folder, ts, _POSE, self._put(numbers)))
        elif isinstance(record, Actors):
            start = self._put(record.location, record.rotation, record.extent)
            entries.append((folder, ts, _ACTORS, self._tuple(record.ids), start))
        elif isinstance(record, Boxes):
            start = self._put(record.corners)
            entries.append((folder, ts, _BOXES, self._tuple(record.ids), start, record.extras))
        elif isinstance(record, dict):  # Predictions
            tracks = list(record.values())
            keys = tuple(self._tuple(track.keys) for track in tracks)
            start = self._put(*(track.offsets for track in tracks))
            entries.append((folder, ts, _PREDICTIONS, self._tuple(tuple(record)), keys, start))
        elif isinstance(record, Plan):
            start = self._put(record.xy, record.speed)
            entries.append((folder, ts, _PLAN, self._tuple(record.keys), start))
        elif isinstance(record, Objects3D):  # five arrays each pickled cost 50 us a file
            start = self._put(
                record.location, record.yaw, record.extent, record.velocity, record.score
            )
            ids, labels = self._tuple(record.ids), self._tuple(record.labels)
            entries.append((folder, ts, _OBJECTS_3D, ids, labels, start))
        else:
            entries.append((folder, ts, _AS_IS, record))

    def add_predictions(
        self,
        folder: str,
        ts: int,
        ids: tuple[str, ...],
        keys: list[tuple[str, ...]],
        offsets: FloatArray,
    ) -> None:
        """A predictions record given in pieces (its ids, each track's keys, all offsets
        end to end): packed as :meth:`add` packs the record they make, without making it."""
        start = self._put(offsets)
        shared = tuple(self._tuple(track_keys) for track_keys in keys)
        self._entries.append((folder, ts, _PREDICTIONS, self._tuple(ids), shared, start))

    def packed(self) -> Packed:
        numbers = np.concatenate(self._blocks) if self._blocks else np.zeros(0)
        return numbers.astype(np.float64, copy=False), self._entries

    def _put(self, *arrays: FloatArray) -> int:
        """Append the arrays' numbers (row-major); where the first one starts."""
        start = self._size
        for array in arrays:
            flat = array.ravel()
            self._blocks.append(flat)
            self._size += flat.size
        return start

    def _tuple(self, items: tuple[str, ...]) -> tuple[str, ...]:
        """One object per distinct tuple of a chunk: pickled once, compared by identity."""
        return self._shared.setdefault(items, items)


def unpack(packed: Packed) -> Iterable[tuple[str, int, Record]]:
    """(folder, timestamp, record) of each packed record, in the order they were added."""
    numbers, entries = packed
    for entry in entries:
        folder, ts, kind = entry[0], entry[1], entry[2]
        record: Record
        if kind == _POSE:
            start = entry[3]
            record = EgoPose(*numbers[start : start + _POSE_WIDTH].tolist())
        elif kind == _ACTORS:
            ids, start = entry[3], entry[4]
            size = 3 * len(ids)
            location, rotation, extent = (
                numbers[start + i * size : start + (i + 1) * size].reshape(-1, 3) for i in range(3)
            )
            record = Actors(ids, location, rotation, extent)
        elif kind == _BOXES:
            ids, start, extras = entry[3], entry[4], entry[5]
            record = Boxes(ids, numbers[start : start + 4 * len(ids)].reshape(-1, 4), extras)
        elif kind == _PREDICTIONS:
            ids, keys, start = entry[3], entry[4], entry[5]
            rows = numbers[start : start + 3 * sum(map(len, keys))].reshape(-1, 3)
            record = dict(zip(ids, map(Track.of, keys, track_offsets(rows, keys)), strict=True))
        elif kind == _PLAN:
            keys, start = entry[3], entry[4]
            size = len(keys)
            xy = numbers[start : start + 2 * size].reshape(-1, 2)
            record = Plan(keys, xy, numbers[start + 2 * size : start + 3 * size])
        elif kind == _OBJECTS_3D:
            record = _objects_3d(numbers, *entry[3:6])
        else:
            record = entry[3]
        yield folder, ts, record


def _objects_3d(
    numbers: FloatArray, ids: tuple[str, ...], labels: tuple[str, ...], start: int
) -> Objects3D:
    """3-D objects from their columns end to end: location, yaw, extent, velocity, score."""
    n = len(ids)
    column = numbers[start : start + 11 * n]
    return Objects3D(
        ids=ids,
        location=column[: 3 * n].reshape(-1, 3),
        yaw=column[3 * n : 4 * n],
        extent=column[4 * n : 7 * n].reshape(-1, 3),
        velocity=column[7 * n : 10 * n].reshape(-1, 3),
        score=column[10 * n :],
        labels=labels,
    )
