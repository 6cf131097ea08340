"""A CARLA experiment-client run folder: telemetry, plan, events as annotations, and the
client's own safety and comfort figures.

``SOURCE``: a folder holding a telemetry file and no running log's ``actors/``.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

from ads_rca.sources.formats import (
    DERIVED_COLLISION,
    PREDICTIONS,
    ReadRequest,
    Source,
    holds_no_running_log,
)

if TYPE_CHECKING:
    from ads_rca.model import RunLog

TELEMETRY_JSON = "telemetry.json"
TELEMETRY_CSV = "telemetry.csv"
#: Files whose presence makes a folder a CARLA experiment-client run.
TELEMETRY_FILES = (TELEMETRY_JSON, TELEMETRY_CSV)


def _detect(path: Path) -> bool:
    telemetry = any(os.path.lexists(path / name) for name in TELEMETRY_FILES)
    return telemetry and path.is_dir() and holds_no_running_log(path)


def _read(path: str | os.PathLike[str], request: ReadRequest) -> RunLog:
    from ads_rca.sources.carla.reader import read_carla_run
    from ads_rca.sources.log.reader import with_predictions

    options = request.source
    log = read_carla_run(path, request.max_file_mb, options.derived_collision)
    if options.predictions:
        return with_predictions(log, options.predictions, request.max_file_mb)
    return log


SOURCE = Source(
    "carla",
    "a CARLA run",
    _detect,
    _read,
    frozenset({DERIVED_COLLISION, PREDICTIONS}),
    refused_as="a CARLA run folder",
)
