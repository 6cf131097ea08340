"""3-D detections, tracked objects and control commands (the optional folders) on
every path the running log's folders take: messages and CDR both ways, the assembler, log
folders, bags, and player → DDS → topic_summary and recorder. A running log without them
sends, lists and writes exactly what it did before they existed.

The codecs' byte equality with rclpy is in test_contract_cdr.py and
test_contract_topic_table.py (their logs carry these folders too); here: the exact values,
the wire layout docs/topics.md promises, messages from other publishers, and hostile folder
files.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pytest
from logcompare import assert_logs_equal
from logfactory import add_3d, awkward_log, make_log, play_through_assembler
from rclpy.serialization import serialize_message

from ads_rca.contract import playback, topics
from ads_rca.contract.errors import MalformedMessage
from ads_rca.model import (
    ALL_FOLDERS,
    OPTIONAL_FOLDERS,
    ControlCommand,
    InputStatus,
    Objects3D,
    RunLog,
)
from ads_rca.sources.bag.reader import iter_bag, read_bag
from ads_rca.sources.bag.writer import write_bag
from ads_rca.sources.log.reader import read_run_log
from ads_rca.sources.log.writer import write_run_log

if TYPE_CHECKING:
    from conftest import RosEnv

OPTIONAL_TOPICS = tuple(t.key for t in topics.TABLE if t.optional and t.folder)


def log_3d(seed: int = 0, **options: bool) -> RunLog:
    return add_3d(make_log(14, 7, seed, orphan_stamps=True, **options), seed)


def only_optional(log: RunLog) -> RunLog:
    """The log's optional folders alone (so a comparison shows exactly those)."""
    return RunLog.from_folders(
        log.metadata, (), {f: log.folder(f) for f in OPTIONAL_FOLDERS}, source=log.source
    )


# --- the wire -------------------------------------------------------------------------------


@pytest.mark.parametrize("serialise", [False, True])
def test_log_to_messages_to_log_is_exact(serialise: bool) -> None:
    log = log_3d(1, duplicate_frame=True)
    assembler = play_through_assembler(log, serialise=serialise)
    assert assembler.complete()
    assert_logs_equal(log, assembler.build())


def test_awkward_values_come_back_exactly_on_both_paths() -> None:
    """NaN, ±inf, -0.0, subnormals, a yaw of 540°, unicode, empty records: the same values
    (NaN equal to NaN) from the message object and from our bytes."""
    log = awkward_log()
    expected = only_optional(log)
    for topic in topics.DATA:
        if not topic.optional:
            continue
        folder = log.folder(str(topic.folder))
        assert folder, topic.key
        for stamp, record in folder.items():
            msg = topic.codec.build(record, stamp, log.frame_ms)
            for back in (
                topic.codec.read(msg, log.frame_ms),
                topic.codec.decode(topic.codec.encode(record, stamp, log.frame_ms), log.frame_ms),
                topic.codec.decode(serialize_message(msg), log.frame_ms),
            ):
                rebuilt = only_optional(log)
                rebuilt.folder(str(topic.folder))[stamp] = back
                assert_logs_equal(expected, rebuilt)
    assert log.detections_3d[0].yaw[2] == 540.0  # not wrapped: the yaw rides in the text


def test_wire_layout_is_what_the_docs_say() -> None:
    objects = Objects3D(
        ("17", "walker"),
        np.array([[1.0, 2.0, 3.0], [4.0, -5.0, 6.0]]),
        np.array([90.0, -30.0]),
        np.array([[2.0, 1.0, 0.5], [0.3, 0.3, 0.9]]),
        np.array([[1.0, 2.0, 0.0], [math.nan, 0.5, math.nan]]),
        np.array([0.9, math.nan]),
        ("CAR", "PEDESTRIAN"),
    )
    msg = topics.TOPICS[topics.TRACKS_3D].codec.build(objects, 1050, 50)
    deleteall, first, second = msg.markers
    assert deleteall.action == 3 and deleteall.ns == "tracks_3d"
    assert (first.id, first.type, first.header.frame_id) == (0, 1, "map")
    p = first.pose.position
    assert (p.x, p.y, p.z) == (1.0, -2.0, 3.0)
    assert (first.scale.x, first.scale.y, first.scale.z) == (4.0, 2.0, 1.0)
    o = first.pose.orientation  # ROS yaw -90°: a quarter turn clockwise about z
    assert np.allclose([o.x, o.y, o.z, o.w], [0.0, 0.0, -math.sqrt(0.5), math.sqrt(0.5)])
    assert json.loads(first.text) == {
        "id": "17",
        "label": "CAR",
        "score": 0.9,
        "yaw_deg": -90.0,
        "velocity": [1.0, -2.0, 0.0],
    }
    assert json.loads(second.text) == {
        "id": "walker",
        "label": "PEDESTRIAN",
        "score": None,
        "yaw_deg": 30.0,
        "velocity": [None, -0.5, None],
        "$nonfinite": {"/score": "nan", "/velocity/0": "nan", "/velocity/2": "nan"},
    }
    command = topics.TOPICS[topics.CONTROL_COMMAND].codec.build(
        ControlCommand(steer=12.5, acceleration=-3.0, speed=8.0), 1050, 50
    )
    assert (command.header.stamp.sec, command.header.stamp.nanosec) == (1, 50_000_000)
    assert command.name == ["steering_tire_angle_deg", "acceleration", "speed"]
    assert list(command.position) == [-12.5, -3.0, 8.0]  # + left in ROS: the sign flips
    assert list(command.velocity) == list(command.effort) == []


def test_other_publishers_messages_are_read_or_refused_in_one_way() -> None:
    """A stack's markers without our text keys, a JointState with other names: read by
    what is there; a text that is no object's, positions short of names: malformed."""
    from sensor_msgs.msg import JointState

    codec = topics.TOPICS[topics.OBJECTS_3D].codec
    objects = log_3d().detections_3d[50]
    msg = codec.build(objects, 50, 50)
    for marker in msg.markers[1:]:
        marker.text = ""
    back = codec.decode(serialize_message(msg), 50)
    assert back.ids == tuple(str(i) for i in range(len(objects)))
    assert back.labels == ("",) * len(objects)
    assert np.isnan(back.score).all() and np.isnan(back.velocity).all()
    np.testing.assert_allclose(back.yaw, objects.yaw, atol=1e-9)  # from the quaternion
    assert np.array_equal(back.location, objects.location)
    for text in ('{"velocity": [1, 2]}', '{"label": 3}', '{"score": "high"}', "[1]", "{"):
        msg.markers[1].text = text
        with pytest.raises(MalformedMessage):
            codec.decode(serialize_message(msg), 50)
        with pytest.raises(MalformedMessage):
            codec.read(msg, 50)
    control = topics.TOPICS[topics.CONTROL_COMMAND].codec
    other = JointState(name=["speed", "wheel", "acceleration"], position=[3.0, 9.0, -1.0])
    got = control.decode(serialize_message(other), 50)
    assert math.isnan(got.steer) and (got.acceleration, got.speed) == (-1.0, 3.0)
    from_object = control.read(other, 50)
    assert math.isnan(from_object.steer)
    assert (from_object.acceleration, from_object.speed) == (-1.0, 3.0)
    short = JointState(name=["speed", "acceleration"], position=[3.0])
    with pytest.raises(MalformedMessage, match="2 names, 1 positions"):
        control.decode(serialize_message(short), 50)
    with pytest.raises(MalformedMessage):
        control.decode(serialize_message(other)[:40], 50)


def test_a_running_log_without_them_sends_exactly_what_it_did() -> None:
    log = make_log(10, 4, 3, duplicate_frame=True, orphan_stamps=True)
    no_notes = tuple(
        k for k in topics.ALL_TOPICS if k not in (topics.ANNOTATIONS, topics.EGO_PATHS)
    )  # a CARLA run's annotations, a snapshot table's paths
    assert topics.advertised(log) == tuple(k for k in no_notes if k not in OPTIONAL_TOPICS)
    for tick in playback.timeline(log):
        names = playback.published_names(topics.frame_payloads(log, tick.stamp_ms))
        assert not set(names) & set(OPTIONAL_TOPICS)
    with_3d = add_3d(make_log(10, 4, 3, duplicate_frame=True, orphan_stamps=True), 3)
    assert topics.advertised(with_3d) == no_notes
    # The optional folders add ticks only at their own stamps (a records-only control).
    plain = [t.stamp_ms for t in playback.timeline(log)]
    extra = [t.stamp_ms for t in playback.timeline(with_3d)]
    assert sorted(set(extra) - set(plain)) == [log.frames[-1] + 7]
    with_3d.detections_3d.clear()
    with_3d.controls.clear()
    assert topics.advertised(with_3d) == tuple(
        k for k in no_notes if k not in (topics.OBJECTS_3D, topics.CONTROL_COMMAND)
    )


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_bags_carry_them_and_declare_them_only_when_there(tmp_path: Path, storage: str) -> None:
    log = log_3d(2)
    counts = write_bag(log, tmp_path / "with", storage)
    names = {key: topics.topic_name(key) for key in OPTIONAL_TOPICS}
    # 3-D detections, tracks, control commands; lane graphs on 3 frames in 4, predicted
    # ones on every third
    assert [counts[names[key]] for key in OPTIONAL_TOPICS] == [12, 7, 10 + 1, 11, 5]
    assert_logs_equal(log, read_bag(tmp_path / "with"))
    write_bag(make_log(6, 3, 2), tmp_path / "without", storage)
    assert not {m.topic for m in iter_bag(tmp_path / "without")} & set(names.values())
    text = (tmp_path / "without" / "metadata.yaml").read_text()  # not declared either
    assert "/ads_rca/perception/detections" in text
    assert not [name for name in names.values() if name in text]


def test_a_monitor_whose_oracle_reads_them_holds_them(monkeypatch: pytest.MonkeyPatch) -> None:
    """The live window keeps an optional folder an oracle names (the 3-D rule will), waits
    for it where a frame marker lists it, and hands it to the oracle in its view."""
    from ads_rca.contract.assembler import run_metadata
    from ads_rca.live.results import FrameMarker
    from ads_rca.live.window import MonitorCore
    from ads_rca.oracles.semantics import Semantics, semantics_for
    from ads_rca.params import make_params

    params = make_params("corrected")
    semantics = semantics_for(params)
    monkeypatch.setattr(
        type(semantics),
        "folders",
        lambda _self, _module: ("actors", "tracks_3d", "pose"),
    )
    assert isinstance(semantics, Semantics)
    core = MonitorCore("perception", params)
    assert core.folders == ("pose", "actors", "tracks_3d")  # in ALL_FOLDERS order
    log = log_3d(9)
    log.inputs = {"tracked_objects": InputStatus("real", "/perception/tracks")}
    core.set_metadata(run_metadata(json.loads(playback.metadata_message(log).data)), 0.0)
    late = log.frames[4]  # its tracks arrive after its marker: the frame waits for them
    assert late in log.tracks_3d
    for index, ts in enumerate(log.frames[:6]):
        for folder in ALL_FOLDERS:  # what the player sends; the core keeps its own folders
            record = log.folder(folder).get(ts)
            if record is not None and (ts, folder) != (late, "tracks_3d"):
                core.add_record(folder, ts, record, 0.1)
        folders = frozenset(f for f in ALL_FOLDERS if ts in log.folder(f))
        core.add_marker(FrameMarker(index, ts, folders), 0.1)
        if ts == late:
            assert core.complete_through == log.frames[3]
            core.add_record("tracks_3d", ts, log.tracks_3d[ts], 0.2)
            assert core.complete_through == late
    view = core.view()
    assert view.inputs == log.inputs  # from run/metadata, as the player sends it
    assert sorted(view.tracks_3d) == [ts for ts in log.frames[:6] if ts in log.tracks_3d]
    assert not view.detections_3d and not view.controls
    expected = only_optional(log)
    expected.metadata = view.metadata  # the document's, with model_inputs
    expected.detections_3d.clear()
    expected.controls.clear()
    expected.lanes.clear()
    expected.lanes_predicted.clear()
    for ts in list(expected.tracks_3d):
        if ts not in view.tracks_3d:
            del expected.tracks_3d[ts]
    assert_logs_equal(expected, only_optional(view), check_frames=False)


# --- log folders ----------------------------------------------------------------------------


def test_log_folder_round_trip_is_exact(tmp_path: Path) -> None:
    log = log_3d(5)
    root = write_run_log(log, tmp_path / "log")
    assert sorted(p.name for p in root.iterdir() if p.is_dir()) == sorted(ALL_FOLDERS)
    first = json.loads((root / "detections_3d" / "detections_3d-50.json").read_bytes())
    assert set(first["d0"]) == {"location", "rotation", "extent", "velocity", "score", "label"}
    back = read_run_log(root)
    assert_logs_equal(log, back)
    plain = read_run_log(write_run_log(make_log(14, 7, 5, orphan_stamps=True), tmp_path / "p"))
    assert [str(p) for p in back.problems] == [str(p) for p in plain.problems]
    assert back.file_of("control", 100) == "control/control-100.json"


def test_absent_folders_are_neither_written_nor_reported(tmp_path: Path) -> None:
    root = write_run_log(make_log(6, 3, 1), tmp_path / "log")
    assert not any((root / f).exists() for f in OPTIONAL_FOLDERS)
    log = read_run_log(root)
    assert not any(p.file.startswith(OPTIONAL_FOLDERS) for p in log.problems)
    assert not (log.detections_3d or log.tracks_3d or log.controls)


def _object(**changes: Any) -> dict[str, Any]:
    entry: dict[str, Any] = {
        "location": {"x": 1.0, "y": 2.0, "z": 0.5},
        "rotation": {"yaw": 10.0},
        "extent": {"x": 2.0, "y": 1.0, "z": 0.8},
        "velocity": {"x": 1.0, "y": None, "z": 0.0},
        "score": None,
        "label": "CAR",
    }
    entry.update(changes)
    return entry


HOSTILE: list[tuple[str, str, str]] = [
    # (file text, field, issue)
    (
        '{"7": {"location": {"x": NaN, "y": 0, "z": 0}, "rotation": {"yaw": 0},'
        ' "extent": {"x": 1, "y": 1, "z": 1}}}',
        "7.location.x",
        "nan is not a finite number",
    ),
    (
        json.dumps({"7": _object(location={"x": "1", "y": 0, "z": 0})}),
        "7.location.x",
        "'1' is not a number",
    ),
    (json.dumps({"7": _object(extent={"x": 1, "y": 1})}), "7.extent.z", "missing"),
    (json.dumps({"7": _object(rotation={"yaw": True})}), "7.rotation.yaw", "True is not a number"),
    (json.dumps({"7": _object(rotation=None)}), "7.rotation", "expected an object, found NoneType"),
    (
        json.dumps({"7": _object(velocity=[1, 2, 3])}),
        "7.velocity",
        "expected an object, found a list",
    ),
    (json.dumps({"7": _object(score="0.5")}), "7.score", "'0.5' is not a number"),
    (json.dumps({"7": _object(label=3)}), "7.label", "3 is not text"),
    # Values numpy would take for numbers (a boolean as 1 or 0, an infinite score as NaN
    # is): the whole-file conversion must leave them to the value-by-value reader.
    (json.dumps({"7": _object(score=False)}), "7.score", "False is not a number"),
    (
        json.dumps({"7": _object(velocity={"x": 1.0, "y": True, "z": 0})}),
        "7.velocity.y",
        "True is not a number",
    ),
    (
        json.dumps({"7": _object(), "8": _object(score=math.inf)}),
        "8.score",
        "inf is not a finite number",
    ),
    (json.dumps({"7": _object(label=None)}), "7.label", "None is not text"),
    (json.dumps({"7": [1, 2]}), "7", "expected an object, found a list"),
    ("[1, 2]", "", "expected an object, found a list"),
]


@pytest.mark.parametrize(("text", "field", "issue"), HOSTILE)
def test_a_bad_value_skips_that_file_of_that_folder_only(
    tmp_path: Path, text: str, field: str, issue: str
) -> None:
    log = log_3d(6)
    root = write_run_log(log, tmp_path / "log")
    ts = 100
    file = f"detections_3d/detections_3d-{ts}.json"
    (root / file).write_text(text)
    back = read_run_log(root)
    found = [p for p in back.problems if p.file == file]
    assert [(p.field, p.issue, p.action, p.severity, p.timestamp_ms) for p in found] == [
        (field, issue, "file skipped", "error", ts)
    ]
    assert ts not in back.detections_3d
    del log.detections_3d[ts]
    assert_logs_equal(log, back)  # every other folder, that frame included, as written


def test_a_clean_file_reads_each_value_as_written(tmp_path: Path) -> None:
    log = log_3d(6)
    root = write_run_log(log, tmp_path / "log")
    file = root / "detections_3d/detections_3d-100.json"
    entries = {
        "7": _object(),  # velocity y unknown (null), score null
        "9": {  # integers, no velocity, score or label at all
            "location": {"x": 3, "y": -4, "z": 0},
            "rotation": {"yaw": -90},
            "extent": {"x": 1, "y": 2, "z": 3},
        },
        "8": _object(velocity=None, score=0.25, label="PEDESTRIAN"),
    }
    file.write_text(json.dumps(entries))
    back = read_run_log(root)
    assert [p for p in back.problems if "detections_3d" in p.file] == []
    objects = back.detections_3d[100]
    assert objects.ids == ("7", "9", "8") and objects.labels == ("CAR", "", "PEDESTRIAN")
    assert objects.location.tolist() == [[1.0, 2.0, 0.5], [3.0, -4.0, 0.0], [1.0, 2.0, 0.5]]
    assert objects.yaw.tolist() == [10.0, -90.0, 10.0]
    assert objects.extent.tolist() == [[2.0, 1.0, 0.8], [1.0, 2.0, 3.0], [2.0, 1.0, 0.8]]
    velocity = objects.velocity
    assert velocity[0, 0] == 1.0 and velocity[0, 2] == 0.0
    assert np.isnan(velocity[0, 1]) and np.isnan(velocity[1:]).all()
    assert np.isnan(objects.score[:2]).all() and objects.score[2] == 0.25
    assert all(a.dtype == np.float64 and a.flags.c_contiguous for a in (objects.location, velocity))


def test_control_files_are_strict_too(tmp_path: Path) -> None:
    log = log_3d(7)
    root = write_run_log(log, tmp_path / "log")
    (root / "control" / "control-50.json").write_text('{"steer": 1, "speed": "fast"}')
    (root / "control" / "control-100.json").write_text('{"steer": null}')
    back = read_run_log(root)
    assert [(p.file, p.field, p.issue) for p in back.problems if p.file.startswith("control")] == [
        ("control/control-50.json", "speed", "'fast' is not a number")
    ]
    assert 50 not in back.controls
    got = back.controls[100]
    assert math.isnan(got.steer) and math.isnan(got.acceleration) and math.isnan(got.speed)


def test_where_the_inputs_came_from_survives_folders_bags_and_messages(tmp_path: Path) -> None:
    """A recording's ``inputs`` (real / derived / assumed / absent) ride in metadata.json's
    ``model_inputs``, hence in run/metadata: a folder or replay of it says the same."""
    log = log_3d(10)
    log.inputs = {
        "ego": InputStatus("real", "/carla/ego_vehicle/odometry (nav_msgs/msg/Odometry)"),
        "predictions_gt": InputStatus("absent", "", "not in the carla-autoware profile"),
        "ground_truth_2d": InputStatus("assumed", "x", "é"),
    }
    folder = read_run_log(write_run_log(log, tmp_path / "log"))
    assert folder.inputs == log.inputs
    assert play_through_assembler(folder, serialise=True).build().inputs == log.inputs
    write_bag(folder, tmp_path / "bag")
    assert read_bag(tmp_path / "bag").inputs == log.inputs
    plain = read_run_log(write_run_log(make_log(3, 2, 0), tmp_path / "plain"))
    assert plain.inputs == {}
    assert "model_inputs" not in (tmp_path / "plain" / "metadata.json").read_text()
    document = json.loads((tmp_path / "log" / "metadata.json").read_text())
    document["model_inputs"]["ego"] = {"state": "guessed"}
    document["model_inputs"]["plan"] = {"state": "real", "source": 3}
    (tmp_path / "log" / "metadata.json").write_text(json.dumps(document))
    hostile = read_run_log(tmp_path / "log")
    assert [(p.file, p.field, p.action) for p in hostile.problems if "inputs" in p.field] == [
        ("metadata.json", "model_inputs.ego", "ignored"),
        ("metadata.json", "model_inputs.plan", "ignored"),
    ]
    assert set(hostile.inputs) == {"predictions_gt", "ground_truth_2d"}


# --- over DDS -------------------------------------------------------------------------------


@pytest.mark.timeout(150)
def test_player_dds_summary_and_recorder_keep_every_value(ros_env: RosEnv, tmp_path: Path) -> None:
    """The player sends a 3-D log; topic_summary (raw CDR, assembler, log-folder writer) and
    the recorder (bag) both give it back exactly."""
    from rosrun import SUMMARY, recorded_counts, start_player, start_recorder

    from ads_rca.ros.launcher import Launcher, node_command

    log = log_3d(8)
    log_dir = write_run_log(log, tmp_path / "log")
    bag, out, ns = tmp_path / "bag", tmp_path / "rebuilt", ros_env.namespace
    summary_params: dict[str, Any] = {
        "topic_namespace": ns,
        "output_json": True,
        "output_dir": str(out),
        "timeout_s": 60.0,
    }
    with Launcher(ros_env.env, echo=sys.stderr) as launcher:
        recorder = start_recorder(launcher, bag, ns, stop_on_finished=True)
        summary = launcher.start("topic_summary", node_command(SUMMARY, summary_params))
        player = start_player(launcher, log_dir, ns, wait_for_subscribers=2)
        assert player.wait(90) == 0, player.output
        assert summary.wait(60) == 0, summary.output
        assert recorder.wait(60) == 0, recorder.output
    original = read_run_log(log_dir)
    assert_logs_equal(original, read_run_log(out))
    assert_logs_equal(original, read_bag(bag))
    counts = recorded_counts(bag, ns)
    assert [counts[key] for key in OPTIONAL_TOPICS] == [
        len(log.detections_3d),
        len(log.tracks_3d),
        len(log.controls),
        len(log.lanes),
        len(log.lanes_predicted),
    ]
