"""``diagnostic_msgs`` for the live graph: one status per judged frame, STALE, the verdict.

ROS conventions (REP-107 style, as ``diagnostic_updater`` does): status ``name``
``ads_rca/<module>``, a ``hardware_id``, level OK / WARN / ERROR / STALE, a short message, and
every number in ``values`` as key/value strings. Nested metrics are flattened to
``parent.child`` keys; lists are JSON text. Pure message building, no node.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

from ads_rca.live.results import LiveResult, plain
from ads_rca.ros.jsontext import dumps_json

OK = DiagnosticStatus.OK
WARN = DiagnosticStatus.WARN
ERROR = DiagnosticStatus.ERROR
STALE = DiagnosticStatus.STALE

VERDICT_NAME = "ads_rca/verdict"


def status_name(module: str) -> str:
    return f"ads_rca/{module}"


def text(value: Any) -> str:
    """A value as a KeyValue string (floats with repr precision, nan/inf spelled out)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else str(value)
    if value is None:
        return ""
    if isinstance(value, str):
        return value
    return dumps_json(plain(value))


def flatten(values: Mapping[str, Any], prefix: str = "") -> list[KeyValue]:
    """Key/values, dicts flattened to ``a.b`` keys (lists stay JSON text)."""
    out: list[KeyValue] = []
    for key, value in values.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping) and value:
            out.extend(flatten(value, f"{name}."))
        else:
            out.append(KeyValue(key=name, value=text(value)))
    return out


def result_status(live: LiveResult, semantics: str, hardware_id: str) -> DiagnosticStatus:
    """One judged frame: ERROR failed, WARN skipped or judged with incomplete inputs, else OK."""
    r = live.result
    if r.failed:
        level, message = ERROR, f"frame {live.frame}: {r.module} failed"
    elif r.skipped or live.incomplete:
        level = WARN
        message = f"frame {live.frame}: " + (
            f"check skipped: {r.skipped}" if r.skipped else "judged with incomplete inputs"
        )
    else:
        level, message = OK, f"frame {live.frame}: ok"
    head: dict[str, Any] = {
        "semantics": semantics,
        "frame": live.frame,
        "index": live.index,
        "stamp_ms": r.timestamp_ms,
        "failed": r.failed,
        "skipped": r.skipped or "",
        "incomplete": "; ".join(live.incomplete),
        "ids": list(r.ids),
        "revision": live.revision,
        "compute_s": live.compute_s,
    }
    values = flatten(head) + flatten(r.metrics, "metric.") + flatten(r.thresholds, "threshold.")
    return DiagnosticStatus(
        level=level,
        name=status_name(r.module),
        message=message,
        hardware_id=hardware_id,
        values=values,
    )


def simple_status(
    name: str, level: bytes, message: str, hardware_id: str, values: Mapping[str, Any]
) -> DiagnosticStatus:
    return DiagnosticStatus(
        level=level, name=name, message=message, hardware_id=hardware_id, values=flatten(values)
    )


def verdict_status(document: Mapping[str, Any], hardware_id: str) -> DiagnosticStatus:
    """The verdict: ERROR naming the primary root cause (OK when no fault was found)."""
    primary = document.get("primary_root_cause")
    level = ERROR if primary else OK
    message = f"root cause: {document.get('verdict')}" if primary else str(document["verdict"])
    head = {
        k: document.get(k)
        for k in (
            "semantics",
            "primary_root_cause",
            "contributing",
            "root_causes",
            "attribution_basis",
            "reason",
            "collision_frame",
            "partner_id",
            "ego_id",
            "verdict_latency_s",
        )
    }
    head["complete"] = (document.get("live") or {}).get("complete")
    modules = {m: dict(v) for m, v in (document.get("modules") or {}).items()}
    values = flatten(head) + flatten(modules, "modules.")
    values += flatten(document.get("evidence") or {}, "evidence.")
    return DiagnosticStatus(
        level=level, name=VERDICT_NAME, message=message, hardware_id=hardware_id, values=values
    )


def array(stamp: Any, statuses: list[DiagnosticStatus]) -> DiagnosticArray:
    msg = DiagnosticArray(status=statuses)
    msg.header.stamp = stamp
    return msg
