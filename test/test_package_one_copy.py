"""Rules that used to be written twice now have one copy.

Problem de-duplication and reading (``problems.py``), the frame number
(``model.frame_number``), the topic → folder table (``contract/topics.py``), the bounded
cache (``oracles/cache.LRU``), the collision event's reading
(``live/results.collision_frame``) and the player's end (``live/results.FollowsRunEnd``)
are each defined once and used by every side.
"""

from __future__ import annotations

import re
from functools import partial
from pathlib import Path

import ads_rca
from ads_rca.contract import topics
from ads_rca.contract.jsontext import loads_json
from ads_rca.contract.playback import Tick, frame_marker
from ads_rca.diagnosis import verdict
from ads_rca.live.aggregate import AggregatorCore
from ads_rca.live.results import FollowsRunEnd, FrameMarker, LiveResult, collision_frame
from ads_rca.live.runid import RunFilter
from ads_rca.live.window import MonitorCore
from ads_rca.model import frame_number
from ads_rca.oracles.base import RunContext
from ads_rca.oracles.cache import LRU
from ads_rca.params import make_params
from ads_rca.problems import Problem, new_problems, problems_from_list
from ads_rca.synth import synthesise

PACKAGE = Path(ads_rca.__file__).resolve().parent

RESULT = {
    "module": "perception",
    "index": 0,
    "stamp_ms": 50,
    "frame": 1,
    "failed": False,
    "skipped": None,
    "ids": [],
    "metrics": {},
    "thresholds": {},
}


def test_a_result_keeps_its_problems_exactly_and_skips_entries_that_are_not_one() -> None:
    """The monitors' problems cross DDS through Problem.to_dict/from_dict; a hostile entry
    (not an object, a missing field) is skipped, never an AttributeError that would stop
    the aggregator (its guard catches KeyError, TypeError and ValueError only)."""
    good = Problem("actors/000050.json", "ego id", "no actor", "check skipped", "error", 50)
    entries = ["x", 3, None, {"file": "a"}, good.to_dict(), {**good.to_dict(), "severity": "?"}]
    result = LiveResult.from_document({**RESULT, "problems": entries})
    assert result.problems == (good,)
    assert LiveResult.from_document(result.to_document()).problems == (good,)
    assert LiveResult.from_document({**RESULT, "problems": {"file": "a"}}).problems == ()
    assert problems_from_list(entries) == [good]


def test_one_de_duplication_rule_for_the_engine_and_the_live_nodes() -> None:
    log = synthesise("cut_in", "perception", 1)
    ctx = RunContext.create(log, make_params("corrected"))
    before = len(ctx.problems)
    ctx.report("f", "x", "issue", 50)
    ctx.report("f", "x", "issue", 100)  # the same problem at another stamp: once
    ctx.merge([Problem("f", "x", "issue", "other action"), Problem("f", "y", "issue", "a")])
    assert [(p.field, p.timestamp_ms) for p in list(ctx.problems)[before:]] == [
        ("x", 50),
        ("y", None),
    ]
    seen: set[tuple[str, str, str]] = set()
    twice = [Problem("f", "x", "i", "a"), Problem("f", "x", "i", "b")]
    assert new_problems(twice, seen) == twice[:1] and new_problems(twice, seen) == []


def test_the_player_numbers_frames_as_the_verdict_does() -> None:
    for stamp, frame_ms in ((50, 50), (75, 50), (0, 50), (7, 3), (100, 0)):
        tick = Tick(stamp, 0, False)
        sent = loads_json(frame_marker(tick, [], frame_ms).data)["frame"]
        assert sent == (frame_number(stamp, frame_ms) if frame_ms > 0 else None)
    # The rule is the model's (time ↔ frame); the contract no longer reaches up to verdict.
    assert not hasattr(verdict, "frame_number")
    assert "ads_rca.diagnosis.verdict" not in (PACKAGE / "contract" / "playback.py").read_text()


def test_one_collision_event_rule_for_the_monitors_and_the_aggregator() -> None:
    runs = RunFilter("one")
    assert collision_frame({"frame": 7}, runs) == 7  # naming no run: a live stack's event
    assert collision_frame({"frame": 7, "run": "two"}, runs) is None
    assert collision_frame({"frame": 8, "run": "one"}, runs) == 8
    assert collision_frame({"frame": "9", "run": "one"}, runs) is None
    assert collision_frame({}, runs) is None
    assert collision_frame({"frame": True}, runs) is None  # a boolean is no frame
    assert collision_frame({"frame": -3}, runs) is None
    # The monitors' one listener (both input paths) and the aggregator read it by this rule.
    for node in ("stack_subscriber.py", "aggregator.py"):
        text = (PACKAGE / "ros" / node).read_text()
        assert "collision_frame(read_document(msg), " in text
    for node in ("monitor.py", "stack_subscriber.py", "aggregator.py"):
        assert 'document.get("frame")' not in (PACKAGE / "ros" / node).read_text()
    assert "listen_for_collisions(" in (PACKAGE / "ros" / "monitor.py").read_text()


def test_the_live_cores_follow_one_run_end() -> None:
    for core in (MonitorCore, AggregatorCore):
        assert issubclass(core, FollowsRunEnd)
        assert "finished" not in vars(core) and "markers_received" not in vars(core)


def test_one_topic_to_folder_table() -> None:
    marker = FrameMarker.from_document({"stamp_ms": 50, "published": list(topics.DATA_TOPICS)})
    assert marker.folders == frozenset(topics.FOLDER_TOPICS)
    live = (PACKAGE / "live" / "results.py").read_text()
    assert "TOPIC_FOLDER:" not in live and "TOPIC_FOLDER " not in live


def test_the_oracles_bound_their_caches_with_the_one_lru() -> None:
    """No hand-rolled cache (an OrderedDict, or a dict cleared when full) in oracles/."""
    hand_rolled = re.compile(r"OrderedDict|\.popitem\(|\.clear\(\)")
    found = [
        f"{path.relative_to(PACKAGE)}:{number}"
        for path in sorted((PACKAGE / "oracles").rglob("*.py"))
        if path.name != "cache.py"
        for number, line in enumerate(path.read_text().splitlines(), 1)
        if hand_rolled.search(line)
    ]
    assert not found
    cache: LRU[int, int] = LRU(2)
    for key in range(5):
        assert cache.get(key, partial(pow, key, 2)) == key * key
    assert len(cache) == 2 and cache.lookup(0) is None and cache.lookup(4) == 16
