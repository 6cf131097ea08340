"""``raw_links`` resolves the raw ids in one pass: the same links as the per-actor numpy form
(each raw id's nearest id on truth below the distance cap, earlier id on truth on ties; per
actor the nearest raw id, earlier raw id on ties), NaN offsets and exact ties included."""

from __future__ import annotations

import numpy as np

from ads_rca.model import Predictions, Track
from ads_rca.oracles.corrected.links import LINK_MAX_DISTANCE, raw_links, step0_offsets


def per_actor_form(raw: Predictions, on_truth: Predictions, ego_id: str | None) -> dict[str, str]:
    on_truth_ids, on_truth_xy = step0_offsets(on_truth, ego_id)
    raw_ids, raw_xy = step0_offsets(raw, None)
    if not on_truth_ids or not raw_ids:
        return {}
    d = np.hypot(
        raw_xy[:, None, 0] - on_truth_xy[None, :, 0], raw_xy[:, None, 1] - on_truth_xy[None, :, 1]
    )
    d = np.where(d < LINK_MAX_DISTANCE, d, np.inf)
    best = np.argmin(d, axis=1)
    reach = np.isfinite(d[np.arange(len(raw_ids)), best])
    out: dict[str, str] = {}
    for col in np.unique(best[reach]).tolist():
        linked = np.flatnonzero((best == col) & reach)
        out[on_truth_ids[col]] = raw_ids[int(linked[np.argmin(d[linked, col])])]
    return out


def tracks(rng: np.random.Generator, count: int, prefix: str) -> Predictions:
    xy = np.round(rng.random((count, 2)) * 6) * 30  # a coarse grid: exact ties, some >= 100 m
    xy[rng.random((count, 2)) < 0.1] = np.nan
    return {
        f"{prefix}{i}": Track(("0", "1"), np.array([[xy[i, 0], xy[i, 1], 0.0], [0.0, 0.0, 0.0]]))
        for i in range(count)
    }


def test_the_same_links_as_the_per_actor_form() -> None:
    rng = np.random.default_rng(8)
    linked = 0
    for case in range(1500):
        raw = tracks(rng, int(rng.integers(0, 9)), "r")
        on_truth = tracks(rng, int(rng.integers(0, 9)), "p")
        ego = "p0" if case % 2 else None
        got, want = raw_links(raw, on_truth, ego), per_actor_form(raw, on_truth, ego)
        assert list(got.items()) == list(want.items()), case  # order too
        linked += len(got)
    assert linked > 1000  # links were made (and contested: several raw ids per actor)


def test_a_shared_actor_goes_to_the_nearest_raw_id_then_the_earlier() -> None:
    """Raw a at 3 m and raw b at 3 m from actor p (a tie: a, the earlier, wins); raw c at 1 m
    from actor q, raw d at 2 m from q: c. Raw e 150 m from everything links to nobody."""

    def at(x: float, y: float) -> Track:
        return Track(("0",), np.array([[x, y, 0.0]]))

    on_truth = {"p": at(0.0, 0.0), "q": at(50.0, 0.0)}
    raw = {
        "d": at(52.0, 0.0),
        "a": at(3.0, 0.0),
        "b": at(0.0, -3.0),
        "c": at(49.0, 0.0),
        "e": at(0.0, 150.0),
    }
    assert raw_links(raw, on_truth, None) == {"p": "a", "q": "c"}


def test_without_ids_on_truth_no_raw_offset_is_read() -> None:
    """No id on truth (an empty file, or only the ego): nothing links, and the raw tracks are not
    read at all (most frames of a long log; a raw track with a key "0" but no rows would
    raise IndexError if its offsets were read)."""
    unreadable = {"r": Track(("0",), np.zeros((0, 3)))}
    assert raw_links(unreadable, {}, None) == {}
    ego_only = {"ego": Track(("0",), np.zeros((1, 3)))}
    assert raw_links(unreadable, ego_only, "ego") == {}
