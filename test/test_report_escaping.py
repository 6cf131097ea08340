"""The HTML report never lets text from a log become markup.

A crash log is rewritten so that EVERY string field a log can carry holds markup: actor ids
(ego and partner included), detection ids, labels and extra keys/values, prediction obstacle
ids and step keys, plan keys, metadata keys and values, file names in every folder, and the
log folder's own path. The report is then parsed with ``html.parser``: only the report's own
elements and attributes may appear, and every payload must come back as plain text.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from hostilereport import (
    ATTRIBUTE,
    FILE_PAYLOAD,
    MATHTEXT,
    SCRIPT,
    assert_only_report_markup,
    hostile_log,
)

from ads_rca.diagnosis.engine import diagnose
from ads_rca.params import make_params
from ads_rca.report.html import render
from ads_rca.sources.registry import open_run


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
