"""The YAML files a user names: parameters (``--config``, a launch ``params_file``), topic
remappings (``--remap``) and stack profiles (``--profile FILE``).

Read as the log reader reads its files (:func:`~ads_rca.foundation.files.read_regular`): only a
regular file, at most :data:`MAX_YAML_BYTES`, so a FIFO or ``/dev/zero`` named by mistake
is refused instead of hanging or filling memory. Text that is not UTF-8, is not YAML,
nests deeper than the parser recurses or holds a scalar the loader cannot build (an
integer of thousands of digits, an impossible date) is one :class:`ConfigError` line
naming the file, never a traceback. PyYAML's safe loader builds no objects but plain
ones, and aliases share one object, so a "billion laughs" document stays small; what
takes it apart (a value shown in an error) cuts it short.
"""

from __future__ import annotations

import os
from typing import Any

from ads_rca.errors import ConfigError
from ads_rca.foundation.files import Unreadable, read_regular

#: Far beyond any parameter, remapping or profile file (a profile is a few KB).
MAX_YAML_BYTES = 1 << 20


def load_yaml(path: str | os.PathLike[str], what: str) -> Any:
    """The document of YAML file ``path`` (``what`` names it in errors: "config",
    "profile"...); ConfigError, one line naming the file, when it cannot be had."""
    import yaml  # only a run given such a file needs it

    name = os.fspath(path)
    if not os.path.lexists(path):
        raise ConfigError(f"{name}: cannot read {what} (no such file)")
    data = read_regular(path, MAX_YAML_BYTES)
    if isinstance(data, Unreadable):
        issue = data.issue.replace(" (max_file_mb)", "")
        raise ConfigError(f"{name}: cannot read {what} ({issue})")
    try:
        return yaml.safe_load(data.decode("utf-8"))
    except (yaml.YAMLError, RecursionError, ValueError) as error:
        # ValueError: bytes that are not UTF-8, and what the safe loader's constructors
        # raise for a scalar it cannot make (an integer past Python's 4300-digit
        # conversion limit, a date like 2001-13-40).
        detail = " ".join(str(error).split())[:200] or type(error).__name__
        if isinstance(error, RecursionError):
            detail = "nested too deep"
        raise ConfigError(f"{name}: not a YAML {what} file: {detail}") from None


def load_config(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Parameters from a YAML file: a flat mapping, or a ROS 2 params file (any node)."""
    document = load_yaml(path, "config")
    if document is None:
        return {}
    if not isinstance(document, dict):
        raise ConfigError(f"{os.fspath(path)}: expected a mapping of parameter names to values")
    merged: dict[str, Any] = {}
    ros_sections = [v for v in document.values() if isinstance(v, dict) and "ros__parameters" in v]
    if ros_sections:
        for section in ros_sections:
            parameters = section["ros__parameters"] or {}
            if not isinstance(parameters, dict):
                raise ConfigError(f"{os.fspath(path)}: ros__parameters is not a mapping")
            merged.update(parameters)
        return merged
    return dict(document)
