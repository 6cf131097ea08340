"""Which reader a path needs: the input formats, told apart by names and ``stat`` only.

Every command that reads a run (and the player) takes ``--format`` / the ``format``
parameter: ``auto`` (the default) detects it from the path, any other name forces that
reader. Detection never opens a file, so a FIFO or a huge file named like one of ours is
refused by the reader that opens it, with its one line.
"""

from __future__ import annotations

import os
from pathlib import Path

from ads_rca.errors import InputError
from ads_rca.io.bag_paths import is_bag

AUTO = "auto"
#: An ADS running-log folder (seed 000: metadata.json and per-frame JSON folders).
LOG = "log"
#: A rosbag2 bag (directory, .mcap or .db3), read through a profile.
BAG = "bag"
#: A CARLA experiment-client run folder (telemetry.json or .csv, run_metadata.json ...).
CARLA = "carla"

#: Every name ``--format`` takes, ``auto`` first.
FORMATS = (AUTO, LOG, BAG, CARLA)

#: Files whose presence makes a folder a CARLA experiment-client run.
CARLA_TELEMETRY = ("telemetry.json", "telemetry.csv")


def checked_format(name: object) -> str:
    """``name`` when it is one of :data:`FORMATS`; InputError (one line) else."""
    if name not in FORMATS:
        shown = repr(name) if len(repr(name)) <= 40 else repr(name)[:37] + "..."
        raise InputError(f"format {shown}: expected one of {', '.join(FORMATS)}")
    return str(name)


def detect_format(path: str | os.PathLike[str]) -> str:
    """The format of ``path``: a bag, a CARLA run folder (a telemetry file and no
    ``actors/`` folder), else a running-log folder (whose reader says what is wrong)."""
    if is_bag(path):
        return BAG
    folder = Path(path)
    telemetry = any(os.path.lexists(folder / name) for name in CARLA_TELEMETRY)
    if telemetry and folder.is_dir() and not (folder / "actors").is_dir():
        return CARLA
    return LOG


def resolved_format(path: str | os.PathLike[str], name: str = AUTO) -> str:
    """``name`` checked, with ``auto`` replaced by what :func:`detect_format` finds."""
    name = checked_format(name)
    return detect_format(path) if name == AUTO else name
