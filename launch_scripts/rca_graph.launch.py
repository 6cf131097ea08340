"""ROS 2 launch file: the live graph (player, four monitors, aggregator, optional recorder).

``ros2 launch ads_rca rca_graph.launch.py log_path:=RUN [record:=BAG] [monitors:=separate]``;
``--show-args`` lists and describes every argument. The arguments are ``ads-rca replay``'s
options under their launch names, and the nodes with their parameters come from the
description replay starts (``ads_rca.ros.graph``: ``LAUNCH_ARGUMENTS``,
``spec_from_arguments``), so the two cannot drift apart.

How it ends (launch's own ``OnProcessExit`` and ``Shutdown``, per ``graph.exit_outcome``):

- the aggregator exits 0 once its verdict is published and acknowledged by every
  subscriber (the recorder among them): the launch shuts down, SIGINT to the rest, the
  recorder finalises its bag, every node exits 0, and ``ros2 launch`` exits 0; with
  ``zenoh:=true`` the Zenoh bridge ends the run instead, once it forwarded the verdict and
  answered late dashboards for ``zenoh_linger`` seconds (30; ``inf``: until Ctrl-C), every
  node running until then;
- a node exits non-zero (the player's 2 for an unusable log, a crash): every node is
  stopped and the launch fails (status 1: ``ros2 launch`` has no other failure status),
  its error line naming the node and its exit status;
- no ``log_path`` (or no such log, a bad ``params_file``, ``rate`` or ``monitors``): one
  error line, no node started, status 1.

``launch``/``launch_ros`` are imported inside the functions, so the module can be linted and
type-checked where they are not installed.
"""

from __future__ import annotations

import functools
from typing import Any

#: Every node discovers on this machine only, whatever the caller's environment says.
LOCAL_DISCOVERY = {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}


def generate_launch_description() -> Any:
    from launch import LaunchDescription
    from launch.actions import DeclareLaunchArgument, OpaqueFunction

    from ads_rca.ros.graph import LAUNCH_ARGUMENTS

    arguments = [
        DeclareLaunchArgument(name, default_value=arg.default, description=arg.description)
        for name, arg in LAUNCH_ARGUMENTS.items()
    ]
    return LaunchDescription([*arguments, OpaqueFunction(function=graph_actions)])


def graph_actions(context: Any) -> list[Any]:
    """The nodes of the graph the arguments describe, each with its exit handler."""
    from launch.actions import RegisterEventHandler
    from launch.event_handlers import OnProcessExit
    from launch.substitutions import LaunchConfiguration
    from launch_ros.actions import Node
    from launch_ros.parameter_descriptions import ParameterValue

    from ads_rca.ros.graph import LAUNCH_ARGUMENTS, spec_from_arguments

    values = {name: LaunchConfiguration(name).perform(context) for name in LAUNCH_ARGUMENTS}
    spec = spec_from_arguments(values)
    actions: list[Any] = []
    for node in spec.nodes():
        # Strings stay strings (launch_ros would read a run id of digits as an integer);
        # a tuple (the bridge's endpoints) is a string array.
        params = {
            name: ParameterValue(value, value_type=str)
            if isinstance(value, str)
            else list(value)
            if isinstance(value, tuple)
            else value
            for name, value in node.params.items()
        }
        process = Node(
            package="ads_rca",
            executable=node.executable,
            output="screen",
            parameters=[params],
            additional_env=LOCAL_DISCOVERY,
        )
        handler = OnProcessExit(
            target_action=process,
            on_exit=functools.partial(on_exit, node.name, spec.last_node),
        )
        actions += [process, RegisterEventHandler(handler)]
    return actions


def on_exit(name: str, last: str, event: Any, context: Any) -> list[Any]:
    """End of the run: shut the launch down; a failed node: fail the launch, saying why."""
    from launch.actions import LogInfo, Shutdown

    from ads_rca.ros.graph import exit_outcome

    outcome = exit_outcome(name, int(event.returncode), context.is_shutdown, last)
    if outcome is None:
        return []
    over, why = outcome
    if not over:
        raise RuntimeError(why)  # launch logs it, stops every node, and returns 1
    return [LogInfo(msg=why), Shutdown(reason=why)]
