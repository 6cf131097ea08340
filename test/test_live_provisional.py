"""A replay in `corrected` judges frames as the run plays, provisionally (docs/live-graph.md
"Provisional results"): its metadata announce the collision, but the partner is read at the
collision frame, the run's last. The monitors used to hold every frame until then, so a
dashboard showed nothing while the log played. Each case compares the final results and the
verdict with ``diagnose`` on the same crash (consistency with our synthesiser)."""

from __future__ import annotations

import pytest
from stackgraph import crash, metrics_difference, offline, same_verdict

from ads_rca.diagnosis.verdict import OracleResult
from ads_rca.live.aggregate import AggregatorCore
from ads_rca.live.results import LiveResult
from ads_rca.live.simulate import run_live
from ads_rca.live.window import WindowSettings
from ads_rca.oracles.base import MODULES
from ads_rca.params import make_params

CRASHES = [
    ("cut_in", "controller"),
    ("lead_braking", "prediction"),
    ("pedestrian_crossing", "perception"),
    ("left_turn", "planning"),
]


@pytest.mark.parametrize(
    ("scenario", "fault", "shared"),
    [(*case, True) for case in CRASHES] + [(*CRASHES[1], False)],
    ids=[f"{s}-{f}" for s, f in CRASHES] + ["a-core-each"],
)
def test_frames_are_judged_provisionally_as_the_run_plays(
    scenario: str, fault: str, shared: bool
) -> None:
    log = crash(scenario, fault)
    expected = offline(scenario, fault, "corrected")
    run = run_live(
        log, make_params("corrected"), WindowSettings(input_timeout_s=1.0), shared=shared
    )
    assert run.outcome is not None
    verdict = run.outcome.document
    assert same_verdict(verdict, expected.to_json()) and run.outcome.complete
    cf = log.metadata.collision_frame
    for module in MODULES:
        results = run.results[module]
        first_final = next(i for i, r in enumerate(results) if not r.provisional)
        early = results[:first_final]
        # Before any final result, the frames up to the look-ahead before the collision
        # were out, marked, judged without the collision against a named actor.
        assert len(early) >= cf - 12, (module, len(early))
        assert all(r.provisional and r.collision_frame == -1 and r.partner_id for r in early)
        latest = {r.stamp_ms: r for r in results}  # published in revision order
        for frame in expected.frames:
            got, want = latest[frame.timestamp_ms], frame.results[module]
            assert not got.provisional and got.collision_frame == cf
            assert got.revision > 0 or frame.timestamp_ms > cf * log.frame_ms - 600
            assert (got.result.failed, got.result.skipped) == (want.failed, want.skipped)
            assert metrics_difference(want.metrics, got.result.metrics) is None
    # Where the most threatening actor was the partner, the provisional results stood.
    assert sum(core.stats.kept for core in {id(c): c for c in run.monitors.values()}.values())


def test_reference_has_no_partner_and_judges_as_it_goes() -> None:
    log = crash(*CRASHES[0])
    run = run_live(log, make_params("reference"), WindowSettings(input_timeout_s=1.0))
    assert not any(r.provisional for rs in run.results.values() for r in rs)


def provisional_result(failed: bool) -> LiveResult:
    result = OracleResult("planning", 100, failed, {}, {}, ("7",), None)
    return LiveResult(index=2, result=result, frame=2, provisional=True, partner_id="7")


@pytest.mark.parametrize("value", ["yes", 1, None, "true", [True], {"a": 1}])
def test_only_a_literal_true_marks_a_result_provisional(value: object) -> None:
    document = provisional_result(False).to_document()
    assert document["provisional"] is True
    assert LiveResult.from_document(document).provisional
    document["provisional"] = value
    assert not LiveResult.from_document(document).provisional


def test_a_provisional_result_never_enters_a_verdict() -> None:
    """Forged or late, a provisional result is shown, never decided on."""
    core = AggregatorCore(make_params("corrected"))
    core.add_result(provisional_result(True), 1.0)
    assert not core.results.has("planning", 2)
    assert core.received["planning"] == 0


def test_a_frame_first_judged_provisionally_is_never_held_back() -> None:
    """A monitor publishes last only results it published before, final and unchanged (the
    aggregator holds them). A provisional result never reached the verdict: its frame's
    final result is sent with the ones that decide, or the aggregator counts it lost."""
    log = crash(*CRASHES[0])
    run = run_live(log, make_params("corrected"), WindowSettings(input_timeout_s=1.0))
    for late in run.deferred:
        before = [
            r
            for r in run.results[late.module]
            if r.stamp_ms == late.stamp_ms and r.revision < late.revision
        ]
        assert before and not before[-1].provisional, (late.module, late.stamp_ms)


def test_a_provisional_status_says_so_and_names_its_actor() -> None:
    from ads_rca.live.diagnostics import ERROR, result_status

    status = result_status(provisional_result(True), "corrected", "ads_rca")
    assert status.level == ERROR  # failing against that actor: said, marked provisional
    assert "(provisional: judged against actor 7, the most threatening" in status.message
    assert ("provisional", "true") in status.values
