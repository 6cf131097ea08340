"""What travels between the live graph's nodes: frame markers and per-frame monitor results.

A monitor's result must reach the aggregator bit for bit (the verdict is computed again from
it), so the JSON form keeps NaN and infinity (``ads_rca.ros.jsontext`` writes them as null
with the strict ``"$nonfinite"`` annotation and reads them back) and every field of
:class:`~ads_rca.oracles.base.OracleResult`. Pure data, no rclpy.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from ads_rca.oracles.base import MODULES, Module, OracleResult
from ads_rca.problems import Problem

#: Player topic keys (docs/topics.md) → log folder, for the markers' ``published`` lists.
TOPIC_FOLDER: dict[str, str] = {
    "ego/odometry": "pose",
    "actors": "actors",
    "perception/detections": "bboxes",
    "perception/ground_truth": "bboxes_gt",
    "prediction/raw": "predictions",
    "prediction/with_perception": "predictions_with_perception",
    "planning/trajectory": "waypoint",
}


@dataclass(frozen=True, slots=True)
class FrameMarker:
    """One ``run/frame`` marker: a stamp, its analysed index and what was sent for it."""

    index: int | None  # None: a records-only stamp
    stamp_ms: int
    folders: frozenset[str] = frozenset()
    duplicate: bool = False

    @classmethod
    def from_document(cls, document: Mapping[str, Any]) -> FrameMarker:
        index = document.get("index")
        published = document.get("published") or ()
        folders = frozenset(TOPIC_FOLDER[str(k)] for k in published if str(k) in TOPIC_FOLDER)
        return cls(
            index if isinstance(index, int) else None,
            int(document.get("stamp_ms", 0)),
            folders,
            bool(document.get("duplicate", False)),
        )


@dataclass(frozen=True)
class LiveResult:
    """One module's judgement of one analysed frame, as a monitor publishes it."""

    index: int  # position in the run's analysed-frame list (the marker's index)
    result: OracleResult
    frame: int | float
    #: The collision frame the result was computed with (-1: none known).
    collision_frame: int = -1
    #: Why the result may differ from the offline one (inputs missing, look-ahead cut ...).
    incomplete: tuple[str, ...] = ()
    revision: int = 0
    ego_id: str | None = None
    partner_id: str | None = None
    problems: tuple[Problem, ...] = ()
    compute_s: float = 0.0  # oracle time
    wait_s: float = 0.0  # from the frame's marker arriving to the result
    session: str = ""  # the monitor process's start token
    run: str = ""  # the run judged (the player's run id; "" = none known)
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def module(self) -> Module:
        return self.result.module

    @property
    def stamp_ms(self) -> int:
        return self.result.timestamp_ms

    def to_document(self) -> dict[str, Any]:
        r = self.result
        return {
            "module": r.module,
            "index": self.index,
            "stamp_ms": r.timestamp_ms,
            "frame": self.frame,
            "failed": r.failed,
            "skipped": r.skipped,
            "ids": list(r.ids),
            "metrics": plain(r.metrics),
            "thresholds": plain(r.thresholds),
            "collision_frame": self.collision_frame,
            "incomplete": list(self.incomplete),
            "revision": self.revision,
            "ego_id": self.ego_id,
            "partner_id": self.partner_id,
            "problems": [p.to_dict() for p in self.problems],
            "compute_s": self.compute_s,
            "wait_s": self.wait_s,
            "session": self.session,
            **({"run": self.run} if self.run else {}),
            **self.extra,
        }

    @classmethod
    def from_document(cls, d: Mapping[str, Any]) -> LiveResult:
        module = str(d["module"])
        if module not in MODULES:
            raise ValueError(f"unknown module {module!r}")
        result = OracleResult(
            module,
            int(d["stamp_ms"]),
            bool(d["failed"]),
            dict(d.get("metrics") or {}),
            {str(k): v for k, v in (d.get("thresholds") or {}).items()},
            tuple(str(i) for i in d.get("ids") or ()),
            d.get("skipped"),
        )
        return cls(
            index=int(d["index"]),
            result=result,
            frame=d["frame"],
            collision_frame=int(d.get("collision_frame", -1)),
            incomplete=tuple(d.get("incomplete") or ()),
            revision=int(d.get("revision", 0)),
            ego_id=d.get("ego_id"),
            partner_id=d.get("partner_id"),
            problems=tuple(problem_from_dict(p) for p in d.get("problems") or ()),
            compute_s=float(d.get("compute_s", 0.0)),
            wait_s=float(d.get("wait_s", 0.0)),
            session=str(d.get("session", "")),
            run=str(d.get("run") or ""),
        )


def problem_from_dict(d: Mapping[str, Any]) -> Problem:
    ts = d.get("timestamp_ms")
    return Problem(
        str(d.get("file", "")),
        str(d.get("field", "")),
        str(d.get("issue", "")),
        str(d.get("action", "")),
        "warning" if d.get("severity") == "warning" else "error",
        int(ts) if isinstance(ts, int) else None,
    )


def plain(value: Any) -> Any:
    """JSON-ready without loss: numpy scalars as Python numbers, tuples as lists (NaN kept)."""
    if isinstance(value, bool | int | float | str) or value is None:
        return value
    if isinstance(value, Mapping):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [plain(v) for v in value]
    if hasattr(value, "tolist"):  # numpy scalar or array
        return plain(value.tolist())
    return str(value)


def new_problems(problems: Iterable[Problem], seen: set[tuple[str, str, str]]) -> list[Problem]:
    """Problems not reported before (by file, field and issue); ``seen`` is updated."""
    out = []
    for problem in problems:
        key = (problem.file, problem.field, problem.issue)
        if key not in seen:
            seen.add(key)
            out.append(problem)
    return out
