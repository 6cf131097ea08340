"""Throughput and latency of the live node graph (every node its own process, real DDS).

Why: the issue's target is >= 50x real time for a 20 Hz log with 50 actors at rate 0. This
plays a synthesised cruise log (no collision, so results stream instead of being held for
the collision partner) through player, four monitors and aggregator, and reports:

- frames per second through the graph: analysed frames / (verdict written - first result),
  and the same as a multiple of real time (20 Hz);
- per monitor, processing time per frame (oracle only, p50/p99) and the delay from the
  frame's marker arriving to its result (p50/p99; includes waiting for look-ahead);
- the verdict latency the aggregator measured;
- CPU seconds each node process used (user + system) from the first result to the verdict,
  beside that span's wall time, per frame and as a share of one core: where the two cores go;
- the whole run's wall and CPU time (graph start to stop: this process and every node
  process, start-up included).

Usage: ``python bench/bench_graph.py [--frames 200] [--actors 50] [--semantics both]``.
"""

from __future__ import annotations

import argparse
import atexit
import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from timing import Clock, process_cpu_s

from ads_rca.oracles.base import MODULES
from ads_rca.params import make_params
from ads_rca.ros.env import pick_domain_id, ros_environment
from ads_rca.ros.graph import Graph, GraphSpec
from ads_rca.sources.log.writer import write_run_log
from ads_rca.synth import synthesise


def percentiles(values: list[float]) -> str:
    if not values:
        return "-"
    p50, p99 = np.percentile(np.array(values) * 1000.0, [50, 99])
    return f"p50 {p50:7.2f} ms  p99 {p99:7.2f} ms"


def run_once(log_dir: Path, frames: int, semantics: str, work: Path) -> dict[str, Any]:
    metrics = work / f"metrics_{semantics}.jsonl"
    spec = GraphSpec(
        log_dir,
        make_params(semantics),
        work / f"verdict_{semantics}.json",
        namespace=f"/bench_{semantics}",
        metrics_log=metrics,
        aggregator_params={"verdict_timeout_s": 60.0},
    )
    env = ros_environment(domain_id=pick_domain_id(), log_dir=work / "ros_log")
    with Clock() as whole, Graph(spec, env) as graph:
        graph.start()
        first = None
        cpu0: dict[str, float] = {}
        deadline = time.monotonic() + 900
        document = None
        while time.monotonic() < deadline:
            if first is None and metrics.exists() and metrics.stat().st_size:
                first = time.monotonic()
                cpu0 = {name: process_cpu_s(p.process.pid) for name, p in graph.processes.items()}
            document = graph.verdict()
            if document is not None:
                break
            time.sleep(0.01)
        done = time.monotonic()
        cpu = {
            name: process_cpu_s(p.process.pid) - cpu0.get(name, 0.0)
            for name, p in graph.processes.items()
        }
        graph.stop()
    if document is None or first is None:
        raise SystemExit(f"no verdict for {semantics}")
    rows = [json.loads(line) for line in metrics.read_text().splitlines() if line]
    fps = (frames - 1) / max(done - first, 1e-9)
    return {
        "semantics": semantics,
        "fps": fps,
        "real_time_x": fps / 20.0,
        "compute": {m: [r["compute_s"] for r in rows if r["module"] == m] for m in MODULES},
        "wait": {m: [r["wait_s"] for r in rows if r["module"] == m] for m in MODULES},
        "verdict_latency_s": document["verdict_latency_s"],
        "complete": document["live"]["complete"],
        "verdict": document["verdict"],
        "cpu": cpu,
        "wall_s": done - first,
        "whole": whole.timing,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=200)
    parser.add_argument("--actors", type=int, default=50)
    parser.add_argument("--semantics", choices=("reference", "corrected", "both"), default="both")
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="ads_rca_bench_graph_"))
    atexit.register(shutil.rmtree, work, True)  # logs, metrics, ROS logs
    log = synthesise("cruise", "none", 1, frames=args.frames, actors=args.actors)
    log_dir = write_run_log(log, work / "log")
    n = len(log.frames)
    print(f"cruise log: {n} frames at 20 Hz, {len(log.actors[log.frames[0]])} actors; rate 0")
    modes = ("reference", "corrected") if args.semantics == "both" else (args.semantics,)
    for semantics in modes:
        r = run_once(log_dir, n, semantics, work)
        print(
            f"\n[{semantics}] {r['fps']:.1f} frames/s through the graph = "
            f"{r['real_time_x']:.2f}x real time (target 50x); verdict latency "
            f"{r['verdict_latency_s']:.3f} s; verdict: {r['verdict']} "
            f"({'complete' if r['complete'] else 'INCOMPLETE'})"
        )
        for m in MODULES:
            print(
                f"  {m:<11} oracle {percentiles(r['compute'][m])} | marker->result "
                f"{percentiles(r['wait'][m])}"
            )
        total = sum(r["cpu"].values())
        wall = r["wall_s"]
        print(f"  per process, first result to verdict ({os.cpu_count()} CPUs):")
        header = f"{'wall s':>7} {'CPU s':>7} {'CPU ms/frame':>13} {'% of a core':>12}"
        print(f"    {'process':<19} {header}")
        for name, seconds in [*r["cpu"].items(), ("total", total)]:
            print(
                f"    {name:<19} {wall:7.2f} {seconds:7.2f} {seconds / n * 1000:13.2f}"
                f" {seconds / max(wall, 1e-9) * 100:12.0f}"
            )
        whole = r["whole"]
        print(
            f"  whole run (graph start to stop, this process and the nodes): "
            f"wall {whole.wall_s:.2f} s, CPU {whole.cpu_s:.2f} s"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
