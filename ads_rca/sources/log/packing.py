"""Parsed records packed for the trip from a reader process to the parent, and rebuilt.

Pickling the records themselves costs about as much as parsing them: a predictions file is a
dozen small arrays and objects, each pickled with a header of its own. Packed, a chunk of
files is one float64 array plus, per record, its ids and keys (equal key tuples are shared,
so each is pickled once a chunk) and where its numbers start. The parent rebuilds every
record as views of that one array: the same values, dtypes and shapes (each a contiguous
block, as the parsers make them). Kinds without arrays (control commands, lane graphs)
travel as they are.

A chunk's numbers are megabytes (a 10,000-frame log's are 400 MB), and a pipe copies them
five times: into the pickle, into the pipe and out of it 64 KiB at a time, into the
received message, into the unpickled array. So a reader process hands a large chunk's
numbers over in a file of shared memory (:class:`SharedNumbers`, in ``/dev/shm``): it
writes them once; the parent maps the file copy-on-write and removes it at once, and its
pages are the records' arrays (no copy: reading the file into an array of its own cost
the parent more than the pipe did, fresh pages to fault in and the file's to free). The
loaded records so hold their numbers in that file system, so a chunk goes there only
while it leaves half of it free (other programs, a DDS transport say, use it too); else,
or where the directory is missing or unwritable, the numbers go in the message as
before. Each reading names its files with a prefix of its own and removes any left when
it ends (an interrupted reading's unreceived chunks); a file outlives the reading only if
the parent is killed outright.
"""

from __future__ import annotations

import contextlib
import itertools
import mmap
import os
from collections.abc import Iterable
from typing import Any

import numpy as np

from ads_rca.model import Actors, Boxes, EgoPose, FloatArray, Objects3D, Plan, Record, Track
from ads_rca.sources.log.records import track_offsets

#: What one packed record says: folder, timestamp, kind, then the kind's fields.
Entry = tuple[Any, ...]
#: A chunk of records: their numbers end to end, and an entry per record.
Packed = tuple[FloatArray, list[Entry]]
#: A chunk as it travels: its numbers may wait in a shared-memory file.
Handed = tuple["FloatArray | SharedNumbers", list[Entry]]
#: Where reader processes leave their chunks' numbers (a tmpfs on Linux).
SHARED_DIR = "/dev/shm"
#: Chunks with fewer bytes of numbers travel in the message (a file costs a few syscalls).
SHARED_MIN_BYTES = 1 << 20
#: The share of that file system a chunk must leave free to go there.
SHARED_FREE_SHARE = 0.5
#: How the files are named (a reading gives its own longer prefix: :func:`sweep_shared`).
SHARED_PREFIX = "ads-rca-chunk-"

_READINGS = itertools.count()

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

    def handed(self, prefix: str = SHARED_PREFIX) -> Handed:
        """:meth:`packed`, its numbers in a shared-memory file named ``prefix...`` when they
        are large (see the module's docstring) and the file can be written."""
        numbers, entries = self.packed()
        if numbers.nbytes >= SHARED_MIN_BYTES:
            shared = SharedNumbers.written(numbers, prefix)
            if shared is not None:
                return shared, entries
        return numbers, entries

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


class SharedNumbers:
    """A chunk's numbers left by a reader process in a shared-memory file, for the parent
    to read (:meth:`taken`), which removes the file. One that reached the parent and was
    never read (the reading stopped) removes its file when it is dropped."""

    __slots__ = ("_mine", "count", "path")

    def __init__(self, path: str, count: int, mine: bool = False) -> None:
        self.path = path
        self.count = count
        self._mine = mine  # the receiving end's copy owns the file

    def __reduce__(self) -> tuple[Any, ...]:
        return (_received, (self.path, self.count))

    @classmethod
    def written(cls, numbers: FloatArray, prefix: str = SHARED_PREFIX) -> SharedNumbers | None:
        """``numbers`` written to a new file of :data:`SHARED_DIR`; None (and no file)
        when that fails (no such directory, not writable, full) or would leave less than
        :data:`SHARED_FREE_SHARE` of its file system free."""
        if not _room_for(numbers.nbytes):
            return None
        import tempfile  # in reading workers only: not in every start-up (with random)

        try:
            fd, path = tempfile.mkstemp(prefix=prefix, suffix=".f64", dir=SHARED_DIR)
        except OSError:
            return None
        try:
            with os.fdopen(fd, "wb") as file:
                numbers.tofile(file)
        except OSError:
            _remove(path)
            return None
        return cls(path, numbers.size)

    def taken(self) -> FloatArray:
        """The numbers: the file's pages mapped copy-on-write (no copy; writable, as an
        unpickled array is), the file removed (its pages go with the last view)."""
        self._mine = False
        try:
            with open(self.path, "rb") as file:
                size = os.fstat(file.fileno()).st_size
                if size != 8 * self.count or size == 0:
                    raise OSError(f"{self.path}: {size} bytes, not the {8 * self.count} written")
                pages = mmap.mmap(file.fileno(), size, access=mmap.ACCESS_COPY)
        finally:
            _remove(self.path)
        return np.frombuffer(pages, np.float64)

    def __del__(self) -> None:
        if self._mine:
            _remove(self.path)


def _room_for(size: int) -> bool:
    """True when ``size`` more bytes leave :data:`SHARED_FREE_SHARE` of
    :data:`SHARED_DIR`'s file system free (the loaded records keep their pages there)."""
    try:
        info = os.statvfs(SHARED_DIR)
    except OSError:
        return False
    free = info.f_bavail * info.f_frsize - size
    return free >= 0 and free >= SHARED_FREE_SHARE * info.f_blocks * info.f_frsize


def _received(path: str, count: int) -> SharedNumbers:
    """A :class:`SharedNumbers` unpickled: the receiving end's, which owns the file."""
    return SharedNumbers(path, count, mine=True)


def reading_prefix() -> str:
    """A file-name prefix of its own for one reading's chunks (this process and a count)."""
    return f"{SHARED_PREFIX}{os.getpid()}-{next(_READINGS)}-"


def sweep_shared(prefix: str) -> None:
    """Remove what is left of a reading's files: chunks a worker wrote that the parent
    never received (the reading was interrupted: Ctrl-C, an error in another chunk)."""
    with contextlib.suppress(OSError):
        for name in os.listdir(SHARED_DIR):
            if name.startswith(prefix):
                _remove(os.path.join(SHARED_DIR, name))


def _remove(path: str) -> None:
    with contextlib.suppress(OSError):
        os.unlink(path)


def unpack(packed: Packed | Handed) -> Iterable[tuple[str, int, Record]]:
    """(folder, timestamp, record) of each packed record, in the order they were added."""
    numbers, entries = packed
    if isinstance(numbers, SharedNumbers):
        numbers = numbers.taken()
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
