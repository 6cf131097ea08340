"""Clean up after a launcher that could not: stop its children, remove its work folder.

``ads-rca replay`` stops its nodes and removes its temporary folder on every exit path it
can run code on (normal end, an exception, SIGINT/SIGTERM/SIGHUP). A SIGKILL leaves it no
such chance: its nodes then get SIGTERM from their parent-death signal
(:mod:`ads_rca.ros.lifeline`), but the folder would stay. So ``replay`` starts this small
process first, in its own session, holding the write end of its stdin: when ``replay``
ends, however it ends, the pipe closes; the reaper then stops whatever processes still
carry ``ADS_RCA_PARENT_PID=<replay's pid>`` (SIGTERM to their groups, SIGKILL after
``grace`` seconds) and removes the folders it was given. Pure Python, Linux ``/proc``.

Usage: ``python -m ads_rca.ros.reaper FOLDER...`` (stdin: a pipe from the launcher).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import sys
import time
from pathlib import Path

from ads_rca.ros.lifeline import PARENT_VARIABLE


def children_of(parent: int, proc: Path = Path("/proc")) -> list[int]:
    """Pids of live processes whose environment says ``parent`` launched them."""
    marker = f"{PARENT_VARIABLE}={parent}".encode()
    out = []
    for entry in proc.iterdir():
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        try:
            environ = (entry / "environ").read_bytes()
            state = (entry / "stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            continue
        if state != "Z" and marker in environ.split(b"\0"):
            out.append(int(entry.name))
    return out


def stop_children(parent: int, grace: float = 10.0) -> list[int]:
    """SIGTERM, then (after ``grace`` s) SIGKILL, every child of ``parent``; their pids."""
    found = children_of(parent)
    for sig in (signal.SIGTERM, signal.SIGKILL):
        for pid in children_of(parent):
            _signal_group(pid, sig)
        deadline = time.monotonic() + grace
        while children_of(parent) and time.monotonic() < deadline:
            time.sleep(0.05)
        if not children_of(parent):
            break
    return found


def _signal_group(pid: int, sig: int) -> None:
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(pid, sig) if os.getpgid(pid) == pid else os.kill(pid, sig)


def main(argv: list[str] | None = None) -> int:
    folders = [Path(a) for a in (sys.argv[1:] if argv is None else argv)]
    parent = os.getppid()
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGHUP, signal.SIG_IGN)
    try:
        while sys.stdin.buffer.read(4096):
            pass  # the launcher writes nothing; EOF means it has ended
    except OSError:
        pass
    stop_children(parent)
    for folder in folders:
        shutil.rmtree(folder, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
