"""Stack mode's cores in-process, over the whole grid, on simulated time.

The same classes the nodes run (:class:`StackFeed` into one :class:`MonitorCore`, the
stack-mode :class:`AggregatorCore`) fed a synthesised crash as a stack sends it
(``simulate.stack_stream``: per-input stamp offsets up to 20 ms, arrival jitter, no markers,
no metadata, the collision announced after its frame). Over DDS: test_ros_stack_graph.py.
"""

from __future__ import annotations

from typing import Any

import pytest
from golden_outputs import first_difference
from stackgraph import crash, metrics_difference, offline, same_verdict
from stacksettings import config

from ads_rca.errors import ConfigError
from ads_rca.live.simulate import LiveRun, run_stack, stack_stream
from ads_rca.live.window import WindowSettings
from ads_rca.model import RunLog
from ads_rca.params import make_params

CRASHES = [
    (scenario, fault)
    for scenario in ("cut_in", "lead_braking", "pedestrian_crossing", "left_turn")
    for fault in ("perception", "prediction", "planning", "controller")
]
MODES = ("reference", "corrected")
ATTRIBUTION_KEYS = ("primary_root_cause", "root_causes", "contributing", "partner_id")


def live(log: RunLog, mode: str, history: int = 400, **stream: Any) -> LiveRun:
    settings = WindowSettings(input_timeout_s=1.0, history_frames=history)
    return run_stack(log, make_params(mode), stack_stream(log, **stream), config(), settings)


def verdict_of(run: LiveRun) -> dict[str, Any]:
    assert run.outcome is not None
    return run.outcome.document


@pytest.mark.slow
@pytest.mark.parametrize("mode", MODES)
def test_every_crash_judged_live_equals_diagnose(mode: str) -> None:
    for scenario, fault in CRASHES:
        log, expected = crash(scenario, fault), offline(scenario, fault, mode)
        run = live(log, mode, seed=3)
        verdict, want = verdict_of(run), expected.to_json()
        assert same_verdict(verdict, want), (scenario, fault)
        assert verdict["live"]["complete"], (scenario, fault)
        # The verdict's frames are the effect window's (a long run's verdict stays small).
        cf_ms = log.metadata.collision_frame * log.frame_ms
        start = cf_ms - verdict["window_frames"] * log.frame_ms
        window = [s for s in log.unique_frames if start <= s <= cf_ms]
        assert [f["timestamp_ms"] for f in verdict["frames"]] == window
        latest = {(r.module, r.stamp_ms): r for rs in run.results.values() for r in rs}
        for frame in expected.frames:
            for module, result in frame.results.items():
                got = latest[(module, frame.timestamp_ms)].result
                assert (got.failed, got.skipped) == (result.failed, result.skipped)
                assert metrics_difference(result.metrics, got.metrics) is None


@pytest.mark.parametrize("mode", MODES)
def test_the_default_history_keeps_the_attribution_exact(mode: str) -> None:
    """Frames older than the re-judged history keep their pre-collision judgement (against
    the most threatening actor, in corrected): only the counts outside the window can move."""
    for scenario, fault in CRASHES[::3]:
        verdict = verdict_of(live(crash(scenario, fault), mode, history=0, seed=4))
        want = offline(scenario, fault, mode).to_json()
        assert {k: verdict[k] for k in ATTRIBUTION_KEYS} == {k: want[k] for k in ATTRIBUTION_KEYS}
        assert first_difference(want["evidence"], verdict["evidence"]) is None


@pytest.mark.slow
@pytest.mark.parametrize("mode", MODES)
def test_two_percent_of_an_input_dropped(mode: str) -> None:
    same = 0
    folders = ("bboxes", "predictions", "waypoint")
    for n, (scenario, fault) in enumerate(CRASHES):
        folder = folders[n % len(folders)]
        log = crash(scenario, fault)
        stream = stack_stream(log, seed=n, drop={folder: 0.02})
        settings = WindowSettings(input_timeout_s=1.0, history_frames=400)
        run = run_stack(log, make_params(mode), stream, config(), settings)
        dropped = set(stream.dropped[folder])
        assert len(dropped) == round(0.02 * len(log.folder(folder))) > 0
        flagged = {
            r.stamp_ms
            for results in run.results.values()
            for r in results
            if f"no {folder} record" in r.incomplete
        }
        assert flagged == dropped
        verdict, want = verdict_of(run), offline(scenario, fault, mode).to_json()
        same += all(verdict[k] == want[k] for k in ATTRIBUTION_KEYS)
    # Measured: every crash keeps its verdict with 2 % of one input gone (16 of 16).
    assert same == len(CRASHES)


@pytest.mark.parametrize("mode", MODES)
def test_a_collision_the_aggregator_never_heard_is_taken_from_the_monitors(mode: str) -> None:
    """The latched collision event can be gone before the aggregator matches it (its
    publisher left): the monitors heard it, and their results closing the collision carry
    its frame. The verdict is the one the event gives, said to come from the monitors; it
    used to wait forever."""
    for scenario, fault in CRASHES[1::5]:
        log = crash(scenario, fault)
        settings = WindowSettings(input_timeout_s=1.0, history_frames=400)
        params, stream = make_params(mode), stack_stream(log, seed=5)
        heard = run_stack(log, params, stream, config(), settings)
        missed = run_stack(log, params, stream, config(), settings, aggregator_hears=False)
        verdict, want = verdict_of(missed), verdict_of(heard)
        assert verdict["live"]["collision_source"] == "monitors", (scenario, fault)
        assert want["live"]["collision_source"] == "event"
        assert verdict["live"]["complete"], (scenario, fault)
        assert verdict["collision_frame"] == log.metadata.collision_frame
        assert {k: verdict[k] for k in ATTRIBUTION_KEYS} == {k: want[k] for k in ATTRIBUTION_KEYS}
        assert verdict["frames"] == want["frames"]


def test_a_measured_period_gives_the_same_verdict() -> None:
    log = crash("cut_in", "planning")
    settings = WindowSettings(input_timeout_s=1.0, history_frames=400)
    run = run_stack(
        log,
        make_params("corrected"),
        stack_stream(log, seed=1),
        config(timesteps_per_frame=0),
        settings,
    )
    want = offline("cut_in", "planning", "corrected").to_json()
    assert same_verdict(verdict_of(run), want)


def test_run_facts_found_wrong_are_said() -> None:
    log = crash("cut_in", "planning")
    settings = WindowSettings(input_timeout_s=1.0)
    wrong = config(ego_id="no-such-actor", timesteps_per_frame=40)
    run = run_stack(log, make_params("reference"), stack_stream(log), wrong, settings)
    assert run.feed is not None
    assert run.feed.fact_problems == [
        "timesteps_per_frame is 40 ms but the reference input's stamps are 50 ms apart",
        "ego_id 'no-such-actor' is not among the actors of the first 20 frames",
    ]


def test_an_unreadable_message_is_skipped_and_said() -> None:
    from ads_rca.live.stack_feed import StackFeed
    from ads_rca.live.window import MonitorCore
    from ads_rca.oracles.base import MODULES

    said: list[tuple[str, str]] = []
    core = MonitorCore(MODULES, make_params("reference"), stack=True)
    feed = StackFeed(config(), core, lambda folder, error: said.append((folder, error)))
    feed.add("bboxes", b"\x00\x01garbage", 0.0)
    [(folder, error)] = said
    assert folder == "bboxes" and "\n" not in error


@pytest.mark.parametrize(
    ("values", "message"),
    [
        (
            {"inputs.actors.layout": "cubes"},
            "parameter inputs.actors.layout: 'cubes' is not a layout",
        ),
        ({"inputs.pose.topic": "odom"}, "inputs.pose.topic: 'odom' is not an absolute"),
        ({"inputs.pose.layout": "none"}, "reference_input: 'pose' is not a provided input"),
        ({"stack_mode": "on"}, "stack_mode: 'on' is not one of"),
    ],
)
def test_bad_stack_parameters_are_one_line_naming_the_parameter(
    values: dict[str, Any], message: str
) -> None:
    with pytest.raises(ConfigError) as error:
        config(**values)
    assert message in str(error.value) and "\n" not in str(error.value)


def test_collisions_detected_on_a_stacks_topics_are_the_logged_ones() -> None:
    """``detect_collisions``: the aggregator's feed of ego pose and actors, framed by their
    stamps, finds each crash at its logged frame; a garbage message is skipped and said."""
    from ads_rca.live.collision_feed import CollisionFeed, collision_document

    for scenario, fault in CRASHES[::4]:
        log = crash(scenario, fault)
        said: list[tuple[str, str]] = []

        def say(folder: str, error: str, said: list[tuple[str, str]] = said) -> None:
            said.append((folder, error))

        feed = CollisionFeed(config(), say)
        feed.add("actors", b"\x00garbage", 0.0)
        found = []
        for message in stack_stream(log, seed=2).messages:
            if message.folder in feed.decoders:
                found += feed.add(message.folder, message.payload, message.arrival_s)
        found += feed.poll(1e9)
        document = collision_document(found[0])
        assert document["frame"] == log.metadata.collision_frame, (scenario, fault)
        assert document["derived"] is True
        assert [folder for folder, _ in said] == ["actors"]


def test_a_collision_frame_held_for_its_inputs_is_waited_for() -> None:
    """A monitor may hold the collision frame ``input_timeout_s`` for its inputs (a message
    DDS delivers late) before judging up to it: the verdict waits that long on top of
    ``verdict_timeout_s`` before giving up, then says it is incomplete and why."""
    from ads_rca.live.aggregate import AggregatorCore

    stack = config(input_timeout_s=30.0)
    core = AggregatorCore(make_params("corrected"), verdict_timeout_s=10.0, stack=stack)
    core.set_collision(40, now=100.0)
    assert core.poll(100.0 + 10.0 + 1.0) is None  # past verdict_timeout_s alone
    assert core.poll(100.0 + 39.9) is None
    outcome = core.poll(100.0 + 40.0)
    assert outcome is not None and not outcome.complete
    assert outcome.why_incomplete == [
        "timed out after 40 s waiting for perception, prediction, planning, controller "
        "to judge up to the collision"
    ]


def test_what_the_stamp_sync_drops_is_said_once_per_change() -> None:
    """The monitor node logs this line (at most once a second): a frame released
    incomplete is then explained by the messages that came late or matched no frame."""
    from ads_rca.live.stack_feed import StackFeed
    from ads_rca.live.window import MonitorCore

    core = MonitorCore("perception", make_params("corrected"), stack=True)
    feed = StackFeed(config(), core, lambda folder, error: None)
    assert feed.sync_news() is None
    feed.sync.counts.late, feed.sync.counts.incomplete = 2, 1
    assert feed.sync_news() == "stamp sync so far: 2 late messages, 1 frames released incomplete"
    assert feed.sync_news() is None  # nothing new
