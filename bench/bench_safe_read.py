"""Benchmark: what the hostile-input checks cost per file, next to parsing it; print a table.

    python bench/bench_safe_read.py [--frames 1000] [--actors 60] [--repeat 5]

Compares ``Path.read_bytes`` (the reader before issue 12) with ``read_regular`` (stat,
non-blocking open, fstat, capped read; and, as a log folder's files are read now, a file
its listing says is regular: no stat, ``O_NOFOLLOW`` open, fstat), and the nesting check
of what the reader keeps (``kept_too_deep``) with ``orjson.loads`` of the same files. Wall
and CPU time, each the best of ``--repeat``, warm file cache; the per-file column is CPU.
"""

from __future__ import annotations

import argparse
import tempfile
from collections.abc import Callable
from pathlib import Path

import orjson
from timing import Timing, best, repeated

from ads_rca.foundation.files import DEFAULT_MAX_FILE_MB, max_bytes, read_regular
from ads_rca.sources.log.reader import kept_too_deep
from ads_rca.sources.log.writer import write_run_log
from ads_rca.synth import synthesise


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--frames", type=int, default=1000)
    parser.add_argument("--actors", type=int, default=60)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        log = synthesise("cruise", "none", seed=0, frames=args.frames, actors=args.actors)
        root = write_run_log(log, Path(tmp) / "log")
        paths = sorted(p for p in root.rglob("*.json") if p.parent != root)
        limit = max_bytes(DEFAULT_MAX_FILE_MB)
        docs = [(p.parent.name, orjson.loads(p.read_bytes())) for p in paths]

        def best_of(work: Callable[[], object]) -> Timing:
            return best(repeated(work, args.repeat))

        rows = [
            (
                "Path.read_bytes (before)",
                best_of(lambda: [p.read_bytes() for p in paths]),
            ),
            (
                "read_regular",
                best_of(lambda: [read_regular(p, limit) for p in paths]),
            ),
            (
                "read_regular, listed (now)",
                best_of(lambda: [read_regular(p, limit, True) for p in paths]),
            ),
            (
                "orjson.loads",
                best_of(lambda: [orjson.loads(p.read_bytes()) for p in paths]),
            ),
            (
                "kept_too_deep (now)",
                best_of(lambda: [kept_too_deep(f, d) for f, d in docs]),
            ),
        ]
    print(f"{len(paths)} record files, {args.frames} frames, {args.actors} actors")
    print(f"{'step':<28}{'wall ms':>10}{'CPU ms':>10}{'CPU µs/file':>13}")
    for name, took in rows:
        wall_ms, cpu_ms = took.wall_s * 1000, took.cpu_s * 1000
        print(f"{name:<28}{wall_ms:>10.1f}{cpu_ms:>10.1f}{cpu_ms * 1000 / len(paths):>13.1f}")


if __name__ == "__main__":
    main()
