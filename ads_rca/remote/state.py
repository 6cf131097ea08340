"""What the Zenoh bridge forwards and remembers, without zenoh or rclpy.

The bridge node hands every monitor result (``metrics/<module>``, a LiveResult's JSON) and
the verdict document (``verdict/json``) to :class:`RemoteState`, which answers with the JSON
samples to put on Zenoh (rate-limited per key; the verdict and the status never dropped)
and keeps what a late dashboard asks the queryables for: the verdict, the status and the
bounded frame history. Every document it sends is strict JSON (no NaN: ``strictjson``).
A message that is not a result or a verdict is counted and its one-line reason kept; it is
never forwarded.

The verdict is held until every result it was decided on has been forwarded (per module,
as many as its ``live.results_received`` counts), at most :data:`VERDICT_HOLD_S`. Why: the
bridge takes one message per topic and turn, so with results still queued (CI: 81 planning
results) the verdict, decided once the aggregator had them all, overtook them, and a
dashboard that stops at the verdict never saw them.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import orjson

from ads_rca.contract.errors import DOCUMENT_ERRORS, MalformedMessage
from ads_rca.foundation import strictjson
from ads_rca.live.results import LiveResult
from ads_rca.oracles.base import MODULES
from ads_rca.remote.history import History, parse_since
from ads_rca.remote.keys import check_prefix, dashboard_key, sample_key
from ads_rca.remote.rate import RateLimiter

#: A sample to put: key expression and strict JSON text.
Put = tuple[str, str]
#: What reading a message may raise (deep nesting: RecursionError).
READ_ERRORS: tuple[type[Exception], ...] = (MalformedMessage, RecursionError, *DOCUMENT_ERRORS)
#: Longest reason kept for a malformed message.
REASON_CHARS = 200
#: Longest a verdict waits for the results it counts (a bridge started late never gets
#: them all: the verdict goes out then, and the status says how many were missing).
VERDICT_HOLD_S = 5.0


class RemoteState:
    """The bridge's dashboard-side state for one prefix."""

    def __init__(
        self,
        prefix: str,
        capacity: int = 2000,
        rates: Mapping[str, float] | None = None,
        run: str = "",
    ) -> None:
        self.prefix = check_prefix(prefix)
        #: Forward only this run's results and verdict ("" = any run): the graph's other
        #: runs sharing the domain and namespace are counted in ``other_runs``.
        self.run = run
        self.other_runs = 0
        #: Published samples' keys.
        self.verdict_key = sample_key(self.prefix, "verdict")
        self.status_key = sample_key(self.prefix, "status")
        #: The queryables' keys.
        self.queries = {
            kind: dashboard_key(self.prefix, kind) for kind in ("verdict", "status", "frames")
        }
        self.history = History(capacity)
        limits: dict[str, float] = {}
        for name, rate in (rates or {}).items():
            if name == "modules":  # each module's key on its own: no burst replaces another's
                limits.update({self.module_key(m): rate for m in MODULES})
            else:
                limits[sample_key(self.prefix, *name.split("/"))] = rate
        self.limiter: RateLimiter[str] = RateLimiter(
            limits, frozenset({self.verdict_key, self.status_key})
        )
        self.results: dict[str, int] = {}
        self.malformed = 0
        self.last_problem = ""
        self.verdict: dict[str, Any] | None = None
        #: A verdict waiting for the results it counts, and since when.
        self._held: tuple[dict[str, Any], float] | None = None
        #: Results the last verdict counted that had not come when it went out.
        self.verdict_ahead = 0
        self.last_index = -1

    def module_key(self, module: str) -> str:
        return sample_key(self.prefix, "modules", module)

    def on_result(self, text: str | bytes, now: float) -> list[Put]:
        """A monitor's result: kept in its frame's history entry and sent on the module's
        key (rate-limited)."""
        try:
            # Twice with orjson (a few µs): the strict form is kept and sent as it came (no
            # walk over it), the plain one is read, which checks it is a result.
            document = _strict_object(text)
            result = LiveResult.from_document(strictjson.from_strict(_strict_object(text)))
        except READ_ERRORS as error:
            self._malformed("result", error)
            return []
        if self.run and result.run and result.run != self.run:
            self.other_runs += 1
            return []
        entry = self.history.frame(result.index) or {
            "index": result.index,
            "frame": document.get("frame"),
            "stamp_ms": result.stamp_ms,
            "modules": {},
        }
        entry["modules"][result.module] = document
        self.history.add_frame(result.index, entry)
        if not result.provisional:  # as the aggregator counts (a verdict is held for these)
            self.results[result.module] = self.results.get(result.module, 0) + 1
        self.last_index = max(self.last_index, result.index)
        puts = self.limiter.offer(self.module_key(result.module), _dumps(document), now)
        return puts + self._release(now) if self._held is not None else puts

    def on_verdict(self, text: str | bytes, now: float) -> list[Put]:
        """The aggregator's verdict document (the ``diagnose --json`` contract): kept and
        sent, never rate-limited."""
        try:
            document = _document(text)
        except READ_ERRORS as error:
            self._malformed("verdict", error)
            return []
        if "primary_root_cause" not in document:
            self._malformed("verdict", ValueError("no primary_root_cause"))
            return []
        live = document.get("live")
        run = live.get("run") if isinstance(live, dict) else None
        if self.run and isinstance(run, str) and run and run != self.run:
            self.other_runs += 1
            return []
        self._held = (document, now)
        return self._release(now)

    def _missing(self, document: Mapping[str, Any]) -> int:
        """Results ``document`` counts (its ``live.results_received``) not forwarded yet."""
        live = document.get("live")
        counted = live.get("results_received") if isinstance(live, dict) else None
        if not isinstance(counted, dict):
            return 0
        return sum(
            max(0, n - self.results.get(str(m), 0))
            for m, n in counted.items()
            if isinstance(n, int) and not isinstance(n, bool)
        )

    def _release(self, now: float, force: bool = False) -> list[Put]:
        """The held verdict's sample once its results are out, or it waited long enough."""
        if self._held is None:
            return []
        document, since = self._held
        missing = self._missing(document)
        if missing and not force and now - since < VERDICT_HOLD_S:
            return []
        self._held, self.verdict, self.verdict_ahead = None, document, missing
        return self.limiter.offer(self.verdict_key, strictjson.dumps(document), now)

    def status(self, now: float, state: str = "running") -> dict[str, Any]:
        """The heartbeat: what was seen so far; ``stopped`` wins over a verdict (the bridge
        is gone; the verdict stays on its own key)."""
        if state != "stopped" and self.verdict is not None:
            state = "verdict"
        return {
            "state": state,
            "run": self.run,
            "time": now,
            "last_index": self.last_index,
            "frames_held": len(self.history),
            "frames_evicted": self.history.evicted,
            "results": dict(self.results),
            "malformed": self.malformed,
            "verdict_ahead_of_results": self.verdict_ahead,
            "other_runs": self.other_runs,
            "last_problem": self.last_problem,
        }

    def heartbeat(self, now: float, state: str = "running") -> list[Put]:
        return self.limiter.offer(self.status_key, strictjson.dumps(self.status(now, state)), now)

    def flush(self, now: float, force: bool = False) -> list[Put]:
        """Rate-limited samples now due (every one with ``force``), and a held verdict
        whose wait is over (with ``force``, at once)."""
        return self.limiter.flush(now, force) + self._release(now, force)

    def answer(self, key: str, parameters: Mapping[str, str], now: float) -> str | None:
        """A queryable's reply for ``key`` (None: nothing to say yet, or not ours)."""
        if key == self.queries["verdict"]:
            return None if self.verdict is None else strictjson.dumps(self.verdict)
        if key == self.queries["status"]:
            return strictjson.dumps(self.status(now))
        if key == self.queries["frames"]:
            since = parse_since(parameters)
            # Every kept result is already strict (its own ``$nonfinite`` inside).
            return _dumps({"since": since, "frames": self.history.since(since)})
        return None

    def _malformed(self, what: str, error: BaseException) -> None:
        self.malformed += 1
        text = str(error).encode("unicode_escape").decode("ascii")
        self.last_problem = f"{what}: {text[:REASON_CHARS]}"


def _strict_object(text: str | bytes) -> dict[str, Any]:
    """A strict JSON object, parsed as it is (NaN literals refused, ``$nonfinite`` kept)."""
    document = orjson.loads(text)
    if not isinstance(document, dict):
        raise MalformedMessage("not a JSON object")
    return document


def _dumps(document: object) -> str:
    """Compact text of a document that is strict already."""
    return orjson.dumps(document).decode("utf-8")


def _document(text: str | bytes) -> dict[str, Any]:
    """A JSON object from a message's text (strict JSON's conventions undone)."""
    document = strictjson.loads(text)
    if not isinstance(document, dict):
        raise ValueError("not a JSON object")
    return document
