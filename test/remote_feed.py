"""A run's results on Zenoh without ROS: the bridge's Zenoh side fed from the simulated graph.

Usage: ``python test/remote_feed.py LOG_FOLDER --listen tcp/127.0.0.1:PORT [--prefix P]
[--pace S] [--hold S] [--run ID]``. Plays ``LOG_FOLDER`` through the live cores in memory (the same
classes the nodes run), then puts every monitor result (``--pace`` seconds apart) and the
verdict through :class:`~ads_rca.remote.publisher.ZenohPublisher`, heartbeats while it
holds, and answers the queryables for ``--hold`` seconds (or until SIGTERM). ``--run``
names the graph's run id in every result and the verdict, as a replay's graph does. Prints
``READY`` once listening and ``VERDICT`` after the verdict is put. Tests of ``watch`` and
``dashboard`` use it where a full ROS graph adds nothing.
"""

from __future__ import annotations

import argparse
import signal
import sys
import time
from pathlib import Path

from ads_rca.contract.jsontext import dumps_json
from ads_rca.live.simulate import run_live
from ads_rca.params import make_params
from ads_rca.remote.publisher import ZenohPublisher
from ads_rca.remote.state import RemoteState
from ads_rca.sources.log.reader import read_run_log


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("log", type=Path)
    parser.add_argument("--listen", required=True)
    parser.add_argument("--prefix", default="")
    parser.add_argument("--pace", type=float, default=0.0)
    parser.add_argument("--hold", type=float, default=60.0)
    parser.add_argument("--start-after", type=float, default=0.0)
    parser.add_argument("--run", default="")
    args = parser.parse_args()
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    run = run_live(read_run_log(args.log), make_params("corrected"))
    assert run.outcome is not None
    # As a replay publishes them: the provisional results as the run plays, the final
    # ones once the collision frame is in (docs/live-graph.md "Provisional results").
    results = sorted(
        (r for module_results in run.results.values() for r in module_results),
        key=lambda r: (not r.provisional, r.index, r.module),
    )
    publisher = ZenohPublisher(RemoteState(args.prefix), listen=[args.listen]).open()
    try:
        print("READY", flush=True)
        time.sleep(args.start_after)
        for result in results:
            document = result.to_document()
            if args.run:
                document["run"] = args.run
            publisher.on_result(dumps_json(document))
            publisher.tick(heartbeat=False)
            if args.pace:
                time.sleep(args.pace)
        verdict = run.outcome.document
        if args.run:
            verdict = {**verdict, "live": {**verdict.get("live", {}), "run": args.run}}
        publisher.on_verdict(dumps_json(verdict))
        publisher.finish("verdict")
        print("VERDICT", flush=True)
        end = time.monotonic() + args.hold
        while time.monotonic() < end:
            time.sleep(0.5)
            publisher.tick(heartbeat=True, state="verdict")
    finally:
        publisher.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
