"""The ``autoware`` profile on recordings shaped like a real Autoware vehicle's: a
synthesised run written as ``ros2 bag record`` keeps it (localisation at 50 Hz, perception at
10 Hz, hundreds of idle topics, no ground truth, no collision topic, an MRM state that turns
to an emergency), in the current types or the legacy ``autoware_auto_*_msgs``, in MCAP,
rosbag2 Iron sqlite3 or pre-Iron sqlite3 without definitions. Each legacy type reads to the
records its current type gives; a pre-Iron bag needs no ``--msg-path``; tracks come from the
predicted objects when no tracking topic was recorded; the frames follow perception and fall
back in the profile's order; hostile values are one line each."""

from __future__ import annotations

import math
import sqlite3
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from profilebags import build, header, write_bag
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore
from writers.autoware_bags import (
    TOPICS,
    AutowareBag,
    AutowareBagOptions,
    typestore,
    write_autoware_bag,
)

from ads_rca.errors import ConfigError, InputError
from ads_rca.model import InputStatus, MrmState, Objects3D, RunLog
from ads_rca.sources.bag.message_types import shipped_files
from ads_rca.sources.bag.profiles.decoders import DECODERS, LEGACY_ALIASES
from ads_rca.sources.bag.profiles.profile import load_profile
from ads_rca.sources.bag.profiles.reader import emergency_onsets
from ads_rca.sources.bag.profiles.recording import read_recording
from ads_rca.sources.bag.reader import load_bag
from ads_rca.synth.recording import MSG_DIR, object_uuid

pytestmark = pytest.mark.timeout(120)

#: When the fail-safe turns to an emergency, on the synthesised run's clock (ms).
EMERGENCY_MS = 3000
#: (legacy types, storage, tracking topic recorded) of each recording the tests read.
VARIANTS = {
    "current": AutowareBagOptions(emergency_at_ms=EMERGENCY_MS),
    "legacy": AutowareBagOptions(legacy=True, storage="humble", emergency_at_ms=EMERGENCY_MS),
    "legacy-iron": AutowareBagOptions(legacy=True, storage="sqlite3", emergency_at_ms=EMERGENCY_MS),
    "untracked": AutowareBagOptions(
        legacy=True, storage="humble", tracking=False, emergency_at_ms=EMERGENCY_MS
    ),
}
LEGACY_PERCEPTION = "autoware_auto_perception_msgs/msg/"
T0 = 1_000 * 1_000_000_000
MS = 1_000_000


@pytest.fixture(scope="module")
def run_log() -> RunLog:
    from synthlogs import synth

    return synth("cut_in", "perception")


@pytest.fixture(scope="module")
def bags(run_log: RunLog, tmp_path_factory: pytest.TempPathFactory) -> dict[str, AutowareBag]:
    root = tmp_path_factory.mktemp("autoware")
    return {
        name: write_autoware_bag(run_log, root / name, options)
        for name, options in VARIANTS.items()
    }


@pytest.fixture(scope="module")
def runs(bags: dict[str, AutowareBag]) -> dict[str, RunLog]:
    return {name: read_recording(bag.path, "autoware") for name, bag in bags.items()}


def _objects(frames: dict[int, Objects3D]) -> dict[int, Any]:
    """Objects per frame as plain values (NaN as None) for exact comparison."""
    return {
        ts: (
            o.ids,
            o.location.tolist(),
            o.yaw.tolist(),
            o.extent.tolist(),
            [[None if math.isnan(v) else v for v in row] for row in o.velocity.tolist()],
            o.score.tolist(),
            o.labels,
        )
        for ts, o in frames.items()
    }


def _records(run: RunLog) -> dict[str, Any]:
    """Everything a recording gives the model, as plain values."""
    return {
        "frames": run.frames,
        "frame_ms": run.frame_ms,
        "pose": run.pose,
        "detections_3d": _objects(run.detections_3d),
        "tracks_3d": _objects(run.tracks_3d),
        "predictions": {
            ts: {i: (t.keys, t.offsets.tolist()) for i, t in p.items()}
            for ts, p in run.predictions.items()
        },
        "plan": {ts: (p.keys, p.xy.tolist(), p.speed.tolist()) for ts, p in run.waypoints.items()},
        "controls": run.controls,
        "vehicle_velocity": run.vehicle_velocity,
        "mrm_states": run.mrm_states,
    }


# --- legacy types ----------------------------------------------------------------------------


@pytest.mark.parametrize("legacy", ["legacy", "legacy-iron"])
def test_each_legacy_type_reads_to_the_records_of_its_current_type(
    runs: dict[str, RunLog], legacy: str
) -> None:
    """The same run recorded in autoware_auto_*_msgs (AckermannControlCommand's
    ``longitudinal.speed`` included) gives every record the current types give."""
    current, old = _records(runs["current"]), _records(runs[legacy])
    assert old == current
    assert len(runs[legacy].controls) > 10 and len(runs[legacy].tracks_3d) > 10
    sources = {name: status.source for name, status in runs[legacy].inputs.items()}
    assert sources["control"] == (
        "/control/command/control_cmd (autoware_auto_control_msgs/msg/AckermannControlCommand)"
    )
    assert sources["tracked_objects"].endswith(f"({LEGACY_PERCEPTION}TrackedObjects)")


def test_every_legacy_alias_is_shipped_and_carries_its_current_types_inputs() -> None:
    for legacy, current in LEGACY_ALIASES.items():
        assert legacy in shipped_files(), legacy
        assert DECODERS[legacy].inputs == DECODERS[current].inputs
        assert DECODERS[legacy].alias_of == current


def test_a_pre_iron_recording_of_legacy_types_needs_no_msg_path(
    bags: dict[str, AutowareBag], runs: dict[str, RunLog]
) -> None:
    """No message_definitions table, no type hashes: the shipped definitions decode it."""
    path = bags["legacy"].path
    with sqlite3.connect(next(path.glob("*.db3"))) as database:
        tables = {row[0] for row in database.execute("SELECT name FROM sqlite_master")}
    assert "message_definitions" not in tables
    contents = load_bag(path)
    assert contents.definitions == {}
    types = contents.types()
    for name in ("TrackedObjects", "PredictedObjects", "DetectedObjects"):
        assert types.source(LEGACY_PERCEPTION + name) == "shipped"
    assert types.source("autoware_adapi_v1_msgs/msg/MrmState") == "shipped"
    assert runs["legacy"].inputs["tracked_objects"].state == "real"


def test_an_iron_recording_of_legacy_types_is_read_with_its_own_idl(
    bags: dict[str, AutowareBag],
) -> None:
    """rosbag2 stores an IDL-defined type as ``ros2idl`` with its #include lines and
    annotations: the bag's own text is what decodes it."""
    contents = load_bag(bags["legacy-iron"].path)
    encoding, text = contents.definitions[LEGACY_PERCEPTION + "TrackedObjects"]
    assert encoding == "ros2idl" and "#include" in text and "@verbatim" in text
    assert contents.types().source(LEGACY_PERCEPTION + "TrackedObjects") == "bag"


def test_current_types_in_a_pre_iron_recording_name_what_they_lack(
    run_log: RunLog, tmp_path: Path
) -> None:
    """The current types are not shipped: a bag without definitions says which it lacks
    (``--msg-path`` supplies them)."""
    bag = write_autoware_bag(run_log, tmp_path / "bag", AutowareBagOptions(storage="humble"))
    with pytest.raises(InputError) as error:
        read_recording(bag.path, "autoware")
    said = str(error.value)
    assert "\n" not in said and "--msg-path" in said
    assert "autoware_perception_msgs/msg/TrackedObjects" in said
    assert "MrmState" not in said and "nav_msgs" not in said
    assert read_recording(bag.path, "autoware", [MSG_DIR]).inputs["plan"].state == "real"


# --- the profile's reading -------------------------------------------------------------------


def test_a_vehicles_recording_reads_with_its_inputs_and_nothing_else(
    bags: dict[str, AutowareBag], runs: dict[str, RunLog]
) -> None:
    """320 idle topics, no ground truth, no collision topic: the inputs Autoware records are
    real, the others absent; the only problem is the fail-safe state published before the
    first perception frame."""
    run, bag = runs["current"], bags["current"]
    assert len(bag.counts) > 300 and sum(1 for n in bag.counts.values() if n == 0) > 300
    real = {name for name, status in run.inputs.items() if status.state == "real"}
    assert real == {
        "ego",
        "detections_3d",
        "tracked_objects",
        "predictions",
        "plan",
        "control",
        "vehicle_velocity",
        "mrm_state",
    }
    assert run.inputs["collision"] == InputStatus("absent", "", "the profile names no topic for it")
    assert run.metadata.collision_frame == -1 and run.actors == {}
    said = [str(p) for p in run.problems]
    assert len(said) == 1 and "/system/fail_safe/mrm_state" in said[0]
    assert said[0].startswith("warning:") and "outside the frames" in said[0]
    raw = run.metadata.raw
    assert raw["source_profile"] == "autoware" and raw["frame_reference"] == "tracked_objects"
    assert (raw["ego_size"], raw["ego_box_offset"]) == ([4.89, 1.896, 1.6], 1.345)
    first_frame = bag.object_frames[0]  # the recording starts with the MRM state at 0 ms
    assert raw["first_message_offset_ms"] == first_frame - 2  # its log time: 2 ms later


def test_the_frames_follow_perception_and_each_takes_the_nearest_ego_pose(
    run_log: RunLog, bags: dict[str, AutowareBag], runs: dict[str, RunLog]
) -> None:
    run, bag = runs["current"], bags["current"]
    assert bag.counts[TOPICS["ego"][0]] > 4 * len(bag.object_frames)  # 50 Hz against 10 Hz
    assert run.frame_ms == 100
    assert run.frames == tuple(ts - bag.object_frames[0] for ts in bag.object_frames)
    for ts in run.frames:
        mine, truth = run.pose[ts], run_log.pose[ts + bag.object_frames[0]]
        assert (mine.x, mine.y, mine.yaw, mine.speed) == pytest.approx(
            (truth.x, truth.y, truth.yaw, truth.speed), abs=1e-9
        )
    assert not any("later message" in str(p) for p in run.problems)


def test_without_a_tracking_topic_the_predictions_time_the_frames(
    runs: dict[str, RunLog],
) -> None:
    run = runs["untracked"]
    assert run.frames == runs["legacy"].frames
    assert run.metadata.raw["frame_reference"] == "predictions"
    predicted = "/perception/object_recognition/objects"
    assert run.inputs["predictions"] == InputStatus(
        "real",
        f"{predicted} ({LEGACY_PERCEPTION}PredictedObjects)",
        "times the frames in place of tracked_objects",
    )
    fallback = [str(p) for p in run.problems if p.field == "reference"]
    assert fallback == [
        f"warning: {run.source}: reference: no usable message on tracked_objects (topic "
        "/perception/object_recognition/tracking/objects not in the bag) (the frames are "
        f"timed by predictions ({predicted}))"
    ]


def test_with_no_perception_message_the_ego_times_the_frames(
    run_log: RunLog, tmp_path: Path
) -> None:
    """Perception's topics declared but silent: the ego's 50 Hz pose makes the frames."""
    silent = replace(run_log, tracks_3d={}, detections_3d={}, predictions={})
    bag = write_autoware_bag(silent, tmp_path / "bag", AutowareBagOptions(mrm=False))
    assert bag.counts[TOPICS["tracked_objects"][0]] == 0
    run = read_recording(bag.path, "autoware")
    assert run.frame_ms == 20 and run.metadata.raw["frame_reference"] == "ego"
    assert len(run.frames) == bag.counts[TOPICS["ego"][0]]
    (said,) = [str(p) for p in run.problems if p.field == "reference"]
    assert "tracked_objects (the topic holds no message)" in said
    assert "predictions (the topic holds no message)" in said
    assert "detections_3d (the topic holds no message)" in said


def test_a_recording_with_no_reference_message_is_one_line(tmp_path: Path) -> None:
    store = typestore()
    stray = build(store, "std_msgs/msg/String", {"data": "hello"})
    bag = write_bag(tmp_path / "bag", store, [("/chatter", "std_msgs/msg/String", T0, stray)])
    with pytest.raises(InputError) as error:
        read_recording(bag, "autoware")
    said = str(error.value)
    assert "\n" not in said
    assert said.startswith(f"{bag}: no usable message on the reference input tracked_objects")
    assert "; nor on ego (/localization/kinematic_state): topic" in said


def test_tracks_derived_from_predictions_equal_the_tracks_written(
    run_log: RunLog, bags: dict[str, AutowareBag], runs: dict[str, RunLog]
) -> None:
    """No tracking topic: each frame's tracks are the predicted objects' own kinematics,
    equal to those the tracking topic carries, and to the run's own tracks."""
    derived, recorded = runs["untracked"], runs["legacy"]
    assert derived.inputs["tracked_objects"] == InputStatus(
        "derived",
        f"/perception/object_recognition/objects ({LEGACY_PERCEPTION}PredictedObjects)",
        "from the predicted objects' own kinematics (topic "
        "/perception/object_recognition/tracking/objects not in the bag)",
    )
    assert _objects(derived.tracks_3d) == _objects(recorded.tracks_3d)
    offset = bags["untracked"].object_frames[0]
    compared = 0
    for ts, tracks in derived.tracks_3d.items():
        truth = run_log.tracks_3d[ts + offset]
        assert tracks.ids == tuple(object_uuid(i).hex() for i in truth.ids)
        assert np.allclose(tracks.location, truth.location, atol=1e-9)
        assert np.allclose(tracks.yaw, truth.yaw, atol=1e-9)
        assert np.allclose(tracks.extent, truth.extent, atol=1e-9)
        assert np.allclose(tracks.velocity, np.nan_to_num(truth.velocity), atol=1e-9)
        assert np.allclose(tracks.score, truth.score.astype(np.float32), atol=1e-7)
        compared += len(tracks)
    assert compared > 50


def test_the_mrm_state_is_a_time_series_with_its_change_to_an_emergency(
    bags: dict[str, AutowareBag], runs: dict[str, RunLog]
) -> None:
    run = runs["legacy"]
    assert run.inputs["mrm_state"] == InputStatus(
        "real", "/system/fail_safe/mrm_state (autoware_adapi_v1_msgs/msg/MrmState)"
    )
    states = run.mrm_states
    assert [s.timestamp_ms for s in states] == list(range(0, 100 * len(states), 100))
    first = next(s for s in states if s.emergency)
    assert first.timestamp_ms == EMERGENCY_MS - bags["legacy"].object_frames[0]
    assert (first.state, first.behavior) == ("MRM_OPERATING", "EMERGENCY_STOP")
    before = {(s.state, s.behavior) for s in states if s.timestamp_ms < first.timestamp_ms}
    assert before == {("NORMAL", "NONE")}
    assert all(s.emergency for s in states if s.timestamp_ms >= first.timestamp_ms)
    assert run.metadata.raw["emergency_onsets_ms"] == [first.timestamp_ms]  # on a frame


def test_the_emergency_onsets_are_each_change_to_an_emergency_on_its_nearest_frame() -> None:
    states = tuple(
        MrmState(ms, state, "NONE")
        for ms, state in [
            (0, "MRM_FAILED"),
            (40, "NORMAL"),
            (149, "MRM_OPERATING"),
            (160, "MRM_SUCCEEDED"),
            (250, "NORMAL"),
            (251, "MRM_OPERATING"),
        ]
    )
    assert emergency_onsets(states, 100) == [0, 100, 300]


def test_without_an_mrm_topic_the_input_is_absent_and_named(
    run_log: RunLog, tmp_path: Path
) -> None:
    bag = write_autoware_bag(run_log, tmp_path / "bag", AutowareBagOptions(mrm=False))
    run = read_recording(bag.path, "autoware")
    assert run.mrm_states == () and "emergency_onsets_ms" not in run.metadata.raw
    assert run.inputs["mrm_state"] == InputStatus(
        "absent",
        "/system/fail_safe/mrm_state (autoware_adapi_v1_msgs/msg/MrmState)",
        "topic /system/fail_safe/mrm_state not in the bag",
    )


# --- a profile's types and references --------------------------------------------------------


def _edited_autoware(tmp_path: Path, old: str, new: str) -> Path:
    text = (Path(load_profile("autoware").file)).read_text()
    assert old in text
    path = tmp_path / "mine.yaml"
    path.write_text(text.replace(old, new))
    return path


def test_a_stored_type_the_profile_does_not_list_names_both_and_the_alias(
    bags: dict[str, AutowareBag], tmp_path: Path
) -> None:
    profile = _edited_autoware(
        tmp_path,
        "[autoware_perception_msgs/msg/TrackedObjects, "
        "autoware_auto_perception_msgs/msg/TrackedObjects]",
        "autoware_perception_msgs/msg/TrackedObjects",
    )
    run = read_recording(bags["legacy"].path, str(profile))
    tracking = "/perception/object_recognition/tracking/objects"
    (said,) = [str(p) for p in run.problems if p.field == tracking]
    assert said == (
        f"error: {run.source}: /perception/object_recognition/tracking/objects: stored type "
        f"{LEGACY_PERCEPTION}TrackedObjects, the profile's tracked_objects is "
        f"autoware_perception_msgs/msg/TrackedObjects ({LEGACY_PERCEPTION}TrackedObjects is a "
        "legacy alias of autoware_perception_msgs/msg/TrackedObjects: list it in "
        "inputs.tracked_objects.type to read it) (topic skipped; tracked_objects absent)"
    )
    assert run.inputs["tracked_objects"].state == "derived"  # the predictions still carry them


def test_a_type_mismatch_is_said_before_definitions_are_asked_for(
    run_log: RunLog, tmp_path: Path
) -> None:
    """A pre-Iron bag of current types read by a profile that lists only the legacy
    tracking type: the error asks for the definitions of what it reads, never for the
    tracked objects' (not read), and says why that topic is not read."""
    bag = write_autoware_bag(run_log, tmp_path / "bag", AutowareBagOptions(storage="humble"))
    profile = _edited_autoware(
        tmp_path,
        "[autoware_perception_msgs/msg/TrackedObjects, "
        "autoware_auto_perception_msgs/msg/TrackedObjects]",
        "autoware_auto_perception_msgs/msg/TrackedObjects",
    )
    with pytest.raises(InputError) as error:
        read_recording(bag.path, str(profile))
    lacking, _, mismatch = str(error.value).partition("; and not read as the profile says: ")
    assert "autoware_perception_msgs/msg/PredictedObjects" in lacking
    assert "TrackedObjects" not in lacking
    assert mismatch == (
        "/perception/object_recognition/tracking/objects: stored type "
        "autoware_perception_msgs/msg/TrackedObjects, the profile's tracked_objects is "
        f"{LEGACY_PERCEPTION}TrackedObjects (autoware_perception_msgs/msg/TrackedObjects is "
        f"the current type of {LEGACY_PERCEPTION}TrackedObjects: list it in "
        "inputs.tracked_objects.type to read it)"
    )


_AUTOWARE_INPUT = "inputs:\n  ego: {topic: /ego, type: nav_msgs/msg/Odometry}\n"


@pytest.mark.parametrize(
    ("document", "said"),
    [
        (
            _AUTOWARE_INPUT + "  plan: {topic: /p, type: []}\n",
            "inputs.plan.type: an empty list",
        ),
        (
            _AUTOWARE_INPUT + "  plan: {topic: /p, type: [autoware_planning_msgs/msg/Trajectory, "
            "autoware_planning_msgs/Trajectory]}\n",
            "inputs.plan.type: ['autoware_planning_msgs/msg/Trajectory', "
            "'autoware_planning_msgs/Trajectory'] names a type twice",
        ),
        (
            _AUTOWARE_INPUT + "  plan: {topic: /p, type: [autoware_planning_msgs/msg/Trajectory, "
            "autoware_auto_control_msgs/msg/AckermannControlCommand]}\n",
            "inputs.plan.type: autoware_auto_control_msgs/msg/AckermannControlCommand carries "
            "control, not plan",
        ),
        (
            _AUTOWARE_INPUT + "  mrm_state: {topic: /m, type: std_msgs/msg/String}\n",
            "inputs.mrm_state.type: no decoder for 'std_msgs/msg/String'",
        ),
        (
            "reference: [tracked_objects, ego]\n" + _AUTOWARE_INPUT,
            "reference: 'tracked_objects' is not an input of the profile",
        ),
        ("reference: []\n" + _AUTOWARE_INPUT, "reference: an empty list"),
        ("reference: [ego, ego]\n" + _AUTOWARE_INPUT, "reference: ['ego', 'ego'] names an input"),
        (
            "reference: mrm_state\n"
            + _AUTOWARE_INPUT
            + "  mrm_state: {topic: /m, type: autoware_adapi_v1_msgs/msg/MrmState}\n",
            "reference: 'mrm_state' is not an input of the profile among",
        ),
        (
            _AUTOWARE_INPUT + "metadata: {ego_size: [4.9, 0, 1.6]}\n",
            "metadata.ego_size: [4.9, 0, 1.6] is not [length, width, height] in m, each above 0",
        ),
        (
            _AUTOWARE_INPUT + "metadata: {ego_box_offset: far}\n",
            "metadata.ego_box_offset: 'far' is not a number (m)",
        ),
    ],
)
def test_type_lists_references_and_vehicle_facts_are_checked_in_one_line(
    tmp_path: Path, document: str, said: str
) -> None:
    path = tmp_path / "mine.yaml"
    path.write_text("profile: mine\n" + document)
    with pytest.raises(ConfigError) as error:
        load_profile(path)
    assert str(error.value).startswith(f"{path}: {said}")
    assert "\n" not in str(error.value)


def test_the_autoware_profile_takes_current_and_legacy_types() -> None:
    profile = load_profile("autoware")
    assert profile.references == ("tracked_objects", "predictions", "detections_3d", "ego")
    assert "actors" not in profile.inputs and "collision" not in profile.inputs
    for name in ("detections_3d", "tracked_objects", "predictions", "plan", "control"):
        spec = profile.inputs[name]
        assert len(spec.types) == 2 and LEGACY_ALIASES[spec.types[1]] == spec.types[0]
    assert profile.inputs["mrm_state"].types == ("autoware_adapi_v1_msgs/msg/MrmState",)


# --- hostile values --------------------------------------------------------------------------


def _predicted_object(uuid: list[int], x: float, paths: list[Any], twist_x: float) -> Any:
    pose = {"position": {"x": x, "y": 2.0}, "orientation": {"w": 1.0}}
    return {
        "object_id": {"uuid": uuid},
        "existence_probability": 0.9,
        "classification": [{"label": 1, "probability": 1.0}],
        "kinematics": {
            "initial_pose_with_covariance": {"pose": pose},
            "initial_twist_with_covariance": {"twist": {"linear": {"x": twist_x}}},
            "predicted_paths": paths,
        },
        "shape": {"dimensions": {"x": 4.0, "y": 2.0, "z": 1.5}},
    }


def _prediction_bag(path: Path, store: Typestore, objects: list[list[Any]], type_name: str) -> Path:
    """One PredictedObjects message per 100 ms frame (the objects given), with the ego."""
    messages = []
    for f, frame_objects in enumerate(objects):
        t = T0 + f * 100 * MS
        ego = {"header": header(t), "pose": {"pose": {"orientation": {"w": 1.0}}}}
        messages.append(
            (TOPICS["ego"][0], TOPICS["ego"][1], t, build(store, "nav_msgs/msg/Odometry", ego))
        )
        predicted = {"header": header(t), "objects": frame_objects}
        messages.append(
            (TOPICS["predictions"][0], type_name, t, build(store, type_name, predicted))
        )
    return write_bag(path, store, messages)


def _path(points: int) -> dict[str, Any]:
    poses = [{"position": {"x": 10.0 + j}, "orientation": {"w": 1.0}} for j in range(points)]
    return {"path": poses, "time_step": {"nanosec": 100_000_000}, "confidence": 1.0}


def test_nan_kinematics_spoil_only_that_frames_derived_tracks(tmp_path: Path) -> None:
    store = typestore()
    uuid = list(range(16))
    frames = [[_predicted_object(uuid, 10.0, [_path(5)], nan)] for nan in (1.0, math.nan, 1.0)]
    legacy = LEGACY_PERCEPTION + "PredictedObjects"
    bag = _prediction_bag(tmp_path / "bag", store, frames, legacy)
    run = read_recording(bag, "autoware")
    assert sorted(run.predictions) == [0, 100, 200]  # the paths are fine
    assert sorted(run.tracks_3d) == [0, 200]
    (said,) = [str(p) for p in run.problems if "derived" in str(p)]
    assert f"message at log time {T0 + 100 * MS} ns" in said
    assert said.endswith(
        "no tracked objects derived from this "
        f"{legacy}: objects[0].kinematics.initial_twist_with_covariance.twist.linear.x: nan, "
        "not a finite number (no derived tracked objects)"
    )


def test_zero_and_one_point_paths_predict_nothing_and_still_give_tracks(tmp_path: Path) -> None:
    store = typestore()
    objects = [
        _predicted_object([1] * 16, 10.0, [_path(0)], 1.0),
        _predicted_object([2] * 16, 20.0, [_path(1)], 1.0),
        _predicted_object([3] * 16, 30.0, [], 1.0),
    ]
    bag = _prediction_bag(
        tmp_path / "bag", store, [objects, objects], LEGACY_PERCEPTION + "PredictedObjects"
    )
    run = read_recording(bag, "autoware")
    assert [p for p in run.problems if p.severity == "error"] == []
    for ts in (0, 100):
        assert all(track.keys == () for track in run.predictions[ts].values())
        assert run.tracks_3d[ts].location[:, 0].tolist() == [10.0, 20.0, 30.0]


def test_a_uuid_of_the_wrong_length_is_one_message_named(tmp_path: Path) -> None:
    """A bag whose own UUID is a sequence: 15 bytes are refused, naming the field."""
    kept = {
        k: v for k, v in typestore().fielddefs.items() if k != "unique_identifier_msgs/msg/UUID"
    }
    store = get_typestore(Stores.EMPTY)
    store.register(kept)
    store.register(get_types_from_msg("uint8[] uuid\n", "unique_identifier_msgs/msg/UUID"))
    objects = [[_predicted_object(list(range(n)), 10.0, [_path(3)], 1.0)] for n in (16, 15, 16)]
    bag = _prediction_bag(tmp_path / "bag", store, objects, LEGACY_PERCEPTION + "PredictedObjects")
    run = read_recording(bag, "autoware")
    assert sorted(run.predictions) == [0, 200]
    (said,) = [str(p) for p in run.problems if "object_id.uuid" in str(p)]
    assert said.endswith("objects[0].object_id.uuid: 15 values, not 16 bytes (message skipped)")


def test_a_legacy_definition_other_than_the_shipped_one_is_one_line(tmp_path: Path) -> None:
    """The bag's own TrackedObject lacks the existence probability the decoder reads: the
    topic is skipped in one line naming the topic, the type, the field and where the
    definition came from; the ego then times the frames."""
    tracked = LEGACY_PERCEPTION + "TrackedObject"
    store = get_typestore(Stores.EMPTY)
    store.register({k: v for k, v in typestore().fielddefs.items() if k != tracked})
    store.register(
        get_types_from_msg(
            "unique_identifier_msgs/UUID object_id\n"
            "autoware_auto_perception_msgs/ObjectClassification[] classification\n"
            "autoware_auto_perception_msgs/TrackedObjectKinematics kinematics\n"
            "autoware_auto_perception_msgs/Shape shape\n",
            tracked,
        )
    )
    messages = []
    for f in range(3):
        t = T0 + f * 100 * MS
        ego = {"header": header(t), "pose": {"pose": {"orientation": {"w": 1.0}}}}
        messages.append(
            (TOPICS["ego"][0], TOPICS["ego"][1], t, build(store, TOPICS["ego"][1], ego))
        )
        pose = {"pose": {"orientation": {"w": 1.0}}}
        kinematics = {"pose_with_covariance": pose}
        objects = {
            "header": header(t),
            "objects": [{"object_id": {"uuid": list(range(16))}, "kinematics": kinematics}],
        }
        messages.append(
            (TOPICS["tracked_objects"][0], tracked + "s", t, build(store, tracked + "s", objects))
        )
    bag = write_bag(tmp_path / "bag", store, messages)
    run = read_recording(bag, "autoware")
    said = [str(p) for p in run.problems if p.severity == "error"]
    assert len(said) == 1
    assert said[0].endswith(
        f"/perception/object_recognition/tracking/objects: {tracked}s has no field "
        "objects[0].existence_probability in the bag's own definition, another layout than "
        "the one shipped with ads_rca: its messages cannot be read as tracked_objects (topic "
        "skipped; tracked_objects absent)"
    )
    assert run.inputs["tracked_objects"].state == "absent"
    assert run.metadata.raw["frame_reference"] == "ego"


@pytest.mark.parametrize("variant", ["legacy", "untracked"])
@pytest.mark.parametrize("mode", ["reference", "corrected"])
def test_inspect_says_what_diagnose_will_judge(
    bags: dict[str, AutowareBag], runs: dict[str, RunLog], variant: str, mode: str
) -> None:
    """What inspect promises for the recommended profile is what diagnose then judges: the
    stack's tracks (derived from predicted objects when untracked) stand in for the world."""
    from ads_rca.commands.inspect_cmd import judged_with
    from ads_rca.diagnosis.engine import diagnose
    from ads_rca.params import make_params
    from ads_rca.sources.bag.survey import survey_bag

    survey = survey_bag(bags[variant].path)
    assert survey.recommendation is not None and survey.recommendation.profile == "autoware"
    fit = next(f for f in survey.fits if f.profile == "autoware")
    promised = judged_with(fit.mapped)[mode]
    judged = diagnose(runs[variant], make_params(mode)).to_json(include_frames=False)
    assert promised == judged["modules_judged"]


def test_a_starting_profile_times_the_frames_by_perception(
    bags: dict[str, AutowareBag], runs: dict[str, RunLog], tmp_path: Path
) -> None:
    """Without ground truth the tracks are the world: the written profile's frames follow
    perception (10 Hz), as the built-in autoware profile's do, not localisation (50 Hz)."""
    from ads_rca.sources.bag.survey import starting_profile, survey_bag

    text = starting_profile(survey_bag(bags["legacy"].path), "my-car")
    assert "reference: [tracked_objects, predictions, detections_3d, ego]" in text
    profile = tmp_path / "my-car.yaml"
    profile.write_text(text)
    written = read_recording(bags["legacy"].path, str(profile))
    assert written.frame_ms == runs["legacy"].frame_ms == 100
    assert written.unique_frames == runs["legacy"].unique_frames
