"""A run without ground truth or collision: judged against what the stack perceived, at its
critical event (docs/real-drives.md).

These runs come from our own synthesiser (consistency, not correctness): its crash logs with
the actors, the 2-D inputs and the collision taken away, as a real drive records them.
"""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from commandline import run_cli

from ads_rca.diagnosis.critical_event import EVENT_KEY, CriticalEvent, explained_event
from ads_rca.diagnosis.engine import diagnose
from ads_rca.diagnosis.events import CHOICE_KEY, choice_of, find_events, hard_brakes
from ads_rca.diagnosis.perceived import EGO_ID, PERCEIVED, perceived_world
from ads_rca.diagnosis.summary import summary_text
from ads_rca.diagnosis.verdict import PERCEPTION_SUSPECTED
from ads_rca.model import Objects3D, RunLog
from ads_rca.params import make_params
from ads_rca.sources.bag.profiles.recording import read_recording
from ads_rca.sources.log.writer import write_run_log
from ads_rca.synth import synthesise


def real_drive(scenario: str, fault: str, seed: int = 0) -> tuple[RunLog, float]:
    """A synthesised crash as a real drive records it, and the contact's time (s)."""
    log = synthesise(scenario, fault, seed)
    contact_s = log.metadata.collision_frame * log.frame_ms / 1000.0
    log.bboxes, log.bboxes_gt, log.predictions_with_perception = {}, {}, {}
    log.actors = {}
    log.frames = tuple(sorted(log.tracks_3d))
    log.metadata = replace(log.metadata, collision_frame=-1, collision_known=False)
    return log, contact_s


def at(time_s: float) -> object:
    return replace(make_params("corrected"), event_time_s=time_s)


@pytest.mark.parametrize("fault", ["prediction", "planning", "controller"])
def test_a_downstream_fault_is_named_against_the_perceived_world(fault: str) -> None:
    log, contact_s = real_drive("cut_in", fault)
    found = diagnose(log, at(contact_s))  # type: ignore[arg-type]
    document = found.to_json(include_frames=False)
    assert document["primary_root_cause"] == fault, document["verdict"]
    assert document["reference"] == PERCEIVED
    assert document["collision"] == "unknown" and document["collision_frame"] == -1
    assert document["event"]["kind"] == "given"
    assert math.isclose(document["event"]["time_s"], contact_s, abs_tol=0.06)
    assert "[explains event given at" in document["verdict"]
    # Perception could only be partly judged: never a conclusive verdict.
    assert document["modules_judged"]["perception"].startswith("partly judged (no ground truth")
    assert document["conclusive"] is False
    assert "no fault found" not in document["verdict"]


def test_a_missed_object_leaves_perception_suspected_never_no_fault() -> None:
    log, contact_s = real_drive("cut_in", "perception")
    found = diagnose(log, at(contact_s))  # type: ignore[arg-type]
    document = found.to_json(include_frames=False)
    assert document["primary_root_cause"] is None
    assert document["reason"] == PERCEPTION_SUSPECTED
    assert document["verdict"].startswith("perception suspected")
    assert document["suspected"] == ["perception"]
    assert "no fault found" not in document["verdict"]


def test_a_wrong_perceived_velocity_is_named_from_the_tracks_own_motion() -> None:
    log, contact_s = real_drive("lead_braking", "perception:velocity")
    found = diagnose(log, at(contact_s))  # type: ignore[arg-type]
    assert found.attribution.primary_root_cause == "perception"
    marks = {
        mark
        for frame in found.frames
        for mark in frame.results["perception"].metrics.get("marks", [])  # type: ignore[union-attr]
    }
    assert "inconsistent track" in marks


def test_the_world_is_the_stacks_tracks_and_ground_truth_wins() -> None:
    log, _ = real_drive("cut_in", "none")
    world = perceived_world(log)
    ts = world.frames[0]
    assert world.actors[ts].ids[0] == EGO_ID
    assert set(world.actors[ts].ids[1:]) == set(log.tracks_3d[ts].ids)
    assert world.inputs["actors"].state == "derived"
    assert world.metadata.raw["reference"] == PERCEIVED
    truth = synthesise("cut_in", "none", 0)
    assert perceived_world(truth) is truth  # actors present: nothing replaced


def test_a_hard_brake_is_found_and_explained_without_a_time() -> None:
    log, _ = real_drive("lead_braking", "none")
    params = make_params("corrected")
    brakes = hard_brakes(perceived_world(log), params)
    assert brakes and all("event_decel 4 m/s²" in e.what for e in brakes)
    found = diagnose(log, params)
    event = found.conclusion.event
    assert event is not None and event.kind in ("near_miss", "hard_brake")
    document = found.to_json(include_frames=False)
    listed = [e["kind"] for e in document["events_found"]]
    assert event.kind in listed
    text = summary_text(document)  # what diagnose and replay print
    assert f"critical event: {event.label}: {event.what}" in text
    assert f"events found: {len(listed)}" in text


def test_without_any_event_the_verdict_says_so() -> None:
    log, _ = real_drive("cruise", "none")
    params = replace(make_params("corrected"), event_decel=100.0, event_ttc_s=0.0)
    params = replace(params, event_clearance=0.0)
    document = diagnose(log, params).to_json(include_frames=False)
    assert document["event"] is None and document["events_found"] == []
    assert "no critical event found" in document["verdict"]
    assert document["verdict"].startswith("inconclusive: collision unknown")
    assert "no fault found" not in document["verdict"] and document["conclusive"] is False


def test_a_time_outside_the_run_is_said_and_nothing_is_explained() -> None:
    log, _ = real_drive("cut_in", "planning")
    document = diagnose(log, at(10_000.0)).to_json(include_frames=False)  # type: ignore[arg-type]
    assert document["event"] is None
    assert any("outside the run's frames" in r for r in document["why_inconclusive"])


@pytest.mark.parametrize(
    "bad",
    [
        None,
        [],
        {"kind": "given"},
        {"kind": "meteor", "timestamp_ms": 0, "frame": 0, "time_s": 0.0, "what": ""},
        {"kind": "given", "timestamp_ms": True, "frame": 0, "time_s": 0.0, "what": ""},
        {"kind": "given", "timestamp_ms": -50, "frame": 0, "time_s": 0.0, "what": ""},
        {"kind": "given", "timestamp_ms": 0, "frame": 0, "time_s": math.nan, "what": ""},
        {"kind": "given", "timestamp_ms": 0, "frame": 0, "time_s": 1e400, "what": ""},
        {"kind": "given", "timestamp_ms": 0, "frame": 0, "time_s": 0.0, "what": 7},
        {"kind": "given", "timestamp_ms": 0, "frame": 0, "time_s": 0.0, "collision": "maybe"},
    ],
)
def test_a_malformed_event_in_the_metadata_explains_nothing(bad: object) -> None:
    assert CriticalEvent.from_dict(bad) is None
    log = synthesise("cut_in", "planning", 0)
    log.metadata = replace(log.metadata, raw={**log.metadata.raw, EVENT_KEY: bad})
    assert explained_event(log.metadata) is None
    assert diagnose(log, make_params("corrected")).attribution.primary_root_cause == "planning"


def test_events_found_are_in_time_order_with_their_thresholds() -> None:
    log, _ = real_drive("lead_braking", "planning")
    found = find_events(perceived_world(log), make_params("corrected"), emergencies=[500])
    assert [e.timestamp_ms for e in found] == sorted(e.timestamp_ms for e in found)
    assert found[0].kind == "emergency" and found[0].timestamp_ms == 500


def test_event_time_on_the_command_line(tmp_path: Path) -> None:
    log = synthesise("cut_in", "planning", 0)
    contact_s = log.metadata.collision_frame * log.frame_ms / 1000.0
    log.metadata = replace(log.metadata, collision_frame=-1, collision_known=False)
    folder = write_run_log(log, tmp_path / "log")
    out = tmp_path / "v.json"
    run_cli("diagnose", str(folder), "--event-time", str(contact_s), "--json", str(out), check=True)
    document = json.loads(out.read_text())
    assert document["event"]["kind"] == "given"
    assert document["primary_root_cause"] == "planning"
    assert document["thresholds"]["event_time_s"] == contact_s


def test_an_object_first_seen_is_no_near_miss_by_time_to_collision(tmp_path: Path) -> None:
    """Its velocity is unknown on its first frame: taken as standing, the lead ahead of a
    following ego was "a collision within 0.8 s" at 10 m. Only clearance counts there."""
    from synthlogs import synth
    from writers.autoware_bags import AutowareBagOptions, write_autoware_bag

    log = synth("lead_braking", "planning")
    bag = write_autoware_bag(log, tmp_path / "bag", AutowareBagOptions(legacy=True)).path
    world = perceived_world(read_recording(bag, "autoware"))
    first_seen: dict[str, int] = {}
    for ts in world.unique_frames:
        for actor in world.actors[ts].ids:
            first_seen.setdefault(actor, ts)
    assert max(first_seen.values()) > min(world.unique_frames)  # someone comes into view
    params = make_params("corrected")
    for event in find_events(world, params):
        if event.kind == "near_miss" and event.timestamp_ms in first_seen.values():
            clearance = float(event.what.split("clearance ")[1].split(" m")[0])
            assert clearance < params.event_clearance, event


@pytest.mark.parametrize("value", ["nan", "-5", "1e12", "abc", "inf"])
def test_a_hostile_event_time_is_one_line_and_exit_2(tmp_path: Path, value: str) -> None:
    log, _ = real_drive("cut_in", "planning")
    folder = write_run_log(log, tmp_path / "log")
    for command in ("diagnose", "replay"):
        refused = run_cli(command, str(folder), f"--event-time={value}", check=False)
        assert refused.returncode == 2, refused.stderr
        assert "Traceback" not in refused.stderr
        # argparse's own refusal ('abc') comes after its usage lines; ours is the only line
        last = refused.stderr.strip().splitlines()[-1]
        assert "event-time" in last or "parameter event_time_s" in last, refused.stderr


@pytest.mark.parametrize(
    "document",
    [
        "yes",
        {"found": "all", "note": 3},
        {"found": [{"kind": "crash", "timestamp_ms": 1, "frame": 0, "time_s": 0.0}], "note": ""},
        {"found": [None, {"kind": "hard_brake", "timestamp_ms": -1, "frame": 0, "time_s": 0}]},
    ],
)
def test_malformed_events_in_a_recordings_metadata_are_left_out(document: object) -> None:
    """A recording of a replay carries the events looked for; a hostile entry lists nothing
    and explains nothing (one that is no mapping at all is as if absent: events are looked
    for), and the run is still diagnosed, never conclusively."""
    log, _ = real_drive("cut_in", "planning")
    log.metadata = replace(log.metadata, raw={**log.metadata.raw, CHOICE_KEY: document})
    choice = choice_of(log.metadata)
    found = diagnose(log, make_params("corrected")).to_json(include_frames=False)
    if choice is not None:
        assert choice.found == () and choice.explained is None
        assert found["event"] is None and found["events_found"] == []
        assert "no critical event found" in found["verdict"]
    else:
        assert isinstance(document, str) and found["events_found"]
    assert found["conclusive"] is False


def _marks(found: object) -> dict[int, list[str]]:
    """Per frame, the marks perception's result found."""
    out: dict[int, list[str]] = {}
    for frame in found.frames:  # type: ignore[attr-defined]
        result = frame.results["perception"]
        out[frame.timestamp_ms] = list(result.metrics.get("marks", []))
    return out


def test_a_detection_the_tracker_dropped_is_an_untracked_detection() -> None:
    """The detector sees the lead ahead, the tracker outputs nothing for it for 5 frames
    before the contact: perception fails there with the mark, from min_persistence frames
    on; with every detection tracked (the synthesiser's tracker), the mark never shows."""
    log, contact_s = real_drive("lead_braking", "planning")
    params = at(contact_s)
    tracked = diagnose(log, params)  # type: ignore[arg-type]
    assert not any("untracked detection" in m for m in _marks(tracked).values())
    contact_ms = round(contact_s * 1000)
    dropped = [ts for ts in sorted(log.tracks_3d) if contact_ms - 5 * log.frame_ms < ts]
    none = np.zeros((0, 3))
    for ts in dropped:  # the tracker outputs nothing; the detector still sees the lead
        log.tracks_3d[ts] = Objects3D((), none, np.zeros(0), none, none, np.zeros(0), ())
    found = diagnose(log, params)  # type: ignore[arg-type]
    marks = _marks(found)
    marked = [ts for ts, m in marks.items() if "untracked detection" in m]
    persistence = make_params("corrected").min_persistence
    assert marked and marked[0] == dropped[persistence - 1], (marked, dropped)
    result = next(f for f in found.frames if f.timestamp_ms == marked[-1]).results["perception"]
    count = result.metrics["untracked_detections"]
    assert result.failed and isinstance(count, int) and count >= 1
    assert "perc3d_match_distance" in result.thresholds
