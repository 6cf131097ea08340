"""Breaks chosen oracles in every Python process started with this folder on PYTHONPATH.

Why: an oracle that raises is a bug in our own code, never an input problem
(docs/verdicts.md), and every output must say so: ``diagnose`` (its forked workers
inherit the patch), and the live graph, whose monitor processes inherit the environment
of ``replay``. The product has no test hook: the oracle tables of both semantics modes
(``SEMANTICS.oracles``, one dict each) are patched from outside, at interpreter start.

``ADS_RCA_TEST_RAISING``: the modules whose oracle raises, comma-separated (``all``: the
four); unset or empty: nothing is patched.
"""

from __future__ import annotations

import os

#: The environment variable naming the modules to break.
VARIABLE = "ADS_RCA_TEST_RAISING"
#: The error every broken oracle raises (its type and message appear in every output).
MESSAGE = "deliberate test failure"


def _patch(wanted: str) -> None:
    from ads_rca.oracles import corrected, reference
    from ads_rca.oracles.base import MODULES, OracleResult, RunContext

    modules = MODULES if wanted == "all" else tuple(m.strip() for m in wanted.split(","))

    def broken(ctx: RunContext, ts: int) -> OracleResult:
        raise ZeroDivisionError(MESSAGE)

    for semantics in (corrected.SEMANTICS, reference.SEMANTICS):
        for module in modules:
            semantics.oracles[module] = broken  # type: ignore[index]


if os.environ.get(VARIABLE, ""):
    _patch(os.environ[VARIABLE])
