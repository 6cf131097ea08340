"""``ads-rca batch --resume`` with other options than the results' (issue 43, item 4).

Real batches (``python -m ads_rca.cli batch`` in a subprocess, one local worker) over real
synthesised log folders. Checked: the first batch records its options in
``OUT/options.json``; ``--resume`` with another ``--semantics``, or a ``--config`` file
whose content changed, is one line, exit status 2, naming each option with its recorded and
its new value, and writes nothing (no row of the other options joins the table); the same
options resume; a folder from before the record resumes when its rows' semantics match
(said in one line, the record written) and is refused when they do not; a record that is
no record is one line.
"""

from __future__ import annotations

import csv
import json
import shutil
import subprocess
from pathlib import Path

import pytest
from commandline import assert_clean, assert_one_line, run_cli

from ads_rca.sources.log.writer import write_run_log
from ads_rca.synth import synthesise

pytest.importorskip("distributed")

#: The record of a batch's options in its folder (a literal: the test runs against old code).
OPTIONS_NAME = "options.json"


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """Two synthesised log folders (80 frames each)."""
    root = tmp_path_factory.mktemp("runs")
    return (
        write_run_log(synthesise("cut_in", "perception", 0, frames=80), root / "run_0"),
        write_run_log(synthesise("cut_in", "planning", 1, frames=80), root / "run_1"),
    )


@pytest.fixture(scope="module")
def first(runs: tuple[Path, Path], tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A finished batch of the first run, made with ``--config`` (its ``CONFIG`` beside it)."""
    root = tmp_path_factory.mktemp("first")
    (root / "thresholds.yaml").write_text("safety_margin: 0.5\n", encoding="utf-8")
    assert_clean(batch(root / "out", str(runs[0])))
    return root


@pytest.fixture
def out(first: Path, tmp_path: Path) -> Path:
    """A copy of :func:`first`'s folder (its config file beside it) to resume."""
    shutil.copytree(first, tmp_path, dirs_exist_ok=True)
    return tmp_path / "out"


def batch(out: Path, *args: str) -> subprocess.CompletedProcess[str]:
    """``ads-rca batch ARGS`` into ``out``, with the thresholds file beside it, one worker."""
    config = str(out.parent / "thresholds.yaml")
    return run_cli(
        "batch", *args, "--config", config, "--workers", "1", "--out", str(out), timeout=300
    )


def rows(out: Path) -> list[dict[str, str]]:
    with (out / "results.csv").open(encoding="utf-8", newline="") as handle:
        return list(csv.DictReader(handle))


def test_the_options_are_recorded(out: Path) -> None:
    recorded = json.loads((out / OPTIONS_NAME).read_text(encoding="utf-8"))
    assert recorded["version"] == 1
    options = recorded["options"]
    assert options["--semantics"] == "corrected"
    assert options["-p safety_margin"] == 0.5
    assert "--workers" not in options and "--timeout" not in options


def test_resume_with_another_semantics_is_refused(runs: tuple[Path, Path], out: Path) -> None:
    before = (out / "results.csv").read_bytes()
    done = batch(out, *map(str, runs), "--resume", "--semantics", "reference")
    assert_one_line(done, "its results were made with other options: --semantics corrected "
                    "(now reference)")  # fmt: skip
    assert "give the same options, or a new --out" in done.stderr
    assert (out / "results.csv").read_bytes() == before
    assert [r["semantics"] for r in rows(out)] == ["corrected"]


def test_resume_with_a_changed_config_file_is_refused(runs: tuple[Path, Path], out: Path) -> None:
    (out.parent / "thresholds.yaml").write_text("safety_margin: 0.8\n", encoding="utf-8")
    done = batch(out, *map(str, runs), "--resume")
    assert_one_line(done, "-p safety_margin 0.5 (now 0.8)")
    assert len(rows(out)) == 1


def test_resume_with_the_same_options_goes_on(runs: tuple[Path, Path], out: Path) -> None:
    done = batch(out, *map(str, runs), "--resume", "--timeout", "300", "--retries", "1")
    assert_clean(done)
    assert "1 of 2 runs already done" in done.stdout
    assert len(rows(out)) == 2


def test_a_folder_from_before_the_record(runs: tuple[Path, Path], out: Path) -> None:
    """No options.json: refused when its rows' semantics differ, else adopted, said, recorded."""
    (out / OPTIONS_NAME).unlink()
    refused = batch(out, *map(str, runs), "--semantics", "reference", "--resume")
    assert_one_line(refused, "its rows were made with other options: --semantics corrected "
                    "(now reference)")  # fmt: skip
    assert not (out / OPTIONS_NAME).exists()
    assert len(rows(out)) == 1
    adopted = batch(out, *map(str, runs), "--resume")
    assert_clean(adopted)
    assert f"has no {OPTIONS_NAME} (made before the options were recorded)" in adopted.stderr
    assert (out / OPTIONS_NAME).is_file()
    assert [r["semantics"] for r in rows(out)] == ["corrected", "corrected"]


@pytest.mark.parametrize("content", [b"", b"\xff\xfe", b"[1, 2]", b'{"version": 9}'])
def test_a_record_that_is_no_record_is_one_line(
    runs: tuple[Path, Path], out: Path, content: bytes
) -> None:
    (out / OPTIONS_NAME).write_bytes(content)
    done = batch(out, str(runs[0]), "--resume")
    assert_one_line(done, f"--resume {out / OPTIONS_NAME}: cannot read")
