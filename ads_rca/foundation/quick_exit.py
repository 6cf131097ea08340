"""Ending the ``ads-rca`` program without freeing what a one-shot command loaded.

A diagnosis holds its run as millions of small objects. Freeing them one by one when the
process ends changes nothing but memory the operating system takes back anyway, and it
cost 0.05 to 0.09 s of a 1 s diagnosis of a 1,957-frame log and 0.6 s of a 10,000-frame,
50-actor one. So the program (:func:`ads_rca.cli.entry`) :func:`allow`\\ s it; a command
that is done hands what it loaded to :func:`keep_until_exit`, and the program, once its
output is flushed, ends with ``os._exit`` (as mypy does for the same reason). Everything a
command writes is closed before it returns; nothing it starts (forked workers, pools) is
still running by then.

A process that opened a Zenoh session must end this way too (:func:`require`). Zenoh's
native threads outlive every session and may still take the GIL while the interpreter
finalizes; Python then ends such a thread with ``pthread_exit``, whose unwinding through
Rust frames aborts the whole process (SIGABRT, "FATAL: exception not rethrown") after its
work was done and its output written: under load, 3 of 60 ``watch --exit-on-verdict`` runs.

``ads_rca.cli.main`` called in-process (tests, another program) never allows it: nothing
is kept, and the objects are freed as usual when the command returns.
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Callable
from typing import NoReturn

_allowed = False
_required = False
_kept: list[object] = []


def run_program(main: Callable[[], int]) -> NoReturn:
    """Run a program's ``main`` as the process, and end the process with its status: at
    once when a command asked for it (:func:`keep_until_exit`, :func:`require`)."""
    allow()
    status = main()
    if requested():
        exit_now(status)
    sys.exit(status)


def allow() -> None:
    """This process is the ``ads-rca`` program: it may end without freeing objects."""
    global _allowed  # noqa: PLW0603 - one process, one program
    _allowed = True


def keep_until_exit(*objects: object) -> None:
    """Keep ``objects`` alive until the program ends, and end it at once (when allowed;
    else nothing happens and they are freed as usual)."""
    if _allowed:
        _kept.extend(objects)


def require() -> None:
    """This process loaded native threads that must not meet a finalizing interpreter (a
    Zenoh session): when it is the program, it ends with ``os._exit``."""
    global _required  # noqa: PLW0603 - one process, one program
    _required = _allowed


def requested() -> bool:
    """A command kept objects for the quick exit, or required it."""
    return bool(_kept) or _required


def exit_now(status: int) -> NoReturn:
    """Flush the log handlers and the standard streams and end the process with
    ``status``, freeing nothing."""
    logging = sys.modules.get("logging")  # imported by what logs: none, no handler to flush
    if logging is not None:
        logging.shutdown()
    flush_standard_streams()
    os._exit(status)


def flush_standard_streams() -> None:
    """What stdout and stderr hold written out, before an ``os._exit`` or a fork (whose
    child would write it again)."""
    for stream in (sys.stdout, sys.stderr):
        # a reader gone, a stream closed or none at all: there is nothing left to keep
        with contextlib.suppress(OSError, ValueError, AttributeError):
            stream.flush()
