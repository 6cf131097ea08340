"""Benchmark: synthesise, write and load a long running log; print a table.

    python bench/bench_load.py [--frames 10000] [--actors 50] [--repeat 3] [--dir out/bench]

Loading is timed on a warm file cache (the log was just written) and reported as the
median of ``--repeat`` runs (wall and CPU each their own median), in frames/s and MB/s of
JSON (by wall time). Writing is dominated by file
creation, which depends on the filesystem: pass ``--dir`` to measure another one.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from timing import Timing, median, timed

from ads_rca.sources.log.reader import read_run_log
from ads_rca.sources.log.writer import write_run_log
from ads_rca.synth import synthesise


def folder_megabytes(root: Path) -> float:
    return sum(f.stat().st_size for f in root.rglob("*.json")) / 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--frames", type=int, default=10_000)
    parser.add_argument("--actors", type=int, default=50)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--dir", default="out/bench", help="where the log is written")
    args = parser.parse_args()

    Path(args.dir).mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=args.dir) as tmp:
        root = Path(tmp) / f"cruise_{args.frames}x{args.actors}"
        log, synth = timed(
            lambda: synthesise("cruise", "none", seed=1, frames=args.frames, actors=args.actors)
        )
        _, write = timed(lambda: write_run_log(log, root))
        megabytes = folder_megabytes(root)
        loads: list[Timing] = []
        for _ in range(args.repeat):
            loaded, took = timed(lambda: read_run_log(root))
            loads.append(took)
        assert len(loaded.frames) == len(log.frames), "every frame must load"
        frames = len(log.frames)
        print(f"log: {frames} frames x {args.actors} actors, {megabytes:.0f} MB of JSON")
        print(f"{'step':<12}{'wall s':>10}{'CPU s':>10}{'frames/s':>12}{'MB/s':>10}")
        for step, took in (("synthesise", synth), ("write", write), ("load", median(loads))):
            wall = took.wall_s
            print(
                f"{step:<12}{wall:>10.2f}{took.cpu_s:>10.2f}{frames / wall:>12.0f}"
                f"{megabytes / wall:>10.1f}"
            )
        print(f"load runs (wall s): {', '.join(f'{t.wall_s:.2f}' for t in loads)}")


if __name__ == "__main__":
    main()
