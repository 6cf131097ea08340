"""Publish throughput of the player at rate 0 to one subscriber process, and conversion speed.

Usage: ``python bench/bench_player.py [--frames N] [--actors M] [--object-dds-frames K]``
(default 10 000 × 50). The log comes from the scenario synthesiser (``cruise``).

Conversion only (no DDS), per frame: the object path (``topics.frame_messages`` building
rclpy message objects, plus ``serialize_message``, which ``publish`` does internally) and the
fast path (``topics.frame_payloads``: the bytes ``publish`` sends as they are); and decoding
those bytes back into model records (``topics.decode_record``, what the monitors do with
each frame).

DDS: the log is written to a temp folder and played by the ``player`` node at rate 0 (each
frame sent once the subscriber acknowledged the previous one) to ``topic_summary`` in another
process, on a private DDS domain with local-only discovery: the fast path (``fast_publish`` +
``fast_decode``) over the whole log, and, with ``--object-dds-frames K``, the object path over
the first K frames for comparison. The machine's load average is printed: other processes on
the same cores slow every number down. Prints one table: each step's wall and CPU time
(user + system; for a DDS step the whole step, both node processes from start to exit, with
this process) and its rate (by wall time; for DDS the player's own publishing span).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path
from typing import Any

from timing import Clock, Timing, load_average, timed

from ads_rca.contract.playback import timeline
from ads_rca.contract.topics import decode_record, frame_messages, frame_payloads
from ads_rca.model import RunLog
from ads_rca.ros.env import pick_domain_id, ros_environment
from ads_rca.ros.launcher import Launcher, node_command
from ads_rca.sources.log.writer import write_run_log


def make_log(frames: int, actors: int, seed: int) -> tuple[RunLog, str]:
    from ads_rca.synth import synthesise

    return synthesise("cruise", "none", seed, frames=frames, actors=actors), "synth cruise"


def conversion_rate(log: RunLog, limit: int, path: str) -> tuple[Timing, int, int]:
    """Timing, frames and messages of one path's per-frame conversion (first ``limit`` ticks).

    ``object``: topics.frame_messages; ``object+cdr``: the same plus serialize_message (what
    publishing an object costs on top); ``fast``: topics.frame_payloads (bytes ready to send).
    """
    ticks = timeline(log)[:limit]
    serialise: Any = None
    if path == "object+cdr":
        from rclpy.serialization import serialize_message as serialise
    messages = 0
    with Clock() as clock:
        for tick in ticks:
            if path == "fast":
                messages += len(frame_payloads(log, tick.stamp_ms))
                continue
            built = frame_messages(log, tick.stamp_ms)
            if serialise is not None:
                for msg in built.values():
                    serialise(msg)
            messages += len(built)
    return clock.timing, len(ticks), messages


def dds_rate(
    log_dir: Path,
    work: Path,
    timeout: float,
    *,
    fast: bool = True,
    stop_frame: int = -1,
) -> dict[str, Any]:
    work.mkdir(parents=True, exist_ok=True)
    summary_file = work / "summary.json"
    env = ros_environment(domain_id=pick_domain_id(), log_dir=work / "ros_log")
    with Launcher(env) as launcher:
        summary = launcher.start(
            "topic_summary",
            node_command(
                "ads_rca.ros.topic_summary",
                {"summary_file": str(summary_file), "timeout_s": timeout, "fast_decode": fast},
            ),
        )
        player = launcher.start(
            "player",
            node_command(
                "ads_rca.ros.player",
                {
                    "log_path": str(log_dir),
                    "rate": 0.0,
                    "wait_for_subscribers": 1,
                    "fast_publish": fast,
                    "stop_frame": stop_frame,
                },
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


def decode_rate(log: RunLog, limit: int) -> tuple[Timing, int, int]:
    """Timing, frames and messages of decoding the fast path's bytes back into model records
    (what a subscriber such as the monitors does with every frame)."""
    payloads = [frame_payloads(log, tick.stamp_ms) for tick in timeline(log)[:limit]]
    messages = 0
    with Clock() as clock:
        for frame in payloads:
            for key, data in frame.items():
                decode_record(key, data, log.frame_ms)
            messages += len(frame)
    return clock.timing, len(payloads), messages


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=10_000)
    parser.add_argument("--actors", type=int, default=50)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--conversion-frames", type=int, default=1000)
    parser.add_argument(
        "--object-dds-frames",
        type=int,
        default=0,
        help="also play this many frames through DDS on the object path (0 = skip)",
    )
    parser.add_argument("--timeout", type=float, default=1800.0)
    args = parser.parse_args(argv)

    load_before = load_average()
    (log, origin), build = timed(lambda: make_log(args.frames, args.actors, args.seed))
    conversions = {
        path: conversion_rate(log, args.conversion_frames, path)
        for path in ("object", "object+cdr", "fast")
    }
    conversions["decode (subscriber side)"] = decode_rate(log, args.conversion_frames)
    runs: dict[str, tuple[dict[str, Any], Timing]] = {}
    with tempfile.TemporaryDirectory(prefix="ads_rca_bench_player_") as tmp:
        work = Path(tmp)
        log_dir, write = timed(lambda: write_run_log(log, work / "log"))
        runs["fast"] = timed(lambda: dds_rate(log_dir, work / "fast", args.timeout))
        if args.object_dds_frames > 0:
            runs["object"] = timed(
                lambda: dds_rate(
                    log_dir,
                    work / "object",
                    args.timeout,
                    fast=False,
                    stop_frame=args.object_dds_frames - 1,
                )
            )
    rows: list[tuple[str, Timing | None, str]] = [
        ("log", None, f"{origin}: {len(log.frames)} frames × {args.actors} actors"),
        ("build log", build, ""),
        ("write log", write, ""),
    ]
    for path, (took, n, messages) in conversions.items():
        rate = f"{n / took.wall_s:,.0f} frames/s, {messages / took.wall_s:,.0f} msgs/s ({n})"
        rows.append((f"conversion only, {path}", took, rate))
    for path, (summary, took) in runs.items():
        status = summary["status"]
        frames = int(status["frames_published"])
        elapsed = float(status["elapsed_s"])
        received = sum(int(row["received"]) for row in summary["topics"].values())
        delivered = "all delivered" if summary["complete"] else f"MISSING {summary['missing']}"
        rows.append(
            (
                f"DDS rate 0, 1 sub, {path}",
                took,
                f"{frames / elapsed:,.0f} frames/s, {received / elapsed:,.0f} msgs/s "
                f"({frames} frames, {received} msgs in {elapsed:.1f} s; {delivered})",
            )
        )
    rows.append(("load average", None, f"{load_before} before, {load_average()} after"))
    width = max(len(name) for name, _, _ in rows)
    print(f"{'bench_player':<{width}}  {'wall s':>7}  {'CPU s':>7}  result")
    for name, step, value in rows:
        wall, cpu = (f"{step.wall_s:7.2f}", f"{step.cpu_s:7.2f}") if step else ("", "")
        print(f"{name:<{width}}  {wall:>7}  {cpu:>7}  {value}".rstrip())
    return 0


if __name__ == "__main__":
    sys.exit(main())
