"""The 3-D perception rule's matching: the stack's 3-D objects to the ground-truth actors, per
timestamp.

Why a module of its own: perception in 3-D judges the match, and without predictions on
ground truth (recordings of real stacks) prediction and planning find the partner's raw
track through it (tracked objects share their ids with the stack's predictions). So the
match is made once per timestamp, cached on the :class:`CorrectedContext`, and read by all
three. Pairs are scored by bird's-eye IoU of oriented boxes, with a centre-distance
fallback for small actors (a pedestrian's box is too small for IoU to survive a few
decimetres of error), and assigned by the Hungarian method (docs/semantics-corrected.md,
"Perception in 3-D").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ads_rca.foundation.geometry import FloatArray, bev_iou
from ads_rca.model import Objects3D
from ads_rca.oracles.corrected.assignment import best_matching
from ads_rca.oracles.corrected.context import CacheName, CorrectedContext, ego_box, other_rows
from ads_rca.params import Params

IntArray = npt.NDArray[np.intp]


def uses_3d(judging: CorrectedContext) -> bool:
    """Whether the 3-D perception rule judges perception (``perception_check``; ``auto``: the
    log has no 2-D detections with 2-D ground truth, and has 3-D objects)."""
    check = judging.params.perception_check
    if check != "auto":
        return check == "3d"
    log = judging.log
    if log.bboxes and log.bboxes_gt:
        return False
    return bool(log.tracks_3d or log.detections_3d)


def source(judging: CorrectedContext) -> tuple[str, dict[int, Objects3D]]:
    """The perceived objects the 3-D perception rule judges: ``("tracked", tracks_3d)`` or
    ``("detected", detections_3d)`` (``perception_3d_source``; ``auto``: tracked objects when
    there are)."""
    chosen = judging.params.perception_3d_source
    if chosen == "detected" or (chosen == "auto" and not judging.log.tracks_3d):
        return "detected", judging.log.detections_3d
    return "tracked", judging.log.tracks_3d


def raw_without_predictions_on_truth(judging: CorrectedContext) -> bool:
    """Whether prediction and planning read the raw predictions linked through the 3-D
    match: the log has no prediction on ground truth at all and the 3-D perception rule is
    in force."""
    return not judging.log.predictions_with_perception and uses_3d(judging)


def match_objects(
    objects: tuple[FloatArray, FloatArray, FloatArray],
    actors: tuple[FloatArray, FloatArray, FloatArray],
    params: Params,
) -> tuple[IntArray, IntArray, FloatArray, FloatArray]:
    """Optimal one-to-one matching of perceived objects to actors, each given as (centres
    (N, 2), half extents (N, 2), yaws (N,) deg).

    A pair is eligible at IoU >= ``perc3d_match_iou``, or, for an actor whose bird's-eye
    area is below ``perc3d_small_area``, at a centre distance <= ``perc3d_match_distance``.
    Scores: the IoU; a pair eligible by distance only, ``perc3d_match_iou`` × (1 − d / 2D)
    (below every IoU match, closer first). Returns matched object rows (ascending), their
    actor columns, their IoUs, and each actor's best IoU over all objects.
    """
    iou = bev_iou(*objects, *actors)
    n, m = iou.shape
    if n == 0 or m == 0:
        empty = np.zeros(0, dtype=np.intp)
        return empty, empty, np.zeros(0), np.zeros(m)
    limit = params.perc3d_match_distance
    diff = objects[0][:, None, :] - actors[0][None, :, :]
    distance = np.hypot(diff[..., 0], diff[..., 1])
    half = actors[1]
    small = 4.0 * half[:, 0] * half[:, 1] < params.perc3d_small_area
    by_iou = iou >= params.perc3d_match_iou
    whole = np.asarray(np.isfinite(np.column_stack(objects)).all(axis=1))  # NaN: no match
    with np.errstate(invalid="ignore"):
        by_distance = small[None, :] & (distance <= limit) & ~by_iou & whole[:, None]
    near = 1.0 - distance / (2.0 * limit) if limit > 0 else np.ones_like(distance)
    score = np.where(by_iou, iou, np.where(by_distance, params.perc3d_match_iou * near, 0.0))
    rows, cols = best_matching(by_iou | by_distance, score)
    return rows, cols, iou[rows, cols], iou.max(axis=0)


@dataclass(frozen=True)
class Match3D:
    """One timestamp's match: the actors (non-ego, with an extent, each id's first row),
    the perceived objects, who is in sensing range, and the matched pairs."""

    source: str
    objects: Objects3D
    actor_ids: tuple[str, ...]
    actor_center: FloatArray  # (G, 2)
    actor_half: FloatArray  # (G, 2) first-appearance half extents
    actor_yaw: FloatArray  # (G,) deg
    actor_in_range: npt.NDArray[np.bool_]  # (G,)
    object_in_range: npt.NDArray[np.bool_]  # (P,)
    rows: IntArray  # matched object rows, ascending
    cols: IntArray  # their actor columns
    iou: FloatArray  # their IoUs
    best: FloatArray  # (G,) each actor's best IoU over all objects

    def object_of(self, actor_id: str) -> int | None:
        """The object row matched to an actor, if any."""
        if actor_id not in self.actor_ids:
            return None
        col = self.actor_ids.index(actor_id)
        hit = np.flatnonzero(self.cols == col)
        return int(self.rows[hit[0]]) if hit.size else None


MATCH: CacheName[Match3D | None] = CacheName("match3d")


def frame_match(judging: CorrectedContext, ts: int) -> Match3D | None:
    """The match at ts (cached); None without an actors file, perceived objects or an ego
    position at ts."""
    return judging.cache(MATCH).get(ts, lambda: _match(judging, ts))


def _match(judging: CorrectedContext, ts: int) -> Match3D | None:
    name, frames = source(judging)
    objects, actors, ego = frames.get(ts), judging.log.actors.get(ts), ego_box(judging, ts)
    if objects is None or actors is None or ego is None:
        return None
    rows = other_rows(judging, ts)
    extents = judging.log.actor_extents
    ids = tuple(actors.ids[r] for r in rows)
    center = actors.location[rows, :2].reshape(-1, 2)
    half = np.array([extents[a][:2] for a in ids], dtype=np.float64).reshape(-1, 2)
    yaw = actors.rotation[rows, 2].reshape(-1)
    obj_center = objects.location[:, :2].reshape(-1, 2)
    obj_half = objects.extent[:, :2].reshape(-1, 2)
    matched, cols, iou, best = match_objects(
        (obj_center, obj_half, objects.yaw), (center, half, yaw), judging.params
    )
    reach = judging.params.perc3d_range
    origin = ego[0]
    with np.errstate(invalid="ignore"):
        actor_in = np.hypot(*(center - origin).T) <= reach
        object_in = np.hypot(*(obj_center - origin).T) <= reach
    return Match3D(
        source=name,
        objects=objects,
        actor_ids=ids,
        actor_center=center,
        actor_half=half,
        actor_yaw=yaw,
        actor_in_range=np.asarray(actor_in, dtype=bool).reshape(-1),
        object_in_range=np.asarray(object_in, dtype=bool).reshape(-1),
        rows=matched,
        cols=cols,
        iou=iou,
        best=best,
    )
