"""Synthesis labels: a synthesised log names its injected fault and partner, and no verdict
reads them.

``metadata.json["synthesis"]`` is the ground truth a benchmark scores the verdict against
(``bench/accuracy.py``), so it must travel with the log (the player forwards the exact
metadata document in ``run/metadata``) but never decide a verdict: removing it leaves every
verdict unchanged, offline (every scenario × fault, both modes) and live (a real replay per
mode).
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest
from golden_outputs import SEED, cases
from verdicts import verdict_keys

from ads_rca.diagnosis.engine import diagnose
from ads_rca.model import RunLog
from ads_rca.params import SEMANTICS, make_params
from ads_rca.ros.launcher import ManagedProcess
from ads_rca.sources.log.reader import read_run_log
from ads_rca.sources.log.writer import write_run_log
from ads_rca.synth import synthesise

if TYPE_CHECKING:
    from conftest import RosEnv

#: Every scenario x fault.
CASES = [pytest.param(*case, id="-".join(case)) for case in cases()]
#: Frames of the cruise log here: its 2,000 by default (every other log is about 100) cost
#: a minute of synthesis and four diagnoses; a shorter cruise has the same label and rules.
CRUISE_FRAMES = 200
#: One live case per mode (a crash with a partner, so the partner label could matter).
LIVE_CASES = [("reference", "cut_in", "perception"), ("corrected", "lead_braking", "prediction")]


def synthesised(scenario: str, fault: str) -> RunLog:
    """The scenario's log with ``fault`` (a cruise :data:`CRUISE_FRAMES` long)."""
    if scenario == "cruise":
        return synthesise(scenario, fault, SEED, frames=CRUISE_FRAMES)
    return synthesise(scenario, fault, SEED)


def write_pair(scenario: str, fault: str, folder: Path) -> tuple[Path, Path]:
    """The synthesised log as written, and a copy whose metadata.json lacks ``synthesis``."""
    labelled = write_run_log(synthesised(scenario, fault), folder / "labelled" / "log")
    bare = folder / "bare" / "log"
    shutil.copytree(labelled, bare)
    metadata = json.loads((bare / "metadata.json").read_text())
    del metadata["synthesis"]
    (bare / "metadata.json").write_text(json.dumps(metadata))
    return labelled, bare


def verdict(log_dir: Path, semantics: str) -> dict[str, Any]:
    document = diagnose(read_run_log(log_dir), make_params(semantics)).to_json()
    document.pop("source")
    return document


@pytest.mark.parametrize(("scenario", "fault"), CASES)
def test_synthesised_metadata_names_the_fault_and_partner(
    tmp_path: Path, scenario: str, fault: str
) -> None:
    log_dir = write_run_log(synthesised(scenario, fault), tmp_path / "log")
    label = json.loads((log_dir / "metadata.json").read_text())["synthesis"]
    assert (label["scenario"], label["fault"], label["seed"]) == (scenario, fault, SEED)
    if scenario == "cruise":
        assert label["partner_id"] is None
    else:
        assert isinstance(label["partner_id"], str) and label["partner_id"]
    # The reader keeps the label (so convert and the player pass it on).
    assert read_run_log(log_dir).metadata.raw["synthesis"] == label


@pytest.mark.parametrize(("scenario", "fault"), CASES)
def test_removing_synthesis_leaves_every_offline_verdict_unchanged(
    tmp_path: Path, scenario: str, fault: str
) -> None:
    labelled, bare = write_pair(scenario, fault, tmp_path)
    for semantics in SEMANTICS:
        assert verdict(labelled, semantics) == verdict(bare, semantics), semantics


def replay(ros_env: RosEnv, log_dir: Path, semantics: str, tmp: Path) -> dict[str, Any]:
    """The live verdict of a real replay (every node its own process), recorded to a bag."""
    out, bag = tmp / "verdict.json", tmp / "bag"
    argv = [sys.executable, "-m", "ads_rca.cli", "replay", str(log_dir), "--semantics", semantics]
    argv += ["--json", str(out), "--record", str(bag), "--domain-id", str(ros_env.domain_id)]
    process = ManagedProcess("replay", [*argv, "--timeout", "90"], ros_env.env)
    assert process.wait(120) == 0, process.output
    document: dict[str, Any] = json.loads(out.read_text())
    assert document["live"]["complete"], document["live"]
    return document


def recorded_metadata(bag: Path, tmp: Path) -> dict[str, Any]:
    """metadata.json of the log the recorded bag converts back to (what the player sent)."""
    folder = tmp / "from_bag"
    cli = [sys.executable, "-m", "ads_rca.cli", "convert", str(bag), str(folder)]
    subprocess.run(cli, check=True, capture_output=True)
    document: dict[str, Any] = json.loads((folder / "metadata.json").read_text())
    return document


@pytest.mark.slow
@pytest.mark.timeout(300)
@pytest.mark.parametrize(("semantics", "scenario", "fault"), LIVE_CASES)
def test_removing_synthesis_leaves_the_live_verdict_unchanged(
    ros_env: RosEnv, tmp_path: Path, semantics: str, scenario: str, fault: str
) -> None:
    labelled, bare = write_pair(scenario, fault, tmp_path)
    runs = {}
    for name, log_dir in (("labelled", labelled), ("bare", bare)):
        (tmp_path / name / "run").mkdir()
        runs[name] = replay(ros_env, log_dir, semantics, tmp_path / name / "run")
    assert verdict_keys(runs["labelled"]) == verdict_keys(runs["bare"])
    assert runs["labelled"]["frames"] == runs["bare"]["frames"]
    # The player forwarded the label: the recorded run/metadata carries it.
    label = json.loads((labelled / "metadata.json").read_text())["synthesis"]
    sent = recorded_metadata(tmp_path / "labelled" / "run" / "bag", tmp_path / "labelled")
    assert sent["synthesis"] == label
    assert "synthesis" not in recorded_metadata(tmp_path / "bare" / "run" / "bag", tmp_path)
