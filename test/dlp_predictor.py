"""A test predictor node: predicts where each actor goes while a scene plays.

``python test/dlp_predictor.py --namespace NS --ego-id ID [--steps 10]`` (the venv's python,
its own process). It subscribes to the contract's ``ego/odometry`` and ``actors`` and, for
each stamp both arrived for, publishes on ``prediction/raw`` (same header stamp) a
constant-position prediction of every actor but the ego: it stays where it is for the next
``--steps`` frames, as offsets in the ego's body frame. The errors are then the distance each
actor really moves, so the scores can be worked out by hand. It subscribes only once the
monitors subscribe to its output, so a stack that waits for its subscribers waits for it.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from ads_rca.contract import topics
from ads_rca.contract.convert import message_stamp_ms
from ads_rca.foundation.geometry import world_to_ego
from ads_rca.model import Actors, EgoPose, Track

WAIT_S = 60.0


def predictions(pose: EgoPose, actors: Actors, ego_id: str, steps: int) -> dict[str, Track]:
    """Every actor but the ego staying put, as ``steps`` ego-frame offsets."""
    out: dict[str, Track] = {}
    keys = tuple(str(k) for k in range(steps))
    offsets = world_to_ego(actors.location[:, 0:2], pose.xy, pose.yaw)
    for row, actor_id in enumerate(actors.ids):
        if actor_id != ego_id:
            out[actor_id] = Track(keys, np.tile([*offsets[row], 0.0], (steps, 1)))
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--namespace", default=topics.DEFAULT_NAMESPACE)
    parser.add_argument("--ego-id", required=True)
    parser.add_argument("--steps", type=int, default=10)
    parser.add_argument("--frame_ms", type=int, default=40)
    args = parser.parse_args()

    import rclpy
    from rclpy.node import Node
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from ads_rca.ros.nodemain import keep_running

    rclpy.init()
    node = Node("dlp_predictor")
    qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
    types = topics.message_types()
    out_key = topics.PREDICTION_RAW
    codec = next(t.codec for t in topics.TABLE if t.key == out_key)
    publisher = node.create_publisher(
        types[out_key], topics.topic_name(out_key, args.namespace), qos
    )
    deadline = time.monotonic() + WAIT_S
    while publisher.get_subscription_count() < 1 and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.05)
    held: dict[int, dict[str, object]] = {}

    def heard(key: str, msg: object) -> None:
        stamp = message_stamp_ms(msg)
        entry = held.setdefault(stamp, {})
        entry[key] = topics.message_to_record(key, msg, args.frame_ms)
        if len(entry) == 2:
            del held[stamp]
            pose, actors = entry[topics.ODOMETRY], entry[topics.ACTORS]
            assert isinstance(pose, EgoPose) and isinstance(actors, Actors)
            record = predictions(pose, actors, args.ego_id, args.steps)
            publisher.publish(codec.build(record, stamp, args.frame_ms))

    for key in (topics.ODOMETRY, topics.ACTORS):
        node.create_subscription(
            types[key],
            topics.topic_name(key, args.namespace),
            lambda msg, key=key: heard(key, msg),
            qos,
        )
    print("predictor ready", flush=True)
    while keep_running() and rclpy.ok():
        rclpy.spin_once(node, timeout_sec=0.1)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
