"""The controller: drives the ego along the plan to the next pose.

Without a fault it tracks the plan exactly (the next pose is plan point 1 at plan speed 1),
so every tracking innovation is zero. A control fault weakens the brake: only a fraction of
the commanded deceleration is realised, and the ego covers the distance its real speed
gives, ending up faster than planned and ahead of the plan toward the partner.
"""

from __future__ import annotations

from dataclasses import dataclass

DT = 0.05


@dataclass
class Controller:
    """Realises the planned speed change; ``brake_gain`` < 1 models a failing brake."""

    brake_gain: float = 1.0

    def step(self, s0: float, v0: float, plan_speed_1: float) -> tuple[float, float]:
        """Next (arc length, speed) from the current ones and the plan's speed at index 1."""
        v1 = plan_speed_1
        if plan_speed_1 < v0:
            v1 = v0 - self.brake_gain * (v0 - plan_speed_1)
        return s0 + 0.5 * (v0 + v1) * DT, v1
