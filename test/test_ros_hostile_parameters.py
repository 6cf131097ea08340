"""ROS parameters of the wrong type or no number: one line naming the parameter, exit 2.

rclpy raises ``InvalidParameterTypeException`` (``-p start_frame:=abc``) and a dynamically
typed double can hold any string; both used to end a node with a traceback. Every node
declares its parameters through ``nodeparams`` and refuses such values in one line.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

from ads_rca.ros.graph import GROUP
from ads_rca.ros.launcher import ManagedProcess, ros_args

if TYPE_CHECKING:
    from conftest import RosEnv

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "cut_in_perception"

CASES = [
    ("ads_rca.ros.player", "start_frame", "abc"),
    ("ads_rca.ros.player", "rate", "abc"),
    ("ads_rca.ros.player", "loop", "maybe"),
    ("ads_rca.ros.aggregator", "verdict_timeout_s", "abc"),
    ("ads_rca.ros.aggregator", "semantics", 7),
    ("monitors", "effect_time_window", "abc"),
    ("ads_rca.ros.recorder", "chunk_size", "abc"),
    ("ads_rca.ros.topic_summary", "timeout_s", "abc"),
]


@pytest.mark.parametrize(("node", "name", "value"), CASES)
def test_a_parameter_of_the_wrong_type_is_one_line_and_exit_2(
    ros_env: RosEnv, tmp_path: Path, node: str, name: str, value: Any
) -> None:
    params: dict[str, Any] = {name: value, "topic_namespace": ros_env.namespace}
    if node == "ads_rca.ros.player":
        params["log_path"] = str(EXAMPLE)
    if node == "ads_rca.ros.recorder":
        params["output"] = str(tmp_path / "bag")
    module = ["ads_rca.ros.monitor", GROUP] if node == "monitors" else [node]
    process = ManagedProcess(node, [sys.executable, "-m", *module, *ros_args(params)], ros_env.env)
    code = process.wait(60)
    output = process.output
    process.stop()
    assert code == 2, output
    assert "Traceback" not in output, output
    assert f"parameter {name}" in output, output


def _start(node: str, assignment: str, ros_env: Any, tmp_path: Path) -> tuple[int | None, str]:
    """Run ``node`` with one raw ``-p`` assignment (plus what it needs to start)."""
    needed: dict[str, Any] = {"topic_namespace": ros_env.namespace}
    if node == "ads_rca.ros.player":
        needed["log_path"] = str(EXAMPLE)
    if node == "ads_rca.ros.recorder":
        needed["output"] = str(tmp_path / "bag")
    module = ["ads_rca.ros.monitor", GROUP] if node == "monitors" else [node]
    argv = [sys.executable, "-m", *module, *ros_args(needed), "-p", assignment]
    process = ManagedProcess(node, argv, ros_env.env)
    code = process.wait(60)
    output = process.output
    process.stop()
    return code, output


RANGE_CASES = [
    ("monitors", "safety_margin:=-1.0", "parameter safety_margin: -1 is out of range [0, 100] m"),
    ("monitors", "window_s:=.nan", "parameter window_s: nan is out of range [0, 3600] s"),
    (
        "monitors",
        "perception_check:=4d",
        "parameter perception_check: '4d' is not one of auto | 2d | 3d",
    ),
    (
        "monitors",
        "episode_rewind_s:=.nan",
        "parameter episode_rewind_s: nan is out of range [0, 86400] s",
    ),
    (
        "monitors",
        "stamp_jump_s:=-.inf",
        "parameter stamp_jump_s: -inf is out of range [0, 86400] s",
    ),
    (
        "ads_rca.ros.aggregator",
        "episode_rewind_s:=-1.0",
        "parameter episode_rewind_s: -1 is out of range [0, 86400] s",
    ),
    (
        "ads_rca.ros.aggregator",
        "window_s:=-3",
        "parameter window_s: -3 is out of range [0, 3600] s",
    ),
    (
        "ads_rca.ros.aggregator",
        "effect_time_window:=-3",
        "parameter effect_time_window: -3 is out of range [0, 100000] frames",
    ),
    ("ads_rca.ros.player", "rate:=-.inf", "parameter rate: -inf is out of range [0, 1000]"),
    ("ads_rca.ros.player", "ack_every:=41", "parameter ack_every: 41 is out of range [1, 40]"),
    (
        "ads_rca.ros.player",
        "event_time_s:=.nan",
        "parameter event_time_s: nan is out of range [-1, 31536000] s",
    ),
    (
        "ads_rca.ros.player",
        "event_decel:=0.0",
        "parameter event_decel: 0 is out of range [0.1, 100] m/s²",
    ),
    (
        "ads_rca.ros.recorder",
        "chunk_size:=0",
        "parameter chunk_size: 0 is out of range [1024, 1073741824] bytes",
    ),
    (
        "ads_rca.ros.recorder",
        "graph_wait_s:=-1.0",
        "parameter graph_wait_s: -1 is out of range [0, 3600] s",
    ),
    (
        "ads_rca.ros.zenoh_bridge",
        "graph_wait_s:=.nan",
        "parameter graph_wait_s: nan is out of range [0, 3600] s",
    ),
    (
        "ads_rca.ros.topic_summary",
        "timeout_s:=-1.0",
        "parameter timeout_s: -1 is out of range [0, 86400] s",
    ),
]


@pytest.mark.parametrize(("node", "assignment", "message"), RANGE_CASES)
def test_a_value_out_of_range_stops_the_node_in_one_line_naming_the_range(
    ros_env: Any, tmp_path: Path, node: str, assignment: str, message: str
) -> None:
    code, output = _start(node, assignment, ros_env, tmp_path)
    assert code == 2, output
    errors = [line for line in output.splitlines() if "[ERROR]" in line]
    assert len(errors) == 1 and errors[0].endswith(f"]: {message}"), output
    assert "Traceback" not in output, output


@pytest.mark.parametrize(
    ("node", "assignment", "known"),
    [
        ("monitors", "safety_margn:=0.8", "safety_margin"),
        ("ads_rca.ros.player", "window_s:=2.0", "log_path"),  # an engine name: not the player's
        ("ads_rca.ros.aggregator", "verdict_jsn:=x.json", "verdict_json"),
    ],
)
def test_an_unknown_parameter_stops_the_node_with_the_known_names(
    ros_env: Any, tmp_path: Path, node: str, assignment: str, known: str
) -> None:
    code, output = _start(node, assignment, ros_env, tmp_path)
    assert code == 2, output
    errors = [line for line in output.splitlines() if "[ERROR]" in line]
    name = assignment.split(":=", maxsplit=1)[0]
    assert len(errors) == 1, output
    assert f"]: unknown parameter '{name}' (known: " in errors[0], output
    assert known in errors[0].split("(known: ")[1].rstrip(")").split(", "), output
    assert "Traceback" not in output, output


@pytest.mark.parametrize(
    ("assignment", "message"),
    [
        ("format:=nonsense", "format 'nonsense': expected one of auto, log, bag,"),
        ("format:='{}'", "format '{}': expected one of auto, log, bag,"),
        ("ego_agent:=" + "x" * 300, "ego_agent: expected an agent token or number"),
        ("submission:=/nonexistent.csv", "--submission applies to atmaCup tables"),
        ("predictions:=/nonexistent_dir", "--predictions applies to CARLA runs"),
    ],
)
def test_a_hostile_source_parameter_stops_the_player_in_one_line(
    ros_env: Any, tmp_path: Path, assignment: str, message: str
) -> None:
    """The player's source options (the CLI's --format, --ego-agent, --submission,
    --predictions) as ROS parameters: refused as the CLI refuses them, one line, exit 2."""
    code, output = _start("ads_rca.ros.player", assignment, ros_env, tmp_path)
    assert code == 2, output
    errors = [line for line in output.splitlines() if "[ERROR]" in line]
    assert len(errors) == 1 and message in errors[0], output
    assert "Traceback" not in output, output
