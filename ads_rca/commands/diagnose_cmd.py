"""``ads-rca diagnose PATH``: load a run, judge every module, print and write the verdict."""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Mapping
from dataclasses import fields
from pathlib import Path
from typing import Any

from ads_rca.commands import command_parser
from ads_rca.commands.input_args import (
    READER_PARAMS,
    add_bag_arguments,
    add_reader_arguments,
    bag_options_from_args,
    checked_max_problems,
    max_file_mb_from_args,
    source_options_from_args,
)
from ads_rca.commands.outputs import check_output_file, unwritten
from ads_rca.commands.progress_bar import terminal_bar
from ads_rca.diagnosis.compare import why_modes_differ
from ads_rca.diagnosis.engine import Diagnosis, diagnose
from ads_rca.diagnosis.summary import summary_text
from ads_rca.errors import EXIT_INTERNAL_ERROR, ConfigError, InputError
from ads_rca.foundation.atomic_write import replacing_text
from ads_rca.foundation.indented_json import write_indented
from ads_rca.foundation.quick_exit import keep_until_exit
from ads_rca.foundation.text import printable
from ads_rca.foundation.workers import checked_workers, loaded_objects_frozen
from ads_rca.foundation.yaml_files import load_config
from ads_rca.model import RunLog
from ads_rca.oracles.semantics import semantics_for
from ads_rca.params import (
    DEFAULT_SEMANTICS,
    SEMANTICS,
    Params,
    parameters_help,
    params_from_sources,
)
from ads_rca.params import parse_assignments as parse_p
from ads_rca.sources.registry import no_frame_message, open_run

#: ``--semantics both``: judge in every mode and say why the verdicts differ.
BOTH = "both"


def add_engine_arguments(parser: argparse.ArgumentParser, both: bool = False) -> None:
    """--semantics, --config and -p: shared by every command that runs the engine
    (``both``: ``--semantics both`` is accepted too)."""
    parser.add_argument(
        "--semantics",
        choices=(*SEMANTICS, BOTH) if both else SEMANTICS,
        default=None,
        help=f"oracle semantics (default {DEFAULT_SEMANTICS}, or the config file's)"
        + (f"; {BOTH}: every mode, and why their verdicts differ" if both else ""),
    )
    parser.add_argument("--config", help="YAML parameters (flat, or a ROS 2 params file)")
    parser.add_argument(
        "-p",
        dest="params",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="set one parameter (repeatable), e.g. -p safety_margin=0.8; what each does in "
        "each mode, its defaults and range: below",
    )
    parser.add_argument(
        "--event-time",
        type=float,
        default=None,
        metavar="SECONDS",
        help="the critical event to explain when the run knows no collision: seconds from "
        "the recording's first message (the parameter event_time_s; this wins over -p)",
    )
    # The parameter table says what a value does in each mode (effect_time_window=15
    # changes nothing in corrected mode at 20 Hz): on --help, laid out as written.
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.epilog = parameters_help()


def params_from_args(args: argparse.Namespace, semantics: str | None = None) -> Params:
    """Config file, then -p overrides; ``semantics``, else --semantics, wins over both.

    A config key that no part of the package reads is refused with the known names (a
    misspelt threshold would otherwise be silently ignored); a value out of range is
    refused naming the file.
    """
    config: dict[str, Any] = load_config(args.config) if args.config else {}
    check_config_keys(args.config, config)
    overrides = parse_p(args.params)
    for name in READER_PARAMS:  # the reader's, not the engine's
        overrides.pop(name, None)
    if getattr(args, "event_time", None) is not None:
        overrides["event_time_s"] = args.event_time
    return params_from_sources(semantics or args.semantics, config, overrides, args.config)


def check_config_keys(path: str | None, config: dict[str, Any]) -> None:
    """Every key of a ``--config`` file is a parameter of the engine, the reader or a node
    of the live graph (a ROS 2 params file for the whole graph is a valid config)."""
    known = {*(f.name for f in fields(Params)), *READER_PARAMS}
    if all(key in known for key in config):
        return
    known |= graph_parameter_names()
    unknown = [str(key) for key in config if key not in known]
    if unknown:
        raise ConfigError(
            f"{path}: unknown parameter {', '.join(map(repr, unknown))} "
            f"(known: {', '.join(sorted(known))})"
        )


def graph_parameter_names() -> set[str]:
    """The parameters the live graph's nodes declare (imports the nodes, hence rclpy: only
    asked when a config file holds more than engine and reader names)."""
    from ads_rca.ros import aggregator, monitor, player, recorder, topic_summary
    from ads_rca.ros.nodeparams import ROS_NODE_PARAMETERS

    tables = (aggregator, monitor, player, recorder, topic_summary)
    return {name for module in tables for name in module.PARAMETERS} | set(ROS_NODE_PARAMETERS)


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = command_parser(subparsers, "diagnose")
    parser.add_argument("path", help="log folder or bag")
    add_engine_arguments(parser, both=True)
    add_reader_arguments(parser)
    add_bag_arguments(parser)
    parser.add_argument("--json", dest="json_out", help="write the verdict JSON here")
    parser.add_argument("--report", help="write a self-contained HTML report here")
    parser.add_argument(
        "--max-problems", type=int, default=10, help="input problems to print (default 10)"
    )
    parser.add_argument(
        "--workers",
        type=int,
        default=os.cpu_count() or 1,
        help="processes reading and judging long logs (default: one per core)",
    )
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    both = args.semantics == BOTH
    if both and (args.json_out or args.report):
        raise InputError(
            f"--semantics {BOTH} prints a comparison; --json and --report take one mode"
        )
    all_params = [params_from_args(args, mode) for mode in (SEMANTICS if both else (None,))]
    max_file_mb = max_file_mb_from_args(args)
    bag = bag_options_from_args(args)
    source = source_options_from_args(args)
    if args.json_out:
        check_output_file(args.json_out, "--json")
    if args.report:
        check_output_file(args.report, "--report")
    workers = checked_workers(args.workers)
    checked_max_problems(args.max_problems)
    log = open_run(
        args.path,
        max_file_mb=max_file_mb,
        progress=terminal_bar("loading"),
        bag=bag,
        workers=workers,
        source=source,
    )
    documents: list[dict[str, Any]] = []
    with loaded_objects_frozen():  # the loaded run stays until the end, in no cycle
        for params in all_params:
            documents.append(_judge_and_write(log, params, args, workers, bool(documents)))
    if both:
        print(printable(why_modes_differ(documents)))
    keep_until_exit(log, documents)  # every file is written and closed
    raised = any(document.get("internal_errors") for document in documents)
    return EXIT_INTERNAL_ERROR if raised else 0


def _judge_and_write(
    log: RunLog, params: Params, args: argparse.Namespace, workers: int, after: bool
) -> dict[str, Any]:
    """Judge ``log`` in one mode, write its files, print its summary (``after`` another
    one: a blank line first); its verdict JSON."""
    if not semantics_for(params).analysed_frames(log):
        source = source_options_from_args(args)
        bag = bag_options_from_args(args)
        raise InputError(no_frame_message(args.path, log, source.source_format, bag))
    result = diagnose(
        log, params, terminal_bar("judging"), workers=workers, render_frames=bool(args.json_out)
    )
    document = result.to_json()
    # The files first: they never depend on stdout (``| head`` may close it early).
    if args.json_out:
        write_json(document, Path(args.json_out))
    if args.report:
        _write_report(result, Path(args.report))
    if after:
        print()
    print(summary_text(document, args.max_problems))
    if args.json_out:
        print(printable(f"verdict JSON: {args.json_out}"))
    if args.report:
        print(printable(f"HTML report: {args.report}"))
    report_internal_errors(result, "diagnose")
    keep_until_exit(result)  # its judging caches too
    return document


def report_internal_errors(result: Diagnosis, command: str) -> None:
    """Each module whose oracle raised: its first traceback and one line on stderr (a bug
    in ads_rca, never the input's fault; the outputs say the module was not judged)."""
    for error in result.conclusion.internal_errors:
        sys.stdout.flush()
        print(result.ctx.tracebacks.get(error.module, ""), end="", file=sys.stderr)
        print(internal_error_line(command, error.to_dict()), file=sys.stderr)


def internal_error_line(command: str, error: Mapping[str, object]) -> str:
    """The line ``diagnose`` and ``replay`` print on stderr after a module's traceback
    (``error``: an entry of the verdict JSON's ``internal_errors``)."""
    return printable(
        f"ads-rca {command}: internal error: the {error.get('module')} check raised on "
        f"{error.get('frames')} frame(s), first at frame {error.get('first_frame')} "
        f"({error.get('error')}); this is a bug in ads_rca, not in the input: please report "
        "it with the traceback above"
    )


def _write_report(result: Diagnosis, path: Path) -> None:
    from ads_rca.report.html import write_report

    try:
        write_report(result, path)
    except OSError as error:  # checked up front; this is a failure during the write
        raise unwritten("--report", path, error) from None


def write_json(document: dict[str, Any], path: Path, option: str = "--json") -> None:
    """The verdict JSON (the contract; NaN and infinity are already null).

    The same bytes as ``json.dumps(document, indent=1)`` plus a newline, written by
    :mod:`ads_rca.foundation.indented_json` (1.6 to 4.5 times faster) piece by piece, into
    a file that replaces ``path`` whole (:mod:`ads_rca.foundation.atomic_write`). The path
    was checked before the work started; a write that fails all the same (disk full, a file
    that refuses data) is still one line naming ``option``, not a traceback, and an earlier
    file at ``path`` is left whole.
    """
    try:
        with replacing_text(path, buffering=1 << 16) as out:
            write_indented(document, out)
            out.write("\n")
    except OSError as error:
        raise unwritten(option, path, error) from None
