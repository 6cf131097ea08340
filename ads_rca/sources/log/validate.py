"""Cross-file checks of a loaded log: what no single file can tell.

Duplicated timestamps, frames missing a file, timestamps off the frame grid or with gaps,
actors with no extent where they first appear, box and prediction ids that match no actor,
empty plans. Each becomes a Problem; runs of frames are reported as one line, not one per
frame, so that a log missing a whole stream stays readable.
"""

from __future__ import annotations

from collections import Counter, defaultdict
from collections.abc import Iterable, Sequence

import numpy as np

from ads_rca.model import FOLDERS, RunLog
from ads_rca.problems import CHECK_SKIPPED, IGNORED, KEPT_VALUE

#: Which folders an analysed frame needs (all of them except actors, which defines frames).
REQUIRED_PER_FRAME = tuple(f for f in FOLDERS if f != "actors")


def validate_run_log(
    log: RunLog,
    listings: dict[str, list[tuple[int, str]]],
    missing_folders: Sequence[str] = (),
) -> None:
    """Append every cross-file problem of ``log`` to ``log.problems``."""
    _duplicates(log, listings)
    _grid_and_gaps(log)
    _missing_files(log, [f for f in REQUIRED_PER_FRAME if f not in missing_folders], listings)
    _first_extents(log)
    _unknown_ids(log)
    _empty_plans(log)


def _duplicates(log: RunLog, listings: dict[str, list[tuple[int, str]]]) -> None:
    for folder, listing in listings.items():
        names: dict[int, list[str]] = defaultdict(list)
        for ts, name in listing:
            names[ts].append(name)
        for ts, group in names.items():
            if len(group) > 1:
                kept = group[-1]
                also = ", ".join(group[:-1])
                effect = (
                    " and the frame is analysed twice in reference mode"
                    if folder == "actors"
                    else ""
                )
                log.problems.add(
                    f"{folder}/{kept}",
                    "timestamp",
                    f"{ts} ms also given by {also}",
                    f"kept the last in directory order{effect}",
                    "warning",
                    ts,
                )


def _grid_and_gaps(log: RunLog) -> None:
    frame_ms = log.frame_ms
    frames = np.array(log.unique_frames, dtype=np.int64)
    if frames.size == 0:
        log.problems.add("actors/", "", "no actors files: no frame to analyse", IGNORED)
        return
    off_grid = frames[frames % frame_ms != 0]
    if off_grid.size:
        log.problems.add(
            "actors/",
            "timestamp",
            f"{off_grid.size} timestamps are not multiples of the {frame_ms} ms frame period "
            f"(first: {int(off_grid[0])} ms)",
            "analysed as they are; look-ahead by whole frames finds no data for them",
            "warning",
            int(off_grid[0]),
        )
    steps = np.diff(frames)
    for index in np.flatnonzero(steps > frame_ms):
        start, end = int(frames[index]), int(frames[index + 1])
        log.problems.add(
            "actors/",
            "timestamp",
            f"gap: no frame between {start} and {end} ms ({(end - start) // frame_ms - 1} missing)",
            "frames around the gap are analysed; look-ahead into it finds no data",
            "warning",
            start,
        )


def _missing_files(
    log: RunLog, folders: Iterable[str], listings: dict[str, list[tuple[int, str]]]
) -> None:
    frames = log.unique_frames
    for folder in folders:
        present = {ts for ts, _ in listings.get(folder, [])}
        missing = [ts for ts in frames if ts not in present]
        for first, last, count in _runs(missing, frames):
            span = f"{first} ms" if count == 1 else f"{first}-{last} ms ({count} frames)"
            log.problems.add(
                f"{folder}/", "", f"no file for frame {span}", CHECK_SKIPPED, "error", first
            )


def _runs(items: Sequence[int], order: Sequence[int]) -> list[tuple[int, int, int]]:
    """Group ``items`` into runs that are consecutive in ``order``: (first, last, count)."""
    position = {ts: i for i, ts in enumerate(order)}
    runs: list[tuple[int, int, int]] = []
    for ts in items:
        if runs and position[ts] == position[runs[-1][1]] + 1:
            first, _, count = runs[-1]
            runs[-1] = (first, ts, count + 1)
        else:
            runs.append((ts, ts, 1))
    return runs


def _first_extents(log: RunLog) -> None:
    seen: set[str] = set()
    # ids tuples all seen (by value: a log read in one process has a tuple a frame)
    all_seen: set[tuple[str, ...]] = set()
    for ts in sorted(log.actors):
        frame = log.actors[ts]
        if frame.ids in all_seen:
            continue
        all_seen.add(frame.ids)  # every id is seen once this frame is done
        for row, actor_id in enumerate(frame.ids):
            if actor_id in seen:
                continue
            seen.add(actor_id)
            if np.isnan(frame.extent[row]).any():
                later = actor_id in log.actor_extents
                log.problems.add(
                    log.file_of("actors", ts),
                    f"{actor_id}.extent",
                    "missing where the actor first appears",
                    "used its next known extent" if later else CHECK_SKIPPED,
                    "error",
                    ts,
                )


def _unknown_ids(log: RunLog) -> None:
    """Ground-truth box ids and predictions_with_perception ids must name actors."""
    for folder, records in (
        ("bboxes_gt", {ts: boxes.ids for ts, boxes in log.bboxes_gt.items()}),
        (
            "predictions_with_perception",
            {ts: tuple(p) for ts, p in log.predictions_with_perception.items()},
        ),
    ):
        unknown: Counter[str] = Counter()
        first_seen: dict[str, int] = {}
        # The unknown ids of each (ids, actors' ids) pair: most frames repeat a pair.
        known_pairs: dict[tuple[tuple[str, ...], tuple[str, ...]], list[str]] = {}
        for ts, ids in records.items():
            actors = log.actors.get(ts)
            if actors is None:
                continue
            pair = (ids, actors.ids)
            missing = known_pairs.get(pair)
            if missing is None:
                # In file order (not a set's hash order): the problems' order is output.
                missing = [a for a in dict.fromkeys(ids) if a not in actors.index]
                known_pairs[pair] = missing
            for actor_id in missing:
                unknown[actor_id] += 1
                first_seen.setdefault(actor_id, ts)
        for actor_id, count in unknown.items():
            ts = first_seen[actor_id]
            log.problems.add(
                log.file_of(folder, ts),
                "id",
                f"id {actor_id!r} is not an actor in the same frame ({count} frames)",
                KEPT_VALUE,
                "warning",
                ts,
            )


def _empty_plans(log: RunLog) -> None:
    empty = [ts for ts, plan in log.waypoints.items() if len(plan) == 0]
    for first, last, count in _runs(empty, sorted(log.waypoints)):
        span = f"{first} ms" if count == 1 else f"{first}-{last} ms ({count} frames)"
        log.problems.add(
            log.file_of("waypoint", first),
            "",
            f"empty plan at {span}",
            CHECK_SKIPPED,
            "error",
            first,
        )
