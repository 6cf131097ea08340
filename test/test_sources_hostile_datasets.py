"""Hostile values in every dataset reader's files, fuzzed with hypothesis: DLP scenes,
OpenLane-V2 segments (and a model's results), atmaCup #18 tables (and a submission, and the
traffic-light files), CARLA client runs (JSON and CSV telemetry).

Each example starts from the repository's own writers (``test/writers/``), replaces a few
values along a drawn path (a file's whole document, an entry, a field, an element) with
hostile ones (huge, negative, NaN or infinite numbers, integers past 64 bits, wrong types,
empty lists and objects, huge strings, control characters), deletes keys, empties tables
or drops their columns, and reads the result through :func:`open_run`. The property: the
read succeeds (what was wrong is in the run's problems) or raises the repository's
:class:`InputError`, one line naming the file or folder; never any other exception.

Then the two cases of issue 41 as a user meets them: ``ads-rca diagnose`` on a DLP scene
with a timestamp of 1e308 and on an atmaCup table of its header alone, one line or a
verdict, never a traceback.
"""

from __future__ import annotations

import copy
import csv
import io
import json
import math
import os
import shutil
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest
from commandline import assert_clean, run_cli
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from writers.atmacup_tables import ROWS, write_submission, write_table
from writers.carla_runs import write_carla_run
from writers.dlp_scenes import STEM, write_dlp_scene
from writers.openlane_segments import write_openlane_predictions, write_openlane_segment

from ads_rca.errors import InputError
from ads_rca.sources.formats import SourceOptions
from ads_rca.sources.registry import open_run

#: Few examples per reader, each a handful of small files, so the suite stays fast;
#: ``ADS_RCA_FUZZ_EXAMPLES=5000`` searches deeper by hand.
FUZZ = settings(
    max_examples=int(os.environ.get("ADS_RCA_FUZZ_EXAMPLES", "40")),
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)


def huge_text(length: int) -> str:
    return "x" * length


NUMBERS = (
    1e308,
    -1e308,
    1.7976931348623157e308,
    5e-324,
    -0.0,
    0,
    -1,
    2**31,
    2**53 + 1,
    2**63,
    -(2**63) - 1,
    10**30,
    10**400,
    math.nan,
    math.inf,
    -math.inf,
)
#: Hostile text: empty, numbers as text, control characters, 100,000 characters.
TEXTS: st.SearchStrategy[str] = st.sampled_from(
    ["", "1e308", "-1e999", "nan", "inf", "0x10", "True", "\x00\n\u202e"]
) | st.just(100_000).map(huge_text)
#: A hostile JSON value.
VALUES: st.SearchStrategy[Any] = (
    st.sampled_from(NUMBERS)
    | st.floats()
    | st.integers(min_value=-(2**70), max_value=2**70)
    | TEXTS
    | st.text(max_size=6)
    | st.sampled_from([None, True, False, [], {}, [[]], {"": None}]).map(copy.deepcopy)
    | st.lists(st.sampled_from(NUMBERS), max_size=4)
)
#: A hostile CSV cell.
CELLS: st.SearchStrategy[str] = TEXTS | st.sampled_from(NUMBERS).map(repr) | st.text(max_size=6)


# --- mutating documents and tables ---------------------------------------------------------


def mutate(data: st.DataObject, document: Any) -> Any:
    """``document`` with one node, along a drawn path, replaced by a hostile value or
    deleted (the whole document replaced when the path is empty)."""
    path: list[Any] = []
    node = document
    while isinstance(node, (dict, list)) and node and data.draw(st.integers(0, 7)) > 0:
        key = data.draw(
            st.sampled_from(sorted(node) if isinstance(node, dict) else range(len(node)))
        )
        path.append(key)
        node = node[key]
    if not path:
        return data.draw(VALUES)
    parent = document
    for key in path[:-1]:
        parent = parent[key]
    if data.draw(st.booleans()):
        del parent[path[-1]]
    else:
        parent[path[-1]] = data.draw(VALUES)
    return document


def mutate_table(data: st.DataObject, rows: list[list[str]]) -> list[list[str]]:
    """A CSV table (header first) with a cell replaced, a row cut or lengthened, the data
    rows dropped, or a column dropped."""
    action = data.draw(
        st.sampled_from(["cell", "cell", "cell", "short", "long", "empty", "column"])
    )
    if action == "empty" or len(rows) < 2:
        return rows[:1]
    if action == "column":
        column = data.draw(st.integers(0, max(len(rows[0]) - 1, 0)))
        return [[c for n, c in enumerate(row) if n != column] for row in rows]
    row = data.draw(st.integers(0, len(rows) - 1))
    if action == "short":
        rows[row] = rows[row][: data.draw(st.integers(0, len(rows[row])))]
    elif action == "long" or not rows[row]:
        rows[row] = [*rows[row], data.draw(CELLS)]
    else:
        rows[row][data.draw(st.integers(0, len(rows[row]) - 1))] = data.draw(CELLS)
    return rows


def read_csv(path: Path) -> list[list[str]]:
    return list(csv.reader(io.StringIO(path.read_text(encoding="utf-8"))))


def write_csv(path: Path, rows: list[list[str]]) -> None:
    with path.open("w", newline="", encoding="utf-8") as out:
        csv.writer(out).writerows(rows)


class Fixture:
    """A folder written once by a writer, copied for each example: its JSON files as
    documents (parsed once), the rest as bytes."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.files = sorted(p.relative_to(root) for p in root.rglob("*") if p.is_file())
        self.json = {
            f: json.loads((root / f).read_text(encoding="utf-8"))
            for f in self.files
            if f.suffix == ".json"
        }
        self.csv = {f: read_csv(root / f) for f in self.files if f.suffix == ".csv"}

    @contextmanager
    def hostile(self, data: st.DataObject, only: tuple[str, ...] = ()) -> Iterator[Path]:
        """A copy with 1 to 3 mutations, each in a drawn file (of ``only`` when given:
        name suffixes)."""
        documents = {f: json.loads(json.dumps(d)) for f, d in self.json.items()}
        tables = {f: [list(r) for r in rows] for f, rows in self.csv.items()}
        targets = [f for f in [*documents, *tables] if not only or str(f).endswith(only)]
        for _ in range(data.draw(st.integers(1, 3))):
            file = data.draw(st.sampled_from(targets))
            if file in documents:
                documents[file] = mutate(data, documents[file])
            else:
                tables[file] = mutate_table(data, tables[file])
        with self.written(documents, tables) as copy:
            yield copy

    @contextmanager
    def written(
        self, documents: dict[Path, Any], tables: dict[Path, list[list[str]]]
    ) -> Iterator[Path]:
        """A copy of the folder with ``documents`` and ``tables`` written over its files."""
        with tempfile.TemporaryDirectory() as tmp:
            copy = Path(tmp) / self.root.name
            shutil.copytree(self.root, copy)
            for file, document in documents.items():
                (copy / file).write_text(json.dumps(document), encoding="utf-8")
            for file, rows in tables.items():
                write_csv(copy / file, rows)
            yield copy

    @contextmanager
    def with_value(self, file: str, path: tuple[Any, ...], value: Any) -> Iterator[Path]:
        """A copy whose JSON ``file`` holds ``value`` at ``path`` (a key or position per
        level; ``-1``: the first entry of an object)."""
        document = json.loads(json.dumps(self.json[Path(file)]))
        node = document
        for n, step in enumerate(path):
            key = sorted(node)[0] if step == -1 else step
            if n == len(path) - 1:
                node[key] = value
            else:
                node = node[key]
        with self.written({Path(file): document}, {}) as copy:
            yield copy


def read_or_refuse(read: Callable[[], object], *names: str) -> None:
    """The property: ``read()`` succeeds, or raises InputError in one line naming one of
    ``names`` (the input's files and folders)."""
    try:
        read()
    except InputError as error:
        message = str(error)
        assert "\n" not in message, message
        assert any(name in message for name in names), message


# --- the readers ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def fixtures(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Fixture]:
    root = tmp_path_factory.mktemp("datasets")
    write_dlp_scene(root / "dlp", frames=8)
    segment = write_openlane_segment(root / "openlane", frames=3)
    write_openlane_predictions(root / "openlane" / "results", segment)
    write_table(root / "atmacup", ROWS)
    write_submission(
        root / "atmacup" / "submission.csv", [r.path for r in ROWS], [r.ident for r in ROWS]
    )
    for schema in ("v0.2", "csv"):
        write_carla_run(root / f"carla-{schema}", schema, ticks=6)
    return {
        name: Fixture(root / name)
        for name in ("dlp", "openlane", "atmacup", "carla-v0.2", "carla-csv")
    }


@FUZZ
@given(data=st.data())
def test_a_hostile_dlp_scene_is_read_or_one_line(
    fixtures: dict[str, Fixture], data: st.DataObject
) -> None:
    derived = data.draw(st.booleans())
    with fixtures["dlp"].hostile(data) as folder:
        scene = folder / f"{STEM}_scene.json"
        options = SourceOptions("dlp", derived_collision=derived)
        read_or_refuse(lambda: open_run(scene, source=options), str(folder), STEM)


@FUZZ
@given(data=st.data())
def test_a_hostile_openlane_segment_is_read_or_one_line(
    fixtures: dict[str, Fixture], data: st.DataObject
) -> None:
    with fixtures["openlane"].hostile(data) as folder:
        segment = next((folder / "train").iterdir())
        options = SourceOptions("openlane", predictions=str(folder / "results"))
        read_or_refuse(lambda: open_run(segment, source=options), str(folder))


@FUZZ
@given(data=st.data())
def test_a_hostile_atmacup_table_is_read_or_one_line(
    fixtures: dict[str, Fixture], data: st.DataObject
) -> None:
    with fixtures["atmacup"].hostile(data) as folder:
        table = folder / "train_features.csv"
        options = SourceOptions("atmacup", submission=str(folder / "submission.csv"))
        read_or_refuse(lambda: open_run(table, source=options), str(folder))


@FUZZ
@given(data=st.data())
def test_a_hostile_atmacup_submission_is_read_or_one_line(
    fixtures: dict[str, Fixture], data: st.DataObject
) -> None:
    with fixtures["atmacup"].hostile(data, only=("submission.csv",)) as folder:
        table = folder / "train_features.csv"
        options = SourceOptions("atmacup", submission=str(folder / "submission.csv"))
        read_or_refuse(lambda: open_run(table, source=options), str(folder))


@FUZZ
@given(data=st.data())
@pytest.mark.parametrize("schema", ["v0.2", "csv"])
def test_a_hostile_carla_run_is_read_or_one_line(
    fixtures: dict[str, Fixture], schema: str, data: st.DataObject
) -> None:
    derived = data.draw(st.booleans())
    with fixtures[f"carla-{schema}"].hostile(data) as folder:
        options = SourceOptions("carla", derived_collision=derived)
        read_or_refuse(lambda: open_run(folder, source=options), str(folder))


# --- the cases of issue 41 through the command line ----------------------------------------


def test_a_dlp_timestamp_of_1e308_skips_its_frame_and_diagnoses_the_rest(tmp_path: Path) -> None:
    """1e308 s is a finite number whose milliseconds are not: it was an OverflowError."""
    from writers.dlp_scenes import frame_token

    write_dlp_scene(tmp_path / "scene", 50)
    frames = tmp_path / "scene" / f"{STEM}_frames.json"
    document = json.loads(frames.read_text(encoding="utf-8"))
    document[frame_token(10)]["timestamp"] = 1e308
    frames.write_text(json.dumps(document), encoding="utf-8")
    done = run_cli("diagnose", str(tmp_path / "scene" / f"{STEM}_scene.json"), timeout=60)
    assert_clean(done, 0)
    assert "49 frames judged" in done.stdout
    assert (
        f"  error: {STEM}_frames.json: timestamp: 1 frames have no time after the previous "
        f"frame's (the first: {frame_token(10)} at 1e+308 s) (frame skipped)"
    ) in done.stdout.splitlines()


@pytest.mark.parametrize("command", ["inspect", "diagnose"])
def test_an_atmacup_table_of_its_header_alone_is_one_line(tmp_path: Path, command: str) -> None:
    """It was ``ValueError: cannot reshape array of size 0``."""
    table = write_table(tmp_path / "atmacup", ROWS)
    table.write_text(table.read_text(encoding="utf-8").splitlines()[0] + "\n", encoding="utf-8")
    done = run_cli(command, str(table), timeout=60)
    assert_clean(done, 2)
    assert done.stderr.splitlines() == [
        f"ads-rca {command}: error: {table}: no data rows: the table holds its header alone"
    ]


def test_an_atmacup_table_of_no_usable_row_is_one_line_naming_the_column(tmp_path: Path) -> None:
    table = write_table(tmp_path / "atmacup", ROWS)
    rows = read_csv(table)
    for row in rows[1:]:
        row[0] = "not an id"
    write_csv(table, rows)
    with pytest.raises(InputError) as error:
        open_run(table)
    assert str(error.value) == (
        f"{table}: ID: none of its 3 data rows is usable (ID: 3 rows: not an ID "
        "{scene}_{deciseconds} (the first: data row 1, 'not an id'))"
    )


#: What the fuzzing found: reader, file, path to the value, value, and the problem said
#: (each was a traceback, or for the headings an infinite yaw said nowhere).
FOUND = {
    "dlp timestamp 1e308": (
        "dlp",
        f"{STEM}_frames.json",
        (-1, "timestamp"),
        1e308,
        "1 frames have no time after the previous frame's",
    ),
    "dlp frame token a list": (
        "dlp",
        f"{STEM}_instances.json",
        (-1, "frame_token"),
        [],
        "1 instances: no frame on the list",
    ),
    "dlp agent token a list": (
        "dlp",
        f"{STEM}_instances.json",
        (-1, "agent_token"),
        [1],
        "1 instances: no agent of the agents file",
    ),
    "dlp heading 1e308": (
        "dlp",
        f"{STEM}_instances.json",
        (-1, "heading"),
        1e308,
        "1 instances: not finite numbers",
    ),
    "dlp obstacle heading 1e308": (
        "dlp",
        f"{STEM}_obstacles.json",
        (-1, "heading"),
        1e308,
        "no finite coords and heading",
    ),
    "carla seed of 400 digits": ("carla-v0.2", "run_metadata.json", ("seed",), 10**400, ""),
    "atmacup light index of 400 digits": (
        "atmacup",
        f"traffic_lights/{ROWS[0].ident}.json",
        (0, "index"),
        10**400,
        "not an integer 0 to 999999: the list position used",
    ),
}


@pytest.mark.parametrize("case", sorted(FOUND))
def test_each_value_the_fuzzing_found_is_read_and_said(
    fixtures: dict[str, Fixture], case: str
) -> None:
    reader, file, path, value, said = FOUND[case]
    formats = {"dlp": "dlp", "carla-v0.2": "carla", "atmacup": "atmacup"}
    with fixtures[reader].with_value(file, path, value) as folder:
        given = {"dlp": folder / f"{STEM}_scene.json", "atmacup": folder / "train_features.csv"}
        log = open_run(given.get(reader, folder), source=SourceOptions(formats[reader]))
    assert log.frames
    assert not said or any(said in p.issue for p in log.problems), list(log.problems)
    if reader == "dlp":
        assert all(math.isfinite(pose.yaw) for pose in log.pose.values())
