"""The fast indented writer gives the json module's bytes, whatever the document."""

from __future__ import annotations

import io
import json
import math
import random
import sys
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ads_rca.foundation.indented_json import dumps_indented, iter_indented, write_indented


def json_module(document: Any) -> str:
    return json.dumps(document, indent=1, allow_nan=False)


#: Floats where orjson and Python spell numbers differently, and their neighbours.
EDGE_FLOATS = [
    1e-4,
    9.99e-5,
    1e-5,
    1.5e-5,
    1e-6,
    2.5e-6,
    1e-7,
    1e-9,
    1e-10,
    5e-324,
    -1e-7,
    -0.0,
    0.0,
    1e15,
    1e16,
    1.234e16,
    1e21,
    1e22,
    1.7976931348623157e308,
    0.1,
    1 / 3,
]
#: Text that looks like numbers, commas and indentation inside strings and keys.
TRICKY_TEXT = [
    "1e-7",
    "x 1e-7",
    "0.00001,",
    " 1e-5",
    "e-5",
    "a\n 1e-7,",
    "\x7f",
    "é",
    "😀",
    "\u2028",
    "\x00\x01\x1f",
    '"',
    "\\",
    "  ",
    '  "k": 1e-7,',
    "pose-050.json",
]

finite = st.floats(allow_nan=False, allow_infinity=False)
small = st.floats(min_value=-1e-4, max_value=1e-4, allow_nan=False)
scalars = (
    st.none()
    | st.booleans()
    | st.integers(min_value=-(2**63), max_value=2**63 - 1)
    | finite
    | small
    | st.sampled_from(EDGE_FLOATS)
    | st.text()
    | st.sampled_from(TRICKY_TEXT)
)
keys = st.text() | st.sampled_from(TRICKY_TEXT)
documents = st.recursive(
    scalars,
    lambda inner: st.lists(inner, max_size=6) | st.dictionaries(keys, inner, max_size=6),
    max_leaves=40,
)


@settings(max_examples=400, deadline=None)
@given(documents)
def test_any_strict_document_is_written_as_the_json_module_writes_it(document: Any) -> None:
    assert dumps_indented(document) == json_module(document)


@settings(max_examples=150, deadline=None)
@given(st.lists(documents, max_size=12), st.integers(min_value=1, max_value=4))
def test_long_lists_and_objects_converted_in_batches_give_the_same_text(
    items: list[Any], batch_items: int
) -> None:
    document = {
        "before": items[:1],
        "frames": items,
        "map": {f"/frames/{i}": item for i, item in enumerate(items)},
        "after": [items, {"é": items}],
    }
    pieces = list(iter_indented(document, batch_items))
    assert "".join(pieces) == json_module(document)
    batches = -(-len(items) // batch_items) if len(items) > batch_items else 0
    assert len(pieces) >= 2 * batches


@pytest.mark.parametrize("value", EDGE_FLOATS + [-v for v in EDGE_FLOATS])
def test_every_edge_float_is_spelled_as_python_spells_it(value: float) -> None:
    document = {"x": value, "list": [value, [value]], "key with 1e-7": f"{value}"}
    assert dumps_indented(document) == json_module(document)
    assert dumps_indented(value) == json_module(value)


def test_what_orjson_cannot_write_goes_through_the_json_module() -> None:
    for document in (
        {"big": 2**70},
        {1: "integer key", 2.5: "float key", None: "null key", False: "bool key"},
        {"lone surrogate": "\ud800"},
    ):
        assert dumps_indented(document) == json_module(document)


def test_a_verdict_sized_document_is_identical_and_its_frames_written_in_batches() -> None:
    frames = [
        {"frame": i, "metrics": {"error": i * 1e-7, "ok": i % 2 == 0, "ids": [str(i), "é"]}}
        for i in range(20_000)
    ]
    document = {"tool": "ads_rca", "frames": frames, "evidence": {"tiny": 5e-324}}
    out = io.StringIO()
    write_indented(document, out)
    assert out.getvalue() == json_module(document)
    assert len(list(iter_indented(document))) > 20  # the frames in batches


def test_non_finite_numbers_are_the_callers_to_make_strict() -> None:
    # Documented contract: orjson writes them as null; the json module would refuse them.
    assert json.loads(dumps_indented({"x": math.nan})) == {"x": None}
    with pytest.raises(ValueError):
        json_module({"x": math.nan})


def test_deep_nesting_within_the_json_modules_reach_is_identical() -> None:
    document: Any = [1e-7]
    for _ in range(min(200, sys.getrecursionlimit() // 4)):
        document = {"k": document}
    assert dumps_indented(document) == json_module(document)


with_nonfinite = st.recursive(
    scalars | st.sampled_from([math.nan, math.inf, -math.inf]),
    lambda inner: st.lists(inner, max_size=5) | st.dictionaries(keys, inner, max_size=5),
    max_leaves=30,
)


@settings(max_examples=200, deadline=None)
@given(st.lists(with_nonfinite, max_size=12), st.lists(st.integers(1, 5), max_size=12))
def test_a_list_rendered_part_by_part_is_the_whole_documents_text(
    items: list[Any], cuts: list[int]
) -> None:
    """A top-level list made strict and written part by part as its items come (a verdict's
    frames as their slices come back): the document's text and its non-finite pointers,
    in order, are those of the document with the whole list in place."""
    from ads_rca.foundation.indented_json import RenderedList
    from ads_rca.foundation.strictjson import to_strict

    rendered = RenderedList("frames")
    start = 0
    for size in [*cuts, len(items)]:
        rendered.extend(items[start : start + size])
        start += size
    assert len(rendered) == len(items)
    around = {"$nonfinite": math.nan, "before": [math.inf, items[:1]]}
    whole = to_strict({**around, "frames": items, "after": {"x": -math.inf}})
    parts = to_strict({**around, "frames": rendered, "after": {"x": -math.inf}})
    assert list(parts) == list(whole) and parts["$nonfinite"] == whole["$nonfinite"]
    assert list(parts["$nonfinite"]) == list(whole["$nonfinite"])  # the same order
    assert dumps_indented(parts) == json_module(whole)


def test_small_floats_of_every_magnitude_are_spelled_as_python_spells_them() -> None:
    """orjson writes 1e-5 <= |x| < 1e-4 in decimals and smaller ones with a one-digit
    exponent; Python writes both as d.ddde-0N. Thousands of each, at the end of lines
    with and without a comma, in lists and objects, beside strings that end the same way."""
    rng = random.Random(20261208)
    values = [rng.choice((1, -1)) * rng.random() * 10 ** rng.uniform(-12, -3) for _ in range(20000)]
    values += [float(f"{v:.{rng.randint(1, 3)}g}") for v in values[:2000]]  # short digits
    document = {"list": values, "map": {str(i): v for i, v in enumerate(values[:3000])}}
    # strings spelled as orjson spells the numbers: never respelled
    document["text"] = [f"{v:.3e}".replace("e-0", "e-") for v in values[:500]]
    assert dumps_indented(document) == json_module(document)
