"""``ads-rca synth OUT_DIR``: write a synthesised crash (or near-miss) log in the seed format,
or with ``--profile`` as a rosbag2 recording of a stack publishing that profile's topics.

A thin shell over :func:`ads_rca.synth.synthesise_run` and
:func:`ads_rca.sources.log.writer.write_run_log` (a log folder),
:func:`ads_rca.synth.recording.write_recording` (a real stack's recording) or
:func:`ads_rca.sources.bag.writer.write_bag` (``--profile ads_rca``: this project's contract).
"""

from __future__ import annotations

import argparse

from ads_rca.commands import command_parser
from ads_rca.commands.outputs import check_output_dir
from ads_rca.errors import ConfigError
from ads_rca.foundation.text import printable
from ads_rca.model import RunLog
from ads_rca.paramspec import check_number
from ads_rca.sources.bag.writer import STORAGES, write_bag
from ads_rca.sources.log.writer import write_run_log
from ads_rca.synth import ALL_FAULTS, SCENARIOS, SynthesisSummary, canonical_fault, synthesise_run
from ads_rca.synth.noise import LEVELS
from ads_rca.synth.recording import PROFILES, write_recording

#: ``--profile`` values: this project's contract and the real stacks' recordings.
BAG_PROFILES = ("ads_rca", *PROFILES)


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = command_parser(subparsers, "synth")
    parser.add_argument("out_dir", metavar="OUT_DIR", help="folder to write the log into")
    parser.add_argument("--scenario", required=True, choices=SCENARIOS)
    parser.add_argument(
        "--fault",
        default="none",
        type=canonical_fault,  # the old spelling "control" is accepted for "controller"
        choices=ALL_FAULTS,
        help="the module whose fault is injected (default none); perception:shifted, "
        "perception:shrunk, perception:velocity misperceive the partner in 3-D",
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--frames", type=int, help="log length when nothing crashes")
    parser.add_argument("--actors", type=int, help="number of background actors")
    parser.add_argument(
        "--noise",
        metavar="K",
        default="1",
        help="noise level: every perception sigma times K, plus a drifting localisation "
        f"error above 1 (default 1; range {LEVELS.text()})",
    )
    parser.add_argument(
        "--profile",
        choices=BAG_PROFILES,
        help="write a rosbag2 bag into OUT_DIR, recorded as from a stack publishing this "
        "profile's topics and types, instead of a log folder",
    )
    parser.add_argument("--storage", choices=STORAGES, help="bag storage (--profile; default mcap)")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    if args.storage is not None and args.profile is None:
        raise ConfigError("--storage: only with --profile (a log folder has no storage)")
    # Checked here, not by argparse, so any bad value is one line naming --noise.
    noise = float(check_number("--noise", args.noise, LEVELS))
    options = {
        name: value
        for name, value in (("frames", args.frames), ("actors", args.actors))
        if value is not None
    }
    log, summary = synthesise_run(args.scenario, args.fault, args.seed, noise, **options)
    if args.profile is None:
        write_run_log(log, args.out_dir)
        print(printable(f"{args.out_dir}: {describe(summary)}"))
        return 0
    storage = args.storage or "mcap"
    counts = _write_bag(log, args.out_dir, args.profile, storage)
    bag = f"{args.profile} {storage} bag, {sum(counts.values())} messages on {len(counts)} topics"
    print(printable(f"{args.out_dir}: {describe(summary)} ({bag})"))
    return 0


def _write_bag(log: RunLog, out_dir: str, profile: str, storage: str) -> dict[str, int]:
    check_output_dir(out_dir, "OUT_DIR")
    if profile == "ads_rca":
        return write_bag(log, out_dir, storage)
    return write_recording(log, out_dir, profile, storage)


def describe(summary: SynthesisSummary) -> str:
    """The synthesis label in words: what happened, never a -1 or None placeholder."""
    head = f"{summary['scenario']}/{summary['fault']} seed {summary['seed']}"
    partner = summary["partner_id"]
    if summary["collision_frame"] >= 0:
        with_whom = f" with actor {partner} (the partner)" if partner is not None else ""
        outcome = f"collision at frame {summary['collision_frame']}{with_whom}"
    elif partner is not None:
        outcome = f"no collision (partner actor {partner} avoided)"
    else:
        outcome = "no collision, no partner"
    if summary["fault_onset_frame"] >= 0:
        fault = f"{summary['fault']} fault from frame {summary['fault_onset_frame']}"
    else:
        fault = "no fault injected"
    return f"{head}: {summary['total_frames']} frames, {outcome}, {fault}"
