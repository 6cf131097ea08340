"""Annotations: timed notes a run carries about itself (a CARLA run's ``events.json``).

An annotation marks a moment ("vehicle_cut_in at 19.0 s: Brake — Vehicle cutting in
ahead"); it is never a collision and never a verdict input. A reader puts a run's
annotations in its metadata under :data:`ANNOTATIONS_KEY`, so they travel with the run
metadata to the live graph; every consumer reads them back through
:func:`annotations_from_document`, which keeps only well-formed entries with bounded text
(a metadata document may come from a topic, so it is not trusted either).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from ads_rca.foundation.text import printable
from ads_rca.model import MAX_TIMESTAMP_MS

#: Key of the metadata document (and of the verdict JSON) holding the annotations.
ANNOTATIONS_KEY = "annotations"
#: The longest kind and text kept (longer ones are cut, with an ellipsis).
MAX_KIND = 64
MAX_TEXT = 200
#: The most annotations a run keeps (a fuzzer's event list is a few dozen).
MAX_ANNOTATIONS = 10_000


@dataclass(frozen=True, slots=True)
class Annotation:
    """One timed note: when (log milliseconds), what kind, what it says, which file."""

    timestamp_ms: int
    kind: str
    text: str
    source: str

    def to_dict(self) -> dict[str, Any]:
        return {
            "timestamp_ms": self.timestamp_ms,
            "kind": self.kind,
            "text": self.text,
            "source": self.source,
        }

    def line(self) -> str:
        """One terminal line, control characters escaped."""
        return printable(f"{self.timestamp_ms / 1000.0:g} s: {self.kind}: {self.text}")


def bounded(text: str, limit: int) -> str:
    """``text`` cut to ``limit`` characters (an ellipsis says so)."""
    return text if len(text) <= limit else text[: limit - 1] + "…"


def annotations_from_document(document: Mapping[str, Any]) -> list[Annotation]:
    """The well-formed annotations of a metadata document, in time order (others left out:
    a timestamp that is not an integer in the log's range, text that is not text)."""
    listed = document.get(ANNOTATIONS_KEY)
    if not isinstance(listed, list):
        return []
    out: list[Annotation] = []
    for entry in listed[:MAX_ANNOTATIONS]:
        if not isinstance(entry, Mapping):
            continue
        stamp, kind = entry.get("timestamp_ms"), entry.get("kind")
        text, source = entry.get("text", ""), entry.get("source", "")
        if not (isinstance(stamp, int) and not isinstance(stamp, bool)):
            continue
        if not 0 <= stamp <= MAX_TIMESTAMP_MS:
            continue
        if not (isinstance(kind, str) and isinstance(text, str) and isinstance(source, str)):
            continue
        out.append(
            Annotation(
                stamp, bounded(kind, MAX_KIND), bounded(text, MAX_TEXT), bounded(source, MAX_KIND)
            )
        )
    return sorted(out, key=lambda a: a.timestamp_ms)
