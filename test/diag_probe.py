"""A test process that writes every ``/diagnostics`` status it receives as a JSON line.

Run as ``python test/diag_probe.py OUT.jsonl [--ros-args ...]``; each line is
``{"t": monotonic seconds, "array": n-th array received, "name", "level", "message",
"hardware_id", "values": {...}}``.
Separate from the pytest process so the tests keep rclpy out of it.
"""

from __future__ import annotations

import json
import sys
import time

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node

from ads_rca.contract import live_topics


def main() -> int:
    out = open(sys.argv[1], "w", encoding="utf-8")  # noqa: SIM115
    rclpy.init(args=[sys.argv[0], *sys.argv[2:]])
    node = Node("diag_probe")
    received = [0]

    def on_message(msg: DiagnosticArray) -> None:
        received[0] += 1
        for s in msg.status:
            row = {
                "t": time.monotonic(),
                "array": received[0],
                "name": s.name,
                "level": int.from_bytes(s.level, "little")
                if isinstance(s.level, bytes)
                else s.level,
                "message": s.message,
                "hardware_id": s.hardware_id,
                "values": {kv.key: kv.value for kv in s.values if not kv.key.startswith("metric")},
            }
            out.write(json.dumps(row) + "\n")
            out.flush()

    node.create_subscription(
        DiagnosticArray, live_topics.DIAGNOSTICS, on_message, live_topics.diagnostics_qos()
    )
    print("probe ready", flush=True)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        out.close()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
