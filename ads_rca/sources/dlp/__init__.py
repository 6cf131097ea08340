"""A Dragon Lake Parking scene: one agent taken as the ego.

``SOURCE``: a ``DJI_XXXX_scene.json`` file, or a folder holding one and no running log's
``actors/`` (its frames, agents, instances and obstacles files beside it).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

from ads_rca.sources.formats import (
    DERIVED_COLLISION,
    EGO_AGENT,
    PREDICTIONS,
    ReadRequest,
    Source,
    holds_no_running_log,
)

if TYPE_CHECKING:
    from ads_rca.model import RunLog

#: How a scene file's name ends.
SCENE_SUFFIX = "_scene.json"


def _detect(path: Path) -> bool:
    if path.name.endswith(SCENE_SUFFIX) and not path.is_dir():
        return True
    if not path.is_dir() or not holds_no_running_log(path):
        return False
    try:
        return any(name.endswith(SCENE_SUFFIX) for name in os.listdir(path))
    except OSError:
        return False


def _read(path: str | os.PathLike[str], request: ReadRequest) -> RunLog:
    from ads_rca.sources.dlp.reader import read_dlp_scene
    from ads_rca.sources.log.reader import with_predictions

    options = request.source
    log = read_dlp_scene(path, request.max_file_mb, options)
    if options.predictions:
        return with_predictions(log, options.predictions, request.max_file_mb)
    return log


SOURCE = Source(
    "dlp",
    "a DLP scene",
    _detect,
    _read,
    frozenset({DERIVED_COLLISION, EGO_AGENT, PREDICTIONS}),
)
