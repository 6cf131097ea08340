"""Nodes started by our launcher die with it, however it ends.

Why: ``ads-rca replay`` (or a test) can be SIGKILLed, crash or be stopped by a service
manager; its nodes, in their own sessions, would then run forever under PID 1. The launcher
puts its pid in :data:`PARENT_VARIABLE`; a node calls :func:`die_with_parent` first thing,
which asks Linux for SIGTERM when the parent goes (``prctl(PR_SET_PDEATHSIG)``, which the
node's normal SIGTERM handling turns into a clean stop) and then checks the parent is still
the one that started it, in case it died before the request was made.

The signal is tied to the THREAD that forked the child: the launcher must start nodes from
a thread that lives as long as they do (``replay`` starts them from its main thread).
Elsewhere than Linux nothing happens. Pure Python: no rclpy import.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import signal
import sys

PARENT_VARIABLE = "ADS_RCA_PARENT_PID"
_PR_SET_PDEATHSIG = 1


def die_with_parent(environ: dict[str, str] | None = None) -> bool:
    """Arm the parent-death signal if a launcher started us; True when armed.

    A parent already gone (we were reparented) ends this process at once with SIGTERM.
    """
    value = (os.environ if environ is None else environ).get(PARENT_VARIABLE, "")
    if not value.isdigit() or not sys.platform.startswith("linux"):
        return False
    libc = ctypes.CDLL(ctypes.util.find_library("c"), use_errno=True)
    if libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0) != 0:
        return False
    if os.getppid() != int(value):
        os.kill(os.getpid(), signal.SIGTERM)
    return True
