"""What travels between the live graph's nodes: frame markers and per-frame monitor results.

A monitor's result must reach the aggregator bit for bit (the verdict is computed again from
it), so the JSON form keeps NaN and infinity (``ads_rca.contract.jsontext`` writes them as null
with the strict ``"$nonfinite"`` annotation and reads them back) and every field of
:class:`~ads_rca.oracles.base.OracleResult`. Pure data, no rclpy.
"""

from __future__ import annotations

import math
import pickle
import sys
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ads_rca.contract.errors import DOCUMENT_ERRORS, MalformedMessage
from ads_rca.contract.topics import TOPIC_FOLDERS
from ads_rca.live.runid import RunFilter, document_run
from ads_rca.model import FOLDERS, MAX_FRAME, MAX_TIMESTAMP_MS, bounded_int
from ads_rca.oracles.base import MODULES, Module, OracleResult
from ads_rca.problems import Problem, problems_from_list

#: Stamps a live message may carry, either side of zero (ROS time's range).
MAX_STAMP = MAX_TIMESTAMP_MS


@dataclass(frozen=True, slots=True)
class FrameMarker:
    """One ``run/frame`` marker: a stamp, its analysed index and what was sent for it."""

    index: int | None  # None: a records-only stamp
    stamp_ms: int
    folders: frozenset[str] = frozenset()
    duplicate: bool = False
    #: The frame is a snapshot table's row (its paths come on ``run/ego_paths``).
    snapshot: bool = False

    @classmethod
    def from_document(cls, document: Mapping[str, Any]) -> FrameMarker:
        """The marker a ``run/frame`` document describes; MalformedMessage (its text the
        reader's error, which is its cause) when it describes none."""
        try:
            index = document.get("index")
            published = document.get("published") or ()
            folders = frozenset(TOPIC_FOLDERS[str(k)] for k in published if str(k) in TOPIC_FOLDERS)
            if isinstance(index, int):
                index = bounded_int(index, "index", 0, MAX_FRAME)
            return cls(
                index if isinstance(index, int) else None,
                bounded_int(document.get("stamp_ms", 0), "stamp_ms", -MAX_STAMP, MAX_STAMP),
                folders,
                bool(document.get("duplicate", False)),
                isinstance(document.get("snapshot"), str),
            )
        except DOCUMENT_ERRORS as error:
            raise MalformedMessage(str(error)) from error


@dataclass(frozen=True)
class LiveResult:
    """One module's judgement of one analysed frame, as a monitor publishes it."""

    index: int  # position in the run's analysed-frame list (the marker's index)
    result: OracleResult
    frame: int | float
    #: The collision frame the result was computed with (-1: none known).
    collision_frame: int = -1
    #: Why the result may differ from the offline one (inputs missing, look-ahead cut ...).
    incomplete: tuple[str, ...] = ()
    revision: int = 0
    ego_id: str | None = None
    partner_id: str | None = None
    problems: tuple[Problem, ...] = ()
    compute_s: float = 0.0  # oracle time
    wait_s: float = 0.0  # from the frame's marker arriving to the result
    #: When the frame's first input reached the monitor (CLOCK_MONOTONIC s, shared by the
    #: processes of one machine; 0: not said): the verdict's latency counts from it.
    arrived_s: float = 0.0
    session: str = ""  # the monitor process's start token
    run: str = ""  # the run judged (the player's run id; "" = none known)
    #: Stack mode: this module's last frame at or before collision frame N (-1: not one):
    #: the module is complete for that collision's verdict.
    closes_collision: int = -1
    #: Stack mode: the frame period the monitor used (measured or given; 0: a player's run).
    frame_ms: int = 0
    #: Stack mode: the episode judged (1, 2, ...: the stamps went back, a new run began);
    #: the aggregator keys results by it, so two episodes never mix.
    episode: int = 1
    #: Judged before the collision partner was known, against the mode's provisional
    #: partner (``partner_id``): shown while the run plays, never part of a verdict; a
    #: later revision replaces it (docs/live-graph.md "Provisional results").
    provisional: bool = False
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def module(self) -> Module:
        return self.result.module

    @property
    def stamp_ms(self) -> int:
        return self.result.timestamp_ms

    @property
    def missing_folders(self) -> list[str]:
        """The input folders this result was judged without."""
        return missing_folders(self.incomplete)

    def to_document(self) -> dict[str, Any]:
        r = self.result
        return {
            "module": r.module,
            "index": self.index,
            "stamp_ms": r.timestamp_ms,
            "frame": self.frame,
            "failed": r.failed,
            "skipped": r.skipped,
            **({"missing_input": True} if r.missing_input else {}),
            **({"internal_error": r.internal_error} if r.internal_error else {}),
            "ids": list(r.ids),
            "metrics": plain(r.metrics),
            "thresholds": plain(r.thresholds),
            "collision_frame": self.collision_frame,
            "incomplete": list(self.incomplete),
            "revision": self.revision,
            "ego_id": self.ego_id,
            "partner_id": self.partner_id,
            "problems": [p.to_dict() for p in self.problems],
            "compute_s": self.compute_s,
            "wait_s": self.wait_s,
            **({"arrived_s": self.arrived_s} if self.arrived_s > 0 else {}),
            "session": self.session,
            **({"run": self.run} if self.run else {}),
            **({"closes_collision": self.closes_collision} if self.closes_collision >= 0 else {}),
            **({"frame_ms": self.frame_ms} if self.frame_ms > 0 else {}),
            **({"episode": self.episode} if self.frame_ms > 0 or self.episode != 1 else {}),
            **({"provisional": True} if self.provisional else {}),
            **self.extra,
        }

    @classmethod
    def from_document(cls, d: Mapping[str, Any]) -> LiveResult:
        """The result a monitor's document describes; MalformedMessage (its text the
        reader's error, which is its cause) when it describes none."""
        try:
            return cls._read(d)
        except DOCUMENT_ERRORS as error:
            raise MalformedMessage(str(error)) from error

    @classmethod
    def _read(cls, d: Mapping[str, Any]) -> LiveResult:
        module = str(d["module"])
        if module not in MODULES:
            raise ValueError(f"unknown module {module!r}")  # made a MalformedMessage above
        result = OracleResult(
            module,
            bounded_int(d["stamp_ms"], "stamp_ms", -MAX_STAMP, MAX_STAMP),
            bool(d["failed"]),
            dict(d.get("metrics") or {}),
            {str(k): v for k, v in (d.get("thresholds") or {}).items()},
            tuple(str(i) for i in d.get("ids") or ()),
            d.get("skipped"),
            d.get("missing_input") is True,
            _text_or_none(d.get("internal_error")),
        )
        return cls(
            index=bounded_int(d["index"], "index", -1, MAX_FRAME),
            result=result,
            frame=d["frame"],
            collision_frame=bounded_int(
                d.get("collision_frame", -1), "collision_frame", -MAX_FRAME, MAX_FRAME
            ),
            incomplete=tuple(d.get("incomplete") or ()),
            revision=bounded_int(d.get("revision", 0), "revision", 0, MAX_FRAME),
            ego_id=d.get("ego_id"),
            partner_id=d.get("partner_id"),
            problems=tuple(problems_from_list(d.get("problems"))),
            compute_s=float(d.get("compute_s", 0.0)),
            wait_s=float(d.get("wait_s", 0.0)),
            arrived_s=_seconds(d.get("arrived_s", 0.0)),
            session=str(d.get("session", "")),
            run=str(d.get("run") or ""),
            closes_collision=bounded_int(
                d.get("closes_collision", -1), "closes_collision", -1, MAX_FRAME
            ),
            frame_ms=bounded_int(d.get("frame_ms", 0), "frame_ms", 0, MAX_STAMP),
            episode=bounded_int(d.get("episode", 1), "episode", 1, MAX_FRAME),
            provisional=d.get("provisional") is True,
        )


#: How a result names an input it was judged without: ``no <folder> record``.
_NO_RECORD = ("no ", " record")


def missing_folders(incomplete: tuple[str, ...]) -> list[str]:
    """The input folders a result's ``incomplete`` reasons say it was judged without."""
    head, tail = _NO_RECORD
    return [
        reason[len(head) : -len(tail)]
        for reason in incomplete
        if reason.startswith(head) and reason.endswith(tail)
    ]


def no_record(folder: str) -> str:
    """The ``incomplete`` reason of a result judged without ``folder``'s record."""
    return f"{_NO_RECORD[0]}{folder}{_NO_RECORD[1]}"


def _seconds(value: object) -> float:
    """A document's clock reading: a finite non-negative number, else 0 (not said)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return 0.0
    seconds = float(value)
    return seconds if math.isfinite(seconds) and seconds > 0 else 0.0


def _text_or_none(value: object) -> str | None:
    """A wire field that is text when present (anything else: absent)."""
    return value if isinstance(value, str) and value else None


def collision_frame(document: Mapping[str, Any], runs: RunFilter) -> int | None:
    """The frame a ``run/collision`` event sets, or None: an event naming another run is
    ignored, one naming no run (a live stack's own event) is taken; the monitors and the
    aggregator read the event by this one rule. MalformedMessage: a frame past MAX_FRAME."""
    if document_run(document) is not None and not runs.accept(document):
        return None
    frame = document.get("frame")
    if not isinstance(frame, int) or isinstance(frame, bool) or frame < 0:
        return None
    if frame > MAX_FRAME:  # an absurd frame would hold the verdict forever
        raise MalformedMessage(f"collision frame {str(frame)[:40]} is past {MAX_FRAME}")
    return frame


@dataclass
class RunEnd:
    """When the player's end counts, for a node that receives its markers.

    DDS does not order topics: the end status may overtake the last markers, so the end only
    counts once as many markers arrived as it announced (a node that joined late never gets
    them all; it ends on its own timeouts).
    """

    markers_received: int = 0
    finished: bool = False
    _announced: int | None = None

    def marker(self) -> None:
        """One more marker arrived."""
        self.markers_received += 1
        self._update()

    def end(self, frames_published: int | None) -> None:
        """The player reached the end after ``frames_published`` markers (None: unknown)."""
        self._announced = 0 if frames_published is None else frames_published
        self._update()

    def _update(self) -> None:
        if self._announced is not None and self.markers_received >= self._announced:
            self.finished = True


class FollowsRunEnd:
    """A node core that follows the player's end (monitor window, aggregator): its
    ``finished`` and ``markers_received`` are its :class:`RunEnd`'s."""

    end: RunEnd

    @property
    def finished(self) -> bool:
        return self.end.finished

    @property
    def markers_received(self) -> int:
        return self.end.markers_received


def plain(value: object) -> Any:
    """JSON-ready without loss: numpy scalars as Python numbers, tuples as lists (NaN kept)."""
    if isinstance(value, bool | int | float | str) or value is None:
        return value
    if isinstance(value, Mapping):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [plain(v) for v in value]
    if hasattr(value, "tolist"):  # numpy scalar or array
        return plain(value.tolist())
    return str(value)


#: A result or marker this far beyond the highest index held is dropped: the columns grow
#: to the largest index, so one absurd index must not allocate gigabytes.
MAX_INDEX_AHEAD = 1 << 16


class Columns:
    """Fixed-size values per analysed-frame index in growable numpy columns (no per-frame
    Python objects: a long run holds a few dozen bytes a frame)."""

    def __init__(self, **dtypes: Any) -> None:
        self._dtypes = dtypes
        self.present = np.zeros(0, dtype=np.bool_)
        self.columns: dict[str, np.ndarray] = {k: np.zeros(0, dtype=t) for k, t in dtypes.items()}
        self.top = -1  # highest index held
        self._count = 0

    def accepts(self, index: int) -> bool:
        return 0 <= index <= self.top + MAX_INDEX_AHEAD

    def set(self, index: int, **values: Any) -> None:
        if index >= len(self.present):
            size = max(1024, 2 * len(self.present), index + 1)
            self.present = np.concatenate([self.present, np.zeros(size - len(self.present), bool)])
            for name, column in self.columns.items():
                grown = np.zeros(size, dtype=self._dtypes[name])
                grown[: len(column)] = column
                self.columns[name] = grown
        if not self.present[index]:
            self._count += 1
        self.present[index] = True
        for name, value in values.items():
            self.columns[name][index] = value
        self.top = max(self.top, index)

    def has(self, index: int) -> bool:
        return 0 <= index < len(self.present) and bool(self.present[index])

    @property
    def count(self) -> int:
        """Indices held."""
        return self._count

    def get(self, name: str, index: int) -> Any:
        return self.columns[name][index].item()

    def indices(self) -> np.ndarray:
        return np.flatnonzero(self.present)


class ResultStore:
    """Each module's latest result per analysed-frame index (the highest revision).

    The oracle results themselves go to an anonymous temporary file (unlinked at creation,
    so nothing is left behind and no other process can open it by name) and are read back
    only when the verdict is rendered; memory holds fixed-size columns: revision, collision
    frame, incompleteness, and where the result lies in the file.
    """

    def __init__(self) -> None:
        self._file = tempfile.TemporaryFile()  # noqa: SIM115 - closed by close()
        self._end = 0
        self._modules = {
            m: Columns(
                revision=np.int64,
                collision=np.int64,
                incomplete=np.bool_,
                missing=np.int64,
                failed=np.bool_,
                offset=np.int64,
                length=np.int64,
            )
            for m in MODULES
        }
        #: Per frame index, the earliest time a monitor said the frame reached it (one
        #: column for the four modules: 8 bytes a frame).
        self._arrivals = Columns(arrived=np.float64)

    def put(self, result: LiveResult) -> bool:
        """Keep ``result`` unless a higher revision is held (or its index is absurd)."""
        columns = self._modules[result.module]
        index = result.index
        if not columns.accepts(index):
            return False
        if columns.has(index) and result.revision < columns.get("revision", index):
            return False
        data = pickle.dumps(result.result, protocol=pickle.HIGHEST_PROTOCOL)
        self._file.seek(self._end)
        self._file.write(data)
        columns.set(
            index,
            revision=result.revision,
            collision=result.collision_frame,
            incomplete=bool(result.incomplete),
            missing=folder_bits(result.missing_folders),
            failed=result.result.failed,
            offset=self._end,
            length=len(data),
        )
        self._end += len(data)
        if result.arrived_s > 0 and self._arrivals.accepts(index):
            held = self._arrivals.has(index)
            if not held or result.arrived_s < self._arrivals.get("arrived", index):
                self._arrivals.set(index, arrived=result.arrived_s)
        return True

    def has(self, module: Module, index: int) -> bool:
        return self._modules[module].has(index)

    def collision_frame(self, module: Module, index: int) -> int:
        return int(self._modules[module].get("collision", index))

    def arrived(self, index: int) -> float | None:
        """The earliest time a monitor said frame ``index`` reached it (None: none said)."""
        if not self._arrivals.has(index):
            return None
        return float(self._arrivals.get("arrived", index))

    def result(self, module: Module, index: int) -> OracleResult:
        """The held result (read back from the file)."""
        columns = self._modules[module]
        self._file.seek(columns.get("offset", index))
        data = self._file.read(columns.get("length", index))
        result: OracleResult = pickle.loads(data)  # our own private file
        # Unpickled keys are new strings each time: share them, as the wire's decoder does.
        metrics = _shared_keys(result.metrics)
        return replace(result, metrics=metrics, thresholds=_shared_keys(result.thresholds))

    def failed_among(self, module: Module, indices: np.ndarray) -> np.ndarray:
        """Those of ``indices`` where ``module``'s held result failed (from the columns)."""
        columns = self._modules[module]
        held = self._held(columns, indices)
        failed: np.ndarray = held[columns.columns["failed"][held]]
        return failed

    def incomplete(self, among: np.ndarray | None = None) -> list[tuple[Module, int]]:
        """(module, index) of the held results judged with incomplete inputs (of the
        indices ``among`` only, when given)."""
        out: list[tuple[Module, int]] = []
        for module, columns in self._modules.items():
            rows = columns.indices() if among is None else self._held(columns, among)
            flagged = rows[columns.columns["incomplete"][rows]]
            out.extend((module, int(i)) for i in flagged)
        return sorted(out)

    def is_incomplete(self, module: Module, index: int) -> bool:
        return bool(self._modules[module].get("incomplete", index))

    def lacking(self, module: Module, among: np.ndarray) -> int | None:
        """The folder bits (:func:`folder_bits`) of the inputs every held result of
        ``module`` among ``among`` was judged without (None: none held)."""
        columns = self._modules[module]
        rows = self._held(columns, among)
        if not rows.size:
            return None
        return int(np.bitwise_and.reduce(columns.columns["missing"][rows]))

    @staticmethod
    def _held(columns: Columns, among: np.ndarray) -> np.ndarray:
        inside = among[among < len(columns.present)]
        held: np.ndarray = inside[columns.present[inside]]
        return held

    def close(self) -> None:
        self._file.close()


def folder_bits(folders: list[str]) -> int:
    """One bit per input folder (model.FOLDERS order) of ``folders``."""
    return sum(1 << FOLDERS.index(f) for f in set(folders) if f in FOLDERS)


def _shared_keys(value: object) -> Any:
    """``value`` with every dict key interned (so a thousand results share their keys)."""
    if isinstance(value, dict):
        return {
            sys.intern(k) if isinstance(k, str) else k: _shared_keys(v) for k, v in value.items()
        }
    if isinstance(value, list):
        return [_shared_keys(v) for v in value]
    return value
