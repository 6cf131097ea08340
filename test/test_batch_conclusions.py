"""``ads-rca batch`` and the rule "unknown is an answer" (docs/verdicts.md).

Pure parts first: a row carries ``conclusive``, ``why_inconclusive``, ``collision`` and the
internal error of its verdict; the summaries count inconclusive verdicts on their own, never
as "no fault found", and a run whose diagnosis raised in our code as failed. Then real
batches on a local Dask cluster on 127.0.0.1 (no mocks): one where every run fails exits
with its own status and prints each failure's path once; one where a run's planning oracle
raises (injected by a ``sitecustomize.py`` on the workers' PYTHONPATH, no hook in the
product) gives that run a row with its error and its verdict JSON, beside a clean run and an
inconclusive one.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from unsure_run import EXAMPLE, unsure_copy

from ads_rca.batch.rows import (
    COLUMNS,
    error_row,
    from_text,
    row_from_document,
    to_text,
)
from ads_rca.batch.store import read_csv, read_parquet
from ads_rca.batch.summary import FAILED, INCONCLUSIVE, NONE, Counts, render_html, summary_text
from ads_rca.commands.batch_cmd import EXIT_NONE_DIAGNOSED
from ads_rca.params import make_params

pytest.importorskip("distributed")
pytest.importorskip("pyarrow")

REPO = Path(__file__).resolve().parents[1]
PARAMS = make_params("corrected")

#: A verdict document as ``diagnose --json`` gives it for a run without detections and
#: without a collision source (only the keys a row reads).
INCONCLUSIVE_DOCUMENT: dict[str, Any] = {
    "semantics": "corrected",
    "collision_frame": -1,
    "collision": "unknown",
    "primary_root_cause": None,
    "root_causes": [],
    "contributing": [],
    "verdict": "inconclusive: collision unknown (no source); perception not judged (no x)",
    "conclusive": False,
    "why_inconclusive": ["collision unknown (no source)", "perception not judged (no x)"],
    "internal_errors": [],
    "frames": [],
}
CONCLUSIVE_DOCUMENT: dict[str, Any] = {
    **INCONCLUSIVE_DOCUMENT,
    "collision_frame": 81,
    "collision": "yes",
    "primary_root_cause": "perception",
    "root_causes": ["perception"],
    "verdict": "perception",
    "conclusive": True,
    "why_inconclusive": [],
}
RAISED_DOCUMENT: dict[str, Any] = {
    **CONCLUSIVE_DOCUMENT,
    "verdict": "perception; inconclusive: planning not judged: internal error (E: x) at frame 3",
    "conclusive": False,
    "why_inconclusive": ["planning not judged: internal error (E: x) at frame 3"],
    "internal_errors": [
        {"module": "planning", "error": "E: x", "first_frame": 3, "first_ms": 150, "frames": 9}
    ],
}


def _row(name: str, document: dict[str, Any]) -> dict[str, Any]:
    return row_from_document(name, f"/runs/{name}", document, PARAMS)


def test_a_row_carries_the_conclusion_and_an_internal_error_makes_it_fail() -> None:
    row = _row("a", INCONCLUSIVE_DOCUMENT)
    assert row["conclusive"] is False and row["collision"] == "unknown"
    assert row["why_inconclusive"] == "collision unknown (no source); perception not judged (no x)"
    assert row["error"] == "" and row["internal_error"] == ""
    assert _row("b", CONCLUSIVE_DOCUMENT)["conclusive"] is True
    # A document that does not say it is conclusive (an older one) is not.
    older = {k: v for k, v in CONCLUSIVE_DOCUMENT.items() if k != "conclusive"}
    assert _row("c", older)["conclusive"] is False
    raised = _row("d", RAISED_DOCUMENT)
    assert raised["internal_error"] == "planning: E: x at frame 3 (9 frames)"
    assert raised["error"] == "internal error: planning: E: x at frame 3 (9 frames)"
    assert raised["primary_root_cause"] == "perception"  # its verdict columns are kept
    assert raised["verdict"] == RAISED_DOCUMENT["verdict"] and raised["conclusive"] is False
    assert set(raised) == set(COLUMNS)


def test_a_bool_column_round_trips_through_the_csv() -> None:
    for value, text in ((True, "true"), (False, "false"), (None, "")):
        assert to_text("conclusive", value) == text
        assert from_text("conclusive", text) is value
    with pytest.raises(ValueError, match="conclusive"):
        from_text("conclusive", "True")  # read_csv drops such a line, --resume redoes it


def test_an_error_row_names_the_run_s_path_once() -> None:
    row = error_row("x", "/runs/a", "/runs/a: no frame to analyse")
    assert row["error"] == "no frame to analyse"
    assert error_row("x", "/runs/a", "/runs/a/metadata.json: bad")["error"] == "metadata.json: bad"
    assert error_row("x", "/runs/a", "timed out after 2 s")["error"] == "timed out after 2 s"


def test_summaries_count_inconclusive_verdicts_apart_and_internal_errors_as_failed() -> None:
    no_fault = {
        **INCONCLUSIVE_DOCUMENT,
        "verdict": "no fault found (no collision)",
        "collision": "no",
        "conclusive": True,
        "why_inconclusive": [],
    }
    blamed_inconclusive = {**CONCLUSIVE_DOCUMENT, "verdict": "perception; inconclusive: r"}
    blamed_inconclusive.update(conclusive=False, why_inconclusive=["r"])
    rows = [
        _row("conclusive", CONCLUSIVE_DOCUMENT),
        _row("no_fault", no_fault),
        _row("inconclusive", INCONCLUSIVE_DOCUMENT),
        _row("blamed_inconclusive", blamed_inconclusive),
        _row("raised", RAISED_DOCUMENT),
        error_row("failed", "/runs/failed", "/runs/failed: not an ADS running log"),
    ]
    assert Counts.of(rows) == Counts(
        runs=6, diagnosed=4, inconclusive=2, failed=2, internal_errors=1
    )
    text = summary_text(rows)
    lines = text.splitlines()
    assert lines[0] == "batch done: 6 runs, 4 diagnosed, 2 failed"
    assert lines[1] == "  of the diagnosed: 2 conclusive, 2 inconclusive"
    assert lines[2].startswith("  of the failed: 1 by an internal error (a bug in ads_rca")
    table = lines[lines.index("by primary root cause:") + 1 : lines.index("failures (2):")]
    counts = dict(line.strip().rsplit(None, 1) for line in table)
    assert counts == {"perception": "2", NONE: "1", INCONCLUSIVE: "1", FAILED: "2"}, text
    assert "  raised /runs/raised: internal error: planning: E: x at frame 3" in text
    assert text.count("/runs/failed") == 1  # the path once, its error without it
    html = render_html(rows)
    assert "2 conclusive, 2 inconclusive" in html and "Inconclusive verdicts (2)" in html
    assert "perception not judged (no x)" in html


def _env(*front: Path) -> dict[str, str]:
    env = dict(os.environ)
    paths = [*map(str, front), str(REPO), env.get("PYTHONPATH", "")]
    env["PYTHONPATH"] = os.pathsep.join(p for p in paths if p)
    return env


def batch(*args: str, env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "ads_rca.cli", "batch", *args],
        capture_output=True,
        text=True,
        timeout=300,
        env=env,
        check=False,
    )


def test_a_batch_where_every_run_fails_exits_3_and_names_each_path_once(tmp_path: Path) -> None:
    runs = []
    for name in ("a", "b", "c"):
        run = tmp_path / name
        run.mkdir()
        (run / "metadata.json").write_text("{}")  # no actors/: no frame to analyse
        runs.append(run)
    out = tmp_path / "out"
    done = batch(*map(str, runs), "--out", str(out), "--workers", "2", env=_env())
    assert done.returncode == EXIT_NONE_DIAGNOSED == 3, done.stderr
    assert "batch done: 3 runs, 0 diagnosed, 3 failed" in done.stdout
    for run in runs:
        assert done.stdout.count(str(run.resolve())) == 1, done.stdout
    assert done.stderr.splitlines()[-1] == "ads-rca batch: no run could be diagnosed (3 failed)"
    assert "Traceback" not in done.stderr
    rows = read_csv(out / "results.csv")  # every output is still written
    assert len(rows) == 3 and all(r["error"].startswith("no frame to analyse") for r in rows)
    assert (out / "summary.html").exists() and len(read_parquet(out / "results.parquet")) == 3


#: Wraps the corrected planning oracle so that it raises on any run whose path names
#: "buggy": every process of the batch (the command, the Dask workers, their forked
#: children) imports it at start-up.
SITECUSTOMIZE = """
import ads_rca.oracles.corrected as corrected

_planning = corrected.SEMANTICS.oracles["planning"]


def _raising(ctx, ts):
    if "buggy" in ctx.log.source:
        raise ZeroDivisionError("injected by test_batch_conclusions")
    return _planning(ctx, ts)


corrected.SEMANTICS.oracles["planning"] = _raising
"""


def test_a_run_whose_oracle_raises_is_a_row_with_its_error_not_a_clean_row(
    tmp_path: Path,
) -> None:
    hook = tmp_path / "hook"
    hook.mkdir()
    (hook / "sitecustomize.py").write_text(SITECUSTOMIZE)
    good = Path(shutil.copytree(EXAMPLE, tmp_path / "good"))
    buggy = Path(shutil.copytree(EXAMPLE, tmp_path / "buggy"))
    unsure = unsure_copy(tmp_path / "unsure")
    out = tmp_path / "out"
    done = batch(
        str(good), str(buggy), str(unsure), "--out", str(out), "--workers", "2", env=_env(hook)
    )
    assert done.returncode == 0, done.stderr  # a run was diagnosed
    rows = {Path(r["path"]).name: r for r in read_csv(out / "results.csv")}
    assert rows["good"]["error"] == "" and rows["good"]["conclusive"] is True
    raised = rows["buggy"]
    expected = "planning: ZeroDivisionError: injected by test_batch_conclusions at frame 1"
    assert raised["internal_error"].startswith(expected), raised
    assert raised["error"] == f"internal error: {raised['internal_error']}"
    assert raised["conclusive"] is False and "internal error" in raised["why_inconclusive"]
    document = json.loads((out / "runs" / f"{raised['run_id']}.json").read_text())
    assert document["internal_errors"][0]["module"] == "planning"  # the child kept them
    assert rows["unsure"]["error"] == "" and rows["unsure"]["conclusive"] is False
    assert rows["unsure"]["collision"] == "unknown"
    assert rows["unsure"]["verdict"].startswith("inconclusive: collision unknown")
    assert "batch done: 3 runs, 2 diagnosed, 1 failed" in done.stdout
    assert "of the diagnosed: 1 conclusive, 1 inconclusive" in done.stdout
    assert "of the failed: 1 by an internal error" in done.stdout
    assert f"{raised['run_id']} {raised['path']}: internal error: planning" in done.stdout
    assert "(no fault found)" not in done.stdout
