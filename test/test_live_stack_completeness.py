"""A stack-mode verdict claims only what it judged, in process.

``live.complete`` is true only when every frame of the effect window was judged on full
inputs, and the conclusion (docs/verdicts.md) says what was not: an input the stack never
sent in the window makes the modules needing it "not judged (no <input>)"; one that stops
inside the window makes them "partly judged"; frames no monitor judged (a restart's gap,
a reference message lost or late) are named by frame number, also when the gap crosses the
window's start (``diagnose`` says the same of a log folder missing those frames). Before,
such verdicts were complete, or "partly judged" for an input never sent, and lost frames
before the window's first judged frame were not named. Over DDS, with an independent
stack: test_ros_stack_independent.py.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from stackgraph import crash
from stacksettings import config

from ads_rca.diagnosis.engine import diagnose
from ads_rca.live.aggregate import AggregatorCore
from ads_rca.live.simulate import LiveRun, StackMessage, StackStream, run_stack, stack_stream
from ads_rca.live.window import WindowSettings
from ads_rca.params import make_params
from ads_rca.sources.log.writer import write_run_log
from ads_rca.sources.registry import open_run

CASE = ("lead_braking", "prediction")  # collision at frame 78
WHOLE_HISTORY = WindowSettings(input_timeout_s=1.0, history_frames=400)


def live(mode: str, keep: Callable[[StackMessage], bool] = lambda m: True) -> dict[str, Any]:
    """The verdict on CASE sent as a stack does, the messages ``keep`` refuses left out."""
    log = crash(*CASE)
    sent = stack_stream(log, seed=3)
    kept = StackStream([m for m in sent.messages if keep(m)], {}, {}, sent.collision_s)
    run = run_stack(log, make_params(mode), kept, config(), WHOLE_HISTORY)
    assert run.outcome is not None
    return run.outcome.document


def frame_of(message: StackMessage) -> int:
    """The log frame a message was sent for (its stamp less the input's offset, rounded)."""
    return round(message.stamp_ms / 50)


def assert_never_no_fault_found(verdict: dict[str, Any]) -> None:
    assert verdict["conclusive"] is False
    assert "no fault found" not in str(verdict["verdict"])
    assert verdict["live"]["complete"] is False


@pytest.mark.parametrize("mode", ["reference", "corrected"])
def test_an_input_never_sent_leaves_its_modules_not_judged(mode: str) -> None:
    verdict = live(mode, lambda m: m.folder != "predictions_with_perception")
    assert_never_no_fault_found(verdict)
    judged = verdict["modules_judged"]
    for module in ("prediction", "planning"):
        assert judged[module] == "not judged (no predictions_gt)", judged
    if mode == "reference":  # neither reads it
        assert (judged["perception"], judged["controller"]) == ("judged", "judged")
    reasons = verdict["live"]["why_incomplete"]
    assert (
        "no predictions_with_perception message on /ads_rca/prediction/with_perception for any "
        "frame of the effect window"
    ) in reasons
    assert "prediction not judged (no predictions_gt)" in verdict["why_inconclusive"]


def test_an_input_that_stops_is_not_judged_or_partly_judged_where_it_stopped() -> None:
    before = live("reference", lambda m: not (m.folder == "bboxes" and frame_of(m) >= 30))
    assert_never_no_fault_found(before)
    assert before["modules_judged"] == {
        "perception": "not judged (no detections_2d)",
        "prediction": "judged",
        "planning": "judged",
        "controller": "judged",
    }
    inside = live("reference", lambda m: not (m.folder == "bboxes" and frame_of(m) >= 75))
    assert_never_no_fault_found(inside)
    judged = inside["modules_judged"]
    window = inside["window_frames"] + 1  # frames 78 - W to 78
    assert judged["perception"].startswith(f"partly judged (4 of {window} window frames: ")
    assert judged["perception"].endswith("at frames 75, 76, 77, 78)")
    assert judged["controller"] == "judged"  # reads no boxes: its frames were complete


@pytest.mark.parametrize(
    ("lost", "only_reference", "named"),
    [
        ((55, 60), False, "frames 58, 59, 60"),  # a restart's gap across the window's start
        ((70, 72), True, "frames 70, 71, 72"),  # their odometry lost: the rest unmatched
    ],
)
def test_frames_no_monitor_judged_make_the_verdict_incomplete(
    lost: tuple[int, int], only_reference: bool, named: str
) -> None:
    def keep(message: StackMessage) -> bool:
        gone = lost[0] <= frame_of(message) <= lost[1]
        return not gone or (only_reference and message.folder != "pose")

    verdict = live("corrected", keep)
    assert_never_no_fault_found(verdict)
    assert f"{named} of the effect window are missing from the run" in verdict["why_inconclusive"]
    assert any(
        reason.startswith(f"{named} of the effect window never judged")
        for reason in verdict["live"]["why_incomplete"]
    )


def test_diagnose_names_window_frames_missing_across_its_start(tmp_path: Path) -> None:
    """The same rule offline: a log folder that lost frames 55 to 60 (window 58 to 78)."""
    folder = write_run_log(crash(*CASE), tmp_path / "log")
    for path in folder.glob("*/*.json"):
        if 55 * 50 <= int(path.stem.rsplit("-", 1)[1]) <= 60 * 50:
            path.unlink()
    document = diagnose(open_run(folder), make_params("corrected")).to_json()
    assert document["conclusive"] is False
    assert (
        "frames 58, 59, 60 of the effect window are missing from the run"
        in (document["why_inconclusive"])
    )


def test_results_a_restarted_monitor_lost_are_named_by_frame_number() -> None:
    """Stack mode indexes frames from a margin before the first stamp heard: the verdict
    named a lost result by that index (perception frames 4166, 4167), not its frame."""
    log, params = crash(*CASE), make_params("reference")
    run: LiveRun = run_stack(log, params, stack_stream(log, seed=3), config(), WHOLE_HISTORY)
    core = AggregatorCore(params, stack=config())
    core.set_collision(78, 0.0)
    results = [r for rs in run.results.values() for r in rs]
    for n, result in enumerate(sorted(results, key=lambda r: (r.stamp_ms, r.revision))):
        if not (result.module == "perception" and result.frame in (70, 71)):
            core.add_result(result, n / 1000)
    outcome = next(o for t in range(100) if (o := core.poll(1.0 + t)) is not None)
    assert "results lost (a monitor restarted): perception frames 70, 71" in (
        outcome.why_incomplete
    )
