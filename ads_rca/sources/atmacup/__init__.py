"""An atmaCup #18 table: independent ego snapshots, and a submission's predicted ego paths
scored as the competition did.

``SOURCE``: ``train_features.csv`` or ``test_features.csv``, or a folder holding one and no
running log's ``actors/`` (``traffic_lights/`` beside it).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

from ads_rca.sources.formats import SUBMISSION, ReadRequest, Source, holds_no_running_log

if TYPE_CHECKING:
    from ads_rca.model import RunLog

#: The table files of an atmaCup #18 dataset folder (a folder must hold exactly one of them).
TABLE_FILES = ("train_features.csv", "test_features.csv")


def _detect(path: Path) -> bool:
    if path.name in TABLE_FILES and not path.is_dir():
        return True
    tables = any(os.path.lexists(path / name) for name in TABLE_FILES)
    return tables and path.is_dir() and holds_no_running_log(path)


def _read(path: str | os.PathLike[str], request: ReadRequest) -> RunLog:
    from ads_rca.sources.atmacup.reader import read_atmacup_table

    return read_atmacup_table(path, request.max_file_mb, request.source)


SOURCE = Source("atmacup", "an atmaCup table", _detect, _read, frozenset({SUBMISSION}))
