"""The ``ads-rca`` program ends a diagnosis without freeing what it loaded, and loses nothing.

The quick exit (:mod:`ads_rca.foundation.quick_exit`) skips the interpreter's teardown: at-exit
handlers do not run. These tests tell it happened by an at-exit handler's line, and check
that everything the command writes (stdout through a pipe, the JSON, the report) is
complete when it does; ``main`` called in-process never ends the process or keeps objects.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from ads_rca.cli import main
from ads_rca.foundation import quick_exit

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "cut_in_perception"
#: The program as its console script runs it, with an at-exit handler that says it ran.
PROGRAM = (
    "import atexit, sys\n"
    "atexit.register(lambda: print('TEARDOWN RAN', file=sys.stderr))\n"
    "from ads_rca.cli import entry\n"
    "sys.argv[0] = 'ads-rca'\n"
    "entry()\n"
)


def program(*args: str) -> subprocess.CompletedProcess[str]:
    command = [sys.executable, "-c", PROGRAM, *args]
    return subprocess.run(command, check=False, capture_output=True, text=True, timeout=120)


def test_a_diagnosis_ends_at_once_with_every_output_complete(tmp_path: Path) -> None:
    out, report = tmp_path / "verdict.json", tmp_path / "report.html"
    done = program("diagnose", str(EXAMPLE), "--json", str(out), "--report", str(report))
    assert done.returncode == 0, done.stderr
    assert "TEARDOWN RAN" not in done.stderr  # ended by the quick exit
    # stdout is a pipe (block-buffered): its last lines were flushed before the end
    assert done.stdout.splitlines()[-2:] == [f"verdict JSON: {out}", f"HTML report: {report}"]
    in_process = tmp_path / "in_process.json"
    assert main(["diagnose", str(EXAMPLE), "--json", str(in_process)]) == 0
    assert json.loads(out.read_text()) == json.loads(in_process.read_text())
    assert report.read_text().rstrip().endswith("</html>")


def test_both_modes_end_at_once_after_the_comparison() -> None:
    done = program("diagnose", str(EXAMPLE), "--semantics", "both")
    assert done.returncode == 0, done.stderr
    assert "TEARDOWN RAN" not in done.stderr
    assert "semantics reference" in done.stdout and "semantics corrected" in done.stdout


def test_an_error_or_another_command_ends_the_usual_way(tmp_path: Path) -> None:
    missing = program("diagnose", str(tmp_path / "no_such_log"))
    assert missing.returncode == 2
    assert missing.stderr.splitlines() == [
        f"ads-rca diagnose: error: {tmp_path / 'no_such_log'}: no such log folder or bag",
        "TEARDOWN RAN",
    ]
    version = program("--version")
    assert version.returncode == 0 and "TEARDOWN RAN" in version.stderr


def test_main_in_process_keeps_nothing(tmp_path: Path) -> None:
    assert main(["diagnose", str(EXAMPLE), "--json", str(tmp_path / "v.json")]) == 0
    assert not quick_exit.requested()  # the run was freed as usual, the caller goes on
