"""The sources and the scorers of their data: :func:`open_run` (which source a path is, and
its reader) and the figures a run's data gives beside the verdict.

Each folder named in :data:`SOURCES` declares its :class:`~ads_rca.sources.formats.Source`
(``SOURCE`` in its ``__init__.py``, imported when first asked for: a source's reader only
when it reads). Everything that depends on which sources exist derives from this table:
``--format``'s names (:data:`FORMATS`), what ``auto`` detects (:data:`DETECTION_ORDER`), which
options a path may be given (:func:`refuse_options`), how batch rows and messages name a
source.

Each module named in :data:`SCORERS` holds a :class:`~ads_rca.diagnosis.Scorer` (``SCORER``),
imported only when a run holds what it scores (:class:`ScorerEntry`): the engine
(:func:`scored_entries`), the summary (:func:`scores_summary_lines`), the not-judged results
(:func:`scored_frame`) and the live statuses (:func:`scored_status`) ask them all, in the
table's order, and never name one.
"""

from __future__ import annotations

import importlib
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ads_rca.diagnosis.scoring import FrameScores, Scorer
from ads_rca.errors import InputError
from ads_rca.foundation.files import DEFAULT_MAX_FILE_MB
from ads_rca.sources.bag.options import BagOptions
from ads_rca.sources.formats import (
    AUTO,
    REFUSALS,
    ReadRequest,
    Source,
    SourceOptions,
    actors_reason,
    shown,
)

if TYPE_CHECKING:
    from ads_rca.diagnosis.verdict import FrameResults, Metric, Module, OracleResult
    from ads_rca.foundation.progress import Progress
    from ads_rca.model import RunLog
    from ads_rca.params import Params

#: The sources, each a folder of :mod:`ads_rca.sources` of that name, in the order
#: ``--format`` lists them (and the refusals name the sources taking an option).
SOURCES: tuple[str, ...] = ("log", "bag", "carla", "dlp", "atmacup", "openlane")
#: The order ``auto`` asks the sources whether a path is theirs: the first to say yes
#: reads it (a folder holding both a CARLA telemetry file and an atmaCup table is the
#: table); the running log last, as it takes what no other does (its reader says what is
#: wrong).
DETECTION_ORDER: tuple[str, ...] = ("bag", "atmacup", "carla", "dlp", "openlane", "log")
#: Every name ``--format`` takes, ``auto`` first.
FORMATS: tuple[str, ...] = (AUTO, *SOURCES)


@cache
def source_named(name: str) -> Source:
    """The declaration of source ``name`` (one of :data:`SOURCES`)."""
    if name not in SOURCES:
        raise KeyError(name)
    found = importlib.import_module(f"{__package__}.{name}").SOURCE
    assert isinstance(found, Source) and found.name == name, name
    return found


def checked_format(name: object) -> str:
    """``name`` when it is one of :data:`FORMATS`; InputError (one line) else."""
    if name not in FORMATS:
        raise InputError(f"format {shown(name)}: expected one of {', '.join(FORMATS)}")
    return str(name)


def detect_format(path: str | os.PathLike[str]) -> str:
    """The source ``path`` is: the first of :data:`DETECTION_ORDER` whose ``detect`` says
    so (by names and ``stat`` only); the last one takes any path."""
    folder = Path(path)
    found = (n for n in DETECTION_ORDER if source_named(n).detect(folder))
    return next(found, DETECTION_ORDER[-1])


def resolved_format(path: str | os.PathLike[str], name: str = AUTO) -> str:
    """``name`` checked, with ``auto`` replaced by what :func:`detect_format` finds."""
    name = checked_format(name)
    return detect_format(path) if name == AUTO else name


def refuse_options(path: str | os.PathLike[str], source: Source, request: ReadRequest) -> None:
    """InputError (one line, :data:`~ads_rca.sources.formats.REFUSALS`) for the first
    option given that ``source`` does not take."""
    for option, message in REFUSALS:
        if option in source.options or not request.given(option):
            continue
        takers = [source_named(n).words + "s" for n in SOURCES if option in source_named(n).options]
        raise InputError(
            message.format(
                path=os.fspath(path),
                takers=listed(takers),
                kind=source.kind,
                refused_as=source.refused_as or source.kind,
            )
        )


def listed(words: list[str], conjunction: str = "and") -> str:
    """``a``, ``a and b``, ``a, b and c`` (or another conjunction)."""
    return f" {conjunction} ".join(filter(None, (", ".join(words[:-1]), words[-1])))


def open_run(
    path: str | os.PathLike[str],
    remap: str | os.PathLike[str] | None = None,
    max_file_mb: float = DEFAULT_MAX_FILE_MB,
    progress: Progress | None = None,
    bag: BagOptions | None = None,
    workers: int = 1,
    source: SourceOptions | None = None,
) -> RunLog:
    """Load a run from any source (``source.source_format``; ``auto`` tells them apart by
    the path), with the options that source takes (``source``'s; a bag's ``bag``, ``remap``
    = topic remapping YAML for this project's topics, also ``bag.remap``); any other option
    given is refused in one line before anything is read. ``max_file_mb`` caps each file
    read whole (larger ones are reported and skipped); ``progress`` sees the files read, or
    the bag messages decoded; ``workers`` > 1 reads a long log folder in that many forked
    processes."""
    bag = bag or BagOptions()
    source = source or SourceOptions()
    remap = remap if remap is not None else bag.remap
    if not os.path.lexists(path):
        raise InputError(f"{os.fspath(path)}: no such log folder or bag")
    chosen = source_named(resolved_format(path, source.source_format))
    request = ReadRequest(source, bag, remap, max_file_mb, progress, workers)
    refuse_options(path, chosen, request)
    return chosen.read(path, request)


def no_frame_message(
    path: str | os.PathLike[str],
    log: RunLog,
    source_format: str = AUTO,
    bag: BagOptions | None = None,
) -> str:
    """Why ``log``, read from ``path`` (a bag with ``bag``'s options), gives no frame to
    analyse, in terms of what the input is (``diagnose`` and the player refuse it in this
    one line): the source's own words when it has them (:attr:`Source.no_frame`), else its
    actors and why they gave none."""
    where = os.fspath(path)
    chosen = source_named(resolved_format(path, source_format))
    if chosen.no_frame is not None:
        return chosen.no_frame(where, log, bag)
    why = actors_reason(log)
    detail = f" (actors: {why})" if why else ""
    return f"{where}: no frame to analyse in {chosen.kind}{detail}"


def _nothing(log: RunLog) -> bool:
    return False


@dataclass(frozen=True)
class ScorerEntry:
    """Where a scorer lives and when a run has anything for it, asked before importing it.

    ``module`` holds ``SCORER``; ``keys`` are the verdict JSON keys it writes (its
    :attr:`~ads_rca.diagnosis.Scorer.keys`: the summary asks it only about a document
    holding one); ``scores`` is the module whose not-judged results it scores frame by
    frame, when the run holds what it scores (``frame_data``); the engine asks it for its
    entries when a frame of that module carries its scores or the run holds what its
    entries come from besides (``run_data``)."""

    name: str
    module: str
    keys: tuple[str, ...]
    scores: Module | None = None
    frame_data: Callable[[RunLog], bool] = _nothing
    run_data: Callable[[RunLog], bool] = _nothing

    def scorer(self) -> Scorer:
        """The scorer itself (its module imported on first use)."""
        return _scorer(self.module)

    def wanted(self, log: RunLog, frames: Sequence[FrameResults]) -> bool:
        """The run judged as ``frames`` has something for :meth:`Scorer.document`."""
        if self.run_data(log):
            return True
        if self.scores is None:
            return False
        # Imported here: the CLI and the launch description read this table without the model.
        from ads_rca.capabilities import NOT_JUDGED

        module = self.scores
        return any(_scored(f.results.get(module), NOT_JUDGED) for f in frames)


@cache
def _scorer(module: str) -> Scorer:
    found = importlib.import_module(module).SCORER
    assert isinstance(found, Scorer), module
    return found


def _scored(result: OracleResult | None, not_judged: str) -> bool:
    """``result`` was not judged (its reason starts ``not_judged``) and carries metrics."""
    return bool(result and result.metrics and (result.skipped or "").startswith(not_judged))


def _metadata_holds(*keys: str) -> Callable[[RunLog], bool]:
    return lambda log: any(key in log.metadata.raw for key in keys)


#: The scorers, in the order their keys come in the verdict JSON.
SCORERS: tuple[ScorerEntry, ...] = (
    ScorerEntry(
        "run_notes",
        "ads_rca.sources.carla.figures",
        ("annotations", "run_figures"),
        run_data=_metadata_holds("annotations", "run_figures"),
    ),
    ScorerEntry(
        "prediction",
        "ads_rca.sources.predictor.scores",
        ("prediction_scores",),
        "prediction",
        frame_data=lambda log: bool(log.predictions),
    ),
    ScorerEntry(
        "lanes",
        "ads_rca.sources.openlane.run_scores",
        ("openlane_scores",),
        "perception",
        frame_data=lambda log: bool(log.lanes or log.lanes_predicted),
    ),
    ScorerEntry(
        "trajectory",
        "ads_rca.sources.atmacup.trajectory_scores",
        ("trajectory_scores",),
        "planning",
        frame_data=lambda log: log.ego_snapshots is not None,
        run_data=lambda log: log.ego_snapshots is not None,
    ),
)
#: The order the summary tells them (by :attr:`ScorerEntry.name`): scores of the run's
#: frames first, what the run says about itself last.
SUMMARY_ORDER: tuple[str, ...] = ("prediction", "trajectory", "lanes", "run_notes")


def scored_entries(log: RunLog, frames: Sequence[FrameResults], semantics: str) -> dict[str, Any]:
    """Every scorer's verdict JSON entries for the run judged as ``frames``, in order."""
    out: dict[str, Any] = {}
    for entry in SCORERS:
        if entry.wanted(log, frames):
            out.update(entry.scorer().document(log, frames, semantics))
    return out


def scores_summary_lines(document: Mapping[str, Any], shown: int = 10) -> list[str]:
    """Every scorer's summary lines for a verdict ``document``, in :data:`SUMMARY_ORDER`."""
    named = {entry.name: entry for entry in SCORERS}
    lines: list[str] = []
    for entry in (named[name] for name in SUMMARY_ORDER):
        if any(key in document for key in entry.keys):
            lines.extend(entry.scorer().summary_lines(document, shown))
    return lines


def scored_frame(
    module: Module, log: RunLog, timestamp_ms: int, params: Params, kept: dict[str, Any]
) -> FrameScores:
    """A not-judged ``module``'s scores at one frame: the first scorer of that module with
    any (``kept``: every scorer's state over the run, by name)."""
    for entry in SCORERS:
        if entry.scores == module and entry.frame_data(log):
            state = kept.setdefault(entry.name, {})
            found = entry.scorer().frame_scores(log, timestamp_ms, params, state)
            if found.metrics:
                return found
    return FrameScores({}, {})


def scored_status(result: OracleResult) -> str | None:
    """What a live status says of a not-judged result a scorer scored (None: none did)."""
    metrics: Mapping[str, Metric] = result.metrics
    for entry in SCORERS:
        if entry.scores == result.module and metrics:
            text = entry.scorer().status_text(metrics)
            if text is not None:
                return text
    return None
