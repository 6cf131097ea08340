"""The monitors' queue of data that arrives before the run's metadata stays bounded."""

from __future__ import annotations

from ads_rca.live.early_queue import EarlyQueue


def test_a_flood_before_the_metadata_keeps_the_newest_within_the_bound() -> None:
    queue: EarlyQueue[int] = EarlyQueue(max_bytes=10_000)
    dropped = [queue.add("actors", bytes(1000), i, float(i)) for i in range(1000)]
    assert queue.size <= 10_000 and len(queue) == 10
    assert sum(dropped) == queue.dropped == 990
    assert [info for _key, _data, info, _arrived in queue.drain()] == list(range(990, 1000))
    assert len(queue) == 0 and queue.size == 0
    assert "990 oldest messages dropped" in queue.overflow_reason()


def test_a_normal_start_loses_nothing() -> None:
    queue: EarlyQueue[str] = EarlyQueue()
    for i in range(500):
        assert queue.add("ego/odometry", bytes(400), f"m{i}", float(i)) == 0
    assert [info for *_rest, info, _arrived in queue.drain()][:2] == ["m0", "m1"]
    assert queue.dropped == 0


def test_one_message_larger_than_the_bound_is_not_kept() -> None:
    queue: EarlyQueue[None] = EarlyQueue(max_bytes=100)
    assert queue.add("actors", bytes(101), None, 0.0) == 1
    assert len(queue) == 0 and queue.size == 0
