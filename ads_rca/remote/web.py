"""``ads-rca dashboard``'s web side: an aiohttp app showing the runs seen on Zenoh, live.

One :class:`Hub` owns the :class:`~ads_rca.remote.view.DashboardModel`; a background task
(:meth:`Hub.pump`) drains the :class:`~ads_rca.remote.client.RemoteLinks` (a Zenoh session
per endpoint) into it on the event loop (zenoh calls back on its own threads) and asks the
queryables for what was missed when the dashboard starts, a link (re)connects or a run it
had not seen appears. Each link's state is part of every event, so the page says whether
Zenoh is reached, not only whether its own stream is. The browser gets one static
page (HTML, JS and CSS served from ``static/``, nothing fetched from elsewhere) and
server-sent events (``/events``).

Pushes are coalesced, not queued: every run has a version that each sample it takes bumps;
each browser's stream remembers which version of each run it was sent and, at most every
:data:`MIN_INTERVAL` seconds, sends the runs that changed since (the verdict only when it
changed). A fast run therefore costs each browser at most ~10 small events a second, a slow
browser holds nothing but that memory, and one that went away is dropped when its stream is
found closed. Every document is clipped (:func:`clip`) before it is sent: strings, lists,
objects and nesting have bounds, so a hostile sample cannot make every page heavy. The page
inserts wire text with ``textContent`` only, and the headers (:data:`SECURITY_HEADERS`) forbid
inline script; the ``Host`` header is checked against the loopback names, so a web page
elsewhere cannot read the API through DNS rebinding.
"""

from __future__ import annotations

import asyncio
import contextlib
import ipaddress
import itertools
import logging
import re
import signal
import sys
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from importlib import resources
from typing import Any

import orjson
from aiohttp import web
from aiohttp.http_exceptions import HttpProcessingError

from ads_rca.errors import ConfigError, InputError
from ads_rca.foundation.text import printable
from ads_rca.remote.client import RemoteLinks
from ads_rca.remote.connections import ConnectionGuard, GuardedProtocol, connection_bounds
from ads_rca.remote.keys import SAMPLE_SUFFIX
from ads_rca.remote.view import RATE_SPAN, DashboardModel, RunView, margin_of, read_verdict

#: Seconds an idle kept-alive connection stays open (aiohttp's default is an hour).
KEEPALIVE_TIMEOUT_S = 15.0
#: Least time between two events to one browser (s): at most ~10 updates a second.
MIN_INTERVAL = 0.1
#: A `ping` event on an idle stream this often (s): proxies keep it open, and the page
#: opens a new stream when none came for 2.5 times this long.
KEEPALIVE = 15.0
#: How often a stream checks that its browser is still there while idle (s).
LIVENESS = 1.0
#: A write that does not finish in this long drops the browser (s).
WRITE_TIMEOUT = 10.0
#: Browsers streaming at once; more get 503.
MAX_CLIENTS = 32
#: Streams one address may hold at once (a client cannot take every slot); more get 429.
MAX_CLIENTS_PER_ADDRESS = 8
#: How often the pump drains the Zenoh queue (s), and how many samples one pass applies.
PUMP_PERIOD = 0.05
PUMP_BATCH = 2000
#: Queryable catch-up: each query's timeout (s), and the least gap between two (s).
CATCH_UP_TIMEOUT = 1.0
CATCH_UP_GAP = 2.0
#: Bounds of what is sent to a browser (see :func:`clip`).
MAX_TEXT = 500
MAX_ITEMS = 60
MAX_KEYS = 120
MAX_DEPTH = 8
#: Sent with every response.
SECURITY_HEADERS = {
    "Content-Security-Policy": (
        "default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self'; "
        "connect-src 'self'; object-src 'none'; base-uri 'none'; form-action 'none'; "
        "frame-ancestors 'none'"
    ),
    "X-Content-Type-Options": "nosniff",
    "X-Frame-Options": "DENY",
    "Referrer-Policy": "no-referrer",
    "Cache-Control": "no-store",
}
#: The static files: name → content type (nothing else is served from the folder).
STATIC_FILES = {
    "index.html": "text/html",
    "app.js": "text/javascript",
    "app.css": "text/css",
}
_AFTER = re.compile(r"^-?[0-9]{1,12}$")


def clip(value: Any, depth: int = 0) -> Any:
    """``value`` with every string, list, object and nesting level bounded (the cut parts
    marked with ``…``): what a browser is sent of a document from the wire."""
    if isinstance(value, str):
        return value if len(value) <= MAX_TEXT else value[:MAX_TEXT] + "…"
    if isinstance(value, dict):
        if depth >= MAX_DEPTH:
            return "…"
        out = {}
        for count, (key, item) in enumerate(value.items()):
            if count >= MAX_KEYS:
                out["…"] = f"{len(value) - MAX_KEYS} more keys"
                break
            out[clip(str(key))] = clip(item, depth + 1)
        return out
    if isinstance(value, list):
        if depth >= MAX_DEPTH:
            return "…"
        items = [clip(item, depth + 1) for item in value[:MAX_ITEMS]]
        if len(value) > MAX_ITEMS:
            items.append(f"… {len(value) - MAX_ITEMS} more")
        return items
    return value


def _nonfinite(document: dict[str, Any] | None, under: str) -> dict[str, Any]:
    """The strict-JSON annotation entries of ``document`` that point under ``under``."""
    found = (document or {}).get("$nonfinite")
    if not isinstance(found, dict):
        return {}
    return {k: v for k, v in found.items() if isinstance(k, str) and k.startswith(under)}


def verdict_digest(view: RunView) -> dict[str, Any] | None:
    """What the page shows of a run's verdict: all of it but the per-frame list (counted:
    the model keeps only its length), and ``outcome``, how it reads (``view.read_verdict``:
    the page never decides that itself)."""
    verdict = view.verdict
    if verdict is None:
        return None
    digest = {k: v for k, v in verdict.items() if k not in ("frames", "$nonfinite")}
    digest["outcome"] = read_verdict(verdict).to_dict()
    digest["frames_count"] = view.verdict_frames
    digest["downloadable"] = view.verdict_payload is not None
    problems = verdict.get("input_problems")
    digest["input_problems"] = len(problems) if isinstance(problems, list) else problems
    annotation = {
        pointer: kind
        for under in ("/evidence/", "/thresholds/")
        for pointer, kind in _nonfinite(verdict, under).items()
    }
    digest["nonfinite"] = annotation
    return dict(clip(digest))


def run_digest(view: RunView, now: float) -> dict[str, Any]:
    """A run's summary as the page draws it, without the verdict (sent on its own)."""
    summary = view.summary(now)
    summary.pop("verdict", None)
    for module, entry in summary["modules"].items():
        entry["nonfinite"] = _nonfinite(view.modules.get(module), "/metrics/")
    summary["id"] = view.name
    summary["has_verdict"] = view.verdict is not None
    summary["timeline_points"] = len(view.timeline)
    summary["timeline_last"] = view.timeline[-1][0] if view.timeline else None
    return dict(clip(summary))


@dataclass(eq=False)  # kept in a set, by identity
class Client:
    """One browser's event stream: which version of each run it was last sent."""

    wake: asyncio.Event = field(default_factory=asyncio.Event)
    #: The peer's address (the per-client limit counts streams by it).
    address: str = ""
    sent: dict[str, tuple[int, int]] = field(default_factory=dict)
    sent_global: int = -1
    sent_names: list[str] | None = None


class Hub:
    """The model, its versions, and the browsers streaming it."""

    def __init__(self, model: DashboardModel) -> None:
        self.model = model
        # Versions come from one counter, so a run dropped and seen again never repeats one.
        self._counter = itertools.count(1)
        self.versions: dict[str, int] = {}
        self.verdict_versions: dict[str, int] = {}
        self.global_version = 0
        self.clients: set[Client] = set()
        self.closing = False
        self.dropped = 0
        self.catch_up_error = ""
        self._digests: dict[str, tuple[int, dict[str, Any]]] = {}
        self._verdicts: dict[str, tuple[int, dict[str, Any] | None]] = {}
        #: Each Zenoh link's state (``client.Link.describe``), as last sent.
        self.links: list[dict[str, Any]] = []
        #: When the pending catch-up was asked for (monotonic; None: none pending).
        self._catch_up_asked: float | None = None
        self._catch_up_wanted = True
        self._last_catch_up = -1e9
        self._rates_at = 0.0

    # Feeding -------------------------------------------------------------------------

    def feed(self, samples: Iterable[tuple[str, bytes]], now: float) -> None:
        """Apply samples (or queryable replies) to the model and mark what they changed."""
        known = set(self.model.runs)
        problems = self.model.problems
        changed = False
        for key, payload in samples:
            event = self.model.apply(key, payload, now)
            if event is None:
                continue
            for name in event["runs"] if event["kind"] == "frames" else (event["name"],):
                self.versions[name] = next(self._counter)
            if event["kind"] == "verdict":
                self.verdict_versions[event["name"]] = next(self._counter)
                if key.endswith(SAMPLE_SUFFIX):  # live: fetch the frames rate limits skipped
                    self._catch_up_wanted = True
            changed = True
        if self.model.problems != problems:
            self.global_version += 1
            changed = True
        if set(self.model.runs) - known:
            self._catch_up_wanted = True  # a run seen first live: ask what it said before
        if changed:
            self._forget_gone()
            self.notify()

    def refresh_rates(self, now: float) -> None:
        """Once a second, mark the runs fed lately as changed, so their frame rate (read
        over the last few seconds) goes on being sent as it falls back to zero."""
        if now - self._rates_at < 1.0:
            return
        self._rates_at = now
        fresh = [n for n, v in self.model.runs.items() if now - v.updated <= RATE_SPAN + 1.5]
        for name in fresh:
            self.versions[name] = next(self._counter)
        if fresh:
            self.notify()

    def _forget_gone(self) -> None:
        for table in (self.versions, self.verdict_versions, self._digests, self._verdicts):
            for name in [n for n in table if n not in self.model.runs]:
                del table[name]

    def notify(self) -> None:
        for client in self.clients:
            client.wake.set()

    async def pump(self, links: RemoteLinks) -> None:
        """Drain ``links`` into the model until cancelled; catch up through the
        queryables at start and when a new run appears (at most every few seconds; the
        links catch up by themselves when one (re)connects); say each link's state."""
        while True:
            now = time.time()
            self.feed(links.drain(PUMP_BATCH), now)
            states = links.states()
            if links.dropped != self.dropped or states != self.links:
                self.dropped, self.links = links.dropped, states
                self.global_version += 1
                self.notify()
            self.refresh_rates(now)
            self._maybe_catch_up(links)
            await asyncio.sleep(PUMP_PERIOD)

    def _maybe_catch_up(self, links: RemoteLinks) -> None:
        asked = self._catch_up_asked
        if asked is not None:
            if links.caught_up < asked:
                return
            self._catch_up_asked = None
            self._last_catch_up = time.monotonic()
            if links.catch_up_error != self.catch_up_error:
                self.catch_up_error = links.catch_up_error
                self.global_version += 1
            # Its replies are all queued now: the runs they name are no reason for another.
            while batch := links.drain(PUMP_BATCH):
                self.feed(batch, time.time())
            self._catch_up_wanted = False
        if not self._catch_up_wanted or time.monotonic() - self._last_catch_up < CATCH_UP_GAP:
            return
        self._catch_up_wanted = False
        self._catch_up_asked = time.monotonic()
        links.request_catch_up()

    # Drawing -------------------------------------------------------------------------

    def digest(self, name: str, now: float) -> dict[str, Any]:
        """The run's digest, computed once per version."""
        version = self.versions.get(name, 0)
        cached = self._digests.get(name)
        if cached is None or cached[0] != version:
            cached = self._digests[name] = (version, run_digest(self.model.runs[name], now))
        return cached[1]

    def verdict(self, name: str) -> dict[str, Any] | None:
        version = self.verdict_versions.get(name, 0)
        cached = self._verdicts.get(name)
        if cached is None or cached[0] != version:
            view = self.model.runs[name]
            cached = self._verdicts[name] = (version, verdict_digest(view))
        return cached[1]

    def header(self, now: float) -> dict[str, Any]:
        return {
            "now": now,
            "names": sorted(self.model.runs),
            "problems": self.model.problems,
            "last_problem": self.model.last_problem,
            "dropped": self.dropped,
            "catch_up_error": self.catch_up_error,
            "zenoh": self.links,
        }

    def snapshot(self, now: float) -> dict[str, Any]:
        """Every run with its verdict: ``GET /api/runs``."""
        runs = [
            {**self.digest(name, now), "verdict": self.verdict(name)}
            for name in sorted(self.model.runs)
        ]
        return {**self.header(now), "runs": runs, "clients": len(self.clients)}

    def message(self, client: Client, now: float) -> bytes | None:
        """The event ``client`` is owed (the runs changed since its last one), None when
        it is up to date."""
        runs = []
        for name in sorted(self.model.runs):
            current = (self.versions.get(name, 0), self.verdict_versions.get(name, 0))
            before = client.sent.get(name)
            if before == current:
                continue
            entry = dict(self.digest(name, now))
            if before is None or before[1] != current[1]:
                entry["verdict"] = self.verdict(name)
            runs.append(entry)
            client.sent[name] = current
        names = sorted(self.model.runs)
        for gone in [p for p in client.sent if p not in self.model.runs]:
            del client.sent[gone]
        if not runs and client.sent_global == self.global_version and client.sent_names == names:
            return None
        client.sent_global = self.global_version
        client.sent_names = names
        data = orjson.dumps({**self.header(now), "runs": runs})
        return b"event: runs\ndata: " + data + b"\n\n"


HUB: web.AppKey[Hub] = web.AppKey("hub", Hub)
GUARD: web.AppKey[ConnectionGuard] = web.AppKey("guard", ConnectionGuard)
ALLOWED_HOSTS: web.AppKey[set[str]] = web.AppKey("allowed_hosts", set)
STATIC: web.AppKey[dict[str, bytes]] = web.AppKey("static", dict)


def _view_of(request: web.Request) -> RunView:
    """The run named in the URL, among the known runs only (never used as a path)."""
    view = request.app[HUB].model.find(request.match_info["run"])
    if view is None:
        raise web.HTTPNotFound(text="no such run\n")
    return view


async def _page(request: web.Request) -> web.Response:
    return _static_response(request, "index.html")


async def _static(request: web.Request) -> web.Response:
    name = request.match_info["name"]
    if name not in STATIC_FILES or name == "index.html":
        raise web.HTTPNotFound()
    return _static_response(request, name)


def _static_response(request: web.Request, name: str) -> web.Response:
    return web.Response(
        body=request.app[STATIC][name], content_type=STATIC_FILES[name], charset="utf-8"
    )


async def _no_icon(request: web.Request) -> web.Response:
    return web.Response(status=204)  # browsers ask; a 404 would show as an error


async def _runs(request: web.Request) -> web.Response:
    hub = request.app[HUB]
    return web.Response(
        body=orjson.dumps(hub.snapshot(time.time())), content_type="application/json"
    )


async def _verdict(request: web.Request) -> web.Response:
    view = _view_of(request)
    if view.verdict is None:
        raise web.HTTPNotFound(text="no verdict yet\n")
    if view.verdict_payload is None:
        raise web.HTTPGone(text="the verdict document was let go to bound memory\n")
    safe = re.sub(r"[^A-Za-z0-9_.-]", "_", "-".join(filter(None, (view.prefix, view.run_id))))
    safe = safe or "root"
    return web.Response(
        body=view.verdict_payload,
        content_type="application/json",
        headers={"Content-Disposition": f'attachment; filename="verdict-{safe}.json"'},
    )


async def _timeline(request: web.Request) -> web.Response:
    view = _view_of(request)
    after_text = request.query.get("after", "-1")
    if not _AFTER.match(after_text):
        raise web.HTTPBadRequest(text="after: an integer frame index\n")
    after = int(after_text)
    points = [[index, clearance] for index, clearance in view.timeline if index > after]
    planning = view.modules.get("planning")
    document = {
        "run": view.prefix,
        "run_id": view.run_id,
        "points": points,
        "margin": margin_of(planning) if planning is not None else None,
    }
    return web.Response(body=orjson.dumps(document), content_type="application/json")


async def _events(request: web.Request) -> web.StreamResponse:
    hub = request.app[HUB]
    address = request.remote or ""
    if len(hub.clients) >= MAX_CLIENTS:
        raise web.HTTPServiceUnavailable(text="too many dashboard pages open\n")
    if sum(c.address == address for c in hub.clients) >= MAX_CLIENTS_PER_ADDRESS:
        raise web.HTTPTooManyRequests(text="too many dashboard pages open from this address\n")
    response = web.StreamResponse(
        headers={"Content-Type": "text/event-stream", "X-Accel-Buffering": "no"}
    )
    await response.prepare(request)
    client = Client(address=address)
    hub.clients.add(client)
    try:
        await asyncio.wait_for(response.write(b"retry: 2000\n\n"), WRITE_TIMEOUT)
        quiet_since = time.monotonic()
        while not hub.closing:
            message = hub.message(client, time.time())
            if message is not None:
                await asyncio.wait_for(response.write(message), WRITE_TIMEOUT)
                quiet_since = time.monotonic()
                await asyncio.sleep(MIN_INTERVAL)  # what changes meanwhile goes in one event
                continue
            try:
                await asyncio.wait_for(client.wake.wait(), LIVENESS)
            except TimeoutError:
                transport = request.transport
                if transport is None or transport.is_closing():
                    break
                if time.monotonic() - quiet_since >= KEEPALIVE:
                    # An event, not a comment: the page sees it and opens a new stream when
                    # none came for a while (a connection that died without closing).
                    ping = b"event: ping\ndata: " + orjson.dumps({"now": time.time()}) + b"\n\n"
                    await asyncio.wait_for(response.write(ping), WRITE_TIMEOUT)
                    quiet_since = time.monotonic()
            client.wake.clear()
    except (ConnectionError, TimeoutError):
        pass  # the browser went away or stopped reading
    finally:
        hub.clients.discard(client)
    return response


@web.middleware
async def _guard(request: web.Request, handler: Callable[[web.Request], Any]) -> web.StreamResponse:
    """Refuse a ``Host`` that is not this server's loopback name (DNS rebinding), and a
    request a page of another origin made (its ``Origin`` is not this server's: a foreign
    page could hold event streams until the user's own page gets none). A request with no
    ``Origin`` (the page's own, a command-line client) is served."""
    guard = request.app.get(GUARD)
    if guard is not None:  # a complete request came: no longer a slow one
        guard.started(request.transport)
    allowed = request.app[ALLOWED_HOSTS]
    if allowed and request.host.lower() not in allowed:
        raise web.HTTPMisdirectedRequest(text="unexpected Host header\n")
    origin = request.headers.get("Origin")
    if origin is not None and origin.lower() != f"{request.scheme}://{request.host}".lower():
        raise web.HTTPForbidden(text="foreign origin\n")
    response: web.StreamResponse = await handler(request)
    return response


async def _headers(request: web.Request, response: web.StreamResponse) -> None:
    for name, value in SECURITY_HEADERS.items():
        response.headers.setdefault(name, value)


async def _on_shutdown(app: web.Application) -> None:
    hub = app[HUB]
    hub.closing = True
    hub.notify()


def load_static() -> dict[str, bytes]:
    """The page's files, read once from the package (works from a wheel or a zip too)."""
    folder = resources.files("ads_rca.remote").joinpath("static")
    return {name: folder.joinpath(name).read_bytes() for name in STATIC_FILES}


def make_app(hub: Hub, allowed_hosts: set[str] | None = None) -> web.Application:
    """The dashboard's routes on ``hub``; ``allowed_hosts`` (``host:port``, lower case)
    are the only ``Host`` headers served (empty or None: any)."""
    app = web.Application(middlewares=[_guard])
    app[HUB] = hub
    app[ALLOWED_HOSTS] = set(allowed_hosts or ())
    app[STATIC] = load_static()
    app.router.add_get("/", _page)
    app.router.add_get("/static/{name}", _static)
    app.router.add_get("/api/runs", _runs)
    app.router.add_get("/api/runs/{run}/verdict.json", _verdict)
    app.router.add_get("/api/runs/{run}/timeline", _timeline)
    app.router.add_get("/events", _events)
    app.router.add_get("/favicon.ico", _no_icon)
    app.on_response_prepare.append(_headers)
    app.on_shutdown.append(_on_shutdown)
    return app


def is_loopback(host: str) -> bool:
    if host.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def loopback_hosts(port: int) -> set[str]:
    """The ``Host`` headers a browser sends for this server on loopback."""
    return {f"{name}:{port}" for name in ("127.0.0.1", "localhost", "[::1]")}


def parse_port(text: str) -> int:
    """``--port``: 0 (any free port) to 65535, refused in one line."""
    shown = text.encode("unicode_escape").decode("ascii")[:20]
    if not re.fullmatch(r"[0-9]{1,5}", text.strip()) or int(text) > 65535:
        raise ConfigError(f"--port: {shown!r} is not a port number (0 to 65535; 0: any free)")
    return int(text)


def check_host(host: str, allow_remote: bool) -> str:
    """``--host``: loopback unless ``allow_remote`` (the dashboard has no authentication)."""
    shown = host.encode("unicode_escape").decode("ascii")[:60]
    if not host or not re.fullmatch(r"[A-Za-z0-9.:\[\]-]+", host):
        raise ConfigError(f"--host: {shown!r} is not a host name or address")
    if not allow_remote and not is_loopback(host):
        raise ConfigError(
            f"--host {shown}: not a loopback address; the dashboard has no authentication, "
            "so pass --allow-remote and put it behind a reverse proxy with TLS and login"
        )
    return host.strip("[]")


@dataclass(frozen=True)
class Options:
    """What ``ads-rca dashboard`` was asked for, checked."""

    host: str
    port: int
    connect: Sequence[str]
    prefix: str | None
    allow_remote: bool


class BadRequestLines(logging.Filter):
    """aiohttp logs a request it could not parse (an over-long request line or header, a
    malformed one: ``HttpProcessingError``) with a traceback. That is a peer's bad input:
    one line, the address and why, instead. Any other exception keeps its traceback (a bug
    in our code is never reported as bad input)."""

    def filter(self, record: logging.LogRecord) -> bool:
        error = record.exc_info[1] if record.exc_info else None
        if isinstance(error, HttpProcessingError):
            peer = record.args[0] if isinstance(record.args, tuple) and record.args else "?"
            why = printable(str(error).splitlines()[0] if str(error) else type(error).__name__)
            record.msg = "ads-rca dashboard: refused a bad request from %s: %s"
            record.args = (peer, why[:200])
            record.exc_info = record.exc_text = None
        return True


@contextlib.contextmanager
def bad_requests_in_one_line() -> Iterator[None]:
    """:class:`BadRequestLines` on aiohttp's server logger while the dashboard serves."""
    logger, found = logging.getLogger("aiohttp.server"), BadRequestLines()
    logger.addFilter(found)
    try:
        yield
    finally:
        logger.removeFilter(found)


def _url(host: str, port: int) -> str:
    return f"http://[{host}]:{port}/" if ":" in host else f"http://{host}:{port}/"


async def serve(options: Options, links: RemoteLinks, ready: Callable[[str], None]) -> int:
    """Serve until SIGINT (returns 130) or SIGTERM (returns 0), then close the Zenoh
    sessions and the web server (on every path: an open session hangs the interpreter at
    exit). ``ready`` gets the page's URL once the port is bound and Zenoh is open."""
    loop = asyncio.get_running_loop()
    stop: asyncio.Future[int] = loop.create_future()

    def stop_with(code: int) -> None:
        if not stop.done():
            stop.set_result(code)

    for sig, code in ((signal.SIGINT, 128 + signal.SIGINT), (signal.SIGTERM, 0)):
        loop.add_signal_handler(sig, stop_with, code)
    hub = Hub(DashboardModel(options.prefix))
    app = make_app(hub)
    app[GUARD] = guard = ConnectionGuard(*connection_bounds())
    runner = web.AppRunner(
        app, access_log=None, shutdown_timeout=2.0, keepalive_timeout=KEEPALIVE_TIMEOUT_S
    )
    listener: asyncio.Server | None = None
    try:
        await runner.setup()
        # "localhost" may resolve to two addresses, which port 0 would give two ports.
        host = "127.0.0.1" if options.host.lower() == "localhost" else options.host
        listener = await _listen(runner, host, options.port, guard)
        port = int(listener.sockets[0].getsockname()[1])
        if not options.allow_remote:
            app[ALLOWED_HOSTS].update(loopback_hosts(port))
        _open(links)
        pump = asyncio.create_task(hub.pump(links.start()))
        try:
            ready(_url(host, port))
            return await stop
        finally:
            pump.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await pump
    finally:
        links.close()
        if listener is not None:
            listener.close()
        await runner.cleanup()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.remove_signal_handler(sig)


async def _listen(
    runner: web.AppRunner, host: str, port: int, guard: ConnectionGuard
) -> asyncio.Server:
    """Accept connections on ``host``:``port`` for ``runner``'s app, each behind ``guard``
    (connections.py); a port that cannot be had is one line (InputError)."""
    factory = runner.server
    assert factory is not None, "the runner is set up first"
    loop = asyncio.get_running_loop()
    try:
        return await loop.create_server(
            lambda: GuardedProtocol(factory(), guard), host, port, reuse_address=True
        )
    except OSError as error:
        reason = error.strerror or str(error)
        raise InputError(f"cannot serve on {host} port {port}: {reason}") from None


def _open(links: RemoteLinks) -> None:
    """Open the Zenoh sessions (a peer's opens with its peer down: the links retry); their
    own errors (an endpoint Zenoh cannot use) as one line."""
    try:
        links.open_now()
    except Exception as error:
        if type(error).__module__.split(".")[0] != "zenoh":
            raise
        raise InputError(f"zenoh: {str(error).splitlines()[0][:200]}") from None


def run(options: Options) -> int:
    """Run the dashboard in this thread until stopped (see :func:`serve`); a bad option
    is a ConfigError before anything starts."""
    links = RemoteLinks(
        options.connect,
        options.prefix,
        mode="peer",
        allow_remote=options.allow_remote,
        catch_up_timeout=CATCH_UP_TIMEOUT,
    )

    def ready(url: str) -> None:
        endpoints = ", ".join(options.connect)
        print(f"ads-rca dashboard: {url} (zenoh: {endpoints}; Ctrl-C stops)", flush=True)
        if not is_loopback(options.host):
            print(
                "ads-rca dashboard: warning: serving beyond loopback with no authentication; "
                "put it behind a reverse proxy with TLS and login",
                file=sys.stderr,
                flush=True,
            )

    with bad_requests_in_one_line():
        return asyncio.run(serve(options, links, ready))
