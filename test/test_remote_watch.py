"""``ads-rca watch``: a terminal dashboard over Zenoh, no ROS at run time.

Real parts only: test/remote_feed.py plays ``examples/cut_in_perception`` through the
simulated live graph and puts every result and the verdict on Zenoh as a loopback peer, in
its own process; ``watch`` runs in a real terminal (a tmux server on a private socket) and
its screen is read back with ``capture-pane``. Hostile documents come from a Zenoh peer in
this process answering on the dashboard keys.
"""

from __future__ import annotations

import contextlib
import io
import itertools
import json
import os
import queue
import re
import shlex
import shutil
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from loopback import free_port
from unsure_run import unsure_copy

from ads_rca.remote.config import session_config
from ads_rca.remote.session import close_session
from ads_rca.remote.view import DashboardModel
from ads_rca.remote.watch import Header, render, safe

pytestmark = pytest.mark.timeout(90)

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "examples" / "cut_in_perception"
TMUX = shutil.which("tmux") or "/usr/bin/tmux"
_COUNTER = itertools.count(1)

#: A verdict, a result and a status written to break a terminal or rich's markup.
HOSTILE_PREFIX = "[red]x[/red]"
HOSTILE_VERDICT = {
    "primary_root_cause": "perception",
    "semantics": "[blink]corrected\x1b[5m",
    "reason": "[bold red]pwned[/] \x1b[2J",
    "partner_id": "\x1b]0;owned\x07[red]x[/red]",
    "attribution_basis": "line1\nline2",
    "contributing": ["[link=http://e.vil]x[/link]"],
    # collision_frame ":warning:" or modules "nonsense": the verdict is dropped (test_remote_view)
    "collision_frame": 81,
    "modules": {"perception": {"[b]why[/b]": "\x1b[2J"}},
    "thresholds": {"safety_margin": "\x1b[31m"},
}
HOSTILE_RESULT = {
    "index": 0,
    "frame": "\x1b[2J[red]f[/red]",
    "failed": True,
    "metrics": {"[b]m[/b]": "\x1b[31mred", "recall": "[i]x"},
}
HOSTILE_STATUS = {"state": "\x1b[2J[green]ok", "time": "soon", "malformed": 3}


def _env() -> dict[str, str]:
    """This checkout's ads_rca first; no tmux of the caller's to nest in."""
    env = {k: v for k, v in os.environ.items() if k not in ("TMUX", "TMUX_PANE")}
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(REPO), env.get("PYTHONPATH")) if p)
    return env


def watch_command(*args: str) -> list[str]:
    return [sys.executable, "-m", "ads_rca.cli", "watch", *args]


def _wait(predicate: Callable[[], bool], timeout: float, what: Callable[[], str]) -> None:
    end = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > end:
            pytest.fail(f"timed out waiting: {what()}")
        time.sleep(0.1)


class Feed:
    """test/remote_feed.py in its own process; its READY / VERDICT lines read on a thread."""

    def __init__(self, endpoint: str, *extra: str, log: Path = EXAMPLE) -> None:
        self.process = subprocess.Popen(
            [
                *(sys.executable, str(REPO / "test" / "remote_feed.py"), str(log)),
                *("--listen", endpoint, "--prefix", "car1", "--hold", "60", *extra),
            ],
            stdout=subprocess.PIPE,
            text=True,
            env=_env(),
            cwd=REPO,
        )
        self.lines: queue.Queue[str] = queue.Queue()
        self.seen: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.process.stdout is not None
        for text in self.process.stdout:
            self.lines.put(text.strip())

    def expect(self, word: str, timeout: float = 30.0) -> None:
        end = time.monotonic() + timeout
        while word not in self.seen:
            try:
                self.seen.append(self.lines.get(timeout=max(0.0, end - time.monotonic())))
            except queue.Empty:
                pytest.fail(f"remote_feed printed {self.seen}, not {word}")

    def stop(self) -> None:
        self.process.terminate()
        try:
            self.process.wait(10)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()


@contextmanager
def feed(endpoint: str, *extra: str, log: Path = EXAMPLE) -> Iterator[Feed]:
    running = Feed(endpoint, *extra, log=log)
    try:
        yield running
    finally:
        running.stop()


def spawn_watch(*args: str) -> subprocess.Popen[str]:
    """``ads-rca watch ARGS`` with its output on pipes (no terminal)."""
    return subprocess.Popen(
        watch_command(*args),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=_env(),
        cwd=REPO,
    )


class Terminal:
    """A command in a real terminal: a detached tmux session on a private server. The shell
    prints ``EXIT:<status>`` after it and keeps the pane open."""

    def __init__(self, command: list[str], width: int = 150, height: int = 50) -> None:
        if not Path(TMUX).exists():
            pytest.skip("no tmux on this machine: the terminal tests need one")
        self.socket = f"ads_rca_watch_{os.getpid()}_{next(_COUNTER)}"
        shell = f'{shlex.join(command)}; echo "EXIT:$?"; sleep 600'
        self._tmux("new-session", "-d", "-x", str(width), "-y", str(height), "-s", "watch", shell)
        self.started = time.monotonic()

    def _tmux(self, *args: str) -> str:
        done = subprocess.run(
            [TMUX, "-L", self.socket, "-f", "/dev/null", *args],
            capture_output=True,
            text=True,
            env=_env(),
            cwd=REPO,
            check=True,
            timeout=10,
        )
        return done.stdout

    def screen(self, colours: bool = False) -> str:
        """What the pane shows, scrollback included, wrapped lines joined (``colours``:
        with its SGR escapes)."""
        escapes = ("-e",) if colours else ()
        return self._tmux("capture-pane", "-p", "-J", *escapes, "-S", "-", "-t", "watch")

    def wait_for(self, *texts: str, timeout: float = 30.0) -> str:
        _wait(lambda: all(t in self.screen() for t in texts), timeout, self.screen)
        return self.screen()

    def exit_status(self, timeout: float = 30.0) -> int:
        found = re.search(r"EXIT:(\d+)", self.wait_for("EXIT:", timeout=timeout))
        assert found is not None
        return int(found.group(1))

    def keys(self, *keys: str) -> None:
        self._tmux("send-keys", "-t", "watch", *keys)

    def close(self) -> None:
        subprocess.run([TMUX, "-L", self.socket, "kill-server"], capture_output=True, check=False)


@contextmanager
def terminal(command: list[str]) -> Iterator[Terminal]:
    if not Path(TMUX).exists():
        pytest.skip("tmux is not installed")
    term = Terminal(command)
    try:
        yield term
    finally:
        term.close()


def module_rows(screen: str) -> dict[str, tuple[str, int, int]]:
    """``module → (status, judged, failed)`` from the screen's module table."""
    rows = re.findall(
        r"^(perception|prediction|planning|controller)\s+"
        r"(OK|FAILED|ROOT CAUSE|skipped|no data)\s+"
        r"(\d+)\s+(\d+)",
        screen,
        re.MULTILINE,
    )
    return {m: (status, int(judged), int(failed)) for m, status, judged, failed in rows}


def expected_run() -> tuple[str, dict[str, set[int]]]:
    """What the feed puts, computed here the way it does: the verdict's primary root
    cause and each module's judged frame indices."""
    from ads_rca.live.simulate import run_live
    from ads_rca.params import make_params
    from ads_rca.sources.log.reader import read_run_log

    run = run_live(read_run_log(EXAMPLE), make_params("corrected"))
    assert run.outcome is not None
    indices = {str(m): {r.index for r in results} for m, results in run.results.items()}
    return str(run.outcome.document["primary_root_cause"]), indices


def test_watch_started_before_the_feed_shows_the_modules_and_the_verdict() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    command = watch_command("--connect", endpoint, "--exit-on-verdict", "--timeout", "60")
    with terminal(command) as term:
        term.wait_for("connecting")  # no peer yet: the watch waits and retries
        with feed(endpoint, "--pace", "0.002"):
            status = term.exit_status()
        screen = term.screen()
    assert status == 0, screen
    assert "Traceback" not in screen
    assert "primary root cause: perception" in screen
    assert "verdict · corrected semantics" in screen
    assert "thresholds (corrected)" in screen
    assert "partner: 2486" in screen and "collision frame: 81" in screen
    rows = module_rows(screen)
    assert set(rows) == {"perception", "prediction", "planning", "controller"}, screen
    assert rows["perception"] == ("ROOT CAUSE", 81, 13)
    assert all(judged == 81 for _, judged, _ in rows.values())
    assert "near misses: 13" in screen


def test_watch_started_after_the_verdict_catches_up_and_ctrl_c_exits_130() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with feed(endpoint) as running:
        running.expect("VERDICT")
        with terminal(watch_command("--connect", endpoint)) as term:
            screen = term.wait_for("primary root cause: perception", "status verdict")
            # The verdict's root cause, its latest frame ok: never shown "OK".
            assert module_rows(screen)["perception"] == ("ROOT CAUSE", 81, 13)
            assert "EXIT:" not in screen  # the live screen, not the final print
            pressed = time.monotonic()
            term.keys("C-c")
            status = term.exit_status(timeout=10)
            took = time.monotonic() - pressed
            after = term.screen()
    assert status == 130, after
    assert took < 5.0
    assert "Traceback" not in after and "KeyboardInterrupt" not in after


def test_an_inconclusive_verdict_shows_as_inconclusive_with_its_reasons(tmp_path: Path) -> None:
    """docs/verdicts.md: never green, never "no fault found"; the module that was not
    judged and the unknown collision shown as such, on the screen and in ``--json``."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with feed(endpoint, log=unsure_copy(tmp_path / "unsure")) as running:
        running.expect("VERDICT")
        command = watch_command("--connect", endpoint, "--exit-on-verdict", "--timeout", "60")
        with terminal(command) as term:
            status = term.exit_status()
            screen, coloured = term.screen(), term.screen(colours=True)
        watcher = spawn_watch(*command[4:], "--json")
        out, err = watcher.communicate(timeout=60)
    assert status == 0 and watcher.returncode == 0, (screen, err)
    assert "verdict: inconclusive: collision unknown (metadata.json gives no usable" in screen
    assert "conclusive: no" in screen
    assert "· perception not judged (no detections_2d)" in screen
    assert "collision: unknown   collision frame: -1" in screen
    assert "no fault found" not in screen and "Traceback" not in screen
    assert re.search(r"^perception\s+not judged\s+81\s+0\s+81\s+not judged \(no", screen, re.M)
    (verdict_line,) = [t for t in coloured.splitlines() if "inconclusive: collision" in t]
    assert verdict_line.count("33m") >= 2, repr(verdict_line)  # the sentence in yellow, its
    assert "32m" not in verdict_line, repr(verdict_line)  # border too; no green
    events = [_strict(text) for text in out.splitlines()]
    (verdict,) = [e for e in events if e["kind"] == "verdict"]
    (final,) = [e for e in events if e["kind"] == "final"]
    assert verdict["conclusive"] is False and verdict["verdict"]["conclusive"] is False
    assert final["conclusive"] is False and final["collision"] == "unknown"
    assert final["verdict"] == verdict["verdict"]["verdict"]
    assert final["why_inconclusive"] == [
        "collision unknown (metadata.json gives no usable collision_frame)",
        "perception not judged (no detections_2d)",
    ]
    assert final["modules"]["perception"]["state"] == "not judged"
    assert final["modules"]["planning"]["state"] == "ok"


def _strict(text: str) -> Any:
    def refuse(constant: str) -> None:
        raise ValueError(f"not strict JSON: {constant}")

    return json.loads(text, parse_constant=refuse)


def test_json_lines_carry_every_frame_and_the_feeds_verdict() -> None:
    primary, indices = expected_run()
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    args = ("--connect", endpoint, "--prefix", "car1", "--json", "--exit-on-verdict")
    watcher = spawn_watch(*args, "--timeout", "60")
    try:
        assert watcher.stderr is not None
        assert "waiting" in watcher.stderr.readline()  # started before the feed
        # The feed waits before its first result so the watch has connected by then
        # (checked below: the first status it saw had no frame yet).
        with feed(endpoint, "--start-after", "2.0"):
            out, err = watcher.communicate(timeout=60)
    finally:
        if watcher.poll() is None:
            watcher.kill()
            watcher.communicate()
    assert watcher.returncode == 0, err
    events = [_strict(text) for text in out.splitlines()]
    assert events and all(e["run"] == "car1" for e in events)
    statuses = [e["status"] for e in events if e["kind"] == "status"]
    assert statuses and statuses[0]["last_index"] == -1, "connected after the first result"
    seen: dict[str, set[int]] = {}
    for event in events:
        if event["kind"] == "module":
            seen.setdefault(event["module"], set()).add(event["result"]["index"])
    assert seen == indices
    verdicts = [e["verdict"] for e in events if e["kind"] == "verdict"]
    assert len(verdicts) == 1 and verdicts[0]["primary_root_cause"] == primary == "perception"
    assert len(verdicts[0]["frames"]) == len(indices["perception"])
    (final,) = [e for e in events if e["kind"] == "final"]
    assert final["primary_root_cause"] == primary and final["semantics"] == "corrected"
    assert {m: v["judged"] for m, v in final["modules"].items()} == {
        m: len(i) for m, i in indices.items()
    }


def _answer(key: str, text: str) -> Callable[[Any], None]:
    """A queryable's callback replying ``text`` on ``key``."""
    return lambda query: query.reply(key, text)


@contextmanager
def hostile_peer(endpoint: str) -> Iterator[None]:
    """A Zenoh peer answering the dashboard queries with hostile documents."""
    import zenoh

    prefix = f"{HOSTILE_PREFIX}/ads_rca"
    answers = {
        f"{prefix}/verdict": HOSTILE_VERDICT,
        f"{prefix}/status": HOSTILE_STATUS,
        f"{prefix}/frames": {"frames": [{"modules": {"perception": HOSTILE_RESULT}}]},
    }
    session = zenoh.open(zenoh.Config.from_json5(session_config("peer", [endpoint])))
    declared: list[Any] = []
    try:
        for key, document in answers.items():
            declared.append(session.declare_queryable(key, _answer(key, json.dumps(document))))
        yield
    finally:
        close_session(session, declared)


def test_hostile_strings_from_the_wire_show_literally_and_inertly() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with hostile_peer(endpoint):
        command = watch_command("--connect", endpoint, "--exit-on-verdict", "--timeout", "30")
        with terminal(command) as term:
            status = term.exit_status()
            screen = term.screen()
    assert status == 0, screen
    assert r"[bold red]pwned[/] \x1b[2J" in screen
    assert f"run {HOSTILE_PREFIX}" in screen
    assert r"\x1b]0;owned\x07[red]x[/red]" in screen
    assert r"line1\x0aline2" in screen
    assert "[link=http://e.vil]x[/link]" in screen
    assert r"[blink]corrected\x1b[5m semantics" in screen
    assert r"\x1b[2J[red]f[/red]" in screen  # the result's frame
    assert module_rows(screen)["perception"] == ("ROOT CAUSE", 1, 1)  # the verdict blames it


def test_render_is_a_pure_function_whose_wire_text_is_inert() -> None:
    from rich.console import Console

    model = DashboardModel()
    base = f"{HOSTILE_PREFIX}/ads_rca"
    assert model.apply(f"{base}/modules/perception.json", json.dumps(HOSTILE_RESULT), 1.0)
    assert model.apply(f"{base}/status", json.dumps(HOSTILE_STATUS), 1.0)
    assert model.apply(f"{base}/verdict", json.dumps(HOSTILE_VERDICT), 1.0)
    model.apply("\x1b[2J/ads_rca/verdict", b"[red]not json", 1.0)  # counted, shown escaped
    header = Header(({"endpoint": "tcp/127.0.0.1:7447", "state": "connected"},))
    screen = render(model.summary(2.0), header, 2.0)
    coloured, plain = io.StringIO(), io.StringIO()
    Console(file=coloured, force_terminal=True, color_system="truecolor", width=140).print(screen)
    Console(file=plain, width=140).print(screen)
    for raw in ("\x1b[2J", "\x1b]0;", "\x07", "\x1b[5m", "\n\nline2", "\x1b[31mred"):
        assert raw not in coloured.getvalue()
    out = plain.getvalue()
    assert "\x1b" not in out
    assert r"[bold red]pwned[/] \x1b[2J" in out and "problems 1" in out
    assert r"last problem: \x1b[2J/ads_rca/verdict" in out
    assert safe("\x1b[2J" * 100).startswith(r"\x1b[2J") and len(safe("x" * 1000)) == 80
    assert safe(None) == "—" and safe(0.123456) == "0.123" and safe(True) == "yes"


def test_render_before_anything_arrived() -> None:
    from rich.console import Console

    buffer = io.StringIO()
    link = {"endpoint": "tcp/127.0.0.1:7447", "state": "connecting", "error": "\x1b[2Jno"}
    header = Header((link,), prefix="car1")
    Console(file=buffer, width=100).print(render(DashboardModel().summary(0.0), header, 0.0))
    assert "runs 0" in buffer.getvalue() and "waiting for a run" in buffer.getvalue()
    assert "tcp/127.0.0.1:7447 connecting (retrying): \\x1b[2Jno" in buffer.getvalue()


_JSON = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | st.text(),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(), inner, max_size=4),
    max_leaves=12,
)
_FIELDS = st.sampled_from(
    [
        "index",
        "frame",
        "failed",
        "skipped",
        "metrics",
        "thresholds",
        "semantics",
        "modules",
        "contributing",
        "live",
        "state",
        "time",
        "malformed",
        "collision_frame",
        "reason",
        "partner_id",
        "attribution_basis",
        "verdict",
        "conclusive",
        "why_inconclusive",
        "collision",
        "internal_errors",
        "modules_judged",
        "internal_error",
        "missing_input",
    ]
)


@settings(max_examples=60, deadline=None)
@given(
    result=st.dictionaries(_FIELDS | st.text(), _JSON, max_size=6),
    verdict=st.dictionaries(_FIELDS | st.text(), _JSON, max_size=8),
    status=st.dictionaries(_FIELDS | st.text(), _JSON, max_size=5),
    clearance=st.floats(-5, 5),
)
def test_render_survives_any_document_shape(
    result: dict[str, Any], verdict: dict[str, Any], status: dict[str, Any], clearance: float
) -> None:
    """Whatever JSON the wire carries, the screen is drawn, and without a control byte."""
    from rich.console import Console

    model = DashboardModel()
    planning = {**result, "index": 3, "metrics": {"c_gt": clearance}}
    model.apply("r/ads_rca/modules/planning.json", json.dumps(planning), 1.0)
    model.apply("r/ads_rca/modules/perception.json", json.dumps({**result, "index": 1}), 1.0)
    model.apply("r/ads_rca/status", json.dumps(status), 1.0)
    model.apply("r/ads_rca/verdict", json.dumps({**verdict, "primary_root_cause": None}), 1.0)
    buffer = io.StringIO()
    header = Header(({"endpoint": "tcp/127.0.0.1:7447", "state": "connected"},))
    Console(file=buffer, width=120).print(render(model.summary(2.0), header, 2.0))
    assert not re.search("[\x00-\x09\x0b-\x1f\x7f-\x9f]", buffer.getvalue())


@pytest.mark.parametrize(
    "args",
    [
        ["--connect", "tcp/nope"],
        ["--connect", "tcp/10.0.0.5:7447"],
        ["--connect", "tcp/127.0.0.1:0"],
        ["--prefix", "car/*"],
        ["--prefix", "a\x1b[2Jb"],
        ["--timeout", "-1"],
        ["--timeout", "nan"],
    ],
)
def test_bad_values_are_one_line_and_exit_2(args: list[str]) -> None:
    done = subprocess.run(
        watch_command(*args),
        capture_output=True,
        text=True,
        env=_env(),
        cwd=REPO,
        timeout=30,
        check=False,
    )
    assert done.returncode == 2
    assert done.stdout == ""
    lines = done.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("ads-rca watch: error: "), done.stderr
    if args[1] == "tcp/10.0.0.5:7447":  # the option to give, as this command spells it
        assert "not on loopback; give --allow-remote" in lines[0]
    assert "\x1b" not in done.stderr


_NO_ROS_PROBE = """
import json, sys
from ads_rca.cli import main
try:
    code = main(sys.argv[1:])
except SystemExit as stop:  # --help
    code = stop.code
roots = {m.split(".")[0] for m in sys.modules}
print(json.dumps({"code": code, "roots": sorted(roots)}))
"""
ROS_ROOTS = {"rclpy", "rcl_interfaces", "std_msgs", "builtin_interfaces", "diagnostic_msgs"}


@pytest.mark.parametrize("mode", ["help", "run"])
def test_watch_loads_no_ros(mode: str) -> None:
    """``--help``, and a whole run that times out (no peer): no ROS module loaded; the
    timeout is one line on stderr and status 3."""
    args = ["--help"] if mode == "help" else ["--connect", f"tcp/127.0.0.1:{free_port()}"]
    args = args if mode == "help" else [*args, "--json", "--timeout", "0.5"]
    done = subprocess.run(
        [sys.executable, "-c", _NO_ROS_PROBE, "watch", *args],
        capture_output=True,
        text=True,
        env=_env(),
        cwd=REPO,
        timeout=60,
        check=False,
    )
    result = json.loads(done.stdout.splitlines()[-1])
    assert not ROS_ROOTS & set(result["roots"])
    if mode == "help":
        assert result["code"] == 0 and "--exit-on-verdict" in done.stdout
    else:
        assert result["code"] == 3
        assert {"zenoh", "rich"} <= set(result["roots"])  # it did run
        lines = done.stderr.splitlines()
        assert lines[0].startswith("ads-rca watch: waiting")
        assert lines[1:] and lines[-1].startswith("ads-rca watch: no verdict within 0.5 s")
        assert len(lines) == 2


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_a_stop_signal_while_waiting_exits_128_plus_it(signum: int) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    process = spawn_watch("--connect", endpoint, "--json")
    try:
        assert process.stderr is not None
        assert "waiting" in process.stderr.readline()  # handlers installed, loop running
        sent = time.monotonic()
        process.send_signal(signum)
        out, err = process.communicate(timeout=10)
        took = time.monotonic() - sent
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
    assert process.returncode == 128 + signum
    assert took < 5.0
    assert out == "" and "Traceback" not in err


def test_every_endpoint_s_runs_are_shown_and_each_endpoint_s_own_state() -> None:
    """Issue 38 items 2 and 5: two bridges on two endpoints publish two runs under one
    prefix, a third endpoint never answers. ``watch`` shows both runs whole and apart (each
    its verdict and counts), and says each endpoint's state, on stderr and on the screen."""
    primary, indices = expected_run()
    up = [f"tcp/127.0.0.1:{free_port()}" for _ in range(2)]
    down = f"tcp/127.0.0.1:{free_port()}"
    connect = [arg for endpoint in (*up, down) for arg in ("--connect", endpoint)]
    with feed(up[0], "--run", "first"), feed(up[1], "--run", "second") as running:
        running.expect("VERDICT")
        watcher = spawn_watch(*connect, "--json", "--timeout", "8")
        out, err = watcher.communicate(timeout=60)
        with terminal(watch_command(*connect, "--timeout", "6")) as term:
            assert term.exit_status() == 0
            screen = term.screen()
    assert watcher.returncode == 0, err
    finals = {e["name"]: e for e in map(_strict, out.splitlines()) if e["kind"] == "final"}
    assert sorted(finals) == ["car1@first", "car1@second"]
    for name, final in finals.items():
        assert final["run"] == "car1" and final["run_id"] == name.split("@")[1]
        assert final["primary_root_cause"] == primary
        for module, seen in indices.items():
            assert final["modules"][module]["judged"] == len(seen), (name, module)
    notes = err.splitlines()
    assert f"ads-rca watch: {up[0]} connected" in notes
    assert f"ads-rca watch: {up[1]} connected" in notes
    (waiting,) = [note for note in notes if down in note]
    assert waiting.startswith(f"ads-rca watch: waiting: {down} connecting (retrying): ")
    assert "run car1 · id first" in screen and "run car1 · id second" in screen
    words = " ".join(screen.split())  # the header may wrap at the terminal's width
    assert f"{up[0]} connected · {up[1]} connected · {down} connecting (retrying)" in words
    assert screen.count(f"primary root cause: {primary}") == 2, screen


def test_an_idle_screen_is_redrawn_once_a_second_not_at_every_look() -> None:
    """Issue 38 item 10: nothing arrives and no link changes, so the screen is drawn once
    a second (it was drawn at every look, 4 a second: 7 % of a core idle)."""
    from ads_rca.remote import watch as watch_module

    drawn: list[float] = []
    original = watch_module.Watcher.screen

    def counted(self: Any) -> Any:
        drawn.append(time.monotonic())
        return original(self)

    endpoint = f"tcp/127.0.0.1:{free_port()}"  # nothing listens: no sample, one state
    options = watch_module.WatchOptions(connect=(endpoint,), timeout=3.2)
    watch_module.Watcher.screen = counted  # type: ignore[method-assign]
    try:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            assert watch_module.watch(options) == watch_module.EXIT_NO_VERDICT
    finally:
        watch_module.Watcher.screen = original  # type: ignore[method-assign]
    looks = 3.2 / watch_module.REFRESH_S
    assert 3 <= len(drawn) <= 6 < looks, drawn
