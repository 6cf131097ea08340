"""``ads-rca replay PATH``: the run through the live node graph, verdict as ``diagnose`` gives it.

Starts the player, the four monitors, the aggregator (and the recorder with ``--record``) as
separate processes on a DDS domain of their own with local-only discovery, waits for the
aggregator's verdict, prints it like ``diagnose`` does, writes the JSON (the ``diagnose
--json`` contract plus ``verdict_latency_s`` and ``live``) and stops everything cleanly. The
monitors run the engine's oracles and the aggregator its attribution, so for a log that ends
at its collision (as recorded crashes do) the verdict equals ``ads-rca diagnose``'s.
"""

from __future__ import annotations

import argparse
import signal
import sys
import tempfile
from pathlib import Path
from typing import Any

from ads_rca.commands.diagnose_cmd import add_engine_arguments, params_from_args, write_json
from ads_rca.commands.input_args import add_reader_arguments, max_file_mb_from_args
from ads_rca.commands.outputs import check_output_dir, check_output_file
from ads_rca.commands.playback_args import add_playback_arguments, check_playback_arguments
from ads_rca.errors import InputError
from ads_rca.ros.env import pick_domain_id, ros_environment
from ads_rca.summary import summary_text
from ads_rca.text import printable, printable_lines


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "replay", help="replay a run through the live node graph (monitors + aggregator)"
    )
    parser.add_argument("path", help="running-log folder (or a bag the player reads)")
    add_engine_arguments(parser)
    add_reader_arguments(parser)
    add_playback_arguments(parser)
    parser.add_argument("--record", metavar="OUT", help="record every topic to this MCAP bag")
    parser.add_argument("--json", dest="json_out", help="write the verdict JSON here")
    parser.add_argument(
        "--monitors",
        choices=("shared", "separate"),
        default="shared",
        help="the four monitors in one process (inputs decoded once; default) or one each",
    )
    parser.add_argument("--verbose", action="store_true", help="show every node's output")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from ads_rca.ros.graph import Graph, GraphSpec, recorder_available

    path = Path(args.path)
    if not path.exists():
        raise InputError(f"{path}: no such log folder or bag")
    check_playback_arguments(args)
    params = params_from_args(args)
    max_file_mb = max_file_mb_from_args(args)
    if args.json_out:
        check_output_file(args.json_out, "--json")
    record = Path(args.record) if args.record else None
    if record is not None and not recorder_available():
        print("ads-rca replay: no recorder node in this installation; not recording")
        record = None
    if record is not None:  # the recorder needs a new (or empty) folder
        check_output_dir(record, "--record")
    domain_id = args.domain_id if args.domain_id is not None else pick_domain_id()
    work = Path(tempfile.mkdtemp(prefix="ads_rca_replay_"))
    env = ros_environment(domain_id=domain_id, log_dir=work / "ros_log")
    spec = GraphSpec(
        log_path=path.resolve(),
        params=params,
        verdict_json=work / "verdict.json",
        rate=args.rate,
        record=record.resolve() if record is not None else None,
        monitors=args.monitors,
        player_params={"max_file_mb": float(max_file_mb)},
    )
    print(
        printable(
            f"ads-rca replay: {path} through the node graph (semantics {params.semantics}, "
            f"rate {args.rate:g}, ROS_DOMAIN_ID={domain_id}, discovery LOCALHOST)"
        ),
        flush=True,
    )
    echo = sys.stdout if args.verbose else None
    with Graph(spec, env, echo=echo) as graph:
        graph.start()
        document = graph.wait_verdict(args.timeout)
        failed = graph.failed() if document is None else {}
        codes = graph.stop()
        outputs = {name: p.output for name, p in graph.processes.items()}
    if document is None:
        for name, code in failed.items():
            last = next((x for x in reversed(outputs[name].splitlines()) if x.strip()), "")
            print(
                printable(
                    f"ads-rca replay: no verdict: {name} exited early ({exit_status(code)})"
                    + (f": {last.strip()}" if last else "")
                ),
                file=sys.stderr,
            )
        if not failed:
            print(f"ads-rca replay: no verdict within {args.timeout:g} s", file=sys.stderr)
        for name, text in outputs.items():
            tail = "\n".join(text.splitlines()[-8:])
            print(printable_lines(f"--- {name} (exit {codes.get(name)}):\n{tail}"), file=sys.stderr)
        return 2 if codes.get("player") == 2 else 1
    print(live_summary(document))
    if args.json_out:
        write_json(document, Path(args.json_out))
        print(printable(f"verdict JSON: {args.json_out}"))
    if record is not None:
        write_json(document, record / "verdict.json")
        print(
            printable(
                f"MCAP recording: {record} (verdict JSON beside it: {record / 'verdict.json'})"
            )
        )
    return 0


def exit_status(code: int) -> str:
    """``status 2`` or ``killed by SIGSEGV``: how a child process ended."""
    if code >= 0:
        return f"status {code}"
    try:
        return f"killed by {signal.Signals(-code).name}"
    except ValueError:
        return f"killed by signal {-code}"


def live_summary(document: dict[str, Any]) -> str:
    """``diagnose``'s summary of the same contract, plus the live graph's own figures."""
    live = document.get("live") or {}
    lines = [summary_text(document, how="judged live")]
    lines.append(f"verdict latency: {document.get('verdict_latency_s', 0.0):.3f} s")
    if not live.get("complete", True):
        lines.append(printable("INCOMPLETE: " + "; ".join(live.get("why_incomplete") or [])))
    return "\n".join(lines)
