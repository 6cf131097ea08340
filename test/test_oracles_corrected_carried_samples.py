"""A floor's samples carried from one context of a run to the next (a live monitor judges
each frame on a new view of its window) are what a fresh context computes: reused only while
the records they read are the same objects, computed again once one of them arrives late or a
view lacks it; and ``diagnose``'s single context carries nothing."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from ads_rca.model import RunLog
from ads_rca.oracles.base import RunContext
from ads_rca.oracles.cache import Carry
from ads_rca.oracles.corrected.context import corrected_context
from ads_rca.oracles.corrected.floors import Samples
from ads_rca.oracles.corrected.prediction import prediction_samples
from ads_rca.params import Params, make_params
from ads_rca.synth import synthesise


def test_a_carried_value_is_reused_only_for_the_same_objects() -> None:
    carry: Carry[int, list[int]] = Carry(size=2)
    record, twin = [1.0], [1.0]  # equal, not the same object
    computed: list[int] = []

    def compute() -> list[int]:
        computed.append(1)
        return [len(computed)]

    first = carry.get(5, (record,), compute)
    assert carry.get(5, (record,), compute) is first and len(computed) == 1
    assert carry.get(5, (twin,), compute) == [2]  # an equal copy is another record
    assert carry.get(5, (twin, None), compute) == [3]  # a source more
    carry.get(6, (), compute)
    carry.get(7, (), compute)
    assert len(carry) == 2  # bounded: 5 is forgotten
    assert carry.get(5, (twin, None), compute) == [6]


def samples_at(log: RunLog, params: Params, ego: str | None, carried: Any, u: int) -> Samples:
    """Prediction's floor samples at u, on a new context of ``log`` (as a live view's)."""
    ctx = RunContext(log, params, ego_id=ego, carried=carried)
    return prediction_samples(corrected_context(ctx), u)


def test_a_sample_is_computed_again_once_a_record_it_read_arrives() -> None:
    log = synthesise("lead_braking", "prediction", 0, actors=5)
    params = make_params("corrected")
    ego = RunContext.create(log, params).ego_id
    frame_ms, steps = log.frame_ms, int(params.prediction_window)
    u = log.frames[30]
    last = u + steps * frame_ms  # the horizon's last step: its largest errors
    early = replace(log, actors={s: a for s, a in log.actors.items() if s != last})
    carried: dict[str, Any] = {}

    fresh = samples_at(log, params, ego, None, u)
    before = samples_at(early, params, ego, carried, u)
    assert fresh and before != fresh  # the late record changes the sample
    after = samples_at(log, params, ego, carried, u)
    assert after == fresh
    assert samples_at(log, params, ego, carried, u) is after  # the same records: carried
    assert samples_at(early, params, ego, carried, u) == before  # a view without it again


def test_diagnose_carries_nothing() -> None:
    log = synthesise("lead_braking", "prediction", 0, actors=5)
    params = make_params("corrected")
    ctx = RunContext.create(log, params)
    assert ctx.carried is None
    prediction_samples(corrected_context(ctx), log.frames[30])
    assert ctx.carried is None
