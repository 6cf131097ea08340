"""Thresholds and settings of the root-cause engine, with each semantics mode's defaults.

The same names are ROS parameters of the nodes, ``-p name=value`` options of the CLI and
keys of the YAML files in ``config/``. Every output records the mode and the values used.
Each value is checked against its range (:mod:`ads_rca.paramspec`) wherever it comes from.
"""

from __future__ import annotations

import textwrap
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, fields, replace
from typing import Any, Literal

from ads_rca.errors import ConfigError
from ads_rca.foundation.text import short_repr
from ads_rca.paramspec import SPECS, check_value

Semantics = Literal["reference", "corrected"]
SEMANTICS: tuple[Semantics, ...] = ("reference", "corrected")
DEFAULT_SEMANTICS: Semantics = "corrected"


@dataclass(frozen=True)
class Params:
    """Every threshold of both modes (each mode reads its own, ``Semantics.parameters``)."""

    semantics: Semantics = DEFAULT_SEMANTICS
    # Shared names.
    effect_time_window: int = 20  # frames
    pred_score_threshold: float = 0.1
    prediction_window: int = 10  # frames
    # reference only.
    perc_score_threshold: float = 0.5
    planning_toleration_future_step: int = 3
    planning_toleration: float = 2.0  # m
    # corrected only.
    window_s: float = 1.0
    perc_match_iou: float = 0.5
    safety_margin: float = 0.5  # m
    understate_min: float = 0.3  # m
    pred_abs_threshold: float = 0.5  # m
    max_decel: float = 8.0  # m/s²
    decel_tolerance: float = 0.5  # m/s²
    standstill_speed: float = 0.1  # m/s
    control_horizon: int = 10  # frames
    control_speed_threshold: float = 1.0  # m/s
    actuator_delay: float = 0.2  # s
    control_lateral_threshold: float = 0.3  # m
    min_persistence: int = 2  # frames (perception, prediction)
    control_min_persistence: int = 3
    planning_min_persistence: int = 1
    heading_min_step: float = 0.1  # m
    perception_check: str = "auto"  # auto | 2d | 3d
    perception_3d_source: str = "auto"  # auto | tracked | detected
    perc3d_match_iou: float = 0.3
    perc3d_match_distance: float = 1.0  # m
    perc3d_small_area: float = 2.0  # m²
    perc3d_range: float = 80.0  # m
    perc3d_velocity_error: float = 1.5  # m/s
    noise_floor_s: float = 3.0  # s of floor frames (the noise-floor rule)
    noise_floor_min_frames: int = 5
    noise_floor_factor: float = 1.5
    # Both modes: the critical event explained when the run knows no collision.
    event_time_s: float = -1.0  # s from the recording's first message; < 0: none given
    event_decel: float = 4.0  # m/s²
    event_clearance: float = 0.3  # m
    event_ttc_s: float = 1.0  # s

    def values(self, names: Iterable[str]) -> dict[str, Any]:
        """``{name: value}`` of the parameters ``names``, in that order (for outputs: a
        mode's ``Semantics.parameters``, an oracle's reported thresholds)."""
        return {name: getattr(self, name) for name in names}


#: Defaults that differ from the field defaults in reference mode.
REFERENCE_DEFAULTS: dict[str, Any] = {"effect_time_window": 10}

_FIELD_TYPES = {f.name: f.type for f in fields(Params)}


def make_params(
    semantics: str = DEFAULT_SEMANTICS, overrides: Mapping[str, Any] | None = None
) -> Params:
    """The mode's defaults with ``overrides`` applied (names checked, values converted)."""
    if semantics not in SEMANTICS:
        raise ConfigError(
            f"semantics must be one of {', '.join(SEMANTICS)}, not {short_repr(semantics)}"
        )
    mode: Semantics = "reference" if semantics == "reference" else "corrected"
    base = Params(semantics=mode)
    if mode == "reference":
        base = replace(base, **REFERENCE_DEFAULTS)
    changes = {name: _convert(name, value) for name, value in dict(overrides or {}).items()}
    changes.pop("semantics", None)
    return replace(base, **changes)


def params_from_sources(
    semantics: str | None,
    config: Mapping[str, Any],
    overrides: Mapping[str, Any],
    config_name: str | None = None,
) -> Params:
    """The parameters of a run from its sources: a chosen ``semantics`` (CLI flag, launch
    argument) wins, then ``overrides`` (``-p``), then the ``config`` file (its engine keys;
    a node's params file has others too), then the mode's defaults. A bad value in the
    config file is refused naming ``config_name``."""
    values = dict(overrides)
    # As given, never str()'d: make_params refuses anything but a mode's name, and str() of
    # a YAML alias bomb (a config file's semantics) would never end.
    mode = semantics or values.pop("semantics", None) or config.get("semantics", DEFAULT_SEMANTICS)
    from_file = engine_overrides(config)
    from_file.pop("semantics", None)
    try:
        make_params(mode, from_file)
    except ConfigError as error:
        raise ConfigError(f"{config_name}: {error}" if config_name else str(error)) from None
    merged = {**from_file, **values}
    merged.pop("semantics", None)
    return make_params(mode, merged)


def parse_assignments(items: list[str]) -> dict[str, str]:
    """``name=value`` strings (CLI ``-p``) into a dict; also accepts ROS's ``name:=value``."""
    out: dict[str, str] = {}
    for item in items:
        name, sep, value = item.replace(":=", "=", 1).partition("=")
        if not sep or not name.strip():
            raise ConfigError(f"-p expects name=value, got {short_repr(item)}")
        out[name.strip()] = value.strip()
    return out


def engine_overrides(values: Mapping[str, Any]) -> dict[str, Any]:
    """The entries of ``values`` that are engine parameters (nodes have others too)."""
    return {k: v for k, v in values.items() if k in _FIELD_TYPES}


def _convert(name: str, value: Any) -> Any:
    if name not in _FIELD_TYPES:
        known = ", ".join(sorted(_FIELD_TYPES))
        raise ConfigError(f"unknown parameter {short_repr(name)} (known: {known})")
    if name == "semantics":
        return value
    return check_value(name, value, SPECS[name].range)


def defaults_text(name: str) -> str:
    """``10 / 20``: the parameter's default in each mode, in :data:`SEMANTICS` order."""
    return " / ".join(str(getattr(make_params(mode), name)) for mode in SEMANTICS)


def parameters_help() -> str:
    """What every threshold does in each mode, its defaults and range (``--help``)."""
    lines = [
        f"parameters (-p NAME=VALUE, --config keys, ROS parameters of the nodes); default "
        f"{' / '.join(SEMANTICS)}, range:"
    ]
    for name, spec in SPECS.items():
        lines.append(f"  {name}: default {defaults_text(name)}, range {spec.range.text()}")
        for mode in SEMANTICS:
            lines += textwrap.wrap(
                spec.effect_in(mode), 88, initial_indent=f"    {mode}: ", subsequent_indent=" " * 6
            )
    return "\n".join(lines)


def parameters_markdown() -> str:
    """The same as a Markdown table (``docs/parameters.md``, checked by a test)."""
    head = " | ".join(f"in `{mode}`" for mode in SEMANTICS)
    lines = [
        f"| parameter | default ({' / '.join(SEMANTICS)}) | range | {head} |",
        "|---|---|---|" + "---|" * len(SEMANTICS),
    ]
    for name, spec in SPECS.items():
        effects = " | ".join(spec.effect_in(mode) for mode in SEMANTICS)
        lines.append(f"| `{name}` | {defaults_text(name)} | {spec.range.text()} | {effects} |")
    return "\n".join(lines)
