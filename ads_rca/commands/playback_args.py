"""Options shared by the commands that play a run onto DDS (``demo``, ``replay``)."""

from __future__ import annotations

import argparse

from ads_rca.errors import InputError


def add_playback_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--rate", type=float, default=0.0, help="playback rate (0 = as fast as acknowledged)"
    )
    parser.add_argument("--timeout", type=float, default=300.0, help="seconds before giving up")
    parser.add_argument("--domain-id", type=int, help="ROS_DOMAIN_ID (default: from the pid)")


def check_playback_arguments(args: argparse.Namespace) -> None:
    if args.rate < 0:
        raise InputError(f"--rate must be >= 0, got {args.rate}")
