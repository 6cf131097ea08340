"""Vectorised geometry shared by the oracles and the synthesiser (numpy, no I/O).

Conventions: CARLA world (left-handed, x forward, y right, z up), angles in degrees at the
interfaces. An ego-frame offset (x, y) at ego yaw θ maps to the world as
``w = anchor + R(θ)·(x, y)`` with ``R(θ) = [[cos θ, −sin θ], [sin θ, cos θ]]``.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


def ego_to_world(offsets_xy: FloatArray, anchor_xy: FloatArray, yaw_deg: float) -> FloatArray:
    """World positions of ego-frame offsets (K, 2) rotated by yaw and added to the anchor.

    ``anchor_xy`` is (2,) or (K, 2) (the reference anchors each step at a different point).
    """
    theta = np.deg2rad(yaw_deg)
    c, s = np.cos(theta), np.sin(theta)
    x, y = offsets_xy[..., 0], offsets_xy[..., 1]
    return np.asarray(anchor_xy, dtype=np.float64) + np.stack((x * c - y * s, x * s + y * c), -1)


def world_to_ego(points_xy: FloatArray, origin_xy: FloatArray, yaw_deg: float) -> FloatArray:
    """Inverse of :func:`ego_to_world`: world points (K, 2) into the ego frame."""
    theta = np.deg2rad(yaw_deg)
    c, s = np.cos(theta), np.sin(theta)
    d = np.asarray(points_xy, dtype=np.float64) - origin_xy
    return np.stack((d[..., 0] * c + d[..., 1] * s, -d[..., 0] * s + d[..., 1] * c), -1)


def axis_aligned_iou(a: FloatArray, b: FloatArray) -> FloatArray:
    """IoU matrix (N, M) of image boxes given as (x1, y1, x2, y2) in any corner order.

    Corners are normalised (min/max of the two points); a zero-area box scores 0 with
    everything. NaN coordinates give NaN.
    """
    a = np.asarray(a, dtype=np.float64).reshape(-1, 4)
    b = np.asarray(b, dtype=np.float64).reshape(-1, 4)
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
    with np.errstate(invalid="ignore", divide="ignore"):
        iou = np.where(union > 0, inter / np.where(union > 0, union, 1.0), 0.0)
    zero_area = (area_a[:, None] <= 0) | (area_b[None, :] <= 0)
    iou = np.where(zero_area, 0.0, iou)
    nan_a = np.asarray(np.isnan(a).any(axis=1))
    nan_b = np.asarray(np.isnan(b).any(axis=1))
    nan = nan_a[:, None] | nan_b[None, :]
    return np.where(nan, np.nan, iou)


def box_corners(
    center_xy: FloatArray, half_extent_xy: FloatArray, yaw_deg: FloatArray
) -> FloatArray:
    """Corners (N, 4, 2) of oriented rectangles, counter-clockwise in x-y."""
    center = np.asarray(center_xy, dtype=np.float64).reshape(-1, 2)
    half = np.asarray(half_extent_xy, dtype=np.float64).reshape(-1, 2)
    theta = np.deg2rad(np.asarray(yaw_deg, dtype=np.float64).reshape(-1))
    c, s = np.cos(theta), np.sin(theta)
    signs = np.array([[1.0, 1.0], [-1.0, 1.0], [-1.0, -1.0], [1.0, -1.0]])
    local = signs[None, :, :] * half[:, None, :]  # (N, 4, 2)
    x = local[..., 0] * c[:, None] - local[..., 1] * s[:, None]
    y = local[..., 0] * s[:, None] + local[..., 1] * c[:, None]
    return center[:, None, :] + np.stack((x, y), -1)
