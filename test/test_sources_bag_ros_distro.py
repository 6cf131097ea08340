"""A bag says honestly which ROS distributions it is for.

- The recorder writes ``ros_distro`` (metadata.yaml and the MCAP ``rosbag2`` record) from
  the distribution it runs on: ``ROS_DISTRO``, else the one that released the installed
  rclpy; a bag written outside ROS (``convert``) names the distribution of the contract's
  types.
- Humble: our bags are rosbag2 metadata version 9. :func:`humble_reads` applies the rules of
  Humble's reader (rosbag2_storage ``metadata_io.cpp`` on the humble branch: yaml-cpp
  ``as<T>()`` per field, by version), which refuse them (each topic's
  ``offered_qos_profiles`` must be a string there; version 9 writes a list). So the README
  claims no Humble playback, and says which distributions read them.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import yaml
from mcap.reader import make_reader

from ads_rca.ros.env import ros_distro
from ads_rca.ros.launcher import Launcher, ParamValue, node_command
from ads_rca.sources.bag.mcap_writer import BAG_VERSION, TYPES_DISTRO, McapBagWriter

if TYPE_CHECKING:
    from conftest import RosEnv

REPO = Path(__file__).resolve().parents[1]


class HumbleRefuses(Exception):
    """Humble's rosbag2 throws (``Exception on parsing info file``) at this field."""


def _need(node: Any, key: str, kind: str) -> Any:
    """yaml-cpp's ``node[key].as<kind>()``: a missing key or a node of another shape throws;
    ``string`` accepts any scalar, ``uint64_t``/``int`` an integer scalar."""
    if not isinstance(node, dict) or key not in node:
        raise HumbleRefuses(f"{key}: missing")
    value = node[key]
    if kind == "string" and (isinstance(value, (dict, list)) or value is None):
        raise HumbleRefuses(f"{key}: a {type(value).__name__}, not a string")
    if kind == "int" and (isinstance(value, bool) or not isinstance(value, int)):
        raise HumbleRefuses(f"{key}: {value!r} is not an integer")
    if kind == "strings" and not (
        isinstance(value, list) and all(isinstance(v, str) for v in value)
    ):
        raise HumbleRefuses(f"{key}: not a list of strings")
    return value


def humble_reads(text: str) -> int:
    """Decode a metadata.yaml as Humble's ``convert<BagMetadata>::decode`` does; its version."""
    info = _need(yaml.safe_load(text), "rosbag2_bagfile_information", "map")
    version = _need(info, "version", "int")
    _need(info, "storage_identifier", "string")
    _need(_need(info, "duration", "map"), "nanoseconds", "int")
    _need(_need(info, "starting_time", "map"), "nanoseconds_since_epoch", "int")
    _need(info, "message_count", "int")
    for entry in _need(info, "topics_with_message_count", "list"):
        topic = _need(entry, "topic_metadata", "map")
        for key in ("name", "type", "serialization_format"):
            _need(topic, key, "string")
        if version >= 4:
            _need(topic, "offered_qos_profiles", "string")
        _need(entry, "message_count", "int")
    _need(info, "relative_file_paths", "strings")
    if version >= 3:
        _need(info, "compression_format", "string")
        _need(info, "compression_mode", "string")
    if version >= 5:
        for file in _need(info, "files", "list"):
            _need(file, "path", "string")
            _need(_need(file, "starting_time", "map"), "nanoseconds_since_epoch", "int")
            _need(_need(file, "duration", "map"), "nanoseconds", "int")
            _need(file, "message_count", "int")
    return int(version)


def write_bag(bag: Path, **options: Any) -> dict[str, Any]:
    with McapBagWriter(bag, **options) as writer:
        writer.add_topic("/chatter", "std_msgs/msg/String", "- depth: 10\n  history: keep_last")
        writer.write("/chatter", 1, b"\x00\x01\x00\x00\x01\x00\x00\x00\x00\x00\x00\x00")
    information: dict[str, Any] = yaml.safe_load((bag / "metadata.yaml").read_text())[
        "rosbag2_bagfile_information"
    ]
    return information


def mcap_distro(bag: Path) -> str:
    with next(bag.glob("*.mcap")).open("rb") as stream:
        record = next(m for m in make_reader(stream).iter_metadata() if m.name == "rosbag2")
    return record.metadata["ROS_DISTRO"]


def test_ros_distro_is_the_running_distribution() -> None:
    assert ros_distro({"ROS_DISTRO": "humble"}) == "humble"
    assert ros_distro({"ROS_DISTRO": " "}) == ros_distro({}) == "kilted"  # rclpy 9.1.2, pinned


def test_the_writer_records_the_distribution_it_is_given(tmp_path: Path) -> None:
    assert write_bag(tmp_path / "a", ros_distro="jazzy")["ros_distro"] == "jazzy"
    assert mcap_distro(tmp_path / "a") == "jazzy"
    assert write_bag(tmp_path / "b")["ros_distro"] == TYPES_DISTRO == "kilted"


def test_a_hostile_ros_distro_stays_data_in_the_bag(tmp_path: Path) -> None:
    """ROS_DISTRO comes from the environment: a line break or YAML syntax in it cannot add
    keys to metadata.yaml or the MCAP metadata; it reads back as the same text."""
    hostile = ros_distro({"ROS_DISTRO": "x\nros_distro: forged\n  - {a: [1"})
    assert hostile == "x\nros_distro: forged\n  - {a: [1"
    information = write_bag(tmp_path / "bag", ros_distro=hostile)
    assert information["ros_distro"] == hostile
    assert mcap_distro(tmp_path / "bag") == hostile


def test_the_recorder_writes_the_distribution_it_runs_on(ros_env: RosEnv, tmp_path: Path) -> None:
    env = dict(ros_env.env, ROS_DISTRO="jazzy")
    params: dict[str, ParamValue] = {"output": str(tmp_path / "bag"), "max_duration_s": 0.5}
    with Launcher(env, echo=sys.stderr) as launcher:
        recorder = launcher.start("recorder", node_command("ads_rca.ros.recorder", params))
        assert recorder.wait(60) == 0, recorder.output
    document = yaml.safe_load((tmp_path / "bag" / "metadata.yaml").read_text())
    assert document["rosbag2_bagfile_information"]["ros_distro"] == "jazzy"
    assert mcap_distro(tmp_path / "bag") == "jazzy"


def test_humbles_reader_refuses_our_bags_and_the_readme_says_so(tmp_path: Path) -> None:
    write_bag(tmp_path / "bag")
    text = (tmp_path / "bag" / "metadata.yaml").read_text()
    try:
        humble_reads(text)
    except HumbleRefuses as refused:
        assert str(refused) == "offered_qos_profiles: a list, not a string"
    else:
        raise AssertionError("Humble's rules accepted a version 9 metadata.yaml")
    # The rules do accept what Humble writes: the same bag with its QoS as a string.
    document = yaml.safe_load(text)
    for entry in document["rosbag2_bagfile_information"]["topics_with_message_count"]:
        entry["topic_metadata"]["offered_qos_profiles"] = "- depth: 10"
    assert humble_reads(yaml.safe_dump(document)) == BAG_VERSION
    readme = (REPO / "README.md").read_text()
    assert "(Humble, Jazzy, Kilted)" not in readme
    assert "metadata version 9" in readme and "Humble's rosbag2 cannot read them" in readme
