"""The text table names its counts for what they are in each mode, and ``diagnose
--semantics both`` says in one line why the modes' verdicts differ.

In ``corrected`` mode the JSON's ``collision`` / ``safe`` counts (names the reference fixes)
are the failing frames in persistent runs inside the effect window / the other failing
frames; the table heads them ``counted`` / ``other`` and says so under it.
"""

from __future__ import annotations

import copy
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from ads_rca.diagnosis.compare import why_modes_differ
from ads_rca.diagnosis.engine import diagnose
from ads_rca.diagnosis.summary import summary_text
from ads_rca.diagnosis.verdict import MODULES
from ads_rca.oracles.semantics import semantics_for
from ads_rca.params import SEMANTICS, make_params
from ads_rca.sources.registry import open_run

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "cut_in_perception"
CLI = [sys.executable, "-m", "ads_rca.cli"]
#: Each mode's verdict document (``Diagnosis.to_json``), by mode name.
Documents = dict[str, dict[str, Any]]
#: The example in both modes (counts known from the JSON: reference blames the
#: controller, 9 frames in its window; corrected perception, 13 counted frames).
WHY = (
    "why the modes differ: perception: corrected counts 13 failing frames in its window, "
    "reference finds no failure (its rule: mean IoU of the matched detections below "
    "perc_score_threshold; missed objects never count); controller: reference counts 9 "
    "failing frames in its window, corrected finds no failure (its rule: summed speed or "
    "lateral tracking error over control_horizon above its threshold, toward the partner)"
)


@pytest.fixture(scope="module")
def documents() -> Documents:
    log = open_run(EXAMPLE)
    return {m: diagnose(log, make_params(m)).to_json() for m in ("reference", "corrected")}


def test_each_mode_heads_the_counts_with_its_own_names(documents: Documents) -> None:
    reference = summary_text(documents["reference"]).splitlines()
    corrected = summary_text(documents["corrected"]).splitlines()
    assert reference[2].startswith("effect window: 10 frames (500 ms)")
    assert reference[3].split() == ["module", "collision", "safe", "first", "failure"]
    assert corrected[3].split() == ["module", "counted", "other", "first", "failure"]
    assert corrected[4].split() == ["perception", "13", "0", "frame", "68"]
    assert corrected[8] == (
        "counted: failing frames in persistent runs inside the effect window; "
        "other: the other failing frames (JSON collision / safe)"
    )
    assert reference[8].startswith("verdict: controller")


def test_the_line_names_each_module_one_mode_blames_and_what_the_other_saw(
    documents: Documents,
) -> None:
    assert why_modes_differ([documents["reference"], documents["corrected"]]) == WHY


@pytest.mark.parametrize("mode", SEMANTICS)
def test_every_mode_states_each_modules_rule(mode: str) -> None:
    rules = semantics_for(mode).rules
    assert list(rules) == list(MODULES)
    assert all(rule and "\n" not in rule for rule in rules.values())


def test_the_modes_agreeing_is_said_too(documents: Documents) -> None:
    same = documents["corrected"]
    assert why_modes_differ([same, same]) == "the modes agree: perception"


def test_uncounted_failures_and_a_different_ranking_are_explained(documents: Documents) -> None:
    reference, corrected = copy.deepcopy(documents["reference"]), documents["corrected"]
    reference["modules"]["perception"]["safe"] = 4  # failed, outside its window
    assert why_modes_differ([reference, corrected]).startswith(
        "why the modes differ: perception: corrected counts 13 failing frames in its window, "
        "reference counts none of its 4 failing frames (window: 10 frames); "
    )
    ranked = copy.deepcopy(corrected)
    ranked.update(primary_root_cause="perception", verdict="x", attribution_basis="b")
    assert why_modes_differ([ranked, corrected]) == (
        "why the modes differ: corrected names perception primary (b); corrected names "
        "perception primary (judged failures in the window)"
    )


def test_diagnose_semantics_both_prints_both_summaries_and_why() -> None:
    result = subprocess.run(
        [*CLI, "diagnose", str(EXAMPLE), "--semantics", "both"],
        capture_output=True,
        text=True,
        check=True,
    )
    lines = result.stdout.splitlines()
    assert lines[0] == f"{EXAMPLE}: 81 frames judged, semantics reference"
    assert f"{EXAMPLE}: 81 frames judged, semantics corrected" in lines
    assert lines[-1] == WHY
    assert result.stderr == ""


def test_both_refuses_one_mode_outputs_in_one_line(tmp_path: Path) -> None:
    out = tmp_path / "v.json"
    argv = [*CLI, "diagnose", str(EXAMPLE), "--semantics", "both", "--json", str(out)]
    result = subprocess.run(argv, capture_output=True, text=True, check=False)
    assert result.returncode == 2
    assert result.stderr == (
        "ads-rca diagnose: error: --semantics both prints a comparison; "
        "--json and --report take one mode\n"
    )
    assert not out.exists()
