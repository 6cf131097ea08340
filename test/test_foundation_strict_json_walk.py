"""The strict walk's shortcuts give what the plain per-item walk gave, object for object.

:func:`ads_rca.foundation.strictjson.to_strict` copies a dict or list in C and replaces only its
items
that are not plain scalars, records a non-finite value with its container's shared path,
and makes the annotation's pointers once per container. The reference below is the walk it
replaced (one Python step per item, a path list copied for each non-finite value), kept
here verbatim in substance: on any document, both must give the same types, values, key
order (the ``"$nonfinite"`` map's order is written to the file) and the same leaf objects.
"""

from __future__ import annotations

import enum
import json
import math
import re
from collections import OrderedDict
from collections.abc import Iterable, Mapping
from types import MappingProxyType
from typing import Any

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from ads_rca.foundation.strictjson import NONFINITE_KEY, VALUE_KEY, from_strict, to_strict

NAN, INF = math.nan, math.inf

# --- the walk before the shortcuts (reference) ----------------------------------------------

_RESERVED = re.compile(r"^\$+(?:nonfinite|value)$")
_PLAIN = frozenset((str, int, bool, type(None)))
Found = list[tuple[list[str], str]]


def reference_to_strict(document: object) -> Any:
    found: Found = []
    plain = _ref_walk(document, [], found)
    forced = isinstance(plain, dict) and NONFINITE_KEY in plain
    if not found and not forced:
        return plain
    if not isinstance(plain, dict):
        annotation = {_ref_pointer([VALUE_KEY, *path]): kind for path, kind in found}
        return {VALUE_KEY: plain, NONFINITE_KEY: annotation}
    out = {_ref_escape(k): v for k, v in plain.items()}
    out[NONFINITE_KEY] = {_ref_pointer([_ref_escape(p[0]), *p[1:]]): k for p, k in found}
    return out


def _ref_walk(value: object, path: list[str], found: Found) -> Any:
    if type(value) is dict:
        return _ref_items(value.items(), path, found, True)
    if type(value) is list or type(value) is tuple:
        return _ref_items(enumerate(value), path, found, False)
    return _ref_general(value, path, found)


def _ref_items(
    pairs: Iterable[tuple[Any, Any]], path: list[str], found: Found, mapping: bool
) -> Any:
    out: dict[str, Any] = {}
    items: list[Any] = []
    for key, item in pairs:
        kind = type(item)
        value = item
        if kind not in _PLAIN and not (kind is float and item - item == 0.0):
            path.append(str(key))
            value = _ref_walk(item, path, found)
            path.pop()
        if mapping:
            out[key if type(key) is str else str(key)] = value
        else:
            items.append(value)
    return out if mapping else items


def _ref_general(value: Any, path: list[str], found: Found) -> Any:
    if isinstance(value, float):
        if math.isfinite(value):
            return value
        kind = "nan" if math.isnan(value) else "inf" if value > 0 else "-inf"
        found.append((list(path), kind))
        return None
    if isinstance(value, str | int) or value is None:
        return value
    if isinstance(value, Mapping):
        return _ref_items(value.items(), path, found, True)
    if isinstance(value, list | tuple):
        return _ref_items(enumerate(value), path, found, False)
    if hasattr(value, "tolist") and callable(value.tolist):
        return _ref_walk(value.tolist(), path, found)
    return value


def _ref_escape(key: str) -> str:
    return "$" + key if _RESERVED.match(key) else key


def _ref_pointer(tokens: list[str]) -> str:
    return "".join("/" + t.replace("~", "~0").replace("/", "~1") for t in tokens)


# --- comparison ------------------------------------------------------------------------------


def identical(a: Any, b: Any) -> bool:
    """Same container types, key order and items; leaves of the same type and value (the
    document's own leaves are the very objects; numpy's ``tolist`` makes new ones)."""
    if type(a) is not type(b):
        return False
    if type(a) is dict:
        return (
            list(a) == list(b)
            and all(type(k) is str for k in a)
            and all(identical(a[k], b[k]) for k in a)
        )
    if type(a) is list:
        return len(a) == len(b) and all(identical(x, y) for x, y in zip(a, b, strict=True))
    return a is b or bool(a == b)


def check(document: Any) -> Any:
    new, old = to_strict(document), reference_to_strict(document)
    assert identical(new, old), (new, old)
    return new


# --- documents -------------------------------------------------------------------------------


class Ratio(float):
    """A float subclass: kept as it is when finite, a null when not."""


class Level(enum.IntEnum):
    LOW = 1


class Name(str, enum.Enum):
    A = "a"


class Tokens(list[Any]):
    pass


def float32(value: float) -> np.float32:
    """``value`` as a float32: 1e308 becomes infinity, on purpose (no warning printed)."""
    with np.errstate(over="ignore"):
        return np.float32(value)


#: Floats whose sum overflows, non-finite ones, and neighbours of the finiteness test.
FLOATS = [NAN, INF, -INF, 1e308, -1e308, 1.7976931348623157e308, 5e-324, -0.0, 0.0, 1.5]
TEXT = ["", "a", "~", "/", "a/b~c", "~1", "$nonfinite", "$$nonfinite", "$value", "$$value", "0"]

scalars = (
    st.none()
    | st.booleans()
    | st.integers(min_value=-(2**70), max_value=2**70)
    | st.floats()
    | st.sampled_from(FLOATS)
    | st.sampled_from(TEXT)
    | st.sampled_from(FLOATS).map(Ratio)
    | st.sampled_from(FLOATS).map(np.float64)
    | st.sampled_from(FLOATS).map(float32)
    | st.integers(-5, 5).map(np.int64)
    | st.booleans().map(np.bool_)
    | st.just(Level.LOW)
    | st.just(Name.A)
    | st.just(1 + 2j)
)
keys = (
    st.sampled_from(TEXT)
    | st.text(max_size=3)
    | st.integers(-3, 3)
    | st.sampled_from([1.5, NAN, True, None, (1, 2), Name.A, Level.LOW])
)


def containers(inner: st.SearchStrategy[Any]) -> st.SearchStrategy[Any]:
    dicts = st.dictionaries(keys, inner, max_size=6)
    str_dicts = st.dictionaries(st.sampled_from(TEXT), inner, max_size=6)
    lists = st.lists(inner, max_size=6)
    return (
        lists
        | str_dicts
        | dicts
        | lists.map(tuple)
        | lists.map(Tokens)
        | str_dicts.map(OrderedDict)
        | str_dicts.map(MappingProxyType)
        | st.lists(st.sampled_from(FLOATS), max_size=4).map(np.array)
    )


documents = st.recursive(scalars, containers, max_leaves=40)


@settings(max_examples=600, deadline=None)
@given(documents)
def test_any_document_comes_out_as_the_plain_walk_made_it(document: Any) -> None:
    check(document)


@settings(max_examples=200, deadline=None)
@given(st.dictionaries(st.sampled_from(TEXT), documents, max_size=5))
def test_a_top_level_object_with_reserved_keys_is_escaped_as_before(document: Any) -> None:
    check(document)


def test_a_dict_whose_later_key_is_not_a_string() -> None:
    """The copy is abandoned at the int key; what its items reported is reported once."""
    document = {"a": NAN, "b": {"c": INF, "d": [-INF]}, 3: NAN, "3": 1.0, "e": [NAN]}
    strict = check({"x": [document, document], "$value": NAN})
    assert list(strict[NONFINITE_KEY]) == [
        "/x/0/a",
        "/x/0/b/c",
        "/x/0/b/d/0",
        "/x/0/3",
        "/x/0/e/0",
        "/x/1/a",
        "/x/1/b/c",
        "/x/1/b/d/0",
        "/x/1/3",
        "/x/1/e/0",
        "/$$value",
    ]


def test_verdict_frames_and_their_text() -> None:
    """A verdict's frames (rows of numbers, ids, per-actor maps, empty maps and lists)."""
    frame = {
        "frame": 3,
        "timestamp_ms": 150,
        "prediction": {
            "failed": False,
            "ids": ["8837"],
            "ade": NAN,
            "ade_per_actor": {"9542": 4.5e-06, "7424": INF},
            "missed": {},
            "false_positives": [],
            "c_pwp": -INF,
            "c_pwp_index": None,
            "ttc": (1.0, NAN),
        },
        "planning": {"failed": True, "c_plan": NAN, "ttc_gt": 1e308},
    }
    frames = [frame, dict(frame, frame=4), {"frame": 5}]
    for document in (frames, {"frames": frames, "verdict": "x"}, {"$nonfinite": frames}):
        strict = check(document)
        text = json.dumps(strict, allow_nan=False)
        assert json.dumps(from_strict(json.loads(text))) == json.dumps(
            json.loads(json.dumps(document))
        )
