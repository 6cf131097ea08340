"""The partner view's per-frame shortcuts give what the plain computation gives, bit for bit.

The `corrected` oracles build a partner view every frame, where numpy's per-call cost
dominates, so the view takes shortcuts: the distance core computes both boxes' (and both
directions') quantities as rows of one array; a pair of series given twice is measured once;
a frame's real series takes the boxes the previous frame's series already read; c_gt is
measured with the frames of the horizon after it; plans with the same keys share one layout.
Each is pinned here against a plain, one-at-a-time transcription or a fresh computation.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ads_rca.foundation.geometry import box_signed_distance
from ads_rca.model import EgoPose, Plan, RunLog
from ads_rca.oracles.base import RunContext
from ads_rca.oracles.corrected.boxes import (
    PlanData,
    Series,
    all_steps,
    build_plan,
    build_plans,
    key_steps,
)
from ads_rca.oracles.corrected.clearance import (
    Clearance,
    pair_clearances,
    partner_view,
    path_length,
    path_lengths,
)
from ads_rca.oracles.corrected.context import corrected_context
from ads_rca.params import make_params
from ads_rca.synth import synthesise

PARAMS = make_params("corrected")


def one_pair(
    ca: list[float], ha: list[float], ya: float, cb: list[float], hb: list[float], yb: float
) -> float:
    """The signed distance of one pair written out plainly (separating axes for the overlap,
    the nearest vertex of either box to the other when apart), in the core's operation order;
    maxima and minima are numpy's (the second of two equal zeros, NaN kept)."""
    ta, tb = np.deg2rad(ya), np.deg2rad(yb)
    c_a, s_a, c_b, s_b = np.cos(ta), np.sin(ta), np.cos(tb), np.sin(tb)
    dx, dy = cb[0] - ca[0], cb[1] - ca[1]
    cos_d, sin_d = c_a * c_b + s_a * s_b, s_b * c_a - c_b * s_a
    ax, ay = dx * c_a + dy * s_a, -dx * s_a + dy * c_a
    bx, by = dx * c_b + dy * s_b, -dx * s_b + dy * c_b
    ac, as_ = abs(cos_d), abs(sin_d)
    g1 = abs(ax) - ha[0] - hb[0] * ac - hb[1] * as_
    g2 = abs(ay) - ha[1] - hb[0] * as_ - hb[1] * ac
    g3 = abs(bx) - hb[0] - ha[0] * ac - ha[1] * as_
    g4 = abs(by) - hb[1] - ha[0] * as_ - ha[1] * ac
    gap = np.maximum(np.maximum(g1, g2), np.maximum(g3, g4))
    if not gap > 0:
        return float(gap)

    def nearest(
        lx: float, ly: float, cos: float, sin: float, hv: list[float], hbox: list[float]
    ) -> float:
        best = np.inf
        for sx, sy in ((1.0, 1.0), (-1.0, 1.0), (-1.0, -1.0), (1.0, -1.0)):
            vx = lx + sx * (cos * hv[0]) + sy * (-sin * hv[1])
            vy = ly + sx * (sin * hv[0]) + sy * (cos * hv[1])
            ex = np.maximum(abs(vx) - hbox[0], 0.0)
            ey = np.maximum(abs(vy) - hbox[1], 0.0)
            best = np.minimum(best, ex * ex + ey * ey)
        return float(best)

    to_b = nearest(ax, ay, cos_d, sin_d, hb, ha)  # B's vertices in A's frame
    to_a = nearest(-bx, -by, cos_d, -sin_d, ha, hb)  # A's in B's
    return float(np.sqrt(np.minimum(to_b, to_a)))


def test_the_distance_core_gives_each_pair_what_one_pair_at_a_time_gives() -> None:
    rng = np.random.default_rng(7)
    for case in range(300):
        n = int(rng.integers(1, 25))
        ca, cb = rng.normal(size=(n, 2)) * 4, rng.normal(size=(n, 2)) * 4
        ha, hb = rng.random((n, 2)) * 3, rng.random((n, 2)) * 3
        ya, yb = rng.normal(size=n) * 90, rng.normal(size=n) * 90
        if case % 3 == 0:  # axis-aligned boxes on a grid: touching and overlapping ones
            ca, cb, ya, yb = (
                np.round(ca),
                np.round(cb),
                np.round(ya / 90) * 90,
                np.round(yb / 90) * 90,
            )
        got = box_signed_distance(ca, ha, ya, cb, hb, yb)
        for i in range(n):
            want = one_pair(list(ca[i]), list(ha[i]), ya[i], list(cb[i]), list(hb[i]), yb[i])
            assert got[i] == want or (np.isnan(got[i]) and np.isnan(want)), (case, i)
            assert np.signbit(got[i]) == np.signbit(want), (case, i)  # -0.0 stays -0.0


def test_a_pair_given_twice_is_measured_once_with_the_clearance_of_each() -> None:
    rng = np.random.default_rng(3)
    w = 6
    ego = Series(rng.normal(size=(w + 1, 2)), rng.normal(size=w + 1) * 40, np.array([2.0, 1.0]))
    other = Series(
        rng.normal(size=(w + 1, 2)) + 3.0, rng.normal(size=w + 1) * 40, np.array([1.5, 0.8])
    )
    other.center[2] = np.nan  # an index without a box is skipped
    twice = pair_clearances([(ego, other), (ego, None), (ego, other)], w)
    (alone,) = pair_clearances([(ego, other)], w)
    for c in (twice[0], twice[2]):
        assert (c.value, c.index) == (alone.value, alone.index)
        assert c.per_index.tobytes() == alone.per_index.tobytes()
    assert twice[1].index == -1 and np.isnan(twice[1].value)
    # the measured distances are the plain ones, index by index (index 0 is never measured)
    plain = [
        one_pair(
            list(ego.center[i]),
            [2.0, 1.0],
            ego.yaw[i],
            list(other.center[i]),
            [1.5, 0.8],
            other.yaw[i],
        )
        for i in range(1, w + 1)
    ]
    assert np.array_equal(alone.per_index[1:], plain, equal_nan=True)
    assert np.isnan(alone.per_index[0])


def test_a_real_series_built_from_the_previous_frame_is_the_one_read_afresh() -> None:
    log = synthesise("cut_in", "prediction", 1)
    frames = sorted(log.actors)
    partner = log.metadata.raw["synthesis"]["partner_id"]
    # The partner leaves some frames' actors files, and some frames have no file at all.
    gone = set(frames[20:60:7])
    actors = {}
    for n, ts in enumerate(frames):
        if n % 11 == 3:
            continue
        frame = log.actors[ts]
        if ts in gone:
            keep = [r for r, a in enumerate(frame.ids) if a != partner]
            frame = replace(
                frame,
                ids=tuple(frame.ids[r] for r in keep),
                location=frame.location[keep],
                rotation=frame.rotation[keep],
                extent=frame.extent[keep],
            )
        actors[ts] = frame
    holed: RunLog = replace(log, actors=actors)
    judging = corrected_context(RunContext.create(holed, PARAMS))
    holes = 0
    for ts in frames:  # in order, as diagnose and the live monitors ask
        got = judging.real_series(partner, ts)
        fresh = corrected_context(RunContext.create(holed, PARAMS)).real_series(partner, ts)
        assert got is not None and fresh is not None
        assert got.center.tobytes() == fresh.center.tobytes(), ts
        assert got.yaw.tobytes() == fresh.yaw.tobytes(), ts
        holes += bool(np.isnan(got.yaw).any())
    assert holes > 0  # the series did have frames without the partner


def test_plans_with_the_same_keys_keep_their_own_points_and_headings() -> None:
    keys = ("3", "0", "x", "1", "1", "2", "5")
    pose = EgoPose(0.0, 0.0, 0.0, 0.0, 0.0, 30.0, 0.0)
    half = np.array([2.0, 1.0])
    first = build_plan(Plan(keys, np.arange(14.0).reshape(7, 2), np.arange(7.0)), pose, half, 4)
    second = build_plan(
        Plan(keys, -(np.arange(14.0).reshape(7, 2) ** 2), np.arange(7.0) + 10), pose, half, 4
    )
    assert first is not None and second is not None
    # steps 0, 1, 2, 3, 5 in order; the repeated "1" keeps its first row; "x" is no step
    assert first.steps.tolist() == second.steps.tolist() == [0, 1, 2, 3, 5]
    assert first.xy[:, 0].tolist() == [2.0, 6.0, 10.0, 0.0, 12.0]
    assert second.xy[:, 0].tolist() == [-4.0, -36.0, -100.0, -0.0, -144.0]
    assert first.speed_at.tolist()[:4] == [1.0, 3.0, 5.0, 0.0] and np.isnan(first.speed_at[4])
    assert second.speed_at.tolist()[:4] == [11.0, 13.0, 15.0, 10.0]
    # step 0's heading is the pose's; step 1's is along step 2 − step 0:
    # (10, 11) − (2, 3) = (8, 8), and (−100, −121) − (−4, −9) = (−96, −112)
    assert first.boxes.yaw[0] == second.boxes.yaw[0] == 30.0
    assert first.boxes.yaw[1] == np.rad2deg(np.arctan2(8.0, 8.0))
    assert second.boxes.yaw[1] == np.rad2deg(np.arctan2(-112.0, -96.0))


def test_a_frame_that_arrives_after_the_previous_series_is_read_then() -> None:
    log = synthesise("cut_in", "prediction", 1)
    frames = sorted(log.actors)
    partner = log.metadata.raw["synthesis"]["partner_id"]
    late = frames[30]  # its actors file arrives after frame 29's series was built
    held = {ts: frame for ts, frame in log.actors.items() if ts != late}
    growing: RunLog = replace(log, actors=held)
    judging = corrected_context(RunContext.create(growing, PARAMS))
    before = judging.real_series(partner, frames[29])
    assert before is not None and np.isnan(before.yaw[1])
    held[late] = log.actors[late]
    after = judging.real_series(partner, frames[30])
    fresh = corrected_context(RunContext.create(growing, PARAMS)).real_series(partner, late)
    assert after is not None and fresh is not None and not np.isnan(after.yaw[0])
    assert after.center.tobytes() == fresh.center.tobytes()
    assert after.yaw.tobytes() == fresh.yaw.tobytes()


def clearance_bits(c: Clearance) -> tuple[bytes, int, bytes]:
    return np.float64(c.value).tobytes(), c.index, c.per_index.tobytes()


def test_c_gt_measured_with_the_frames_after_it_is_c_gt_measured_alone() -> None:
    log = synthesise("cut_in", "prediction", 1)
    frames = sorted(set(log.frames))
    judging = corrected_context(RunContext.create(log, PARAMS))
    partner = judging.partner_id
    assert partner is not None
    for ts in frames[:: 1 if len(frames) < 400 else 2] + frames[:40][::-1]:
        view = partner_view(judging, ts)
        plan = judging.plan(ts)
        if plan is None or view.real is None:
            continue
        (alone,) = pair_clearances([(plan.boxes, view.real)], judging.window)
        assert clearance_bits(view.c_gt) == clearance_bits(alone), ts


def test_a_frame_whose_real_boxes_grew_since_its_batch_is_measured_afresh() -> None:
    log = synthesise("cut_in", "prediction", 1)
    frames = sorted(set(log.frames))
    w = max(int(PARAMS.prediction_window), 1)
    ts, nxt, late = frames[40], frames[41], frames[41 + w]  # late: nxt's last horizon index
    held = {t: frame for t, frame in log.actors.items() if t != late}
    growing: RunLog = replace(log, actors=held)
    judging = corrected_context(RunContext.create(growing, PARAMS))
    partner_view(judging, ts)  # measures nxt's c_gt too, without the late frame
    held[late] = log.actors[late]
    got = partner_view(judging, nxt)
    fresh = partner_view(corrected_context(RunContext.create(growing, PARAMS)), nxt)
    assert np.isfinite(got.c_gt.per_index[w])  # the late frame is measured
    assert clearance_bits(got.c_gt) == clearance_bits(fresh.c_gt)


def test_a_later_plan_with_a_key_that_is_no_step_is_reported_when_its_frame_is_judged() -> None:
    """c_gt's batch does not build that plan early: the report keeps its place in the run's
    problems (after those of the frames before it)."""
    log = synthesise("cut_in", "prediction", 1)
    frames = sorted(set(log.frames))
    ts, later = frames[40], frames[43]
    plan = log.waypoints[later]
    odd = Plan((*plan.keys[:-1], "x"), plan.xy, plan.speed)
    ctx = RunContext.create(replace(log, waypoints={**log.waypoints, later: odd}), PARAMS)
    judging = corrected_context(ctx)
    partner_view(judging, ts)
    assert not [p for p in ctx.problems if "non-integer" in p.issue]
    partner_view(judging, later)
    assert [p.timestamp_ms for p in ctx.problems if "non-integer" in p.issue] == [later]


def test_a_frame_takes_its_batch_real_boxes_only_while_it_reads_the_same_records() -> None:
    """The batch's real boxes at a later frame stand in for the frame's own read while every
    actors record they were read from is the one there now; a record replaced since (a live
    window reading a frame again) is read afresh."""
    log = synthesise("cut_in", "prediction", 1)
    frames = sorted(set(log.frames))
    w = max(int(PARAMS.prediction_window), 1)
    ts, nxt, moved = frames[40], frames[41], frames[41 + w]  # moved: nxt's last index
    held = dict(log.actors)
    live: RunLog = replace(log, actors=held)
    judging = corrected_context(RunContext.create(live, PARAMS))
    partner = judging.partner_id
    assert partner is not None
    partner_view(judging, ts)  # measures nxt's real boxes and c_gt too
    same = partner_view(judging, nxt)
    again = partner_view(corrected_context(RunContext.create(live, PARAMS)), nxt)
    assert same.real is not None and again.real is not None
    assert same.real.center.tobytes() == again.real.center.tobytes()
    assert clearance_bits(same.c_gt) == clearance_bits(again.c_gt)
    # the same again, with the partner 1 m further along x at the moved frame
    judging = corrected_context(RunContext.create(live, PARAMS))
    partner_view(judging, ts)
    old = held[moved]
    row = old.index[partner]
    location = old.location.copy()
    location[row, 0] += 1.0
    held[moved] = replace(old, location=location)
    got = partner_view(judging, nxt)
    fresh = partner_view(corrected_context(RunContext.create(live, PARAMS)), nxt)
    assert got.real is not None and fresh.real is not None
    assert got.real.center[w, 0] == old.location[row, 0] + 1.0
    assert got.real.center.tobytes() == fresh.real.center.tobytes()
    assert clearance_bits(got.c_gt) == clearance_bits(fresh.c_gt)


def plan_bits(p: PlanData | None) -> object:
    if p is None:
        return None
    arrays = (p.steps, p.xy, p.speed, p.boxes.center, p.boxes.yaw, p.boxes.half, p.speed_at)
    return tuple(a.tobytes() for a in arrays), p.rows


def test_keys_are_all_steps_exactly_when_each_reads_as_an_integer() -> None:
    # the memoised answer is the array test's, asked again (the memo) or not
    for keys in [("0", "1", "2"), ("2", "0"), ("0", "x"), ("1.5",), (), ("0", "-1"), ("0", "1")]:
        want = not (key_steps(keys) < 0).any()
        assert all_steps(keys) is want and all_steps(keys) is want, keys
    assert all_steps(("0", "1")) and not all_steps(("0", "x")) and not all_steps(("0", "-1"))


def test_plans_built_together_are_each_plan_built_alone() -> None:
    """Plans with the same keys are built as rows of one array: bit for bit each plan's own
    build, with the pose's yaw at step 0 (or where the first heading is too short), short
    steps keeping the previous heading, and plans with other keys built alone."""
    rng = np.random.default_rng(3)
    half = np.array([2.0, 1.0])
    for keys in [("0", "1", "2", "3", "4", "5", "6"), ("3", "1", "x", "2", "1", "7", "4")]:
        plans, poses = [], []
        for n in range(6):
            xy = np.cumsum(rng.normal(size=(7, 2)), axis=0)
            if n == 1:
                xy[2] = xy[0]  # a heading from two equal points is too short
            if n == 2:
                xy[:] = xy[0]  # no heading anywhere: the pose's throughout
            plans.append(Plan(keys, xy, rng.uniform(0, 10, 7)))
            poses.append(EgoPose(0.0, 0.0, 0.0, 0.0, 0.0, float(rng.uniform(-180, 180)), 0.0))
        for window in (3, 5, 9):
            together = build_plans(plans, poses, half, window)
            alone = [
                build_plan(p, pose, half, window) for p, pose in zip(plans, poses, strict=True)
            ]
            assert [plan_bits(p) for p in together] == [plan_bits(p) for p in alone]
    mixed = [plans[0], Plan(("0", "2", "1", "3", "4", "5", "6"), plans[1].xy, plans[1].speed)]
    together = build_plans(mixed, poses[:2], half, 5)
    alone = [build_plan(p, pose, half, 5) for p, pose in zip(mixed, poses[:2], strict=True)]
    assert [plan_bits(p) for p in together] == [plan_bits(p) for p in alone]


def test_path_lengths_together_are_each_series_path_length() -> None:
    """The batch's path lengths are each series' own, bit for bit (sums of 1 to 40 steps,
    past numpy's 8-way blocks), and a series missing a box is left to path_length."""
    rng = np.random.default_rng(5)
    for points in (2, 3, 9, 11, 17, 31, 41):
        series = [
            Series(
                np.cumsum(rng.normal(size=(points, 2)) * 7.0, axis=0),
                rng.normal(size=points),
                np.ones(2),
            )
            for _ in range(6)
        ]
        holed = Series(series[2].center.copy(), series[2].yaw.copy(), np.ones(2))
        holed.yaw[points // 2] = np.nan
        series[2] = holed
        got = path_lengths(series)
        assert got[2] is None
        for n in (0, 1, 3, 4, 5):
            assert np.float64(got[n]).tobytes() == np.float64(path_length(series[n])).tobytes()
    # two steps by hand: (0,0) -> (3,4) -> (3,10) is 5 + 6
    steps = Series(np.array([[0.0, 0.0], [3.0, 4.0], [3.0, 10.0]]), np.zeros(3), np.ones(2))
    assert path_lengths([steps, steps]) == [11.0, 11.0]


def series_bits(s: Series | None) -> object:
    return None if s is None else (s.center.tobytes(), s.yaw.tobytes(), s.half.tobytes())


def test_a_run_of_real_series_read_at_once_is_the_chain_of_previous_frames() -> None:
    """The batch's real series at ts + frame_ms, ts + 2·frame_ms, … are read at once: bit for
    bit what building each from the one before gives, with frames missing from the log (read as
    absent, and read again by each later series: one arriving after ts's series was built
    is taken) and a state whose yaw is NaN."""
    log = synthesise("cut_in", "prediction", 1)
    frames = sorted(log.actors)
    partner = log.metadata.raw["synthesis"]["partner_id"]
    held = {t: f for t, f in log.actors.items() if t not in (frames[33], frames[45])}
    odd = held[frames[38]]
    rotation = odd.rotation.copy()
    rotation[odd.index[partner], 2] = np.nan
    held[frames[38]] = replace(odd, rotation=rotation)
    holed: RunLog = replace(log, actors=held)
    judging = corrected_context(RunContext.create(holed, PARAMS))
    w = judging.window
    for ts in (frames[28], frames[30], frames[36]):
        real = judging.real_series(partner, ts)
        assert real is not None
        if ts == frames[30]:  # frame 33 arrives after ts's series was read
            held[frames[33]] = log.actors[frames[33]]
        run = judging.real_series_run(partner, ts, real, w)
        chain: list[Series | None] = []
        prev: Series | None = real
        for k in range(1, w + 1):
            prev = judging.real_series_after(partner, ts + k * judging.frame_ms, prev)
            chain.append(prev)
        assert [series_bits(s) for s in run] == [series_bits(s) for s in chain]
    assert any(np.isnan(s.yaw).any() for s in run)  # the holes are in the run
