"""A self-contained HTML report of a diagnosis, for the engineer debugging the crash.

The page: the verdict and per-module counts; the bird's-eye scene at the primary module's
first failure and at the collision; the evidence of each blamed module as tables; the
modules' headline metrics over time, with a note for every series that ends early and why;
the thresholds and the input problems. Figures come from :mod:`ads_rca.report.figures` as
base64 PNG, so the page is one file that opens anywhere, offline: no script, no link, no
external URL, and no text of a log ever becomes SVG markup.

Everything in a log is untrusted (ids, keys, file names, metadata, the folder's own path):
the page is built only with :func:`el`, which escapes every child and attribute value that
is not itself :class:`Html` it built, so text from a log can only ever be a text node.
"""

from __future__ import annotations

import html
import math
import re
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from matplotlib.figure import Figure

from ads_rca.capabilities import JUDGED
from ads_rca.diagnosis.conclusion import COLLISION_UNKNOWN_STATE
from ads_rca.diagnosis.engine import Diagnosis
from ads_rca.diagnosis.summary import collision_text, window_text
from ads_rca.foundation.atomic_write import replace_text
from ads_rca.oracles.base import MODULES
from ads_rca.report.figures import (
    Skipped,
    frame_text,
    metrics_figure,
    png_base64,
    scene_figure,
    scene_frames,
    series_ends,
)
from ads_rca.sources.carla.annotations import annotations_from_document
from ads_rca.sources.carla.figures import figures_from_document

#: Nested evidence deeper than this is shown as text, not as tables within tables.
TABLE_DEPTH = 3
#: Longest list shown item by item in an evidence cell.
LIST_ITEMS = 20

_CSS = """
body { font-family: sans-serif; margin: 2em; max-width: 90em; color: #222; }
table { border-collapse: collapse; margin: 0.3em 0; }
td, th { border: 1px solid #ccc; padding: 2px 8px; text-align: left; vertical-align: top; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
table table { margin: 0; font-size: 0.95em; }
.verdict { font-size: 1.4em; font-weight: bold; }
.scenes { display: flex; flex-wrap: wrap; gap: 1em; }
figure { margin: 0; } figcaption { font-weight: bold; margin-bottom: 0.3em; }
img { max-width: 100%; height: auto; }
.note { color: #555; }
"""


# --- HTML: escaping is the default ---------------------------------------------------------


class Html(str):
    """Markup this module built (its own tags, escaped text): the only text joined unescaped."""

    __slots__ = ()


_VOID = frozenset({"meta", "img", "br"})
_NAME = re.compile(r"^[a-z][a-z0-9-]*$")


def el(tag: str, *children: object, **attrs: object) -> Html:
    """An element: ``children`` are escaped text unless :class:`Html`, attribute values always
    escaped (``class_`` → ``class``). Tag and attribute names come from this module only."""
    names = [tag, *(name.rstrip("_") for name in attrs)]
    if not all(_NAME.match(name) for name in names):
        raise ValueError(f"not an HTML name: {names}")
    attributes = "".join(
        f' {name.rstrip("_")}="{html.escape(_text(value), quote=True)}"'
        for name, value in attrs.items()
    )
    if tag in _VOID:
        return Html(f"<{tag}{attributes}>")
    return Html(f"<{tag}{attributes}>{join(children)}</{tag}>")


def join(children: Iterable[object]) -> Html:
    """Concatenate nodes: :class:`Html` as is, anything else as escaped text."""
    return Html(
        "".join(c if isinstance(c, Html) else html.escape(_text(c), quote=True) for c in children)
    )


# --- the page ------------------------------------------------------------------------------


def write_report(result: Diagnosis, path: Path) -> None:
    """The report at ``path``, replacing it whole (an earlier one is kept if the write
    fails: :mod:`ads_rca.foundation.atomic_write`)."""
    # A lone surrogate from a log (JSON's "\ud800") cannot be UTF-8: written as its escape.
    replace_text(path, render(result), errors="backslashreplace")


def render(result: Diagnosis) -> str:
    a = result.attribution
    meta = result.log.metadata
    skipped = Skipped()
    scenes = [
        el(
            "figure",
            el("figcaption", caption.capitalize(), ", frame ", frame_text(frame)),
            _img(
                scene_figure(result, frame, skipped, caption), f"scene at frame {frame_text(frame)}"
            ),
        )
        for caption, frame in scene_frames(result)
    ]
    metrics = _img(metrics_figure(result, skipped), "metrics over time")
    ends = [end.line() for end in series_ends(result)]
    unplotted = skipped.lines()
    conclusion = result.conclusion
    rows = [_row("th", "module", "collision", "safe", "first failure")]
    rows += [
        _row("td", m, v.collision, v.safe, _first_failure(v.first_failure_frame, status))
        for m, v, status in ((m, a.modules[m], conclusion.modules.get(m, JUDGED)) for m in MODULES)
    ]
    evidence = [
        join([el("h3", m), value_table(a.modules[m].evidence or {})]) for m in a.root_causes
    ]
    body = [
        el("h1", "Root-cause analysis"),
        el(
            "p",
            result.log.source,
            " \N{EM DASH} semantics ",
            el("b", result.params.semantics),
            f", {len(result.frames)} frames judged ({result.log.frame_ms} ms each), ",
            collision_text(meta.collision_frame, conclusion.collision != COLLISION_UNKNOWN_STATE),
            ", ego ",
            result.ctx.ego_id,
            ", partner ",
            a.partner_id,
        ),
        el("p", "Verdict: ", conclusion.verdict_text(a), class_="verdict"),
        *(
            [el("p", "Inconclusive because:"), el("ul", *(el("li", r) for r in conclusion.reasons))]
            if conclusion.reasons
            else []
        ),
        el("p", "Attribution basis: ", a.attribution_basis),
        el("p", window_text(result.semantics.effect_window(result.params, result.log.frame_ms))),
        el("table", *rows),
        el("h2", "Scene from above"),
        el(
            "p",
            "Boxes are the actors' ground truth; the line from a box's centre marks its front. "
            "Predictions and the plan are those the stack logged at that frame.",
            class_="note",
        ),
        el("div", *scenes, class_="scenes") if scenes else el("p", "no frame to draw"),
        el("h2", "Evidence"),
        *(evidence or [el("p", "none")]),
        el("h2", "Metrics over time"),
        el(
            "p",
            "Per module, the metrics its oracle judges by (red crosses: failing frames; red "
            "band: the effect window before the collision).",
            class_="note",
        ),
        metrics,
        el("h3", f"Series that end early ({len(ends)})"),
        el("ul", *(el("li", line) for line in ends)),
        el("h3", f"Not plotted ({len(unplotted)})"),
        el("ul", *(el("li", line) for line in unplotted)),
        *_run_notes(result),
        el("h2", "Thresholds"),
        value_table(result.semantics.used(result.params)),
        el("h2", f"Input problems ({len(result.problems)})"),
        el("ul", *(el("li", str(p)) for p in result.problems)),
    ]
    head = el(
        "head",
        el("meta", charset="utf-8"),
        el("title", "ads_rca: ", result.log.source),
        el("style", Html(_CSS)),
    )
    return f"<!doctype html>\n{el('html', head, el('body', *body))}\n"


def _run_notes(result: Diagnosis) -> list[Html]:
    """The run's own figures and annotations (a CARLA run's), when it has any."""
    raw = result.log.metadata.raw
    out: list[Html] = []
    figures = figures_from_document(raw)
    if figures:
        out += [el("h2", "The run's own figures"), value_table(figures)]
    annotations = annotations_from_document(raw)
    if annotations:
        out += [
            el("h2", f"Annotations ({len(annotations)})"),
            el("p", "Events the run recorded (dotted lines above): not collisions.", class_="note"),
            el(
                "table",
                _row("th", "time (ms)", "kind", "text", "file"),
                *(_row("td", a.timestamp_ms, a.kind, a.text, a.source) for a in annotations),
            ),
        ]
    return out


def _img(fig: Figure, alt: str) -> Html:
    return el("img", alt=alt, src=f"data:image/png;base64,{png_base64(fig)}")


def value_table(values: Mapping[Any, Any], depth: int = 0) -> Html:
    """A key / value table; a nested mapping becomes a table in its cell."""
    return el("table", *(el("tr", el("th", k), _cell(v, depth)) for k, v in values.items()))


def _cell(value: Any, depth: int) -> Html:
    if isinstance(value, Mapping) and value and depth < TABLE_DEPTH:
        return el("td", value_table(value, depth + 1))
    if _is_number(value):
        return el("td", _text(value), class_="num")
    return el("td", _text(value))


def _first_failure(frame: int | float | None, status: str) -> object:
    """The table's last cell: the module's status when it was not fully judged."""
    return frame if status == JUDGED else status


def _row(cell: str, *values: object) -> Html:
    return el("tr", *(el(cell, v) for v in values))


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _text(value: Any, inner: bool = False) -> str:
    """A value as a reader wants it: 4 significant digits, a list as its items (an inner
    list in brackets)."""
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return f"{value:.4g}" if math.isfinite(value) else str(value)
    if isinstance(value, Mapping):
        return "{" + ", ".join(f"{_text(k)}: {_text(v, True)}" for k, v in value.items()) + "}"
    if isinstance(value, list | tuple):
        items = [_text(v, inner=True) for v in value[:LIST_ITEMS]]
        if len(value) > LIST_ITEMS:
            items.append(f"\N{HORIZONTAL ELLIPSIS} ({len(value) - LIST_ITEMS} more)")
        if inner:
            return "[" + ", ".join(items) + "]"
        return ", ".join(items) if items else "(none)"
    return str(value)
