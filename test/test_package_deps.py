"""Every import the package makes is a declared dependency.

A workspace built with ``rosdep install`` + ``colcon build`` gets exactly what package.xml
declares; an undeclared import fails there later with ModuleNotFoundError. So every
third-party module imported anywhere in ``ads_rca/`` and ``launch_scripts/`` (walked with
ast, imports inside functions included), plus the message packages the topic table loads by
name, must map to a key package.xml declares: a ROS package under its own name, a Python
library under its rosdep key (rosdistro's ``rosdep/python.yaml``). ``setup.py`` must name
the PyPI distribution of every non-ROS one, for ``pip install``.
"""

from __future__ import annotations

import ast
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

from ads_rca.contract import topics

REPO = Path(__file__).resolve().parents[1]

#: Import name → rosdep key, for the modules that are no ROS package.
ROSDEP_KEYS = {
    "numpy": "python3-numpy",
    "scipy": "python3-scipy",
    "yaml": "python3-yaml",
    "matplotlib": "python3-matplotlib",
    "tqdm": "python3-tqdm",
    "orjson": "python3-orjson",
    "aiohttp": "python3-aiohttp",
    "rosbags": "python3-rosbags-pip",
    "rich": "python3-rich",
    "mcap": "mcap-ros2-support",  # no key for mcap itself; this one pip-installs it
    "zstandard": "mcap-ros2-support",  # a dependency of mcap
    "lz4": "mcap-ros2-support",  # a dependency of mcap
    "zenoh": "python3-eclipse-zenoh-pip",
    "dask": "python3-dask",  # Debian's python3-dask; the rosdep key is our guess
    "distributed": "python3-distributed",  # Debian's python3-distributed; key guessed too
    "pyarrow": "python3-pyarrow-pip",  # no distribution package we know of: pip, guessed key
}
#: Import name → the PyPI distribution setup.py must require for it.
PIP_NAMES = {"yaml": "pyyaml", "zstandard": "mcap", "lz4": "mcap", "zenoh": "eclipse-zenoh"}


def third_party_imports() -> dict[str, str]:
    """Top-level module → one file importing it."""
    found: dict[str, str] = {}
    files = [*(REPO / "ads_rca").rglob("*.py"), *(REPO / "launch_scripts").glob("*.py")]
    for path in files:
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            else:
                continue
            for name in names:
                top = name.split(".")[0]
                if top not in sys.stdlib_module_names and top != "ads_rca":
                    found.setdefault(top, str(path.relative_to(REPO)))
    for type_name in topics.MESSAGE_TYPE_NAMES.values():  # imported by name at run time
        found.setdefault(type_name.split("/")[0], "ads_rca/contract/topics.py")
    return found


def declared(kinds: tuple[str, ...] = ("depend", "exec_depend")) -> set[str]:
    root = ET.parse(REPO / "package.xml").getroot()
    return {element.text.strip() for kind in kinds for element in root.iter(kind) if element.text}


def install_requires() -> set[str]:
    tree = ast.parse((REPO / "setup.py").read_text())
    call = next(
        node
        for node in ast.walk(tree)
        if isinstance(node, ast.Call) and getattr(node.func, "id", "") == "setup"
    )
    value = next(k.value for k in call.keywords if k.arg == "install_requires")
    assert isinstance(value, ast.List)
    return {ast.literal_eval(item) for item in value.elts}


def test_every_import_is_declared_in_package_xml() -> None:
    imports = third_party_imports()
    # The walk sees imports inside functions (launch files, zstandard) and the topic table's.
    assert {"rclpy", "numpy", "mcap", "zstandard", "launch_ros", "rosgraph_msgs"} <= set(imports)
    keys = declared()
    missing = {
        f"{name} ({where}) → {ROSDEP_KEYS.get(name, name)}"
        for name, where in imports.items()
        if ROSDEP_KEYS.get(name, name) not in keys
    }
    assert not missing, f"declare in package.xml: {sorted(missing)}"


def test_every_python_library_is_in_install_requires() -> None:
    needed = {PIP_NAMES.get(name, name) for name in third_party_imports() if name in ROSDEP_KEYS}
    assert needed - install_requires() == set()


def test_package_xml_keys_are_rosdeps_own_names() -> None:
    """No pip distribution name where rosdep wants its key (``pyyaml``, ``rosbags``...)."""
    keys = declared(("depend", "exec_depend", "build_depend", "test_depend"))
    assert not keys & {"pyyaml", "rosbags", "mcap", "orjson", "numpy", "matplotlib", "tqdm"}
    assert not {k for k in keys if k.startswith("python3-")} - {
        *ROSDEP_KEYS.values(),
        "python3-pytest",
        "python3-shapely",
    }
