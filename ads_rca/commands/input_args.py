"""Options of the log reader shared by every command that reads a log (``max_file_mb``).

The reader's settings are not engine thresholds, but keep one name everywhere: the CLI flag
``--max-file-mb``, ``-p max_file_mb=N`` and the ``max_file_mb`` key of a ``--config`` file
(commands with engine options), and the player node's ROS parameter ``max_file_mb``.
"""

from __future__ import annotations

import argparse
from typing import Any

from ads_rca.io.files import DEFAULT_MAX_FILE_MB
from ads_rca.params import load_config, parse_assignments
from ads_rca.paramspec import MAX_FILE_MB, check_number

#: The reader's parameter names (popped from ``-p`` / config before the engine sees them).
READER_PARAMS = ("max_file_mb",)


def add_reader_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--max-file-mb",
        type=float,
        default=None,
        metavar="MB",
        help=f"skip (and report) log files larger than this (default {DEFAULT_MAX_FILE_MB:g}; "
        f"range {MAX_FILE_MB.text()})",
    )


def max_file_mb_from_args(args: argparse.Namespace) -> float:
    """--max-file-mb, else ``-p max_file_mb=``, else the config file's, else the default."""
    if getattr(args, "max_file_mb", None) is not None:
        return float(check_number("max_file_mb", args.max_file_mb, MAX_FILE_MB))
    overrides: dict[str, Any] = parse_assignments(getattr(args, "params", None) or [])
    config_path = getattr(args, "config", None)
    config: dict[str, Any] = load_config(config_path) if config_path else {}
    value = overrides.get("max_file_mb", config.get("max_file_mb", DEFAULT_MAX_FILE_MB))
    return float(check_number("max_file_mb", value, MAX_FILE_MB))
