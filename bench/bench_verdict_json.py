"""Benchmark: writing the verdict JSON, the json module against ``indented_json``; a table.

    python bench/bench_verdict_json.py [--frames 2000 10000] [--actors 11] [--repeat 3]

For each frame count a ``cruise`` log (its last frame declared the collision, so every frame
is judged against a partner) is synthesised and diagnosed in corrected mode in this process;
then its ``diagnose --json`` document is written to a scratch file by
``json.dump(document, indent=1)`` (the writer before) and by
``indented_json.write_indented`` (now). Wall and CPU time, each the best of ``--repeat``;
the most memory the write allocates at once (tracemalloc); and whether the bytes are equal.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import tracemalloc
from collections.abc import Callable
from pathlib import Path
from typing import Any

from bench_memory import cruise_crashing_at_the_end
from timing import Clock, Timing, best

from ads_rca.diagnosis.engine import diagnose
from ads_rca.foundation.indented_json import write_indented
from ads_rca.params import make_params

WRITERS: dict[str, Callable[[Any, Any], None]] = {
    "json.dump (before)": lambda document, out: json.dump(document, out, indent=1),
    "indented_json (now)": write_indented,
}


def verdict_document(frames: int, actors: int) -> dict[str, Any]:
    log = cruise_crashing_at_the_end(frames, actors)
    return diagnose(log, make_params("corrected"), workers=1).to_json()


def best_seconds(document: Any, writer: Callable[[Any, Any], None], target: Path, n: int) -> Timing:
    times = []
    for _ in range(max(n, 1)):
        with target.open("w") as out, Clock() as clock:
            writer(document, out)
        times.append(clock.timing)
    return best(times)


def added_peak_mb(document: Any, writer: Callable[[Any, Any], None], target: Path) -> float:
    """Most memory allocated at once while writing (tracemalloc: Python objects, numpy
    arrays and orjson's output all report to it), in MB."""
    tracemalloc.start()
    try:
        with target.open("w") as out:
            writer(document, out)
        return tracemalloc.get_traced_memory()[1] / 1e6
    finally:
        tracemalloc.stop()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--frames", type=int, nargs="*", default=[2000, 10_000])
    parser.add_argument("--actors", type=int, default=11)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    print("frames  MB     writer                 wall s  CPU s   added peak MB  same bytes")
    with tempfile.TemporaryDirectory() as tmp:
        for frames in args.frames:
            document = verdict_document(frames, args.actors)
            texts: dict[str, bytes] = {}
            for name, writer in WRITERS.items():
                target = Path(tmp) / f"{len(texts)}.json"
                took = best_seconds(document, writer, target, args.repeat)
                peak = added_peak_mb(document, writer, target)
                texts[name] = target.read_bytes()
                megabytes = len(texts[name]) / 1e6
                same = len(set(texts.values())) == 1
                cells = f"{frames:<7} {megabytes:<6.1f} {name:<22} {took.wall_s:<7.3f}"
                print(f"{cells} {took.cpu_s:<7.3f} {peak:<14.1f} {same}", flush=True)


if __name__ == "__main__":
    main()
