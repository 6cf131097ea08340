"""A process-group leader, as a terminal's shell is: starts commands in its own group.

``python pgroup.py SPEC.json``: SPEC holds ``{"out": DIR, "commands": {name: argv}}``. Every
command starts in this process's group (so a signal to the group reaches all of them at
once, as Ctrl-C in a terminal does), its output goes to ``DIR/<name>.out``; when all have
ended, their exit statuses are written to ``DIR/codes.json``. The leader itself survives the
group's SIGINT/SIGTERM (a no-op handler, which, unlike SIG_IGN, children do not inherit).
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path


def main() -> int:
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda signum, frame: None)
    spec = json.loads(Path(sys.argv[1]).read_text())
    out = Path(spec["out"])
    processes = {}
    for name, argv in spec["commands"].items():
        with (out / f"{name}.out").open("w") as sink:
            processes[name] = subprocess.Popen(argv, stdout=sink, stderr=subprocess.STDOUT)
    codes = {name: process.wait() for name, process in processes.items()}
    (out / "codes.json").write_text(json.dumps(codes))
    return 0


if __name__ == "__main__":
    sys.exit(main())
