"""Benchmark: synthesise, write and load a long running log; print a table.

    python bench/bench_load.py [--frames 10000] [--actors 50] [--repeat 3] [--dir out/bench]

Loading is timed on a warm file cache (the log was just written) and reported as the
median of ``--repeat`` runs, in frames/s and MB/s of JSON. Writing is dominated by file
creation, which depends on the filesystem: pass ``--dir`` to measure another one.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

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
        start = time.perf_counter()
        log = synthesise("cruise", "none", seed=1, frames=args.frames, actors=args.actors)
        synth_s = time.perf_counter() - start
        start = time.perf_counter()
        write_run_log(log, root)
        write_s = time.perf_counter() - start
        megabytes = folder_megabytes(root)
        loads = []
        for _ in range(args.repeat):
            start = time.perf_counter()
            loaded = read_run_log(root)
            loads.append(time.perf_counter() - start)
        assert len(loaded.frames) == len(log.frames), "every frame must load"
        load_s = statistics.median(loads)
        frames = len(log.frames)
        print(f"log: {frames} frames x {args.actors} actors, {megabytes:.0f} MB of JSON")
        print(f"{'step':<12}{'seconds':>10}{'frames/s':>12}{'MB/s':>10}")
        for step, seconds in (("synthesise", synth_s), ("write", write_s), ("load", load_s)):
            print(
                f"{step:<12}{seconds:>10.2f}{frames / seconds:>12.0f}{megabytes / seconds:>10.1f}"
            )
        print(f"load runs (s): {', '.join(f'{s:.2f}' for s in loads)}")


if __name__ == "__main__":
    main()
