"""The scorer protocol: the figures a run's data gives beside
the verdict come from the scorers of :data:`ads_rca.sources.registry.SCORERS`, which the
engine, the summary, the not-judged results and the live statuses ask without naming any
dataset. A scorer registered in-process shows in each of them; a scorer whose data a run
does not hold is not even imported.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import types
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import pytest

import ads_rca
from ads_rca.diagnosis.engine import diagnose
from ads_rca.diagnosis.scoring import FrameScores, Scorer
from ads_rca.diagnosis.summary import summary_text
from ads_rca.diagnosis.verdict import FrameResults, Metric
from ads_rca.live.diagnostics import OK, result_status
from ads_rca.live.results import LiveResult
from ads_rca.model import RunLog
from ads_rca.oracles.base import RunContext
from ads_rca.oracles.semantics import not_judged
from ads_rca.params import Params, make_params
from ads_rca.sources import registry
from ads_rca.sources.log.writer import write_run_log
from ads_rca.sources.registry import SCORERS, SUMMARY_ORDER, ScorerEntry
from ads_rca.synth import synthesise

PACKAGE = Path(ads_rca.__file__).resolve().parent
#: The modules that iterate the scorers: none may name a dataset.
ITERATING = (
    "diagnosis/engine.py",
    "diagnosis/summary.py",
    "live/window.py",
    "live/diagnostics.py",
    "live/aggregate.py",
    "oracles/semantics.py",
    "oracles/base.py",
    "batch/rows.py",
    "batch/work.py",
)
DATASET_NAMES = re.compile(r"openlane|atmacup|\bdlp\b|dragon lake|carla", re.IGNORECASE)


def test_the_modules_that_iterate_the_scorers_name_no_dataset() -> None:
    named = {
        module: sorted({m.lower() for m in DATASET_NAMES.findall((PACKAGE / module).read_text())})
        for module in ITERATING
    }
    assert {module: found for module, found in named.items() if found} == {}


def test_the_table_agrees_with_its_scorers() -> None:
    assert sorted(SUMMARY_ORDER) == sorted(entry.name for entry in SCORERS)
    for entry in SCORERS:
        assert entry.scorer().keys == entry.keys, entry.name


# --- a scorer registered in-process -------------------------------------------------------------


class ToyScorer(Scorer):
    """Scores the controller's not-judged frames with their stamp, counts them over the run."""

    keys = ("toy_scores",)

    def document(
        self, log: RunLog, frames: Sequence[FrameResults], semantics: str
    ) -> dict[str, Any]:
        return {"toy_scores": {"frames": len(frames), "semantics": semantics}}

    def summary_lines(self, document: Mapping[str, Any], shown: int) -> list[str]:
        return [f"toy scores: {document['toy_scores']['frames']} frames"]

    def frame_scores(
        self, log: RunLog, timestamp_ms: int, params: Params, kept: dict[str, Any]
    ) -> FrameScores:
        kept["seen"] = kept.get("seen", 0) + 1
        return FrameScores({"toy_stamp": timestamp_ms, "toy_seen": kept["seen"]}, {"toy": 1.0})

    def status_text(self, metrics: Mapping[str, Metric]) -> str | None:
        return f"toy scored at {metrics['toy_stamp']}" if "toy_stamp" in metrics else None


@pytest.fixture
def toy_scorer(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    module = types.ModuleType("toy_scorer_module")
    module.SCORER = ToyScorer()  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "toy_scorer_module", module)
    entry = ScorerEntry(
        "toy",
        "toy_scorer_module",
        ("toy_scores",),
        "controller",
        frame_data=lambda log: True,
        run_data=lambda log: True,
    )
    monkeypatch.setattr(registry, "SCORERS", (*SCORERS, entry))
    monkeypatch.setattr(registry, "SUMMARY_ORDER", (*SUMMARY_ORDER, "toy"))
    yield
    registry._scorer.cache_clear()


@pytest.fixture(scope="module")
def small_run() -> RunLog:
    return synthesise("cut_in", "perception", seed=4)


def test_to_json_and_the_summary_ask_a_registered_scorer(
    small_run: RunLog, toy_scorer: None
) -> None:
    document = diagnose(small_run, make_params("corrected")).to_json()
    keys = [key for key in document if key != "$nonfinite"]  # json_safe's, always last
    assert keys[-1] == "toy_scores"  # after the contract's keys, in table order
    assert document["toy_scores"] == {"frames": len(document["frames"]), "semantics": "corrected"}
    lines = summary_text(document).splitlines()
    toy = lines.index(f"toy scores: {len(document['frames'])} frames")
    assert lines[toy + 1].startswith("input problems")  # the run's figures, then its problems


def test_a_not_judged_result_and_its_live_status_ask_a_registered_scorer(
    small_run: RunLog, toy_scorer: None
) -> None:
    ctx = RunContext.create(small_run, make_params("corrected"))
    stamps = small_run.frames[:2]
    results = [not_judged("controller", "not judged (no control)", True, ctx, ts) for ts in stamps]
    assert [r.metrics for r in results] == [
        {"toy_stamp": stamps[0], "toy_seen": 1},
        {"toy_stamp": stamps[1], "toy_seen": 2},  # the scorer's state lasts the run
    ]
    assert results[0].thresholds == {"toy": 1.0} and results[0].skipped == "not judged (no control)"
    unscored = not_judged("controller", "not judged (no control)", False, ctx, stamps[0])
    assert unscored.metrics == {} and unscored.thresholds == {}
    status = result_status(LiveResult(1, results[1], 7), "corrected", "test")
    expected = f"frame 7: toy scored at {stamps[1]}; the verdict rule: not judged (no control)"
    assert (status.level, status.message) == (OK, expected)


def test_a_run_without_a_scorers_data_never_imports_it(tmp_path: Path) -> None:
    """A small diagnosis loads no dataset's scoring code: each scorer module is imported
    only when a run holds what it scores."""
    folder = write_run_log(synthesise("cut_in", "perception", seed=4), tmp_path / "log")
    code = (
        "import json, sys\n"
        "from ads_rca.cli import main\n"
        "from ads_rca.sources.registry import SCORERS\n"
        f"status = main(['diagnose', {str(folder)!r}, '--json', {str(tmp_path / 'v.json')!r}])\n"
        "print(json.dumps([status, [e.module for e in SCORERS if e.module in sys.modules]]))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    status, imported = json.loads(done.stdout.strip().splitlines()[-1])
    assert status == 0 and imported == []
