"""The ``ads-rca`` command line: one subcommand per module in :mod:`ads_rca.commands`.

Every subcommand is a thin shell over the same core the ROS nodes use. Bad input never
produces a traceback: an :class:`~ads_rca.errors.AdsRcaError` (a log, a path or a parameter
that cannot be used) becomes one line on stderr and exit status 2, as does an option given
``--`` for a value (``--timeout=--``: argparse passes it on as an empty list). Like any
Unix filter, the command ends quietly when the reader of its output goes away
(``ads-rca ... | head``): no BrokenPipeError traceback, exit status 141 (128 + SIGPIPE, what
the shell reports for ``cat`` in the same place), as Ctrl-C gives 130.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
from collections.abc import Sequence

from ads_rca import __version__
from ads_rca.commands import add_commands
from ads_rca.errors import AdsRcaError
from ads_rca.foundation import quick_exit
from ads_rca.foundation.text import printable


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The parser of every command, or only of command ``only`` (what a run of it needs:
    the other commands' modules are not imported)."""
    parser = argparse.ArgumentParser(
        prog="ads-rca", description="Root-cause analysis of autonomous-driving crashes."
    )
    parser.add_argument("--version", action="version", version=f"ads-rca {__version__}")
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    add_commands(subparsers, only)
    return parser


def command_named(argv: Sequence[str]) -> str | None:
    """The command ``argv`` runs, when its first word names one (else None: ``--help``,
    ``--version`` or a mistake, which the full parser answers)."""
    return argv[0] if argv and not argv[0].startswith("-") else None


#: Exit statuses of a command stopped by a signal's effect (128 + the signal's number).
EXIT_INTERRUPTED = 128 + signal.SIGINT
EXIT_BROKEN_PIPE = 128 + signal.SIGPIPE


def main(argv: Sequence[str] | None = None) -> int:
    try:
        try:
            return run(argv)
        finally:  # what is still buffered (a pipe's whole output, often) is written here
            sys.stdout.flush()
    except BrokenPipeError:
        # Nothing more can be written, and the interpreter's own flush at exit would
        # fail again: point stdout at /dev/null so it ends quietly.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
        return EXIT_BROKEN_PIPE


def entry() -> None:
    """The ``ads-rca`` program: :func:`main`, then the end of the process (at once, when the
    command kept what it loaded: :mod:`ads_rca.foundation.quick_exit`)."""
    quick_exit.run_program(main)


def dash_dash_value(words: Sequence[str]) -> str | None:
    """The first ``--option=--`` before the end of the options (a bare ``--``): argparse
    gives such an option an empty list for a value, whatever its type, and the command
    then raised a TypeError on it (``batch --timeout=--``, issue 43)."""
    for word in words:
        if word == "--":
            return None
        if word.startswith("--") and word.endswith("=--") and len(word) > 5:
            return word
    return None


def run(argv: Sequence[str] | None) -> int:
    words = sys.argv[1:] if argv is None else list(argv)
    command = command_named(words)
    odd = dash_dash_value(words)
    if odd is not None:
        prog = f"ads-rca {command}" if command else "ads-rca"
        option = odd.removesuffix("=--")
        print(printable(f"{prog}: error: {odd}: '--' is no value of {option}"), file=sys.stderr)
        return 2
    args = build_parser(command).parse_args(words)
    try:
        return int(args.run(args))
    except AdsRcaError as error:
        print(printable(f"ads-rca {args.command}: error: {error}"), file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED


if __name__ == "__main__":
    entry()
