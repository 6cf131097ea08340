"""The pure-Python launcher and environment: network rule enforced, clean escalating stop."""

from __future__ import annotations

import math
import sys
from pathlib import Path

from ads_rca.ros.env import pick_domain_id, ros_environment
from ads_rca.ros.launcher import ManagedProcess, format_param, node_command, ros_args


def test_environment_always_local_only_with_domain_and_log_dir(tmp_path: Path) -> None:
    base = {"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET", "ROS_STATIC_PEERS": "10.0.0.1"}
    env = ros_environment(domain_id=17, log_dir=tmp_path, base=base)
    assert env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    assert "ROS_STATIC_PEERS" not in env
    assert env["ROS_DOMAIN_ID"] == "17" and env["ROS_LOG_DIR"] == str(tmp_path)
    picked = ros_environment(base={})
    assert 1 <= int(picked["ROS_DOMAIN_ID"]) <= 101 and picked["ROS_LOG_DIR"]
    assert all(1 <= pick_domain_id(t) <= 101 for t in range(300))


def test_parameters_are_formatted_for_ros_args() -> None:
    assert format_param(True) == "true"
    assert format_param(3) == "3"
    assert format_param(0.0) == "0.0"
    assert format_param(math.inf) == ".inf"  # YAML's: a double to rcl and to PyYAML
    assert format_param("123") == '"123"'
    assert ros_args({"rate": 2.0}, "p.yaml") == [
        "--ros-args",
        "--params-file",
        "p.yaml",
        "-p",
        "rate:=2.0",
    ]
    assert node_command("m")[1:] == ["-m", "m"]


def test_stop_escalates_to_sigterm_when_sigint_is_ignored(tmp_path: Path) -> None:
    script = (
        "import signal, sys, time\n"
        "signal.signal(signal.SIGINT, signal.SIG_IGN)\n"
        "print('ready', flush=True)\n"
        "time.sleep(60)\n"
    )
    process = ManagedProcess(
        "stubborn", [sys.executable, "-c", script], ros_environment(domain_id=5, log_dir=tmp_path)
    )
    for _ in range(200):
        if "ready" in process.output:
            break
        process.wait(0.05)
    assert process.stop(timeout=0.5) == -15
    assert process.output == "ready"


def test_config_player_yaml_lists_every_parameter_with_its_default() -> None:
    from pathlib import Path

    import yaml

    from ads_rca.ros.player import PARAMETERS

    path = Path(__file__).resolve().parent.parent / "config" / "player.yaml"
    params = yaml.safe_load(path.read_text())["/**"]["ros__parameters"]
    assert params == {name: entry[0] for name, entry in PARAMETERS.items()}


def test_config_zenoh_bridge_yaml_lists_every_parameter_with_its_default() -> None:
    from pathlib import Path

    import yaml

    from ads_rca.ros.zenoh_bridge import PARAMETERS

    path = Path(__file__).resolve().parent.parent / "config" / "zenoh_bridge.yaml"
    params = yaml.safe_load(path.read_text())["/**"]["ros__parameters"]
    # An empty list cannot be written in a params file (rcl cannot type it): commented out.
    stated = {name: entry[0] for name, entry in PARAMETERS.items() if entry[0] != []}
    assert params == stated
    for name in set(PARAMETERS) - set(stated):
        assert f"# {name}: [" in path.read_text()
