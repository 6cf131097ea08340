"""Pinhole projection of actors' 3-D boxes into the ego camera's image (``bboxes_gt``).

The camera sits at ``camera_loc`` in the ego body frame (x forward, y right, z up, as the
CARLA world), looks along the ego's x axis, 1920×1080 px, 90° horizontal field of view.
Image u grows with body y (right), v grows downward. Boxes are clipped to the near plane
(edges crossing it contribute their crossing point) and to the image, so an actor right
beside the bumper still gets the visible part of its box.
"""

from __future__ import annotations

import numpy as np

from ads_rca.synth.geometry import FloatArray, to_body

WIDTH, HEIGHT = 1920, 1080
FOCAL = 959.5  # = (WIDTH - 1) / 2 / tan(45°)
CX, CY = 959.5, 539.5
NEAR = 0.2  # m in front of the camera
MIN_SIDE = 2.0  # px: smaller clipped boxes are not "in view"

_SIGNS = np.array(
    [[sx, sy, sz] for sx in (1.0, -1.0) for sy in (1.0, -1.0) for sz in (0.0, 2.0)]
)  # corner = centre_ground + (sx*ex, sy*ey, sz*ez): boxes stand on the ground
_EDGES = np.array(
    [(a, b) for a in range(8) for b in range(a + 1, 8) if np.sum(_SIGNS[a] != _SIGNS[b]) == 1]
)


def project_boxes(
    ego_xy: FloatArray,
    ego_yaw: float,
    camera_loc: tuple[float, float, float],
    xy: FloatArray,
    yaw: FloatArray,
    extent: FloatArray,
) -> tuple[FloatArray, np.ndarray]:
    """Image boxes (N, 4) as (x1, y1, x2, y2) and an in-view mask (N,) for actors on the ground.

    ``xy``/``yaw`` (radians) are world poses, ``extent`` half sizes (N, 3).
    """
    n = xy.shape[0]
    rel_yaw = yaw - ego_yaw
    centre = to_body(xy, ego_xy, ego_yaw)
    c, s = np.cos(rel_yaw)[:, None], np.sin(rel_yaw)[:, None]
    lx = _SIGNS[None, :, 0] * extent[:, None, 0]
    ly = _SIGNS[None, :, 1] * extent[:, None, 1]
    x = centre[:, None, 0] + lx * c - ly * s - camera_loc[0]
    y = centre[:, None, 1] + lx * s + ly * c - camera_loc[1]
    z = _SIGNS[None, :, 2] * extent[:, None, 2] - camera_loc[2]
    corners = np.stack([x, y, z], axis=-1)  # (N, 8, 3) camera frame
    a, b = corners[:, _EDGES[:, 0]], corners[:, _EDGES[:, 1]]
    da, db = a[..., 0] - NEAR, b[..., 0] - NEAR
    crossing = (da * db) < 0.0
    t = np.where(crossing, da / np.where(crossing, da - db, 1.0), 0.0)
    cut = a + t[..., None] * (b - a)
    points = np.concatenate([corners, cut], axis=1)  # (N, 8 + 12, 3)
    valid = np.concatenate([corners[..., 0] >= NEAR, crossing], axis=1)
    depth = np.maximum(points[..., 0], NEAR)
    u = CX + FOCAL * points[..., 1] / depth
    v = CY - FOCAL * points[..., 2] / depth
    big = 1e9
    x1 = np.where(valid, u, big).min(axis=1)
    x2 = np.where(valid, u, -big).max(axis=1)
    y1 = np.where(valid, v, big).min(axis=1)
    y2 = np.where(valid, v, -big).max(axis=1)
    boxes = np.stack(
        [
            np.clip(x1, 0, WIDTH - 1),
            np.clip(y1, 0, HEIGHT - 1),
            np.clip(x2, 0, WIDTH - 1),
            np.clip(y2, 0, HEIGHT - 1),
        ],
        axis=1,
    )
    in_view = (
        valid.any(axis=1)
        & (boxes[:, 2] - boxes[:, 0] >= MIN_SIDE)
        & (boxes[:, 3] - boxes[:, 1] >= MIN_SIDE)
    )
    return boxes.reshape(n, 4), in_view
