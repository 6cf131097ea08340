"""ROS 2 launch file: the live graph (player, four monitors, aggregator, optional recorder).

``monitors:=shared`` (the default) runs the four monitor nodes in one ``monitors`` process,
which receives and decodes the inputs once; ``monitors:=separate`` runs one process each.

For users with a ROS install (``ros2 launch ads_rca rca_graph.launch.py log_path:=RUN``);
here ``ads-rca replay`` starts the same graph through ``ads_rca.ros.graph``. ``launch`` and
``launch_ros`` are not installed in this venv, so their imports stay inside
:func:`generate_launch_description` and the module can be linted and type-checked without them.
Every node gets the engine parameter file of the chosen semantics (``config/rca_<mode>.yaml``),
then the launch arguments.
"""

from __future__ import annotations

from typing import Any

MONITORS = ("perception_monitor", "prediction_monitor", "planning_monitor", "controller_monitor")


def generate_launch_description() -> Any:
    import os

    from ament_index_python.packages import get_package_share_directory
    from launch import LaunchDescription
    from launch.actions import DeclareLaunchArgument
    from launch.conditions import IfCondition
    from launch.substitutions import LaunchConfiguration, PythonExpression
    from launch_ros.actions import Node

    share = get_package_share_directory("ads_rca")
    arguments = {
        "log_path": "",
        "rate": "0.0",
        "semantics": "corrected",
        "topic_namespace": "/ads_rca",
        "verdict_json": "verdict.json",
        "record": "false",
        "record_output": "rca_recording",
        "monitors": "shared",
    }
    semantics = LaunchConfiguration("semantics")
    engine_file = PythonExpression(
        ["'", os.path.join(share, "config", "rca_"), "' + '", semantics, "' + '.yaml'"]
    )
    common = {"topic_namespace": LaunchConfiguration("topic_namespace"), "semantics": semantics}
    env = {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    layout = LaunchConfiguration("monitors")
    shared = IfCondition(PythonExpression(["'", layout, "' == 'shared'"]))
    separate = IfCondition(PythonExpression(["'", layout, "' == 'separate'"]))
    # The player waits until every process subscribed to run/frame.
    subscribers = PythonExpression(
        [
            "1 + (1 if '",
            layout,
            "' == 'shared' else 4) + (1 if '",
            LaunchConfiguration("record"),
            "'.lower() == 'true' else 0)",
        ]
    )
    nodes = [
        Node(
            package="ads_rca",
            executable="recorder",
            name="recorder",
            output="screen",
            parameters=[
                {
                    "output": LaunchConfiguration("record_output"),
                    "topic_namespace": LaunchConfiguration("topic_namespace"),
                }
            ],
            condition=IfCondition(LaunchConfiguration("record")),
            additional_env=env,
        ),
        Node(
            package="ads_rca",
            executable="aggregator",
            name="aggregator",
            output="screen",
            parameters=[
                engine_file,
                {**common, "verdict_json": LaunchConfiguration("verdict_json")},
            ],
            additional_env=env,
        ),
        Node(
            package="ads_rca",
            executable="monitors",
            output="screen",
            parameters=[engine_file, common],
            condition=shared,
            additional_env=env,
        ),
        *(
            Node(
                package="ads_rca",
                executable=name,
                name=name,
                output="screen",
                parameters=[engine_file, common],
                condition=separate,
                additional_env=env,
            )
            for name in MONITORS
        ),
        Node(
            package="ads_rca",
            executable="player",
            name="player",
            output="screen",
            parameters=[
                os.path.join(share, "config", "player.yaml"),
                {
                    "log_path": LaunchConfiguration("log_path"),
                    "rate": LaunchConfiguration("rate"),
                    "topic_namespace": LaunchConfiguration("topic_namespace"),
                    "wait_for_subscribers": subscribers,
                },
            ],
            additional_env=env,
        ),
    ]
    return LaunchDescription(
        [
            *(
                DeclareLaunchArgument(name, default_value=default)
                for name, default in arguments.items()
            ),
            *nodes,
        ]
    )
