"""The short human summary of a verdict, rendered from the JSON contract.

``diagnose`` and ``replay`` both print this, from the same document they write with
``--json``, so the offline and live outputs read the same.
"""

from __future__ import annotations

from typing import Any

from ads_rca.capabilities import JUDGED
from ads_rca.diagnosis.conclusion import COLLISION_UNKNOWN_STATE
from ads_rca.diagnosis.critical_event import CriticalEvent
from ads_rca.foundation.text import printable, short
from ads_rca.oracles.base import MODULES
from ads_rca.oracles.semantics import MODES, Semantics, semantics_for
from ads_rca.problems import Problem, ProblemLog
from ads_rca.sources.registry import scores_summary_lines


def collision_text(collision_frame: int, known: bool = True) -> str:
    """How the summary and the report name the run's collision frame: -1 is none (unknown
    when the run has no collision source: never "no collision" then), a frame below it is
    before the run (the reference counts every failure as a collision then)."""
    if collision_frame >= 0:
        return f"collision at frame {collision_frame}"
    if collision_frame < -1:
        return f"collision frame {collision_frame}: before the run"
    return "no collision in this run" if known else "collision unknown"


def summary_text(document: dict[str, Any], max_problems: int = 10, how: str = "judged") -> str:
    """Counts per module, the verdict with evidence, and the input problems.

    Each line is made printable on its own (source, ids, evidence come from the log), so no
    text from the log can start a line of its own or drive the terminal.
    """
    lines = [
        f"{document.get('source')}: {len(document.get('frames') or [])} frames {how}, "
        f"semantics {document.get('semantics')}"
    ]
    collision = document.get("collision_frame", -1)
    collision = collision if isinstance(collision, int) else -1
    partner = document.get("partner_id")
    text = collision_text(collision, document.get("collision") != COLLISION_UNKNOWN_STATE)
    lines.append(f"{text} with actor {partner}" if partner and collision >= 0 else text)
    lines.extend(event_lines(document, max_problems))
    lines.append(window_text(document.get("effect_window")))
    (counted, other), legend = count_columns(document.get("semantics"))
    lines.append(f"{'module':<12}{counted:>10}{other:>7}  first failure")
    judged = document.get("modules_judged") or {}
    for module in MODULES:
        counts = document["modules"][module]
        first = counts.get("first_failure_frame")
        shown = "-" if first is None else f"frame {first}"
        status = judged.get(module, JUDGED)
        if status != JUDGED:
            shown = str(status)
        lines.append(f"{module:<12}{counts['collision']:>10}{counts['safe']:>7}  {shown}")
    if legend:
        lines.append(legend)
    lines.append(f"verdict: {document.get('verdict')}  [{document.get('attribution_basis')}]")
    why = document.get("why_inconclusive")
    if isinstance(why, list) and why:
        lines.append("  inconclusive because:")
        lines.extend(f"    {reason}" for reason in why[:max_problems])
        if len(why) > max_problems:
            lines.append(f"    ... {len(why) - max_problems} more")
    evidence = document.get("evidence") or {}
    lines.extend(
        f"  {module}: " + ", ".join(_flat(evidence[module])[:10])
        for module in document.get("root_causes") or []
        if evidence.get(module)
    )
    lines.extend(scores_summary_lines(document))
    problems = ProblemLog(Problem.from_dict(p) for p in document.get("input_problems") or [])
    lines.append(f"input problems: {len(problems)}")
    lines.extend(f"  {line}" for line in problems.summary_lines(max_problems))
    return "\n".join(printable(line) for line in lines)


def event_lines(document: dict[str, Any], max_events: int = 10) -> list[str]:
    """The critical event explained and every event found, each with its time (none when
    the run knew its collision: no event was looked for)."""
    if "events_found" not in document:
        return []
    lines = []
    event = CriticalEvent.from_dict(document.get("event"))
    if event is not None:
        lines.append(f"critical event: {event.label}: {event.what}")
    found = [e for e in map(CriticalEvent.from_dict, document.get("events_found") or []) if e]
    lines.append(f"events found: {len(found)}")
    lines.extend(f"  {e.label}: {e.what}" for e in found[:max_events])
    if len(found) > max_events:
        lines.append(f"  ... {len(found) - max_events} more")
    return lines


def window_text(window: Any) -> str:
    """``effect window: 20 frames (1000 ms) = max(...); counts frames ...``."""
    if not isinstance(window, dict):
        return "effect window: unknown"
    return (
        f"effect window: {window.get('frames')} frames ({window.get('ms')} ms) = "
        f"{window.get('rule')}; counts {window.get('counts')}"
    )


def count_columns(semantics: object) -> tuple[tuple[str, str], str]:
    """The mode's names for the two counts, and what they mean (the JSON keys for a
    document of no known mode)."""
    mode = semantics_for(semantics) if isinstance(semantics, str) and semantics in MODES else None
    found = mode or Semantics
    return found.count_columns, found.count_legend


def _flat(values: dict[str, Any], prefix: str = "") -> list[str]:
    """``key=value`` items, nested dicts flattened with dotted keys."""
    items: list[str] = []
    for key, value in values.items():
        if isinstance(value, dict):
            items.extend(_flat(value, f"{prefix}{key}."))
        else:
            items.append(f"{prefix}{key}={short(value)}")
    return items
