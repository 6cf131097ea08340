"""The synthesiser's failure kind (an :class:`~ads_rca.errors.InputError`: one line, exit 2)."""

from __future__ import annotations

from ads_rca.errors import InputError


class SynthesisError(InputError, ValueError):
    """Bad arguments, or no acceptable scene for a seed."""
