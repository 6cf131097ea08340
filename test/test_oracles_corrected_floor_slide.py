"""The floors' incremental reads equal the naive ones: :class:`Slide` returns what computing
every key would (windows sliding, jumping, shrinking, with gaps and a changed tag), and the
stable-sort median and robust sigma pick exactly the plain-Python values (and the short-list
median numpy's); floor frames read as a range equal those read through the frame set."""

from __future__ import annotations

import math
import random
from functools import partial

import numpy as np

from ads_rca.model import RunLog, RunMetadata, Track
from ads_rca.oracles.base import RunContext
from ads_rca.oracles.cache import Slide
from ads_rca.oracles.corrected.context import corrected_context
from ads_rca.oracles.corrected.floors import (
    _offset_displacement,
    _shared_keys_displacements,
    floor_frames,
    list_median,
    list_robust_sigma,
    median,
    robust_sigma,
)
from ads_rca.params import make_params


def test_a_slide_reads_what_computing_every_key_gives() -> None:
    rng = random.Random(18)
    computed: list[int] = []

    def value(key: int, tag: int) -> tuple[int, int]:
        computed.append(key)
        return key * 7 + tag, tag

    slide: Slide[tuple[int, int]] = Slide()
    start, tag = 0, 0
    for _ in range(3000):
        start += rng.choice((1, 1, 1, 1, 0, 2, 5, -3, 60))
        if rng.random() < 0.05:
            tag = rng.randrange(3)
        keys = [k for k in range(start, start + rng.choice((60, 60, 59, 10, 0))) if k % 11]
        computed.clear()
        got = slide.read(keys, partial(value, tag=tag), tag)
        assert got == [(k * 7 + tag, tag) for k in keys]
        assert len(computed) <= len(keys)


def test_a_slide_computes_only_the_new_key_when_the_window_moves_by_one() -> None:
    computed: list[int] = []

    def value(key: int) -> int:
        computed.append(key)
        return key

    slide: Slide[int] = Slide()
    slide.read(list(range(10, 70)), value)
    computed.clear()
    assert slide.read(list(range(11, 71)), value) == list(range(11, 71))
    assert computed == [70]


def plain_median(values: list[float]) -> float:
    ordered = sorted(values)
    mid = len(ordered) // 2
    return ordered[mid] if len(ordered) % 2 else 0.5 * (ordered[mid - 1] + ordered[mid])


def test_median_and_robust_sigma_are_the_plain_python_readings_bit_for_bit() -> None:
    rng = np.random.default_rng(18)
    for case in range(2000):
        values = rng.normal(size=int(rng.integers(1, 70))) * 10.0 ** rng.integers(-3, 3)
        if case % 3 == 0:
            values = np.round(values, 1)  # ties
        if case % 5 == 0:
            values[rng.random(len(values)) < 0.3] = rng.choice([0.0, -0.0])
        listed = values.tolist()
        assert np.float64(median(listed)).tobytes() == np.float64(plain_median(listed)).tobytes()
        centre = plain_median(listed)
        want = 1.4826 * plain_median([abs(v - centre) for v in listed])
        assert np.float64(robust_sigma(listed)).tobytes() == np.float64(want).tobytes()
        assert robust_sigma(values) == robust_sigma(listed)
        assert np.float64(list_robust_sigma(listed)).tobytes() == np.float64(want).tobytes()


def test_the_short_list_robust_sigma_is_numpys_bit_for_bit_nan_and_infinity_included() -> None:
    # a NaN or an infinity (inf - inf is NaN, which Python's sort places anywhere) goes to
    # numpy; every other list is sorted in plain Python and must give the same bits
    rng = np.random.default_rng(9)
    specials = [0.0, -0.0, math.inf, -math.inf, math.nan, 1e308, -1e308]
    assert list_robust_sigma([]) == 0.0
    for case in range(3000):
        values = np.round(rng.normal(size=int(rng.integers(1, 15))), case % 3).tolist()
        if case % 3 == 0:
            values[int(rng.integers(len(values)))] = specials[case % len(specials)]
        with np.errstate(invalid="ignore"):  # inf - inf in numpy's reading
            got, want = list_robust_sigma(values), robust_sigma(values)
        assert np.float64(got).tobytes() == np.float64(want).tobytes(), values


def test_the_short_list_median_is_numpys_bit_for_bit_nan_included() -> None:
    # ties, signed zeros, infinities and NaN (numpy sorts NaN last; the list reading hands
    # such lists to numpy): the plain-Python sort picks the same bits every time
    rng = np.random.default_rng(8)
    specials = [0.0, -0.0, math.inf, -math.inf, math.nan, 1.5]
    for case in range(3000):
        values = np.round(rng.normal(size=int(rng.integers(1, 15))), case % 3).tolist()
        if case % 4 == 0:
            values[int(rng.integers(len(values)))] = specials[case % len(specials)]
        got, want = list_median(values), median(values)
        assert np.float64(got).tobytes() == np.float64(want).tobytes(), values


def test_floor_frames_of_a_run_without_gaps_are_the_ones_a_set_reads() -> None:
    # every frame_ms from 0 (the range shortcut), then with a gap, a repeated frame and an
    # off-grid frame (each read through the frame set): always the log's frames u with
    # ts - 80 frame_ms <= u < ts - 20 frame_ms (W = 20, L = 60 at 50 ms)
    log = RunLog(metadata=RunMetadata(50, (1.3, 0.0, 1.8), -1, 400), frames=())
    judging = corrected_context(RunContext(log, make_params("corrected")))
    regular = tuple(range(0, 200 * 50, 50))
    for frames in (
        regular,
        regular[:90] + regular[91:],
        regular[:90] + regular[89:],
        (*regular[:90], 90 * 50 + 7, *regular[91:]),
        regular[7:30],
        (25, *regular[1:]),
    ):
        log.frames = frames
        present = set(frames)
        for ts in range(-100, 220 * 50, 25):
            want = [u for u in range(ts - 80 * 50, ts - 20 * 50, 50) if u in present]
            assert floor_frames(judging, ts) == want, (frames[:3], ts)


def test_linked_pairs_with_the_same_keys_give_each_pairs_own_displacement() -> None:
    """Perception's samples take every linked pair at once when all tracks share their keys:
    each actor's value is the pair's own max distance over the shared steps, bit for bit,
    with NaN steps ignored and a pair without a finite distance (all NaN, or an infinite
    one) left out."""
    keys = ("2", "0", "x", "1", "1", "5")  # steps 0, 1, 2 below a window of 3; "1" twice
    rng = np.random.default_rng(7)
    raw_tracks = [Track(keys, rng.normal(size=(6, 3)) * 10) for _ in range(5)]
    on_truth_tracks = [Track(keys, rng.normal(size=(6, 3)) * 10) for _ in range(5)]
    raw_tracks[1].offsets[0, 0] = np.nan  # step 2 of actor b has no distance: its others count
    raw_tracks[2].offsets[:, 1] = np.nan  # no step of c has one: left out
    raw_tracks[3].offsets[3, 0] = np.inf  # d's step 1 is infinitely far: left out
    actors = ["a", "b", "c", "d", "e"]
    got = _shared_keys_displacements(actors, raw_tracks, on_truth_tracks, keys, 3)
    want: dict[str, float] = {}
    for actor, a, b in zip(actors, raw_tracks, on_truth_tracks, strict=True):
        value = _offset_displacement(a, b, 3)
        if math.isfinite(value):
            want[actor] = value
    assert list(got) == list(want) == ["a", "b", "e"]
    assert [np.float64(v).tobytes() for v in got.values()] == [
        np.float64(v).tobytes() for v in want.values()
    ]
    # b by hand: steps 0 ("0", row 1) and 1 (row 3, the first "1"); step 2 is NaN
    d = [
        float(np.hypot(*(raw_tracks[1].offsets[r, :2] - on_truth_tracks[1].offsets[r, :2])))
        for r in (1, 3)
    ]
    assert got["b"] == max(d)
