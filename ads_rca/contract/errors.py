"""Failure kinds of the message contract (all :class:`~ads_rca.errors.AdsRcaError`).

Anyone on the domain can publish on the contract's topics, and a bag nobody checked can hold
anything, so reading a message fails in one typed way, :class:`MalformedMessage` (bytes,
JSON text or a document that is not a usable message of its topic): the nodes skip and
count it, the bag reader reports it as a Problem. A node catches that class and nothing
broader, so a ``KeyError`` or ``TypeError`` of our own code is never taken for a bad message.
The kinds stay ValueErrors (a KeyError for :class:`UnknownMessageType`), as before they were
typed.
"""

from __future__ import annotations

from ads_rca.errors import AdsRcaError


class ContractError(AdsRcaError):
    """Base of the contract's errors."""


class MalformedMessage(ContractError, ValueError):
    """A message that is not a usable message of its topic: skipped, never half-used."""


class CdrError(MalformedMessage):
    """Bytes that are not a well-formed message of the expected type (cut, damaged, or a
    count or length larger than the message)."""


class JsonTextError(MalformedMessage):
    """A JSON text that cannot be read: invalid, or nested deeper than the parsers read."""


class NoStamp(ContractError, ValueError):
    """A MarkerArray without markers: well-formed, but it carries no log time (dropped
    without a word: a stack may send one when nothing is seen)."""


class UnknownTopic(ContractError, ValueError):
    """A topic key that is not one of the contract's data topics (a caller's mistake)."""


class UnknownMessageType(ContractError, KeyError):
    """A message type with no ``.msg`` definition installed (a bag can still record it
    without its schema)."""


class IncompleteRun(ContractError, ValueError):
    """The messages received so far describe no run (no ``run/metadata`` message)."""


#: What reading an untrusted JSON document with Python's own operations raises (a key
#: missing, a list where an object belongs, a string or ``Infinity`` where an integer
#: belongs). The readers of the contract's documents turn these into MalformedMessage
#: right where they read, so no caller catches them.
DOCUMENT_ERRORS: tuple[type[Exception], ...] = (
    LookupError,
    TypeError,
    ValueError,
    AttributeError,
    ArithmeticError,
)
