"""The layers import downwards only: the pure packages load no ROS.

``contract/`` (topic table, conversion, CDR codec, playback, assembler), ``sources/``, ``live/``,
the oracles and the engine must work where no ROS runtime is installed or wanted (offline
diagnosis, bag conversion, simulation). Checks: importing every module of those packages
in a fresh interpreter loads no rclpy or message package; none of them names
``ads_rca.ros`` in an import (the nodes sit on top and import the core, never the reverse);
every module of the package has a layer and no import, lazy ones included, runs from a
layer to a higher one (:data:`LAYERS`); ``ros/`` holds only ROS glue and the environment of
the processes; and docs/architecture.md's module table names every module.
"""

from __future__ import annotations

import ast
import json
import re
import subprocess
import sys
from pathlib import Path

import ads_rca

PACKAGE = Path(ads_rca.__file__).resolve().parent

#: The layers, bottom first: a module may import its own layer's modules and lower layers'
#: only. Entries are module names or packages (a package holds all its submodules).
LAYERS: tuple[tuple[str, ...], ...] = (
    ("ads_rca", "ads_rca.errors", "ads_rca.foundation"),
    ("ads_rca.problems", "ads_rca.paramspec", "ads_rca.params"),
    ("ads_rca.model", "ads_rca.sources.openlane.lanes", "ads_rca.sources.atmacup.snapshots"),
    (
        "ads_rca.diagnosis",
        "ads_rca.diagnosis.verdict",
        "ads_rca.capabilities",
        "ads_rca.sources.carla.annotations",
        "ads_rca.sources.carla.figures",
        "ads_rca.sources.predictor.scores",
        "ads_rca.sources.openlane.scores",
        "ads_rca.sources.openlane.run_scores",
        "ads_rca.sources.atmacup.trajectory_scores",
    ),
    ("ads_rca.contract",),
    ("ads_rca.sources", "ads_rca.synth"),
    ("ads_rca.oracles",),
    (
        "ads_rca.diagnosis.conclusion",
        "ads_rca.diagnosis.events",
        "ads_rca.diagnosis.engine",
        "ads_rca.diagnosis.summary",
        "ads_rca.diagnosis.compare",
    ),
    ("ads_rca.live", "ads_rca.report"),
    ("ads_rca.remote", "ads_rca.batch"),
    ("ads_rca.ros",),
    ("ads_rca.commands", "ads_rca.cli"),
)
_ROS_LAYER = next(i for i, layer in enumerate(LAYERS) if "ads_rca.ros" in layer)
#: Packages and modules that must import without ROS: every layer below the nodes.
PURE = tuple(entry for layer in LAYERS[:_ROS_LAYER] for entry in layer if entry != "ads_rca")
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
    files = [PACKAGE / "diagnosis/engine.py"]
    for sub in ("foundation", "diagnosis", "contract", "sources", "live", "oracles"):
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
    assert "ads_rca.sources.bag.reader" in result["imported"]
    ros = [m for m in result["loaded"] if m.split(".")[0] in ROS_MODULES]
    assert ros == []


def _imported_modules(path: Path) -> list[str]:
    """Every module name an import statement of ``path`` names, the imports inside
    functions included (``from a import b`` gives ``a`` and ``a.b``)."""
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


#: Modules of ``ros/`` that load no ROS package: the environment and lifetime of the
#: processes we start, their launcher and the graph description. Anything else pure belongs
#: in a core package.
ROS_ENVIRONMENT = {"env", "fastdds_profile", "domains", "lifeline", "reaper", "launcher", "graph"}


def _module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _all_modules() -> dict[str, Path]:
    return {_module_name(path): path for path in sorted(PACKAGE.rglob("*.py"))}


def _layer(module: str) -> int:
    """Index in LAYERS of the longest entry that is ``module`` or a package holding it."""
    best, rank = -1, -1
    for index, layer in enumerate(LAYERS):
        for entry in layer:
            inside = module.startswith(entry + ".") and entry != "ads_rca"  # no catch-all
            if (module == entry or inside) and len(entry) > best:
                best, rank = len(entry), index
    return rank


def _target(name: str, modules: dict[str, Path]) -> str | None:
    """The ads_rca module an imported name refers to (``pkg.mod.func`` → ``pkg.mod``)."""
    while name and name not in modules:
        name = name.rpartition(".")[0]
    return name or None


def test_every_module_imports_only_its_own_layer_and_lower() -> None:
    modules = _all_modules()
    assert "ads_rca.contract.topics" in modules and "ads_rca.ros.player" in modules
    unplaced = [m for m in modules if _layer(m) < 0]
    assert unplaced == []
    upward: list[str] = []
    for module, path in modules.items():
        for name in _imported_modules(path):
            target = _target(name, modules) if name.startswith("ads_rca") else None
            if target is not None and _layer(target) > _layer(module):
                upward.append(f"{module} -> {target}")
    assert upward == []


def test_ros_holds_only_ros_glue_and_the_process_environment() -> None:
    pure = []
    for path in sorted((PACKAGE / "ros").glob("*.py")):
        if path.stem in ROS_ENVIRONMENT or path.stem == "__init__":
            continue
        loaded = {name.split(".")[0] for name in _imported_modules(path)}
        if not loaded & set(ROS_MODULES):
            pure.append(path.name)
    assert pure == []


#: A backticked path in the first column of a row of the module table.
_TABLE_PATH = re.compile(r"`([a-z_/]+(?:\.py)?)`")


def _documented() -> set[str]:
    text = (PACKAGE.parent / "docs" / "architecture.md").read_text()
    table = text.split("| module | concept |", 1)[1].split("\n\n", 1)[0]
    named: set[str] = set()
    for row in table.splitlines()[2:]:
        named.update(_TABLE_PATH.findall(row.split("|")[1]))
    return named


def test_the_architecture_table_names_every_module() -> None:
    """Every module is a row of docs/architecture.md's table, by its path; a package row
    (``synth/``) stands for its modules only while none of them has a row of its own."""
    named = _documented()
    files = [p.relative_to(PACKAGE).as_posix() for p in sorted(PACKAGE.rglob("*.py"))]
    missing = []
    for file in files:
        if file.endswith("__init__.py"):
            continue
        folder = file.rpartition("/")[0] + "/"
        listed_alone = any(n.startswith(folder) and n.endswith(".py") for n in named)
        if file not in named and (listed_alone or folder not in named):
            missing.append(file)
    assert missing == []
    stale = [n for n in named if not (PACKAGE / n).exists()]
    assert stale == []
