"""ROS 2 launch file: stack mode, beside a running stack (monitors, aggregator, recorder).

``ros2 launch ads_rca stack_graph.launch.py [stack_params:=config/stack_carla.yaml]
[semantics:=reference] [record:=BAG] [detect_collisions:=true]``; ``--show-args`` describes
every argument. No player: the monitors judge the stack's own topics (docs/live-graph.md,
"Stack mode"), framed by the header stamps of the input ``reference_input`` names, and the
aggregator gives a verdict at each collision (``run/collision``, the stack's
``collision_topic``, or detected from ground truth). The stack file (``config/stack_*.yaml``)
says which topic carries each input and how, and the run facts (frame period, ego id,
camera location). The run has no end of its own: stop it with Ctrl-C (every node exits 0 and
the recorder finalises its bag), or ``exit_after_verdict:=true`` to end after the first
verdict.

``launch``/``launch_ros`` are imported inside the functions, so the module can be linted and
type-checked where they are not installed.
"""

from __future__ import annotations

from typing import Any

#: Every node discovers on this machine only, whatever the caller's environment says.
LOCAL_DISCOVERY = {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}

#: name -> (default, description); "" for stack_params = the package's stack_contract.yaml.
ARGUMENTS: dict[str, tuple[str, str]] = {
    "stack_params": ("", "Stack file: inputs, layouts, run facts ('' = stack_contract.yaml)."),
    "semantics": ("corrected", "Oracle semantics: reference or corrected."),
    "namespace": ("/ads_rca", "Namespace of the graph's own topics."),
    "record": ("", "Record every topic to this new bag directory ('' = no recording)."),
    "verdict_json": ("", "Write each verdict's JSON here (verdict N > 1: name.N.json)."),
    "detect_collisions": ("false", "Detect collisions from ground truth (flagged derived)."),
    "exit_after_verdict": ("false", "End the launch once the first verdict is out."),
    "zenoh": ("false", "Start the zenoh_bridge node: results on Zenoh (docs/remote.md)."),
    "zenoh_mode": ("peer", "Zenoh session mode: peer or client."),
    "zenoh_listen": ("tcp/127.0.0.1:7447", "Zenoh endpoints to listen on, comma-separated."),
    "zenoh_connect": ("", "Zenoh endpoints to connect to, comma-separated ('' = none)."),
    "zenoh_prefix": ("", "Key prefix of every Zenoh sample."),
    "zenoh_allow_remote": ("false", "Allow Zenoh endpoints off loopback (TLS, access control)."),
    "rate_modules": ("20.0", "Most JSON samples per second per module key (0 = all)."),
}


def generate_launch_description() -> Any:
    from launch import LaunchDescription
    from launch.actions import DeclareLaunchArgument, OpaqueFunction

    arguments = [
        DeclareLaunchArgument(name, default_value=default, description=text)
        for name, (default, text) in ARGUMENTS.items()
    ]
    return LaunchDescription([*arguments, OpaqueFunction(function=stack_actions)])


def bridge_parameters(values: dict[str, str]) -> dict[str, Any]:
    """The Zenoh bridge beside the stack: every verdict forwarded, no end of its own (the
    launch's end, Ctrl-C or the aggregator's exit, stops it; it sends what it has first)."""
    from ads_rca.ros.graph import bridge_params

    def endpoints(text: str) -> tuple[str, ...]:
        return tuple(part.strip() for part in text.split(",") if part.strip())

    params: dict[str, Any] = bridge_params(
        values["zenoh_mode"],
        endpoints(values["zenoh_listen"]),
        endpoints(values["zenoh_connect"]),
        values["zenoh_prefix"],
        values["zenoh_allow_remote"].lower() == "true",
        values["rate_modules"],
        0.0,
        allow_option="zenoh_allow_remote:=true",
        listen_option="zenoh_listen:=tcp/127.0.0.1:PORT",
    )
    return {
        name: list(value) if isinstance(value, tuple) else value for name, value in params.items()
    } | {"topic_namespace": values["namespace"]}


def rule(value: Any) -> str:
    """A parameter value as the text of a ``-p name:=value`` rule: JSON, which rcl reads as
    YAML (a string stays quoted: never read as a number, a bool or a mapping)."""
    import json

    return json.dumps(value)


def stack_actions(context: Any) -> list[Any]:
    """The recorder (if asked), the aggregator and the monitors, with the stack file."""
    from ament_index_python.packages import get_package_share_directory
    from launch.actions import EmitEvent, RegisterEventHandler
    from launch.event_handlers import OnProcessExit
    from launch.events import Shutdown
    from launch.substitutions import LaunchConfiguration
    from launch_ros.actions import Node

    values = {name: LaunchConfiguration(name).perform(context) for name in ARGUMENTS}
    stack_file = values["stack_params"] or (
        f"{get_package_share_directory('ads_rca')}/config/stack_contract.yaml"
    )
    common = {
        "semantics": values["semantics"],
        "topic_namespace": values["namespace"],
        "stack_mode": "stack",
    }
    aggregator = {
        **common,
        "detect_collisions": values["detect_collisions"].lower() == "true",
        "exit_after_verdict": values["exit_after_verdict"].lower() == "true",
        **({"verdict_json": values["verdict_json"]} if values["verdict_json"] else {}),
    }

    def node(executable: str, parameters: list[Any]) -> Any:
        """The stack file as a params file; the launch arguments' values as ``-p`` rules,
        which win over every params file (a file's ``/**/aggregator`` section would
        otherwise beat a plain parameter dict, as rcl merges them)."""
        files = [p for p in parameters if isinstance(p, str)]
        given = {k: v for p in parameters if isinstance(p, dict) for k, v in p.items()}
        return Node(
            package="ads_rca",
            executable=executable,
            output="screen",
            parameters=files,
            ros_arguments=[arg for k, v in given.items() for arg in ("-p", f"{k}:={rule(v)}")],
            additional_env=LOCAL_DISCOVERY,
        )

    recorder = {"output": values["record"], "topic_namespace": values["namespace"]}
    actions = [node("recorder", [recorder])] if values["record"] else []
    if values["zenoh"].lower() == "true":
        actions.append(node("zenoh_bridge", [bridge_parameters(values)]))
    agg = node("aggregator", [stack_file, aggregator])
    monitors = node("monitors", [stack_file, common])
    end = OnProcessExit(target_action=agg, on_exit=[EmitEvent(event=Shutdown())])
    return [*actions, agg, monitors, RegisterEventHandler(end)]
