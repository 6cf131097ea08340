"""The progress hook of the long steps: files read, bag messages decoded, frames judged.

A step hands its items to the hook and iterates over what it gets back, so the core never
knows whether (or how) progress is shown: ``diagnose`` passes a bar on a terminal
(:mod:`ads_rca.commands.progress_bar`), everything else passes nothing.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from typing import Protocol, TypeVar

T = TypeVar("T")


class Progress(Protocol):
    """Yields back every item of ``items``, in order (showing progress on the way)."""

    def __call__(self, items: Iterable[T], /) -> Iterable[T]: ...


def tracked(items: Iterable[T], progress: Progress | None) -> Iterable[T]:
    """``items`` through ``progress`` when there is one."""
    return items if progress is None else progress(items)


def advancer(
    items: Sequence[T], progress: Callable[[Iterable[T]], Iterable[T]] | None
) -> Callable[[int], None]:
    """For items handled elsewhere in chunks (worker processes): a function that moves the
    progress of ``items`` on by so many items."""
    if progress is None:
        return lambda done: None
    bar = iter(progress(items))

    def advance(done: int) -> None:
        for _ in range(done):
            next(bar, None)

    return advance
