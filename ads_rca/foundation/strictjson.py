"""Strict JSON out, the same values back: the one convention for NaN and infinity.

RFC 8259 JSON has no NaN or Infinity. Python's json module writes them as literals that
strict parsers (orjson, JavaScript's ``JSON.parse``, jq, ...) reject, so every JSON document
this project emits goes through :func:`to_strict` (docs/topics.md, "Non-finite numbers"):

- each non-finite float becomes ``null``;
- the top-level object gets one more key, ``"$nonfinite"``: a map from the JSON Pointer
  (RFC 6901, into the document as written) of each such ``null`` to what it was: ``"nan"``,
  ``"inf"`` or ``"-inf"``;
- a document whose top level is not an object (a list, a bare number) is wrapped:
  ``{"$value": <document>, "$nonfinite": {"/$value/...": ...}}``;
- so that a log's own keys can never pass for the annotation, whenever a document is
  annotated every top-level key made of ``$`` signs and ``nonfinite`` or ``value`` gains one
  more leading ``$`` (``"$nonfinite"`` → ``"$$nonfinite"``), and a document that has a
  top-level ``"$nonfinite"`` key of its own is always annotated (maybe with an empty map).

:func:`from_strict` undoes all of it exactly. A document with only finite numbers and no
such key comes out unchanged, so its text is what it was before the convention existed.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

#: Top-level key of the annotation: JSON Pointer → "nan" | "inf" | "-inf".
NONFINITE_KEY = "$nonfinite"
#: Key of the wrapper around a document whose top level is not an object.
VALUE_KEY = "$value"

_RESERVED = re.compile(r"^\$+(?:nonfinite|value)$")
_ESCAPED = re.compile(r"^\$\$+(?:nonfinite|value)$")
_INDEX = re.compile(r"^(?:0|[1-9][0-9]*)$")
_KIND_VALUE = {"nan": math.nan, "inf": math.inf, "-inf": -math.inf}


def nonfinite_kind(value: float) -> str:
    """``"nan"``, ``"inf"`` or ``"-inf"``."""
    return "nan" if math.isnan(value) else "inf" if value > 0 else "-inf"


def all_finite(document: object) -> bool:
    """True when no float anywhere in the document is NaN or infinite."""
    if isinstance(document, float):
        return math.isfinite(document)
    if isinstance(document, Mapping):
        return all(all_finite(v) for v in document.values())
    if isinstance(document, list | tuple):
        return all(all_finite(v) for v in document)
    return True


def to_strict(document: object) -> Any:
    """The document as strict-JSON-ready data (see the module doc): non-finite floats as
    None plus the annotation; numpy scalars and arrays as Python values, tuples as lists,
    keys as strings. Always a new structure. Apply it once: its output has a top-level
    ``"$nonfinite"`` of its own, which a second pass would escape like a log's key."""
    found: list[_Found] = []
    plain = _walk(document, (), found)
    forced = isinstance(plain, dict) and NONFINITE_KEY in plain
    if not found and not forced:
        return plain
    if not isinstance(plain, dict):
        return {VALUE_KEY: plain, NONFINITE_KEY: _annotation(found, "/" + VALUE_KEY)}
    out = {_escape(k): v for k, v in plain.items()}
    annotation = _annotation(found, "")
    if any(map(_RESERVED.match, plain)):  # the pointers name the keys as escaped
        annotation = {_escape_first(p): kind for p, kind in annotation.items()}
    out[NONFINITE_KEY] = annotation
    return out


def from_strict(document: Any) -> Any:
    """The document :func:`to_strict` was given (for JSON just parsed: modified in place).

    Anything without a top-level ``"$nonfinite"`` object is returned as it is; annotation
    entries that do not point at a ``null`` are ignored.
    """
    if not isinstance(document, dict) or not isinstance(document.get(NONFINITE_KEY), dict):
        return document
    annotation = document.pop(NONFINITE_KEY)
    for pointer, kind in annotation.items():
        if isinstance(pointer, str) and kind in _KIND_VALUE:
            _restore(document, pointer, _KIND_VALUE[kind])
    if VALUE_KEY in document:
        return document[VALUE_KEY]
    return {(k[1:] if _ESCAPED.match(k) else k): v for k, v in document.items()}


def dumps(document: object, indent: int | None = None) -> str:
    """Strict JSON text of a document (compact, or indented like ``json.dumps``)."""
    separators = (",", ":") if indent is None else None
    return json.dumps(to_strict(document), indent=indent, separators=separators, allow_nan=False)


def loads(text: str | bytes) -> Any:
    """Parse JSON text and undo the convention (NaN/Infinity literals are also read)."""
    return from_strict(json.loads(text))


#: Values the walk copies as they are (exact types: subclasses take the general path).
_PLAIN = frozenset((str, int, bool, type(None)))

#: A non-finite float the walk found: its container's JSON Pointer tokens, its own token
#: (None when the tokens are its own: a value :func:`_general` was given), the value.
_Found = tuple[tuple[str, ...], str | None, float]
#: The non-finite floats found in a part of a document, in document order.
NonFinite = list[_Found]


class StrictValue:
    """A value of a document made strict already, where it sits (:func:`strict_items`):
    :func:`to_strict` takes it as it is, with the non-finite values found in it
    (``nonfinite``, pointers from the document's root) in its place in the annotation."""

    nonfinite: NonFinite


def strict_items(items: list[Any], key: str, first: int) -> tuple[list[Any], NonFinite]:
    """Items ``first``, ``first + 1``... of the list under the top-level ``key`` of a
    document, made strict as :func:`to_strict` makes them there, and the non-finite values
    found in them (for a :class:`StrictValue` holding the list, made part by part)."""
    found: NonFinite = []
    return _walk_items(list(items), (key,), found, first), found


def _walk(value: Any, path: tuple[str, ...], found: list[_Found]) -> Any:
    """The strict copy of ``value`` (``path``: its JSON Pointer tokens).

    A dict or list is copied at once (in C), then only its items that are not plain scalars
    are replaced: a verdict is mostly numbers, and a module's row holds a few lists, dicts
    and non-finite values among twenty. A non-finite value is recorded with its container's
    path (one tuple, shared), so its pointer costs nothing until the annotation. A dict with
    a key that is not a str is built by :func:`_pairs` instead. Anything else takes
    :func:`_general`.
    """
    kind = type(value)
    plain = _PLAIN
    if kind is dict:
        out = dict(value)
        mark = len(found)
        for key, item in out.items():
            if type(key) is not str:
                del found[mark:]  # _pairs finds them again, in the same order
                return _pairs(value.items(), path, found)
            kind = type(item)
            if kind in plain or (kind is float and item - item == 0.0):  # 0: finite
                continue
            out[key] = _replaced(item, kind, path, key, found)
        return out
    if kind is list or kind is tuple:
        return _walk_items(list(value), path, found)
    return _general(value, path, found)


def _walk_items(
    items: list[Any], path: tuple[str, ...], found: list[_Found], first: int = 0
) -> list[Any]:
    """``items`` (a copy, replaced in place) made strict: items ``first``, ``first + 1``...
    of the list at ``path``."""
    plain = _PLAIN
    for index, item in enumerate(items):
        kind = type(item)
        if kind in plain or (kind is float and item - item == 0.0):
            continue
        items[index] = _replaced(item, kind, path, str(first + index), found)
    return items


def _replaced(item: Any, kind: type, path: tuple[str, ...], token: str, found: list[_Found]) -> Any:
    """The strict value of a container's item that is no plain scalar (``kind``: its
    type, ``token``: its key or index there): a non-finite float as None (recorded), an
    empty dict or list as a new one, anything else walked."""
    if kind is float:
        found.append((path, token, item))
        return None
    if (kind is dict or kind is list) and not item:
        return kind()
    return _walk(item, (*path, token), found)


def _pairs(
    pairs: Iterable[tuple[Any, Any]], path: tuple[str, ...], found: list[_Found]
) -> dict[str, Any]:
    """A mapping that is not a plain dict of str keys: each key as str, each value walked."""
    out: dict[str, Any] = {}
    for key, item in pairs:
        token = key if type(key) is str else str(key)
        out[token] = _walk(item, (*path, token), found)
    return out


def _general(value: object, path: tuple[str, ...], found: list[_Found]) -> Any:
    if isinstance(value, StrictValue):
        found.extend(value.nonfinite)
        return value
    if isinstance(value, float):
        if math.isfinite(value):
            return value
        found.append((path, None, value))
        return None
    if isinstance(value, str | int) or value is None:
        return value
    if isinstance(value, Mapping):
        return _pairs(value.items(), path, found)
    if isinstance(value, list | tuple):
        return _walk(list(value), path, found)
    if hasattr(value, "tolist") and callable(value.tolist):  # numpy scalar or array
        return _walk(value.tolist(), path, found)
    return value


def _annotation(found: list[_Found], root: str) -> dict[str, str]:
    """Pointer → kind for each value found, in document order (the map is written in it).

    A container's values come one after another: its pointer is made once for them."""
    out: dict[str, str] = {}
    last: tuple[str, ...] | None = None
    prefix = ""
    for path, token, value in found:
        if path is not last:
            last = path
            prefix = root + _pointer(path) + "/"
        if token is None:
            pointer = prefix[:-1]
        elif "~" in token or "/" in token:
            pointer = prefix[:-1] + _pointer((token,))
        else:
            pointer = prefix + token
        out[pointer] = nonfinite_kind(value)
    return out


def _escape(key: str) -> str:
    return "$" + key if _RESERVED.match(key) else key


def _escape_first(pointer: str) -> str:
    """The pointer with its first token escaped (a reserved key has no ``~`` nor ``/``)."""
    first, slash, rest = pointer[1:].partition("/")
    return "/" + _escape(first) + slash + rest


def _pointer(tokens: Sequence[str]) -> str:
    joined = "/" + "/".join(tokens)
    if "~" not in joined and joined.count("/") == len(tokens):  # nothing to escape (usual)
        return joined
    return "".join("/" + t.replace("~", "~0").replace("/", "~1") for t in tokens)


def _restore(document: dict[str, Any], pointer: str, value: float) -> None:
    """Put ``value`` where ``pointer`` names a null; do nothing if it names anything else."""
    if not pointer.startswith("/"):
        return
    tokens = [t.replace("~1", "/").replace("~0", "~") for t in pointer[1:].split("/")]
    container: object = document
    for token in tokens[:-1]:
        container = _child(container, token)
    last = tokens[-1]
    if isinstance(container, dict) and last in container and container[last] is None:
        container[last] = value
    elif isinstance(container, list):
        index = _index(container, last)
        if index is not None and container[index] is None:
            container[index] = value


def _child(container: object, token: str) -> object:
    if isinstance(container, dict):
        return container.get(token)
    if isinstance(container, list):
        index = _index(container, token)
        return None if index is None else container[index]
    return None


def _index(items: list[object], token: str) -> int | None:
    """A list index token as RFC 6901 spells it (no leading zeros), inside the list."""
    if _INDEX.match(token) and int(token) < len(items):
        return int(token)
    return None
