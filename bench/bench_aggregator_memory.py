"""Benchmark: the aggregator core's memory against run length; prints a table.

    python bench/bench_aggregator_memory.py [--frames 1000 5000 10000 20000]

Feeds :class:`~ads_rca.live.aggregate.AggregatorCore` (the aggregator node's pure core)
markers and the four modules' results of N frames, as the monitors publish them: the
results of a diagnosed synthetic crash run, repeated with increasing indices and stamps.
Each N runs in a fresh process. Columns: memory the core retains once fed (tracemalloc),
the peak while feeding, the peak while rendering the verdict (its ``frames`` list is
O(frames) by contract), and the process's max RSS; then the wall and CPU time of feeding
and rendering (with tracemalloc on, which slows Python allocation down: for comparing rows,
not as the node's speed). The retained column must stay flat: results are spilled to a
temporary file, only fixed-size columns stay in memory.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tracemalloc
from dataclasses import replace

from timing import Clock


def one_run(frames: int, semantics: str) -> dict[str, float]:
    from ads_rca.diagnosis.engine import diagnose
    from ads_rca.live.aggregate import AggregatorCore
    from ads_rca.live.results import FrameMarker, LiveResult
    from ads_rca.params import make_params
    from ads_rca.synth import synthesise

    params = make_params(semantics)
    log = synthesise("cut_in", "perception", seed=2)
    template = diagnose(log, params).frames
    frame_ms = log.frame_ms
    metadata = replace(log.metadata, collision_frame=frames, total_frames=frames)
    tracemalloc.start()
    core = AggregatorCore(params, verdict_timeout_s=1e9)
    core.set_metadata(metadata, "bench", 0.0)
    base = tracemalloc.get_traced_memory()[0]
    tracemalloc.reset_peak()
    clock = Clock().start()
    for index in range(frames):
        stamp = (index + 1) * frame_ms
        core.add_marker(FrameMarker(index, stamp), 0.0)
        source = template[index % len(template)]
        for result in source.results.values():
            moved = LiveResult(index, replace(result, timestamp_ms=stamp), index + 1, frames)
            # Through the wire form, as from a monitor: each result its own objects.
            core.add_result(LiveResult.from_document(moved.to_document()), 0.0)
    retained, feed_peak = tracemalloc.get_traced_memory()
    tracemalloc.reset_peak()
    core.set_finished(0.0)
    outcome = core.poll(1.0)
    assert outcome is not None and len(outcome.document["frames"]) == frames
    took = clock.timing
    verdict_peak = tracemalloc.get_traced_memory()[1]
    return {
        "wall_s": took.wall_s,
        "cpu_s": took.cpu_s,
        "retained_mb": (retained - base) / 2**20,
        "feed_peak_mb": (feed_peak - base) / 2**20,
        "verdict_peak_mb": (verdict_peak - base) / 2**20,
        "rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--frames", type=int, nargs="+", default=[1000, 5000, 10_000, 20_000])
    parser.add_argument("--semantics", nargs="+", default=["reference", "corrected"])
    parser.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(one_run(int(args.child[0]), args.child[1])))
        return
    print("AggregatorCore fed N frames x 4 results (tracemalloc MB above the empty core)")
    print(f"{'semantics':<11}{'frames':>8}{'retained':>10}{'feed pk':>9}{'verdict pk':>11}", end="")
    print(f"{'max RSS':>9}{'wall s':>8}{'CPU s':>8}")
    for semantics in args.semantics:
        for frames in args.frames:
            command = [sys.executable, __file__, "--child", str(frames), semantics]
            done = subprocess.run(command, capture_output=True, text=True, check=True)
            row = json.loads(done.stdout.strip().splitlines()[-1])
            print(
                f"{semantics:<11}{frames:>8}{row['retained_mb']:>10.2f}{row['feed_peak_mb']:>9.2f}"
                f"{row['verdict_peak_mb']:>11.1f}{row['rss_mb']:>9.0f}"
                f"{row['wall_s']:>8.2f}{row['cpu_s']:>8.2f}",
                flush=True,
            )


if __name__ == "__main__":
    main()
