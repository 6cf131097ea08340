"""Frames from header stamps: a synthesised run sent the way a stack does.

Each topic of a synthesised log is stamped at its frame's time plus a per-topic offset (up
to 20 ms either way) and arrives with jitter (reordered across frames); :class:`StampSync`
must give back exactly the log's frames, each with the message of every topic stamped for
it. Then: 2 % of one topic dropped, duplicates, late messages and floods.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from ads_rca.contract.topics import DATA, ODOMETRY
from ads_rca.errors import ConfigError
from ads_rca.live.stamp_sync import StampSync, SyncedFrame, SyncSettings, measure_period
from ads_rca.model import RunLog
from ads_rca.synth import synthesise

#: The topics a synthesised run carries: every data topic but the map perception only an
#: OpenLane-V2 segment has (a stack sends the topics it has; its layouts name them).
INPUTS = tuple(
    topic.key
    for topic in DATA
    if topic.key != ODOMETRY and topic.folder not in ("lanes", "lanes_predicted")
)
TIMEOUT_S = 2.0
#: (topic, stamp_ms, payload, arrival_s); the payload names the log frame it came from.
Message = tuple[str, int, tuple[str, int], float]


@pytest.fixture(scope="module")
def log() -> RunLog:
    return synthesise("cut_in", "perception", 1)


def stack_messages(log: RunLog, seed: int, jitter_s: float = 0.08) -> list[Message]:
    """Every record of the log as a stack would send it, in arrival order."""
    rng = np.random.default_rng(seed)
    offsets = {topic.key: int(rng.integers(-20, 21)) for topic in DATA}
    offsets[ODOMETRY] = 0
    messages: list[Message] = []
    for topic in DATA:
        assert topic.folder is not None
        for stamp in log.folder(topic.folder):
            arrival = stamp / 1000 + float(rng.uniform(0, jitter_s))
            messages.append((topic.key, stamp + offsets[topic.key], (topic.key, stamp), arrival))
    messages.sort(key=lambda m: m[3])
    return messages


def run(
    sync: StampSync[tuple[str, int]], messages: list[Message]
) -> list[tuple[SyncedFrame[tuple[str, int]], float]]:
    """Feed the messages, poll every 10 ms and after the last one; (frame, release time)."""
    out: list[tuple[SyncedFrame[tuple[str, int]], float]] = []
    now = 0.0
    for topic, stamp, payload, arrival in messages:
        while now + 0.01 < arrival:
            now += 0.01
            out.extend((frame, now) for frame in sync.poll(now))
        now = arrival
        out.extend((frame, now) for frame in sync.add(topic, stamp, payload, now))
    end = now + TIMEOUT_S
    out.extend((frame, end) for frame in sync.poll(end))
    return out


def new_sync(period_ms: float | None) -> StampSync[tuple[str, int]]:
    return StampSync(SyncSettings(INPUTS, period_ms=period_ms, input_timeout_s=TIMEOUT_S))


def assert_associated(frame: SyncedFrame[tuple[str, int]]) -> None:
    """Every input of the frame came from the log frame it is stamped for."""
    for topic, payload in frame.inputs.items():
        assert payload == (topic, frame.stamp_ms)


@pytest.mark.parametrize("period_ms", [50.0, None], ids=["timesteps_per_frame", "measured"])
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_jittered_offset_run_gives_exactly_the_logs_frames(
    log: RunLog, period_ms: float | None, seed: int
) -> None:
    messages = stack_messages(log, seed)
    frames = log.unique_frames
    odometry = [m[1] for m in messages if m[0] == ODOMETRY]
    assert odometry != sorted(odometry)  # the arrival order really does reorder frames
    sync = new_sync(period_ms)
    released = [frame for frame, _ in run(sync, messages)]
    assert [f.stamp_ms for f in released] == list(frames)
    assert all(f.complete and f.reason == "complete" for f in released)
    for frame in released:
        assert set(frame.inputs) == {ODOMETRY, *INPUTS}
        assert_associated(frame)
    assert sync.period_ms == 50.0
    assert (sync.counts.late, sync.counts.duplicates, sync.counts.unmatched) == (0, 0, 0)
    assert (sync.held_frames, sync.held_messages) == (0, 0)


@pytest.mark.parametrize("topic", ["perception/detections", "planning/trajectory"])
def test_two_percent_dropped_frames_are_released_incomplete_after_the_timeout(
    log: RunLog, topic: str
) -> None:
    messages = stack_messages(log, 4)
    rng = np.random.default_rng(5)
    mine = [i for i, m in enumerate(messages) if m[0] == topic]
    lost = {int(i) for i in rng.choice(mine, size=round(0.02 * len(mine)), replace=False)}
    assert len(lost) == 2
    lost_frames = {messages[i][2][1] for i in lost}
    arrival = {m[2][1]: m[3] for m in messages if m[0] == ODOMETRY}
    sync = new_sync(50.0)
    released = run(sync, [m for i, m in enumerate(messages) if i not in lost])
    assert [f.stamp_ms for f, _ in released] == list(log.unique_frames)
    for frame, when in released:
        assert_associated(frame)
        if frame.stamp_ms in lost_frames:
            assert (frame.missing, frame.reason) == ((topic,), "timeout")
            assert when >= arrival[frame.stamp_ms] + TIMEOUT_S
            assert set(frame.inputs) == {ODOMETRY, *INPUTS} - {topic}
        else:
            assert frame.complete
    assert sync.counts.incomplete == 2


def test_a_dropped_reference_loses_its_frame_and_its_inputs_count_unmatched(
    log: RunLog,
) -> None:
    messages = stack_messages(log, 7)
    frames = list(log.unique_frames)
    lost = {frames[40], frames[70]}
    kept = [m for m in messages if not (m[0] == ODOMETRY and m[1] in lost)]
    sync = new_sync(50.0)
    released = [frame for frame, _ in run(sync, kept)]
    assert [f.stamp_ms for f in released] == [f for f in frames if f not in lost]
    for frame in released:
        assert_associated(frame)
        assert frame.complete
        after_gap = frame.stamp_ms - 50 in lost
        assert frame.reason == ("timeout" if after_gap else "complete")
    assert sync.counts.unmatched == len(INPUTS) * len(lost)


def test_duplicates_keep_the_first_and_are_counted(log: RunLog) -> None:
    messages = stack_messages(log, 6)
    doubled: list[Message] = []
    for topic, stamp, payload, arrival in messages:
        doubled.append((topic, stamp, payload, arrival))
        if stamp % 200 == 0:  # every fourth frame's messages twice, the copy marked
            doubled.append((topic, stamp, (topic, -1), arrival + 0.001))
    sync = new_sync(50.0)
    released = [frame for frame, _ in run(sync, doubled)]
    assert [f.stamp_ms for f in released] == list(log.unique_frames)
    for frame in released:
        assert_associated(frame)
    # A copy of a message whose frame was already released counts as late, not duplicate.
    assert sync.counts.duplicates + sync.counts.late == len(doubled) - len(messages)
    assert sync.counts.duplicates > 0
    assert sync.counts.unmatched == 0


def test_late_messages_are_dropped_and_counted() -> None:
    sync: StampSync[str] = StampSync(SyncSettings(("a",), period_ms=50.0, measure_stamps=2))
    for i, stamp in enumerate((0, 50, 100)):
        sync.add(ODOMETRY, stamp, f"odom{stamp}", float(i))
    out = sync.add("a", 3, "a3", 3.0) + sync.add("a", 48, "a48", 3.0)
    assert [(f.stamp_ms, f.inputs) for f in out] == [
        (0, {ODOMETRY: "odom0", "a": "a3"}),
        (50, {ODOMETRY: "odom50", "a": "a48"}),
    ]
    assert sync.released_ms == 50
    assert sync.add("a", 52, "late: nearest frame 50 is out", 3.0) == []
    assert sync.add("a", 75, "late: a tie goes to the earlier frame", 3.0) == []
    assert sync.add(ODOMETRY, 50, "late: frame released", 3.0) == []
    assert sync.add(ODOMETRY, 20, "late: older than every held frame", 3.0) == []
    assert sync.counts.late == 4
    [frame] = sync.add("a", 99, "a99", 3.0)
    assert (frame.stamp_ms, frame.inputs, frame.stamps) == (
        100,
        {ODOMETRY: "odom100", "a": "a99"},
        {ODOMETRY: 100, "a": 99},
    )
    assert (sync.counts.duplicates, sync.counts.unmatched, sync.counts.incomplete) == (0, 0, 0)
    assert sync.counts.text() == "4 late messages"


def test_the_nearest_message_is_used_and_the_other_counted_unmatched() -> None:
    sync: StampSync[str] = StampSync(SyncSettings(("a",), period_ms=50.0, measure_stamps=2))
    sync.add("a", 30, "a30", 0.0)
    sync.add("a", 45, "a45", 0.0)
    sync.add("a", 10, "a10 (nearer to 50 than to 0? no: to 0)", 0.0)
    assert sync.add(ODOMETRY, 0, "odom0", 0.0) == []
    out = sync.add(ODOMETRY, 50, "odom50", 0.0)
    assert [(f.stamp_ms, f.stamps) for f in out] == [
        (0, {ODOMETRY: 0, "a": 10}),
        (50, {ODOMETRY: 50, "a": 45}),
    ]
    assert sync.counts.unmatched == 1  # a30: nearest to frame 50, but a45 is nearer


def test_a_gap_waits_for_the_reordered_frame_and_the_first_frames_for_the_period() -> None:
    sync: StampSync[str] = StampSync(SyncSettings(("a",), input_timeout_s=1.0, measure_stamps=4))
    for stamp in (0, 50, 100):
        sync.add("a", stamp + 5, f"a{stamp}", 0.0)
        assert sync.add(ODOMETRY, stamp, f"odom{stamp}", 0.0) == []  # period not known yet
    sync.add("a", 205, "a200", 0.0)
    out = sync.add(ODOMETRY, 200, "odom200", 0.0)
    assert sync.period_ms == 50.0  # median of 50, 50 and 100
    assert [f.stamp_ms for f in out] == [0, 50, 100]  # 200 waits: 150 may still come
    assert sync.add("a", 155, "a150", 0.5) == []
    out = sync.add(ODOMETRY, 150, "odom150", 0.5)
    assert [(f.stamp_ms, f.reason) for f in out] == [(150, "complete"), (200, "complete")]
    sync.add(ODOMETRY, 350, "odom350", 0.6)
    sync.add("a", 355, "a350", 0.6)
    assert sync.poll(1.59) == []
    [frame] = sync.poll(1.6)  # nothing came for 250 and 300: released on its timeout
    assert (frame.stamp_ms, frame.reason, frame.inputs) == (
        350,
        "timeout",
        {ODOMETRY: "odom350", "a": "a350"},
    )


def test_memory_stays_bounded_under_a_flood() -> None:
    limit = 50
    sync: StampSync[int] = StampSync(SyncSettings(("a",), period_ms=50.0, max_pending_frames=limit))
    released: list[SyncedFrame[int]] = []
    for i in range(10_000):
        released += sync.add(ODOMETRY, 1_000_000 + 50 * i, i, 0.0)  # no input: none completes
        released += sync.add("a", 100_000_000 + 7 * i, i, 0.0)  # far from every frame
        assert sync.held_frames <= limit and sync.held_messages <= limit
    want = list(range(1_000_000, 1_000_000 + 50 * (10_000 - limit), 50))
    assert [f.stamp_ms for f in released] == want
    assert all(f.reason == "overflow" and f.missing == ("a",) for f in released)
    assert (sync.counts.overflow, sync.counts.dropped) == (10_000 - limit, 10_000 - limit)
    assert len(sync.flush()) == limit and sync.held_frames == 0


def test_a_flood_of_reference_stamps_makes_at_most_two_frames_a_period() -> None:
    """Issue 43: 4,000 reference messages a second, a quarter of a millisecond apart, each
    made a frame (4,764 flood frames judged). Once the period is known, a stamp less than
    half a period from a held or released frame's is skipped and counted; a duplicate is
    still a duplicate."""
    sync: StampSync[int] = StampSync(SyncSettings(("a",), period_ms=50.0))
    for j in range(4000):
        sync.add(ODOMETRY, 1000 + j // 4, j, 0.0)
    assert sync.held_frames == 40  # 1000, 1025, 1050, ...: at most two a period
    assert sync.counts.crowded == 4000 - 40 * 4 and sync.counts.duplicates == 40 * 3
    assert "reference stamps within half a period of a frame skipped (a flood)" in (
        sync.counts.text()
    )
    measuring: StampSync[int] = StampSync(SyncSettings(("a",)))  # the period not known yet
    for stamp in (0, 1, 2):
        measuring.add(ODOMETRY, stamp, stamp, 0.0)
    assert measuring.held_frames == 3 and measuring.counts.crowded == 0


def test_period_is_the_median_of_positive_differences() -> None:
    assert measure_period([100, 0, 50, 50, 250, 150]) == 50.0  # reordered, a duplicate, a gap
    assert measure_period([7]) is None


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"inputs": (ODOMETRY,)}, "inputs: the reference topic 'ego/odometry' is listed too"),
        ({"inputs": ("a", "a")}, "inputs: a topic is listed twice in ['a', 'a']"),
        ({"sync_slop_ms": 0.0}, "sync_slop_ms must be a positive number, not 0.0"),
        ({"period_ms": float("nan")}, "period_ms must be a positive number, not nan"),
        ({"input_timeout_s": -1.0}, "input_timeout_s must be a positive number, not -1.0"),
        ({"max_pending_frames": 0}, "max_pending_frames must be at least 1, not 0"),
        ({"measure_stamps": 1}, "measure_stamps must be at least 2, not 1"),
    ],
)
def test_bad_settings_name_the_parameter(options: dict[str, object], message: str) -> None:
    arguments: dict[str, object] = {"inputs": ("a",), **options}
    with pytest.raises(ConfigError) as error:
        SyncSettings(**arguments)  # type: ignore[arg-type]
    assert str(error.value) == message


def test_an_unknown_topic_is_refused() -> None:
    sync: StampSync[str] = StampSync(SyncSettings(("a",)))
    with pytest.raises(ConfigError, match="topic 'b' is not an input of the stamp sync"):
        sync.add("b", 0, "", 0.0)


def test_an_input_never_heard_stops_holding_frames_once_given_up_on() -> None:
    """Input b never comes: the first frames wait their timeout, then b is given up on
    and later frames go as soon as a has come (``absent``, b named missing), without a
    timeout each. A message of b brings it back. The node gives an input up at once when
    its topic has no publisher (give_up)."""
    settings = SyncSettings(("a", "b"), period_ms=50.0, measure_stamps=2, input_timeout_s=5.0)
    sync: StampSync[str] = StampSync(settings)
    out: list[Any] = []
    for i, stamp in enumerate(range(0, 500, 50)):  # 10 frames, 0.1 s apart
        now = i * 0.1
        out += sync.add(ODOMETRY, stamp, f"o{stamp}", now) + sync.add("a", stamp, f"a{stamp}", now)
    assert out == []  # b never heard, no timeout yet: held
    out = sync.poll(5.0)  # frame 0 timed out: b given up, every held frame goes now
    assert [f.stamp_ms for f in out] == list(range(0, 500, 50))
    assert out[0].reason == "timeout" and {f.reason for f in out[1:]} == {"absent"}
    assert all(f.missing == ("b",) for f in out) and sync.absent == {"b"}
    released = sync.add(ODOMETRY, 500, "o500", 5.1) + sync.add("a", 500, "a500", 5.1)
    assert [(f.stamp_ms, f.reason) for f in released] == [(500, "absent")]
    sync.add("b", 550, "b550", 5.2)  # b is heard: awaited again
    assert sync.absent == set()
    assert sync.add(ODOMETRY, 550, "o550", 5.2) + sync.add("a", 550, "a550", 5.2) != []
    fresh: StampSync[str] = StampSync(settings)
    fresh.give_up(["b", "not an input"])
    assert fresh.absent == {"b"}
    fresh.add(ODOMETRY, 0, "o0", 0.0)
    fresh.add(ODOMETRY, 50, "o50", 0.0)
    assert [f.stamp_ms for f in fresh.add("a", 0, "a0", 0.0)] == [0]  # no wait for b
    fresh.resume(["b"])  # a publisher of b was found: frames wait for it again
    assert fresh.absent == set() and fresh.add("a", 50, "a50", 0.1) == []


def test_a_stamp_on_the_grid_is_a_whole_number_of_periods_from_the_newest_frame() -> None:
    sync: StampSync[str] = StampSync(SyncSettings(("a",), period_ms=50.0, measure_stamps=2))
    assert not sync.on_grid(0)  # no frame yet: no grid
    for i, stamp in enumerate((1000, 1050)):
        sync.add(ODOMETRY, stamp, f"odom{stamp}", float(i))
    assert [sync.on_grid(s) for s in (1100, 1103, 1150, 1250, 1075, 1090, 1010)] == [
        True,
        True,  # within a tenth of a period
        True,
        True,
        False,  # between two frames
        False,
        False,
    ]
