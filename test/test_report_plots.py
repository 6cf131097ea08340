"""Non-finite and absurd values never reach a plot of the report.

A pose of ``1e400`` is read as infinity (and kept, with a problem); one of ``1.7e308`` is
finite but beyond what matplotlib can scale. Either used to crash ``diagnose --report``.
Now every series drops what it cannot draw and the report says how many points and why.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from matplotlib import pyplot as plt
from matplotlib.figure import Figure
from matplotlib.patches import Polygon

from ads_rca.diagnosis.engine import Diagnosis, diagnose
from ads_rca.params import make_params
from ads_rca.report.figures import (
    NON_FINITE,
    OUT_OF_RANGE,
    PLOT_LIMIT,
    Skipped,
    metrics_figure,
    scene_figure,
    scene_frames,
)
from ads_rca.sources.log.writer import write_run_log
from ads_rca.sources.registry import open_run
from ads_rca.synth import synthesise

#: Pose values as the log writes them (strings): infinite once read, or finite but absurd.
POSE_VALUES = {"inf": "1e400", "absurd": "1.7e308", "nan": "NaN"}


def log_with_pose_x(folder: Path, value: str) -> Path:
    """A planning-fault crash whose every pose has ``x`` = value, one actor far away, a plan
    point at infinity and a prediction offset of 1e300."""
    write_run_log(synthesise("cut_in", "planning", seed=1), folder)
    for path in (folder / "pose").iterdir():
        document = json.loads(path.read_text())
        document["x"] = value
        path.write_text(json.dumps(document))
    for path in (folder / "actors").iterdir():
        actors = json.loads(path.read_text())
        last = list(actors)[-1]
        actors[last]["location"]["x"] = 1e300
        path.write_text(json.dumps(actors))
    for path in (folder / "waypoint").iterdir():
        plan = json.loads(path.read_text())
        plan[next(iter(plan))]["x"] = float("inf")
        path.write_text(json.dumps(plan))
    for path in (folder / "predictions").iterdir():
        tracks = json.loads(path.read_text())
        for steps in tracks.values():
            steps[next(iter(steps))]["y"] = 1e300
        path.write_text(json.dumps(tracks))
    return folder


def assert_drawable(fig: Figure) -> None:
    """Every number in the figure's artists is finite and within the plot limit."""
    for ax in fig.axes:
        assert np.isfinite(ax.get_xlim()).all() and np.isfinite(ax.get_ylim()).all()
        for line in ax.get_lines():
            xy = np.asarray(line.get_xydata(), dtype=float)
            assert np.isfinite(xy).all() and (np.abs(xy) <= PLOT_LIMIT).all(), line
        for patch in ax.patches:
            if isinstance(patch, Polygon):
                xy = np.asarray(patch.get_xy(), dtype=float)
                assert np.isfinite(xy).all() and (np.abs(xy) <= PLOT_LIMIT).all()
            assert np.isfinite(patch.get_verts()).all()
        for text in ax.texts:
            assert np.isfinite(np.asarray(text.get_position(), dtype=float)).all()
    fig.canvas.draw()  # and it renders


@pytest.mark.parametrize("kind", sorted(POSE_VALUES))
def test_diagnose_report_with_unplottable_values(tmp_path: Path, kind: str) -> None:
    log_dir = log_with_pose_x(tmp_path / "log", POSE_VALUES[kind])
    out = tmp_path / "report.html"
    done = subprocess.run(
        [sys.executable, "-m", "ads_rca.cli", "diagnose", str(log_dir), "--report", str(out)],
        check=False,
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    page = out.read_text()
    reason = OUT_OF_RANGE if kind == "absurd" else NON_FINITE
    assert f"scene, ego pose: 1 point not plotted because {reason}" in page
    assert f"not plotted because {NON_FINITE}" in page  # the plan point at infinity
    assert f"not plotted because {OUT_OF_RANGE}" in page  # 1e300


@pytest.mark.parametrize("semantics", ["corrected", "reference"])
@pytest.mark.parametrize("kind", sorted(POSE_VALUES))
def test_figures_hold_only_drawable_numbers(tmp_path: Path, kind: str, semantics: str) -> None:
    result: Diagnosis = diagnose(
        open_run(log_with_pose_x(tmp_path / "log", POSE_VALUES[kind])), make_params(semantics)
    )
    skipped = Skipped()
    metrics = metrics_figure(result, skipped)
    scenes = [scene_figure(result, frame, skipped) for _, frame in scene_frames(result)]
    assert_drawable(metrics)
    assert scenes
    for scene in scenes:
        assert_drawable(scene)
    series = {name for name, _ in skipped.counts}
    assert "scene, ego pose" in series and "scene, plan" in series
    assert all(n > 0 for n in skipped.counts.values())
    for figure in [metrics, *scenes]:  # as the report does once a figure is encoded
        plt.close(figure)


def test_skipped_counts_each_reason() -> None:
    skipped = Skipped()
    keep = skipped.keep(
        "s",
        np.array([0.0, 1.0, 2.0, 3.0, 4.0]),
        np.array([1.0, np.nan, np.inf, 1e300, -2.0]),
        absent=[False, True, False, False, False],
    )
    assert keep.tolist() == [True, False, False, False, True]
    assert skipped.counts == {("s", NON_FINITE): 1, ("s", OUT_OF_RANGE): 1}  # NaN was absent
    assert skipped.lines() == [
        f"s: 1 point not plotted because {NON_FINITE}",
        f"s: 1 point not plotted because {OUT_OF_RANGE}",
    ]
