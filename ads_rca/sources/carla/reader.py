"""Reader for CARLA experiment-client runs: a ``runs/<scenario>/`` folder.

What is read (docs/formats.md "CARLA experiment-client runs" has the whole mapping):

- ``telemetry.json`` (the documented schema and its v0.2 variant with ``speed_fd`` /
  ``speed_actor`` and traffic lights), or ``telemetry.csv`` (header-driven, the ego only)
  when the JSON is absent or unusable: one analysed frame per tick, at
  ``round(1000 · t_sim)`` ms. Poses are CARLA world already (the "SAE" label of the file
  covers only the body-frame velocities, y left), so they are taken as they are.
- the actors: vehicles and walkers only; their half extents come from the bundled CARLA
  blueprint table (:mod:`.carla_blueprints`), so they are *assumed*; the ego becomes the
  actor ``ego`` at its pose, with its blueprint's extent (``scenario.yaml``
  ``ego_vehicle``).
- ``run_metadata.json``: the frame rate and the run's facts (scenario, map, seed, versions).
- ``events.json``: annotations (:mod:`ads_rca.sources.carla.annotations`), never collisions.
- ``plan.json`` where present: the ego's scripted reference path, resampled at every frame
  as a plan of the next :data:`PLAN_STEPS` frames, so the control-tracking check can run.
- no collision: the run records none (−1), unless ``derived_collision`` asks for the first
  tick where the ego's box overlaps another's (oriented boxes, assumed extents): *derived*.

The run's own safety and comfort figures (:mod:`ads_rca.sources.carla.figures`) and its capability
record (every model input: real, derived, assumed or absent, and why) go in the metadata.
Bad input is reported like the running-log reader does: a bad value is read as NaN or a
default and reported with its file and field, a bad tick or actor is skipped and reported;
only a folder with no usable telemetry at all raises InputError (one line).
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ads_rca.capabilities import source_statuses
from ads_rca.errors import ConfigError, InputError
from ads_rca.foundation.files import DEFAULT_MAX_FILE_MB, read_regular
from ads_rca.foundation.geometry import FloatArray
from ads_rca.model import (
    INPUTS_KEY,
    MAX_TIMESTAMP_MS,
    Actors,
    EgoPose,
    InputStatus,
    Plan,
    Record,
    RunLog,
    RunMetadata,
    most_common_step,
)
from ads_rca.problems import (
    DROPPED_RECORD,
    IGNORED,
    KEPT_VALUE,
    SKIPPED_FILE,
    SKIPPED_FRAME,
    USED_DEFAULT,
    ProblemLog,
)
from ads_rca.sources.carla import TELEMETRY_CSV, TELEMETRY_JSON
from ads_rca.sources.carla.annotations import (
    ANNOTATIONS_KEY,
    MAX_ANNOTATIONS,
    MAX_KIND,
    Annotation,
    bounded,
)
from ads_rca.sources.carla.blueprints import blueprint_extent
from ads_rca.sources.carla.figures import (
    BASIS,
    FIGURES_KEY,
    ActorRows,
    EgoTrack,
    overlaps,
    run_figures,
)
from ads_rca.sources.carla.telemetry import (
    DEFAULT_FPS,
    EGO_ACTOR_ID,
    MAX_FPS,
    Telemetry,
    kind_of,
    telemetry_from_csv,
    telemetry_from_json,
    valid_fps,
)
from ads_rca.sources.log.reader import UNUSABLE, check_max_file_mb, decode_file
from ads_rca.sources.log.records import FieldReader, is_json_number, json_number

FORMAT_NAME = "carla_experiment_client"
RUN_METADATA = "run_metadata.json"
EVENTS = "events.json"
PLAN = "plan.json"
SCENARIO = "scenario.yaml"

#: Plan points per frame: the frame itself and the next PLAN_STEPS frames of the path.
PLAN_STEPS = 10
#: The run facts of ``run_metadata.json`` carried into the metadata (text bounded).
RUN_FACTS = ("scenario_id", "map", "seed", "server_version", "client_version", "duration")


def read_carla_run(
    path: str | os.PathLike[str],
    max_file_mb: float = DEFAULT_MAX_FILE_MB,
    derived_collision: bool = False,
) -> RunLog:
    """Load a CARLA experiment-client run folder (see the module docstring)."""
    root = Path(path)
    limit = check_max_file_mb(max_file_mb)
    if not root.is_dir():
        raise InputError(f"{root}: not a folder (a CARLA run is a folder)")
    problems = ProblemLog()
    facts = _json_object(root, RUN_METADATA, problems, limit)
    scenario = _scenario(root, problems)
    telemetry = _telemetry(root, problems, limit)
    fps = _frame_rate(facts, telemetry, problems)
    frame_ms = max(1, round(1000.0 / fps))
    if abs(1000.0 / fps - frame_ms) > 1e-9:
        problems.add(
            RUN_METADATA,
            "fps",
            f"{fps:g} fps is not a whole number of milliseconds a frame",
            f"{KEPT_VALUE}: frames numbered at {frame_ms} ms",
            "warning",
        )
    ticks = _ticks(telemetry, problems)
    _check_spacing([telemetry.stamps[i] for i in ticks], frame_ms, telemetry.file, problems)
    ego_blueprint = scenario.get("ego_vehicle")
    if not isinstance(ego_blueprint, str):
        if ego_blueprint is not None:
            problems.add(SCENARIO, "ego_vehicle", "not text", "class default used", "warning")
        ego_blueprint = ""
    ego_half, ego_known = blueprint_extent(ego_blueprint, "vehicle")
    ego_values = np.asarray([telemetry.ego[i] for i in ticks], dtype=np.float64).reshape(-1, 9)
    ego = EgoTrack(
        ego_values[:, 0:2],
        ego_values[:, 5],
        ego_values[:, 6],
        ego_values[:, 7:9],
        np.array(ego_half[:2]),
    )
    found = _actor_table(telemetry, ticks)
    rows = found.rows
    dt = 1.0 / fps
    figures = run_figures(ego, rows, dt, actors_recorded=telemetry.schema != "csv")
    hit = overlaps(ego, rows)
    collision_frame = -1
    if derived_collision and hit.any():
        first_tick = int(rows.tick[hit].min())
        collision_frame = round(telemetry.stamps[ticks[first_tick]] / frame_ms)

    stamps = [telemetry.stamps[i] for i in ticks]
    pose: dict[int, Record] = {}
    actors: dict[int, Record] = {}
    ego_extent = np.array(ego_half, dtype=np.float64)
    for n, ts in enumerate(stamps):
        x, y, z, roll, pitch, yaw, speed = (float(v) for v in ego_values[n, :7])
        pose[ts] = EgoPose(x, y, z, roll, pitch, yaw, speed)
        actors[ts] = found.at(n, ego_values[n], ego_extent)
    plan_file, waypoints = _plan(root, problems, limit, stamps, dt)
    annotations = _events(root, problems, limit)

    raw: dict[str, Any] = {
        "source_format": FORMAT_NAME,
        "telemetry_schema": telemetry.schema,
        "timesteps_per_frame": frame_ms,
        "collision_frame": collision_frame,
        "total_frames": (stamps[-1] // frame_ms + 1) if stamps else 0,
        "ego_blueprint": bounded(ego_blueprint, MAX_KIND),
        **_run_facts(facts),
        ANNOTATIONS_KEY: [a.to_dict() for a in annotations],
        FIGURES_KEY: {"basis": BASIS, **{k: _plain(v) for k, v in figures.items()}},
    }
    inputs = _capabilities(
        telemetry, ego_blueprint, ego_known, found.unknown, plan_file, derived_collision
    )
    raw[INPUTS_KEY] = {name: status.to_dict() for name, status in inputs.items()}
    metadata = RunMetadata(
        frame_ms, (0.0, 0.0, 0.0), collision_frame, int(raw["total_frames"]), raw
    )
    return RunLog.from_folders(
        metadata,
        tuple(stamps),
        {"pose": pose, "actors": actors, "waypoint": waypoints},
        problems=problems,
        source=str(root),
        inputs=inputs,
    )


# --- files -------------------------------------------------------------------------------


def _json_file(root: Path, name: str, problems: ProblemLog, limit: int) -> Any:
    """The document of ``root/name``; UNUSABLE (reported) when unreadable or invalid, and
    None when the file is not there."""
    path = root / name
    if not os.path.lexists(path):
        return None
    return decode_file(read_regular(path, limit), name, problems, None)


def _json_object(root: Path, name: str, problems: ProblemLog, limit: int) -> dict[str, Any]:
    document = _json_file(root, name, problems, limit)
    if document is None:
        problems.add(name, "", "missing", USED_DEFAULT, "warning")
        return {}
    if document is UNUSABLE:
        return {}
    if not isinstance(document, dict):
        problems.add(name, "", f"expected an object, found {kind_of(document)}", SKIPPED_FILE)
        return {}
    return document


def _scenario(root: Path, problems: ProblemLog) -> dict[str, Any]:
    """``scenario.yaml`` (only its ``ego_vehicle`` is used); {} when absent or unusable."""
    if not os.path.lexists(root / SCENARIO):
        return {}
    from ads_rca.foundation.yaml_files import load_yaml

    try:
        document = load_yaml(root / SCENARIO, SCENARIO)
    except ConfigError as error:
        problems.add(SCENARIO, "", str(error).split(": ", 1)[-1], SKIPPED_FILE)
        return {}
    if not isinstance(document, dict):
        problems.add(SCENARIO, "", f"expected a mapping, found {kind_of(document)}", SKIPPED_FILE)
        return {}
    return document


def _telemetry(root: Path, problems: ProblemLog, limit: int) -> Telemetry:
    """The JSON telemetry, else the CSV; InputError when neither gives a tick."""
    document = _json_file(root, TELEMETRY_JSON, problems, limit)
    if document is not None and document is not UNUSABLE:
        telemetry = telemetry_from_json(document, problems)
        if telemetry is not None and telemetry.stamps:
            return telemetry
    if os.path.lexists(root / TELEMETRY_CSV):
        data = read_regular(root / TELEMETRY_CSV, limit)
        if isinstance(data, bytes):
            telemetry = telemetry_from_csv(data, problems)
            if telemetry.stamps:
                if document is not None:
                    problems.add(TELEMETRY_JSON, "", "unusable", f"{TELEMETRY_CSV} read instead")
                return telemetry
        else:
            problems.add(TELEMETRY_CSV, "", data.issue, SKIPPED_FILE)
    if document is None and not os.path.lexists(root / TELEMETRY_CSV):
        raise InputError(f"{root}: no {TELEMETRY_JSON} or {TELEMETRY_CSV}")
    found = list(problems)
    why = f" ({found[-1].file}: {found[-1].field or 'file'}: {found[-1].issue})" if found else ""
    raise InputError(f"{root}: no usable tick in its telemetry{why}")


def _frame_rate(facts: Mapping[str, Any], telemetry: Telemetry, problems: ProblemLog) -> float:
    """``run_metadata.json`` fps, else the telemetry's, else 1 / fixed_delta_seconds, else
    the client's 20 fps (reported)."""
    reader = FieldReader(RUN_METADATA, problems, None, text_numbers_reported=True)
    if "fps" in facts:
        fps = reader.number(facts, "fps", "fps")
        if valid_fps(fps):
            return fps
        reader.report("fps", f"{fps!r} is not a frame rate (1 to {MAX_FPS:g})", IGNORED)
    if telemetry.fps is not None:
        return telemetry.fps
    if "fixed_delta_seconds" in facts:
        step = reader.number(facts, "fixed_delta_seconds", "fixed_delta_seconds")
        if step > 0 and valid_fps(1.0 / step):
            return 1.0 / step
    problems.add(
        RUN_METADATA, "fps", "no frame rate given", f"{USED_DEFAULT}: {DEFAULT_FPS:g}", "warning"
    )
    return DEFAULT_FPS


def _ticks(telemetry: Telemetry, problems: ProblemLog) -> list[int]:
    """Tick positions in time order, a repeated time kept once (the first; others reported)."""
    order = sorted(range(len(telemetry.stamps)), key=telemetry.stamps.__getitem__)
    if order != list(range(len(order))):
        problems.add(telemetry.file, "t_sim", "ticks not in time order", "sorted", "warning")
    kept: list[int] = []
    for i in order:
        if kept and telemetry.stamps[kept[-1]] == telemetry.stamps[i]:
            problems.add(
                telemetry.file,
                "t_sim",
                "time repeated",
                SKIPPED_FRAME,
                timestamp_ms=telemetry.stamps[i],
            )
            continue
        kept.append(i)
    return kept


def _check_spacing(stamps: Sequence[int], frame_ms: int, file: str, problems: ProblemLog) -> None:
    """Say so when the ticks' most common spacing is not the frame period the rate gives
    (frame numbers then do not count ticks)."""
    common = most_common_step(stamps)
    if common is not None and abs(common - frame_ms) > 1:
        problems.add(
            file,
            "t_sim",
            f"ticks are {common} ms apart, the frame rate gives {frame_ms} ms",
            f"{KEPT_VALUE}: frames numbered at {frame_ms} ms",
            "warning",
        )


# --- model ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class ActorTable:
    """The kept actors of the kept ticks: as figure rows (ticks renumbered to time order),
    location, rotation and extent per row, their ids, each tick's rows, and the blueprints
    the table does not know (sorted)."""

    rows: ActorRows
    table: FloatArray  # (K, 9)
    ids: list[str]
    per_tick: list[list[int]]
    unknown: list[str]

    def at(self, tick: int, ego: FloatArray, ego_extent: FloatArray) -> Actors:
        """One tick's actors: the ego first (so it is the actor matched to the pose), then
        the recorded vehicles and walkers in file order."""
        mine = self.per_tick[tick]
        table = np.vstack([np.concatenate([ego[0:6], ego_extent])[None, :], self.table[mine]])
        ids = (EGO_ACTOR_ID, *(self.ids[r] for r in mine))
        return Actors(ids, table[:, 0:3].copy(), table[:, 3:6].copy(), table[:, 6:9].copy())


def _actor_table(telemetry: Telemetry, ticks: Sequence[int]) -> ActorTable:
    position = {tick: n for n, tick in enumerate(ticks)}
    keep = [r for r, tick in enumerate(telemetry.actor_tick) if tick in position]
    tick = np.array([position[telemetry.actor_tick[r]] for r in keep], dtype=np.int64)
    numbers: dict[str, int] = {}
    actor = np.array(
        [numbers.setdefault(telemetry.actor_id[r], len(numbers)) for r in keep], dtype=np.int64
    )
    values = np.asarray([telemetry.actor_values[r] for r in keep], dtype=np.float64).reshape(-1, 7)
    extents = [blueprint_extent(telemetry.actor_type[r], telemetry.actor_kind[r]) for r in keep]
    half = np.asarray([e for e, _ in extents], dtype=np.float64).reshape(-1, 3)
    unknown = {
        telemetry.actor_type[r] or f"(no type_id, {telemetry.actor_kind[r]})"
        for r, (_, known) in zip(keep, extents, strict=True)
        if not known
    }
    rows = ActorRows(
        tick,
        actor,
        values[:, 0:2],
        values[:, 5],
        half[:, 0:2],
        values[:, 6],
        np.array([telemetry.actor_kind[r] == "vehicle" for r in keep], dtype=bool),
    )
    per_tick: list[list[int]] = [[] for _ in ticks]
    for row, t in enumerate(tick.tolist()):
        per_tick[t].append(row)
    table = np.concatenate([values[:, 0:6], half], axis=1)
    return ActorTable(rows, table, [telemetry.actor_id[r] for r in keep], per_tick, sorted(unknown))


def _plan(
    root: Path, problems: ProblemLog, limit: int, stamps: Sequence[int], dt: float
) -> tuple[str | None, dict[int, Record]]:
    """The ego's reference path of ``plan.json`` as a plan at each frame it covers."""
    document = _json_file(root, PLAN, problems, limit)
    if document is None or document is UNUSABLE:
        return None, {}
    if not isinstance(document, dict) or not isinstance(document.get("actors"), list):
        problems.add(PLAN, "actors", "expected an object with an actors list", SKIPPED_FILE)
        return None, {}
    egos = [
        (n, a)
        for n, a in enumerate(document["actors"])
        if isinstance(a, dict) and (a.get("role") in ("ego", "hero") or a.get("id") == "ego")
    ]
    if not egos:
        problems.add(PLAN, "actors", "no actor with role ego", SKIPPED_FILE)
        return None, {}
    n, ego = egos[0]
    points = ego.get("trajectory")
    where = f"actors[{n}].trajectory"
    if not isinstance(points, list):
        problems.add(PLAN, where, f"expected a list, found {kind_of(points)}", SKIPPED_FILE)
        return None, {}
    reader = FieldReader(PLAN, problems, None, text_numbers_reported=True)
    table = np.array(
        [
            [reader.number(p, k, f"{where}[{m}].{k}") for k in ("t", "x", "y", "v")]
            if isinstance(p, dict)
            else [math.nan] * 4
            for m, p in enumerate(points)
        ],
        dtype=np.float64,
    ).reshape(-1, 4)
    usable = np.isfinite(table).all(axis=1)
    if not usable.all():
        problems.add(
            PLAN, where, f"{int((~usable).sum())} points without finite t, x, y, v", DROPPED_RECORD
        )
    table = table[usable]
    table = table[np.argsort(table[:, 0], kind="stable")]
    if len(table) < 2 or table[-1, 0] <= table[0, 0]:
        problems.add(PLAN, where, "fewer than two timed points", SKIPPED_FILE)
        return None, {}
    times = np.asarray(stamps, dtype=np.float64)[:, None] / 1000.0 + dt * np.arange(PLAN_STEPS + 1)
    inside = (times >= table[0, 0]) & (times <= table[-1, 0])
    x = np.interp(times, table[:, 0], table[:, 1])
    y = np.interp(times, table[:, 0], table[:, 2])
    v = np.interp(times, table[:, 0], table[:, 3])
    # a plan is the frame's point and the following ones while the path lasts
    lengths = np.where(
        inside[:, 0], np.argmin(np.c_[inside, np.zeros(len(inside), bool)], axis=1), 0
    )
    keys = tuple(str(i) for i in range(PLAN_STEPS + 1))
    plans: dict[int, Record] = {}
    for row in np.flatnonzero(lengths).tolist():
        count = int(lengths[row])
        xy = np.stack([x[row, :count], y[row, :count]], axis=1)
        plans[stamps[row]] = Plan(keys[:count], xy, v[row, :count].copy())
    return PLAN, plans


def _events(root: Path, problems: ProblemLog, limit: int) -> list[Annotation]:
    """``events.json``'s events as annotations (time ``t_event``, else ``t``)."""
    document = _json_file(root, EVENTS, problems, limit)
    if document is None or document is UNUSABLE:
        return []
    listed = document.get("events") if isinstance(document, dict) else None
    if not isinstance(listed, list):
        problems.add(EVENTS, "events", "expected an object with an events list", SKIPPED_FILE)
        return []
    if len(listed) > MAX_ANNOTATIONS:
        problems.add(EVENTS, "events", f"more than {MAX_ANNOTATIONS} events", "the first kept")
    reader = FieldReader(EVENTS, problems, None, text_numbers_reported=True)
    out: list[Annotation] = []
    for n, event in enumerate(listed[:MAX_ANNOTATIONS]):
        where = f"events[{n}]"
        if not isinstance(event, dict):
            reader.report(where, f"expected an object, found {kind_of(event)}", DROPPED_RECORD)
            continue
        key = "t_event" if "t_event" in event else "t"
        seconds = reader.number(event, key, f"{where}.{key}")
        if not (math.isfinite(seconds) and 0.0 <= seconds * 1000.0 <= MAX_TIMESTAMP_MS):
            reader.report(f"{where}.{key}", "not a time inside the log's range", DROPPED_RECORD)
            continue
        texts = [event.get(k, "") for k in ("type", "decision_text", "reason_text")]
        if not all(isinstance(t, str) for t in texts):
            reader.report(
                where, "type, decision_text and reason_text must be text", "read as empty"
            )
            texts = [t if isinstance(t, str) else "" for t in texts]
        kind, decision, reason = texts
        text = " — ".join(t for t in (decision, reason) if t)
        out.append(
            Annotation(round(seconds * 1000.0), bounded(kind or "event", MAX_KIND), text, EVENTS)
        )
    return sorted(out, key=lambda a: a.timestamp_ms)


def _run_facts(facts: Mapping[str, Any]) -> dict[str, Any]:
    """The run facts of ``run_metadata.json`` (text bounded; other values left out)."""
    out: dict[str, Any] = {}
    for key in RUN_FACTS:
        value = facts.get(key)
        if isinstance(value, str):
            out[key] = bounded(value, MAX_KIND)
        elif is_json_number(value) and math.isfinite(json_number(value)):  # 10**400 is not
            out[key] = value
    return out


def _capabilities(
    telemetry: Telemetry,
    ego_blueprint: str,
    ego_known: bool,
    unknown: Sequence[str],
    plan_file: str | None,
    derived_collision: bool,
) -> dict[str, InputStatus]:
    """Every model input of this run: real, derived, assumed or absent, and why."""
    ego_extent = (
        f"its extent from blueprint {ego_blueprint}"
        if ego_known
        else f"its extent the vehicle class default ({ego_blueprint or 'no ego_vehicle'})"
    )
    if telemetry.schema == "csv":
        actors = InputStatus(
            "derived", TELEMETRY_CSV, f"the ego only ({ego_extent}): the CSV holds no other actor"
        )
    else:
        unknown_text = f"; class default for {', '.join(unknown[:5])}" if unknown else ""
        others = sorted(telemetry.other_kinds.items())
        skipped = f"; not actors: {', '.join(f'{k} ({n})' for k, n in others)}" if others else ""
        actors = InputStatus(
            "assumed",
            telemetry.file,
            "positions recorded; half extents assumed from the CARLA 0.9.15 blueprint table"
            f"{unknown_text}; the ego added at its pose, {ego_extent}{skipped}",
        )
    collision = (
        InputStatus(
            "derived",
            telemetry.file,
            "first tick where the ego's box overlaps another's (assumed extents)",
        )
        if derived_collision
        else InputStatus(
            "absent", "", "the run records no collision; events.json times are annotations"
        )
    )
    plan = (
        InputStatus(
            "derived",
            plan_file,
            "the ego's scripted reference path, resampled per frame (not a planner's "
            "output): it enables the control-tracking check only",
        )
        if plan_file
        else InputStatus("absent", "", "no plan.json")
    )
    given = {
        "ego": InputStatus("real", telemetry.file, ""),
        "actors": actors,
        "plan": plan,
        "control": InputStatus("absent", "", "pedal and steering inputs only, no commanded speed"),
        "collision": collision,
        "clock": InputStatus("absent", "", "a run folder has no clock topic"),
    }
    return source_statuses(given, "the CARLA experiment client records no")


def _plain(value: float | int) -> float | int | None:
    """A figure for JSON: NaN (no such figure in this run) as null."""
    return None if isinstance(value, float) and not math.isfinite(value) else value
