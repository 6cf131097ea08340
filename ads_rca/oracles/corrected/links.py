"""The reference's linking rule: which raw prediction speaks for which actor.

Each raw id links to the id on truth (file order, ego skipped) with the smallest distance between
the unrotated step-"0" offsets, strictly below ``LINK_MAX_DISTANCE``, earlier id on ties. If
several raw ids link to one actor, the one nearest that actor's step "0" on truth speaks for it.
The 2-D perception rule links the partner this way, the noise-floor rule every actor (its
samples).
"""

from __future__ import annotations

import math

import numpy as np

from ads_rca.foundation.geometry import FloatArray
from ads_rca.model import Predictions

#: The reference's linking rule only considers step-"0" offsets closer than this.
LINK_MAX_DISTANCE = 100.0


def step0_offsets(tracks: Predictions, skip: str | None) -> tuple[list[str], FloatArray]:
    """Ids (file order, ``skip`` left out) with a step "0", and those offsets (N, 2)."""
    ids = [obstacle for obstacle in tracks if obstacle != skip]
    if not ids:
        return [], np.zeros((0, 2))
    keys = tracks[ids[0]].keys
    if "0" in keys and [tracks[i].keys for i in ids].count(keys) == len(ids):  # the usual case
        row = keys.index("0")
        return ids, np.array([tracks[i].offsets[row, :2] for i in ids])
    found = [(i, tracks[i].offset("0")) for i in ids]
    kept = [(i, offset[:2]) for i, offset in found if offset is not None]
    if not kept:
        return [], np.zeros((0, 2))
    return [i for i, _ in kept], np.array([offset for _, offset in kept])


def raw_links(raw: Predictions, on_truth: Predictions, ego_id: str | None) -> dict[str, str]:
    """{actor id on truth: the raw id linked to it} for every actor some raw id links to."""
    on_truth_ids, on_truth_xy = step0_offsets(on_truth, ego_id)
    if not on_truth_ids:  # most frames of a long log: no raw offsets to read
        return {}
    raw_ids, raw_xy = step0_offsets(raw, None)
    if not raw_ids:
        return {}
    diff = raw_xy[:, None] - on_truth_xy[None, :]  # (raw, on_truth, 2)
    d = np.hypot(diff[..., 0], diff[..., 1])
    d[~(d < LINK_MAX_DISTANCE)] = np.inf  # NaN too
    best = d.argmin(axis=1)  # the first minimum: the earlier id on truth on ties
    nearest = np.minimum.reduce(d, axis=1)
    # one pass over the raw ids in order (ids are few: Python beats a numpy call per actor)
    winner: dict[int, tuple[float, int]] = {}  # column on truth -> (distance, raw row)
    for row, (col, distance) in enumerate(zip(best.tolist(), nearest.tolist(), strict=True)):
        if distance < math.inf and (col not in winner or distance < winner[col][0]):
            winner[col] = (distance, row)  # strictly nearer: the earlier raw id on ties
    return {on_truth_ids[col]: raw_ids[winner[col][1]] for col in sorted(winner)}
