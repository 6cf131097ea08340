"""Stack-published inputs (PoseStamped, Path, CARLA bridge markers) → model records, no DDS.

Real rclpy message classes are built from synthesised logs and read back; the records must
equal the log's. Derived speeds are distance / time per interval: the log's speed exactly
where it is constant over the interval, the interval's mean speed otherwise (the
synthesiser integrates with the trapezoid rule; on the left turn the chord is a little
shorter than the arc, so there the mean holds to 1e-2 m/s).
"""

from __future__ import annotations

import itertools
import math
import random
from collections.abc import Callable
from functools import cache, partial
from typing import TYPE_CHECKING

import numpy as np
import pytest

from ads_rca.contract import convert, stack_inputs
from ads_rca.contract.errors import MalformedMessage
from ads_rca.model import Actors, RunLog
from ads_rca.synth import SCENARIOS, synthesise

if TYPE_CHECKING:
    from geometry_msgs.msg import PoseStamped
    from visualization_msgs.msg import MarkerArray

TOL = 1e-9


@cache
def run_log(scenario: str) -> RunLog:
    if scenario == "cruise":
        return synthesise("cruise", "none", 1, frames=200)
    return synthesise(scenario, "controller", 1)


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_pose_stamped_series_gives_the_log_poses_and_derived_speed(scenario: str) -> None:
    log = run_log(scenario)
    msgs = [stack_inputs.pose_stamped(log.pose[t], t) for t in log.frames]
    out = stack_inputs.pose_stamped_series(msgs)
    assert [p.stamp_ms for p in out] == list(log.frames)
    assert all(p.speed_derived for p in out)
    for t, got in zip(log.frames, out, strict=True):
        want = log.pose[t]
        assert np.allclose(
            [got.pose.x, got.pose.y, got.pose.z, got.pose.roll, got.pose.pitch, got.pose.yaw],
            [want.x, want.y, want.z, want.roll, want.pitch, want.yaw],
            rtol=0.0,
            atol=TOL,
        )
    assert math.isnan(out[0].pose.speed)
    logged = np.array([log.pose[t].speed for t in log.frames])
    derived = np.array([p.pose.speed for p in out])[1:]
    constant = logged[1:] == logged[:-1]
    assert constant.sum() >= 10
    np.testing.assert_allclose(derived[constant], logged[1:][constant], rtol=0.0, atol=TOL)
    mean_tol = 1e-2 if scenario == "left_turn" else TOL
    mean = 0.5 * (logged[1:] + logged[:-1])
    np.testing.assert_allclose(derived, mean, rtol=0.0, atol=mean_tol)


def test_streamed_pose_equals_the_series() -> None:
    log = run_log("lead_braking")
    msgs = [stack_inputs.pose_stamped(log.pose[t], t) for t in log.frames[:20]]
    series = stack_inputs.pose_stamped_series(msgs)
    streamed = [stack_inputs.pose_stamped_pose(msgs[0], None)] + [
        stack_inputs.pose_stamped_pose(msg, prev) for prev, msg in itertools.pairwise(msgs)
    ]
    assert [(p.stamp_ms, p.pose.x, p.pose.yaw) for p in streamed] == [
        (p.stamp_ms, p.pose.x, p.pose.yaw) for p in series
    ]
    assert [p.pose.speed for p in streamed[1:]] == [p.pose.speed for p in series[1:]]


def test_odometry_keeps_its_measured_speed() -> None:
    log = run_log("cut_in")
    t = log.frames[5]
    got = stack_inputs.odometry_stack_pose(convert.pose_to_odometry(log.pose[t], t))
    assert got.stamp_ms == t and not got.speed_derived
    assert got.pose.speed == log.pose[t].speed


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_path_gives_the_log_plan(scenario: str) -> None:
    log = run_log(scenario)
    frame_ms = log.metadata.timesteps_per_frame
    for t in log.frames:
        plan = log.waypoints[t]
        got = stack_inputs.path_to_plan(stack_inputs.plan_to_path(plan, t, frame_ms), frame_ms)
        assert got.keys == plan.keys
        np.testing.assert_allclose(got.xy, plan.xy, rtol=0.0, atol=TOL)
        # Within 0.02 m/s (the chord of a curve; the interval means were 0.2 m/s off while
        # braking at 8 m/s²), but next to where the plan's acceleration changes (it starts
        # braking, or stops mid-interval): there 0.1 m/s (standstill_speed).
        changes = np.flatnonzero(np.abs(np.diff(plan.speed, 2)) > 1e-6) + 1
        kinked = np.zeros(len(plan.speed), dtype=bool)
        for k in changes:
            kinked[max(k - 2, 0) : k + 3] = True
        error = np.abs(got.speed - plan.speed)
        assert (error[~kinked] <= 2e-2).all() and (error[kinked] <= 0.1).all(), error


def test_path_speeds_are_exact_under_constant_acceleration_on_any_stamps() -> None:
    """Braking at 8 m/s² from 10 m/s, points at uneven times: every point's own speed."""
    seconds = np.array([0.0, 0.05, 0.1, 0.18, 0.2, 0.31, 0.4, 0.45])
    travelled = 10.0 * seconds - 4.0 * seconds**2
    location = np.c_[travelled * 0.6, travelled * 0.8, np.zeros(len(seconds))]
    stamps = np.round(seconds * 1e9).astype(np.int64)
    speeds = stack_inputs.point_speeds(location, stamps)
    np.testing.assert_allclose(speeds, 10.0 - 8.0 * seconds, rtol=0.0, atol=1e-9)
    two = stack_inputs.point_speeds(location[:2], stamps[:2])
    np.testing.assert_allclose(two, [travelled[1] / 0.05] * 2, rtol=0.0, atol=1e-9)
    assert np.isnan(stack_inputs.point_speeds(location[:1], stamps[:1])).all()


def test_path_keys_round_to_the_nearest_step_and_one_point_has_no_speed() -> None:
    log = run_log("cut_in")
    t = log.frames[0]
    path = stack_inputs.plan_to_path(log.waypoints[t], t, 50)
    path.poses[2].header.stamp = convert.to_time(t + 2 * 50 + 24)
    path.poses[3].header.stamp = convert.to_time(t + 3 * 50 + 26)
    assert stack_inputs.path_to_plan(path, 50).keys[:5] == ("0", "1", "2", "4", "4")
    del path.poses[1:]
    one = stack_inputs.path_to_plan(path, 50)
    assert one.keys == ("0",) and math.isnan(float(one.speed[0]))


def test_quaternions_are_normalised() -> None:
    msg = _poses(1)[0]
    want = stack_inputs.pose_stamped_series([msg])[0].pose
    q = msg.pose.orientation
    q.x, q.y, q.z, q.w = 2.0 * q.x, 2.0 * q.y, 2.0 * q.z, 2.0 * q.w
    got = stack_inputs.pose_stamped_series([msg])[0].pose
    assert got.yaw == pytest.approx(want.yaw, abs=TOL)
    assert got.roll == pytest.approx(want.roll, abs=TOL)


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_carla_markers_give_the_log_actors(scenario: str) -> None:
    log = run_log(scenario)
    for t in log.frames[::7]:
        actors = log.actors[t]
        got = stack_inputs.carla_markers_to_actors(stack_inputs.actors_to_carla_markers(actors, t))
        assert got.ids == actors.ids
        np.testing.assert_array_equal(got.location, actors.location)
        np.testing.assert_allclose(got.rotation, actors.rotation, rtol=0.0, atol=TOL)
        np.testing.assert_allclose(got.extent, actors.extent, rtol=0.0, atol=TOL)


def test_carla_markers_skip_what_is_not_an_actor_cube() -> None:
    from visualization_msgs.msg import Marker

    log = run_log("cut_in")
    t = log.frames[0]
    msg = stack_inputs.actors_to_carla_markers(log.actors[t], t)
    msg.markers.insert(0, Marker(action=Marker.DELETEALL))
    msg.markers.append(Marker(header=msg.markers[1].header, id=1, type=Marker.TEXT_VIEW_FACING))
    assert stack_inputs.carla_markers_to_actors(msg).ids == log.actors[t].ids


# --- bad messages -----------------------------------------------------------------------------


def _poses(count: int) -> list[PoseStamped]:
    log = run_log("cut_in")
    return [stack_inputs.pose_stamped(log.pose[t], t) for t in log.frames[:count]]


def test_bad_pose_series_raise_the_contract_error() -> None:
    msgs = _poses(3)
    with pytest.raises(MalformedMessage, match="no PoseStamped"):
        stack_inputs.pose_stamped_series([])
    unsorted = [msgs[0], msgs[2], msgs[1]]
    with pytest.raises(MalformedMessage, match="stamp 2 is not after"):
        stack_inputs.pose_stamped_series(unsorted)
    with pytest.raises(MalformedMessage, match="stamp 1 is not after"):
        stack_inputs.pose_stamped_series([msgs[0], msgs[0]])
    msgs[1].pose.position.x = math.nan
    with pytest.raises(MalformedMessage, match="pose 1 is not finite"):
        stack_inputs.pose_stamped_series(msgs)
    odom = _poses(1)[0]
    odom.header.frame_id = "odom"
    with pytest.raises(MalformedMessage, match="frame 'odom', expected 'map'"):
        stack_inputs.pose_stamped_series([odom])
    zero = _poses(1)[0]
    q = zero.pose.orientation
    q.x = q.y = q.z = q.w = 0.0
    with pytest.raises(MalformedMessage, match="zero quaternion"):
        stack_inputs.pose_stamped_series([zero])


def test_bad_paths_raise_the_contract_error() -> None:
    from nav_msgs.msg import Path

    log = run_log("cut_in")
    t = log.frames[0]
    with pytest.raises(MalformedMessage, match="Path has no poses"):
        stack_inputs.path_to_plan(Path(header=convert.header(t, "map")), 50)
    unsorted = stack_inputs.plan_to_path(log.waypoints[t], t, 50)
    unsorted.poses[3], unsorted.poses[4] = unsorted.poses[4], unsorted.poses[3]
    with pytest.raises(MalformedMessage, match="Path: stamp 4 is not after"):
        stack_inputs.path_to_plan(unsorted, 50)
    nan = stack_inputs.plan_to_path(log.waypoints[t], t, 50)
    nan.poses[5].pose.position.y = math.inf
    with pytest.raises(MalformedMessage, match="Path: pose 5 is not finite"):
        stack_inputs.path_to_plan(nan, 50)
    foreign = stack_inputs.plan_to_path(log.waypoints[t], t, 50)
    foreign.poses[1].header.frame_id = "odom"
    with pytest.raises(MalformedMessage, match="Path pose is in frame 'odom'"):
        stack_inputs.path_to_plan(foreign, 50)


def test_bad_carla_markers_raise_the_contract_error() -> None:
    log = run_log("cut_in")
    t = log.frames[0]
    nan = stack_inputs.actors_to_carla_markers(log.actors[t], t)
    nan.markers[1].pose.orientation.x = math.nan
    with pytest.raises(MalformedMessage, match="CARLA markers: pose 1 is not finite"):
        stack_inputs.carla_markers_to_actors(nan)
    size = stack_inputs.actors_to_carla_markers(log.actors[t], t)
    size.markers[0].scale.y = math.nan
    with pytest.raises(MalformedMessage, match="cube size is not finite"):
        stack_inputs.carla_markers_to_actors(size)
    twice = stack_inputs.actors_to_carla_markers(log.actors[t], t)
    twice.markers[1].id = twice.markers[0].id
    with pytest.raises(MalformedMessage, match="repeat an actor id"):
        stack_inputs.carla_markers_to_actors(twice)
    foreign = stack_inputs.actors_to_carla_markers(log.actors[t], t)
    foreign.markers[0].header.frame_id = "ego_vehicle"
    with pytest.raises(MalformedMessage, match="frame 'ego_vehicle'"):
        stack_inputs.carla_markers_to_actors(foreign)


def _outcome(read: Callable[[], Actors]) -> tuple[str, ...]:
    """A reading's records as bytes, or its error's text."""
    try:
        actors = read()
    except MalformedMessage as error:
        return ("error", str(error))
    arrays = (actors.location, actors.rotation, actors.extent)
    shapes = repr([a.shape for a in arrays])
    return ("actors", repr(actors.ids), shapes, *(a.tobytes().hex() for a in arrays))


def _hostile_markers(rng: random.Random, actors: Actors, t: int) -> MarkerArray:
    """The bridge's cubes of ``actors`` with a few hostile changes."""
    from geometry_msgs.msg import Point
    from std_msgs.msg import ColorRGBA
    from visualization_msgs.msg import Marker

    msg = stack_inputs.actors_to_carla_markers(actors, t)
    values = [math.nan, math.inf, -math.inf, 0.0, -0.0, 1e308, -5e-324, 2.0**70]
    for _ in range(rng.choice((0, 1, 1, 2, 3))):
        if not msg.markers:
            break
        m = rng.choice(msg.markers)
        change = rng.randrange(9)
        if change == 0:
            field = rng.choice(("position", "orientation"))
            setattr(getattr(m.pose, field), rng.choice("xyz"), rng.choice(values))
        elif change == 1:
            m.pose.orientation.x = m.pose.orientation.y = m.pose.orientation.z = 0.0
            m.pose.orientation.w = rng.choice((0.0, -0.0, 1e-12))
        elif change == 2:
            setattr(m.scale, rng.choice("xyz"), rng.choice(values))
        elif change == 3:
            m.header.frame_id = rng.choice(("", "odom", "map ", "mäp", "m" * 300))
        elif change == 4:
            m.id = rng.choice((msg.markers[0].id, -(2**31), 2**31 - 1, 0))
        elif change == 5:
            m.action = rng.choice((Marker.DELETE, Marker.DELETEALL, 5))
        elif change == 6:
            m.type = rng.choice((Marker.ARROW, Marker.SPHERE, Marker.TEXT_VIEW_FACING, 99))
        elif change == 7:  # fields the bridge leaves empty, filled
            m.text, m.ns = "actor", "carla"
            m.points = [Point(x=1.0, y=2.0, z=3.0)]
            m.mesh_resource = "package://car.dae"
            m.colors = [ColorRGBA(r=1.0)]
        else:
            msg.markers.insert(rng.randrange(len(msg.markers) + 1), Marker(type=Marker.CUBE))
    return msg


def test_carla_marker_bytes_read_as_the_message_objects_do() -> None:
    """The monitors subscribe to the CARLA markers as CDR bytes: their reading must give the
    records and the errors the message objects give, on hostile values too (NaN, ±inf,
    zero quaternions, foreign frames, repeated ids, other types and actions, filled fields,
    a default marker), and refuse bytes that are no MarkerArray."""
    from rclpy.serialization import serialize_message

    rng = random.Random(15)
    log = run_log("cut_in")
    seen = {"error": 0, "actors": 0}
    for case in range(600):
        t = log.frames[case % len(log.frames)]
        msg = _hostile_markers(rng, log.actors[t], t)
        data = serialize_message(msg)
        want = _outcome(partial(stack_inputs.carla_markers_to_actors, msg))
        got = _outcome(partial(stack_inputs.decode_carla_markers, data))
        assert got == want, (case, want[:2], got[:2])
        seen[want[0]] += 1
    assert seen["error"] > 100 and seen["actors"] > 100
    empty = serialize_message(stack_inputs.actors_to_carla_markers(log.actors[log.frames[0]], 0))
    for bad in (b"", b"\x00\x01\x00\x00", empty[:-7], b"\x00\x01\x00\x00\xff\xff\xff\xff"):
        with pytest.raises(MalformedMessage):
            stack_inputs.decode_carla_markers(bad)
