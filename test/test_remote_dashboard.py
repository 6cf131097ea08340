"""``ads-rca dashboard``, with real parts only: runs played onto Zenoh by
``remote_feed.py`` processes, the dashboard as its own process, and Debian's chromium driven
by Playwright. The page shows each module's status and the verdict of a live replay without
a reload; the download is the feed's verdict; several runs are listed; text from the wire
stays text; a late dashboard catches up; bad options are one line; signals stop it cleanly.
The event stream's coalescing and its dropping of closed streams are checked in-process.
"""

from __future__ import annotations

import asyncio
import contextlib
import io
import json
import os
import queue
import re
import signal
import socket
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import orjson
import pytest
from headless import chromium, wait_for_connection
from loopback import free_port
from unsure_run import unsure_copy

from ads_rca.oracles.base import MODULES
from ads_rca.remote.client import RemoteClient
from ads_rca.remote.config import session_config
from ads_rca.remote.session import close_session
from ads_rca.remote.view import DashboardModel

pytestmark = pytest.mark.timeout(120)

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "examples" / "cut_in_perception"
FEED = REPO / "test" / "remote_feed.py"
#: Markup that runs script if it is ever parsed as HTML.
HOSTILE = '<img src=x onerror="window.pwned=1">'


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    return env


class Lines:
    """A process's stdout lines, read on a thread so a test can wait with a deadline."""

    def __init__(self, process: subprocess.Popen[str]) -> None:
        self.lines: queue.Queue[str] = queue.Queue()
        assert process.stdout is not None
        threading.Thread(target=self._read, args=(process.stdout,), daemon=True).start()

    def _read(self, stream: Iterable[str]) -> None:
        for line in stream:
            self.lines.put(line)

    def wait_for(self, pattern: str, timeout: float = 30.0) -> str:
        end = time.monotonic() + timeout
        while (left := end - time.monotonic()) > 0:
            try:
                line = self.lines.get(timeout=left)
            except queue.Empty:
                break
            if re.search(pattern, line):
                return line
        raise AssertionError(f"no line matching {pattern!r} within {timeout} s")


def _stop(process: subprocess.Popen[str]) -> None:
    if process.poll() is None:
        process.terminate()
        try:
            process.wait(10)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


@dataclass
class Feed:
    endpoint: str
    process: subprocess.Popen[str]
    lines: Lines


@contextmanager
def feed(
    prefix: str,
    pace: float = 0.0,
    start_after: float = 0.0,
    log: Path = EXAMPLE,
    endpoint: str = "",
    run: str = "",
) -> Iterator[Feed]:
    """``remote_feed.py`` playing ``log`` (the bundled crash) onto Zenoh under ``prefix``
    (on ``endpoint``, a free port by default; its results naming ``run``)."""
    endpoint = endpoint or f"tcp/127.0.0.1:{free_port()}"
    argv = [sys.executable, str(FEED), str(log), "--listen", endpoint, "--prefix", prefix]
    argv += ["--pace", str(pace), "--start-after", str(start_after), "--hold", "90"]
    argv += ["--run", run]
    process = subprocess.Popen(argv, stdout=subprocess.PIPE, text=True, env=_env())
    try:
        lines = Lines(process)
        lines.wait_for("^READY")
        yield Feed(endpoint, process, lines)
    finally:
        _stop(process)


@dataclass
class Dashboard:
    url: str
    process: subprocess.Popen[str]

    def get(
        self, path: str, host: str | None = None, origin: str | None = None
    ) -> tuple[int, dict[str, str], bytes]:
        request = urllib.request.Request(self.url + path.lstrip("/"))
        if host is not None:
            request.add_header("Host", host)
        if origin is not None:
            request.add_header("Origin", origin)
        try:
            with urllib.request.urlopen(request, timeout=10) as response:
                return response.status, dict(response.headers), response.read()
        except urllib.error.HTTPError as error:
            return error.code, dict(error.headers), error.read()

    def runs(self) -> dict[str, Any]:
        status, _, body = self.get("/api/runs")
        assert status == 200
        document: dict[str, Any] = json.loads(body)
        return document

    def runs_by_id(self) -> dict[str, Any]:
        return {run["id"]: run for run in self.runs()["runs"]}


def _wait_until(condition: Callable[[], bool], timeout: float = 30.0) -> None:
    end = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < end, "timed out"
        time.sleep(0.1)


def start_dashboard(*connect: str) -> tuple[subprocess.Popen[str], Lines]:
    argv = [sys.executable, "-m", "ads_rca.cli", "dashboard", "--port", "0"]
    for endpoint in connect:
        argv += ["--connect", endpoint]
    process = subprocess.Popen(
        argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env()
    )
    return process, Lines(process)


@contextmanager
def dashboard(*connect: str) -> Iterator[Dashboard]:
    """``ads-rca dashboard`` on a free port, stopped with SIGINT at the end (and checked to
    have ended cleanly)."""
    process, lines = start_dashboard(*connect)
    try:
        url = re.search(r"http://\S+/", lines.wait_for("^ads-rca dashboard: http://"))
        assert url is not None
        yield Dashboard(url.group(0), process)
        process.send_signal(signal.SIGINT)
        _, err = process.communicate(timeout=10)
        assert process.returncode == 130, err
        assert "Traceback" not in err
    finally:
        _stop(process)


def feed_verdict(endpoint: str, prefix: str) -> dict[str, Any]:
    """The verdict the feed answers on Zenoh, read with a session of the test's own."""
    model = DashboardModel(prefix)
    with RemoteClient([endpoint]) as client:
        client.catch_up()
        for key, payload in client.drain():
            model.apply(key, payload, time.time())
    view = model.find(prefix)
    assert view is not None and view.verdict_payload is not None
    verdict: dict[str, Any] = json.loads(view.verdict_payload)  # the document as received
    return verdict


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    with chromium() as launched:
        yield launched


#: The page's colours as pixels (app.css --good, --bad).
GOOD_PIXEL, BAD_PIXEL = (30, 123, 52), (179, 38, 30)


def colours_shown(shot: bytes) -> set[str]:
    """Which of the page's good (green) and bad (red) colours a screenshot shows: what a
    user sees, after the CSS and the fonts, not what the DOM says."""
    from PIL import Image

    image = Image.open(io.BytesIO(shot)).convert("RGB")
    found = set()
    for count, colour in image.getcolors(maxcolors=1 << 20) or []:
        rgb: tuple[int, int, int] = colour  # type: ignore[assignment]
        for name, target in (("good", GOOD_PIXEL), ("bad", BAD_PIXEL)):
            near = sum(abs(int(a) - b) for a, b in zip(rgb, target, strict=True)) < 40
            if count >= 3 and near:
                found.add(name)
    return found


def screenshot(page: Any, selector: str) -> tuple[str, bytes, str]:
    """The element's text, a screenshot of where it is, and its text again: the page
    redraws its tables as events come, so an element may be replaced while it is shot
    (its place stays; compare the two texts to know the shot shows that text)."""
    for _ in range(50):
        before = page.text_content(selector) or ""
        box = page.locator(selector).bounding_box()  # None: replaced just now
        if box is not None:
            shot = page.screenshot(clip=box)
            return before, shot, page.text_content(selector) or ""
        time.sleep(0.02)
    raise AssertionError(f"{selector}: never stayed on the page long enough to be shot")


#: The number of lines each module's name takes in the modules table, in page script.
NAME_LINES = (
    "Array.from(document.querySelectorAll('#modules tr[data-module] td:first-child'))"
    ".map((e) => { const r = document.createRange(); r.selectNodeContents(e);"
    " return r.getClientRects().length; })"
)


def _module_statuses(page: Any) -> dict[str, tuple[str, int]]:
    found: dict[str, tuple[str, int]] = page.evaluate(
        """() => Object.fromEntries(
            Array.from(document.querySelectorAll('#modules tr[data-module]')).map((row) => [
                row.dataset.module,
                [row.querySelector('.status').textContent,
                 Number(row.querySelector('.judged').textContent)],
            ]))"""
    )
    return found


@pytest.mark.slow
def test_the_page_follows_a_live_replay_without_reload(browser: Any) -> None:
    with feed("car1", pace=0.015, start_after=2.5) as car, dashboard(car.endpoint) as board:
        page = browser.new_page()
        requested: list[str] = []
        page.on("request", lambda request: requested.append(request.url))
        page.goto(board.url)
        page.evaluate("window.sameDocument = true")
        page.wait_for_function("() => Number(document.getElementById('index').textContent) >= 0")
        first = int(page.text_content("#index"))
        assert first < 80, "the run was over before the page saw it: nothing to follow live"
        page.wait_for_function(
            f"() => Number(document.getElementById('index').textContent) > {first}"
        )
        page.wait_for_function(  # every module judged at least once, its status shown
            """() => Array.from(document.querySelectorAll('#modules .judged'))
                     .every((cell) => Number(cell.textContent) > 0)"""
        )
        statuses = _module_statuses(page)
        assert sorted(statuses) == sorted(MODULES)
        for status, judged in statuses.values():  # while it plays: judged provisionally
            assert status in ("ok (provisional)", "failing (provisional)"), status
            assert judged > 0
        # Screenshots during the run: each module's status in its colour, as seen.
        wait_for_connection(page, "live", timeout=10_000)
        assert colours_shown(screenshot(page, "#connection")[1]) == {"good"}
        checked = 0
        for module in MODULES:
            before, shot, after = screenshot(page, f"#modules tr[data-module={module}] .status")
            if before == after and before.startswith(("ok", "failing")):  # not redrawn between
                expected = {"good"} if before.startswith("ok") else {"bad"}
                assert colours_shown(shot) == expected, (module, before)
                checked += 1
        assert checked >= 2, "the statuses changed under every screenshot"
        page.wait_for_function(
            "() => document.getElementById('verdict-primary').textContent === 'perception'",
            timeout=30_000,
        )
        page.wait_for_function("() => document.getElementById('index').textContent === '80'")
        page.wait_for_function(  # the final results replaced the provisional ones
            """() => Array.from(document.querySelectorAll('#modules .status'))
                     .every((cell) => !cell.textContent.includes('provisional'))"""
        )
        blamed = page.eval_on_selector(  # the verdict's root cause: red, never a green "ok"
            "#modules tr[data-module=perception] .status",
            "node => [node.textContent, getComputedStyle(node).color]",
        )
        assert blamed[0].startswith("root cause in the verdict (latest frame"), blamed
        assert blamed[1] != GOOD
        # Screenshots after the run: the blamed module and the verdict in red, never green.
        perception = screenshot(page, "#modules tr[data-module=perception]")[1]
        assert colours_shown(perception) == {"bad"}
        assert colours_shown(screenshot(page, "#verdict-outcome")[1]) == {"bad"}
        assert page.screenshot(full_page=True)  # the whole page renders
        cells = page.eval_on_selector_all(  # the key metrics shown, every one in the tooltip
            "#modules td.metrics",
            "els => els.map(e => [e.textContent.split(' · ').length,"
            " (e.getAttribute('title') || '').split('\\n').length])",
        )
        assert all(shown <= 4 and shown <= total for shown, total in cells), cells
        assert any(total > 4 for _, total in cells), cells
        page.set_viewport_size({"width": 360, "height": 800})  # a phone: names never split
        # Read once laid out at the new width: once in CI every name read 0 lines just
        # after the resize. Then exactly one line each.
        page.wait_for_function(f"() => {NAME_LINES}.every((count) => count > 0)")
        lines = page.evaluate(f"() => {NAME_LINES}")
        assert lines == [1, 1, 1, 1], lines
        assert page.evaluate("window.sameDocument") is True  # updated in place, never reloaded
        assert page.locator("#timeline-box polyline").count() == 1
        assert page.text_content("#runs tbody tr[data-run='car1'] td:last-child") == "perception"
        assert page.text_content("#runs tbody tr[data-run='car1'] td:first-child") == "car1"
        facts = page.text_content("#verdict-facts")
        assert "collision frame81" in facts and "semantics modecorrected" in facts
        assert page.locator("#verdict-thresholds tr").count() > 10
        assert page.locator("#evidence [data-module='perception']").count() == 1

        href = page.get_attribute("#download", "href")
        assert href == "/api/runs/car1/verdict.json"
        download = page.request.get(board.url.rstrip("/") + href)
        assert download.status == 200
        assert download.headers["content-disposition"].startswith("attachment")
        served = orjson.loads(download.body())
        sent = feed_verdict(car.endpoint, "car1")
        assert served["primary_root_cause"] == sent["primary_root_cause"] == "perception"
        assert len(served["frames"]) == len(sent["frames"]) == 81
        assert served == sent

        headers = page.request.get(board.url).headers
        csp = headers["content-security-policy"]
        assert "default-src 'self'" in csp and "unsafe-inline" not in csp
        assert headers["x-content-type-options"] == "nosniff"
        assert requested and all(url.startswith(board.url) for url in requested)
        page.close()


@pytest.mark.slow
def test_the_page_says_whether_zenoh_is_reached_and_recovers_after_an_outage(
    browser: Any,
) -> None:
    """Issue 38 items 4 and 5. Green "live" only while Zenoh is reached, as seen on a
    screenshot; each endpoint's state; a bridge that goes away is said within seconds, and
    one back with another run on the same prefix and endpoint is followed again, its run
    beside the first (never erasing it)."""
    endpoint, other = (f"tcp/127.0.0.1:{free_port()}" for _ in range(2))
    with dashboard(endpoint, other) as board:
        page = browser.new_page()
        page.goto(board.url)
        wait_for_connection(page, "zenoh not connected: no results can arrive")
        links = page.text_content("#zenoh") or ""
        assert f"{endpoint} not connected" in links and f"{other} not connected" in links
        assert colours_shown(screenshot(page, "#connection")[1]) == {"bad"}
        with feed("car1", endpoint=endpoint, run="first"):
            wait_for_connection(page, "live · zenoh 1 of 2 connected")
            page.wait_for_function(
                "() => document.getElementById('verdict-primary').textContent === 'perception'"
            )
            assert colours_shown(screenshot(page, "#connection")[1]) == set()  # amber, not green
            assert f"{endpoint} connected" in (page.text_content("#zenoh") or "")
            first = board.runs()["runs"]
        wait_for_connection(page, "zenoh not connected: no results can arrive")  # the outage, said
        assert re.search(
            f"{re.escape(endpoint)} not connected since .+ \\(reconnecting\\)",
            page.text_content("#zenoh") or "",
        )
        with feed("car1", endpoint=endpoint, run="second"), feed("car1", endpoint=other, run="x"):
            wait_for_connection(page, "live")
            assert colours_shown(screenshot(page, "#connection")[1]) == {"good"}
            page.wait_for_function("() => document.querySelectorAll('#runs tbody tr').length === 3")
            rows = page.eval_on_selector_all(
                "#runs tbody tr", "rows => rows.map(r => r.cells[0].textContent)"
            )
            assert rows == ["car1 · run first", "car1 · run second", "car1 · run x"]
            runs = {run["id"]: run for run in board.runs()["runs"]}
            (before,) = first
            assert runs["car1@first"]["modules"] == before["modules"]  # kept whole
            for name in ("car1@second", "car1@x"):

                def judged(name: str = name) -> bool:
                    return board.runs_by_id().get(name, {}).get("verdict") is not None

                _wait_until(judged)
                assert board.runs_by_id()[name]["verdict"]["primary_root_cause"] == "perception"
        page.close()


#: The page's colours (app.css): good (green) is for a passing module or a conclusive
#: "no fault found" only; warn for what could not be judged.
GOOD, WARN = "rgb(30, 123, 52)", "rgb(154, 103, 0)"


def test_an_inconclusive_verdict_shows_inconclusive_with_its_reasons_never_green(
    browser: Any, tmp_path: Path
) -> None:
    """docs/verdicts.md: a live verdict without the evidence (no detections, no collision
    source), fed by a real Zenoh peer: inconclusive with its reasons, the module not judged
    and the collision unknown shown as such; nothing says "no fault found" or is green."""
    with feed("unsure", log=unsure_copy(tmp_path / "unsure")) as car:
        car.lines.wait_for("^VERDICT")
        sent = feed_verdict(car.endpoint, "unsure")
        with dashboard(car.endpoint) as board:
            page = browser.new_page()
            page.goto(board.url)
            page.wait_for_function(
                "() => document.getElementById('verdict-outcome').textContent !== ''"
            )
            page.wait_for_function("() => document.getElementById('index').textContent === '80'")
            outcome = page.locator("#verdict-outcome")
            assert outcome.text_content() == sent["verdict"]
            assert sent["verdict"].startswith("inconclusive: collision unknown")
            assert outcome.get_attribute("class") == "outcome outcome-inconclusive"
            assert outcome.evaluate("node => getComputedStyle(node).color") == WARN
            assert page.text_content("#verdict-conclusive") == "no"
            assert sent["primary_root_cause"] is None  # said as such, not as a dash
            assert page.text_content("#verdict-primary") == "none found (inconclusive)"
            reasons = page.eval_on_selector_all(
                "#verdict-reasons li", "els => els.map(e => e.textContent)"
            )
            assert reasons == sent["why_inconclusive"] and len(reasons) == 2
            facts = page.text_content("#verdict-facts")
            assert "conclusiveno" in facts and "collisionunknown" in facts
            assert page.text_content("#runs tbody tr[data-run='unsure'] td:last-child") == (
                "inconclusive"
            )
            # Read in one evaluation: the rows are redrawn with every event.
            cell = page.eval_on_selector(
                "#modules tr[data-module=perception] .status",
                "node => [node.textContent, getComputedStyle(node).color]",
            )
            assert cell == ["not judged (no detections_2d)", WARN]
            assert "no fault found" not in page.text_content("body")
            green = page.eval_on_selector_all(
                "#verdict *, #runs td, #modules tr[data-module=perception] td",
                f"els => els.filter(e => getComputedStyle(e).color === {GOOD!r}).length",
            )
            assert green == 0
            page.close()


@contextmanager
def hostile_peer() -> Iterator[str]:
    """A Zenoh peer answering the catch-up with markup in every string a page shows."""
    import zenoh

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    verdict = {
        "primary_root_cause": HOSTILE,
        "contributing": [HOSTILE],
        "root_causes": [HOSTILE],
        "attribution_basis": HOSTILE,
        "reason": HOSTILE,
        "partner_id": HOSTILE,
        "semantics": HOSTILE,
        "thresholds": {HOSTILE: 1},
        "evidence": {HOSTILE: {"basis": HOSTILE, "metrics": {HOSTILE: HOSTILE}}},
        "frames": [],
    }
    result = {"index": 0, "frame": HOSTILE, "failed": True, "metrics": {HOSTILE: HOSTILE}}
    answers = {
        "evil/ads_rca/verdict": verdict,
        "evil/ads_rca/status": {"state": HOSTILE},
        "evil/ads_rca/frames": {"frames": [{"modules": {"perception": result}}]},
    }

    def answer(key: str, payload: str) -> Callable[[Any], None]:
        return lambda query: query.reply(key, payload)

    session = zenoh.open(zenoh.Config.from_json5(session_config("peer", listen=[endpoint])))
    declared: list[Any] = []
    try:
        for key, document in answers.items():
            declared.append(session.declare_queryable(key, answer(key, json.dumps(document))))
        yield endpoint
    finally:
        close_session(session, declared)


def test_finished_runs_are_listed_caught_up_and_hostile_text_stays_text(browser: Any) -> None:
    with feed("car_a") as car_a, feed("car_b") as car_b, hostile_peer() as evil:
        car_a.lines.wait_for("^VERDICT")
        car_b.lines.wait_for("^VERDICT")
        with dashboard(car_a.endpoint, car_b.endpoint, evil) as board:  # after the verdicts
            page = browser.new_page()
            page.goto(board.url)
            page.wait_for_function(
                "() => document.querySelectorAll('#run-select option').length === 3"
            )
            options = page.eval_on_selector_all(
                "#run-select option", "els => els.map(e => e.value)"
            )
            assert options == ["car_a", "car_b", "evil"]
            for run in ("car_a", "car_b"):
                page.select_option("#run-select", run)
                page.wait_for_function(
                    "() => document.getElementById('verdict-primary').textContent === 'perception'"
                )
                assert page.text_content("#run-name") == run
                assert page.text_content("#index") == "80"

            page.select_option("#run-select", "evil")
            page.wait_for_function(
                f"() => document.getElementById('verdict-primary').textContent === {HOSTILE!r}"
            )
            page.wait_for_function(  # the hostile result too, drawn after the verdict's event
                "() => document.querySelector('#modules tr[data-module=perception] .judged')"
                ".textContent === '1'"
            )
            for selector in ("#verdict-facts", "#verdict-thresholds", "#evidence", "#modules"):
                assert HOSTILE in page.text_content(selector), selector
            assert page.text_content("#frame") == HOSTILE
            assert page.text_content("#state") == HOSTILE
            assert page.locator("img").count() == 0
            assert page.evaluate("typeof window.pwned") == "undefined"
            download = page.request.get(board.url + "api/runs/evil/verdict.json")
            assert download.headers["content-type"].startswith("application/json")
            assert orjson.loads(download.body())["partner_id"] == HOSTILE
            page.close()


def test_bad_options_are_one_line_and_exit_status_2() -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        taken = str(busy.getsockname()[1])
        cases = {
            "not a port": (["--port", "http"], "--port"),
            "port too high": (["--port", "70000"], "--port"),
            "port in use": (["--port", taken], "cannot serve on 127.0.0.1 port"),
            "any interface": (["--host", "0.0.0.0"], "--allow-remote"),
            "another host": (["--host", "192.0.2.7"], "not a loopback address"),
            "remote zenoh": (
                ["--connect", "tcp/192.0.2.7:7447"],
                "not on loopback; give --allow-remote",
            ),
            "bad endpoint": (["--connect", "http://x"], "PROTOCOL/HOST:PORT"),
            "bad prefix": (["--prefix", "car/*"], "--prefix"),
        }
        base = [sys.executable, "-m", "ads_rca.cli", "dashboard"]
        local = ["--connect", f"tcp/127.0.0.1:{free_port()}"]
        running = {
            name: subprocess.Popen(
                [*base, *local, *argv], stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=_env()
            )
            for name, (argv, _) in cases.items()
        }
        for name, process in running.items():
            out, err = process.communicate(timeout=30)
            assert process.returncode == 2, (name, err)
            assert out == b"", name
            lines = err.decode().splitlines()
            assert len(lines) == 1 and lines[0].startswith("ads-rca dashboard: error: "), name
            assert cases[name][1] in lines[0], (name, lines[0])


def _open_stream(url: str, origin: str = "") -> socket.socket:
    """A raw event-stream request, its first event read: a browser that stays connected."""
    host, port = re.findall(r"http://([^:/]+):(\d+)/", url)[0]
    stream = socket.create_connection((host, int(port)), timeout=10)
    said = f"Origin: {origin}\r\n" if origin else ""
    stream.sendall(f"GET /events HTTP/1.1\r\nHost: {host}:{port}\r\n{said}\r\n".encode())
    received = b""
    while b"event: runs" not in received:
        chunk = stream.recv(65536)
        assert chunk, "stream closed"
        received += chunk
    return stream


def test_foreign_origins_are_refused_and_one_address_cannot_take_every_stream() -> None:
    """Any page could hold event streams until the user's own page got 503 (32 slots):
    a request whose Origin is not this server's is refused; one address holds at most 8
    streams (429 beyond), the rest stay for others."""
    from ads_rca.remote.web import MAX_CLIENTS_PER_ADDRESS

    with dashboard(f"tcp/127.0.0.1:{free_port()}") as board:
        own = board.url.rstrip("/")
        for path in ("/events", "/api/runs", "/"):
            for foreign in ("http://evil.example", "null", own.replace("http", "https")):
                assert board.get(path, origin=foreign)[0] == 403, (path, foreign)
        assert board.get("/api/runs", origin=own)[0] == 200
        streams = [_open_stream(board.url, origin=own) for _ in range(MAX_CLIENTS_PER_ADDRESS)]
        try:
            status, _, body = board.get("/events")
            assert status == 429 and b"from this address" in body
        finally:
            for stream in streams:
                stream.close()
        deadline = time.monotonic() + 10  # closed streams are noticed within a second
        while _events_status(board.url) != 200:
            assert time.monotonic() < deadline, "a closed stream's slot never came back"
            time.sleep(0.2)


def _events_status(url: str) -> int:
    """The status an event-stream request gets now (the stream is closed at once)."""
    host, port = re.findall(r"http://([^:/]+):(\d+)/", url)[0]
    with socket.create_connection((host, int(port)), timeout=10) as stream:
        stream.sendall(f"GET /events HTTP/1.1\r\nHost: {host}:{port}\r\n\r\n".encode())
        first = stream.recv(64).split(b"\r\n", 1)[0]
    return int(first.split()[1])


def test_sigint_and_sigterm_stop_it_cleanly_with_streams_open() -> None:
    with feed("car1") as car:
        car.lines.wait_for("^VERDICT")
        stops = {signal.SIGINT: 130, signal.SIGTERM: 0}
        started = {sig: start_dashboard(car.endpoint) for sig in stops}
        streams = []
        try:
            for _, lines in started.values():
                line = lines.wait_for("^ads-rca dashboard: http://")
                streams.append(_open_stream(line.split()[2]))
            for sig, (process, _) in started.items():
                process.send_signal(sig)
            begun = time.monotonic()
            for sig, (process, _) in started.items():
                _, err = process.communicate(timeout=10)
                assert process.returncode == stops[sig], err
                assert err == "", err
            assert time.monotonic() - begun < 5.0
        finally:
            for stream in streams:
                stream.close()
            for process, _ in started.values():
                _stop(process)


def _result(index: int) -> bytes:
    document = {"index": index, "frame": index + 1, "failed": False, "metrics": {"c_gt": 5.0}}
    return orjson.dumps(document)


async def _stream_events(url: str, until: Callable[[dict[str, Any]], bool]) -> list[Any]:
    import aiohttp

    events: list[Any] = []
    async with aiohttp.ClientSession() as session, session.get(url) as response:
        assert response.headers["Content-Type"] == "text/event-stream"
        async for raw in response.content:
            line = raw.decode().rstrip("\n")
            if line.startswith("data: "):
                events.append((time.monotonic(), json.loads(line[6:])))
                if until(events[-1][1]):
                    break
    return events


def test_events_are_coalesced_and_closed_streams_dropped() -> None:
    """In-process, no Zenoh: 400 results in 0.8 s reach a browser's stream as at most ~10
    events a second, the last with the last result; a closed stream is forgotten."""
    from aiohttp import web

    from ads_rca.remote.web import Hub, make_app

    async def scenario() -> None:
        hub = Hub(DashboardModel())
        app = make_app(hub)
        runner = web.AppRunner(app, shutdown_timeout=1.0)
        await runner.setup()
        site = web.TCPSite(runner, "127.0.0.1", 0)
        await site.start()
        url = f"http://127.0.0.1:{runner.addresses[0][1]}"
        try:

            async def produce() -> None:
                while not hub.clients:
                    await asyncio.sleep(0.01)
                for index in range(400):
                    hub.feed([("car9/ads_rca/modules/planning.json", _result(index))], time.time())
                    await asyncio.sleep(0.002)

            producer = asyncio.create_task(produce())
            events = await _stream_events(
                url + "/events",
                lambda event: any(r["last_index"] == 399 for r in event["runs"]),
            )
            await producer
            timed = [(at, event) for at, event in events if event["runs"]]
            span = timed[-1][0] - timed[0][0]
            assert len(timed) <= span / 0.1 + 2, (len(timed), span)
            assert all(event["names"] == ["car9"] for _, event in timed)
            await asyncio.wait_for(_until(lambda: not hub.clients), 5.0)

            import aiohttp

            async with aiohttp.ClientSession() as session:
                async with session.get(url + "/api/runs/car9/timeline?after=395") as response:
                    points = (await response.json())["points"]
                    assert [p[0] for p in points] == [396, 397, 398, 399]
                for path, code in (
                    ("/api/runs/car9/verdict.json", 404),  # no verdict yet
                    ("/api/runs/nope/timeline", 404),
                    ("/api/runs/car9/timeline?after=x", 400),
                    ("/static/..%2Fweb.py", 404),
                    ("/static/index.html", 404),
                ):
                    async with session.get(url + path) as response:
                        assert response.status == code, path
                        assert "nosniff" in response.headers["X-Content-Type-Options"]
        finally:
            await runner.cleanup()

    run_in_thread(lambda: asyncio.run(scenario()))


def run_in_thread(body: Callable[[], None]) -> None:
    """``body`` on a thread of its own: Playwright's sync API keeps an event loop running
    on this one while the browser fixture lives, and asyncio.run refuses to nest."""
    failures: list[BaseException] = []

    def target() -> None:
        try:
            body()
        except BaseException as error:
            failures.append(error)

    thread = threading.Thread(target=target)
    thread.start()
    thread.join(60)
    assert not thread.is_alive(), "the scenario did not end"
    if failures:
        raise failures[0]


async def _until(condition: Callable[[], bool]) -> None:
    while not condition():
        await asyncio.sleep(0.02)


def test_what_is_sent_is_bounded() -> None:
    from ads_rca.remote.web import MAX_ITEMS, MAX_TEXT, clip

    deep: Any = "x"
    for _ in range(50):
        deep = [deep]
    clipped = clip({"s": "y" * 10_000, "l": list(range(1000)), "d": deep})
    assert len(clipped["s"]) == MAX_TEXT + 1
    assert len(clipped["l"]) == MAX_ITEMS + 1
    assert len(json.dumps(clipped)) < 2000


def _peak_rss_mb(pid: int) -> float:
    """The process's peak resident set (VmHWM), MB."""
    for text in Path(f"/proc/{pid}/status").read_text().splitlines():
        if text.startswith("VmHWM:"):
            return int(text.split()[1]) / 1024
    raise AssertionError("no VmHWM")


def _limited() -> None:
    import resource

    resource.setrlimit(resource.RLIMIT_AS, (3 << 29, 3 << 29))  # 1.5 GiB of address space


def test_forged_large_verdicts_are_bounded_in_memory() -> None:
    """Issue 41 item 7: twelve forged 10 MB verdicts (each under its own run id) took the
    dashboard to 600-680 MB and a MemoryError; under a 1.5 GB address-space cap it died.
    Now the per-frame list is not kept (its length is), the documents kept for download
    are bounded in bytes, and a sample over its key's limit is dropped before it is
    decoded or queued. The dashboard keeps serving, every run's verdict reads, and the
    downloads give the documents as received."""
    import zenoh

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    frame = {"index": 0, "frame": 1, "results": {"perception": {"metrics": {"x": "y" * 2000}}}}
    BLOCK = zenoh.CongestionControl.BLOCK  # as the bridge puts: a large sample is not dropped
    session = zenoh.open(zenoh.Config.from_json5(session_config("peer", listen=[endpoint])))
    argv = [sys.executable, "-m", "ads_rca.cli", "dashboard", "--port", "0"]
    process = subprocess.Popen(
        [*argv, "--connect", endpoint],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=_env(),
        preexec_fn=_limited,  # noqa: PLW1509 (setrlimit only, before exec)
    )
    try:
        lines = Lines(process)
        found = re.search(r"http://\S+/", lines.wait_for("^ads-rca dashboard: http://"))
        assert found is not None
        board = Dashboard(found.group(0), process)
        _wait_until(lambda: any(link["state"] == "connected" for link in board.runs()["zenoh"]))
        sizes = []
        for n in range(12):
            verdict = {
                "primary_root_cause": None,
                "conclusive": False,
                "why_inconclusive": ["forged"],
                "live": {"run": f"forged{n}"},
                "frames": [frame] * 4900,
            }
            payload = json.dumps(verdict).encode()
            sizes.append(len(payload))
            session.put("car1/ads_rca/verdict.json", payload, congestion_control=BLOCK)
        oversize = json.dumps({"primary_root_cause": None, "frames": ["x" * (65 << 20)]})
        session.put("car1/ads_rca/verdict.json", oversize.encode(), congestion_control=BLOCK)
        _wait_until(lambda: sum(r["verdict"] is not None for r in board.runs()["runs"]) == 12, 60)
        assert min(sizes) > 10_000_000
        _wait_until(lambda: board.runs()["dropped"] == 1, 60)  # the 65 MB one, never decoded
        snapshot = board.runs()
        assert all(r["verdict"]["frames_count"] == 4900 for r in snapshot["runs"])
        status, _, body = board.get("/api/runs/car1%40forged11/verdict.json")
        assert status == 200 and len(body) == sizes[11]
        peak = _peak_rss_mb(process.pid)
        assert peak < 450, f"peak resident set {peak:.0f} MB"
        assert process.poll() is None
    finally:
        close_session(session, ())
        _stop(process)
    assert "Traceback" not in (process.stderr.read() if process.stderr else "")


def test_an_over_long_request_line_is_one_log_line() -> None:
    """Issue 41 item 8: aiohttp logged a traceback (``LineTooLong``) per refused request."""
    process, lines = start_dashboard(f"tcp/127.0.0.1:{free_port()}")
    try:
        found = re.search(r"http://(\S+):(\d+)/", lines.wait_for("^ads-rca dashboard: http://"))
        assert found is not None
        for _ in range(3):
            with socket.create_connection((found.group(1), int(found.group(2))), 10) as stream:
                stream.sendall(b"GET /" + b"a" * 20_000 + b" HTTP/1.1\r\nHost: x\r\n\r\n")
                reply = stream.recv(200)
            assert reply.split(b"\r\n")[0].endswith(b" 400 Bad Request"), reply
        process.send_signal(signal.SIGINT)
        _, err = process.communicate(timeout=10)
    finally:
        _stop(process)
    refused = [line for line in err.splitlines() if "refused a bad request" in line]
    assert len(refused) == 3, err
    assert "Traceback" not in err and "LineTooLong" not in err.replace("Line is too long", "")


def _few_files() -> None:
    import resource

    resource.setrlimit(resource.RLIMIT_NOFILE, (256, 256))


def test_a_slow_request_flood_is_bounded_and_the_dashboard_recovers() -> None:
    """Issue 43 item 5: at ``ulimit -n 1024``, 1,100 half-open requests took the dashboard
    past its file descriptors (EMFILE tracebacks, unreachable until they stopped). Here at
    256 descriptors, 300 requests whose headers never end: the connections over the bound
    are closed at once, the slow ones after the request timeout, the process keeps its
    descriptors, says so in one line, and serves the page again while the flood's sockets
    are still open on the attacker's side."""
    from ads_rca.remote.connections import REQUEST_TIMEOUT_S

    argv = [sys.executable, "-m", "ads_rca.cli", "dashboard", "--port", "0"]
    process = subprocess.Popen(
        [*argv, "--connect", f"tcp/127.0.0.1:{free_port()}"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=_env(),
        preexec_fn=_few_files,  # noqa: PLW1509 (setrlimit only, before exec)
    )
    flood: list[socket.socket] = []
    try:
        lines = Lines(process)
        found = re.search(r"http://(\S+):(\d+)/", lines.wait_for("^ads-rca dashboard: http://"))
        assert found is not None
        address = (found.group(1), int(found.group(2)))
        for _ in range(300):
            with contextlib.suppress(OSError):
                stream = socket.create_connection(address, 5)
                stream.sendall(b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\n")  # never ends
                flood.append(stream)
        assert len(flood) > 100
        start = time.monotonic()

        def served() -> bool:
            try:
                with urllib.request.urlopen(f"http://{address[0]}:{address[1]}/", timeout=2) as r:
                    return bool(r.status == 200)
            except OSError:
                return False

        _wait_until(served, REQUEST_TIMEOUT_S + 15)
        assert time.monotonic() - start < REQUEST_TIMEOUT_S + 15
        assert process.poll() is None
        fds = len(os.listdir(f"/proc/{process.pid}/fd"))
        assert fds < 200, fds
        process.send_signal(signal.SIGINT)
        _, err = process.communicate(timeout=10)
    finally:
        for stream in flood:
            stream.close()
        _stop(process)
    assert "Traceback" not in err and "Too many open files" not in err, err[-2000:]
    said = [line for line in err.splitlines() if "connections refused over the limit" in line]
    assert 1 <= len(said) <= 3, err[-2000:]
