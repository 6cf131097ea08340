"""``ads-rca watch``: a terminal dashboard of the runs on Zenoh, with no ROS at run time.

A Zenoh client session per endpoint (:class:`~ads_rca.remote.client.RemoteLinks`) feeds
every sample into a :class:`~ads_rca.remote.view.DashboardModel`; :func:`render` draws the model's
summary with rich (a pure function: tests render it without a terminal) and ``--json``
prints the model's events as JSON lines instead. It works whenever it is started: before
the run (the session is retried until the peer listens, the subscription waits), during or
after it (the queryables are asked on every connection, and again every few seconds until
anything arrives, since the bridge may come up after the router).

Every string drawn comes from a log through the wire: it is made printable (control
characters and ANSI escapes shown as ``\\x1b``) and only ever put in a ``rich.text.Text``,
never parsed as rich markup. The session is closed on every exit path; a stop signal only
sets a flag the loop checks, so the terminal is restored and nothing is left open.
"""

from __future__ import annotations

import math
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from types import FrameType
from typing import IO, Any

import orjson
from rich.console import Console, Group, RenderableType
from rich.panel import Panel
from rich.rule import Rule
from rich.table import Table
from rich.text import Text

from ads_rca.capabilities import NOT_JUDGED
from ads_rca.diagnosis.conclusion import PARTLY_JUDGED
from ads_rca.diagnosis.summary import count_columns
from ads_rca.foundation.text import printable
from ads_rca.oracles.base import MODULES
from ads_rca.remote.client import CONNECTED, CONNECTING, DISCONNECTED, RemoteLinks
from ads_rca.remote.config import DEFAULT_ENDPOINT
from ads_rca.remote.keys import SAMPLE_SUFFIX, check_prefix
from ads_rca.remote.view import (
    BLAMED,
    FAILING,
    INCOMPLETE,
    INTERNAL_ERROR,
    NO_FAULT_FOUND,
    OK,
    ROOT_CAUSE,
    SKIPPED,
    WAITING,
    DashboardModel,
    key_metric_names,
    read_verdict,
)

#: Exit status when ``--timeout`` passes without a verdict.
EXIT_NO_VERDICT = 3
#: Seconds between catch-up queries while nothing has been received.
CATCH_UP_EVERY_S = 2.0
#: How long one catch-up query waits for its replies (s).
CATCH_UP_TIMEOUT_S = 2.0
#: Seconds between looks at what arrived (and checks of the stop flag).
REFRESH_S = 0.25
#: Seconds between redraws of a screen nothing changed on.
IDLE_REDRAW_S = 1.0
#: Runs drawn at once: the ones updated last (the rest are counted in the header).
RUNS_SHOWN = 4
#: Near-miss warnings drawn per run (the newest).
NEAR_MISSES_SHOWN = 4
#: Longest text drawn from the wire in one cell.
TEXT_LIMIT = 80
#: How the module table names each module state (``view.module_state``), and its style:
#: nothing but a judged, passing result is green.
STATE_LABELS: Mapping[str, tuple[str, str]] = {
    OK: ("OK", "green"),
    FAILING: ("FAILED", "bold red"),
    SKIPPED: ("skipped", "yellow"),
    WAITING: ("no data", "dim"),
    NOT_JUDGED: ("not judged", "yellow"),
    PARTLY_JUDGED: ("partly judged", "yellow"),
    INTERNAL_ERROR: ("INTERNAL ERROR", "bold red"),
    INCOMPLETE: ("incomplete inputs", "yellow"),
    BLAMED: ("ROOT CAUSE", "bold red"),
}
#: The verdict panel's colour for what the verdict says: never green unless conclusive.
VERDICT_STYLES: Mapping[str, str] = {ROOT_CAUSE: "red", NO_FAULT_FOUND: "green"}
#: Reasons listed under an inconclusive verdict (the rest are counted).
REASONS_SHOWN = 6
#: Thresholds named in the verdict panel (the rest are counted).
THRESHOLDS_SHOWN = (
    "safety_margin",
    "window_s",
    "effect_time_window",
    "perc_match_iou",
    "pred_abs_threshold",
    "control_speed_threshold",
)


# ---------------------------------------------------------------------------- drawing


def safe(value: object, limit: int = TEXT_LIMIT) -> str:
    """``value`` as one inert line: numbers short, None as a dash, control characters as
    escapes, at most ``limit`` characters."""
    if value is None:
        text = "—"
    elif isinstance(value, bool):
        text = "yes" if value else "no"
    elif isinstance(value, float):
        text = f"{value:.3g}" if math.isfinite(value) else str(value)
    elif isinstance(value, str | int):
        text = str(value)
    else:  # lists and objects: compact JSON (it came as JSON)
        try:
            text = orjson.dumps(value).decode()
        except TypeError:
            text = repr(value)
    text = printable(text[: limit * 4])
    return text if len(text) <= limit else text[: limit - 1] + "…"


def cell(value: object, style: str = "", limit: int = TEXT_LIMIT) -> Text:
    """A Text of ``value`` made :func:`safe` (a Text is never parsed as markup)."""
    return Text(safe(value, limit), style=style)


def line(*parts: tuple[object, str] | str) -> Text:
    """A line of labels (plain ``str``, ours) and wire values (``(value, style)``, made
    safe)."""
    text = Text()
    for part in parts:
        if isinstance(part, str):
            text.append(part, style="bold")
        else:
            text.append(safe(part[0]), style=part[1])
    return text


@dataclass(frozen=True)
class Header:
    """What the screen says about the watcher itself, beside the model's summary: each
    endpoint's link (``client.Link.describe``), the prefix watched, samples dropped."""

    links: tuple[Mapping[str, Any], ...]
    prefix: str | None = None
    dropped: int = 0


def link_text(link: Mapping[str, Any]) -> str:
    """An endpoint and its state in words: "connected", "connecting (retrying): <why>",
    "not connected (reconnecting): <why>"."""
    state = link.get("state")
    text = f"{link.get('endpoint')} {state}"
    if state != CONNECTED:
        text += " (reconnecting)" if state == DISCONNECTED else " (retrying)"
        if link.get("error"):
            text += f": {link.get('error')}"
    return printable(text)


def render(summary: Mapping[str, Any], header: Header, now: float) -> RenderableType:
    """The whole screen from a :meth:`DashboardModel.summary` (pure: no terminal needed)."""
    runs = summary.get("runs") or []
    problems = int(summary.get("problems") or 0) + header.dropped
    top = Text()
    top.append("ads-rca watch", style="bold")
    top.append(f"  runs {len(runs)}")
    for link in header.links:
        top.append("  ·  ")
        top.append(link_text(link), style="green" if link.get("state") == CONNECTED else "yellow")
    if header.prefix is not None:
        top.append("  ·  prefix ")
        top.append(printable(header.prefix or "(none)"))
    top.append("  ·  problems ")
    top.append(str(problems), style="red" if problems else "")
    parts: list[RenderableType] = [top]
    if summary.get("last_problem"):
        parts.append(line("last problem: ", (summary.get("last_problem"), "red")))
    if not runs:
        parts.append(Text("waiting for a run's results and verdict…", style="dim"))
    newest = sorted(runs, key=lambda run: _number(run.get("updated")), reverse=True)
    if len(runs) > RUNS_SHOWN:
        hidden = len(runs) - RUNS_SHOWN
        parts.append(Text(f"{hidden} older runs not shown (--prefix picks one)", style="dim"))
    for run in sorted(newest[:RUNS_SHOWN], key=lambda run: str(run.get("name"))):
        parts.extend(render_run(run, now))
    return Group(*parts)


def _number(value: object) -> float:
    """A number from the wire for sorting (anything else sorts first)."""
    ok = isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
    return float(value) if ok else -math.inf  # type: ignore[arg-type]


def render_run(run: Mapping[str, Any], now: float) -> list[RenderableType]:
    """One run: its progress, a table of its modules, its near misses, its verdict."""
    name = run.get("run")
    title = Text("run ", style="bold")
    title.append(safe(name) if name else "(no prefix)", style="bold cyan")
    if run.get("run_id"):
        title.append(" · id ", style="bold")
        title.append(safe(run.get("run_id")), style="cyan")
    parts: list[RenderableType] = [Rule(title, align="left")]
    parts.append(progress_line(run, now))
    parts.append(module_table(run.get("modules") or {}))
    parts.extend(near_miss_lines(run.get("near_misses") or []))
    verdict = run.get("verdict")
    if isinstance(verdict, Mapping):
        parts.append(verdict_panel(verdict))
    else:
        parts.append(Text("verdict: not yet", style="dim"))
    return parts


def progress_line(run: Mapping[str, Any], now: float) -> Text:
    """Frame, index, rate and the bridge's heartbeat."""
    text = line(
        "frame ",
        (run.get("last_frame"), "cyan"),
        "  index ",
        (run.get("last_index"), ""),
        "  rate ",
    )
    rate = run.get("rate")
    text.append(f"{rate:.1f} frames/s" if isinstance(rate, int | float) else "—")
    status = run.get("status")
    text.append("  ·  status ", style="bold")
    if not isinstance(status, Mapping):
        text.append("no heartbeat yet", style="dim")
        return text
    state = status.get("state")
    text.append(safe(state), style="green" if state == "verdict" else "yellow")
    stamp = status.get("time")
    if isinstance(stamp, int | float) and not isinstance(stamp, bool) and math.isfinite(stamp):
        age = now - stamp
        if 0 <= age < 1e6:
            text.append(f" ({age:.1f} s ago)", style="dim")
    malformed = status.get("malformed")
    if isinstance(malformed, int) and not isinstance(malformed, bool) and malformed:
        text.append(f"  · bridge dropped {malformed} malformed", style="red")
    return text


def module_status(entry: Mapping[str, Any]) -> Text:
    """The module's state; "(provisional)" while its latest result was judged before the
    collision partner was known."""
    label, style = STATE_LABELS.get(str(entry.get("state")), STATE_LABELS[WAITING])
    if entry.get("provisional") is True:
        label += " (provisional)"
    return Text(label, style=style)


def key_metrics(module: str, latest: Mapping[str, Any]) -> Text:
    """A few plain metrics of the latest result (the skip reason when it was skipped)."""
    if latest.get("skipped"):
        return cell(latest.get("skipped"), "yellow")
    metrics = latest.get("metrics")
    if not isinstance(metrics, Mapping):
        return Text("")
    text = Text()
    for name in key_metric_names(module, metrics):
        if text:
            text.append("  ")
        text.append(safe(name, 30), style="dim")
        text.append(" ")
        text.append(safe(metrics.get(name), 20))
    return text


def module_table(modules: Mapping[str, Any]) -> Table:
    table = Table(box=None, pad_edge=False, header_style="bold", expand=False)
    for heading, justify in (
        ("module", "left"),
        ("status", "left"),
        ("judged", "right"),
        ("failed", "right"),
        ("latest", "right"),
        ("key metrics of the latest result", "left"),
    ):
        table.add_column(heading, justify=justify)  # type: ignore[arg-type]
    for module in MODULES:
        entry = modules.get(module)
        entry = entry if isinstance(entry, Mapping) else {}
        latest = entry.get("latest")
        latest = latest if isinstance(latest, Mapping) else {}
        failed = entry.get("failed_frames")
        table.add_row(
            Text(module),
            module_status(entry),
            cell(entry.get("judged", 0)),
            cell(failed, "red" if failed else ""),
            cell(latest.get("frame")) if latest else Text("—"),
            module_detail(module, entry, latest),
        )
    return table


def module_detail(module: str, entry: Mapping[str, Any], latest: Mapping[str, Any]) -> Text:
    """Why a module is not judged, partly judged or raised (the verdict's words, else its
    latest result's); otherwise the latest result's key metrics."""
    detail = entry.get("detail")
    if detail and entry.get("state") in (NOT_JUDGED, PARTLY_JUDGED, INTERNAL_ERROR):
        return cell(detail, STATE_LABELS[str(entry["state"])][1], limit=2 * TEXT_LIMIT)
    return key_metrics(module, latest) if latest else Text("")


def near_miss_lines(near_misses: Sequence[Any]) -> list[Text]:
    shown = [n for n in near_misses if isinstance(n, Mapping)][-NEAR_MISSES_SHOWN:]
    if not shown:
        return []
    heading = Text(f"near misses: {len(near_misses)} (newest {len(shown)})", style="bold yellow")
    return [heading] + [
        line(
            "  ⚠ frame ",
            (near.get("frame"), "yellow"),
            ": ",
            (near.get("module"), ""),
            " clearance ",
            (near.get("clearance"), "yellow"),
            " m < margin ",
            (near.get("margin"), ""),
            " m",
        )
        for near in shown
    ]


def verdict_panel(verdict: Mapping[str, Any]) -> Panel:
    """The verdict: what it concludes (or why it cannot: docs/verdicts.md), its cause,
    basis, collision, partner and the semantics mode it came from (named in the title and
    beside its thresholds)."""
    semantics = verdict.get("semantics")
    primary = verdict.get("primary_root_cause")
    reading = read_verdict(verdict)
    style = VERDICT_STYLES.get(reading.kind, "yellow")
    contributing = verdict.get("contributing")
    if isinstance(contributing, list):
        contributing_text = ", ".join(safe(c, 40) for c in contributing) or "none"
    else:
        contributing_text = safe(contributing)
    body: list[Text] = [
        labelled("verdict: ", cell(reading.text, f"bold {style}", 3 * TEXT_LIMIT)),
        conclusive_line(reading.conclusive, reading.stated),
        *(
            labelled("  · ", cell(reason, "yellow", 2 * TEXT_LIMIT))
            for reason in reading.reasons[:REASONS_SHOWN]
        ),
        *(
            [Text(f"  (+{len(reading.reasons) - REASONS_SHOWN} more)", style="dim")]
            if len(reading.reasons) > REASONS_SHOWN
            else []
        ),
        line("primary root cause: ", (primary if primary else "none", "bold red")),
        line("contributing: ", (contributing_text, "")),
        line("attribution basis: ", (verdict.get("attribution_basis"), "")),
        line(
            "collision: ",
            (reading.collision, "yellow" if reading.collision == "unknown" else ""),
            "   collision frame: ",
            (verdict.get("collision_frame"), ""),
            "   partner: ",
            (verdict.get("partner_id"), "cyan"),
            "   ego: ",
            (verdict.get("ego_id"), ""),
        ),
    ]
    if verdict.get("reason") is not None:
        body.append(line("reason: ", (verdict.get("reason"), "yellow")))
    body.append(counts_line(verdict))
    body.append(thresholds_line(verdict))
    live = verdict.get("live")
    if isinstance(live, Mapping):
        complete = live.get("complete") is True
        why = live.get("why_incomplete")
        body.append(
            line(
                "live: ",
                ("complete" if complete else "incomplete", "green" if complete else "yellow"),
                *((("  ", ""), (why, "yellow")) if why and not complete else ()),
            )
        )
    title = Text("verdict · ", style="bold")
    title.append(f"{safe(semantics, 30)} semantics", style="bold magenta")
    return Panel(Group(*body), title=title, title_align="left", border_style=style, expand=False)


def labelled(label: str, value: Text) -> Text:
    """Our bold label, then a wire value already made safe (:func:`cell`)."""
    text = Text(label, style="bold")
    text.append_text(value)
    return text


def conclusive_line(conclusive: bool, stated: bool) -> Text:
    if conclusive:
        return line("conclusive: ", ("yes", "green"))
    return line("conclusive: ", ("no" if stated else "not stated: read as no", "bold yellow"))


def counts_line(verdict: Mapping[str, Any]) -> Text:
    """Per module, the window's two counts under the mode's own names."""
    (counted, other), _legend = count_columns(verdict.get("semantics"))
    text = Text(f"{counted}/{other}: ", style="bold")
    modules = verdict.get("modules")
    modules = modules if isinstance(modules, Mapping) else {}
    for module in MODULES:
        counts = modules.get(module)
        counts = counts if isinstance(counts, Mapping) else {}
        if module != MODULES[0]:
            text.append("  ·  ")
        text.append(f"{module} ")
        text.append(f"{safe(counts.get('collision'), 12)}/{safe(counts.get('safe'), 12)}")
    return text


def thresholds_line(verdict: Mapping[str, Any]) -> Text:
    thresholds = verdict.get("thresholds")
    text = line("thresholds (", (verdict.get("semantics"), "magenta"), "): ")
    if not isinstance(thresholds, Mapping):
        text.append("—")
        return text
    named = [name for name in THRESHOLDS_SHOWN if name in thresholds]
    text.append("  ".join(f"{name} {safe(thresholds[name], 16)}" for name in named))
    others = len(thresholds) - len(named)
    if others > 0:
        text.append(f"  (+{others} more)", style="dim")
    return text


# ------------------------------------------------------------------------- the loop


class Watcher:
    """The sessions (one per endpoint: opened, retried, caught up) and the model they feed."""

    def __init__(
        self,
        connect: Sequence[str] = (DEFAULT_ENDPOINT,),
        prefix: str | None = None,
        allow_remote: bool = False,
        clock: Callable[[], float] = time.time,
    ) -> None:
        self.prefix = None if prefix is None else check_prefix(prefix)
        # Checks the endpoints and the prefix now (ConfigError: one line, exit 2).
        self.links = RemoteLinks(
            connect, self.prefix, "client", allow_remote, CATCH_UP_TIMEOUT_S, wall=clock
        )
        self.endpoints = self.links.endpoints
        self.model = DashboardModel(self.prefix)
        self.clock = clock
        self.received = 0
        self.verdicts = 0
        self._started = False
        self._next_catch_up = 0.0
        #: When a live verdict asked for a catch-up (0: none), and when the last finished one
        #: began: the bridge rate-limits each module's live samples, so the frames in
        #: between are fetched from its history once the verdict is in, before the final
        #: counts.
        self._verdict_catch_up = 0.0
        #: The begin time of the last finished catch-up whose replies were all drained.
        self._drained_through = 0.0

    def connection(self) -> str:
        """Each endpoint and its state, in words."""
        return "; ".join(link_text(state) for state in self.links.states())

    def header(self) -> Header:
        return Header(tuple(self.links.states()), self.prefix, self.links.dropped)

    def step(self) -> list[dict[str, Any]]:
        """Apply what arrived (the links' thread opens, reopens and catches up), and ask
        for a catch-up every few seconds until anything arrives (the bridge may join the
        router after ``watch`` does): the model's events, oldest first."""
        if not self._started:
            self._started = True
            self.links.start()
        tick = time.monotonic()
        # Read before draining: the links' thread queues a catch-up's replies, then says
        # when that query began, so every reply of a query begun by then is drained below.
        finished = self.links.caught_up
        if self.links.any_connected() and not self.received and tick >= self._next_catch_up:
            self._request_catch_up(tick)
        events = []
        for key, payload in self.links.drain():
            self.received += 1
            event = self.model.apply(key, payload, self.clock())
            if event is not None:
                events.append(event)
                self.verdicts += event["kind"] == "verdict"
                if event["kind"] == "verdict" and key.endswith(SAMPLE_SUFFIX):
                    self._verdict_catch_up = tick
                    self._request_catch_up(tick)
        self._drained_through = finished
        return events

    def settled(self) -> bool:
        """The catch-up a live verdict asked for has run and its replies were drained (or
        it timed out): a query begun before the verdict, or replies still queued, do not
        count (under load the final digest once counted 2 of 103 frames)."""
        asked = self._verdict_catch_up
        return (
            asked == 0.0
            or self._drained_through >= asked
            or time.monotonic() - asked > 3 * CATCH_UP_TIMEOUT_S + 1.0
        )

    def _request_catch_up(self, tick: float) -> None:
        self._next_catch_up = tick + CATCH_UP_EVERY_S
        self.links.request_catch_up()

    def close(self) -> None:
        """Stop the links' thread and close every session (safe to call twice)."""
        self.links.close()

    def screen(self) -> RenderableType:
        now = self.clock()
        return render(self.model.summary(now), self.header(), now)

    def final_event(self, name: str) -> dict[str, Any] | None:
        """A run's digest once its verdict is in: the cause, the mode and the counts."""
        view = self.model.runs.get(name)
        if view is None or view.verdict is None:
            return None
        summary = view.summary(self.clock())
        verdict = view.verdict
        reading = read_verdict(verdict)
        return {
            "run": view.prefix,
            "run_id": view.run_id,
            "name": view.name,
            "kind": "final",
            "semantics": verdict.get("semantics"),
            "verdict": reading.text,
            "conclusive": reading.conclusive,
            "why_inconclusive": list(reading.reasons),
            "collision": reading.collision,
            "primary_root_cause": verdict.get("primary_root_cause"),
            "contributing": verdict.get("contributing"),
            "attribution_basis": verdict.get("attribution_basis"),
            "collision_frame": verdict.get("collision_frame"),
            "partner_id": verdict.get("partner_id"),
            "last_index": summary["last_index"],
            "last_frame": summary["last_frame"],
            "modules": {
                m: {"judged": e["judged"], "failed_frames": e["failed_frames"], "state": e["state"]}
                for m, e in summary["modules"].items()
            },
            "near_misses": len(summary["near_misses"]),
            "problems": self.model.problems,
        }


class StopSignals:
    """SIGINT and SIGTERM set a flag the loop checks (so the terminal is restored and the
    session closed in order); a second signal raises KeyboardInterrupt."""

    def __init__(self) -> None:
        self.signum = 0
        self.event = threading.Event()

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        if self.signum:
            raise KeyboardInterrupt
        self.signum = signum
        self.event.set()

    @contextmanager
    def installed(self) -> Iterator[StopSignals]:
        if threading.current_thread() is not threading.main_thread():
            yield self  # only the main thread may handle signals
            return
        previous = {s: signal.signal(s, self._handle) for s in (signal.SIGINT, signal.SIGTERM)}
        try:
            yield self
        finally:
            for sig, handler in previous.items():
                signal.signal(sig, handler)

    def wait(self, seconds: float) -> None:
        self.event.wait(seconds)


@dataclass(frozen=True)
class WatchOptions:
    connect: tuple[str, ...] = (DEFAULT_ENDPOINT,)
    prefix: str | None = None
    allow_remote: bool = False
    json: bool = False
    exit_on_verdict: bool = False
    timeout: float | None = None


def watch(options: WatchOptions, out: IO[bytes] | None = None) -> int:
    """Run the dashboard until a stop signal, the verdict (``exit_on_verdict``) or the
    timeout; the exit status (0, :data:`EXIT_NO_VERDICT`, or 128 + the signal)."""
    watcher = Watcher(options.connect, options.prefix, options.allow_remote)
    stop = StopSignals()
    with stop.installed():
        try:
            if options.json:
                code = _json_loop(watcher, options, stop, out or sys.stdout.buffer)
            else:
                code = _screen_loop(watcher, options, stop)
        finally:
            watcher.close()
    if stop.signum:
        return 128 + stop.signum
    if code == EXIT_NO_VERDICT:
        where = watcher.connection()
        print(
            f"ads-rca watch: no verdict within {options.timeout:g} s "
            f"({', '.join(watcher.endpoints)}: {where})",
            file=sys.stderr,
        )
    return code


def _done(watcher: Watcher, options: WatchOptions, stop: StopSignals, deadline: float) -> bool:
    if stop.signum:
        return True
    if options.exit_on_verdict and watcher.verdicts and watcher.settled():
        return True
    return time.monotonic() >= deadline


def _code(watcher: Watcher) -> int:
    return 0 if watcher.verdicts else EXIT_NO_VERDICT


def _deadline(options: WatchOptions) -> float:
    return math.inf if options.timeout is None else time.monotonic() + options.timeout


def _json_loop(watcher: Watcher, options: WatchOptions, stop: StopSignals, out: IO[bytes]) -> int:
    """One strict JSON line per event, flushed each; after a run's (new) verdict, its
    ``final`` digest. A verdict delivered twice (subscription and catch-up) prints once.
    While the peer is not up, one note on stderr says so."""
    deadline = _deadline(options)
    printed: dict[str, Any] = {}
    finals: list[str] = []  # runs whose final digest waits for the verdict's catch-up
    noted: dict[str, str] = {}  # each endpoint's state as said on stderr
    while True:
        events = watcher.step()
        for link in watcher.header().links:
            _note_link(link, noted)
        for event in events:
            if event["kind"] == "verdict":
                if printed.get(event["name"]) == event["verdict"]:
                    continue
                printed[event["name"]] = event["verdict"]
                _write(out, event)
                finals.append(event["name"])
            else:
                _write(out, event)
        done = _done(watcher, options, stop, deadline)
        if finals and (watcher.settled() or done):
            for name in dict.fromkeys(finals):
                final = watcher.final_event(name)
                if final is not None:
                    _write(out, final)
            finals.clear()
        if done:
            return _code(watcher)
        stop.wait(REFRESH_S)


def _note_link(link: Mapping[str, Any], noted: dict[str, str]) -> None:
    """On stderr (stdout holds JSON only): an endpoint that does not answer yet, once, with
    why; then each change of its state."""
    endpoint, state = str(link.get("endpoint")), str(link.get("state"))
    said = noted.get(endpoint)
    if state == CONNECTING and (said is not None or not link.get("error")):
        return
    if said != state:
        noted[endpoint] = state
        waiting = "waiting: " if state == CONNECTING else ""
        print(f"ads-rca watch: {waiting}{link_text(link)}", file=sys.stderr, flush=True)


def _write(out: IO[bytes], event: Mapping[str, Any]) -> None:
    out.write(orjson.dumps(event) + b"\n")
    out.flush()


def _screen_loop(watcher: Watcher, options: WatchOptions, stop: StopSignals) -> int:
    """The live screen, redrawn a few times a second; once a verdict made it stop, the
    last screen is printed again on the normal screen, so it stays in the terminal."""
    from rich.live import Live

    console = Console()
    deadline = _deadline(options)
    drawn_at, drawn_links = -math.inf, None
    with Live(
        console=console,
        screen=console.is_terminal,
        auto_refresh=False,
        redirect_stdout=False,
        redirect_stderr=False,
    ) as live:
        while True:
            events = watcher.step()
            links = watcher.header().links
            tick = time.monotonic()
            # Drawn when something came or a link changed, else once a second (ages and
            # rates move): drawing every check was 7 % of a core for an idle screen.
            if events or links != drawn_links or tick - drawn_at >= IDLE_REDRAW_S:
                screen = watcher.screen()
                live.update(screen, refresh=True)
                drawn_at, drawn_links = tick, links
            if _done(watcher, options, stop, deadline):
                break
            stop.wait(REFRESH_S)
    if watcher.verdicts and not stop.signum and console.is_terminal:
        console.print(watcher.screen())
    return _code(watcher)
