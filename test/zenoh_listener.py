"""A remote dashboard's view of the bridge, in its own process, with no ROS at all.

Usage: ``python test/zenoh_listener.py OUT.jsonl --connect tcp/127.0.0.1:PORT [--key EXPR]
[--query SELECTOR ...] [--until-verdict] [--timeout S]``. Opens a Zenoh client session,
subscribes to ``--key`` (default ``**``: the JSON and the raw CDR samples), and writes one
JSON line per sample (key, encoding, payload as text or base64, receive time in ns). With
``--query`` it first sends those gets (repeated until one answers, the bridge may come
later) and writes each reply as a line with ``"reply": true``. It stops on SIGTERM, after
the verdict sample (``--until-verdict``) or at ``--timeout``, and writes a last line
``{"end": true, "rclpy_loaded": ...}``: the proof that no ROS was needed.
"""

from __future__ import annotations

import argparse
import base64
import json
import queue
import signal
import sys
import time
from pathlib import Path
from typing import Any

import zenoh

from ads_rca.remote.config import session_config

STOP: list[int] = []


def line(key: str, encoding: str, payload: bytes, reply: bool = False) -> dict[str, Any]:
    row: dict[str, Any] = {"key": key, "encoding": encoding, "t_ns": time.time_ns()}
    if encoding.startswith("application/json"):
        row["text"] = payload.decode("utf-8")
    else:
        row["b64"] = base64.b64encode(payload).decode("ascii")
    if reply:
        row["reply"] = True
    return row


def open_session(config_text: str, deadline: float) -> Any:
    """A client cannot open before its peer listens: retry until ``deadline``."""
    while True:
        try:
            return zenoh.open(zenoh.Config.from_json5(config_text))
        except zenoh.ZError:
            if time.monotonic() > deadline or STOP:
                raise
            time.sleep(0.1)


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("out", type=Path)
    parser.add_argument("--connect", default="")
    parser.add_argument("--listen", default="", help="be a listening peer instead of a client")
    parser.add_argument("--key", default="**")
    parser.add_argument("--query", action="append", default=[])
    parser.add_argument("--until-verdict", action="store_true")
    parser.add_argument("--timeout", type=float, default=120.0)
    args = parser.parse_args()
    signal.signal(signal.SIGTERM, lambda signum, frame: STOP.append(signum))
    samples: queue.Queue[dict[str, Any]] = queue.Queue()

    def on_sample(sample: Any) -> None:
        samples.put(line(str(sample.key_expr), str(sample.encoding), sample.payload.to_bytes()))

    if args.listen:
        text = session_config("peer", [args.listen], [args.connect] if args.connect else [])
    else:
        text = session_config("client", [], [args.connect])
    deadline = time.monotonic() + args.timeout
    verdict = False
    with args.out.open("w") as out, open_session(text, deadline) as session:
        subscriber = session.declare_subscriber(args.key, on_sample)
        try:
            print("LISTENING", flush=True)
            pending = list(args.query)
            while pending and not STOP and time.monotonic() < deadline:
                for selector in list(pending):
                    replies = [r.ok for r in session.get(selector, timeout=1.0) if r.ok]
                    for ok in replies:
                        row = line(str(ok.key_expr), str(ok.encoding), ok.payload.to_bytes(), True)
                        out.write(json.dumps(row) + "\n")
                    if replies:
                        pending.remove(selector)
                time.sleep(0.1)
            while not STOP and time.monotonic() < deadline and not verdict:
                try:
                    row = samples.get(timeout=0.1)
                except queue.Empty:
                    continue
                out.write(json.dumps(row) + "\n")
                out.flush()
                verdict = args.until_verdict and row["key"].endswith("ads_rca/verdict.json")
            while not samples.empty():
                out.write(json.dumps(samples.get()) + "\n")
            out.write(json.dumps({"end": True, "rclpy_loaded": "rclpy" in sys.modules}) + "\n")
        finally:
            subscriber.undeclare()
    return 0


if __name__ == "__main__":
    sys.exit(main())
