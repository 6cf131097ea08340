"""``diagnostic_msgs`` for the live graph: a module's latest judged frame, STALE, the verdict.

ROS conventions (REP-107 style, as ``diagnostic_updater`` does): status ``name``
``ads_rca/<module>``, a ``hardware_id``, level OK / WARN / ERROR / STALE, a short message, and
every number in ``values`` as key/value strings. Nested metrics are flattened to
``parent.child`` keys; lists are JSON text. Pure: no rclpy, no message package.

Tools that read ``/diagnostics`` (rqt_robot_monitor, diagnostic_aggregator, Foxglove's
Diagnostics panel) key statuses by name and keep the last one of an array, so an array holds
at most one status per name: a monitor's batch of judged frames becomes one status, its
latest frame, with how many were judged and failed since the previous one
(:func:`batch_status`). The frame-by-frame history is on the ``metrics/<module>`` topics.
Before any collision a planning batch whose plan came closer to its partner (the most
threatening actor) than ``safety_margin`` is a near miss, level WARN (:func:`near_miss`).
Earlier, as each frame arrives and while no collision is known, an actor that kept at its
velocity meets the ego within ``event_ttc_s`` is a **collision warning**: a WARN status of
its own, ``ads_rca/collision_warning`` (:func:`collision_warning`), so a failing planning
frame's ERROR never hides it and a passing one's OK never clears it.

Statuses are plain :class:`Status` values; :func:`encode_array` writes a DiagnosticArray's
CDR bytes directly, for the monitors' statuses (a 40-value status as rclpy objects cost the
monitor more than judging the frame), and :func:`status_runs` reads the names and runs back
from bytes. The rclpy message (the verdict, heartbeats) is built by
:func:`ads_rca.ros.diagnostics.array`.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

from ads_rca.capabilities import NOT_JUDGED
from ads_rca.contract.cdr import CdrWriter
from ads_rca.contract.cdr_decode import CdrReader
from ads_rca.contract.errors import CdrError
from ads_rca.contract.jsontext import dumps_json
from ads_rca.foundation.text import shown_id
from ads_rca.live.results import LiveResult, plain
from ads_rca.live.runid import RUN_KEY
from ads_rca.params import make_params
from ads_rca.sources.registry import scored_status

#: diagnostic_msgs/DiagnosticStatus levels (a ``byte`` field).
OK = 0
WARN = 1
ERROR = 2
STALE = 3


@dataclass(frozen=True)
class Status:
    """One DiagnosticStatus as plain data: level, name, message, hardware_id, key/values."""

    level: int
    name: str
    message: str
    hardware_id: str
    values: list[tuple[str, str]]


VERDICT_NAME = "ads_rca/verdict"
WARNING_NAME = "ads_rca/collision_warning"


def status_name(module: str) -> str:
    return f"ads_rca/{module}"


def internal_error_head(module: str) -> str:
    """How the live outputs name a module's internal error (a bug in our code): its status
    message and the monitor's logged traceback, which ``replay`` finds by it."""
    return f"internal error in the {module} check"


def heartbeat_name(module: str) -> str:
    """The status a monitor sends periodically to say it is alive."""
    return f"{status_name(module)}/monitor"


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


def flatten(values: Mapping[str, Any], prefix: str = "") -> list[tuple[str, str]]:
    """Key/values, dicts flattened to ``a.b`` keys (lists stay JSON text)."""
    out: list[tuple[str, str]] = []
    for key, value in values.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping) and value:
            out.extend(flatten(value, f"{name}."))
        else:
            out.append((name, text(value)))
    return out


def batch_status(results: Sequence[LiveResult], semantics: str, hardware_id: str) -> Status:
    """One module's judged batch as one status: its latest (last judged) frame, as
    :func:`result_status`, plus ``judged_since_last`` and ``failed_since_last`` (the
    batch's frames), and the failures in the message when the latest frame passed."""
    latest = results[-1]
    failed = sum(r.result.failed for r in results)
    status = result_status(latest, semantics, hardware_id)
    message = status.message
    if failed and not latest.result.failed:
        message += f" ({failed} of {len(results)} frames since the last status failed)"
    level = status.level
    raised = next((r for r in results if r.result.internal_error), None)
    if raised is not None and not latest.result.internal_error:  # never hidden by a pass
        level = ERROR
        message += (
            f"; {internal_error_head(raised.module)} at frame {raised.frame} "
            f"({raised.result.internal_error})"
        )
    close = near_miss(results, semantics)
    if close:
        message = close if level == OK else f"{message}; {close}"
        level = max(level, WARN)
    counts = [("judged_since_last", str(len(results))), ("failed_since_last", str(failed))]
    return replace(status, level=level, message=message, values=counts + status.values)


def near_miss(results: Sequence[LiveResult], semantics: str) -> str:
    """The batch's closest near miss as a message ("" if none): a planning result judged
    without a known collision whose real clearance ``c_gt`` to its partner is finite and
    below ``safety_margin`` (the result's own threshold, else the mode's default)."""
    found: tuple[float, float, LiveResult] | None = None
    for live in results:
        r = live.result
        c_gt = r.metrics.get("c_gt")
        if r.module != "planning" or live.collision_frame >= 0 or not isinstance(c_gt, float):
            continue
        margin = r.thresholds.get("safety_margin")
        if not isinstance(margin, float):
            margin = make_params(semantics).safety_margin
        if math.isfinite(c_gt) and c_gt < margin and (found is None or c_gt < found[0]):
            found = (c_gt, margin, live)
    if found is None:
        return ""
    c_gt, margin, live = found
    partner = live.partner_id or (live.result.ids[0] if live.result.ids else "")
    return (
        f"near miss at frame {live.frame}: clearance {c_gt:.2f} m to actor "
        f"{shown_id(partner)} below safety_margin {margin} m"
    )


@dataclass(frozen=True)
class CollisionWarning:
    """A frame at which an actor, kept at its velocity, meets the ego (kept at its speed)
    within ``event_ttc_s``, or is within ``event_clearance`` of it."""

    stamp_ms: int
    frame: int
    clearance_m: float
    ttc_s: float  # inf: no contact within event_ttc_s (the clearance made it one)
    actor: str


def collision_warning(
    found: Sequence[CollisionWarning], ttc_limit_s: float, hardware_id: str, run: str = ""
) -> Status | None:
    """The most imminent of ``found`` (the least time to collision, then the least
    clearance) as a WARN status of its own, ``ads_rca/collision_warning``; None if none."""
    if not found:
        return None
    w = min(found, key=lambda x: (x.ttc_s, x.clearance_m, x.stamp_ms))
    actor = shown_id(w.actor)
    if math.isfinite(w.ttc_s):
        message = (
            f"collision predicted in {w.ttc_s:.2f} s with actor {actor} at frame {w.frame} "
            f"(event_ttc_s {ttc_limit_s:g} s)"
        )
    else:
        message = f"actor {actor} {w.clearance_m:.2f} m from the ego at frame {w.frame}"
    values = [
        ("frame", str(w.frame)),
        ("stamp_ms", str(w.stamp_ms)),
        ("ttc_s", f"{w.ttc_s:.3f}"),
        ("clearance_m", f"{w.clearance_m:.3f}"),
        ("actor", actor),
        ("event_ttc_s", f"{ttc_limit_s:g}"),
        *([(RUN_KEY, run)] if run else []),
    ]
    return Status(WARN, WARNING_NAME, message, hardware_id, values)


def result_status(live: LiveResult, semantics: str, hardware_id: str) -> Status:
    """One judged frame: ERROR failed, STALE when the run has no data for the module (its
    inputs are absent: never OK), WARN skipped or judged with incomplete inputs, else OK."""
    r = live.result
    if r.internal_error:
        level = ERROR
        message = f"frame {live.frame}: {internal_error_head(r.module)} ({r.internal_error})"
    elif r.failed:
        level, message = ERROR, f"frame {live.frame}: {r.module} failed"
    elif r.skipped and r.skipped.startswith(NOT_JUDGED) and (scored := scored_status(r)):
        level = OK  # not judged, but a scorer scored what the run holds for the module
        message = f"frame {live.frame}: {scored}; the verdict rule: {r.skipped}"
    elif r.skipped and r.skipped.startswith(NOT_JUDGED):
        level, message = STALE, f"frame {live.frame}: no data: {r.skipped}"
    elif r.skipped or live.incomplete or r.missing_input:
        level = WARN
        message = f"frame {live.frame}: " + (
            f"check skipped: {r.skipped}" if r.skipped else "judged with incomplete inputs"
        )
    else:
        level, message = OK, f"frame {live.frame}: ok"
    if live.provisional:
        message += (
            f" (provisional: judged against actor {live.partner_id}, the most threatening, "
            "before the collision frame arrived)"
        )
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
        **({"provisional": True} if live.provisional else {}),
    }
    if live.run:
        head[RUN_KEY] = live.run
    values = flatten(head) + flatten(r.metrics, "metric.") + flatten(r.thresholds, "threshold.")
    return Status(level, status_name(r.module), message, hardware_id, values)


def simple_status(
    name: str, level: int, message: str, hardware_id: str, values: Mapping[str, Any]
) -> Status:
    return Status(level, name, message, hardware_id, flatten(values))


def verdict_status(document: Mapping[str, Any], hardware_id: str) -> Status:
    """The verdict (docs/verdicts.md): ERROR naming the primary root cause or an internal
    error, WARN when inconclusive without one, OK only for a conclusive "no fault found"."""
    primary = document.get("primary_root_cause")
    found = bool(primary or document.get("internal_errors"))
    level = ERROR if found else (OK if document.get("conclusive") is True else WARN)
    message = f"root cause: {document.get('verdict')}" if primary else str(document["verdict"])
    head = {
        k: document.get(k)
        for k in (
            "semantics",
            "conclusive",
            "collision",
            "primary_root_cause",
            "contributing",
            "root_causes",
            "attribution_basis",
            "reason",
            "collision_frame",
            "effect_window",
            "partner_id",
            "ego_id",
            "verdict_latency_s",
            "why_inconclusive",
        )
    }
    live = document.get("live") or {}
    head["complete"] = live.get("complete")
    for key in ("episode", "collision_number"):  # stack mode: which episode, which crash
        if key in live:
            head[key] = live[key]
    if live.get(RUN_KEY):
        head[RUN_KEY] = live[RUN_KEY]
    modules = {m: dict(v) for m, v in (document.get("modules") or {}).items()}
    values = flatten(head) + flatten(modules, "modules.")
    values += flatten(document.get("evidence") or {}, "evidence.")
    return Status(level, VERDICT_NAME, message, hardware_id, values)


def encode_array(stamp_ns: int, statuses: list[Status]) -> bytes:
    """A DiagnosticArray as CDR bytes (header frame_id "", as
    :func:`ads_rca.ros.diagnostics.array` builds it)."""
    w = CdrWriter()
    w.stamp(*divmod(stamp_ns, 1_000_000_000))
    w.string("")
    w.u32(len(statuses))
    for status in statuses:
        w.buffer.append(status.level)
        for field in (status.name, status.message, status.hardware_id):
            w.string(field)
        w.u32(len(status.values))
        for key, value in status.values:
            w.string(key)
            w.string(value)
    return w.getvalue()


def status_names(data: bytes) -> list[str]:
    """The status names of a DiagnosticArray in CDR bytes (what heartbeat watching needs),
    without building the message; [] for bytes that are not one."""
    return [name for name, _run in status_runs(data)]


def status_runs(data: bytes) -> list[tuple[str, str]]:
    """(name, value of its ``run`` key or "") per status of a DiagnosticArray in CDR bytes,
    without building the message; [] for bytes that are not one."""
    try:
        reader = CdrReader(data)
        reader.skip_header()
        out = []
        for _ in range(reader.u32()):
            reader.position += 1  # level
            name = reader.string()
            reader.skip_string()  # message
            reader.skip_string()  # hardware_id
            run = ""
            for _ in range(reader.u32()):
                key = reader.string()
                if key == RUN_KEY:
                    run = reader.string()
                else:
                    reader.skip_string()
            out.append((name, run))
        return out
    except (CdrError, IndexError, struct.error, UnicodeDecodeError):
        return []
