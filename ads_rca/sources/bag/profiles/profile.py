"""Profiles: which topic and message type carry each model input of a recording, and how.

A real stack's bag carries its own types on its own topics; a profile (YAML) names them per
model input (ego, actors, 3-D detections, predictions, ...), with the frame the geometry is
given in and the run facts the bag cannot carry (the camera's mounting). Built-ins ship as
package data (``ads_rca/sources/bag/profiles/builtin/<name>.yaml``); ``--profile FILE`` reads the
user's
own. A profile is checked completely when loaded, so a typo is one line naming the file and
key (``ConfigError``), not a silently absent input at diagnosis time. The ``ads_rca``
profile is this project's contract (``contract: true``): its bags are read by the contract
reader (``sources/bag/reader.py``), the profile only names the topics for ``inspect``.

An input may accept several types (``type: [current, legacy]``: a stack that changed its
message package, as Autoware did in 2024); the bag's stored type picks one. ``reference``
may list inputs: the first with a usable message times the frames (a real vehicle's
perception may not have run; the fall-back is said).
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path
from typing import Any

from ads_rca.capabilities import MODEL_INPUTS
from ads_rca.contract import topics
from ads_rca.contract.rosmsg import normalise_type
from ads_rca.errors import ConfigError
from ads_rca.foundation.text import short_repr
from ads_rca.foundation.yaml_files import load_yaml
from ads_rca.sources.bag.profiles import BUILTIN_PROFILES
from ads_rca.sources.bag.profiles.decoders import DECODERS, FRAMES, aliases_of

#: The inputs a profile without ``reference`` times the frames by, the first it has.
DEFAULT_REFERENCES = ("actors", "ego", "clock")
#: The inputs that can time the frames (a ``reference`` list tries them in its own order).
REFERENCE_INPUTS = (
    *DEFAULT_REFERENCES,
    "tracked_objects",
    "predictions",
    "detections_3d",
    "detections_2d",
)
#: Inputs a recording may carry that no module's rule reads: the vehicle's own velocity
#: report and the stack's fail-safe (MRM) state, series the core turns into events.
RECORDING_INPUTS = ("vehicle_velocity", "mrm_state")
#: Every input a profile may name.
PROFILE_INPUTS = (*MODEL_INPUTS, *RECORDING_INPUTS)
#: Which predicted path a prediction input takes.
PATHS = ("most_probable",)
BUILTIN_NAMES = BUILTIN_PROFILES

_TOP_KEYS = ("profile", "description", "reference", "contract", "inputs", "metadata")
_INPUT_KEYS = ("topic", "type", "frame", "path")
_METADATA_KEYS = ("camera_loc", "ego_role", "ego_size", "ego_box_offset")
#: The contract's input → the log folder its topic carries (the ``ads_rca`` profile).
_CONTRACT_FOLDERS = {
    "ego": "pose",
    "actors": "actors",
    "detections_2d": "bboxes",
    "ground_truth_2d": "bboxes_gt",
    "predictions": "predictions",
    "predictions_gt": "predictions_with_perception",
    "plan": "waypoint",
}


@dataclass(frozen=True, slots=True)
class InputSpec:
    """One model input's source: topic, ROS type (``pkg/msg/Type``; the one a writer
    writes), the other types it accepts, the frame its geometry is in, and (predictions)
    which path."""

    input: str
    topic: str
    type: str
    frame: str = "map"
    path: str = "most_probable"
    #: Further types the input accepts (a stack's legacy package), after ``type``.
    also: tuple[str, ...] = ()

    @property
    def types(self) -> tuple[str, ...]:
        """Every type the input accepts, ``type`` first."""
        return (self.type, *self.also)

    @property
    def source(self) -> str:
        """``/topic (pkg/msg/Type)``: how an input status names where it came from."""
        return f"{self.topic} ({self.type})"

    def accepts(self, stored: str) -> bool:
        """A topic stored with type ``stored`` carries this input."""
        return normalise_type(stored) in {normalise_type(t) for t in self.types}

    def as_stored(self, stored: str) -> InputSpec:
        """This input read from a topic of type ``stored`` (one it accepts)."""
        return replace(self, type=normalise_type(stored), also=())


@dataclass(frozen=True)
class Profile:
    """A checked profile: name, where it was read from, the inputs it names, run facts."""

    name: str
    file: str
    description: str
    #: The inputs that may time the frames, in the order they are tried.
    references: tuple[str, ...]
    inputs: Mapping[str, InputSpec]
    #: The camera's mounting in the ego frame (x forward, y right, z up), when given.
    camera_loc: tuple[float, float, float] | None = None
    ego_role: str = ""
    #: Read by the contract reader (the ``ads_rca`` profile), not by the profiled reader.
    contract: bool = False
    raw: Mapping[str, Any] = field(default_factory=dict, compare=False)
    #: Run facts the profile states for the metadata (``ego_size``, ``ego_box_offset``).
    facts: Mapping[str, Any] = field(default_factory=dict)

    @property
    def reference(self) -> str:
        """The input that times the frames when it has messages."""
        return self.references[0]

    def topics(self) -> dict[str, InputSpec]:
        """Topic name → the input it carries (a topic names one input: checked on load)."""
        return {spec.topic: spec for spec in self.inputs.values()}


def builtin_path(name: str) -> Path:
    """The package-data file of a built-in profile."""
    return Path(str(resources.files("ads_rca.sources.bag.profiles") / "builtin" / f"{name}.yaml"))


def load_profile(name_or_path: str | os.PathLike[str]) -> Profile:
    """A built-in profile by name, else the profile FILE at that path; ConfigError (one
    line, naming the file and key) for anything that is not a valid profile."""
    text = str(name_or_path)
    path = builtin_path(text) if text in BUILTIN_NAMES else Path(text)
    if text not in BUILTIN_NAMES and not os.path.lexists(path):
        raise ConfigError(f"{text}: no such profile (a file, or one of {', '.join(BUILTIN_NAMES)})")
    return parse_profile(load_yaml(path, "profile"), str(path))


def parse_profile(document: object, file: str) -> Profile:
    """A profile document checked field by field (see the module docstring)."""
    if not isinstance(document, dict):
        raise ConfigError(f"{file}: a profile is a mapping with 'profile' and 'inputs'")
    _known(file, "", document, _TOP_KEYS)
    name = _text(file, "profile", document.get("profile"))
    description = _text(file, "description", document.get("description", ""), empty=True)
    contract = document.get("contract", False)
    if not isinstance(contract, bool):
        raise ConfigError(f"{file}: contract: {short_repr(contract)} is not true or false")
    inputs_doc = document.get("inputs")
    if not isinstance(inputs_doc, dict) or not inputs_doc:
        raise ConfigError(f"{file}: inputs: a mapping of model input → topic and type")
    inputs = {str(key): _input(file, key, value, contract) for key, value in inputs_doc.items()}
    seen: dict[str, str] = {}
    for spec in inputs.values():
        if spec.topic in seen:
            raise ConfigError(
                f"{file}: inputs.{spec.input}.topic: {spec.topic} is already "
                f"inputs.{seen[spec.topic]}'s"
            )
        seen[spec.topic] = spec.input
    references = _references(file, document.get("reference"), inputs)
    camera_loc, ego_role, facts = _metadata(file, document.get("metadata", {}))
    return Profile(
        name=name,
        file=file,
        description=description,
        references=references,
        inputs=inputs,
        camera_loc=camera_loc,
        ego_role=ego_role,
        contract=contract,
        raw=document,
        facts=facts,
    )


def _references(file: str, value: object, inputs: Mapping[str, InputSpec]) -> tuple[str, ...]:
    """``reference``: one input or a list of them, each of :data:`REFERENCE_INPUTS` and of the
    profile; absent, the first of :data:`DEFAULT_REFERENCES` the profile has."""
    if value is None:
        found = next((i for i in DEFAULT_REFERENCES if i in inputs), None)
        if found is None:
            raise ConfigError(
                f"{file}: reference: none given and the profile has none of "
                f"{', '.join(DEFAULT_REFERENCES)} to time the frames"
            )
        return (found,)
    listed = value if isinstance(value, list) else [value]
    if not listed:
        raise ConfigError(f"{file}: reference: an empty list")
    for entry in listed:
        if entry not in REFERENCE_INPUTS or entry not in inputs:
            raise ConfigError(
                f"{file}: reference: {short_repr(entry)} is not an input of the profile among "
                f"{', '.join(REFERENCE_INPUTS)}"
            )
    if len(set(listed)) < len(listed):
        raise ConfigError(f"{file}: reference: {short_repr(value, 80)} names an input twice")
    return tuple(str(entry) for entry in listed)


def mismatch(spec: InputSpec, stored: str) -> str:
    """Why a topic stored with a type the input does not accept is not read: both types,
    and whether a decoder would read the stored one as this input (a legacy alias of an
    accepted type, or another type that carries it) the profile could list."""
    wants = " or ".join(spec.types)
    said = f"stored type {stored}, the profile's {spec.input} is {wants}"
    decoder = DECODERS.get(normalise_type(stored))
    if decoder is None or spec.input not in decoder.inputs:
        return f"{said} (no decoder reads {stored} as {spec.input})"
    accepted = {normalise_type(t) for t in spec.types}
    if accepted & {normalise_type(stored), *aliases_of(stored)}:
        kind = "a legacy alias of" if decoder.alias_of else "the current type of"
        related = next(t for t in spec.types if normalise_type(t) in aliases_of(stored))
        return (
            f"{said} ({stored} is {kind} {related}: list it in inputs.{spec.input}.type to read it)"
        )
    return f"{said} (a decoder reads {stored} as {spec.input}: list it in inputs.{spec.input}.type)"


def contract_type(name: str) -> str | None:
    """The contract's message type of a model input (None: the contract has no topic)."""
    if name == "clock":
        return topics.MESSAGE_TYPE_NAMES[topics.CLOCK]
    folder = _CONTRACT_FOLDERS.get(name)
    return None if folder is None else topics.MESSAGE_TYPE_NAMES[topics.FOLDER_TOPICS[folder]]


def _input(file: str, key: object, value: object, contract: bool) -> InputSpec:
    where = f"inputs.{key}"
    if key not in PROFILE_INPUTS or (contract and key in RECORDING_INPUTS):
        known = MODEL_INPUTS if contract else PROFILE_INPUTS
        raise ConfigError(f"{file}: {where}: not a model input (one of {', '.join(known)})")
    if not isinstance(value, dict):
        raise ConfigError(f"{file}: {where}: a mapping with 'topic' and 'type'")
    _known(file, f"{where}.", value, _INPUT_KEYS)
    topic = _text(file, f"{where}.topic", value.get("topic"))
    if not topic.startswith("/") or any(c.isspace() for c in topic):
        raise ConfigError(
            f"{file}: {where}.topic: {short_repr(topic)} is not an absolute topic name"
        )
    type_names = _types(file, f"{where}.type", value.get("type"))
    if contract and len(type_names) > 1:
        raise ConfigError(f"{file}: {where}.type: the contract has one type per input")
    for type_name in type_names:
        _check_type(file, where, str(key), type_name, contract)
    frame = _text(file, f"{where}.frame", value.get("frame", "map"))
    if frame not in FRAMES:
        raise ConfigError(
            f"{file}: {where}.frame: {short_repr(frame)} is not one of {', '.join(FRAMES)}"
        )
    path = _text(file, f"{where}.path", value.get("path", PATHS[0]))
    if path not in PATHS:
        raise ConfigError(
            f"{file}: {where}.path: {short_repr(path)} is not one of {', '.join(PATHS)}"
        )
    if "path" in value and key not in ("predictions", "predictions_gt"):
        raise ConfigError(f"{file}: {where}.path: only a prediction input takes a path")
    return InputSpec(str(key), topic, type_names[0], frame, path, type_names[1:])


def _types(file: str, where: str, value: object) -> tuple[str, ...]:
    """``type``: one type name, or a list of them (each once)."""
    listed = value if isinstance(value, list) else [value]
    names = tuple(_text(file, where, entry) for entry in listed)
    if not names:
        raise ConfigError(f"{file}: {where}: an empty list")
    if len({normalise_type(n) for n in names}) < len(names):
        raise ConfigError(f"{file}: {where}: {short_repr(value, 80)} names a type twice")
    return names


def _check_type(file: str, where: str, key: str, type_name: str, contract: bool) -> None:
    """The type can carry the input: the contract's own, or one a decoder reads so."""
    if contract:
        expected = contract_type(key)
        if expected is None or type_name != expected:
            wants = expected or "no contract topic"
            raise ConfigError(f"{file}: {where}.type: {type_name} (the contract's is {wants})")
        return
    decoder = DECODERS.get(type_name)
    if decoder is None:
        raise ConfigError(
            f"{file}: {where}.type: no decoder for {short_repr(type_name)} (known: "
            f"{', '.join(sorted(DECODERS))})"
        )
    if key not in decoder.inputs:
        raise ConfigError(
            f"{file}: {where}.type: {type_name} carries {', '.join(sorted(decoder.inputs))},"
            f" not {key}"
        )


def _metadata(
    file: str, value: object
) -> tuple[tuple[float, float, float] | None, str, dict[str, Any]]:
    """The camera's mounting, the ego's role name, and the run facts for the metadata."""
    if not isinstance(value, dict):
        raise ConfigError(f"{file}: metadata: a mapping ({', '.join(_METADATA_KEYS)})")
    _known(file, "metadata.", value, _METADATA_KEYS)
    camera_loc = _triple(file, "camera_loc", value.get("camera_loc"))
    ego_role = _text(file, "metadata.ego_role", value.get("ego_role", ""), empty=True)
    facts: dict[str, Any] = {}
    size = _triple(file, "ego_size", value.get("ego_size"), positive=True)
    if size is not None:
        facts["ego_size"] = list(size)
    offset = value.get("ego_box_offset")
    if offset is not None:
        if not _is_number(offset) or not math.isfinite(float(offset)):
            raise ConfigError(
                f"{file}: metadata.ego_box_offset: {short_repr(offset, 60)} is not a number (m)"
            )
        facts["ego_box_offset"] = float(offset)
    return camera_loc, ego_role, facts


def _triple(
    file: str, key: str, value: object, positive: bool = False
) -> tuple[float, float, float] | None:
    """A metadata value of three finite numbers (``positive``: each above 0), or None."""
    if value is None:
        return None
    numbers = [float(v) for v in value if _is_number(v)] if isinstance(value, list) else []
    ok = len(numbers) == 3 and isinstance(value, list) and len(value) == 3
    if not ok or not all(map(math.isfinite, numbers)) or (positive and min(numbers) <= 0):
        shape = "[length, width, height] in m, each above 0" if positive else "[x, y, z]"
        raise ConfigError(f"{file}: metadata.{key}: {short_repr(value, 60)} is not {shape}")
    return (numbers[0], numbers[1], numbers[2])


def _is_number(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _known(file: str, prefix: str, document: dict[Any, Any], keys: tuple[str, ...]) -> None:
    for key in document:
        if key not in keys:
            raise ConfigError(f"{file}: {prefix}{key}: unknown key (known: {', '.join(keys)})")


def _text(file: str, where: str, value: object, empty: bool = False) -> str:
    """A string value (non-empty unless ``empty``)."""
    if not isinstance(value, str):
        raise ConfigError(f"{file}: {where}: {short_repr(value, 60)} is not a string")
    if not empty and not value:
        raise ConfigError(f"{file}: {where}: empty")
    return value
