"""Benchmark: where one core's time goes in ``ads-rca diagnose`` (issue #42, item 1).

    python bench/bench_cpu_stages.py [--size 2000x11] [--repeat 3] [--dir out/bench]

Issue #42 asks for ``diagnose`` at ten times the reference tool in CPU time with one worker,
and for a profile of where a single core's time goes. This prints that profile as a table
of wall and CPU time per stage, for each semantics, on a ``cruise`` log written as
bench_cpu_per_core.py writes it (its last frame declared the collision, the optional
folders removed).

Each run is a fresh process (this script with ``--child``) that does what ``ads-rca
diagnose LOG --workers 1 --json FILE`` does, one stage after the other:

* start-up: the interpreter and its site hooks (a venv with ROS wheels runs the
  interpreter twice: their bootstrap re-executes it), up to this script's first line;
* imports: the modules the command loads before reading;
* reading: listing, reading, decoding and parsing the files, validating the log;
* judging: every frame's four oracles, then the attribution;
* verdict document, writing (the verdict JSON, indented) and the printed summary.

A second kind of run splits reading and judging further: reading into file reads (system
calls), JSON decoding, record building and the rest (listing, checks, assembly); judging
into each module's oracle and the rest (the attribution, the loop). Each piece is timed
around every call, which costs about a microsecond a call (14,000 files, 8,000 oracle
calls a 2,000-frame log): its rows say "split" and their total is printed beside the
plain run's. Medians of ``--repeat`` runs of each kind.

Figures are only as quiet as the machine: CPU time is barely affected by other work on the
cores, wall time is. The load average is printed before and after.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from timing import timed

#: The stages of a plain run, in order.
STAGES = ("start-up", "imports", "reading", "judging", "verdict document", "writing", "summary")
#: The pieces of a split run (module names are added as the oracles are wrapped).
READING_PIECES = ("file reads", "JSON decoding", "record building")
AS_INSTALLED = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}


def cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


class Stages:
    """Wall and CPU seconds per named stage, summed over the calls timed under it."""

    def __init__(self) -> None:
        self.seconds: dict[str, list[float]] = {}

    def add(self, name: str, wall: float, cpu: float) -> None:
        found = self.seconds.setdefault(name, [0.0, 0.0])
        found[0] += wall
        found[1] += cpu

    def timing(self, name: str, work: Callable[[], Any]) -> Any:
        result, took = timed(work)
        self.add(name, took.wall_s, took.cpu_s)
        return result

    def wrapped(self, name: str, function: Callable[..., Any]) -> Callable[..., Any]:
        """``function`` timed under ``name`` at every call."""

        def timed(*args: Any, **kwargs: Any) -> Any:
            wall, cpu = time.perf_counter(), time.process_time()
            try:
                return function(*args, **kwargs)
            finally:
                self.add(name, time.perf_counter() - wall, time.process_time() - cpu)

        return timed


def child(log: str, semantics: str, launched: float, split: bool, out: str) -> None:
    """One ``diagnose`` in this fresh process, its stages' timings printed as JSON."""
    stages = Stages()
    stages.add("start-up", time.perf_counter() - launched, cpu_s())

    def imports() -> None:  # what the command loads before it reads
        for module in ("ads_rca.cli", "ads_rca.commands.diagnose_cmd"):
            importlib.import_module(module)

    stages.timing("imports", imports)
    from ads_rca.commands.diagnose_cmd import write_json
    from ads_rca.diagnosis import engine
    from ads_rca.diagnosis.summary import summary_text
    from ads_rca.foundation.workers import loaded_objects_frozen
    from ads_rca.params import make_params
    from ads_rca.sources.log import reader
    from ads_rca.sources.registry import open_run

    if split:  # the reader's and the engine's names, each call timed
        for name, piece in (("read_regular", "file reads"), ("decode_json", "JSON decoding")):
            setattr(reader, name, stages.wrapped(piece, getattr(reader, name)))
        for folder, parse in list(reader.PARSERS.items()):
            reader.PARSERS[folder] = stages.wrapped("record building", parse)
        chosen = getattr(engine, "semantics_for")  # noqa: B009 - replaced just below

        class Timed:
            """The mode's semantics, its oracles timed per module."""

            def __init__(self, semantics: Any) -> None:
                self.semantics = semantics

            def __getattr__(self, name: str) -> Any:
                return getattr(self.semantics, name)

            def judging_oracles(self, log: Any) -> dict[str, Any]:
                oracles = self.semantics.judging_oracles(log)
                return {m: stages.wrapped(f"oracle: {m}", f) for m, f in oracles.items()}

        setattr(engine, "semantics_for", lambda params: Timed(chosen(params)))  # noqa: B010

    run = stages.timing("reading", lambda: open_run(log, workers=1))
    with loaded_objects_frozen():
        params = make_params(semantics)
        result = stages.timing(
            "judging", lambda: engine.diagnose(run, params, None, workers=1, render_frames=True)
        )
        document = stages.timing("verdict document", result.to_json)
        stages.timing("writing", lambda: write_json(document, Path(out)))
        with open(os.devnull, "w") as sink:
            stages.timing("summary", lambda: print(summary_text(document), file=sink))
    json.dump(stages.seconds, sys.stdout)


def run_child(log: Path, semantics: str, split: bool, out: Path) -> dict[str, list[float]]:
    argv = [sys.executable, __file__, "--child", str(log), semantics, str(time.perf_counter())]
    argv += ["--out", str(out)] + (["--split"] if split else [])
    done = subprocess.run(argv, env=AS_INSTALLED, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise SystemExit(f"child failed ({done.returncode}): {done.stderr.strip()[-300:]}")
    found: dict[str, list[float]] = json.loads(done.stdout)
    return found


def median_of(runs: list[dict[str, list[float]]]) -> dict[str, tuple[float, float]]:
    names = list(dict.fromkeys(name for run in runs for name in run))
    return {
        name: (
            statistics.median(run.get(name, [0.0, 0.0])[0] for run in runs),
            statistics.median(run.get(name, [0.0, 0.0])[1] for run in runs),
        )
        for name in names
    }


def table(semantics: str, plain: dict[str, tuple[float, float]], split: dict[str, Any]) -> None:
    total_wall = sum(plain[s][0] for s in STAGES if s in plain)
    total_cpu = sum(plain[s][1] for s in STAGES if s in plain)
    print(f"\n{semantics}: stage                     wall s    CPU s   CPU share")
    for stage in STAGES:
        wall, cpu = plain.get(stage, (0.0, 0.0))
        print(f"  {stage:<32}{wall:>8.3f}{cpu:>9.3f}{cpu / total_cpu:>10.1%}")
        pieces: tuple[str, ...]
        if stage == "reading":
            pieces = READING_PIECES
        elif stage == "judging":
            pieces = tuple(name for name in split if name.startswith("oracle: "))
        else:
            continue
        covered = sum(split[p][1] for p in pieces if p in split)
        for piece in pieces:
            wall_p, cpu_p = split.get(piece, (0.0, 0.0))
            print(f"    split: {piece:<23}{wall_p:>8.3f}{cpu_p:>9.3f}")
        rest = split[stage][1] - covered
        print(f"    split: {'the rest':<23}{'':>8}{rest:>9.3f}")
        print(f"    split: {stage + ', in all':<23}{split[stage][0]:>8.3f}{split[stage][1]:>9.3f}")
    print(f"  {'whole process':<32}{total_wall:>8.3f}{total_cpu:>9.3f}")


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawTextHelpFormatter
    )
    parser.add_argument("--size", default="2000x11", help="FRAMESxACTORS of the cruise log")
    parser.add_argument("--repeat", type=int, default=3, help="runs of each kind (median)")
    parser.add_argument("--dir", default="out/bench", help="where the log is written")
    parser.add_argument("--child", nargs=3, metavar=("LOG", "SEMANTICS", "LAUNCHED"))
    parser.add_argument("--split", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--out", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        log, semantics, launched = args.child
        child(log, semantics, float(launched), args.split, args.out)
        return
    from bench_cpu_per_core import parse_size
    from bench_memory import write_seed_format_log
    from timing import load_average

    frames, actors = parse_size(args.size)
    Path(args.dir).mkdir(parents=True, exist_ok=True)
    before = load_average()
    with tempfile.TemporaryDirectory(dir=Path(args.dir).resolve()) as tmp:
        log = Path(tmp) / f"cruise_{frames}x{actors}"
        write_seed_format_log(log, frames, actors)
        out = Path(tmp) / "verdict.json"
        print(
            f"one `ads-rca diagnose --workers 1 --json` in a fresh process per run, cruise "
            f"{frames}x{actors}; medians of {args.repeat} runs; {os.cpu_count()} CPUs; "
            "CPU = user + system s"
        )
        for semantics in ("reference", "corrected"):
            run_child(log, semantics, False, out)  # warms the file and bytecode caches
            plain = [run_child(log, semantics, False, out) for _ in range(args.repeat)]
            split = [run_child(log, semantics, True, out) for _ in range(args.repeat)]
            table(semantics, median_of(plain), median_of(split))
    print(f"\nload average: {before} before, {load_average()} after")


if __name__ == "__main__":
    main()
