"""The stack-mode settings the in-process stack tests run with: every stack parameter at
its default, with the facts a stack file gives (50 ms frames, the camera's place)."""

from __future__ import annotations

from typing import Any

from ads_rca.live.stack_config import STACK_PARAMETERS, StackConfig


def config(input_timeout_s: float = 1.0, **values: Any) -> StackConfig:
    defaults = {name: entry[0] for name, entry in STACK_PARAMETERS.items()}
    facts = {"timesteps_per_frame": 50, "camera_loc.x": 1.3, "camera_loc.z": 1.8}
    return StackConfig.from_values({**defaults, **facts, **values}, input_timeout_s=input_timeout_s)
