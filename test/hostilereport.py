"""A crash log whose every string field carries markup, and the check that a report page
holds only the report's own markup (``html.parser``: elements, attributes, images)."""

from __future__ import annotations

import json
from html.parser import HTMLParser
from pathlib import Path
from typing import Any

from ads_rca.model import FILE_PREFIX, FOLDERS
from ads_rca.sources.log.writer import write_run_log
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
