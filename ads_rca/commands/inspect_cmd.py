"""``ads-rca inspect PATH``: what a log or bag holds, which model inputs it gives, which
modules each semantics mode can therefore judge, and every problem found while reading it."""

from __future__ import annotations

import argparse
from collections import Counter
from pathlib import Path
from typing import Any

from ads_rca.capabilities import input_status, present, statuses_to_document
from ads_rca.commands import command_parser
from ads_rca.commands.input_args import (
    add_bag_arguments,
    add_reader_arguments,
    bag_options_from_args,
    checked_max_problems,
    max_file_mb_from_args,
    source_options_from_args,
)
from ads_rca.commands.progress_bar import terminal_bar
from ads_rca.diagnosis.conclusion import COLLISION_NO, COLLISION_UNKNOWN_STATE, collision_state
from ads_rca.foundation.strictjson import dumps
from ads_rca.foundation.text import printable
from ads_rca.model import FOLDERS, RunLog
from ads_rca.oracles.semantics import MODES, semantics_for
from ads_rca.sources.bag import NAME as BAG
from ads_rca.sources.bag.options import BagOptions
from ads_rca.sources.bag.reader import BagContents, load_bag, read_bag
from ads_rca.sources.registry import open_run, resolved_format


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = command_parser(
        subparsers,
        "inspect",
    )
    parser.add_argument("path", help="log folder or bag")
    parser.add_argument("--json", action="store_true", help="print the summary as JSON")
    add_reader_arguments(parser)
    add_bag_arguments(parser)
    parser.add_argument(
        "--max-problems", type=int, default=20, help="problem lines to print (default 20)"
    )
    parser.set_defaults(run=run)


def summary(log: RunLog, contents: BagContents | None = None) -> dict[str, Any]:
    """What ``inspect --json`` prints (``contents``: the bag's topics, when a bag)."""
    meta = log.metadata
    statuses = input_status(log)
    out: dict[str, Any] = {
        "source": log.source,
        "timesteps_per_frame": meta.timesteps_per_frame,
        "collision_frame": meta.collision_frame,
        "collision": collision_state(log, present(statuses["collision"])),
        "total_frames": meta.total_frames,
        "analysed_frames": len(log.frames),
        "unique_frames": len(log.unique_frames),
        "files": {folder: len(log.folder(folder)) for folder in FOLDERS},
        "actors": len({a for frame in log.actors.values() for a in frame.ids}),
        "inputs": statuses_to_document(statuses),
        "modules_judged": {mode: semantics_for(mode).judged(log) for mode in MODES},
        "problems": [p.to_dict() for p in log.problems],
    }
    if contents is not None:
        counts = Counter(m.topic for m in contents.messages)
        out["topics"] = [
            {"name": name, "type": msg_type, "count": counts[name]}
            for name, msg_type in sorted(contents.topics.items())
        ]
    return out


def _load(path: str, args: argparse.Namespace) -> tuple[RunLog, BagContents | None]:
    bag = bag_options_from_args(args)
    source = source_options_from_args(args)
    progress = terminal_bar("loading")
    if resolved_format(path, source.source_format) != BAG:
        log = open_run(
            path,
            max_file_mb=max_file_mb_from_args(args),
            progress=progress,
            bag=bag,
            source=source,
        )
        return log, None
    contents = load_bag(path)
    if bag.contract:
        return read_bag(path, remap=bag.remap, progress=progress, contents=contents), contents
    from ads_rca.sources.bag.profiles.recording import read_recording

    log = read_recording(path, bag.profile, bag.msg_path, progress, contents=contents)
    return log, contents


def text_lines(info: dict[str, Any]) -> list[str]:
    """The human summary: one item per line (every line is escaped by the caller)."""
    lines = [
        f"{info['source']}: {info['analysed_frames']} analysed frames "
        f"({info['unique_frames']} timestamps) at {info['timesteps_per_frame']} ms, "
        f"{info['actors']} actors, {_collision_words(info)}, "
        f"total_frames {info['total_frames']}",
    ]
    if "topics" in info:
        lines.append(f"topics: {len(info['topics'])}")
        lines.extend(f"  {t['name']}  {t['type']}  {t['count']}" for t in info["topics"])
    else:
        lines.append("files: " + ", ".join(f"{k} {v}" for k, v in info["files"].items()))
    found = [n for n, s in info["inputs"].items() if s["state"] != "absent"]
    missing = [n for n, s in info["inputs"].items() if s["state"] == "absent"]
    lines.append("inputs found: " + (", ".join(found) or "none"))
    for name in found:
        status = info["inputs"][name]
        detail = ", ".join(x for x in (status["source"], status["reason"]) if x)
        if status["state"] != "real" or detail:
            lines.append(f"  {name}: {status['state']}" + (f" ({detail})" if detail else ""))
    lines.append("inputs missing: " + (", ".join(missing) or "none"))
    for name in missing:
        reason = info["inputs"][name]["reason"]
        if reason:
            lines.append(f"  {name}: {reason}")
    for mode, judged in info["modules_judged"].items():
        lines.append(f"{mode}: " + "; ".join(f"{m} {v}" for m, v in judged.items()))
    return lines


def _collision_words(info: dict[str, Any]) -> str:
    """``collision frame N``, ``no collision`` (the run's source says none) or ``collision
    unknown`` (it has none): never -1, which reads as none (docs/verdicts.md)."""
    state = info["collision"]
    if state == COLLISION_UNKNOWN_STATE:
        return "collision unknown"
    return "no collision" if state == COLLISION_NO else f"collision frame {info['collision_frame']}"


def run(args: argparse.Namespace) -> int:
    checked_max_problems(args.max_problems)
    if not Path(args.path).exists():
        open_run(args.path, bag=BagOptions())  # the one-line "no such log folder or bag"
    log, contents = _load(args.path, args)
    info = summary(log, contents)
    if args.json:
        print(dumps(info, indent=2))  # strict JSON: NaN/inf as null + "$nonfinite"
        return 0
    lines = [
        *text_lines(info),
        f"problems: {len(log.problems)}",
        *(f"  {line}" for line in log.problems.summary_lines(args.max_problems)),
    ]
    for line in lines:  # names, sources and problems come from the log: one line each, escaped
        print(printable(line))
    return 0
