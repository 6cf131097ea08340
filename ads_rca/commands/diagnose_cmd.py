"""``ads-rca diagnose PATH``: load a run, judge every module, print and write the verdict."""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from ads_rca.commands.input_args import (
    READER_PARAMS,
    add_reader_arguments,
    max_file_mb_from_args,
)
from ads_rca.commands.outputs import check_output_file
from ads_rca.engine import diagnose
from ads_rca.errors import InputError
from ads_rca.io import open_run
from ads_rca.oracles.semantics import semantics_for
from ads_rca.params import (
    DEFAULT_SEMANTICS,
    SEMANTICS,
    Params,
    engine_overrides,
    load_config,
    make_params,
)
from ads_rca.params import parse_assignments as parse_p
from ads_rca.summary import summary_text
from ads_rca.text import printable

#: Logs longer than this get a progress bar on stderr (when it is a terminal).
PROGRESS_MIN_FRAMES = 300


def add_engine_arguments(parser: argparse.ArgumentParser) -> None:
    """--semantics, --config and -p: shared by every command that runs the engine."""
    parser.add_argument(
        "--semantics",
        choices=SEMANTICS,
        default=None,
        help=f"oracle semantics (default {DEFAULT_SEMANTICS}, or the config file's)",
    )
    parser.add_argument("--config", help="YAML parameters (flat, or a ROS 2 params file)")
    parser.add_argument(
        "-p",
        dest="params",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="set one parameter (repeatable), e.g. -p effect_time_window=15",
    )


def params_from_args(args: argparse.Namespace) -> Params:
    """Config file, then -p overrides; --semantics wins over both."""
    config: dict[str, Any] = load_config(args.config) if args.config else {}
    overrides = parse_p(args.params)
    for name in READER_PARAMS:  # the reader's, not the engine's
        overrides.pop(name, None)
    semantics = (
        args.semantics
        or overrides.pop("semantics", None)
        or config.get("semantics", DEFAULT_SEMANTICS)
    )
    # A node's params file also holds node parameters (log_path, rate...): keep the engine's.
    values = {**engine_overrides(config), **overrides}
    values.pop("semantics", None)
    return make_params(str(semantics), values)


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = subparsers.add_parser("diagnose", help="find the root cause of a crash in a run log")
    parser.add_argument("path", help="running-log folder")
    add_engine_arguments(parser)
    add_reader_arguments(parser)
    parser.add_argument("--json", dest="json_out", help="write the verdict JSON here")
    parser.add_argument("--report", help="write a self-contained HTML report here")
    parser.add_argument(
        "--max-problems", type=int, default=10, help="input problems to print (default 10)"
    )
    parser.add_argument(
        "--workers",
        type=int,
        default=os.cpu_count() or 1,
        help="processes judging frames of long logs (default: one per core)",
    )
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    params = params_from_args(args)
    max_file_mb = max_file_mb_from_args(args)
    if args.json_out:
        check_output_file(args.json_out, "--json")
    if args.report:
        check_output_file(args.report, "--report")
    log = open_run(args.path, max_file_mb=max_file_mb)
    if not semantics_for(params).analysed_frames(log):
        raise InputError(f"{args.path}: no frame to analyse (no readable actors/ file)")
    result = diagnose(log, params, _progress_bar(len(log.frames)), workers=max(1, args.workers))
    document = result.to_json()
    print(summary_text(document, args.max_problems))
    if args.json_out:
        write_json(document, Path(args.json_out))
        print(printable(f"verdict JSON: {args.json_out}"))
    if args.report:
        from ads_rca.report.html import write_report

        try:
            write_report(result, Path(args.report))
        except OSError as error:  # checked up front; this is a failure during the write
            raise InputError(f"--report {args.report}: {error.strerror}") from None
        print(printable(f"HTML report: {args.report}"))
    return 0


def write_json(document: dict[str, Any], path: Path) -> None:
    """The verdict JSON (the contract; NaN and infinity are already null).

    Streamed to the file piece by piece: the text of a long run's frames is never held
    whole in memory (the same bytes as ``json.dumps(document, indent=1)`` plus a newline).
    The path was checked before the work started; a write that fails all the same (disk
    full, a file that refuses data) is still one line, not a traceback.
    """
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with path.open("w", encoding="utf-8", buffering=1 << 16) as out:
            json.dump(document, out, indent=1, allow_nan=False)
            out.write("\n")
    except OSError as error:
        raise InputError(f"{path}: cannot write the verdict JSON ({error.strerror})") from None


def _progress_bar(frames: int) -> Callable[[Iterable[int]], Iterable[int]] | None:
    if frames < PROGRESS_MIN_FRAMES:
        return None
    from tqdm import tqdm

    def wrap(timestamps: Iterable[int]) -> Iterable[int]:
        # disable=None: shown on a terminal only, so logs and pipes stay clean.
        bar: Iterable[int] = tqdm(
            timestamps, total=frames, unit="frame", file=sys.stderr, disable=None
        )
        return bar

    return wrap
