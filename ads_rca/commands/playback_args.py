"""Options shared by the commands that play a run onto DDS (``demo``, ``replay``)."""

from __future__ import annotations

import argparse

from ads_rca.paramspec import PLAYBACK_TIMEOUT, RATE, check_number
from ads_rca.ros.domains import free_domain_id
from ads_rca.ros.env import (
    ALLOW_EXTERNAL_VARIABLE,
    MAX_DOMAIN_ID,
    MAX_VALID_DOMAIN_ID,
    parse_domain_id,
    pick_domain_id,
    requested_domain_id,
)


def add_playback_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--rate",
        type=float,
        default=0.0,
        help=f"playback rate (0 = as fast as acknowledged; range {RATE.text()})",
    )
    parser.add_argument(
        "--timeout",
        type=float,
        default=300.0,
        help=f"seconds before giving up (default 300; range {PLAYBACK_TIMEOUT.text()})",
    )
    parser.add_argument(
        "--domain-id",
        metavar="ID",
        help=f"ROS_DOMAIN_ID, 0..{MAX_VALID_DOMAIN_ID} (default: ROS_DOMAIN_ID from the "
        f"environment, else one in 1..{MAX_DOMAIN_ID} that no participant on this machine uses)",
    )
    parser.add_argument(
        "--allow-external-discovery",
        action="store_true",
        help="keep ROS_DISCOVERY_SERVER, ROS_STATIC_PEERS, Fast DDS profiles files and the "
        "other variables that can take discovery off this machine (default: cleared; "
        f"same as {ALLOW_EXTERNAL_VARIABLE}=1)",
    )


def check_playback_arguments(args: argparse.Namespace) -> None:
    check_number("--rate", args.rate, RATE)
    check_number("--timeout", args.timeout, PLAYBACK_TIMEOUT)


def allow_external(args: argparse.Namespace) -> bool | None:
    """True with ``--allow-external-discovery``; None leaves it to the environment."""
    return True if args.allow_external_discovery else None


def choose_domain_id(args: argparse.Namespace) -> tuple[int, str]:
    """The domain to run on and how it was chosen: ``--domain-id``, else a non-empty
    ``ROS_DOMAIN_ID`` (both checked: InputError on a bad value), else a free one."""
    if args.domain_id is not None:
        return parse_domain_id(args.domain_id, "--domain-id"), "--domain-id"
    requested = requested_domain_id(None)
    if requested is not None:
        return requested, "from ROS_DOMAIN_ID"
    free = free_domain_id()
    if free is None:
        return pick_domain_id(), "every domain in use: the run id keeps runs apart"
    return free, "free"
