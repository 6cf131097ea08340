"""The Zenoh bridge's options of ``ads-rca replay``: the node's parameters, same names.

``--zenoh`` starts the ``zenoh_bridge`` node with the graph; ``--zenoh-listen``,
``--zenoh-connect``, ``--zenoh-mode``, ``--zenoh-prefix``, ``--zenoh-allow-remote``,
``--rate-modules``-style limits and ``--zenoh-linger`` map one to one onto its ROS
parameters (docs/remote.md). Values are checked here, before any node starts, with the
same checks the node makes, so a bad endpoint is one line and exit 2.
"""

from __future__ import annotations

import argparse

from ads_rca.remote.config import DEFAULT_ENDPOINT, MODES
from ads_rca.ros.graph import bridge_params
from ads_rca.ros.launcher import ParamValue


def add_zenoh_arguments(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("Zenoh bridge (remote dashboards; docs/remote.md)")
    group.add_argument(
        "--zenoh", action="store_true", help="start the zenoh_bridge node with the graph"
    )
    group.add_argument(
        "--zenoh-mode", choices=MODES, default="peer", help="Zenoh session mode (peer)"
    )
    group.add_argument(
        "--zenoh-listen",
        action="append",
        metavar="ENDPOINT",
        help=f"endpoint to listen on, repeatable (default {DEFAULT_ENDPOINT})",
    )
    group.add_argument(
        "--zenoh-connect", action="append", metavar="ENDPOINT", help="endpoint to connect to"
    )
    group.add_argument("--zenoh-prefix", default="", help="key prefix of every sample")
    group.add_argument(
        "--zenoh-allow-remote",
        action="store_true",
        help="allow endpoints off loopback (then configure Zenoh TLS and access control)",
    )
    group.add_argument(
        "--rate-modules",
        default="20",
        metavar="HZ",
        help="most JSON samples per second per module key (0 = all; default 20)",
    )
    group.add_argument(
        "--zenoh-linger",
        default="30",
        metavar="S",
        help="after the verdict, outputs written and every other node stopped, the bridge "
        "serves the run to late dashboards this long (default 30 s; inf: until Ctrl-C)",
    )


def zenoh_params_from_args(args: argparse.Namespace) -> dict[str, ParamValue] | None:
    """The bridge's parameters (None without ``--zenoh``); ConfigError (one line) for a bad
    endpoint, prefix, rate or linger."""
    if not args.zenoh:
        args.zenoh_linger = 0.0
        return None
    params = bridge_params(
        args.zenoh_mode,
        tuple(args.zenoh_listen or ()),
        tuple(args.zenoh_connect or ()),
        args.zenoh_prefix,
        bool(args.zenoh_allow_remote),
        args.rate_modules,
        args.zenoh_linger,
    )
    args.zenoh_linger = params["linger_s"]
    return params
