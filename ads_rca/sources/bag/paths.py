"""What is a bag on disk, by names and ``stat`` only (never opened).

Every command that takes a log folder or a bag asks :func:`is_bag` first; it lives apart
from the bag readers so that a log folder is read without importing them (and rosbags).
"""

from __future__ import annotations

import os
from pathlib import Path

BAG_SUFFIXES = (".mcap", ".db3")
METADATA_YAML = "metadata.yaml"


def present(path: Path) -> bool:
    """``path`` names something other than a directory (a FIFO or a dangling symlink too:
    what it is is said when it is read). Only ``stat``s: never opens."""
    return os.path.lexists(path) and not path.is_dir()


def storage_files(directory: Path) -> list[Path]:
    """Everything in ``directory`` named like a storage file (regular or not)."""
    return sorted(p for p in directory.iterdir() if p.suffix in BAG_SUFFIXES and present(p))


def is_bag(path: str | os.PathLike[str]) -> bool:
    """A bag directory (metadata.yaml, or storage files: a split recording whose
    metadata.yaml was never written has several) or a .mcap/.db3 file."""
    p = Path(path)
    if p.is_dir():
        return present(p / METADATA_YAML) or bool(storage_files(p))
    return p.suffix in BAG_SUFFIXES and present(p)
