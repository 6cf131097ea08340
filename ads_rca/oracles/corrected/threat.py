"""Before a collision: the most threatening actor, judged as the partner.

Why: a live stack has no collision frame until it crashes (and a good run never does), yet
the `corrected` rules are all about one partner. Until a collision names the real one, each
frame is judged against the actor the ego is closest to hitting by the rules' own measure:
the non-ego actor with the least clearance c_gt (the ego's plan boxes against the actor's
real boxes over ``prediction_window``, :mod:`.clearance`); at a frame without a plan, or
where no actor's clearance is defined, the actor with the least box distance at ts (the
collision partner's own rule, :func:`.context.nearest_actor`). Ties go to the earlier actor
in file order. The choice is cached per timestamp, so the four oracles agree on it.
"""

from __future__ import annotations

import numpy as np

from ads_rca.oracles.corrected.boxes import Series
from ads_rca.oracles.corrected.clearance import index_distances, lowest
from ads_rca.oracles.corrected.context import (
    CacheName,
    CorrectedContext,
    ego_box,
    nearest_actor,
    other_rows,
)

THREAT: CacheName[str | None] = CacheName("threat")


def most_threatening(judging: CorrectedContext, ts: int) -> str | None:
    """The provisional partner at ts (cached per timestamp); None without actors."""
    return judging.cache(THREAT).get(ts, lambda: _choose(judging, ts))


def _choose(judging: CorrectedContext, ts: int) -> str | None:
    rows = other_rows(judging, ts)
    if not rows:
        return None
    ids = [judging.log.actors[ts].ids[r] for r in rows]
    plan = judging.plan(ts)
    if plan is not None:
        found = least_clearance(judging, ts, plan.boxes, ids)
        if found is not None:
            return found
    ego = ego_box(judging, ts)
    return None if ego is None else nearest_actor(judging, ts, ego)


def least_clearance(judging: CorrectedContext, ts: int, ego: Series, ids: list[str]) -> str | None:
    """Of ``ids``, the one with the least clearance c_gt to the ego's plan boxes (None when
    no clearance is defined): every actor's real boxes from one table, one distance call."""
    w, n = judging.window, len(ids)
    if w < 1:
        return None
    states = judging.states_over(
        judging.gids(ids), [ts + i * judging.frame_ms for i in range(w + 1)]
    )
    extents = judging.log.actor_extents
    half = np.array([extents[a][:2] for a in ids], dtype=np.float64)
    dist = index_distances(
        np.broadcast_to(ego.center, (n, w + 1, 2)),
        np.broadcast_to(ego.half, (n, 2)),
        np.broadcast_to(ego.yaw, (n, w + 1)),
        states[:, :, :2],
        half,
        states[:, :, 2],
    )
    low, _ = lowest(dist)
    if not np.isfinite(low).any():
        return None
    return ids[int(np.argmin(low))]
