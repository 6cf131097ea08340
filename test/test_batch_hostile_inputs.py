"""``ads-rca batch`` given hostile inputs: a ``--scheduler`` that is no Dask scheduler
(issue 41).

No mocks: real TCP servers on 127.0.0.1 (threads of this test) against the command in a
subprocess with its address space limited. Checked: an HTTP server and a server that
accepts and stays silent are each one line on stderr, exit status 2, within the connect
timeout, no traceback, nothing allocated on the peer's say-so (1.5 GB of address space is
plenty); a peer that closes or refuses is one line too; a real Dask scheduler passes the
check.
"""

from __future__ import annotations

import os
import resource
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from ads_rca.batch.scheduler import TIMEOUT, check_scheduler
from ads_rca.errors import InputError
from ads_rca.sources.log.writer import write_run_log
from ads_rca.synth import synthesise

pytest.importorskip("distributed")

REPO = Path(__file__).resolve().parents[1]
#: Address space of the command: far below the 3.07 EiB an HTTP reply asked distributed for.
MEMORY_LIMIT = 1536 << 20
HTTP_REPLY = (
    b"HTTP/1.1 400 Bad Request\r\nContent-Type: text/plain\r\nContent-Length: 11\r\n"
    b"Connection: close\r\n\r\nBad Request"
)


def _limit_memory() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))


def batch(
    *args: str, timeout: float = 120, cwd: Path | None = None
) -> tuple[subprocess.CompletedProcess[str], float]:
    """``ads-rca batch ARGS`` in a subprocess (address space limited), and its wall time."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    start = time.monotonic()
    done = subprocess.run(
        [sys.executable, "-m", "ads_rca.cli", "batch", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=env,
        cwd=cwd,
        check=False,
        preexec_fn=_limit_memory,
    )
    return done, time.monotonic() - start


def serve(answer: Callable[[socket.socket], None]) -> Iterator[int]:
    """A TCP server on 127.0.0.1 (a thread) calling ``answer`` on each connection; its port."""
    server = socket.create_server(("127.0.0.1", 0))
    connections: list[socket.socket] = []
    stop = threading.Event()

    def accept() -> None:
        server.settimeout(0.2)
        while not stop.is_set():
            try:
                connection, _ = server.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            connections.append(connection)
            threading.Thread(target=answer, args=(connection,), daemon=True).start()

    thread = threading.Thread(target=accept, daemon=True)
    thread.start()
    try:
        yield server.getsockname()[1]
    finally:
        stop.set()
        thread.join(5)
        server.close()
        for connection in connections:
            connection.close()


def answer_http(connection: socket.socket) -> None:
    """An HTTP server's answer to bytes that are no request: 400 (as nginx gives it)."""
    connection.settimeout(5)
    try:
        connection.recv(65536)
        connection.sendall(HTTP_REPLY)
    except OSError:
        pass


def stay_silent(connection: socket.socket) -> None:
    """Accept, read nothing, say nothing (the connection stays open until the test ends)."""


@pytest.fixture
def http_port() -> Iterator[int]:
    yield from serve(answer_http)


@pytest.fixture
def silent_port() -> Iterator[int]:
    yield from serve(stay_silent)


@pytest.fixture(scope="module")
def small_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A synthesised log folder (120 frames)."""
    root = tmp_path_factory.mktemp("hostile_batch")
    return write_run_log(synthesise("cut_in", "perception", 0, frames=120), root / "run_0")


def assert_one_line(done: subprocess.CompletedProcess[str], message: str) -> None:
    output = done.stdout + done.stderr
    assert "Traceback" not in output, output
    assert done.returncode == 2, output
    assert done.stderr.count("\n") == 1, done.stderr
    assert message in done.stderr, done.stderr


def test_a_scheduler_answering_http_is_one_line_at_once(
    http_port: int, small_run: Path, tmp_path: Path
) -> None:
    address = f"tcp://127.0.0.1:{http_port}"
    done, seconds = batch(str(small_run), "--scheduler", address, "--out", str(tmp_path / "o"))
    assert_one_line(
        done, f"--scheduler {address}: not a Dask scheduler (its answer began with b'HTTP/1.1'"
    )
    assert seconds < TIMEOUT
    assert not (tmp_path / "o").exists()  # refused before the output folder is made


@pytest.mark.slow
def test_a_silent_scheduler_is_one_line_within_the_timeout(
    silent_port: int, small_run: Path, tmp_path: Path
) -> None:
    address = f"tcp://127.0.0.1:{silent_port}"
    done, seconds = batch(
        str(small_run), "--scheduler", address, "--out", str(tmp_path / "o"), timeout=3 * TIMEOUT
    )
    assert_one_line(
        done, f"--scheduler {address}: not a Dask scheduler (no handshake within {TIMEOUT:g} s)"
    )
    # The whole command: the timeout plus the interpreter's start (a few seconds at most).
    assert TIMEOUT <= seconds < TIMEOUT + 10


def test_a_peer_that_closes_or_refuses_is_one_line() -> None:
    def close(connection: socket.socket) -> None:
        connection.close()

    for port in serve(close):
        with pytest.raises(InputError, match="it closed the connection without a Dask handshake"):
            check_scheduler(f"tcp://127.0.0.1:{port}")
    with socket.create_server(("127.0.0.1", 0)) as unused:
        port = unused.getsockname()[1]
    with pytest.raises(InputError, match=r"cannot connect \(Connection refused\)"):
        check_scheduler(f"tcp://127.0.0.1:{port}")
    with pytest.raises(InputError, match="expected an address like tcp://host:8786"):
        check_scheduler("tcp://127.0.0.1")


def test_a_real_scheduler_passes_the_check() -> None:
    from distributed import LocalCluster

    with LocalCluster(  # type: ignore[no-untyped-call]
        n_workers=0,
        processes=False,
        protocol="tcp",
        host="127.0.0.1",
        dashboard_address="127.0.0.1:0",
    ) as cluster:
        check_scheduler(cluster.scheduler_address, timeout=10)
