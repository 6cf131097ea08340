"""The runs in flight: submitted lazily, at most a window of them at a time.

Issue 43: ``batch`` submitted one task per run up front. At 100k runs the client built
100k futures and the scheduler 100k tasks before the first row (~90 s), the client held
1.7 GB, and Ctrl-C had 100k futures to cancel (a ``TimeoutError`` after 80 s). A
:class:`Window` submits the next run only when one has been answered, so the client holds
at most :func:`window_size` runs' jobs and futures whatever the batch's size, the first
row comes as soon as the first run is done, and an interrupted batch has only the window
to cancel. It knows nothing of Dask: ``submit`` is any function that starts a run and
returns a handle (the shell's: ``client.submit`` and ``as_completed.add``), so the
scheduling is tested without a cluster.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Iterable, Iterator
from typing import Generic, TypeVar

_Run = TypeVar("_Run")

#: In-flight runs per worker thread: one running, the rest queued on the worker, so no
#: thread waits for the client's round trip between two runs.
PER_THREAD = 4
#: The smallest and largest window (a remote cluster's threads are counted at the start).
MIN_WINDOW = 8
MAX_WINDOW = 4096


def window_size(threads: int) -> int:
    """Runs in flight for ``threads`` worker threads: enough to keep each busy while the
    client writes rows, few enough that the client holds next to nothing per batch size."""
    return max(MIN_WINDOW, min(MAX_WINDOW, PER_THREAD * max(threads, 1)))


class Window(Generic[_Run]):
    """At most ``size`` runs of ``runs`` submitted and not yet answered.

    :meth:`fill` submits runs (drawn lazily from ``runs``) until ``size`` are in flight;
    :meth:`answered` takes a run's handle back and submits the next; :attr:`in_flight`
    is what an interrupted batch cancels.
    """

    def __init__(
        self,
        runs: Iterable[_Run],
        submit: Callable[[_Run], Hashable],
        size: int,
    ) -> None:
        if size < 1:
            raise ValueError(f"a window of {size} runs")
        self.size = size
        self._runs: Iterator[_Run] = iter(runs)
        self._submit = submit
        self._in_flight: dict[Hashable, _Run] = {}
        self.submitted = 0
        self.exhausted = False

    @property
    def in_flight(self) -> list[Hashable]:
        """The handles of the runs submitted and not yet answered."""
        return list(self._in_flight)

    def __len__(self) -> int:
        return len(self._in_flight)

    def fill(self) -> None:
        """Submit runs until ``size`` are in flight or there is none left."""
        while not self.exhausted and len(self._in_flight) < self.size:
            run = next(self._runs, None)
            if run is None:
                self.exhausted = True
                return
            handle = self._submit(run)
            self._in_flight[handle] = run
            self.submitted += 1

    def answered(self, handle: Hashable) -> _Run:
        """The run ``handle`` was submitted for, out of the window (the next one submitted)."""
        run = self._in_flight.pop(handle)
        self.fill()
        return run

    def stop(self) -> list[Hashable]:
        """No more runs: the in-flight handles, for cancelling; the window is emptied."""
        self.exhausted = True
        handles = list(self._in_flight)
        self._in_flight.clear()
        return handles

    @property
    def done(self) -> bool:
        """Every run submitted and answered."""
        return self.exhausted and not self._in_flight
