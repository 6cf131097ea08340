"""Recordings of real stacks through profiles: the map ↔ CARLA
conventions both ways, each decoder on messages laid out as the published definitions say,
the profile files' validation, and whole bags (MCAP and sqlite3, written with rosbags) in the
carla-autoware and vision_msgs layouts read back into a RunLog: frames from stamps, the
collision frame, predictions as offsets, the plan, the inputs found and missing. Hostile
messages (NaN, a string where a number belongs, a short uuid, 10^5 objects) are each a
Problem naming the field, never a traceback."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from profilebags import build, decoder, header, stamp, typestore, write_bag
from rosbags.typesys.store import Typestore

from ads_rca.capabilities import MODEL_INPUTS
from ads_rca.contract import topics
from ads_rca.contract.errors import MalformedMessage
from ads_rca.errors import ConfigError, InputError
from ads_rca.model import EgoPose, InputStatus
from ads_rca.sources.bag.profiles import decoders, frames
from ads_rca.sources.bag.profiles.decoders import PredictedPaths
from ads_rca.sources.bag.profiles.profile import (
    BUILTIN_NAMES,
    builtin_path,
    contract_type,
    load_profile,
)
from ads_rca.sources.bag.profiles.reader import (
    read_profiled,
    sample_plan,
    track_offsets,
    travel_times,
)
from ads_rca.sources.bag.reader import load_bag

pytestmark = pytest.mark.timeout(120)

T0 = 1_000 * 1_000_000_000  # the first frame's stamp, ns
PERIOD = 100_000_000  # 100 ms frames
MS = 1_000_000


@pytest.fixture(scope="module")
def store() -> Typestore:
    return typestore()


def _quat_yaw(yaw_rad: float) -> dict[str, float]:
    return {"z": math.sin(yaw_rad / 2), "w": math.cos(yaw_rad / 2)}


def _pose(x: float, y: float, z: float = 0.0, yaw: float = 0.0) -> dict[str, Any]:
    return {"position": {"x": x, "y": y, "z": z}, "orientation": _quat_yaw(yaw)}


# --- frames ---------------------------------------------------------------------------------


def test_map_to_carla_and_back_is_exact() -> None:
    xyz = np.array([[1.5, -2.25, 0.5], [-3.0, 4.0, -1.0]])
    carla = frames.map_to_carla_xyz(xyz)
    assert carla.tolist() == [[1.5, 2.25, 0.5], [-3.0, -4.0, -1.0]]
    assert frames.carla_to_map_xyz(carla).tolist() == xyz.tolist()
    rpy = np.array([10.0, -20.0, 135.0])
    back = frames.quaternion_to_carla_rpy(*frames.carla_rpy_to_quaternion(rpy))
    assert np.allclose(back, rpy, atol=1e-12)


def test_driving_along_map_y_is_carla_yaw_minus_90_and_back() -> None:
    q = frames.rpy_to_quaternion(0.0, 0.0, math.pi / 2)  # map: heading +y (left)
    assert frames.quaternion_to_carla_rpy(*q) == pytest.approx([0.0, 0.0, -90.0])
    # heading CARLA +y (right): map yaw −90°
    q_carla_y = frames.carla_rpy_to_quaternion(np.array([0.0, 0.0, 90.0]))
    assert frames.quaternion_to_rpy(*q_carla_y) == pytest.approx([0.0, 0.0, -math.pi / 2])


def test_a_body_twist_turns_with_the_body_into_the_world() -> None:
    # 5 m/s forward, body yawed +90° in map: world map (0, 5), CARLA (0, −5)
    world = frames.body_to_world(np.array([5.0, 0.0, 0.0]), math.pi / 2)
    assert world == pytest.approx([0.0, 5.0, 0.0])
    assert frames.world_to_body(world, math.pi / 2) == pytest.approx([5.0, 0.0, 0.0])
    carla = decoders.world_velocity(np.array([[5.0, 0.0, 0.0]]), np.array([-90.0]), "map")
    assert carla[0] == pytest.approx([0.0, -5.0, 0.0])
    as_is = decoders.world_velocity(np.array([[5.0, 0.0, 0.0]]), np.array([90.0]), "carla")
    assert as_is[0] == pytest.approx([0.0, 5.0, 0.0])


# --- decoders -------------------------------------------------------------------------------


def _round_trip(store: Typestore, type_name: str, values: dict[str, Any]) -> Any:
    """A message as a bag gives it back: built, serialised, deserialised."""
    msg = build(store, type_name, values)
    return store.deserialize_cdr(store.serialize_cdr(msg, type_name), type_name)


def test_odometry_is_the_ego_pose_in_carla(store: Typestore) -> None:
    msg = _round_trip(
        store,
        "nav_msgs/msg/Odometry",
        {
            "header": header(T0 + 7),
            "pose": {"pose": _pose(10.0, 3.0, 0.5, math.pi / 2)},
            "twist": {"twist": {"linear": {"x": 3.0, "y": 4.0}}},
        },
    )
    pose = decoders.decode_odometry(msg, "map")
    assert (pose.x, pose.y, pose.z, pose.speed) == (10.0, -3.0, 0.5, 5.0)
    assert pose.yaw == pytest.approx(-90.0)
    assert decoders.DECODERS["nav_msgs/msg/Odometry"].stamp(msg) == T0 + 7
    assert decoders.decode_odometry(msg, "carla").y == 3.0


def test_object_array_is_actors_with_half_extents(store: Typestore) -> None:
    objects = [
        {
            "id": 42,
            "pose": _pose(20.0, 3.5, 0.7, math.pi / 2),
            "shape": {"type": 1, "dimensions": [4.0, 2.0, 1.5]},
        },
        {"id": 7, "pose": _pose(1.0, 0.0), "shape": {"type": 3, "dimensions": [1.8, 0.3]}},
        {"id": 42, "pose": _pose(0.0, 0.0), "shape": {"type": 1, "dimensions": [2, 2, 2]}},
    ]
    msg = _round_trip(
        store, "derived_object_msgs/msg/ObjectArray", {"header": header(T0), "objects": objects}
    )
    actors = decoders.decode_object_array(msg, "map")
    assert actors.ids == ("42", "7", "42")  # a repeated id is kept, as a log's file is
    assert actors.index["42"] == 0
    assert actors.location[0].tolist() == [20.0, -3.5, 0.7]
    assert actors.rotation[0] == pytest.approx([0.0, 0.0, -90.0])
    assert actors.extent.tolist() == [[2.0, 1.0, 0.75], [0.3, 0.3, 0.9], [1.0, 1.0, 1.0]]
    empty = _round_trip(store, "derived_object_msgs/msg/ObjectArray", {"header": header(T0)})
    none = decoders.decode_object_array(empty, "map")
    assert len(none) == 0 and none.location.shape == (0, 3) and none.extent.shape == (0, 3)


def _autoware_object(x: float, y: float, yaw: float, **more: Any) -> dict[str, Any]:
    kinematics: dict[str, Any] = {
        "pose_with_covariance": {"pose": _pose(x, y, 0.0, yaw)},
        "twist_with_covariance": {"twist": {"linear": {"x": 5.0}}},
    }
    kinematics.update(more.pop("kinematics", {}))
    return {
        "existence_probability": 0.9,
        "classification": [
            {"label": 1, "probability": 0.3},
            {"label": 7, "probability": 0.7},
        ],
        "kinematics": kinematics,
        "shape": {"dimensions": {"x": 4.0, "y": 2.0, "z": 1.6}},
        **more,
    }


def test_detected_objects_are_3d_detections_in_carla(store: Typestore) -> None:
    objects = [
        _autoware_object(20.5, 3.5, math.pi / 2, kinematics={"has_twist": True}),
        _autoware_object(1.0, 2.0, 0.0, classification=[]),
    ]
    msg = _round_trip(
        store,
        "autoware_perception_msgs/msg/DetectedObjects",
        {"header": header(T0), "objects": objects},
    )
    det = decoders.decode_detected_objects(msg, "map")
    assert det.ids == ("d0", "d1")
    assert det.location.tolist() == [[20.5, -3.5, 0.0], [1.0, -2.0, 0.0]]
    assert det.yaw == pytest.approx([-90.0, 0.0])
    assert det.extent.tolist() == [[2.0, 1.0, 0.8], [2.0, 1.0, 0.8]]
    assert det.velocity[0] == pytest.approx([0.0, -5.0, 0.0])  # body +x, heading map +y
    assert np.isnan(det.velocity[1]).all()  # has_twist false: unknown
    assert det.score == pytest.approx([0.9, 0.9])
    assert det.labels == ("PEDESTRIAN", "UNKNOWN")


def test_tracked_objects_take_the_uuid_as_id(store: Typestore) -> None:
    objects = [{"object_id": {"uuid": list(range(16))}, **_autoware_object(3.0, 0.0, 0.0)}]
    msg = _round_trip(
        store,
        "autoware_perception_msgs/msg/TrackedObjects",
        {"header": header(T0), "objects": objects},
    )
    tracks = decoders.decode_tracked_objects(msg, "map")
    assert tracks.ids == ("000102030405060708090a0b0c0d0e0f",)
    assert tracks.velocity[0].tolist() == [5.0, 0.0, 0.0]


def test_predicted_objects_take_the_most_confident_path(store: Typestore) -> None:
    paths = [
        {
            "path": [_pose(0.0, 0.0), _pose(9.0, 9.0)],
            "time_step": {"nanosec": 500_000_000},
            "confidence": 0.2,
        },
        {
            "path": [_pose(30.0, 2.0), _pose(32.5, 2.0), _pose(35.0, 2.0)],
            "time_step": {"nanosec": 500_000_000},
            "confidence": 0.8,
        },
    ]
    objects = [{"object_id": {"uuid": [255] * 16}, "kinematics": {"predicted_paths": paths}}]
    msg = _round_trip(
        store,
        "autoware_perception_msgs/msg/PredictedObjects",
        {"header": header(T0), "objects": objects},
    )
    predicted = decoders.decode_predicted_objects(msg, "map")
    assert predicted.ids == ("f" * 32,)
    assert predicted.points[0].tolist() == [[30.0, -2.0, 0.0], [32.5, -2.0, 0.0], [35.0, -2.0, 0.0]]
    assert predicted.step_s == (0.5,)


def test_prediction_offsets_of_a_straight_constant_velocity_object() -> None:
    # 5 m/s along CARLA +x, points every 0.5 s for 3 s; 100 ms frames: 30 keys.
    points = np.array([[30.0 + 2.5 * j, -2.0, 1.0] for j in range(7)])
    paths = PredictedPaths(("a",), (points,), (0.5,))
    ego = EgoPose(10.0, 0.0, 0.5, 0.0, 0.0, 0.0, 8.0)
    track = track_offsets(paths, 0.0, 0.1, ego)["a"]
    assert track.keys == tuple(str(k) for k in range(30))
    expected = [[20.0 + 0.5 * (k + 1), -2.0, 0.5] for k in range(30)]
    assert np.allclose(track.offsets, expected, atol=1e-12)
    # the message stamped 20 ms before its frame: key k is 0.02 s further along
    late = track_offsets(paths, 0.02, 0.1, ego)["a"]
    assert len(late.keys) == 29
    assert late.offsets[0] == pytest.approx([20.6, -2.0, 0.5])
    # an ego heading CARLA −y (map +y): a point 10 m ahead is offset (10, 0)
    turned = EgoPose(0.0, 0.0, 0.0, 0.0, 0.0, -90.0, 0.0)
    ahead = PredictedPaths(("b",), (np.array([[0.0, -10.0, 0.0], [0.0, -10.0, 0.0]]),), (1.0,))
    offsets = track_offsets(ahead, 0.0, 0.5, turned)["b"]
    assert offsets.keys == ("0", "1")
    assert np.allclose(offsets.offsets, [[10.0, 0.0, 0.0]] * 2, atol=1e-12)


def test_trajectory_control_and_collision(store: Typestore) -> None:
    points = [
        {
            "pose": _pose(5.0 + i, 0.5 * i),
            "longitudinal_velocity_mps": 8.0 - i,
            "time_from_start": {"nanosec": 100_000_000 * i},
        }
        for i in range(3)
    ]
    trajectory = _round_trip(
        store, "autoware_planning_msgs/msg/Trajectory", {"header": header(T0), "points": points}
    )
    timed = decoders.decode_trajectory(trajectory, "map")
    assert timed.times_s.tolist() == [0.0, 0.1, 0.2]
    assert timed.xy.tolist() == [[5.0, 0.0], [6.0, -0.5], [7.0, -1.0]]
    assert timed.speed.tolist() == [8.0, 7.0, 6.0]
    # The model's plan at a 50 ms period: every other sample between the points.
    plan = sample_plan(timed.times_s, timed.xy, timed.speed, 0.0, 0.05)
    assert plan.keys == ("0", "1", "2", "3", "4")
    assert np.allclose(plan.xy, [[5.0, 0.0], [5.5, -0.25], [6.0, -0.5], [6.5, -0.75], [7.0, -1.0]])
    assert np.allclose(plan.speed, [8.0, 7.5, 7.0, 6.5, 6.0])
    # A message stamped 20 ms before its frame: key 0 is 20 ms along.
    late = sample_plan(timed.times_s, timed.xy, timed.speed, 0.02, 0.05)
    assert late.keys == ("0", "1", "2", "3") and np.allclose(late.xy[0], [5.2, -0.1])
    # Not filled: timed by spacing and speed (1.118 m at 7.5 m/s, then at 6.5 m/s).
    assert np.allclose(
        travel_times(timed.xy, timed.speed), [0.0, 1.118034 / 7.5, 1.118034 / 7.5 + 1.118034 / 6.5]
    )
    backwards = [dict(p) for p in points]
    backwards[2]["time_from_start"] = {"nanosec": 50_000_000}
    bad = _round_trip(
        store, "autoware_planning_msgs/msg/Trajectory", {"header": header(T0), "points": backwards}
    )
    with pytest.raises(MalformedMessage, match=r"points\[2\]\.time_from_start: 0.05 s"):
        decoders.decode_trajectory(bad, "map")
    control = _round_trip(
        store,
        "autoware_control_msgs/msg/Control",
        {
            "stamp": stamp(T0 + 5),
            "lateral": {"steering_tire_angle": 0.25},
            "longitudinal": {"velocity": 8.0, "acceleration": -2.0},
        },
    )
    command = decoders.decode_control(control, "map")
    assert command.steer == pytest.approx(-math.degrees(np.float32(0.25)))  # ROS left → CARLA
    assert (command.acceleration, command.speed) == (-2.0, 8.0)
    assert decoders.DECODERS["autoware_control_msgs/msg/Control"].stamp(control) == T0 + 5
    event = _round_trip(
        store, "carla_msgs/msg/CarlaCollisionEvent", {"header": header(T0), "other_actor_id": 42}
    )
    assert decoders.decode_collision(event, "map").other_actor_id == "42"
    clock = _round_trip(store, "rosgraph_msgs/msg/Clock", {"clock": stamp(T0 + 9)})
    assert decoders.DECODERS["rosgraph_msgs/msg/Clock"].stamp(clock) == T0 + 9


def test_vision_msgs_detections(store: Typestore) -> None:
    hypothesis = [{"hypothesis": {"class_id": "car", "score": 0.8}}]
    two_d = _round_trip(
        store,
        "vision_msgs/msg/Detection2DArray",
        {
            "header": header(T0),
            "detections": [
                {
                    "id": "car-1",
                    "results": hypothesis,
                    "bbox": {
                        "center": {"position": {"x": 100.0, "y": 50.0}},
                        "size_x": 40.0,
                        "size_y": 20.0,
                    },
                },
                {
                    "bbox": {
                        "center": {"position": {"x": 10.0, "y": 10.0}},
                        "size_x": 2.0,
                        "size_y": 4.0,
                    }
                },
            ],
        },
    )
    boxes = decoders.decode_detection_2d_array(two_d, "map")
    assert boxes.ids == ("car-1", "d1")
    assert boxes.corners.tolist() == [[80.0, 40.0, 120.0, 60.0], [9.0, 8.0, 11.0, 12.0]]
    assert boxes.extras == ({"label": "car", "score": 0.8}, {})
    three_d = _round_trip(
        store,
        "vision_msgs/msg/Detection3DArray",
        {
            "header": header(T0),
            "detections": [
                {
                    "id": "t7",
                    "results": hypothesis,
                    "bbox": {
                        "center": _pose(10.0, 2.0, 0.5, math.radians(30)),
                        "size": {"x": 4.0, "y": 2.0, "z": 1.6},
                    },
                },
            ],
        },
    )
    objects = decoders.decode_detection_3d_array(three_d, "map")
    assert objects.ids == ("t7",) and objects.labels == ("car",)
    assert objects.location.tolist() == [[10.0, -2.0, 0.5]]
    assert objects.yaw == pytest.approx([-30.0])
    assert objects.extent.tolist() == [[2.0, 1.0, 0.8]]
    assert objects.score.tolist() == [0.8] and np.isnan(objects.velocity).all()


def test_bad_values_name_the_field(store: Typestore) -> None:
    nan_pose = _round_trip(
        store,
        "nav_msgs/msg/Odometry",
        {"pose": {"pose": {"position": {"x": math.nan}, "orientation": {"w": 1.0}}}},
    )
    with pytest.raises(MalformedMessage, match=r"^pose\.pose\.position\.x: nan, not a finite"):
        decoders.decode_odometry(nan_pose, "map")
    zero_q = _round_trip(store, "nav_msgs/msg/Odometry", {})
    with pytest.raises(MalformedMessage, match=r"^pose\.pose\.orientation: zero quaternion"):
        decoders.decode_odometry(zero_q, "map")
    bad_dims = _round_trip(
        store,
        "autoware_perception_msgs/msg/DetectedObjects",
        {
            "objects": [
                _autoware_object(0, 0, 0),
                _autoware_object(0, 0, 0, shape={"dimensions": {"x": math.inf}}),
            ]
        },
    )
    with pytest.raises(MalformedMessage, match=r"^objects\[1\]\.shape\.dimensions\.x: inf"):
        decoders.decode_detected_objects(bad_dims, "map")


def test_a_string_where_a_number_belongs_is_named() -> None:
    """The bag's own definitions decide the layout: one whose Lateral carries the angle as a
    string decodes, and the decoder refuses the field by name."""
    hostile = typestore(
        {
            "autoware_control_msgs/msg/Lateral": "builtin_interfaces/Time stamp\n"
            "builtin_interfaces/Time control_time\nstring steering_tire_angle\n"
        }
    )
    msg = _round_trip(
        hostile, "autoware_control_msgs/msg/Control", {"lateral": {"steering_tire_angle": "0.1"}}
    )
    with pytest.raises(
        MalformedMessage, match=r"^lateral\.steering_tire_angle: str '0\.1', not a number"
    ):
        decoders.decode_control(msg, "map")


def test_a_uuid_of_the_wrong_length_is_named() -> None:
    hostile = typestore({"unique_identifier_msgs/msg/UUID": "uint8[] uuid\n"})
    objects = [{"object_id": {"uuid": [1] * 16}}, {"object_id": {"uuid": [1] * 15}}]
    msg = _round_trip(hostile, "autoware_perception_msgs/msg/TrackedObjects", {"objects": objects})
    with pytest.raises(MalformedMessage, match=r"^objects\[1\]\.object_id\.uuid: 15 values"):
        decoders.decode_tracked_objects(msg, "map")


def test_a_missing_field_is_named() -> None:
    hostile = typestore({"carla_msgs/msg/CarlaCollisionEvent": "std_msgs/Header header\n"})
    msg = _round_trip(hostile, "carla_msgs/msg/CarlaCollisionEvent", {})
    with pytest.raises(MalformedMessage, match=r"^other_actor_id: missing"):
        decoders.decode_collision(msg, "map")


def test_a_hundred_thousand_objects_are_read_in_one_pass(store: Typestore) -> None:
    """Bounded work per object (columns, not records); the bench, not this test, times it."""
    template = build(
        store,
        "derived_object_msgs/msg/Object",
        {"pose": _pose(1.0, 2.0), "shape": {"dimensions": [4.0, 2.0, 1.0]}},
    )
    from dataclasses import replace

    n = 100_000
    objects = [replace(template, id=i) for i in range(n)]
    msg = build(store, "derived_object_msgs/msg/ObjectArray", {"objects": objects})
    actors = decoders.decode_object_array(msg, "map")
    assert len(actors) == n and actors.ids[-1] == str(n - 1)
    assert actors.location.shape == (n, 3) and (actors.location[:, 1] == -2.0).all()
    assert (actors.extent == [2.0, 1.0, 0.5]).all()


# --- profiles ---------------------------------------------------------------------------------


def test_builtin_profiles_load() -> None:
    autoware = load_profile("carla-autoware")
    assert autoware.reference == "actors" and autoware.camera_loc == (1.5, 0.0, 2.4)
    assert autoware.inputs["predictions"].topic == "/perception/object_recognition/objects"
    assert autoware.ego_role == "ego_vehicle"
    vision = load_profile("vision_msgs")
    assert vision.inputs["detections_3d"].type == "vision_msgs/msg/Detection3DArray"
    assert set(BUILTIN_NAMES) == {p.stem for p in builtin_path("x").parent.glob("*.yaml")}


def test_the_ads_rca_profile_is_the_contract() -> None:
    profile = load_profile("ads_rca")
    assert profile.contract
    for name, spec in profile.inputs.items():
        assert spec.type == contract_type(name)
        key = next(k for k in topics.ALL_TOPICS if topics.topic_name(k) == spec.topic)
        assert topics.MESSAGE_TYPE_NAMES[key] == spec.type


_GOOD = (
    "profile: mine\ninputs:\n"
    "  actors: {topic: /objects, type: derived_object_msgs/msg/ObjectArray}\n"
)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("- a list", "a profile is a mapping"),
        (_GOOD + "colour: red\n", "colour: unknown key"),
        (
            "profile: mine\ninputs:\n  radar: {topic: /r, type: nav_msgs/msg/Odometry}\n",
            "inputs.radar: not a model input",
        ),
        (_GOOD.replace("}", ", qos: 1}"), "inputs.actors.qos: unknown key"),
        (
            _GOOD.replace("derived_object_msgs/msg/ObjectArray", "my_msgs/msg/Things"),
            "inputs.actors.type: no decoder for 'my_msgs/msg/Things'",
        ),
        (
            _GOOD.replace("derived_object_msgs/msg/ObjectArray", "nav_msgs/msg/Odometry"),
            "inputs.actors.type: nav_msgs/msg/Odometry carries ego, not actors",
        ),
        (_GOOD.replace("/objects", "objects"), "inputs.actors.topic: 'objects' is not an abs"),
        (_GOOD.replace("/objects", "3"), "inputs.actors.topic: 3 is not a string"),
        (_GOOD.replace("}", ", frame: utm}"), "inputs.actors.frame: 'utm' is not one of map"),
        (_GOOD.replace("}", ", path: all}"), "inputs.actors.path: 'all' is not one of"),
        (_GOOD.replace("}", ", path: most_probable}"), "inputs.actors.path: only a prediction"),
        (_GOOD + "reference: ego\n", "reference: 'ego' is not an input of the profile"),
        (_GOOD + "metadata: {camera_loc: [1, x, 2]}\n", "metadata.camera_loc: [1, 'x', 2]"),
        (_GOOD + "metadata: {camera_loc: [1, .nan, 2]}\n", "metadata.camera_loc:"),
        (_GOOD + "metadata: {fov: 90}\n", "metadata.fov: unknown key"),
        (
            "profile: mine\ninputs:\n"
            "  plan: {topic: /p, type: autoware_planning_msgs/msg/Trajectory}\n",
            "reference: none given",
        ),
        ("profile: [1\n", "not a YAML profile"),
        (
            _GOOD + "  ego: {topic: /objects, type: nav_msgs/msg/Odometry}\n",
            "inputs.ego.topic: /objects is already inputs.actors's",
        ),
        (_GOOD + "contract: yes please\n", "contract: 'yes please' is not true or false"),
    ],
)
def test_profile_errors_are_one_line_naming_file_and_key(
    tmp_path: Path, text: str, message: str
) -> None:
    path = tmp_path / "mine.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError) as caught:
        load_profile(path)
    said = str(caught.value)
    assert "\n" not in said and said.startswith(f"{path}: ")
    assert message in said


def test_an_unknown_profile_name_lists_the_builtins() -> None:
    with pytest.raises(ConfigError, match=r"^apollo: no such profile .*carla-autoware.*autoware"):
        load_profile("apollo")


# --- whole bags ---------------------------------------------------------------------------------

UUID_A = list(range(16))
PARTNER = 42


def _carla_autoware_messages(store: Typestore) -> list[tuple[str, str, int, Any]]:
    """Ten 100 ms frames: the ego drives along map +x at 10 m/s, actor 42 waits ahead;
    Autoware sees it, tracks it, predicts it driving along map +x at 5 m/s, plans and
    commands; the collision is reported 10 ms after frame 7. Stamps jitter by a few ms."""
    out: list[tuple[str, str, int, Any]] = []
    p = load_profile("carla-autoware").inputs

    def add(name: str, ns: int, values: dict[str, Any], log_delay: int = 2 * MS) -> None:
        out.append(
            (p[name].topic, p[name].type, ns + log_delay, build(store, p[name].type, values))
        )

    for f in range(10):
        t = T0 + f * PERIOD + (3 * MS if f in (3, 6) else 0)  # the reference jitters
        ego_x = float(f)
        add(
            "actors",
            t,
            {
                "header": header(t),
                "objects": [
                    {"id": 1, "pose": _pose(ego_x, 0.0), "shape": {"dimensions": [4.0, 2.0, 1.5]}},
                    {
                        "id": PARTNER,
                        "pose": _pose(20.0, -3.5, 0.0, math.pi / 2),
                        "shape": {"dimensions": [4.0, 2.0, 1.5]},
                    },
                ],
            },
        )
        ego_t = t - 20 * MS
        add(
            "ego",
            ego_t,
            {
                "header": header(ego_t),
                "pose": {"pose": _pose(ego_x, 0.0, 0.5)},
                "twist": {"twist": {"linear": {"x": 10.0}}},
            },
        )
        add(
            "detections_3d",
            t,
            {
                "header": header(t),
                "objects": [
                    _autoware_object(20.5, -3.5, math.pi / 2, kinematics={"has_twist": True})
                ],
            },
        )
        add(
            "tracked_objects",
            t,
            {
                "header": header(t),
                "objects": [
                    {"object_id": {"uuid": UUID_A}, **_autoware_object(20.0, -3.5, math.pi / 2)}
                ],
            },
        )
        frame_t = T0 + f * PERIOD
        path = [_pose(30.0 + 2.5 * j, 2.0) for j in range(7)]
        add(
            "predictions",
            frame_t,
            {
                "header": header(frame_t),
                "objects": [
                    {
                        "object_id": {"uuid": UUID_A},
                        "kinematics": {
                            "predicted_paths": [
                                {
                                    "path": path,
                                    "time_step": {"nanosec": 500_000_000},
                                    "confidence": 1.0,
                                }
                            ]
                        },
                    }
                ],
            },
        )
        add(
            "plan",
            t,
            {
                "header": header(t),
                "points": [
                    {"pose": _pose(ego_x + i, 0.0), "longitudinal_velocity_mps": 10.0}
                    for i in range(5)
                ],
            },
        )
        add(
            "control",
            t,
            {
                "stamp": stamp(t),
                "lateral": {"steering_tire_angle": 0.0},
                "longitudinal": {"velocity": 10.0, "acceleration": -1.0},
            },
        )
    collision_t = T0 + 7 * PERIOD + 10 * MS
    add("collision", collision_t, {"header": header(collision_t), "other_actor_id": PARTNER})
    later = collision_t + 50 * MS
    add("collision", later, {"header": header(later), "other_actor_id": 5})
    return out


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_a_carla_autoware_bag_becomes_a_run(tmp_path: Path, store: Typestore, storage: str) -> None:
    messages = _carla_autoware_messages(store)
    # stray and repeated messages: an ego pose a second before the run, a repeated detection
    early = T0 - 1_000 * MS
    messages.append(
        (
            "/carla/ego_vehicle/odometry",
            "nav_msgs/msg/Odometry",
            early,
            build(
                store,
                "nav_msgs/msg/Odometry",
                {"header": header(early), "pose": {"pose": _pose(0.0, 0.0)}},
            ),
        )
    )
    repeat = T0 + 3 * PERIOD + 10 * MS
    messages.append(
        (
            "/perception/object_recognition/detection/objects",
            "autoware_perception_msgs/msg/DetectedObjects",
            repeat,
            build(
                store, "autoware_perception_msgs/msg/DetectedObjects", {"header": header(repeat)}
            ),
        )
    )
    bag = write_bag(tmp_path / "bag", store, sorted(messages, key=lambda m: m[2]), storage)
    log = read_profiled(load_bag(bag), load_profile("carla-autoware"), decoder(store), str(bag))

    assert log.frame_ms == 100
    assert log.frames == tuple(range(0, 1000, 100))
    meta = log.metadata
    assert (meta.collision_frame, meta.total_frames, meta.camera_loc) == (7, 10, (1.5, 0.0, 2.4))
    assert dict(meta.raw) == {
        "source_profile": "carla-autoware",
        "ego_role": "ego_vehicle",
        "first_message_offset_ms": 1000,  # the stray pose a second before frame 0
        "collision_partner": "42",
    }
    assert sorted(log.pose) == list(range(0, 1000, 100))  # the early pose dropped
    assert log.pose[300].x == 3.0 and log.pose[300].speed == 10.0
    assert log.actors[700].ids == ("1", "42") and log.actors[700].location[1, 1] == 3.5
    assert len(log.detections_3d[300]) == 0  # the later (empty) message of frame 3 kept
    assert log.detections_3d[400].velocity[0] == pytest.approx([0.0, -5.0, 0.0])
    track_id = bytes(UUID_A).hex()
    assert log.tracks_3d[500].ids == (track_id,)
    assert log.controls[200].acceleration == -1.0 and log.controls[200].steer == 0.0
    plan = log.waypoints[200]
    assert plan.keys == ("0", "1", "2", "3", "4") and plan.xy[4].tolist() == [6.0, 0.0]
    track = log.predictions[200][track_id]  # ego at x 2: offsets 28 + 0.5 (k + 1), y −2
    assert len(track.keys) == 30
    assert np.allclose(track.offsets, [[28.0 + 0.5 * (k + 1), -2.0, -0.5] for k in range(30)])
    assert log.predictions_with_perception == {}

    assert log.inputs["ego"] == InputStatus(
        "real", "/carla/ego_vehicle/odometry (nav_msgs/msg/Odometry)"
    )
    assert {name: s.state for name, s in log.inputs.items()} == {
        "ego": "real",
        "actors": "real",
        "detections_2d": "absent",
        "ground_truth_2d": "absent",
        "detections_3d": "real",
        "tracked_objects": "real",
        "predictions": "real",
        "predictions_gt": "absent",
        "plan": "real",
        "control": "real",
        "collision": "real",
        "clock": "absent",
    }
    assert log.inputs["clock"].reason == "topic /clock not in the bag"
    assert log.inputs["detections_2d"].reason == "the profile names no topic for it"
    assert set(log.inputs) == set(MODEL_INPUTS)

    said = [str(p) for p in log.problems]
    assert any("/clock: topic /clock not in the bag" in s for s in said)
    assert any(f"message at log time {early} ns" in s and "outside the frames" in s for s in said)
    assert any("frame 3 has a later message" in s for s in said)


def test_vision_msgs_bag_and_its_inputs(tmp_path: Path, store: Typestore) -> None:
    p = load_profile("vision_msgs").inputs
    messages = []
    for f in range(4):
        t = T0 + f * PERIOD
        for name, values in (
            (
                "actors",
                {
                    "header": header(t),
                    "objects": [
                        {"id": 1, "pose": _pose(f, 0.0), "shape": {"dimensions": [4.0, 2.0, 1.5]}}
                    ],
                },
            ),
            ("ego", {"header": header(t), "pose": {"pose": _pose(f, 0.0)}}),
            (
                "detections_2d",
                {
                    "header": header(t),
                    "detections": [
                        {
                            "id": "a",
                            "bbox": {
                                "center": {"position": {"x": 50.0, "y": 60.0}},
                                "size_x": 10.0,
                                "size_y": 8.0,
                            },
                        }
                    ],
                },
            ),
            ("ground_truth_2d", {"header": header(t), "detections": []}),
            (
                "detections_3d",
                {
                    "header": header(t),
                    "detections": [
                        {
                            "id": "a",
                            "bbox": {"center": _pose(9.0, 1.0), "size": {"x": 2, "y": 2, "z": 2}},
                        }
                    ],
                },
            ),
        ):
            messages.append((p[name].topic, p[name].type, t, build(store, p[name].type, values)))
    bag = write_bag(tmp_path / "vision", store, messages, "sqlite3")
    log = read_profiled(load_bag(bag), load_profile("vision_msgs"), decoder(store), str(bag))
    assert log.frames == (0, 100, 200, 300) and log.metadata.collision_frame == -1
    assert log.bboxes[200].corners.tolist() == [[45.0, 56.0, 55.0, 64.0]]
    assert len(log.bboxes_gt[200]) == 0
    assert log.detections_3d[300].location.tolist() == [[9.0, -1.0, 0.0]]
    states = {name: s.state for name, s in log.inputs.items()}
    assert [n for n, s in states.items() if s == "real"] == [
        "ego",
        "actors",
        "detections_2d",
        "ground_truth_2d",
        "detections_3d",
    ]
    assert log.inputs["collision"].reason == "topic /carla/ego_vehicle/collision not in the bag"
    assert "collision_partner" not in log.metadata.raw


def test_hostile_messages_are_skipped_and_named(tmp_path: Path, store: Typestore) -> None:
    p = load_profile("carla-autoware").inputs
    messages = []
    for f in range(3):
        t = T0 + f * PERIOD
        messages.append(
            (
                p["actors"].topic,
                p["actors"].type,
                t,
                build(store, p["actors"].type, {"header": header(t)}),
            )
        )  # empty ObjectArrays
        x = math.nan if f == 1 else 0.0
        messages.append(
            (
                p["ego"].topic,
                p["ego"].type,
                t,
                build(
                    store,
                    p["ego"].type,
                    {
                        "header": header(t),
                        "pose": {"pose": {"position": {"x": x}, "orientation": {"w": 1.0}}},
                    },
                ),
            )
        )
    messages.append(
        (
            "/control/command/control_cmd",
            "nav_msgs/msg/Odometry",
            T0,
            build(store, "nav_msgs/msg/Odometry", {"header": header(T0)}),
        )
    )
    bag = write_bag(tmp_path / "hostile", store, messages)
    contents = load_bag(bag)
    cut = contents.messages[1]
    contents.messages[1] = type(cut)(
        cut.topic, cut.msg_type, cut.log_time_ns, cut.data[:9], cut.source
    )
    log = read_profiled(contents, load_profile("carla-autoware"), decoder(store), str(bag))
    assert log.frames == (0, 100, 200) and all(len(a) == 0 for a in log.actors.values())
    assert sorted(log.pose) == [200]  # frame 0's bytes cut, frame 1's x NaN
    said = [str(p) for p in log.problems]
    nan = [s for s in said if "pose.pose.position.x: nan" in s]
    assert len(nan) == 1 and f"message at log time {T0 + PERIOD} ns" in nan[0]
    assert any("cannot deserialise" in s for s in said)
    mismatch = [s for s in said if "/control/command/control_cmd: stored type" in s]
    assert mismatch == [
        f"error: {bag}: /control/command/control_cmd: stored type nav_msgs/msg/Odometry, the "
        "profile's control is autoware_control_msgs/msg/Control or "
        "autoware_auto_control_msgs/msg/AckermannControlCommand (no decoder reads "
        "nav_msgs/msg/Odometry as control) (topic skipped; control absent)"
    ]
    assert log.inputs["control"].state == "absent"


def test_a_bag_without_the_reference_topic_is_refused(tmp_path: Path, store: Typestore) -> None:
    bag = write_bag(
        tmp_path / "no_actors",
        store,
        [
            (
                "/carla/ego_vehicle/odometry",
                "nav_msgs/msg/Odometry",
                T0,
                build(store, "nav_msgs/msg/Odometry", {"header": header(T0)}),
            )
        ],
    )
    with pytest.raises(InputError) as caught:
        read_profiled(load_bag(bag), load_profile("carla-autoware"), decoder(store), str(bag))
    assert str(caught.value) == (
        f"{bag}: no usable message on the reference input actors (/carla/objects): topic "
        "/carla/objects not in the bag"
    )


def test_the_contract_profile_is_not_read_here(tmp_path: Path, store: Typestore) -> None:
    bag = write_bag(
        tmp_path / "any",
        store,
        [("/clock", "rosgraph_msgs/msg/Clock", T0, build(store, "rosgraph_msgs/msg/Clock"))],
    )
    with pytest.raises(ConfigError, match="read by the contract reader"):
        read_profiled(load_bag(bag), load_profile("ads_rca"), decoder(store), str(bag))


def test_a_reference_whose_messages_are_all_unusable_is_refused(
    tmp_path: Path, store: Typestore
) -> None:
    unusable = {"header": header(T0), "objects": [{"id": 1}]}  # a zero quaternion
    bag = write_bag(
        tmp_path / "bad_actors",
        store,
        [
            (
                "/carla/objects",
                "derived_object_msgs/msg/ObjectArray",
                T0,
                build(store, "derived_object_msgs/msg/ObjectArray", unusable),
            )
        ],
    )
    with pytest.raises(InputError) as caught:
        read_profiled(load_bag(bag), load_profile("carla-autoware"), decoder(store), str(bag))
    assert str(caught.value) == (
        f"{bag}: no usable message on the reference input actors (/carla/objects): none of "
        "its 1 messages could be used (see the problems)"
    )


def test_a_list_where_a_number_belongs_is_named() -> None:
    hostile = typestore(
        {
            "autoware_perception_msgs/msg/DetectedObject": "float32[] existence_probability\n"
            "ObjectClassification[] classification\nDetectedObjectKinematics kinematics\n"
            "Shape shape\n"
        }
    )
    objects = [
        {**_autoware_object(0, 0, 0), "existence_probability": [0.5]},
        {**_autoware_object(0, 0, 0), "existence_probability": [0.5, 0.1]},
    ]
    msg = _round_trip(hostile, "autoware_perception_msgs/msg/DetectedObjects", {"objects": objects})
    with pytest.raises(
        MalformedMessage, match=r"^objects\[0\]\.existence_probability: ndarray .*not a number"
    ):
        decoders.decode_detected_objects(msg, "map")


def test_a_user_profile_in_the_carla_frame_timed_by_the_ego(
    tmp_path: Path, store: Typestore
) -> None:
    profile_file = tmp_path / "mine.yaml"
    profile_file.write_text(
        "profile: mine\nreference: ego\ninputs:\n"
        "  ego: {topic: /ego, type: nav_msgs/msg/Odometry, frame: carla}\n"
        "  actors: {topic: /gt, type: derived_object_msgs/msg/ObjectArray, frame: carla}\n"
    )
    messages = []
    for f in range(5):
        t = T0 + f * 50 * MS
        ego = {"header": header(t), "pose": {"pose": _pose(f, 2.0, 0.0, math.radians(30))}}
        messages.append(
            ("/ego", "nav_msgs/msg/Odometry", t, build(store, "nav_msgs/msg/Odometry", ego))
        )
        if f % 2 == 0:  # ground truth at half the rate
            gt = {"header": header(t), "objects": [{"id": 3, "pose": _pose(5.0, 2.0)}]}
            messages.append(
                (
                    "/gt",
                    "derived_object_msgs/msg/ObjectArray",
                    t,
                    build(store, "derived_object_msgs/msg/ObjectArray", gt),
                )
            )
    bag = write_bag(tmp_path / "mine", store, messages)
    log = read_profiled(load_bag(bag), load_profile(profile_file), decoder(store), str(bag))
    assert log.frame_ms == 50 and log.metadata.total_frames == 5
    assert log.frames == (0, 100, 200)  # the analysed frames are those with ground truth
    assert sorted(log.pose) == [0, 50, 100, 150, 200]
    assert log.pose[50].y == 2.0  # as given: no flip
    assert log.pose[50].yaw == pytest.approx(30.0)
    assert log.actors[100].location.tolist() == [[5.0, 2.0, 0.0]]
    assert np.isnan(log.actors[100].extent).all()  # no shape dimensions: unknown
    assert log.metadata.camera_loc == (0.0, 0.0, 0.0)  # no 2-D input: nothing said of it
    assert [str(p) for p in log.problems] == []
