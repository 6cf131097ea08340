"""``ads-rca inspect PATH``: what a log or bag holds, which model inputs it gives, which
modules each semantics mode can therefore judge, and every problem found while reading it.

A bag with no ``--profile`` is surveyed (:mod:`ads_rca.sources.bag.survey`): every topic
with its type, messages, rate and span, each built-in profile's fit and the one to use, read
without decoding a message, so any rosbag2 bag lists; this project's own bags are then read
as before. ``--write-profile FILE`` writes a starting profile from the bag's types."""

from __future__ import annotations

import argparse
import os
from collections import Counter
from pathlib import Path
from typing import Any

from ads_rca.capabilities import (
    MODEL_INPUTS,
    input_status,
    present,
    statuses_to_document,
)
from ads_rca.commands import command_parser
from ads_rca.commands.input_args import (
    add_bag_arguments,
    add_reader_arguments,
    bag_options_from_args,
    checked_max_problems,
    max_file_mb_from_args,
    source_options_from_args,
)
from ads_rca.commands.outputs import check_output_file, unwritten
from ads_rca.commands.progress_bar import terminal_bar
from ads_rca.diagnosis.conclusion import COLLISION_NO, COLLISION_UNKNOWN_STATE, collision_state
from ads_rca.errors import InputError
from ads_rca.foundation.atomic_write import replace_text
from ads_rca.foundation.strictjson import dumps
from ads_rca.foundation.text import printable
from ads_rca.model import FOLDERS, InputStatus, RunLog
from ads_rca.oracles.semantics import MODES, semantics_for
from ads_rca.problems import Problem, ProblemLog
from ads_rca.sources.bag import NAME as BAG
from ads_rca.sources.bag.options import BagOptions
from ads_rca.sources.bag.reader import BagContents, load_bag, read_bag
from ads_rca.sources.bag.survey import (
    BagSurvey,
    listing_lines,
    picks,
    profile_lines,
    profile_name,
    starting_profile,
    survey_bag,
    survey_contents,
)
from ads_rca.sources.registry import open_run, resolved_format

#: Characters of one printed line: a bag's names are untrusted (a 10 kB topic name is
#: cut where it is shown; this bounds every other line too).
MAX_LINE_CHARS = 2000


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = command_parser(
        subparsers,
        "inspect",
    )
    parser.add_argument("path", help="log folder or bag")
    parser.add_argument("--json", action="store_true", help="print the summary as JSON")
    add_reader_arguments(parser)
    add_bag_arguments(
        parser,
        no_profile="default for a bag: list it, fit every built-in profile and recommend "
        "one; this project's own bags are read as well",
    )
    parser.add_argument(
        "--write-profile",
        metavar="FILE",
        help="a bag: write a starting profile YAML to FILE, each model input on the topic "
        "of its type with most messages, the other candidates as comments, to check and edit",
    )
    parser.add_argument(
        "--force", action="store_true", help="let --write-profile replace an existing FILE"
    )
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


def survey_summary(survey: BagSurvey) -> dict[str, Any]:
    """What ``inspect --json`` prints of a bag surveyed alone (no run read): the listing,
    the profiles' fits, the recommendation and what each mode could judge with it."""
    recommended = survey.recommendation.profile if survey.recommendation else None
    fit = next((f for f in survey.fits if f.profile == recommended), None)
    return {
        "source": survey.path,
        **survey.to_dict(),
        "modules_judged_with_recommended": None if fit is None else judged_with(fit.mapped),
        "problems": [p.to_dict() for p in survey.problems],
    }


def judged_with(mapped: tuple[str, ...]) -> dict[str, dict[str, str]]:
    """Per mode, which modules a run with (only) the ``mapped`` inputs could judge, as the
    reader and diagnose would make it: tracks derived from predicted objects, and the
    stack's tracks as the world when there is no ground truth (docs/real-drives.md)."""
    statuses = {
        name: InputStatus("real") if name in mapped else InputStatus("absent")
        for name in MODEL_INPUTS
    }
    if "tracked_objects" not in mapped and "predictions" in mapped:
        statuses["tracked_objects"] = InputStatus("derived")
    perceived = "actors" not in mapped and "ego" in mapped and present(statuses["tracked_objects"])
    if perceived:
        statuses["actors"] = InputStatus("derived")
    out: dict[str, dict[str, str]] = {}
    for mode in MODES:
        judged = semantics_for(mode).judged_for(statuses, perceived)
        out[mode] = {str(module): verdict for module, verdict in judged.items()}
    return out


def _load(
    path: str, args: argparse.Namespace, writing: bool
) -> tuple[RunLog | None, BagContents | None, BagSurvey | None]:
    """The run (None: a bag only surveyed), the bag's contents when read whole, and the
    bag's survey (None: not a bag)."""
    bag = bag_options_from_args(args)
    source = source_options_from_args(args)
    if resolved_format(path, source.source_format) != BAG:
        if writing:
            raise InputError(f"--write-profile: {path} is not a bag")
        log = open_run(
            path,
            max_file_mb=max_file_mb_from_args(args),
            progress=terminal_bar("loading"),
            bag=bag,
            source=source,
        )
        return log, None, None
    if args.profile is None and not bag.remap:
        survey = survey_bag(path, bag.msg_path)
        recommended = survey.recommendation.profile if survey.recommendation else None
        if not any(fit.contract and fit.profile == recommended for fit in survey.fits):
            return None, None, survey
        try:  # this project's own bag: its run is read too
            contents = load_bag(path)
            log = read_bag(path, progress=terminal_bar("loading"), contents=contents)
        except InputError as error:  # a damaged run/metadata: the bag is still listed
            issue = str(error).removeprefix(f"{path}: ")
            survey.problems.append(Problem(path, "", issue, "the run is not read"))
            return None, None, survey
        return log, contents, survey
    contents = load_bag(path)
    progress = terminal_bar("loading")
    if bag.contract:
        log = read_bag(path, remap=bag.remap, progress=progress, contents=contents)
    else:
        from ads_rca.sources.bag.profiles.recording import read_recording

        log = read_recording(path, bag.profile, bag.msg_path, progress, contents=contents)
    return log, contents, survey_contents(contents, bag.msg_path)


def text_lines(info: dict[str, Any]) -> list[str]:
    """The human summary: one item per line (every line is escaped by the caller)."""
    lines = [
        f"{info['source']}: {info['analysed_frames']} analysed frames "
        f"({info['unique_frames']} timestamps) at {info['timesteps_per_frame']} ms, "
        f"{info['actors']} actors, {_collision_words(info)}, "
        f"total_frames {info['total_frames']}",
    ]
    if "topics" not in info:
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
    target = _profile_target(args.write_profile, args.force)
    log, contents, survey = _load(args.path, args, target is not None)
    written = _write_profile(target, survey) if target is not None and survey else None
    info = summary(log, contents) if log is not None else {}
    if survey is not None:  # the run's summary (if read), the bag's listing and fits
        info |= survey.to_dict() if log is not None else survey_summary(survey)
    if written is not None:
        info["written_profile"] = written
    if args.json:
        print(dumps(info, indent=2))  # strict JSON: NaN/inf as null + "$nonfinite"
        return 0
    problems = log.problems if log is not None else ProblemLog(survey.problems if survey else ())
    run_lines = text_lines(info) if log is not None else []
    lines = [
        *run_lines[:1],  # what the run is, first; then the bag's topics
        *(listing_lines(survey) if survey is not None else ()),
        *run_lines[1:],
        *(profile_lines(survey) if survey is not None and args.profile is None else ()),
        *_judged_lines(info),
        *_written_lines(written),
        f"problems: {len(problems)}",
        *(f"  {line}" for line in problems.summary_lines(args.max_problems)),
    ]
    for line in lines:  # names, sources and problems come from the log: one line each, escaped
        print(_cut(printable(line)))
    return 0


def _cut(line: str) -> str:
    return line if len(line) <= MAX_LINE_CHARS else line[: MAX_LINE_CHARS - 1] + "…"


def _judged_lines(info: dict[str, Any]) -> list[str]:
    judged = info.get("modules_judged_with_recommended")
    profile = (info.get("recommendation") or {}).get("profile")
    if not judged or not profile:
        return []
    return [
        f"with --profile {profile}, {mode}: " + "; ".join(f"{m} {v}" for m, v in modules.items())
        for mode, modules in judged.items()
    ]


def _profile_target(path: str | None, force: bool) -> Path | None:
    """``--write-profile FILE`` checked before any work: writable, and new unless
    ``--force`` (a user's edited profile is not lost to a second run)."""
    if path is None:
        if force:
            raise InputError("--force: only with --write-profile FILE")
        return None
    target = check_output_file(path, "--write-profile")
    if os.path.lexists(target) and not force:
        raise InputError(f"--write-profile {target}: exists (--force replaces it)")
    return target


def _write_profile(target: Path, survey: BagSurvey) -> dict[str, Any]:
    """Write the bag's starting profile to ``target`` (whole or not at all: a temporary
    file beside it, then renamed), and say what it maps."""
    text = starting_profile(survey, profile_name(target))
    try:
        replace_text(target, text)
    except OSError as error:
        raise unwritten("--write-profile", target, error) from None
    chosen = picks(survey.topics)
    return {"path": str(target), "inputs": {name: t.name for name, t in chosen.items()}}


def _written_lines(written: dict[str, Any] | None) -> list[str]:
    if written is None:
        return []
    inputs = ", ".join(written["inputs"])
    return [f"profile written: {written['path']} (maps {inputs}; check it, then --profile FILE)"]
