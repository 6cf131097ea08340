"""A reader QoS for a topic outside our contract: one that matches every publisher of it.

Like rosbag2: reliable only if every publisher offers reliable, latched (TRANSIENT_LOCAL)
only if every publisher is, so a reader never asks more than some writer offers (which would
not match, and nothing would arrive). Used by the recorder and the Zenoh bridge for the
topics they find by discovery.
"""

from __future__ import annotations

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy


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
