"""Publish throughput of the player at rate 0 to one subscriber process, and conversion speed.

Usage: ``python bench/bench_player.py [--frames N] [--actors M]`` (default 10 000 × 50).
The log comes from the scenario synthesiser (``cruise``). It is written to a temp folder,
played by the ``player`` node at rate 0 (each frame sent once the subscriber acknowledged the
previous one) to ``topic_summary`` in another process, on a private DDS domain with
local-only discovery. Prints one table.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from ads_rca.io.json_writer import write_run_log
from ads_rca.model import RunLog
from ads_rca.ros.convert import frame_messages
from ads_rca.ros.env import pick_domain_id, ros_environment
from ads_rca.ros.launcher import Launcher, node_command
from ads_rca.ros.playback import timeline


def make_log(frames: int, actors: int, seed: int) -> tuple[RunLog, str]:
    from ads_rca.synth import synthesise

    return synthesise("cruise", "none", seed, frames=frames, actors=actors), "synth cruise"


def conversion_rate(log: RunLog, limit: int) -> tuple[float, float, int]:
    """frames/s and messages/s of convert.frame_messages alone (first ``limit`` ticks)."""
    ticks = timeline(log)[:limit]
    messages = 0
    start = time.perf_counter()
    for tick in ticks:
        messages += len(frame_messages(log, tick.stamp_ms))
    elapsed = time.perf_counter() - start
    return len(ticks) / elapsed, messages / elapsed, len(ticks)


def dds_rate(log_dir: Path, work: Path, timeout: float) -> dict[str, Any]:
    summary_file = work / "summary.json"
    env = ros_environment(domain_id=pick_domain_id(), log_dir=work / "ros_log")
    with Launcher(env) as launcher:
        summary = launcher.start(
            "topic_summary",
            node_command(
                "ads_rca.ros.topic_summary",
                {"summary_file": str(summary_file), "timeout_s": timeout},
            ),
        )
        player = launcher.start(
            "player",
            node_command(
                "ads_rca.ros.player",
                {"log_path": str(log_dir), "rate": 0.0, "wait_for_subscribers": 1},
            ),
        )
        player_code = player.wait(timeout)
        summary_code = summary.wait(timeout)
    if player_code != 0 or summary_code != 0 or not summary_file.exists():
        raise SystemExit(
            f"bench failed: player {player_code}, topic_summary {summary_code}\n"
            + player.output[-2000:]
            + summary.output[-2000:]
        )
    document: dict[str, Any] = json.loads(summary_file.read_text())
    return document


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=10_000)
    parser.add_argument("--actors", type=int, default=50)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--conversion-frames", type=int, default=1000)
    parser.add_argument("--timeout", type=float, default=1800.0)
    args = parser.parse_args(argv)

    t0 = time.perf_counter()
    log, origin = make_log(args.frames, args.actors, args.seed)
    build_s = time.perf_counter() - t0
    conv_fps, conv_mps, conv_n = conversion_rate(log, args.conversion_frames)
    with tempfile.TemporaryDirectory(prefix="ads_rca_bench_player_") as tmp:
        work = Path(tmp)
        t0 = time.perf_counter()
        log_dir = write_run_log(log, work / "log")
        write_s = time.perf_counter() - t0
        summary = dds_rate(log_dir, work, args.timeout)
    status = summary["status"]
    frames = int(status["frames_published"])
    elapsed = float(status["elapsed_s"])
    received = sum(int(row["received"]) for row in summary["topics"].values())
    rows = [
        ("log", f"{origin}: {len(log.frames)} frames × {args.actors} actors"),
        ("build / write log", f"{build_s:.1f} s / {write_s:.1f} s"),
        ("conversion only", f"{conv_fps:,.0f} frames/s, {conv_mps:,.0f} msgs/s ({conv_n} frames)"),
        (
            "DDS, rate 0, 1 sub",
            f"{frames / elapsed:,.0f} frames/s, {received / elapsed:,.0f} msgs/s",
        ),
        ("DDS playback time", f"{elapsed:.1f} s for {frames} frames, {received} messages"),
        ("all delivered", "yes" if summary["complete"] else f"NO, missing {summary['missing']}"),
    ]
    width = max(len(name) for name, _ in rows)
    print(f"{'bench_player':<{width}}  result")
    for name, value in rows:
        print(f"{name:<{width}}  {value}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
