"""ROS 2 launch file: the ads_rca player with its parameter file (``ros2 launch`` in a ROS install).

``launch``/``launch_ros`` are not installed in this venv (``ads-rca demo`` plays the same role
here), so their imports stay inside :func:`generate_launch_description`: the module can be
linted and type-checked without them.
"""

from __future__ import annotations

from typing import Any


def generate_launch_description() -> Any:
    import os

    from ament_index_python.packages import get_package_share_directory
    from launch import LaunchDescription
    from launch.actions import DeclareLaunchArgument
    from launch.substitutions import LaunchConfiguration
    from launch_ros.actions import Node

    params_file = os.path.join(get_package_share_directory("ads_rca"), "config", "player.yaml")
    arguments = {
        "log_path": "",
        "rate": "1.0",
        "topic_namespace": "/ads_rca",
        "start_frame": "0",
        "stop_frame": "-1",
    }
    return LaunchDescription(
        [
            *(
                DeclareLaunchArgument(name, default_value=default)
                for name, default in arguments.items()
            ),
            Node(
                package="ads_rca",
                executable="player",
                name="player",
                output="screen",
                parameters=[
                    params_file,
                    {name: LaunchConfiguration(name) for name in arguments},
                ],
                additional_env={"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"},
            ),
        ]
    )
