"""What every oracle shares: its result type, the run context, and the ego's identity.

An oracle is a pure function ``(ctx, ts) -> OracleResult`` of one analysed frame plus the
run context. It never raises on bad data: where the data a check needs is missing it
reports the input problem through ``ctx.report`` (once per file and field) and returns a
result with ``failed=False`` and ``skipped`` saying why.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from ads_rca.model import RunLog
from ads_rca.params import Params
from ads_rca.problems import CHECK_SKIPPED, Problem, ProblemLog

Module = Literal["perception", "prediction", "planning", "controller"]
#: Pipeline order, upstream first (the reference's names).
MODULES: tuple[Module, ...] = ("perception", "prediction", "planning", "controller")

Metric = float | int | str | bool | None | list[Any] | dict[str, Any]


@dataclass(frozen=True)
class OracleResult:
    """One module judged at one frame."""

    module: Module
    timestamp_ms: int
    failed: bool
    metrics: dict[str, Metric] = field(default_factory=dict)
    thresholds: dict[str, float] = field(default_factory=dict)
    ids: tuple[str, ...] = ()
    #: Why the check could not run (missing input), else None.
    skipped: str | None = None


@dataclass
class RunContext:
    """A log with the parameters and derived facts every oracle needs."""

    log: RunLog
    params: Params
    ego_id: str | None = None
    problems: ProblemLog = field(default_factory=ProblemLog)
    _reported: set[tuple[str, str, str]] = field(default_factory=set, repr=False)

    @classmethod
    def create(cls, log: RunLog, params: Params) -> RunContext:
        ctx = cls(log, params)
        ctx.ego_id = find_ego_id(ctx)
        return ctx

    @property
    def tpf(self) -> int:
        return self.log.tpf

    def report(self, file: str, field_name: str, issue: str, ts: int | None = None) -> None:
        """An input problem found while judging (reported once per file, field and issue)."""
        key = (file, field_name, issue)
        if key not in self._reported:
            self._reported.add(key)
            self.problems.add(file, field_name, issue, CHECK_SKIPPED, "error", ts)

    def merge(self, problems: Iterable[Problem]) -> None:
        """Problems found by a copy of this context (a worker process), minus repeats."""
        for problem in problems:
            key = (problem.file, problem.field, problem.issue)
            if key not in self._reported:
                self._reported.add(key)
                self.problems.extend([problem])


#: The reference reads the ego's identity at this timestamp.
EGO_ID_TIMESTAMP_MS = 50
EGO_MATCH_DISTANCE_M = 0.5


def find_ego_id(ctx: RunContext) -> str | None:
    """The ego's actor id: the first actor (file order) within 0.5 m of the pose, per axis.

    reference: at exactly 50 ms; where that actors file or pose is missing, or no actor
    qualifies, the earliest analysed frame with both files (reported). corrected: the
    earliest analysed frame with both files directly.
    """
    log = ctx.log
    if ctx.params.semantics == "reference":
        found = _ego_at(log, EGO_ID_TIMESTAMP_MS)
        if found is not None:
            return found
        missing = [
            f"{name}/"
            for name, folder in (("actors", log.actors), ("pose", log.pose))
            if EGO_ID_TIMESTAMP_MS not in folder
        ]
        issue = (
            f"no {' or '.join(missing)} file at 50 ms"
            if missing
            else "no actor within 0.5 m of the pose at 50 ms"
        )
        ctx.report(
            log.file_of("actors", EGO_ID_TIMESTAMP_MS),
            "ego id",
            f"{issue} (the reference stops here; used the earliest frame)",
            EGO_ID_TIMESTAMP_MS,
        )
    for ts in log.unique_frames:
        if ts in log.actors and ts in log.pose:
            found = _ego_at(log, ts)
            if found is not None:
                return found
            break
    ctx.report("actors/", "ego id", "no actor matches the ego pose in the first frame")
    return None


def _ego_at(log: RunLog, ts: int) -> str | None:
    actors, pose = log.actors.get(ts), log.pose.get(ts)
    if actors is None or pose is None or len(actors) == 0:
        return None
    close = (np.abs(actors.location[:, 0] - pose.x) < EGO_MATCH_DISTANCE_M) & (
        np.abs(actors.location[:, 1] - pose.y) < EGO_MATCH_DISTANCE_M
    )
    rows = np.flatnonzero(close)
    return actors.ids[int(rows[0])] if rows.size else None
