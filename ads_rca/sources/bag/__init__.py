"""rosbag2 bags (MCAP and sqlite3): our own topics, and real stacks' recordings read through
profiles (``profiles/``); the message types from the bag itself.

``SOURCE``: a bag directory or storage file (:func:`~ads_rca.sources.bag.paths.is_bag`),
read through the profile given (default: this project's topics, optionally remapped).
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING

from ads_rca.errors import InputError
from ads_rca.sources.bag.options import BagOptions
from ads_rca.sources.bag.paths import is_bag
from ads_rca.sources.formats import PROFILE, ReadRequest, Source, actors_reason

if TYPE_CHECKING:
    from ads_rca.model import RunLog

NAME = "bag"


def read_as_bag(path: str | os.PathLike[str], request: ReadRequest) -> RunLog | None:
    """``path`` read as the bag options of ``request`` say: through a stack's profile, or
    as this project's topics when they are remapped or ``path`` is a bag; None when
    neither (no bag option given, no bag: another reader's path)."""
    bag, remap = request.bag, request.remap
    if not bag.contract:
        if remap is not None:  # a remap given beside the options: the options' own check
            BagOptions(bag.profile, str(remap), bag.msg_path)
        if not is_bag(path):
            raise InputError(f"{os.fspath(path)}: profile {bag.profile!r} reads bags; not a bag")
        from ads_rca.sources.bag.profiles.recording import read_recording

        return read_recording(path, bag.profile, bag.msg_path, request.progress)
    if remap is not None or is_bag(path):
        from ads_rca.sources.bag.reader import read_bag

        return read_bag(path, remap=remap, progress=request.progress)
    return None


def _read(path: str | os.PathLike[str], request: ReadRequest) -> RunLog:
    found = read_as_bag(path, request) if is_bag(path) else None
    if found is None:  # not detected as a bag: --format forced it
        raise InputError(
            f"{os.fspath(path)}: --format {NAME}: not a bag (a .mcap or .db3 file, "
            "or a folder with metadata.yaml)"
        )
    return found


def _no_frame(where: str, log: RunLog, bag: BagOptions | None) -> str:
    if bag is not None and not bag.contract:
        profile = log.metadata.raw.get("source_profile") or bag.profile
        return (
            f"{where}: no frame to analyse: the frames are the {profile} profile's actors "
            f"messages, and its actors input gave none ({actors_reason(log) or 'no message'})"
        )
    return f"{where}: no frame to analyse: the bag has no run/frame marker and no actors message"


SOURCE = Source(NAME, "a bag", is_bag, _read, frozenset({PROFILE}), no_frame=_no_frame)
