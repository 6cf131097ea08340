"""Wall and CPU time of a piece of work or of a whole child process, for the bench tables.

Every bench prints both: wall time alone hides whether a step was busy or waiting (for a
child, a pipe, a busy machine), and on two cores shared with other work the two can differ
a lot. CPU time is user + system seconds:

* :class:`Clock` (in this process): this process's CPU (``time.process_time``, every thread)
  plus the CPU of the child processes it reaped meanwhile (``RUSAGE_CHILDREN``: forked
  workers, node processes a launcher started and waited for, and whatever they reaped);
* :func:`run_child` (a whole process): ``os.wait4``'s usage of that child alone, with its
  reaped descendants and its peak resident set;
* :func:`process_cpu_s` (a process still running, Linux): ``/proc/<pid>/stat``.

A CPU figure above the wall figure means more than one core worked.
"""

from __future__ import annotations

import os
import resource
import signal
import statistics
import subprocess
import tempfile
import threading
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import IO, TypeVar

_T = TypeVar("_T")


@dataclass(frozen=True)
class Timing:
    """Wall seconds and CPU (user + system) seconds of one piece of work."""

    wall_s: float
    cpu_s: float

    def __add__(self, other: Timing) -> Timing:
        return Timing(self.wall_s + other.wall_s, self.cpu_s + other.cpu_s)

    @property
    def cores(self) -> float:
        """CPU over wall: how many cores were busy on average (NaN for no wall time)."""
        return self.cpu_s / self.wall_s if self.wall_s > 0 else float("nan")


def _children_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


class Clock:
    """Times the block it wraps: ``with Clock() as clock: ...`` then ``clock.timing``.

    CPU is this process's (all its threads) plus that of the children reaped within the
    block. Read ``clock.timing`` inside the block for the time so far; ``Clock().start()``
    starts one without a block (read it whenever).
    """

    def __init__(self) -> None:
        self._wall0 = self._cpu0 = self._children0 = 0.0
        self._done: Timing | None = None

    def __enter__(self) -> Clock:
        return self.start()

    def start(self) -> Clock:
        self._done = None
        self._wall0 = time.perf_counter()
        self._cpu0 = time.process_time()
        self._children0 = _children_cpu_s()
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        trace: TracebackType | None,
    ) -> None:
        self._done = self._now()

    def _now(self) -> Timing:
        cpu = time.process_time() - self._cpu0 + _children_cpu_s() - self._children0
        return Timing(time.perf_counter() - self._wall0, cpu)

    @property
    def timing(self) -> Timing:
        return self._done if self._done is not None else self._now()

    @property
    def wall_s(self) -> float:
        return self.timing.wall_s

    @property
    def cpu_s(self) -> float:
        return self.timing.cpu_s


def timed(work: Callable[[], _T]) -> tuple[_T, Timing]:
    """``work()``'s result and its :class:`Timing`."""
    with Clock() as clock:
        result = work()
    return result, clock.timing


def repeated(work: Callable[[], object], repeat: int) -> list[Timing]:
    """The timing of each of ``repeat`` calls of ``work`` (at least one)."""
    return [timed(work)[1] for _ in range(max(repeat, 1))]


def best(timings: Iterable[Timing]) -> Timing:
    """The least wall time and the least CPU time (each its own minimum)."""
    found = list(timings)
    return Timing(min(t.wall_s for t in found), min(t.cpu_s for t in found))


def median(timings: Iterable[Timing]) -> Timing:
    """The median wall time and the median CPU time (each its own median)."""
    found = list(timings)
    return Timing(
        statistics.median(t.wall_s for t in found), statistics.median(t.cpu_s for t in found)
    )


@dataclass(frozen=True)
class ChildRun:
    """One finished child process: exit code, wall and CPU time, peak memory, output."""

    returncode: int
    timing: Timing
    max_rss_mb: float
    stdout: str
    stderr: str
    #: Stopped for running past its time limit.
    timed_out: bool = False

    @property
    def wall_s(self) -> float:
        return self.timing.wall_s

    @property
    def cpu_s(self) -> float:
        return self.timing.cpu_s


def run_child(
    argv: Sequence[str],
    *,
    cwd: Path | str | None = None,
    env: Mapping[str, str] | None = None,
    capture: bool = True,
    timeout_s: float | None = None,
) -> ChildRun:
    """Run ``argv`` to its end; its wall time, and its CPU time and peak resident set from
    ``os.wait4`` (its own, with the descendants it reaped; nothing else of this process).

    Output goes to temporary files (any size, no pipe to drain meanwhile) and is returned
    decoded; with ``capture=False`` it is discarded. With ``timeout_s`` the child runs in a
    process group of its own, which is sent SIGINT when the time is up (so it can stop what
    it started) and SIGKILL 20 s later if it has not ended.
    """
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        sinks: tuple[int | IO[bytes], int | IO[bytes]] = (
            (out, err) if capture else (subprocess.DEVNULL, subprocess.DEVNULL)
        )
        start = time.perf_counter()
        child = subprocess.Popen(
            argv,
            cwd=cwd,
            env=env,
            stdout=sinks[0],
            stderr=sinks[1],
            start_new_session=timeout_s is not None,
        )
        stopper = _Stopper(child.pid, timeout_s)
        try:
            _pid, status, usage = os.wait4(child.pid, 0)
        except BaseException:
            child.kill()
            child.wait()
            raise
        finally:
            stopper.cancel()
        wall = time.perf_counter() - start
        child.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        err.seek(0)
        stdout = out.read().decode(errors="replace")
        stderr = err.read().decode(errors="replace")
    return ChildRun(
        child.returncode,
        Timing(wall, usage.ru_utime + usage.ru_stime),
        usage.ru_maxrss / 1024,
        stdout,
        stderr,
        stopper.fired,
    )


class _Stopper:
    """Interrupts a process group after a delay (then kills it), unless cancelled first."""

    def __init__(self, pid: int, delay_s: float | None) -> None:
        self.pid = pid
        self.fired = False
        self._done = threading.Event()
        self._thread: threading.Thread | None = None
        if delay_s is not None:
            self._thread = threading.Thread(target=self._run, args=(delay_s,), daemon=True)
            self._thread.start()

    def _run(self, delay_s: float) -> None:
        if self._done.wait(delay_s):
            return
        self.fired = True
        for sig, grace_s in ((signal.SIGINT, 20.0), (signal.SIGKILL, 0.0)):
            try:
                os.killpg(self.pid, sig)
            except ProcessLookupError:
                return
            if self._done.wait(grace_s):
                return

    def cancel(self) -> None:
        self._done.set()
        if self._thread is not None:
            self._thread.join()


def process_cpu_s(pid: int) -> float:
    """User + system CPU seconds of a running process (Linux /proc; NaN once it is gone)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return float("nan")
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def load_average() -> str:
    """The 1-, 5- and 15-minute load averages (other work on the same cores slows every
    figure down), or ``?`` where the system does not say."""
    try:
        return " ".join(Path("/proc/loadavg").read_text().split()[:3])
    except OSError:
        return "?"
