"""Synthesised runs written as recordings of real stacks (the recording readers' fixtures)
read back with rosbags' own reader, independently of ours, and checked against the run exactly.

Each profile × storage: message counts per topic, the decoded fields of every type against
the model (the CARLA → ROS ``map`` flip, full sizes, uuids, predicted paths in the map
frame), the header stamps, and the stored definitions equal to the shipped ``.msg`` text.
The synthesiser has no 3-D perception or control yet, so those records are added to the
synthesised run here (from its ground truth), to test their writers too.
"""

from __future__ import annotations

import math
import sqlite3
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.interfaces import MessageDefinitionFormat

from ads_rca.cli import main
from ads_rca.errors import ConfigError
from ads_rca.model import Actors, ControlCommand, Objects3D, RunLog
from ads_rca.sources.errors import OutputExists
from ads_rca.synth import synthesise_run
from ads_rca.synth.recording import (
    EPOCH_NS,
    MSG_DIR,
    PROFILES,
    actor_numbers,
    object_uuid,
    path_headings,
    profile_topics,
    write_recording,
)

SEPARATOR = "=" * 80 + "\n"
#: Object velocities given to the added 3-D records (CARLA world m/s): not along any axis,
#: so a missing body-frame rotation or y flip shows.
VELOCITY = np.array([3.0, -4.0, 0.0])


def _objects(actors: Actors, prefix: str, ego: str) -> Objects3D:
    """The non-ego actors as 3-D objects (ids ``prefix + actor id``); the last one's
    velocity unknown."""
    rows = [i for i, actor_id in enumerate(actors.ids) if actor_id != ego]
    velocity = np.tile(VELOCITY, (len(rows), 1))
    velocity[-1] = np.nan
    return Objects3D(
        ids=tuple(prefix + actors.ids[i] for i in rows),
        location=actors.location[rows],
        yaw=actors.rotation[rows, 2],
        extent=actors.extent[rows],
        velocity=velocity,
        score=np.linspace(0.5, 0.9, len(rows)),
        labels=tuple("vehicle" if i % 2 else "pedestrian" for i in range(len(rows))),
    )


def _tracks(actors: Actors, ego: str, predicted: list[str]) -> Objects3D:
    """The non-ego actors as tracks, the first ones under predicted ids, so that some
    predicted objects are tracked and (at least one) are not."""
    objects = _objects(actors, "", ego)
    ids = list(objects.ids)
    n = max(0, min(len(ids), len(predicted)) - 1)
    ids[:n] = predicted[:n]
    return replace(objects, ids=tuple(ids))


def _with_3d(log: RunLog, ego: str) -> RunLog:
    """``log`` plus 3-D detections and tracks of its actors and control commands."""
    tracks = {
        ts: _tracks(a, ego, list(log.predictions.get(ts, {}))) for ts, a in log.actors.items()
    }
    return replace(
        log,
        detections_3d={ts: _objects(a, "d", ego) for ts, a in log.actors.items()},
        tracks_3d=tracks,
        controls={
            ts: ControlCommand(steer=10.0 - 0.1 * i, acceleration=-2.5, speed=p.speed)
            for i, (ts, p) in enumerate(sorted(log.pose.items()))
        },
    )


@pytest.fixture(scope="module")
def run() -> tuple[RunLog, dict[str, Any]]:
    log, summary = synthesise_run("cut_in", "perception", 0)
    return _with_3d(log, summary["ego_id"]), dict(summary)


Read = dict[str, list[tuple[int, Any]]]


def _read(bag: Path) -> tuple[Read, dict[str, tuple[MessageDefinitionFormat, str]]]:
    """Messages per topic (log time, decoded) and each topic's stored definition."""
    messages: Read = {}
    with AnyReader([bag]) as reader:
        definitions = {c.topic: (c.msgdef.format, c.msgdef.data) for c in reader.connections}
        for connection, log_time, raw in reader.messages():
            decoded = reader.deserialize(raw, connection.msgtype)
            messages.setdefault(connection.topic, []).append((log_time, decoded))
    return messages, definitions


@pytest.fixture(scope="module")
def bags(
    run: tuple[RunLog, dict[str, Any]], tmp_path_factory: pytest.TempPathFactory
) -> dict[tuple[str, str], tuple[dict[str, int], Read, dict[str, Any]]]:
    log, _ = run
    out = {}
    for profile in PROFILES:
        for storage in ("mcap", "sqlite3"):
            bag = tmp_path_factory.mktemp("bags") / f"{profile}_{storage}"
            counts = write_recording(log, bag, profile, storage)
            out[profile, storage] = (counts, *_read(bag))
    return out


CASES = [(p, s) for p in PROFILES for s in ("mcap", "sqlite3")]


def _stamp(header_or_time: Any) -> int:
    t = getattr(header_or_time, "stamp", header_or_time)
    return int(t.sec) * 10**9 + int(t.nanosec)


def _ms(log_time: int) -> int:
    assert (log_time - EPOCH_NS) % 1_000_000 == 0
    return (log_time - EPOCH_NS) // 1_000_000


def _map_yaw(q: Any) -> float:
    """Yaw of a planar quaternion (roll = pitch = 0), radians."""
    return 2.0 * math.atan2(q.z, q.w)


def _carla_xy(p: Any) -> np.ndarray:
    return np.array([p.x, -p.y])


@pytest.mark.parametrize(("profile", "storage"), CASES)
def test_every_input_of_the_run_is_one_topic_with_one_message_per_record(
    bags: Any, run: Any, profile: str, storage: str
) -> None:
    log, _ = run
    counts, messages, _ = bags[profile, storage]
    expected = {
        "clock": len(log.unique_frames),
        "ego": len(log.pose),
        "actors": len(log.actors),
        "collision": 1,
        "detections_3d": len(log.detections_3d),
        "tracked_objects": len(log.tracks_3d),
        "predictions": len(log.predictions),
        "plan": len(log.waypoints),
        "control": len(log.controls),
        "detections_2d": len(log.bboxes),
        "ground_truth_2d": len(log.bboxes_gt),
    }
    want = {topic: expected[name] for name, (topic, _type) in profile_topics(profile).items()}
    assert counts == want
    assert {topic: len(found) for topic, found in messages.items()} == want
    assert min(want.values()) == 1 and len(log.unique_frames) == 99
    for found in messages.values():  # header stamp = log time = the frame's timestamp
        for log_time, msg in found:
            header = getattr(msg, "header", None) or getattr(msg, "clock", None) or msg
            assert _stamp(header) == log_time and _ms(log_time) in log.unique_frames


@pytest.mark.parametrize(("profile", "storage"), CASES)
def test_ego_odometry_and_ground_truth_are_the_carla_run_flipped_into_map(
    bags: Any, run: Any, profile: str, storage: str
) -> None:
    log, summary = run
    _, messages, _ = bags[profile, storage]
    for log_time, odom in messages["/carla/ego_vehicle/odometry"]:
        pose = log.pose[_ms(log_time)]
        assert (odom.header.frame_id, odom.child_frame_id) == ("map", "ego_vehicle")
        position = odom.pose.pose.position
        assert (position.x, position.y, position.z) == (pose.x, -pose.y, pose.z)
        yaw = _map_yaw(odom.pose.pose.orientation)
        assert math.degrees(yaw) == pytest.approx(-pose.yaw, abs=1e-9)  # the yaw's sign flips
        linear = odom.twist.twist.linear  # body frame: the speed is along x
        assert (linear.x, linear.y, linear.z) == (pose.speed, 0.0, 0.0)
    for log_time, array in messages["/carla/objects"]:
        actors = log.actors[_ms(log_time)]
        assert [o.id for o in array.objects] == [int(i) for i in actors.ids]  # ego included
        assert summary["ego_id"] in actors.ids
        for row, obj in enumerate(array.objects):
            assert obj.shape.type == 1  # BOX
            assert obj.shape.dimensions.tolist() == (2.0 * actors.extent[row]).tolist()
            assert _carla_xy(obj.pose.position).tolist() == actors.location[row, :2].tolist()
            yaw = math.degrees(_map_yaw(obj.pose.orientation))
            assert yaw == pytest.approx(-actors.rotation[row, 2], abs=1e-9)
    ((log_time, event),) = messages["/carla/ego_vehicle/collision"]
    assert _ms(log_time) == log.metadata.collision_frame * log.frame_ms == 99 * 50
    assert event.other_actor_id == int(summary["partner_id"]) == 876


def test_3d_detections_and_tracks_carry_full_sizes_body_frame_twists_and_stable_uuids(
    bags: Any, run: Any
) -> None:
    log, _ = run
    _, messages, _ = bags["carla-autoware", "mcap"]
    detected = messages["/perception/object_recognition/detection/objects"]
    tracked = messages["/perception/object_recognition/tracking/objects"]
    for (log_time, dets), (_, tracks) in zip(detected, tracked, strict=True):
        ts = _ms(log_time)
        for key, msg in (("d", dets), ("t", tracks)):
            objects = (log.detections_3d if key == "d" else log.tracks_3d)[ts]
            assert len(msg.objects) == len(objects) > 1
            for row, obj in enumerate(msg.objects):
                assert obj.existence_probability == np.float32(objects.score[row])
                (classification,) = obj.classification
                assert classification.label == (1 if objects.labels[row] == "vehicle" else 7)
                assert obj.shape.type == 0  # BOUNDING_BOX, full sizes
                dims = obj.shape.dimensions
                assert [dims.x, dims.y, dims.z] == (2.0 * objects.extent[row]).tolist()
                pose = obj.kinematics.pose_with_covariance.pose
                assert _carla_xy(pose.position).tolist() == objects.location[row, :2].tolist()
                yaw = _map_yaw(pose.orientation)
                assert math.degrees(yaw) == pytest.approx(-objects.yaw[row], abs=1e-9)
                # The twist is in the object's body frame: rotate by its map yaw, flip y.
                body = obj.kinematics.twist_with_covariance.twist.linear
                world = np.array(
                    [
                        math.cos(yaw) * body.x - math.sin(yaw) * body.y,
                        -(math.sin(yaw) * body.x + math.cos(yaw) * body.y),
                    ]
                )
                unknown = row == len(objects) - 1
                assert world == pytest.approx(np.zeros(2) if unknown else VELOCITY[:2])
                if key == "d":
                    assert obj.kinematics.has_twist is not unknown
            if key == "t":
                uuids = [bytes(o.object_id.uuid) for o in msg.objects]
                assert uuids == [object_uuid(i) for i in objects.ids]
    # The same id has the same uuid in every recording (uuid5 of the id text).
    assert object_uuid("876").hex() == "9428ecfa881f5ee1bef892a946173b4c"


def test_predicted_paths_start_at_the_object_and_hold_each_key_in_the_map_frame(
    bags: Any, run: Any
) -> None:
    log, _ = run
    _, messages, _ = bags["carla-autoware", "sqlite3"]
    checked = {"tracked": 0, "untracked": 0}
    for log_time, msg in messages["/perception/object_recognition/objects"]:
        ts = _ms(log_time)
        pose, predictions = log.pose[ts], log.predictions[ts]
        tracks = log.tracks_3d[ts]
        assert [bytes(o.object_id.uuid) for o in msg.objects] == [
            object_uuid(i) for i in predictions
        ]
        yaw = math.radians(pose.yaw)
        for obj, (object_id, track) in zip(msg.objects, predictions.items(), strict=True):
            (path,) = obj.kinematics.predicted_paths
            assert (path.confidence, _stamp(path.time_step)) == (1.0, 50 * 1_000_000)
            points = np.array([_carla_xy(p.position) for p in path.path])
            assert len(points) == len(track.keys) + 1 == 31
            # Key k is path point k + 1; its offset in the ego body frame is recovered.
            d = points[1:] - [pose.x, pose.y]
            offsets = np.column_stack(
                [
                    math.cos(yaw) * d[:, 0] + math.sin(yaw) * d[:, 1],
                    -math.sin(yaw) * d[:, 0] + math.cos(yaw) * d[:, 1],
                ]
            )
            assert offsets == pytest.approx(track.offsets[:, :2], abs=1e-9)
            if object_id in tracks.ids:  # path[0]: the tracked position
                row = tracks.ids.index(object_id)
                assert points[0].tolist() == tracks.location[row, :2].tolist()
                assert obj.shape.dimensions.x == 2.0 * tracks.extent[row, 0]
                checked["tracked"] += 1
            else:  # key "0" minus one step
                assert points[0] == pytest.approx(2 * points[1] - points[2], abs=1e-9)
                checked["untracked"] += 1
    assert sum(checked.values()) == sum(len(p) for p in log.predictions.values())
    assert min(checked.values()) > 50  # both kinds of path[0], many times


def test_trajectory_and_control_points_are_timed_by_the_frame_period(bags: Any, run: Any) -> None:
    log, _ = run
    _, messages, _ = bags["carla-autoware", "mcap"]
    for log_time, trajectory in messages["/planning/scenario_planning/trajectory"]:
        plan = log.waypoints[_ms(log_time)]
        assert len(trajectory.points) == len(plan) == 31
        for i, point in enumerate(trajectory.points):
            assert _stamp(point.time_from_start) == i * 50 * 1_000_000
            assert _carla_xy(point.pose.position).tolist() == plan.xy[i].tolist()
            assert point.longitudinal_velocity_mps == np.float32(plan.speed[i])
    for log_time, control in messages["/control/command/control_cmd"]:
        command = log.controls[_ms(log_time)]
        # ROS steers left positive, CARLA right positive.
        steer = control.lateral.steering_tire_angle
        assert steer == np.float32(-math.radians(command.steer))
        assert control.longitudinal.acceleration == np.float32(-2.5)
        assert control.longitudinal.velocity == np.float32(command.speed)
        assert control.longitudinal.is_defined_acceleration is True


def test_vision_msgs_boxes_round_trip_and_3d_detections_keep_their_ids(bags: Any, run: Any) -> None:
    log, _ = run
    _, messages, _ = bags["vision_msgs", "sqlite3"]
    for topic, records in (
        ("/perception/detections_2d", log.bboxes),
        ("/perception/ground_truth_2d", log.bboxes_gt),
    ):
        for log_time, array in messages[topic]:
            boxes = records[_ms(log_time)]
            assert [d.id for d in array.detections] == list(boxes.ids)
            for row, det in enumerate(array.detections):
                centre, half = det.bbox.center.position, (det.bbox.size_x / 2, det.bbox.size_y / 2)
                corners = [
                    centre.x - half[0],
                    centre.y - half[1],
                    centre.x + half[0],
                    centre.y + half[1],
                ]
                assert corners == pytest.approx(boxes.corners[row].tolist(), abs=1e-9)
                (result,) = det.results
                assert result.hypothesis.class_id == boxes.extras[row]["label"]
                assert result.hypothesis.score == 1.0  # no score in the run: certain
    for log_time, array in messages["/perception/detections_3d"]:
        objects = log.detections_3d[_ms(log_time)]
        assert [d.id for d in array.detections] == list(objects.ids)
        for row, det in enumerate(array.detections):
            size = det.bbox.size
            assert [size.x, size.y, size.z] == (2.0 * objects.extent[row]).tolist()
            assert det.results[0].hypothesis.score == objects.score[row]


@pytest.mark.parametrize(("profile", "storage"), CASES)
def test_each_topic_stores_the_stacks_own_definition_text(
    bags: Any, profile: str, storage: str
) -> None:
    _, _, definitions = bags[profile, storage]
    shipped = {
        f"{p.parent.parent.name}/{p.stem}": p.read_text(encoding="utf-8")
        for p in MSG_DIR.glob("*/msg/*.msg")
    }
    seen = 0
    for topic, (fmt, text) in definitions.items():
        assert fmt == MessageDefinitionFormat.MSG
        msgtype = next(t for n, (tp, t) in profile_topics(profile).items() if tp == topic)
        package, _, short = msgtype.split("/")
        first, *rest = text.split(SEPARATOR)
        sections = {f"{package}/{short}": first}
        for section in rest:
            header, body = section.split("\n", 1)
            assert header.startswith("MSG: ")
            sections[header[5:]] = body
        for name, body in sections.items():
            if name in shipped:
                assert body == shipped[name]
                seen += 1
    assert seen >= 10


def test_without_definitions_a_sqlite3_bag_is_an_old_one(run: Any, tmp_path: Path) -> None:
    log, _ = run
    bag = tmp_path / "old"
    write_recording(log, bag, "carla-autoware", "sqlite3", definitions=False)
    (db3,) = bag.glob("*.db3")
    with sqlite3.connect(db3) as db:
        assert db.execute("SELECT count(*) FROM message_definitions").fetchone() == (0,)
        assert db.execute("SELECT count(*) FROM topics").fetchone() == (9,)
    db.close()
    with pytest.raises(AnyReaderError, match="no type definitions"):
        AnyReader([bag]).open()
    with pytest.raises(ConfigError, match="only be sqlite3"):
        write_recording(log, tmp_path / "m", "carla-autoware", "mcap", definitions=False)


def test_ids_that_are_not_uint32_are_numbered_above_the_rest_and_recorded(
    run: Any, tmp_path: Path
) -> None:
    log, _ = run
    ts = log.frames[0]
    actors = log.actors[ts]
    renamed = Actors(
        ("hero", "12", "007", *actors.ids[3:]), actors.location, actors.rotation, actors.extent
    )
    small = replace(log, actors={ts: renamed}, frames=(ts,))
    numbers = actor_numbers(small)
    top = max(int(i) for i in renamed.ids if i.isdigit() and str(int(i)) == i)
    assert (numbers["hero"], numbers["12"], numbers["007"]) == (top + 1, 12, top + 2)
    write_recording(small, tmp_path / "bag", "vision_msgs", "mcap")
    meta = yaml.safe_load((tmp_path / "bag" / "metadata.yaml").read_text())
    custom = meta["rosbag2_bagfile_information"]["custom_data"]
    assert custom["ads_rca.actor_ids"] == f'{{"007": {top + 2}, "hero": {top + 1}}}'
    assert custom["ads_rca.camera_loc"] == "[1.3, 0.0, 1.8]"
    assert '"partner_id": "876"' in custom["ads_rca.synthesis"]


def test_a_recording_is_never_written_over_another(run: Any, tmp_path: Path) -> None:
    log, _ = run
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "x").write_text("")
    with pytest.raises(OutputExists, match="not an empty folder"):
        write_recording(log, tmp_path / "full", "vision_msgs", "mcap")
    (tmp_path / "empty").mkdir()
    write_recording(log, tmp_path / "empty", "vision_msgs", "mcap")  # an empty one is used


def test_synth_profile_writes_a_bag_and_storage_alone_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["synth", str(tmp_path / "bag"), "--scenario", "cruise", "--frames", "20"]
    assert (
        main([*argv, "--actors", "1", "--profile", "carla-autoware", "--storage", "sqlite3"]) == 0
    )
    assert capsys.readouterr().out == (
        f"{tmp_path / 'bag'}: cruise/none seed 0: 20 frames, no collision, no partner, "
        "no fault injected (carla-autoware sqlite3 bag, 160 messages on 9 topics)\n"
    )
    messages, _ = _read(tmp_path / "bag")
    assert {t: len(m) for t, m in messages.items()} == {
        "/clock": 20,
        "/carla/ego_vehicle/odometry": 20,
        "/carla/objects": 20,
        "/perception/object_recognition/objects": 20,
        "/planning/scenario_planning/trajectory": 20,
        "/perception/object_recognition/detection/objects": 20,
        "/perception/object_recognition/tracking/objects": 20,
        "/control/command/control_cmd": 20,
    }  # the collision topic is offered, and empty: nothing crashed
    assert main(["synth", str(tmp_path / "log"), "--scenario", "cruise", "--storage", "mcap"]) == 2
    assert capsys.readouterr().err == (
        "ads-rca synth: error: --storage: only with --profile (a log folder has no storage)\n"
    )
    assert not (tmp_path / "log").exists()


def _headings_by_loop(points: np.ndarray, initial: float) -> np.ndarray:
    """The obviously-correct transcription: walk the points, face the next one."""
    out, heading = np.empty(len(points)), initial
    for i in range(len(points)):
        j = min(i + 1, len(points) - 1)
        dx, dy = points[j, :2] - points[j - 1, :2] if j > 0 else (0.0, 0.0)
        if math.hypot(dx, dy) > 1e-9:
            heading = math.atan2(dy, dx)
        out[i] = heading
    return out


def test_path_headings_face_the_next_point_and_hold_through_stops() -> None:
    rng = np.random.default_rng(16)
    for n in range(7):
        for _ in range(100):
            points = rng.normal(size=(n, 3))
            points[rng.random(n) < 0.4] = 0.0  # repeated points: a stop
            got = path_headings(points, 0.7)
            # numpy's arctan2 is vectorised per CPU (AVX-512 here, AVX2 there) and may end a
            # bit away from libm's atan2: the same heading, within one unit in the last place.
            np.testing.assert_array_max_ulp(got, _headings_by_loop(points, 0.7), maxulp=1)
    assert (
        path_headings(np.array([[0.0, 0, 0], [0, 1, 0], [0, 1, 0]]), 0.0).tolist()
        == [math.pi / 2] * 3
    )
