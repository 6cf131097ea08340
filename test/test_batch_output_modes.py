"""The permissions of what the commands write (issue 43, item 6f).

A tester saw ``results.csv``, ``results.parquet`` and ``runs/*.json`` created 0600 (a
``mkstemp`` temporary renamed over the name) beside a 0644 ``summary.html``. Every output is
a plain file the user shares as any other: created with mode 0666 less the umask (0644
under umask 022), each alike. Real subprocesses of ``python -m ads_rca.cli`` under a known
umask: every file of a batch's ``--out`` (and its folders, 0777 less the umask), and
``diagnose``'s ``--json`` and ``--report``.
"""

from __future__ import annotations

import os
import stat
import subprocess
import sys
from pathlib import Path

import pytest
from commandline import EXAMPLE

pytest.importorskip("distributed")


def run_with_umask(umask: int, *args: str) -> subprocess.CompletedProcess[str]:
    """``ads-rca ARGS`` in a child process whose umask is ``umask``."""
    return subprocess.run(
        [sys.executable, "-m", "ads_rca.cli", *args],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
        preexec_fn=lambda: os.umask(umask),
    )


def modes(root: Path) -> dict[str, int]:
    """Every file and folder under ``root`` (itself included) → its permission bits."""
    found = {".": stat.S_IMODE(root.stat().st_mode)}
    for path in root.rglob("*"):
        found[str(path.relative_to(root))] = stat.S_IMODE(path.lstat().st_mode)
    return found


@pytest.mark.parametrize("umask", [0o022, 0o027])
def test_every_batch_output_is_created_with_the_umask(tmp_path: Path, umask: int) -> None:
    out = tmp_path / "out"
    done = run_with_umask(umask, "batch", str(EXAMPLE), "--workers", "1", "--out", str(out))
    assert done.returncode == 0, done.stderr
    found = modes(out)
    assert {"results.csv", "results.parquet", "summary.html", "runs"} <= set(found), found
    assert any(name.startswith("runs/") and name.endswith(".json") for name in found), found
    expected = {name: (0o777 if (out / name).is_dir() else 0o666) & ~umask for name in found}
    assert {name: oct(mode) for name, mode in found.items()} == {
        name: oct(mode) for name, mode in expected.items()
    }


def test_diagnose_outputs_are_created_with_the_umask(tmp_path: Path) -> None:
    umask = 0o027
    json_out, report = tmp_path / "verdict.json", tmp_path / "report.html"
    done = run_with_umask(
        umask, "diagnose", str(EXAMPLE), "--json", str(json_out), "--report", str(report)
    )
    assert done.returncode == 0, done.stderr
    for path in (json_out, report):
        assert oct(stat.S_IMODE(path.stat().st_mode)) == oct(0o666 & ~umask), path
