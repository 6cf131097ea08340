"""An actors file's numbers go into one flat list for numpy (records._actors_fast): it must
give exactly what the row-of-tuples conversion it replaced gave (kept here as the
reference), the same table or the same refusal (then the reader walks the file and says
what is wrong), on clean documents, hostile ones and random damage; and whole logs read in
one process and in workers stay equal."""

from __future__ import annotations

import copy
import json
import random
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from logcompare import assert_logs_equal

from ads_rca.model import Actors
from ads_rca.problems import ProblemLog
from ads_rca.sources.log.reader import read_run_log
from ads_rca.sources.log.records import _actors_fast, _clean, parse_actors
from ads_rca.sources.log.writer import write_run_log
from ads_rca.synth import synthesise


def rows_of_tuples(document: dict[str, Any]) -> Actors | None:
    """The conversion _actors_fast made before: a tuple of nine numbers an actor, one
    (N, 9) array of them."""
    try:
        table = np.array(
            [
                (
                    a["location"]["x"],
                    a["location"]["y"],
                    a["location"]["z"],
                    a["rotation"]["roll"],
                    a["rotation"]["pitch"],
                    a["rotation"]["yaw"],
                    a["extent"]["x"],
                    a["extent"]["y"],
                    a["extent"]["z"],
                )
                for a in list(document.values())
            ]
        )
    except (KeyError, TypeError, ValueError, AttributeError):
        return None
    if not _clean(table, 9, ndim=2):
        return None
    table = table.astype(np.float64).reshape(-1, 9)
    ids = tuple(str(k) for k in document)
    return Actors(ids, table[:, 0:3].copy(), table[:, 3:6].copy(), table[:, 6:9].copy())


def assert_same(document: Any) -> Actors | None:
    fast = _actors_fast(document)
    expected = rows_of_tuples(document)
    assert (fast is None) == (expected is None), (document, fast, expected)
    if fast is not None and expected is not None:
        assert fast.ids == expected.ids
        for name in ("location", "rotation", "extent"):
            got, want = getattr(fast, name), getattr(expected, name)
            assert got.dtype == want.dtype == np.float64
            assert got.shape == want.shape == (len(document), 3)
            assert got.flags.c_contiguous and got.flags.owndata  # its own block, as before
            assert got.tobytes() == want.tobytes()  # -0.0 and every last bit
    return fast


def actor(x: Any = 1.5, yaw: Any = -90.0, ez: Any = 0.75) -> dict[str, Any]:
    return {
        "extent": {"x": 2.25, "y": 1.0, "z": ez},
        "location": {"x": x, "y": -3.0, "z": 0.0},
        "rotation": {"pitch": 0.5, "roll": -0.0, "yaw": yaw},
    }


def test_a_clean_file_gives_location_rotation_and_extent_in_columns() -> None:
    # actor "7": location (1.5, -3, 0), rotation roll -0.0, pitch 0.5, yaw -90, extent
    # (2.25, 1, 0.75); actor "8" the same with x 4 (an int, read as 4.0) and yaw 1e300
    fast = assert_same({"7": actor(), "8": actor(x=4, yaw=1e300)})
    assert fast is not None
    assert fast.ids == ("7", "8")
    assert fast.location.tolist() == [[1.5, -3.0, 0.0], [4.0, -3.0, 0.0]]
    assert fast.rotation.tolist() == [[-0.0, 0.5, -90.0], [-0.0, 0.5, 1e300]]
    assert np.signbit(fast.rotation[0, 0])
    assert fast.extent.tolist() == [[2.25, 1.0, 0.75]] * 2


def test_an_empty_file_gives_no_actors() -> None:
    fast = assert_same({})
    assert fast is not None and fast.ids == () and fast.location.shape == (0, 3)


HOSTILE: dict[str, Any] = {
    "string number": {"7": actor(x="1.5")},
    "every x a string": {"7": actor(x="1.5"), "8": actor(x="2")},
    "null": {"7": actor(x=None)},
    "NaN": {"7": actor(x=float("nan"))},
    "infinity": {"7": actor(yaw=float("-inf"))},
    "boolean": {"7": actor(x=True)},
    "every number a boolean": {"7": {k: dict.fromkeys(v, True) for k, v in actor().items()}},
    "big integer": {"7": actor(x=2**70)},
    "integer past the float range": {"7": actor(x=10**400)},
    "a list for a number": {"7": actor(x=[1.5])},
    "every x a list": {"7": actor(x=[1.5]), "8": actor(x=[2.5])},
    "one of two x a list": {"7": actor(x=[1.5]), "8": actor()},
    "every value a list": {
        "7": {k: {a: [1.0] for a in v} for k, v in actor().items()},
    },
    "a dict for a number": {"7": actor(ez={"z": 1})},
    "a list for an actor": {"7": [1, 2, 3]},
    "a string for an actor": {"7": "actor"},
    "null actor": {"7": None},
    "a list for the location": {"7": {**actor(), "location": [1.0, 2.0, 0.0]}},
    "a string for the rotation": {"7": {**actor(), "rotation": "xyz"}},
    "missing extent": {"7": {k: v for k, v in actor().items() if k != "extent"}},
    "missing z": {"7": {**actor(), "location": {"x": 1.0, "y": 2.0}}},
    "missing yaw": {"7": {**actor(), "rotation": {"pitch": 0.0, "roll": 0.0}}},
    "ints only": {"7": {k: dict.fromkeys(v, 3) for k, v in actor().items()}},
}


@pytest.mark.parametrize("name", list(HOSTILE))
def test_a_hostile_file_gives_what_the_tuples_gave(name: str) -> None:
    assert_same(HOSTILE[name])


def test_a_refused_file_is_walked_and_reported() -> None:
    """The flat list refuses a string number; the walk reads it silently (the reference
    does) and reports the NaN: the same as before the flat list."""
    problems = ProblemLog()
    record = parse_actors({"7": actor(x="1.5", yaw=float("nan"))}, "actors/a-1.json", problems, 1)
    assert record is not None and record.location[0, 0] == 1.5
    assert [p.field for p in problems] == ["7.rotation.yaw"]


def test_randomly_damaged_documents_give_what_the_tuples_gave() -> None:
    """Values, sections and actors replaced by other JSON values, keys deleted: each
    document gives the reference's table or its refusal."""
    rng = random.Random(20261128)
    values: list[Any] = [
        0,
        -0.0,
        1.5,
        2**63,
        2**64,
        10**30,
        True,
        False,
        None,
        "1",
        "",
        [],
        [1.0],
        [1.0, 2.0],
        [[1.0]],
        {},
        {"x": 1.0},
        float("nan"),
        float("inf"),
    ]
    base = {str(i): actor(x=float(i), yaw=i * 7.5) for i in range(4)}
    taken = 0
    for _ in range(3000):
        document = copy.deepcopy(base)
        for _edit in range(rng.randint(1, 3)):
            actor_id = rng.choice(list(document))
            target = document[actor_id]
            if not isinstance(target, dict) or rng.random() < 0.05:
                document[actor_id] = rng.choice(values)
                continue
            section = rng.choice(list(target) or ["location"])
            if not isinstance(target.get(section), dict) or rng.random() < 0.1:
                target[section] = rng.choice(values)
                continue
            key = rng.choice(list(target[section]) or ["x"])
            if rng.random() < 0.1:
                target[section].pop(key, None)
            else:
                target[section][key] = rng.choice(values)
        taken += assert_same(document) is not None
    assert 0 < taken < 3000  # some damage (an int, a boolean for a number) keeps it numeric


def test_a_log_with_hostile_actors_reads_the_same_in_workers(tmp_path: Path) -> None:
    """Actors files with strings, lists, NaN and missing sections, read in this process and
    in two forked readers: the same log and the same problems."""
    log = write_run_log(synthesise("cut_in", "prediction", seed=4, frames=200), tmp_path / "a")
    damages = [
        lambda a: a["location"].update(x="12.5"),
        lambda a: a["rotation"].update(yaw=[1.0]),
        lambda a: a.pop("extent"),
        lambda a: a["extent"].update(z=None),
        lambda a: a["location"].update(y=True),
    ]
    files = sorted((log / "actors").iterdir())
    for index, path in enumerate(files[::20]):
        document = json.loads(path.read_text())
        damages[index % len(damages)](document[next(iter(document))])
        path.write_text(json.dumps(document))
    # 109 actors files, every 20th damaged: 6 files; the fifth damage (a boolean, read as
    # 1.0 on both paths) keeps its file numeric: 5 left to the walk
    assert len(files) == 109
    assert sum(1 for p in files if _actors_fast(json.loads(p.read_text())) is None) == 5
    one, two = read_run_log(log), read_run_log(log, workers=2)
    assert_logs_equal(one, two, angle_tol=0.0)
    assert list(one.problems) == list(two.problems)
    assert any("12.5" in p.issue or "x" in p.field for p in one.problems)
