"""What each parameter is: its unit, its range, and what it does in each semantics mode.

Why one table: the range is checked in the same words on the command line (``-p``,
``--config``) and by the nodes (whose ROS descriptors carry it as a
``FloatingPointRange`` / ``IntegerRange``), and the help, the ROS descriptions and
``docs/parameters.md`` say what a parameter does from the same text, so they cannot drift.
A value out of range (``safety_margin=-1``, ``nan``, ``window_s=-3``) would silently change
a verdict; it is refused instead, in one line naming the range.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from ads_rca.errors import ConfigError
from ads_rca.foundation.text import short_repr


@dataclass(frozen=True)
class Range:
    """Inclusive bounds of a numeric parameter (``integer``: whole numbers only)."""

    low: float
    high: float
    integer: bool = False
    unit: str = ""

    def text(self) -> str:
        """``[0, 100] m``: as the refusal and the docs show it."""
        unit = f" {self.unit}" if self.unit else ""
        return f"[{_number_text(self.low)}, {_number_text(self.high)}]{unit}"

    def check(self, name: str, value: float) -> None:
        """Raise ConfigError unless ``low <= value <= high``: NaN never is, and infinity only
        where a bound is infinite (:data:`LINGER`'s "until stopped")."""
        if math.isnan(value) or not self.low <= value <= self.high:
            raise ConfigError(
                f"parameter {name}: {_number_text(value)} is out of range {self.text()}"
            )


@dataclass(frozen=True)
class Choice:
    """The values a text parameter may take (the first is its usual default)."""

    options: tuple[str, ...]
    integer: bool = False  # the interface of :class:`Range`: never a whole number

    def text(self) -> str:
        """``one of auto | 2d | 3d``: as the refusal and the docs show it."""
        return "one of " + " | ".join(self.options)

    def check(self, name: str, value: object) -> None:
        """Raise ConfigError unless ``value`` is one of the options."""
        if value not in self.options:
            raise ConfigError(f"parameter {name}: {short_repr(value)} is not {self.text()}")


def _number_text(value: float) -> str:
    if isinstance(value, float) and value.is_integer() and abs(value) < 1e15:
        return str(int(value))
    return f"{value:g}" if isinstance(value, float) else str(value)


@dataclass(frozen=True)
class ParamSpec:
    """One engine parameter: its range, and per mode what it does (a mode absent from
    ``effect`` does not read it)."""

    range: Range | Choice
    effect: Mapping[str, str] = field(default_factory=dict)

    def effect_in(self, mode: str) -> str:
        return self.effect.get(mode, "not read in this mode")


def _both(effect: str) -> dict[str, str]:
    """The same effect in both modes (the event rules are not a mode's)."""
    return {"reference": effect, "corrected": effect}


def _frames(low: int, high: int) -> Range:
    return Range(low, high, integer=True, unit="frames")


#: What ``effect_time_window`` does in ``corrected`` (the help's old example did nothing there).
_CORRECTED_WINDOW = (
    "a lower bound on the window: W = max(effect_time_window, round(window_s / frame period)) "
    "frames before the collision; it changes the verdict only when above round(window_s / "
    "frame period) (20 frames at the default 1 s and 20 Hz)"
)

#: Every engine threshold, in :class:`~ads_rca.params.Params` field order.
SPECS: dict[str, ParamSpec] = {
    "effect_time_window": ParamSpec(
        _frames(0, 100_000),
        {
            "reference": "a failing frame is counted as `collision` when its time is after "
            "(collision_frame - effect_time_window) frames, with no upper bound; else `safe`",
            "corrected": _CORRECTED_WINDOW,
        },
    ),
    "pred_score_threshold": ParamSpec(
        Range(0.0, 1000.0),
        {
            "reference": "prediction fails when the partner is within 4 m and error / distance "
            ">= this",
            "corrected": "displacement threshold = max(pred_abs_threshold, this x the distance "
            "the partner travelled over the horizon)",
        },
    ),
    "prediction_window": ParamSpec(
        _frames(1, 1000),
        {"corrected": "horizon of every clearance: prediction keys k < this, plan indices 1..this"},
    ),
    "perc_score_threshold": ParamSpec(
        Range(0.0, 1.0),
        {"reference": "perception fails when the mean matched IoU is below this"},
    ),
    "planning_toleration_future_step": ParamSpec(
        Range(0, 1000, integer=True, unit="plan steps"),
        {"reference": "plan indices below this use tolerance 0, later ones -planning_toleration"},
    ),
    "planning_toleration": ParamSpec(
        Range(0.0, 1000.0, unit="m"),
        {
            "reference": "tolerance of the plan-vs-prediction gap test from "
            "planning_toleration_future_step on"
        },
    ),
    "window_s": ParamSpec(
        Range(0.0, 3600.0, unit="s"),
        {
            "corrected": "the window in seconds: W = max(effect_time_window, round(window_s / "
            "frame period)) frames before the collision"
        },
    ),
    "perc_match_iou": ParamSpec(
        Range(0.0, 1.0),
        {"corrected": "a detection matches a gt box (optimal matching) only at IoU >= this"},
    ),
    "safety_margin": ParamSpec(
        Range(0.0, 100.0, unit="m"),
        {
            "corrected": "clearance below which a future state is a conflict (real conflict: "
            "c_gt < this; planning fails when c_plan < this)"
        },
    ),
    "understate_min": ParamSpec(
        Range(0.0, 100.0, unit="m"),
        {
            "corrected": "a clearance understatement (c_pwp - c_gt, c_raw - c_ref) below this is "
            "noise, not a failure"
        },
    ),
    "pred_abs_threshold": ParamSpec(
        Range(0.0, 1000.0, unit="m"),
        {"corrected": "floor of the displacement threshold (see pred_score_threshold)"},
    ),
    "max_decel": ParamSpec(
        Range(0.1, 100.0, unit="m/s²"),
        {
            "corrected": "braking limit: planning is not blamed when already braking at it, and "
            "the safer plan brakes at it"
        },
    ),
    "decel_tolerance": ParamSpec(
        Range(0.0, 100.0, unit="m/s²"),
        {"corrected": "braking within this of max_decel counts as at the limit"},
    ),
    "standstill_speed": ParamSpec(
        Range(0.0, 100.0, unit="m/s"),
        {"corrected": "a plan slower than this counts as standing still (planning)"},
    ),
    "control_horizon": ParamSpec(
        _frames(1, 1000),
        {"corrected": "control tracking errors are summed over this many steps per frame"},
    ),
    "control_speed_threshold": ParamSpec(
        Range(0.0, 1000.0, unit="m/s"),
        {
            "corrected": "speed tracking threshold = max(this, actuator_delay x the largest "
            "commanded deceleration)"
        },
    ),
    "actuator_delay": ParamSpec(
        Range(0.0, 10.0, unit="s"),
        {"corrected": "see control_speed_threshold"},
    ),
    "control_lateral_threshold": ParamSpec(
        Range(0.0, 100.0, unit="m"),
        {
            "corrected": "control fails when the summed lateral drift toward the partner exceeds "
            "this"
        },
    ),
    "min_persistence": ParamSpec(
        _frames(1, 1000),
        {
            "corrected": "perception and prediction failures count only in runs at least this "
            "long inside the window"
        },
    ),
    "control_min_persistence": ParamSpec(_frames(1, 1000), {"corrected": "the same for control"}),
    "planning_min_persistence": ParamSpec(_frames(1, 1000), {"corrected": "the same for planning"}),
    "heading_min_step": ParamSpec(
        Range(0.0, 100.0, unit="m"),
        {"corrected": "predicted motion shorter than this keeps the previous heading"},
    ),
    "perception_check": ParamSpec(
        Choice(("auto", "2d", "3d")),
        {
            "corrected": "which perception rule: 2d (image boxes), 3d (bird's-eye boxes) or "
            "auto (2d when the log has 2-D detections and ground truth, else 3d when it has "
            "tracked objects or 3-D detections)"
        },
    ),
    "perception_3d_source": ParamSpec(
        Choice(("auto", "tracked", "detected")),
        {
            "corrected": "the 3-D rule judges tracked objects or 3-D detections; auto: tracked "
            "objects when the log has any"
        },
    ),
    "perc3d_match_iou": ParamSpec(
        Range(0.0, 1.0),
        {"corrected": "a perceived 3-D object matches an actor only at bird's-eye IoU >= this"},
    ),
    "perc3d_match_distance": ParamSpec(
        Range(0.0, 100.0, unit="m"),
        {
            "corrected": "a small actor (perc3d_small_area) also matches a perceived object "
            "whose centre is at most this far"
        },
    ),
    "perc3d_small_area": ParamSpec(
        Range(0.0, 1000.0, unit="m²"),
        {"corrected": "actors with a smaller bird's-eye area are matched by distance too"},
    ),
    "perc3d_range": ParamSpec(
        Range(0.0, 100_000.0, unit="m"),
        {
            "corrected": "sensing range: the 3-D rule counts actors and perceived objects "
            "within this distance of the ego"
        },
    ),
    "perc3d_velocity_error": ParamSpec(
        Range(0.0, 1000.0, unit="m/s"),
        {
            "corrected": "a perceived velocity off by more than this is tested over the "
            "stack's whole plan: perception fails if it made the partner look safer"
        },
    ),
    "noise_floor_s": ParamSpec(
        # bounded: every frame reads its floor frames, and a live window keeps them
        Range(0.0, 60.0, unit="s"),
        {
            "corrected": "each module's error floor is read from this long a stretch of the "
            "run, ending one effect window before the frame judged (0: no floors)"
        },
    ),
    "noise_floor_min_frames": ParamSpec(
        _frames(1, 100_000),
        {"corrected": "fewer floor frames than this give no floor (the fixed thresholds alone)"},
    ),
    "noise_floor_factor": ParamSpec(
        Range(0.0, 100.0),
        {
            "corrected": "an error must stand out from its floor by this many floors (control: "
            "this many times 2 sigma per sqrt of steps); 0 turns the floors off"
        },
    ),
    "event_time_s": ParamSpec(
        Range(-1.0, 31_536_000.0, unit="s"),
        _both(
            "the critical event to explain when the run knows no collision: seconds from the "
            "recording's first message (negative: none given; events are looked for)"
        ),
    ),
    "event_decel": ParamSpec(
        Range(0.1, 100.0, unit="m/s²"),
        _both("a hard brake: the ego decelerating at this or more (over 0.2 s)"),
    ),
    "event_clearance": ParamSpec(
        Range(0.0, 100.0, unit="m"),
        _both("a near miss: an object's box this close to the ego's, or closer"),
    ),
    "event_ttc_s": ParamSpec(
        Range(0.0, 60.0, unit="s"),
        _both("a near miss: a collision within this time, both keeping their velocity"),
    ),
}


#: The log reader's parameter (not an engine threshold; ``commands/input_args.py``).
MAX_FILE_MB = Range(0.001, 1_048_576.0, unit="MB")
#: A node's timeout or period, in seconds (up to an hour).
SECONDS = Range(0.0, 3600.0, unit="s")
#: How long the Zenoh bridge serves a run to late dashboards after its verdict
#: (``--zenoh-linger``, ``linger_s``): inf serves it until the bridge is stopped.
LINGER = Range(0.0, math.inf, unit="s")
#: Stack mode's ``episode_rewind_s``: how far the reference stamps may go back before a new
#: episode begins (0: never; up to a day).
EPISODE_REWIND = Range(0.0, 86_400.0, unit="s")
#: Playback speed relative to log time (the player's ``rate``, ``--rate``; 0 = no clock).
RATE = Range(0.0, 1000.0)
#: ``replay`` / ``demo --timeout``: seconds to wait for the verdict (at most a week).
PLAYBACK_TIMEOUT = Range(0.001, 604800.0, unit="s")


def check_value(name: str, value: Any, bounds: Range | Choice) -> int | float | str:
    """``value`` checked against a parameter's range or choices (see :func:`check_number`)."""
    if isinstance(bounds, Choice):
        bounds.check(name, value)
        return str(value)
    return check_number(name, value, bounds)


def check_number(name: str, value: Any, bounds: Range) -> int | float:
    """``value`` (a number, or text of one) as the parameter's type, within ``bounds``;
    else ConfigError naming the parameter (and the range)."""
    if isinstance(value, bool):
        raise ConfigError(f"parameter {name}: {short_repr(value)} is not a number")
    try:
        number = float(value)
    except (TypeError, ValueError, OverflowError):
        raise ConfigError(f"parameter {name}: {short_repr(value)} is not a number") from None
    if bounds.integer and math.isfinite(number):
        if not number.is_integer():
            raise ConfigError(f"parameter {name}: {short_repr(value)} is not an integer")
        bounds.check(name, int(number))
        return int(number)
    bounds.check(name, number)
    return number
