"""Readers and writers of run logs. :func:`open_run` picks the reader for a path."""

from __future__ import annotations

import os

from ads_rca.model import RunLog


def open_run(path: str | os.PathLike[str]) -> RunLog:
    """Load a run from any supported source (today: an ADS running-log folder)."""
    from ads_rca.io.json_log import read_run_log

    return read_run_log(path)
