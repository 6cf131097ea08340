"""Why two modes' verdicts on one log differ, in one line.

``diagnose --semantics both`` judges a log in every mode. The verdicts often differ (the
modes judge with different rules and windows), and the first question is then which module
made the difference and what the other mode saw of it. The answer is read from the modes'
JSON documents, as the summary is, and from each mode's own short statement of its rules
(``Semantics.rules``), quoted where a mode finds no failure at all.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from ads_rca.diagnosis.verdict import MODULES, Module
from ads_rca.oracles.semantics import MODES, semantics_for

Document = Mapping[str, Any]


def why_modes_differ(documents: Sequence[Document]) -> str:
    """One line: the shared verdict, or per module that one mode blames and another does
    not, what each counted; when both blame the same modules, how they rank them."""
    verdicts = {str(d.get("verdict")) for d in documents}
    if len(verdicts) == 1:
        return f"the modes agree: {verdicts.pop()}"
    reasons = [_module_reason(documents, module) for module in MODULES]
    found = [r for r in reasons if r]
    if not found:  # the same modules blamed, ranked differently
        found = [
            f"{_name(d)} names {d.get('primary_root_cause') or 'none'} primary "
            f"({d.get('attribution_basis')})"
            for d in documents
        ]
    return "why the modes differ: " + "; ".join(found)


def _module_reason(documents: Sequence[Document], module: Module) -> str:
    blame = [module in (d.get("root_causes") or []) for d in documents]
    if all(blame) or not any(blame):
        return ""
    said = [_counted(d, module) for d, blamed in zip(documents, blame, strict=True) if blamed]
    said += [
        _not_counted(d, module) for d, blamed in zip(documents, blame, strict=True) if not blamed
    ]
    return f"{module}: " + ", ".join(said)


def _counted(document: Document, module: Module) -> str:
    counts = document["modules"][module]
    if not counts["collision"]:  # blamed on another basis (a fallback)
        return f"{_name(document)} blames it ({document.get('attribution_basis')})"
    return f"{_name(document)} counts {_frames(counts['collision'])} in its window"


def _not_counted(document: Document, module: Module) -> str:
    counts = document["modules"][module]
    if counts["collision"]:
        return f"{_name(document)} counts {_frames(counts['collision'])} but blames others"
    if not counts["safe"]:
        rule = _rule(document, module)
        return f"{_name(document)} finds no failure" + (f" (its rule: {rule})" if rule else "")
    return (
        f"{_name(document)} counts none of its {_frames(counts['safe'])} "
        f"(window: {document.get('window_frames')} frames)"
    )


def _rule(document: Document, module: Module) -> str:
    name = document.get("semantics")
    if not isinstance(name, str) or name not in MODES:
        return ""
    return semantics_for(name).rules.get(module, "")


def _frames(count: int) -> str:
    return f"{count} failing frame" + ("" if count == 1 else "s")


def _name(document: Document) -> str:
    return str(document.get("semantics"))
