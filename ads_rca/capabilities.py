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

from collections.abc import Collection, Mapping, Sequence
from typing import TypeVar

from ads_rca.model import InputStatus, RunLog

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
#: How every "not judged (no ...)" reason starts (a result skipped for it is "no data").
NOT_JUDGED = "not judged"
Key = TypeVar("Key", bound=str)


def recorded(log: RunLog) -> bool:
    """The run says which inputs it has (a recording), rather than its folders showing it."""
    return bool(log.inputs)


def complete(inputs: Mapping[str, InputStatus]) -> dict[str, InputStatus]:
    """A recording's statuses for every model input (one it does not list is absent)."""
    return {name: inputs.get(name, InputStatus("absent")) for name in MODEL_INPUTS}


def input_status(log: RunLog) -> dict[str, InputStatus]:
    """Every model input's status: the reader's record (``log.inputs``; a log folder or the
    run metadata carries it as ``model_inputs``), else what the log's records show
    (:func:`held_status`)."""
    if log.inputs:
        return complete(log.inputs)
    held = {field for field in INPUT_FIELDS.values() if getattr(log, field)}
    return held_status(held, log.metadata.collision_known)


def held_status(fields: Collection[str], collision_known: bool = True) -> dict[str, InputStatus]:
    """The statuses of a running log whose RunLog ``fields`` hold records: those real, the
    others absent; the collision comes from metadata.json (absent when it gives no usable
    ``collision_frame``). The live aggregator, which holds no records, asks it with the
    folders the player's frame markers listed."""
    out: dict[str, InputStatus] = {}
    for name in MODEL_INPUTS:
        field = INPUT_FIELDS.get(name)
        if field is not None:
            out[name] = (
                InputStatus("real") if field in fields else InputStatus("absent", "", "no records")
            )
    out["collision"] = (
        InputStatus("real", "metadata.json", "")
        if collision_known
        else InputStatus("absent", "", "metadata.json gives no usable collision_frame")
    )
    out["clock"] = InputStatus("absent", "", "a log folder has no clock")
    return {name: out[name] for name in MODEL_INPUTS}


#: What each model input is, in words ("the source records no <this>").
INPUT_WORDS = {
    "ego": "ego pose",
    "actors": "actors",
    "detections_2d": "2-D detections",
    "ground_truth_2d": "2-D ground-truth boxes",
    "detections_3d": "3-D detections",
    "tracked_objects": "tracked objects",
    "predictions": "predictions",
    "predictions_gt": "predictions on ground truth",
    "plan": "plan",
    "control": "control commands",
    "collision": "collision",
    "clock": "clock",
}


def source_statuses(given: Mapping[str, InputStatus], lacking: str) -> dict[str, InputStatus]:
    """Every model input of a dataset's run: ``given``'s statuses, the others absent because
    ``lacking`` (e.g. "a parking-lot scene holds no") that input."""
    return {
        name: given.get(name) or InputStatus("absent", "", f"{lacking} {INPUT_WORDS[name]}")
        for name in MODEL_INPUTS
    }


def statuses_to_document(statuses: Mapping[str, InputStatus]) -> dict[str, dict[str, str]]:
    """The JSON form (verdict JSON, inspect)."""
    return {name: status.to_dict() for name, status in statuses.items()}


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
            out[module] = f"{NOT_JUDGED} (no {', '.join(fewest)})"
    return out


__all__ = [
    "INPUT_FIELDS",
    "JUDGED",
    "MODEL_INPUTS",
    "NOT_JUDGED",
    "complete",
    "held_status",
    "input_status",
    "judged_modules",
    "recorded",
    "source_statuses",
    "statuses_to_document",
]
