"""The topic contract without DDS: log → messages → assembler → log is lossless."""

from __future__ import annotations

import math

import numpy as np
import pytest
from logcompare import assert_logs_equal
from logfactory import make_log, play_through_assembler

from ads_rca.contract import convert, playback, topics
from ads_rca.contract.assembler import RunLogAssembler, run_metadata
from ads_rca.model import Boxes, Plan


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_log_to_messages_to_log_is_lossless(seed: int) -> None:
    log = make_log(25, 12, seed, duplicate_frame=True, orphan_stamps=True)
    assembler = play_through_assembler(log)
    assert assembler.complete()
    rebuilt = assembler.build()
    assert_logs_equal(log, rebuilt, angle_tol=1e-9)
    assert rebuilt.source == log.source
    assert rebuilt.metadata.raw["scenario"] == "factory"


def test_round_trip_survives_cdr_serialisation() -> None:
    log = make_log(6, 5, 7, orphan_stamps=True)
    assert_logs_equal(log, play_through_assembler(log, serialise=True).build())


def test_synthesised_log_round_trips() -> None:
    from ads_rca.synth import synthesise

    log = synthesise("cruise", "none", 1, frames=40, actors=6, horizon=10)
    assert_logs_equal(log, play_through_assembler(log).build(), angle_tol=1e-9)


def test_carla_to_ros_convention_matches_the_carla_bridge() -> None:
    log = make_log(1, 1, 0)
    ts = log.frames[0]
    pose = log.pose[ts]
    odom = convert.pose_to_odometry(pose, ts)
    assert (odom.pose.pose.position.x, odom.pose.pose.position.y) == (pose.x, -pose.y)
    assert odom.header.frame_id == "map" and odom.child_frame_id == "base_link"
    assert odom.twist.twist.linear.x == pose.speed
    # CARLA yaw +90° (clockwise seen from above, left-handed) is ROS yaw −90°.
    q = convert.carla_rpy_to_quaternions(np.array([0.0, 0.0, 90.0]))[0]
    assert q == pytest.approx([0.0, 0.0, -math.sqrt(0.5), math.sqrt(0.5)])
    # CARLA pitch +10° (nose up) is ROS pitch −10°: quaternion y negative.
    assert convert.carla_rpy_to_quaternions(np.array([0.0, 10.0, 0.0]))[0][1] < 0


def test_angles_round_trip_within_1e_9_degrees() -> None:
    rng = np.random.default_rng(3)
    rpy = np.column_stack(
        (rng.uniform(-180, 180, 5000), rng.uniform(-89.9, 89.9, 5000), rng.uniform(-180, 180, 5000))
    )
    rpy[:4] = np.array([[0, 0, 180], [0, 0, -179.999999], [179.9, 0, 0], [0, -89.999, 45]])
    back = convert.quaternions_to_carla_rpy(convert.carla_rpy_to_quaternions(rpy))
    diff = np.abs((back - rpy + 180.0) % 360.0 - 180.0)
    assert diff.max() < 1e-9


def test_stamps_carry_log_milliseconds() -> None:
    for ms in (0, 1, 50, 999, 1000, 123_456_789, -50):
        assert convert.from_time(convert.to_time(ms)) == ms
    assert convert.to_time(1050).sec == 1 and convert.to_time(1050).nanosec == 50_000_000


def test_marker_ids_numeric_actor_ids_kept_others_negative_and_stable() -> None:
    assert convert.marker_id("746") == 746
    assert convert.marker_id("0") == 0
    for text in ("walker_3", "0042", "4294967296", "-5", ""):
        value = convert.marker_id(text)
        assert -(2**31) <= value < 0
        assert value == convert.marker_id(text)


def test_boxes_keep_corners_as_written_and_extras_in_order() -> None:
    boxes = Boxes(
        ids=("3", "ped_1"),
        corners=np.array([[10.5, 20.0, 5.0, 2.0], [np.nan, 1.0, 2.0, 3.0]]),
        extras=({"score": 0.9, "label": "car"}, {"weird": float("inf"), "n": 2**70}),
    )
    msg = topics.TOPICS[topics.DETECTIONS].codec.build(boxes, 100, 50)
    assert msg.markers[0].action == msg.markers[0].DELETEALL
    first = msg.markers[1]
    assert first.header.frame_id == "camera_image" and first.ns == "detections"
    assert [(p.x, p.y) for p in first.points] == [
        (10.5, 20.0),
        (5.0, 20.0),
        (5.0, 2.0),
        (10.5, 2.0),
        (10.5, 20.0),
    ]
    back = convert.markers_to_boxes(msg)
    assert back.ids == boxes.ids
    assert np.array_equal(back.corners, boxes.corners, equal_nan=True)
    assert [list(e.items()) for e in back.extras] == [list(e.items()) for e in boxes.extras]


def test_empty_predictions_publish_only_deleteall() -> None:
    msg = topics.TOPICS[topics.PREDICTION_RAW].codec.build({}, 50, 50)
    assert [m.action for m in msg.markers] == [msg.markers[0].DELETEALL]
    assert convert.markers_to_predictions(msg) == {}


def test_plan_keys_that_are_not_canonical_integers_are_dropped() -> None:
    plan = Plan(
        keys=("0", "1", "01", "x", "3"),
        xy=np.arange(10, dtype=float).reshape(5, 2),
        speed=np.arange(5, dtype=float),
    )
    msg = convert.plan_to_trajectory(plan, 100, 50)
    assert [convert.from_duration(p.time_from_start) for p in msg.points] == [0, 50, 150]
    assert msg.joint_names == ["ego"] and msg.header.frame_id == "map"
    back = convert.trajectory_to_plan(msg, 50)
    assert back.keys == ("0", "1", "3")
    assert np.array_equal(back.xy, plan.xy[[0, 1, 4]])
    log = make_log(2, 2, 0)
    log.waypoints[log.frames[0]] = plan
    marker = playback.read_document(
        playback.frame_marker(playback.Tick(log.frames[0], 0), [], 50, dropped_plan_keys=2)
    )
    assert playback.dropped_plan_keys(log, log.frames[0]) == marker["dropped_plan_keys"] == 2


def test_missing_folder_record_is_not_published_and_marker_says_so() -> None:
    log = make_log(8, 3, 0)
    ts = log.frames[4]  # pose is missing on every fifth frame
    assert ts not in log.pose
    messages = topics.frame_messages(log, ts)
    names = playback.published_names(messages)
    assert topics.ODOMETRY not in names and topics.ACTORS in names
    marker = playback.read_document(playback.frame_marker(playback.Tick(ts, 4), names, 50))
    assert marker == {
        "index": 4,
        "stamp_ms": ts,
        "frame": ts // 50,
        "published": names,
        "duplicate": False,
    }


def test_frame_ranges_partition_the_timeline() -> None:
    log = make_log(10, 2, 0, duplicate_frame=True, orphan_stamps=True)
    ticks = playback.timeline(log)
    assert [t.stamp_ms for t in ticks] == sorted(t.stamp_ms for t in ticks)
    assert sum(t.duplicate for t in ticks) == 1
    assert [t.index for t in ticks if t.index is not None] == list(range(len(log.frames)))
    parts = [playback.select(ticks, 0, 3), playback.select(ticks, 4, 6), playback.select(ticks, 7)]
    assert [t for part in parts for t in part] == ticks
    assert [t.index for t in playback.select(ticks, 2, 2)] == [2]
    assert playback.select(ticks, 99) == []


def test_assembler_reports_what_is_missing() -> None:
    log = make_log(3, 2, 0)
    assembler = RunLogAssembler()
    tick = playback.timeline(log)[0]
    messages = topics.frame_messages(log, tick.stamp_ms)
    assembler.add(topics.FRAME, playback.frame_marker(tick, playback.published_names(messages), 50))
    assembler.add(topics.STATUS, playback.status_message(playback.FINISHED, 2))
    assert not assembler.complete()
    missing = assembler.missing()
    assert missing[topics.FRAME] == 1 and missing[topics.ACTORS] == 1
    assert missing[topics.METADATA] == 1


def test_topic_names_follow_the_namespace() -> None:
    assert topics.topic_name(topics.ODOMETRY) == "/ads_rca/ego/odometry"
    assert topics.topic_name(topics.ACTORS, "sim/") == "/sim/actors"
    assert topics.topic_name(topics.FRAME, "/") == "/run/frame"
    assert topics.topic_name(topics.CLOCK, "/x") == "/clock"
    assert topics.QOS[topics.METADATA].describe() == "RELIABLE, TRANSIENT_LOCAL, KEEP_LAST 1"


def test_run_metadata_reads_the_exact_document_and_rejects_garbage() -> None:
    exact = {"timesteps_per_frame": 50, "collision_frame": 12}
    message = {"timesteps_per_frame": 99, "metadata_json": exact}
    assert run_metadata(message).collision_frame == 12
    assert run_metadata(message).timesteps_per_frame == 50
    assert run_metadata({"timesteps_per_frame": 20}).timesteps_per_frame == 20
    for bad in ({}, {"timesteps_per_frame": "fast"}, {"metadata_json": {"collision_frame": 3}}):
        with pytest.raises(ValueError, match="unusable run/metadata"):
            run_metadata(bad)
