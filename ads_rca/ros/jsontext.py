"""Lossless JSON text for the contract's String payloads and Marker ``text`` fields.

orjson is fast and keeps key order, but writes NaN/Infinity as null and rejects integers
beyond 64 bits; log extras may hold either, so those documents fall back to the json module
(whose NaN/Infinity literals both decoders below read back).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import Any

import orjson


def dumps_json(document: Any) -> str:
    """Compact JSON; falls back to the json module for NaN/Infinity and huge ints (lossless)."""
    try:
        text = orjson.dumps(document).decode()
    except TypeError:  # int beyond 64 bits
        return json.dumps(document, separators=(",", ":"))
    if "null" in text and not _all_finite(document):
        return json.dumps(document, separators=(",", ":"))
    return text


def loads_json(text: str) -> Any:
    try:
        return orjson.loads(text)
    except orjson.JSONDecodeError:
        return json.loads(text)


def _all_finite(document: Any) -> bool:
    if isinstance(document, float):
        return math.isfinite(document)
    if isinstance(document, Mapping):
        return all(_all_finite(v) for v in document.values())
    if isinstance(document, list | tuple):
        return all(_all_finite(v) for v in document)
    return True
