"""The source registry: every source is a folder declaring
its ``Source``, and what depends on which sources exist derives from the registry's table:
detection in its order (by names and ``stat`` only), the options a source takes refused in
one line for the others, ``--format``'s names, the words of messages and batch rows. A
source registered in-process is detected, read and named without any other change.
"""

from __future__ import annotations

import os
import sys
import types
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import pytest

from ads_rca.errors import InputError
from ads_rca.model import RunLog, RunMetadata
from ads_rca.sources import registry
from ads_rca.sources.bag.options import BagOptions
from ads_rca.sources.formats import (
    DERIVED_COLLISION,
    EGO_AGENT,
    PREDICTIONS,
    PROFILE,
    REFUSALS,
    SUBMISSION,
    ReadRequest,
    Source,
    SourceOptions,
)
from ads_rca.sources.registry import (
    DETECTION_ORDER,
    FORMATS,
    SOURCES,
    detect_format,
    open_run,
    source_named,
)


def _touch(path: Path, text: str = "") -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


# --- the table ---------------------------------------------------------------------------------


def test_every_source_is_a_folder_declaring_itself_and_is_detected_once() -> None:
    assert sorted(DETECTION_ORDER) == sorted(SOURCES)
    assert ("auto", *SOURCES) == FORMATS
    for name in SOURCES:
        declared = source_named(name)
        assert declared.name == name and declared.kind.split(" ", 1)[0] in ("a", "an")
        assert (Path(registry.__file__).parent / name / "__init__.py").is_file()
    # The last one asked takes any path: nothing is left unread.
    assert source_named(DETECTION_ORDER[-1]).detect(Path("/nonexistent/anything"))


def test_the_words_of_batch_rows_and_messages_come_from_the_declarations() -> None:
    assert [source_named(n).words for n in SOURCES] == [
        "log folder",
        "bag",
        "CARLA run",
        "DLP scene",
        "atmaCup table",
        "OpenLane-V2 segment",
    ]


# --- detection order ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("files", "expected"),
    [
        (["telemetry.json"], "carla"),
        (["train_features.csv"], "atmacup"),
        (["DJI_0001_scene.json"], "dlp"),
        (["info/1000.json"], "openlane"),
        (["metadata.yaml"], "bag"),
        ([], "log"),
        # A folder two sources would claim is the one asked first.
        (["telemetry.json", "train_features.csv"], "atmacup"),
        (["telemetry.json", "DJI_0001_scene.json"], "carla"),
        (["DJI_0001_scene.json", "info/1000.json"], "dlp"),
        (["metadata.yaml", "telemetry.json"], "bag"),
        # A running log's own actors/ wins over any dataset's files beside it.
        (["actors/actors-0.json", "telemetry.json", "train_features.csv"], "log"),
        (["actors/actors-0.json", "DJI_0001_scene.json", "info/1.json"], "log"),
    ],
)
def test_auto_asks_the_sources_in_the_registry_order(
    tmp_path: Path, files: list[str], expected: str
) -> None:
    folder = tmp_path / "run"
    folder.mkdir()
    for name in files:
        _touch(folder / name, "{}")
    assert detect_format(folder) == expected


def test_detection_never_opens_a_file(tmp_path: Path) -> None:
    """A FIFO named like a dataset's file is told by its name; reading it is the reader's."""
    folder = tmp_path / "run"
    folder.mkdir()
    os.mkfifo(folder / "telemetry.json")
    assert detect_format(folder) == "carla"  # would block if it were opened
    os.mkfifo(tmp_path / "x_scene.json")
    assert detect_format(tmp_path / "x_scene.json") == "dlp"


# --- option checks -----------------------------------------------------------------------------

#: An option given, as open_run takes it.
GIVEN: dict[str, tuple[SourceOptions, BagOptions]] = {
    DERIVED_COLLISION: (SourceOptions(derived_collision=True), BagOptions()),
    EGO_AGENT: (SourceOptions(ego_agent="3"), BagOptions()),
    PREDICTIONS: (SourceOptions(predictions="/nonexistent/predictions"), BagOptions()),
    SUBMISSION: (SourceOptions(submission="/nonexistent/sub.csv"), BagOptions()),
    PROFILE: (SourceOptions(), BagOptions("carla-autoware")),
}
#: What each source's refusal says, as today's messages (pinned by the dataset tests).
REFUSED = {
    DERIVED_COLLISION: "the derived collision check applies to CARLA runs and DLP scenes, not to",
    EGO_AGENT: "ego_agent applies to DLP scenes, not to",
    PREDICTIONS: "--predictions applies to CARLA runs, DLP scenes and OpenLane-V2 segments "
    "(which hold no predictions), not to",
    SUBMISSION: "--submission applies to atmaCup tables, not to",
    PROFILE: "--profile and --remap apply to bags, not to",
}


@pytest.fixture
def any_path(tmp_path: Path) -> Path:
    return _touch(tmp_path / "somewhere" / "file.txt")


@pytest.mark.parametrize("name", SOURCES)
@pytest.mark.parametrize("option", [option for option, _ in REFUSALS])
def test_an_option_a_source_does_not_take_is_refused_before_reading(
    any_path: Path, name: str, option: str
) -> None:
    declared = source_named(name)
    if option in declared.options:
        pytest.skip(f"{name} takes {option}")
    options, bag = GIVEN[option]
    with pytest.raises(InputError) as refused:
        open_run(any_path, bag=bag, source=replace(options, source_format=name))
    if option == PROFILE:
        expected = f"{REFUSED[option]} {declared.refused_as or declared.kind}"
    else:
        expected = f"{any_path}: {REFUSED[option]} {declared.kind}"
    assert str(refused.value) == expected


def test_an_openlane_segment_refuses_a_submission(any_path: Path) -> None:
    """The if-chain returned before its submission check for a segment, which then read
    the segment and ignored the submission; the table refuses it as for any source."""
    with pytest.raises(InputError, match="--submission applies to atmaCup tables, not to an "):
        open_run(any_path, source=SourceOptions("openlane", submission="sub.csv"))


def test_the_first_option_given_is_the_one_refused(any_path: Path) -> None:
    both = SourceOptions("atmacup", derived_collision=True, ego_agent="1")
    with pytest.raises(InputError, match="derived collision check"):
        open_run(any_path, source=both)


# --- a source registered in-process -------------------------------------------------------------


@pytest.fixture
def toy_source(monkeypatch: pytest.MonkeyPatch) -> Iterator[list[str]]:
    """A source ``toy`` (a ``*.toy`` file) taking submissions, asked before any other."""
    read: list[str] = []

    def _read(path: str | os.PathLike[str], request: ReadRequest) -> RunLog:
        read.append(f"{os.fspath(path)} {request.source.submission}")
        return RunLog(metadata=RunMetadata(50, (0.0, 0.0, 0.0), -1, 0, {}), frames=())

    module = types.ModuleType("ads_rca.sources.toy")
    module.SOURCE = Source(  # type: ignore[attr-defined]
        "toy", "a toy run", lambda path: path.suffix == ".toy", _read, frozenset({SUBMISSION})
    )
    monkeypatch.setitem(sys.modules, "ads_rca.sources.toy", module)
    monkeypatch.setattr(registry, "SOURCES", (*SOURCES, "toy"))
    monkeypatch.setattr(registry, "DETECTION_ORDER", ("toy", *DETECTION_ORDER))
    monkeypatch.setattr(registry, "FORMATS", (*FORMATS, "toy"))
    source_named.cache_clear()
    yield read
    source_named.cache_clear()


def test_a_source_registered_in_the_table_is_detected_read_and_named(
    tmp_path: Path, toy_source: list[str]
) -> None:
    run = _touch(tmp_path / "a.toy")
    assert detect_format(run) == "toy"
    open_run(run, source=SourceOptions(submission="s.csv"))
    assert toy_source == [f"{run} s.csv"]
    assert SourceOptions.from_values({"format": "toy"}).source_format == "toy"
    with pytest.raises(InputError, match=r"predictions applies to .* not to a toy run"):
        open_run(run, source=SourceOptions(predictions="p"))
    with pytest.raises(InputError, match="--submission applies to atmaCup tables and toy runs"):
        open_run(tmp_path, source=SourceOptions("log", submission="s.csv"))
