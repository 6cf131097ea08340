"""The live graph's pure core (no ROS): windowed judging equals ``diagnose``, memory is
bounded, late collisions, stalled inputs and lost results are handled.

``run_live`` plays a log's timeline through the same MonitorCore / AggregatorCore classes
the nodes use, in one process.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from logfactory import make_log
from synthlogs import synth, write_log_with_unreadable_values
from verdicts import failed_flags, verdict_keys

from ads_rca.contract.jsontext import dumps_json, loads_json
from ads_rca.diagnosis.engine import diagnose
from ads_rca.live.aggregate import AggregatorCore
from ads_rca.live.results import FrameMarker, LiveResult
from ads_rca.live.simulate import run_live
from ads_rca.live.window import MonitorCore, WindowSettings
from ads_rca.model import RunLog
from ads_rca.oracles.base import MODULES
from ads_rca.params import Params, make_params
from ads_rca.problems import Problem
from ads_rca.sources.log.reader import read_run_log
from ads_rca.synth import FAULTS, SCENARIOS, synthesise


def assert_same_as_diagnose(log: RunLog, semantics: str, **options: Any) -> Any:
    params = make_params(semantics)
    offline = diagnose(log, params).to_json()
    run = run_live(log, params, **options)
    assert run.outcome is not None
    live = run.outcome.document
    assert verdict_keys(live) == verdict_keys(offline)
    assert failed_flags(live) == failed_flags(offline)
    assert live["frames"] == offline["frames"]  # same records in: bit-identical metrics
    return run


#: Every crash scenario with every fault (the DDS replay tests run the CASES subset).
MATRIX = [(s, f) for s in SCENARIOS if s != "cruise" for f in FAULTS] + [("cruise", "none")]


#: One core per module (``*_monitor`` processes) or one for all four (``monitors``).
LAYOUTS = pytest.mark.parametrize("shared", [False, True], ids=["separate", "shared"])


@LAYOUTS
@pytest.mark.parametrize("semantics", ["reference", "corrected"])
@pytest.mark.parametrize("case", MATRIX, ids=["-".join(c) for c in MATRIX])
def test_windowed_judging_equals_diagnose(
    case: tuple[str, str], semantics: str, shared: bool
) -> None:
    run = assert_same_as_diagnose(synth(*case), semantics, shared=shared)
    assert run.outcome is not None and run.outcome.complete


@LAYOUTS
@pytest.mark.parametrize("semantics", ["reference", "corrected"])
def test_reader_problems_reach_the_monitors_and_the_verdict(
    tmp_path: Path, semantics: str, shared: bool
) -> None:
    """The oracles read the reader's problems: live judging must get them too."""
    log = read_run_log(write_log_with_unreadable_values(tmp_path / "log"))
    assert sum(p.action == "read as NaN" for p in log.problems) == 14
    run = assert_same_as_diagnose(log, semantics, shared=shared)
    assert run.outcome is not None
    offline = diagnose(log, make_params(semantics)).to_json()
    assert run.outcome.document["input_problems"] == offline["input_problems"]


def test_problems_survive_a_round_trip_through_json() -> None:
    problem = Problem("pose/pose-100.json", "x", "missing", "read as NaN", "warning", 100)
    assert Problem.from_dict(loads_json(dumps_json(problem.to_dict()))) == problem
    bad: object
    for bad in ([], {"file": 1}, {**problem.to_dict(), "timestamp_ms": "100"}):
        with pytest.raises(ValueError):
            Problem.from_dict(bad)


@LAYOUTS
@pytest.mark.parametrize("semantics", ["reference", "corrected"])
def test_duplicated_frames_and_records_only_stamps(semantics: str, shared: bool) -> None:
    log = make_log(30, 6, 3, duplicate_frame=True, orphan_stamps=True)
    assert len(log.frames) != len(log.unique_frames)
    run = assert_same_as_diagnose(log, semantics, shared=shared)
    judged = len([r for r in run.results["perception"] if not r.provisional])
    assert judged == (len(log.frames) if semantics == "reference" else len(log.unique_frames))


@LAYOUTS
@pytest.mark.parametrize("semantics", ["reference", "corrected"])
def test_memory_does_not_grow_with_run_length(semantics: str, shared: bool) -> None:
    params = make_params(semantics)
    held = []
    for frames in (150, 300):
        log = synthesise("cruise", "none", 4, frames=frames, actors=10)
        run = run_live(log, params, shared=shared)
        assert run.outcome is not None and run.outcome.complete
        held.append(max(run.max_held_records.values()))
    assert held[0] == held[1]
    # a window of frames (the effect window, the noise floors' frames before it, the control
    # horizon: about 125 frames of 9 folders), not the run
    assert held[1] < 10 * 130


def test_windowed_judging_equals_diagnose_under_noise() -> None:
    """Rule 8's floors read the frames before the effect window: the live window keeps
    them, so a noisy run is judged as offline (the floors decide this crash: without them
    perception is blamed)."""
    log = synthesise("lead_braking", "planning", 0, 10.0)
    run = assert_same_as_diagnose(log, "corrected", shared=True)
    assert run.outcome is not None and run.outcome.complete
    assert run.outcome.document["primary_root_cause"] == "planning"


def test_late_collision_event_reevaluates_the_held_window() -> None:
    log = synth("cut_in", "perception")
    params = make_params("corrected")
    offline = diagnose(log, params).to_json()
    run = run_live(log, params, metadata_collision=False)
    assert run.outcome is not None
    live = run.outcome.document
    assert live["live"]["collision_source"] == "event"
    assert verdict_keys(live)["primary_root_cause"] == offline["primary_root_cause"]
    assert live["modules"] == offline["modules"]
    assert live["partner_id"] == offline["partner_id"]
    assert any(r.revision > 0 for r in run.results["perception"])


def test_a_topic_that_stops_is_reported_not_waited_on() -> None:
    log = synth("lead_braking", "prediction")
    last = len(log.frames) - 8

    def deliver(folder: str, stamp: int) -> bool:
        return not (folder == "pose" and stamp >= log.frames[last])

    params = make_params("corrected")
    settings = WindowSettings(input_timeout_s=0.5)
    run = run_live(log, params, settings, deliver=deliver)
    assert run.outcome is not None
    live = run.outcome.document
    assert live["live"]["complete"] is False
    assert live["live"]["incomplete_results"]
    assert len(live["frames"]) == len(log.frames)
    flagged = [r for r in run.results["controller"] if r.incomplete]
    assert flagged and all("no pose record" in " ".join(r.incomplete) for r in flagged[-3:])


def test_lookahead_holds_a_reference_prediction_frame_until_it_arrives() -> None:
    log = synth("lead_braking", "prediction")
    params = make_params("reference")
    core = MonitorCore("prediction", params)
    core.set_metadata(log.metadata, 0.0)
    frame_ms = log.frame_ms
    keys = max(int(t.steps.max()) for t in log.predictions_with_perception[log.frames[0]].values())
    judged: list[LiveResult] = []
    for n, ts in enumerate(log.frames[: keys + 2]):
        for folder in ("pose", "actors", "predictions_with_perception"):
            record = log.folder(folder).get(ts)
            if record is not None:
                core.add_record(folder, ts, record, 0.1)
        folders = frozenset(f for f in ("pose", "actors", "predictions_with_perception"))
        core.add_marker(FrameMarker(n, ts, folders), 0.1)
        judged += core.poll(0.1)
        if ts < log.frames[0] + keys * frame_ms:
            assert not judged, f"judged before its look-ahead (at {ts} ms)"
    assert [r.index for r in judged][:1] == [0]


def test_result_json_round_trip_is_exact() -> None:
    log = synth("left_turn", "controller")
    run = run_live(log, make_params("corrected"))
    for module in MODULES:
        for result in run.results[module][-5:]:
            back = LiveResult.from_document(loads_json(dumps_json(result.to_document())))
            assert back.result.failed == result.result.failed
            assert dumps_json(back.to_document()) == dumps_json(result.to_document())


def ended_run(log: RunLog, params: Params, **options: Any) -> AggregatorCore:
    """An aggregator (``options``: its own) that heard ``log``'s metadata, every frame
    marker and the end of the run, and no result yet."""
    aggregator = AggregatorCore(params, **options)
    aggregator.set_metadata(log.metadata, log.source, 0.0)
    for n, ts in enumerate(log.frames):
        aggregator.add_marker(FrameMarker(n, ts), 0.0)
    aggregator.set_finished(0.0)
    return aggregator


def test_lost_results_do_not_hold_the_verdict() -> None:
    log = synth("cut_in", "perception")
    params = make_params("reference")
    run = run_live(log, params)
    aggregator = ended_run(log, params, verdict_timeout_s=100.0)
    for module in MODULES:
        for result in run.results[module]:
            if not (module == "planning" and 10 <= result.index < 20):  # monitor was down
                aggregator.add_result(result, 0.0)
    outcome = aggregator.poll(1.0)
    assert outcome is not None and not outcome.complete
    assert "planning frames 10, 11" in outcome.why_incomplete[0]
    assert len(outcome.document["frames"]) == len(log.frames)


def test_stalled_inputs_give_an_incomplete_verdict_after_the_timeout() -> None:
    log = synth("cut_in", "perception")
    aggregator = AggregatorCore(make_params("corrected"), stall_timeout_s=3.0)
    aggregator.set_metadata(log.metadata, log.source, 0.0)
    for n, ts in enumerate(log.frames[:20]):
        aggregator.add_marker(FrameMarker(n, ts), 0.0)
    assert aggregator.poll(2.0) is None
    outcome = aggregator.poll(3.5)
    assert outcome is not None and "stalled" in outcome.why_incomplete[0]
    assert aggregator.poll(4.0) is None  # once


def test_end_of_run_waits_for_the_markers_the_status_announced() -> None:
    """DDS may deliver ``finished`` before the last markers: the end counts only after them."""
    log = synth("lead_braking", "prediction")
    core = MonitorCore("perception", make_params("corrected"))
    core.set_metadata(log.metadata, 0.0)
    frames = list(enumerate(log.frames))
    for n, ts in frames[:-1]:
        for folder in core.folders:
            record = log.folder(folder).get(ts)
            if record is not None:
                core.add_record(folder, ts, record, 0.1)
        held = [folder for folder in core.folders if ts in log.folder(folder)]
        core.add_marker(FrameMarker(n, ts, frozenset(held)), 0.1)
    core.set_finished(0.1, frames_published=len(frames))
    finished_early = core.finished  # a local: mypy would keep core.finished narrowed
    # Only provisional results before the last frame (corrected reads the partner there).
    assert not finished_early and all(r.provisional for r in core.poll(0.2))
    n, ts = frames[-1]
    held = [folder for folder in core.folders if ts in log.folder(folder)]
    for folder in held:
        core.add_record(folder, ts, log.folder(folder)[ts], 0.3)
    core.add_marker(FrameMarker(n, ts, frozenset(held)), 0.3)
    results = [r for r in core.poll(0.3) if not r.provisional]
    assert core.finished and len(results) == len(frames)
    assert not any(r.incomplete for r in results)


@pytest.mark.parametrize("value", ["abc", float("nan"), -1.0, float("inf"), True, None, [1]])
def test_a_hostile_arrival_time_is_not_said_and_the_latency_says_so(value: object) -> None:
    """A result's ``arrived_s`` from the wire that is no finite positive number is taken as
    not said (0); a verdict whose collision frame no monitor dated counts its latency from
    the last result's arrival at the aggregator, and says so."""
    log = synth("cut_in", "perception")
    params = make_params("reference")
    run = run_live(log, params)
    aggregator = ended_run(log, params)
    for module in MODULES:
        for result in run.results[module]:
            document = {**result.to_document(), "arrived_s": value}
            back = LiveResult.from_document(loads_json(dumps_json(document)))
            assert back.arrived_s == 0.0
            aggregator.add_result(back, 1.0)
    outcome = aggregator.poll(2.0)
    assert outcome is not None
    document = outcome.document
    assert document["verdict_latency_from"] == "the collision frame's arrival (its marker) here"
    assert document["verdict_latency_s"] == 2.0  # the markers came at 0.0, the verdict at 2.0
