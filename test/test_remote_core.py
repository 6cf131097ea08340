"""The remote bridge's pure core: keys, endpoints, rate limits, history, with
hostile values, and one real loopback Zenoh session opened with the built config."""

from __future__ import annotations

import json

import pytest
from loopback import free_port

from ads_rca.diagnosis.verdict import Metric, Module
from ads_rca.errors import ConfigError
from ads_rca.remote.config import session_config
from ads_rca.remote.history import History, parse_since
from ads_rca.remote.keys import check_prefix, dashboard_key, ros_key, sample_key
from ads_rca.remote.rate import RateLimiter


def test_ros_keys_follow_the_zenoh_bridge_ros2dds_convention() -> None:
    assert ros_key("/diagnostics") == "diagnostics"
    assert ros_key("/rca/verdict", "car1") == "car1/rca/verdict"
    assert ros_key("rca/verdict", "/fleet/car1/") == "fleet/car1/rca/verdict"
    assert dashboard_key("car1", "verdict") == "car1/ads_rca/verdict"
    assert sample_key("car1", "verdict") == "car1/ads_rca/verdict.json"
    assert dashboard_key("", "modules", "perception") == "ads_rca/modules/perception"


@pytest.mark.parametrize(
    "prefix",
    ["car/*", "a//b", "**", "x$y", "a b", "q?x", "#", "é", "a\x00b", "x" * 201, ".", "a/../b"],
)
def test_hostile_prefixes_are_refused_in_one_line(prefix: str) -> None:
    with pytest.raises(ConfigError) as error:
        check_prefix(prefix)
    assert "\n" not in str(error.value) and "\x00" not in str(error.value)


def test_endpoints_stay_on_loopback_unless_allowed() -> None:
    config = json.loads(session_config())
    assert config["scouting"] == {"multicast": {"enabled": False}, "gossip": {"enabled": False}}
    assert config["listen"]["endpoints"] == ["tcp/127.0.0.1:7447"]
    with pytest.raises(ConfigError, match="not on loopback"):
        session_config(listen=["tcp/0.0.0.0:7447"])
    with pytest.raises(ConfigError, match="not on loopback"):
        session_config("client", listen=[], connect=["tcp/10.0.0.5:7447"])
    remote = json.loads(session_config(listen=["tcp/0.0.0.0:7447"], allow_remote=True))
    assert remote["listen"]["endpoints"] == ["tcp/0.0.0.0:7447"]
    assert json.loads(session_config(listen=["tcp/[::1]:7447"]))["mode"] == "peer"
    for bad in ("tcp/127.0.0.1", "tcp/127.0.0.1:0", "tcp/127.0.0.1:70000", "http://x:1", ""):
        with pytest.raises(ConfigError):
            session_config(listen=[bad])
    with pytest.raises(ConfigError, match="mode"):
        session_config("router")
    with pytest.raises(ConfigError, match="client"):
        session_config("client", listen=[])


def test_rate_limits_keep_the_newest_sample_and_never_drop_the_verdict() -> None:
    limiter: RateLimiter[int] = RateLimiter({"frames": 2.0, "verdict": 1.0}, frozenset({"verdict"}))
    assert limiter.offer("frames", 1, 0.0) == [("frames", 1)]
    assert limiter.offer("frames", 2, 0.1) == []
    assert limiter.offer("frames", 3, 0.2) == []  # replaces 2: the newest is what waits
    assert limiter.flush(0.3) == []
    assert limiter.flush(0.5) == [("frames", 3)]
    assert limiter.offer("verdict", 9, 0.5) == [("verdict", 9)]
    assert limiter.offer("verdict", 10, 0.51) == [("verdict", 10)]
    assert limiter.offer("other", 1, 0.0) == [("other", 1)]  # no limit
    limiter.offer("frames", 4, 0.6)
    assert limiter.flush(0.6, force=True) == [("frames", 4)]
    for rate in (-1.0, float("nan"), float("inf")):
        with pytest.raises(ConfigError):
            RateLimiter({"frames": rate})


def test_history_is_bounded_and_answers_since() -> None:
    history = History(3)
    for n in range(5):
        history.add_frame(n, {"frame": n})
    assert len(history) == 3 and history.evicted == 2
    assert [d["frame"] for d in history.since(-1)] == [2, 3, 4]
    assert [d["frame"] for d in history.since(3)] == [4]
    history.add_frame(3, {"frame": 3, "revision": 1})  # a re-judged frame replaces its own
    assert history.since(2) == [{"frame": 3, "revision": 1}, {"frame": 4}]
    assert parse_since({}) == -1 and parse_since({"since": "12"}) == 12
    for bad in ("x", "1.5", "-2", "1e3", "99999999999999999", " ", "0x10"):
        with pytest.raises(ConfigError):
            parse_since({"since": bad})
    with pytest.raises(ConfigError):
        History(0)


def test_a_loopback_peer_and_client_exchange_a_sample() -> None:
    import zenoh

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    peer_config = zenoh.Config.from_json5(session_config("peer", listen=[endpoint]))
    client_config = zenoh.Config.from_json5(session_config("client", listen=[], connect=[endpoint]))
    key = dashboard_key("test", "status")
    with zenoh.open(peer_config) as peer:
        queryable = peer.declare_queryable(
            key, lambda query: query.reply(key, json.dumps({"state": "running"}))
        )
        try:
            with zenoh.open(client_config) as client:
                replies = []
                for _attempt in range(50):  # the client may still be connecting
                    replies = [r.ok for r in client.get(key, timeout=0.5) if r.ok is not None]
                    if replies:
                        break
                assert replies
                assert json.loads(replies[0].payload.to_string()) == {"state": "running"}
        finally:
            queryable.undeclare()  # type: ignore[no-untyped-call]


def result_text(index: int, module: Module = "perception", failed: bool = False) -> str:
    from ads_rca.foundation import strictjson
    from ads_rca.live.results import LiveResult
    from ads_rca.oracles.base import OracleResult

    metrics: dict[str, Metric] = {"recall": float("nan"), "note": "</script><b>\u202e"}
    result = OracleResult(module, index * 50, failed, metrics, {"safety_margin": 0.5})
    return strictjson.dumps(LiveResult(index, result, index).to_document())


def test_remote_state_forwards_results_and_answers_late_dashboards() -> None:
    from ads_rca.foundation import strictjson
    from ads_rca.remote.state import RemoteState

    state = RemoteState("car1", capacity=3, rates={"modules": 10.0})
    puts = state.on_result(result_text(0), 0.0)
    assert [key for key, _ in puts] == ["car1/ads_rca/modules/perception.json"]
    sent = puts[0][1]
    assert "NaN" not in sent and strictjson.loads(sent)["metrics"]["recall"] != 0.5
    assert state.on_result(result_text(1), 0.01) == []  # within 0.1 s: pending
    assert state.on_result(result_text(2), 0.02) == []  # the newest replaces it
    planning = state.on_result(result_text(0, "planning"), 0.03)  # its own key, its own limit
    assert [key for key, _ in planning] == ["car1/ads_rca/modules/planning.json"]
    assert state.flush(0.05) == []
    due = state.flush(0.2)
    assert [(key, strictjson.loads(text)["index"]) for key, text in due] == [
        ("car1/ads_rca/modules/perception.json", 2)
    ]
    for n in range(1, 5):
        state.on_result(result_text(n), 1.0 + n)
    frames = strictjson.loads(state.answer("car1/ads_rca/frames", {"since": "2"}, 9.0) or "")
    assert [f["index"] for f in frames["frames"]] == [3, 4]
    assert state.history.evicted == 2  # capacity 3 of frames 0..4
    assert state.answer("car1/ads_rca/verdict", {}, 9.0) is None
    verdict = {"primary_root_cause": "perception", "note": float("inf")}
    assert [k for k, _ in state.on_verdict(strictjson.dumps(verdict), 9.0)] == [
        "car1/ads_rca/verdict.json"
    ]
    assert [k for k, _ in state.on_verdict(strictjson.dumps(verdict), 9.01)] == [
        "car1/ads_rca/verdict.json"
    ]  # never rate-limited
    answered = strictjson.loads(state.answer("car1/ads_rca/verdict", {}, 9.0) or "")
    assert answered["primary_root_cause"] == "perception"
    status = strictjson.loads(state.answer("car1/ads_rca/status", {}, 9.5) or "")
    assert status["state"] == "verdict" and status["results"] == {"perception": 7, "planning": 1}
    with pytest.raises(ConfigError):
        state.answer("car1/ads_rca/frames", {"since": "soon"}, 9.0)


def test_the_verdict_waits_for_the_results_it_counts() -> None:
    """CI: the bridge took one message per topic and turn, so the verdict (decided once the
    aggregator had every result) went out with 81 planning results still queued, and a
    dashboard stopping at the verdict never saw them. It now waits for as many results per
    module as its ``live.results_received`` counts, at most VERDICT_HOLD_S."""
    from ads_rca.foundation import strictjson
    from ads_rca.remote.state import VERDICT_HOLD_S, RemoteState

    verdict = {
        "primary_root_cause": "planning",
        "live": {"results_received": {"perception": 1, "planning": 2}},
    }
    state = RemoteState("car1", rates={"modules": 0.0})
    state.on_result(result_text(0), 0.0)
    assert state.on_verdict(strictjson.dumps(verdict), 1.0) == []  # 2 planning results due
    assert state.answer("car1/ads_rca/verdict", {}, 1.0) is None
    assert [k for k, _ in state.on_result(result_text(0, "planning"), 1.1)] == [
        "car1/ads_rca/modules/planning.json"
    ]
    assert [k for k, _ in state.on_result(result_text(1, "planning"), 1.2)] == [
        "car1/ads_rca/modules/planning.json",  # the last result first,
        "car1/ads_rca/verdict.json",  # then the verdict
    ]
    assert (
        strictjson.loads(state.answer("car1/ads_rca/status", {}, 2.0) or "")[
            "verdict_ahead_of_results"
        ]
        == 0
    )
    # A bridge that missed results (started late): the verdict goes out after the hold,
    # or at once when the bridge stops, and the status says how many it went ahead of.
    for force, at in ((False, 10.0 + VERDICT_HOLD_S), (True, 10.0)):
        late = RemoteState("car1", rates={"modules": 0.0})
        assert late.on_verdict(strictjson.dumps(verdict), 10.0) == []
        assert late.flush(10.0 + VERDICT_HOLD_S / 2) == []
        assert [k for k, _ in late.flush(at, force=force)] == ["car1/ads_rca/verdict.json"]
        assert late.status(at)["verdict_ahead_of_results"] == 3
        assert late.status(at)["state"] == "verdict"
        # The bridge's last heartbeat: it stopped, after its verdict too.
        assert late.status(at, "stopped")["state"] == "stopped"


@pytest.mark.parametrize(
    "text",
    ["", "{", "[]", "null", '{"module": "wheels"}', "[" * 100_000, b"\xff\xfe", '{"index": "x"}'],
)
def test_remote_state_counts_what_is_not_a_result_and_forwards_nothing(text: str | bytes) -> None:
    from ads_rca.remote.state import RemoteState

    state = RemoteState("")
    assert state.on_result(text, 0.0) == []
    assert state.on_verdict(text, 0.0) == []
    assert state.malformed == 2
    assert "\n" not in state.last_problem and len(state.last_problem) < 260


def test_the_bridge_counts_final_results_only_and_holds_the_verdict_for_them() -> None:
    """A replay's monitors publish provisional results as it plays, then each frame's
    final one; the verdict counts the final ones (live.results_received). Counting the
    provisional ones let the verdict overtake the last finals (CI: 11 planning frames)."""
    from ads_rca.foundation import strictjson
    from ads_rca.remote.state import RemoteState

    state = RemoteState("car1", rates={"modules": 0.0})
    for index in range(3):
        document = {"module": "planning", "index": index, "stamp_ms": 50 * index}
        document |= {"frame": index, "failed": False, "provisional": True}
        state.on_result(strictjson.dumps(document), 1.0)
    verdict = {"primary_root_cause": None, "live": {"results_received": {"planning": 3}}}
    assert state.on_verdict(strictjson.dumps(verdict), 1.0) == []  # held: no final yet
    for index in range(3):
        document = {"module": "planning", "index": index, "stamp_ms": 50 * index}
        puts = state.on_result(strictjson.dumps(document | {"frame": index, "failed": False}), 1.1)
    assert "car1/ads_rca/verdict.json" in [k for k, _ in puts]
    assert state.status(1.2)["results"] == {"planning": 3}
