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

from ads_rca.ros.launcher import ManagedProcess, ros_args
from ads_rca.ros.monitor import GROUP

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
