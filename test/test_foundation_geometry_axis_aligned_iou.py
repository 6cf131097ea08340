"""``axis_aligned_iou`` with its masks applied in place gives, bit for bit, what the
three-``np.where`` form gave (NaN, infinite, zero-area and touching boxes included): the
golden outputs depend on every IoU's last bit."""

from __future__ import annotations

import numpy as np

from ads_rca.foundation.geometry import axis_aligned_iou


def where_form(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ax1, ax2 = np.minimum(a[:, 0], a[:, 2]), np.maximum(a[:, 0], a[:, 2])
    ay1, ay2 = np.minimum(a[:, 1], a[:, 3]), np.maximum(a[:, 1], a[:, 3])
    bx1, bx2 = np.minimum(b[:, 0], b[:, 2]), np.maximum(b[:, 0], b[:, 2])
    by1, by2 = np.minimum(b[:, 1], b[:, 3]), np.maximum(b[:, 1], b[:, 3])
    iw = np.minimum(ax2[:, None], bx2[None, :]) - np.maximum(ax1[:, None], bx1[None, :])
    ih = np.minimum(ay2[:, None], by2[None, :]) - np.maximum(ay1[:, None], by1[None, :])
    inter = np.clip(iw, 0.0, None) * np.clip(ih, 0.0, None)
    area_a = (ax2 - ax1) * (ay2 - ay1)
    area_b = (bx2 - bx1) * (by2 - by1)
    union = area_a[:, None] + area_b[None, :] - inter
    iou = np.where(union > 0, inter / np.where(union > 0, union, 1.0), 0.0)
    iou = np.where((area_a[:, None] <= 0) | (area_b[None, :] <= 0), 0.0, iou)
    nan = np.isnan(a).any(axis=1)[:, None] | np.isnan(b).any(axis=1)[None, :]
    return np.where(nan, np.nan, iou)


def test_the_same_bits_as_the_where_form_on_random_boxes() -> None:
    rng = np.random.default_rng(18)
    with np.errstate(invalid="ignore", divide="ignore"):
        for case in range(3000):
            n, m = rng.integers(0, 30, size=2)
            a, b = rng.random((n, 4)) * 100, rng.random((m, 4)) * 100
            if case % 3 == 0:  # NaN coordinates
                a[rng.random((n, 4)) < 0.1] = np.nan
                b[rng.random((m, 4)) < 0.1] = np.nan
            if case % 4 == 0:  # zero-area boxes
                a[:, 2] = np.where(rng.random(n) < 0.3, a[:, 0], a[:, 2])
                b[:, 3] = np.where(rng.random(m) < 0.3, b[:, 1], b[:, 3])
            if case % 5 == 0:  # touching and identical boxes
                a, b = np.round(a / 10) * 10, np.round(b / 10) * 10
            if case % 7 == 0:  # infinite coordinates
                a[rng.random((n, 4)) < 0.1] = np.inf
                b[rng.random((m, 4)) < 0.1] = -np.inf
            got, want = axis_aligned_iou(a, b), where_form(a, b)
            assert got.shape == want.shape and got.tobytes() == want.tobytes(), case


def test_a_matcher_s_nan_score_is_the_nan_form_with_nan_made_0() -> None:
    """``nan_score=0.0`` (what the Hungarian matcher asks for) gives, bit for bit, the NaN
    form passed through ``np.nan_to_num``: no other IoU is NaN or infinite (the division is
    guarded by union > 0 and an intersection never exceeds either area), and -0.0 from
    touching boxes at a zero coordinate stays -0.0."""
    rng = np.random.default_rng(21)
    with np.errstate(invalid="ignore", divide="ignore"):
        for case in range(2000):
            n, m = rng.integers(0, 15, size=2)
            a, b = rng.random((n, 4)) * 100, rng.random((m, 4)) * 100
            if case % 2 == 0:
                a[rng.random((n, 4)) < 0.1] = np.nan
                b[rng.random((m, 4)) < 0.1] = np.nan
            if case % 3 == 0:  # touching at signed zeros
                a, b = np.round(a / 50) * 50 - 50, -(np.round(b / 50) * 50 - 50)
            if case % 5 == 0:
                a[rng.random((n, 4)) < 0.1] = np.inf
                b[rng.random((m, 4)) < 0.1] = -np.inf
            got = axis_aligned_iou(a, b, nan_score=0.0)
            want = np.nan_to_num(where_form(a, b), nan=0.0)
            assert got.tobytes() == want.tobytes(), case
