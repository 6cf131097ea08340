"""Reader for Dragon Lake Parking (DLP) scenes: ``DJI_XXXX_{scene,frames,agents,
instances,obstacles}.json``.

A drone's view of a parking lot: every moving agent's trajectory and the parked cars, no ADS
and no crash (docs/formats.md "Dragon Lake Parking scenes" has the whole mapping):

- frames: DLP's linked list from the scene's ``first_frame`` through ``next``, at
  ``round(1000 · timestamp)`` ms; a broken link or a cycle ends it (reported);
- the ego: DLP has none, so one agent stands in: ``ego_agent`` (a token, or a number in
  token order), else the longest-lived moving car (said in the metadata and the capability
  record); the analysed frames are the ego's lifetime;
- actors: every agent's instance in the frame and every obstacle (static), numbered 1…
  in token order (agents, then obstacles; the tokens kept in the metadata); half extents
  from the full sizes, heights assumed per class; the ego's speed is signed (negative when
  reversing: its heading against its motion, the DLP API's rule);
- DLP's local frame is right-handed: positions and headings are mirrored into the model's
  (y' = −y, yaw' = −degrees(heading));
- no collision, unless ``derived_collision`` asks for the first overlap of the ego's box with
  another's (flagged derived).

The instances file is huge (a scene holds over a million instances): it and the frames file
are streamed (:mod:`.json_stream`), each instance kept as a few numbers in typed arrays, so
memory holds the model, not the JSON. Bad input is reported as the running-log reader does;
problems of instances are counted per kind (one line each, not one per instance).
"""

from __future__ import annotations

import math
import os
from array import array
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from ads_rca.capabilities import source_statuses
from ads_rca.errors import InputError
from ads_rca.foundation.files import DEFAULT_MAX_FILE_MB, Unreadable, open_regular, read_regular
from ads_rca.foundation.geometry import FloatArray
from ads_rca.model import (
    INPUTS_KEY,
    MAX_TIMESTAMP_MS,
    Actors,
    EgoPose,
    InputStatus,
    Record,
    RunLog,
    RunMetadata,
    most_common_step,
)
from ads_rca.problems import (
    DROPPED_RECORD,
    IGNORED,
    SKIPPED_FILE,
    SKIPPED_FRAME,
    USED_DEFAULT,
    ProblemLog,
)
from ads_rca.sources.carla.figures import ActorRows, EgoTrack, overlaps
from ads_rca.sources.dlp import SCENE_SUFFIX
from ads_rca.sources.errors import InvalidJson
from ads_rca.sources.formats import SourceOptions
from ads_rca.sources.json_stream import object_members
from ads_rca.sources.log.reader import UNUSABLE, check_max_file_mb, decode_file
from ads_rca.sources.log.records import json_number
from ads_rca.sources.predictor.scores import ACTOR_TYPES_KEY

FORMAT_NAME = "dlp"
PARTS = ("scene", "frames", "agents", "instances", "obstacles")
#: DLP's frame period (25 fps) when the timestamps do not give one.
DEFAULT_TPF = 40
#: Half heights (m) per class: DLP gives lengths and widths only.
HALF_HEIGHTS: Mapping[str, float] = {
    "car": 0.75,
    "bus": 1.5,
    "truck": 1.5,
    "bicycle": 0.9,
    "pedestrian": 0.9,
}
DEFAULT_HALF_HEIGHT = 0.75
#: Full sizes (m) for an agent whose size is unusable.
DEFAULT_SIZES: Mapping[str, tuple[float, float]] = {"pedestrian": (0.83, 0.83)}
DEFAULT_SIZE = (4.6, 1.9)
MAX_TEXT = 64
#: The most (ego tick, obstacle) pairs the derived collision check holds at once.
OVERLAP_BLOCK = 1_000_000
SOURCE_FRAME = (
    "DLP local frame (right-handed, metres) mirrored into the model's: y' = -y, "
    "yaw' = -degrees(heading)"
)


def scene_files(path: str | os.PathLike[str]) -> dict[str, Path]:
    """The five files of the scene at ``path`` (its ``_scene.json``, or a folder holding
    exactly one); InputError when there is no such scene or the folder holds several."""
    given = Path(path)
    if given.is_dir():
        scenes = sorted(n for n in os.listdir(given) if n.endswith(SCENE_SUFFIX))
        if len(scenes) != 1:
            raise InputError(
                f"{given}: {len(scenes)} DLP scenes (*{SCENE_SUFFIX}) here: give one scene file"
            )
        given = given / scenes[0]
    if not given.name.endswith(SCENE_SUFFIX):
        raise InputError(f"{given}: not a DLP scene file (*{SCENE_SUFFIX})")
    stem = given.name[: -len(SCENE_SUFFIX)]
    return {part: given.with_name(f"{stem}_{part}.json") for part in PARTS}


@dataclass
class Agents:
    """The scene's agents (moving) then obstacles (static), one row each, in id order."""

    tokens: list[str] = field(default_factory=list)
    kinds: list[str] = field(default_factory=list)
    half: list[tuple[float, float, float]] = field(default_factory=list)
    moving: int = 0  # rows [0, moving) are agents, the rest obstacles
    obstacle_pose: list[tuple[float, float, float]] = field(default_factory=list)  # x y yaw

    def index(self) -> dict[str, int]:
        return {t: n for n, t in enumerate(self.tokens[: self.moving])}


@dataclass
class Instances:
    """Every usable instance, columnar: frame position, agent row, x, y, heading, speed."""

    frame: array[int] = field(default_factory=lambda: array("l"))
    agent: array[int] = field(default_factory=lambda: array("l"))
    values: array[float] = field(default_factory=lambda: array("d"))  # x y heading speed
    dropped: Counter[tuple[str, str]] = field(default_factory=Counter)

    def drop(self, field_name: str, issue: str) -> None:
        self.dropped[(field_name, issue)] += 1


def read_dlp_scene(
    path: str | os.PathLike[str],
    max_file_mb: float = DEFAULT_MAX_FILE_MB,
    source: SourceOptions | None = None,
) -> RunLog:
    """Load one DLP scene (see the module docstring)."""
    source = source or SourceOptions()
    limit = check_max_file_mb(max_file_mb)
    files = scene_files(path)
    problems = ProblemLog()
    names = {part: file.name for part, file in files.items()}
    scene = _whole(files["scene"], names["scene"], problems, limit)
    if not isinstance(scene, dict):
        raise InputError(f"{files['scene']}: not a usable DLP scene file ({_last(problems)})")
    agents = _agents(files, names, problems, limit)
    frame_order, stamps = _frame_list(files["frames"], names["frames"], scene, problems, limit)
    instances = _instances(
        files["instances"], names["instances"], frame_order, agents, limit, problems
    )
    for (field_name, issue), count in sorted(instances.dropped.items()):
        problems.add(names["instances"], field_name, f"{count} instances: {issue}", DROPPED_RECORD)
    table = _table(instances)
    why = _why_unusable(
        agents,
        instances,
        [
            f"{p.field}: {p.issue}" if p.field else p.issue
            for p in problems
            if p.file == names["instances"]
        ],
    )
    ego, chosen_by = _choose_ego(agents, table, source.ego_agent, files["instances"], why)
    return _run_log(files, names, scene, agents, stamps, table, ego, chosen_by, source, problems)


# --- files ---------------------------------------------------------------------------------


def _whole(path: Path, name: str, problems: ProblemLog, limit: int) -> Any:
    """A small file decoded whole; UNUSABLE (reported) when missing or unusable."""
    if not os.path.lexists(path):
        problems.add(name, "", "missing", SKIPPED_FILE)
        return UNUSABLE
    return decode_file(read_regular(path, limit), name, problems, None)


def _streamed(path: Path, name: str, problems: ProblemLog, limit: int) -> Any:
    """The members of a big file, streamed; what came before a defect is kept (reported)."""
    if not os.path.lexists(path):
        raise InputError(f"{path}: missing (a DLP scene needs all five files)")
    stream = open_regular(path)
    if isinstance(stream, Unreadable):
        raise InputError(f"{path}: {stream.issue}")
    count = 0
    with stream:
        try:
            for key, value in object_members(stream, limit):
                count += 1
                yield key, value
        except InvalidJson as error:
            problems.add(name, "", f"invalid JSON ({error}): the first {count} kept", SKIPPED_FILE)


def _last(problems: ProblemLog) -> str:
    found = list(problems)
    return f"{found[-1].issue}" if found else "not an object"


def _text(value: object, default: str) -> str:
    return value[:MAX_TEXT] if isinstance(value, str) and value.isprintable() else default


def _agents(
    files: Mapping[str, Path], names: Mapping[str, str], problems: ProblemLog, limit: int
) -> Agents:
    """Agents (token order) then obstacles (token order); bad entries reported."""
    out = Agents()
    listed = _whole(files["agents"], names["agents"], problems, limit)
    if not isinstance(listed, dict):
        raise InputError(f"{files['agents']}: not a usable DLP agents file ({_last(problems)})")
    for tok in sorted(listed):
        entry = listed[tok]
        where = _text(tok, "?")
        if not isinstance(entry, dict) or len(tok) > MAX_TEXT or not tok.isprintable():
            problems.add(
                names["agents"], where, "not an agent (an object keyed by a token)", DROPPED_RECORD
            )
            continue
        kind = _text(entry.get("type"), "Undefined")
        out.tokens.append(tok)
        out.kinds.append(kind)
        out.half.append(_half(entry.get("size"), kind, names["agents"], f"{where}.size", problems))
    out.moving = len(out.tokens)
    obstacles = _whole(files["obstacles"], names["obstacles"], problems, limit)
    if obstacles is UNUSABLE:
        return out
    if not isinstance(obstacles, dict):
        problems.add(names["obstacles"], "", "expected an object", SKIPPED_FILE)
        return out
    for tok in sorted(obstacles):
        entry = obstacles[tok]
        where = _text(tok, "?")
        coords = entry.get("coords") if isinstance(entry, dict) else None
        xy = (
            [json_number(v) for v in coords]
            if isinstance(coords, list) and len(coords) == 2
            else []
        )
        heading = json_number(entry.get("heading")) if isinstance(entry, dict) else math.nan
        if len(tok) > MAX_TEXT or len(xy) != 2 or not _finite_pose(xy, heading):
            problems.add(names["obstacles"], where, "no finite coords and heading", DROPPED_RECORD)
            continue
        kind = _text(entry.get("type"), "Undefined")
        out.tokens.append(tok)
        out.kinds.append(kind)
        out.half.append(
            _half(entry.get("size"), kind, names["obstacles"], f"{where}.size", problems)
        )
        out.obstacle_pose.append((xy[0], 0.0 - xy[1], 0.0 - math.degrees(heading)))
    return out


def _finite_pose(xy: list[float], heading: float) -> bool:
    """Finite coordinates, and a heading whose degrees are finite too (1e308 rad is not)."""
    return all(map(math.isfinite, [*xy, math.degrees(heading)]))


def _half(
    size: object, kind: str, file: str, where: str, problems: ProblemLog
) -> tuple[float, float, float]:
    """Half extents from DLP's full [length, width]; the class's height assumed."""
    height = HALF_HEIGHTS.get(kind.lower(), DEFAULT_HALF_HEIGHT)
    values = [json_number(v) for v in size] if isinstance(size, list) and len(size) == 2 else []
    if len(values) != 2 or not all(math.isfinite(v) and v > 0 for v in values):
        full = DEFAULT_SIZES.get(kind.lower(), DEFAULT_SIZE)
        problems.add(
            file,
            where,
            "not a [length, width] of positive numbers",
            f"{USED_DEFAULT}: {full[0]:g} x {full[1]:g} m",
        )
        values = list(full)
    return values[0] / 2.0, values[1] / 2.0, height


def _frame_list(
    path: Path, name: str, scene: Mapping[str, Any], problems: ProblemLog, limit: int
) -> tuple[dict[str, int], list[int]]:
    """Each listed frame's position on the list from ``first_frame``, and its time (ms)."""
    frames: dict[str, tuple[float, str]] = {}
    bad = 0
    for tok, entry in _streamed(path, name, problems, limit):
        if not isinstance(entry, dict) or not isinstance(entry.get("next", ""), str):
            bad += 1
            continue
        frames[tok] = (json_number(entry.get("timestamp")), entry.get("next", ""))
    if bad:
        problems.add(name, "", f"{bad} frames are not objects with a next token", DROPPED_RECORD)
    current = scene.get("first_frame")
    if not isinstance(current, str) or current not in frames:
        raise InputError(f"{path}: no frame is the scene's first_frame")
    order: dict[str, int] = {}
    stamps: list[int] = []
    visited: set[str] = set()
    untimed: list[tuple[str, float]] = []
    while current:
        if current in visited:
            problems.add(
                name, _text(current, "?"), "the next links make a cycle", "the list ends here"
            )
            break
        entry = frames.get(current)
        if entry is None:
            problems.add(
                name, _text(current, "?"), "a next link names no frame", "the list ends here"
            )
            break
        seconds, following = entry
        visited.add(current)
        ms = seconds * 1000.0  # 1e308 s is finite, its milliseconds are not
        stamp = round(ms) if math.isfinite(ms) else None
        if stamp is None or not 0 <= stamp <= MAX_TIMESTAMP_MS or (stamps and stamp <= stamps[-1]):
            untimed.append((current, seconds))
        else:
            order[current] = len(stamps)
            stamps.append(stamp)
        current = following
    if untimed:  # one line, however many: a file of text timestamps has one per frame
        first, value = untimed[0]
        problems.add(
            name,
            "timestamp",
            f"{len(untimed)} frames have no time after the previous frame's (the first: "
            f"{_text(first, '?')} at {value!r} s)",
            SKIPPED_FRAME,
        )
    off_list = len(frames) - len(visited)
    if off_list > 0:
        problems.add(
            name, "", f"{off_list} frames are not on the list from first_frame", IGNORED, "warning"
        )
    return order, stamps


def _instances(
    path: Path,
    name: str,
    frame_order: Mapping[str, int],
    agents: Agents,
    limit: int,
    problems: ProblemLog,
) -> Instances:
    out = Instances()
    index = agents.index()
    for _, entry in _streamed(path, name, problems, limit):
        if not isinstance(entry, dict):
            out.drop("", "not an object")
            continue
        frame_token, agent_token = entry.get("frame_token"), entry.get("agent_token")
        frame = frame_order.get(frame_token) if isinstance(frame_token, str) else None
        agent = index.get(agent_token) if isinstance(agent_token, str) else None
        if frame is None:
            out.drop("frame_token", "no frame on the list")
            continue
        if agent is None:
            out.drop("agent_token", "no agent of the agents file")
            continue
        coords = entry.get("coords")
        xy = (
            [json_number(v) for v in coords]
            if isinstance(coords, list) and len(coords) == 2
            else []
        )
        heading, speed = json_number(entry.get("heading")), json_number(entry.get("speed"))
        if len(xy) != 2 or not _finite_pose(xy, heading):
            out.drop("coords, heading", "not finite numbers")
            continue
        out.frame.append(frame)
        out.agent.append(agent)
        out.values.extend((xy[0], xy[1], heading, speed))
    return out


# --- the model -------------------------------------------------------------------------------


@dataclass(frozen=True)
class Table:
    """The instances sorted by (frame, agent), one of each pair, as arrays."""

    frame: npt.NDArray[np.int64]
    agent: npt.NDArray[np.int64]
    xy: FloatArray  # DLP frame (right-handed)
    heading: FloatArray  # radians, DLP frame
    speed: FloatArray
    duplicates: int


def _table(instances: Instances) -> Table:
    frame = np.frombuffer(instances.frame, dtype=np.int_).astype(np.int64)
    agent = np.frombuffer(instances.agent, dtype=np.int_).astype(np.int64)
    values = np.frombuffer(instances.values, dtype=np.float64).reshape(-1, 4)
    order = np.lexsort((agent, frame))
    frame, agent, values = frame[order], agent[order], values[order]
    first = np.ones(len(frame), dtype=bool)
    first[1:] = (frame[1:] != frame[:-1]) | (agent[1:] != agent[:-1])
    return Table(
        frame[first],
        agent[first],
        values[first, 0:2],
        values[first, 2],
        values[first, 3],
        int((~first).sum()),
    )


def _why_unusable(agents: Agents, instances: Instances, issues: list[str]) -> str:
    """Why the instances file left an agent without a usable instance, briefly: for the
    one line naming it (issue 43: "no agent has a usable instance" said neither)."""
    if not agents.moving:
        return "the agents file lists no agent"
    read = len(instances.agent) + sum(instances.dropped.values())
    if not read and not issues:
        return "the file lists no instance"
    kept = f"{len(instances.agent)} of its {read} instances usable"
    return "; ".join([kept, *issues[:3]]) + ("; ..." if len(issues) > 3 else "")


def _choose_ego(
    agents: Agents, table: Table, wanted: str, instances: Path, why: str = ""
) -> tuple[int, str]:
    """The ego's agent row and how it was chosen (``instances``: the file named, with
    ``why``, when the agent wanted or every agent has no usable instance)."""
    lives = np.bincount(table.agent, minlength=agents.moving)
    if wanted:
        if wanted in agents.tokens[: agents.moving]:
            row = agents.tokens.index(wanted)
        elif wanted.isdigit() and 1 <= int(wanted) <= agents.moving:
            row = int(wanted) - 1
        else:
            raise InputError(
                f"ego_agent {wanted}: no such agent (a token of the agents file, or a number "
                f"1 to {agents.moving} in token order)"
            )
        if lives[row] == 0:
            raise InputError(
                f"{instances}: ego_agent {wanted}: agent {agents.tokens[row]} has no usable "
                f"instance ({why})"
            )
        return row, "ego_agent"
    cars = [n for n in range(agents.moving) if agents.kinds[n].lower() == "car" and lives[n] > 0]
    candidates = cars or [n for n in range(agents.moving) if lives[n] > 0]
    if not candidates:
        raise InputError(
            f"{instances}: no agent has a usable instance in the scene, so nothing can be the "
            f"ego ({why})"
        )
    row = max(candidates, key=lambda n: (lives[n], -n))
    rule = "the longest-lived moving car" if cars else "the longest-lived agent (no car moves)"
    return row, f"default: {rule}"


def _signed_speed(xy: FloatArray, heading: FloatArray, speed: FloatArray) -> FloatArray:
    """DLP's speeds signed by the API's rule (``Dataset.states_from_utm``): negated where
    the heading points against the motion from the previous to the next instance (the
    first and last use themselves), however small that motion: a parked car whose position
    jitters by millimetres backwards reads negative there, as in the API; exactly no motion
    keeps the sign. Negated, not made negative: the API multiplies the file's speed by -1."""
    if len(xy) < 2:
        return speed.copy()
    ahead = np.vstack([xy[1:], xy[-1:]])
    behind = np.vstack([xy[:1], xy[:-1]])
    motion = ahead - behind
    along = motion[:, 0] * np.cos(heading) + motion[:, 1] * np.sin(heading)
    out: FloatArray = np.where(along < 0, -speed, speed)
    return out


def _run_log(
    files: Mapping[str, Path],
    names: Mapping[str, str],
    scene: Mapping[str, Any],
    agents: Agents,
    stamps: list[int],
    table: Table,
    ego: int,
    chosen_by: str,
    source: SourceOptions,
    problems: ProblemLog,
) -> RunLog:
    if table.duplicates:
        problems.add(
            names["instances"],
            "",
            f"{table.duplicates} instances repeat an agent's frame",
            "the first kept",
        )
    frame_ms = most_common_step(stamps) or DEFAULT_TPF  # the list's times only increase
    mine = table.agent == ego
    ego_frames = table.frame[mine]
    lifetime = int(ego_frames[-1] - ego_frames[0] + 1)
    if len(ego_frames) < lifetime:
        problems.add(
            names["instances"],
            "",
            f"the ego has no instance in {lifetime - len(ego_frames)} frames of its lifetime",
            "those frames skipped",
        )
    ego_xy = mirrored(table.xy[mine])
    ego_yaw = 0.0 - np.degrees(table.heading[mine])  # 0 - x: no -0.0
    ego_speed = _signed_speed(table.xy[mine], table.heading[mine], table.speed[mine])
    half = np.asarray(agents.half, dtype=np.float64).reshape(-1, 3)
    ids = [str(n + 1) for n in range(len(agents.tokens))]
    obstacle_rows = np.arange(agents.moving, len(agents.tokens))
    obstacles = np.asarray(agents.obstacle_pose, dtype=np.float64).reshape(-1, 3)
    bounds = (
        np.searchsorted(table.frame, ego_frames),
        np.searchsorted(table.frame, ego_frames, "right"),
    )
    pose: dict[int, Record] = {}
    actors: dict[int, Record] = {}
    for n, frame in enumerate(ego_frames.tolist()):
        stamp = stamps[frame]
        pose[stamp] = EgoPose(
            float(ego_xy[n, 0]),
            float(ego_xy[n, 1]),
            0.0,
            0.0,
            0.0,
            float(ego_yaw[n]),
            float(ego_speed[n]),
        )
        rows = np.arange(bounds[0][n], bounds[1][n])
        rows = np.concatenate([rows[table.agent[rows] == ego], rows[table.agent[rows] != ego]])
        who = np.concatenate([table.agent[rows], obstacle_rows])
        location = np.zeros((len(who), 3))
        location[: len(rows), 0:2] = mirrored(table.xy[rows])
        location[len(rows) :, 0:2] = obstacles[:, 0:2]
        rotation = np.zeros((len(who), 3))
        rotation[: len(rows), 2] = 0.0 - np.degrees(table.heading[rows])
        rotation[len(rows) :, 2] = obstacles[:, 2]
        actors[stamp] = Actors(tuple(ids[w] for w in who.tolist()), location, rotation, half[who])
    collision_frame = -1
    if source.derived_collision:
        collision_frame = _first_overlap(
            table, ego, ego_frames, ego_xy, ego_yaw, half, obstacles, agents, stamps, frame_ms
        )
    frames = tuple(stamps[f] for f in ego_frames.tolist())
    raw: dict[str, Any] = {
        "source_format": FORMAT_NAME,
        "timesteps_per_frame": frame_ms,
        "collision_frame": collision_frame,
        "total_frames": (frames[-1] // frame_ms + 1) if frames else 0,
        "scene": {
            "filename": _text(scene.get("filename"), ""),
            "timestamp": _text(scene.get("timestamp"), ""),
            "frames": len(stamps),
            "agents": agents.moving,
            "obstacles": len(agents.tokens) - agents.moving,
        },
        "source_frame": SOURCE_FRAME,
        "ego_agent": {
            "id": ids[ego],
            "token": agents.tokens[ego],
            "type": agents.kinds[ego],
            "frames": len(ego_frames),
            "chosen_by": chosen_by,
        },
        "actor_tokens": dict(zip(ids, agents.tokens, strict=True)),
        ACTOR_TYPES_KEY: dict(zip(ids, agents.kinds, strict=True)),
    }
    inputs = _capabilities(names, agents, ego, ids, chosen_by, source.derived_collision)
    raw[INPUTS_KEY] = {key: status.to_dict() for key, status in inputs.items()}
    metadata = RunMetadata(
        frame_ms, (0.0, 0.0, 0.0), collision_frame, int(raw["total_frames"]), raw
    )
    return RunLog.from_folders(
        metadata,
        frames,
        {"pose": pose, "actors": actors},
        problems=problems,
        source=str(files["scene"]),
        inputs=inputs,
    )


def mirrored(xy: FloatArray) -> FloatArray:
    """DLP's right-handed (x, y) as the model's left-handed (x, -y) (no -0.0)."""
    out: FloatArray = np.stack([xy[:, 0], 0.0 - xy[:, 1]], axis=1)
    return out


def _first_overlap(
    table: Table,
    ego: int,
    ego_frames: npt.NDArray[np.int64],
    ego_xy: FloatArray,
    ego_yaw: FloatArray,
    half: FloatArray,
    obstacles: FloatArray,
    agents: Agents,
    stamps: list[int],
    frame_ms: int,
) -> int:
    """The frame number where the ego's box first overlaps an agent's or an obstacle's."""
    tick_of = {f: n for n, f in enumerate(ego_frames.tolist())}
    others = np.flatnonzero((table.agent != ego) & np.isin(table.frame, ego_frames))
    ticks = np.array([tick_of[f] for f in table.frame[others].tolist()], dtype=np.int64)
    track = EgoTrack(
        ego_xy, ego_yaw, np.zeros(len(ego_xy)), np.zeros((len(ego_xy), 2)), half[ego, :2]
    )
    rows = ActorRows(
        ticks,
        table.agent[others],
        mirrored(table.xy[others]),
        -np.degrees(table.heading[others]),
        half[table.agent[others], :2],
        table.speed[others],
        np.ones(len(others), dtype=bool),
    )
    hits = ticks[overlaps(track, rows)].tolist()
    count = len(obstacles)
    step = max(1, OVERLAP_BLOCK // max(count, 1))  # ego ticks x obstacles, in bounded blocks
    for start in range(0, len(ego_xy) if count else 0, step):
        block = np.arange(start, min(len(ego_xy), start + step))
        tick = np.repeat(block, count)
        parked = ActorRows(
            tick,
            np.tile(np.arange(count), len(block)),
            np.tile(obstacles[:, 0:2], (len(block), 1)),
            np.tile(obstacles[:, 2], len(block)),
            np.tile(half[agents.moving :, 0:2], (len(block), 1)),
            np.zeros(len(tick)),
            np.ones(len(tick), dtype=bool),
        )
        hit = tick[overlaps(track, parked)]
        if hit.size:
            hits.append(int(hit.min()))
            break
    if not hits:
        return -1
    return round(stamps[int(ego_frames[min(hits)])] / frame_ms)


def _capabilities(
    names: Mapping[str, str],
    agents: Agents,
    ego: int,
    ids: list[str],
    chosen_by: str,
    derived_collision: bool,
) -> dict[str, InputStatus]:
    who = f"agent {ids[ego]} ({agents.kinds[ego]}, token {agents.tokens[ego][:12]}…)"
    ego_status = (
        InputStatus("real", names["instances"], f"{who}, chosen by ego_agent")
        if chosen_by == "ego_agent"
        else InputStatus(
            "assumed",
            names["instances"],
            f"DLP has no ego: {who} stands in ({chosen_by}; choose with ego_agent)",
        )
    )
    given = {
        "ego": ego_status,
        "actors": InputStatus(
            "real",
            names["instances"],
            "moving agents' instances and the parked obstacles (static), mirrored from DLP's "
            "right-handed frame; half extents from full sizes, heights assumed per class",
        ),
        "plan": InputStatus("absent", "", "the ego's future is its actual path, not a plan"),
        "collision": (
            InputStatus(
                "derived",
                names["instances"],
                "first overlap of the ego's box with "
                "another's (full sizes: tight parking may touch)",
            )
            if derived_collision
            else InputStatus("absent", "", "naturalistic data: no collision recorded")
        ),
        "clock": InputStatus("absent", "", "a scene has no clock topic"),
    }
    return source_statuses(given, "a DLP scene holds no")
