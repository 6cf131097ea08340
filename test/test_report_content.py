"""The HTML report reads as an engineer debugging the crash needs it.

On the bundled crash (perception missed the cutting-in partner 2486 from frame 47; the
clearance fell below the margin at frame 68; collision at frame 81): the page is one file
with nothing external, shows the scene from above at the first failure and at the
collision, every axis says its unit, the plan and the actors are in the legend and their
labels sit beside the boxes, the perception panel plots the partner's clearance (not the
overall recall), each series that ends early is explained, and the evidence is a table.
"""

from __future__ import annotations

import json
import re
from html.parser import HTMLParser
from pathlib import Path

import pytest
from matplotlib.figure import Figure
from matplotlib.patches import Polygon

from ads_rca.diagnosis.engine import Diagnosis, diagnose
from ads_rca.oracles.base import MODULES
from ads_rca.oracles.semantics import MODES, semantics_for
from ads_rca.params import make_params
from ads_rca.report.figures import (
    Skipped,
    legend_labels,
    metrics_figure,
    scene_figure,
    scene_frames,
    series_ends,
)
from ads_rca.report.html import render, value_table
from ads_rca.sources.registry import open_run

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "cut_in_perception"
PARTNER, EGO = "2486", "1323"


@pytest.fixture(scope="module")
def corrected() -> Diagnosis:
    return diagnose(open_run(EXAMPLE), make_params("corrected"))


@pytest.fixture(scope="module")
def page(corrected: Diagnosis) -> str:
    return render(corrected)


class Elements(HTMLParser):
    """Start tags with their attributes, and the text inside each ``li`` and ``figcaption``."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.tags: list[tuple[str, dict[str, str | None]]] = []
        self.items: list[str] = []
        self.captions: list[str] = []
        self._into: list[str] | None = None

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.tags.append((tag, dict(attrs)))
        if tag in ("li", "figcaption"):
            (self.items if tag == "li" else self.captions).append("")
            self._into = self.items if tag == "li" else self.captions

    def handle_endtag(self, tag: str) -> None:
        if tag in ("li", "figcaption"):
            self._into = None

    def handle_data(self, data: str) -> None:
        if self._into is not None:
            self._into[-1] += data


def elements(page: str) -> Elements:
    parsed = Elements()
    parsed.feed(page)
    parsed.close()
    return parsed


def test_the_page_is_self_contained(page: str) -> None:
    """No script, no link, no URL but the figures' own data: it opens offline, anywhere."""
    parsed = elements(page)
    tags = {tag for tag, _ in parsed.tags}
    assert not tags & {"script", "link", "iframe", "object", "embed", "a", "base"}
    for _tag, attrs in parsed.tags:
        assert "href" not in attrs
        if "src" in attrs:
            assert (attrs["src"] or "").startswith("data:image/png;base64,")
    outside_images = re.sub(r'src="data:image/png;base64,[A-Za-z0-9+/=]*"', "", page)
    assert not re.search(r"https?:|//[a-z]|url\(|@import", outside_images)


def test_scenes_at_the_first_failure_and_at_the_collision(corrected: Diagnosis, page: str) -> None:
    assert scene_frames(corrected) == [("first failure (perception)", 68), ("collision", 81)]
    parsed = elements(page)
    assert parsed.captions == ["First failure (perception), frame 68", "Collision, frame 81"]
    alts = [attrs.get("alt") for tag, attrs in parsed.tags if tag == "img"]
    assert alts == ["scene at frame 68", "scene at frame 81", "metrics over time"]


def test_one_scene_when_the_first_failure_is_the_collision(corrected: Diagnosis) -> None:
    a = corrected.attribution
    primary = a.primary_root_cause
    assert primary is not None
    first = a.modules[primary].first_failure_frame
    a.modules[primary].first_failure_frame = corrected.log.metadata.collision_frame
    try:
        assert scene_frames(corrected) == [("collision and first failure (perception)", 81)]
    finally:
        a.modules[primary].first_failure_frame = first


def test_every_axis_says_its_unit(corrected: Diagnosis) -> None:
    metrics = metrics_figure(corrected, Skipped())
    panels = metrics.axes[: len(MODULES)]
    units = [re.search(r"\(([^()]*)\)$", ax.get_ylabel().replace("\n", " ")) for ax in panels]
    assert [u.group(1) if u else None for u in units] == ["m", "m", "m", "m/s"]
    assert panels[-1].get_xlabel() == "frame"
    (time_axis,) = panels[0].child_axes
    assert time_axis.get_xlabel() == "time since the log's start (s)"
    for _caption, frame in scene_frames(corrected):
        (ax,) = scene_figure(corrected, frame, Skipped()).axes
        assert ax.get_xlabel() == "x (m)"
        assert ax.get_ylabel().startswith("y (m")


def test_the_scene_legend_names_the_plan_and_the_actors(corrected: Diagnosis) -> None:
    scene = scene_figure(corrected, 68, Skipped())
    labels = legend_labels(scene)
    for entry in ("ego", "collision partner", "plan (waypoints)", "other actors"):
        assert entry in labels
    assert "predictions with perception" in labels


def label_overlaps(fig: Figure) -> list[tuple[str, str]]:
    """(label, box) pairs where an actor's label covers the ego's or the partner's box."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()  # type: ignore[attr-defined]
    (ax,) = fig.axes
    boxes = [
        (str(p.get_label()), p.get_window_extent(renderer))
        for p in ax.patches
        if isinstance(p, Polygon) and p.get_label() in ("ego", "collision partner")
    ]
    assert len(boxes) == 2
    found = []
    for text in ax.texts:
        patch = text.get_bbox_patch()
        extent = (patch or text).get_window_extent(renderer)
        found += [(text.get_text(), name) for name, box in boxes if extent.overlaps(box)]
    return found


def test_actor_labels_sit_beside_the_boxes(corrected: Diagnosis) -> None:
    for _caption, frame in scene_frames(corrected):
        scene = scene_figure(corrected, frame, Skipped())
        texts = sorted(t.get_text() for t in scene.axes[0].texts)
        assert texts == [f"ego {EGO}", f"partner {PARTNER}"]
        assert label_overlaps(scene) == []


def test_the_perception_panel_shows_the_partner_not_the_recall(corrected: Diagnosis) -> None:
    perception = metrics_figure(corrected, Skipped()).axes[0]
    assert perception.get_title(loc="left") == f"perception \N{EM DASH} partner {PARTNER}"
    lines = {str(line.get_label()) for line in perception.get_lines()}
    assert {"c_gt", "c_raw", "safety_margin = 0.5", "failed frame"} <= lines
    assert "recall" not in lines and "mean_iou" not in lines
    legend = perception.get_legend()
    assert legend is not None
    assert "partner in view but unmatched" in [t.get_text() for t in legend.texts]
    assert "clearance to the partner" in perception.get_ylabel().replace("\n", " ")


def test_series_that_end_early_are_explained(corrected: Diagnosis, page: str) -> None:
    assert [end.line() for end in series_ends(corrected)] == [
        "perception c_gt: no value after frame 80 (frame 81: the log's last frame, where the "
        "oracle reports no c_gt)",
        "perception c_raw: no value after frame 47 (34 frames up to frame 81: raw_linked = false)",
        "prediction displacement_error: no value after frame 80 (frame 81: the log's last "
        "frame, where the oracle reports no displacement_error)",
        "planning c_plan: no value after frame 47 (34 frames up to frame 81: "
        "partner_in_planner_inputs = false)",
        "planning c_gt: no value after frame 80 (frame 81: the log's last frame, where the "
        "oracle reports no c_gt)",
        "controller sum_speed_innovation: no value after frame 80 (frame 81: check skipped at "
        "1 frame(s): missing pose at 4100 ms)",
    ]
    items = elements(page).items
    for end in series_ends(corrected):
        assert end.line() in items
    planning = metrics_figure(corrected, Skipped()).axes[2]
    assert [t.get_text() for t in planning.texts] == ["no c_plan after frame 47 (see notes)"]


def test_evidence_is_a_table_not_a_python_dict(page: str) -> None:
    evidence = page[page.index("<h2>Evidence</h2>") : page.index("<h2>Metrics over time</h2>")]
    assert "{'" not in evidence and "':" not in evidence
    assert '<tr><th>first_failing_frame</th><td class="num">68</td></tr>' in evidence
    assert "<tr><th>partner_matched</th><td>false</td></tr>" in evidence
    assert '<tr><th>c_gt</th><td class="num">0.4992</td></tr>' in evidence
    assert "<tr><th>runs</th><td>[68, 80]</td></tr>" in evidence
    assert "<tr><th>missed</th><td><table><tr><th>2486</th>" in evidence


def test_evidence_cells_escape_markup_and_show_nan() -> None:
    table = value_table({"<b>key</b>": {"<i>": float("nan"), "ids": ["<script>", 1e-7]}})
    assert "<b>" not in table and "<i>" not in table and "<script>" not in table
    assert "<th>&lt;b&gt;key&lt;/b&gt;</th>" in table
    assert '<th>&lt;i&gt;</th><td class="num">nan</td>' in table
    assert "<td>&lt;script&gt;, 1e-07</td>" in table


@pytest.mark.parametrize("mode", sorted(MODES))
def test_every_headline_names_its_unit(mode: str) -> None:
    semantics = semantics_for(mode)
    assert set(semantics.headline) == set(MODULES)
    for choices in semantics.headline.values():
        assert choices
        for choice in choices:
            assert choice.keys and choice.unit and choice.quantity
            assert set(choice.gates) <= set(choice.keys)
            assert choice.threshold is None or choice.threshold in semantics.parameters


def test_a_hostile_log_with_nan_still_renders_as_text_only(tmp_path: Path) -> None:
    """Markup in every string and NaN poses: the new sections (scenes, notes, evidence
    tables) keep log text as text, and the series the NaN cuts short are explained."""
    from hostilereport import assert_only_report_markup, hostile_log

    folder, ids = hostile_log(tmp_path)
    for frame in range(60, 66):  # before the collision: the partner is still found
        path = folder / "pose" / f"pose-{frame * 50}.json"
        document = json.loads(path.read_text())
        document["x"] = "NaN"
        path.write_text(json.dumps(document))
    result = diagnose(open_run(folder), make_params("corrected"))
    page = render(result)
    text = assert_only_report_markup(page)
    partner = result.attribution.partner_id
    assert partner is not None
    assert partner in ids.values() and partner in text
    ends = series_ends(result)
    assert ends and all(end.line() in text for end in ends)
    # both scenes draw the ego's path through frames 60-65 (within 40 frames of 68 and 81)
    assert "scene, ego path: 12 points not plotted because non-finite" in text
