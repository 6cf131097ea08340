"""A program that opened a Zenoh session ends without finalizing the interpreter.

Zenoh's native threads outlive every session. One that takes the GIL while the interpreter
finalizes is ended by Python with ``pthread_exit``, whose unwinding through Rust frames
aborts the process (SIGABRT, "FATAL: exception not rethrown") after the command's work was
done: CI once saw ``watch --exit-on-verdict`` end that way. The window is narrow in the
product, so this test opens it wide and on purpose: a thread still inside a Zenoh query when
``main`` returns (it waits on a real queryable, in a second real session, that never
answers). Without the quick exit the process aborts every time.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap

from loopback import free_port

from ads_rca.foundation import quick_exit
from ads_rca.remote.client import RemoteClient

PROGRAM = textwrap.dedent(
    """
    import atexit, sys, threading, time
    from ads_rca.foundation import quick_exit
    from ads_rca.remote.client import RemoteClient

    atexit.register(lambda: print("TEARDOWN RAN", file=sys.stderr))
    endpoint = sys.argv[1]
    KEPT = []

    def main() -> int:
        client = RemoteClient((), "car1", mode="peer", listen=(endpoint,)).open()
        # A queryable that never answers, kept until the very end; the subscriber's thread
        # is no daemon (the interpreter would wait for it for ever): it goes.
        KEPT.append(client._session.declare_queryable("car1/ads_rca/status"))
        client._subscriber.undeclare()
        asking = threading.Thread(target=client.catch_up, kwargs={"timeout": 30.0}, daemon=True)
        asking.start()
        time.sleep(0.5)  # the query is on its way and waits for a reply
        assert asking.is_alive()
        print("RETURNING", flush=True)
        return 0

    quick_exit.run_program(main)
    """
)


def test_a_program_with_a_zenoh_query_in_flight_ends_cleanly() -> None:
    for _ in range(3):
        endpoint = f"tcp/127.0.0.1:{free_port()}"
        done = subprocess.run(
            [sys.executable, "-c", PROGRAM, endpoint],
            capture_output=True,
            text=True,
            timeout=60,
            check=False,
        )
        assert done.stdout == "RETURNING\n", done.stderr
        assert done.returncode == 0, done.stderr  # -6 (SIGABRT) without the quick exit
        assert "FATAL" not in done.stderr and "TEARDOWN RAN" not in done.stderr


def test_a_session_opened_in_process_leaves_the_interpreter_alone() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with RemoteClient((endpoint,), "car1", mode="peer", listen=(endpoint,)):
        pass
    assert not quick_exit.requested()  # a test or another program calling us goes on
