"""``ads-rca dashboard``: a web page of the runs on Zenoh, live.

Serves :mod:`ads_rca.remote.web` on 127.0.0.1 (another interface only with
``--allow-remote``: the page has no authentication) and joins Zenoh as a peer that listens
nowhere and connects to the ``--connect`` endpoints (retrying until they answer). No rclpy:
it runs where no ROS is installed. docs/dashboard.md has the page, the endpoints and the
security notes.
"""

from __future__ import annotations

import argparse

from ads_rca.commands import command_parser
from ads_rca.remote.config import DEFAULT_ENDPOINT
from ads_rca.remote.keys import check_prefix

DEFAULT_PORT = 8765


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = command_parser(
        subparsers,
        "dashboard",
        description="Serve a live web dashboard of the runs the bridge puts on Zenoh: each "
        "module's results, the clearance timeline, the verdict with its evidence.",
    )
    parser.add_argument(
        "--connect",
        action="append",
        metavar="ENDPOINT",
        help=f"Zenoh endpoint to connect to, repeatable (default {DEFAULT_ENDPOINT})",
    )
    parser.add_argument("--prefix", help="show this run's prefix only (default: every run)")
    parser.add_argument(
        "--host", default="127.0.0.1", help="address to serve on (default 127.0.0.1)"
    )
    parser.add_argument(
        "--port", default=str(DEFAULT_PORT), help=f"port (default {DEFAULT_PORT}; 0: any free)"
    )
    parser.add_argument(
        "--allow-remote",
        action="store_true",
        help="allow a --host and --connect endpoints beyond loopback; the page has NO "
        "authentication: put it behind a reverse proxy with TLS and login",
    )
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    # aiohttp takes a quarter of a second to import: only this command pays for it.
    from ads_rca.remote import web

    options = web.Options(
        host=web.check_host(args.host, args.allow_remote),
        port=web.parse_port(args.port),
        connect=tuple(args.connect or (DEFAULT_ENDPOINT,)),
        prefix=None if args.prefix is None else check_prefix(args.prefix, "--prefix"),
        allow_remote=bool(args.allow_remote),
    )
    return web.run(options)
