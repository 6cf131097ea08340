"""Zenoh key expressions for the graph's results.

Two families. Raw CDR samples follow the zenoh-bridge-ros2dds convention: the ROS topic name
without its leading slash, under an optional prefix, so a remote ``zenoh-bridge-ros2dds``
re-publishes them into its own ROS graph. JSON for dashboards lives under
``<prefix>/ads_rca/...``: queryables on ``verdict``, ``status`` and ``frames``, published
samples on ``verdict.json``, ``status.json`` and ``modules/<module>.json``. Why the suffix:
the graph's default namespace is ``/ads_rca``, so the raw key of the verdict topic
(DiagnosticArray) is ``<prefix>/ads_rca/verdict`` itself; a ``.`` never occurs in a ROS
name, so a JSON sample can never share a key with a CDR one (a remote bridge would
re-publish it into ROS as a broken message).

A prefix is one or more plain chunks: no wildcard or reserved
character, no empty chunk, so a key built from it never matches more than it names.
"""

from __future__ import annotations

import re

from ads_rca.errors import ConfigError

#: The dashboards' subtree under the prefix.
DASHBOARD_ROOT = "ads_rca"
#: What a key chunk may hold: letters, digits and ``_ - . ~ +``; no ``* $ ? # @`` or space.
_CHUNK = re.compile(r"^[A-Za-z0-9_.~+-]+$")
#: Longest prefix accepted (a key carries it on every sample).
MAX_PREFIX = 200


def check_prefix(prefix: str, what: str = "prefix") -> str:
    """``prefix`` without surrounding slashes, refused in one line when a chunk is empty or
    holds a wildcard or reserved character ("" is no prefix)."""
    stripped = prefix.strip("/")
    if not stripped:
        return ""
    if len(stripped) > MAX_PREFIX:
        raise ConfigError(f"{what}: longer than {MAX_PREFIX} characters")
    for chunk in stripped.split("/"):
        if not _CHUNK.match(chunk) or not chunk.strip("."):  # "." and "..": path steps in a URL
            shown = chunk.encode("unicode_escape").decode("ascii")[:40]
            raise ConfigError(
                f"{what}: chunk {shown!r} is empty, only dots, or holds a character other than "
                "letters, digits and _ - . ~ +"
            )
    return stripped


def ros_key(topic: str, prefix: str = "") -> str:
    """The zenoh-bridge-ros2dds key of a ROS topic: its name without the leading slash,
    under ``prefix`` (``/rca/verdict`` → ``rca/verdict``; prefix ``car1`` →
    ``car1/rca/verdict``)."""
    name = check_prefix(topic, f"topic {topic[:60]!r}")
    if not name:
        raise ConfigError(f"topic {topic[:60]!r}: empty name")
    base = check_prefix(prefix)
    return f"{base}/{name}" if base else name


#: What a published JSON sample's key ends with (a queryable's key has no suffix).
SAMPLE_SUFFIX = ".json"


def sample_key(prefix: str, *parts: str) -> str:
    """The key of a published JSON sample: :func:`dashboard_key` + ``.json``."""
    return dashboard_key(prefix, *parts) + SAMPLE_SUFFIX


def dashboard_key(prefix: str, *parts: str) -> str:
    """``<prefix>/ads_rca/<parts>``: a queryable's key (``verdict``, ``status``,
    ``frames``); published samples add :data:`SAMPLE_SUFFIX` (:func:`sample_key`)."""
    base = check_prefix(prefix)
    tail = "/".join(check_prefix(part, "key part") for part in parts)
    head = f"{base}/{DASHBOARD_ROOT}" if base else DASHBOARD_ROOT
    return f"{head}/{tail}" if tail else head
