"""A recording of a real stack, read through a profile into a RunLog (one call for every
command and the player).

The bag's storage files are read once (:func:`ads_rca.sources.bag.reader.load_bag`), its message
types come from the bag itself (:mod:`ads_rca.sources.bag.message_types`, plus ``--msg-path``), the
profile says which topic and type carries each model input
(:mod:`ads_rca.sources.bag.profiles.profile`),
and the reader turns messages into model records (:mod:`ads_rca.sources.bag.profiles.reader`). The
input statuses (``RunLog.inputs``) travel in the run metadata (``model_inputs``), so the live
graph, which rebuilds the run from the player's topics, judges what ``diagnose`` judges.
"""

from __future__ import annotations

import os
from collections.abc import Sequence

from ads_rca.errors import InputError
from ads_rca.foundation.progress import Progress
from ads_rca.foundation.text import printable
from ads_rca.model import RunLog
from ads_rca.sources.bag.profiles.profile import Profile, load_profile
from ads_rca.sources.bag.profiles.reader import mismatches, read_profiled, stored_types
from ads_rca.sources.bag.reader import BagContents, BagMessage, load_bag


def read_recording(
    path: str | os.PathLike[str],
    profile: str | Profile,
    msg_path: Sequence[str | os.PathLike[str]] = (),
    progress: Progress | None = None,
    contents: BagContents | None = None,
) -> RunLog:
    """The run a bag of a real stack holds, read with ``profile`` (a name or a file).

    InputError (one line) when the bag cannot be read, carries none of the profile's
    reference inputs, or lacks the definition of a type the profile reads from it (naming
    every such type, and every topic stored as a type its input does not accept: that one's
    definition is never asked for); every other defect is a Problem in the log."""
    chosen = profile if isinstance(profile, Profile) else load_profile(profile)
    contents = contents if contents is not None else load_bag(path)
    types = contents.types(msg_path)
    read = {spec.topic for spec in chosen.inputs.values()}
    try:
        types.require(
            stored_types(contents.topics, chosen),
            {topic: kind for topic, kind in contents.topics.items() if topic in read},
        )
    except InputError as error:
        other = mismatches(contents.topics, chosen)
        if not other:
            raise
        raise InputError(
            printable(f"{error}; and not read as the profile says: " + "; ".join(other))
        ) from None

    def decode(message: BagMessage, type_name: str) -> object:
        return types.decode(message.data, type_name)

    def definition_of(type_name: str) -> str:
        source = types.source(type_name)
        words = _DEFINITION_WORDS.get(source or "", "its definition")
        if source == "bag" and types.differs_from_shipped(type_name):
            words += ", another layout than the one shipped with ads_rca"
        return words

    return read_profiled(contents, chosen, decode, os.fspath(path), progress, definition_of)


#: Where a type's definition came from (``BagTypes.source``), in words.
_DEFINITION_WORDS = {
    "bag": "the bag's own definition",
    "msg-path": "the definition under --msg-path",
    "shipped": "the definition shipped with ads_rca",
    "standard": "ROS Kilted's definition",
}


__all__ = ["read_recording"]
