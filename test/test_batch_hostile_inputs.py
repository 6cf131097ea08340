"""``ads-rca batch`` given hostile inputs: a ``--scheduler`` that is no Dask scheduler, a
glob over a tree with symlink loops (issue 41).

No mocks: real TCP servers on 127.0.0.1 (threads of this test) against the command in a
subprocess with its address space limited; real trees with real symlink loops. Checked:
an HTTP server and a server that accepts and stays silent are each one line on stderr,
exit status 2, within the connect timeout, no traceback, nothing allocated on the peer's
say-so (1.5 GB of address space is plenty); a real Dask scheduler passes the check; a
``'root/**'`` over ``a/b -> ..`` loops ends within seconds with the runs found and a line
saying the loops were skipped; the walk's bounds (depth, entries) hold.
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
from commandline import assert_one_line

from ads_rca.batch import inputs
from ads_rca.batch.inputs import MAX_GLOB_DEPTH, expand_inputs, run_id
from ads_rca.batch.scheduler import TIMEOUT, check_scheduler
from ads_rca.batch.store import read_csv
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
        connection.settimeout(5)
        connection.recv(65536)  # our handshake read first: a clean close, not a reset
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


def loop_tree(root: Path, run: Path) -> Path:
    """``root`` holding a copy of ``run`` and two loops, ``a/b -> ..`` and ``c/d -> ..``."""
    root.mkdir()
    os.symlink(run, root / "run_0")
    for folder, link in (("a", "b"), ("c", "d")):
        (root / folder).mkdir()
        (root / folder / link).symlink_to("..")
    return root


def test_a_glob_over_symlink_loops_ends_with_the_runs_found(
    small_run: Path, tmp_path: Path
) -> None:
    root = loop_tree(tmp_path / "root", small_run)
    out = tmp_path / "out"
    done, seconds = batch(f"{root}/**", "--out", str(out), "--workers", "1", timeout=60)
    assert "Traceback" not in done.stdout + done.stderr
    assert done.returncode == 0, done.stderr
    assert f"{root}/**: 2 symlink loop(s) not followed (a folder inside itself)" in done.stderr
    rows = {row["path"]: row for row in read_csv(out / "results.csv")}
    real = os.path.realpath
    assert rows[real(small_run)]["error"] == ""  # the run, found through its symlink
    assert {real(root), real(root / "a"), real(root / "c")} <= set(rows)  # each folder once
    assert seconds < 45


def test_the_walk_skips_loops_and_second_paths_and_says_so(small_run: Path, tmp_path: Path) -> None:
    root = loop_tree(tmp_path / "root", small_run)
    os.symlink(small_run, root / "again")  # the same run by another path: not a loop
    notes: list[str] = []
    start = time.process_time()
    runs = expand_inputs([f"{root}/**/actors"], notes.append)
    assert time.process_time() - start < 1
    assert [run.path for run in runs] == [os.path.realpath(small_run / "actors")]
    assert notes == [
        f"{root}/**/actors: 2 symlink loop(s) not followed (a folder inside itself)",
        f"{root}/**/actors: 1 folder(s) reached again by another path, searched once",
    ]


def test_the_walk_is_bounded_in_depth_and_entries(
    small_run: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    deep = tmp_path / "deep"
    folder = deep
    for _ in range(MAX_GLOB_DEPTH + 3):
        folder = folder / "d"
    folder.mkdir(parents=True)
    os.symlink(small_run, folder / "run")  # below the bound: not found
    os.symlink(small_run, deep / "d" / "run")
    notes: list[str] = []
    runs = expand_inputs([f"{deep}/**/run"], notes.append)
    assert [run.run_id for run in runs] == [run_id(small_run)]
    assert notes == [
        f"{deep}/**/run: 1 folder(s) more than {MAX_GLOB_DEPTH} levels below '**' not searched"
    ]
    monkeypatch.setattr(inputs, "MAX_GLOB_ENTRIES", 50)
    with pytest.raises(InputError, match=r"the glob's walk passed 50 entries: narrow it"):
        expand_inputs([f"{deep}/**/run"])


def test_a_bag_reached_through_a_link_without_suffix_is_read_as_given(tmp_path: Path) -> None:
    """Issue 43 item 3: a content-addressed store (DVC-style) names its files by hash, and
    the runs are links to them. `diagnose runs/crash.mcap` read the bag; `batch` resolved
    the link first, lost the `.mcap` name and refused it ("not a folder"). The format is
    now decided from the path given; the run id still comes from the resolved path."""
    from commandline import convert_example

    bag = convert_example(tmp_path / "bag", "--storage", "mcap")
    (stored,) = list(bag.glob("*.mcap"))
    store = tmp_path / "store"
    store.mkdir()
    blob = store / "3f9a0c5e1b7d2a46"
    stored.rename(blob)
    runs = tmp_path / "runs"
    runs.mkdir()
    (runs / "crash.mcap").symlink_to(blob)
    done, _ = batch(str(runs / "crash.mcap"), "--out", str(tmp_path / "out"), "--workers", "1")
    assert done.returncode == 0, done.stderr
    (row,) = read_csv(tmp_path / "out" / "results.csv")
    assert row["error"] == "" and row["primary_root_cause"] == "perception", row
    assert row["run_id"] == run_id(blob)  # one run, however it is reached
