"""``ads-rca inspect PATH``: what a log holds, and every problem found while reading it."""

from __future__ import annotations

import argparse
from typing import Any

from ads_rca.commands.input_args import add_reader_arguments, max_file_mb_from_args
from ads_rca.commands.progress_bar import terminal_bar
from ads_rca.io import open_run
from ads_rca.model import FOLDERS, RunLog
from ads_rca.strictjson import dumps
from ads_rca.text import printable


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = subparsers.add_parser(
        "inspect", help="summarise a run log and list the problems found in it"
    )
    parser.add_argument("path", help="log folder or bag")
    parser.add_argument("--json", action="store_true", help="print the summary as JSON")
    add_reader_arguments(parser)
    parser.add_argument(
        "--max-problems", type=int, default=20, help="problem lines to print (default 20)"
    )
    parser.set_defaults(run=run)


def summary(log: RunLog) -> dict[str, Any]:
    meta = log.metadata
    return {
        "source": log.source,
        "timesteps_per_frame": meta.timesteps_per_frame,
        "collision_frame": meta.collision_frame,
        "total_frames": meta.total_frames,
        "analysed_frames": len(log.frames),
        "unique_frames": len(log.unique_frames),
        "files": {folder: len(log.folder(folder)) for folder in FOLDERS},
        "actors": len({a for frame in log.actors.values() for a in frame.ids}),
        "problems": [p.to_dict() for p in log.problems],
    }


def run(args: argparse.Namespace) -> int:
    log = open_run(
        args.path, max_file_mb=max_file_mb_from_args(args), progress=terminal_bar("loading")
    )
    if args.json:
        print(dumps(summary(log), indent=2))  # strict JSON: NaN/inf as null + "$nonfinite"
        return 0
    info = summary(log)
    lines = [
        f"{info['source']}: {info['analysed_frames']} analysed frames "
        f"({info['unique_frames']} timestamps) at {info['timesteps_per_frame']} ms, "
        f"{info['actors']} actors, collision frame {info['collision_frame']}, "
        f"total_frames {info['total_frames']}",
        "files: " + ", ".join(f"{k} {v}" for k, v in info["files"].items()),
        f"problems: {len(log.problems)}",
        *(f"  {line}" for line in log.problems.summary_lines(args.max_problems)),
    ]
    for line in lines:  # the source and problems come from the log: one line each, escaped
        print(printable(line))
    return 0
