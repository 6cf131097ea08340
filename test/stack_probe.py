"""A plain rclpy subscriber process that records everything a test stack publishes.

``python test/stack_probe.py SPEC.json OUT.json``: SPEC holds ``{"topics": {name: type},
"stop_file": path, "timeout_s": s}``. Every topic is read reliably, KEEP_ALL (so nothing is lost
at rate 0); each message gives a row ``{"topic", "stamps": [header stamps in ms, one per
marker for a MarkerArray], "text" (a String's data), "received_ns" (the middleware's
reception time), "n" (order taken)}``. The graph's topic names are sampled while it runs
(their union is ``"graph"``). Once ``stop_file`` exists (the test makes it when the
publisher, which waits for every acknowledgement, has exited) it takes what its readers
hold, writes OUT and exits 0; after ``timeout_s`` without it, the same with exit 1.
Separate from the pytest process so the tests keep rclpy out of it.
"""

from __future__ import annotations

import importlib
import json
import sys
import time
from pathlib import Path
from typing import Any

import rclpy
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy


def _ms(stamp: Any) -> int:
    return int(stamp.sec) * 1000 + round(int(stamp.nanosec) / 1_000_000)


def stamps(msg: Any) -> list[int]:
    """The header stamps a message carries (ms)."""
    if hasattr(msg, "header"):
        return [_ms(msg.header.stamp)]
    if hasattr(msg, "markers"):
        return [_ms(m.header.stamp) for m in msg.markers]
    if hasattr(msg, "clock"):
        return [_ms(msg.clock)]
    return []


def main() -> int:
    spec = json.loads(Path(sys.argv[1]).read_text())
    rclpy.init(args=[])
    node = Node("stack_probe")
    rows: list[dict[str, Any]] = []
    qos = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE)

    def callback(topic: str) -> Any:
        def on_message(msg: Any, info: Any) -> None:
            text = getattr(msg, "data", None)
            rows.append(
                {
                    "topic": topic,
                    "stamps": stamps(msg),
                    "text": text if isinstance(text, str) else None,
                    "received_ns": int(info["received_timestamp"]),
                    "n": len(rows),
                }
            )

        return on_message

    for name, type_name in spec["topics"].items():
        package, _, cls = type_name.split("/")
        msg_type = getattr(importlib.import_module(f"{package}.msg"), cls)
        node.create_subscription(msg_type, name, callback(name), qos)
    graph: set[str] = set()
    stop = Path(spec["stop_file"])
    deadline = time.monotonic() + float(spec["timeout_s"])
    print("probe ready", flush=True)
    try:
        while not stop.exists() and time.monotonic() < deadline:
            rclpy.spin_once(node, timeout_sec=0.05)
            graph.update(name for name, _ in node.get_topic_names_and_types())
        stopped = stop.exists()
        taken = -1
        while taken != len(rows):  # drain what is already in the readers' histories
            taken = len(rows)
            rclpy.spin_once(node, timeout_sec=0.2)
        Path(sys.argv[2]).write_text(json.dumps({"messages": rows, "graph": sorted(graph)}))
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0 if stopped else 1


if __name__ == "__main__":
    sys.exit(main())
