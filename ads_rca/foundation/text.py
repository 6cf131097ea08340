"""Text from a log made safe for a terminal: control characters shown as escapes.

A log is untrusted: a file name, an actor id or a field value can hold a newline (and so
forge a whole output line such as ``verdict: planning``), an ANSI escape sequence (clear the
screen, recolour, move the cursor) or a bidi override (show text in another order than it
is). Everything human-facing that can carry such text goes through :func:`printable`.
JSON outputs keep the exact strings: JSON escapes control characters itself.

How a figure or an id is shown in a line (:func:`short`, :func:`precise`, :func:`metres`,
:func:`shown_id`) is here too, so the summary, the live statuses and every scorer of a
run's data show them alike.
"""

from __future__ import annotations

import re
import reprlib

#: C0 controls (tab and newline included), DEL, C1 controls, the Unicode line and
#: paragraph separators, the bidi embedding/override/isolate controls, and lone surrogates
#: (JSON's ``"\ud800"`` parses to one, and no terminal or UTF-8 file can take it).
_UNSAFE = re.compile(
    "[\x00-\x1f\x7f-\x9f\u2028\u2029\u200e\u200f\u202a-\u202e\u2066-\u2069\ud800-\udfff]"
)


def _escape(match: re.Match[str]) -> str:
    code = ord(match.group())
    return f"\\x{code:02x}" if code <= 0xFF else f"\\u{code:04x}"


def printable(text: object) -> str:
    """``str(text)`` with every unsafe character as ``\\x0a`` / ``\\u202e`` escapes.

    Backslashes are left as they are: the escapes are for reading, not for parsing back.
    """
    return _UNSAFE.sub(_escape, str(text))


def printable_lines(text: str) -> str:
    """Each line of ``text`` made printable, keeping its line breaks (another process's
    output, shown line by line)."""
    return "\n".join(printable(line) for line in text.split("\n"))


#: A few levels and items of a container, a few dozen characters of a string or number.
_SHORT = reprlib.Repr()
_SHORT.maxlevel, _SHORT.maxlist, _SHORT.maxdict, _SHORT.maxtuple = 3, 4, 4, 4
_SHORT.maxstring = _SHORT.maxother = _SHORT.maxlong = 40


def short_repr(value: object, limit: int = 40) -> str:
    """A repr of a value a user gave, at most ``limit`` characters, for an error message.

    Never walks more than a few levels and items: a YAML document whose aliases share one
    list nine times at each of nine levels is tiny, but its full repr is 9**9 items long.
    """
    text = _SHORT.repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


#: Characters of an actor or row id a message shows (ids come from a log: untrusted).
ID_CHARS = 64


def shown_id(identifier: str) -> str:
    """An id for a message: control characters escaped, at most :data:`ID_CHARS`."""
    if len(identifier) > ID_CHARS:
        identifier = identifier[:ID_CHARS] + "…"
    return printable(identifier)


def short(value: object) -> str:
    """A figure or a value for a line of a summary: a float to 3 significant digits, any
    other value as text of at most 60 characters."""
    if isinstance(value, float):
        return f"{value:.3g}"
    text = str(value)
    return text if len(text) <= 60 else text[:57] + "..."


def precise(value: object) -> str:
    """A figure compared to others' to many digits (a competition's metric): 6 significant
    digits; any other value as :func:`short` shows it."""
    return f"{value:.6g}" if isinstance(value, float) else short(value)


def metres(value: object) -> str:
    """A distance for a status line: ``1.23 m``, ``-`` when it is no number."""
    return f"{value:.2f} m" if isinstance(value, float) else "-"
