"""Structured reports of what was wrong in an input, and what we did about it.

Nothing in ads_rca raises on bad input data: every defect becomes a :class:`Problem` naming
the file and field, what was wrong and the action taken (frame skipped, record dropped,
default used, value kept). The CLI prints them one per line; the JSON output lists them.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Iterator
from dataclasses import asdict, dataclass
from typing import Any, Literal

from ads_rca.foundation.text import printable

Severity = Literal["error", "warning"]

# What the reader (or an oracle) did about a problem.
SKIPPED_FILE = "file skipped"
SKIPPED_FRAME = "frame skipped"
DROPPED_RECORD = "record dropped"
USED_DEFAULT = "default used"
KEPT_VALUE = "value kept"
CHECK_SKIPPED = "check skipped for this frame"
IGNORED = "ignored"


@dataclass(frozen=True, slots=True)
class Problem:
    """One defect of the input: where (file, field), what, and what was done."""

    file: str
    field: str
    issue: str
    action: str
    severity: Severity = "error"
    timestamp_ms: int | None = None

    def __str__(self) -> str:
        """One terminal line: text from the log has its control characters escaped."""
        where = f"{self.file}: {self.field}" if self.field else self.file
        return printable(f"{self.severity}: {where}: {self.issue} ({self.action})")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, document: object) -> Problem:
        """The inverse of :meth:`to_dict` (raises ValueError for anything else)."""
        if not isinstance(document, dict):
            raise ValueError(f"a problem is a JSON object, not {type(document).__name__}")
        texts = [document.get(k) for k in ("file", "field", "issue", "action")]
        severity = document.get("severity", "error")
        stamp = document.get("timestamp_ms")
        if not all(isinstance(t, str) for t in texts) or severity not in ("error", "warning"):
            raise ValueError(f"not a problem: {document!r}")
        if stamp is not None and (not isinstance(stamp, int) or isinstance(stamp, bool)):
            raise ValueError(f"timestamp_ms must be an integer: {document!r}")
        file, field, issue, action = (str(t) for t in texts)
        return cls(file, field, issue, action, severity, stamp)

    @property
    def key(self) -> tuple[str, str, str]:
        """What makes two reports the same problem: file, field and issue."""
        return (self.file, self.field, self.issue)


def problems_from_list(entries: object) -> list[Problem]:
    """The problems a JSON list holds (:meth:`Problem.from_dict`); entries that are not one,
    or a value that is not a list, are skipped."""
    out: list[Problem] = []
    for entry in entries if isinstance(entries, list) else []:
        try:
            out.append(Problem.from_dict(entry))
        except ValueError:
            continue
    return out


def new_problems(problems: Iterable[Problem], seen: set[tuple[str, str, str]]) -> list[Problem]:
    """Problems not reported before (by :attr:`Problem.key`); ``seen`` is updated."""
    out = []
    for problem in problems:
        if problem.key not in seen:
            seen.add(problem.key)
            out.append(problem)
    return out


class ProblemLog:
    """An append-only list of problems, shared by every stage that reads the input."""

    def __init__(self, problems: Iterable[Problem] = ()) -> None:
        self._problems: list[Problem] = list(problems)

    def add(
        self,
        file: str,
        field: str,
        issue: str,
        action: str,
        severity: Severity = "error",
        timestamp_ms: int | None = None,
    ) -> None:
        self._problems.append(Problem(file, field, issue, action, severity, timestamp_ms))

    def extend(self, problems: Iterable[Problem]) -> None:
        self._problems.extend(problems)

    def __iter__(self) -> Iterator[Problem]:
        return iter(self._problems)

    def __len__(self) -> int:
        return len(self._problems)

    def __bool__(self) -> bool:
        return bool(self._problems)

    def summary_lines(self, limit: int = 20) -> list[str]:
        """One line per problem, at most ``limit``, then a count of the rest by issue."""
        lines = [str(p) for p in self._problems[:limit]]
        rest = self._problems[limit:]
        if rest:
            by_issue = Counter(p.issue.split(":")[0] for p in rest)
            kinds = ", ".join(f"{n}× {issue}" for issue, n in by_issue.most_common(5))
            lines.append(printable(f"... and {len(rest)} more problems ({kinds})"))
        return lines
