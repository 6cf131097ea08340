"""Benchmark: diagnose time and peak memory vs log length and actor count; prints a table.

    python bench/bench_diagnose.py [--frames 1000 10000] [--actors 50 200] [--workers N]

Each configuration runs in its own process (so peak memory is its own): synthesise a
``cruise`` log, write it under ``--dir``, then time loading it from disk and judging it.
The cruise log has no crash, so its last frame is declared the collision frame: the
corrected rules then judge every frame against the nearest actor as the partner, which is
the expensive path. Cost should grow linearly with frames (the last column: wall µs per
frame). CPU is the process's own plus its judging workers' (forked, reaped before it ends).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

from timing import timed


def one_run(
    frames: int, actors: int, semantics: str, folder: Path, workers: int
) -> dict[str, float]:
    """Synthesise, write, load and diagnose one log (in this process)."""
    from bench_memory import write_frames_log

    from ads_rca.diagnosis.engine import diagnose
    from ads_rca.params import make_params
    from ads_rca.sources.log.reader import read_run_log

    write_frames_log(folder, frames, actors)
    loaded, load = timed(lambda: read_run_log(folder))
    result, judge = timed(lambda: diagnose(loaded, make_params(semantics), workers=workers))
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return {
        "frames": len(result.frames),
        "load_s": load.wall_s,
        "load_cpu_s": load.cpu_s,
        "judge_s": judge.wall_s,
        "judge_cpu_s": judge.cpu_s,
        "peak_mb": peak_mb,
        "problems": len(result.problems),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--frames", type=int, nargs="+", default=[1000, 10_000])
    parser.add_argument("--actors", type=int, nargs="+", default=[50, 200])
    parser.add_argument("--semantics", default="corrected", choices=["reference", "corrected"])
    parser.add_argument("--dir", default="out/bench", help="where logs are written")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--child", nargs=2, type=int, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        frames, actors = args.child
        print(json.dumps(one_run(frames, actors, args.semantics, Path(args.dir), args.workers)))
        return

    Path(args.dir).mkdir(parents=True, exist_ok=True)
    print(
        f"semantics {args.semantics}, {args.workers} judging workers; each row in its own "
        "process; load = JSON from disk"
    )
    header = f"{'frames':>7}{'actors':>7}{'load s':>9}{'CPU s':>8}{'judge s':>9}{'CPU s':>8}"
    print(header + f"{'total s':>9}{'CPU s':>8}{'peak MB':>9}{'µs/frame':>10}")
    for actors in args.actors:
        for frames in args.frames:
            with tempfile.TemporaryDirectory(dir=args.dir) as tmp:
                command = [sys.executable, __file__, "--child", str(frames), str(actors)]
                command += ["--semantics", args.semantics, "--dir", str(Path(tmp) / "log")]
                command += ["--workers", str(args.workers)]
                done = subprocess.run(command, capture_output=True, text=True, check=True)
            row = json.loads(done.stdout.strip().splitlines()[-1])
            total = row["load_s"] + row["judge_s"]
            total_cpu = row["load_cpu_s"] + row["judge_cpu_s"]
            per_frame = total / row["frames"] * 1e6
            print(
                f"{row['frames']:>7}{actors:>7}{row['load_s']:>9.2f}{row['load_cpu_s']:>8.2f}"
                f"{row['judge_s']:>9.2f}{row['judge_cpu_s']:>8.2f}{total:>9.2f}{total_cpu:>8.2f}"
                f"{row['peak_mb']:>9.0f}{per_frame:>10.0f}",
                flush=True,
            )


if __name__ == "__main__":
    main()
