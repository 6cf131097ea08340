"""Outputs written onto a full disk (issue 41): one line, exit status 2, nothing lost.

A real full disk: a small tmpfs mounted for the test (``fulldisk.small_tmpfs``; skipped
where mounting is not permitted), filled to its last byte. Checked, each command in a
subprocess: ``diagnose --json F`` and ``--report F`` say so in one line, exit 2, and F keeps
its earlier content byte for byte (it was truncated before); ``batch --out`` on a disk that
fills mid-batch is one line and exit 2, no ``OSError`` traceback, every row written before
is whole with its verdict JSON, and once there is room ``--resume`` completes the batch;
a CSV row that only partly fits is cut off again, so the file ends on a whole row.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from commandline import assert_one_line
from fulldisk import fill, small_tmpfs

from ads_rca.batch.rows import error_row
from ads_rca.batch.store import CSV_NAME, ResultStore, StoreError, read_csv
from ads_rca.sources.log.writer import write_run_log
from ads_rca.synth import synthesise

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "examples" / "cut_in_perception"
PREVIOUS = "the previous verdict, to keep\n"


def ads_rca(*args: str, timeout: float = 180) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    return subprocess.run(
        [sys.executable, "-m", "ads_rca.cli", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=env,
        check=False,
    )


@pytest.mark.parametrize("option", ["--json", "--report"])
def test_diagnose_onto_a_full_disk_keeps_the_earlier_file(option: str, tmp_path: Path) -> None:
    with small_tmpfs(tmp_path / "disk", "64k") as disk:
        target = disk / "verdict"
        target.write_text(PREVIOUS)
        fill(disk)
        done = ads_rca("diagnose", str(EXAMPLE), option, str(target), "--workers", "1")
        assert target.read_text() == PREVIOUS  # it was truncated, then left empty
        assert_one_line(
            done,
            f"ads-rca diagnose: error: {option} {target}: cannot write (No space left on "
            "device); left as it was",
        )
        assert sorted(p.name for p in disk.iterdir()) == ["filler", "verdict"]


@pytest.mark.slow
def test_batch_onto_a_disk_that_fills_keeps_every_row_written(tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    for i, (scenario, fault) in enumerate(
        [
            ("cut_in", "perception"),
            ("lead_braking", "planning"),
            ("cut_in", "none"),
            ("left_turn", "controller"),
            ("pedestrian_crossing", "prediction"),
            ("cut_in", "planning"),
        ]
    ):
        write_run_log(synthesise(scenario, fault, 0, frames=120), runs / f"run_{i}")
    # Each verdict JSON is about 330 kB: two or so fit.
    with small_tmpfs(tmp_path / "disk", "800k") as disk:
        out = disk / "out"
        done = ads_rca("batch", f"{runs}/run_*", "--out", str(out), "--workers", "1")
        assert_one_line(done, f"ads-rca batch: error: --out {out}/")
        assert "cannot write (No space left on device); the " in done.stderr
        assert "finished runs written before are kept (--resume continues the batch)" in (
            done.stderr
        )
        text = (out / CSV_NAME).read_text()
        assert text.endswith("\n")
        rows = read_csv(out / CSV_NAME)
        assert 1 <= len(rows) < 6 and len(text.splitlines()) == 1 + len(rows)
        assert f"the {len(rows)} finished runs" in done.stderr
        for row in rows:
            assert row["error"] == "", row
            document = json.loads((out / "runs" / f"{row['run_id']}.json").read_bytes())
            assert document["root_causes"] is not None
        assert not [p for p in out.rglob(".*.tmp")]  # no temporary file left
        # Room again: --resume keeps those rows and completes the batch.
        remount = ["mount", "-o", "remount,size=8m", str(disk)]
        assert subprocess.run(remount, check=False).returncode == 0
        done = ads_rca("batch", f"{runs}/run_*", "--out", str(out), "--workers", "1", "--resume")
        assert done.returncode == 0, done.stderr
        assert f"--resume: {len(rows)} of 6 runs already done" in done.stdout
        assert [r["run_id"] for r in read_csv(out / CSV_NAME)][: len(rows)] == [
            r["run_id"] for r in rows
        ]
        assert len(read_csv(out / CSV_NAME)) == 6


def test_a_row_that_only_partly_fits_is_cut_off_again(tmp_path: Path) -> None:
    with small_tmpfs(tmp_path / "disk", "64k") as disk:
        store = ResultStore(disk / "out")
        fill(disk)  # what is left: the slack of the CSV's last page
        added = 0
        with pytest.raises(StoreError, match=r"results.csv: cannot write \(No space left"):
            while True:
                store.add(error_row(f"{added:016x}", f"/runs/{added}", "x" * 300), None)
                added += 1
        assert added >= 1  # some rows fitted in the slack, the next one did not
        text = (disk / "out" / CSV_NAME).read_text()
        assert text.endswith("\n")
        assert [row["run_id"] for row in read_csv(disk / "out" / CSV_NAME)] == [
            f"{i:016x}" for i in range(added)
        ]
        store.close()  # after the failure: what can be written is, no second error
