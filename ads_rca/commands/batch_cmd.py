"""``ads-rca batch INPUTS...``: diagnose many runs on a Dask cluster, one row each.

The shell around :mod:`ads_rca.batch`: it checks every input and option before any work,
owns the Dask client (and, locally, the :class:`~distributed.LocalCluster`, bound to
127.0.0.1), submits one task per run through a bounded window
(:mod:`ads_rca.batch.window`), writes each row as it arrives and prints the summary.
Without ``--scheduler`` a local cluster of ``--workers`` processes is started on loopback
(its dashboard on a random loopback port); with ``--scheduler tcp://host:port`` the same
tasks go to an existing cluster, which must see the inputs at the same paths
(docs/scaling.md); a ``tcp://`` address is first checked to speak Dask
(:mod:`ads_rca.batch.scheduler`: else one line within the connect timeout). Every exit path
closes the client and the cluster; Ctrl-C keeps every finished row and exits 130. A write
that fails mid-batch (a full disk) is one line and exit status 2, every row and file
written before it whole (:class:`~ads_rca.batch.store.StoreError`). A batch in which no run
could be diagnosed exits :data:`EXIT_NONE_DIAGNOSED` once every output is written: a script
must not read "all runs failed" as success.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import math
import os
import signal
import sys
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, NoReturn

from ads_rca.batch.inputs import expand_inputs
from ads_rca.batch.interruption import Interruption
from ads_rca.batch.options import OPTIONS_NAME, check_resume, options_record, write_record
from ads_rca.batch.rows import error_row
from ads_rca.batch.scheduler import TIMEOUT, check_scheduler
from ads_rca.batch.store import CSV_NAME, PARQUET_NAME, RUNS_DIR, ResultStore
from ads_rca.batch.summary import Counts, summary_text, write_html
from ads_rca.batch.window import Window, window_size
from ads_rca.batch.work import Job, Outcome, diagnose_job
from ads_rca.commands import command_parser
from ads_rca.commands.diagnose_cmd import add_engine_arguments, params_from_args
from ads_rca.commands.input_args import (
    add_bag_arguments,
    add_reader_arguments,
    bag_options_from_args,
    max_file_mb_from_args,
    source_options_from_args,
)
from ads_rca.commands.outputs import check_output_dir
from ads_rca.errors import InputError
from ads_rca.foundation.text import printable
from ads_rca.foundation.workers import checked_workers
from ads_rca.sources.bag.options import BagOptions
from ads_rca.sources.formats import shown

EXIT_INTERRUPTED = 130
#: Every run failed (no verdict, or an internal error): as ``watch``'s "no verdict".
EXIT_NONE_DIAGNOSED = 3
HTML_NAME = "summary.html"
#: Seconds to wait for ``--scheduler`` to answer.
CONNECT_TIMEOUT = TIMEOUT
DEFAULT_TIMEOUT = 600.0
#: ``--timeout`` must be below this (about 116 days: a typo, not a limit).
MAX_TIMEOUT = 1e7
#: Seconds the client and the local cluster get to close (then they are left to the exit).
CLOSE_TIMEOUT = 10
#: Dask settings of the client and of the local cluster (its workers get them through their
#: nannies): no statistical profiler (it sampled each worker's task thread every 10 ms for
#: a dashboard page no batch reads) and the event loops' health tick every 500 ms instead of
#: every 20 ms (it only warns of a blocked loop), as distributed's own cluster tests run. Idle,
#: a local cluster of 2 workers then costs 0.27 s of CPU in 10 s instead of 0.94 s.
DASK_CONFIG = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "500ms",
}
SCHEMES = ("tcp://", "tls://", "ucx://", "inproc://", "ws://", "wss://")


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = command_parser(subparsers, "batch")
    parser.add_argument(
        "inputs",
        nargs="+",
        metavar="INPUT",
        help="log folder, bag, glob (quoted: 'runs/*') or text file of paths (one a line)",
    )
    parser.add_argument("--out", default="batch_out", help="output folder (default batch_out)")
    parser.add_argument(
        "--workers",
        type=int,
        default=os.cpu_count() or 1,
        help="local worker processes (default: one per core; ignored with --scheduler)",
    )
    parser.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="run on an existing dask.distributed cluster (tcp://host:port) instead of a "
        "local one; its workers must see the inputs at the same paths",
    )
    parser.add_argument(
        "--timeout",
        default=DEFAULT_TIMEOUT,
        metavar="SECONDS",
        help="per-run limit: a run still going is killed and reported (default 600)",
    )
    parser.add_argument(
        "--retries",
        type=int,
        default=3,
        help="times a run is retried when its worker dies (default 3)",
    )
    parser.add_argument(
        "--resume", action="store_true", help="skip the runs already in --out's results"
    )
    add_engine_arguments(parser)
    add_reader_arguments(parser)
    add_bag_arguments(parser)
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    params = params_from_args(args)
    max_file_mb = max_file_mb_from_args(args)
    source = source_options_from_args(args)
    bag = _absolute(bag_options_from_args(args))
    checked_workers(args.workers)
    args.timeout = checked_timeout(args.timeout)
    if not 0 <= args.retries <= 100:
        raise InputError(f"--retries {args.retries}: expected 0 to 100")
    if args.scheduler is not None and not args.scheduler.startswith(SCHEMES):
        raise InputError(
            f"--scheduler {printable(args.scheduler)}: expected an address like tcp://host:8786"
        )
    runs = expand_inputs(args.inputs, _note)
    out = Path(args.out)
    if not args.resume and out.is_dir() and any(out.iterdir()):
        raise InputError(
            f"--out {out}: exists and is not empty (--resume continues the batch there)"
        )
    check_output_dir(out, "--out", empty=not args.resume)
    record = options_record(params, max_file_mb, source, bag)
    if args.resume:
        _check_resume(out, record)
    if args.scheduler:
        check_scheduler(args.scheduler, CONNECT_TIMEOUT)
    store = ResultStore(out, resume=args.resume)
    with store.writing(out / OPTIONS_NAME):
        write_record(out, record)
    done = store.done
    todo = sum(1 for r in runs if r.run_id not in done)
    # Made one at a time as the window takes them: the client never holds every job.
    jobs = (
        Job(r.run_id, r.path, params, max_file_mb, bag, args.timeout, source)
        for r in runs
        if r.run_id not in done
    )
    skipped = len(runs) - todo
    if skipped:
        print(printable(f"--resume: {skipped} of {len(runs)} runs already done in {out}"))
    interruption = Interruption(_exit_now)
    with interruption.installed():
        try:
            if todo:
                _run_jobs(jobs, todo, store, args, interruption)
        except KeyboardInterrupt:
            interruption.requested = True
        finally:
            store.close()  # a second Ctrl-C meanwhile exits at once (the rows are whole)
    interrupted = interruption.requested
    rows = list(store.rows.values())
    print(summary_text(rows, str(out), interrupted))
    if interrupted:
        left = len(runs) - sum(r.run_id in store.rows for r in runs)
        print(
            printable(f"interrupted: {left} runs left; ads-rca batch --resume --out {out} ..."),
            file=sys.stderr,
        )
        return EXIT_INTERRUPTED
    with store.writing(out / HTML_NAME):
        write_html(rows, out / HTML_NAME, str(out))
    print(printable(f"results: {out / PARQUET_NAME}, {out / CSV_NAME}, {out / RUNS_DIR}/"))
    print(printable(f"HTML summary: {out / HTML_NAME}"))
    counts = Counts.of(rows)
    if counts.runs and not counts.diagnosed:
        print(f"ads-rca batch: no run could be diagnosed ({counts.failed} failed)", file=sys.stderr)
        return EXIT_NONE_DIAGNOSED
    return 0


def checked_timeout(value: str | float) -> float:
    """``--timeout`` as seconds: a number in (0, :data:`MAX_TIMEOUT`), else one line
    (text, not argparse's float: an empty or hostile value was a usage block or, for
    ``--timeout=--``, a TypeError traceback)."""
    try:
        seconds = float(value)
    except (TypeError, ValueError):
        seconds = math.nan
    if not 0 < seconds < MAX_TIMEOUT:  # nan, inf, 1e999 (inf) and -1 fail here too
        raise InputError(
            f"--timeout {_given(value)}: expected a positive number of seconds "
            f"below {MAX_TIMEOUT:,.0f}"
        )
    return seconds


def _given(value: object) -> str:
    """A value as typed when it reads plainly (``-1``), else quoted and escaped."""
    text = str(value)
    plain = text.strip() == text and text.isprintable() and 0 < len(text) <= 40
    return text if plain else shown(value)


def _check_resume(out: Path, record: dict[str, Any]) -> None:
    """``--resume`` only with the options ``out``'s rows were made with (one line when
    not; :mod:`ads_rca.batch.options`)."""
    old = check_resume(out, record)
    if old:
        _note(old)


def _note(line: str) -> None:
    """What the inputs' expansion skipped (a symlink loop...): one line on stderr."""
    print(printable(f"ads-rca batch: {line}"), file=sys.stderr)


def _absolute(bag: BagOptions) -> BagOptions:
    """Paths the workers read, made absolute (their working folder is not ours)."""
    profile = bag.profile
    if os.path.isfile(profile):
        profile = os.path.abspath(profile)
    remap = os.path.abspath(bag.remap) if bag.remap else None
    return BagOptions(profile, remap, tuple(os.path.abspath(p) for p in bag.msg_path))


def _run_jobs(
    jobs: Iterable[Job],
    total: int,
    store: ResultStore,
    args: argparse.Namespace,
    interruption: Interruption,
) -> None:
    """Diagnose ``jobs`` through a :class:`~ads_rca.batch.window.Window` of tasks, writing
    each row as it comes; on Ctrl-C (or any error) the tasks in flight are cancelled."""
    from distributed import as_completed

    with _client(args) as client:
        answers = as_completed()

        def submit(job: Job) -> Any:
            future = client.submit(diagnose_job, job, key=f"ads-rca-batch-{job.run_id}", pure=False)
            answers.add(future)
            return future

        window: Window[Job] = Window(jobs, submit, window_size(_threads(client, args)))
        update = _progress(total)
        try:
            window.fill()
            while not window.done:
                with interruption.waiting():
                    future = next(answers)
                job = window.answered(future)  # and the next run submitted
                outcome = _outcome(future, job)
                future.release()
                store.add(outcome.row, outcome.json)
                del future, outcome  # nothing of the run kept once its row is written
                update()
                interruption.check()
        except BaseException:
            _quiet()
            with contextlib.suppress(Exception):
                client.cancel(window.stop())
            raise
        finally:
            update(done=True)


def _threads(client: Any, args: argparse.Namespace) -> int:
    """Worker threads to keep busy: ``--workers`` locally, the cluster's at the start."""
    if not args.scheduler:
        return int(args.workers)
    try:
        return sum(int(n) for n in client.nthreads().values()) or 1
    except Exception:  # the window is a bound, not a promise: any size works
        return int(args.workers)


def _quiet() -> None:
    """Nothing distributed logs from here on is news: closing with tasks in flight makes it
    say so per task (issue 43: ~12,000 lines of stderr on Ctrl-C at 100k runs)."""
    logging.disable(logging.CRITICAL)


def _exit_now() -> NoReturn:
    """A second Ctrl-C: the local workers killed, exit 130 without waiting for anything."""
    import multiprocessing

    for child in multiprocessing.active_children():
        with contextlib.suppress(Exception):
            child.kill()
    os.write(2, b"ads-rca batch: interrupted again: exiting now\n")
    os._exit(EXIT_INTERRUPTED)


def _outcome(future: Any, job: Job) -> Outcome:
    """The task's answer, or a row saying why there is none (its worker died too often)."""
    try:
        outcome = future.result()
    except Exception as error:
        name = type(error).__name__
        message = f"{name}: {error}" if name != "KilledWorker" else "its worker died every try"
        return Outcome(error_row(job.run_id, job.path, message), None)
    assert isinstance(outcome, Outcome)
    return outcome


@contextmanager
def _client(args: argparse.Namespace) -> Iterator[Any]:
    """A client of ``--scheduler``, or of a new local cluster on loopback; closed at exit."""
    import dask
    from distributed import Client, LocalCluster

    cluster = None
    client = None
    try:
        with dask.config.set(
            {**DASK_CONFIG, "distributed.scheduler.allowed-failures": args.retries}
        ):
            if args.scheduler:
                try:
                    client = Client(args.scheduler, timeout=CONNECT_TIMEOUT)
                except (OSError, TimeoutError) as error:
                    raise InputError(
                        f"--scheduler {printable(args.scheduler)}: cannot connect ({error})"
                    ) from None
            else:
                # Workers start with SIGINT ignored (inherited through spawn): a Ctrl-C
                # at the terminal reaches the whole process group, and only this process
                # should act on it (closing the cluster), not print a worker's traceback.
                with _no_interrupt():
                    cluster = LocalCluster(
                        n_workers=args.workers,
                        threads_per_worker=1,
                        processes=True,
                        host="127.0.0.1",
                        dashboard_address="127.0.0.1:0",  # None still starts one on :8787
                        # A run's failure is its row; what a worker logs on its own is
                        # no news, and while the cluster closes it is a scheduler gone
                        # (a heartbeat's traceback on a loaded machine, after Ctrl-C).
                        silence_logs=logging.CRITICAL,
                    )
                client = Client(cluster)
            yield client
    finally:
        _quiet()  # what closing logs (tasks cancelled, workers gone) is no news
        try:
            if client is not None:
                client.close(timeout=CLOSE_TIMEOUT)
            if cluster is not None:
                cluster.close(timeout=CLOSE_TIMEOUT)
        finally:
            logging.disable(logging.NOTSET)


@contextmanager
def _no_interrupt() -> Iterator[None]:
    """SIGINT ignored in the block: the local workers started in it inherit that."""
    try:
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    except ValueError:  # not the main thread
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def _progress(total: int) -> Callable[..., None]:
    """A bar on a terminal (stderr) only; ``update(done=True)`` closes it."""
    if not sys.stderr.isatty():
        return lambda done=False: None
    from tqdm import tqdm

    bar = tqdm(total=total, desc="runs", unit="run", file=sys.stderr, leave=False)

    def update(done: bool = False) -> None:
        if done:
            bar.close()
        else:
            bar.update(1)

    return update
