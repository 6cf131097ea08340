"""Vectorised geometry shared by the oracles and the synthesiser (numpy, no I/O).

Conventions: CARLA world (left-handed, x forward, y right, z up), angles in degrees at the
interfaces. An ego-frame offset (x, y) at ego yaw θ maps to the world as
``w = anchor + R(θ)·(x, y)`` with ``R(θ) = [[cos θ, −sin θ], [sin θ, cos θ]]``.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


def ego_to_world(
    offsets_xy: FloatArray, anchor_xy: FloatArray, yaw_deg: float | FloatArray
) -> FloatArray:
    """World positions of ego-frame offsets (K, 2) rotated by yaw and added to the anchor.

    ``anchor_xy`` is (2,) or (K, 2) (the reference anchors each step at a different point);
    ``yaw_deg`` a scalar or one yaw per row (K,).
    """
    theta = np.deg2rad(yaw_deg)
    c, s = np.cos(theta), np.sin(theta)
    x, y = offsets_xy[..., 0], offsets_xy[..., 1]
    world: FloatArray = np.asarray(anchor_xy, dtype=np.float64) + np.stack(
        (x * c - y * s, x * s + y * c), -1
    )
    return world


def world_to_ego(
    points_xy: FloatArray, origin_xy: FloatArray, yaw_deg: float | FloatArray
) -> FloatArray:
    """Inverse of :func:`ego_to_world`: world points (K, 2) into the ego frame (origin (2,)
    or (K, 2), yaw a scalar or (K,))."""
    theta = np.deg2rad(yaw_deg)
    c, s = np.cos(theta), np.sin(theta)
    d = np.asarray(points_xy, dtype=np.float64) - origin_xy
    return np.stack((d[..., 0] * c + d[..., 1] * s, -d[..., 0] * s + d[..., 1] * c), -1)


def axis_aligned_iou(a: FloatArray, b: FloatArray, nan_score: float = math.nan) -> FloatArray:
    """IoU matrix (N, M) of image boxes given as (x1, y1, x2, y2) in any corner order.

    Corners are normalised (min/max of the two points); a zero-area box scores 0 with
    everything. NaN coordinates give ``nan_score`` (NaN unless a matcher asks for 0).

    Why it is laid out so: a frame has ten to fifty boxes a side, where a numpy call costs
    more than its arithmetic. Both sets are normalised at once, coordinate-major (contiguous
    rows are the cheapest operands); widths and heights are one (2, N, M) array, so each
    step is one broadcast call for both axes, done in place; the guarded division and the
    masks are skipped when no pair needs them. Every pair still sees the same IEEE
    operations in the same order.
    """
    a = np.asarray(a, dtype=np.float64).reshape(-1, 4)
    b = np.asarray(b, dtype=np.float64).reshape(-1, 4)
    n = len(a)
    coords = np.concatenate((a, b)).T.copy()  # (4, N + M): x1, y1, x2, y2
    low = np.minimum(coords[:2], coords[2:])  # normalised (x1, y1)
    high = np.maximum(coords[:2], coords[2:])  # normalised (x2, y2)
    side = high - low
    area = side[0] * side[1]
    # (width, height) of every pair's intersection, clipped at 0 (np.clip's result)
    sides = np.minimum(high[:, :n, None], high[:, None, n:])
    sides -= np.maximum(low[:, :n, None], low[:, None, n:])
    np.maximum(sides, 0.0, out=sides)
    inter = np.multiply(sides[0], sides[1], out=sides[0])
    union = area[:n, None] + area[n:]
    union -= inter
    positive = union > 0
    iou: FloatArray
    if np.logical_and.reduce(positive, axis=None):  # the division needs no guard
        iou = np.divide(inter, union, out=union)
    else:
        iou = np.zeros(union.shape)
        np.divide(inter, union, out=iou, where=positive)
    # the masks are outer products of per-box flags, applied in place; with every area > 0
    # (so none NaN, so no NaN coordinate) there is nothing to mask
    if not np.logical_and.reduce(area > 0):
        empty, nan = area <= 0, np.logical_or.reduce(np.isnan(coords), axis=0)
        iou[empty[:n, None] | empty[n:]] = 0.0
        iou[nan[:n, None] | nan[n:]] = nan_score
    return iou


def axis_aligned_ious(
    a_sets: Sequence[FloatArray], b_sets: Sequence[FloatArray], nan_score: float = math.nan
) -> list[FloatArray]:
    """``axis_aligned_iou(a_sets[k], b_sets[k], nan_score)`` for every k, bit for bit.

    Why: a run's frames each hold about ten boxes a side, so one frame's IoUs cost a dozen
    numpy calls for a hundred pairs. Here every frame's pairs are laid end to end and each
    pair gets the same IEEE operations in the same order, once for the whole batch.
    """
    n = np.array([len(a) for a in a_sets], dtype=np.intp)
    m = np.array([len(b) for b in b_sets], dtype=np.intp)
    a = np.concatenate([np.zeros((0, 4)), *a_sets]).reshape(-1, 4)
    b = np.concatenate([np.zeros((0, 4)), *b_sets]).reshape(-1, 4)
    a_coords, b_coords = a.T.copy(), b.T.copy()  # (4, boxes): x1, y1, x2, y2
    a_low, a_high = np.minimum(a_coords[:2], a_coords[2:]), np.maximum(a_coords[:2], a_coords[2:])
    b_low, b_high = np.minimum(b_coords[:2], b_coords[2:]), np.maximum(b_coords[:2], b_coords[2:])
    a_side, b_side = a_high - a_low, b_high - b_low
    a_area, b_area = a_side[0] * a_side[1], b_side[0] * b_side[1]
    # frame k's pairs in row-major order: each a box repeated once per b box of its frame,
    # against col: that frame's b boxes in order (np.repeat and np.take, not fancy indexing:
    # several times faster on these sizes)
    per_row = np.repeat(m, n)  # pairs of each a box
    row_start = np.cumsum(per_row) - per_row  # its first pair
    b_start = np.repeat(np.cumsum(m) - m, n)  # its frame's first b box
    cols = np.arange(int(n @ m)) + np.repeat(b_start - row_start, per_row)
    sides = np.minimum(np.repeat(a_high, per_row, axis=1), np.take(b_high, cols, axis=1))
    sides -= np.maximum(np.repeat(a_low, per_row, axis=1), np.take(b_low, cols, axis=1))
    inter = np.maximum(sides[0], 0.0) * np.maximum(sides[1], 0.0)  # (width, height) clipped
    union = np.repeat(a_area, per_row) + np.take(b_area, cols) - inter
    iou: FloatArray = np.zeros(union.shape)
    np.divide(inter, union, out=iou, where=union > 0)
    if not (np.logical_and.reduce(a_area > 0) and np.logical_and.reduce(b_area > 0)):
        a_nan = np.logical_or.reduce(np.isnan(a_coords), axis=0)
        b_nan = np.logical_or.reduce(np.isnan(b_coords), axis=0)
        iou[np.repeat(a_area <= 0, per_row) | np.take(b_area <= 0, cols)] = 0.0
        iou[np.repeat(a_nan, per_row) | np.take(b_nan, cols)] = nan_score
    bounds = [0, *np.cumsum(n * m).tolist()]
    return [
        iou[start:stop].reshape(rows_k, cols_k)
        for start, stop, rows_k, cols_k in zip(
            bounds[:-1], bounds[1:], n.tolist(), m.tolist(), strict=True
        )
    ]


#: Pair scores computed at once by the block-wise box matchers: a few arrays of this many
#: floats (2 MB each) bound the working memory of a frame, whatever its box count.
BLOCK_PAIRS = 1 << 18


def overlap_blocks(
    a: FloatArray, b: FloatArray, max_pairs: int = BLOCK_PAIRS
) -> Iterator[tuple[int, int, npt.NDArray[np.intp]]]:
    """Row blocks of image boxes ``a`` (N, 4) with the columns of ``b`` (M, 4) worth scoring.

    Yields ``(start, stop, cols)``: rows ``a[start:stop]`` (in order, at most ``max_pairs``
    pairs a block) and, ascending, the boxes of ``b`` whose normalised extent touches the
    block's. A pair left out has no overlap, so its intersection is 0 and its IoU 0 (or NaN:
    NaN coordinates compare false and are left out too): the pair can neither match nor
    raise a best IoU above 0. Blocks with no such column are skipped.
    """
    bx1, bx2 = np.fmin(b[:, 0], b[:, 2]), np.fmax(b[:, 0], b[:, 2])
    by1, by2 = np.fmin(b[:, 1], b[:, 3]), np.fmax(b[:, 1], b[:, 3])
    ax1, ax2 = np.fmin(a[:, 0], a[:, 2]), np.fmax(a[:, 0], a[:, 2])
    ay1, ay2 = np.fmin(a[:, 1], a[:, 3]), np.fmax(a[:, 1], a[:, 3])
    rows = max(1, max_pairs // max(len(b), 1))
    with np.errstate(invalid="ignore"):
        for start in range(0, len(a), rows):
            stop = min(start + rows, len(a))
            block = slice(start, stop)
            # fmin/fmax skip NaN; an all-NaN block gives NaN bounds and keeps nothing.
            keep = bx2 >= np.fmin.reduce(ax1[block])
            keep &= bx1 <= np.fmax.reduce(ax2[block])
            keep &= by2 >= np.fmin.reduce(ay1[block])
            keep &= by1 <= np.fmax.reduce(ay2[block])
            cols = np.flatnonzero(keep)
            if cols.size:
                yield start, stop, cols


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


def _clip_half_plane(
    poly: FloatArray, count: npt.NDArray[np.intp], start: FloatArray, edge: FloatArray
) -> tuple[FloatArray, npt.NDArray[np.intp]]:
    """One Sutherland–Hodgman step for K convex polygons at once: each polygon (K, V, 2)
    with ``count`` (K,) vertices, clipped to the left of its own directed edge ``start`` +
    t·``edge`` (K, 2); the kept vertices come first (at most V + 1 of 2·V slots)."""
    k, v = poly.shape[0], poly.shape[1]
    slot = np.arange(v)
    live = slot[None, :] < count[:, None]
    nxt = np.where(slot[None, :] + 1 < count[:, None], slot[None, :] + 1, 0)
    rel = poly - start[:, None, :]
    side = edge[:, None, 0] * rel[..., 1] - edge[:, None, 1] * rel[..., 0]  # (K, V) ≥ 0 inside
    side_next = np.take_along_axis(side, nxt, axis=1)
    poly_next = np.take_along_axis(poly, nxt[..., None], axis=1)
    inside, inside_next = side >= 0, side_next >= 0
    cross = live & (inside != inside_next)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.where(cross, side / np.where(cross, side - side_next, 1.0), 0.0)
    meet = poly + t[..., None] * (poly_next - poly)
    out = np.stack((poly, meet), axis=2).reshape(k, 2 * v, 2)  # vertex i, then its crossing
    keep = np.stack((live & inside, cross), axis=2).reshape(k, 2 * v)
    order = np.argsort(~keep, axis=1, kind="stable")
    return np.take_along_axis(out, order[..., None], axis=1), keep.sum(axis=1)


def _polygon_area(poly: FloatArray, count: npt.NDArray[np.intp]) -> FloatArray:
    """Shoelace area (K,) of polygons (K, V, 2) with ``count`` leading vertices each."""
    v = poly.shape[1]
    slot = np.arange(v)
    nxt = np.where(slot[None, :] + 1 < count[:, None], slot[None, :] + 1, 0)
    poly_next = np.take_along_axis(poly, nxt[..., None], axis=1)
    term = poly[..., 0] * poly_next[..., 1] - poly_next[..., 0] * poly[..., 1]
    term = np.where(slot[None, :] < count[:, None], term, 0.0)
    area: FloatArray = 0.5 * np.abs(term.sum(axis=1))
    return area


def bev_iou(
    center_a: npt.ArrayLike,
    half_a: npt.ArrayLike,
    yaw_a: npt.ArrayLike,
    center_b: npt.ArrayLike,
    half_b: npt.ArrayLike,
    yaw_b: npt.ArrayLike,
) -> FloatArray:
    """IoU matrix (N, M) of oriented rectangles seen from above (bird's eye view).

    Centres (N, 2) / (M, 2), half extents (N, 2) / (M, 2), yaws in degrees. Exact: each
    pair's intersection is the first rectangle clipped by the second's four edges
    (Sutherland–Hodgman, every pair at once); pairs whose circumscribed circles do not meet
    are 0 without clipping. Zero-area boxes and NaN give 0 (they never match).
    """
    ca = np.asarray(center_a, dtype=np.float64).reshape(-1, 2)
    cb = np.asarray(center_b, dtype=np.float64).reshape(-1, 2)
    ha = np.asarray(half_a, dtype=np.float64).reshape(-1, 2)
    hb = np.asarray(half_b, dtype=np.float64).reshape(-1, 2)
    ya = np.asarray(yaw_a, dtype=np.float64).reshape(-1)
    yb = np.asarray(yaw_b, dtype=np.float64).reshape(-1)
    n, m = len(ca), len(cb)
    iou = np.zeros((n, m))
    if n == 0 or m == 0:
        return iou
    area_a, area_b = 4.0 * ha[:, 0] * ha[:, 1], 4.0 * hb[:, 0] * hb[:, 1]
    radius_a, radius_b = np.hypot(ha[:, 0], ha[:, 1]), np.hypot(hb[:, 0], hb[:, 1])
    gap = np.hypot(ca[:, None, 0] - cb[None, :, 0], ca[:, None, 1] - cb[None, :, 1])
    with np.errstate(invalid="ignore"):
        near = gap < radius_a[:, None] + radius_b[None, :]  # NaN compares false
        near &= (area_a[:, None] > 0) & (area_b[None, :] > 0)
    near &= np.isfinite(ya)[:, None] & np.isfinite(yb)[None, :]
    rows, cols = np.nonzero(near)
    if rows.size == 0:
        return iou
    corners_a = box_corners(ca, ha, ya)  # counter-clockwise
    corners_b = box_corners(cb, hb, yb)
    poly = np.zeros((rows.size, 8, 2))
    poly[:, :4] = corners_a[rows]
    count = np.full(rows.size, 4, dtype=np.intp)
    clip = corners_b[cols]
    for e in range(4):
        start = clip[:, e]
        poly, count = _clip_half_plane(poly, count, start, clip[:, (e + 1) % 4] - start)
        poly, count = poly[:, :8], np.minimum(count, 8)  # a convex 4-gon clipped 4 times
    inter = _polygon_area(poly, count)
    union = area_a[rows] + area_b[cols] - inter
    iou[rows, cols] = np.where(union > 0, inter / np.where(union > 0, union, 1.0), 0.0)
    return iou


def box_signed_distance(
    center_a: npt.ArrayLike,
    half_a: npt.ArrayLike,
    yaw_a: npt.ArrayLike,
    center_b: npt.ArrayLike,
    half_b: npt.ArrayLike,
    yaw_b: npt.ArrayLike,
) -> FloatArray:
    """Signed edge-to-edge distance (N,) between pairs of oriented rectangles.

    Positive: the Euclidean distance between the two rectangles. Zero: touching. Negative:
    minus the penetration depth, the smallest translation along a separating-axis candidate
    (the four edge normals) that separates them. Arguments broadcast: centres (N, 2) or
    (2,), half extents (N, 2) or (2,), yaws in degrees (N,) or scalar. NaN inputs give NaN.

    Separating axes give the overlap; when separated, the distance of two disjoint convex
    polygons is reached at a vertex of one, so it is the smallest vertex-to-rectangle
    distance, each computed in the other rectangle's frame.
    """
    args = (
        np.asarray(center_a, dtype=np.float64).reshape(-1, 2),
        np.asarray(half_a, dtype=np.float64).reshape(-1, 2),
        np.asarray(yaw_a, dtype=np.float64).reshape(-1),
        np.asarray(center_b, dtype=np.float64).reshape(-1, 2),
        np.asarray(half_b, dtype=np.float64).reshape(-1, 2),
        np.asarray(yaw_b, dtype=np.float64).reshape(-1),
    )
    n = max(len(x) for x in args)
    ca, ha, ya, cb, hb, yb = (np.repeat(x, n, axis=0) if len(x) == 1 else x for x in args)
    return signed_distance_rows(ca, ya, cb, yb, half_rows(np.concatenate((ha, hb), axis=1)))


def signed_distance_rows(
    ca: FloatArray, ya: FloatArray, cb: FloatArray, yb: FloatArray, halves: FloatArray
) -> FloatArray:
    """:func:`box_signed_distance` of N pairs given whole: centres (N, 2), yaws (N,) in
    degrees, and the half extents as rows (6, 2N), each of A's pairs then B's:
    :func:`half_rows`.

    Why it is laid out so: the oracles measure a few pairs at a time, where a numpy call
    costs more than its arithmetic, and same-shape contiguous operands are the cheapest. So
    each quantity of the two boxes (or of the two directions, B's vertices in A's frame and
    A's in B's) is one row of 2N, and the vertices' four sign cases are written out; every
    pair still sees the IEEE operations of a vertices-to-box distance per direction (the
    form ``test_box_distance_both_directions_at_once`` checks it against) and the
    separating-axis gap in the same order (negations and swapped operands of + and × are exact).
    """
    n = len(ya)
    m = 2 * n
    # cos, sin of A's, B's and again A's yaws: [:2n] is each box's, [n:] the other box's.
    theta = np.deg2rad(np.concatenate((ya, yb, ya)))
    cos, sin = np.cos(theta), np.sin(theta)
    c, s, c_o, s_o = cos[:m], sin[:m], cos[n:], sin[n:]
    # Each box's rotation seen from the other, rows −sin, cos, sin: δ = yaw_b − yaw_a from
    # A, −δ from B.
    rot = np.empty((3, m))
    cross_a, cross_b = s_o * c, c_o * s
    np.subtract(cross_b, cross_a, out=rot[0])
    np.add(c * c_o, s * s_o, out=rot[1])
    np.subtract(cross_a, cross_b, out=rot[2])
    # The other box's centre in each box's frame (A sees B at d, B sees A at −d): rows x, y.
    centres = np.concatenate((ca.T, cb.T, ca.T), axis=1)
    dx, dy = centres[0, n:] - centres[0, :m], centres[1, n:] - centres[1, :m]
    local = np.empty((2, m))
    np.add(dx * c, dy * s, out=local[0])
    np.subtract(dy * c, dx * s, out=local[1])
    own, other_x, other_y = halves[:2], halves[2:4], halves[4:]
    # Separating axes, per axis of each box: |offset| − own half − the other's projection.
    abs_rot = np.abs(rot)  # |sin|, |cos|, |sin|
    sep = np.abs(local)
    sep -= own
    sep -= other_x * abs_rot[1:]
    sep -= other_y * abs_rot[:2]
    per_box = np.maximum(sep[0], sep[1])
    gap = np.maximum(per_box[:n], per_box[n:])  # > 0 iff separated; else −penetration
    # The other box's vertices, centre ± hx·(cos, sin) ± hy·(−sin, cos), against the box.
    half_x, half_y = rot[1:] * other_x, rot[:2] * other_y
    plus, minus = local + half_x, local - half_x
    vert = np.empty((4, 2, m))
    np.add(plus, half_y, out=vert[0])
    np.add(minus, half_y, out=vert[1])
    np.subtract(minus, half_y, out=vert[2])
    np.subtract(plus, half_y, out=vert[3])
    np.abs(vert, out=vert)
    vert -= own
    np.maximum(vert, 0.0, out=vert)
    vert *= vert
    d2 = (vert[:, 0] + vert[:, 1]).reshape(8, n).min(axis=0)  # 4 vertices × 2 directions
    out: FloatArray = np.where(gap > 0, np.sqrt(d2), gap)
    return out


def half_rows(halves: FloatArray) -> FloatArray:
    """Half extents (K, 4), each row A's x, y then B's x, y, as :func:`signed_distance_rows`
    takes them: rows (6, 2K) of each box's own x, own y, the other's x twice, its y twice
    (each row A's K values, then B's)."""
    rows: FloatArray = np.asarray(halves, dtype=np.float64).T[_HALF_ROWS].reshape(6, -1)
    return rows


#: Columns of (A x, A y, B x, B y) making :func:`half_rows`' rows.
_HALF_ROWS = np.array([[0, 2], [1, 3], [2, 0], [2, 0], [3, 1], [3, 1]])


def polyline_nearest(points: FloatArray, polylines: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Nearest point on each polyline (H, M, 2; NaN-padded rows) to each point (H, 2).

    Returns the nearest points (H, 2) and the distances (H,); NaN where a polyline has no
    finite point. A polyline of one point is that point.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    lines = np.asarray(polylines, dtype=np.float64)
    h = len(pts)
    if lines.shape[1] == 1:
        a = b = lines
    else:
        a, b = lines[:, :-1, :], lines[:, 1:, :]
        # A segment whose end is padding degenerates to its start point.
        b = np.where(np.isnan(b), a, b)
    ab = b - a
    ap = pts[:, None, :] - a
    denom = np.einsum("hmi,hmi->hm", ab, ab)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.where(denom > 0, np.einsum("hmi,hmi->hm", ap, ab) / denom, 0.0)
    t = np.clip(np.nan_to_num(t), 0.0, 1.0)
    q = a + t[..., None] * ab
    diff = pts[:, None, :] - q
    dist = np.sqrt(np.einsum("hmi,hmi->hm", diff, diff))
    finite = np.isfinite(dist)
    any_finite = finite.any(axis=1)
    best = np.argmin(np.where(finite, dist, np.inf), axis=1)
    rows = np.arange(h)
    nearest = np.where(any_finite[:, None], q[rows, best], np.nan)
    distance = np.where(any_finite, dist[rows, best], np.nan)
    return nearest, distance


def signed_lateral_offset(
    points: FloatArray, polylines: FloatArray, yaw_deg: FloatArray
) -> FloatArray:
    """Offset (H,) of each point from its polyline, signed along the ego-frame y axis.

    ``|p - q|`` for the nearest polyline point q, with the sign of ``(-sin ψ, cos ψ)·(p - q)``
    (ψ = ``yaw_deg``); 0 on the polyline, NaN where the polyline is empty.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    nearest, distance = polyline_nearest(pts, polylines)
    theta = np.deg2rad(np.asarray(yaw_deg, dtype=np.float64).reshape(-1))
    side = -np.sin(theta) * (pts[:, 0] - nearest[:, 0]) + np.cos(theta) * (
        pts[:, 1] - nearest[:, 1]
    )
    return np.where(side < 0, -distance, distance)


def along_polyline(polyline: FloatArray, arc: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Points (K, 2) at arc lengths ``arc`` (K,) along a polyline (M, 2) from its start,
    and the heading (K,) in degrees of the segment each lies on.

    Beyond the end the last segment is extended; zero-length segments are skipped for the
    heading (NaN when every segment has zero length).
    """
    line = np.asarray(polyline, dtype=np.float64).reshape(-1, 2)
    s = np.asarray(arc, dtype=np.float64).reshape(-1)
    seg = np.diff(line, axis=0)
    length = np.hypot(seg[:, 0], seg[:, 1])
    keep = length > 0
    if not keep.any():
        return np.broadcast_to(line[0], (len(s), 2)).copy(), np.full(len(s), np.nan)
    starts, seg, length = line[:-1][keep], seg[keep], length[keep]
    cum = np.concatenate(([0.0], np.cumsum(length)))
    idx = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(length) - 1)
    local = s - cum[idx]
    unit = seg[idx] / length[idx, None]
    points = starts[idx] + local[:, None] * unit
    return points, np.rad2deg(np.arctan2(unit[:, 1], unit[:, 0]))
