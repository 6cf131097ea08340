"""Which modules a run lets be judged: never a silent "no fault found"
because an input was absent."""

from __future__ import annotations

from ads_rca.capabilities import (
    MODEL_INPUTS,
    input_status,
    judged_modules,
    recorded,
    statuses_to_document,
)
from ads_rca.diagnosis.engine import diagnose
from ads_rca.diagnosis.summary import summary_text
from ads_rca.model import InputStatus, read_inputs
from ads_rca.oracles.semantics import semantics_for
from ads_rca.params import Params
from ads_rca.synth import synthesise


def _absent(*names: str) -> dict[str, InputStatus]:
    out = {name: InputStatus("real", f"/{name}", "") for name in MODEL_INPUTS}
    out.update({name: InputStatus("absent", f"/{name}", "topic not in the bag") for name in names})
    return out


def test_a_running_log_is_judged_whole_from_its_folders() -> None:
    log = synthesise("cut_in", "planning", 1)
    statuses = input_status(log)
    assert not recorded(log)
    # A synthesised run holds every folder, the 3-D ones too; a log folder has no clock.
    assert [n for n, s in statuses.items() if s.state == "absent"] == ["clock"]
    for mode in ("reference", "corrected"):
        assert set(semantics_for(mode).judged(log).values()) == {"judged"}


def test_each_alternative_of_a_requirement_suffices_and_the_nearest_one_is_named() -> None:
    requires = {"m": (("a", "b"), ("c",)), "n": (("a",),), "o": ()}
    statuses = {"a": InputStatus("real"), "b": InputStatus("absent"), "c": InputStatus("derived")}
    assert judged_modules(requires, statuses) == {"m": "judged", "n": "judged", "o": "judged"}
    statuses["c"] = InputStatus("absent")
    assert judged_modules(requires, statuses)["m"] == "not judged (no b)"
    assert judged_modules({"m": (("x", "y"), ("a", "b", "c"))}, statuses) == {
        "m": "not judged (no x, y)"  # both lack two: the first alternative named
    }


def test_a_carla_autoware_recording_without_2d_and_pwp() -> None:
    statuses = _absent("detections_2d", "ground_truth_2d", "predictions_gt", "detections_3d")
    reference = judged_modules(semantics_for("reference").requires, statuses)
    assert reference == {
        "perception": "not judged (no detections_2d, ground_truth_2d)",
        "prediction": "not judged (no predictions_gt)",
        "planning": "not judged (no predictions_gt)",
        "controller": "judged",
    }
    corrected = judged_modules(semantics_for("corrected").requires, statuses)
    assert corrected == dict.fromkeys(
        ("perception", "prediction", "planning", "controller"), "judged"
    )
    no_plan = judged_modules(
        semantics_for("corrected").requires,
        _absent("plan", "tracked_objects", "detections_3d", "detections_2d"),
    )
    assert no_plan["planning"] == "not judged (no plan)"
    assert no_plan["perception"] == "not judged (no plan, detections_2d)"


def test_statuses_survive_the_run_metadata_and_hostile_documents_are_left_out() -> None:
    statuses = _absent("plan")
    document = {"model_inputs": statuses_to_document(statuses)}
    assert read_inputs(document) == (statuses, [])
    hostile = {
        "plan": {"state": "sure", "source": "/p"},  # unknown state
        "ego": {"state": "real", "source": ["/x"], "reason": 3},  # wrong types
        "actors": "real",  # not a mapping
        "clock": {"state": "absent"},
    }
    inputs, issues = read_inputs({"model_inputs": hostile})
    assert inputs == {"clock": InputStatus("absent")}
    assert [field for field, _issue in issues] == [
        "model_inputs.plan",
        "model_inputs.ego",
        "model_inputs.actors",
    ]
    assert read_inputs({"model_inputs": [1, 2]})[0] == {}


def test_a_recording_without_a_plan_says_no_module_was_judged_at_any_frame() -> None:
    log = synthesise("lead_braking", "planning", 1)
    log.waypoints.clear()
    log.inputs = _absent("plan", "detections_3d", "tracked_objects")
    assert recorded(log)
    document = diagnose(log, Params(semantics="corrected")).to_json()
    why = "not judged (no plan)"
    assert set(document["modules_judged"].values()) == {why}
    for module in ("perception", "prediction", "planning", "controller"):
        assert {f[module]["skipped"] for f in document["frames"]} == {why}
    # No problem per frame for the absent plan: the modules were simply not judged.
    assert not [p for p in document["input_problems"] if "waypoint" in p["file"]]
    # Nothing was judged, so nothing may be said to be at fault or not (docs/verdicts.md).
    reasons = [f"{m} {why}" for m in ("perception", "prediction", "planning", "controller")]
    assert document["verdict"] == "inconclusive: " + "; ".join(reasons)
    assert document["conclusive"] is False
    assert document["primary_root_cause"] is None
    assert document["reason"] == "inconclusive"
    assert document["why_inconclusive"] == reasons
    text = summary_text(document)
    assert f"planning             0      0  {why}" in text
    assert "no fault found" not in text
    assert f"  inconclusive because:\n    perception {why}\n" in text
