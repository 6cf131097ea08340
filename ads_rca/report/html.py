"""A self-contained HTML report of a diagnosis: verdict, metric plots, a top-down scene.

Figures are drawn with matplotlib (Agg, no display needed) and embedded as base64 PNG, so
the page is one file that opens anywhere, offline.
"""

from __future__ import annotations

import base64
import html
import io
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Polygon

from ads_rca.engine import Diagnosis
from ads_rca.geometry import box_corners, ego_to_world
from ads_rca.oracles.base import MODULES, Module

#: Per mode and module, the metric plotted over time (first one present wins) and the
#: threshold parameter drawn with it.
HEADLINE: dict[str, dict[Module, list[tuple[str, str | None]]]] = {
    "reference": {
        "perception": [("mean_iou", "perc_score_threshold")],
        "prediction": [("ratio", "pred_score_threshold")],
        "planning": [("gap_y", None), ("gap_x", None)],
        "controller": [("s_x", None)],
    },
    "corrected": {
        "perception": [("recall", None), ("mean_iou", "perc_match_iou")],
        "prediction": [("displacement_error", None), ("ade", None)],
        "planning": [("c_plan", "safety_margin"), ("c_gt", "safety_margin")],
        "controller": [("sum_speed_innovation", "control_speed_threshold")],
    },
}


def write_report(result: Diagnosis, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(render(result))


def render(result: Diagnosis) -> str:
    a = result.attribution
    meta = result.log.metadata
    rows = "".join(
        f"<tr><td>{m}</td><td>{a.modules[m].collision}</td><td>{a.modules[m].safe}</td>"
        f"<td>{_text(a.modules[m].first_failure_frame)}</td></tr>"
        for m in MODULES
    )
    evidence = "".join(f"<h3>{m}</h3>{_table(a.modules[m].evidence or {})}" for m in a.root_causes)
    problems = "".join(f"<li>{html.escape(str(p))}</li>" for p in result.problems)
    thresholds = _table(result.params.used())
    scene_frame = _scene_frame(result)
    return f"""<!doctype html>
<html><head><meta charset="utf-8"><title>ads_rca: {html.escape(result.log.source)}</title>
<style>
body {{ font-family: sans-serif; margin: 2em; max-width: 70em; }}
table {{ border-collapse: collapse; }} td, th {{ border: 1px solid #ccc; padding: 2px 8px; }}
.verdict {{ font-size: 1.4em; font-weight: bold; }}
</style></head><body>
<h1>Root-cause analysis</h1>
<p>{html.escape(result.log.source)} &mdash; semantics <b>{result.params.semantics}</b>,
{len(result.frames)} frames judged, collision frame {meta.collision_frame},
ego {_text(result.ctx.ego_id)}, partner {_text(a.partner_id)}</p>
<p class="verdict">Verdict: {html.escape(result.verdict_text)}</p>
<p>Attribution basis: {html.escape(a.attribution_basis)}</p>
<table><tr><th>module</th><th>collision</th><th>safe</th><th>first failure</th></tr>{rows}
</table>
<h2>Evidence</h2>{evidence or "<p>none</p>"}
<h2>Metrics over time</h2>
<img alt="metrics" src="data:image/png;base64,{_png(_metrics_figure(result))}">
<h2>Scene at frame {_text(scene_frame)}</h2>
<img alt="scene" src="data:image/png;base64,{_png(_scene_figure(result, scene_frame))}">
<h2>Thresholds</h2>{thresholds}
<h2>Input problems ({len(result.problems)})</h2><ul>{problems}</ul>
</body></html>
"""


def _metrics_figure(result: Diagnosis) -> Figure:
    fig, axes = plt.subplots(len(MODULES), 1, figsize=(10, 2.2 * len(MODULES)), sharex=True)
    frames = np.array([float(f.frame) for f in result.frames])
    meta = result.log.metadata
    window = result.params.window_frames(meta.timesteps_per_frame)
    used = result.params.used()
    for ax, module in zip(axes, MODULES, strict=True):
        key, threshold = _headline(result, module)
        values = np.array([_metric(f.results.get(module), key) for f in result.frames])
        failed = np.array(
            [bool(f.results[module].failed) for f in result.frames if module in f.results]
        )
        ax.plot(frames, values, lw=1, label=key or "no metric")
        if failed.size == frames.size and failed.any():
            ax.plot(frames[failed], np.nan_to_num(values[failed]), "rx", label="failed")
        if threshold and threshold in used:
            ax.axhline(float(used[threshold]), color="orange", ls="--", label=threshold)
        if meta.has_collision:
            ax.axvline(meta.collision_frame, color="red", lw=1)
            ax.axvspan(meta.collision_frame - window, meta.collision_frame, color="red", alpha=0.08)
        ax.set_ylabel(module)
        ax.legend(loc="upper left", fontsize=7)
    axes[-1].set_xlabel("frame")
    fig.tight_layout()
    return fig


def _headline(result: Diagnosis, module: Module) -> tuple[str | None, str | None]:
    present = {k for f in result.frames if module in f.results for k in f.results[module].metrics}
    for key, threshold in HEADLINE[result.params.semantics][module]:
        if key in present:
            return key, threshold
    for frame in result.frames:  # otherwise the first numeric metric the oracle reports
        metrics = frame.results[module].metrics if module in frame.results else {}
        for key, value in metrics.items():
            if isinstance(value, int | float) and not isinstance(value, bool):
                return key, None
    return None, None


def _metric(result: Any, key: str | None) -> float:
    if result is None or key is None:
        return float("nan")
    value = result.metrics.get(key)
    return float(value) if isinstance(value, int | float) and value is not None else float("nan")


def _scene_frame(result: Diagnosis) -> int | float | None:
    """The primary module's first failing frame, else the collision frame, else the last."""
    a = result.attribution
    if a.primary_root_cause is not None:
        first = a.modules[a.primary_root_cause].first_failure_frame
        if first is not None:
            return first
    if result.log.metadata.has_collision:
        return result.log.metadata.collision_frame
    return result.frames[-1].frame if result.frames else None


def _scene_figure(result: Diagnosis, frame: int | float | None) -> Figure:
    fig, ax = plt.subplots(figsize=(8, 8))
    log = result.log
    ts = None if frame is None else round(float(frame) * log.tpf)
    if ts is None or ts not in log.actors:
        ax.text(0.5, 0.5, "no actors at this frame", ha="center", transform=ax.transAxes)
        return fig
    actors = log.actors[ts]
    extents = log.actor_extents
    partner = result.attribution.partner_id
    ego = result.ctx.ego_id
    for row, actor_id in enumerate(actors.ids):
        half = extents.get(actor_id)
        if half is None:
            continue
        corners = box_corners(actors.location[row, :2], half[:2], actors.rotation[row, 2])[0]
        color = "tab:blue" if actor_id == ego else "tab:red" if actor_id == partner else "0.6"
        ax.add_patch(Polygon(corners, closed=True, fill=False, color=color, lw=1.5))
        if actor_id in (ego, partner):
            x, y = actors.location[row, :2].tolist()
            ax.annotate(actor_id, (x, y), fontsize=8, color=color)
    pose = log.pose.get(ts)
    if pose is not None:
        for name, style in (("predictions_with_perception", "g."), ("predictions", "m+")):
            for obstacle_id, track in log.folder(name).get(ts, {}).items():
                if obstacle_id == ego or len(track.keys) == 0:
                    continue
                world = ego_to_world(track.offsets[:, :2], pose.xy, pose.yaw)
                ax.plot(world[:, 0], world[:, 1], style, ms=3)
    plan = log.waypoints.get(ts)
    if plan is not None and len(plan):
        ax.plot(plan.xy[:, 0], plan.xy[:, 1], "b-", lw=1, label="plan")
    if pose is not None:
        ax.set_xlim(pose.x - 40, pose.x + 40)
        ax.set_ylim(pose.y - 40, pose.y + 40)
    ax.set_aspect("equal")
    ax.invert_yaxis()  # CARLA's y points right of x: draw it as a map seen from above
    ax.set_title("ego (blue), partner (red), pwp (green), raw predictions (magenta), plan")
    return fig


def _png(fig: Figure) -> str:
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=90)
    plt.close(fig)
    return base64.b64encode(buffer.getvalue()).decode("ascii")


def _table(values: dict[str, Any]) -> str:
    rows = "".join(
        f"<tr><td>{html.escape(str(k))}</td><td>{html.escape(_text(v))}</td></tr>"
        for k, v in values.items()
    )
    return f"<table>{rows}</table>"


def _text(value: Any) -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)
