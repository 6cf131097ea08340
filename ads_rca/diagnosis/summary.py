"""The short human summary of a verdict, rendered from the JSON contract.

``diagnose`` and ``replay`` both print this, from the same document they write with
``--json``, so the offline and live outputs read the same.
"""

from __future__ import annotations

from typing import Any

from ads_rca.capabilities import JUDGED
from ads_rca.diagnosis.conclusion import COLLISION_UNKNOWN_STATE
from ads_rca.foundation.text import printable
from ads_rca.oracles.base import MODULES
from ads_rca.oracles.semantics import MODES, Semantics, semantics_for
from ads_rca.problems import Problem, ProblemLog
from ads_rca.sources.atmacup.trajectory_scores import TRAJECTORY_SCORES_KEY
from ads_rca.sources.carla.annotations import annotations_from_document
from ads_rca.sources.carla.figures import FIGURE_KEYS, figures_from_document
from ads_rca.sources.openlane.run_scores import OPENLANE_SCORES_KEY
from ads_rca.sources.openlane.run_scores import summary_lines as openlane_lines
from ads_rca.sources.predictor.scores import MISS_M, SCORES_KEY


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
    lines.extend(run_notes_lines(document))
    problems = ProblemLog(Problem.from_dict(p) for p in document.get("input_problems") or [])
    lines.append(f"input problems: {len(problems)}")
    lines.extend(f"  {line}" for line in problems.summary_lines(max_problems))
    return "\n".join(printable(line) for line in lines)


def run_notes_lines(document: dict[str, Any], shown: int = 10) -> list[str]:
    """The run's own figures and annotations (a CARLA run's) and a predictor's scores, when
    it has any."""
    lines: list[str] = []
    scores = document.get(SCORES_KEY)
    if isinstance(scores, dict) and scores.get("scored"):
        lines.append(
            f"prediction scores ({scores['scored']} tracks against the realised future): "
            + _score_text(scores)
        )
        by_type = scores.get("by_type")
        for kind, row in (by_type if isinstance(by_type, dict) else {}).items():
            if isinstance(row, dict):
                lines.append(f"  {kind}: {row.get('scored')} tracks, {_score_text(row)}")
    lines.extend(trajectory_lines(document.get(TRAJECTORY_SCORES_KEY), shown))
    lines.extend(openlane_lines(document.get(OPENLANE_SCORES_KEY)))
    figures = figures_from_document(document)
    if figures:
        values = ", ".join(f"{k}={_short(figures[k])}" for k in FIGURE_KEYS)
        lines.append(f"run figures: {values}")
    annotations = annotations_from_document(document)
    if annotations:
        lines.append(f"annotations ({len(annotations)}; events, not collisions):")
        lines.extend(f"  {a.line()}" for a in annotations[:shown])
        if len(annotations) > shown:
            lines.append(f"  ... {len(annotations) - shown} more")
    return lines


def trajectory_lines(scores: object, shown: int = 10) -> list[str]:
    """A snapshot table's ego-trajectory scores (``trajectory_scores``): the competition's
    MAE, ADE and FDE, per horizon, the worst rows; or why nothing was scored."""
    if not isinstance(scores, dict):
        return []
    head = f"trajectory scores ({scores.get('scored')} of {scores.get('rows')} rows scored"
    if not scores.get("scored"):
        return [f"{head}): {scores.get('note', 'nothing scored')}"]
    lines = [
        f"{head}; {scores.get('no_truth')} without a realised path, "
        f"{scores.get('no_prediction')} without a prediction): MAE {_precise(scores.get('mae'))} "
        f"(the competition's, over x, y, z), ADE {_short(scores.get('ade'))} m, "
        f"FDE {_short(scores.get('fde'))} m (3-D)"
    ]
    horizons = scores.get("by_horizon")
    if isinstance(horizons, list):
        lines.append(
            "  by horizon (mean distance): "
            + ", ".join(
                f"{_short(h.get('horizon_s'))} s {_short(h.get('distance'))} m"
                for h in horizons
                if isinstance(h, dict)
            )
        )
    worst = scores.get("worst_rows")
    if isinstance(worst, list) and worst:
        lines.append("  worst rows by ADE:")
        lines.extend(
            f"    {row.get('id')}: ADE {_short(row.get('ade'))} m, FDE "
            f"{_short(row.get('fde'))} m, MAE {_short(row.get('mae'))}"
            for row in worst[:shown]
            if isinstance(row, dict)
        )
    return lines


def _precise(value: object) -> str:
    return f"{value:.6g}" if isinstance(value, float) else _short(value)


def _score_text(row: dict[str, Any]) -> str:
    return (
        f"ADE {_short(row.get('ade'))} m, FDE {_short(row.get('fde'))} m, "
        f"miss rate {_short(row.get('miss_rate'))} (FDE > {MISS_M:g} m)"
    )


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
            items.append(f"{prefix}{key}={_short(value)}")
    return items


def _short(value: object) -> str:
    if isinstance(value, float):
        return f"{value:.3g}"
    text = str(value)
    return text if len(text) <= 60 else text[:57] + "..."
