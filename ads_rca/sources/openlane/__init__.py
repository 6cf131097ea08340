"""An OpenLane-V2 segment: traffic elements and lane graphs, and the benchmark's own figures
for a map-perception model.

``SOURCE``: a segment folder (an ``info/`` of ``<timestamp>.json`` files and no running log's
``actors/``), that ``info/`` itself, or a dataset root holding ``data_dict_*.json``.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

from ads_rca.sources.formats import PREDICTIONS, ReadRequest, Source, holds_no_running_log

if TYPE_CHECKING:
    from ads_rca.model import RunLog

#: The folder of a segment's per-frame files, and the split index's prefix.
INFO = "info"
INDEX_PREFIX = "data_dict_"


def _detect(path: Path) -> bool:
    if not path.is_dir() or not holds_no_running_log(path):
        return False
    if path.name == INFO:
        return True
    info = path / INFO
    try:
        if info.is_dir() and any(n.endswith(".json") for n in os.listdir(info)):
            return True
        return any(n.startswith(INDEX_PREFIX) and n.endswith(".json") for n in os.listdir(path))
    except OSError:
        return False


def _read(path: str | os.PathLike[str], request: ReadRequest) -> RunLog:
    from ads_rca.sources.openlane.reader import read_openlane_segment

    return read_openlane_segment(path, request.max_file_mb, request.source)


SOURCE = Source("openlane", "an OpenLane-V2 segment", _detect, _read, frozenset({PREDICTIONS}))
