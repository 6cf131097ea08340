"""Which reader a path needs: the input formats, told apart by names and ``stat`` only.

Every command that reads a run (and the player) takes ``--format`` / the ``format``
parameter: ``auto`` (the default) detects it from the path, any other name forces that
reader. Detection never opens a file, so a FIFO or a huge file named like one of ours is
refused by the reader that opens it, with its one line.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ads_rca.errors import InputError
from ads_rca.sources.bag.paths import is_bag

if TYPE_CHECKING:
    from ads_rca.model import RunLog
    from ads_rca.sources.bag.options import BagOptions

AUTO = "auto"
#: An ADS running-log folder (seed 000: metadata.json and per-frame JSON folders).
LOG = "log"
#: A rosbag2 bag (directory, .mcap or .db3), read through a profile.
BAG = "bag"
#: A CARLA experiment-client run folder (telemetry.json or .csv, run_metadata.json ...).
CARLA = "carla"
#: A Dragon Lake Parking scene: ``DJI_XXXX_scene.json`` (or a folder holding one) and its
#: frames, agents, instances and obstacles files beside it.
DLP = "dlp"
#: An OpenLane-V2 segment: ``<segment>/info/<timestamp>.json`` (the segment folder or its
#: ``info/``).
OPENLANE = "openlane"

#: An atmaCup #18 driving table: ``train_features.csv`` or ``test_features.csv`` (or a
#: folder holding one), ``traffic_lights/`` beside it.
ATMACUP = "atmacup"

#: Every name ``--format`` takes, ``auto`` first.
FORMATS = (AUTO, LOG, BAG, CARLA, DLP, ATMACUP, OPENLANE)
#: What each format is, as messages name it.
FORMAT_NAMES = {
    BAG: "a bag",
    LOG: "a running log",
    CARLA: "a CARLA run",
    DLP: "a DLP scene",
    OPENLANE: "an OpenLane-V2 segment",
    ATMACUP: "an atmaCup table",
}

#: Files whose presence makes a folder a CARLA experiment-client run.
CARLA_TELEMETRY = ("telemetry.json", "telemetry.csv")
DLP_SCENE = "_scene.json"
#: The folder of an OpenLane-V2 segment's per-frame files, and the split index's prefix.
OPENLANE_INFO = "info"
OPENLANE_INDEX = "data_dict_"
#: The table files of an atmaCup #18 dataset folder.
ATMACUP_TABLES = ("train_features.csv", "test_features.csv")


#: The reader options a user gives by name (CLI flag, ``-p``, config key, ROS parameter).
SOURCE_PARAMS = ("format", "derived_collision", "ego_agent", "predictions", "submission")
#: The longest ``ego_agent`` (a DLP token is 40 hex digits).
MAX_EGO_AGENT = 64


@dataclass(frozen=True)
class SourceOptions:
    """Which reader reads a run (``format``) and the options of the dataset formats:
    ``derived_collision`` (a CARLA or DLP run's first box overlap is its collision, flagged
    derived), ``ego_agent`` (which DLP agent is the ego; "" = the default choice),
    ``predictions`` (a folder of a predictor's prediction files to score against a CARLA
    run's or a DLP scene's realised future; "" = none) and ``submission`` (an atmaCup #18
    submission CSV, predicted ego paths to score against the table's realised ones; "" =
    none)."""

    source_format: str = AUTO
    derived_collision: bool = False
    ego_agent: str = ""
    predictions: str = ""
    submission: str = ""

    @classmethod
    def from_values(cls, values: Mapping[str, Any]) -> SourceOptions:
        """From :data:`SOURCE_PARAMS` values as a user gives them (text from ``-p`` or a
        launch argument, typed from YAML or a ROS parameter), each checked: InputError,
        one line naming it."""
        derived = values.get("derived_collision", False)
        if isinstance(derived, str) and derived.strip().lower() in ("true", "false"):
            derived = derived.strip().lower() == "true"
        if not isinstance(derived, bool):
            raise InputError(f"derived_collision: expected true or false, not {_shown(derived)}")
        ego = values.get("ego_agent", "")
        if isinstance(ego, int) and not isinstance(ego, bool):
            ego = str(ego)
        if not isinstance(ego, str) or len(ego) > MAX_EGO_AGENT or not ego.isprintable():
            raise InputError(
                f"ego_agent: expected an agent token or number (at most {MAX_EGO_AGENT} "
                f"printable characters), not {_shown(ego)}"
            )
        predictions = values.get("predictions", "")
        if not isinstance(predictions, str):
            raise InputError(f"predictions: expected a folder path, not {_shown(predictions)}")
        submission = values.get("submission", "")
        if not isinstance(submission, str):
            raise InputError(f"submission: expected a file path, not {_shown(submission)}")
        return cls(
            checked_format(values.get("format", AUTO)),
            derived,
            ego.strip(),
            predictions,
            submission,
        )

    def as_params(self) -> dict[str, str | bool]:
        """The same options as the player's ROS parameters."""
        return {
            "format": self.source_format,
            "derived_collision": self.derived_collision,
            "ego_agent": self.ego_agent,
            "predictions": str(Path(self.predictions).resolve()) if self.predictions else "",
            "submission": str(Path(self.submission).resolve()) if self.submission else "",
        }


def _shown(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def checked_format(name: object) -> str:
    """``name`` when it is one of :data:`FORMATS`; InputError (one line) else."""
    if name not in FORMATS:
        raise InputError(f"format {_shown(name)}: expected one of {', '.join(FORMATS)}")
    return str(name)


def detect_format(path: str | os.PathLike[str]) -> str:
    """The format of ``path``: a bag, a CARLA run folder (a telemetry file and no
    ``actors/`` folder), a DLP scene (a ``_scene.json`` file, or a folder with one and no
    ``actors/``), an atmaCup table (``train_features.csv`` / ``test_features.csv``, or a
    folder with one and no ``actors/``), else a running-log folder (whose reader says what
    is wrong). After CARLA's and DLP's checks: an OpenLane-V2 segment (a folder with an
    ``info/`` of JSON files and no ``actors/``, that ``info/`` itself, or a dataset root
    holding ``data_dict_*.json``)."""
    if is_bag(path):
        return BAG
    folder = Path(path)
    if folder.name.endswith(DLP_SCENE) and not folder.is_dir():
        return DLP
    if folder.name in ATMACUP_TABLES and not folder.is_dir():
        return ATMACUP
    tables = any(os.path.lexists(folder / name) for name in ATMACUP_TABLES)
    if tables and folder.is_dir() and not (folder / "actors").is_dir():
        return ATMACUP
    telemetry = any(os.path.lexists(folder / name) for name in CARLA_TELEMETRY)
    if telemetry and folder.is_dir() and not (folder / "actors").is_dir():
        return CARLA
    if folder.is_dir() and not (folder / "actors").is_dir():
        try:
            if any(name.endswith(DLP_SCENE) for name in os.listdir(folder)):
                return DLP
        except OSError:
            pass
    if _openlane(folder):
        return OPENLANE
    return LOG


def _openlane(folder: Path) -> bool:
    """An OpenLane-V2 segment (a folder with an ``info/`` of ``*.json`` files and no
    ``actors/``, or that ``info/`` itself) or a dataset root (``data_dict_*.json``), by names."""
    if not folder.is_dir() or (folder / "actors").is_dir():
        return False
    if folder.name == OPENLANE_INFO:
        return True
    info = folder / OPENLANE_INFO
    try:
        if info.is_dir() and any(n.endswith(".json") for n in os.listdir(info)):
            return True
        return any(n.startswith(OPENLANE_INDEX) and n.endswith(".json") for n in os.listdir(folder))
    except OSError:
        return False


def resolved_format(path: str | os.PathLike[str], name: str = AUTO) -> str:
    """``name`` checked, with ``auto`` replaced by what :func:`detect_format` finds."""
    name = checked_format(name)
    return detect_format(path) if name == AUTO else name


def no_frame_message(
    path: str | os.PathLike[str],
    log: RunLog,
    source_format: str = AUTO,
    bag: BagOptions | None = None,
) -> str:
    """Why ``log``, read from ``path`` (a bag with ``bag``'s options), gives no frame to
    analyse, in terms of what the input is (``diagnose`` and the player refuse it in this
    one line): a running log its own ``actors/`` files; a bag read through a stack's profile
    the input whose messages make the frames (actors) and why it gave none; a bag of this
    project's contract its frame markers and actors topic; another dataset its actors."""
    where = os.fspath(path)
    fmt = resolved_format(path, source_format)
    if fmt == LOG:
        return f"{where}: no frame to analyse (no readable actors/ file)"
    actors = log.inputs.get("actors")
    why = "" if actors is None else ", ".join(x for x in (actors.source, actors.reason) if x)
    if fmt == BAG and bag is not None and not bag.contract:
        profile = log.metadata.raw.get("source_profile") or bag.profile
        return (
            f"{where}: no frame to analyse: the frames are the {profile} profile's actors "
            f"messages, and its actors input gave none ({why or 'no message'})"
        )
    if fmt == BAG:
        return (
            f"{where}: no frame to analyse: the bag has no run/frame marker and no actors message"
        )
    detail = f" (actors: {why})" if why else ""
    return f"{where}: no frame to analyse in {FORMAT_NAMES[fmt]}{detail}"
