"""A test trajectory-prediction model: answers each snapshot row it hears.

``python test/ego_path_model.py --namespace NS [--shift-x 1.0] [--subscribers 3]
[--run-id ID] [--after-result] [--hostile]`` (the venv's python, its own process: another
participant than the player's). It subscribes to ``run/ego_paths`` and, for each row the
player sends (a message with a ``realised`` path), publishes on the same topic
``{"stamp_ms", "id", "predicted", "submission", "run"}``: the realised path shifted
``--shift-x`` metres in x, so each row's ADE and FDE are exactly that shift and its MAE a
third of it. Answers wait until ``--subscribers`` readers (itself among them) match its
publisher, so none is lost to discovery; with ``--run-id`` it is one of the subscribers the
run's player waits for (``run/frame`` and the run's ready topic), so it hears every row.
``--after-result``: a slow model, answering a row only once the planning monitor's first
result for it is out (``metrics/planning``), so the monitor must score it again.
``--hostile``: before each answer, three messages no node may use: text that is no JSON, a
path 1e300 m away, and a path 5 m off that names another run.
"""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any

from ads_rca.contract import live_topics, topics
from ads_rca.contract.errors import JsonTextError
from ads_rca.contract.jsontext import dumps_json, loads_json

NAME = "shift-model"
WAIT_S = 60.0


def answer(document: dict[str, Any], shift_x: float) -> dict[str, Any] | None:
    """The model's message for the player's row (None: not a player's row)."""
    realised = document.get("realised")
    if not isinstance(realised, list) or document.get("submission") == NAME:
        return None
    return {
        "stamp_ms": document["stamp_ms"],
        "id": document.get("id", ""),
        "predicted": shifted(realised, shift_x),
        "submission": NAME,
        "run": document.get("run", ""),
    }


def hostile(reply: dict[str, Any]) -> list[str]:
    """Messages about ``reply``'s row that must change nothing."""
    absurd = {**reply, "predicted": [[1e300, 0.0, 0.0]] * 6}
    foreign = {**reply, "run": "another_run", "predicted": shifted(reply["predicted"], 4.0)}
    return ["{not json", dumps_json(absurd), dumps_json(foreign)]


def shifted(path: list[list[float]], dx: float) -> list[list[float]]:
    return [[x + dx, y, z] for x, y, z in path]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--namespace", default=topics.DEFAULT_NAMESPACE)
    parser.add_argument("--shift-x", type=float, default=1.0)
    parser.add_argument("--subscribers", type=int, default=3)
    parser.add_argument("--after-result", action="store_true")
    parser.add_argument("--hostile", action="store_true")
    parser.add_argument("--run-id", default="")
    args = parser.parse_args()

    import rclpy
    from rclpy.node import Node
    from std_msgs.msg import String

    from ads_rca.ros.nodemain import keep_running, subscribe_ready

    rclpy.init()
    node = Node("ego_path_model")
    name = topics.topic_name(topics.EGO_PATHS, args.namespace)
    publisher = node.create_publisher(String, name, topics.qos_profile(topics.EGO_PATHS))
    waiting: list[dict[str, Any]] = []
    held: dict[int, dict[str, Any]] = {}  # --after-result: rows whose result is not out
    judged: set[int] = set()

    def heard(msg: String) -> None:
        try:
            document = loads_json(msg.data)
        except JsonTextError:  # its own hostile text, heard back
            return
        reply = answer(document, args.shift_x) if isinstance(document, dict) else None
        if reply is None:
            return
        stamp = reply["stamp_ms"]
        if args.after_result and stamp not in judged:
            held[stamp] = reply
        else:
            waiting.append(reply)

    def result(msg: String) -> None:
        stamp = loads_json(msg.data).get("stamp_ms")
        if isinstance(stamp, int):
            judged.add(stamp)
            if stamp in held:
                waiting.append(held.pop(stamp))

    node.create_subscription(
        String, name, heard, topics.qos_profile(topics.EGO_PATHS, keep_all=True)
    )
    if args.run_id:  # counted among the subscribers the run's player waits for
        frame = topics.topic_name(topics.FRAME, args.namespace)
        node.create_subscription(String, frame, lambda _msg: None, topics.qos_profile(topics.FRAME))
        subscribe_ready(node, args.namespace, args.run_id)
    if args.after_result:
        metrics = topics.topic_name(live_topics.metrics_key("planning"), args.namespace)
        node.create_subscription(String, metrics, result, live_topics.metrics_qos())
    print("model ready", flush=True)
    deadline = time.monotonic() + WAIT_S
    sent = 0
    while keep_running() and rclpy.ok():
        rclpy.spin_once(node, timeout_sec=0.01)
        matched = publisher.get_subscription_count() >= args.subscribers
        if waiting and (matched or time.monotonic() > deadline):
            for reply in waiting:
                if args.hostile:
                    for text in hostile(reply):
                        publisher.publish(String(data=text))
                publisher.publish(String(data=dumps_json(reply)))
                sent += 1
            print(f"answered {sent} rows", flush=True)
            waiting.clear()
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
