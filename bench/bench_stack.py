"""Benchmark: stack mode's cores at log rate (issue #15), in one process on simulated time.

    python bench/bench_stack.py [--actors 50] [--frames 400] [--long 1000 5000 20000]

The classes the ``monitors`` and ``aggregator`` nodes run in stack mode (the stamp sync into
one monitor core judging the four modules, the stack-mode aggregator), fed a synthesised
run as a stack sends it (per-input stamp offsets, arrival jitter). Wall and CPU times are
this process's own (no DDS: the nodes add decoding and publishing on top).

* per frame: the monitor's work from a frame's release to its four results, p50/p99 (the
  target at 20 Hz is p99 < 10 ms), and the whole stream's wall and CPU time per frame, on a
  ``lead_braking`` crash with ``--actors`` background actors, both modes;
* verdict: wall and CPU time from the collision announcement to the verdict (re-judging the
  held history, less what was judged ahead against the warned actor, and attributing),
  default history and a whole-run history;
* long runs: records held, the Python heap the monitor side allocated and still holds
  (tracemalloc, started after the stream was built) after N frames of ``cruise`` judged
  live, and the verdict's wall and CPU time for a collision announced at the last frame: flat
  in N (bounded windows; the verdict reads back only the effect window), the figure the
  issue asks for at 20,000 frames.
"""

from __future__ import annotations

import argparse
import time
import tracemalloc

import numpy as np
from timing import Clock, Timing

from ads_rca.live.aggregate import AggregatorCore
from ads_rca.live.simulate import stack_stream
from ads_rca.live.stack_config import STACK_PARAMETERS, StackConfig
from ads_rca.live.stack_feed import StackFeed
from ads_rca.live.window import MonitorCore, WindowSettings
from ads_rca.model import RunLog
from ads_rca.oracles.base import MODULES
from ads_rca.params import make_params
from ads_rca.synth import synthesise


def config() -> StackConfig:
    values = {name: entry[0] for name, entry in STACK_PARAMETERS.items()}
    values |= {"timesteps_per_frame": 50, "camera_loc.x": 1.3, "camera_loc.z": 1.8}
    return StackConfig.from_values(values, input_timeout_s=1.0)


def time_to_verdict(
    core: MonitorCore, feed: StackFeed, aggregator: AggregatorCore, frame: int, now: float
) -> Timing:
    """Wall and CPU time from announcing a collision at ``frame`` to the aggregator's verdict
    (re-judging, closing the horizon, attributing), on simulated time from ``now``."""
    deadline = time.perf_counter() + 120
    with Clock() as clock:
        core.set_collision(frame, now)
        aggregator.set_collision(frame, now)
        outcome = None
        while outcome is None and time.perf_counter() < deadline:
            feed.poll(now)
            for result in core.poll(now):
                aggregator.add_result(result, now)
            outcome = aggregator.poll(now)
            now += 0.001
    return clock.timing


def play(log: RunLog, mode: str, history: int) -> dict[str, float]:
    """Stream ``log``; per-frame wall times, CPU per frame, verdict latency, heap."""
    params = make_params(mode)
    core = MonitorCore(MODULES, params, WindowSettings(history_frames=history), stack=True)
    feed = StackFeed(config(), core, lambda folder, error: None)
    aggregator = AggregatorCore(params, stack=config())
    stream = stack_stream(log, seed=1)
    frame_s: list[float] = []
    with Clock() as streamed:
        for message in stream.messages:
            now = message.arrival_s
            started = time.perf_counter()
            feed.add(message.folder, message.payload, now)
            feed.poll(now)
            results = core.poll(now)
            for result in results:
                aggregator.add_result(result, now)
            core.collision_warnings()  # as the monitors node polls: warn, judge ahead
            core.prepare()
            if results:
                frame_s.append((time.perf_counter() - started) / (len(results) / len(MODULES)))
    frames = max(1, len(log.unique_frames))
    verdict = Timing(float("nan"), float("nan"))
    if log.metadata.collision_frame >= 0:
        now = stream.messages[-1].arrival_s + 0.001
        verdict = time_to_verdict(core, feed, aggregator, log.metadata.collision_frame, now)
    times = np.array(frame_s) * 1000
    return {
        "p50_ms": float(np.percentile(times, 50)) if times.size else float("nan"),
        "p99_ms": float(np.percentile(times, 99)) if times.size else float("nan"),
        "wall_ms": streamed.wall_s / frames * 1000,
        "cpu_ms": streamed.cpu_s / frames * 1000,
        "verdict_ms": verdict.wall_s * 1000,
        "verdict_cpu_ms": verdict.cpu_s * 1000,
        "held": float(core.held_records()),
    }


def long_run(frames: int, actors: int) -> tuple[int, float, Timing]:
    """Records held, heap the monitor side holds (MB) after ``frames`` of cruise, and the
    verdict's wall and CPU time for a collision announced at the last frame."""
    log = synthesise("cruise", "none", 1, frames=frames, actors=actors)
    messages = stack_stream(log, seed=1).messages  # the stack's side, not measured
    tracemalloc.start()
    params = make_params("corrected")
    core = MonitorCore(MODULES, params, stack=True)
    feed = StackFeed(config(), core, lambda folder, error: None)
    aggregator = AggregatorCore(params, stack=config())
    for message in messages:
        feed.add(message.folder, message.payload, message.arrival_s)
        feed.poll(message.arrival_s)
        for result in core.poll(message.arrival_s):
            aggregator.add_result(result, message.arrival_s)
    current, _peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    now = messages[-1].arrival_s + 0.001
    verdict = time_to_verdict(core, feed, aggregator, log.frames[-1] // log.frame_ms, now)
    return core.held_records(), current / 1e6, verdict


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--actors", type=int, default=50)
    parser.add_argument("--frames", type=int, default=400)
    parser.add_argument("--long", type=int, nargs="+", default=[1000, 5000, 20000])
    args = parser.parse_args()
    crash = synthesise("lead_braking", "perception", 1, actors=args.actors)
    print(f"lead_braking crash, {len(crash.unique_frames)} frames, {args.actors} background actors")
    print(
        f"{'mode':10} {'history':>8} {'p50 ms':>8} {'p99 ms':>8} {'wall ms/fr':>11} "
        f"{'CPU ms/fr':>10} {'verdict ms':>11} {'CPU ms':>8}"
    )
    for mode in ("reference", "corrected"):
        for history in (0, 400):
            row = play(crash, mode, history)
            print(
                f"{mode:10} {history or 'auto':>8} {row['p50_ms']:8.2f} {row['p99_ms']:8.2f} "
                f"{row['wall_ms']:11.2f} {row['cpu_ms']:10.2f} {row['verdict_ms']:11.1f} "
                f"{row['verdict_cpu_ms']:8.1f}",
                flush=True,
            )
    print(f"\ncruise judged live in stack mode (corrected, {args.actors} actors)")
    print(f"{'frames':>8} {'records held':>13} {'heap MB':>8} {'verdict ms':>11} {'CPU ms':>8}")
    for frames in args.long:
        held, heap, verdict = long_run(frames, args.actors)
        print(
            f"{frames:8d} {held:13d} {heap:8.1f} {verdict.wall_s * 1000:11.1f} "
            f"{verdict.cpu_s * 1000:8.1f}",
            flush=True,
        )


if __name__ == "__main__":
    main()
