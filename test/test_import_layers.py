"""The layers import downwards only: the pure packages load no ROS (issue #13 item 1).

``contract/`` (topic table, conversion, CDR codec, playback, assembler), ``io/``, ``live/``,
the oracles and the engine must work where no ROS runtime is installed or wanted (offline
diagnosis, bag conversion, simulation). Two checks: importing every module of those packages
in a fresh interpreter loads no rclpy or message package, and none of them names
``ads_rca.ros`` in an import (the nodes sit on top and import the core, never the reverse).
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import ads_rca

PACKAGE = Path(ads_rca.__file__).resolve().parent

#: Packages and modules that must import without ROS.
PURE = ("ads_rca.contract", "ads_rca.io", "ads_rca.live", "ads_rca.oracles", "ads_rca.engine")
#: Top-level modules that only a ROS process may load.
ROS_MODULES = (
    "rclpy",
    "std_msgs",
    "geometry_msgs",
    "visualization_msgs",
    "diagnostic_msgs",
    "nav_msgs",
    "trajectory_msgs",
    "rosgraph_msgs",
    "builtin_interfaces",
)

_PROBE = """
import importlib, json, pkgutil, sys
names = []
for name in {pure!r}:
    module = importlib.import_module(name)
    names.append(name)
    for info in pkgutil.walk_packages(getattr(module, "__path__", []), name + "."):
        importlib.import_module(info.name)
        names.append(info.name)
print(json.dumps({{"imported": names, "loaded": sorted(sys.modules)}}))
"""


def _pure_files() -> list[Path]:
    files = [PACKAGE / "engine.py"]
    for sub in ("contract", "io", "live", "oracles"):
        files.extend(sorted((PACKAGE / sub).rglob("*.py")))
    return files


def test_pure_packages_load_no_ros_module() -> None:
    out = subprocess.run(
        [sys.executable, "-c", _PROBE.format(pure=PURE)],
        capture_output=True,
        text=True,
        check=True,
        timeout=120,
    )
    result = json.loads(out.stdout)
    assert "ads_rca.contract.cdr" in result["imported"]  # the walk reached the submodules
    assert "ads_rca.io.bag_reader" in result["imported"]
    ros = [m for m in result["loaded"] if m.split(".")[0] in ROS_MODULES]
    assert ros == []


def _imported_modules(path: Path) -> list[str]:
    names: list[str] = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names.extend(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.append(node.module)
            names.extend(f"{node.module}.{alias.name}" for alias in node.names)
    return names


def test_pure_packages_never_import_the_node_layer() -> None:
    files = _pure_files()
    assert len(files) > 20
    offenders = [
        f"{path.relative_to(PACKAGE)}: {name}"
        for path in files
        for name in _imported_modules(path)
        if name == "ads_rca.ros" or name.startswith("ads_rca.ros.")
    ]
    assert offenders == []
