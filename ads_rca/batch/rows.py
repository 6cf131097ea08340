"""One flat row per run: the columns of ``results.csv`` / ``results.parquet``.

A row is built from the ``diagnose --json`` document of the run (the same contract, so a
batch row and ``ads-rca diagnose`` never disagree), or stands for a run that could not be
diagnosed: then ``error`` says why and the verdict columns are empty. A run whose diagnosis
hit an internal error (our own code raised: docs/verdicts.md) keeps its verdict columns but
is no clean row: ``internal_error`` names the bug and ``error`` is set too, so a run counts
as failed exactly when ``error`` is set, as ``diagnose`` exits non-zero for it.
:data:`COLUMNS` fixes every column's name and type, the same in every row, part and file.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from ads_rca.oracles.base import MODULES
from ads_rca.oracles.semantics import semantics_for
from ads_rca.params import Params
from ads_rca.sources.registry import SOURCES, listed, source_named

#: Column types: "str", "int" (nullable), "float" (NaN when unknown), "bool" (nullable).
STR, INT, FLOAT, BOOL = "str", "int", "float", "bool"
#: ``error`` of a run whose diagnosis raised in our own code starts with it.
INTERNAL_ERROR = "internal error"

#: (name, type, meaning), in the files' order.
COLUMN_DOCS: tuple[tuple[str, str, str], ...] = (
    ("run_id", STR, "stable id: SHA-256 of the resolved path, 16 hex digits"),
    ("path", STR, "the run's resolved path"),
    ("format", STR, listed([source_named(name).words for name in SOURCES], "or")),
    ("profile", STR, "the bag profile read through (bags only)"),
    ("semantics", STR, "oracle semantics"),
    ("scenario", STR, "scenario family (metadata synthesis.scenario), when known"),
    ("injected_fault", STR, "the synthesiser's injected fault, when known"),
    ("collision_frame", INT, "frame of the collision (-1: none or unknown)"),
    ("collision", STR, "whether the run collided: yes, no or unknown (no collision source)"),
    ("primary_root_cause", STR, "the module blamed first ('' when none)"),
    ("root_causes", STR, "every root cause, ';'-separated"),
    ("contributing", STR, "contributing modules, ';'-separated"),
    ("attribution_basis", STR, "how the verdict was reached"),
    ("verdict", STR, "the verdict sentence"),
    ("conclusive", BOOL, "the evidence let the verdict conclude (empty: no verdict)"),
    ("why_inconclusive", STR, "why it could not, '; '-separated ('' when conclusive)"),
    *(
        column
        for m in MODULES
        for column in (
            (f"{m}_collision", INT, f"{m}: failures in the effect window"),
            (f"{m}_safe", INT, f"{m}: failures outside it"),
            (f"{m}_first_failure", INT, f"{m}: first failing frame (empty: none)"),
            (f"{m}_metric", STR, f"{m}: the headline metric of the mode"),
            (f"{m}_metric_min", FLOAT, f"{m}: its smallest finite value over the frames"),
            (f"{m}_metric_max", FLOAT, f"{m}: its largest finite value over the frames"),
        )
    ),
    ("frames", INT, "frames judged"),
    ("window_frames", INT, "frames in the effect window"),
    ("input_problems", INT, "input problems the reader reported"),
    ("diagnose_seconds", FLOAT, "wall time of reading and judging the run"),
    ("worker", STR, "host:pid of the process that diagnosed it"),
    ("error", STR, "why the run failed: no verdict, or an internal error ('' when none)"),
    ("internal_error", STR, "our own code raised: per module, its error, first frame, count"),
)
COLUMNS: tuple[str, ...] = tuple(name for name, _, _ in COLUMN_DOCS)
TYPES: dict[str, str] = {name: kind for name, kind, _ in COLUMN_DOCS}

Row = dict[str, Any]


def storable(row: Row) -> Row:
    """``row`` with every text valid UTF-8, as CSV, Parquet and HTML need: a lone surrogate
    (a file name's undecodable byte, JSON's ``"\\ud800"`` in a label) as its escape."""
    return {
        name: value.encode("utf-8", "backslashreplace").decode("utf-8")
        if isinstance(value, str)
        else value
        for name, value in row.items()
    }


def empty_row(run_id: str, path: str) -> Row:
    row: Row = {name: _missing(TYPES[name]) for name in COLUMNS}
    row.update(run_id=run_id, path=path)
    return row


def error_row(run_id: str, path: str, error: str, **known: Any) -> Row:
    """A run without a verdict: ``error`` (one line) says why."""
    row = empty_row(run_id, path)
    row.update({k: v for k, v in known.items() if k in TYPES})
    row["error"] = _one_line(_without_path(str(error), path)) or "failed"
    return row


def internal_error_row(run_id: str, path: str, error: Exception, **known: Any) -> Row:
    """A run whose diagnosis raised in our own code before any verdict: a bug in ads_rca,
    never reported as bad input."""
    text = _one_line(f"{type(error).__name__}: {error}")
    return error_row(run_id, path, f"{INTERNAL_ERROR}: {text}", internal_error=text, **known)


def _one_line(text: str) -> str:
    return " ".join(text.split())[:2000]


def _without_path(error: str, path: str) -> str:
    """The error without the run's path in front (the row's ``path`` holds it): each
    failure's path is printed once. A file inside the run keeps its relative name."""
    for lead in (f"{path}: ", f"{path}/"):
        if path and error.startswith(lead):
            return error[len(lead) :]
    return error


def internal_errors_text(document: Mapping[str, Any]) -> str:
    """``internal_errors`` of a verdict document in words: per module, its first error,
    where, and on how many frames (``''``: none)."""
    errors = document.get("internal_errors")
    if not isinstance(errors, list):
        return ""
    return _one_line(
        "; ".join(
            f"{e.get('module')}: {e.get('error')} at frame {e.get('first_frame')} "
            f"({e.get('frames')} frames)"
            if isinstance(e, Mapping)
            else str(e)
            for e in errors
        )
    )


def row_from_document(
    run_id: str,
    path: str,
    document: Mapping[str, Any],
    params: Params,
    **known: Any,
) -> Row:
    """The row of a diagnosed run, from its ``diagnose --json`` document."""
    row = empty_row(run_id, path)
    row.update({k: v for k, v in known.items() if k in TYPES})
    bug = internal_errors_text(document)
    row.update(
        semantics=str(document.get("semantics") or ""),
        collision_frame=_int(document.get("collision_frame")),
        primary_root_cause=str(document.get("primary_root_cause") or ""),
        root_causes=";".join(map(str, document.get("root_causes") or [])),
        contributing=";".join(map(str, document.get("contributing") or [])),
        attribution_basis=str(document.get("attribution_basis") or ""),
        verdict=str(document.get("verdict") or ""),
        collision=str(document.get("collision") or ""),
        # A document that does not say so never reads as conclusive (docs/verdicts.md).
        conclusive=document.get("conclusive") is True,
        why_inconclusive="; ".join(map(str, document.get("why_inconclusive") or [])),
        frames=len(document.get("frames") or []),
        window_frames=_int(document.get("window_frames")),
        input_problems=len(document.get("input_problems") or []),
        internal_error=bug,
        error=f"{INTERNAL_ERROR}: {bug}" if bug else "",
    )
    modules = document.get("modules") or {}
    frames: Sequence[Mapping[str, Any]] = document.get("frames") or []
    headlines = semantics_for(params).headline
    for m in MODULES:
        counts = modules.get(m) or {}
        row[f"{m}_collision"] = _int(counts.get("collision"))
        row[f"{m}_safe"] = _int(counts.get("safe"))
        row[f"{m}_first_failure"] = _int(counts.get("first_failure_frame"))
        key = _headline_key(m, headlines.get(m, ()), frames)
        if key is not None:
            values = [
                float(v)
                for f in frames
                if isinstance(v := (f.get(m) or {}).get(key), (int, float))
                and not isinstance(v, bool)
                and math.isfinite(v)
            ]
            row[f"{m}_metric"] = key
            row[f"{m}_metric_min"] = min(values) if values else math.nan
            row[f"{m}_metric_max"] = max(values) if values else math.nan
    return row


def _headline_key(module: str, headlines: Sequence[Any], frames: Sequence[Any]) -> str | None:
    """The first key of the first headline present in the run (the report's choice)."""
    for headline in headlines:
        first = headline.keys[0]
        if any(first in (f.get(module) or {}) for f in frames):
            return str(first)
    return None


def _int(value: Any) -> int | None:
    return value if isinstance(value, int) and not isinstance(value, bool) else None


def _missing(kind: str) -> Any:
    return math.nan if kind == FLOAT else ("" if kind == STR else None)


#: A bool column's CSV cells.
_BOOL_TEXT = {True: "true", False: "false"}


def from_text(name: str, text: str) -> Any:
    """A CSV cell back to its column's type (``--resume`` reads the CSV)."""
    kind = TYPES[name]
    if kind == STR:
        return text
    if text == "":
        return _missing(kind)
    if kind == BOOL:
        if text not in ("true", "false"):
            raise ValueError(f"{name}: {text!r} is not true or false")
        return text == "true"
    return int(text) if kind == INT else float(text)


def to_text(name: str, value: Any) -> str:
    """A value as its CSV cell (empty for a missing number or bool)."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    if isinstance(value, bool):
        return _BOOL_TEXT[value]
    return repr(value) if isinstance(value, float) else str(value)
