"""``ads-rca demo LOG_DIR``: play a log over ROS 2 to a subscriber process and show what arrived.

Starts ``topic_summary`` and the ``player`` as separate processes through the launcher, on
a DDS domain of their own with local-only discovery (the network rule), and prints their
prefixed output: the player's reading of the log and the subscriber's per-topic table.
With ``--out`` the subscriber also rebuilds the log from the messages into ``DIR``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ads_rca.commands import command_parser
from ads_rca.commands.outputs import check_output_dir
from ads_rca.commands.playback_args import (
    add_playback_arguments,
    allow_external,
    check_playback_arguments,
    choose_domain_id,
)
from ads_rca.errors import InputError
from ads_rca.ros.env import discovery_note, ros_environment
from ads_rca.ros.launcher import Launcher, ParamValue, node_command


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = command_parser(subparsers, "demo")
    parser.add_argument("log_dir", metavar="PATH", help="log folder or bag")
    parser.add_argument("--out", help="write the log rebuilt from the messages here")
    add_playback_arguments(parser)
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    log_dir = Path(args.log_dir)
    if not log_dir.exists():  # the player reads either, and says what is wrong with it
        raise InputError(f"{log_dir}: no such log folder or bag")
    check_playback_arguments(args)
    out = check_output_dir(args.out, "--out", empty=False) if args.out else None
    domain_id, domain_how = choose_domain_id(args)
    log_root = None
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        log_root = out / "ros_log"
    env = ros_environment(
        domain_id=domain_id, log_dir=log_root, allow_external=allow_external(args)
    )
    summary_params: dict[str, ParamValue] = {"timeout_s": float(args.timeout)}
    if out is not None:
        summary_params.update(
            output_json=True,
            output_dir=str(out / "rebuilt_log"),
            summary_file=str(out / "topic_summary.json"),
        )
    player_params: dict[str, ParamValue] = {
        "log_path": str(log_dir.resolve()),
        "rate": float(args.rate),
        "wait_for_subscribers": 1,
    }
    print(
        f"ads-rca demo: ROS_DOMAIN_ID={domain_id} ({domain_how}), {discovery_note(env)}",
        flush=True,
    )
    with Launcher(env, echo=sys.stdout) as launcher:
        summary = launcher.start(
            "topic_summary", node_command("ads_rca.ros.topic_summary", summary_params)
        )
        player = launcher.start("player", node_command("ads_rca.ros.player", player_params))
        player_code = player.wait(args.timeout)
        if player_code != 0:
            summary.stop()
        summary_code = summary.wait(args.timeout)
    print(f"ads-rca demo: player exit {player_code}, topic_summary exit {summary_code}")
    if out is not None and summary_code == 0:
        print(f"ads-rca demo: rebuilt log in {out / 'rebuilt_log'}")
    if player_code == 2:
        return 2
    return 0 if player_code == 0 and summary_code == 0 else 1
