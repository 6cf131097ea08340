"""``ads-rca diagnose``: attribution of injected faults, the JSON contract, the CLI's behaviour."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import pytest
from commandline import run_cli

from ads_rca.diagnosis.engine import diagnose
from ads_rca.diagnosis.verdict import NO_COLLISION, NO_MODULE_FAILED
from ads_rca.oracles.base import MODULES
from ads_rca.oracles.semantics import semantics_for
from ads_rca.params import make_params
from ads_rca.sources.log.writer import write_run_log
from ads_rca.synth import FAULTS, SCENARIOS, synthesise

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "cut_in_perception"
CRASH_SCENARIOS = [s for s in SCENARIOS if s != "cruise"]


def strict_json(text: str) -> Any:
    """JSON that must not contain NaN or Infinity (the contract writes them as null)."""

    def reject(constant: str) -> None:
        raise AssertionError(f"non-finite constant {constant} in the JSON")

    return json.loads(text, parse_constant=reject)


@pytest.mark.parametrize("fault", FAULTS)
@pytest.mark.parametrize("scenario", CRASH_SCENARIOS)
def test_corrected_names_the_injected_module(scenario: str, fault: str) -> None:
    log = synthesise(scenario, fault, seed=2)
    result = diagnose(log, make_params("corrected"))
    attribution = result.attribution
    if fault == "none":
        assert attribution.primary_root_cause is None
        assert attribution.reason in (NO_COLLISION, NO_MODULE_FAILED)
        assert result.verdict_text.startswith("no fault found")
    else:
        assert attribution.primary_root_cause == fault  # a fault is named by its module
        assert attribution.modules[fault].evidence
    assert not [p for p in result.problems if "check failed" in p.issue]


def test_json_contract_in_both_modes(tmp_path: Path) -> None:
    for semantics in ("reference", "corrected"):
        out = tmp_path / f"{semantics}.json"
        done = run_cli(
            "diagnose", str(EXAMPLE), "--semantics", semantics, "--json", str(out), check=True
        )
        assert f"semantics {semantics}" in done.stdout
        document = strict_json(out.read_text())
        assert document["semantics"] == semantics
        assert document["thresholds"] == semantics_for(semantics).used(make_params(semantics))
        assert document["collision_frame"] == 81
        assert set(document["modules"]) == set(MODULES)
        for counts in document["modules"].values():
            assert isinstance(counts["collision"], int) and isinstance(counts["safe"], int)
            first = counts["first_failure_frame"]
            assert first is None or isinstance(first, int)
        causes = document["root_causes"]
        assert causes == [m for m in MODULES if m in causes]  # pipeline order
        assert document["primary_root_cause"] == (causes[0] if causes else None)
        assert len(document["frames"]) == 81
        assert set(document["frames"][0]) >= {"frame", "timestamp_ms", *MODULES}
        assert document["input_problems"] == []
    assert strict_json((tmp_path / "corrected.json").read_text())["primary_root_cause"] == (
        "perception"
    )


def test_parameters_from_config_and_p_are_used_and_recorded(tmp_path: Path) -> None:
    config = tmp_path / "rca.yaml"
    config.write_text(
        "/**:\n  ros__parameters:\n    semantics: reference\n    effect_time_window: 5\n"
        "    log_path: ignored-node-parameter\n"
    )
    out = tmp_path / "v.json"
    run_cli("diagnose", str(EXAMPLE), "--config", str(config), "-p", "perc_score_threshold=0.9",
            "--json", str(out), check=True)  # fmt: skip
    document = strict_json(out.read_text())
    assert document["semantics"] == "reference"
    assert document["thresholds"]["effect_time_window"] == 5
    assert document["thresholds"]["perc_score_threshold"] == 0.9
    # The example's controller fails on its 80 frames up to frame 80 (collision at 81): the
    # reference window (frame > 81 - 5) holds 4 of them (9 with the default 10).
    controller = document["modules"]["controller"]
    assert (controller["collision"], controller["safe"]) == (4, 76)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["-p", "no_such_threshold=1"], "unknown parameter 'no_such_threshold'"),
        (["-p", "effect_time_window=1.5"], "is not an integer"),
        (["-p", "safety_margin"], "-p expects name=value"),
    ],
)
def test_bad_parameters_are_one_line_errors(args: list[str], message: str) -> None:
    done = run_cli("diagnose", str(EXAMPLE), *args)
    assert done.returncode == 2
    assert message in done.stderr and done.stderr.count("\n") == 1
    assert "Traceback" not in done.stderr


def test_logs_that_cannot_be_diagnosed_exit_non_zero(tmp_path: Path) -> None:
    missing = run_cli("diagnose", str(tmp_path / "nope"))
    assert missing.returncode == 2 and "no such log folder" in missing.stderr
    empty = tmp_path / "empty"
    (empty / "actors").mkdir(parents=True)
    (empty / "metadata.json").write_text('{"timesteps_per_frame": 50}')
    nothing = run_cli("diagnose", str(empty))
    assert nothing.returncode == 2 and "no frame to analyse" in nothing.stderr
    assert "Traceback" not in missing.stderr + nothing.stderr


def test_damaged_log_is_still_diagnosed_and_problems_reported(tmp_path: Path) -> None:
    log_dir = tmp_path / "log"
    shutil.copytree(EXAMPLE, log_dir)
    (log_dir / "bboxes" / "bboxes-3000.json").write_text('[{"id": 1, "bounding_b')
    (log_dir / "pose" / "pose-3500.json").unlink()
    waypoints = log_dir / "waypoint" / "waypoints-3600.json"
    waypoints.write_text(waypoints.read_text().replace('"speed":', '"speed": "fast", "x_":', 1))
    out = tmp_path / "v.json"
    for semantics in ("reference", "corrected"):
        done = run_cli(
            "diagnose", str(log_dir), "--semantics", semantics, "--json", str(out), check=True
        )
        assert "input problems:" in done.stdout
        document = strict_json(out.read_text())
        files = {p["file"] for p in document["input_problems"]}
        assert "bboxes/bboxes-3000.json" in files and "pose/" in files
        assert len(document["frames"]) == 81
    assert document["primary_root_cause"] == "perception"


def test_html_report_is_self_contained(tmp_path: Path) -> None:
    report = tmp_path / "r.html"
    run_cli("diagnose", str(EXAMPLE), "--report", str(report), check=True)
    page = report.read_text()
    assert "Verdict: perception" in page
    assert page.count("data:image/png;base64,") == 3  # scenes at frames 68 and 81, metrics
    assert "http://" not in page and "https://" not in page


def test_no_collision_says_no_fault_found(tmp_path: Path) -> None:
    log = synthesise("cruise", "none", seed=3, frames=60, actors=5)
    out = tmp_path / "v.json"
    run_cli("diagnose", str(write_run_log(log, tmp_path / "log")), "--json", str(out), check=True)
    document = strict_json(out.read_text())
    assert document["primary_root_cause"] is None and document["reason"] == NO_COLLISION
    assert document["verdict"] == "no fault found (no collision)"


@pytest.mark.parametrize("semantics", ["reference", "corrected"])
def test_judging_in_worker_processes_gives_the_same_diagnosis(
    semantics: str, tmp_path: Path
) -> None:
    log = synthesise("cruise", "none", seed=5, frames=450, actors=8)
    log_dir = write_run_log(log, tmp_path / "log")
    (log_dir / "pose" / "pose-5000.json").write_text("{")  # a problem found while judging
    (log_dir / "waypoint" / "waypoints-9000.json").unlink()
    from ads_rca.sources.log.reader import read_run_log

    params = make_params(semantics)
    alone = diagnose(read_run_log(log_dir), params).to_json()
    shared = diagnose(read_run_log(log_dir), params, workers=2).to_json()
    assert len(alone["frames"]) >= 400  # long enough to be split between the workers
    assert shared == alone


@pytest.mark.parametrize("semantics", ["reference", "corrected"])
def test_frames_written_as_their_slices_come_back_are_the_same_bytes(
    semantics: str, tmp_path: Path
) -> None:
    """``diagnose --json`` with workers makes the frames' text as each judged slice comes
    back: the file is byte for byte the one written from the whole document, non-finite
    pointers (in the frames and around them) in the same order; the summary counts the
    frames alike."""
    log = synthesise("cruise", "none", seed=5, frames=450, actors=6)
    log_dir = write_run_log(log, tmp_path / "log")
    (log_dir / "pose" / "pose-5000.json").write_text("{")  # a problem found while judging
    outputs = []
    for workers in ("1", "2"):
        out = tmp_path / f"v{workers}.json"
        done = run_cli(
            "diagnose",
            str(log_dir),
            "--semantics",
            semantics,
            "--workers",
            workers,
            "--json",
            str(out),
            check=True,
        )
        outputs.append((out.read_bytes(), done.stdout))
    (alone, alone_summary), (shared, shared_summary) = outputs
    assert shared == alone
    assert shared_summary.replace("v2.json", "v1.json") == alone_summary
    document = json.loads(alone)
    assert len(document["frames"]) >= 400  # long enough to be split between the workers
    assert any(p.startswith("/frames/") for p in document.get("$nonfinite", {})), semantics
    assert alone == (json.dumps(document, indent=1) + "\n").encode()
