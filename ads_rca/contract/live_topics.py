"""Names and QoS of the live graph's own topics (monitors, aggregator, collision events).

Kept apart from the player's contract (``topics.py``) because these are outputs of the
analysis, not log data. No rclpy import at module level: the QoS functions import it when a
node calls them. Relative names live under ``topic_namespace`` like the contract's.

- ``metrics/<module>`` (std_msgs/String; RELIABLE, TRANSIENT_LOCAL, KEEP_LAST 5000): JSON of
  one :class:`~ads_rca.live.results.LiveResult` per judged frame;
- ``metrics/<module>/values`` (sensor_msgs/JointState, QoS as ``metrics/<module>``): the same
  results as labelled numbers for plotting tools (:mod:`ads_rca.live.numeric`);
- ``run/collision`` (std_msgs/String, latched): JSON ``{"frame": N}``, a live stack's
  collision event;
- ``verdict`` (diagnostic_msgs/DiagnosticArray, latched): the verdict status;
- ``verdict/json`` (std_msgs/String, latched): the ``diagnose --json`` document (+ ``live``);
- ``/diagnostics`` (diagnostic_msgs/DiagnosticArray; RELIABLE, VOLATILE, KEEP_LAST 100): per
  judged frame, STALE, heartbeats;
- ``run/ready_<run_id>`` (std_msgs/String, never published): every node given a ``run_id``
  subscribes to it, so a player given the same ``run_id`` can count its own run's
  subscribers before playing, not another run's sharing the domain and namespace.

Metrics are TRANSIENT_LOCAL so an aggregator started late (or restarted) still gets every
result a running monitor published, and so does a recorder that discovers the topics late.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

from ads_rca.contract.topics import topic_name
from ads_rca.diagnosis.verdict import MODULES, Module

if TYPE_CHECKING:
    from rclpy.qos import QoSProfile

COLLISION = "run/collision"
VERDICT = "verdict"
VERDICT_JSON = "verdict/json"
DIAGNOSTICS = "/diagnostics"
METRICS_DEPTH = 5000


def metrics_key(module: str) -> str:
    return f"metrics/{module}"


def values_key(module: Module | str) -> str:
    """The plottable numeric form of ``metrics/<module>``."""
    return f"{metrics_key(module)}/values"


READY_PREFIX = "run/ready_"


def ready_key(run_id: str) -> str:
    """The topic whose subscribers are the nodes of run ``run_id`` (see the module doc)."""
    return READY_PREFIX + run_id


def latched_qos() -> QoSProfile:
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=1,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL,
    )


def metrics_qos(subscriber: bool = False) -> QoSProfile:
    """Lossless: the publisher keeps its last results for late joiners; readers keep all."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(
        history=HistoryPolicy.KEEP_ALL if subscriber else HistoryPolicy.KEEP_LAST,
        depth=METRICS_DEPTH,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL,
    )


def diagnostics_qos() -> QoSProfile:
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=100,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.VOLATILE,
    )


def graph_topics(namespace: str) -> dict[str, tuple[str, Callable[[], QoSProfile]]]:
    """The graph's own outputs a recorder subscribes to from its start: full name →
    (type, reader QoS). Found by discovery instead, a monitor's first results (or a short
    run's every result) could be published and acknowledged before the recorder matched."""
    out: dict[str, tuple[str, Callable[[], QoSProfile]]] = {}
    for module in MODULES:
        for key, msg_type in (
            (metrics_key(module), "std_msgs/msg/String"),
            (values_key(module), "sensor_msgs/msg/JointState"),
        ):
            out[topic_name(key, namespace)] = (msg_type, lambda: metrics_qos(subscriber=True))
    out[topic_name(VERDICT, namespace)] = ("diagnostic_msgs/msg/DiagnosticArray", latched_qos)
    out[topic_name(VERDICT_JSON, namespace)] = ("std_msgs/msg/String", latched_qos)
    out[DIAGNOSTICS] = ("diagnostic_msgs/msg/DiagnosticArray", diagnostics_qos)
    return out
