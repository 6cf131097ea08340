"""A reader QoS for a topic outside our contract: one that matches every publisher of it.

Like rosbag2: reliable only if every publisher offers reliable, latched (TRANSIENT_LOCAL)
only if every publisher is, so a reader never asks more than some writer offers (which would
not match, and nothing would arrive). Used by the recorder and the Zenoh bridge for the
topics they find by discovery.

A topic read from the start, before its publishers are known (a collision topic), gets
:func:`any_durability` instead: latched, volatile reliable and volatile best-effort
readers, so every publisher matches one of them, as reliably as it offers.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.subscription import Subscription


def offered_qos(node: Node, name: str, keep_all: bool = False, depth: int = 1000) -> QoSProfile:
    """The matching reader QoS of topic ``name`` (KEEP_ALL or KEEP_LAST ``depth``)."""
    info = node.get_publishers_info_by_topic(name)
    latched = bool(info) and all(
        p.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in info
    )
    reliable = all(p.qos_profile.reliability == ReliabilityPolicy.RELIABLE for p in info)
    return QoSProfile(
        history=HistoryPolicy.KEEP_ALL if keep_all else HistoryPolicy.KEEP_LAST,
        depth=depth,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
    )


def any_durability(
    node: Node, msg_type: Any, name: str, callback: Callable[[Any], None], depth: int = 10
) -> list[Subscription[Any]]:
    """Readers of ``name`` that together match any publisher, each as reliably as it
    offers: TRANSIENT_LOCAL reliable (a latched publisher's last messages reach a late
    reader), VOLATILE reliable (the default QoS, as CARLA's collision sensor offers it: no
    message lost under load) and VOLATILE best-effort (a sensor QoS). A publisher several
    match delivers each message more than once: ``callback`` must take a repeat as a no-op
    (a collision frame heard again is)."""

    def qos(reliability: ReliabilityPolicy, durability: DurabilityPolicy) -> QoSProfile:
        return QoSProfile(
            history=HistoryPolicy.KEEP_LAST,
            depth=depth,
            reliability=reliability,
            durability=durability,
        )

    # A reader that cannot match some publisher leaves it to another one, so rcl's
    # "incompatible QoS: no messages will be received" warning would be false: not logged.
    quiet = SubscriptionEventCallbacks(incompatible_qos=lambda _event: None)
    reliable, best_effort = ReliabilityPolicy.RELIABLE, ReliabilityPolicy.BEST_EFFORT
    latched, volatile = DurabilityPolicy.TRANSIENT_LOCAL, DurabilityPolicy.VOLATILE
    return [
        node.create_subscription(
            msg_type, name, callback, qos(reliable, latched), event_callbacks=quiet
        ),
        node.create_subscription(
            msg_type, name, callback, qos(reliable, volatile), event_callbacks=quiet
        ),
        node.create_subscription(msg_type, name, callback, qos(best_effort, volatile)),
    ]
