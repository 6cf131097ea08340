"""Ctrl-C in a batch: stop between two rows, close quickly; a second Ctrl-C exits at once.

Python raises ``KeyboardInterrupt`` wherever the main thread is: in a row half written, in
distributed's own code (issue 43: a ``KeyboardInterrupt`` inside a client call became a
``TimeoutError`` traceback). Here the first SIGINT only raises where the batch waits for
its next answer (:meth:`Interruption.waiting`), where nothing is half done; anywhere else
it is noted and raised at the next :meth:`Interruption.check` (after the row being written
is whole). A second SIGINT, while the batch closes, calls ``exit_now``: the user asked
twice, so nothing more is waited for (the rows written are whole; ``--resume`` redoes the
rest). No Dask here: the shell gives ``exit_now``.
"""

from __future__ import annotations

import signal
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from types import FrameType
from typing import NoReturn


class Interruption:
    """The batch's SIGINT handler (see the module docstring)."""

    def __init__(self, exit_now: Callable[[], NoReturn]) -> None:
        self.requested = False
        self._exit_now = exit_now
        self._waiting = False

    def handle(self, signum: int, frame: FrameType | None) -> None:
        """The signal handler: the first Ctrl-C stops the batch, the second exits."""
        if self.requested:
            self._exit_now()
        self.requested = True
        if self._waiting:
            self._waiting = False
            raise KeyboardInterrupt

    def check(self) -> None:
        """``KeyboardInterrupt`` if Ctrl-C came meanwhile (call it between two rows)."""
        if self.requested:
            raise KeyboardInterrupt

    @contextmanager
    def waiting(self) -> Iterator[None]:
        """A wait Ctrl-C may cut short at once (nothing is being written)."""
        self.check()
        self._waiting = True
        try:
            yield
        finally:
            self._waiting = False

    @contextmanager
    def installed(self) -> Iterator[Interruption]:
        """This object as SIGINT's handler for the block (the previous one restored). An
        ignored SIGINT (a batch started in the background) stays ignored."""
        previous = signal.getsignal(signal.SIGINT)
        try:
            if previous is not signal.SIG_IGN:
                signal.signal(signal.SIGINT, self.handle)
        except ValueError:  # not the main thread: no handler of ours
            previous = signal.SIG_IGN
        try:
            yield self
        finally:
            if previous is not signal.SIG_IGN:
                signal.signal(signal.SIGINT, signal.SIG_DFL if previous is None else previous)
