"""Stack mode judges held frames ahead against a warned actor, and a collision keeps a
frame's results when its partner and data did not change (docs/live-graph.md "Verdict
latency"). Each case compares every frame's result and the verdict with ``diagnose`` on
the same crash: the shortcut may make the verdict sooner, never different. These are
consistency checks on our synthesiser's crashes."""

from __future__ import annotations

from typing import Any

import pytest
from stackgraph import crash, metrics_difference, offline, same_verdict
from stacksettings import config

from ads_rca.live.simulate import LiveRun, run_stack, stack_stream
from ads_rca.live.window import MonitorCore, WindowSettings
from ads_rca.params import make_params

#: One crash per scenario, each fault once.
CRASHES = [
    ("cut_in", "controller"),
    ("lead_braking", "prediction"),
    ("pedestrian_crossing", "perception"),
    ("left_turn", "planning"),
]


def live(scenario: str, fault: str, **options: Any) -> LiveRun:
    log = crash(scenario, fault)
    settings = WindowSettings(input_timeout_s=1.0, history_frames=400)
    stream = stack_stream(log, seed=3)
    return run_stack(log, make_params("corrected"), stream, config(), settings, **options)


def assert_equals_diagnose(run: LiveRun, scenario: str, fault: str) -> None:
    expected = offline(scenario, fault, "corrected")
    assert run.outcome is not None
    assert same_verdict(run.outcome.document, expected.to_json()), (scenario, fault)
    latest = {(r.module, r.stamp_ms): r for rs in run.results.values() for r in rs}
    partner = expected.to_json()["partner_id"]
    for frame in expected.frames:
        for module, want in frame.results.items():
            got = latest[(module, frame.timestamp_ms)]
            assert got.partner_id == partner, (scenario, fault, frame.timestamp_ms)
            assert (got.result.failed, got.result.skipped) == (want.failed, want.skipped)
            assert metrics_difference(want.metrics, got.result.metrics) is None


@pytest.mark.parametrize(("scenario", "fault"), CRASHES)
def test_results_judged_ahead_against_the_partner_are_the_collision_results(
    scenario: str, fault: str
) -> None:
    run = live(scenario, fault)
    core = run.monitors["planning"]
    assert core.threat is not None  # the crash was warned of ...
    assert core.stats.prepared > 0  # ... frames were judged ahead against its actor ...
    assert core.stats.kept > 0  # ... and the collision kept results instead of judging
    assert_equals_diagnose(run, scenario, fault)


def test_results_judged_ahead_against_another_actor_are_not_used() -> None:
    """The warned actor is not always the partner: then every result judged ahead is
    dropped and the frame is judged again against the partner."""
    scenario, fault = CRASHES[1]
    expected = offline(scenario, fault, "corrected")
    partner, ego = expected.to_json()["partner_id"], expected.ctx.ego_id
    decoy = next(a for a in sorted(crash(scenario, fault).actor_extents) if a not in (partner, ego))

    def warn_of_the_decoy(core: MonitorCore) -> None:
        if core.threat is not None:
            core.threat = decoy

    run = live(scenario, fault, warned=warn_of_the_decoy)
    core = run.monitors["planning"]
    assert core.stats.prepared > 0
    assert_equals_diagnose(run, scenario, fault)
    honest = live(scenario, fault).monitors["planning"]
    assert core.stats.kept < honest.stats.kept  # frames judged ahead were judged again


def test_nothing_is_judged_ahead_without_a_warning() -> None:
    scenario, fault = CRASHES[0]

    def no_warning(core: MonitorCore) -> None:
        core.threat = None

    run = live(scenario, fault, warned=no_warning)
    assert run.monitors["planning"].stats.prepared == 0
    assert_equals_diagnose(run, scenario, fault)


def test_only_results_published_before_unchanged_are_sent_last() -> None:
    """The monitors publish kept results of frames before the effect window after the
    others of their poll, so the verdict comes first: the aggregator reads which of those
    frames failed from what it already holds. That holds only for a result published
    before with the same judgement; a result judged ahead was never published."""
    deferred = 0
    for scenario, fault in CRASHES:
        run = live(scenario, fault)
        deferred += len(run.deferred)
        for late in run.deferred:  # each was heard before, the same
            before = [
                r
                for r in run.results[late.module]
                if r.stamp_ms == late.stamp_ms and r.revision < late.revision
            ]
            assert before, (scenario, fault, late.module, late.stamp_ms)
            assert before[-1].result == late.result, (scenario, fault, late.stamp_ms)
            assert before[-1].partner_id == late.partner_id
    assert deferred > 0  # the shortcut was taken


def test_a_warning_older_than_the_effect_window_judges_nothing_ahead() -> None:
    """A threat that passed (a near miss) does not keep doubling the monitors' work."""
    scenario, fault = CRASHES[0]

    def long_ago(core: MonitorCore) -> None:
        core.threat_ms = -(10**9)

    run = live(scenario, fault, warned=long_ago)
    assert run.monitors["planning"].threat is not None
    assert run.monitors["planning"].stats.prepared == 0
    assert_equals_diagnose(run, scenario, fault)
