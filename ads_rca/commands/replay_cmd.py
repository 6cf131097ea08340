"""``ads-rca replay PATH``: the run through the live node graph, verdict as ``diagnose`` gives it.

Starts the player, the four monitors, the aggregator (and the recorder with ``--record``) as
separate processes on a DDS domain of their own with local-only discovery, waits for the
aggregator's verdict, stops the nodes cleanly (the recorder finalising its bag), prints the
verdict like ``diagnose`` does and writes the JSON (the ``diagnose --json`` contract plus
``verdict_latency_s`` and ``live``). With ``--zenoh`` the bridge alone then serves the run to
late dashboards for ``--zenoh-linger`` seconds; a stop signal then loses nothing. The
monitors run the engine's oracles and the aggregator its attribution, so for a log that ends
at its collision (as recorded crashes do) the verdict equals ``ads-rca diagnose``'s.
"""

from __future__ import annotations

import argparse
import itertools
import math
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator, Mapping
from contextlib import contextmanager, suppress
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING, Any

from ads_rca.commands import command_parser
from ads_rca.commands.diagnose_cmd import (
    add_engine_arguments,
    internal_error_line,
    params_from_args,
    write_json,
)
from ads_rca.commands.input_args import (
    add_bag_arguments,
    add_reader_arguments,
    bag_options_from_args,
    max_file_mb_from_args,
    source_options_from_args,
)
from ads_rca.commands.outputs import check_output_dir, check_output_file
from ads_rca.commands.playback_args import (
    add_playback_arguments,
    allow_external,
    check_playback_arguments,
    choose_domain_id,
)
from ads_rca.commands.zenoh_args import add_zenoh_arguments, zenoh_params_from_args
from ads_rca.diagnosis.summary import summary_text
from ads_rca.errors import EXIT_INTERNAL_ERROR, AdsRcaError, InputError
from ads_rca.foundation.text import printable, printable_lines
from ads_rca.params import Params
from ads_rca.ros.env import discovery_note, ros_environment
from ads_rca.ros.graph import LAUNCH_ARGUMENTS, exit_status
from ads_rca.ros.launcher import ParamValue
from ads_rca.ros.lifeline import PARENT_VARIABLE
from ads_rca.sources.bag.profiles import BUILTIN_PROFILES

if TYPE_CHECKING:
    from ads_rca.ros.graph import Graph, GraphSpec


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = command_parser(subparsers, "replay")
    parser.add_argument("path", help="log folder or bag")
    parser.add_argument(
        "--namespace",
        default=LAUNCH_ARGUMENTS["namespace"].default,
        help=LAUNCH_ARGUMENTS["namespace"].description,
    )
    add_engine_arguments(parser)
    add_reader_arguments(parser)
    add_bag_arguments(parser, remap_flags=("--bag-remap", "--remap"), remap_dest="bag_remap")
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
    add_zenoh_arguments(parser)
    parser.set_defaults(run=run)


def _resolved_profile(profile: str) -> str:
    """A built-in profile's name as given; a profile file's absolute path (the player runs
    in another working directory)."""
    return profile if profile in BUILTIN_PROFILES else str(Path(profile).resolve())


def run(args: argparse.Namespace) -> int:
    from ads_rca.ros.graph import recorder_available

    path = Path(args.path)
    if not path.exists():
        raise InputError(f"{path}: no such log folder or bag")
    check_playback_arguments(args)
    params = params_from_args(args)
    player_params: dict[str, ParamValue] = {"max_file_mb": float(max_file_mb_from_args(args))}
    source = source_options_from_args(args)
    player_params.update(source.as_params())
    bag = bag_options_from_args(args)
    if bag.remap:
        player_params["bag_remap"] = str(Path(bag.remap).resolve())
    player_params["profile"] = _resolved_profile(bag.profile)
    if bag.msg_path:
        player_params["msg_path"] = os.pathsep.join(str(Path(d).resolve()) for d in bag.msg_path)
    if args.json_out:
        check_output_file(args.json_out, "--json")
    record = Path(args.record) if args.record else None
    if record is not None and not recorder_available():
        print("ads-rca replay: no recorder node in this installation; not recording")
        record = None
    if record is not None:  # the recorder needs a new (or empty) folder
        check_output_dir(record, "--record")
    domain_id, domain_how = choose_domain_id(args)
    with stop_signals() as graphs:
        try:
            return _run_graph(
                args, params, player_params, path, record, domain_id, domain_how, graphs
            )
        except Interrupted as stop:
            print(f"ads-rca replay: stopped by {stop}; every node stopped", file=sys.stderr)
            return 128 + stop.signum


def _run_graph(
    args: argparse.Namespace,
    params: Params,
    player_params: dict[str, ParamValue],
    path: Path,
    record: Path | None,
    domain_id: int,
    domain_how: str,
    graphs: list[Graph],
) -> int:
    """The replay in a work folder that is removed however it ends."""
    from ads_rca.ros.graph import GraphSpec

    work = Path(tempfile.mkdtemp(prefix="ads_rca_replay_"))
    reaper = start_reaper(work)
    try:
        env = ros_environment(
            domain_id=domain_id, log_dir=work / "ros_log", allow_external=allow_external(args)
        )
        spec = GraphSpec(
            log_path=path.resolve(),
            params=params,
            verdict_json=work / "verdict.json",
            rate=args.rate,
            record=record.resolve() if record is not None else None,
            monitors=args.monitors,
            namespace=args.namespace,
            player_params=player_params,
            zenoh_params=zenoh_params_from_args(args),
        )
        print(
            printable(
                f"ads-rca replay: {path} through the node graph (semantics "
                f"{params.semantics}, rate {args.rate:g}, ROS_DOMAIN_ID={domain_id} "
                f"({domain_how}), {discovery_note(env)}, run {spec.run_id})"
            ),
            flush=True,
        )
        return _replay(args, spec, env, record, graphs)
    finally:
        shutil.rmtree(work, ignore_errors=True)
        if reaper is not None and reaper.stdin is not None:
            reaper.stdin.close()  # the reaper finds nothing left to do and exits
            with suppress(subprocess.TimeoutExpired):
                reaper.wait(5.0)


def start_reaper(work: Path) -> subprocess.Popen[bytes] | None:
    """The process that stops our nodes and removes ``work`` if we are SIGKILLed
    (:mod:`ads_rca.ros.reaper`); None if it cannot start (we still clean up ourselves)."""
    env = {**os.environ, PARENT_VARIABLE: str(os.getpid())}
    try:
        return subprocess.Popen(
            [sys.executable, "-m", "ads_rca.ros.reaper", str(work)],
            stdin=subprocess.PIPE,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            env=env,
            start_new_session=True,
        )
    except OSError:
        return None


class Interrupted(AdsRcaError):
    """A stop signal (SIGINT, SIGTERM, SIGHUP) arrived: stop the graph and exit (caught by
    ``replay`` itself, which says which signal and exits 128 + its number; while the bridge
    lingers after the verdict, with the run's status: its outputs are written)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


@contextmanager
def stop_signals() -> Iterator[list[Graph]]:
    """The first stop signal raises :class:`Interrupted` (so the graph is stopped in
    order and the work folder removed); any later one SIGKILLs the nodes of the graph
    put in the yielded list, and cleaning up goes on."""
    received: list[int] = []
    graphs: list[Graph] = []

    def handle(signum: int, frame: FrameType | None) -> None:
        received.append(signum)
        if len(received) == 1:
            raise Interrupted(signum)
        for graph in graphs:
            graph.launcher.kill_all()

    previous = {sig: signal.signal(sig, handle) for sig in STOP_SIGNALS}
    try:
        yield graphs
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def _replay(
    args: argparse.Namespace,
    spec: GraphSpec,
    env: dict[str, str],
    record: Path | None,
    graphs: list[Graph],
) -> int:
    """Run the graph to its verdict and report it; with ``--zenoh``, every output written
    and every other node stopped, the bridge then serves the run to late dashboards."""
    from ads_rca.ros.graph import BRIDGE_NAME, Graph

    echo = sys.stdout if args.verbose else None
    graph = Graph(spec, env, echo=echo)
    graphs.append(graph)
    try:
        with graph:
            graph.start()
            document = graph.wait_verdict(args.timeout)
            if document is None:
                failed = graph.failed()
                codes = graph.stop()
                return no_verdict(args, failed, codes, node_outputs(graph))
            zenoh = spec.zenoh_params
            if zenoh is not None:
                wait_forwarded(graph)
            graph.stop(keep=(BRIDGE_NAME,) if zenoh is not None else ())
            status = report_verdict(args, document, record, node_outputs(graph))
            if zenoh is not None:
                serve_late_dashboards(graph, zenoh, float(args.zenoh_linger))
            return status
    except Interrupted:
        graph.launcher.stop_all()  # again: the signal may have cut the first stop short
        raise


def node_outputs(graph: Graph) -> dict[str, str]:
    """Every node's output so far, by name."""
    return {name: p.output for name, p in graph.processes.items()}


def no_verdict(
    args: argparse.Namespace,
    failed: Mapping[str, int],
    codes: Mapping[str, int],
    outputs: Mapping[str, str],
) -> int:
    """Why there is no verdict (the nodes that exited early, or the timeout) and each node's
    last lines, on stderr; 2 when the player found the input unusable, else 1."""
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


def report_verdict(
    args: argparse.Namespace,
    document: dict[str, Any],
    record: Path | None,
    outputs: Mapping[str, str],
) -> int:
    """The summary, ``--json``, the recording's verdict.json and any internal error, as
    ``diagnose`` gives them; the exit status they make (0, or :data:`EXIT_INTERNAL_ERROR`)."""
    print(live_summary(document))
    if args.json_out:
        write_json(document, Path(args.json_out))
        print(printable(f"verdict JSON: {args.json_out}"))
    if record is not None:
        write_json(document, record / "verdict.json", "--record")
        print(
            printable(
                f"MCAP recording: {record} (verdict JSON beside it: {record / 'verdict.json'})"
            )
        )
    return EXIT_INTERNAL_ERROR if report_internal_errors(document, outputs) else 0


#: A line a node's logger starts (rcutils' console format): the end of a logged traceback.
_LOG_LINE = re.compile(r"\[(DEBUG|INFO|WARN|ERROR|FATAL)\] ")


def report_internal_errors(document: dict[str, Any], outputs: Mapping[str, str]) -> bool:
    """As ``diagnose`` does, after every output is written: each module whose oracle raised
    in a monitor, the traceback that monitor logged and one line, on stderr. True when any
    did (``replay`` then exits :data:`EXIT_INTERNAL_ERROR`)."""
    errors = [e for e in document.get("internal_errors") or () if isinstance(e, dict)]
    for error in errors:
        sys.stdout.flush()
        trace = logged_traceback(outputs, str(error.get("module")))
        if trace:
            print(printable_lines(trace), file=sys.stderr)
        print(internal_error_line("replay", error), file=sys.stderr)
    return bool(errors)


def logged_traceback(outputs: Mapping[str, str], module: str) -> str:
    """The traceback a monitor logged for ``module`` (``ros/monitor.py``: one error line
    naming it, the traceback on the lines after), from the nodes' outputs; '' if none."""
    from ads_rca.live.diagnostics import internal_error_head

    head = f"]: {internal_error_head(module)};"
    for text in outputs.values():
        lines = text.splitlines()
        start = next((i for i, line in enumerate(lines) if head in line), None)
        if start is not None:
            block = itertools.takewhile(lambda x: not _LOG_LINE.match(x), lines[start + 1 :])
            return "\n".join(block)
    return ""


def wait_forwarded(graph: Graph) -> None:
    """Until the Zenoh bridge forwarded the verdict (it logs
    :data:`~ads_rca.ros.graph.BRIDGE_FORWARDED`), so stopping the rest of the graph takes
    nothing from it; at most its hold for the results the verdict counts and 5 s more,
    then the graph is stopped anyway, saying so."""
    from ads_rca.remote.state import VERDICT_HOLD_S
    from ads_rca.ros.graph import BRIDGE_FORWARDED, BRIDGE_NAME

    bridge = graph.processes.get(BRIDGE_NAME)
    wait = VERDICT_HOLD_S + 5.0
    deadline = time.monotonic() + wait
    while bridge is not None and bridge.returncode is None:
        if BRIDGE_FORWARDED in bridge.output:
            return
        if time.monotonic() >= deadline:
            print(
                f"ads-rca replay: the Zenoh bridge did not forward the verdict within "
                f"{wait:g} s; stopping the graph anyway",
                file=sys.stderr,
            )
            return
        time.sleep(0.05)


def serve_late_dashboards(graph: Graph, zenoh: Mapping[str, ParamValue], linger_s: float) -> None:
    """The run's outputs are written and the rest of the graph stopped: the bridge serves the
    run to late dashboards for ``linger_s`` (it exits by itself then; inf: until a stop
    signal), and is stopped. A stop signal now loses nothing, so it only ends this wait:
    ``replay`` exits with the run's status, not 128 + the signal."""
    from ads_rca.ros.graph import BRIDGE_NAME

    bridge = graph.processes.get(BRIDGE_NAME)
    if bridge is None or bridge.returncode is not None:
        return
    try:
        print(lingering_line(zenoh, linger_s), flush=True)
        if bridge.wait(None if math.isinf(linger_s) else linger_s + 10.0) is None:
            print("ads-rca replay: the Zenoh bridge did not finish; stopping it", file=sys.stderr)
        graph.launcher.stop_all()
    except Interrupted as stop:
        print(
            f"ads-rca replay: stopped by {stop} while serving late dashboards; "
            "every output was written",
            file=sys.stderr,
        )
        graph.launcher.stop_all()  # a second signal SIGKILLs it (stop_signals)


def lingering_line(zenoh: Mapping[str, ParamValue], linger_s: float) -> str:
    """Where and how long the bridge serves the run after its verdict, and that stopping it
    sooner loses nothing."""
    listen, connect = _texts(zenoh.get("zenoh_listen")), _texts(zenoh.get("zenoh_connect"))
    where = f"on {', '.join(listen)}" if listen else f"through {', '.join(connect)}"
    prefix = str(zenoh.get("zenoh_prefix") or "")
    under = f" under prefix {prefix}" if prefix else ""
    until = "until Ctrl-C" if math.isinf(linger_s) else f"for {linger_s:g} s (Ctrl-C ends it)"
    return printable(
        f"Zenoh bridge: serving this run to late dashboards {where}{under} {until}; "
        "every output is written, nothing is lost by stopping it"
    )


def _texts(value: ParamValue | None) -> tuple[str, ...]:
    return tuple(str(v) for v in value) if isinstance(value, tuple) else ()


def live_summary(document: dict[str, Any]) -> str:
    """``diagnose``'s summary of the same contract, plus the live graph's own figures."""
    live = document.get("live") or {}
    lines = [summary_text(document, how="judged live")]
    lines.append(f"verdict latency: {document.get('verdict_latency_s', 0.0):.3f} s")
    if not live.get("complete", True):
        lines.append(printable("INCOMPLETE: " + "; ".join(live.get("why_incomplete") or [])))
    return "\n".join(lines)
