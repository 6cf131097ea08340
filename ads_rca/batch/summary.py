"""What a finished batch says: the printed and the self-contained HTML summary.

Both are built from the rows alone (:mod:`ads_rca.batch.rows`), so a resumed batch summarises
its old rows and new ones alike. Following docs/verdicts.md, an inconclusive verdict is
counted on its own and never as "no fault found", and a run whose diagnosis hit an internal
error counts as failed. The HTML page follows the run report's rules
(:mod:`ads_rca.report.html`): one file, figures as embedded PNGs, every text from a row
escaped by construction, no script and no link.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ads_rca.batch.rows import Row
from ads_rca.foundation.atomic_write import replace_text
from ads_rca.foundation.text import printable
from ads_rca.oracles.base import MODULES

#: A conclusive verdict without a root cause: no collision, or no module failed.
NONE = "(no fault found)"
#: A verdict without a root cause that could not conclude: never "no fault found".
INCONCLUSIVE = "(inconclusive)"
#: Failures and slowest runs listed.
LISTED = 10
FAILED = "(failed)"
#: How to see an internal error's traceback (a batch row holds one line).
INTERNAL_HINT = "a bug in ads_rca, not in the input: `ads-rca diagnose PATH` prints its traceback"


def cause(row: Row) -> str:
    """The row's place in the root-cause counts."""
    if row["error"]:
        return FAILED
    if row["primary_root_cause"]:
        return str(row["primary_root_cause"])
    return NONE if row["conclusive"] is True else INCONCLUSIVE


@dataclass(frozen=True)
class Counts:
    """How a batch's runs ended: what both summaries say and the exit status reads."""

    runs: int
    diagnosed: int
    inconclusive: int
    failed: int
    internal_errors: int

    @classmethod
    def of(cls, rows: Sequence[Row]) -> Counts:
        diagnosed = [r for r in rows if not r["error"]]
        return cls(
            runs=len(rows),
            diagnosed=len(diagnosed),
            # A row that does not say conclusive (None) is not.
            inconclusive=sum(r["conclusive"] is not True for r in diagnosed),
            failed=len(rows) - len(diagnosed),
            internal_errors=sum(bool(r["internal_error"]) for r in rows),
        )

    def lines(self) -> list[str]:
        """The counts in words: runs, diagnosed, failed, then what each holds."""
        lines = [f"{self.runs} runs, {self.diagnosed} diagnosed, {self.failed} failed"]
        if self.diagnosed:
            conclusive = self.diagnosed - self.inconclusive
            lines.append(
                f"of the diagnosed: {conclusive} conclusive, {self.inconclusive} inconclusive"
            )
        if self.internal_errors:
            lines.append(
                f"of the failed: {self.internal_errors} by an internal error ({INTERNAL_HINT})"
            )
        return lines


def summary_text(rows: Sequence[Row], out: str = "", interrupted: bool = False) -> str:
    """Counts by root cause, by scenario family when known, and the failures."""
    failed = [r for r in rows if r["error"]]
    state = "interrupted" if interrupted else "done"
    first, *more = Counts.of(rows).lines()
    lines = [f"batch {state}: {first}" + (f" ({out})" if out else "")]
    lines.extend(f"  {line}" for line in more)
    causes = Counter(cause(r) for r in rows)
    width = max(len(name) for name in causes) + 2 if causes else 14
    lines.append("by primary root cause:")
    lines.extend(f"  {name:<{width}}{count:>7}" for name, count in _ordered(causes))
    families = sorted({str(r["scenario"]) for r in rows if r["scenario"]})
    if families:
        columns = [c for c, _ in _ordered(causes)]
        column = max(13, width)
        lines.append("by scenario family:")
        lines.append(f"  {'scenario':<22}{'runs':>6}" + "".join(f"{c:>{column}}" for c in columns))
        for family in families:
            of = [r for r in rows if r["scenario"] == family]
            counts = Counter(cause(r) for r in of)
            lines.append(
                f"  {family[:21]:<22}{len(of):>6}"
                + "".join(f"{counts[c]:>{column}}" for c in columns)
            )
    if failed:
        lines.append(f"failures ({len(failed)}):")
        lines.extend(f"  {r['run_id']} {r['path']}: {r['error']}" for r in failed[:LISTED])
        if len(failed) > LISTED:
            lines.append(f"  ... {len(failed) - LISTED} more in the results")
    return "\n".join(printable(line) for line in lines)


def _ordered(counts: Counter[str]) -> list[tuple[str, int]]:
    order = {name: i for i, name in enumerate((*MODULES, NONE, INCONCLUSIVE, FAILED))}
    return sorted(counts.items(), key=lambda item: (order.get(item[0], -1), item[0]))


def _numbers(rows: Sequence[Row], column: str) -> list[float]:
    values = [r[column] for r in rows if isinstance(r[column], int | float)]
    return [float(v) for v in values if math.isfinite(v) and abs(v) < 1e15]


def write_html(rows: Sequence[Row], path: Path, title: str = "") -> None:
    """The HTML summary of ``rows`` (see the module docstring), replacing ``path`` whole."""
    # A lone surrogate from a log (JSON's "\ud800") cannot be UTF-8: written as its escape.
    replace_text(path, render_html(rows, title), errors="backslashreplace")


def render_html(rows: Sequence[Row], title: str = "") -> str:
    import matplotlib.pyplot as plt

    from ads_rca.report.figures import plot_text, png_base64
    from ads_rca.report.html import _CSS, Html, el

    def image(fig: Any, alt: str) -> Html:
        return el("img", alt=alt, src=f"data:image/png;base64,{png_base64(fig)}")

    causes = _ordered(Counter(cause(r) for r in rows))
    fig, ax = plt.subplots(figsize=(6, 3))
    ax.bar([plot_text(c) for c, _ in causes], [n for _, n in causes], color="#4477aa")
    ax.set_ylabel("runs")
    ax.set_title("primary root cause")
    fig.tight_layout()
    figures = [el("figure", el("figcaption", "Root-cause distribution"), image(fig, "root causes"))]
    metric_columns = ["diagnose_seconds", *(f"{m}_metric_min" for m in MODULES)]
    for column in metric_columns:
        values = _numbers(rows, column)
        if not values:
            continue
        names = sorted(
            {
                str(r[column.replace("_min", "")])
                for r in rows
                if column != "diagnose_seconds" and r[column.replace("_min", "")]
            }
        )
        label = column if column == "diagnose_seconds" else f"{column} ({', '.join(names)})"
        fig, ax = plt.subplots(figsize=(4.5, 3))
        ax.hist(values, bins=min(30, max(5, len(values) // 5)), color="#66aa55")
        ax.set_xlabel(plot_text(label))
        ax.set_ylabel("runs")
        fig.tight_layout()
        figures.append(el("figure", el("figcaption", label), image(fig, label)))

    def table(head: Sequence[str], body: Sequence[Sequence[Any]]) -> Html:
        return el(
            "table",
            el("tr", *(el("th", h) for h in head)),
            *(el("tr", *(el("td", "" if v is None else v) for v in line)) for line in body),
        )

    failed = [r for r in rows if r["error"]]
    inconclusive = [r for r in rows if not r["error"] and r["conclusive"] is not True]
    slow = sorted(rows, key=lambda r: -(_numbers([r], "diagnose_seconds") or [0.0])[0])[:LISTED]
    families = sorted({str(r["scenario"]) for r in rows if r["scenario"]})
    cause_names = [c for c, _ in causes]
    by_family = [
        [f, sum(r["scenario"] == f for r in rows)]
        + [sum(r["scenario"] == f and cause(r) == c for r in rows) for c in cause_names]
        for f in families
    ]
    body = [
        el("h1", "Batch diagnosis", f": {title}" if title else ""),
        *(el("p", line) for line in Counts.of(rows).lines()),
        el("h2", "By primary root cause"),
        table(["root cause", "runs"], causes),
        *(
            [el("h2", "By scenario family"), table(["scenario", "runs", *cause_names], by_family)]
            if families
            else []
        ),
        el("h2", "Plots"),
        el("div", *figures, class_="scenes"),
        el("h2", f"Slowest runs ({len(slow)})"),
        table(
            ["run id", "path", "seconds", "frames", "error"],
            [
                [r["run_id"], r["path"], f"{r['diagnose_seconds']:.2f}", r["frames"], r["error"]]
                for r in slow
            ],
        ),
        el("h2", f"Inconclusive verdicts ({len(inconclusive)})"),
        table(
            ["run id", "path", "verdict", "why inconclusive"],
            [[r["run_id"], r["path"], r["verdict"], r["why_inconclusive"]] for r in inconclusive],
        ),
        el("h2", f"Failures ({len(failed)})"),
        table(["run id", "path", "error"], [[r["run_id"], r["path"], r["error"]] for r in failed]),
    ]
    head = el(
        "head",
        el("meta", charset="utf-8"),
        el("title", "ads_rca batch", f": {title}" if title else ""),
        el("style", Html(_CSS)),
    )
    return f"<!doctype html>\n{el('html', head, el('body', *body))}\n"
