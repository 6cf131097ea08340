"""Which model inputs a run has, and so which modules can be judged.

A recording of a real stack may lack inputs a running log always has (no 2-D boxes, no
predictions on ground truth): a module whose inputs are absent is "not judged (no <input>)"
in every output, never a silent "no fault found". Each semantics mode says what its modules
need (:attr:`ads_rca.oracles.semantics.Semantics.requires`: per module, alternative sets of
inputs, any one of which suffices); the run says what it has: ``RunLog.inputs`` (a
recording's reader fills it, and the player sends it in the run metadata as ``inputs``), else
what its folders hold.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, TypeVar

from ads_rca.model import INPUT_STATES, InputStatus, RunLog

#: Every model input, in pipeline order (docs/recordings.md "Model inputs").
MODEL_INPUTS = (
    "ego",
    "actors",
    "detections_2d",
    "ground_truth_2d",
    "detections_3d",
    "tracked_objects",
    "predictions",
    "predictions_gt",
    "plan",
    "control",
    "collision",
    "clock",
)

#: The RunLog field holding each input's records (collision and clock have none).
INPUT_FIELDS = {
    "ego": "pose",
    "actors": "actors",
    "detections_2d": "bboxes",
    "ground_truth_2d": "bboxes_gt",
    "detections_3d": "detections_3d",
    "tracked_objects": "tracks_3d",
    "predictions": "predictions",
    "predictions_gt": "predictions_with_perception",
    "plan": "waypoints",
    "control": "controls",
}

JUDGED = "judged"
Key = TypeVar("Key", bound=str)
#: The key of the run metadata document that carries the input status to the live graph.
METADATA_KEY = "inputs"


def recorded(log: RunLog) -> bool:
    """The run says which inputs it has (a recording), rather than its folders showing it."""
    return bool(log.inputs or statuses_from_document(log.metadata.raw.get(METADATA_KEY)))


def input_status(log: RunLog) -> dict[str, InputStatus]:
    """Every model input's status: the reader's record (``log.inputs``, else the run
    metadata's ``inputs``), else what the log's records show (a running log: a folder with
    records is real, an empty one absent; the collision comes from metadata.json)."""
    recorded = log.inputs or statuses_from_document(log.metadata.raw.get(METADATA_KEY))
    if recorded:
        return {name: recorded.get(name, InputStatus("absent")) for name in MODEL_INPUTS}
    out: dict[str, InputStatus] = {}
    for name in MODEL_INPUTS:
        field = INPUT_FIELDS.get(name)
        if field is not None:
            held = bool(getattr(log, field))
            out[name] = InputStatus("real") if held else InputStatus("absent", "", "no records")
    out["collision"] = InputStatus("real", "metadata.json", "")
    out["clock"] = InputStatus("absent", "", "a log folder has no clock")
    return {name: out[name] for name in MODEL_INPUTS}


def statuses_to_document(statuses: Mapping[str, InputStatus]) -> dict[str, dict[str, str]]:
    """The JSON form (run metadata, verdict JSON, inspect)."""
    return {
        name: {"state": s.state, "source": s.source, "reason": s.reason}
        for name, s in statuses.items()
    }


def statuses_from_document(document: Any) -> dict[str, InputStatus]:
    """Read back :func:`statuses_to_document`'s form; anything malformed is ignored (the
    statuses are then computed from the records), unknown inputs and states dropped."""
    if not isinstance(document, Mapping):
        return {}
    out: dict[str, InputStatus] = {}
    for name, entry in document.items():
        if name not in MODEL_INPUTS or not isinstance(entry, Mapping):
            continue
        state = entry.get("state")
        if state in INPUT_STATES:
            source, reason = entry.get("source", ""), entry.get("reason", "")
            out[name] = InputStatus(
                state,
                source if isinstance(source, str) else "",
                reason if isinstance(reason, str) else "",
            )
    return out


def present(status: InputStatus) -> bool:
    return status.state != "absent"


def judged_modules(
    requires: Mapping[Key, Sequence[Sequence[str]]], statuses: Mapping[str, InputStatus]
) -> dict[Key, str]:
    """Per module: ``judged``, or ``not judged (no a, b)`` naming what the first alternative
    it could use lacks (the alternative missing the fewest inputs; the earlier on ties)."""
    out: dict[Key, str] = {}
    for module, alternatives in requires.items():
        missing = [
            [name for name in option if not present(statuses.get(name, InputStatus("absent")))]
            for option in alternatives
        ]
        if not alternatives or any(not lack for lack in missing):
            out[module] = JUDGED
        else:
            fewest = min(missing, key=len)
            out[module] = f"not judged (no {', '.join(fewest)})"
    return out


__all__ = [
    "INPUT_FIELDS",
    "JUDGED",
    "METADATA_KEY",
    "MODEL_INPUTS",
    "input_status",
    "judged_modules",
    "recorded",
    "statuses_from_document",
    "statuses_to_document",
]
