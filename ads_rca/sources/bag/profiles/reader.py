"""A real stack's bag, read through a profile, into a :class:`RunLog`.

The stack's messages carry header stamps, not frame numbers, so the frames are made here:
the profile's reference input times them (its list is tried in order: the first input with a
usable message; one passed over is a warning). Its period is the median stamp difference
rounded to whole milliseconds, frame f = round((stamp − t0) / period), timestamp f·period
ms, so the model's frame grid holds. Every other message goes to the frame nearest its
stamp, if within half a period of the reference's first-to-last span (else it is dropped,
said once per input). An input recorded at the frames' rate keeps the later of two messages
on one frame and reports the earlier; one recorded faster (localisation at 50 Hz on
perception's 10 Hz frames) gives each frame the message nearest the frame's time. The
collision frame is the frame nearest the first collision event (the later one on a tie).
Predictions become offsets in the ego's body frame of their frame, so they are kept only
where the ego pose is known. A recording without tracked objects still carries them in its
predicted objects' own kinematics: tracks are derived from those (``derived``). The
fail-safe (MRM) state is kept as a time series, every message on the run's clock.

Nothing here reads storage or types: the caller gives the bag's contents and ``decode``
(message, type) → rosbags object (the bag's own definitions), so this stays pure and the
same for MCAP and sqlite3. Every defect is a Problem naming the topic (and the message's
log time and field); a topic whose definition lacks a field its decoder reads is skipped
whole, said once; only a bag with no usable reference message raises InputError.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, TypeVar, cast

import numpy as np

from ads_rca.capabilities import INPUT_FIELDS, MODEL_INPUTS
from ads_rca.contract.errors import MalformedMessage
from ads_rca.diagnosis.critical_event import EMERGENCY_KEY, START_OFFSET_KEY
from ads_rca.errors import ConfigError, InputError
from ads_rca.foundation.geometry import world_to_ego
from ads_rca.foundation.progress import Progress, tracked
from ads_rca.model import (
    ControlCommand,
    EgoPose,
    FloatArray,
    InputStatus,
    MrmState,
    Objects3D,
    Plan,
    Predictions,
    RunLog,
    RunMetadata,
    Track,
    VehicleVelocity,
)
from ads_rca.problems import DROPPED_RECORD, USED_DEFAULT, Problem, ProblemLog
from ads_rca.sources.bag.profiles.decoders import (
    CollisionEvent,
    FailSafeState,
    PredictedPaths,
    TimedPlan,
    decoder_for,
    missing_field,
)
from ads_rca.sources.bag.profiles.profile import RECORDING_INPUTS, InputSpec, Profile, mismatch
from ads_rca.sources.bag.storage import BagMessage

if TYPE_CHECKING:
    from ads_rca.sources.bag.reader import BagContents

R = TypeVar("R")

#: The frame period when the reference has a single stamp (nothing to measure).
DEFAULT_PERIOD_MS = 50
#: An input whose median stamp spacing is below this share of the frame period is recorded
#: faster than the frames: each frame takes its message nearest the frame's time.
FASTER_THAN_FRAMES = 0.75
#: Keys of ``metadata.raw`` the reader sets besides the profile's facts.
FRAME_REFERENCE = "frame_reference"
_SKIPPED = "message skipped"
_NS_PER_MS = 1_000_000
#: The inputs read into per-frame folders of the model as decoded, by folder (the field of
#: each is the folder's name), and the prediction inputs, resampled per frame, to theirs.
_FOLDERS = {
    INPUT_FIELDS[name]: name for name in ("ego", "actors", "detections_2d", "ground_truth_2d")
}
_PREDICTION_FOLDERS = {name: INPUT_FIELDS[name] for name in ("predictions", "predictions_gt")}
#: The inputs kept as events or a time series rather than one record per frame.
_NOT_FRAMED = ("collision", "clock", "mrm_state")


@dataclass(frozen=True, slots=True)
class Stamped:
    """One decoded message: its stamp and log time (ns), where it came from, its record."""

    stamp_ns: int
    log_time_ns: int
    file: str
    record: object


@dataclass(frozen=True, slots=True)
class Grid:
    """The frames the reference input makes: first stamp, period (ns), first/last frame."""

    t0_ns: int
    period_ns: int
    last: int

    def nearest(self, stamp_ns: int) -> int:
        """The frame nearest a stamp (the later one on a tie)."""
        return math.floor((stamp_ns - self.t0_ns) / self.period_ns + 0.5)

    def on_grid(self, stamp_ns: int) -> bool:
        """Within half a period of the reference's first-to-last span."""
        offset = stamp_ns - self.t0_ns
        return -self.period_ns / 2 <= offset <= (self.last + 0.5) * self.period_ns

    def frame_ns(self, frame: int) -> int:
        return self.t0_ns + frame * self.period_ns

    def clock_ms(self, stamp_ns: int) -> int:
        """A stamp on the run's clock (ms; frame 0 at 0)."""
        return round((stamp_ns - self.t0_ns) / _NS_PER_MS)

    @property
    def period_ms(self) -> int:
        return self.period_ns // _NS_PER_MS


def read_profiled(
    contents: BagContents,
    profile: Profile,
    decode: Callable[[BagMessage, str], Any],
    source: str,
    progress: Progress | None = None,
    definition_of: Callable[[str], str] | None = None,
) -> RunLog:
    """The run a bag carries in ``profile``'s layout (see the module docstring).

    ``decode`` gives the rosbags object of a message as the named type (MalformedMessage
    when it cannot; ``progress`` sees every message); ``source`` names the bag in problems,
    errors and ``RunLog.source``; ``definition_of`` names where a type's definition came
    from, in the line that says it lacks a field its decoder reads."""
    if profile.contract:
        raise ConfigError(
            f"{profile.file}: the {profile.name} profile is read by the contract reader"
        )
    problems = list(contents.problems)
    named = (*MODEL_INPUTS, *(name for name in RECORDING_INPUTS if name in profile.inputs))
    inputs = {
        name: InputStatus("absent", "", "the profile names no topic for it") for name in named
    }
    usable = usable_inputs(contents.topics, profile, inputs, source, problems)
    reading = _Decoding(usable, decode, inputs, problems, definition_of)
    decoded = reading.all(contents.messages, progress)
    reference = _reference(profile, decoded, inputs, contents, source, problems)
    grid = _grid(decoded[reference], usable[reference], problems)
    framed = {
        name: _to_frames(stamped, usable[name], grid, problems)
        for name, stamped in decoded.items()
        if name not in _NOT_FRAMED
    }
    _mark_read(inputs, usable, framed, decoded)
    if reference != profile.reference:
        inputs[reference] = InputStatus(
            "real", usable[reference].source, f"times the frames in place of {profile.reference}"
        )
    folders: dict[str, dict[int, Any]] = {
        folder: {ts: s.record for ts, s in framed.get(name, {}).items()}
        for folder, name in _FOLDERS.items()
    }
    poses = cast("dict[int, EgoPose]", folders["pose"])
    for name, folder in _PREDICTION_FOLDERS.items():
        if name in framed:
            folders[folder] = _predictions(framed[name], usable[name], poses, grid, problems)
    if "plan" in framed:
        folders["waypoint"] = _plans(framed["plan"], usable["plan"], grid, problems)
    tracks = _records(framed.get("tracked_objects", {}), Objects3D)
    if inputs["tracked_objects"].state != "real" and framed.get("predictions"):
        tracks = _derived_tracks(framed["predictions"], usable["predictions"], inputs, problems)
    frames = folders["actors"] if "actors" in profile.inputs else framed[reference]
    mrm_states = _mrm_states(decoded.get("mrm_state"), usable, grid, inputs, problems)
    raw: dict[str, Any] = {}
    if inputs.get("mrm_state", InputStatus("absent")).state == "real":
        raw[EMERGENCY_KEY] = emergency_onsets(mrm_states, grid.period_ms)
    collisions = decoded.get("collision", [])
    metadata = _metadata(profile, grid, collisions, contents, reference, problems, raw)
    return RunLog.from_folders(
        metadata,
        tuple(sorted(frames)),
        folders,
        problems=ProblemLog(problems),
        source=source,
        detections_3d=_records(framed.get("detections_3d", {}), Objects3D),
        tracks_3d=tracks,
        controls=_records(framed.get("control", {}), ControlCommand),
        vehicle_velocity=_records(framed.get("vehicle_velocity", {}), VehicleVelocity),
        mrm_states=mrm_states,
        inputs=inputs,
    )


def _reference(
    profile: Profile,
    decoded: dict[str, list[Stamped]],
    inputs: dict[str, InputStatus],
    contents: BagContents,
    source: str,
    problems: list[Problem],
) -> str:
    """The first of the profile's reference inputs with a usable message; each one passed
    over is a warning. InputError (one line naming each one tried and why) when none has."""
    for position, name in enumerate(profile.references):
        if not decoded.get(name):
            continue
        passed = [
            f"{earlier} ({_why_none(profile.inputs[earlier], decoded, inputs, contents)})"
            for earlier in profile.references[:position]
        ]
        if passed:
            problems.append(
                Problem(
                    source,
                    "reference",
                    f"no usable message on {', '.join(passed)}",
                    f"the frames are timed by {name} ({profile.inputs[name].topic})",
                    "warning",
                )
            )
        return name
    said = "; nor on ".join(
        f"{name} ({profile.inputs[name].topic}): "
        f"{_why_none(profile.inputs[name], decoded, inputs, contents)}"
        for name in profile.references
    )
    raise InputError(f"{source}: no usable message on the reference input {said}")


def _why_none(
    spec: InputSpec,
    decoded: dict[str, list[Stamped]],
    inputs: dict[str, InputStatus],
    contents: BagContents,
) -> str:
    """Why an input has no usable message: its status's reason (not in the bag, another
    type, a definition without a field it reads), or what its topic held."""
    if spec.input not in decoded:
        return inputs[spec.input].reason
    count = sum(message.topic == spec.topic for message in contents.messages)
    if count == 0:
        return "the topic holds no message"
    return f"none of its {count} messages could be used (see the problems)"


def _mark_read(
    inputs: dict[str, InputStatus],
    usable: dict[str, InputSpec],
    framed: dict[str, dict[int, Stamped]],
    decoded: dict[str, list[Stamped]],
) -> None:
    """Each input decoded real when a message of it was placed on a frame (the clock: when
    one was decoded; the collision always: a topic without events means none happened);
    the fail-safe state is said by :func:`_mrm_states`."""
    for name, spec in usable.items():
        if name not in decoded or name == "mrm_state":
            continue  # a topic skipped whole: its status says why
        placed = framed.get(name) or (name == "clock" and decoded["clock"])
        if placed or name == "collision":
            inputs[name] = InputStatus("real", spec.source)
        else:
            inputs[name] = InputStatus("absent", spec.source, f"no usable message on {spec.topic}")


def _metadata(
    profile: Profile,
    grid: Grid,
    collisions: list[Stamped],
    contents: BagContents,
    reference: str,
    problems: list[Problem],
    more: Mapping[str, Any],
) -> RunMetadata:
    """The run facts: the grid's period and length, the collision, the profile's camera and
    vehicle, how far frame 0 is from the recording's first message, what timed the frames,
    and ``more`` (the emergency onsets)."""
    collision_frame, partner = _collision(collisions, grid, problems)
    raw: dict[str, Any] = {"source_profile": profile.name, "ego_role": profile.ego_role}
    raw.update(profile.facts)
    raw.update(more)
    first = min((m.log_time_ns for m in contents.messages), default=grid.t0_ns)
    raw[START_OFFSET_KEY] = max(0, round((grid.t0_ns - first) / _NS_PER_MS))
    if len(profile.references) > 1:
        raw[FRAME_REFERENCE] = reference
    if partner is not None:
        raw["collision_partner"] = partner
    camera_loc = profile.camera_loc
    if camera_loc is None:
        camera_loc = (0.0, 0.0, 0.0)
        if {"detections_2d", "ground_truth_2d"} & set(profile.inputs):
            problems.append(
                Problem(
                    profile.file,
                    "metadata.camera_loc",
                    "not given",
                    f"{USED_DEFAULT}: [0, 0, 0]",
                    "warning",
                )
            )
    return RunMetadata(grid.period_ms, camera_loc, collision_frame, grid.last + 1, raw=raw)


def _records(framed: Mapping[int, Stamped], kind: type[R]) -> dict[int, R]:
    """The records of a framed input, as the type its decoder makes."""
    return {ts: cast("R", s.record) for ts, s in framed.items()}


def usable_inputs(
    stored: Mapping[str, str],
    profile: Profile,
    inputs: dict[str, InputStatus],
    source: str,
    problems: list[Problem],
) -> dict[str, InputSpec]:
    """Input → its spec as the bag stores it (the stored type, one the input accepts) for
    the profile's topics the bag holds; the others are absent, said in ``inputs`` and as a
    Problem (a topic of another type names both types, and the alias that would read it)."""
    usable: dict[str, InputSpec] = {}
    for name, spec in profile.inputs.items():
        if spec.topic not in stored:
            reason = f"topic {spec.topic} not in the bag"
            inputs[name] = InputStatus("absent", spec.source, reason)
            problems.append(Problem(source, spec.topic, reason, f"{name} absent", "warning"))
        elif not spec.accepts(stored[spec.topic]):
            reason = mismatch(spec, stored[spec.topic])
            inputs[name] = InputStatus("absent", spec.source, reason)
            problems.append(Problem(source, spec.topic, reason, f"topic skipped; {name} absent"))
        else:
            usable[name] = spec.as_stored(stored[spec.topic])
    return usable


def stored_types(stored: Mapping[str, str], profile: Profile) -> list[str]:
    """The stored types of the profile's topics the bag holds as a type the input accepts:
    the definitions the reading needs."""
    return sorted(
        {
            stored[spec.topic]
            for spec in profile.inputs.values()
            if spec.topic in stored and spec.accepts(stored[spec.topic])
        }
    )


def mismatches(stored: Mapping[str, str], profile: Profile) -> list[str]:
    """``topic: why`` for each profile topic the bag holds as a type its input does not
    accept (said beside a missing definition, which another type would not need)."""
    return [
        f"{spec.topic}: {mismatch(spec, stored[spec.topic])}"
        for spec in profile.inputs.values()
        if spec.topic in stored and not spec.accepts(stored[spec.topic])
    ]


class _Decoding:
    """Every message of the usable inputs decoded, in log-time order. An unusable message is
    a Problem; a topic whose definition lacks a field its decoder reads is skipped whole
    (every message would fail alike), said once, its input absent."""

    def __init__(
        self,
        usable: dict[str, InputSpec],
        decode: Callable[[BagMessage, str], Any],
        inputs: dict[str, InputStatus],
        problems: list[Problem],
        definition_of: Callable[[str], str] | None,
    ) -> None:
        self.by_topic = {spec.topic: spec for spec in usable.values()}
        self.decode = decode
        self.inputs = inputs
        self.problems = problems
        self.definition_of = definition_of

    def all(
        self, messages: list[BagMessage], progress: Progress | None
    ) -> dict[str, list[Stamped]]:
        """Input → its decoded messages (inputs skipped whole are left out)."""
        out: dict[str, list[Stamped]] = {spec.input: [] for spec in self.by_topic.values()}
        for message in tracked(messages, progress):
            spec = self.by_topic.get(message.topic)
            if spec is None:
                continue
            decoder = decoder_for(spec.type)
            if decoder is None:  # a contract profile: not this reader's
                continue
            try:
                msg = self.decode(message, spec.type)
                stamp = decoder.stamp(msg)
                record = decoder.decode(msg, spec.frame)
            except MalformedMessage as error:
                self._unusable(message, spec, error, out)
                continue
            out[spec.input].append(
                Stamped(stamp, message.log_time_ns, message.source or message.topic, record)
            )
        return out

    def _unusable(
        self,
        message: BagMessage,
        spec: InputSpec,
        error: MalformedMessage,
        out: dict[str, list[Stamped]],
    ) -> None:
        where = message.source or message.topic
        path = missing_field(error)
        if path is None:
            self.problems.append(
                Problem(
                    where,
                    message.topic,
                    f"message at log time {message.log_time_ns} ns: cannot use this "
                    f"{spec.type}: {error}",
                    _SKIPPED,
                )
            )
            return
        definition = self.definition_of(spec.type) if self.definition_of else "its definition"
        reason = (
            f"{spec.type} has no field {path} in {definition}: its messages cannot be read as "
            f"{spec.input}"
        )
        self.problems.append(
            Problem(where, message.topic, reason, f"topic skipped; {spec.input} absent")
        )
        self.inputs[spec.input] = InputStatus("absent", spec.source, reason)
        del self.by_topic[spec.topic]
        del out[spec.input]


def _grid(reference: list[Stamped], spec: InputSpec, problems: list[Problem]) -> Grid:
    """The frame grid of the reference's stamps (see the module docstring)."""
    stamps = np.unique(np.array([s.stamp_ns for s in reference], dtype=np.int64))
    t0 = int(stamps[0])
    if len(stamps) > 1:
        period_ms = max(1, round(float(np.median(np.diff(stamps))) / _NS_PER_MS))
    else:
        period_ms = DEFAULT_PERIOD_MS
        problems.append(
            Problem(
                spec.topic,
                "header.stamp",
                "one stamp only: no frame period to measure",
                f"{USED_DEFAULT}: {DEFAULT_PERIOD_MS} ms",
                "warning",
            )
        )
    period_ns = period_ms * _NS_PER_MS
    last = math.floor((int(stamps[-1]) - t0) / period_ns + 0.5)
    return Grid(t0, period_ns, last)


def _to_frames(
    stamped: list[Stamped], spec: InputSpec, grid: Grid, problems: list[Problem]
) -> dict[int, Stamped]:
    """Timestamp (ms) → the message of each frame (see the module docstring)."""
    ordered = sorted(stamped, key=lambda s: (s.stamp_ns, s.log_time_ns))
    inside = [item for item in ordered if grid.on_grid(item.stamp_ns)]
    _say_outside(
        [item for item in ordered if not grid.on_grid(item.stamp_ns)], spec, grid, problems
    )
    if _faster_than_frames(inside, grid):
        return _nearest_per_frame(inside, grid)
    out: dict[int, Stamped] = {}
    frame_ms = grid.period_ms
    for item in inside:
        ts = grid.nearest(item.stamp_ns) * frame_ms
        earlier = out.get(ts)
        if earlier is not None:
            problems.append(
                Problem(
                    earlier.file,
                    spec.topic,
                    f"message at log time {earlier.log_time_ns} ns, stamp {earlier.stamp_ns} "
                    f"ns: frame {ts // frame_ms} has a later message ({item.stamp_ns} ns)",
                    "earlier message dropped",
                    "warning",
                    ts,
                )
            )
        out[ts] = item
    return out


def _faster_than_frames(ordered: list[Stamped], grid: Grid) -> bool:
    """The input's median stamp spacing is well below the frame period (a faster topic)."""
    stamps = np.unique(np.array([s.stamp_ns for s in ordered], dtype=np.int64))
    if len(stamps) < 3:
        return False
    return float(np.median(np.diff(stamps))) < FASTER_THAN_FRAMES * grid.period_ns


def _nearest_per_frame(ordered: list[Stamped], grid: Grid) -> dict[int, Stamped]:
    """Each frame's message nearest the frame's time (the later on a tie)."""
    best: dict[int, tuple[int, Stamped]] = {}
    for item in ordered:
        frame = grid.nearest(item.stamp_ns)
        distance = abs(item.stamp_ns - grid.frame_ns(frame))
        kept = best.get(frame)
        if kept is None or distance <= kept[0]:
            best[frame] = (distance, item)
    return {frame * grid.period_ms: item for frame, (_d, item) in best.items()}


def _say_outside(
    outside: list[Stamped], spec: InputSpec, grid: Grid, problems: list[Problem]
) -> None:
    """One warning for an input's messages outside the frames (the first one named)."""
    if not outside:
        return
    first = outside[0]
    what = f"message at log time {first.log_time_ns} ns, stamp {first.stamp_ns} ns"
    if len(outside) > 1:
        what = f"{len(outside)} messages (the first: {what})"
    problems.append(
        Problem(
            first.file,
            spec.topic,
            f"{what}: outside the frames of {grid.t0_ns} ns + [0, {grid.last}] × "
            f"{grid.period_ms} ms by more than half a period",
            _SKIPPED if len(outside) == 1 else "messages skipped",
            "warning",
        )
    )


def _derived_tracks(
    framed: dict[int, Stamped],
    spec: InputSpec,
    inputs: dict[str, InputStatus],
    problems: list[Problem],
) -> dict[int, Objects3D]:
    """Tracked objects per frame from the predicted objects' own kinematics (a recording
    without tracked objects); ``tracked_objects`` becomes ``derived`` when any frame has
    them. A message whose kinematics cannot be read gives none (said; once per topic when
    its definition lacks the field)."""
    out: dict[int, Objects3D] = {}
    lacking_said = False
    for ts, item in sorted(framed.items()):
        states = cast("PredictedPaths", item.record).states
        if isinstance(states, Objects3D):
            out[ts] = states
            continue
        path = missing_field(states)
        if path is not None and lacking_said:
            continue
        lacking_said = lacking_said or path is not None
        where = f"message at log time {item.log_time_ns} ns: " if path is None else ""
        problems.append(
            Problem(
                item.file,
                spec.topic,
                f"{where}no tracked objects derived from this {spec.type}: {states}",
                "no derived tracked objects" + ("" if path is None else " from this topic"),
                timestamp_ms=None if path is not None else ts,
            )
        )
    if out:
        why = inputs["tracked_objects"].reason
        inputs["tracked_objects"] = InputStatus(
            "derived", spec.source, f"from the predicted objects' own kinematics ({why})"
        )
    return out


def _mrm_states(
    stamped: list[Stamped] | None,
    usable: dict[str, InputSpec],
    grid: Grid,
    inputs: dict[str, InputStatus],
    problems: list[Problem],
) -> tuple[MrmState, ...]:
    """The fail-safe state of every message within the frames, in time order, on the run's
    clock; the input is real when there is one (``stamped`` None: not read)."""
    spec = usable.get("mrm_state")
    if spec is None or stamped is None:
        return ()
    ordered = sorted(stamped, key=lambda s: (s.stamp_ns, s.log_time_ns))
    _say_outside([s for s in ordered if not grid.on_grid(s.stamp_ns)], spec, grid, problems)
    states = tuple(
        MrmState(grid.clock_ms(item.stamp_ns), record.state, record.behavior)
        for item in ordered
        if grid.on_grid(item.stamp_ns)
        for record in [cast("FailSafeState", item.record)]
    )
    if states:
        inputs["mrm_state"] = InputStatus("real", spec.source)
    else:
        inputs["mrm_state"] = InputStatus(
            "absent", spec.source, f"no usable message on {spec.topic}"
        )
    return states


def emergency_onsets(states: tuple[MrmState, ...], frame_ms: int) -> list[int]:
    """The frame timestamps (the nearest frame, the later on a tie) at which the fail-safe
    state turned to an emergency (the first message too, when it is one)."""
    onsets: list[int] = []
    before = False
    for state in states:
        if state.emergency and not before:
            onsets.append(math.floor(state.timestamp_ms / frame_ms + 0.5) * frame_ms)
        before = state.emergency
    return onsets


def _predictions(
    framed: dict[int, Stamped],
    spec: InputSpec,
    poses: dict[int, EgoPose],
    grid: Grid,
    problems: list[Problem],
) -> dict[int, Predictions]:
    """Each frame's predicted paths as the model's keyed offsets in the ego body frame:
    key k is the position (k+1)·frame_ms after the frame's time, linearly interpolated along the
    path, for as long as the path lasts."""
    out: dict[int, Predictions] = {}
    frame_ms = grid.period_ms
    for ts, item in sorted(framed.items()):
        pose = poses.get(ts)
        if pose is None:
            problems.append(
                Problem(
                    item.file,
                    spec.topic,
                    f"frame {ts // frame_ms}: no ego pose to put the predictions in its body frame",
                    DROPPED_RECORD,
                    timestamp_ms=ts,
                )
            )
            continue
        paths = cast("PredictedPaths", item.record)
        if len(set(paths.ids)) < len(paths.ids):
            problems.append(
                Problem(
                    item.file,
                    spec.topic,
                    f"frame {ts // frame_ms}: {len(paths.ids) - len(set(paths.ids))} objects "
                    "repeat an object_id",
                    "the last object of each id kept",
                    timestamp_ms=ts,
                )
            )
        delay_s = (grid.frame_ns(ts // frame_ms) - item.stamp_ns) / 1e9
        out[ts] = track_offsets(paths, delay_s, frame_ms / 1000.0, pose)
    return out


def _plans(
    framed: dict[int, Stamped], spec: InputSpec, grid: Grid, problems: list[Problem]
) -> dict[int, Plan]:
    """Each frame's trajectory as the model's plan: key i is the point ``i``·frame_ms after the
    frame's time (``time_from_start`` from the message's stamp), x, y and speed linearly
    interpolated, for as long as the trajectory lasts. A trajectory whose times are not
    filled (all zero) is timed by its points' spacing and speeds, and that is said once."""
    out: dict[int, Plan] = {}
    frame_ms = grid.period_ms
    said = False
    for ts, item in sorted(framed.items()):
        timed = cast("TimedPlan", item.record)
        times = timed.times_s
        if len(times) > 1 and times[-1] <= 0.0:
            times = travel_times(timed.xy, timed.speed)
            if not said:
                problems.append(
                    Problem(
                        item.file,
                        spec.topic,
                        f"frame {ts // frame_ms}: time_from_start not filled",
                        "times derived from the points' spacing and speeds",
                        severity="warning",
                        timestamp_ms=ts,
                    )
                )
                said = True
        delay_s = (grid.frame_ns(ts // frame_ms) - item.stamp_ns) / 1e9
        out[ts] = sample_plan(times, timed.xy, timed.speed, delay_s, frame_ms / 1000.0)
    return out


def travel_times(xy: FloatArray, speed: FloatArray) -> FloatArray:
    """Seconds to each point along a path driven at its points' speeds (the mean of the
    two ends per segment, at least 0.1 m/s so a stop point is reached)."""
    step = np.hypot(*np.diff(xy, axis=0).T)
    mean_speed = np.maximum((speed[1:] + speed[:-1]) / 2.0, 0.1)
    out: FloatArray = np.concatenate([[0.0], np.cumsum(step / mean_speed)])
    return out


def sample_plan(
    times: FloatArray, xy: FloatArray, speed: FloatArray, delay_s: float, frame_s: float
) -> Plan:
    """The plan of keys "0", "1", ...: the trajectory at ``delay_s + i·frame_s`` seconds from
    its start, while inside it (a point exactly at a sample time is taken as is)."""
    if len(times) == 0:
        return Plan((), np.zeros((0, 2)), np.zeros(0))
    count = int(np.floor((times[-1] - delay_s) / frame_s + 1e-9)) + 1 if times[-1] >= delay_s else 1
    at = np.clip(delay_s + np.arange(count) * frame_s, times[0], times[-1])
    points = np.column_stack([np.interp(at, times, xy[:, 0]), np.interp(at, times, xy[:, 1])])
    return Plan(tuple(str(i) for i in range(count)), points, np.interp(at, times, speed))


def track_offsets(
    paths: PredictedPaths, delay_s: float, frame_s: float, pose: EgoPose
) -> Predictions:
    """The model's predictions of one frame from world paths: key k at ``delay_s + (k+1)·
    frame_s`` seconds after the message stamp, while within the path; offsets are world
    points minus the ego position, rotated into the ego's body frame (x forward, y right).

    Objects whose paths have the same length and step are interpolated together."""
    groups: dict[tuple[int, float], list[int]] = {}
    for row, (points, step) in enumerate(zip(paths.points, paths.step_s, strict=True)):
        groups.setdefault((len(points), step), []).append(row)
    tracks: dict[int, Track] = {}
    origin = np.array([pose.x, pose.y])
    for (length, step), rows in groups.items():
        span = (length - 1) * step
        count = 0 if length < 2 else max(0, math.floor((span - delay_s) / frame_s + 1e-9))
        query = delay_s + frame_s * np.arange(1, count + 1)
        query = query[(query >= 0) & (query <= span + 1e-9)]
        keys = tuple(str(k) for k in range(len(query)))
        points = np.stack([paths.points[row] for row in rows])  # (M, P, 3)
        if len(query):
            where = query / step
            j = np.minimum(np.floor(where).astype(np.int64), length - 2)
            w = (where - j)[None, :, None]
            world = points[:, j] * (1.0 - w) + points[:, j + 1] * w  # (M, K, 3)
        else:
            world = np.zeros((len(rows), 0, 3))
        xy = world_to_ego(world[..., :2], origin, pose.yaw)
        offsets = np.concatenate([xy, world[..., 2:] - pose.z], axis=-1)
        for i, row in enumerate(rows):
            tracks[row] = Track(keys, offsets[i])
    return {paths.ids[row]: tracks[row] for row in range(len(paths.ids))}


def _collision(
    events: list[Stamped], grid: Grid, problems: list[Problem]
) -> tuple[int, str | None]:
    """The frame of the first collision event and the other actor's id (-1, None: none)."""
    if not events:
        return -1, None
    first = min(events, key=lambda s: (s.stamp_ns, s.log_time_ns))
    frame = grid.nearest(first.stamp_ns)
    if not grid.on_grid(first.stamp_ns):
        problems.append(
            Problem(
                first.file,
                "collision",
                f"first collision at stamp {first.stamp_ns} ns is frame {frame}, outside the "
                f"reference's frames 0..{grid.last}",
                "value kept",
                "warning",
            )
        )
    return frame, cast("CollisionEvent", first.record).other_actor_id
