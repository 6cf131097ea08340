"""``box_signed_distance`` measures both directions' vertex distances in one call on the
pairs stacked twice: the same bits as two calls (broadcast, NaN and touching boxes
included), since every operation is elementwise."""

from __future__ import annotations

import numpy as np

from ads_rca.foundation.geometry import FloatArray, box_signed_distance

#: The four vertices' signs along each box axis.
_SX = np.array([[1.0], [-1.0], [-1.0], [1.0]])
_SY = np.array([[1.0], [1.0], [-1.0], [-1.0]])


def _vertices_to_box(
    lx: FloatArray,
    ly: FloatArray,
    cos_d: FloatArray,
    sin_d: FloatArray,
    h_vert: FloatArray,
    h_box: FloatArray,
) -> FloatArray:
    """Squared min distance (N,) from the 4 vertices of one box to another box that is
    axis-aligned at the origin (zero for vertices inside): one direction, as the distance
    was computed before it took both at once.

    (lx, ly): the first box's centre in the second's frame; (cos_d, sin_d): its rotation
    there; ``h_vert``, ``h_box``: half extents (N, 2).
    """
    hx, hy = h_vert[:, 0], h_vert[:, 1]
    ax, ay, bx, by = cos_d * hx, sin_d * hx, -sin_d * hy, cos_d * hy
    vx = lx + _SX * ax + _SY * bx
    vy = ly + _SX * ay + _SY * by
    ex = np.maximum(np.abs(vx) - h_box[:, 0], 0.0)
    ey = np.maximum(np.abs(vy) - h_box[:, 1], 0.0)
    out: FloatArray = (ex * ex + ey * ey).min(axis=0)
    return out


def two_calls(
    ca: np.ndarray, ha: np.ndarray, ya: np.ndarray, cb: np.ndarray, hb: np.ndarray, yb: np.ndarray
) -> np.ndarray:
    n = len(ca)
    ha, hb = np.broadcast_to(ha, (n, 2)), np.broadcast_to(hb, (n, 2))
    ta, tb = np.deg2rad(np.broadcast_to(ya, (n,))), np.deg2rad(np.broadcast_to(yb, (n,)))
    cb = np.broadcast_to(cb, (n, 2))
    dx, dy = cb[:, 0] - ca[:, 0], cb[:, 1] - ca[:, 1]
    c_a, s_a, c_b, s_b = np.cos(ta), np.sin(ta), np.cos(tb), np.sin(tb)
    cos_d, sin_d = c_a * c_b + s_a * s_b, s_b * c_a - c_b * s_a
    ax, ay = dx * c_a + dy * s_a, -dx * s_a + dy * c_a
    bx, by = dx * c_b + dy * s_b, -dx * s_b + dy * c_b
    ac, as_ = np.abs(cos_d), np.abs(sin_d)
    hax, hay, hbx, hby = ha[:, 0], ha[:, 1], hb[:, 0], hb[:, 1]
    gap = np.maximum(
        np.maximum(
            np.abs(ax) - hax - hbx * ac - hby * as_, np.abs(ay) - hay - hbx * as_ - hby * ac
        ),
        np.maximum(
            np.abs(bx) - hbx - hax * ac - hay * as_, np.abs(by) - hby - hax * as_ - hay * ac
        ),
    )
    d2 = np.minimum(
        _vertices_to_box(ax, ay, cos_d, sin_d, hb, ha),
        _vertices_to_box(-bx, -by, cos_d, -sin_d, ha, hb),
    )
    return np.where(gap > 0, np.sqrt(d2), gap)


def test_the_same_bits_as_one_call_per_direction() -> None:
    rng = np.random.default_rng(18)
    with np.errstate(invalid="ignore"):
        for case in range(2000):
            n = int(rng.integers(1, 60))
            ca, cb = rng.normal(size=(n, 2)) * 5, rng.normal(size=(n, 2)) * 5
            ha, hb = rng.random((n, 2)) * 3, rng.random((n, 2)) * 3
            ya, yb = rng.normal(size=n) * 90, rng.normal(size=n) * 90
            if case % 3 == 0:  # one box against many, as the partner search asks
                cb, hb, yb = cb[0], np.array([2.0, 1.0]), np.asarray(30.0)
            if case % 4 == 0:  # axis-aligned and touching boxes
                ya, ca = np.round(ya / 90) * 90, np.round(ca)
            if case % 5 == 0:
                ca[rng.random(ca.shape) < 0.1] = np.nan
            got = box_signed_distance(ca, ha, ya, cb, hb, yb)
            want = two_calls(ca, ha, ya, cb, hb, yb)
            assert got.tobytes() == want.tobytes(), case
