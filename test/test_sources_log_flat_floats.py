"""A predictions, waypoint or boxes file's numbers go through records.finite_floats
(``struct``) instead of ``np.array``: on clean, hostile and randomly damaged documents the
record and the problems are what the walk (the reader's slow path, which says what is
wrong) gives."""

from __future__ import annotations

import copy
import random
from typing import Any

import numpy as np
import pytest

from ads_rca.model import Boxes, Plan, Predictions
from ads_rca.problems import ProblemLog
from ads_rca.sources.log.records import (
    POSE_FIELDS,
    FieldReader,
    _track,
    boxes_walked,
    finite_floats,
    parse_boxes,
    parse_plan,
    parse_pose,
    parse_predictions,
    pose_walked,
)

VALUES: list[Any] = [
    0,
    -0.0,
    1.5,
    2**53 + 1,
    2**63,
    2**64,
    2**70,
    -(2**70),
    10**30,
    10**400,
    True,
    False,
    None,
    "1",
    "",
    "12.5",
    " 7 ",
    "nan",
    "-inf",
    "1e400",
    "0x10",
    [],
    [1.0],
    {},
    {"x": 1.0},
    float("nan"),
    float("inf"),
]


def walked_predictions(document: dict[str, Any]) -> tuple[Predictions, list[Any]]:
    problems = ProblemLog()
    reader = FieldReader("p.json", problems, 1)
    return {str(k): _track(v, str(k), reader) for k, v in document.items()}, list(problems)


def walked_plan(document: dict[str, Any]) -> tuple[Plan, list[Any]]:
    problems = ProblemLog()
    reader = FieldReader("w.json", problems, 1)
    rows = [
        [reader.number(p, name, f"{k}.{name}") for name in ("x", "y", "speed")]
        for k, p in document.items()
    ]
    table = np.array(rows, dtype=np.float64).reshape(-1, 3)
    return Plan(tuple(map(str, document)), table[:, :2].copy(), table[:, 2].copy()), list(problems)


def same_predictions(document: dict[str, Any]) -> None:
    problems = ProblemLog()
    got = parse_predictions(document, "p.json", problems, 1)
    want, want_problems = walked_predictions(document)
    assert got is not None and list(got) == list(want)
    for key, track in got.items():
        assert track.keys == want[key].keys
        assert track.offsets.dtype == np.float64 and track.offsets.shape == want[key].offsets.shape
        assert track.offsets.tobytes() == want[key].offsets.tobytes()  # every last bit
    assert list(problems) == want_problems


def same_plan(document: dict[str, Any]) -> None:
    problems = ProblemLog()
    got = parse_plan(document, "w.json", problems, 1)
    want, want_problems = walked_plan(document)
    assert got is not None and got.keys == want.keys
    assert got.xy.tobytes() == want.xy.tobytes() and got.speed.tobytes() == want.speed.tobytes()
    assert got.xy.shape == want.xy.shape and got.speed.shape == want.speed.shape
    assert list(problems) == want_problems


def walked_boxes(document: list[Any]) -> tuple[Boxes, list[Any]]:
    problems = ProblemLog()
    return boxes_walked(document, FieldReader("b.json", problems, 1)), list(problems)


def same_boxes(document: list[Any]) -> None:
    problems = ProblemLog()
    got = parse_boxes(document, "b.json", problems, 1)
    want, want_problems = walked_boxes(document)
    assert got is not None and got.ids == want.ids and got.extras == want.extras
    assert got.corners.dtype == np.float64 and got.corners.shape == want.corners.shape
    assert got.corners.tobytes() == want.corners.tobytes()
    assert list(problems) == want_problems


def same_pose(document: Any) -> None:
    problems, walk_problems = ProblemLog(), ProblemLog()
    got = parse_pose(document, "pose.json", problems, 1)
    want = pose_walked(document, FieldReader("pose.json", walk_problems, 1))
    assert repr(got) == repr(want)  # NaN fields compare equal as text
    assert list(problems) == list(walk_problems)


def pose() -> dict[str, Any]:
    """A pose as the seed format writes it: every value as text."""
    return {name: str(12.5 + i) for i, name in enumerate(POSE_FIELDS)}


def boxes(n: int = 3) -> list[Any]:
    return [
        {"id": 7 + i, "bounding_box": [[i * 1.5, -i / 3], [i * 1.5 + 2.0, 1.25]], "score": 0.9}
        for i in range(n)
    ]


def predictions(n: int = 3, steps: int = 4) -> dict[str, Any]:
    return {
        str(9000 + i): {str(k): {"x": i + k * 0.1, "y": -k / 3, "z": 0.0} for k in range(steps)}
        for i in range(n)
    }


def plan(steps: int = 5) -> dict[str, Any]:
    return {str(k): {"x": k * 1.25, "y": -k / 7, "speed": 12.5} for k in range(steps)}


@pytest.mark.parametrize("value", VALUES, ids=repr)
def test_one_hostile_value_gives_what_the_walk_gives(value: Any) -> None:
    for axis in ("x", "y", "z"):
        document = predictions()
        document["9001"]["2"][axis] = value
        same_predictions(document)
    for name in ("x", "y", "speed"):
        document = plan()
        document["3"][name] = value
        same_plan(document)
    for point in (0, 1):
        for coordinate in (0, 1):
            corners = boxes()
            corners[1]["bounding_box"][point][coordinate] = value
            same_boxes(corners)
        corners = boxes()
        corners[2]["bounding_box"][point] = value  # a point that is no [x, y]
        same_boxes(corners)
    corners = boxes()
    corners[0]["bounding_box"] = value  # no pair of points
    same_boxes(corners)
    for name in POSE_FIELDS:
        document = pose()
        document[name] = value
        same_pose(document)
        del document[name]  # a field missing, another hostile
        same_pose(document)
    same_pose(value)  # a pose file that is no object


def test_a_clean_pose_is_read_without_the_walk() -> None:
    document = pose()
    document["speed"] = 3  # numbers as JSON numbers too
    got = parse_pose(document, "pose.json", ProblemLog(), 1)
    assert got is not None and got.x == 12.5 and got.speed == 3.0
    same_pose(document)


def test_empty_files_give_empty_records() -> None:
    same_predictions({})
    same_plan({})
    same_boxes([])
    assert parse_predictions({}, "p.json", ProblemLog(), 1) == {}


def test_finite_floats_is_float_of_each_value() -> None:
    values = [1, -0.0, True, 2**63 + 5, 0.1, 2**70]
    got = finite_floats(values)
    assert got is not None and got.dtype == np.float64
    assert got.tobytes() == np.array([float(v) for v in values]).tobytes()
    for bad in ("1", None, [1.0], 10**400, float("nan"), float("-inf")):
        assert finite_floats([1.0, bad]) is None


def test_randomly_damaged_documents_give_what_the_walk_gives() -> None:
    rng = random.Random(20261207)
    for _ in range(1500):
        document = copy.deepcopy(predictions(3, 5))
        for _edit in range(rng.randint(1, 3)):
            track = document[rng.choice(list(document))]
            step = track[rng.choice(list(track))]
            step[rng.choice(["x", "y", "z"])] = rng.choice(VALUES)
        same_predictions(document)
        waypoints = copy.deepcopy(plan())
        for _edit in range(rng.randint(1, 3)):
            waypoints[rng.choice(list(waypoints))][rng.choice(["x", "y", "speed"])] = rng.choice(
                VALUES
            )
        same_plan(waypoints)
        damaged = copy.deepcopy(boxes(4))
        for _edit in range(rng.randint(1, 3)):
            box = damaged[rng.randrange(len(damaged))]
            box["bounding_box"][rng.randrange(2)][rng.randrange(2)] = rng.choice(VALUES)
        same_boxes(damaged)
