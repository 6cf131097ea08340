"""Fault injection: which module misbehaves, from which frame, and how.

One fault, one module, from an onset frame; every module downstream reacts to the faulty
output. The onset is placed just before the fault-free twin first had to react to the
partner (its planner braked for it), so the fault is what turns a near miss into a crash.

- ``perception`` (= ``perception:missed``): the partner is never detected again; its track
  coasts, then is dropped, so no raw prediction links to it. Three 3-D variants keep the
  partner detected (its 2-D box stays as the camera sees it) but perceive it so that it seems
  to clear the ego's path; the tracker, the raw predictions and the planner follow
  (:mod:`ads_rca.synth.perception3d` says how much):
  ``perception:shifted`` (its position moved sideways away from the ego's path),
  ``perception:shrunk`` (its extent shrunk) and ``perception:velocity`` (its velocity wrong:
  a braking lead not braking, oncoming or crossing traffic standing).
- ``prediction``: the partner gets an optimistic wrong motion model (see
  :func:`ads_rca.synth.prediction.wrong_model`) in both prediction files.
- ``planning``: the planner ignores the partner and keeps speed through the conflict.
- ``controller``: the brake realises only ``BRAKE_GAIN`` of the commanded deceleration.

A fault is named by the module it hits, as the verdict names it
(:data:`ads_rca.diagnosis.verdict.MODULES`),
so a label compares with a verdict without translation; a variant is ``module:variant``
(:func:`fault_module` gives its module). ``control``, the controller fault's former name,
is still accepted (:func:`canonical_fault`).
"""

from __future__ import annotations

from dataclasses import dataclass

FAULTS = ("none", "perception", "prediction", "planning", "controller")
#: How a perception fault perceives the partner; ``missed`` is what ``perception`` does.
PERCEPTION_VARIANTS = ("missed", "shifted", "shrunk", "velocity")
#: The variant faults beyond :data:`FAULTS` (``perception:missed`` is ``perception``).
VARIANT_FAULTS = tuple(f"perception:{v}" for v in PERCEPTION_VARIANTS[1:])
#: Every fault name the synthesiser takes.
ALL_FAULTS = (*FAULTS, "perception:missed", *VARIANT_FAULTS)
#: Former spellings still accepted → the name used everywhere.
FAULT_ALIASES = {"control": "controller"}
BRAKE_GAIN = 0.1
#: Frames between the onset and the twin's first reaction to the partner.
ONSET_LEAD = 3


@dataclass(frozen=True)
class FaultSpec:
    """An injected fault: the module, the first frame it is active and, for perception, how
    the partner is misperceived (one of :data:`PERCEPTION_VARIANTS`)."""

    module: str
    onset: int
    variant: str = "missed"

    @classmethod
    def named(cls, fault: str, onset: int) -> FaultSpec:
        """The fault called ``fault`` (a name in :data:`ALL_FAULTS`) from ``onset``."""
        module, _, variant = canonical_fault(fault).partition(":")
        return cls(module, onset, variant or "missed")

    def active(self, module: str, frame: int) -> bool:
        return self.module == module and frame >= self.onset

    def perceived(self, frame: int) -> str:
        """How perception misperceives the partner at ``frame``: a variant, or "" (no fault)."""
        return self.variant if self.active("perception", frame) else ""


NO_FAULT = FaultSpec("none", 1 << 30)


def canonical_fault(name: str) -> str:
    """The fault's name as outputs spell it (an old alias mapped; anything else unchanged)."""
    return FAULT_ALIASES.get(name, name)


def fault_module(name: str) -> str:
    """The module a fault name blames, as the verdict names it (``perception:shifted`` →
    ``perception``)."""
    return canonical_fault(name).partition(":")[0]


def onset_for(reaction_frame: int) -> int:
    """The onset frame given the twin's first reaction to the partner."""
    return max(reaction_frame - ONSET_LEAD, 2)
