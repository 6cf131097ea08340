"""A self-contained HTML report of a diagnosis: verdict, metric plots, a top-down scene.

Figures are drawn with matplotlib (Agg, no display needed) and embedded as base64 PNG, so
the page is one file that opens anywhere, offline, and no text of a log ever becomes SVG
markup.

Everything in a log is untrusted (ids, keys, file names, metadata, the folder's own path):

- The page is built only with :func:`el`, which escapes every child and attribute value that
  is not itself :class:`Html` it built, so text from a log can only ever be a text node.
- Numbers reach matplotlib only when finite and within ±:data:`PLOT_LIMIT`; each series says
  in the report how many points it could not draw and why.
- Strings reach matplotlib only through :func:`plot_text` (no mathtext, bounded length).
"""

from __future__ import annotations

import base64
import html
import io
import re
from collections import Counter
from collections.abc import Iterable, Mapping
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import numpy.typing as npt
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.patches import Polygon

from ads_rca.engine import Diagnosis
from ads_rca.geometry import FloatArray, box_corners, ego_to_world
from ads_rca.oracles.base import MODULES, Metric, Module, OracleResult

#: Largest magnitude drawn. Beyond it no log quantity (metres, ms, scores) means anything,
#: and near float's limit matplotlib's transforms overflow (1.7e308 fails to draw).
PLOT_LIMIT = 1e15
#: Longest text drawn in a figure (an id of a million characters would stall the layout).
PLOT_TEXT_MAX = 40

NON_FINITE = "non-finite"
OUT_OF_RANGE = f"beyond ±{PLOT_LIMIT:.0e}"

_CSS = """
body { font-family: sans-serif; margin: 2em; max-width: 70em; }
table { border-collapse: collapse; } td, th { border: 1px solid #ccc; padding: 2px 8px; }
.verdict { font-size: 1.4em; font-weight: bold; }
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


class Skipped:
    """What the figures could not draw: per series, how many points and why."""

    def __init__(self) -> None:
        self.counts: Counter[tuple[str, str]] = Counter()

    def keep(
        self, series: str, *coords: object, absent: npt.ArrayLike | None = None
    ) -> npt.NDArray[np.bool_]:
        """Mask of the points whose every coordinate is drawable; counts the others.

        Each coordinate is an array with one row per point (a 2-D row is one point, e.g. a
        box's corners). ``absent`` marks points with no value at all (not counted)."""
        arrays = [_floats(c) for c in coords]
        rows = arrays[0].shape[0] if arrays[0].ndim else 1
        flat = [a.reshape(rows, -1) for a in arrays]
        finite = np.logical_and.reduce([np.isfinite(a).all(axis=1) for a in flat])
        with np.errstate(invalid="ignore"):
            bounded = np.logical_and.reduce([(np.abs(a) <= PLOT_LIMIT).all(axis=1) for a in flat])
        counted = np.ones(rows, bool) if absent is None else ~np.asarray(absent, bool)
        self.add(series, NON_FINITE, int((~finite & counted).sum()))
        self.add(series, OUT_OF_RANGE, int((finite & ~bounded & counted).sum()))
        return np.asarray(finite & bounded)

    def add(self, series: str, reason: str, count: int = 1) -> None:
        if count:
            self.counts[(series, reason)] += count

    def lines(self) -> list[str]:
        return [
            f"{series}: {n} point{'s' if n != 1 else ''} not plotted because {reason}"
            for (series, reason), n in self.counts.items()
        ]


def write_report(result: Diagnosis, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(render(result))


def render(result: Diagnosis) -> str:
    a = result.attribution
    meta = result.log.metadata
    skipped = Skipped()
    metrics_png = _png(metrics_figure(result, skipped))
    frame = scene_frame(result)
    scene_png = _png(scene_figure(result, frame, skipped))
    rows = [_row("th", "module", "collision", "safe", "first failure")]
    rows += [
        _row("td", m, v.collision, v.safe, v.first_failure_frame)
        for m, v in ((m, a.modules[m]) for m in MODULES)
    ]
    evidence = [join([el("h3", m), _table(a.modules[m].evidence or {})]) for m in a.root_causes]
    unplotted = skipped.lines()
    body = [
        el("h1", "Root-cause analysis"),
        el(
            "p",
            result.log.source,
            " \N{EM DASH} semantics ",
            el("b", result.params.semantics),
            f", {len(result.frames)} frames judged, collision frame ",
            meta.collision_frame,
            ", ego ",
            result.ctx.ego_id,
            ", partner ",
            a.partner_id,
        ),
        el("p", "Verdict: ", result.verdict_text, class_="verdict"),
        el("p", "Attribution basis: ", a.attribution_basis),
        el("table", *rows),
        el("h2", "Evidence"),
        *(evidence or [el("p", "none")]),
        el("h2", "Metrics over time"),
        el("img", alt="metrics", src=f"data:image/png;base64,{metrics_png}"),
        el("h2", "Scene at frame ", frame),
        el("img", alt="scene", src=f"data:image/png;base64,{scene_png}"),
        el("h2", f"Not plotted ({len(unplotted)})"),
        el("ul", *(el("li", line) for line in unplotted)),
        el("h2", "Thresholds"),
        _table(result.semantics.used(result.params)),
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


def _table(values: Mapping[str, object]) -> Html:
    return el("table", *(_row("td", k, v) for k, v in values.items()))


def _row(cell: str, *values: object) -> Html:
    return el("tr", *(el(cell, v) for v in values))


def _text(value: object) -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


# --- figures -------------------------------------------------------------------------------


def plot_text(value: object) -> str:
    """Text for a figure: at most :data:`PLOT_TEXT_MAX` characters, ``$`` escaped (a log
    string must not be parsed as mathtext, where ``$\\frac{$`` makes drawing fail)."""
    text = str(value)
    if len(text) > PLOT_TEXT_MAX:
        text = text[: PLOT_TEXT_MAX - 1] + "\N{HORIZONTAL ELLIPSIS}"
    return text.replace("$", r"\$")  # no unescaped "$" left: never mathtext


def metrics_figure(result: Diagnosis, skipped: Skipped) -> Figure:
    fig, axes = plt.subplots(len(MODULES), 1, figsize=(10, 2.2 * len(MODULES)), sharex=True)
    frames = _floats([f.frame for f in result.frames])
    meta = result.log.metadata
    window = result.window_frames
    used = result.semantics.used(result.params)
    for ax, module in zip(axes, MODULES, strict=True):
        key, threshold = _headline(result, module)
        raw = [_metric(f.results.get(module), key) for f in result.frames]
        values = _floats(raw)
        absent = [not isinstance(v, int | float | np.number) for v in raw]
        failed = np.array(
            [bool(f.results[module].failed) for f in result.frames if module in f.results]
        )
        series = f"metrics, {module}" + (f" ({key})" if key else "")
        drawable = skipped.keep(series, frames, values, absent=absent)
        label = plot_text(key or "no metric")
        color = None
        for run in _runs(drawable):
            (line,) = ax.plot(frames[run], values[run], lw=1, color=color, label=label)
            color, label = line.get_color(), "_nolegend_"
        if label != "_nolegend_":  # nothing drawable: keep the legend entry
            ax.plot([], [], lw=1, label=label)
        if failed.size == frames.size and failed.any():
            # a failed frame without a drawable value is marked on 0
            on = failed & np.isfinite(frames) & (np.abs(frames) <= PLOT_LIMIT)
            ax.plot(frames[on], np.where(drawable, values, 0.0)[on], "rx", label="failed")
        if threshold and threshold in used:
            level = _floats([used[threshold]])
            if skipped.keep(f"metrics, {module} threshold {threshold}", level)[0]:
                ax.axhline(float(level[0]), color="orange", ls="--", label=plot_text(threshold))
        if meta.has_collision:
            span = _floats([meta.collision_frame - window, meta.collision_frame])
            if skipped.keep(f"metrics, {module} collision window", *span)[0]:
                ax.axvline(float(span[1]), color="red", lw=1)
                ax.axvspan(float(span[0]), float(span[1]), color="red", alpha=0.08)
        ax.set_ylabel(module)
        ax.legend(loc="upper left", fontsize=7)
    axes[-1].set_xlabel("frame")
    fig.tight_layout()
    return fig


def _headline(result: Diagnosis, module: Module) -> tuple[str | None, str | None]:
    present = {k for f in result.frames if module in f.results for k in f.results[module].metrics}
    for key, threshold in result.semantics.headline[module]:
        if key in present:
            return key, threshold
    for frame in result.frames:  # otherwise the first numeric metric the oracle reports
        metrics = frame.results[module].metrics if module in frame.results else {}
        for key, value in metrics.items():
            if isinstance(value, int | float) and not isinstance(value, bool):
                return key, None
    return None, None


def _metric(result: OracleResult | None, key: str | None) -> Metric | None:
    if result is None or key is None:
        return None
    return result.metrics.get(key)


def scene_frame(result: Diagnosis) -> int | float | None:
    """The primary module's first failing frame, else the collision frame, else the last."""
    a = result.attribution
    if a.primary_root_cause is not None:
        first = a.modules[a.primary_root_cause].first_failure_frame
        if first is not None:
            return first
    if result.log.metadata.has_collision:
        return result.log.metadata.collision_frame
    return result.frames[-1].frame if result.frames else None


def scene_figure(result: Diagnosis, frame: int | float | None, skipped: Skipped) -> Figure:
    fig, ax = plt.subplots(figsize=(8, 8))
    log = result.log
    stamp = _floats([frame])[0] * log.tpf
    ts = round(float(stamp)) if np.isfinite(stamp) else None
    if ts is None or ts not in log.actors:
        ax.text(0.5, 0.5, "no actors at this frame", ha="center", transform=ax.transAxes)
        return fig
    partner = result.attribution.partner_id
    ego = result.ctx.ego_id
    _draw_actors(ax, result, ts, ego, partner, skipped)
    pose = log.pose.get(ts)
    centre: FloatArray | None = None
    if pose is not None:
        xy = np.array([pose.x, pose.y], dtype=np.float64)
        if skipped.keep("scene, ego pose", xy[:1], xy[1:])[0]:
            centre = xy
        predicted = (
            ("predictions_with_perception", "g.", log.predictions_with_perception),
            ("predictions", "m+", log.predictions),
        )
        for name, style, folder in predicted:
            for obstacle_id, track in folder.get(ts, {}).items():
                if obstacle_id == ego or len(track.keys) == 0:
                    continue
                with np.errstate(invalid="ignore", over="ignore"):
                    world = ego_to_world(track.offsets[:, :2], pose.xy, pose.yaw)
                ok = skipped.keep(f"scene, {name}", world[:, 0], world[:, 1])
                ax.plot(world[ok, 0], world[ok, 1], style, ms=3)
    plan = log.waypoints.get(ts)
    if plan is not None and len(plan):
        ok = skipped.keep("scene, plan", plan.xy[:, 0], plan.xy[:, 1])
        label = "plan"
        for run in _runs(ok):
            ax.plot(plan.xy[run, 0], plan.xy[run, 1], "b-", lw=1, label=label)
            label = "_nolegend_"
    if centre is not None:
        ax.set_xlim(centre[0] - 40, centre[0] + 40)
        ax.set_ylim(centre[1] - 40, centre[1] + 40)
    ax.set_aspect("equal")
    ax.invert_yaxis()  # CARLA's y points right of x: draw it as a map seen from above
    ax.set_title("ego (blue), partner (red), pwp (green), raw predictions (magenta), plan")
    return fig


def _draw_actors(
    ax: Axes, result: Diagnosis, ts: int, ego: str | None, partner: str | None, skipped: Skipped
) -> None:
    actors = result.log.actors[ts]
    extents = result.log.actor_extents
    for row, actor_id in enumerate(actors.ids):
        half = extents.get(actor_id)
        if half is None:
            continue
        with np.errstate(invalid="ignore", over="ignore"):
            corners = box_corners(actors.location[row, :2], half[:2], actors.rotation[row, 2])[0]
        if not skipped.keep("scene, actors", corners.reshape(1, -1))[0]:
            continue
        color = "tab:blue" if actor_id == ego else "tab:red" if actor_id == partner else "0.6"
        ax.add_patch(Polygon(corners, closed=True, fill=False, color=color, lw=1.5))
        if actor_id in (ego, partner):
            x, y = actors.location[row, :2].tolist()
            ax.annotate(plot_text(actor_id), (x, y), fontsize=8, color=color)


def _floats(values: object) -> FloatArray:
    """float64 array of any values: NaN for what is not a number, ±inf for huge ints."""
    if isinstance(values, np.ndarray):
        return values.astype(np.float64, copy=False)
    if not isinstance(values, list | tuple):  # one value
        return np.array([_float(values)], dtype=np.float64)
    return np.array([_float(v) for v in values], dtype=np.float64)


def _float(value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.number):
        return float(value) if isinstance(value, bool) else float("nan")
    try:
        return float(value)
    except OverflowError:
        return float("inf") if value > 0 else float("-inf")


def _runs(mask: npt.NDArray[np.bool_]) -> list[slice]:
    """Slices of the consecutive True stretches of a mask (a line is drawn per stretch)."""
    edges = np.flatnonzero(np.diff(np.concatenate(([0], mask.astype(np.int8), [0]))))
    return [
        slice(int(start), int(stop)) for start, stop in zip(edges[::2], edges[1::2], strict=True)
    ]


def _png(fig: Figure) -> str:
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=90)
    plt.close(fig)
    return base64.b64encode(buffer.getvalue()).decode("ascii")
