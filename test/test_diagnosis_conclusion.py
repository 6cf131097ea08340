"""What a verdict may claim (docs/verdicts.md): the rule of ``conclusion.conclude`` and how
the text summary and ``/diagnostics`` render it.

Each case starts from a synthesised crash whose verdict is conclusive and takes one piece of
evidence away: a module's input, an input at some window frames, frames of the window, the
collision source, a working oracle. The verdict then says what it lacks and is never "no
fault found"; a root cause found among the judged modules is still named.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import pytest

from ads_rca.diagnosis.conclusion import conclude
from ads_rca.diagnosis.engine import diagnose
from ads_rca.diagnosis.summary import summary_text
from ads_rca.diagnosis.verdict import MODULES
from ads_rca.live import diagnostics as diag
from ads_rca.model import InputStatus, RunLog
from ads_rca.oracles.semantics import semantics_for
from ads_rca.params import make_params
from ads_rca.synth import synthesise

MODES = ("reference", "corrected")


@pytest.fixture(scope="module")
def crash() -> RunLog:
    return synthesise("lead_braking", "planning", 1)


def _document(log: RunLog, mode: str) -> dict[str, Any]:
    return diagnose(log, make_params(mode)).to_json()


@pytest.mark.parametrize("mode", MODES)
def test_a_whole_run_is_conclusive(crash: RunLog, mode: str) -> None:
    document = _document(crash, mode)
    assert document["conclusive"] is True and document["why_inconclusive"] == []
    assert document["collision"] == "yes" and document["internal_errors"] == []
    assert set(document["modules_judged"].values()) == {"judged"}
    assert "inconclusive" not in str(document["verdict"])


@pytest.mark.parametrize("mode", MODES)
def test_frames_missing_from_the_window_are_named(crash: RunLog, mode: str) -> None:
    log = synthesise("lead_braking", "planning", 1)
    collision = log.metadata.collision_frame
    lost = {(collision - 5) * log.frame_ms, (collision - 4) * log.frame_ms}
    log.frames = tuple(ts for ts in log.frames if ts not in lost)
    document = _document(log, mode)
    assert document["conclusive"] is False
    named = f"frames {collision - 5}, {collision - 4} of the effect window are missing"
    assert any(r.startswith(named) for r in document["why_inconclusive"])
    assert "; inconclusive: " in str(document["verdict"]) or str(document["verdict"]).startswith(
        "inconclusive: "
    )


@pytest.mark.parametrize("mode", MODES)
def test_an_input_missing_at_window_frames_makes_its_modules_partly_judged(
    crash: RunLog, mode: str
) -> None:
    log = synthesise("lead_braking", "planning", 1)
    gone = (log.metadata.collision_frame - 3) * log.frame_ms
    del log.waypoints[gone]
    document = _document(log, mode)
    statuses = document["modules_judged"]
    assert isinstance(statuses, dict)
    partly = [m for m in MODULES if str(statuses[m]).startswith("partly judged (")]
    assert "planning" in partly, statuses
    assert f"at frame {log.metadata.collision_frame - 3})" in statuses["planning"]
    assert document["conclusive"] is False
    assert [f"{m} {statuses[m]}" for m in partly] == [
        r for r in document["why_inconclusive"] if "partly judged" in r
    ]


def test_no_collision_known_is_no_fault_found_and_unknown_is_never() -> None:
    cruise = synthesise("cruise", "none", 1, frames=60, actors=5)
    known = _document(cruise, "corrected")
    assert known["verdict"] == "no fault found (no collision)" and known["collision"] == "no"
    assert known["conclusive"] is True
    # metadata.json gave no collision_frame: -1 only stands in for it.
    cruise.metadata = replace(cruise.metadata, collision_known=False)
    unknown = _document(cruise, "corrected")
    assert unknown["collision"] == "unknown" and unknown["conclusive"] is False
    assert unknown["reason"] == "collision unknown"
    # Nothing else to explain either: said so, with what each module's status was.
    assert unknown["verdict"] == (
        "inconclusive: collision unknown (metadata.json gives no usable collision_frame); "
        "no critical event found; modules: perception judged, prediction judged, "
        "planning judged, controller judged"
    )
    assert unknown["event"] is None and unknown["events_found"] == []
    text = summary_text(unknown)
    assert "collision unknown" in text.splitlines()[1]
    assert "no fault found" not in text and "no collision in this run" not in text


def test_a_recording_without_a_collision_input_has_its_collision_unknown() -> None:
    log = synthesise("cruise", "none", 1, frames=60, actors=5)
    log.inputs = {name: InputStatus("real") for name in ("ego", "actors", "plan")}
    log.inputs["collision"] = InputStatus("absent", "", "the profile maps no collision input")
    params = make_params("corrected")
    frames = diagnose(log, params).frames
    conclusion = conclude(semantics_for(params), params, log, frames)
    assert conclusion.collision == "unknown" and not conclusion.conclusive
    assert conclusion.reasons[0] == "collision unknown (the profile maps no collision input)"


@pytest.mark.parametrize(
    ("document", "level"),
    [
        ({"primary_root_cause": "planning", "conclusive": True, "verdict": "planning"}, diag.ERROR),
        (
            {"primary_root_cause": "planning", "conclusive": False, "verdict": "planning; ..."},
            diag.ERROR,
        ),
        (
            {"primary_root_cause": None, "conclusive": True, "verdict": "no fault found (x)"},
            diag.OK,
        ),
        (
            {"primary_root_cause": None, "conclusive": False, "verdict": "inconclusive: x"},
            diag.WARN,
        ),
        ({"primary_root_cause": None, "verdict": "no fault found (an older node)"}, diag.WARN),
        (
            {
                "primary_root_cause": None,
                "conclusive": False,
                "internal_errors": [{"module": "planning"}],
                "verdict": "inconclusive: planning not judged: internal error (...)",
            },
            diag.ERROR,
        ),
    ],
)
def test_the_verdict_status_is_ok_only_for_a_conclusive_no_fault_found(
    document: dict[str, object], level: int
) -> None:
    status = diag.verdict_status(document, "hw")
    assert status.level == level
    assert ("conclusive", "true" if document.get("conclusive") else "false") in status.values or (
        "conclusive" not in document
    )
