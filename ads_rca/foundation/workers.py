"""Forked worker processes: whether forking is safe here, and a map over chunks in them.

Reading a long log and judging its frames are CPU-bound pure Python + numpy (threads do not
help); a forked worker inherits everything the parent has loaded without copying it, so the
work only needs the item it is given. Both the reader (files) and the engine (frames) map a
module-level function over chunks with :func:`map_forked` and handle the results in chunk
order (the reader puts its problems back in file order), so the outcome is the
single-process one; the callers keep that
single-process path for short inputs and where forking is not available.

The map forks its workers itself, without :mod:`multiprocessing`: importing it and
:mod:`concurrent.futures`, and an executor's thread and queues, cost ~20 ms a diagnosis
(two maps) for nothing these maps use. Each worker takes the next item's position from a
pipe of tickets (a free worker takes it: chunks differ in cost) and writes each result,
pickled and length-prefixed, to a pipe of its own; the parent reads whichever pipe has
data and unpickles the results itself, in items' order.
"""

from __future__ import annotations

import contextlib
import fcntl
import gc
import os
import pickle
import select
import signal
import struct
import sys
from collections.abc import Callable, Generator, Iterator, Sequence
from contextlib import contextmanager
from typing import Generic, NoReturn, TypeVar

from ads_rca.errors import AdsRcaError, InputError
from ads_rca.foundation.quick_exit import flush_standard_streams

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
    """Fork only where it is the platform's safe default (Linux: macOS's system libraries
    do not survive a fork, and spawning is its default) and no ROS context runs here
    (rclpy's threads and DDS sockets do not survive a fork)."""
    return sys.platform == "linux" and "rclpy" not in sys.modules


def map_forked(
    function: Callable[[_T], _R], items: Sequence[_T], workers: int
) -> Generator[_R, None, None]:
    """``function`` of each item in ``workers`` forked processes, yielded in items' order
    as they are done (the caller handles one while the workers compute the next).

    The workers are forked copies of this process: ``function`` and what it needs beyond
    its item (module globals set before this is called) are there, never sent; an item
    is sent as its position in ``items``, a result comes back pickled. The collector's
    objects are frozen meanwhile (:func:`loaded_objects_frozen`), so the workers'
    collections do not write to (and copy) every page they inherited. What an item
    raised in a worker is raised here in its turn; a worker that dies is a RuntimeError
    naming its item. When the caller stops early (an error, Ctrl-C), the workers still
    running are killed; all are reaped before this ends.
    """
    with loaded_objects_frozen():
        pool = _Pool(function, items)
        try:
            pool.start(min(workers, len(items)))  # the workers: the collector as it was
            # Here, the results are unpickled: containers by the thousand, in no cycle.
            with collector_paused():
                for index in range(len(items)):
                    yield pool.result(index)
        finally:
            pool.close()


#: What a worker writes before each message: the item's position, the message's kind and
#: the length of the pickle that follows.
_HEADER = struct.Struct("<IBQ")
#: The kinds: the worker took the item (so that its death names it), its result, its error.
_STARTED, _RESULT, _ERROR = range(3)
#: An item's position, as the workers take them from the pipe of tickets.
_TICKET = struct.Struct("<I")
#: Tickets a write: one of at most PIPE_BUF bytes is atomic, so a worker reads whole ones.
_TICKETS_PER_WRITE = select.PIPE_BUF // _TICKET.size
#: The room asked for in each worker's pipe (Linux's most without privilege, 64 KiB if
#: refused): a worker leaves a large result there while the parent handles an earlier one.
_PIPE_BYTES = 1 << 20
#: How results and errors are pickled (5: large buffers without extra copies).
_PROTOCOL = pickle.HIGHEST_PROTOCOL


class _Worker:
    """A forked worker as the parent sees it: its pipe and the message being read."""

    __slots__ = ("body", "fd", "got", "header", "index", "kind", "pid", "status")

    def __init__(self, pid: int, fd: int) -> None:
        self.pid = pid
        self.fd = fd
        self.header = bytearray(_HEADER.size)
        self.body: bytearray | None = None  # the message's pickle once its header is read
        self.got = 0  # bytes read of the header, then of the body
        self.kind = _RESULT
        self.index = -1  # the item it computes
        self.status: int | None = None  # once reaped


class _Pool(Generic[_T, _R]):
    """The workers of one :func:`map_forked`. They take the items' positions from a pipe
    of tickets the parent fills and closes; each writes its messages to a pipe of its own,
    and the parent reads whichever has data (never waiting on one while another worker
    waits on its full pipe), keeping results that come early until their turn."""

    def __init__(self, function: Callable[[_T], _R], items: Sequence[_T]) -> None:
        self._function = function
        self._items = items
        self._workers: list[_Worker] = []
        self._reading: dict[int, _Worker] = {}  # by pipe, until it ends
        self._done: dict[int, tuple[int, bytearray]] = {}
        self._delivered = 0
        self._poll = select.poll()
        self._tickets = -1  # the tickets' write end while some are to be written
        self._issued = 0

    def start(self, count: int) -> None:
        """Fork ``count`` workers, the tickets they take written as far as the pipe holds."""
        if count <= 0:
            return
        flush_standard_streams()  # else each worker would write what is buffered again
        takes, self._tickets = os.pipe()
        try:
            os.set_blocking(self._tickets, False)
            self._feed()
            if self._tickets >= 0:  # more tickets than the pipe holds: written as taken
                self._poll.register(self._tickets, select.POLLOUT)
            for _ in range(count):
                self._fork(takes)
        finally:
            os.close(takes)

    def _fork(self, takes: int) -> None:
        read_fd, write_fd = os.pipe()
        try:
            with contextlib.suppress(OSError):
                fcntl.fcntl(write_fd, fcntl.F_SETPIPE_SZ, _PIPE_BYTES)
            pid = os.fork()
        except BaseException:
            os.close(read_fd)
            os.close(write_fd)
            raise
        if pid == 0:
            for fd in (read_fd, self._tickets, *self._reading):
                if fd >= 0:
                    os.close(fd)
            _serve(self._function, self._items, takes, write_fd)
        os.close(write_fd)
        worker = _Worker(pid, read_fd)
        self._workers.append(worker)
        self._reading[read_fd] = worker
        self._poll.register(read_fd, select.POLLIN)

    def _feed(self) -> None:
        """Write the tickets the pipe has room for; close it after the last one (the end
        of the workers' work) or once no worker is left to read them."""
        count = len(self._items)
        while self._issued < count:
            stop = min(count, self._issued + _TICKETS_PER_WRITE)
            block = struct.pack(f"<{stop - self._issued}I", *range(self._issued, stop))
            try:
                os.write(self._tickets, block)
            except BlockingIOError:
                return
            except BrokenPipeError:
                break
            self._issued = stop
        with contextlib.suppress(KeyError):
            self._poll.unregister(self._tickets)
        os.close(self._tickets)
        self._tickets = -1

    def result(self, index: int) -> _R:
        """Item ``index``'s result (or its error raised), read as it comes."""
        while index not in self._done:
            if not self._reading:
                raise self._lost(index)
            for fd, _ in self._poll.poll():
                if fd == self._tickets:
                    self._feed()
                else:
                    self._read(self._reading[fd])
        kind, body = self._done.pop(index)
        self._delivered += 1
        if kind == _ERROR:
            raise _worker_error(body)
        result: _R = pickle.loads(body)
        return result

    def _read(self, worker: _Worker) -> None:
        """Read what ``worker`` has written, up to the end of its header or message."""
        buffer = worker.header if worker.body is None else worker.body
        got = os.readv(worker.fd, [memoryview(buffer)[worker.got :]])
        if got == 0:
            self._end(worker)
            return
        worker.got += got
        if worker.got < len(buffer):
            return
        worker.got = 0
        if worker.body is None:
            worker.index, worker.kind, size = _HEADER.unpack(worker.header)
            if worker.kind == _STARTED:
                return
            worker.body = bytearray(size)
            if size:
                return
        self._done[worker.index] = (worker.kind, worker.body)
        worker.body = None
        worker.index = -1

    def _end(self, worker: _Worker) -> None:
        """``worker``'s pipe is closed: it ran out of tickets, or it died (an error naming
        its item if it had one; else the item whose ticket it took is missed later)."""
        self._poll.unregister(worker.fd)
        os.close(worker.fd)
        del self._reading[worker.fd]
        if worker.index >= 0:
            raise RuntimeError(
                f"a worker process {_ending(_reap(worker))} while computing item"
                f" {self._named(worker.index)}"
            )

    def _lost(self, index: int) -> RuntimeError:
        """The error when every worker has ended without computing item ``index``."""
        endings = ", ".join(sorted({_ending(_reap(worker)) for worker in self._workers}))
        return RuntimeError(
            f"the worker processes ended ({endings}) without computing item {self._named(index)}"
        )

    def _named(self, index: int) -> str:
        return f"{index} of {len(self._items)} ({self._items[index]!r})"

    def close(self) -> None:
        """Close the pipes and reap every worker, killing those still running unless every
        result came (then they are ending of themselves, their output flushed)."""
        for fd in self._reading:
            os.close(fd)
        self._reading.clear()
        if self._tickets >= 0:
            os.close(self._tickets)
            self._tickets = -1
        if self._delivered < len(self._items):
            for worker in self._workers:
                if worker.status is None:
                    with contextlib.suppress(ProcessLookupError):
                        os.kill(worker.pid, signal.SIGKILL)
        for worker in self._workers:
            _reap(worker)


def _reap(worker: _Worker) -> int:
    """``worker``'s wait status, waiting for its end if it is not reaped yet."""
    if worker.status is None:
        worker.status = os.waitpid(worker.pid, 0)[1]
    return worker.status


def _ending(status: int) -> str:
    """How a process ended, from its wait status: 'was killed by SIGKILL', 'exited with 1'."""
    if os.WIFSIGNALED(status):
        number = os.WTERMSIG(status)
        try:
            return f"was killed by {signal.Signals(number).name}"
        except ValueError:
            return f"was killed by signal {number}"
    return f"exited with {os.waitstatus_to_exitcode(status)}"


def _serve(function: Callable[[_T], _R], items: Sequence[_T], takes: int, out: int) -> NoReturn:
    """A worker's life: compute the items whose tickets it takes, write each one's result
    or error, end when the tickets do. It ends with ``os._exit``, running none of the
    parent's cleanup (the ``finally`` blocks up its stack, atexit handlers)."""
    status = 0
    try:
        _leave_signals_to_parent()
        while ticket := os.read(takes, _TICKET.size):
            (index,) = _TICKET.unpack(ticket)
            _send(out, index, _STARTED, b"")
            try:
                kind, payload = _RESULT, pickle.dumps(function(items[index]), _PROTOCOL)
            except BaseException as error:  # the parent raises it, whatever it is
                kind, payload = _ERROR, _pickled_error(error)
            _send(out, index, kind, payload)
    except BaseException:  # the parent has gone (a broken pipe), or this process is broken
        status = 1
        with contextlib.suppress(BaseException):
            import traceback

            traceback.print_exc()
    finally:
        flush_standard_streams()
        os._exit(status)


def _leave_signals_to_parent() -> None:
    """A worker ignores Ctrl-C (the terminal sends it to the parent too, which kills the
    workers as it stops: one way out, no traceback a worker) and ends at any other signal
    the parent handles in Python (its handlers act on the parent's state, not a copy's).
    An ignored signal stays ignored."""
    for number in signal.valid_signals():
        if callable(signal.getsignal(number)):
            signal.signal(number, signal.SIG_IGN if number == signal.SIGINT else signal.SIG_DFL)


def _send(fd: int, index: int, kind: int, payload: bytes) -> None:
    """One message: its header, then ``payload`` whole (a pipe may take it in parts)."""
    parts = (_HEADER.pack(index, kind, len(payload)), payload)
    sent = os.writev(fd, parts)
    for part in parts:
        view = memoryview(part)[sent:]
        sent = max(0, sent - len(part))
        while view:
            view = view[os.write(fd, view) :]


def _pickled_error(error: BaseException) -> bytes:
    """``error`` for the parent: its traceback as text, a line naming it, and itself
    pickled when it can be (else the parent raises a RuntimeError with that line)."""
    import traceback  # 2.5 ms, for errors only

    try:
        pickled = pickle.dumps(error, _PROTOCOL)
    except Exception:
        pickled = b""
    text = "".join(traceback.format_exception(error))
    return pickle.dumps((text, f"{type(error).__name__}: {error}", pickled), _PROTOCOL)


class WorkerTraceback(AdsRcaError):
    """The cause of an exception raised in a worker process: the traceback there (the
    exception unpickled here has none of its own)."""

    def __str__(self) -> str:
        return f"\n{self.args[0]}"


def _worker_error(body: bytearray) -> BaseException:
    """The exception a worker sent (:func:`_pickled_error`), its traceback as its cause."""
    text, line, pickled = pickle.loads(body)
    error: object
    try:
        error = pickle.loads(pickled)
    except Exception:
        error = None
    if not isinstance(error, BaseException):
        error = RuntimeError(f"in a worker process: {line}")
    error.__cause__ = WorkerTraceback(text)
    return error


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
