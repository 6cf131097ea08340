"""The floors' incremental reads equal the naive ones: :class:`Slide` returns what computing
every key would (windows sliding, jumping, shrinking, with gaps and a changed tag), and the
stable-sort median and robust sigma pick exactly the plain-Python values."""

from __future__ import annotations

import random
from functools import partial

import numpy as np

from ads_rca.oracles.cache import Slide
from ads_rca.oracles.corrected.floors import median, robust_sigma


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
