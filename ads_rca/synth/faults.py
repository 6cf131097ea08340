"""Fault injection: which module misbehaves, from which frame, and how.

One fault, one module, from an onset frame; every module downstream reacts to the faulty
output. The onset is placed just before the fault-free twin first had to react to the
partner (its planner braked for it), so the fault is what turns a near miss into a crash.

- ``perception``: the partner is never detected again; its track coasts, then is dropped,
  so no raw prediction links to it.
- ``prediction``: the partner gets an optimistic wrong motion model (see
  :func:`ads_rca.synth.prediction.wrong_model`) in both prediction files.
- ``planning``: the planner ignores the partner and keeps speed through the conflict.
- ``controller``: the brake realises only ``BRAKE_GAIN`` of the commanded deceleration.

A fault is named by the module it hits, as the verdict names it (:data:`ads_rca.verdict.MODULES`),
so a label compares with a verdict without translation. ``control``, this fault's former name,
is still accepted (:func:`canonical_fault`).
"""

from __future__ import annotations

from dataclasses import dataclass

FAULTS = ("none", "perception", "prediction", "planning", "controller")
#: Former spellings still accepted → the name used everywhere.
FAULT_ALIASES = {"control": "controller"}
BRAKE_GAIN = 0.1
#: Frames between the onset and the twin's first reaction to the partner.
ONSET_LEAD = 3


@dataclass(frozen=True)
class FaultSpec:
    """An injected fault: the module and the first frame it is active."""

    module: str
    onset: int

    def active(self, module: str, frame: int) -> bool:
        return self.module == module and frame >= self.onset


NO_FAULT = FaultSpec("none", 1 << 30)


def canonical_fault(name: str) -> str:
    """The fault's name as outputs spell it (an old alias mapped; anything else unchanged)."""
    return FAULT_ALIASES.get(name, name)


def onset_for(reaction_frame: int) -> int:
    """The onset frame given the twin's first reaction to the partner."""
    return max(reaction_frame - ONSET_LEAD, 2)
