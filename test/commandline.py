"""The ``ads-rca`` command line run as a user runs it: a child process, output captured.

:func:`run_cli` starts ``python -m ads_rca.cli`` with this interpreter; ``script=True``
starts the ``ads-rca`` console script of this venv instead (what ``pip install`` puts on
the PATH). A run that outlives ``timeout`` raises ``TimeoutExpired``: a hang fails the test.
"""

from __future__ import annotations

import os
import resource
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

from ads_rca.cli import main as cli

#: The console script beside this interpreter.
ADS_RCA = str(Path(sys.executable).with_name("ads-rca"))
REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "examples" / "cut_in_perception"
#: Address space of a :func:`run_limited` run: plenty for a diagnosis, far below the
#: machine's memory (reading /dev/zero until memory runs out fails the test, not the machine).
MEMORY_LIMIT = 3 << 30


def run_cli(
    *args: str, check: bool = False, timeout: float = 120, script: bool = False, **popen: Any
) -> subprocess.CompletedProcess[str]:
    """``ads-rca ARGS``; ``check``: assert it exited 0 (its stderr as the message)."""
    command = [ADS_RCA] if script else [sys.executable, "-m", "ads_rca.cli"]
    done = subprocess.run(
        [*command, *args], capture_output=True, text=True, timeout=timeout, check=False, **popen
    )
    if check:
        assert done.returncode == 0, done.stderr
    return done


def start_cli(*args: str) -> subprocess.Popen[str]:
    """``ads-rca ARGS`` started as at a terminal, output on pipes, this checkout first on
    the path: with SIGINT's default action, whatever this test run inherited (a suite
    started as a background job of a script ignores SIGINT, and the command rightly keeps an
    ignored SIGINT ignored: a Ctrl-C test then saw a finished command)."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    # A Python handler here is the default action in the child (an exec resets handlers,
    # not an ignored disposition).
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        return subprocess.Popen(
            [sys.executable, "-m", "ads_rca.cli", *args],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
            cwd=REPO,
        )
    finally:
        signal.signal(signal.SIGINT, previous)


def run_script(*args: str, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    """The ``ads-rca`` console script with ``args``, whatever its exit status."""
    return run_cli(*args, timeout=timeout, script=True)


def _limit_memory() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))


def run_limited(*args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    """``ads-rca ARGS`` with its address space limited to :data:`MEMORY_LIMIT`."""
    return run_cli(*args, timeout=timeout, preexec_fn=_limit_memory)


def assert_clean(done: subprocess.CompletedProcess[str], code: int = 0) -> None:
    """No traceback in its output, and the exit status ``code``."""
    output = done.stdout + done.stderr
    assert "Traceback" not in output, output
    assert done.returncode == code, output


def assert_one_line(done: subprocess.CompletedProcess[str], message: str) -> None:
    """A refusal as every command gives one: exit 2, one stderr line holding ``message``,
    no traceback."""
    output = done.stdout + done.stderr
    assert "Traceback" not in output, output
    assert done.returncode == 2, output
    assert done.stderr.count("\n") == 1, done.stderr
    assert message in done.stderr, done.stderr


def convert_example(out: Path, *options: str) -> Path:
    """The bundled example converted to a bag at ``out`` by ``ads-rca convert`` (in process)."""
    assert cli(["convert", str(EXAMPLE), str(out), *options]) == 0
    return out
