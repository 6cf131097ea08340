"""Parsing a CARLA experiment-client run's telemetry: ``telemetry.json`` or ``.csv``.

Both schema versions of the JSON (v0: ``ego.speed``; v0.2: ``speed_fd`` / ``speed_actor``,
finite-difference actor speeds, traffic lights) and the header-driven CSV (the ego only).
Each tick becomes one row of :class:`Telemetry` (columnar, so the reader builds arrays in
one go); a value that is not a number is read as NaN or a default and reported with its
field path, a tick without a usable time or ego position is skipped and reported, an actor
that is not a vehicle or walker is counted, not kept. See :mod:`.carla_run` for the model.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from ads_rca.model import MAX_TIMESTAMP_MS
from ads_rca.problems import (
    DROPPED_RECORD,
    IGNORED,
    SKIPPED_FILE,
    SKIPPED_FRAME,
    USED_DEFAULT,
    ProblemLog,
)
from ads_rca.sources.carla import TELEMETRY_CSV, TELEMETRY_JSON
from ads_rca.sources.carla.annotations import MAX_KIND, bounded
from ads_rca.sources.log.records import FieldReader, show_value

#: The ego's actor id (CARLA ids are integers, so no recorded actor has it).
EGO_ACTOR_ID = "ego"
#: The client's frame rate when neither the run nor its telemetry says one.
DEFAULT_FPS = 20.0
MAX_FPS = 1000.0
KEPT_KINDS = ("vehicle", "walker")
#: The longest actor id kept (CARLA's are small integers).
MAX_ID = 64


@dataclass
class Telemetry:
    """Every tick of a run, columnar: the ego per tick, the kept actors one row each."""

    file: str
    schema: str
    fps: float | None  # the telemetry's own metadata.fps, when it gives one
    stamps: list[int] = field(default_factory=list)
    ego: list[list[float]] = field(default_factory=list)  # x y z roll pitch yaw speed vx vy
    actor_tick: list[int] = field(default_factory=list)
    actor_id: list[str] = field(default_factory=list)
    actor_kind: list[str] = field(default_factory=list)
    actor_type: list[str] = field(default_factory=list)
    actor_values: list[list[float]] = field(default_factory=list)  # x y z roll pitch yaw speed
    other_kinds: dict[str, int] = field(default_factory=dict)


def telemetry_from_json(document: Any, problems: ProblemLog) -> Telemetry | None:
    file = TELEMETRY_JSON
    if not isinstance(document, dict):
        problems.add(file, "", f"expected an object, found {kind_of(document)}", SKIPPED_FILE)
        return None
    frames = document.get("frames")
    if not isinstance(frames, list):
        problems.add(file, "frames", f"expected a list, found {kind_of(frames)}", SKIPPED_FILE)
        return None
    meta = document.get("metadata")
    if not isinstance(meta, dict):
        if meta is not None:
            problems.add(file, "metadata", f"expected an object, found {kind_of(meta)}", IGNORED)
        meta = {}
    v02 = meta.get("schema_version") == "0.2" or any(
        isinstance(f, dict) and isinstance(f.get("ego"), dict) and "speed_fd" in f["ego"]
        for f in frames[:1]
    )
    reader = FieldReader(file, problems, None, text_numbers_reported=True)
    fps = reader.number(meta, "fps", "metadata.fps") if "fps" in meta else None
    out = Telemetry(file, "v0.2" if v02 else "v0", fps if fps is None or valid_fps(fps) else None)
    for n, frame in enumerate(frames):
        where = f"frames[{n}]"
        if not isinstance(frame, dict):
            problems.add(file, where, f"expected an object, found {kind_of(frame)}", SKIPPED_FRAME)
            continue
        stamp = _stamp(frame, where, reader, out.fps)
        ego = frame.get("ego")
        if stamp is None:
            continue
        reader.timestamp_ms = stamp
        if not isinstance(ego, dict):
            problems.add(
                file,
                f"{where}.ego",
                f"expected an object, found {kind_of(ego)}",
                SKIPPED_FRAME,
                timestamp_ms=stamp,
            )
            continue
        values = _ego_values(ego, f"{where}.ego", reader)
        if values is None:
            continue
        tick = len(out.stamps)
        out.stamps.append(stamp)
        out.ego.append(values)
        listed = frame.get("actors", [])
        if not isinstance(listed, list):
            reader.report(f"{where}.actors", f"expected a list, found {kind_of(listed)}", IGNORED)
            continue
        seen: set[str] = set()
        for m, actor in enumerate(listed):
            _actor(actor, f"{where}.actors[{m}]", tick, seen, reader, out)
    return out


def _stamp(
    frame: Mapping[str, Any], where: str, reader: FieldReader, fps: float | None
) -> int | None:
    """The tick's time in ms: ``t_sim``, else ``frame`` / fps; None (reported) when neither
    gives a time inside the log's range."""
    if "t_sim" in frame:
        seconds = reader.number(frame, "t_sim", f"{where}.t_sim")
    elif "frame" in frame:
        rate = fps or DEFAULT_FPS
        seconds = reader.number(frame, "frame", f"{where}.frame") / rate
        reader.report(
            f"{where}.t_sim", "missing", f"{USED_DEFAULT}: frame / {rate:g} fps", "warning"
        )
    else:
        reader.report(f"{where}.t_sim", "missing (no frame either)", SKIPPED_FRAME)
        return None
    if not (math.isfinite(seconds) and 0.0 <= seconds * 1000.0 <= MAX_TIMESTAMP_MS):
        reader.report(f"{where}.t_sim", f"{seconds!r} s is outside the log's range", SKIPPED_FRAME)
        return None
    return round(seconds * 1000.0)


def _ego_values(ego: Mapping[str, Any], where: str, reader: FieldReader) -> list[float] | None:
    """x y z roll pitch yaw speed vx vy of one tick's ego; None (reported) without x, y."""
    position = ego.get("position")
    if not isinstance(position, dict) or "x" not in position or "y" not in position:
        reader.report(f"{where}.position", "missing", SKIPPED_FRAME)
        return None
    orientation = ego.get("orientation")
    if not isinstance(orientation, dict):
        reader.report(f"{where}.orientation", "missing", "read as NaN")
        orientation = {}
    velocity = ego.get("velocity")
    body = (
        [reader.number(velocity, k, f"{where}.velocity.{k}") for k in ("vx", "vy")]
        if isinstance(velocity, dict)
        else [math.nan, math.nan]
    )
    speed_key = next((k for k in ("speed_fd", "speed", "speed_actor") if k in ego), None)
    if speed_key is not None:
        speed = reader.number(ego, speed_key, f"{where}.{speed_key}")
    else:
        speed = math.hypot(*body)
        reader.report(f"{where}.speed", "missing", f"{USED_DEFAULT}: |velocity|", "warning")
    return [
        reader.number(position, "x", f"{where}.position.x"),
        reader.number(position, "y", f"{where}.position.y"),
        reader.number(position, "z", f"{where}.position.z", 0.0),
        reader.number(orientation, "roll", f"{where}.orientation.roll", 0.0),
        reader.number(orientation, "pitch", f"{where}.orientation.pitch", 0.0),
        reader.number(orientation, "yaw", f"{where}.orientation.yaw"),
        speed,
        *body,
    ]


def _actor(
    actor: Any, where: str, tick: int, seen: set[str], reader: FieldReader, out: Telemetry
) -> None:
    """One listed actor: kept (a vehicle or walker with an id and a position) or reported."""
    if not isinstance(actor, dict):
        reader.report(where, f"expected an object, found {kind_of(actor)}", DROPPED_RECORD)
        return
    kind = actor.get("type")
    if kind not in KEPT_KINDS:
        label = bounded(kind, MAX_KIND) if isinstance(kind, str) else kind_of(kind)
        out.other_kinds[label] = out.other_kinds.get(label, 0) + 1
        return
    raw_id = actor.get("id")
    if isinstance(raw_id, bool) or not isinstance(raw_id, int | str):
        reader.report(f"{where}.id", f"{show_value(raw_id)} is not an id", DROPPED_RECORD)
        return
    actor_id = str(raw_id)
    if actor_id == EGO_ACTOR_ID or len(actor_id) > MAX_ID or actor_id in seen:
        issue = (
            f"{show_value(raw_id)} is the ego's actor id"
            if actor_id == EGO_ACTOR_ID
            else f"{show_value(raw_id)} is listed twice in this tick"
            if actor_id in seen
            else f"longer than {MAX_ID} characters"
        )
        reader.report(f"{where}.id", issue, DROPPED_RECORD)
        return
    position = actor.get("position")
    if not isinstance(position, dict) or "x" not in position or "y" not in position:
        reader.report(f"{where}.position", "missing", DROPPED_RECORD)
        return
    rotation = actor.get("rotation")
    if not isinstance(rotation, dict):
        reader.report(f"{where}.rotation", "missing", "read as 0", "warning")
        rotation = {}
    type_id = actor.get("type_id")
    speed = _actor_speed(actor, where, reader)
    seen.add(actor_id)
    out.actor_tick.append(tick)
    out.actor_id.append(actor_id)
    out.actor_kind.append(kind)
    out.actor_type.append(type_id if isinstance(type_id, str) else "")
    out.actor_values.append(
        [
            reader.number(position, "x", f"{where}.position.x"),
            reader.number(position, "y", f"{where}.position.y"),
            reader.number(position, "z", f"{where}.position.z", 0.0),
            *(
                reader.number(rotation, a, f"{where}.rotation.{a}", 0.0)
                for a in ("roll", "pitch", "yaw")
            ),
            speed,
        ]
    )


def _actor_speed(actor: Mapping[str, Any], where: str, reader: FieldReader) -> float:
    """``speed`` (v0.2: ``speed_fd``), else the magnitude of ``velocity``, else NaN."""
    key = next((k for k in ("speed_fd", "speed") if k in actor), None)
    if key is not None:
        return reader.number(actor, key, f"{where}.{key}")
    velocity = actor.get("velocity")
    if isinstance(velocity, dict):
        return math.hypot(*(reader.number(velocity, a, f"{where}.velocity.{a}", 0.0) for a in "xy"))
    return math.nan


#: telemetry.csv columns: ego value -> the columns that may hold it, first present wins.
CSV_COLUMNS: Mapping[str, tuple[str, ...]] = {
    "x": ("world_x",),
    "y": ("world_y",),
    "z": ("world_z",),
    "roll": ("roll",),
    "pitch": ("pitch",),
    "yaw": ("yaw",),
    "speed": ("speed_fd", "speed", "speed_actor"),
    "vx": ("vx",),
    "vy": ("vy",),
}


def telemetry_from_csv(data: bytes, problems: ProblemLog) -> Telemetry:
    """The ego's ticks of ``telemetry.csv`` (no actors: the CSV holds the ego only)."""
    file = TELEMETRY_CSV
    out = Telemetry(file, "csv", None)
    try:
        text = data.decode("utf-8-sig")
        table = list(csv.reader(io.StringIO(text, newline="")))
    except (UnicodeDecodeError, csv.Error) as error:
        problems.add(file, "", f"unreadable CSV ({str(error).splitlines()[0][:80]})", SKIPPED_FILE)
        return out
    if not table:
        problems.add(file, "", "empty file", SKIPPED_FILE)
        return out
    header = [name.strip() for name in table[0]]
    column = {name: header.index(name) for name in header if header.count(name) == 1}
    where_t = "t_sim" if "t_sim" in column else "frame" if "frame" in column else None
    needed = [
        c[0] for key, c in CSV_COLUMNS.items() if key in ("x", "y", "yaw") and c[0] not in column
    ]
    if where_t is None or needed:
        missing = ", ".join(([] if where_t else ["t_sim"]) + needed)
        problems.add(file, "header", f"no column {missing}", SKIPPED_FILE)
        return out
    picks = {
        key: next((column[c] for c in names if c in column), None)
        for key, names in CSV_COLUMNS.items()
    }
    reader = FieldReader(file, problems, None, text_numbers_reported=False)
    for line, row in enumerate(table[1:], start=2):
        if not row:
            continue
        cells = dict(enumerate(row))
        where = f"line {line}"
        scale = 1.0 if where_t == "t_sim" else 1.0 / DEFAULT_FPS
        seconds = reader.number(cells, column[where_t], f"{where}.{where_t}") * scale
        if not (math.isfinite(seconds) and 0.0 <= seconds * 1000.0 <= MAX_TIMESTAMP_MS):
            reader.report(f"{where}.{where_t}", "not a time inside the log's range", SKIPPED_FRAME)
            continue
        stamp = round(seconds * 1000.0)
        reader.timestamp_ms = stamp
        values = [
            math.nan if at is None else reader.number(cells, at, f"{where}.{header[at]}")
            for at in picks.values()
        ]
        if picks["z"] is None:
            values[2] = 0.0
        out.stamps.append(stamp)
        out.ego.append(values)
    return out


def valid_fps(fps: float) -> bool:
    return math.isfinite(fps) and 1.0 <= fps <= MAX_FPS


def kind_of(value: object) -> str:
    """What a JSON value is, for a problem message."""
    names: dict[type, str] = {dict: "an object", list: "a list", str: "text"}
    return "nothing" if value is None else names.get(type(value), type(value).__name__)
