"""The launch file and replay start one graph description, and a launch ends.

Everywhere: the launch arguments are ``replay``'s options (described), the graph they
describe is the one replay starts, bad arguments are one line, the end-of-run rule, and a
real graph run the way the launch file runs it (the aggregator ends the run once its
verdict is recorded; the rest then stops with status 0).

Where ``launch``/``launch_ros`` are installed (a ROS install; they are not on the package
registries, so CI skips these): the launch description's arguments are checked through the
``launch`` API, and where ``ros2 launch`` is installed too the package is built with colcon
and launched for real: status 0 with the verdict in the recording, a failing player ends the
launch with status 1 naming it, a missing ``log_path`` is one error line and no node starts.
"""

from __future__ import annotations

import importlib.util
import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import pytest
import yaml

from ads_rca.cli import build_parser
from ads_rca.errors import AdsRcaError, InputError
from ads_rca.params import make_params
from ads_rca.ros.graph import (
    LAUNCH_ARGUMENTS,
    REPLAY_ONLY,
    Graph,
    exit_outcome,
    spec_from_arguments,
)

if TYPE_CHECKING:
    from conftest import RosEnv

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "examples" / "cut_in_perception"
LAUNCH_FILE = REPO / "launch_scripts" / "rca_graph.launch.py"
pytestmark = pytest.mark.timeout(240)


def replay_options() -> set[str]:
    parser = build_parser("replay")
    subparsers = next(a for a in parser._actions if a.dest == "command" or a.choices)
    replay = subparsers.choices["replay"]  # type: ignore[index]
    return {action.dest for action in replay._actions if action.dest != "help"}


def test_launch_arguments_are_replays_options_and_described() -> None:
    mirrored = {argument.replay_option for argument in LAUNCH_ARGUMENTS.values()}
    assert mirrored | set(REPLAY_ONLY) == replay_options()
    assert not mirrored & set(REPLAY_ONLY)
    asked = {"bag_remap", "semantics", "params_file", "record", "rate", "monitors", "namespace"}
    assert asked <= set(LAUNCH_ARGUMENTS)
    for name, argument in LAUNCH_ARGUMENTS.items():
        assert argument.description.strip(), name


def test_arguments_describe_replays_graph(tmp_path: Path) -> None:
    params_file = tmp_path / "rca.yaml"
    params_file.write_text(
        "/**:\n  ros__parameters:\n    semantics: reference\n    safety_margin: 0.75\n"
    )
    remap = tmp_path / "remap.yaml"
    remap.write_text("{}\n")
    spec = spec_from_arguments(
        {
            "log_path": str(EXAMPLE),
            "params_file": str(params_file),
            "record": str(tmp_path / "bag"),
            "monitors": "separate",
            "namespace": "/elsewhere",
            "rate": "2",
            "bag_remap": str(remap),
            "max_file_mb": "8",
        }
    )
    nodes = {node.name: node for node in spec.nodes()}
    assert list(nodes) == [
        "recorder",
        "aggregator",
        "perception_monitor",
        "prediction_monitor",
        "planning_monitor",
        "controller_monitor",
        "player",
    ]
    assert {node.executable for node in nodes.values()} == set(nodes)
    assert {node.params["topic_namespace"] for node in nodes.values()} == {"/elsewhere"}
    assert len({node.params["run_id"] for node in nodes.values()}) == 1
    assert nodes["recorder"].params["output"] == str(tmp_path / "bag")
    aggregator = nodes["aggregator"].params
    assert aggregator["exit_after_verdict"] is True
    assert "verdict_json" not in aggregator
    for name in ("aggregator", "controller_monitor"):
        assert nodes[name].params["semantics"] == "reference"
        assert nodes[name].params["safety_margin"] == 0.75
        assert nodes[name].params["effect_time_window"] == 10  # reference's default
    player = nodes["player"].params
    assert player["log_path"] == str(EXAMPLE)
    assert player["rate"] == 2.0
    assert player["bag_remap"] == str(remap)
    assert player["max_file_mb"] == 8.0
    assert player["wait_for_subscribers"] == 6
    # semantics:= wins over the params file, as --semantics does over --config
    corrected = spec_from_arguments(
        {"log_path": str(EXAMPLE), "params_file": str(params_file), "semantics": "corrected"}
    )
    assert corrected.params == make_params("corrected", {"safety_margin": 0.75})
    assert [n.name for n in corrected.nodes()] == ["aggregator", "monitors", "player"]
    assert corrected.nodes()[1].executable == "monitors"
    # event_time:= beats the params file's event_time_s, and reaches the player
    given = spec_from_arguments({"log_path": str(EXAMPLE), "event_time": "3.5"})
    assert given.params.event_time_s == 3.5
    assert {n.name: n.params for n in given.nodes()}["player"]["event_time_s"] == 3.5


@pytest.mark.parametrize(
    ("values", "message"),
    [
        ({}, "log_path is required: ros2 launch ads_rca rca_graph.launch.py log_path:="),
        ({"log_path": "/no/such/run"}, "log_path /no/such/run: no such log folder or bag"),
        ({"monitors": "both"}, "monitors must be shared or separate, not 'both'"),
        ({"rate": "fast"}, "parameter rate: 'fast' is not a number"),
        ({"rate": "-1"}, "parameter rate: -1 is out of range [0, 1000]"),
        ({"max_file_mb": "0"}, "parameter max_file_mb: 0 is out of range [0.001, 1048576] MB"),
        ({"semantics": "mine"}, "semantics must be one of reference, corrected, not 'mine'"),
        ({"params_file": "/no/such.yaml"}, "/no/such.yaml: cannot read config"),
        ({"event_time": "abc"}, "parameter event_time_s: 'abc' is not a number"),
        ({"event_time": "nan"}, "parameter event_time_s: nan is out of range [-1, 31536000] s"),
        ({"event_time": "-5"}, "parameter event_time_s: -5 is out of range [-1, 31536000] s"),
    ],
)
def test_bad_arguments_are_one_line(values: dict[str, str], message: str) -> None:
    with pytest.raises(InputError) as error:
        spec_from_arguments({"log_path": str(EXAMPLE), **values} if values else {})
    assert str(error.value).startswith(message)
    assert "\n" not in str(error.value)


def test_end_of_run_rule() -> None:
    assert exit_outcome("aggregator", 0) == (True, "run over: the aggregator published the verdict")
    assert exit_outcome("aggregator", 0, stopping=True) is None
    assert exit_outcome("player", 0) is None
    assert exit_outcome("monitors", 0) is None
    assert exit_outcome("player", 2) == (
        False,
        "player exited with status 2: the graph cannot give a verdict",
    )
    assert exit_outcome("recorder", -9, stopping=True) == (
        False,
        "recorder exited with killed by SIGKILL: the graph cannot give a verdict",
    )


def test_graph_description_loads_no_ros() -> None:
    """The launch file and ``replay`` read the description before any ROS process runs."""
    probe = "import sys, ads_rca.ros.graph; print(sorted(m for m in sys.modules if 'rclpy' in m))"
    out = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, check=True
    ).stdout
    assert out.strip() == "[]"


def test_a_launched_graph_ends_when_the_verdict_is_recorded(
    ros_env: RosEnv, tmp_path: Path
) -> None:
    """The launch file's graph, run by our launcher under the same rule: the aggregator exits
    0 by itself once every subscriber (the recorder) has the verdict; stopping the rest then
    gives status 0 everywhere and a bag holding the verdict."""
    spec = spec_from_arguments(
        {
            "log_path": str(EXAMPLE),
            "record": str(tmp_path / "bag"),
            "namespace": ros_env.namespace,
            "verdict_json": str(tmp_path / "verdict.json"),
        }
    )
    with Graph(spec, ros_env.env, echo=sys.stderr) as graph:
        graph.start()
        aggregator = graph.processes["aggregator"]
        assert aggregator.wait(180.0) == 0, aggregator.output
        assert exit_outcome("aggregator", 0) is not None
        codes = graph.stop()
    assert codes == dict.fromkeys(codes, 0), {n: p.output for n, p in graph.processes.items()}
    assert set(codes) == {"recorder", "aggregator", "monitors", "player"}
    assert (tmp_path / "verdict.json").is_file()
    metadata = yaml.safe_load((tmp_path / "bag" / "metadata.yaml").read_text())
    counts = {
        entry["topic_metadata"]["name"]: entry["message_count"]
        for entry in metadata["rosbag2_bagfile_information"]["topics_with_message_count"]
    }
    assert counts[f"{ros_env.namespace}/verdict"] == 1
    assert counts[f"{ros_env.namespace}/verdict/json"] == 1


def test_player_launch_arguments_are_described_player_parameters() -> None:
    from ads_rca.ros.player import PARAMETERS

    spec = importlib.util.spec_from_file_location(
        "player_launch", LAUNCH_FILE.with_name("player.launch.py")
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    for name in module.ARGUMENTS:
        assert PARAMETERS[name][1].strip(), name


# --- with launch / ros2 launch installed (a ROS install) ------------------------------------


def test_launch_description_declares_every_argument_with_a_description() -> None:
    pytest.importorskip("launch", reason="launch is not installed (a ROS install has it)")
    pytest.importorskip("launch_ros", reason="launch_ros is not installed")
    from launch.actions import DeclareLaunchArgument, OpaqueFunction

    spec = importlib.util.spec_from_file_location("rca_graph_launch", LAUNCH_FILE)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    description = module.generate_launch_description()
    declared = [e for e in description.entities if isinstance(e, DeclareLaunchArgument)]
    assert [d.name for d in declared] == list(LAUNCH_ARGUMENTS)
    for argument in declared:
        assert argument.description.strip(), argument.name
        assert argument.default_value is not None
    assert any(isinstance(e, OpaqueFunction) for e in description.entities)


def _ros2() -> Path | None:
    """``ros2`` with its launch verb, next to our interpreter or on PATH; else None."""
    found = Path(sys.executable).parent / "ros2"
    candidate = found if found.exists() else shutil.which("ros2")
    if candidate is None or importlib.util.find_spec("ros2launch") is None:
        return None
    return Path(candidate)


@pytest.fixture(scope="module")
def launch_env(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    ros2 = _ros2()
    if ros2 is None:
        pytest.skip(
            "ros2 launch is not installed (not on the package registries; a ROS install has it)"
        )
    from colconbuild import build_workspace

    prefix = build_workspace(tmp_path_factory.mktemp("launch_ws")) / "ads_rca"
    site = next((prefix / "lib").glob("python3*/site-packages"))
    return {
        "AMENT_PREFIX_PATH": str(prefix),
        "PYTHONPATH": str(site),
        "PATH": f"{ros2.parent}{os.pathsep}{os.environ.get('PATH', '')}",
        "ROS2": str(ros2),
    }


def ros2_launch(
    launch_env: dict[str, str], ros_env: RosEnv, *arguments: str
) -> subprocess.CompletedProcess[str]:
    env = {**ros_env.env, **launch_env}
    return subprocess.run(
        [launch_env["ROS2"], "launch", "ads_rca", "rca_graph.launch.py", *arguments],
        env=env,
        capture_output=True,
        text=True,
        timeout=200,
        check=False,
    )


def test_ros2_launch_ends_with_status_0_when_the_run_is_over(
    launch_env: dict[str, str], ros_env: RosEnv, tmp_path: Path
) -> None:
    bag = tmp_path / "bag"
    result = ros2_launch(
        launch_env,
        ros_env,
        f"log_path:={EXAMPLE}",
        f"record:={bag}",
        f"namespace:={ros_env.namespace}",
        "monitors:=separate",
    )
    output = result.stdout + result.stderr
    assert result.returncode == 0, output
    assert "run over: the aggregator published the verdict" in output
    assert "verdict: perception" in output
    metadata = yaml.safe_load((bag / "metadata.yaml").read_text())
    topics = {
        entry["topic_metadata"]["name"]: entry["message_count"]
        for entry in metadata["rosbag2_bagfile_information"]["topics_with_message_count"]
    }
    assert topics[f"{ros_env.namespace}/verdict/json"] == 1


def test_ros2_launch_fails_with_the_failing_node_named(
    launch_env: dict[str, str], ros_env: RosEnv, tmp_path: Path
) -> None:
    empty = tmp_path / "empty"
    empty.mkdir()
    result = ros2_launch(
        launch_env, ros_env, f"log_path:={empty}", f"namespace:={ros_env.namespace}"
    )
    output = result.stdout + result.stderr
    assert result.returncode == 1, output
    assert "player exited with status 2: the graph cannot give a verdict" in output
    assert "run over" not in output


def test_ros2_launch_without_log_path_is_one_line_and_starts_nothing(
    launch_env: dict[str, str], ros_env: RosEnv
) -> None:
    result = ros2_launch(launch_env, ros_env)
    output = result.stdout + result.stderr
    assert result.returncode == 1, output
    assert "log_path is required: ros2 launch ads_rca rca_graph.launch.py log_path:=" in output
    assert "process started" not in output


def test_ros2_launch_with_the_bridge_ends_once_it_forwarded_the_verdict(
    launch_env: dict[str, str], ros_env: RosEnv, tmp_path: Path
) -> None:
    from loopback import free_port
    from rosrun import listener, rows

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    out = tmp_path / "remote.jsonl"
    remote = listener(ros_env.env, out, "--connect", endpoint, "--until-verdict")
    try:
        result = ros2_launch(
            launch_env,
            ros_env,
            f"log_path:={EXAMPLE}",
            f"namespace:={ros_env.namespace}",
            "zenoh:=true",
            f"zenoh_listen:={endpoint}",
            "zenoh_linger:=1",
        )
        assert remote.wait(30) == 0, remote.output
    finally:
        remote.stop()
    output = result.stdout + result.stderr
    assert result.returncode == 0, output
    assert "run over: the Zenoh bridge forwarded the verdict" in output
    verdicts = [r for r in rows(out) if r.get("key") == "ads_rca/verdict.json"]
    assert json.loads(verdicts[0]["text"])["primary_root_cause"] == "perception"


def test_the_bridge_lingers_30_s_by_default_and_inf_serves_until_stopped() -> None:
    """Late dashboards get the run for 30 s after its verdict, in replay and in the launch;
    ``inf`` keeps the bridge serving until Ctrl-C."""
    from loopback import free_port

    replay = build_parser("replay").parse_args(["replay", str(EXAMPLE)])
    assert float(replay.zenoh_linger) == float(LAUNCH_ARGUMENTS["zenoh_linger"].default) == 30
    for given, linger in (({}, 30.0), ({"zenoh_linger": "inf"}, math.inf)):
        listen = f"tcp/127.0.0.1:{free_port()}"
        values = {"log_path": str(EXAMPLE), "zenoh": "true", "zenoh_listen": listen, **given}
        spec = spec_from_arguments(values)
        assert spec.zenoh_params is not None and spec.zenoh_params["linger_s"] == linger


def test_launch_arguments_start_the_bridge_only_on_request() -> None:
    base = {"log_path": str(EXAMPLE)}
    assert spec_from_arguments(base).zenoh_params is None
    assert spec_from_arguments(base).last_node == "aggregator"
    spec = spec_from_arguments(
        {**base, "zenoh": "true", "zenoh_connect": "tcp/127.0.0.1:7000, tcp/127.0.0.1:7001"}
    )
    assert spec.last_node == "zenoh_bridge"
    bridge = next(node for node in spec.nodes() if node.name == "zenoh_bridge")
    assert bridge.params["zenoh_connect"] == ("tcp/127.0.0.1:7000", "tcp/127.0.0.1:7001")
    assert bridge.params["zenoh_listen"] == ("tcp/127.0.0.1:7447",)
    assert bridge.params["run_id"] == spec.run_id and bridge.params["exit_after_verdict"]
    assert exit_outcome("aggregator", 0, last="zenoh_bridge") is None
    assert exit_outcome("zenoh_bridge", 0, last="zenoh_bridge") == (
        True,
        "run over: the Zenoh bridge forwarded the verdict",
    )
    for bad, message in (
        ({"zenoh": "yes"}, "zenoh must be true or false"),
        (
            {"zenoh": "true", "zenoh_listen": "tcp/0.0.0.0:1"},
            "not on loopback; give zenoh_allow_remote:=true",
        ),
        ({"zenoh": "true", "zenoh_linger": "-3"}, "zenoh_linger"),
        ({"zenoh": "true", "zenoh_linger": "-inf"}, "zenoh_linger: -inf is out of range"),
        ({"zenoh": "true", "zenoh_linger": "nan"}, "zenoh_linger: nan is out of range"),
        ({"zenoh": "true", "zenoh_linger": "soon"}, "zenoh_linger: 'soon' is not a number"),
        ({"zenoh": "true", "zenoh_linger": ""}, "zenoh_linger: '' is not a number"),
    ):
        with pytest.raises(AdsRcaError, match=message):
            spec_from_arguments({**base, **bad})
