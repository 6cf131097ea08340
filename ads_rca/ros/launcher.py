"""Starts ROS nodes as separate processes and stops them cleanly; a tiny ``ros2 launch``.

``launch``/``ros2`` are not available here, and the CLI (``ads-rca demo``/``replay``) and the
tests need to run a graph of nodes anyway. Each child gets the safe environment of
:mod:`ads_rca.ros.env`, its output is read line by line (kept, and optionally echoed with a
``[name]`` prefix), and stopping escalates SIGINT → SIGTERM → SIGKILL with timeouts.

Children must not outlive us, whatever ends us: each runs in its own session (so a
terminal's Ctrl-C reaches only us, and we stop them in order; signals go to the child's
whole process group) and learns our pid through ``ADS_RCA_PARENT_PID``, with which our
nodes arm a parent-death signal at start (:mod:`ads_rca.ros.lifeline`). Start children
from a thread that lives as long as they do (the parent-death signal follows the thread).
Pure Python: no rclpy import.
"""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Collection, Iterable, Mapping
from types import TracebackType
from typing import TextIO

from ads_rca.ros.env import ros_environment
from ads_rca.ros.lifeline import PARENT_VARIABLE

ParamValue = bool | int | float | str | tuple[str, ...]


def format_param(value: ParamValue) -> str:
    """A value as ``-p name:=value`` wants it (YAML): floats keep a '.' (infinity is YAML's
    ``.inf``, a double to rcl and to PyYAML alike), strings are quoted, a tuple of strings
    is a YAML flow list (a string array; rcl cannot type an empty one)."""
    if isinstance(value, tuple):
        if not value:
            raise ValueError("an empty list parameter has no type: leave it out")
        return "[" + ", ".join(format_param(item) for item in value) + "]"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return (".inf" if value > 0 else "-.inf") if math.isinf(value) else repr(value)
    escaped = value.replace("\\", "\\\\").replace('"', '\\"')
    return f'"{escaped}"'


def ros_args(
    params: Mapping[str, ParamValue] | None = None,
    params_file: str | os.PathLike[str] | None = None,
) -> list[str]:
    """``--ros-args [--params-file f] -p k:=v ...`` (empty when there is nothing to pass).

    rcl lets a later argument override an earlier one, so the file comes first and each
    explicit ``-p`` wins over it.
    """
    args: list[str] = []
    if params_file is not None:
        args += ["--params-file", os.fspath(params_file)]
    for name, value in (params or {}).items():
        args += ["-p", f"{name}:={format_param(value)}"]
    return ["--ros-args", *args] if args else []


def node_command(
    module: str,
    params: Mapping[str, ParamValue] | None = None,
    params_file: str | os.PathLike[str] | None = None,
) -> list[str]:
    """argv running ``python -m module`` with ROS arguments (same interpreter as ours)."""
    return [sys.executable, "-m", module, *ros_args(params, params_file)]


class ManagedProcess:
    """One child process: output collected by a reader thread, clean stop."""

    def __init__(
        self,
        name: str,
        argv: list[str],
        env: Mapping[str, str] | None = None,
        echo: TextIO | None = None,
        cwd: str | os.PathLike[str] | None = None,
    ) -> None:
        self.name = name
        self.argv = argv
        self.lines: list[str] = []
        self._echo = echo
        self._lock = threading.Lock()
        child_env = dict(env) if env is not None else ros_environment()
        child_env[PARENT_VARIABLE] = str(os.getpid())
        self.process = subprocess.Popen(
            argv,
            env=child_env,
            cwd=cwd,
            start_new_session=True,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            bufsize=1,
        )
        self._reader = threading.Thread(target=self._read, name=f"out-{name}", daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            text = line.rstrip("\n")
            with self._lock:
                self.lines.append(text)
                if self._echo is not None:
                    try:
                        self._echo.write(f"[{self.name}] {text}\n")
                        self._echo.flush()
                    except (BrokenPipeError, ValueError):
                        # Its reader went away (``| head``) or it was closed: stop echoing
                        # but keep draining the child, which would block on a full pipe.
                        self._echo = None

    @property
    def output(self) -> str:
        with self._lock:
            return "\n".join(self.lines)

    @property
    def returncode(self) -> int | None:
        return self.process.poll()

    def wait(self, timeout: float | None = None) -> int | None:
        """Exit status, or None if still running after ``timeout`` seconds."""
        try:
            code = self.process.wait(timeout)
        except subprocess.TimeoutExpired:
            return None
        self._reader.join(timeout=2.0)
        return code

    def signal(self, sig: int) -> None:
        """Send ``sig`` to the child's process group (it and anything it started)."""
        if self.process.poll() is not None:
            return
        try:
            os.killpg(self.process.pid, sig)
        except (ProcessLookupError, PermissionError):
            self.process.send_signal(sig)

    def stop(self, timeout: float = 5.0) -> int:
        """SIGINT, then SIGTERM, then SIGKILL, each given ``timeout`` seconds; exit status."""
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
            if self.process.poll() is not None:
                break
            self.signal(sig)
            if self.wait(timeout) is not None:
                break
        code = self.process.wait()
        self._reader.join(timeout=2.0)
        return code


class Launcher:
    """Starts named processes in one environment; stops whatever still runs on exit."""

    def __init__(self, env: Mapping[str, str] | None = None, echo: TextIO | None = None) -> None:
        self.env = dict(env) if env is not None else ros_environment()
        self.echo = echo
        self.processes: dict[str, ManagedProcess] = {}

    def start(self, name: str, argv: list[str]) -> ManagedProcess:
        process = ManagedProcess(name, argv, self.env, self.echo)
        self.processes[name] = process
        return process

    def wait_all(self, timeout: float, names: Iterable[str] | None = None) -> dict[str, int | None]:
        """Wait up to ``timeout`` seconds in total; exit status per process (None: running)."""
        deadline = time.monotonic() + timeout
        out: dict[str, int | None] = {}
        for name in list(names) if names is not None else list(self.processes):
            remaining = max(0.0, deadline - time.monotonic())
            out[name] = self.processes[name].wait(remaining)
        return out

    def stop_all(self, timeout: float = 5.0, keep: Collection[str] = ()) -> dict[str, int]:
        """Stop every process but those named in ``keep``, last started first."""
        return {
            name: process.stop(timeout)
            for name, process in reversed(self.processes.items())
            if name not in keep
        }

    def kill_all(self) -> None:
        """SIGKILL every process group now (an impatient second stop request)."""
        for process in self.processes.values():
            process.signal(signal.SIGKILL)

    def __enter__(self) -> Launcher:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.stop_all()
