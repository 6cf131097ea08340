"""``ads-rca watch``: a live terminal dashboard of the runs a Zenoh bridge publishes.

No ROS at run time: Zenoh and rich only, imported when the command runs (so ``ads-rca``
starts as fast as before). The work is in :mod:`ads_rca.remote.watch`.
"""

from __future__ import annotations

import argparse
import math

from ads_rca.commands import command_parser
from ads_rca.errors import ConfigError
from ads_rca.remote.config import DEFAULT_ENDPOINT


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = command_parser(
        subparsers,
        "watch",
        description="Watch the runs a zenoh bridge publishes: per-module status and metrics, "
        "frame and rate, near-miss warnings and the verdict when it arrives. Start it before, "
        "during or after a run. Exit status: 0 once a verdict was shown (--exit-on-verdict, "
        "--timeout), 2 for a bad option, 3 when --timeout passes without a verdict, 130 on "
        "Ctrl-C, 143 on SIGTERM.",
    )
    parser.add_argument(
        "--connect",
        action="append",
        metavar="ENDPOINT",
        help=f"zenoh endpoint to connect to, repeatable (default {DEFAULT_ENDPOINT})",
    )
    parser.add_argument(
        "--prefix", help="watch the run under this key prefix only (default: every run)"
    )
    parser.add_argument(
        "--allow-remote",
        action="store_true",
        help="allow endpoints that are not on loopback (use Zenoh's TLS and access control)",
    )
    parser.add_argument(
        "--json", action="store_true", help="print one JSON line per event instead of a screen"
    )
    parser.add_argument(
        "--exit-on-verdict", action="store_true", help="exit (status 0) once a verdict is shown"
    )
    parser.add_argument(
        "--timeout",
        metavar="S",
        help="stop after S seconds: status 0 if a verdict was shown, else 3",
    )
    parser.set_defaults(run=run)


def timeout_from_args(text: str | None) -> float | None:
    """``--timeout``: a positive, finite number of seconds (one line when not)."""
    if text is None:
        return None
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        shown = text.encode("unicode_escape").decode("ascii")[:40]
        raise ConfigError(f"--timeout: {shown!r} is not a positive number of seconds")
    return value


def run(args: argparse.Namespace) -> int:
    from ads_rca.remote.watch import WatchOptions, watch

    options = WatchOptions(
        connect=tuple(args.connect or (DEFAULT_ENDPOINT,)),
        prefix=args.prefix,
        allow_remote=args.allow_remote,
        json=args.json,
        exit_on_verdict=args.exit_on_verdict,
        timeout=timeout_from_args(args.timeout),
    )
    return watch(options)
