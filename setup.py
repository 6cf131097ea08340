"""ament_python package definition: works with `pip install` and with `colcon build`."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = "ads_rca"

# Every ROS executable, as `ros2 run ads_rca <name>` finds it under lib/ads_rca.
NODES = {
    "player": "ads_rca.ros.player:main",
    "topic_summary": "ads_rca.ros.topic_summary:main",
    "recorder": "ads_rca.ros.recorder:main",
    "perception_monitor": "ads_rca.ros.monitor:perception_main",
    "prediction_monitor": "ads_rca.ros.monitor:prediction_main",
    "planning_monitor": "ads_rca.ros.monitor:planning_main",
    "controller_monitor": "ads_rca.ros.monitor:controller_main",
    "monitors": "ads_rca.ros.monitor:group_main",
    "aggregator": "ads_rca.ros.aggregator:main",
    "zenoh_bridge": "ads_rca.ros.zenoh_bridge:entry",
}

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(include=[PACKAGE, f"{PACKAGE}.*"]),
    # The built-in profiles, the definitions (with their licences) the bag reader falls back
    # on for old recordings, the stacks' .msg files that synthesised recordings are typed by,
    # and the web dashboard's page.
    package_data={
        PACKAGE: [
            "py.typed",
            "sources/bag/profiles/builtin/*.yaml",
            "sources/bag/definitions/README.md",
            "sources/bag/definitions/*/LICENSE",
            "sources/bag/definitions/*/msg/*.idl",
            "sources/bag/definitions/*/msg/*.msg",
            "synth/msgs/README.md",
            "synth/msgs/*/LICENSE",
            "synth/msgs/*/msg/*.msg",
            "remote/static/*",
        ]
    },
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", glob("config/*.yaml")),
        (f"share/{PACKAGE}/launch_scripts", glob("launch_scripts/*.py")),
    ],
    # ROS client libraries, messages and launch come from the ROS install (colcon) or from the
    # pinned wheels in requirements.txt (plain pip), so they are deliberately not
    # install_requires; package.xml declares them for rosdep. mcap brings zstandard and lz4.
    install_requires=[
        "numpy",
        "scipy",
        "orjson",
        "pyyaml",
        "tqdm",
        "matplotlib",
        "rosbags",
        "mcap",
        "eclipse-zenoh",
        "rich",
        "aiohttp",
        "dask",
        "distributed",
        "pyarrow",
    ],
    zip_safe=True,
    maintainer="ads_rca maintainers",
    maintainer_email="maintainers@ads-rca.dev",
    description="Root-cause analysis of autonomous-driving crashes on ROS 2.",
    license="Apache-2.0",
    python_requires=">=3.10",
    entry_points={
        "console_scripts": [f"{name} = {target}" for name, target in NODES.items()]
        + ["ads-rca = ads_rca.cli:entry"],
    },
)
