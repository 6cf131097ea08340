"""The report's figures: the modules' headline metrics over time, the bird's-eye scenes.

Drawn with matplotlib (Agg, no display needed). Each builder returns a
:class:`~matplotlib.figure.Figure`, so tests can read its axes, labels and legends.

Everything in a log is untrusted:

- Numbers reach matplotlib only when finite and within ±:data:`PLOT_LIMIT`; each series says
  in the report how many points it could not draw and why (:class:`Skipped`).
- Strings reach matplotlib only through :func:`plot_text` (no mathtext, bounded length).

What a panel plots is the mode's :class:`~ads_rca.oracles.semantics.Headline`; where a
series ends before the last judged frame, :func:`series_ends` says from which frame and why
(the oracle's skip reason, the flag that explains it, or the end of the log).
"""

from __future__ import annotations

import base64
import io
import textwrap
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.patches import Polygon

from ads_rca.diagnosis.engine import Diagnosis
from ads_rca.diagnosis.verdict import FrameResults
from ads_rca.foundation.geometry import box_corners, ego_to_world
from ads_rca.oracles.base import MODULES, Module
from ads_rca.oracles.semantics import Headline
from ads_rca.sources.carla.annotations import annotations_from_document

#: Largest magnitude drawn. Beyond it no log quantity (metres, ms, scores) means anything,
#: and near float's limit matplotlib's transforms overflow (1.7e308 fails to draw).
PLOT_LIMIT = 1e15
#: Longest text drawn in a figure (an id of a million characters would stall the layout).
PLOT_TEXT_MAX = 40

NON_FINITE = "non-finite"
OUT_OF_RANGE = f"beyond ±{PLOT_LIMIT:.0e}"

#: A series missing at most this many last frames ends with the log: it is listed under the
#: figure as such, not marked on the panel (a mark there would hide the end).
TAIL_FRAMES = 3
#: Series of at most this many frames show a dot per frame (more would be a smear).
MARKED_FRAMES = 200
#: Half the side of the square a scene shows at least, around the ego and the partner (m).
SCENE_HALF_SPAN_M = 20.0
#: How far back a scene draws the ego's and the partner's paths (frames).
SCENE_TRAIL_FRAMES = 40

EGO_COLOR, PARTNER_COLOR, OTHER_COLOR = "tab:blue", "tab:red", "0.55"
PLAN_COLOR, RAW_COLOR, PWP_COLOR = "tab:cyan", "tab:purple", "tab:green"
SERIES_COLORS = ("tab:blue", "tab:purple", "tab:brown")


class Skipped:
    """What the figures could not draw: per series, how many points and why."""

    def __init__(self) -> None:
        self.counts: Counter[tuple[str, str]] = Counter()

    def keep(self, series: str, *coords: Any, absent: Any = None) -> np.ndarray:
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


def plot_text(value: Any) -> str:
    """Text for a figure: at most :data:`PLOT_TEXT_MAX` characters, ``$`` escaped (a log
    string must not be parsed as mathtext, where ``$\\frac{$`` makes drawing fail)."""
    text = str(value)
    if len(text) > PLOT_TEXT_MAX:
        text = text[: PLOT_TEXT_MAX - 1] + "\N{HORIZONTAL ELLIPSIS}"
    return text.replace("$", r"\$")  # no unescaped "$" left: never mathtext


def frame_text(frame: Any) -> str:
    """A frame number as a report writes it (4 significant digits for a float)."""
    return f"{frame:.4g}" if isinstance(frame, float) else str(frame)


# --- what each panel plots, and where its series end -------------------------------------


def headline(result: Diagnosis, module: Module) -> Headline | None:
    """The mode's first headline for ``module`` whose first key the run reports."""
    present = {k for f in result.frames if module in f.results for k in f.results[module].metrics}
    for choice in result.semantics.headline[module]:
        if choice.keys[0] in present:
            return choice
    return None


def fallback_headline(result: Diagnosis, module: Module) -> Headline | None:
    """Where no headline applies, the first numeric metric the oracle reports (unit unknown)."""
    for frame in result.frames:
        metrics = frame.results[module].metrics if module in frame.results else {}
        for key, value in metrics.items():
            if isinstance(value, int | float) and not isinstance(value, bool):
                return Headline((key,), key, "unit not declared")
    return None


@dataclass(frozen=True)
class SeriesEnd:
    """A plotted series with no value after ``last`` (None: no value at all) up to ``end``."""

    module: Module
    key: str
    last: int | float | None
    end: int | float
    missing: int
    reason: str

    def line(self) -> str:
        if self.last is None:
            return f"{self.module} {self.key}: no value at any judged frame ({self.reason})"
        span = (
            f"frame {frame_text(self.end)}"
            if self.missing == 1
            else f"{self.missing} frames up to frame {frame_text(self.end)}"
        )
        return (
            f"{self.module} {self.key}: no value after frame {frame_text(self.last)} "
            f"({span}: {self.reason})"
        )


def series_ends(result: Diagnosis) -> list[SeriesEnd]:
    """Every headline series that stops before the last judged frame, with the reason."""
    found: list[SeriesEnd] = []
    for module in MODULES:
        chosen = headline(result, module) or fallback_headline(result, module)
        if chosen is None:
            continue
        for key in chosen.keys:
            end = _series_end(result, module, chosen, key)
            if end is not None:
                found.append(end)
    return found


def _series_end(result: Diagnosis, module: Module, chosen: Headline, key: str) -> SeriesEnd | None:
    frames = result.frames
    if not frames:
        return None
    values = _floats([_metric(f, module, key) for f in frames])
    with np.errstate(invalid="ignore"):
        has = np.isfinite(values) & (np.abs(values) <= PLOT_LIMIT)
    if has[-1]:
        return None
    valued = np.flatnonzero(has)
    after = frames[int(valued[-1]) + 1 :] if valued.size else frames
    last = frames[int(valued[-1])].frame if valued.size else None
    reason = _why_absent(after, module, chosen, key, at_log_end=valued.size > 0)
    return SeriesEnd(module, key, last, frames[-1].frame, len(after), reason)


def _why_absent(
    frames: Sequence[FrameResults], module: Module, chosen: Headline, key: str, at_log_end: bool
) -> str:
    """Why ``frames`` have no ``key``: skipped checks, the headline's gates, or the log's end."""
    results = [f.results[module] for f in frames if module in f.results]
    reasons: list[str] = []
    if len(results) < len(frames):
        reasons.append(f"not judged at {len(frames) - len(results)} frame(s)")
    skips = Counter(r.skipped for r in results if r.skipped is not None)
    if skips:
        (first, n), *more = skips.most_common()
        extra = f", and {len(more)} other reason(s)" if more else ""
        reasons.append(f"check skipped at {n} frame(s): {first}{extra}")
    judged = [r for r in results if r.skipped is None]
    if judged:
        gates = [
            f"{gate} = {str(value).lower()}"
            for gate, value in chosen.gates.get(key, ())
            if all(r.metrics.get(gate) is value for r in judged)
        ]
        if gates:
            reasons.append(" and ".join(gates))
        elif at_log_end and not skips and len(judged) <= TAIL_FRAMES:
            where = "frame" if len(judged) == 1 else f"{len(judged)} frames"
            reasons.append(f"the log's last {where}, where the oracle reports no {key}")
        else:
            reasons.append(f"the oracle reports no {key} there")
    return "; ".join(reasons)


def _metric(frame: FrameResults, module: Module, key: str | None) -> Any:
    result = frame.results.get(module)
    if result is None or key is None:
        return None
    return result.metrics.get(key)


# --- metrics over time -------------------------------------------------------------------


def metrics_figure(result: Diagnosis, skipped: Skipped) -> Figure:
    """One panel per module: its headline metrics, threshold, failures, the effect window."""
    fig, axes = plt.subplots(len(MODULES), 1, figsize=(11, 2.6 * len(MODULES)), sharex=True)
    ends = {(e.module, e.key): e for e in series_ends(result)}
    for ax, module in zip(axes, MODULES, strict=True):
        _metric_panel(ax, result, module, skipped, ends)
    axes[-1].set_xlabel("frame")
    frame_s = result.log.frame_ms / 1000.0
    top = axes[0].secondary_xaxis("top", functions=(lambda f: f * frame_s, lambda t: t / frame_s))
    top.set_xlabel("time since the log's start (s)")
    # fixed margins, room for the legends on the right: one draw (no tight layout pass)
    fig.subplots_adjust(left=0.08, right=0.76, top=0.93, bottom=0.06, hspace=0.35)
    return fig


def _metric_panel(
    ax: Axes,
    result: Diagnosis,
    module: Module,
    skipped: Skipped,
    ends: dict[tuple[Module, str], SeriesEnd],
) -> None:
    frames = _floats([f.frame for f in result.frames])
    frame_ok = np.isfinite(frames) & (np.abs(frames) <= PLOT_LIMIT)
    chosen = headline(result, module) or fallback_headline(result, module)
    partner = result.attribution.partner_id
    title: str = module
    if chosen is not None and chosen.partner and partner is not None:
        title += f" \N{EM DASH} partner {plot_text(partner)}"
    ax.set_title(title, loc="left", fontsize=9, fontweight="bold")
    if chosen is None:
        ax.text(0.5, 0.5, "no numeric metric reported", ha="center", transform=ax.transAxes)
        ax.set_ylabel("(no metric)")
        return
    unit = "-" if chosen.unit == "1" else chosen.unit
    ax.set_ylabel(textwrap.fill(f"{plot_text(chosen.quantity)} ({unit})", 24), fontsize=8)
    if chosen.band is not None:
        _band(ax, result, module, chosen.band, frames, frame_ok)
    _collision_window(ax, result, skipped, module)
    _annotation_lines(ax, result, skipped, module)
    marks: list[tuple[str, str, SeriesEnd, float, float]] = []
    marker = "." if len(frames) <= MARKED_FRAMES else ""
    for key, color in zip(chosen.keys, SERIES_COLORS, strict=False):
        raw = [_metric(f, module, key) for f in result.frames]
        values = _floats(raw)
        absent = [not isinstance(v, int | float | np.number) or isinstance(v, bool) for v in raw]
        drawable = skipped.keep(f"metrics, {module} ({key})", frames, values, absent=absent)
        label = plot_text(key)
        for run in _runs(drawable):
            ax.plot(frames[run], values[run], lw=1.3, color=color, label=label, marker=marker, ms=3)
            label = "_nolegend_"
        if label != "_nolegend_":  # nothing drawable: keep the legend entry
            ax.plot([], [], lw=1.3, color=color, label=f"{label} (no value)")
        end = ends.get((module, key))
        if end is not None and end.last is not None and drawable.any():
            at = int(np.flatnonzero(drawable)[-1])
            if len(drawable) - at > TAIL_FRAMES:
                marks.append((key, color, end, float(frames[at]), float(values[at])))
    _levels(ax, result, module, chosen, frames, frame_ok, skipped)
    low, high = ax.get_ylim()
    for key, color, end, x, y in marks:
        high_up = y > (low + high) / 2  # the text goes where there is room: below, or above
        ax.annotate(
            f"no {plot_text(key)} after frame {frame_text(end.last)} (see notes)",
            (x, y),
            xytext=(-10, -16) if high_up else (10, 12),
            textcoords="offset points",
            ha="right" if high_up else "left",
            fontsize=7,
            color=color,
            arrowprops={"arrowstyle": "-", "color": color, "lw": 0.6},
        )
    failed = np.array(
        [bool(f.results[module].failed) if module in f.results else False for f in result.frames],
        dtype=bool,
    )
    if failed.any():
        on = failed & frame_ok
        # along the bottom edge: a failure is marked whether or not it has a value
        ax.plot(
            frames[on],
            np.full(int(on.sum()), 0.04),
            "x",
            color="red",
            ms=5,
            transform=ax.get_xaxis_transform(),
            label="failed frame",
        )
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7, borderaxespad=0)


def _levels(
    ax: Axes,
    result: Diagnosis,
    module: Module,
    chosen: Headline,
    frames: np.ndarray,
    frame_ok: np.ndarray,
    skipped: Skipped,
) -> None:
    """The threshold parameter as a level, the per-frame limit as a dashed step line."""
    signs = (1.0, -1.0) if chosen.both_signs else (1.0,)
    used = result.semantics.used(result.params)
    if chosen.threshold is not None and chosen.threshold in used:
        level = _floats([used[chosen.threshold]])
        if skipped.keep(f"metrics, {module} threshold {chosen.threshold}", level)[0]:
            label = plot_text(f"{chosen.threshold} = {used[chosen.threshold]:.4g}")
            for sign in signs:
                ax.axhline(sign * float(level[0]), color="orange", ls="--", lw=1, label=label)
                label = "_nolegend_"
    if chosen.limit is not None:
        values = _floats([_metric(f, module, chosen.limit) for f in result.frames])
        ok = skipped.keep(f"metrics, {module} ({chosen.limit})", frames, values) & frame_ok
        label = plot_text(f"{chosen.limit} (applied)")
        for sign in signs:
            for run in _runs(ok):
                ax.step(
                    frames[run],
                    sign * values[run],
                    where="mid",
                    color="orange",
                    ls="--",
                    lw=1,
                    label=label,
                )
                label = "_nolegend_"


def _band(
    ax: Axes,
    result: Diagnosis,
    module: Module,
    band: tuple[str, str],
    frames: np.ndarray,
    frame_ok: np.ndarray,
) -> None:
    """Shade the frames where the band's flag is true (half a frame either side)."""
    key, text = band
    on = np.array([_metric(f, module, key) is True for f in result.frames], dtype=bool) & frame_ok
    label = plot_text(text)
    for run in _runs(on):
        start, stop = float(frames[run][0]), float(frames[run][-1])
        ax.axvspan(start - 0.5, stop + 0.5, color="0.5", alpha=0.15, hatch="//", lw=0, label=label)
        label = "_nolegend_"


def _collision_window(ax: Axes, result: Diagnosis, skipped: Skipped, module: Module) -> None:
    meta = result.log.metadata
    if not meta.has_collision:
        return
    span = _floats([meta.collision_frame - result.window_frames, meta.collision_frame])
    if skipped.keep(f"metrics, {module} collision window", *span)[0]:
        ax.axvspan(
            float(span[0]),
            float(span[1]),
            color="red",
            alpha=0.07,
            label=f"effect window ({result.window_frames} frames)",
        )
        ax.axvline(float(span[1]), color="red", lw=1, label="collision")


def _annotation_lines(ax: Axes, result: Diagnosis, skipped: Skipped, module: Module) -> None:
    """The run's annotations (a CARLA run's events) as dotted lines at their frames."""
    found = annotations_from_document(result.log.metadata.raw)
    if not found or result.log.frame_ms <= 0:
        return
    at = _floats([a.timestamp_ms / result.log.frame_ms for a in found])
    drawable = skipped.keep(f"metrics, {module} annotations", at)
    label = "annotation (event, not a collision)"
    for x in at[drawable]:
        ax.axvline(float(x), color="purple", lw=0.8, ls=":", label=label)
        label = "_nolegend_"


# --- the bird's-eye scenes ---------------------------------------------------------------


def scene_frames(result: Diagnosis) -> list[tuple[str, int | float]]:
    """(caption, frame) of each scene, in time order: the primary module's first failure and
    the collision (one scene when they coincide); with neither, the last judged frame."""
    scenes: list[tuple[str, int | float]] = []
    a = result.attribution
    if a.primary_root_cause is not None:
        first = a.modules[a.primary_root_cause].first_failure_frame
        if first is not None:
            scenes.append((f"first failure ({a.primary_root_cause})", first))
    meta = result.log.metadata
    if meta.has_collision:
        if scenes and scenes[0][1] == meta.collision_frame:
            scenes = [(f"collision and {scenes[0][0]}", meta.collision_frame)]
        else:
            scenes.append(("collision", meta.collision_frame))
    if not scenes and result.frames:
        scenes.append(("last judged frame", result.frames[-1].frame))
    return sorted(scenes, key=lambda scene: _float(scene[1]))


def scene_figure(
    result: Diagnosis, frame: int | float | None, skipped: Skipped, caption: str = ""
) -> Figure:
    """The scene from above at ``frame``: boxes, paths, predictions, the plan; metres."""
    fig, ax = plt.subplots(figsize=(5.8, 6.5))
    fig.subplots_adjust(left=0.15, right=0.97, top=0.92, bottom=0.22)  # the legend below
    log = result.log
    stamp = _floats([frame])[0] * log.frame_ms
    ts = round(float(stamp)) if np.isfinite(stamp) and abs(stamp) <= PLOT_LIMIT else None
    failing = _failing_at(result, ts)
    title = f"{caption + ', ' if caption else ''}frame {frame_text(frame)}"
    if ts is not None:
        title += f", t = {ts / 1000:.2f} s"
    title += f"\nmodules failing at this frame: {', '.join(failing) or 'none'}"
    ax.set_title(title, fontsize=9, loc="left")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m, downwards: CARLA's y is right of x)")
    if ts is None or ts not in log.actors:
        ax.text(0.5, 0.5, "no actors at this frame", ha="center", transform=ax.transAxes)
        return fig
    partner = result.attribution.partner_id
    ego = result.ctx.ego_id
    focus = _draw_actors(ax, result, ts, ego, partner, skipped)
    _draw_trails(ax, result, ts, ego, partner, skipped)
    _draw_predictions(ax, result, ts, ego, skipped)
    plan = log.waypoints.get(ts)
    if plan is not None and len(plan):
        ok = skipped.keep("scene, plan", plan.xy[:, 0], plan.xy[:, 1])
        label = "plan (waypoints)"
        for run in _runs(ok):
            ax.plot(
                plan.xy[run, 0],
                plan.xy[run, 1],
                "-",
                color=PLAN_COLOR,
                lw=1.5,
                marker=".",
                ms=4,
                label=label,
            )
            label = "_nolegend_"
    _frame_view(ax, focus)
    ax.set_aspect("equal", adjustable="box")
    ax.invert_yaxis()  # CARLA's y points right of x: draw it as a map seen from above
    ax.grid(True, lw=0.3, alpha=0.5)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.09), fontsize=8, ncols=2)
    return fig


def _failing_at(result: Diagnosis, ts: int | None) -> list[str]:
    for f in result.frames:
        if f.timestamp_ms == ts:
            return [m for m in MODULES if m in f.results and f.results[m].failed]
    return []


def _draw_actors(
    ax: Axes, result: Diagnosis, ts: int, ego: str | None, partner: str | None, skipped: Skipped
) -> list[np.ndarray]:
    """Every actor's box with a heading tick; ego and partner labelled beside (not on) their
    box. Returns the centres the view must hold (ego and partner)."""
    actors = result.log.actors[ts]
    extents = result.log.actor_extents
    focus: list[np.ndarray] = []
    labelled: list[tuple[str, str, np.ndarray, float]] = []
    other_label = "other actors"
    for row, actor_id in enumerate(actors.ids):
        half = extents.get(actor_id)
        if half is None:
            continue
        with np.errstate(invalid="ignore", over="ignore"):
            corners = box_corners(actors.location[row, :2], half[:2], actors.rotation[row, 2])[0]
        if not skipped.keep("scene, actors", corners.reshape(1, -1))[0]:
            continue
        centre = corners.mean(axis=0)
        front = corners[[0, 3]].mean(axis=0)
        if actor_id == ego:
            color, label, name = EGO_COLOR, "ego", f"ego {plot_text(actor_id)}"
        elif actor_id == partner:
            color, label, name = (
                PARTNER_COLOR,
                "collision partner",
                f"partner {plot_text(actor_id)}",
            )
        else:
            color, label, name = OTHER_COLOR, other_label, ""
            other_label = "_nolegend_"
        ax.add_patch(Polygon(corners, closed=True, fill=True, fc=color, alpha=0.25, ec="none"))
        ax.add_patch(Polygon(corners, closed=True, fill=False, ec=color, lw=1.5, label=label))
        ax.plot([centre[0], front[0]], [centre[1], front[1]], "-", color=color, lw=1.5)
        if actor_id in (ego, partner):
            focus.append(centre)
            radius = float(np.hypot(*(corners[0] - centre)))
            labelled.append((name, color, centre, radius))  # the id beside, not in the legend
    for label, color, centre, radius in labelled:
        away = _away_from(centre, [c for _, _, c, _ in labelled if c is not centre])
        at = centre + away * (radius + 4.0)  # beside the box, pointing at it
        ax.annotate(
            label,
            xy=(float(centre[0]), float(centre[1])),
            xytext=(float(at[0]), float(at[1])),
            fontsize=8,
            color=color,
            ha="center",
            va="center",
            bbox={"boxstyle": "round,pad=0.2", "fc": "white", "ec": color, "alpha": 0.85},
            arrowprops={"arrowstyle": "-", "color": color, "lw": 0.8},
        )
    return focus


def _away_from(centre: np.ndarray, others: list[np.ndarray]) -> np.ndarray:
    """A unit vector from the other labelled actors to ``centre`` (default: one side)."""
    if others:
        direction = centre - np.mean(others, axis=0)
        norm = float(np.hypot(*direction))
        if norm > 1e-6:
            return np.asarray(direction / norm)
    return np.array([0.0, -1.0])


def _draw_trails(
    ax: Axes, result: Diagnosis, ts: int, ego: str | None, partner: str | None, skipped: Skipped
) -> None:
    """The ego's and the partner's positions over the last frames: how they got here."""
    log = result.log
    stamps = [s for s in log.unique_frames if ts - SCENE_TRAIL_FRAMES * log.frame_ms <= s <= ts]
    ego_xy = np.array([log.pose[s].xy for s in stamps if s in log.pose]).reshape(-1, 2)
    partner_xy = np.array(
        [
            log.actors[s].location[log.actors[s].index[partner], :2]
            for s in stamps
            if partner is not None and s in log.actors and partner in log.actors[s].index
        ]
    ).reshape(-1, 2)
    seconds = SCENE_TRAIL_FRAMES * log.frame_ms / 1000
    for name, xy, color in (("ego", ego_xy, EGO_COLOR), ("partner", partner_xy, PARTNER_COLOR)):
        if not len(xy):
            continue
        ok = skipped.keep(f"scene, {name} path", xy[:, 0], xy[:, 1])
        label = f"{name} path, last {seconds:.3g} s"
        for run in _runs(ok):
            ax.plot(xy[run, 0], xy[run, 1], ":", color=color, lw=1, label=label)
            label = "_nolegend_"


def _draw_predictions(
    ax: Axes, result: Diagnosis, ts: int, ego: str | None, skipped: Skipped
) -> None:
    log = result.log
    pose = log.pose.get(ts)
    if pose is None:
        return
    xy = np.array([pose.x, pose.y], dtype=np.float64)
    skipped.keep("scene, ego pose", xy[:1], xy[1:])
    for name, folder, color, marker, text in (
        (
            "predictions_with_perception",
            log.predictions_with_perception,
            PWP_COLOR,
            ".",
            "predictions with perception",
        ),
        ("predictions", log.predictions, RAW_COLOR, "+", "raw predictions"),
    ):
        label = text
        for obstacle_id, track in folder.get(ts, {}).items():
            if obstacle_id == ego or len(track.keys) == 0:
                continue
            with np.errstate(invalid="ignore", over="ignore"):
                world = ego_to_world(track.offsets[:, :2], pose.xy, pose.yaw)
            ok = skipped.keep(f"scene, {name}", world[:, 0], world[:, 1])
            if ok.any():
                ax.plot(
                    world[ok, 0], world[ok, 1], marker, color=color, ms=4, ls="none", label=label
                )
                label = "_nolegend_"


def _frame_view(ax: Axes, focus: list[np.ndarray]) -> None:
    """Hold the ego and the partner with a margin, at least 2 × SCENE_HALF_SPAN_M wide."""
    if not focus:
        return
    points = np.array(focus)
    low, high = points.min(axis=0), points.max(axis=0)
    centre = (low + high) / 2
    half = max(float((high - low).max()) / 2 + 10.0, SCENE_HALF_SPAN_M)
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)


def png_base64(fig: Figure) -> str:
    """The figure as base64 PNG (for a data: URL), and closed."""
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=90)
    plt.close(fig)
    return base64.b64encode(buffer.getvalue()).decode("ascii")


def legend_labels(fig: Figure) -> list[str]:
    """Every legend entry of a figure (tests read what a reader can identify)."""
    legends = [ax.get_legend() for ax in fig.axes]
    return [t.get_text() for legend in legends if legend is not None for t in legend.texts]


def _floats(values: Any) -> np.ndarray:
    """float64 array of any values: NaN for what is not a number, ±inf for huge ints."""
    if isinstance(values, np.ndarray):
        return values.astype(np.float64, copy=False)
    if not isinstance(values, list | tuple):  # one value
        return np.array([_float(values)], dtype=np.float64)
    return np.array([_float(v) for v in values], dtype=np.float64)


def _float(value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.number):
        return float(value) if isinstance(value, bool) else float("nan")
    try:
        return float(value)
    except OverflowError:
        return float("inf") if value > 0 else float("-inf")


def _runs(mask: np.ndarray) -> list[slice]:
    """Slices of the consecutive True stretches of a mask (a line is drawn per stretch)."""
    edges = np.flatnonzero(np.diff(np.concatenate(([0], mask.astype(np.int8), [0]))))
    return [
        slice(int(start), int(stop)) for start, stop in zip(edges[::2], edges[1::2], strict=True)
    ]


__all__ = [
    "NON_FINITE",
    "OUT_OF_RANGE",
    "PLOT_LIMIT",
    "PLOT_TEXT_MAX",
    "SeriesEnd",
    "Skipped",
    "headline",
    "legend_labels",
    "metrics_figure",
    "plot_text",
    "png_base64",
    "scene_figure",
    "scene_frames",
    "series_ends",
]
