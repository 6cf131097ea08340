"""The forked map (:func:`ads_rca.foundation.workers.map_forked`) with real forks: results in order
whatever the items cost, a worker's exception raised in the parent, a dead worker an error
rather than a hang, workers killed and reaped when the caller stops early, no descriptor
left open, large results whole."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from types import FrameType

import pytest

from ads_rca.errors import InputError
from ads_rca.foundation.workers import WorkerTraceback, can_fork, map_forked

# Not can_fork(): the suite's ROS tests load rclpy into this process, and the map itself
# forks wherever it is asked to (its callers ask can_fork() first).
pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="forked workers need Linux")

#: No test here may take longer: a hang is a failure, not a stuck run.
WATCHDOG_S = 30.0


class Hung(Exception):
    pass


@pytest.fixture(autouse=True)
def watchdog() -> Iterator[None]:
    """Fail a test that waits for more than :data:`WATCHDOG_S` (the alarm interrupts the
    parent's wait; the workers reset its handler and the timer is not inherited)."""

    def expire(signum: int, frame: FrameType | None) -> None:
        raise Hung(f"no answer within {WATCHDOG_S} s")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, WATCHDOG_S)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def children() -> set[int]:
    """This process's children, zombies included (from /proc)."""
    found = set()
    me = os.getpid()
    for name in os.listdir("/proc"):
        if name.isdigit():
            try:
                stat = Path(f"/proc/{name}/stat").read_text()
            except OSError:  # ended meanwhile
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == me:
                found.add(int(name))
    return found


def open_fds() -> int:
    return len(os.listdir("/proc/self/fd"))


def _square(n: int) -> int:
    return n * n


def _slow_first(n: int) -> tuple[int, int]:
    """Item 0 takes 0.5 s, the others 10 ms: the worker and the item."""
    time.sleep(0.5 if n == 0 else 0.01)
    return os.getpid(), n


def _fails_at_3(n: int) -> int:
    if n == 3:
        raise ValueError(f"bad item {n}")
    return n


def _input_error(n: int) -> int:
    raise InputError(f"log/{n}.json: too large")


class _Unpicklable(Exception):
    def __init__(self, a: int, b: int) -> None:
        super().__init__(f"{a} and {b}")


def _raises_unpicklable(n: int) -> int:
    raise _Unpicklable(n, n + 1)


def _dies_at_2(n: int) -> int:
    if n == 2:
        os.kill(os.getpid(), signal.SIGKILL)
    time.sleep(0.01)
    return n


def _exits_at_1(n: int) -> int:
    if n == 1:
        os._exit(3)
    return n


def _sleeps(n: int) -> int:
    time.sleep(0.05 if n == 0 else 5.0)
    return os.getpid()


def _ctrl_c_here(n: int) -> str:
    os.kill(os.getpid(), signal.SIGINT)
    time.sleep(0.01)
    return "went on"


#: Bytes a big result holds (the judged frames of a long log are megabytes).
BIG = 20 * 1024 * 1024


def _big(n: int) -> bytes:
    return bytes([n]) * 17 + bytes(range(256)) * (BIG // 256)


def test_results_come_in_items_order_and_a_free_worker_takes_the_next_item() -> None:
    before = open_fds()
    done = list(map_forked(_slow_first, range(10), 2))
    assert [n for _, n in done] == list(range(10))
    slow_worker = done[0][0]
    # While one worker spends 0.5 s on item 0, the other takes every other item.
    assert all(pid != slow_worker for pid, _ in done[1:])
    assert children() == set()
    assert open_fds() == before


def test_more_workers_than_items_and_no_items() -> None:
    assert list(map_forked(_square, range(3), 8)) == [0, 1, 4]
    assert list(map_forked(_square, [], 2)) == []
    assert list(map_forked(_square, range(5), 1)) == [0, 1, 4, 9, 16]


def test_more_items_than_the_pipe_of_tickets_holds() -> None:
    count = 20_000  # 4 bytes a ticket: more than a 64 KiB pipe holds at once
    assert list(map_forked(_square, range(count), 2)) == [n * n for n in range(count)]


def test_an_exception_in_a_worker_is_raised_in_its_turn_with_its_type_and_message() -> None:
    before = open_fds()
    got: list[int] = []
    with pytest.raises(ValueError, match=r"^bad item 3$") as raised:
        got.extend(map_forked(_fails_at_3, range(8), 2))
    assert got == [0, 1, 2]  # the items before it, all of them
    cause = raised.value.__cause__
    assert isinstance(cause, WorkerTraceback) and "_fails_at_3" in str(cause)
    assert children() == set()
    assert open_fds() == before


def test_an_input_error_stays_an_input_error() -> None:
    with pytest.raises(InputError, match=r"^log/0\.json: too large$"):
        list(map_forked(_input_error, range(4), 2))


def test_an_exception_that_does_not_unpickle_is_a_runtime_error_naming_it() -> None:
    with pytest.raises(RuntimeError, match=r"in a worker process: _Unpicklable: 0 and 1"):
        list(map_forked(_raises_unpicklable, range(4), 2))


def test_a_worker_killed_mid_map_is_an_error_naming_its_item() -> None:
    before = open_fds()
    with pytest.raises(RuntimeError, match=r"killed by SIGKILL while computing item 2 of 6"):
        list(map_forked(_dies_at_2, range(6), 2))
    assert children() == set()
    assert open_fds() == before


def test_a_worker_exiting_without_its_result_is_an_error_naming_its_item() -> None:
    with pytest.raises(RuntimeError, match=r"exited with 3 while computing item 1 of 4 \(1\)"):
        list(map_forked(_exits_at_1, range(4), 2))
    assert children() == set()


def test_a_caller_stopping_early_kills_and_reaps_every_worker() -> None:
    before = open_fds()
    results = map_forked(_sleeps, range(6), 2)
    first = next(results)
    running = children()
    assert first in running and len(running) == 2
    results.close()  # the other worker is 5 s into its item: killed, not waited for
    assert children() == set()
    for pid in running:
        with pytest.raises(ChildProcessError):  # reaped: no zombie left
            os.waitpid(pid, os.WNOHANG)
    assert open_fds() == before


def test_an_error_in_the_callers_loop_kills_and_reaps_every_worker() -> None:
    before = open_fds()
    started = time.monotonic()
    with pytest.raises(KeyError):
        for _ in map_forked(_sleeps, range(6), 2):
            raise KeyError("the caller's")
    assert time.monotonic() - started < 2.0
    assert children() == set()
    assert open_fds() == before


def test_ctrl_c_while_waiting_kills_and_reaps_every_worker() -> None:
    def interrupt(signum: int, frame: FrameType | None) -> None:
        raise KeyboardInterrupt

    before = open_fds()
    previous = signal.signal(signal.SIGALRM, interrupt)
    try:
        signal.setitimer(signal.ITIMER_REAL, 0.3)
        with pytest.raises(KeyboardInterrupt):
            list(map_forked(_sleeps, range(6), 2))
    finally:
        signal.signal(signal.SIGALRM, previous)
    assert children() == set()
    assert open_fds() == before


def test_a_worker_leaves_ctrl_c_to_the_parent() -> None:
    """The terminal sends Ctrl-C to the workers too: they go on until the parent kills them
    (no KeyboardInterrupt traceback from each)."""
    assert list(map_forked(_ctrl_c_here, range(3), 2)) == ["went on"] * 3


def test_big_results_arrive_whole() -> None:
    before = open_fds()
    for n, result in enumerate(map_forked(_big, range(4), 2)):
        assert result == _big(n)
    assert open_fds() == before


def test_buffered_output_is_written_once_and_nothing_is_imported_for_the_pool() -> None:
    """The parent's buffered stdout is flushed before the fork (else every worker would
    write it again at its end); the pool needs neither multiprocessing nor
    concurrent.futures (each costs milliseconds to import)."""
    code = (
        "import sys\n"
        "from ads_rca.foundation.workers import can_fork, map_forked\n"
        "def square(n): return n * n\n"
        "print('before', end='')\n"
        "assert can_fork() and list(map_forked(square, range(4), 2)) == [0, 1, 4, 9]\n"
        "loaded = {'multiprocessing', 'concurrent'} & {m.split('.')[0] for m in sys.modules}\n"
        "print(' after', sorted(loaded))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout == "before after []\n"


def test_no_fork_where_ros_runs(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delitem(sys.modules, "rclpy", raising=False)  # another test loaded it
    assert can_fork()
    monkeypatch.setitem(sys.modules, "rclpy", object())
    assert not can_fork()
