"""CPU of an idle ``ads-rca watch`` screen and ``ads-rca dashboard`` (issue 38 item 10).

Why: a dashboard left open beside a vehicle for hours should cost next to nothing while no
result comes. Each front end runs as its own process for ``SECONDS`` (default 20) beside a
bridge's Zenoh side that put the bundled crash's run and now only heartbeats once a second
(a bridge lingering after its verdict: the screen shows the whole run), then with nothing
listening (retrying). ``watch`` runs in a 150 x 50 pseudo-terminal, so it draws its full
screen as in tmux. After a warm-up (imports, first connection), CPU is the process's user +
system time from /proc over the measured wall time; the table gives both and CPU per wall
second (% of a core).

Usage: ``python bench/bench_watch_idle.py [SECONDS] [--repo PATH]`` (``--repo``: run the
front ends of another checkout, e.g. a git worktree of an older commit, for an A/B).
"""

from __future__ import annotations

import argparse
import fcntl
import os
import pty
import re
import signal
import socket
import struct
import subprocess
import sys
import termios
import threading
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from ads_rca.contract.jsontext import dumps_json  # noqa: E402
from ads_rca.live.simulate import run_live  # noqa: E402
from ads_rca.params import make_params  # noqa: E402
from ads_rca.remote.publisher import ZenohPublisher  # noqa: E402
from ads_rca.remote.state import RemoteState  # noqa: E402
from ads_rca.sources.log.reader import read_run_log  # noqa: E402


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def finished_run(endpoint: str, stop: threading.Event) -> None:
    """A bridge's Zenoh side after the bundled crash's run: every result and the verdict
    put once, the queryables answered, a heartbeat a second (as a lingering bridge)."""
    run = run_live(read_run_log(REPO / "examples" / "cut_in_perception"), make_params())
    assert run.outcome is not None
    publisher = ZenohPublisher(RemoteState("car1"), listen=[endpoint]).open()
    try:
        for results in run.results.values():
            for result in results:
                publisher.on_result(dumps_json(result.to_document()))
        publisher.on_verdict(dumps_json(run.outcome.document))
        publisher.tick(heartbeat=False)
        while not stop.wait(1.0):
            publisher.tick(heartbeat=True, state="verdict")
    finally:
        publisher.close()


#: Seconds a front end runs before it is measured (imports, first connection).
WARM_UP_S = 4.0


def process_cpu(pid: int) -> float:
    """User + system CPU seconds of a running process (/proc/<pid>/stat)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def measure(process: subprocess.Popen[bytes], seconds: float, drain: int | None) -> float:
    """CPU seconds ``process`` used over ``seconds`` after :data:`WARM_UP_S`; the pty
    ``drain`` is read meanwhile so a screen never blocks on it."""

    def wait(span: float) -> None:
        end = time.monotonic() + span
        while time.monotonic() < end:
            if drain is None:
                time.sleep(0.1)
                continue
            try:
                os.read(drain, 65536)
            except OSError:
                time.sleep(0.1)

    wait(WARM_UP_S)
    before = process_cpu(process.pid)
    wait(seconds)
    used = process_cpu(process.pid) - before
    process.send_signal(signal.SIGTERM)
    process.wait(30)
    return used


def run_watch(repo: Path, endpoint: str, seconds: float) -> float:
    """``watch`` in a pty (its full screen drawn); CPU s over ``seconds``."""
    env = {**os.environ, "PYTHONPATH": str(repo), "COLUMNS": "150", "LINES": "50"}
    argv = [sys.executable, "-m", "ads_rca.cli", "watch", "--connect", endpoint]
    main, secondary = pty.openpty()
    # A 150 x 50 terminal, as tmux gives (a pty starts at 0 x 0).
    fcntl.ioctl(secondary, termios.TIOCSWINSZ, struct.pack("HHHH", 50, 150, 0, 0))
    process = subprocess.Popen(argv, stdin=secondary, stdout=secondary, stderr=secondary, env=env)
    os.close(secondary)
    os.set_blocking(main, False)
    try:
        return measure(process, seconds, main)
    finally:
        os.close(main)


def run_dashboard(repo: Path, endpoint: str, seconds: float) -> float:
    """``dashboard`` with no page open; CPU s over ``seconds``."""
    env = {**os.environ, "PYTHONPATH": str(repo)}
    argv = [sys.executable, "-m", "ads_rca.cli", "dashboard", "--port", "0"]
    argv += ["--connect", endpoint]
    process = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, env=env)
    assert process.stdout is not None
    line = process.stdout.readline().decode()
    assert re.search(r"http://", line), line
    return measure(process, seconds, None)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("seconds", nargs="?", type=float, default=20.0)
    parser.add_argument("--repo", type=Path, default=REPO)
    args = parser.parse_args()
    rows = []
    for where in ("a run shown, idle", "nothing listening"):
        endpoint = f"tcp/127.0.0.1:{free_port()}"
        stop = threading.Event()
        bridge = None
        if where != "nothing listening":
            bridge = threading.Thread(target=finished_run, args=(endpoint, stop), daemon=True)
            bridge.start()
        try:
            for name, runner in (("watch (screen)", run_watch), ("dashboard", run_dashboard)):
                cpu = runner(args.repo, endpoint, args.seconds)
                rows.append((name, where, args.seconds, cpu))
        finally:
            stop.set()
            if bridge is not None:
                bridge.join(10)
    print(f"idle front ends, {args.seconds:g} s each, repo {args.repo}")
    print(f"{'front end':<16} {'Zenoh':<18} {'wall s':>7} {'CPU s':>7} {'% core':>7}")
    for name, where, wall, cpu in rows:
        print(f"{name:<16} {where:<18} {wall:7.1f} {cpu:7.2f} {100 * cpu / wall:7.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
