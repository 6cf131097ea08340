"""The HTML report never lets text from a log become markup.

A crash log is rewritten so that EVERY string field a log can carry holds markup: actor ids
(ego and partner included), detection ids, labels and extra keys/values, prediction obstacle
ids and step keys, plan keys, metadata keys and values, file names in every folder, and the
log folder's own path. The report is then parsed with ``html.parser``: only the report's own
elements and attributes may appear, and every payload must come back as plain text.
"""

from __future__ import annotations

import json
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path
from typing import Any

import pytest

from ads_rca.diagnosis.engine import diagnose
from ads_rca.model import FILE_PREFIX, FOLDERS
from ads_rca.params import make_params
from ads_rca.report.html import render
from ads_rca.sources.log.writer import write_run_log
from ads_rca.sources.registry import open_run
from ads_rca.synth import synthesise

#: Elements and attributes the report itself writes; nothing else may appear.
REPORT_TAGS = {"html", "head", "meta", "title", "style", "body", "h1", "h2", "h3", "p", "b"}
REPORT_TAGS |= {"table", "tr", "th", "td", "img", "ul", "li", "div", "figure", "figcaption"}
REPORT_ATTRIBUTES = {"charset", "class", "alt", "src"}

SCRIPT = '<script>alert("{}")</script>'
#: Breaks out of an attribute, then of a tag; plus a mathtext bomb for the figures.
ATTRIBUTE = "\"' onmouseover='alert(1)' x=\"><svg onload=alert(1)>"
MATHTEXT = r"$\frac{$"
#: File names cannot hold "/", but can hold < > " ' (and spaces).
FILE_PAYLOAD = "<img src=x onerror=alert(1)>"


def actor_payload(actor_id: str) -> str:
    return SCRIPT.format(actor_id) + ATTRIBUTE + MATHTEXT


def hostile_log(root: Path) -> tuple[Path, dict[str, str]]:
    """A cut-in crash whose every string field carries markup; returns folder and id map."""
    folder = root / f"log {FILE_PAYLOAD}\"'"
    log = synthesise("cut_in", "perception", seed=3)
    write_run_log(log, folder)
    after = max(log.frames) + log.frame_ms  # stamps past the end: the crash is judged as before
    ids: dict[str, str] = {}

    def rename(actor_id: Any) -> str:
        return ids.setdefault(str(actor_id), actor_payload(actor_id))

    for path in sorted((folder / "actors").iterdir()):
        document = json.loads(path.read_text())
        path.write_text(json.dumps({rename(k): v for k, v in document.items()}))
    for path in sorted((folder / "bboxes_gt").iterdir()):
        boxes = json.loads(path.read_text())
        path.write_text(json.dumps([{**b, "id": rename(b["id"])} for b in boxes]))
    for path in sorted((folder / "bboxes").iterdir()):
        boxes = json.loads(path.read_text())
        for box in boxes:
            box["id"] = SCRIPT.format(f"det {box['id']}")
            box["label"] = SCRIPT.format("label")
            box[SCRIPT.format("extra key")] = SCRIPT.format("extra value")
        path.write_text(json.dumps(boxes))
    for name in ("predictions", "predictions_with_perception"):
        for path in sorted((folder / name).iterdir()):
            tracks = json.loads(path.read_text())
            renamed = {rename(k): v for k, v in tracks.items()}
            for track in list(renamed.values())[:1]:
                track[SCRIPT.format("step key")] = {"x": 1.0, "y": 0.0, "z": 0.0}
            path.write_text(json.dumps(renamed))
    for path in sorted((folder / "waypoint").iterdir())[:3]:
        plan = json.loads(path.read_text())
        plan[SCRIPT.format("plan key")] = {"x": 0.0, "y": 0.0, "speed": 1.0}
        path.write_text(json.dumps(plan))
    metadata = json.loads((folder / "metadata.json").read_text())
    metadata[SCRIPT.format("metadata key")] = SCRIPT.format("metadata value")
    metadata["total_frames"] = SCRIPT.format("total_frames")
    metadata["ego_config"][SCRIPT.format("ego key")] = ATTRIBUTE
    (folder / "metadata.json").write_text(json.dumps(metadata))
    for sub in FOLDERS:
        prefix = FILE_PREFIX[sub]
        (folder / sub / f"{prefix}-{FILE_PAYLOAD}-{after}.json").write_text("{}")
        (folder / sub / f"{prefix}-\"'><b>-{after + log.frame_ms}.json").write_text("[")
    return folder, ids


class Structure(HTMLParser):
    """Every element, attribute, comment and declaration of a page, and its text."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.tags: list[tuple[str, list[tuple[str, str | None]]]] = []
        self.other: list[str] = []
        self.text: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.tags.append((tag, attrs))

    def handle_startendtag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.tags.append((tag, attrs))

    def handle_data(self, data: str) -> None:
        self.text.append(data)

    def handle_comment(self, data: str) -> None:
        self.other.append(f"comment {data}")

    def handle_decl(self, decl: str) -> None:
        if decl.lower() != "doctype html":
            self.other.append(f"declaration {decl}")

    def handle_pi(self, data: str) -> None:
        self.other.append(f"processing instruction {data}")

    def unknown_decl(self, data: str) -> None:
        self.other.append(f"unknown declaration {data}")


def parse(page: str) -> Structure:
    structure = Structure()
    structure.feed(page)
    structure.close()
    return structure


def assert_only_report_markup(page: str) -> str:
    """No element, attribute or script of the page comes from a log; returns its text."""
    structure = parse(page)
    assert structure.other == []
    tags = {tag for tag, _ in structure.tags}
    assert tags <= REPORT_TAGS, tags - REPORT_TAGS
    assert "script" not in tags and "svg" not in tags
    for tag, attrs in structure.tags:
        names = {name for name, _ in attrs}
        assert names <= REPORT_ATTRIBUTES, (tag, attrs)
        assert not any(name.startswith("on") for name in names)
        if tag == "img":
            src = dict(attrs)["src"]
            assert src is not None and src.startswith("data:image/png;base64,")
            assert set(src[22:]) <= set(
                "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/="
            )
    assert [tag for tag, _ in structure.tags].count("img") in (2, 3)  # metrics, 1 or 2 scenes
    assert [tag for tag, _ in structure.tags].count("style") == 1
    return "".join(structure.text)


@pytest.mark.parametrize("semantics", ["corrected", "reference"])
def test_markup_in_every_log_string_stays_text(tmp_path: Path, semantics: str) -> None:
    folder, ids = hostile_log(tmp_path)
    result = diagnose(open_run(folder), make_params(semantics))
    assert result.ctx.ego_id is not None
    shown = [str(folder), result.ctx.ego_id]
    if semantics == "corrected":  # the reference names no partner
        assert result.attribution.partner_id is not None
        shown.append(result.attribution.partner_id)
    assert all(actor in ids.values() for actor in shown[1:])  # the payloads reach the report
    page = render(result)
    text = assert_only_report_markup(page)
    assert "<script" not in page.lower() and "<svg" not in page.lower()
    for payload in shown:
        assert payload in text  # shown, as text
    problems = "\n".join(str(p) for p in result.problems)
    assert FILE_PAYLOAD in problems and FILE_PAYLOAD in text  # file names, as text
    assert SCRIPT.format("total_frames") in problems
    for problem in result.problems:
        assert str(problem) in text


def test_every_string_of_the_report_is_escaped_text(tmp_path: Path) -> None:
    """Whatever ends in the page as text is exactly the escaped string, nowhere raw."""
    folder, _ = hostile_log(tmp_path)
    result = diagnose(open_run(folder), make_params("corrected"))
    page = render(result)
    for raw in (SCRIPT.format("total_frames"), ATTRIBUTE, FILE_PAYLOAD, str(folder)):
        assert raw not in page
    assert "&lt;img src=x onerror=alert(1)&gt;" in page


def test_diagnose_report_from_the_command_line(tmp_path: Path) -> None:
    """The CLI path too: the report of the hostile log is written, markup kept as text."""
    folder, ids = hostile_log(tmp_path)
    out = tmp_path / "report.html"
    done = subprocess.run(
        [sys.executable, "-m", "ads_rca.cli", "diagnose", str(folder), "--report", str(out)],
        check=False,
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    text = assert_only_report_markup(out.read_text())
    assert any(payload in text for payload in ids.values())


@pytest.mark.parametrize("text", [MATHTEXT, r"a\$b", r"\$x$", "$$", "\\", r"$\alpha$", "x" * 500])
def test_figure_text_is_never_mathtext_and_draws(text: str) -> None:
    """A log string with ``$`` is shown as written, not parsed as mathtext (which fails)."""
    from matplotlib import cbook
    from matplotlib.figure import Figure

    from ads_rca.report.figures import PLOT_TEXT_MAX, plot_text

    shown = plot_text(text)
    assert not cbook.is_math_text(shown)
    assert len(shown.replace(r"\$", "$")) <= PLOT_TEXT_MAX
    if len(text) <= PLOT_TEXT_MAX:
        assert shown.replace(r"\$", "$") == text
    fig = Figure()
    fig.add_subplot().annotate(shown, (0, 0))
    fig.canvas.draw()
