"""Planar geometry of the synthesiser: rotations and the separating-axis gap of boxes.

Everything is vectorised over leading dimensions so a whole frame (all actors, all plan
steps) is one numpy call. Angles are radians here; the log's degrees are converted at the
edges. The CARLA world is left-handed (x forward, y right), but a yaw ψ still maps a body
offset (x, y) to the world as (x cos ψ − y sin ψ, x sin ψ + y cos ψ), exactly as the
format's rotation rule says, so no special handling is needed in 2-D.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


def heading_vector(yaw: FloatArray) -> FloatArray:
    """Unit vectors (..., 2) along yaw (radians)."""
    return np.stack([np.cos(yaw), np.sin(yaw)], axis=-1)


def to_body(points: FloatArray, origin: FloatArray, yaw: float) -> FloatArray:
    """World points (..., 2) into the body frame at ``origin`` with heading ``yaw`` (rad)."""
    c, s = np.cos(yaw), np.sin(yaw)
    d = points - origin
    return np.stack([d[..., 0] * c + d[..., 1] * s, -d[..., 0] * s + d[..., 1] * c], axis=-1)


def to_world(offsets: FloatArray, origin: FloatArray, yaw: float) -> FloatArray:
    """Body offsets (..., 2) at ``origin`` / ``yaw`` (rad) into world points."""
    c, s = np.cos(yaw), np.sin(yaw)
    x, y = offsets[..., 0], offsets[..., 1]
    return np.stack([origin[0] + x * c - y * s, origin[1] + x * s + y * c], axis=-1)


def sat_gap(
    c1: FloatArray,
    yaw1: FloatArray,
    h1: FloatArray,
    c2: FloatArray,
    yaw2: FloatArray,
    h2: FloatArray,
) -> FloatArray:
    """Separating-axis gap between oriented boxes (broadcast over leading dimensions).

    Positive: the largest separation along any of the four box axes (a lower bound of the
    true edge-to-edge distance, so a conservative clearance). Negative: minus the
    penetration depth. Zero: touching.
    """
    d = c2 - c1
    a1 = heading_vector(yaw1)
    a2 = heading_vector(yaw2)
    b1 = np.stack([-a1[..., 1], a1[..., 0]], axis=-1)
    b2 = np.stack([-a2[..., 1], a2[..., 0]], axis=-1)
    axes = (a1, b1, a2, b2)
    best: FloatArray | None = None
    for axis in axes:
        r1 = h1[..., 0] * np.abs(_dot(a1, axis)) + h1[..., 1] * np.abs(_dot(b1, axis))
        r2 = h2[..., 0] * np.abs(_dot(a2, axis)) + h2[..., 1] * np.abs(_dot(b2, axis))
        gap = np.abs(_dot(d, axis)) - r1 - r2
        best = gap if best is None else np.maximum(best, gap)
    assert best is not None
    return best


def _dot(a: FloatArray, b: FloatArray) -> FloatArray:
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1]
