"""Opening and closing a Zenoh session so the process can exit.

A process that exits with an open session holding subscribers, publishers or queryables
hangs at interpreter exit, so every owner undeclares what it declared and closes the session
on every exit path, through :func:`close_session`. Zenoh's threads outlive the session, so
a program that opened one ends without finalizing the interpreter
(:func:`ads_rca.foundation.quick_exit.require`).
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterable
from types import TracebackType
from typing import Any, Self

from ads_rca.foundation import quick_exit


def open_session(config_text: str) -> Any:
    """A Zenoh session of the JSON5 configuration ``config_text`` (``zenoh.ZError`` when it
    cannot open)."""
    import zenoh

    quick_exit.require()
    return zenoh.open(zenoh.Config.from_json5(config_text))


def close_session(session: Any, declared: Iterable[Any]) -> None:
    """Undeclare ``declared`` (each failure ignored: the session may be gone already), then
    close ``session`` (None: nothing to close)."""
    for entity in declared:
        with contextlib.suppress(Exception):
            entity.undeclare()
    if session is not None:
        session.close()


class SessionOwner:
    """``with owner:`` opens it and closes it however the block ends (subclasses define
    ``open`` returning themselves and ``close``, safe to call twice)."""

    def open(self) -> Self:
        raise NotImplementedError

    def close(self) -> None:
        raise NotImplementedError

    def __enter__(self) -> Self:
        return self.open()

    def __exit__(
        self,
        kind: type[BaseException] | None,
        value: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()
