"""Synthesised crash logs shared by the tests: each (scenario, fault) synthesised once per
process (a pytest-xdist worker is a process), with the seed and options the suite uses.

A :class:`~ads_rca.model.RunLog` is never changed by the code under test, so every test of
the process can be handed the same object; a test that needs a changed log copies it.
"""

from __future__ import annotations

import json
from pathlib import Path

from ads_rca.model import RunLog
from ads_rca.sources.log.writer import write_run_log
from ads_rca.synth import synthesise

#: Every scenario and every fault kind at least once.
CASES = [
    ("cut_in", "perception"),
    ("lead_braking", "prediction"),
    ("pedestrian_crossing", "planning"),
    ("left_turn", "controller"),
    ("cruise", "none"),
]
_LOGS: dict[tuple[str, str], RunLog] = {}


def synth(scenario: str, fault: str) -> RunLog:
    """The scenario with the fault injected, seed 1 (cruise: 150 frames and 12 actors)."""
    if (scenario, fault) not in _LOGS:
        options = {"frames": 150, "actors": 12} if scenario == "cruise" else {}
        _LOGS[scenario, fault] = synthesise(scenario, fault, 1, **options)
    return _LOGS[scenario, fault]


def write_log_with_unreadable_values(folder: Path) -> Path:
    """lead_braking with a control fault, where 7 pose files lack x and speed: the reader
    reads them as NaN and reports it, and reference skips (not fails) those checks."""
    write_run_log(synthesise("lead_braking", "controller", 0), folder)
    poses = sorted((folder / "pose").iterdir())
    for path in poses[40:61:3]:
        document = json.loads(path.read_text())
        del document["x"], document["speed"]
        path.write_text(json.dumps(document))
    return folder
