"""The rclpy DiagnosticArray of plain statuses (the verdict, heartbeats, STALE).

The statuses themselves, their CDR bytes and their reading are pure and live in
:mod:`ads_rca.live.diagnostics`; this is the message-object glue a node publishes.
"""

from __future__ import annotations

from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

from ads_rca.live.diagnostics import Status


def status_msg(status: Status) -> DiagnosticStatus:
    return DiagnosticStatus(
        level=bytes([status.level]),
        name=status.name,
        message=status.message,
        hardware_id=status.hardware_id,
        values=[KeyValue(key=k, value=v) for k, v in status.values],
    )


def array(stamp: Any, statuses: list[Status]) -> DiagnosticArray:
    """The rclpy message (``stamp``: a builtin_interfaces/Time)."""
    msg = DiagnosticArray(status=[status_msg(s) for s in statuses])
    msg.header.stamp = stamp
    return msg
