"""An ADS running-log folder (the reference tool's format): reading it with the reference's
rules, writing one, packing parsed records between processes.

``SOURCE``: the source that takes any path no other source claims (its reader says what is
wrong with it); given a bag's options it reads the path as a bag would be read, so a
profile or remapping on a folder is refused by the bag's reader, in its words.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

from ads_rca.errors import InputError
from ads_rca.sources.bag.paths import is_bag
from ads_rca.sources.formats import PROFILE, ReadRequest, Source

if TYPE_CHECKING:
    from ads_rca.model import RunLog
    from ads_rca.sources.bag.options import BagOptions

NAME = "log"


def _read(path: str | os.PathLike[str], request: ReadRequest) -> RunLog:
    from ads_rca.sources.bag import read_as_bag
    from ads_rca.sources.log.reader import read_run_log

    if is_bag(path):  # detection never says log for a bag: --format forced it
        raise InputError(f"{os.fspath(path)}: --format {NAME}: this is a bag")
    found = read_as_bag(path, request)
    if found is not None:
        return found
    return read_run_log(path, request.max_file_mb, request.progress, request.workers)


def _no_frame(where: str, log: RunLog, bag: BagOptions | None) -> str:
    return f"{where}: no frame to analyse (no readable actors/ file)"


def _any(path: Path) -> bool:
    return True


SOURCE = Source(
    NAME,
    "a running log",
    _any,
    _read,
    frozenset({PROFILE}),
    label="log folder",
    no_frame=_no_frame,
)
