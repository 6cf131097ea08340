"""``diagnose --json`` stays the same on the example and every synthesised log.

The outputs in ``test/golden/diagnose_outputs.json.gz`` were recorded with
``golden_outputs.py --write``; a change to any verdict, in either mode, fails here and names
the logs whose output changed and where. Equal bytes pass at once; otherwise everything but
floats must be equal and floats must agree to ``REL_TOL`` (``golden_outputs.py`` says why).
"""

from __future__ import annotations

import pytest
from golden_outputs import REL_TOL, cases, first_difference, outputs, stored


@pytest.mark.slow
def test_diagnose_json_is_the_recorded_output() -> None:
    recorded = stored()
    assert len(recorded) == 2 * (1 + len(cases()))
    now = outputs()
    assert now.keys() == recorded.keys()
    changed = []
    for key in sorted(recorded):
        if now[key]["sha256"] == recorded[key]["sha256"]:
            continue
        where = first_difference(recorded[key]["json"], now[key]["json"])
        if where is not None:
            changed.append(f"{key} at {where}")
    message = f"diagnose --json changed (floats to {REL_TOL:g}) for: "
    assert not changed, message + "; ".join(changed)


def test_the_comparison_sees_a_changed_verdict_and_forgives_a_last_bit() -> None:
    old = {"verdict": "perception", "frames": [{"c_gt": 0.1 + 0.2, "ids": ["7"]}]}
    last_bit = {"verdict": "perception", "frames": [{"c_gt": 0.3, "ids": ["7"]}]}
    assert first_difference(old, last_bit) is None
    planning = {**old, "verdict": "planning"}
    assert first_difference(old, planning) == "/verdict: 'perception' -> 'planning'"
    moved = {"verdict": "perception", "frames": [{"c_gt": 0.3001, "ids": ["7"]}]}
    assert first_difference(old, moved) == "/frames/0/c_gt: 0.30000000000000004 -> 0.3001"
    assert first_difference(old, {**old, "frames": []}) == "/frames: 1 items -> 0"
    assert first_difference({"a": 1}, {"a": 1.0}) == "/a: 1 -> 1.0"
