"""What the player sends and in which order: the timeline, frame markers, metadata and status.

Pure data (no rclpy) so the player node stays a thin loop and the assembler can read back
exactly what the player wrote. The timeline holds every analysed frame (``RunLog.frames``,
duplicates kept) plus every timestamp that has a record in some folder without being an
analysed frame ("records-only" stamps, e.g. a pose file with no actors file): publishing
those too is what makes the topic stream carry the whole log, losslessly.
"""

from __future__ import annotations

from bisect import bisect_left
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from ads_rca.contract import topics
from ads_rca.contract.convert import carried_plan_rows
from ads_rca.contract.jsontext import dumps_json, loads_json
from ads_rca.model import ALL_FOLDERS, RunLog, frame_number
from ads_rca.problems import Problem, problems_from_list
from ads_rca.sources.carla.annotations import Annotation, annotations_from_document

if TYPE_CHECKING:
    from std_msgs.msg import String

#: Key in the metadata message holding the exact ``metadata.json`` document.
METADATA_DOCUMENT_KEY = "metadata_json"
#: Key in the metadata message listing the problems found while reading the log.
INPUT_PROBLEMS_KEY = "input_problems"

PLAYING = "playing"
FINISHED = "finished"


@dataclass(frozen=True, slots=True)
class Tick:
    """One step of playback: a log timestamp and its place in the analysed-frame list."""

    stamp_ms: int
    index: int | None  # position in RunLog.frames; None for a records-only stamp
    duplicate: bool = False  # the same stamp already appeared earlier in RunLog.frames


def timeline(log: RunLog) -> list[Tick]:
    """Analysed frames in order, with records-only stamps merged in by time (ascending)."""
    analysed = set(log.frames)
    stamps: set[int] = set()
    for folder in ALL_FOLDERS:
        stamps.update(log.folder(folder))
    extras = sorted(stamps - analysed)
    ticks: list[Tick] = []
    seen: set[int] = set()
    position = 0
    for index, ts in enumerate(log.frames):
        while position < len(extras) and extras[position] < ts:
            ticks.append(Tick(extras[position], None))
            position += 1
        ticks.append(Tick(ts, index, ts in seen))
        seen.add(ts)
    ticks.extend(Tick(ts, None) for ts in extras[position:])
    return ticks


def select(ticks: list[Tick], start_frame: int = 0, stop_frame: int = -1) -> list[Tick]:
    """Ticks of analysed frames ``start_frame..stop_frame`` (inclusive; -1 = to the end).

    A records-only stamp travels with the analysed frame before it (those before the first
    frame travel with frame 0), so consecutive ranges partition the timeline.
    """
    analysed_at = [pos for pos, tick in enumerate(ticks) if tick.index is not None]
    count = len(analysed_at)
    stop = count - 1 if stop_frame < 0 else min(stop_frame, count - 1)
    if start_frame >= count or stop < start_frame:
        return []
    lo = 0 if start_frame <= 0 else analysed_at[start_frame]
    hi = len(ticks) if stop + 1 >= count else analysed_at[stop + 1]
    return ticks[lo:hi]


def frame_marker(
    tick: Tick, published: list[str], timesteps_per_frame: int, **extra: object
) -> String:
    """The ``run/frame`` message sent after a tick's data: what was published for it."""
    from std_msgs.msg import String

    frame_ms = timesteps_per_frame
    frame = frame_number(tick.stamp_ms, frame_ms) if frame_ms > 0 else None
    document = {
        "index": tick.index,
        "stamp_ms": tick.stamp_ms,
        "frame": frame,
        "published": published,
        "duplicate": tick.duplicate,
        **extra,
    }
    return String(data=dumps_json(document))


def annotations_by_tick(log: RunLog, ticks: list[Tick]) -> dict[int, list[Annotation]]:
    """Each annotation on the first tick at or after its time (those after the last tick on
    the last), keyed by the tick's position in ``ticks``; none before the first tick's
    time is lost either: it goes with the first."""
    found = annotations_from_document(log.metadata.raw)
    if not found or not ticks:
        return {}
    stamps = [tick.stamp_ms for tick in ticks]  # ascending (a timeline is)
    out: dict[int, list[Annotation]] = {}
    for annotation in found:
        position = bisect_left(stamps, annotation.timestamp_ms)
        out.setdefault(min(position, len(ticks) - 1), []).append(annotation)
    return out


def annotation_message(annotation: Annotation, **extra: object) -> String:
    """``run/annotations``: one annotation (kind, text, its time and file) as JSON."""
    from std_msgs.msg import String

    return String(data=dumps_json({**annotation.to_dict(), **extra}))


def dropped_plan_keys(log: RunLog, timestamp_ms: int) -> int:
    """How many plan keys at this stamp the trajectory cannot carry (non-integer keys)."""
    plan = log.waypoints.get(timestamp_ms)
    return 0 if plan is None else len(plan) - len(carried_plan_rows(plan))


def metadata_message(log: RunLog, **extra: object) -> String:
    """``run/metadata``: the metadata.json document's keys, plus what the run adds.

    Added keys: ``source``, ``frames`` (number of analysed frames), ``problems`` (number of
    reader problems), ``input_problems`` (those problems, as ``diagnose --json`` lists them:
    some oracles read them, e.g. a value the reader had to read as NaN is skipped, not
    judged) and ``metadata_json`` (the exact document, so a key of the document called
    ``source`` or ``frames`` is not lost).
    """
    from std_msgs.msg import String

    document = log.metadata_document()
    out: dict[str, Any] = dict(document)
    out.update(
        source=log.source,
        frames=len(log.frames),
        problems=len(log.problems),
        **extra,
    )
    out[INPUT_PROBLEMS_KEY] = [problem.to_dict() for problem in log.problems]
    out[METADATA_DOCUMENT_KEY] = document
    return String(data=dumps_json(out))


def read_input_problems(document: dict[str, Any]) -> list[Problem]:
    """The reader problems a metadata message lists (entries that are not one are skipped)."""
    return problems_from_list(document.get(INPUT_PROBLEMS_KEY))


def status_message(state: str, frames_published: int, **extra: object) -> String:
    """``player/status``: ``frames_published`` counts the ``run/frame`` markers sent."""
    from std_msgs.msg import String

    return String(data=dumps_json({"state": state, "frames_published": frames_published, **extra}))


def read_document(msg: String) -> dict[str, Any]:
    """The JSON object in a contract String message ({} if it is not an object)."""
    document = loads_json(msg.data)
    return document if isinstance(document, dict) else {}


def published_names(messages: Mapping[str, object]) -> list[str]:
    """Topic keys (relative names) of the data messages sent for a tick, in send order."""
    return [key for key in topics.DATA_TOPICS if key in messages]
