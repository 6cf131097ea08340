"""A hostile local process on a stack's reference topic (issue 43): no ads_rca import.

``python test/hostile_publisher.py --topic /carla/ego_vehicle/odometry [--after N]`` (the
venv's python, its own process: its own participant and writer). It listens to the
stack's ``/clock`` until it has heard ``--after`` ticks (the stack's odometry went first, so
it is never the first writer, and it knows the stack's time) and its writer matched
``--readers`` readers (the monitors'), then publishes ``nav_msgs/Odometry`` on the topic.
It reads ``/clock``, not the odometry, so the stack, which waits for a reader on each of
its data topics, never takes it for the monitors. It sends:

1. three messages stamped with the wall clock (a clock glitch: wall time beside a simulated
   clock, 56 years ahead of the stack's stamps), 50 ms apart;
2. ``--nan`` messages whose pose is NaN, stamped between the stack's frames (the newest
   tick + 25 ms + 50 ms steps), 5 ms apart;
3. a flood: ``--flood`` messages at about 4,000 a second, stamped a quarter of a
   millisecond apart from the newest tick on.

It waits for its messages to be acknowledged (at most 10 s), prints one JSON line (what it
sent, the newest real stamp it heard) and exits 0; 1 when the stack sent too little within
``--wait-s``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Sequence

import rclpy
from builtin_interfaces.msg import Time
from nav_msgs.msg import Odometry
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock

#: Messages of the flood a second.
FLOOD_RATE = 4000.0


def stamp(ms: int) -> Time:
    return Time(sec=ms // 1000, nanosec=(ms % 1000) * 1_000_000)


def stamp_ms(t: Time) -> int:
    return int(t.sec) * 1000 + int(t.nanosec) // 1_000_000


def odometry(ms: int, nan: bool = False) -> Odometry:
    """An ego pose: at rest at the origin, or NaN."""
    msg = Odometry()
    msg.header.stamp = stamp(ms)
    msg.header.frame_id = "map"
    msg.child_frame_id = "ego_vehicle"
    msg.pose.pose.orientation.w = 1.0
    if nan:
        msg.pose.pose.position.x = math.nan
        msg.pose.pose.position.y = math.nan
        msg.twist.twist.linear.x = math.nan
    return msg


def main(argv: Sequence[str]) -> int:
    parser = argparse.ArgumentParser(prog="hostile_publisher")
    parser.add_argument("--topic", required=True)
    parser.add_argument("--clock", default="/clock")
    parser.add_argument("--after", type=int, default=15)
    parser.add_argument("--nan", type=int, default=40)
    parser.add_argument("--flood", type=int, default=2000)
    parser.add_argument("--readers", type=int, default=1)
    parser.add_argument("--wait-s", type=float, default=30.0)
    options = parser.parse_args(argv)
    rclpy.init()
    node = Node("hostile_publisher")
    qos = QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=1000,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.VOLATILE,
    )
    heard: list[Clock] = []
    node.create_subscription(Clock, options.clock, heard.append, qos)
    pub = node.create_publisher(Odometry, options.topic, qos)
    deadline = time.monotonic() + options.wait_s
    # Heard the stack, and matched every reader (the monitors'): nothing is lost.
    while len(heard) < options.after or pub.get_subscription_count() < options.readers:
        if time.monotonic() > deadline:
            count = pub.get_subscription_count()
            print(f"hostile_publisher: heard {len(heard)}, {count} readers", file=sys.stderr)
            return 1
        rclpy.spin_once(node, timeout_sec=0.05)
    newest = max(stamp_ms(m.clock) for m in heard)
    sent = {"future": 0, "nan": 0, "flood": 0}
    wall = int(time.time() * 1000)
    for k in range(3):  # wall time beside simulated time
        pub.publish(odometry(wall + 50 * k))
        sent["future"] += 1
        time.sleep(0.01)
    for k in range(options.nan):
        pub.publish(odometry(newest + 25 + 50 * k, nan=True))
        sent["nan"] += 1
        time.sleep(0.005)
    rclpy.spin_once(node, timeout_sec=0.0)
    newest = max(stamp_ms(m.clock) for m in heard)
    start = time.monotonic()
    for j in range(options.flood):
        pub.publish(odometry(newest + 1 + j // 4))
        sent["flood"] += 1
        ahead = start + (j + 1) / FLOOD_RATE - time.monotonic()
        if ahead > 0:
            time.sleep(ahead)
    flood_s = time.monotonic() - start
    acked = pub.wait_for_all_acked(Duration(seconds=10.0))
    print(
        json.dumps(
            {
                "sent": sent,
                "total": sum(sent.values()),
                "newest_heard_ms": newest,
                "flood_rate": round(options.flood / flood_s),
                "acked": acked,
            }
        ),
        flush=True,
    )
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
