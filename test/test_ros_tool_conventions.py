"""What ROS tools expect of our outputs: diagnostics keyed by name, plottable metrics, camera.

- ``/diagnostics``: one status per module per array (rqt_robot_monitor, the
  diagnostic_aggregator and Foxglove key statuses by name and keep only the last);
- ``metrics/<module>/values``: the JSON metrics as numbers with labels, equal frame by frame
  to the JSON, in a recorded MCAP read back with mcap-ros2-support;
- the camera: its static transform and CameraInfo, latched, built from the run metadata.
"""

from __future__ import annotations

import json
import math
import shutil
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from cdrlayout import differences
from rosrun import wait_for

from ads_rca.contract import cdr, topics
from ads_rca.contract.camera import Intrinsics, camera_intrinsics, camera_mount
from ads_rca.contract.jsontext import loads_json
from ads_rca.live import diagnostics as diag
from ads_rca.live.numeric import HEAD, NumericLayout
from ads_rca.live.results import LiveResult
from ads_rca.oracles.base import MODULES, OracleResult
from ads_rca.ros.launcher import ManagedProcess, node_command
from ads_rca.sources.log.reader import read_run_log

pytestmark = pytest.mark.timeout(180)


def _result(index: int, failed: bool, metrics: dict[str, Any] | None = None) -> LiveResult:
    oracle = OracleResult("perception", 50 * index, failed, metrics or {}, {}, (), None)
    return LiveResult(index=index, result=oracle, frame=index, run="r1")


def test_a_judged_batch_is_one_status_for_its_latest_frame() -> None:
    batch = [_result(3, False), _result(4, True), _result(5, True), _result(6, False)]
    status = diag.batch_status(batch, "corrected", "hw")
    values = dict(status.values)
    assert status.name == "ads_rca/perception"
    assert status.level == diag.OK  # the latest frame passed
    assert status.message == "frame 6: ok (2 of 4 frames since the last status failed)"
    assert values["frame"] == "6" and values["index"] == "6" and values["run"] == "r1"
    assert values["judged_since_last"] == "4" and values["failed_since_last"] == "2"
    failing = diag.batch_status(batch[:2], "corrected", "hw")
    assert failing.level == diag.ERROR
    assert failing.message == "frame 4: perception failed"
    assert dict(failing.values)["failed_since_last"] == "1"
    # The encoded array holds that one status (what the aggregator's raw reader sees).
    assert diag.status_runs(diag.encode_array(0, [status])) == [("ads_rca/perception", "r1")]


def test_numeric_rows_keep_every_label_at_its_position() -> None:
    layout = NumericLayout(["c_plan", "c_gt"])
    assert layout.labels == [*HEAD, "c_plan", "c_gt"]
    first = layout.row(_result(2, True, {"c_gt": 1.5, "ids_n": 3, "note": "x", "m": {"a": 1}}))
    assert layout.labels == [*HEAD, "c_plan", "c_gt", "ids_n"]
    assert _same(first, [2.0, 1.0, 0.0, 0.0, 0.0, math.nan, 1.5, 3.0])
    second = layout.row(_result(3, False, {"late": None, "flag": True, "c_plan": -0.25}))
    assert layout.labels == [*HEAD, "c_plan", "c_gt", "ids_n", "late", "flag"]
    assert _same(second, [3.0, 0.0, 0.0, 0.0, 0.0, -0.25, math.nan, math.nan, math.nan, 1.0])


def _same(a: list[float], b: list[float]) -> bool:
    return np.array_equal(np.asarray(a), np.asarray(b), equal_nan=True)


def test_joint_state_bytes_equal_rclpy() -> None:
    """Byte for byte. rclpy's serialize_message reports 8 bytes more for a JointState: its
    size calculation aligns the two empty float64[] (velocity, effort) that the writer does
    not; those trailing bytes are uninitialised and no reader looks at them."""
    from rclpy.serialization import deserialize_message, serialize_message
    from sensor_msgs.msg import JointState

    for names, values in ((["frame", "c_gt"], [61.0, math.nan]), ([], [])):
        msg = JointState(name=names, position=values)
        msg.header.stamp.sec, msg.header.stamp.nanosec = 3, 50_000_000
        ours = cdr.encode_joint_state(3050, names, values)
        theirs = serialize_message(msg)
        assert len(theirs) == len(ours) + 8
        assert not differences(ours, theirs[: len(ours)], msg)
        back = deserialize_message(ours, JointState)
        assert back.name == names and _same(list(back.position), values)


def test_recorded_values_equal_the_json_metrics_frame_by_frame(
    ros_env: Any, tmp_path: Path, log_dirs: Any
) -> None:
    """A replay recorded to MCAP, read back with mcap-ros2-support: per module, the n-th
    ``values`` message holds the n-th JSON result's numbers, labelled, at its log time."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    log_dir = log_dirs("cut_in", "planning")
    bag = tmp_path / "bag"
    argv = [sys.executable, "-m", "ads_rca.cli", "replay", str(log_dir), "--record", str(bag)]
    argv += ["--domain-id", str(ros_env.domain_id), "--timeout", "90"]
    replay = ManagedProcess("replay", argv, ros_env.env)
    assert replay.wait(120) == 0, replay.output
    documents: dict[str, list[dict[str, Any]]] = {m: [] for m in MODULES}
    rows: dict[str, list[Any]] = {m: [] for m in MODULES}
    with next(bag.glob("*.mcap")).open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        # In the order recorded (= published, per topic): the log times (rmw's reception
        # stamps) of a burst are not always increasing, and log-time order would mix them.
        for schema, channel, _raw, msg in reader.iter_decoded_messages(log_time_order=False):
            parts = channel.topic.split("/")  # "", "ads_rca", "metrics", module[, "values"]
            if parts[2:3] != ["metrics"]:
                continue
            if parts[4:] == ["values"]:
                assert schema is not None and schema.name == "sensor_msgs/msg/JointState"
                rows[parts[3]].append(msg)
            else:
                documents[parts[3]].append(loads_json(msg.data))
    verdict = json.loads((bag / "verdict.json").read_text())
    for module in MODULES:
        assert len(documents[module]) == len(rows[module]), module
        # Each frame's final result, after any provisional one shown while the run played.
        finals = [d for d in documents[module] if not d.get("provisional")]
        assert len(finals) == len(verdict["frames"]), module
        for document, msg in zip(documents[module], rows[module], strict=True):
            assert (
                msg.header.stamp.sec * 1000 + msg.header.stamp.nanosec // 10**6
                == (document["stamp_ms"])
            )
            assert list(msg.name[: len(HEAD)]) == list(HEAD)
            expected = _numbers(document)
            assert set(expected) <= set(msg.name)  # every numeric metric is there
            got = dict(zip(msg.name, msg.position, strict=True))
            for label, value in got.items():
                want = expected.get(label, math.nan)  # a label of another frame: NaN here
                assert value == want or (math.isnan(value) and math.isnan(want)), label
    # The documented position of the partner's clearance (docs/topics.md).
    assert rows["planning"][0].name[6] == "c_gt"


def _numbers(document: dict[str, Any]) -> dict[str, float]:
    """The JSON result's plottable numbers, transcribed from docs/topics.md."""
    out = {
        "frame": float(document["frame"]),
        "failed": float(document["failed"]),
        "skipped": float(bool(document["skipped"])),
        "incomplete": float(bool(document["incomplete"])),
        "revision": float(document["revision"]),
    }
    for key, value in document["metrics"].items():
        if key in out or isinstance(value, str | list | dict):
            continue
        out[key] = math.nan if value is None else float(value)
    return out


EXAMPLE = Path(__file__).parents[1] / "examples" / "cut_in_perception"


def _with_camera(tmp_path: Path, **camera: Any) -> Path:
    """The example log with CARLA's camera attributes added to its metadata."""
    log_dir = tmp_path / "log"
    shutil.copytree(EXAMPLE, log_dir)
    document = json.loads((log_dir / "metadata.json").read_text())
    document["ego_config"]["camera"].update(camera)
    (log_dir / "metadata.json").write_text(json.dumps(document))
    return log_dir


def test_the_camera_mount_and_intrinsics_come_from_the_metadata(tmp_path: Path) -> None:
    metadata = read_run_log(EXAMPLE).metadata  # camera_loc [1.3, 0.0, 1.8], no intrinsics
    mount = camera_mount(metadata)
    assert (mount.parent, mount.child) == ("base_link", "camera_image")
    assert mount.translation == (1.3, -0.0, 1.8)
    # The optical frame: z along the body's x (forward), x along -y (right), y along -z.
    x, y, z, w = mount.rotation
    matrix = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    assert np.array_equal(matrix.T, [[0, -1, 0], [0, 0, -1], [1, 0, 0]])  # rows: optical axes
    assert camera_intrinsics(metadata) is None
    given = read_run_log(_with_camera(tmp_path, image_size_x="1920", image_size_y=1080, fov=90))
    focal = 1920 / (2 * math.tan(math.pi / 4))  # 960 (and a last bit: tan(45°) < 1)
    assert camera_intrinsics(given.metadata) == Intrinsics(1920, 1080, focal, focal, 960.0, 540.0)
    for bad, field in (({"fov": 180}, "fov"), ({"image_size_x": 19.5}, "image_size_x")):
        log = read_run_log(
            _with_camera(
                tmp_path / field, **{"image_size_x": 1920, "image_size_y": 1080, "fov": 90, **bad}
            )
        )
        with pytest.raises(ValueError, match=f"ego_config.camera.{field}:"):
            camera_intrinsics(log.metadata)


def test_tf_message_bytes_equal_the_reference_serialiser() -> None:
    """No tf2_msgs wheel, so rclpy cannot serialise a TFMessage here: rosbags' Kilted type
    store can (its bytes equal rclpy's, environment.md)."""
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_KILTED)
    types = store.types
    mount = camera_mount(read_run_log(EXAMPLE).metadata)
    transform = types["geometry_msgs/msg/TransformStamped"](
        header=types["std_msgs/msg/Header"](
            stamp=types["builtin_interfaces/msg/Time"](sec=0, nanosec=50_000_000),
            frame_id=mount.parent,
        ),
        child_frame_id=mount.child,
        transform=types["geometry_msgs/msg/Transform"](
            translation=types["geometry_msgs/msg/Vector3"](*mount.translation),
            rotation=types["geometry_msgs/msg/Quaternion"](*mount.rotation),
        ),
    )
    message = types["tf2_msgs/msg/TFMessage"](transforms=[transform])
    reference = bytes(store.serialize_cdr(message, "tf2_msgs/msg/TFMessage"))
    assert cdr.encode_tf_message(50, [mount]) == reference


def test_a_late_subscriber_gets_the_camera(ros_env: Any, tmp_path: Path) -> None:
    """Over DDS: the player sends the camera once at start, latched; a subscriber that
    joins afterwards still gets CameraInfo (and /tf_static where tf2_msgs is installed)
    with the metadata's numbers."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from sensor_msgs.msg import CameraInfo

    try:
        from tf2_msgs.msg import TFMessage
    except ImportError:
        TFMessage = None
    log_dir = _with_camera(tmp_path, image_size_x=800, image_size_y=600, fov=60.0)
    params = {
        "log_path": str(log_dir),
        "topic_namespace": ros_env.namespace,
        "wait_for_subscribers": 1,  # nobody subscribes to run/frame: the player stays up
        "wait_timeout_s": 60.0,
    }
    player = ManagedProcess("player", node_command("ads_rca.ros.player", params), ros_env.env)
    context = rclpy.Context()
    try:
        # The player logs this line after publishing: the subscriber below joins late.
        wait_for(lambda: "camera/camera_info: 800x600 px" in player.output, 30, "camera_info")
        rclpy.init(context=context)
        node = rclpy.create_node("late_camera_subscriber", context=context)
        got: dict[str, Any] = {}
        node.create_subscription(
            CameraInfo,
            topics.topic_name(topics.CAMERA_INFO, ros_env.namespace),
            lambda msg: got.setdefault("info", msg),
            topics.qos_profile(topics.CAMERA_INFO),
        )
        if TFMessage is not None:
            node.create_subscription(
                TFMessage,
                topics.TF_STATIC,
                lambda msg: got.setdefault("tf", msg),
                topics.qos_profile(topics.TF_STATIC),
            )
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        wanted = {"info"} if TFMessage is None else {"info", "tf"}
        deadline = time.monotonic() + 20
        while not wanted <= set(got) and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        assert wanted <= set(got), player.output
    finally:
        player.stop()
        rclpy.try_shutdown(context=context)
    info = got["info"]
    focal = 800 / (2 * math.tan(math.radians(60.0) / 2))
    assert info.header.frame_id == "camera_image" and (info.width, info.height) == (800, 600)
    assert list(info.k) == [focal, 0.0, 400.0, 0.0, focal, 300.0, 0.0, 0.0, 1.0]
    assert list(info.p) == [focal, 0.0, 400.0, 0.0, 0.0, focal, 300.0, 0.0, 0.0, 0.0, 1.0, 0.0]
    assert info.distortion_model == "plumb_bob" and list(info.d) == [0.0] * 5
    assert info.header.stamp.sec * 1000 + info.header.stamp.nanosec // 10**6 == 50  # frame 1
    if TFMessage is None:
        assert "tf2_msgs is not installed: /tf_static not published" in player.output
        return
    (transform,) = got["tf"].transforms
    assert (transform.header.frame_id, transform.child_frame_id) == ("base_link", "camera_image")
    t, q = transform.transform.translation, transform.transform.rotation
    assert (t.x, t.y, t.z) == (1.3, -0.0, 1.8)
    assert (q.x, q.y, q.z, q.w) == (-0.5, 0.5, -0.5, 0.5)
