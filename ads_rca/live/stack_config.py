"""Stack mode's run facts and inputs, from parameters: what ``run/metadata`` says otherwise.

Beside a running stack there is no player to announce the frame period, the
camera mounting, the ego or which topic carries what. :class:`StackConfig` is all of that,
read from node parameters (names in :data:`STACK_PARAMETERS`, the same in
``config/stack_*.yaml``): the input that defines frames, each model input's topic and
layout (:mod:`ads_rca.contract.stack_layouts`), the period (given, or measured from the
reference stamps), the association slop, the ego id and the camera location. Every value
is checked here, one line naming the parameter. Pure: no rclpy.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from ads_rca.capabilities import INPUT_FIELDS, source_statuses
from ads_rca.contract import live_topics, topics
from ads_rca.contract.stack_layouts import CONTRACT, Layout, layout
from ads_rca.errors import ConfigError
from ads_rca.foundation.text import printable
from ads_rca.live.stamp_sync import SyncSettings
from ads_rca.model import FOLDER_FIELDS, FOLDERS, INPUTS_KEY, InputStatus, RunMetadata
from ads_rca.paramspec import EPISODE_REWIND, Range

#: ``stack_mode`` values: ``stack`` (a stack's topics), ``player`` (the player's contract) or
#: ``auto`` (stack when nobody publishes ``run/metadata``). Not on/off: YAML reads those as
#: booleans.
STACK_MODES = ("auto", "stack", "player")

#: Folders a stack can provide, in the model's order.
INPUT_FOLDERS: tuple[str, ...] = tuple(f for f in FOLDERS if f in topics.FOLDER_TOPICS)

#: A stack's run has no known end: the reference's look-ahead is bounded by the data.
UNBOUNDED_FRAMES = 1 << 40

_MS = Range(0.0, 3_600_000.0, unit="ms")
_METRES = Range(-1000.0, 1000.0, unit="m")

#: ``inputs.<folder>.layout`` value for an input the stack does not provide.
NOT_PROVIDED = "none"

#: The stack parameters of the monitors and the aggregator: name → (default, description
#: [, range]), and ``inputs.<folder>.topic`` / ``.layout`` for every input (below).
STACK_PARAMETERS: dict[str, tuple[Any, str] | tuple[Any, str, Range]] = {
    "stack_mode": (
        "auto",
        "Inputs: stack (a running stack's own topics, no player), player, or auto (stack "
        "when nobody publishes run/metadata).",
    ),
    "reference_input": ("pose", "The input whose header stamps define the frames."),
    "timesteps_per_frame": (
        0,
        "Stack mode: the frame period in ms (0: measured from the reference stamps).",
        Range(0, 3_600_000, integer=True, unit="ms"),
    ),
    "sync_slop_ms": (
        0.0,
        "Stack mode: an input joins the frame whose stamp is nearest within this (0: half "
        "a period).",
        _MS,
    ),
    "ego_id": ("", "Stack mode: the ego's actor id ('' = found by the mode's ego rule)."),
    "camera_loc.x": (0.0, "Stack mode: camera location x on the ego (m).", _METRES),
    "camera_loc.y": (0.0, "Stack mode: camera location y on the ego (m).", _METRES),
    "camera_loc.z": (0.0, "Stack mode: camera location z on the ego (m).", _METRES),
    "episode_rewind_s": (
        1.0,
        "Stack mode: the reference input's header stamps going back by more than this start "
        "a new episode (a stack or simulator restarted; 0: never).",
        EPISODE_REWIND,
    ),
    "stamp_jump_s": (
        10.0,
        "Stack mode: a reference header stamp more than this ahead of the newest one is "
        "implausible (a clock glitch) and skipped, counted, unless 3 in a row and another "
        "input's stamps confirm the jump (0: never skip).",
        EPISODE_REWIND,
    ),
    "inputs_best_effort": (
        False,
        "Stack mode: subscribe BEST_EFFORT (a stack publishing best effort; reliable "
        "publishers match too, but losses are not repaired).",
    ),
}
for _folder in INPUT_FOLDERS:
    STACK_PARAMETERS[f"inputs.{_folder}.topic"] = (
        "",
        f"Stack mode: the topic carrying {_folder} ('' = the contract's, under topic_namespace).",
    )
    STACK_PARAMETERS[f"inputs.{_folder}.layout"] = (
        CONTRACT,
        f"Stack mode: how that topic carries {_folder} ('{NOT_PROVIDED}': the stack does "
        "not provide it; see docs/live-graph.md).",
    )


@dataclass(frozen=True, slots=True)
class StackInput:
    """One provided input: its topic and layout."""

    folder: str
    topic: str
    layout: Layout


@dataclass(frozen=True)
class StackConfig:
    """Stack mode's run facts and inputs (see the module docstring)."""

    inputs: dict[str, StackInput]  #: provided inputs only, by folder
    reference: str = "pose"
    timesteps_per_frame: int = 0  #: 0: measured
    sync_slop_ms: float = 0.0  #: 0: half a period
    input_timeout_s: float = 5.0
    max_pending_frames: int = 1200
    ego_id: str = ""
    camera_loc: tuple[float, float, float] = (0.0, 0.0, 0.0)
    mode: str = "auto"
    best_effort: bool = False
    not_provided: tuple[str, ...] = field(default=())
    #: Stamps going back by more than this begin a new episode (0: never).
    episode_rewind_s: float = 1.0
    #: A reference stamp more than this ahead of the newest is skipped unless confirmed.
    stamp_jump_s: float = 10.0

    def __post_init__(self) -> None:
        if self.mode not in STACK_MODES:
            raise ConfigError(
                printable(f"parameter stack_mode: {self.mode!r} is not one of {STACK_MODES}")
            )
        if self.reference not in self.inputs:
            raise ConfigError(
                printable(
                    f"parameter reference_input: {self.reference!r} is not a provided input "
                    f"({', '.join(self.inputs) or 'none'})"
                )
            )

    @classmethod
    def from_values(
        cls,
        values: Mapping[str, Any],
        namespace: str = topics.DEFAULT_NAMESPACE,
        input_timeout_s: float = 5.0,
        max_pending_frames: int = 1200,
    ) -> StackConfig:
        """From node parameter values (names of :data:`STACK_PARAMETERS`; a topic left ''
        is the contract's under ``namespace``); ConfigError naming the parameter for a
        layout, topic or reference that cannot be used."""
        inputs: dict[str, StackInput] = {}
        absent: list[str] = []
        for folder in INPUT_FOLDERS:
            name = str(values.get(f"inputs.{folder}.layout", CONTRACT))
            if name == NOT_PROVIDED:
                absent.append(folder)
                continue
            topic = str(values.get(f"inputs.{folder}.topic", "")) or topics.topic_name(
                topics.FOLDER_TOPICS[folder], namespace
            )
            if not topic.startswith("/") or any(c.isspace() for c in topic):
                raise ConfigError(
                    printable(
                        f"parameter inputs.{folder}.topic: {topic!r} is not an absolute topic name"
                    )
                )
            inputs[folder] = StackInput(folder, topic, layout(folder, name))
        loc = tuple(float(values.get(f"camera_loc.{axis}", 0.0)) for axis in "xyz")
        return cls(
            inputs=inputs,
            reference=str(values.get("reference_input", "pose")),
            timesteps_per_frame=int(values.get("timesteps_per_frame", 0)),
            sync_slop_ms=float(values.get("sync_slop_ms", 0.0)),
            input_timeout_s=input_timeout_s,
            max_pending_frames=max_pending_frames,
            ego_id=str(values.get("ego_id", "")),
            camera_loc=(loc[0], loc[1], loc[2]),
            mode=str(values.get("stack_mode", "auto")),
            best_effort=bool(values.get("inputs_best_effort", False)),
            not_provided=tuple(absent),
            episode_rewind_s=float(values.get("episode_rewind_s", 1.0)),
            stamp_jump_s=float(values.get("stamp_jump_s", 10.0)),
        )

    def sync_settings(self, folders: Iterable[str], reference: str = "") -> SyncSettings:
        """Stamp synchronisation over the provided inputs among ``folders`` (the ones the
        judged modules read), keyed by folder; frames from ``reference`` ('' = the
        ``reference_input``)."""
        reference = reference or self.reference
        wanted = [f for f in INPUT_FOLDERS if f in set(folders) and f in self.inputs]
        return SyncSettings(
            inputs=tuple(f for f in wanted if f != reference),
            reference=reference,
            period_ms=float(self.timesteps_per_frame) or None,
            sync_slop_ms=self.sync_slop_ms or None,
            input_timeout_s=self.input_timeout_s,
            max_pending_frames=self.max_pending_frames,
        )

    def input_topics(self, folders: Iterable[str]) -> dict[str, str]:
        """Folder → topic of the inputs read for ``folders``: the reference first, then the
        provided ones among them (what the stamp sync expects)."""
        settings = self.sync_settings(folders)
        return {f: self.inputs[f].topic for f in (settings.reference, *settings.inputs)}

    def metadata(self, timesteps_per_frame: int) -> RunMetadata:
        """The run metadata these facts give (no collision known, no end known), with the
        inputs the stack provides (:data:`~ads_rca.model.INPUTS_KEY`): a module lacking one
        is "not judged", as ``diagnose`` says of a recording without it."""
        folder_of = {field_name: folder for folder, field_name in FOLDER_FIELDS.items()}
        given = {
            name: InputStatus("real", self.inputs[folder].topic, "")
            for name, folder in ((n, folder_of[f]) for n, f in INPUT_FIELDS.items())
            if folder in self.inputs
        }
        given["collision"] = InputStatus("real", live_topics.COLLISION, "")
        statuses = source_statuses(given, "the stack does not provide")
        return RunMetadata(
            timesteps_per_frame=timesteps_per_frame,
            camera_loc=self.camera_loc,
            collision_frame=-1,
            total_frames=UNBOUNDED_FRAMES,
            raw={
                "stack": {"ego_id": self.ego_id, "reference_input": self.reference},
                INPUTS_KEY: {name: status.to_dict() for name, status in statuses.items()},
            },
        )

    def derived(self) -> tuple[str, ...]:
        """What the layouts in use derive rather than carry (said on every result)."""
        return tuple(i.layout.derived for i in self.inputs.values() if i.layout.derived)


def period_to_frame_ms(period_ms: float) -> int:
    """A measured period as the metadata's integer milliseconds (at least 1)."""
    return max(1, math.floor(period_ms + 0.5))
