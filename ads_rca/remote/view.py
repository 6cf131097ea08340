"""What a remote dashboard knows about the runs it watches, without zenoh, rclpy or a UI.

``ads-rca watch`` and ``ads-rca dashboard`` both feed every Zenoh sample (key and payload)
and every queryable reply into one :class:`DashboardModel`, and draw from it. A run is the
prefix in front of ``ads_rca/`` in a key, so several runs (one per prefix) are told apart.
Nothing from the wire is trusted: a key that is not one of ours, a payload that is too big,
not strict JSON or not an object, or a module that is not one of ours is counted as a
problem and dropped; kept documents are bounded in number. Drawing code must still escape
every string (they come from logs).

A verdict is read as docs/verdicts.md says (:func:`read_verdict`, :func:`module_state`): an
inconclusive verdict is never drawn as "no fault found", a module not judged, partly judged
or whose check raised is drawn as such, and a verdict whose conclusion fields have the wrong
type is refused like any malformed sample (:func:`check_verdict`). A verdict that does not
say ``conclusive`` at all (a bridge older than the rule) is read as not conclusive: nothing
checked that its evidence was whole, and "no fault found" is the one answer a diagnosis
must not give by default.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import orjson

from ads_rca.capabilities import JUDGED, NOT_JUDGED
from ads_rca.contract.errors import MalformedMessage
from ads_rca.diagnosis.conclusion import (
    COLLISION_NO,
    COLLISION_UNKNOWN_STATE,
    COLLISION_YES,
    PARTLY_JUDGED,
)
from ads_rca.live.runid import RUN_ID_PATTERN
from ads_rca.oracles.base import MODULES
from ads_rca.remote.keys import DASHBOARD_ROOT, SAMPLE_SUFFIX

#: The queryables a dashboard asks on connecting.
QUERIES = ("verdict", "status", "frames")
#: Largest verdict or frames reply accepted (a verdict carries every frame, about 2.5 kB
#: each: 64 MiB holds a run of about 25,000 frames, 21 minutes at 20 Hz).
MAX_PAYLOAD = 64 * 1024 * 1024
#: Largest module result or heartbeat accepted (a result is a few kB).
MAX_SMALL_PAYLOAD = 1024 * 1024
#: Verdict documents kept for download, all runs together (bytes as received); past it the
#: documents of the runs updated longest ago are let go (their digests stay).
MAX_VERDICT_BYTES = 256 * 1024 * 1024
#: Clearance points kept per run for the timeline.
TIMELINE_POINTS = 5000
#: Near-miss warnings kept per run.
NEAR_MISSES = 50
#: Metrics read as "clearance" for the timeline and the near-miss warning, first found wins.
CLEARANCE_METRICS = ("c_gt", "clearance", "min_clearance")
#: Near-miss margin when a result names no ``safety_margin`` threshold (m).
DEFAULT_MARGIN = 0.5
#: Runs tracked at once (the oldest-updated is forgotten beyond it).
MAX_RUNS = 64
#: Wall-clock span over which the frame rate is measured (s).
RATE_SPAN = 5.0
#: The shortest span a rate is measured over (s): a burst is not a rate.
RATE_MIN_SPAN = 1.0
#: The name of the run with neither a prefix nor a run id (:func:`run_name`).
ROOT_NAME = "@"
#: ``collision`` of a verdict (docs/verdicts.md).
COLLISION_STATES = (COLLISION_YES, COLLISION_NO, COLLISION_UNKNOWN_STATE)
#: What a verdict says, as every dashboard names it: a root cause named (conclusive or
#: not), a conclusive "no fault found", or inconclusive without a root cause.
ROOT_CAUSE, NO_FAULT_FOUND, INCONCLUSIVE = "root cause", "no fault found", "inconclusive"
#: The reason given for a verdict that does not say whether it is conclusive.
UNSTATED = "the verdict does not say whether it is conclusive (an ads_rca older than the rule)"
#: A module's state in a dashboard's table (:func:`module_state`; also ``NOT_JUDGED`` and
#: ``PARTLY_JUDGED``).
WAITING, OK, FAILING, SKIPPED = "waiting", "ok", "failing", "skipped"
INCOMPLETE = "incomplete inputs"
INTERNAL_ERROR = "internal error"
#: A module the verdict names as a root cause: never shown "ok" because its latest frame
#: passed (the failure that decided is in the effect window, not at the run's end).
BLAMED = "root cause"


def parse_key(key: str) -> tuple[str, str, str | None] | None:
    """``(prefix, kind, module)`` of a dashboard key: a sample's (``<prefix>/ads_rca/
    verdict.json``, ``status.json``, ``modules/<module>.json``) or a queryable reply's
    (``verdict``, ``status``, ``frames``); None when it is not one (a raw CDR key)."""
    sample = key.endswith(SAMPLE_SUFFIX)
    chunks = (key[: -len(SAMPLE_SUFFIX)] if sample else key).split("/")
    for at in range(len(chunks) - 1, -1, -1):
        if chunks[at] != DASHBOARD_ROOT:
            continue
        rest = chunks[at + 1 :]
        prefix = "/".join(chunks[:at])
        if len(rest) == 1 and rest[0] in (("verdict", "status") if sample else QUERIES):
            return prefix, rest[0], None
        if sample and len(rest) == 2 and rest[0] == "modules" and rest[1] in MODULES:
            return prefix, "modules", rest[1]
    return None


def payload_limit(key: str) -> int:
    """The largest payload taken for ``key``, judged from the key alone (before anything is
    decoded or queued): verdicts and frames replies :data:`MAX_PAYLOAD`, the rest (module
    results, heartbeats, keys that are not ours) :data:`MAX_SMALL_PAYLOAD`."""
    parsed = parse_key(key)
    return (
        MAX_PAYLOAD
        if parsed is not None and parsed[1] in ("verdict", "frames")
        else (MAX_SMALL_PAYLOAD)
    )


def _number(value: object) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    number = float(value)
    return number if math.isfinite(number) else None


def clearance_of(document: Mapping[str, Any]) -> float | None:
    """The true clearance a result reports (m), None when it reports none."""
    metrics = document.get("metrics")
    if not isinstance(metrics, Mapping):
        return None
    for name in CLEARANCE_METRICS:
        found = _number(metrics.get(name))
        if found is not None:
            return found
    return None


def margin_of(document: Mapping[str, Any]) -> float:
    thresholds = document.get("thresholds")
    if isinstance(thresholds, Mapping):
        found = _number(thresholds.get("safety_margin"))
        if found is not None:
            return found
    return DEFAULT_MARGIN


def run_of(kind: str, document: Mapping[str, Any]) -> str:
    """The graph's run id a document names ("" if none): a result's and the status's
    ``run``, the verdict's ``live.run``. A run that is no run id (``live/runid.py``: it
    could never come from a graph) is refused (:class:`MalformedMessage`)."""
    if kind == "verdict":
        live = document.get("live")
        found = live.get("run") if isinstance(live, Mapping) else None
    else:
        found = document.get("run")
    if found is None or found == "":
        return ""
    if not isinstance(found, str) or not RUN_ID_PATTERN.fullmatch(found):
        raise MalformedMessage("run is not a run id (1 to 64 letters, digits or '_')")
    return found


def run_name(prefix: str, run_id: str) -> str:
    """A run's name among the dashboards' runs and in URLs: its prefix (``@`` for none),
    then ``@<run id>`` when its documents name one. Unique: neither a run id nor a prefix
    the model keeps holds ``@``."""
    if run_id:
        return f"{prefix}@{run_id}"
    return prefix or ROOT_NAME


def _texts(value: object) -> bool:
    return isinstance(value, list) and all(isinstance(item, str) for item in value)


#: The verdict fields a dashboard shows, and the shapes it can show them in (a field that
#: is absent is no error; one of another shape drops the verdict).
_TEXT_OR_NULL = ("primary_root_cause", "attribution_basis", "semantics", "verdict")
_TEXT_LISTS = ("root_causes", "contributing")
_OBJECTS = ("thresholds", "evidence", "modules")


def check_verdict(document: Mapping[str, Any]) -> None:
    """Refuse (:class:`MalformedMessage`) a verdict a dashboard cannot read safely: no
    ``primary_root_cause``, a field it shows of another shape (``primary_root_cause`` an
    object...), or conclusion fields (docs/verdicts.md) of the wrong type or contradicting
    each other. A missing conclusion field is no error (:func:`read_verdict`)."""
    if "primary_root_cause" not in document:
        raise MalformedMessage("verdict without primary_root_cause")
    for name in _TEXT_OR_NULL:
        if document.get(name) is not None and not isinstance(document[name], str):
            raise MalformedMessage(f"verdict: {name} is not a text or null")
    for name in _TEXT_LISTS:
        if name in document and not _texts(document[name]):
            raise MalformedMessage(f"verdict: {name} is not a list of texts")
    for name in _OBJECTS:
        if name in document and not isinstance(document[name], dict):
            raise MalformedMessage(f"verdict: {name} is not an object")
    frame = document.get("collision_frame")
    if frame is not None and (not isinstance(frame, int) or isinstance(frame, bool)):
        raise MalformedMessage("verdict: collision_frame is not an integer or null")
    partner = document.get("partner_id")
    if (partner is not None and not isinstance(partner, str | int)) or isinstance(partner, bool):
        raise MalformedMessage("verdict: partner_id is not a text, an integer or null")
    conclusive = document.get("conclusive")
    if "conclusive" in document and not isinstance(conclusive, bool):
        raise MalformedMessage("verdict: conclusive is not true or false")
    if "why_inconclusive" in document and not _texts(document["why_inconclusive"]):
        raise MalformedMessage("verdict: why_inconclusive is not a list of texts")
    if "collision" in document and document["collision"] not in COLLISION_STATES:
        raise MalformedMessage("verdict: collision is not yes, no or unknown")
    errors = document.get("internal_errors", [])
    if not isinstance(errors, list) or not all(isinstance(e, dict) for e in errors):
        raise MalformedMessage("verdict: internal_errors is not a list of objects")
    judged = document.get("modules_judged", {})
    if not isinstance(judged, dict) or not all(isinstance(v, str) for v in judged.values()):
        raise MalformedMessage("verdict: modules_judged is not an object of texts")
    if conclusive is True and (document.get("why_inconclusive") or errors):
        raise MalformedMessage("verdict: conclusive, yet it lists why not or internal errors")


@dataclass(frozen=True)
class VerdictReading:
    """What a dashboard may say of a checked verdict (docs/verdicts.md)."""

    #: :data:`ROOT_CAUSE`, :data:`NO_FAULT_FOUND` or :data:`INCONCLUSIVE`.
    kind: str
    conclusive: bool
    #: The verdict says whether it is conclusive (False: an older bridge's verdict).
    stated: bool
    #: Why it is not conclusive, in words (empty when it is).
    reasons: tuple[str, ...]
    #: ``yes``, ``no`` or ``unknown``.
    collision: str
    #: The verdict sentence to show: never "no fault found" unless conclusive.
    text: str

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "conclusive": self.conclusive,
            "stated": self.stated,
            "reasons": list(self.reasons),
            "collision": self.collision,
            "text": self.text,
        }


def read_verdict(document: Mapping[str, Any]) -> VerdictReading:
    """How a verdict :func:`check_verdict` accepted is shown. Without ``conclusive`` it is
    not conclusive (:data:`UNSTATED`); without ``collision``, a collision frame other than
    -1 is a collision and -1 is unknown (an older verdict said "no collision" unchecked)."""
    stated = isinstance(document.get("conclusive"), bool)
    conclusive = document.get("conclusive") is True
    reasons = tuple(document.get("why_inconclusive") or ()) if stated else (UNSTATED,)
    if not conclusive and not reasons:
        reasons = ("the verdict gives no reason",)
    collision = document.get("collision")
    if collision not in COLLISION_STATES:
        frame = document.get("collision_frame")
        known = isinstance(frame, int) and not isinstance(frame, bool) and frame != -1
        collision = COLLISION_YES if known else COLLISION_UNKNOWN_STATE
    primary = document.get("primary_root_cause")
    sent = document.get("verdict")
    text = sent if isinstance(sent, str) else ""
    if primary:
        kind = ROOT_CAUSE
        text = text or str(primary)
    elif conclusive:
        kind = NO_FAULT_FOUND
        text = text or NO_FAULT_FOUND
    else:
        kind = INCONCLUSIVE
        if not text.startswith(INCONCLUSIVE):  # an older verdict's "no fault found"
            text = f"{INCONCLUSIVE}: {'; '.join(reasons)}"
    return VerdictReading(kind, conclusive, stated, () if conclusive else reasons, collision, text)


def module_state(latest: Mapping[str, Any] | None, verdict_status: object) -> tuple[str, str]:
    """A module's ``(state, detail)`` in a dashboard's table: the verdict's status when it
    is not ``judged`` (not judged, partly judged, internal error: final for the run), else
    its latest result's (waiting, failing, internal error, not judged, skipped, judged on
    incomplete inputs, ok). ``detail`` is the status in words (a skip: its reason)."""
    if isinstance(verdict_status, str) and verdict_status != JUDGED:
        if f"{INTERNAL_ERROR} (" in verdict_status:
            return INTERNAL_ERROR, verdict_status
        if verdict_status.startswith(PARTLY_JUDGED):
            return PARTLY_JUDGED, verdict_status
        return NOT_JUDGED, verdict_status
    if latest is None:
        return WAITING, ""
    error = latest.get("internal_error")
    if isinstance(error, str) and error:
        return INTERNAL_ERROR, f"{INTERNAL_ERROR} ({error})"
    if latest.get("failed") is True:
        return FAILING, ""
    skipped = latest.get("skipped")
    if isinstance(skipped, str) and skipped.startswith(NOT_JUDGED):
        return NOT_JUDGED, skipped
    if skipped is not None and skipped is not False and skipped != "":
        return SKIPPED, skipped if isinstance(skipped, str) else str(skipped)
    if latest.get("missing_input") is True:
        return INCOMPLETE, ""
    return OK, ""


#: The metrics shown first for each module's latest result, when it has them; the list is
#: filled up to :data:`METRICS_SHOWN` with its other plain metrics, in its own order (a
#: result carries 20-30: the rest stay in the result, and in the page's tooltip).
KEY_METRICS: Mapping[str, tuple[str, ...]] = {
    "perception": ("recall", "precision", "mean_iou", "partner_matched"),
    "prediction": ("ade", "fde", "displacement_error", "miss_rate"),
    "planning": ("c_gt", "c_plan", "ttc_gt", "partner_in_planner_inputs"),
    "controller": (
        "tracking_failure",
        "speed_tracking_error",
        "lateral_tracking_error",
        "toward_partner",
    ),
}
METRICS_SHOWN = 4


def key_metric_names(module: str, metrics: Mapping[str, Any]) -> list[str]:
    """The names of the metrics a dashboard shows of a result (:data:`KEY_METRICS`)."""
    names = [n for n in KEY_METRICS.get(module, ()) if n in metrics]
    for name, value in metrics.items():
        if len(names) >= METRICS_SHOWN:
            break
        plain = value is None or isinstance(value, str | int | float)
        if name not in names and plain:
            names.append(name)
    return names[:METRICS_SHOWN]


def blamed(verdict: Mapping[str, Any] | None) -> set[str]:
    """The modules a (checked) verdict names as root causes: its primary and the rest."""
    if verdict is None:
        return set()
    named = verdict.get("root_causes")
    out = {m for m in named if m in MODULES} if isinstance(named, list) else set()
    primary = verdict.get("primary_root_cause")
    return out | ({primary} if primary in MODULES else set())


@dataclass
class RunView:
    """One run's state as a dashboard shows it."""

    prefix: str
    #: The graph's run id its documents name ("" until one does): each run under a prefix
    #: has a view of its own, so one run's samples never add to or erase another's.
    run_id: str = ""
    modules: dict[str, dict[str, Any]] = field(default_factory=dict)
    failures: dict[str, int] = field(default_factory=dict)
    judged: dict[str, int] = field(default_factory=dict)
    timeline: deque[tuple[int, float]] = field(
        default_factory=lambda: deque(maxlen=TIMELINE_POINTS)
    )
    near_misses: deque[dict[str, Any]] = field(default_factory=lambda: deque(maxlen=NEAR_MISSES))
    status: dict[str, Any] | None = None
    #: The verdict without its per-frame list (what every dashboard shows; the list can be
    #: tens of MB of objects), with the list's length in :attr:`verdict_frames`.
    verdict: dict[str, Any] | None = None
    verdict_frames: int | None = None
    #: The verdict as received, for download (None: none, or let go to bound memory:
    #: :data:`MAX_VERDICT_BYTES`).
    verdict_payload: bytes | None = None
    last_index: int = -1
    last_frame: Any = None
    updated: float = 0.0
    _seen: dict[tuple[str, int], int] = field(default_factory=dict)

    @property
    def name(self) -> str:
        """Its name among the runs and in URLs (:func:`run_name`)."""
        return run_name(self.prefix, self.run_id)

    _arrivals: deque[tuple[float, int]] = field(default_factory=lambda: deque(maxlen=4096))

    def add_result(self, module: str, document: dict[str, Any], now: float) -> None:
        """A module's result for one frame (a re-judged frame replaces its count)."""
        index = document.get("index")
        if not isinstance(index, int) or isinstance(index, bool):
            raise MalformedMessage("result without an integer index")
        self.modules[module] = document
        key = (module, index)
        failed = 1 if document.get("failed") is True else 0
        before = self._seen.get(key)
        if before is None:
            self.judged[module] = self.judged.get(module, 0) + 1
        self.failures[module] = self.failures.get(module, 0) + failed - (before or 0)
        self._seen[key] = failed
        if len(self._seen) > 4 * TIMELINE_POINTS:  # bounded: forget the oldest frames' flags
            for old in list(self._seen)[: len(self._seen) // 2]:
                del self._seen[old]
        if index > self.last_index:
            self.last_index = index
            self.last_frame = document.get("frame")
            self._arrivals.append((now, index))
        clearance = clearance_of(document)
        if clearance is not None and module == "planning":
            if not self.timeline or self.timeline[-1][0] < index:
                self.timeline.append((index, clearance))
            margin = margin_of(document)
            if before is not None:  # re-judged: its latest judgement is the one that counts
                self._forget_near_miss(index)
            if clearance < margin:
                self.near_misses.append(
                    {
                        "index": index,
                        "frame": document.get("frame"),
                        "module": module,
                        "clearance": clearance,
                        "margin": margin,
                    }
                )
        self.updated = now

    def _forget_near_miss(self, index: int) -> None:
        """Drop a frame's near miss (one frame is at most one near miss, however often the
        live graph re-judges it)."""
        kept = [near for near in self.near_misses if near["index"] != index]
        if len(kept) != len(self.near_misses):
            self.near_misses.clear()
            self.near_misses.extend(kept)

    def rate(self, now: float) -> float:
        """New analysed frames per second over the last :data:`RATE_SPAN` seconds (0:
        idle). The span runs to ``now`` and is at least a second: a burst (the end of a
        run judged at once, a catch-up) reads as the frames it brought per second, not
        as the frames over the milliseconds they took, and an idle run decays to 0."""
        recent = [(t, i) for t, i in self._arrivals if now - t <= RATE_SPAN]
        if len(recent) < 2:
            return 0.0
        span = max(now - recent[0][0], RATE_MIN_SPAN)
        return (recent[-1][1] - recent[0][1]) / span

    def summary(self, now: float) -> dict[str, Any]:
        """A JSON-ready digest: what a dashboard draws (every float finite or None)."""
        modules = {}
        judged = (self.verdict or {}).get("modules_judged") or {}
        for module in MODULES:
            latest = self.modules.get(module)
            state, detail = module_state(latest, judged.get(module))
            if state in (OK, FAILING) and module in blamed(self.verdict):
                was = "latest frame failing" if state == FAILING else "latest frame ok"
                state, detail = BLAMED, f"root cause in the verdict ({was})"
            modules[module] = {
                "judged": self.judged.get(module, 0),
                "failed_frames": self.failures.get(module, 0),
                "state": state,
                "detail": detail,
                # Judged before the collision partner was known (docs/live-graph.md).
                "provisional": latest is not None and latest.get("provisional") is True,
                # What a table shows of the latest result's metrics (the rest: on demand).
                "key_metrics": key_metric_names(module, metrics)
                if latest is not None and isinstance(metrics := latest.get("metrics"), dict)
                else [],
                "latest": None
                if latest is None
                else {
                    "index": latest.get("index"),
                    "frame": latest.get("frame"),
                    "failed": latest.get("failed") is True,
                    "skipped": latest.get("skipped"),
                    "internal_error": latest.get("internal_error"),
                    "missing_input": latest.get("missing_input") is True,
                    "metrics": latest.get("metrics"),
                },
            }
        return {
            "run": self.prefix,
            "run_id": self.run_id,
            "name": self.name,
            "last_index": self.last_index,
            "last_frame": self.last_frame,
            "rate": round(self.rate(now), 2),
            "modules": modules,
            "near_misses": list(self.near_misses),
            "status": self.status,
            "verdict": self.verdict,
            "updated": self.updated,
        }


class DashboardModel:
    """Every run seen, fed sample by sample (see the module doc). A run is a prefix and
    the run id its documents name: two graphs publishing under one prefix, or one stray
    sample naming another run, make two runs, never one reset view. A document naming no
    run (a bridge's status beside a stack, an older tool's result) goes to the prefix's
    run updated last; the first document naming a run adopts the prefix's unnamed run."""

    def __init__(self, prefix: str | None = None) -> None:
        self.only = prefix  # watch one prefix (None: every run)
        #: By :func:`run_name`.
        self.runs: dict[str, RunView] = {}
        self.problems = 0
        self.last_problem = ""

    def run(self, prefix: str, run_id: str = "") -> RunView:
        """The view of ``run_id`` under ``prefix`` (see the class doc), made if new."""
        if not run_id:
            latest = self.latest_under(prefix)
            if latest is not None:
                return latest
        view = self.runs.get(run_name(prefix, run_id))
        if view is not None:
            return view
        unnamed = self.runs.pop(run_name(prefix, ""), None)
        if unnamed is not None:
            unnamed.run_id = run_id
            self.runs[unnamed.name] = unnamed
            return unnamed
        if len(self.runs) >= MAX_RUNS:
            oldest = min(self.runs.values(), key=lambda v: v.updated)
            del self.runs[oldest.name]
        view = RunView(prefix, run_id)
        self.runs[view.name] = view
        return view

    def latest_under(self, prefix: str) -> RunView | None:
        """The run under ``prefix`` updated last (None: none)."""
        under = [view for view in self.runs.values() if view.prefix == prefix]
        return max(under, key=lambda view: view.updated) if under else None

    def find(self, name: str) -> RunView | None:
        """The run of that name; a bare prefix names its run updated last."""
        view = self.runs.get(name)
        if view is not None or "@" in name:
            return view
        return self.latest_under(name)

    def apply(self, key: str, payload: bytes | str, now: float) -> dict[str, Any] | None:
        """One sample or reply; the event it makes, or None when it was dropped (and
        counted as a problem) or not ours. An event has ``run`` (the prefix), ``kind`` and
        ``run_id`` and ``name`` (:func:`run_name`); a frames reply's, the names of the
        ``runs`` its results went to."""
        parsed = parse_key(key)
        if parsed is None:
            self._problem(f"not a dashboard key: {key[:80]!r}")
            return None
        prefix, kind, module = parsed
        if self.only is not None and prefix != self.only:
            return None
        if "@" in prefix:  # a Zenoh verbatim chunk: never a bridge's prefix (keys.py)
            self._problem(f"{key[:80]}: '@' in the prefix")
            return None
        limit = payload_limit(key)
        if len(payload) > limit:
            self._problem(f"{key[:80]}: payload larger than {limit} bytes")
            return None
        try:
            document = orjson.loads(payload)
        except orjson.JSONDecodeError as error:
            self._problem(f"{key[:80]}: not JSON ({str(error)[:80]})")
            return None
        if not isinstance(document, dict):
            self._problem(f"{key[:80]}: not a JSON object")
            return None
        try:
            if kind == "frames":
                return self._frames(prefix, document, now)
            view = self.run(prefix, run_of(kind, document))
            head = {"run": prefix, "run_id": view.run_id, "name": view.name}
            if kind == "modules":
                assert module is not None
                view.add_result(module, document, now)
                return {**head, "kind": "module", "module": module, "result": document}
            if kind == "verdict":
                check_verdict(document)
                frames = document.get("frames")
                view.verdict = {k: v for k, v in document.items() if k != "frames"}
                view.verdict_frames = len(frames) if isinstance(frames, list) else None
                raw = payload if isinstance(payload, bytes) else payload.encode()
                self._keep_verdict(view, raw)
                view.updated = now
                conclusive = read_verdict(document).conclusive
                return {**head, "kind": kind, kind: document, "conclusive": conclusive}
            view.status = document
            view.updated = now
            return {**head, "kind": kind, kind: document}
        except MalformedMessage as error:
            self._problem(f"{key[:80]}: {str(error)[:120]}")
            return None

    def _frames(self, prefix: str, document: dict[str, Any], now: float) -> dict[str, Any]:
        """A frames reply: each result goes to the run it names (a bridge beside a stack
        keeps several runs' frames)."""
        frames = document.get("frames")
        if not isinstance(frames, list):
            raise MalformedMessage("frames reply without a frames list")
        added = 0
        names: dict[str, None] = {}
        for entry in frames:
            modules = entry.get("modules") if isinstance(entry, dict) else None
            if not isinstance(modules, dict):
                raise MalformedMessage("frames entry without modules")
            for module, result in modules.items():
                if module in MODULES and isinstance(result, dict):
                    view = self.run(prefix, run_of("modules", result))
                    view.add_result(module, result, now)
                    names[view.name] = None
                    added += 1
        return {"run": prefix, "kind": "frames", "results": added, "runs": list(names)}

    def _keep_verdict(self, view: RunView, payload: bytes) -> None:
        """Keep ``payload`` for download, letting go of the documents of the runs updated
        longest ago while all of them together exceed :data:`MAX_VERDICT_BYTES` (twelve
        forged 10 MB verdicts once took a dashboard to 680 MB and a MemoryError)."""
        view.verdict_payload = payload
        kept = [v for v in self.runs.values() if v.verdict_payload is not None]
        total = sum(len(v.verdict_payload or b"") for v in kept)
        for old in sorted(kept, key=lambda v: v.updated):
            if total <= MAX_VERDICT_BYTES:
                break
            if old is view:
                continue
            total -= len(old.verdict_payload or b"")
            old.verdict_payload = None
        if total > MAX_VERDICT_BYTES:  # this one alone is over the bound
            view.verdict_payload = None

    def _problem(self, reason: str) -> None:
        self.problems += 1
        self.last_problem = reason.encode("unicode_escape").decode("ascii")[:200]

    def summary(self, now: float) -> dict[str, Any]:
        return {
            "runs": [self.runs[name].summary(now) for name in sorted(self.runs)],
            "problems": self.problems,
            "last_problem": self.last_problem,
        }
