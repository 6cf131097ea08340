"""Stack mode's guard on the reference input, in process (issue 43).

A hostile tester blinded stack mode: three odometry messages stamped far ahead, a stream
of NaN poses or a flood on the reference topic made every later real message late, or
thousands of flood frames judged, while /diagnostics stayed OK. The rules
(ads_rca/live/stack_guard.py): the reference topic is locked to its first writer (another
writer's messages counted, skipped); a NaN pose is malformed, never a frame; a forward jump
is confirmed only when the stack's other inputs moved on too; reference stamps closer than
half a period to a frame (a flood) are skipped; and the report is never OK while anything
was refused, an ERROR while the real stream's frames are dropped as late. Over DDS, with a
hostile process: test_ros_stack_hostile_writer.py.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import pytest
from stackgraph import crash, offline, same_verdict
from stacksettings import config

from ads_rca.contract import topics
from ads_rca.live import diagnostics as diag
from ads_rca.live.episodes import ForwardJumps
from ads_rca.live.simulate import LiveRun, StackMessage, StackStream, run_stack, stack_stream
from ads_rca.live.stack_guard import StackGuard, WriterLock, pose_problem, writer_gid
from ads_rca.live.window import WindowSettings
from ads_rca.model import EgoPose
from ads_rca.params import make_params

CASE = ("cut_in", "perception")  # collision at frame 103
WHOLE_HISTORY = WindowSettings(input_timeout_s=1.0, history_frames=400)
REAL, HOSTILE = b"\x01" * 16, b"\x02" * 16
POSE = next(t for t in topics.DATA if t.folder == "pose")

#: Messages to add to the stream: (log, stack stream, the 41st frame's stamp and arrival).
Attack = Callable[[int, float], list[StackMessage]]


def attacked(attack: Attack, writer: bytes | None = REAL) -> tuple[LiveRun, list[str]]:
    """The crash sent as a stack does, with ``attack``'s messages from ``writer`` from the
    41st frame on; the run and what the feed reported as skipped."""
    log = crash(*CASE)
    stream = stack_stream(log, seed=3)
    middle = sorted(log.folder("pose"))[40]
    at = next(m.arrival_s for m in stream.messages if m.stamp_ms == middle and m.folder == "pose")
    extra = attack(middle, at)
    messages = [*stream.messages, *extra]
    messages.sort(key=lambda m: m.arrival_s)
    hostile = {id(m) for m in extra}
    said: list[str] = []
    run = run_stack(
        log,
        make_params("corrected"),
        StackStream(messages, stream.offsets_ms, stream.dropped, stream.collision_s),
        config(),
        WHOLE_HISTORY,
        drain_s=30.0,
        skipped=lambda folder, error: said.append(error),
        writer=lambda m: writer if id(m) in hostile else REAL,
    )
    return run, said


def judged_as_diagnose(run: LiveRun) -> None:
    """The verdict is diagnose's, complete, and every frame of the log judged, no other."""
    log = crash(*CASE)
    [verdict] = run.verdicts
    assert same_verdict(verdict.document, offline(*CASE, "corrected").to_json())
    assert verdict.document["live"]["complete"] is True, verdict.document["live"]
    assert {r.stamp_ms for r in run.results["controller"]} == set(log.unique_frames)
    assert run.episodes == []


def pose_at(stamp: int, pose: EgoPose | None = None) -> bytes:
    log = crash(*CASE)
    return POSE.codec.encode(pose or log.folder("pose")[50], stamp, log.frame_ms)


def future(middle: int, at: float) -> list[StackMessage]:
    """A clock glitch: three odometry messages stamped with the wall clock, 50 ms apart."""
    wall = int(time.time() * 1000)
    return [
        StackMessage(at + 0.001 * (k + 1), "pose", wall + 50 * k, pose_at(wall + 50 * k))
        for k in range(3)
    ]


def nan_poses(middle: int, at: float) -> list[StackMessage]:
    """200 NaN poses stamped between the stack's frames."""
    nan = EgoPose(*[float("nan")] * 7)
    return [
        StackMessage(at + 0.001 + 0.05 * k, "pose", s, pose_at(s, nan))
        for k, s in enumerate(middle + 25 + 50 * k for k in range(200))
    ]


def flood(middle: int, at: float) -> list[StackMessage]:
    """4,000 messages in a second, stamped a quarter of a millisecond apart."""
    return [
        StackMessage(at + 0.00025 * j, "pose", middle + 1 + j // 4, pose_at(middle + 1 + j // 4))
        for j in range(4000)
    ]


@pytest.mark.parametrize("attack", [future, nan_poses, flood])
def test_a_second_writer_on_the_reference_topic_is_ignored(attack: Attack) -> None:
    """Before: three wall-clock stamps split the run into episodes, NaN poses became frames,
    the flood 1,000 frames (each case: a verdict other than diagnose's)."""
    run, _ = attacked(attack, HOSTILE)
    judged_as_diagnose(run)
    assert run.feed is not None
    guard = run.feed.guard
    assert guard.lock.ignored == {HOSTILE: len(attack(0, 0.0))}
    level, line, values = guard.report(100.0)
    assert level == diag.WARN
    assert line == f"second publisher on pose: {len(attack(0, 0.0))} messages ignored"
    assert values["ignored_other_writers"] == len(attack(0, 0.0))


def test_a_clock_glitch_of_the_odometry_alone_moves_nothing() -> None:
    """The stack's own writer stamps three odometry messages with the wall clock (its other
    inputs stay on simulated time): before, the third confirmed the jump, the real stamps
    after it began a new episode and the verdict was not diagnose's. Now the jump is not
    confirmed: no other input moved on."""
    run, _ = attacked(future)
    judged_as_diagnose(run)
    assert run.feed is not None
    assert run.feed.guard.implausible == run.feed.sync.counts.implausible == 3
    level, line, _ = run.feed.guard.report(100.0)
    assert (level, line) == (diag.WARN, "3 pose stamps implausibly far ahead skipped")


def test_nan_poses_are_malformed_never_frames() -> None:
    run, said = attacked(nan_poses)
    judged_as_diagnose(run)
    assert run.feed is not None
    assert run.feed.guard.malformed == 200
    assert said[0] == (
        "pose not finite (x, y, z, roll, pitch, yaw, speed): it cannot define a frame; skipped"
    )
    assert run.feed.guard.report(100.0)[1] == "200 malformed pose messages skipped (NaN/inf pose)"


def test_a_flood_from_the_stack_s_own_writer_does_not_starve_the_real_frames() -> None:
    """At most two frames a period: every real frame judged, the flood's skipped but for
    one stamp between two real frames (judged incomplete, named), nothing dropped late."""
    run, _ = attacked(flood)
    assert run.feed is not None
    counts = run.feed.sync.counts
    assert counts.crowded > 3000 and counts.late == 0, counts
    log = crash(*CASE)
    judged = {r.stamp_ms for r in run.results["controller"]}
    assert judged >= set(log.unique_frames)
    extra = judged - set(log.unique_frames)
    assert len(extra) <= 1000 // 50 * 2, sorted(extra)  # at most one between two real ones
    [verdict] = run.verdicts
    want = offline(*CASE, "corrected").to_json()
    assert verdict.document["primary_root_cause"] == want["primary_root_cause"]
    assert run.feed.guard.crowded == counts.crowded


def test_the_writer_lock() -> None:
    lock = WriterLock()
    assert lock.accept(None)  # an rmw without GIDs: nothing to tell writers apart by
    assert lock.accept(REAL) and lock.writer == REAL
    assert not lock.accept(HOSTILE) and not lock.accept(HOSTILE)
    assert lock.ignored == {HOSTILE: 2} and lock.total_ignored == 2
    lock.release()  # the stack's process left the graph: the next writer is taken
    assert lock.accept(HOSTILE) and not lock.accept(REAL)
    info = {"publisher_gid": {"implementation_identifier": "rmw_fastrtps_cpp", "data": REAL}}
    assert writer_gid(info) == REAL
    assert writer_gid(None) is None and writer_gid({"publisher_gid": None}) is None


def test_the_report_is_never_ok_while_refusing() -> None:
    guard = StackGuard("/carla/ego_vehicle/odometry")
    assert guard.report(0.0) == (diag.OK, "", guard.report(0.0)[2])
    guard.count_late(2, 5, now=10.0)
    level, line, values = guard.report(11.0)
    assert level == diag.ERROR  # the real stream's frames are being lost now
    assert line == (
        "2 /carla/ego_vehicle/odometry messages dropped as late (their frames not judged); "
        "5 input messages dropped as late"
    )
    assert (values["late_reference"], values["late_inputs"]) == (2, 5)
    assert guard.report(16.0)[0] == diag.WARN  # none for 5 s: said, no longer an error
    guard.lock.accept(REAL)
    for writer in (HOSTILE, b"\x03" * 16):
        guard.lock.accept(writer)
    assert (
        guard.lines()[0] == "2 other publishers on /carla/ego_vehicle/odometry: 2 messages ignored"
    )
    assert pose_problem({"x": 1.0, "yaw": float("inf")}) is not None
    assert pose_problem({"x": 1.0}) is None


def test_a_forward_jump_needs_the_other_inputs_to_confirm_it() -> None:
    jumps = ForwardJumps(jump_ms=10_000.0, corroborate=True)
    assert [jumps.check(s, 200) for s in (60_200, 60_250, 60_300)] == ["skipped"] * 3
    jumps.other(150, 200)  # an input on the old clock: nothing
    assert jumps.check(60_350, 200) == "skipped"
    jumps.other(60_320, 200)  # the stack's other inputs moved on too: a real jump
    assert jumps.check(60_400, 200) == "confirmed"
    assert (jumps.skipped, jumps.confirmed) == (4, 1)
