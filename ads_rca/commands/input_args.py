"""Options of the log reader shared by every command that reads a log (``max_file_mb``,
``format``, ``derived_collision``, ``ego_agent``, ``predictions``, ``submission``).

The reader's settings are not engine thresholds, but keep one name everywhere: the CLI flag
(``--max-file-mb``, ``--format``, ``--derived-collision``, ``--ego-agent``,
``--predictions``, ``--submission``), ``-p max_file_mb=N`` and the same key of a
``--config`` file (commands with engine options), and the player node's ROS parameter of
that name.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from ads_rca.errors import InputError
from ads_rca.foundation.files import DEFAULT_MAX_FILE_MB
from ads_rca.foundation.yaml_files import load_config
from ads_rca.params import parse_assignments
from ads_rca.paramspec import MAX_FILE_MB, check_number
from ads_rca.sources.bag.options import BagOptions
from ads_rca.sources.bag.profiles import BUILTIN_PROFILES, DEFAULT_PROFILE
from ads_rca.sources.formats import AUTO, SOURCE_PARAMS, SourceOptions
from ads_rca.sources.registry import FORMATS

#: The reader's parameter names (popped from ``-p`` / config before the engine sees them).
READER_PARAMS = ("max_file_mb", *SOURCE_PARAMS)
#: The defaults of the source options (``SourceOptions``), by parameter name.
SOURCE_DEFAULTS = {
    "format": AUTO,
    "derived_collision": False,
    "ego_agent": "",
    "predictions": "",
    "submission": "",
}


def add_reader_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--max-file-mb",
        type=float,
        default=None,
        metavar="MB",
        help=f"skip (and report) log files larger than this (default {DEFAULT_MAX_FILE_MB:g}; "
        f"range {MAX_FILE_MB.text()})",
    )
    parser.add_argument(
        "--format",
        default=None,
        metavar="NAME",
        help=f"the input's format: {', '.join(FORMATS)} (default {AUTO}: told by the path; "
        "docs/formats.md)",
    )
    parser.add_argument(
        "--ego-agent",
        default=None,
        metavar="TOKEN|N",
        help="a DLP scene has no ego: the agent to take as one, by token or by number in "
        "token order (default: the longest-lived moving car)",
    )
    parser.add_argument(
        "--predictions",
        default=None,
        metavar="DIR",
        help="a folder of a predictor's prediction files (the seed format, ids = actor ids) "
        "to score against a CARLA run's or DLP scene's realised future; for an OpenLane-V2 "
        "segment, a model's per-frame results (<timestamp>.json)",
    )
    parser.add_argument(
        "--submission",
        default=None,
        metavar="FILE",
        help="an atmaCup #18 submission CSV (x_0 ... z_5, optionally an ID column): predicted "
        "ego paths to score against the table's realised ones (MAE, ADE, FDE)",
    )
    parser.add_argument(
        "--derived-collision",
        action="store_const",
        const=True,
        default=None,
        help="a CARLA run or DLP scene records no collision: take the first frame where the "
        "ego's box overlaps another's as one, flagged derived (default off)",
    )


def _reader_setting(args: argparse.Namespace, name: str, default: Any) -> Any:
    """The flag, else ``-p name=``, else the config file's key, else ``default``."""
    if getattr(args, name, None) is not None:
        return getattr(args, name)
    overrides: dict[str, Any] = parse_assignments(getattr(args, "params", None) or [])
    if name in overrides:
        return overrides[name]
    config_path = getattr(args, "config", None)
    config: dict[str, Any] = load_config(config_path) if config_path else {}
    return config.get(name, default)


def max_file_mb_from_args(args: argparse.Namespace) -> float:
    """--max-file-mb, else ``-p max_file_mb=``, else the config file's, else the default."""
    value = _reader_setting(args, "max_file_mb", DEFAULT_MAX_FILE_MB)
    return float(check_number("max_file_mb", value, MAX_FILE_MB))


def source_options_from_args(args: argparse.Namespace) -> SourceOptions:
    """``format``, ``derived_collision``, ``ego_agent``, ``predictions`` and ``submission`` as
    :func:`max_file_mb_from_args` finds them, each checked (one line naming it)."""
    return SourceOptions.from_values(
        {name: _reader_setting(args, name, default) for name, default in SOURCE_DEFAULTS.items()}
    )


def add_bag_arguments(
    parser: argparse.ArgumentParser,
    remap_flags: tuple[str, ...] = ("--remap",),
    remap_dest: str = "remap",
    no_profile: str = "",
) -> None:
    """--profile, --remap and --msg-path: shared by every command that reads a bag.
    ``no_profile``: what the command does with a bag when --profile is not given (then
    None), instead of reading it with the default profile."""
    default = f"default {DEFAULT_PROFILE}: this project's own topics"
    parser.add_argument(
        "--profile",
        default=None if no_profile else DEFAULT_PROFILE,
        metavar="NAME|FILE",
        help=f"which topics and types carry the model's inputs: a built-in profile "
        f"({', '.join(BUILTIN_PROFILES)}) or a profile YAML ({no_profile or default})",
    )
    parser.add_argument(
        *remap_flags,
        dest=remap_dest,
        metavar="YAML",
        help="topic remapping YAML (profile ads_rca): their topic name -> contract topic key",
    )
    parser.add_argument(
        "--msg-path",
        action="append",
        default=[],
        metavar="DIR",
        help="directory of .msg files (DIR/<package>/msg/<Type>.msg) for message types the "
        "bag carries no definition of (repeatable)",
    )


def bag_options_from_args(args: argparse.Namespace) -> BagOptions:
    """The bag options given on the command line, each checked before any work."""
    remap = getattr(args, "remap", None) or getattr(args, "bag_remap", None)
    if remap:
        from ads_rca.foundation.yaml_files import load_yaml

        load_yaml(remap, "remapping")  # a FIFO, /dev/zero, bad YAML: refused before any work
    msg_path = tuple(getattr(args, "msg_path", None) or ())
    for directory in msg_path:
        if not Path(directory).is_dir():
            raise InputError(f"--msg-path {directory}: no such directory")
    profile = str(getattr(args, "profile", None) or DEFAULT_PROFILE)
    return BagOptions(profile, remap or None, msg_path)


def checked_max_problems(value: int) -> int:
    """``--max-problems`` when it is 0 or more; a negative one printed all but the last few
    problems and called those "more"."""
    if value < 0:
        raise InputError(f"--max-problems {value}: expected 0 or more")
    return value
