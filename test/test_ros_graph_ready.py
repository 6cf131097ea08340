"""The recorder and the Zenoh bridge are counted ready only once they hear the graph.

A player waits for every node's ``run/ready_<id>`` subscription; that says nothing about
whether the recorder (or the bridge) has matched the monitors' and the aggregator's
publishers. In one CI run the recorder had not, the 109-frame run ended and the graph was
stopped, and the bag held no result. Over real DDS, each node in its own process: with
``graph_wait_s`` the node does not subscribe to the ready topic while the graph's outputs
have no publisher, does once they all have one (publishers created by this test, with the
QoS the monitors and the aggregator use), and after ``graph_wait_s`` without them it is
ready anyway and names the topics still alone.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest
from loopback import free_port
from rosrun import wait_for

from ads_rca.contract import live_topics, topics
from ads_rca.ros.launcher import ManagedProcess, ParamValue, node_command, ros_args

if TYPE_CHECKING:
    from conftest import RosEnv

pytestmark = pytest.mark.timeout(120)

RUN = "ready1"
NODES = ("recorder", "zenoh_bridge")


def start(ros_env: RosEnv, tmp_path: Path, name: str, wait_s: float) -> ManagedProcess:
    params: dict[str, ParamValue] = {
        "topic_namespace": ros_env.namespace,
        "run_id": RUN,
        "graph_wait_s": wait_s,
    }
    if name == "recorder":
        params["output"] = str(tmp_path / "bag")
        return ManagedProcess(name, node_command("ads_rca.ros.recorder", params), ros_env.env)
    params["zenoh_listen"] = (f"tcp/127.0.0.1:{free_port()}",)
    argv = [sys.executable, "-m", "ads_rca.ros.zenoh_bridge", *ros_args(params)]
    return ManagedProcess(name, argv, ros_env.env)


@contextmanager
def running(process: ManagedProcess) -> Iterator[ManagedProcess]:
    """``process``, stopped (SIGINT, as a launch does) when the block ends."""
    try:
        yield process
    finally:
        process.stop()


@dataclass
class PlayerSide:
    """A node in this process holding the run's ready and frame publishers, as a player."""

    node: Any
    ready: Any
    frame: Any


@pytest.fixture
def player_side(ros_env: RosEnv) -> Iterator[PlayerSide]:
    import rclpy
    from std_msgs.msg import String

    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node("player_side", context=context)
    ns = ros_env.namespace
    ready = node.create_publisher(String, topics.topic_name(live_topics.ready_key(RUN), ns), 1)
    frame_topic = topics.topic_name(topics.FRAME, ns)
    frame = node.create_publisher(String, frame_topic, topics.qos_profile(topics.FRAME))
    try:
        yield PlayerSide(node, ready, frame)
    finally:
        node.destroy_node()
        rclpy.shutdown(context=context)


def graph_publishers(node: Any, namespace: str) -> list[Any]:
    """A publisher on every graph output, with the QoS its real publisher offers."""
    from rclpy.qos import QoSProfile

    from ads_rca.contract import rosmsg

    offered: dict[str, QoSProfile] = {
        "std_msgs/msg/String": live_topics.metrics_qos(),
        "sensor_msgs/msg/JointState": live_topics.metrics_qos(),
    }
    made = []
    for name, (msg_type, reader_qos) in live_topics.graph_topics(namespace).items():
        qos = reader_qos() if "verdict" in name or name == live_topics.DIAGNOSTICS else None
        cls = rosmsg.message_class(msg_type)
        made.append(node.create_publisher(cls, name, qos or offered[msg_type]))
    return made


@pytest.mark.parametrize("name", NODES)
def test_ready_only_once_every_graph_output_has_a_publisher(
    ros_env: RosEnv, tmp_path: Path, player_side: PlayerSide, name: str
) -> None:
    with running(start(ros_env, tmp_path, name, 60.0)) as process:
        wait_for(lambda: player_side.frame.get_subscription_count() >= 1, 60, "the node")
        time.sleep(1.5)
        assert process.returncode is None, process.output
        assert player_side.ready.get_subscription_count() == 0, process.output
        made = graph_publishers(player_side.node, ros_env.namespace)
        assert len(made) == len(live_topics.graph_topics(ros_env.namespace))
        wait_for(lambda: player_side.ready.get_subscription_count() == 1, 30, "ready")
        assert "no publisher of" not in process.output
    assert process.returncode == 0, process.output


@pytest.mark.parametrize("name", NODES)
def test_ready_anyway_after_graph_wait_naming_the_topics_alone(
    ros_env: RosEnv, tmp_path: Path, player_side: PlayerSide, name: str
) -> None:
    with running(start(ros_env, tmp_path, name, 1.0)) as process:
        wait_for(lambda: player_side.ready.get_subscription_count() == 1, 60, "ready")
        wait_for(lambda: "no publisher of" in process.output, 10, "the warning")
    (line,) = [s for s in process.output.splitlines() if "no publisher of" in s]
    ns = ros_env.namespace
    for topic in (f"{ns}/metrics/planning", f"{ns}/verdict", live_topics.DIAGNOSTICS):
        assert topic in line, line
    assert "after 1 s; ready anyway" in line


def test_replay_and_the_launch_file_give_the_wait_inside_the_players() -> None:
    """The graph's recorder and bridge wait (``GRAPH_WAIT_S``), and give up before the
    player, which started after them, stops waiting for them and plays anyway."""
    from ads_rca.params import make_params
    from ads_rca.ros.graph import BRIDGE_NAME, GRAPH_WAIT_S, GraphSpec, bridge_params

    zenoh = bridge_params("peer", ("tcp/127.0.0.1:7447",), (), "", False, 20.0, 0.0)
    spec = GraphSpec(Path("log"), make_params("corrected"), None, record=Path("bag"))
    spec.zenoh_params = zenoh
    nodes = {node.name: node.params for node in spec.nodes()}
    assert nodes["recorder"]["graph_wait_s"] == nodes[BRIDGE_NAME]["graph_wait_s"]
    assert 0 < GRAPH_WAIT_S == nodes["recorder"]["graph_wait_s"]
    assert float(str(nodes["player"]["wait_timeout_s"])) > GRAPH_WAIT_S
