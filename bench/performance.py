"""Run the benches and (re)write docs/performance.md from what they print.

    python bench/performance.py [--quick] [--only NAME ...] [--out docs/performance.md]
                                [--reference DIR --reference-python PY] [--timeout S]

Each bench of :data:`BENCHES` runs as its own process, one after another, at the sizes of
the default set (sized for a 2-core machine: about 35 minutes there, bench_stack.py's
20,000-frame run the longest part) or, with ``--quick``, at small sizes (a smoke run of
about 2 minutes). The page gets the machine's facts (CPU, cores, memory, Python, the
commit, the date, the load average at the start and the end), a summary row per bench
(its whole process's wall and CPU time from ``wait4``, its peak memory, the load average
before and after it, its exit status) and each bench's output as it printed it. A bench
that cannot run here is listed as "not run" with the reason; one that fails is shown
failing, with its output. Nothing on the page is written by hand: edit this script or the
benches, then regenerate (``make bench``).

Scratch logs go to a temporary folder (removed at the end); ``--only`` runs some benches
(the page then lists only those: use it with ``--out`` elsewhere for a look at one).
"""

from __future__ import annotations

import argparse
import datetime
import importlib.util
import os
import platform
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from timing import ChildRun, Clock, load_average, run_child

BENCH = Path(__file__).resolve().parent
REPO = BENCH.parent
PAGE = REPO / "docs" / "performance.md"
#: Stands for the scratch folder in the commands the page shows.
SCRATCH = "SCRATCH"


@dataclass(frozen=True)
class Bench:
    """One bench script, what it measures, and its arguments in each set."""

    script: str
    measures: str
    full: tuple[str, ...]
    quick: tuple[str, ...]
    #: Python modules it cannot run without (beyond the package's own requirements).
    requires: tuple[str, ...] = ()

    @property
    def name(self) -> str:
        return self.script.removesuffix(".py")


BENCHES: tuple[Bench, ...] = (
    Bench(
        "bench_load.py",
        "synthesising, writing and loading a long log (frames/s, MB/s of JSON)",
        ("--dir", SCRATCH),
        ("--frames", "500", "--actors", "20", "--repeat", "2", "--dir", SCRATCH),
    ),
    Bench(
        "bench_diagnose.py",
        "loading and judging a log in one process, against frames and actors (peak memory)",
        ("--actors", "50", "--dir", SCRATCH),
        ("--frames", "500", "--actors", "20", "--dir", SCRATCH),
    ),
    Bench(
        "bench_vs_reference.py",
        "whole `ads-rca diagnose` processes (both modes), beside the reference tool's",
        ("--repeat", "3", "--dir", SCRATCH),
        ("--sizes", "500x11", "--repeat", "2", "--dir", SCRATCH),
    ),
    Bench(
        "bench_cpu_per_core.py",
        "CPU per core of whole `ads-rca diagnose` runs, one worker and default, vs issue #42",
        ("--sizes", "132x11", "2000x11", "10000x50", "--repeat", "3", "--dir", SCRATCH),
        ("--sizes", "132x11", "500x11", "--repeat", "2", "--dir", SCRATCH),
    ),
    Bench(
        "bench_cpu_stages.py",
        "where one core's time goes in a one-worker `diagnose`, stage by stage (both modes)",
        ("--size", "2000x11", "--repeat", "3", "--dir", SCRATCH),
        ("--size", "300x11", "--repeat", "1", "--dir", SCRATCH),
    ),
    Bench(
        "bench_player.py",
        "the player's conversion speed and its DDS throughput at rate 0 to one subscriber",
        ("--frames", "2000", "--object-dds-frames", "500"),
        ("--frames", "300", "--conversion-frames", "200"),
        ("rclpy",),
    ),
    Bench(
        "bench_graph.py",
        "frames/s through the live node graph, monitor and verdict latency, CPU per node",
        (),
        ("--frames", "60", "--actors", "20", "--semantics", "corrected"),
        ("rclpy",),
    ),
    Bench(
        "bench_zenoh.py",
        "the Zenoh bridge on loopback (throughput, latency, CPU) and the dashboard's latency",
        (),
        ("--messages", "500", "--dashboard-frames", "40"),
        ("rclpy", "zenoh", "aiohttp"),
    ),
    Bench(
        "bench_recorder.py",
        "the recorder's MB/s over DDS with no message lost, and the MCAP writer alone",
        (),
        ("--frames", "300"),
        ("rclpy",),
    ),
    Bench(
        "bench_memory.py",
        "peak memory and time of `ads-rca diagnose` against boxes per frame and frames",
        ("--frames", "1000", "10000", "50000", "--dir", SCRATCH),
        ("--boxes", "1000", "--frames", "1000", "--dir", SCRATCH),
    ),
    Bench(
        "bench_aggregator_memory.py",
        "the live aggregator's retained memory against run length",
        (),
        ("--frames", "1000", "--semantics", "corrected"),
    ),
    Bench(
        "bench_safe_read.py",
        "what the hostile-input checks cost per file, next to parsing it",
        (),
        ("--frames", "200", "--repeat", "3"),
    ),
    Bench(
        "bench_verdict_json.py",
        "writing the verdict JSON: the json module against `indented_json`",
        (),
        ("--frames", "1000", "--repeat", "2"),
    ),
    Bench(
        "bench_report.py",
        "the HTML report's rendering time and size (the bundled example)",
        (),
        ("--repeat", "2"),
    ),
    Bench(
        "bench_atmacup.py",
        "reading and scoring an atmaCup #18 table of the competition's 43,371 rows",
        ("--dir", SCRATCH),
        ("--rows", "4000", "--rounds", "1", "--dir", SCRATCH),
    ),
    Bench(
        "bench_dlp.py",
        "peak memory and time of reading a Dragon Lake Parking scene, streamed vs whole",
        ("--dir", SCRATCH),
        ("--frames", "2000", "--dir", SCRATCH),
    ),
    Bench(
        "bench_batch.py",
        "`ads-rca batch` throughput (runs/min) with 1 and 2 local Dask workers",
        ("--runs", "300", "--distinct", "40", "--dir", SCRATCH),
        ("--runs", "20", "--distinct", "10", "--frames", "100", "--dir", SCRATCH),
    ),
    Bench(
        "bench_stack.py",
        "stack mode's monitor and aggregator cores at log rate, in one process",
        (),
        ("--actors", "20", "--long", "500"),
    ),
    Bench(
        "bench_stack_grid.py",
        "stack mode over real DDS on the crash grid: verdicts and frames against diagnose",
        ("--modes", "corrected"),
        ("--modes", "corrected", "--scenarios", "cut_in", "--faults", "perception"),
        ("rclpy",),
    ),
    Bench(
        "bench_stack_latency.py",
        "stack mode beside an independent stack over DDS: verdict latency, judging lag",
        ("--crashes", "8"),
        ("--crashes", "2", "--actors", "20"),
        ("rclpy",),
    ),
    Bench(
        "bench_real_drive_bags.py",
        "attribution on real-drive-shaped bags through inspect and diagnose --event-time",
        ("5",),
        ("1", "--scenarios", "cut_in", "--faults", "prediction,planning"),
    ),
    Bench(
        "accuracy.py",
        "attribution accuracy of the corrected semantics on synthesised faults",
        ("20",),
        ("1", "--scenarios", "cut_in,lead_braking"),
    ),
)


@dataclass(frozen=True)
class Outcome:
    """What running one bench gave: its process, the commands shown, notes for the page."""

    bench: Bench
    shown: str
    run: ChildRun | None
    load_before: str
    load_after: str
    notes: tuple[str, ...] = ()
    skipped: str = ""

    @property
    def status(self) -> str:
        if self.run is None:
            return f"not run: {self.skipped}"
        if self.run.timed_out:
            return f"stopped: over the time limit (exit {self.run.returncode})"
        return "ok" if self.run.returncode == 0 else f"failed: exit {self.run.returncode}"


def arguments(bench: Bench, args: argparse.Namespace, scratch: Path) -> list[str]:
    """The bench's arguments in this run's set, the scratch folder filled in."""
    chosen = bench.quick if args.quick else bench.full
    out = [str(scratch / bench.name) if a == SCRATCH else a for a in chosen]
    if bench.script == "bench_vs_reference.py" and args.reference:
        out += ["--reference", args.reference]
        if args.reference_python:
            out += ["--reference-python", args.reference_python]
    return out


def reference_note(args: argparse.Namespace) -> str:
    """Why the reference tool's side of bench_vs_reference.py is or is not in the table."""
    if not args.reference:
        return (
            "Reference tool: not run: it is not part of this project and no checkout of it "
            "was given (`bench/performance.py --reference DIR --reference-python PY`, which "
            "bench_vs_reference.py runs as `PY DIR/main.py log_dir=LOG`); only our commands "
            "are timed."
        )
    if not (Path(args.reference) / "main.py").is_file():
        return f"Reference tool: not found: `{args.reference}/main.py` does not exist."
    return f"Reference tool: `{args.reference}/main.py` run by `{args.reference_python or 'PY'}`."


def missing(bench: Bench) -> str:
    """Why ``bench`` cannot run here ("" when it can)."""
    absent = [name for name in bench.requires if importlib.util.find_spec(name) is None]
    return f"needs the Python module {', '.join(absent)}, not installed here" if absent else ""


def run_bench(bench: Bench, args: argparse.Namespace, scratch: Path) -> Outcome:
    argv = arguments(bench, args, scratch)
    shown = " ".join(["python", f"bench/{bench.script}", *argv]).replace(str(scratch), SCRATCH)
    notes = (reference_note(args),) if bench.script == "bench_vs_reference.py" else ()
    before = load_average()
    if reason := missing(bench):
        return Outcome(bench, shown, None, before, before, notes, reason)
    run = run_child(
        [sys.executable, str(BENCH / bench.script), *argv], cwd=REPO, timeout_s=args.timeout
    )
    return Outcome(bench, shown, run, before, load_average(), notes)


def git(*argv: str) -> str:
    done = subprocess.run(["git", *argv], cwd=REPO, capture_output=True, text=True, check=False)
    return done.stdout.strip() if done.returncode == 0 else "?"


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "?"


def memory_gib() -> str:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal:"):
                return f"{int(line.split()[1]) / 2**20:.1f} GiB"
    except OSError:
        pass
    return "?"


def commit() -> str:
    """The commit, and whether the working tree (others may work in it) differed from it."""
    head = git("log", "-1", "--format=%h %s")
    changed = [
        line for line in git("status", "--porcelain", "--untracked-files=no").splitlines() if line
    ]
    if changed:
        head += f" (with uncommitted changes in {len(changed)} tracked files at the start)"
    return head


def machine_rows(
    started: datetime.datetime, minutes: float, loads: tuple[str, str]
) -> list[tuple[str, str]]:
    usable = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else "?"
    return [
        ("CPU", f"{cpu_model()}; {os.cpu_count()} cores, {usable} usable by the benches"),
        ("memory", memory_gib()),
        ("Python", f"{platform.python_implementation()} {platform.python_version()}"),
        ("system", platform.platform()),
        ("commit", commit()),
        ("date", f"{started:%Y-%m-%d %H:%M} UTC; the run took {minutes:.0f} min"),
        ("load average (1, 5, 15 min)", f"{loads[0]} at the start, {loads[1]} at the end"),
    ]


#: Where a core's time goes: design, kept with the page (not printed by a bench).
DESIGN: tuple[str, ...] = (
    "",
    "## Where a core's time goes",
    "",
    "A one-worker `diagnose` of a 2,000-frame, 11-actor log (14,000 files, 50 MB of JSON)",
    "spends its CPU in four places. *Reading* is about half: per file four system calls",
    "(open without following a link, `fstat`, one read of the stated size, close), the JSON",
    "decode (orjson; two thirds of the bytes are the predictions' tracks) and one array",
    "conversion that turns the document into its record (a flat list of numbers packed by",
    "`struct` or read by `np.array`); only a file the conversion refuses is walked value by value",
    "to report what is wrong, and the cyclic collector is paused meanwhile (decoded JSON holds",
    "no cycles). *Judging* is a quarter to a third (the corrected rules cost about 1.5 times the",
    "reference ones): four oracles a frame on arrays of a few dozen numbers, so the cost is per",
    "call, not per number, and what several rules or frames share (the partner's view, c_gt",
    "measured in batches ahead, both modes' box IoUs scored 64 frames at a time, the noise",
    "floors' sliding windows) is computed once and cached by timestamp; per-run tables group",
    "the frames that list the same actors. *Start-up* is 0.1 s, the whole of a small run's",
    "cost: the interpreter (run twice in a venv with ROS wheels: their bootstrap re-executes",
    "it to set the library path), numpy",
    "(half of it) and the command's own modules only, with one BLAS thread (`import ads_rca`",
    "sets `OPENBLAS_NUM_THREADS=1` unless the environment gives a number: OpenBLAS's pool of",
    "threads, started when numpy loads, never speeds up arrays of a few dozen numbers, and its",
    "spinning cost a small run 40 % of its CPU and a 2,000-frame one 9 to 15 %, none of the",
    "wall time); the HTML report, the live graph",
    "(rclpy), pandas, pyarrow and scipy are imported by the commands and options that use",
    "them, never by `diagnose`. *The verdict document* is 5 to 10 per cent: one walk makes it",
    "strict JSON and `indented_json` writes it. More workers fork the reading and judging of a",
    "long log: they save wall time and add CPU (forks, records packed back), so the figure per",
    "core is the one-worker one ([bench_cpu_per_core.py](#bench_cpu_per_core)).",
    "[bench_cpu_stages.py](#bench_cpu_stages) prints this split for both modes: each stage's",
    "wall and CPU time, reading split into file reads, JSON decoding and record building,",
    "judging into the four oracles.",
)


def intro(args: argparse.Namespace) -> list[str]:
    lines = [
        "# Performance",
        "",
        "<!-- Generated by bench/performance.py: do not edit; regenerate with `make bench`. -->",
        "",
        "This page is generated: every figure on it is printed by a script in `bench/`, copied",
        "as it printed it. Regenerate it with one command, `make bench` (which runs",
        "`.venv/bin/python bench/performance.py`: the default set, sized for 2 cores); add",
        "`--quick` for a smoke run of a few minutes at small sizes. Each bench can also be run",
        "alone, with the command shown in its section (`SCRATCH`: a scratch folder).",
        "",
        "Every table gives wall time (elapsed) and CPU time (user + system seconds of the",
        "process and of the child processes it waited for: forked workers, node processes).",
        "CPU above wall means more than one core worked; CPU well below wall means waiting (for",
        "a child, a pipe, the disk, or cores taken by other work). The machine is shared (other",
        "test runs may use the same two cores), so the load average is recorded at the start,",
        "at the end and around each bench: read figures taken under load as upper bounds.",
        *DESIGN,
    ]
    if args.quick:
        lines += [
            "",
            "**This page comes from a `--quick` run: small sizes, to check that the benches run,",
            "not figures to quote. `make bench` regenerates it at the default sizes.**",
        ]
    if args.only:
        lines += ["", f"**Only some benches were run (`--only {' '.join(args.only)}`).**"]
    return lines


def table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(cell.replace("|", "\\|") for cell in row) + " |" for row in rows]
    return out


def summary(outcomes: Sequence[Outcome]) -> list[str]:
    rows = []
    for o in outcomes:
        run = o.run
        figures = (
            (f"{run.wall_s:.1f}", f"{run.cpu_s:.1f}", f"{run.max_rss_mb:.0f}")
            if run
            else ("", "", "")
        )
        rows.append(
            (
                f"[{o.bench.script}](#{o.bench.name})",
                o.bench.measures,
                *figures,
                f"{o.load_before} → {o.load_after}",
                o.status,
            )
        )
    header = (
        "bench",
        "what it measures",
        "wall s",
        "CPU s",
        "peak MB",
        "load before → after",
        "result",
    )
    return [
        "## Summary",
        "",
        "Each bench's whole process (`wait4`): wall and CPU seconds, peak resident set.",
        "",
        *table(header, rows),
    ]


def section(o: Outcome) -> list[str]:
    lines = [
        f'<a id="{o.bench.name}"></a>',
        f"## {o.bench.script}",
        "",
        f"{o.bench.measures[0].upper()}{o.bench.measures[1:]}.",
        "",
    ]
    lines += [f"`{o.shown}`", ""]
    lines += [*(f"{note}\n" for note in o.notes)]
    if o.run is None:
        return [*lines, f"Not run: {o.skipped}", ""]
    run = o.run
    whole = f"{run.wall_s:.1f} s wall, {run.cpu_s:.1f} s CPU, peak {run.max_rss_mb:.0f} MB"
    load = f"load average {o.load_before} before, {o.load_after} after"
    lines += [
        f"Whole process: {whole}; {load}; {o.status}.",
        "",
        "```text",
        *run.stdout.rstrip("\n").splitlines(),
        "```",
        "",
    ]
    if run.returncode != 0 and run.stderr.strip():
        tail = run.stderr.rstrip("\n").splitlines()[-30:]
        lines += ["Its error output (last lines):", "", "```text", *tail, "```", ""]
    return lines


def page(
    args: argparse.Namespace, outcomes: Sequence[Outcome], machine: list[tuple[str, str]]
) -> str:
    lines = intro(args)
    lines += ["", "## Machine", "", *table(("", ""), machine), ""]
    lines += [*summary(outcomes), ""]
    for o in outcomes:
        lines += section(o)
    return "\n".join(lines).rstrip("\n") + "\n"


def chosen(args: argparse.Namespace) -> list[Bench]:
    if not args.only:
        return list(BENCHES)
    names = {b.name: b for b in BENCHES}
    unknown = [n for n in args.only if n.removesuffix(".py") not in names]
    if unknown:
        raise SystemExit(f"--only: unknown bench {unknown}; choose from {sorted(names)}")
    return [names[n.removesuffix(".py")] for n in args.only]


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--quick", action="store_true", help="small sizes: a smoke run of a few minutes"
    )
    parser.add_argument("--only", nargs="+", metavar="NAME", help="run only these benches")
    parser.add_argument("--out", type=Path, default=PAGE, help="the page to write")
    parser.add_argument("--reference", help="a checkout of the reference tool (its main.py)")
    parser.add_argument(
        "--reference-python", help="the interpreter with the reference tool's dependencies"
    )
    parser.add_argument(
        "--timeout", type=float, default=1800.0, help="seconds a bench may run before it is stopped"
    )
    args = parser.parse_args(argv)
    benches = chosen(args)
    started = datetime.datetime.now(datetime.timezone.utc)
    load_start = load_average()
    outcomes: list[Outcome] = []
    with Clock() as whole, tempfile.TemporaryDirectory(prefix="ads_rca_performance_") as tmp:
        for n, bench in enumerate(benches, 1):
            print(f"[{n}/{len(benches)}] {bench.script} ...", end="", file=sys.stderr, flush=True)
            outcome = run_bench(bench, args, Path(tmp))
            outcomes.append(outcome)
            run = outcome.run
            took = f" {run.wall_s:.0f} s wall, {run.cpu_s:.0f} s CPU;" if run else ""
            print(f"{took} {outcome.status}", file=sys.stderr, flush=True)
            shutil.rmtree(Path(tmp) / bench.name, ignore_errors=True)
    machine = machine_rows(started, whole.wall_s / 60, (load_start, load_average()))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(page(args, outcomes, machine))
    print(f"wrote {args.out}", file=sys.stderr)
    return 0 if all(o.status == "ok" for o in outcomes) else 1


if __name__ == "__main__":
    sys.exit(main())
