"""``ads-rca synth OUT_DIR``: write a synthesised crash (or near-miss) log in the seed format.

A thin shell over :func:`ads_rca.synth.synthesise_run` and
:func:`ads_rca.io.json_writer.write_run_log`.
"""

from __future__ import annotations

import argparse

from ads_rca.io.json_writer import write_run_log
from ads_rca.synth import FAULTS, SCENARIOS, synthesise_run


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = subparsers.add_parser(
        "synth", help="synthesise a closed-loop run log with an injected fault"
    )
    parser.add_argument("out_dir", metavar="OUT_DIR", help="folder to write the log into")
    parser.add_argument("--scenario", required=True, choices=SCENARIOS)
    parser.add_argument("--fault", default="none", choices=FAULTS)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--frames", type=int, help="log length when nothing crashes")
    parser.add_argument("--actors", type=int, help="number of background actors")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    options = {
        name: value
        for name, value in (("frames", args.frames), ("actors", args.actors))
        if value is not None
    }
    log, summary = synthesise_run(args.scenario, args.fault, args.seed, **options)
    write_run_log(log, args.out_dir)
    print(
        f"{args.out_dir}: {summary['scenario']}/{summary['fault']} seed {summary['seed']}: "
        f"{summary['total_frames']} frames, collision frame {summary['collision_frame']}, "
        f"partner {summary['partner_id']}, fault onset {summary['fault_onset_frame']}"
    )
    return 0
