"""A value on the command line wins over every shipped params file, for every key in it.

rcl merges params files and ``-p`` rules by node-name pattern, and rclpy applied a file's
node-specific section (``/**/aggregator`` of config/stack_*.yaml) after a ``-p`` rule:
``-p detect_collisions:=true`` was silently overridden, and stack mode gave no verdict.
Each node now applies its command line last (``nodeparams.command_line_overrides``).

For each shipped YAML and each node that reads it, one real node process is started with
``--params-file YAML`` and, for EVERY key of the sections that apply to it, a ``-p`` giving
another valid value (a new key in a shipped file is covered without touching this test);
the node's own "parameters in force" line must show each command-line value.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest
import yaml
from rosrun import wait_for

from ads_rca.ros.launcher import ManagedProcess, format_param

if TYPE_CHECKING:
    from conftest import RosEnv

pytestmark = pytest.mark.timeout(120)

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "config"
EXAMPLE = ROOT / "examples" / "cut_in_perception"

#: (params file, node module argv, node name whose line is read).
NODES = [
    ("stack_carla.yaml", ["ads_rca.ros.aggregator"], "aggregator"),
    ("stack_carla.yaml", ["ads_rca.ros.monitor", "monitors"], "planning_monitor"),
    ("stack_contract.yaml", ["ads_rca.ros.aggregator"], "aggregator"),
    ("stack_contract.yaml", ["ads_rca.ros.monitor", "monitors"], "perception_monitor"),
    ("rca_reference.yaml", ["ads_rca.ros.aggregator"], "aggregator"),
    ("rca_corrected.yaml", ["ads_rca.ros.monitor", "monitors"], "controller_monitor"),
    ("player.yaml", ["ads_rca.ros.player"], "player"),
    ("zenoh_bridge.yaml", ["ads_rca.ros.zenoh_bridge"], "zenoh_bridge"),
]
#: Another valid value for the keys a rule below cannot make one for (choices, names).
OTHER: dict[str, Any] = {
    "stack_mode": "auto",
    "reference_input": "actors",
    "format": "log",
    "log_path": str(EXAMPLE),
    "run_id": "from_the_command_line",
    "zenoh_mode": "peer",  # client needs endpoints: the mode is read, listen changes below
    "zenoh_listen": ["tcp/127.0.0.1:7449"],
    "ego_id": "7",
    "perception_check": "3d",
    "perception_3d_source": "tracked",
}
#: Keys left as the file has them, and why (each still overridden by the same value).
SAME = {
    "semantics": "the other mode reads other thresholds (the mode is shown as 'semantics X')",
    "layout": "each input's layout must fit its topic's type",
    "wait_for_subscribers": "1 would hold the player before it logs",
    "profile": "the example is a log folder: a bag's profile is refused for it",
    "derived_collision": "the example is a log folder: it has no derived collision",
    "zenoh_mode": "client mode needs a peer to connect to",
}


def flatten(document: Any, prefix: str = "") -> dict[str, Any]:
    """``{"inputs": {"pose": {"topic": t}}}`` → ``{"inputs.pose.topic": t}``."""
    if not isinstance(document, dict):
        return {prefix: document}
    out: dict[str, Any] = {}
    for key, value in document.items():
        out.update(flatten(value, f"{prefix}.{key}" if prefix else str(key)))
    return out


def keys_for(file: str, node: str) -> dict[str, Any]:
    """Every key of the file's sections that apply to ``node`` (``/**`` and its own)."""
    document = yaml.safe_load((CONFIG / file).read_text())
    out: dict[str, Any] = {}
    for pattern, section in document.items():
        if pattern == "/**" or pattern.rsplit("/", 1)[-1] in (
            node,
            node.rsplit("_", maxsplit=1)[-1],
        ):
            out.update(flatten(section["ros__parameters"]))
    return out


def other_value(name: str, value: Any, file: str) -> Any:
    leaf = name.rsplit(".", 1)[-1]
    if leaf in SAME or name in SAME:
        return value
    if leaf in OTHER:
        return OTHER[leaf]
    if isinstance(value, bool):
        return not value
    if isinstance(value, int):
        return value + 1
    if isinstance(value, float):
        return value + 0.5
    if isinstance(value, str) and (leaf == "topic" or leaf.endswith("_topic")):
        return f"{value or '/ads_rca/x'}_from_cli"
    if leaf == "topic_namespace":
        return "/from_cli"
    if isinstance(value, str) and leaf in ("zenoh_prefix", "predictions", "submission"):
        return "" if leaf != "zenoh_prefix" else "cli"
    if isinstance(value, str):
        return value
    raise AssertionError(f"{file}: no other value for {name}={value!r}")


def shown(value: Any) -> str:
    return repr(float(value)) if isinstance(value, float) else repr(value)


@pytest.mark.parametrize(("file", "module", "node"), NODES, ids=[f"{f}-{n}" for f, _, n in NODES])
def test_the_command_line_wins_over_the_params_file_for_every_key(
    ros_env: RosEnv, file: str, module: list[str], node: str
) -> None:
    keys = keys_for(file, node)
    assert keys, file
    given = {name: other_value(name, value, file) for name, value in keys.items()}
    if node == "player":
        given["log_path"] = str(EXAMPLE)
    args = ["--ros-args", "--params-file", str(CONFIG / file)]
    for name, value in given.items():
        args += [
            "-p",
            f"{name}:={format_param(tuple(value) if isinstance(value, list) else value)}",
        ]
    # Our own namespace, last: the same rule must keep it (the graph stays ours).
    if "topic_namespace" in given:
        args += ["-p", f"topic_namespace:={ros_env.namespace}"]
        given["topic_namespace"] = ros_env.namespace
    process = ManagedProcess(node, [sys.executable, "-m", *module, *args], ros_env.env)
    try:
        line = wait_for(
            lambda: next(
                (text for text in process.lines if f"[{node}]: parameters in force" in text),
                None,
            ),
            60,
            f"{node}'s parameters in force",
        )
    finally:
        process.stop()
    said = {name: f"{name}={shown(value)}" for name, value in given.items()}
    if "semantics" in given:
        said["semantics"] = f"semantics {given['semantics']};"
    missing = [text for text in said.values() if text not in line]
    assert missing == [], (line, process.output[-2000:])


def test_the_rules_read_are_the_nodes_own_and_typed_as_rcl_types_them() -> None:
    from ads_rca.errors import ConfigError
    from ads_rca.ros.nodeparams import command_line_overrides, command_line_rules

    argv = ["node", "--ros-args", "-p", "a:=1", "--param", "aggregator:b:=x", "-p", "planner:c:=2"]
    argv += ["--params-file", "f.yaml", "-p", "a:=3", "-p", "broken", "--", "-p", "d:=4"]
    assert command_line_rules("aggregator", argv) == {"a": "3", "b": "x"}
    typed = {p.name: p.value for p in command_line_overrides("aggregator", argv)}
    assert typed == {"a": 3, "b": "x"}
    # What rcl keeps as text stays text; nothing is expanded or run.
    hostile = ["--ros-args", "-p", "x:=&a [*a, *a]", "-p", "y:=!!python/object:os.system ls"]
    hostile += ["-p", "z:=k: v", "-p", "w:=2023-01-01", "-p", "n:=.nan", "-p", "t:=true"]
    values = {p.name: p.value for p in command_line_overrides("n", hostile)}
    assert values["x"] == "&a [*a, *a]" and values["z"] == "k: v" and values["w"] == "2023-01-01"
    assert values["y"].startswith("!!python") and values["t"] is True
    assert values["n"] != values["n"]  # NaN: refused later by the range check, in one line
    with pytest.raises(ConfigError, match=r"^parameter m: '\[1, a\]' mixes types in one array$"):
        command_line_overrides("n", ["--ros-args", "-p", "m:=[1, a]"])
