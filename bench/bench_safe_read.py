"""Benchmark: what the hostile-input checks cost per file, next to parsing it; print a table.

    python bench/bench_safe_read.py [--frames 1000] [--actors 60] [--repeat 5]

Compares ``Path.read_bytes`` (the reader before issue 12) with ``read_regular`` (stat,
non-blocking open, fstat, capped read; and, as a log folder's files are read now, a file
its listing says is regular: no stat, ``O_NOFOLLOW`` open, fstat), and the nesting check
of what the reader keeps (``kept_too_deep``) with ``orjson.loads`` of the same files. CPU
time, best of ``--repeat``, warm file cache.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import orjson

from ads_rca.foundation.files import DEFAULT_MAX_FILE_MB, max_bytes, read_regular
from ads_rca.sources.log.reader import kept_too_deep
from ads_rca.sources.log.writer import write_run_log
from ads_rca.synth import synthesise


def best_ms(work: Callable[[], Any], repeat: int) -> float:
    times = []
    for _ in range(repeat):
        start = time.process_time()
        work()
        times.append(time.process_time() - start)
    return min(times) * 1000.0


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
        rows = [
            (
                "Path.read_bytes (before)",
                best_ms(lambda: [p.read_bytes() for p in paths], args.repeat),
            ),
            (
                "read_regular",
                best_ms(lambda: [read_regular(p, limit) for p in paths], args.repeat),
            ),
            (
                "read_regular, listed (now)",
                best_ms(lambda: [read_regular(p, limit, True) for p in paths], args.repeat),
            ),
            (
                "orjson.loads",
                best_ms(lambda: [orjson.loads(p.read_bytes()) for p in paths], args.repeat),
            ),
            (
                "kept_too_deep (now)",
                best_ms(lambda: [kept_too_deep(f, d) for f, d in docs], args.repeat),
            ),
        ]
    print(f"{len(paths)} record files, {args.frames} frames, {args.actors} actors")
    print(f"{'step':<28}{'total ms':>10}{'µs/file':>10}")
    for name, total in rows:
        print(f"{name:<28}{total:>10.1f}{total * 1000 / len(paths):>10.1f}")


if __name__ == "__main__":
    main()
