"""The reference verdict: failures counted in and before the reference's (unbounded) window.

Moved here from ``diagnosis/verdict.py`` so the verdict types do not depend on the oracles; the
rule is unchanged (docs/semantics-reference.md, "Attribution").
"""

from __future__ import annotations

from collections.abc import Sequence

from ads_rca.diagnosis.verdict import (
    BASIS_REFERENCE,
    NO_COLLISION,
    NO_MODULE_FAILED,
    Attribution,
    FrameResults,
    ModuleVerdict,
)
from ads_rca.oracles.base import MODULES, RunContext

#: The one collision frame that means "no collision" to the reference (``== -1``).
NO_COLLISION_FRAME = -1


def attribute_reference(frames: Sequence[FrameResults], ctx: RunContext) -> Attribution:
    """The reference verdict: count failures in and before the (unbounded) window.

    A failure at ts counts as ``collision`` when collision_frame is not -1 (the reference's
    test: any other negative frame is a collision before the run, so every failure counts)
    and ts > (collision_frame - effect_time_window) * frame_ms, with no upper bound; else ``safe``.
    Root causes are the modules with any ``collision`` count, in pipeline order.
    """
    collision_frame = ctx.log.metadata.collision_frame
    frame_ms = ctx.frame_ms
    start_ms = (collision_frame - ctx.params.effect_time_window) * frame_ms
    modules = {m: ModuleVerdict() for m in MODULES}
    for frame in frames:
        for module, result in frame.results.items():
            if not result.failed:
                continue
            verdict = modules[module]
            if collision_frame != NO_COLLISION_FRAME and frame.timestamp_ms > start_ms:
                verdict.collision += 1
                if verdict.first_failure_frame is None:
                    verdict.first_failure_frame = frame.frame
            else:
                verdict.safe += 1
    for module in MODULES:  # modules that only failed outside the window: first failure at all
        verdict = modules[module]
        if verdict.first_failure_frame is None and verdict.safe:
            verdict.first_failure_frame = next(
                f.frame for f in frames if module in f.results and f.results[module].failed
            )
    root_causes = [m for m in MODULES if modules[m].collision > 0]
    reason = None
    if not root_causes:
        reason = NO_COLLISION if collision_frame == NO_COLLISION_FRAME else NO_MODULE_FAILED
    return Attribution(
        modules=modules,
        root_causes=root_causes,
        primary_root_cause=root_causes[0] if root_causes else None,
        contributing=root_causes[1:],
        attribution_basis=BASIS_REFERENCE,
        reason=reason,
    )
