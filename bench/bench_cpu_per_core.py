"""Benchmark: CPU time per core of whole ``ads-rca diagnose`` processes, against issue #42's goal.

    python bench/bench_cpu_per_core.py [--sizes 132x11 2000x11 10000x50] [--repeat 5]
                                       [--dir out/bench]

Issue #42 ("speed per core") asks for ``diagnose`` at ten times the reference tool in CPU
time (user + system, one worker) on a 2,000-frame, 11-actor log, in both semantics. The
reference tool is not on this machine, so its figure is the issue's, a constant here:
:data:`REFERENCE_CPU_S`, 9.4 s of CPU on a 1,957-frame, 11-actor log (issue #42, item 1);
the goal is therefore :data:`GOAL_CPU_S` = 0.94 s.

For each size FRAMESxACTORS a ``cruise`` log is written under ``--dir`` (as
bench_vs_reference.py writes it: its last frame declared the collision, the optional
folders removed), and the bundled example ``examples/cut_in_perception`` is added as the
smallest run (start-up dominates it). Each command is ``ads-rca diagnose LOG --semantics S
--json FILE`` with ``--workers 1`` and with the default workers (one per core), run
``--repeat`` times after one warm-up run, round-robin; the table gives each one's median wall
and median CPU time (from ``wait4``: the process and the workers it forked) and, for the
one-worker rows of an 11-actor log of at least 1,000 frames, the reference's CPU time
divided by ours (scaled to the log's frames, which the reference's cost grows with; its cost
at other actor counts is not known here).

Figures are only as quiet as the machine: CPU time is barely affected by other work on the
cores, wall time is. The load average is printed before and after.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from bench_memory import write_seed_format_log
from timing import Timing, load_average, run_child

#: The reference tool's CPU time (user + system, s) on a 1,957-frame, 11-actor log, as
#: issue #42 ("speed per core", item 1) measured it: "the corrected diagnosis costs 2.95 s
#: against the reference tool's 9.4 s".
REFERENCE_CPU_S = 9.4
REFERENCE_FRAMES = 1957
REFERENCE_ACTORS = 11
#: Issue #42's goal: ten times the reference tool in CPU time.
GOAL_CPU_S = REFERENCE_CPU_S / 10
DEFAULT_SIZES = ("132x11", "2000x11")
EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "cut_in_perception"
AS_INSTALLED = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}


@dataclass
class Run:
    """One command line and its timings."""

    label: str
    frames: int
    actors: int
    semantics: str
    workers: str
    argv: list[str]
    times: list[Timing] = field(default_factory=list)
    failed: str = ""

    def once(self, counted: bool) -> None:
        if self.failed:
            return
        done = run_child(self.argv, env=AS_INSTALLED)
        if done.returncode != 0:
            self.failed = f"exit {done.returncode}: {done.stderr.strip()[-100:]}"
        elif counted:
            self.times.append(done.timing)

    def row(self) -> str:
        head = f"{self.label:<30}{self.semantics:<11}{self.workers:>8}"
        if self.failed or not self.times:
            return f"{head}  failed: {self.failed}"
        wall = statistics.median(t.wall_s for t in self.times)
        cpu = statistics.median(t.cpu_s for t in self.times)
        ratio = goal = ""
        if self.workers == "1" and self.frames >= 1000 and self.actors == REFERENCE_ACTORS:
            reference = REFERENCE_CPU_S * self.frames / REFERENCE_FRAMES
            ratio = f"{reference / cpu:.1f}x"
            goal = "met" if reference / cpu >= 10 else "not met"
        return f"{head}{wall:>9.2f}{cpu:>9.2f}{ratio:>10}{goal:>9}"


def parse_size(text: str) -> tuple[int, int]:
    frames, _, actors = text.partition("x")
    if not (frames.isdigit() and actors.isdigit() and int(actors) >= 1):
        raise argparse.ArgumentTypeError(f"{text!r} is not FRAMESxACTORS (e.g. 2000x11)")
    return int(frames), int(actors)


def runs_on(log: Path, label: str, frames: int, actors: int, scratch: Path) -> list[Run]:
    found = []
    for semantics in ("reference", "corrected"):
        for workers in ("1", str(os.cpu_count() or 1)):
            argv = [sys.executable, "-m", "ads_rca.cli", "diagnose", str(log)]
            argv += ["--semantics", semantics, "--workers", workers]
            argv += ["--json", str(scratch / f"{label}-{semantics}-{workers}.json")]
            shown = workers if workers == "1" else f"{workers} (dflt)"
            found.append(Run(label, frames, actors, semantics, shown, argv))
    return found


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawTextHelpFormatter
    )
    parser.add_argument("--sizes", nargs="+", type=parse_size, default=None)
    parser.add_argument("--repeat", type=int, default=5, help="counted runs (median)")
    parser.add_argument("--dir", default="out/bench", help="where the logs are written")
    args = parser.parse_args()
    sizes = args.sizes or [parse_size(s) for s in DEFAULT_SIZES]
    Path(args.dir).mkdir(parents=True, exist_ok=True)
    before = load_average()
    with tempfile.TemporaryDirectory(dir=Path(args.dir).resolve()) as tmp:
        scratch = Path(tmp)
        frames_of_example = sum(1 for _ in (EXAMPLE / "pose").glob("*.json"))
        runs = runs_on(EXAMPLE, f"example ({frames_of_example} frames)", 0, 0, scratch)
        for frames, actors in sizes:
            log = scratch / f"cruise_{frames}x{actors}"
            write_seed_format_log(log, frames, actors)
            runs += runs_on(log, f"cruise {frames}x{actors}", frames, actors, scratch)
        for round_ in range(args.repeat + 1):  # round 0 warms the file and bytecode caches
            for run in runs:
                run.once(counted=round_ > 0)
    print(
        f"whole `ads-rca diagnose --json` processes: medians of {args.repeat} runs after a "
        f"warm-up; {os.cpu_count()} CPUs; CPU = user + system s (workers included)"
    )
    print(
        f"reference tool (not on this machine): {REFERENCE_CPU_S} s CPU on a "
        f"{REFERENCE_FRAMES}-frame, 11-actor log (issue #42), scaled by frames (11 actors only); "
        f"goal: 10x, i.e. {GOAL_CPU_S:.2f} s CPU at 1,957 frames, one worker"
    )
    print(
        f"{'log':<30}{'semantics':<11}{'workers':>8}{'wall s':>9}{'CPU s':>9}"
        f"{'vs ref':>10}{'10x':>9}"
    )
    for run in runs:
        print(run.row(), flush=True)
    print(f"load average: {before} before, {load_average()} after")


if __name__ == "__main__":
    main()
