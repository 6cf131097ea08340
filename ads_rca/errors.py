"""Typed errors: the root of every exception ads_rca defines, and the kinds every layer shares.

Only what cannot be used at all raises; bad values inside a log are a ``Problem`` and the
diagnosis goes on. Each subpackage with failure kinds of its own derives them from
:class:`AdsRcaError` in its ``errors`` module (``contract.errors``, ``io.errors``,
``synth.errors``), so a caller catches the kind it can handle and a programming bug
(a ``KeyError`` or ``TypeError`` in our own code) is never taken for bad input. The command
line and the nodes turn any :class:`AdsRcaError` that reaches them into one line and exit
status 2.
"""

from __future__ import annotations

#: Exit status of a command that finished its outputs although our own code raised while
#: judging (sysexits' EX_SOFTWARE): the verdict is inconclusive, the bug is printed.
EXIT_INTERNAL_ERROR = 70


class AdsRcaError(Exception):
    """Base of every error ads_rca raises on purpose."""


class InputError(AdsRcaError):
    """What the user gave (a log, a bag, an output path, a parameter) cannot be used at all.
    One-line message."""


class ConfigError(InputError):
    """A parameter or configuration value that cannot be used (``-p``, ``--config``, a
    node's ROS parameter): one line naming the parameter."""
