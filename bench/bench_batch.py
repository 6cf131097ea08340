"""Benchmark: ``ads-rca batch`` throughput (runs per minute) with 1 and 2 local workers.

    python bench/bench_batch.py [--runs 1000] [--frames 200] [--workers 1 2] [--distinct K]
                                [--repeat N] [--dir DIR]

    # small logs, where the batch's own per-run cost shows (issue 42):
    python bench/bench_batch.py --runs 60 --frames 150 --distinct 20 --repeat 3

Synthesises ``--runs`` crash logs of ``--frames`` frames (scenarios and faults cycled,
written once under ``--dir`` and reused by later runs of the bench), then times the whole
command (cluster start, every run diagnosed, results and summary written) once per worker
count, each into a fresh output folder. Prints the command's wall time and CPU time (user
+ system from ``wait4``: the command, its cluster and its workers), runs/min per worker
count (by wall time), the CPU per run (the whole command's CPU over the runs: diagnosis,
workers, client and start-up) and the scaling figure (runs/min with N workers over runs/min
with the first count). With ``--repeat N`` each worker count is timed N times and the
median wall and the median CPU are printed. The summary's per-run diagnose time (median) is
printed too: with one core per worker the rest is the cluster's and the command's own
overhead. The load average before and after is printed: on a shared machine, read the CPU
columns first.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import sys
import tempfile
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from timing import Clock, Timing, median, run_child

REPO = Path(__file__).resolve().parents[1]
SCENARIOS = ("cut_in", "lead_braking", "pedestrian_crossing", "left_turn")
FAULTS = ("none", "perception", "prediction", "planning", "controller")


def _make(args: tuple[int, int, str]) -> str:
    i, frames, root = args
    from ads_rca.sources.log.writer import write_run_log
    from ads_rca.synth import synthesise

    scenario = SCENARIOS[i % len(SCENARIOS)]
    fault = FAULTS[(i // len(SCENARIOS)) % len(FAULTS)]
    seed = i // (len(SCENARIOS) * len(FAULTS))
    folder = Path(root) / f"run_{i:05d}_{scenario}_{fault}"
    if not (folder / "metadata.json").exists():
        tmp = folder.with_name(folder.name + ".tmp")
        shutil.rmtree(tmp, ignore_errors=True)
        write_run_log(synthesise(scenario, fault, seed, frames=frames), tmp)
        os.replace(tmp, folder)
    return str(folder)


def make_runs(n: int, frames: int, root: Path, distinct: int) -> list[str]:
    """``n`` run folders: ``distinct`` synthesised logs, the rest copies of them (synthesis
    costs more than diagnosis; the batch reads and judges every copy all the same)."""
    root.mkdir(parents=True, exist_ok=True)
    unique = min(n, distinct)
    with ProcessPoolExecutor(max_workers=os.cpu_count() or 1) as pool:
        made = list(pool.map(_make, [(i, frames, str(root)) for i in range(unique)]))
    for i in range(unique, n):
        source = Path(made[i % unique])
        folder = root / f"{source.name}_copy{i:05d}"
        if not folder.exists():
            shutil.copytree(source, folder)
        made.append(str(folder))
    return made


def time_batch(listing: Path, workers: int, out: Path) -> tuple[Timing, list[float], int]:
    env = dict(
        os.environ,
        PYTHONPATH=os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])),
    )
    argv = [sys.executable, "-m", "ads_rca.cli", "batch", str(listing), "--out", str(out)]
    done = run_child([*argv, "--workers", str(workers)], env=env)
    if done.returncode != 0:
        sys.exit(f"batch failed ({done.returncode}): {done.stderr}")
    sys.path.insert(0, str(REPO))
    from ads_rca.batch.store import read_csv

    rows = read_csv(out / "results.csv")
    errors = sum(1 for r in rows if r["error"])
    return done.timing, [float(r["diagnose_seconds"]) for r in rows], errors


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--runs", type=int, default=1000)
    parser.add_argument("--frames", type=int, default=200)
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    parser.add_argument(
        "--distinct", type=int, default=0, help="synthesise this many logs, copy for the rest"
    )
    parser.add_argument("--repeat", type=int, default=1, help="times each count, the median")
    parser.add_argument(
        "--dir", type=Path, default=Path(tempfile.gettempdir()) / "ads_rca_bench_batch"
    )
    args = parser.parse_args()
    # absolute: a paths file's relative lines are read from the file's own folder
    args.dir = args.dir.resolve()
    runs_dir = args.dir / f"runs_{args.frames}f"
    with Clock() as made:
        paths = make_runs(args.runs, args.frames, runs_dir, args.distinct or args.runs)
    print(
        f"{len(paths)} runs of {args.frames} frames ready in {made.wall_s:.1f} s wall, "
        f"{made.cpu_s:.1f} s CPU ({runs_dir})"
    )
    listing = args.dir / f"paths_{args.runs}_{args.frames}.txt"
    listing.write_text("".join(f"{p}\n" for p in paths))
    print(f"load average before: {_load()}")
    print(
        f"{'workers':>8}{'wall s':>9}{'CPU s':>9}{'runs/min':>10}{'CPU ms/run':>12}"
        f"{'scaling':>9}{'median run s':>14}{'errors':>8}"
    )
    base = None
    for workers in args.workers:
        timings: list[Timing] = []
        seconds: list[float] = []
        errors = 0
        for _ in range(max(args.repeat, 1)):
            out = args.dir / f"out_w{workers}"
            shutil.rmtree(out, ignore_errors=True)
            took, run_seconds, run_errors = time_batch(listing, workers, out)
            timings.append(took)
            seconds += run_seconds
            errors = max(errors, run_errors)
        took = median(timings)
        rate = len(paths) / took.wall_s * 60
        base = base or rate
        print(
            f"{workers:>8}{took.wall_s:>9.1f}{took.cpu_s:>9.1f}{rate:>10.0f}"
            f"{took.cpu_s / len(paths) * 1000:>12.0f}{rate / base:>9.2f}"
            f"{statistics.median(seconds):>14.3f}{errors:>8}",
            flush=True,
        )
    print(f"load average after: {_load()}")


def _load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


if __name__ == "__main__":
    main()
