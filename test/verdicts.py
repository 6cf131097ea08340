"""Comparing verdict documents: the keys a verdict consists of, per-frame flags, and
equality with floats within 1e-9 relative (what crosses DDS as quaternions comes back
about 1e-16 off)."""

from __future__ import annotations

from typing import Any

from ads_rca.oracles.base import MODULES


def verdict_keys(document: dict[str, Any]) -> dict[str, Any]:
    keys = (
        "semantics",
        "thresholds",
        "collision_frame",
        "modules",
        "root_causes",
        "primary_root_cause",
        "contributing",
        "attribution_basis",
        "reason",
        "modules_judged",
        "verdict",
        "partner_id",
        "ego_id",
        "evidence",
    )
    return {k: document[k] for k in keys}


def assert_close(a: Any, b: Any, path: str = "") -> None:
    """Equal, floats within 1e-9 relative (angles cross DDS as quaternions: ~1e-16 off)."""
    if isinstance(a, float) and isinstance(b, float):
        assert abs(a - b) <= 1e-9 * max(1.0, abs(a)), f"{path}: {a} != {b}"
    elif isinstance(a, dict) and isinstance(b, dict):
        assert a.keys() == b.keys(), f"{path}: keys {a.keys()} != {b.keys()}"
        for key in a:
            assert_close(a[key], b[key], f"{path}.{key}")
    elif isinstance(a, list) and isinstance(b, list):
        assert len(a) == len(b), f"{path}: length {len(a)} != {len(b)}"
        for n, (x, y) in enumerate(zip(a, b, strict=True)):
            assert_close(x, y, f"{path}[{n}]")
    else:
        assert a == b, f"{path}: {a!r} != {b!r}"


def failed_flags(document: dict[str, Any]) -> list[tuple[Any, ...]]:
    return [
        (f["frame"], *((f[m]["failed"], f[m].get("skipped")) for m in MODULES))
        for f in document["frames"]
    ]
