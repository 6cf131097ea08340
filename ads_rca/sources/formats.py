"""What a source is and which options it takes: the declaration every source folder makes.

Every command that reads a run (and the player) takes ``--format`` / the ``format``
parameter: ``auto`` (the default) detects the source from the path, any other name forces
that source's reader. Each folder of :mod:`ads_rca.sources` declares its :class:`Source` in
its ``__init__.py`` (name, words, detection, reader, the options it takes), and
:mod:`ads_rca.sources.registry` lists them: nothing here names a source. Detection never
opens a file, so a FIFO or a huge file named like one of ours is refused by the reader that
opens it, with its one line.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ads_rca.errors import InputError

if TYPE_CHECKING:
    from ads_rca.foundation.progress import Progress
    from ads_rca.model import RunLog
    from ads_rca.sources.bag.options import BagOptions

AUTO = "auto"

#: The source options a source may take (:attr:`Source.options`), each refused in one line
#: by a source that does not (:data:`REFUSALS`).
DERIVED_COLLISION = "derived_collision"
EGO_AGENT = "ego_agent"
PREDICTIONS = "predictions"
SUBMISSION = "submission"
#: A bag's options: ``--profile`` other than the default, or ``--remap``.
PROFILE = "profile"

#: How a source refuses a given option it does not take, in the order they are checked:
#: ``{path}``, ``{takers}`` (the sources that take it, in words), ``{kind}`` (this one's
#: :attr:`Source.kind`), ``{refused_as}`` (its :attr:`Source.refused_as`).
REFUSALS: tuple[tuple[str, str], ...] = (
    (
        DERIVED_COLLISION,
        "{path}: the derived collision check applies to {takers}, not to {kind}",
    ),
    (EGO_AGENT, "{path}: ego_agent applies to {takers}, not to {kind}"),
    (
        PREDICTIONS,
        "{path}: --predictions applies to {takers} (which hold no predictions), not to {kind}",
    ),
    (SUBMISSION, "{path}: --submission applies to {takers}, not to {kind}"),
    (PROFILE, "--profile and --remap apply to bags, not to {refused_as}"),
)


@dataclass(frozen=True)
class ReadRequest:
    """What a source's reader is asked besides the path: ``source`` (its options), ``bag``
    (a profile, ``.msg`` directories) and ``remap`` (a topic remapping YAML, given beside
    ``bag`` or in it), ``max_file_mb`` (each file read whole at most), ``progress`` (sees
    the files read or the messages decoded) and ``workers`` (forked reader processes)."""

    source: SourceOptions
    bag: BagOptions
    remap: str | os.PathLike[str] | None
    max_file_mb: float
    progress: Progress | None = None
    workers: int = 1

    def given(self, option: str) -> bool:
        """Whether the user gave ``option`` (one of :data:`REFUSALS`' names)."""
        if option == PROFILE:
            return self.remap is not None or not self.bag.contract
        return bool(getattr(self.source, option))


@dataclass(frozen=True)
class Source:
    """One source of runs, declared by its folder (``SOURCE`` in its ``__init__.py``).

    ``name`` is what ``--format`` takes (the folder's name); ``kind`` what messages call one
    ("a bag"); ``detect`` says, by names and ``stat`` only, never opening a file,
    whether a path is one (asked in :data:`~ads_rca.sources.registry.DETECTION_ORDER`, so it
    may assume the earlier sources said no); ``read`` loads it (importing its reader then);
    ``options`` are the source options it takes (the others are refused before it reads);
    ``label`` names it in batch rows ("" = ``kind`` without its article; plural with an
    "s" in the refusals); ``refused_as`` names it when refusing a bag's options ("" =
    ``kind``); ``no_frame`` says why a run of it gives no frame (None: its actors gave
    none)."""

    name: str
    kind: str
    detect: Callable[[Path], bool]
    read: Callable[[str | os.PathLike[str], ReadRequest], RunLog]
    options: frozenset[str] = frozenset()
    label: str = ""
    refused_as: str = ""
    no_frame: Callable[[str, RunLog, BagOptions | None], str] | None = None

    @property
    def words(self) -> str:
        """How batch rows name it: :attr:`label`, else :attr:`kind` without its article."""
        return self.label or self.kind.split(" ", 1)[-1]


def holds_no_running_log(folder: Path) -> bool:
    """``folder`` has no ``actors/`` folder: a running log's own files beside a dataset's
    win over it, whatever else the folder holds (detection of the datasets asks it)."""
    return not (folder / "actors").is_dir()


def actors_reason(log: RunLog) -> str:
    """Where the run's actors came from and why they gave nothing, as its capability
    record says ("" when it says nothing)."""
    actors = log.inputs.get("actors")
    return "" if actors is None else ", ".join(x for x in (actors.source, actors.reason) if x)


#: The reader options a user gives by name (CLI flag, ``-p``, config key, ROS parameter).
SOURCE_PARAMS = ("format", DERIVED_COLLISION, EGO_AGENT, PREDICTIONS, SUBMISSION)
#: The longest ``ego_agent`` (the longest agent token a dataset names its agents by is 40
#: hex digits).
MAX_EGO_AGENT = 64


@dataclass(frozen=True)
class SourceOptions:
    """Which source reads a run (``format``) and the options a source may take (each
    source says which it takes, :attr:`Source.options`): ``derived_collision`` (a run that
    records no collision takes its first box overlap as one, flagged derived),
    ``ego_agent`` (which agent is the ego; "" = the source's default choice),
    ``predictions`` (a folder of a predictor's prediction files, or a model's results, to
    score; "" = none) and ``submission`` (a competition submission's predicted ego paths to
    score against the realised ones; "" = none)."""

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
        from ads_rca.sources.registry import checked_format

        derived = values.get("derived_collision", False)
        if isinstance(derived, str) and derived.strip().lower() in ("true", "false"):
            derived = derived.strip().lower() == "true"
        if not isinstance(derived, bool):
            raise InputError(f"derived_collision: expected true or false, not {shown(derived)}")
        ego = values.get("ego_agent", "")
        if isinstance(ego, int) and not isinstance(ego, bool):
            ego = str(ego)
        if not isinstance(ego, str) or len(ego) > MAX_EGO_AGENT or not ego.isprintable():
            raise InputError(
                f"ego_agent: expected an agent token or number (at most {MAX_EGO_AGENT} "
                f"printable characters), not {shown(ego)}"
            )
        predictions = values.get("predictions", "")
        if not isinstance(predictions, str):
            raise InputError(f"predictions: expected a folder path, not {shown(predictions)}")
        submission = values.get("submission", "")
        if not isinstance(submission, str):
            raise InputError(f"submission: expected a file path, not {shown(submission)}")
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


def shown(value: object) -> str:
    """A value a user gave, for a one-line message (at most 40 characters)."""
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."
