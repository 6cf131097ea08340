"""The ``ads-rca`` command line: one subcommand per module in :mod:`ads_rca.commands`.

Every subcommand is a thin shell over the same core the ROS nodes use. Bad input never
produces a traceback: an :class:`~ads_rca.errors.AdsRcaError` (a log, a path or a parameter
that cannot be used) becomes one line on stderr and exit status 2.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from ads_rca import __version__
from ads_rca.commands import COMMANDS
from ads_rca.errors import AdsRcaError
from ads_rca.text import printable


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="ads-rca", description="Root-cause analysis of autonomous-driving crashes."
    )
    parser.add_argument("--version", action="version", version=f"ads-rca {__version__}")
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for command in COMMANDS:
        command.register(subparsers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.run(args))
    except AdsRcaError as error:
        print(printable(f"ads-rca {args.command}: error: {error}"), file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
