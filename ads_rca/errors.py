"""Typed errors. Only input that cannot be used at all raises; everything else is a Problem."""

from __future__ import annotations


class AdsRcaError(Exception):
    """Base of every error ads_rca raises on purpose."""


class InputError(AdsRcaError):
    """The input cannot be used at all (no such folder, nothing readable). One-line message."""
