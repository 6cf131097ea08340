"""The in-memory form of one ADS run: metadata plus, per timestamp, what each module logged.

Pure data, no I/O. Per-frame records keep the file order of their entries (the reference
semantics iterate in file order) and hold numbers in numpy arrays so metric code can work on
whole frames at once. Geometry stays in the log's own frame: the CARLA world (left-handed,
metres, angles in degrees); conversions to ROS conventions live in ``ads_rca.contract``.

Timestamps are integer milliseconds. Frame ``f`` is ``f * timesteps_per_frame`` ms.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING, Any, TypedDict, cast

import numpy as np
import numpy.typing as npt

from ads_rca.foundation.text import short_repr
from ads_rca.problems import ProblemLog
from ads_rca.sources.atmacup.snapshots import EgoSnapshots
from ads_rca.sources.openlane.lanes import LaneGraph

if TYPE_CHECKING:
    from typing import Unpack  # Python 3.11; annotations only (the package runs on 3.10)

FloatArray = npt.NDArray[np.float64]

#: The per-frame folders of a running log, in the order the pipeline produces them.
FOLDERS = (
    "pose",
    "actors",
    "bboxes",
    "bboxes_gt",
    "predictions",
    "predictions_with_perception",
    "waypoint",
)

#: Optional per-frame folders, our extension of the seed format for what recordings of real
#: stacks carry (3-D detections, tracked objects, control commands) and for map perception
#: (an OpenLane-V2 segment's lane graphs, ground truth and predicted). A running log has
#: none: then nothing is read, written, sent or checked for them, and every output stays as
#: it was.
OPTIONAL_FOLDERS = ("detections_3d", "tracks_3d", "control", "lanes", "lanes_predicted")

#: Every per-frame folder, the optional ones last.
ALL_FOLDERS = FOLDERS + OPTIONAL_FOLDERS

#: The largest timestamp a log may give (file names, the frame period): the last
#: millisecond ROS time can carry (builtin_interfaces/Time's seconds are an int32, some
#: 68 years), so every frame read can be played and recorded; every one below is exact as a
#: float and fits the int64 arrays the checks use.
MAX_TIMESTAMP_MS = 2**31 * 1000 - 1
#: The largest frame number (either sign) or index a run may name: twice the
#: milliseconds ROS time can carry, so every frame past it is past every stamp of any log,
#: with any effect window before it, and a collision frame clamped to it judges as the
#: absurd one did; int64 columns hold it.
MAX_FRAME = 2**42


def bounded_int(value: Any, name: str, low: int, high: int) -> int:
    """``value`` when it is an integer in [low, high] (an integral float, as other JSON
    writers give, too); TypeError (not an integer) or ValueError (out of range) naming
    ``name`` else. For numbers a message or a recording states: past int64 one overflowed
    the aggregator's columns inside a callback, an absurd frame held a verdict forever, a
    zero frame period divided by 0."""
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if not isinstance(value, int) or isinstance(value, bool):
        raise TypeError(f"{name} is not an integer: {short_repr(value)}")
    if not low <= value <= high:
        sign = "-" if value < 0 else ""
        shown = value if abs(value) < 10**30 else f"{sign}2**{value.bit_length() - 1} or more"
        raise ValueError(f"{name} {shown} is outside [{low}, {high}]")
    return value


#: The :class:`RunLog` field holding each folder's records.
FOLDER_FIELDS = {folder: folder for folder in ALL_FOLDERS} | {
    "waypoint": "waypoints",
    "control": "controls",
}

#: The seed format's file-name prefix per folder (any prefix is accepted when reading).
FILE_PREFIX = {
    "pose": "pose",
    "actors": "actors",
    "bboxes": "bboxes",
    "bboxes_gt": "bboxes_gt",
    "predictions": "predictions",
    "predictions_with_perception": "predictions",
    "waypoint": "waypoints",
    "detections_3d": "detections_3d",
    "tracks_3d": "tracks_3d",
    "control": "control",
    "lanes": "lanes",
    "lanes_predicted": "lanes_predicted",
}


def frame_number(timestamp_ms: int, frame_ms: int) -> int | float:
    """Frame index of a timestamp: an int on the frame grid, else a float (the verdict's
    frames and the player's frame markers number frames with this one rule)."""
    return timestamp_ms // frame_ms if timestamp_ms % frame_ms == 0 else timestamp_ms / frame_ms


def most_common_step(stamps: Sequence[int]) -> int | None:
    """The most common difference between consecutive stamps (ascending, no repeats; the
    smallest on ties): a dataset's frame period. None for fewer than two stamps."""
    steps = np.diff(np.asarray(stamps, dtype=np.int64))
    if steps.size == 0:
        return None
    values, counts = np.unique(steps, return_counts=True)
    return int(values[np.argmax(counts)])


@dataclass(frozen=True, slots=True)
class RunMetadata:
    """``metadata.json``: frame period, camera mounting, collision frame, length."""

    timesteps_per_frame: int
    camera_loc: tuple[float, float, float]
    collision_frame: int
    total_frames: int
    #: The file's content as read, so that writers reproduce keys we do not interpret.
    raw: Mapping[str, Any] = field(default_factory=dict, compare=False)
    #: The source gave a usable collision frame (-1 included: known to be none); False when
    #: it gave none and -1 stands in for it: the collision is unknown (docs/verdicts.md).
    collision_known: bool = True

    @property
    def has_collision(self) -> bool:
        return self.collision_frame >= 0

    @property
    def end_ms(self) -> int:
        """``total_frames * frame_ms``: the last timestamp the reference looks ahead to."""
        return self.total_frames * self.timesteps_per_frame

    def to_dict(self) -> dict[str, Any]:
        """The metadata as a ``metadata.json`` document (unknown keys preserved)."""
        out = dict(self.raw)
        out["timesteps_per_frame"] = self.timesteps_per_frame
        ego_config = dict(out.get("ego_config") or {})
        camera = dict(ego_config.get("camera") or {})
        camera["camera_loc"] = list(self.camera_loc)
        ego_config["camera"] = camera
        out["ego_config"] = ego_config
        if self.collision_known:
            out["collision_frame"] = self.collision_frame
        else:  # written as the source gave it: no collision frame, so read back unknown
            out.pop("collision_frame", None)
        out["total_frames"] = self.total_frames
        return out


@dataclass(frozen=True, slots=True)
class EgoPose:
    """One ``pose/`` file: the ego state (world metres, degrees, m/s)."""

    x: float
    y: float
    z: float
    roll: float
    pitch: float
    yaw: float
    speed: float

    @property
    def xy(self) -> FloatArray:
        return np.array([self.x, self.y])


@dataclass(frozen=True, eq=False)
class Actors:
    """One ``actors/`` file: every vehicle and pedestrian, ego included, in file order.

    ``extent`` holds HALF sizes as written in this file (NaN where missing);
    ``rotation`` columns are roll, pitch, yaw in degrees.
    """

    ids: tuple[str, ...]
    location: FloatArray  # (N, 3)
    rotation: FloatArray  # (N, 3) roll, pitch, yaw
    extent: FloatArray  # (N, 3) half sizes

    @cached_property
    def index(self) -> dict[str, int]:
        """Row of each id (the first row, should an id repeat)."""
        out: dict[str, int] = {}
        for row, actor_id in enumerate(self.ids):
            out.setdefault(actor_id, row)
        return out

    def __len__(self) -> int:
        return len(self.ids)


@dataclass(frozen=True, eq=False)
class Boxes:
    """One ``bboxes/`` or ``bboxes_gt/`` file: 2-D image boxes in file order.

    ``corners`` rows are (x1, y1, x2, y2) exactly as written (not normalised);
    ``extras`` keeps every other key of each record (label, score ...).
    """

    ids: tuple[str, ...]
    corners: FloatArray  # (N, 4)
    extras: tuple[Mapping[str, Any], ...]

    def __len__(self) -> int:
        return len(self.ids)


@dataclass(frozen=True, eq=False)
class Track:
    """One obstacle's predicted offsets: step keys (file order, as written) and (K, 3) offsets.

    Offsets are in the ego's body frame (x forward, y as CARLA). Keys stay strings because
    the reference matches them textually; :attr:`steps` gives their integer values.
    """

    keys: tuple[str, ...]
    offsets: FloatArray  # (K, 3)

    @classmethod
    def of(cls, keys: tuple[str, ...], offsets: FloatArray) -> Track:
        """The track ``cls(keys, offsets)`` makes, its fields put in its ``__dict__`` directly
        instead of by the frozen ``__init__``'s ``object.__setattr__`` per field: a large log
        rebuilds hundreds of thousands (0.23 against 0.37 us each)."""
        track = object.__new__(cls)
        fields = track.__dict__
        fields["keys"] = keys
        fields["offsets"] = offsets
        return track

    @cached_property
    def steps(self) -> npt.NDArray[np.int64]:
        """Integer value of each key; -1 where a key is not an integer."""
        return np.array([step_value(k) for k in self.keys], dtype=np.int64)

    def offset(self, key: str) -> FloatArray | None:
        """Offset for a key string (first occurrence), or None."""
        try:
            row: FloatArray = self.offsets[self.keys.index(key)]
        except ValueError:
            return None
        return row


#: ``predictions/`` or ``predictions_with_perception/`` file: obstacle id -> track, file order.
Predictions = dict[str, Track]


@dataclass(frozen=True, eq=False)
class Plan:
    """One ``waypoint/`` file: plan points in file order (key i = i frames ahead)."""

    keys: tuple[str, ...]
    xy: FloatArray  # (N, 2) world metres
    speed: FloatArray  # (N,) m/s

    @cached_property
    def index(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for row, key in enumerate(self.keys):
            out.setdefault(key, row)
        return out

    @cached_property
    def steps(self) -> npt.NDArray[np.int64]:
        """Integer value of each key; -1 where a key is not an integer."""
        return np.array([step_value(k) for k in self.keys], dtype=np.int64)

    def point(self, key: str) -> FloatArray | None:
        row = self.index.get(key)
        return None if row is None else self.xy[row]

    def __len__(self) -> int:
        return len(self.keys)


@dataclass(frozen=True, eq=False)
class Objects3D:
    """One frame of 3-D objects a stack perceived (detections or tracks), in the log's world
    frame like :class:`Actors` (CARLA: left-handed, metres, degrees).

    Real stacks detect in 3-D, not as image boxes; recordings of them carry these
    instead of ``bboxes/``. ``extent`` holds HALF sizes; ``velocity`` is world m/s (NaN where
    the message gives none); ``score`` is the existence probability or confidence (NaN where
    none); ``labels`` the class names as text (never trusted for output without escaping).
    Detections without ids of their own get ``d<row>``.
    """

    ids: tuple[str, ...]
    location: FloatArray  # (N, 3)
    yaw: FloatArray  # (N,) degrees
    extent: FloatArray  # (N, 3) half sizes
    velocity: FloatArray  # (N, 3)
    score: FloatArray  # (N,)
    labels: tuple[str, ...]

    def __len__(self) -> int:
        return len(self.ids)


@dataclass(frozen=True, slots=True)
class ControlCommand:
    """One control command of the stack (NaN where the message gives none): steering tire
    angle in degrees (CARLA sign: positive turns right), longitudinal acceleration m/s²,
    target speed m/s."""

    steer: float
    acceleration: float
    speed: float


@dataclass(frozen=True, slots=True)
class VehicleVelocity:
    """The vehicle's own velocity report (recordings of real stacks), in its axes: along
    them m/s (lateral CARLA-signed: positive right), heading rate degrees/s (CARLA-signed:
    positive turns right)."""

    longitudinal: float
    lateral: float
    heading_rate: float


#: The fail-safe states in which the stack is running a minimal risk manoeuvre or has ended
#: one (an emergency).
EMERGENCY_STATES = ("MRM_OPERATING", "MRM_SUCCEEDED", "MRM_FAILED")


@dataclass(frozen=True, slots=True)
class MrmState:
    """The stack's fail-safe state at one moment (Autoware's minimal risk manoeuvre, MRM):
    the message's time on the run's clock (ms, frame 0 at 0; it may fall between frames),
    its state (``NORMAL``, ``MRM_OPERATING``, ``MRM_SUCCEEDED``, ``MRM_FAILED``,
    ``UNKNOWN``) and behaviour (``NONE``, ``EMERGENCY_STOP``, ``COMFORTABLE_STOP``,
    ``PULL_OVER``, ``UNKNOWN``) by name."""

    timestamp_ms: int
    state: str
    behavior: str

    @property
    def emergency(self) -> bool:
        return self.state in EMERGENCY_STATES


#: What one per-frame file holds; which one is set by its folder (see :meth:`RunLog.folder`).
Record = EgoPose | Actors | Boxes | Predictions | Plan | Objects3D | ControlCommand | LaneGraph


class LogExtras(TypedDict, total=False):
    """The fields of a :class:`RunLog` besides metadata, frames and the per-folder dicts."""

    problems: ProblemLog
    source: str
    files: dict[str, dict[int, str]]
    first_extents: dict[str, FloatArray]
    detections_3d: dict[int, Objects3D]
    tracks_3d: dict[int, Objects3D]
    controls: dict[int, ControlCommand]
    inputs: dict[str, InputStatus]
    lanes: dict[int, LaneGraph]
    lanes_predicted: dict[int, LaneGraph]
    ego_snapshots: EgoSnapshots | None
    vehicle_velocity: dict[int, VehicleVelocity]
    mrm_states: tuple[MrmState, ...]


#: How a model input is present in a run: ``real`` (read from the source as is), ``derived``
#: (computed from other data: a speed from poses), ``assumed`` (a default stood in) or
#: ``absent``.
INPUT_STATES = ("real", "derived", "assumed", "absent")


@dataclass(frozen=True, slots=True)
class InputStatus:
    """One model input's presence in a run: its state, where it came from (a topic and type,
    a file) and, unless real, why."""

    state: str
    source: str = ""
    reason: str = ""

    def to_dict(self) -> dict[str, str]:
        return {"state": self.state, "source": self.source, "reason": self.reason}


#: Key of ``metadata.json`` (hence of ``run/metadata``) holding :attr:`RunLog.inputs`, so a
#: log folder written from a recording, or its replay, says where each input came from as
#: the recording did (absent for a running log, whose inputs are all real).
INPUTS_KEY = "model_inputs"


def read_inputs(
    document: Mapping[str, Any],
) -> tuple[dict[str, InputStatus], list[tuple[str, str]]]:
    """The inputs a metadata document lists under :data:`INPUTS_KEY`, and the (field, issue)
    of every entry that is not one (left out)."""
    listed = document.get(INPUTS_KEY)
    if listed is None:
        return {}, []
    if not isinstance(listed, Mapping):
        return {}, [(INPUTS_KEY, f"expected an object, found {type(listed).__name__}")]
    inputs: dict[str, InputStatus] = {}
    issues: list[tuple[str, str]] = []
    for name, entry in listed.items():
        field = f"{INPUTS_KEY}.{name}"
        if not isinstance(entry, Mapping) or entry.get("state") not in INPUT_STATES:
            issues.append(
                (field, f"expected {{state: {' | '.join(INPUT_STATES)}, source, reason}}")
            )
            continue
        source, reason = entry.get("source", ""), entry.get("reason", "")
        if not isinstance(source, str) or not isinstance(reason, str):
            issues.append((field, "source and reason must be text"))
            continue
        inputs[str(name)] = InputStatus(str(entry["state"]), source, reason)
    return inputs, issues


@dataclass(eq=False)
class RunLog:
    """A whole run, as loaded from any source.

    ``frames`` are the analysed timestamps: one per ``actors/`` file, ascending, duplicates
    kept (the reference analyses a duplicated timestamp twice). Per-folder dicts map a
    timestamp to its record; a timestamp absent from a dict had no (usable) file.
    """

    metadata: RunMetadata
    frames: tuple[int, ...]
    pose: dict[int, EgoPose] = field(default_factory=dict)
    actors: dict[int, Actors] = field(default_factory=dict)
    bboxes: dict[int, Boxes] = field(default_factory=dict)
    bboxes_gt: dict[int, Boxes] = field(default_factory=dict)
    predictions: dict[int, Predictions] = field(default_factory=dict)
    predictions_with_perception: dict[int, Predictions] = field(default_factory=dict)
    waypoints: dict[int, Plan] = field(default_factory=dict)
    problems: ProblemLog = field(default_factory=ProblemLog)
    source: str = ""
    #: folder -> timestamp -> file name it was read from (for problem reports); may be empty.
    files: dict[str, dict[int, str]] = field(default_factory=dict)
    #: Half extents at first appearance seen BEFORE the frames held here (a live monitor's
    #: bounded window of a longer run); they win over the extents in ``actors``.
    first_extents: dict[str, FloatArray] = field(default_factory=dict)
    #: 3-D perception (recordings of real stacks; empty for running logs): detections and
    #: tracked objects per timestamp.
    detections_3d: dict[int, Objects3D] = field(default_factory=dict)
    tracks_3d: dict[int, Objects3D] = field(default_factory=dict)
    #: The stack's control commands per timestamp (recordings of real stacks).
    controls: dict[int, ControlCommand] = field(default_factory=dict)
    #: Where each model input came from and how (``ads_rca.capabilities``); empty means a
    #: running log, whose folders are all real.
    inputs: dict[str, InputStatus] = field(default_factory=dict)
    #: Map perception per timestamp (OpenLane-V2 segments; empty for every other source):
    #: the ground truth's lane centerlines, traffic elements and topology, and a model's
    #: prediction of them (``--predictions``); the optional folders ``lanes`` and
    #: ``lanes_predicted``.
    lanes: dict[int, LaneGraph] = field(default_factory=dict)
    lanes_predicted: dict[int, LaneGraph] = field(default_factory=dict)
    #: A table of independent snapshots (atmaCup #18): each row's vehicle state, realised
    #: and predicted future ego paths (``ads_rca.sources.atmacup.snapshots``); None for other
    # sources.
    ego_snapshots: EgoSnapshots | None = None
    #: The vehicle's own velocity reports per timestamp (recordings of real stacks).
    vehicle_velocity: dict[int, VehicleVelocity] = field(default_factory=dict)
    #: The stack's fail-safe (MRM) state, every message in time order (recordings of real
    #: stacks that record it; empty otherwise): a change to an emergency state is an event.
    mrm_states: tuple[MrmState, ...] = ()

    @classmethod
    def from_folders(
        cls,
        metadata: RunMetadata,
        frames: tuple[int, ...],
        folders: Mapping[str, Mapping[int, Record]],
        **fields: Unpack[LogExtras],
    ) -> RunLog:
        """A run from per-folder dicts keyed by the names in :data:`ALL_FOLDERS` (any missing).

        A folder holds only its own record type (the readers build them so); the casts say
        which, without a per-record check on the load path.
        """
        records = {name: dict(folders.get(name, {})) for name in FOLDERS}
        log = cls(
            metadata=metadata,
            frames=frames,
            pose=cast("dict[int, EgoPose]", records["pose"]),
            actors=cast("dict[int, Actors]", records["actors"]),
            bboxes=cast("dict[int, Boxes]", records["bboxes"]),
            bboxes_gt=cast("dict[int, Boxes]", records["bboxes_gt"]),
            predictions=cast("dict[int, Predictions]", records["predictions"]),
            predictions_with_perception=cast(
                "dict[int, Predictions]", records["predictions_with_perception"]
            ),
            waypoints=cast("dict[int, Plan]", records["waypoint"]),
            **fields,
        )
        for name in OPTIONAL_FOLDERS:
            log.folder(name).update(folders.get(name, {}))
        return log

    def metadata_document(self) -> dict[str, Any]:
        """``metadata.json`` of this run: the metadata's document plus, for a recording of a
        real stack, its inputs (:data:`INPUTS_KEY`)."""
        document = self.metadata.to_dict()
        if self.inputs:
            document[INPUTS_KEY] = {name: s.to_dict() for name, s in self.inputs.items()}
        return document

    @property
    def frame_ms(self) -> int:
        """Milliseconds per frame."""
        return self.metadata.timesteps_per_frame

    @property
    def unique_frames(self) -> tuple[int, ...]:
        """Analysed timestamps with duplicates removed (what ``corrected`` analyses)."""
        return tuple(dict.fromkeys(self.frames))

    def frame_index(self, timestamp_ms: int) -> float:
        return timestamp_ms / self.frame_ms

    @cached_property
    def actor_extents(self) -> dict[str, FloatArray]:
        """Each actor's half extent where it first appears with one (ascending time).

        Only actors present in ``actors`` are listed; ``first_extents`` (earlier frames of a
        live window) takes precedence for them.
        """
        extents: dict[str, FloatArray] = {}
        known = self.first_extents
        # ids tuples whose every id has one (by value: a log read in one process has a
        # tuple a frame, equal from frame to frame)
        complete: set[tuple[str, ...]] = set()
        for ts in sorted(self.actors):
            frame = self.actors[ts]
            if frame.ids in complete:
                continue
            for row, actor_id in enumerate(frame.ids):
                if actor_id in extents:
                    continue
                if actor_id in known:
                    extents[actor_id] = known[actor_id]
                elif not np.isnan(frame.extent[row]).any():
                    extents[actor_id] = frame.extent[row]
            if all(actor_id in extents for actor_id in frame.ids):
                complete.add(frame.ids)  # later frames listing them add nothing
        return extents

    def file_of(self, folder: str, timestamp_ms: int) -> str:
        """The file a record came from (or would have), relative to the log folder."""
        name = self.files.get(folder, {}).get(timestamp_ms)
        return f"{folder}/{name or f'{FILE_PREFIX[folder]}-{timestamp_ms}.json'}"

    def folder(self, name: str) -> dict[int, Record]:
        """The per-timestamp dict of a folder by its name in :data:`ALL_FOLDERS` (KeyError for
        another name; the dict itself: writes through it land in the log, and callers put
        only the folder's record type)."""
        records: dict[int, Record] = getattr(self, FOLDER_FIELDS[name])
        return records


#: Integer step keys past this are no step (they would not fit the int64 step arrays).
_MAX_STEP = 2**62


def step_value(key: str) -> int:
    """The integer a step key spells, -1 where it is none (or too large for int64)."""
    try:
        value = int(key)
    except ValueError:
        return -1
    return value if -_MAX_STEP <= value <= _MAX_STEP else -1
