"""The reference's linking rule: which raw prediction speaks for which actor.

Each raw id links to the pwp id (file order, ego skipped) with the smallest distance between
the unrotated step-"0" offsets, strictly below ``LINK_MAX_DISTANCE``, earlier id on ties. If
several raw ids link to one actor, the one nearest that actor's pwp step "0" speaks for it.
Rule 2 links the partner this way, rule 8 every actor (its samples).
"""

from __future__ import annotations

import numpy as np

from ads_rca.geometry import FloatArray
from ads_rca.model import Predictions

#: The reference's linking rule only considers step-"0" offsets closer than this.
LINK_MAX_DISTANCE = 100.0


def step0_offsets(tracks: Predictions, skip: str | None) -> tuple[list[str], FloatArray]:
    """Ids (file order, ``skip`` left out) with a step "0", and those offsets (N, 2)."""
    ids = [obstacle for obstacle in tracks if obstacle != skip]
    if not ids:
        return [], np.zeros((0, 2))
    keys = tracks[ids[0]].keys
    if "0" in keys and all(tracks[i].keys == keys for i in ids):  # the usual case
        row = keys.index("0")
        return ids, np.array([tracks[i].offsets[row, :2] for i in ids])
    found = [(i, tracks[i].offset("0")) for i in ids]
    kept = [(i, offset[:2]) for i, offset in found if offset is not None]
    if not kept:
        return [], np.zeros((0, 2))
    return [i for i, _ in kept], np.array([offset for _, offset in kept])


def raw_links(raw: Predictions, pwp: Predictions, ego_id: str | None) -> dict[str, str]:
    """{pwp actor id: the raw id linked to it} for every actor some raw id links to."""
    pwp_ids, pwp_xy = step0_offsets(pwp, ego_id)
    raw_ids, raw_xy = step0_offsets(raw, None)
    if not pwp_ids or not raw_ids:
        return {}
    d = np.hypot(raw_xy[:, None, 0] - pwp_xy[None, :, 0], raw_xy[:, None, 1] - pwp_xy[None, :, 1])
    d = np.where(d < LINK_MAX_DISTANCE, d, np.inf)
    best = np.argmin(d, axis=1)
    reach = np.isfinite(d[np.arange(len(raw_ids)), best])
    out: dict[str, str] = {}
    for col in np.unique(best[reach]).tolist():
        linked = np.flatnonzero((best == col) & reach)
        out[pwp_ids[col]] = raw_ids[int(linked[np.argmin(d[linked, col])])]
    return out
