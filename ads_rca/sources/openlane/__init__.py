"""An OpenLane-V2 segment: traffic elements and lane graphs, and the benchmark's own figures
for a map-perception model.

``SOURCE``: a segment folder (an ``info/`` of ``<timestamp>.json`` files and no running log's
``actors/``), that ``info/`` itself, a dataset root holding ``data_dict_*.json``, or a split
folder (``val/``: segment folders); the last two are read as one line naming their segments.
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
#: Entries of a folder looked at for a segment folder (a split holds hundreds).
SPLIT_LOOK = 64


def _detect(path: Path) -> bool:
    if not path.is_dir() or not holds_no_running_log(path):
        return False
    if path.name == INFO:
        return True
    info = path / INFO
    try:
        if info.is_dir() and any(n.endswith(".json") for n in os.listdir(info)):
            return True
        names = os.listdir(path)
        if any(n.startswith(INDEX_PREFIX) and n.endswith(".json") for n in names):
            return True
        # A split folder: its entries are segment folders (names and stat only).
        return any((path / n / INFO).is_dir() for n in sorted(names)[:SPLIT_LOOK])
    except OSError:
        return False


def _read(path: str | os.PathLike[str], request: ReadRequest) -> RunLog:
    from ads_rca.sources.openlane.reader import read_openlane_segment

    return read_openlane_segment(path, request.max_file_mb, request.source)


SOURCE = Source("openlane", "an OpenLane-V2 segment", _detect, _read, frozenset({PREDICTIONS}))
