"""Collision derived from ground truth: ego box overlapping an actor box.

The whole-log detector must find every synthesised crash at the log's collision frame with
the synthesis label's partner (every scenario × fault, seeds 1 and 2), and nothing in the
crash-free twins and cruise. Hand-built frames pin the numbering (one collision per
contact, a new one after separation, deepest first in a frame), the stream's rules
(stale stamps, a frame without pose) and that hostile values never detect.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from ads_rca.errors import ConfigError
from ads_rca.foundation.geometry import box_signed_distance
from ads_rca.live.collision_detect import Collision, CollisionDetector, detect_collisions
from ads_rca.model import Actors, EgoPose
from ads_rca.synth import FAULTS, SCENARIOS, synthesise_run
from ads_rca.synth.geometry import sat_gap

CRASH_SCENARIOS = [s for s in SCENARIOS if s != "cruise"]
SEEDS = (1, 2)

EGO_HALF = (2.0, 1.0)
CAR_HALF = (2.0, 1.0)


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("scenario", CRASH_SCENARIOS)
@pytest.mark.parametrize("fault", FAULTS)
def test_synthesised_runs(scenario: str, fault: str, seed: int) -> None:
    """Crash: one collision, at the logged frame, with the labelled partner. Twin: none."""
    log, summary = synthesise_run(scenario, fault, seed)
    found = detect_collisions(log)
    if fault == "none":
        assert summary["collision_frame"] == -1
        assert found == []
        return
    assert log.metadata.collision_frame == summary["collision_frame"] > 0
    assert len(found) == 1
    first = found[0]
    assert (first.number, first.frame, first.actor_id) == (
        1,
        log.metadata.collision_frame,
        summary["partner_id"],
    )
    assert first.timestamp_ms == log.metadata.collision_frame * log.frame_ms
    assert first.depth_m > 0.0


def test_same_rule_as_the_synthesiser() -> None:
    """The detector's distance is the synthesiser's separating-axis gap where they overlap
    (so "below zero" is one rule), on 20,000 random box pairs of which many overlap."""
    rng = np.random.default_rng(15)
    n = 20_000
    ca, cb = rng.uniform(-4, 4, (n, 2)), rng.uniform(-4, 4, (n, 2))
    ha, hb = rng.uniform(0.2, 3, (n, 2)), rng.uniform(0.2, 3, (n, 2))
    ya, yb = rng.uniform(-180, 180, n), rng.uniform(-180, 180, n)
    ours = box_signed_distance(ca, ha, ya, cb, hb, yb)
    theirs = sat_gap(ca, np.deg2rad(ya), ha, cb, np.deg2rad(yb), hb)
    overlap = theirs < 0
    assert 0.3 * n < overlap.sum() < 0.9 * n
    np.testing.assert_array_equal(ours < 0, overlap)
    np.testing.assert_allclose(ours[overlap], theirs[overlap], rtol=0, atol=1e-9)


@pytest.mark.parametrize("seed", SEEDS)
def test_cruise_detects_none(seed: int) -> None:
    log, summary = synthesise_run("cruise", "none", seed, frames=400)
    assert summary["collision_frame"] == -1
    assert len(log.frames) == 400
    assert detect_collisions(log) == []


def actors(
    rows: list[tuple[str, float, float, float]],
    half: list[tuple[float, float]] | None = None,
) -> Actors:
    """An actors record: (id, x, y, yaw_deg) rows; the ego first, every box a car's."""
    n = len(rows)
    loc = np.zeros((n, 3))
    rot = np.zeros((n, 3))
    loc[:, 0] = [r[1] for r in rows]
    loc[:, 1] = [r[2] for r in rows]
    rot[:, 2] = [r[3] for r in rows]
    ext = np.full((n, 3), 0.8)
    ext[:, :2] = half if half is not None else [EGO_HALF, *[CAR_HALF] * (n - 1)]
    return Actors(tuple(r[0] for r in rows), loc, rot, ext)


def pose(x: float, y: float = 0.0, yaw: float = 0.0) -> EgoPose:
    return EgoPose(x, y, 0.0, 0.0, 0.0, yaw, 0.0)


def feed(detector: CollisionDetector, gaps: list[float]) -> list[list[Collision]]:
    """Ego at the origin, car "a" ahead with the given edge gaps (m), one frame each."""
    out: list[list[Collision]] = []
    for k, gap in enumerate(gaps, start=1):
        x = EGO_HALF[0] + CAR_HALF[0] + gap
        out.append(detector.update(50 * k, pose(0.0), actors([("ego", 0, 0, 0), ("a", x, 0, 0)])))
    return out


def test_one_contact_is_one_collision_and_separation_starts_a_new_one() -> None:
    detector = CollisionDetector(50)
    per_frame = feed(detector, [1.0, 0.1, 0.0, -0.2, -0.5, -0.3, 0.5, 2.0, -0.1, -0.4])
    assert [len(c) for c in per_frame] == [0, 0, 0, 1, 0, 0, 0, 0, 1, 0]
    assert [(c.number, c.frame, c.timestamp_ms, c.actor_id) for c in detector.collisions] == [
        (1, 4, 200, "a"),
        (2, 9, 450, "a"),
    ]
    assert detector.collisions[0].depth_m == pytest.approx(0.2, abs=1e-12)
    assert detector.ego_id == "ego"  # found by the oracles' ego rule (pose match)
    assert detector.in_contact == frozenset({"a"})


def test_touching_is_not_a_collision() -> None:
    detector = CollisionDetector(50)
    feed(detector, [0.0, 0.0])
    assert detector.collisions == []


def test_simultaneous_contacts_deepest_first() -> None:
    detector = CollisionDetector(50, ego_id="ego")
    frame = actors([("ego", 0, 0, 0), ("far", 3.8, 0, 0), ("deep", 0, -1.5, 90.0)])
    found = detector.update(50, pose(0.0), frame)
    # "deep": a car across the ego's right side, 1.5 m off its centre, reaching 0.5 m past
    # the ego's far side: the SAT depth along the ego's y axis is 1.5 m;
    # "far": 0.2 m into the front.
    assert [(c.number, c.actor_id) for c in found] == [(1, "deep"), (2, "far")]
    assert [c.depth_m for c in found] == pytest.approx([1.5, 0.2], abs=1e-9)


def test_rotated_boxes_use_oriented_geometry() -> None:
    """Centres 3.0 m apart diagonally: axis-aligned boxes would overlap, rotated ones don't."""
    detector = CollisionDetector(50, ego_id="ego")
    d = 3.0 / math.sqrt(2.0)
    frame = actors([("ego", 0, 0, 45.0), ("a", d, -d, 45.0)])  # side by side at 45°
    assert detector.update(50, pose(0.0, 0.0, 45.0), frame) == []
    frame = actors([("ego", 0, 0, 45.0), ("a", 0.6 * d, -0.6 * d, 45.0)])
    assert [c.actor_id for c in detector.update(100, pose(0.0, 0.0, 45.0), frame)] == ["a"]


def test_stale_stamps_are_ignored_and_counted() -> None:
    detector = CollisionDetector(50)
    overlap = actors([("ego", 0, 0, 0), ("a", 3.0, 0, 0)])
    assert len(detector.update(100, pose(0.0), overlap)) == 1
    assert detector.update(100, pose(0.0), overlap) == []
    assert detector.update(50, pose(0.0), overlap) == []
    assert detector.ignored_frames == 2
    assert len(detector.collisions) == 1


def test_frame_without_pose_uses_the_ego_record() -> None:
    detector = CollisionDetector(50, ego_id="ego")
    assert len(detector.update(50, None, actors([("ego", 10, 0, 0), ("a", 13.0, 0, 0)]))) == 1


def test_ego_half_override() -> None:
    """With a 0.5 m ego half length the car 3.5 m ahead is 1 m clear, not 0.5 m deep."""
    frame = actors([("ego", 0, 0, 0), ("a", 3.5, 0, 0)])
    assert len(CollisionDetector(50).update(50, pose(0.0), frame)) == 1
    small = CollisionDetector(50, ego_id="ego", ego_half=np.array([0.5, 1.0]))
    assert small.update(50, pose(0.0), frame) == []


NAN = float("nan")
INF = float("inf")


@pytest.mark.parametrize(
    ("ego_pose", "rows", "half"),
    [
        (pose(NAN), [("ego", 0, 0, 0), ("a", 3.0, 0, 0)], None),
        (pose(0.0, NAN), [("ego", 0, 0, 0), ("a", 3.0, 0, 0)], None),
        (pose(0.0, 0.0, NAN), [("ego", 0, 0, 0), ("a", 3.0, 0, 0)], None),
        (pose(INF), [("ego", 0, 0, 0), ("a", INF, 0, 0)], None),
        (pose(0.0), [("ego", 0, 0, 0), ("a", NAN, 0, 0)], None),
        (pose(0.0), [("ego", 0, 0, 0), ("a", 3.0, 0, NAN)], None),
        (pose(0.0), [("ego", 0, 0, 0), ("a", 3.0, 0, 0)], [EGO_HALF, (NAN, 1.0)]),
        (pose(0.0), [("ego", 0, 0, 0), ("a", 3.0, 0, 0)], [EGO_HALF, (-2.0, 1.0)]),
        (pose(0.0), [("ego", 0, 0, 0), ("a", 3.0, 0, 0)], [EGO_HALF, (INF, 1.0)]),
        (pose(0.0), [("ego", 0, 0, 0), ("a", 3.0, 0, 0)], [(NAN, NAN), CAR_HALF]),
        (pose(0.0), [("ego", 0, 0, 0), ("a", 3.0, 0, 0)], [(-2.0, 1.0), CAR_HALF]),
    ],
)
def test_hostile_values_never_detect(
    ego_pose: EgoPose,
    rows: list[tuple[str, float, float, float]],
    half: list[tuple[float, float]] | None,
) -> None:
    detector = CollisionDetector(50, ego_id="ego")
    assert detector.update(50, ego_pose, actors(rows, half)) == []
    assert detector.collisions == []


def test_unknowable_frame_neither_starts_nor_ends_a_contact() -> None:
    """A NaN glitch inside a contact is not a separation: still one collision."""
    detector = CollisionDetector(50, ego_id="ego")
    overlap = actors([("ego", 0, 0, 0), ("a", 3.0, 0, 0)])
    glitch = actors([("ego", 0, 0, 0), ("a", NAN, 0, 0)])
    detector.update(50, pose(0.0), overlap)
    detector.update(100, pose(0.0), glitch)
    detector.update(150, pose(0.0), actors([("ego", 0, 0, 0)]))  # "a" absent
    detector.update(200, pose(0.0), overlap)
    assert [c.number for c in detector.collisions] == [1]


def test_no_ego_no_detection() -> None:
    """No actor matches the pose and no ego id: the ego box is unknown, nothing detected."""
    detector = CollisionDetector(50)
    assert detector.update(50, pose(100.0), actors([("x", 0, 0, 0), ("a", 3.0, 0, 0)])) == []
    assert detector.update(100, None, None) == []
    assert detector.ego_id is None


def test_bad_period_is_a_config_error() -> None:
    with pytest.raises(ConfigError, match="frame_ms must be positive, got 0"):
        CollisionDetector(0)
