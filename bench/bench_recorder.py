"""Recorder throughput (MB/s of CDR payload) with no message lost, and raw writer speed.

Usage: ``python bench/bench_recorder.py [--frames N] [--actors M] [--compression zstd]``
(default 2 000 × 50). A synthesised ``cruise`` log is played by the ``player`` at rate 0
(each frame sent once every subscriber acknowledged the previous one) to the ``recorder``
in another process, on a private DDS domain with local-only discovery. The recorder's
throughput is payload bytes / (last − first reception time); "lost" compares the per-topic
counts in the bag with what the frame markers announced. The offline rows time
:class:`McapBagWriter` alone on the same bytes (no DDS) for each compression. Each row's
wall and CPU time (user + system) are the step's: for the recorder, both node processes
from start to exit and this process reading the bag back; MB/s is by wall time (the
recorder's over its reception span).
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
from collections import Counter
from pathlib import Path
from typing import Any

from timing import Clock, Timing, timed

from ads_rca.contract import rosmsg, topics
from ads_rca.contract.assembler import RunLogAssembler
from ads_rca.ros.env import pick_domain_id, ros_environment
from ads_rca.ros.launcher import Launcher, node_command
from ads_rca.sources.bag.mcap_writer import COMPRESSIONS, McapBagWriter
from ads_rca.sources.bag.reader import iter_bag
from ads_rca.sources.log.writer import write_run_log


def record(log_dir: Path, bag: Path, work: Path, compression: str) -> dict[str, Any]:
    env = ros_environment(domain_id=pick_domain_id(), log_dir=work / "ros_log")
    params: dict[str, str | bool] = {
        "output": str(bag),
        "stop_on_finished": True,
        "compression": compression,
    }
    with Launcher(env) as launcher:
        recorder = launcher.start("recorder", node_command("ads_rca.ros.recorder", params))
        player = launcher.start(
            "player",
            node_command(
                "ads_rca.ros.player",
                {"log_path": str(log_dir), "rate": 0.0, "wait_for_subscribers": 1},
            ),
        )
        codes = (player.wait(600), recorder.wait(120))
    if codes != (0, 0):
        raise SystemExit(f"player/recorder exit {codes}:\n{player.output}\n{recorder.output}")
    progress = RunLogAssembler()
    counts: Counter[str] = Counter()
    keys = {name: key for key, name in topics.topic_names().items()}
    payload, first, last = 0, None, 0
    messages = list(iter_bag(bag))
    for m in messages:
        key = keys[m.topic]
        counts[key] += 1
        payload += len(m.data)
        first = m.log_time_ns if first is None else min(first, m.log_time_ns)
        last = max(last, m.log_time_ns)
        if key in (topics.FRAME, topics.STATUS):
            progress.add(key, rosmsg.deserialize(m.data, m.msg_type))
    lost = {
        k: progress.expected[k] - counts[k]
        for k in progress.expected
        if counts[k] < progress.expected[k]
    }
    seconds = (last - (first or 0)) / 1e9
    size = sum(p.stat().st_size for p in bag.glob("*.mcap"))
    return {
        "messages": len(messages),
        "payload_mb": payload / 1e6,
        "file_mb": size / 1e6,
        "seconds": seconds,
        "mb_s": payload / 1e6 / seconds if seconds else float("nan"),
        "msg_s": len(messages) / seconds if seconds else float("nan"),
        "lost": lost,
        "frames": progress.status.get("frames_published"),
        "data": [(m.topic, m.msg_type, m.log_time_ns, m.data) for m in messages],
    }


def offline(
    data: list[tuple[str, str, int, bytes]], work: Path, compression: str
) -> tuple[Timing, float]:
    """The writer's timing and MB/s (by wall time) on ``data``."""
    out = work / f"offline_{compression}"
    with Clock() as clock, McapBagWriter(out, compression=compression) as writer:
        for topic, msg_type, log_time, payload in data:
            if not writer.has_topic(topic):
                writer.add_topic(topic, msg_type)
            writer.write(topic, log_time, payload)
    shutil.rmtree(out)
    return clock.timing, sum(len(d[3]) for d in data) / 1e6 / clock.wall_s


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=2000)
    parser.add_argument("--actors", type=int, default=50)
    parser.add_argument("--compression", choices=sorted(COMPRESSIONS), default="zstd")
    args = parser.parse_args()
    from ads_rca.synth import synthesise

    log = synthesise("cruise", "none", 0, frames=args.frames, actors=args.actors)
    with tempfile.TemporaryDirectory(prefix="ads_rca_bench_rec_") as tmp:
        work = Path(tmp)
        log_dir = write_run_log(log, work / "log")
        r, took = timed(lambda: record(log_dir, work / "bag", work, args.compression))
        print(f"log: synth cruise, {len(log.frames)} frames x {args.actors} actors")
        print(
            f"recorder ({args.compression}): {r['messages']} messages, "
            f"{r['payload_mb']:.1f} MB payload -> {r['file_mb']:.1f} MB file, received in "
            f"{r['seconds']:.2f} s ({r['msg_s']:.0f} msg/s); "
            f"frames {r['frames']}, lost {r['lost'] or 'none'}"
        )
        print(f"{'step':<26}{'wall s':>8}{'CPU s':>8}{'MB/s':>8}")
        print(f"{'recorder over DDS (' + args.compression + ')':<26}", end="")
        print(f"{took.wall_s:>8.2f}{took.cpu_s:>8.2f}{r['mb_s']:>8.1f}")
        for compression in sorted(COMPRESSIONS):
            writer, rate = offline(r["data"], work, compression)
            print(
                f"{'writer alone (' + compression + ')':<26}"
                f"{writer.wall_s:>8.2f}{writer.cpu_s:>8.2f}{rate:>8.0f}"
            )
    return 1 if r["lost"] else 0


if __name__ == "__main__":
    sys.exit(main())
