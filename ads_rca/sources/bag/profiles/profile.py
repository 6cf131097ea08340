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
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from ads_rca.capabilities import MODEL_INPUTS
from ads_rca.contract import topics
from ads_rca.errors import ConfigError
from ads_rca.foundation.text import short_repr
from ads_rca.foundation.yaml_files import load_yaml
from ads_rca.sources.bag.profiles import BUILTIN_PROFILES
from ads_rca.sources.bag.profiles.decoders import DECODERS, FRAMES

#: The inputs that can time the frames, in the order a profile without ``reference`` tries.
REFERENCE_INPUTS = ("actors", "ego", "clock")
#: Which predicted path a prediction input takes.
PATHS = ("most_probable",)
BUILTIN_NAMES = BUILTIN_PROFILES

_TOP_KEYS = ("profile", "description", "reference", "contract", "inputs", "metadata")
_INPUT_KEYS = ("topic", "type", "frame", "path")
_METADATA_KEYS = ("camera_loc", "ego_role")
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
    """One model input's source: topic, ROS type (``pkg/msg/Type``), the frame its geometry
    is in, and (predictions) which path."""

    input: str
    topic: str
    type: str
    frame: str = "map"
    path: str = "most_probable"

    @property
    def source(self) -> str:
        """``/topic (pkg/msg/Type)``: how an input status names where it came from."""
        return f"{self.topic} ({self.type})"


@dataclass(frozen=True)
class Profile:
    """A checked profile: name, where it was read from, the inputs it names, run facts."""

    name: str
    file: str
    description: str
    reference: str
    inputs: Mapping[str, InputSpec]
    #: The camera's mounting in the ego frame (x forward, y right, z up), when given.
    camera_loc: tuple[float, float, float] | None = None
    ego_role: str = ""
    #: Read by the contract reader (the ``ads_rca`` profile), not by the profiled reader.
    contract: bool = False
    raw: Mapping[str, Any] = field(default_factory=dict, compare=False)

    def topics(self) -> dict[str, InputSpec]:
        """Topic name → the input it carries (a topic names one input: checked on load)."""
        return {spec.topic: spec for spec in self.inputs.values()}


def builtin_path(name: str) -> Path:
    """The package-data file of a built-in profile."""
    return Path(str(resources.files("ads_rca.sources.bag.profiles") / "builtin" / f"{name}.yaml"))


def matching_builtin(topics: Iterable[str]) -> str | None:
    """The built-in stack profile (not the contract) whose topics a bag carries most of, at
    least two of them: what to suggest for a bag read without a profile."""
    held = set(topics)
    best, best_count = None, 1
    for name in BUILTIN_NAMES:
        profile = load_profile(name)
        if profile.contract:
            continue
        count = len(held & {spec.topic for spec in profile.inputs.values()})
        if count > best_count:
            best, best_count = name, count
    return best


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
    reference = document.get("reference")
    if reference is None:
        reference = next((i for i in REFERENCE_INPUTS if i in inputs), None)
        if reference is None:
            raise ConfigError(
                f"{file}: reference: none given and the profile has none of "
                f"{', '.join(REFERENCE_INPUTS)} to time the frames"
            )
    elif reference not in REFERENCE_INPUTS or reference not in inputs:
        raise ConfigError(
            f"{file}: reference: {short_repr(reference)} is not an input of the profile among "
            f"{', '.join(REFERENCE_INPUTS)}"
        )
    camera_loc, ego_role = _metadata(file, document.get("metadata", {}))
    return Profile(
        name=name,
        file=file,
        description=description,
        reference=str(reference),
        inputs=inputs,
        camera_loc=camera_loc,
        ego_role=ego_role,
        contract=contract,
        raw=document,
    )


def contract_type(name: str) -> str | None:
    """The contract's message type of a model input (None: the contract has no topic)."""
    if name == "clock":
        return topics.MESSAGE_TYPE_NAMES[topics.CLOCK]
    folder = _CONTRACT_FOLDERS.get(name)
    return None if folder is None else topics.MESSAGE_TYPE_NAMES[topics.FOLDER_TOPICS[folder]]


def _input(file: str, key: object, value: object, contract: bool) -> InputSpec:
    where = f"inputs.{key}"
    if key not in MODEL_INPUTS:
        raise ConfigError(f"{file}: {where}: not a model input (one of {', '.join(MODEL_INPUTS)})")
    if not isinstance(value, dict):
        raise ConfigError(f"{file}: {where}: a mapping with 'topic' and 'type'")
    _known(file, f"{where}.", value, _INPUT_KEYS)
    topic = _text(file, f"{where}.topic", value.get("topic"))
    if not topic.startswith("/") or any(c.isspace() for c in topic):
        raise ConfigError(
            f"{file}: {where}.topic: {short_repr(topic)} is not an absolute topic name"
        )
    type_name = _text(file, f"{where}.type", value.get("type"))
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
    if contract:
        expected = contract_type(str(key))
        if expected is None or type_name != expected:
            wants = expected or "no contract topic"
            raise ConfigError(f"{file}: {where}.type: {type_name} (the contract's is {wants})")
    else:
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
    return InputSpec(str(key), topic, type_name, frame, path)


def _metadata(file: str, value: object) -> tuple[tuple[float, float, float] | None, str]:
    if not isinstance(value, dict):
        raise ConfigError(f"{file}: metadata: a mapping (camera_loc, ego_role)")
    _known(file, "metadata.", value, _METADATA_KEYS)
    camera = value.get("camera_loc")
    camera_loc: tuple[float, float, float] | None = None
    if camera is not None:
        numbers = [float(v) for v in camera if _is_number(v)] if isinstance(camera, list) else []
        if len(numbers) != 3 or len(camera) != 3 or not all(map(math.isfinite, numbers)):
            raise ConfigError(
                f"{file}: metadata.camera_loc: {short_repr(camera, 60)} is not [x, y, z]"
            )
        camera_loc = (numbers[0], numbers[1], numbers[2])
    ego_role = _text(file, "metadata.ego_role", value.get("ego_role", ""), empty=True)
    return camera_loc, ego_role


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
