"""``ads-rca convert IN OUT``: running-log folder ↔ rosbag2 bag, losslessly, without ROS.

The direction follows the input: a log folder becomes a bag directory (MCAP or sqlite3)
holding what the player would publish; a bag (directory, ``.mcap`` or ``.db3``, e.g. from the
``recorder`` node) becomes a log folder. A thin shell over :mod:`ads_rca.sources.bag.writer`,
:mod:`ads_rca.sources.bag.reader` and :mod:`ads_rca.sources.log.writer`.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ads_rca.commands import command_parser
from ads_rca.commands.input_args import (
    add_bag_arguments,
    add_reader_arguments,
    bag_options_from_args,
    max_file_mb_from_args,
    source_options_from_args,
)
from ads_rca.commands.outputs import check_output_dir
from ads_rca.contract import topics
from ads_rca.errors import InputError
from ads_rca.foundation.text import printable
from ads_rca.model import RunLog
from ads_rca.sources.bag import NAME as BAG
from ads_rca.sources.bag.mcap_writer import COMPRESSIONS, DEFAULT_CHUNK_SIZE
from ads_rca.sources.bag.reader import read_bag
from ads_rca.sources.bag.writer import STORAGES, McapOptions, write_bag
from ads_rca.sources.log.writer import write_run_log
from ads_rca.sources.registry import open_run, resolved_format


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = command_parser(
        subparsers,
        "convert",
        description="LOG_DIR OUT_BAG writes a bag; BAG OUT_DIR writes a log folder.",
    )
    parser.add_argument("source", metavar="IN", help="log folder or bag")
    parser.add_argument("out", metavar="OUT", help="bag directory or log folder to create")
    parser.add_argument("--storage", choices=STORAGES, default="mcap", help="bag storage")
    parser.add_argument(
        "--compression", choices=sorted(COMPRESSIONS), default="zstd", help="MCAP chunks"
    )
    parser.add_argument("--chunk-size", type=int, default=DEFAULT_CHUNK_SIZE)
    parser.add_argument(
        "--namespace",
        default=None,
        help="topic namespace (bag: written / read; default: "
        f"{topics.DEFAULT_NAMESPACE} when writing, detected when reading)",
    )
    add_reader_arguments(parser)
    add_bag_arguments(parser)
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    source, out = Path(args.source), Path(args.out)
    if not source.exists():
        raise InputError(f"{source}: no such log folder or bag")
    check_output_dir(out, "OUT")
    max_file_mb = max_file_mb_from_args(args)
    bag = bag_options_from_args(args)
    options_in = source_options_from_args(args)
    fmt = resolved_format(source, options_in.source_format)
    if fmt == BAG or bag.remap:
        if bag.contract:
            log = read_bag(source, remap=bag.remap, namespace=args.namespace)
        else:
            log = open_run(source, bag=bag)
        write_run_log(log, out)
        print(printable(f"{source} → {out}: log folder, {len(log.frames)} analysed frames"))
        if log.problems:  # a cut or damaged bag must not become a clean-looking folder
            print(printable(f"problems in {source}: {len(log.problems)}"), file=sys.stderr)
            for line in log.problems.summary_lines(10):
                print(f"  {line}", file=sys.stderr)
        return 0
    # Any other source (a log folder, a dataset's run): written as a log folder's bag would be.
    log = open_run(source, max_file_mb=max_file_mb, source=options_in)
    if not bag.contract:
        return _write_recording(log, source, out, bag.profile, args.storage)
    options: McapOptions = {}
    if args.storage == "mcap":
        options = {"compression": args.compression, "chunk_size": args.chunk_size}
    counts = write_bag(
        log, out, args.storage, namespace=args.namespace or topics.DEFAULT_NAMESPACE, **options
    )
    print(
        printable(
            f"{source} → {out}: {args.storage} bag, {sum(counts.values())} messages on "
            f"{len(counts)} topics, {len(log.frames)} analysed frames"
        )
    )
    return 0


def _write_recording(log: RunLog, source: Path, out: Path, profile: str, storage: str) -> int:
    """A log folder written as a stack publishing ``profile``'s topics would record it."""
    from ads_rca.synth.recording import PROFILES, write_recording

    if profile not in PROFILES:
        raise InputError(
            f"--profile {profile}: a log folder can be written as {', '.join(PROFILES)} "
            "(or the ads_rca contract, the default)"
        )
    counts = write_recording(log, out, profile, storage)
    print(
        printable(
            f"{source} → {out}: {storage} bag as a {profile} stack records it, "
            f"{sum(counts.values())} messages on {len(counts)} topics"
        )
    )
    return 0
