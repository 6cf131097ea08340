"""The dashboards' Zenoh links (``remote/client.py``): one real loopback session per endpoint.

Issue 38 items 2 and 4: each endpoint's state is its own (one up, one down, one never
there), a link whose peer went away says so, and a session that reached nobody for
``REOPEN_AFTER_S`` is opened afresh, so recovery never rests on Zenoh's own reconnection
whatever the outage's length. The outage's length is given to :meth:`Link.maintain` as its
clock (``tick``), so the test does not sleep through it; the sessions, the peer going away
and coming back, and the samples are real.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import pytest
import zenoh
from loopback import free_port

from ads_rca.remote import client as client_module
from ads_rca.remote.client import (
    CONNECTED,
    CONNECTING,
    DISCONNECTED,
    REOPEN_AFTER_S,
    Link,
    RemoteClient,
    RemoteLinks,
)
from ads_rca.remote.config import session_config
from ads_rca.remote.session import close_session

pytestmark = pytest.mark.timeout(60)


@contextmanager
def peer(endpoint: str) -> Iterator[Any]:
    """A Zenoh peer listening on ``endpoint`` (a bridge, as far as a link can tell)."""
    session = zenoh.open(zenoh.Config.from_json5(session_config("peer", (endpoint,), ())))
    try:
        yield session
    finally:
        close_session(session, ())


def until(condition: Callable[[], bool], timeout: float = 15.0) -> None:
    end = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < end, "timed out"
        time.sleep(0.05)


@pytest.mark.parametrize("mode", ["client", "peer"])
def test_a_link_says_its_state_and_opens_afresh_after_a_long_outage(mode: str) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    link = Link(endpoint, RemoteClient((endpoint,), mode=mode))
    tick = 0.0

    def look() -> bool:
        nonlocal tick
        tick += 0.1
        return link.maintain(tick, wall=1000.0 + tick)

    try:
        look()
        assert link.state == (CONNECTING if mode == "client" else DISCONNECTED)
        with peer(endpoint):
            arrived: list[bool] = []

            def connects() -> bool:
                arrived.append(look())
                return link.state == CONNECTED

            until(connects)
            assert arrived[-1] is True and link.error == ""  # said once, when it connects
            assert look() is False
            connected_since = link.since

        def gone() -> bool:
            look()
            return link.state == DISCONNECTED

        until(gone)  # the peer went away: said at once
        assert link.since > connected_since
        tick += REOPEN_AFTER_S + 1.0  # an outage longer than Zenoh is relied on for
        look()
        assert link.reopened == 1 and "opening a new session" in link.error
        assert link.state == DISCONNECTED
        with peer(endpoint) as back:
            until(lambda: look() and link.state == CONNECTED)
            link.client.catch_up(timeout=0.5)  # the new session works: a query goes out
            # Put until heard: the new subscription reaches the peer a moment after.
            until(
                lambda: (
                    back.put("car1/ads_rca/status.json", b"{}")
                    or any(k == "car1/ads_rca/status.json" for k, _ in link.client.drain())
                )
            )
    finally:
        link.client.close()


def test_every_endpoint_is_reached_and_each_says_its_own_state() -> None:
    up = [f"tcp/127.0.0.1:{free_port()}" for _ in range(2)]
    down = f"tcp/127.0.0.1:{free_port()}"
    links = RemoteLinks([*up, down, up[0]], mode="client")  # a repeated endpoint: one link
    assert links.endpoints == (*up, down)
    with peer(up[0]) as first, peer(up[1]) as second:
        links.start()
        try:
            until(
                lambda: [s["state"] for s in links.states()] == [CONNECTED, CONNECTED, CONNECTING]
            )
            states = links.states()
            assert states[2]["error"] and "Unable to connect" in states[2]["error"]
            seen: set[str] = set()

            def heard_both() -> bool:
                first.put("car1/ads_rca/status.json", b"{}")
                second.put("car2/ads_rca/status.json", b"{}")
                seen.update(k for k, _ in links.drain())
                return len(seen) == 2

            until(heard_both)
            assert seen == {"car1/ads_rca/status.json", "car2/ads_rca/status.json"}
        finally:
            links.close()
    assert not any(link.opened or link.connected for link in links.links)


def test_each_link_asks_its_own_queryables_when_it_connects() -> None:
    """A link that connects is caught up at once: the replies of both endpoints arrive."""
    endpoints = [f"tcp/127.0.0.1:{free_port()}" for _ in range(2)]
    with peer(endpoints[0]) as first, peer(endpoints[1]) as second:
        for session, prefix in ((first, "car1"), (second, "car2")):
            key = f"{prefix}/ads_rca/status"
            reply = f'{{"state": "verdict", "run": "{prefix}"}}'.encode()
            session.declare_queryable(key, lambda query, k=key, r=reply: query.reply(k, r))
        links = RemoteLinks(endpoints, mode="client", catch_up_timeout=1.0).start()
        try:
            seen: set[str] = set()

            def both_replied_and_caught_up() -> bool:
                seen.update(k for k, _ in links.drain())
                # the replies arrive while the catch-up's queries are still open; it says
                # caught up once the last one has ended
                return len(seen) == 2 and links.caught_up > 0

            until(both_replied_and_caught_up)
            assert seen == {"car1/ads_rca/status", "car2/ads_rca/status"}
            assert links.catch_up_error == ""
        finally:
            links.close()


def test_a_sample_through_a_link_not_yet_marked_connected_is_looked_at_at_once(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A peer session connects on Zenoh's own retry, between two looks at the link: its
    first sample wakes the links' thread, so the link says connected beside it, not at the
    period's end (the dashboard's page said "zenoh not connected" beside results)."""
    monkeypatch.setattr(client_module, "LINK_PERIOD_S", 40.0)  # no look but the first
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    links = RemoteLinks([endpoint], mode="peer")
    links.open_now()
    links.start()
    try:
        until(lambda: links.states()[0]["state"] == DISCONNECTED)  # the first look: nobody
        with peer(endpoint) as bridge:
            heard: list[str] = []

            def a_sample_came() -> bool:
                bridge.put("car1/ads_rca/status.json", b"{}")
                heard.extend(key for key, _ in links.drain())
                return bool(heard)

            until(a_sample_came)
            until(lambda: links.states()[0]["state"] == CONNECTED, timeout=5.0)
    finally:
        links.close()
