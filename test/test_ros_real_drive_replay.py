"""A real drive through the live graph: a legacy Autoware recording (pre-Iron sqlite3, no
message definitions, no ground truth, no collision topic) replayed over DDS, each node in its
own process, gives diagnose's verdict: the world the stack perceived, the same critical event
explained (the MRM onset it finds, or the time the user gives) and the same events listed.

The bag is written by our own fixture writer from our synthesiser's crash: this checks that
the live graph agrees with diagnose (consistency), not that either is right on a real drive.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import pytest
from writers.autoware_bags import AutowareBagOptions, write_autoware_bag

from ads_rca.diagnosis.engine import diagnose
from ads_rca.params import make_params
from ads_rca.ros.launcher import ManagedProcess
from ads_rca.sources.bag.profiles.recording import read_recording

if TYPE_CHECKING:
    from conftest import RosEnv

pytestmark = pytest.mark.timeout(240)

#: The fail-safe's emergency, on the synthesised run's clock (ms): an event found without
#: any time given.
EMERGENCY_MS = 3000
#: Keys a live verdict shares with diagnose's (the live one adds ``live`` and its latency).
SHARED = (
    "verdict",
    "primary_root_cause",
    "reference",
    "event",
    "events_found",
    "suspected",
    "collision",
    "collision_frame",
    "modules_judged",
    "thresholds",
    "conclusive",
    "why_inconclusive",
)


@pytest.fixture(scope="module")
def drive(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from synthlogs import synth

    log = synth("lead_braking", "planning")
    options = AutowareBagOptions(legacy=True, storage="humble", emergency_at_ms=EMERGENCY_MS)
    return write_autoware_bag(log, tmp_path_factory.mktemp("drive") / "bag", options).path


@pytest.mark.parametrize("event_time", [None, "2.5"], ids=["found", "given"])
def test_replay_of_a_real_drive_equals_diagnose(
    ros_env: RosEnv, drive: Path, tmp_path: Path, event_time: str | None
) -> None:
    out = tmp_path / "verdict.json"
    given = ["--event-time", event_time] if event_time else []
    argv = [sys.executable, "-m", "ads_rca.cli", "replay", str(drive), "--profile", "autoware"]
    argv += [*given, "--json", str(out), "--domain-id", str(ros_env.domain_id)]
    replay = ManagedProcess("replay", [*argv, "--timeout", "120"], ros_env.env)
    assert replay.wait(180) in (0, 1), replay.output
    live = json.loads(out.read_text())
    overrides = {"event_time_s": event_time} if event_time else {}
    offline = diagnose(read_recording(drive, "autoware"), make_params("corrected", overrides))
    expected = offline.to_json()
    for key in SHARED:
        assert live.get(key) == expected.get(key), key
    assert live["reference"] == "perceived" and live["collision"] == "unknown"
    kind = "given" if event_time else "emergency"
    assert live["event"]["kind"] == kind, live["event"]
    assert any(e["kind"] == "emergency" for e in live["events_found"])
    assert live["conclusive"] is False  # no collision source: never "no fault found"
