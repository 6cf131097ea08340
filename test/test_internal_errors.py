"""An oracle that raises is a bug in our own code (docs/verdicts.md "internal error").

The oracles are broken from outside, by ``test/raising_oracles/sitecustomize.py`` on
``PYTHONPATH`` (no hook in the product): every process started with it, the forked judging
workers and the live graph's monitors included, runs the broken oracles. Then:

- ``diagnose`` writes its JSON, names the module "not judged: internal error (...) at frame
  N", files no input problem about it, never says "no fault found", prints the traceback on
  stderr and exits 70, with one module or all four raising, in both modes, alone or with
  ``--workers 2`` on a log long enough to be judged in forked workers.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from ads_rca.engine import PARALLEL_MIN_FRAMES
from ads_rca.errors import EXIT_INTERNAL_ERROR
from ads_rca.io.json_writer import write_run_log
from ads_rca.oracles.base import MODULES
from ads_rca.synth import synthesise

SITE = Path(__file__).resolve().parent / "raising_oracles"
#: What the broken oracles raise (sitecustomize.MESSAGE), as every output names it.
ERROR = "ZeroDivisionError: deliberate test failure"


def raising_env(modules: str, base: dict[str, str] | None = None) -> dict[str, str]:
    """The environment that breaks ``modules`` (comma-separated, or ``all``)."""
    env = dict(os.environ if base is None else base)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(SITE), env.get("PYTHONPATH", "")) if p)
    env["ADS_RCA_TEST_RAISING"] = modules
    return env


def diagnose_raising(
    log_dir: Path, out: Path, modules: str, *options: str
) -> subprocess.CompletedProcess[str]:
    argv = [sys.executable, "-m", "ads_rca.cli", "diagnose", str(log_dir), "--json", str(out)]
    return subprocess.run(
        [*argv, *options], capture_output=True, text=True, env=raising_env(modules), check=False
    )


def assert_internal_errors(document: dict[str, Any], broken: tuple[str, ...]) -> None:
    """The verdict of a run whose ``broken`` modules raised at every frame."""
    assert [e["module"] for e in document["internal_errors"]] == list(broken)
    assert all(e["error"] == ERROR for e in document["internal_errors"])
    for module in broken:
        status = document["modules_judged"][module]
        assert status.startswith(f"not judged: internal error ({ERROR}) at frame "), status
    assert document["conclusive"] is False
    assert any("internal error" in reason for reason in document["why_inconclusive"])
    assert "no fault found" not in document["verdict"]
    assert not [p for p in document["input_problems"] if "deliberate" in json.dumps(p)]
    assert all(
        frame[module]["internal_error"] == ERROR
        for frame in document["frames"]
        for module in broken
    )


@pytest.fixture(scope="module")
def crash_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A planning fault: with planning broken, nothing may be blamed in its place."""
    folder = tmp_path_factory.mktemp("crash") / "log"
    return write_run_log(synthesise("lead_braking", "planning", 1), folder)


@pytest.mark.parametrize("semantics", ["corrected", "reference"])
@pytest.mark.parametrize("modules", ["all", "planning"])
def test_diagnose_says_internal_error_writes_its_outputs_and_exits_70(
    crash_log: Path, tmp_path: Path, modules: str, semantics: str
) -> None:
    out, report = tmp_path / "verdict.json", tmp_path / "report.html"
    done = diagnose_raising(
        crash_log, out, modules, "--semantics", semantics, "--report", str(report)
    )
    assert done.returncode == EXIT_INTERNAL_ERROR, done.stderr
    broken = MODULES if modules == "all" else (modules,)
    assert_internal_errors(json.loads(out.read_text()), broken)
    assert report.is_file() and "internal error" in report.read_text()
    assert "Traceback (most recent call last)" in done.stderr and ERROR in done.stderr
    for module in broken:
        assert f"internal error: the {module} check raised on" in done.stderr
    assert "no fault found" not in done.stdout and "Traceback" not in done.stdout


@pytest.mark.parametrize("modules", ["all", "controller"])
def test_diagnose_in_forked_workers_says_the_same(tmp_path: Path, modules: str) -> None:
    """The workers' results and first tracebacks come back to the parent."""
    log = synthesise("cruise", "none", seed=5, frames=PARALLEL_MIN_FRAMES + 30, actors=5)
    log_dir = write_run_log(log, tmp_path / "log")
    outputs = []
    for workers in ("1", "2"):
        out = tmp_path / f"verdict{workers}.json"
        done = diagnose_raising(log_dir, out, modules, "--workers", workers)
        assert done.returncode == EXIT_INTERNAL_ERROR, done.stderr
        assert done.stderr.count("Traceback (most recent call last)") == (
            len(MODULES) if modules == "all" else 1
        )
        document = json.loads(out.read_text())
        assert len(document["frames"]) >= PARALLEL_MIN_FRAMES
        assert_internal_errors(document, MODULES if modules == "all" else (modules,))
        outputs.append(document)
    assert outputs[0]["internal_errors"] == outputs[1]["internal_errors"]
    assert outputs[0]["verdict"] == outputs[1]["verdict"]
