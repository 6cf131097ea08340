"""Subcommands of ``ads-rca``: each module has ``register(subparsers)`` setting ``run``.

The modules are named here, not imported, with each command's one-line help: a run imports
only its own command's module (a ``diagnose`` needs neither the bag writers of ``convert``
nor Dask of ``batch``), and ``ads-rca --help`` or a mistyped command, which need only the
names and help lines, import none of them.
"""

from __future__ import annotations

import argparse
import importlib
from dataclasses import dataclass
from types import ModuleType
from typing import Any


@dataclass(frozen=True)
class Command:
    """A subcommand: the module that registers and runs it, and its line in the help."""

    module: str
    help: str


#: Every command, in the order ``ads-rca --help`` lists them.
COMMANDS: dict[str, Command] = {
    "diagnose": Command(
        "ads_rca.commands.diagnose_cmd", "find the root cause of a crash in a run log"
    ),
    "batch": Command(
        "ads_rca.commands.batch_cmd",
        "diagnose many runs on a Dask cluster: one row each, and a summary",
    ),
    "inspect": Command(
        "ads_rca.commands.inspect_cmd",
        "summarise a run log or bag: topics, model inputs found and missing, which modules "
        "can be judged, and the problems found in it",
    ),
    "demo": Command(
        "ads_rca.commands.demo_cmd",
        "play a log on ROS 2 topics to a subscriber process (local-only DDS)",
    ),
    "replay": Command(
        "ads_rca.commands.replay_cmd",
        "replay a run through the live node graph (monitors + aggregator)",
    ),
    "synth": Command(
        "ads_rca.commands.synth_cmd", "synthesise a closed-loop run log with an injected fault"
    ),
    "convert": Command(
        "ads_rca.commands.convert_cmd",
        "convert a running-log folder to a rosbag2 bag, or a bag to a log folder",
    ),
    "watch": Command(
        "ads_rca.commands.watch_cmd",
        "a live terminal dashboard of runs on Zenoh: modules, frame rate, near misses, the "
        "verdict (no ROS needed)",
    ),
    "dashboard": Command(
        "ads_rca.commands.dashboard_cmd",
        "serve a live web dashboard of the runs on Zenoh (127.0.0.1 by default)",
    ),
}


def add_commands(subparsers: argparse._SubParsersAction[Any], only: str | None) -> None:
    """Every command's parser: ``only``'s in full (its module imported and registered), the
    others as their name and help line (what ``--help`` lists and a mistake is told)."""
    for name, command in COMMANDS.items():
        if name == only:
            module: ModuleType = importlib.import_module(command.module)
            module.register(subparsers)
        else:
            subparsers.add_parser(name, help=command.help)


def command_parser(
    subparsers: argparse._SubParsersAction[Any], name: str, **options: Any
) -> argparse.ArgumentParser:
    """The parser of command ``name`` with its help line from :data:`COMMANDS` (a command
    module's ``register`` starts with it)."""
    parser: argparse.ArgumentParser = subparsers.add_parser(
        name, help=COMMANDS[name].help, **options
    )
    return parser
