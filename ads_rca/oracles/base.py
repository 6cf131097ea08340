"""What every oracle shares: the run context, and the ego's identity.

An oracle is a pure function ``(ctx, ts) -> OracleResult`` of one analysed frame plus the
run context. It never raises on bad data: where the data a check needs is missing it
reports the input problem through ``ctx.report`` (once per file and field) and returns a
result with ``failed=False`` and ``skipped`` saying why.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ads_rca.diagnosis.perceived import EGO_ID, is_perceived
from ads_rca.diagnosis.verdict import MODULES, Metric, Module, OracleResult
from ads_rca.model import Actors, EgoPose, RunLog
from ads_rca.oracles.semantics import EGO_ID_TIMESTAMP_MS, semantics_for
from ads_rca.params import Params
from ads_rca.problems import CHECK_SKIPPED, Problem, ProblemLog, new_problems

# The per-frame result types live with the verdict (they are its contract); oracles name
# them from here.
__all__ = [
    "EGO_ID_TIMESTAMP_MS",
    "MODULES",
    "Metric",
    "Module",
    "OracleResult",
    "RunContext",
    "earliest_ego",
    "ego_at",
    "ego_row",
]


@dataclass
class RunContext:
    """A log with the parameters and derived facts every oracle needs."""

    log: RunLog
    params: Params
    ego_id: str | None = None
    problems: ProblemLog = field(default_factory=ProblemLog)
    _reported: set[tuple[str, str, str]] = field(default_factory=set, repr=False)
    #: What each scorer keeps over the run's frames, by scorer name (a scorer's figures of
    #: a run so far pool earlier frames: a live monitor gives every context of its run the
    #: same one; :func:`ads_rca.sources.registry.scored_frame`).
    scorer_state: dict[str, Any] = field(default_factory=dict, repr=False)
    #: Per module, the traceback of the first exception its oracle raised (a bug in our
    #: code: the command prints it; the verdict names the module's internal error).
    tracebacks: dict[Module, str] = field(default_factory=dict, repr=False)
    #: Per-frame values the oracles carry from one context of the run to the next, by name
    #: (:class:`~ads_rca.oracles.cache.Carry`): a live monitor judges each frame on a new
    #: view of its window and gives every one the same dict. None: nothing carried
    #: (``diagnose`` judges a run on one context, whose own caches suffice).
    carried: dict[str, Any] | None = field(default=None, repr=False)

    @classmethod
    def create(cls, log: RunLog, params: Params) -> RunContext:
        ctx = cls(log, params)
        if is_perceived(log):  # the ego its pose made (its box may not centre on the pose)
            ctx.ego_id = EGO_ID
        elif not _records_no_actors(log):  # else no actor can match: nothing to find or report
            ctx.ego_id = semantics_for(params).find_ego(ctx)
        return ctx

    @property
    def frame_ms(self) -> int:
        return self.log.frame_ms

    def report(self, file: str, field_name: str, issue: str, ts: int | None = None) -> None:
        """An input problem found while judging (reported once per file, field and issue)."""
        problem = Problem(file, field_name, issue, CHECK_SKIPPED, "error", ts)
        self.merge([problem])

    def merge(self, problems: Iterable[Problem]) -> None:
        """Problems found by a copy of this context (a worker process), minus repeats."""
        self.problems.extend(new_problems(problems, self._reported))


def _records_no_actors(log: RunLog) -> bool:
    """The run's capability record says it has no actors (a dataset of map perception only,
    a recording without them)."""
    status = log.inputs.get("actors")
    return bool(log.inputs) and (status is None or status.state == "absent")


EGO_MATCH_DISTANCE_M = 0.5
#: A localised pose may be this far (m) from the ego's actor entry (``tolerant`` matching).
EGO_NEAREST_MAX_M = 2.0


def earliest_ego(ctx: RunContext, tolerant: bool = False) -> str | None:
    """The ego in the earliest analysed frame with both an actors and a pose file (see
    :func:`ego_at`; ``tolerant``: else the actor nearest the pose within
    ``EGO_NEAREST_MAX_M``, as a drifting localisation puts it); None, reported, when no
    actor matches there."""
    log = ctx.log
    for ts in log.unique_frames:
        if ts in log.actors and ts in log.pose:
            found = ego_at(log, ts)
            if found is None and tolerant:
                found = nearest_ego(log, ts)
            if found is not None:
                return found
            break
    ctx.report("actors/", "ego id", "no actor matches the ego pose in the first frame")
    return None


def ego_at(log: RunLog, ts: int) -> str | None:
    """The first actor (file order) within 0.5 m of the ego pose at ``ts``, per axis."""
    actors, pose = log.actors.get(ts), log.pose.get(ts)
    if actors is None or pose is None:
        return None
    row = ego_row(actors, pose)
    return actors.ids[row] if row is not None else None


def nearest_ego(log: RunLog, ts: int) -> str | None:
    """The actor nearest the ego pose at ``ts`` (first in file order on ties) when it is
    within ``EGO_NEAREST_MAX_M``."""
    actors, pose = log.actors.get(ts), log.pose.get(ts)
    if actors is None or pose is None or len(actors) == 0:
        return None
    distance = np.hypot(actors.location[:, 0] - pose.x, actors.location[:, 1] - pose.y)
    distance = np.where(np.isnan(distance), np.inf, distance)
    row = int(np.argmin(distance))
    return actors.ids[row] if distance[row] <= EGO_NEAREST_MAX_M else None


def ego_row(actors: Actors, pose: EgoPose) -> int | None:
    """The row of :func:`ego_at`'s match in one actors record (the live detector's too)."""
    if len(actors) == 0:
        return None
    close = (np.abs(actors.location[:, 0] - pose.x) < EGO_MATCH_DISTANCE_M) & (
        np.abs(actors.location[:, 1] - pose.y) < EGO_MATCH_DISTANCE_M
    )
    rows = np.flatnonzero(close)
    return int(rows[0]) if rows.size else None
