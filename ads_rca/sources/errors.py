"""Failure kinds of reading and writing logs and bags (all :class:`~ads_rca.errors.AdsRcaError`).

A damaged file is not an error of the run: the readers catch :class:`CorruptRecord` and
:class:`InvalidJson` where they meet them and report a ``Problem`` (file skipped, rest of
the bag salvaged). Only :class:`OutputExists` reaches the user, as one line.
"""

from __future__ import annotations

from ads_rca.errors import AdsRcaError, InputError


class CorruptRecord(AdsRcaError, ValueError):
    """A storage record that cannot be what its header says (a length past its body, a
    compression it does not name): the walk stops or skips there and says so."""


class InvalidJson(AdsRcaError, ValueError):
    """A log file's bytes that are not JSON, or nest deeper than the parser reads."""


class StrictFileError(AdsRcaError, ValueError):
    """A value of an optional folder's file (3-D objects, control) that is not what the
    format says: the reader skips that file for that folder and reports the field."""

    def __init__(self, field: str, issue: str) -> None:
        super().__init__(f"{field}: {issue}")
        self.field = field
        self.issue = issue


class OutputExists(InputError, FileExistsError):
    """A bag is written only into a new or empty folder, never over another bag."""
