"""The noise-floor rule (docs/semantics-corrected.md, "Noise floors"): each module's error floor
from the run itself.

Hand-computed floors on a real context (samples given by hand), the floor frames, and
end to end on synthesised crashes at ten times today's noise: the fault the old rules
blamed on perception is found, and with the floors off (``noise_floor_factor`` 0) it is
not, so the floors are what fixes it. Clean runs keep their verdicts
(test_diagnosis_golden_outputs).
"""

from __future__ import annotations

from dataclasses import replace
from functools import cache

import numpy as np
import pytest

from ads_rca.diagnosis.engine import diagnose
from ads_rca.model import RunLog
from ads_rca.oracles.base import RunContext, earliest_ego
from ads_rca.oracles.corrected import SEMANTICS
from ads_rca.oracles.corrected.context import corrected_context
from ads_rca.oracles.corrected.control import control_floors
from ads_rca.oracles.corrected.floors import (
    BASIS_NONE,
    BASIS_OTHERS,
    BASIS_PARTNER,
    actor_floor,
    floor_frames,
    perception_floor,
    robust_sigma,
    step_floor,
)
from ads_rca.params import make_params
from ads_rca.synth import synthesise


@cache
def noisy(scenario: str, fault: str, seed: int, level: float) -> RunLog:
    return synthesise(scenario, fault, seed, level)


def clean_context(**overrides: float) -> tuple[RunContext, str]:
    log = synthesise("lead_braking", "planning", 0)
    ctx = RunContext.create(log, make_params("corrected", overrides))
    judging = corrected_context(ctx)
    partner = judging.partner_id
    assert partner is not None
    return ctx, partner


def test_robust_sigma_and_the_step_floor_by_hand() -> None:
    # median 2, absolute deviations 1 0 0 1 7 -> MAD 1
    assert robust_sigma([1.0, 2.0, 2.0, 3.0, 9.0]) == pytest.approx(1.4826)
    assert robust_sigma([]) == 0.0
    # steps 0, 1, 0, 1, 0, 1: differences ±1, MAD 0 around median... [1,-1,1,-1,1]: med 1
    floor = step_floor([0.0, 1.0, 0.0, 1.0, 0.0, 1.0], 5)
    assert floor.frames == 5
    assert floor.value == pytest.approx(0.0)  # median |d − 1| = 0: three of five are 1
    assert step_floor([0.0, 1.0, 0.0], 5).basis == BASIS_NONE  # two differences: too few
    # a steady offset is no noise: differencing removes it
    assert step_floor([0.4] * 10, 5).value == 0.0


def test_floor_frames_end_one_effect_window_before_ts() -> None:
    ctx, _ = clean_context(noise_floor_s=1.0)
    judging = corrected_context(ctx)
    frame_ms = judging.frame_ms
    ts = 90 * frame_ms
    frames = floor_frames(judging, ts)
    # W = 20 frames (window_s 1 s at 20 Hz), L = 20 frames: frames 50 … 69
    assert frames == [n * frame_ms for n in range(50, 70)]
    assert floor_frames(judging, 10 * frame_ms) == []  # before the run's first frame


def test_the_floor_is_the_others_median_then_the_partners_spread_then_none() -> None:
    ctx, partner = clean_context()
    judging = corrected_context(ctx)
    ts = max(judging.log.frames)

    def others(_judging: object, u: int) -> dict[str, float]:
        # per frame: others 1 and 3 (median 2) or 2 and 6 (median 4); the partner far off
        return {"a": 1.0, "b": 3.0, partner: 50.0} if u % 100 else {"a": 2.0, "b": 6.0}

    floor = actor_floor(judging, ts, others)
    frames = floor_frames(judging, ts)
    assert floor.basis == BASIS_OTHERS and floor.frames == len(frames) == 60
    assert floor.value == pytest.approx(float(np.median([2.0 if u % 100 else 4.0 for u in frames])))

    def alone(_judging: object, u: int) -> dict[str, float]:
        return {
            partner: 5.0 + (0.2 if (u // judging.frame_ms) % 2 else -0.2)
        }  # a bias and a jitter

    floor = actor_floor(judging, ts, alone)
    assert floor.basis == BASIS_PARTNER
    assert floor.value == pytest.approx(1.4826 * 0.2)  # the jitter, not the 5 m bias

    def short(_judging: object, u: int) -> dict[str, float]:
        return {"a": 1.0} if u == floor_frames(judging, ts)[0] else {}

    assert actor_floor(judging, ts, short).basis == BASIS_NONE
    assert actor_floor(judging, ts, short).value == 0.0


def floors_at(level: float) -> tuple[float, float, int]:
    """Perception's and control's lateral floor ten frames before the crash, and the
    control floor's step count (lead_braking, planning fault, seed 0)."""
    log = noisy("lead_braking", "planning", 0, level)
    judging = corrected_context(RunContext.create(log, make_params("corrected")))
    ts = max(log.frames) - 10 * log.frame_ms
    perception = perception_floor(judging, ts)
    assert perception.basis == BASIS_OTHERS and perception.frames >= 55
    _speed, lateral = control_floors(judging, ts)
    return perception.value, lateral.value, lateral.frames


def test_the_floors_measure_the_noise_of_the_run() -> None:
    perception_1, lateral_1, steps = floors_at(1.0)
    perception_10, lateral_10, _ = floors_at(10.0)
    assert steps == 59  # 60 floor frames, 59 differences
    # today's noise: the raw predictions sit about half a metre off those on truth, the controller
    # tracks its plan within millimetres
    assert 0.3 < perception_1 < 1.0 and lateral_1 < 0.01
    assert perception_10 > 4 * perception_1
    assert lateral_10 > 0.05  # 2 sigma over 10 steps: above the fixed 0.3 m


#: Crashes at ten times today's noise whose planning / control fault the fixed thresholds
#: blamed on perception (bench/accuracy.py --noise 10, before the noise-floor rule).
NOISY_CASES = [
    ("lead_braking", "planning", 0, False),
    ("lead_braking", "controller", 0, False),
    ("pedestrian_crossing", "planning", 0, True),
    ("pedestrian_crossing", "controller", 0, True),
]


@pytest.mark.parametrize(
    "case",
    NOISY_CASES,
    ids=["-".join(map(str, c[:3])) + ("-3d" if c[3] else "") for c in NOISY_CASES],
)
def test_under_noise_the_floors_find_the_injected_fault(case: tuple[str, str, int, bool]) -> None:
    scenario, fault, seed, three_d = case
    log = noisy(scenario, fault, seed, 10.0)
    if three_d:  # what a 3-D stack's recording carries
        log = replace(log, bboxes={}, bboxes_gt={}, predictions_with_perception={})
    found = diagnose(log, make_params("corrected"))
    assert found.attribution.primary_root_cause == fault
    assert found.attribution.root_causes == [fault]
    # Without the floors the noise counts as perception failures, which rule 7 now keeps
    # from the blame: perception never misled the planner (it was shown the conflict), and
    # its noise counted only after the controller had failed (issue 40).
    off = diagnose(log, make_params("corrected", {"noise_floor_factor": 0.0}))
    assert "perception" in off.attribution.root_causes
    assert off.attribution.primary_root_cause == fault


def test_floors_are_reported_with_their_basis_and_parameters() -> None:
    log = noisy("lead_braking", "planning", 0, 10.0)
    found = diagnose(log, make_params("corrected"))
    result = found.frames[-1].results["perception"]
    assert result.thresholds["noise_floor_factor"] == 1.5
    assert result.thresholds["noise_floor_s"] == 3.0
    control = found.frames[-15].results["controller"].metrics
    assert control["lateral_floor_basis"] == "steps"
    assert control["lateral_floor_frames"] == 59
    threshold = control["lateral_threshold"]
    assert isinstance(threshold, float) and threshold > 0.3  # ten times the noise raises it
    clean = diagnose(noisy("lead_braking", "planning", 0, 1.0), make_params("corrected"))
    metrics = clean.frames[-15].results["controller"].metrics
    # a straight road: only rounding's curvature (below 1e-12 m) adds to the fixed threshold
    assert metrics["lateral_threshold"] == pytest.approx(0.3, abs=1e-12)
    assert metrics["curve_allowance"] == pytest.approx(0.0, abs=1e-12)


def test_the_corrected_ego_tolerates_a_localisation_error() -> None:
    log = synthesise("cut_in", "none", 0)
    first = min(log.pose)
    pose = log.pose[first]
    log.pose[first] = replace(pose, x=pose.x + 0.8)
    reference = RunContext.create(log, make_params("reference"))
    corrected = RunContext.create(log, make_params("corrected"))
    assert corrected.ego_id == log.metadata.raw["synthesis"]["ego_id"]
    assert earliest_ego(corrected) is None  # the strict 0.5 m rule finds none
    assert SEMANTICS.find_ego(corrected) == corrected.ego_id
    assert reference.ego_id != corrected.ego_id or reference.ego_id is None
