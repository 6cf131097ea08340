"""Fault injection: which module misbehaves, from which frame, and how.

One fault, one module, from an onset frame; every module downstream reacts to the faulty
output. The onset is placed just before the fault-free twin first had to react to the
partner (its planner braked for it), so the fault is what turns a near miss into a crash.

- ``perception``: the partner is never detected again; its track coasts, then is dropped,
  so no raw prediction links to it.
- ``prediction``: the partner gets an optimistic wrong motion model (see
  :func:`ads_rca.synth.prediction.wrong_model`) in both prediction files.
- ``planning``: the planner ignores the partner and keeps speed through the conflict.
- ``control``: the brake realises only ``BRAKE_GAIN`` of the commanded deceleration.
"""

from __future__ import annotations

from dataclasses import dataclass

FAULTS = ("none", "perception", "prediction", "planning", "control")
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


def onset_for(reaction_frame: int) -> int:
    """The onset frame given the twin's first reaction to the partner."""
    return max(reaction_frame - ONSET_LEAD, 2)
