"""Stack mode's episodes in process: stamps that go back begin a new run.

A simulator that restarts (a new episode from stamp 0) sends stamps its previous episode
already had. Before, the new episode's frames were dropped as late by the stamp sync and
its crash ignored (its frame was before the first crash's), or judged on the old episode's
data. Now the monitors' feed begins a new episode (fresh window, sync, partner, collisions)
when the reference stamps go back by more than ``episode_rewind_s``, every result carries its
episode, and the aggregator keys results by it: each episode's crash gets its own verdict,
equal to ``diagnose`` of that episode's log alone. Over DDS, with an independent stack:
test_ros_stack_independent.py.
"""

from __future__ import annotations

import itertools
from dataclasses import replace

import pytest
from stackgraph import crash, offline, same_verdict
from stacksettings import config

from ads_rca.live.aggregate import AggregatorCore, VerdictOutcome
from ads_rca.live.episodes import (
    CURRENT,
    NEW,
    NEXT,
    PREVIOUS,
    EpisodeAggregator,
    EpisodeClock,
    ForwardJumps,
)
from ads_rca.live.results import LiveResult
from ads_rca.live.simulate import LiveRun, run_stack, stack_episodes
from ads_rca.live.window import WindowSettings
from ads_rca.oracles.base import MODULES
from ads_rca.params import make_params

FIRST, SECOND = ("cut_in", "perception"), ("lead_braking", "prediction")
WHOLE_HISTORY = WindowSettings(input_timeout_s=1.0, history_frames=400)


def two_episodes(
    mode: str, gap_s: float, first: tuple[str, str] = FIRST, second: tuple[str, str] = SECOND
) -> LiveRun:
    """``first`` then ``second``, each with its own stamps (the second from 50 ms again)."""
    logs = [crash(*first), crash(*second)]
    stream, collisions = stack_episodes(logs, gap_s=gap_s, seed=3)
    params = make_params(mode)
    return run_stack(
        logs[0], params, stream, config(), WHOLE_HISTORY, collisions=collisions, drain_s=30.0
    )


def test_the_rule_says_where_each_stamp_belongs() -> None:
    clock = EpisodeClock(rewind_ms=1000.0)
    assert [clock.reference(s) for s in (50, 100, 150, 5150)] == [CURRENT] * 4
    assert clock.reference(4200) == CURRENT  # back by less than the bound: not an episode
    assert clock.place(4500) == CURRENT  # a late input of this episode
    assert clock.place(3000) == NEXT  # more than the bound before: an episode not begun yet
    assert (clock.reference(50), clock.number) == (NEW, 2)  # back by 5.1 s: episode 2
    assert clock.place(5100) == PREVIOUS  # a late message of episode 1
    assert clock.place(100) == CURRENT
    clock.close_previous()
    assert clock.place(5100) == CURRENT  # episode 1 is closed: nothing is taken for it
    never = EpisodeClock(rewind_ms=0.0)
    assert [never.reference(s) for s in (5000, 50)] == [CURRENT, CURRENT]


@pytest.mark.parametrize(
    ("mode", "gap_s", "cases"),
    [
        ("corrected", 1.0, (FIRST, SECOND)),
        ("reference", 0.0, (FIRST, SECOND)),
        ("corrected", 0.0, (SECOND, FIRST)),
    ],
)
def test_each_episode_gets_its_own_verdict_equal_to_diagnose(
    mode: str, gap_s: float, cases: tuple[tuple[str, str], tuple[str, str]]
) -> None:
    """A second episode from stamp 50 again, a second after the first crash or at once.
    Before, the second episode's messages were dropped as late and its crash (at frame 78,
    before the first's 103) ignored; or, its crash later than the first's, judged on the
    frames after the first's stamps with the first's partner: "no fault found", complete."""
    run = two_episodes(mode, gap_s, *cases)
    assert len(run.verdicts) == 2
    for outcome, case, episode in zip(run.verdicts, cases, (1, 2), strict=True):
        document = outcome.document
        assert same_verdict(document, offline(*case, mode).to_json()), (case, document["verdict"])
        assert document["collision_frame"] == crash(*case).metadata.collision_frame
        assert document["live"]["episode"] == episode
        assert document["live"]["collision_number"] == 1
        assert document["live"]["complete"] is True, document["live"]
        assert document["conclusive"] is True
    second = crash(*cases[1])
    cf_ms = second.metadata.collision_frame * second.frame_ms
    document = run.verdicts[1].document
    start = cf_ms - document["window_frames"] * second.frame_ms
    window = [f["timestamp_ms"] for f in document["frames"]]
    assert window == [s for s in second.unique_frames if start <= s <= cf_ms]
    [report] = run.episodes
    assert (report.episode, report.next_episode, report.collisions) == (1, 2, 1)
    results = [r for rs in run.results.values() for r in rs]
    assert {r.episode for r in results} == {1, 2}
    cf = second.metadata.collision_frame
    assert all(r.collision_frame in (-1, cf) for r in results if r.episode == 2)
    assert run.feed is not None and run.feed.sync.counts.late == 0


def test_an_episode_without_a_collision_is_reported_when_the_next_begins() -> None:
    """The first episode ends without a crash, its last 100 ms of messages still arriving
    after the second episode's first ones: they are its own, the second's frames complete."""
    run = two_episodes("reference", -0.1, first=("cut_in", "none"))
    [report] = run.episodes
    assert report.text() == (
        "episode 2 began (the stamps went back); episode 1 ended: frames 1 to 200, "
        "0 collisions, 0 verdicts"
    )
    [verdict] = run.verdicts
    assert verdict.document["live"]["episode"] == 2
    assert verdict.document["live"]["complete"] is True, verdict.document["live"]
    assert same_verdict(verdict.document, offline(*SECOND, "reference").to_json())
    first = [r for r in run.results["controller"] if r.episode == 1]
    assert sorted({r.stamp_ms for r in first}) == list(crash("cut_in", "none").unique_frames)
    assert not [r.incomplete for r in first if r.incomplete]  # its late messages were its own


def interleaved(run: LiveRun) -> list[LiveResult]:
    """Every result, each module's in its order, the modules round-robin (DDS orders one
    topic, not the four), the first episode's last third after the second's first fifth."""

    def round_robin(episode: int) -> list[LiveResult]:
        lists = [[r for r in run.results[m] if r.episode == episode] for m in MODULES]
        return [r for row in itertools.zip_longest(*lists) for r in row if r is not None]

    first, second = round_robin(1), round_robin(2)
    cut, ahead = 2 * len(first) // 3, len(second) // 5
    return first[:cut] + second[:ahead] + first[cut:] + second[ahead:]


@pytest.mark.parametrize("mode", ["reference", "corrected"])
def test_late_results_of_an_ended_episode_stay_in_it(mode: str) -> None:
    """The aggregator hears the second crash, and the second episode's first results, while
    a third of the first episode's results are still to come: each verdict is still its own
    episode's, the heard collision given to the episode whose monitors judged with it."""
    params = make_params(mode)
    results = interleaved(two_episodes(mode, 1.0))
    episodes = EpisodeAggregator(lambda: AggregatorCore(params, stack=config()), stack=True)
    verdicts: list[VerdictOutcome] = []
    episodes.set_collision(103, 0.0)  # the first crash, heard before any result
    for n, result in enumerate(results):
        now = n / 1000  # a result a millisecond
        if n and result.episode == 2 and results[n - 1].episode == 1:
            episodes.set_collision(78, now)  # the second crash, before the first's tail
        episodes.add_result(result, now)
        verdicts += [e for e in episodes.poll(now) if isinstance(e, VerdictOutcome)]
    assert [v.document["live"]["episode"] for v in verdicts] == [1, 2]
    for outcome, case in zip(verdicts, (FIRST, SECOND), strict=True):
        document = outcome.document
        assert same_verdict(document, offline(*case, mode).to_json()), case
        assert document["live"]["collision_source"] == "event"
        assert document["live"]["complete"] is True, document["live"]
    assert episodes.dropped == 0


def test_forward_jumps_are_skipped_unless_confirmed() -> None:
    jumps = ForwardJumps(jump_ms=10_000.0)
    assert jumps.check(100, None) == "plausible"  # nothing accepted yet
    assert jumps.check(150, 100) == "plausible"
    assert jumps.check(2**32 * 1000, 150) == "skipped"  # a glitch: the grid does not move
    assert jumps.check(200, 150) == "plausible"  # the real stream goes on
    assert jumps.check(60_200, 200) == "skipped"  # a real jump (the stack's clock moved)
    assert jumps.check(60_250, 200) == "skipped"
    assert jumps.check(60_300, 200) == "confirmed"  # the third in a row: taken
    assert (jumps.skipped, jumps.confirmed) == (3, 1)
    assert ForwardJumps(jump_ms=0.0).check(2**40, 150) == "plausible"  # 0: never skip


@pytest.mark.parametrize(("mode", "rewind_s"), [("reference", 0.0), ("corrected", 1.0)])
def test_one_odometry_message_far_in_the_future_moves_nothing(mode: str, rewind_s: float) -> None:
    """Issue 41 item 6: one reference message stamped 2^32 s ahead made the last frame
    42,949,672,959 and dropped 200-340 later messages as late. One stamped 68 years ahead
    (a header's int32 seconds hold no more) is skipped and counted; every later message is
    judged, and the verdict is diagnose's. Without episodes (``episode_rewind_s`` 0) the
    glitch's frame was released and every later message dropped as late; with them, the
    glitch and the real stamps after it were split into episodes."""
    from ads_rca.contract import topics
    from ads_rca.live.simulate import StackMessage, stack_stream

    log = crash(*FIRST)
    stream = stack_stream(log, seed=3)
    pose = next(t for t in topics.DATA if t.folder == "pose")
    middle = sorted(log.folder("pose"))[40]
    future = (2**31 - 10) * 1000  # 68 years on: the largest a header's int32 seconds holds
    payload = pose.codec.encode(log.folder("pose")[middle], future, log.frame_ms)
    at = next(m.arrival_s for m in stream.messages if m.stamp_ms == middle and m.folder == "pose")
    stream.messages.append(StackMessage(at + 0.001, "pose", future, payload))
    stream.messages.sort(key=lambda m: m.arrival_s)
    settings = replace(config(), episode_rewind_s=rewind_s)
    run = run_stack(log, make_params(mode), stream, settings, WHOLE_HISTORY, drain_s=30.0)
    assert run.episodes == []
    assert run.feed is not None
    counts = run.feed.sync.counts
    assert (counts.implausible, counts.late) == (1, 0), counts
    assert "1 reference stamps implausibly far ahead skipped" in counts.text()
    [verdict] = run.verdicts
    assert same_verdict(verdict.document, offline(*FIRST, mode).to_json())
    stamps = {r.stamp_ms for r in run.results["controller"]}
    assert stamps == set(log.unique_frames)
