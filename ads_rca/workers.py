"""Forked worker processes: whether forking is safe here, and a map over chunks in them.

Reading a long log and judging its frames are CPU-bound pure Python + numpy (threads do not
help); a forked worker inherits everything the parent has loaded without copying it, so the
work only needs the item it is given. Both the reader (files) and the engine (frames) map a
module-level function over chunks with :func:`map_forked` and handle the results in chunk
order (the reader puts its problems back in file order), so the outcome is the
single-process one; the callers keep that
single-process path for short inputs and where forking is not available.
"""

from __future__ import annotations

import gc
import sys
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import TypeVar

from ads_rca.errors import InputError

_T = TypeVar("_T")
_R = TypeVar("_R")

#: The most worker processes a command starts (``--workers``): far beyond any machine's
#: useful count, and a typo (``--workers 100000``) is an error, not a fork bomb.
MAX_WORKERS = 512


def checked_workers(workers: int, flag: str = "--workers") -> int:
    """``workers`` when it is 1 to :data:`MAX_WORKERS`; InputError naming ``flag`` else."""
    if not 1 <= workers <= MAX_WORKERS:
        raise InputError(f"{flag} {workers}: expected 1 to {MAX_WORKERS}")
    return workers


def can_fork() -> bool:
    """Fork only where it is the platform's safe default and no ROS context runs here
    (rclpy's threads and DDS sockets do not survive a fork)."""
    import multiprocessing

    return "fork" in multiprocessing.get_all_start_methods() and "rclpy" not in sys.modules


def map_forked(function: Callable[[_T], _R], items: Sequence[_T], workers: int) -> Iterator[_R]:
    """``function`` of each item in ``workers`` forked processes, yielded in items' order
    as they are done (the caller handles one while the workers compute the next).

    ``function`` must be a module-level function (the workers find it by name); what it
    needs beyond its item it reads from module globals set before this is called. The
    collector's objects are frozen meanwhile (:func:`loaded_objects_frozen`), so the
    workers' collections do not write to (and copy) every page they inherited.
    """
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    with loaded_objects_frozen():
        context = multiprocessing.get_context("fork")
        with ProcessPoolExecutor(max_workers=workers, mp_context=context) as pool:
            results = pool.map(function, items)  # forks the workers, collector as it was
            # Here, the results are unpickled: containers by the thousand, in no cycle.
            with collector_paused():
                yield from results


#: How many :func:`loaded_objects_frozen` blocks are open (the collector has one frozen set).
_frozen_depth = 0


@contextmanager
def loaded_objects_frozen() -> Iterator[None]:
    """Everything allocated so far out of the collector's sight until the outermost such
    block ends (blocks nest: an inner one freezes what is new and unfreezes nothing).

    A loaded run is millions of objects in no cycle; with them in sight every full
    collection walks them all, so building a 10,000-frame verdict document took three
    times as long. Frozen objects are still freed by reference counting.
    """
    global _frozen_depth  # noqa: PLW0603 - one frozen set per process, as the collector has
    gc.freeze()
    _frozen_depth += 1
    try:
        yield
    finally:
        _frozen_depth -= 1
        if _frozen_depth == 0:
            gc.unfreeze()


@contextmanager
def collector_paused() -> Iterator[None]:
    """The cyclic garbage collector off for a burst of allocations without cycles (decoded
    JSON, freed by reference counting), as it was after: its full passes over everything
    already loaded find nothing to free there and cost a few per cent of the reading."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            _skip_young_collections()
            gc.enable()


def _skip_young_collections() -> None:
    """Hand what was allocated while the collector was paused to the oldest generation
    without a scan (freezing it, then unfreezing it unless a :func:`loaded_objects_frozen`
    block is open: then it stays frozen with the loaded run). Else the first allocation
    after the pause starts a young collection over all of it (15 ms after reading a
    1,957-frame log) and the next middle and full ones walk it again (35 ms while building
    its corrected verdict). Garbage in a cycle among it is still found by a full
    collection."""
    gc.freeze()
    if _frozen_depth == 0:
        gc.unfreeze()
