"""Names and QoS of the live graph's own topics (monitors, aggregator, collision events).

Kept apart from the player's contract (``topics.py``) because these are outputs of the
analysis, not log data. No rclpy import at module level: the QoS functions import it when a
node calls them. Relative names live under ``topic_namespace`` like the contract's.

- ``metrics/<module>`` (std_msgs/String; RELIABLE, TRANSIENT_LOCAL, KEEP_LAST 5000): JSON of
  one :class:`~ads_rca.live.results.LiveResult` per judged frame;
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
result a running monitor published.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from rclpy.qos import QoSProfile

COLLISION = "run/collision"
VERDICT = "verdict"
VERDICT_JSON = "verdict/json"
DIAGNOSTICS = "/diagnostics"
METRICS_DEPTH = 5000


def metrics_key(module: str) -> str:
    return f"metrics/{module}"


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
