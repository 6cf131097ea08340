"""An oracle that raises is a bug in our own code (docs/verdicts.md "internal error").

The oracles are broken from outside, by ``test/raising_oracles/sitecustomize.py`` on
``PYTHONPATH`` (no hook in the product): every process started with it, the forked judging
workers and the live graph's monitors included, runs the broken oracles. Then:

- ``diagnose`` writes its JSON, names the module "not judged: internal error (...) at frame
  N", files no input problem about it, never says "no fault found", prints the traceback on
  stderr and exits 70, with one module or all four raising, in both modes, alone or with
  ``--workers 2`` on a log long enough to be judged in forked workers;
- ``replay``: the same verdict, the module's ``/diagnostics`` status ERROR "internal
  error", the monitor's logged traceback on stderr, exit 70;
- a monitor's batch whose latest frame passed is still ERROR when an earlier one raised.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

from ads_rca.diagnosis.engine import PARALLEL_MIN_FRAMES
from ads_rca.diagnosis.verdict import OracleResult
from ads_rca.errors import EXIT_INTERNAL_ERROR
from ads_rca.live import diagnostics as diag
from ads_rca.live.results import LiveResult
from ads_rca.oracles.base import MODULES
from ads_rca.ros.launcher import ManagedProcess
from ads_rca.sources.log.writer import write_run_log
from ads_rca.synth import synthesise

if TYPE_CHECKING:
    from collections.abc import Callable

    from conftest import RosEnv

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


@pytest.mark.slow
def test_replay_says_internal_error_on_diagnostics_and_exits_70(
    ros_env: RosEnv, tmp_path: Path, log_dirs: Callable[[str, str], Path]
) -> None:
    """The monitors inherit the broken oracle from replay's environment. Played at half
    speed (4 s): /diagnostics is volatile, and the probe hears the monitors only once
    discovery matched them (up to ~2.5 s, docs of test_ros_live_graph)."""
    from rosrun import jsonl, start_probe

    diag_file = tmp_path / "diag.jsonl"
    probe = start_probe(ros_env, diag_file)
    out = tmp_path / "verdict.json"
    argv = [sys.executable, "-m", "ads_rca.cli", "replay", str(log_dirs("cut_in", "planning"))]
    argv += ["--json", str(out), "--domain-id", str(ros_env.domain_id), "--rate", "0.5"]
    replay = ManagedProcess("replay", argv, raising_env("planning", ros_env.env))
    try:
        code = replay.wait(120)
    finally:
        probe.stop()
    assert code == EXIT_INTERNAL_ERROR, replay.output
    document = json.loads(out.read_text())
    assert document["live"]["complete"], document["live"]
    assert_internal_errors(document, ("planning",))
    statuses = [r for r in jsonl(diag_file) if r["name"] == diag.status_name("planning")]
    # A heartbeat before the module's first result is STALE (nothing judged yet): on a
    # loaded machine one may come first. Every status after it says the internal error.
    planning = [r for r in statuses if r["level"] != diag.STALE or planning_seen(statuses, r)]
    assert planning and all(r["level"] == diag.ERROR for r in planning), statuses
    assert all(diag.internal_error_head("planning") in r["message"] for r in planning)
    verdict = [r for r in jsonl(diag_file) if r["name"] == diag.VERDICT_NAME]
    assert verdict and verdict[-1]["level"] == diag.ERROR, verdict
    # The monitor's traceback, logged once, is on replay's stderr, then replay's line.
    assert replay.output.count("Traceback (most recent call last)") == 1, replay.output
    assert ERROR in replay.output
    assert "ads-rca replay: internal error: the planning check raised on" in replay.output


def _live(frame: int, error: str | None = None, failed: bool = False) -> LiveResult:
    result = OracleResult("planning", frame * 50, failed, internal_error=error)
    return LiveResult(index=frame, result=result, frame=frame, collision_frame=-1)


def test_a_batch_whose_latest_frame_passed_is_error_when_one_raised() -> None:
    status = diag.batch_status([_live(1, ERROR), _live(2)], "corrected", "hw")
    assert status.level == diag.ERROR
    assert f"internal error in the planning check at frame 1 ({ERROR})" in status.message
    assert diag.batch_status([_live(1), _live(2)], "corrected", "hw").level == diag.OK


def planning_seen(statuses: list[dict[str, Any]], record: dict[str, Any]) -> bool:
    """Whether an ERROR status came before ``record`` (a STALE one after it is a failure)."""
    return any(r["level"] == diag.ERROR for r in statuses[: statuses.index(record)])
