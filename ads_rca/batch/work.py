"""Diagnose one run of a batch, isolated in a child process with a timeout.

:func:`diagnose_job` is what a Dask task runs. The diagnosis itself happens in a child
forked for the run (``os.fork``: the worker's modules are already imported, so a child costs
a few milliseconds), and the worker thread only waits for its answer on a pipe:

- a run that raises (an unreadable or corrupt log, no frame to analyse) gives a row with the
  error; one whose diagnosis raised in our own code (an oracle, the engine) gives a row with
  its ``internal_error`` (a bug, never reported as bad input), and its verdict JSON when the
  engine still made one;
- a run still going after ``timeout`` seconds is killed (SIGKILL) and gives a row
  "timed out"; a thread could not be stopped, a process can;
- a child that dies (a segfault in a library, the out-of-memory killer) gives a row naming
  the signal.

So nothing a run does can stop the batch or the worker. The answer is the row and the
verdict JSON's bytes (the same bytes as ``diagnose --json``): the client writes every file,
so workers need to see the inputs only, never the output folder. POSIX only (fork).
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import pickle
import select
import signal
import socket
import sys
import time
import traceback
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from ads_rca.batch.rows import Row, error_row, internal_error_row, row_from_document
from ads_rca.errors import AdsRcaError
from ads_rca.foundation.indented_json import dumps_indented
from ads_rca.params import Params
from ads_rca.sources.bag.options import BagOptions
from ads_rca.sources.formats import SourceOptions

#: prctl(2): a signal to get when the parent dies.
_PR_SET_PDEATHSIG = 1
#: Bytes read from the child's pipe at a time.
_CHUNK = 1 << 16


@dataclass(frozen=True)
class Job:
    """One run and how to diagnose it (pickled to the worker)."""

    run_id: str
    path: str
    params: Params
    max_file_mb: float
    bag: BagOptions
    timeout: float
    source: SourceOptions = SourceOptions()  # noqa: RUF009 - frozen, so one shared default is safe


@dataclass
class Outcome:
    """What a task returns: the row and, for a diagnosed run, its verdict JSON."""

    row: Row
    json: bytes | None


def diagnose_job(job: Job) -> Outcome:
    """Diagnose ``job`` in a forked child, at most ``job.timeout`` seconds (see module doc)."""
    warm_up()
    worker = f"{socket.gethostname()}:{os.getpid()}"
    started = time.monotonic()
    read_fd, write_fd = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: never returns
        os.close(read_fd)
        _child(job, write_fd, worker)
    os.close(write_fd)
    try:
        data, timed_out = _read_until(read_fd, started + job.timeout)
    finally:
        os.close(read_fd)
    if timed_out:
        _kill(pid)
    status = _reap(pid)
    elapsed = time.monotonic() - started
    known = {"worker": worker, "diagnose_seconds": elapsed, **_format(job)}
    if timed_out:
        return Outcome(
            error_row(job.run_id, job.path, f"timed out after {job.timeout:g} s", **known), None
        )
    if os.WIFSIGNALED(status):
        name = signal.Signals(os.WTERMSIG(status)).name
        return Outcome(
            error_row(job.run_id, job.path, f"diagnosis killed by {name}", **known), None
        )
    try:
        outcome = pickle.loads(data)
    except Exception:  # an exit before the answer was whole
        code = os.WEXITSTATUS(status) if os.WIFEXITED(status) else status
        message = f"diagnosis ended without an answer (exit status {code})"
        return Outcome(error_row(job.run_id, job.path, message, **known), None)
    assert isinstance(outcome, Outcome)
    return outcome


_WARM: list[bool] = []


def warm_up() -> None:
    """Import, once per worker, every module a diagnosis loads (the readers, the engine,
    every oracle, scipy's): a child forked after it starts with them (copy-on-write), where
    each child would otherwise import them again (~1 s a run)."""
    if _WARM:
        return
    import importlib
    import pkgutil

    import ads_rca.oracles

    names = [
        "ads_rca.diagnosis.engine",
        "ads_rca.sources.registry",
        "ads_rca.sources.log.reader",
        "ads_rca.sources.bag.reader",
    ]
    names += ["ads_rca.capabilities"]
    # The corrected matching of crowds imports SciPy's packages on first need (0.4 s).
    names += ["scipy.optimize", "scipy.sparse.csgraph"]
    names += [
        info.name for info in pkgutil.walk_packages(ads_rca.oracles.__path__, "ads_rca.oracles.")
    ]
    for name in names:
        importlib.import_module(name)
    _WARM.append(True)


def _child(job: Job, write_fd: int, worker: str) -> None:
    code = 0
    try:
        _orphan_ends(job.timeout)
        outcome = run_job(job, worker)
        payload = pickle.dumps(outcome, protocol=pickle.HIGHEST_PROTOCOL)
        view = memoryview(payload)
        while view:
            written = os.write(write_fd, view)
            view = view[written:]
    except BaseException:
        code = 1
        with contextlib.suppress(BaseException):
            traceback.print_exc()
    finally:
        os._exit(code)


def _orphan_ends(timeout: float) -> None:
    """The child ends with its worker (killed mid-run), or at the latest ``timeout`` + 5 s
    after it started: never an orphan judging on."""
    for number in (signal.SIGINT, signal.SIGTERM, signal.SIGALRM):
        # A Python handler (the worker's) becomes the default action; an ignored signal
        # stays ignored: a batch started where SIGINT is ignored (a background job of a
        # script) must not lose its runs to a Ctrl-C meant for others in its group.
        if number == signal.SIGALRM or callable(signal.getsignal(number)):
            signal.signal(number, signal.SIG_DFL)
    signal.setitimer(signal.ITIMER_REAL, timeout + 5.0)
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
        except (OSError, AttributeError):
            pass


def run_job(job: Job, worker: str = "") -> Outcome:
    """Read and judge the run in this process (the child's work; no timeout here)."""
    from ads_rca.diagnosis.engine import diagnose
    from ads_rca.foundation.workers import loaded_objects_frozen
    from ads_rca.oracles.semantics import semantics_for
    from ads_rca.sources.registry import no_frame_message, open_run

    started = time.monotonic()
    known: dict[str, Any] = {"worker": worker, **_format(job)}
    try:
        log = open_run(
            job.path,
            max_file_mb=job.max_file_mb,
            bag=job.bag,
            source=job.source,
        )
        known.update(_labels(log.metadata.raw))
        if not semantics_for(job.params).analysed_frames(log):
            raise AdsRcaError(no_frame_message(job.path, log, job.source.source_format, job.bag))
        with loaded_objects_frozen():  # the loaded run, out of the collector's sight
            document = diagnose(log, job.params, None, workers=1).to_json()
            text = dumps_indented(document) + "\n"
    except AdsRcaError as error:
        known["diagnose_seconds"] = time.monotonic() - started
        return Outcome(error_row(job.run_id, job.path, str(error), **known), None)
    except Exception as error:  # a bug in ads_rca, never the input's fault
        known["diagnose_seconds"] = time.monotonic() - started
        return Outcome(internal_error_row(job.run_id, job.path, error, **known), None)
    known["diagnose_seconds"] = time.monotonic() - started
    # An oracle that raised leaves a verdict (inconclusive) and its internal_errors: the
    # row keeps both and counts as failed, as `diagnose` exits 70 for it.
    row = row_from_document(job.run_id, job.path, document, job.params, **known)
    return Outcome(row, text.encode("utf-8"))


def _format(job: Job) -> dict[str, str]:
    """The format column (the source's words, ``Source.words``), and the profile of a bag."""
    from ads_rca.errors import AdsRcaError
    from ads_rca.sources.bag import NAME as BAG
    from ads_rca.sources.registry import DETECTION_ORDER, resolved_format, source_named

    try:
        found = resolved_format(job.path, job.source.source_format)
    except (OSError, AdsRcaError):
        found = DETECTION_ORDER[-1]  # what takes any path
    return {
        "format": source_named(found).words,
        "profile": job.bag.profile if found == BAG else "",
        "semantics": job.params.semantics,
    }


def _labels(raw: Any) -> dict[str, str]:
    """Scenario family and injected fault from metadata ``synthesis``, when present."""
    synthesis = raw.get("synthesis") if isinstance(raw, Mapping) else None
    if not isinstance(synthesis, Mapping):
        return {}
    return {
        key: value
        for key, value in (
            ("scenario", synthesis.get("scenario")),
            ("injected_fault", synthesis.get("fault")),
        )
        if isinstance(value, str)
    }


def _read_until(fd: int, deadline: float) -> tuple[bytes, bool]:
    """Everything written to ``fd`` until EOF; (what came, True) at ``deadline``."""
    chunks: list[bytes] = []
    while True:
        left = deadline - time.monotonic()
        if left <= 0:
            return b"".join(chunks), True
        ready, _, _ = select.select([fd], [], [], left)
        if not ready:
            continue
        chunk = os.read(fd, _CHUNK)
        if not chunk:
            return b"".join(chunks), False
        chunks.append(chunk)


def _kill(pid: int) -> None:
    with contextlib.suppress(ProcessLookupError):
        os.kill(pid, signal.SIGKILL)


def _reap(pid: int) -> int:
    while True:
        try:
            return os.waitpid(pid, 0)[1]
        except InterruptedError:
            continue
