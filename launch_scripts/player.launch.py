"""ROS 2 launch file: the ads_rca player with its parameter file (``ros2 launch`` in a ROS install).

Each argument is the player parameter of the same name, described by the node's own
parameter table (``ads_rca.ros.player.PARAMETERS``; ``--show-args`` prints it). ``launch``
and ``launch_ros`` are imported inside :func:`generate_launch_description`, so the module can
be linted and type-checked where they are not installed.
"""

from __future__ import annotations

from typing import Any

#: The player parameters exposed as launch arguments, with their launch defaults.
ARGUMENTS = {
    "log_path": "",
    "rate": "1.0",
    "topic_namespace": "/ads_rca",
    "start_frame": "0",
    "stop_frame": "-1",
}


def generate_launch_description() -> Any:
    import os

    from ament_index_python.packages import get_package_share_directory
    from launch import LaunchDescription
    from launch.actions import DeclareLaunchArgument
    from launch.substitutions import LaunchConfiguration
    from launch_ros.actions import Node

    from ads_rca.ros.player import PARAMETERS

    params_file = os.path.join(get_package_share_directory("ads_rca"), "config", "player.yaml")
    return LaunchDescription(
        [
            *(
                DeclareLaunchArgument(name, default_value=default, description=PARAMETERS[name][1])
                for name, default in ARGUMENTS.items()
            ),
            Node(
                package="ads_rca",
                executable="player",
                name="player",
                output="screen",
                parameters=[
                    params_file,
                    {name: LaunchConfiguration(name) for name in ARGUMENTS},
                ],
                additional_env={"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"},
            ),
        ]
    )
