"""A progress bar on stderr for the long steps of a command, on a terminal only.

Loading a long log takes seconds before the first frame is judged; a bar covers loading
(files read, bag messages decoded) and judging. Nothing is shown when stderr is not a
terminal (a pipe, a file, CI), nor for short steps, so logs and pipes stay clean.
"""

from __future__ import annotations

import sys
from collections.abc import Iterable, Sized
from typing import TypeVar

from ads_rca.foundation.progress import Progress

T = TypeVar("T")

#: Steps with fewer items than this finish too fast for a bar.
MIN_ITEMS = {"loading": 1000, "judging": 300}
UNITS = {"loading": "item", "judging": "frame"}


def terminal_bar(step: str) -> Progress | None:
    """The bar of ``step`` ("loading" or "judging") when stderr is a terminal, else None."""
    if not sys.stderr.isatty():
        return None

    def wrap(items: Iterable[T], /) -> Iterable[T]:
        if isinstance(items, Sized) and len(items) < MIN_ITEMS[step]:
            return items
        from tqdm import tqdm

        # leave=False: the bar is cleared when the step ends, so the terminal keeps only
        # the results.
        bar: Iterable[T] = tqdm(items, desc=step, unit=UNITS[step], file=sys.stderr, leave=False)
        return bar

    return wrap
