"""Per-run facts the `corrected` oracles share, derived on first use and cached.

The oracles are per-frame functions ``(ctx, ts)`` that will also run in live monitors on a
bounded window of frames, so nothing here scans the whole log up front: the one per-run
fact is the collision partner (read at ``collision_frame``); before any collision a live
stack can ask for a provisional partner per timestamp instead (:meth:`CorrectedContext.
judge_without_collision`, the rule in :mod:`.threat`); everything else is derived
per timestamp from ts and the frames the rules look ahead to, and kept in small LRU caches
so the four oracles (and the control horizon's overlapping plans) build each thing once.

The caches live on a :class:`CorrectedContext` attached to the :class:`RunContext` as a
private attribute (``RunContext`` is a plain dataclass we do not own), so they die with it.
They assume the data at ts … ts + horizon is final when an oracle first asks for ts.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cached_property
from typing import Any, Generic, TypeVar, cast

import numpy as np
import numpy.typing as npt

from ads_rca.diagnosis.critical_event import explained_event
from ads_rca.foundation.geometry import FloatArray, box_signed_distance
from ads_rca.model import FOLDERS, EgoPose, Plan, Record, RunLog, Track
from ads_rca.oracles.base import RunContext
from ads_rca.oracles.cache import CACHE_SIZE, LRU, Carry, Slide
from ads_rca.oracles.corrected.boxes import (
    PlanData,
    Series,
    all_steps,
    build_plan,
    build_plans,
    build_predicted,
    key_steps,
)
from ads_rca.params import Params

V = TypeVar("V")
#: A rule that looks over the stack's own plan looks at most this far ahead (s), whatever
#: steps a plan names.
PLAN_HORIZON_MAX_S = 10.0


def window_terms(params: Params, frame_ms: int) -> dict[str, int]:
    """The window each parameter asks for, in frames: ``effect_time_window``, and
    ``window_s`` seconds at this frame period."""
    return {
        "effect_time_window": params.effect_time_window,
        "window_s": round(params.window_s * 1000.0 / frame_ms),
    }


def window_frames(params: Params, frame_ms: int) -> int:
    """W: ``effect_time_window`` frames, or ``window_s`` seconds when that is longer."""
    return max(window_terms(params, frame_ms).values())


def floor_span(params: Params, frame_ms: int) -> int:
    """Frames from the oldest floor frame of ts to ts (the noise-floor rule): W + L."""
    return window_frames(params, frame_ms) + round(params.noise_floor_s * 1000.0 / frame_ms)


class CacheName(Generic[V]):
    """A per-timestamp cache's name, typed by what it holds, so each oracle module's cache is
    typed where it is used although all of them live in one dict."""

    def __init__(self, name: str) -> None:
        self.name = name


#: World state tables (max gid + 1, 3): x, y, yaw (deg) by timestamp, NaN where an actor is
#: absent.
LOCATIONS: CacheName[FloatArray | None] = CacheName("locations")

#: Each timestamp's real series (:meth:`CorrectedContext.real_series`) and whose it is.
REAL_SERIES: CacheName[tuple[str, Series]] = CacheName("real_series")
_NO_POINT = np.full((1, 2), np.nan)
_NO_YAW = np.full(1, np.nan)

#: A partner rule for frames judged without a known collision: (context, ts) -> actor id.
PartnerRule = Callable[["CorrectedContext", int], "str | None"]


def no_partner(judging: CorrectedContext, ts: int) -> None:
    """Without a collision nobody is the partner (``ads-rca diagnose``, and live by default)."""
    return None


class CorrectedContext:
    """The `corrected` oracles' view of one run: parameters, identities and caches."""

    def __init__(self, ctx: RunContext) -> None:
        self.ctx = ctx
        self.log: RunLog = ctx.log
        self.params: Params = ctx.params
        self.frame_ms: int = ctx.log.frame_ms
        self.window: int = max(int(ctx.params.prediction_window), 1)
        self.ego_id: str | None = ctx.ego_id
        self._partner: tuple[int, str | None] | None = None
        self._provisional: PartnerRule = no_partner
        self.plans: LRU[int, PlanData | None] = LRU()
        #: Per-timestamp caches of the oracle modules, by name: each holds a frame's floor
        #: frames and look-ahead (the noise-floor rule), so a floor reads each sample once.
        self.caches: dict[str, LRU[int, object]] = {}
        self.cache_size = CACHE_SIZE + floor_span(self.params, self.frame_ms)
        #: The floors' sliding runs of per-frame values, by name (the noise-floor rule).
        self.slides: dict[str, Slide[object]] = {}
        self.ts_max = max(self.log.frames) if self.log.frames else 0
        #: The log's per-folder dicts by folder name (``RunLog.folder`` builds a dict per call).
        self.folders: dict[str, dict[int, Record]] = {
            name: self.log.folder(name) for name in FOLDERS
        }
        self._frame_set: tuple[tuple[int, ...], frozenset[int]] | None = None
        #: A run-wide integer for every actor id seen so far (grows as frames are read).
        self._gid: dict[str, int] = {}
        self._reported: dict[tuple[str, ...], dict[str, Any]] = {}

    @cached_property
    def ego_half(self) -> FloatArray:
        """The ego's half extent (x, y); NaN where it has none, reported when a check first
        needs it (a run no rule judges, e.g. a snapshot table, needs none: the live monitor,
        which asks each frame's partner, must not report what ``diagnose`` never looked at)."""
        extent = self.log.actor_extents.get(self.ego_id) if self.ego_id is not None else None
        if extent is None:
            self.ctx.report(
                "actors/", "ego extent", "the ego has no actor extent; clearances undefined"
            )
            return np.full(2, np.nan)
        return np.asarray(extent[:2], dtype=np.float64)

    def reported(self, names: tuple[str, ...]) -> dict[str, Any]:
        """A fresh ``{name: value}`` of the parameters ``names`` (the results' thresholds),
        copied from one made per context (every result of every frame reports them)."""
        found = self._reported.get(names)
        if found is None:
            found = self._reported[names] = self.params.values(names)
        return dict(found)

    # -- identities -------------------------------------------------------------------------
    @property
    def partner_id(self) -> str | None:
        """The collision partner (cached per collision frame; None without a collision)."""
        cf = self.log.metadata.collision_frame
        if self._partner is None or self._partner[0] != cf:
            event = explained_event(self.log.metadata) is not None
            partner = (self._event_partner() if event else find_partner(self)) if cf >= 0 else None
            self._partner = (cf, partner)
        return self._partner[1]

    def _event_partner(self) -> str | None:
        """At an event that is not a collision (a hard brake, a near miss, a time given),
        nothing touched the ego: the partner is the actor most threatening there (the rule
        of :mod:`.threat`), at the event's frame or the latest earlier one with actors."""
        from ads_rca.oracles.corrected.threat import most_threatening

        event_ms = self.log.metadata.collision_frame * self.frame_ms
        held = [ts for ts in self.log.unique_frames if ts <= event_ms and ts in self.log.actors]
        return most_threatening(self, held[-1]) if held else None

    def judge_without_collision(self, rule: PartnerRule) -> None:
        """Judge frames before any collision against ``rule``'s actor at each timestamp
        (a live stack, where the collision may never come): see :meth:`partner_at`."""
        self._provisional = rule

    def partner_at(self, ts: int) -> str | None:
        """The partner the oracles judge ts against: the collision partner once there is a
        collision, else the provisional rule's actor (None unless
        :meth:`judge_without_collision` set one)."""
        if self.log.metadata.collision_frame >= 0:
            return self.partner_id
        return self._provisional(self, ts)

    def cache(self, name: CacheName[V]) -> LRU[int, V]:
        """A named per-timestamp cache (created on first use)."""
        if name.name not in self.caches:
            self.caches[name.name] = LRU(self.cache_size)
        # The name's type parameter is the one promise about what its cache holds.
        return cast("LRU[int, V]", self.caches[name.name])

    def carried(
        self, name: CacheName[V], ts: int, sources: tuple[object, ...], compute: Callable[[], V]
    ) -> V:
        """``compute()``'s value at ts, carried from an earlier context of the run while
        it read the same ``sources`` (records, by identity; :attr:`RunContext.carried`),
        computed here when the run carries nothing."""
        store = self.ctx.carried
        if store is None:
            return compute()
        carry = store.get(name.name)
        if carry is None:
            carry = store[name.name] = Carry(self.cache_size)
        return cast("Carry[int, V]", carry).get(ts, sources, compute)

    def slide(self, name: CacheName[V]) -> Slide[V]:
        """A named sliding run of per-frame values (created on first use)."""
        if name.name not in self.slides:
            self.slides[name.name] = Slide()
        return cast("Slide[V]", self.slides[name.name])

    def seconds(self, index: int | npt.NDArray[np.int64]) -> FloatArray:
        """Time of horizon index i in seconds (frames × frame_ms / 1000)."""
        return np.asarray(index, dtype=np.float64) * (self.frame_ms / 1000.0)

    def frame_set(self) -> frozenset[int]:
        """The log's analysed frames as a set (rebuilt when a live window's frames change)."""
        frames = self.log.frames
        if self._frame_set is None or self._frame_set[0] is not frames:
            self._frame_set = (frames, frozenset(frames))
        return self._frame_set[1]

    def in_log(self, ts: int) -> bool:
        """Whether ``ts`` lies within the analysed span (missing data there is a problem)."""
        return ts <= self.ts_max

    def missing(self, folder: str, ts: int, what: str) -> None:
        """Report a missing input file needed at ``ts`` (once per file)."""
        self.ctx.report(self.log.file_of(folder, ts), "", f"missing ({what})", ts)

    # -- plans ------------------------------------------------------------------------------
    def plan(self, ts: int) -> PlanData | None:
        """The plan at ts with the ego's plan boxes, or None without a usable plan or pose."""
        return self.plans.get(ts, lambda: self._build_plan(ts))

    def plans_ahead(self, frames: list[int]) -> None:
        """Build the plans of ``frames`` not built yet in one go (:func:`build_plans`): those
        with a plan of integer keys and a pose (any other is left to :meth:`plan`, which
        reports what it must)."""
        plans = self.plans
        waypoints, poses = self.log.waypoints, self.log.pose
        todo = [
            u
            for u in frames
            if u not in plans
            and (plan := waypoints.get(u)) is not None
            and len(plan) > 0
            and u in poses
            and all_steps(plan.keys)
        ]
        if len(todo) < 2:
            return
        built = build_plans(
            [waypoints[u] for u in todo], [poses[u] for u in todo], self.ego_half, self.window
        )
        for u, data in zip(todo, built, strict=True):
            plans.put(u, data)

    def _build_plan(self, ts: int) -> PlanData | None:
        plan, pose = self.log.waypoints.get(ts), self.log.pose.get(ts)
        if plan is None or pose is None or len(plan) == 0:
            return None
        if not all_steps(plan.keys):
            self.ctx.report(
                self.log.file_of("waypoint", ts), "keys", "non-integer plan key ignored", ts
            )
        return build_plan(plan, pose, self.ego_half, self.window)

    def plan_horizon(self, plan: Plan) -> int:
        """The plan's own horizon in frames: its last integer step, at most
        :data:`PLAN_HORIZON_MAX_S` (-1 without an integer step)."""
        last = int(key_steps(plan.keys).max(initial=-1))
        return min(last, round(PLAN_HORIZON_MAX_S * 1000 / self.frame_ms))

    # -- actors -----------------------------------------------------------------------------
    def actor_state(self, actor_id: str, ts: int) -> tuple[FloatArray, float] | None:
        """An actor's world location (2,) and yaw (deg) at ts, if it has an entry there."""
        actors = self.log.actors.get(ts)
        if actors is None:
            return None
        row = actors.index.get(actor_id)
        if row is None:
            return None
        return actors.location[row, :2], float(actors.rotation[row, 2])

    def gids(self, ids: list[str] | tuple[str, ...]) -> npt.NDArray[np.int64]:
        """Run-wide integer ids of actor ids (new ones are registered)."""
        table = self._gid
        return np.array([table.setdefault(a, len(table)) for a in ids], dtype=np.int64)

    def _location_table(self, ts: int) -> FloatArray | None:
        """States (G, 3): x, y, yaw at ts indexed by run-wide id (NaN for ids absent at ts)."""
        actors = self.log.actors.get(ts)
        if actors is None:
            return None
        gids = self.gids(actors.ids)
        table = np.full((len(self._gid), 3), np.nan)
        table[gids[::-1], :2] = actors.location[::-1, :2]  # the first row of a repeated id
        table[gids[::-1], 2] = actors.rotation[::-1, 2]
        return table

    def locations_over(self, gids: npt.NDArray[np.int64], times: list[int]) -> FloatArray:
        """World locations (N, T, 2) of the actors ``gids`` at each of ``times`` (NaN where
        absent)."""
        return self.states_over(gids, times)[:, :, :2]

    def states_over(self, gids: npt.NDArray[np.int64], times: list[int]) -> FloatArray:
        """World locations and yaws (N, T, 3) of the actors ``gids`` at each of ``times``
        (NaN where absent): every actor's boxes over a horizon without a loop over actors.
        When every time has a table knowing every id (the usual case), the tables are read
        as one array, in one gather instead of one per time."""
        cache, actors = self.cache(LOCATIONS), self.log.actors
        tables: list[FloatArray | None] = []
        for t in times:
            table = cache.lookup(t)
            if table is None and t in actors:
                table = self._location_table(t)
                cache.put(t, table)
            tables.append(table)
        top = int(gids.max()) if len(gids) else -1
        size = len(tables[0]) if tables and tables[0] is not None else -1
        if top < size and all(table is not None and len(table) == size for table in tables):
            return np.array(tables).transpose(1, 0, 2)[gids]
        out = np.full((len(gids), len(times), 3), np.nan)
        for j, table in enumerate(tables):
            if table is None:
                continue
            if top < len(table):
                out[:, j] = table[gids]
            else:  # ids first seen after this table was made are absent at t
                known = gids < len(table)
                out[known, j] = table[gids[known]]
        return out

    def real_series(self, actor_id: str, ts: int) -> Series | None:
        """The actor's real boxes at ts + i·frame_ms, i = 0..W (None without an extent).

        The previous frame's series of the same actor (kept per timestamp) lends the boxes
        it had at the frames both read (:meth:`real_series_after`).
        """
        cache = self.cache(REAL_SERIES)
        prev = cache.lookup(ts - self.frame_ms)
        series = self.real_series_after(
            actor_id, ts, prev[1] if prev is not None and prev[0] == actor_id else None
        )
        if series is not None:
            cache.put(ts, (actor_id, series))
        return series

    def keep_real_series(self, actor_id: str, ts: int, series: Series) -> None:
        """Keep ``series`` as the actor's real series at ts (built elsewhere on the very
        records :meth:`real_series` would read: :meth:`real_sources`)."""
        self.cache(REAL_SERIES).put(ts, (actor_id, series))

    def real_sources(self, actor_id: str, ts: int) -> tuple[object, ...]:
        """What the actor's real series at ts is read from: the actor, its extent and the
        actors records at ts, ts + frame_ms, …, ts + W·frame_ms (None where absent), compared by
        identity: a series built on the same objects is the one a fresh read gives."""
        actors, frame_ms = self.log.actors, self.frame_ms
        records = [actors.get(ts + i * frame_ms) for i in range(self.window + 1)]
        return (actor_id, self.log.actor_extents.get(actor_id), *records)

    def real_series_run(self, actor_id: str, ts: int, real: Series, count: int) -> list[Series]:
        """:meth:`real_series_after` at ts + frame_ms, …, ts + count·frame_ms, each from the one
        before, starting from ``real`` (the series at ts), read at once: a frame's box is
        ``real``'s where ``real`` has its yaw, else the state read now (``real``'s or none
        without one); the series are read-only windows of one array."""
        extent = self.log.actor_extents.get(actor_id)
        if extent is None or count < 1:
            return []
        w, frame_ms = self.window, self.frame_ms
        center = np.full((count + w + 1, 2), np.nan)
        yaw = np.full(count + w + 1, np.nan)
        center[: w + 1], yaw[: w + 1] = real.center, real.yaw
        for i in (np.flatnonzero(np.isnan(yaw[1:])) + 1).tolist():
            state = self.actor_state(actor_id, ts + i * frame_ms)
            if state is not None:
                center[i], yaw[i] = state
        center.flags.writeable = yaw.flags.writeable = False
        half = np.asarray(extent[:2], dtype=np.float64)
        return [
            Series(center[k : k + w + 1], yaw[k : k + w + 1], half) for k in range(1, count + 1)
        ]

    def real_series_after(self, actor_id: str, ts: int, prev: Series | None) -> Series | None:
        """:meth:`real_series` at ts, taking the boxes ``prev`` (the actor's series at
        ts − frame_ms) had at indices 1..W, so one new state is read (and again those it lacked:
        a frame may have arrived since); kept nowhere."""
        extent = self.log.actor_extents.get(actor_id)
        if extent is None:
            return None
        w, frame_ms = self.window, self.frame_ms
        todo: list[int] | range
        if prev is not None:
            center = np.concatenate((prev.center[1:], _NO_POINT))
            yaw = np.concatenate((prev.yaw[1:], _NO_YAW))
            absent = np.isnan(yaw[:w])  # no state there (or a NaN one): read again
            todo = [*np.flatnonzero(absent).tolist(), w] if absent.any() else [w]
        else:
            center, yaw, todo = np.full((w + 1, 2), np.nan), np.full(w + 1, np.nan), range(w + 1)
        for i in todo:
            state = self.actor_state(actor_id, ts + i * frame_ms)
            if state is not None:
                center[i], yaw[i] = state
        return Series(center, yaw, np.asarray(extent[:2], dtype=np.float64))

    def predicted_series(
        self,
        track: Track,
        pose: EgoPose,
        actor_id: str,
        ts: int,
        horizon: int | None = None,
        half: FloatArray | None = None,
    ) -> Series | None:
        """Predicted boxes of an actor (the prediction frame): key k at index k + 1, anchored
        at the pose; indices 0..W, or 0..``horizon``; the actor's half extent, or ``half``."""
        extent = self.log.actor_extents.get(actor_id)
        if extent is None:
            return None
        state = self.actor_state(actor_id, ts)
        return build_predicted(
            track,
            pose,
            state,
            np.asarray(extent[:2], dtype=np.float64) if half is None else half,
            self.window if horizon is None else horizon,
            self.params.heading_min_step,
        )


def find_partner(judging: CorrectedContext) -> str | None:
    """The non-ego actor with the smallest signed box distance to the ego at collision_frame.

    Boxes from location, rotation yaw and first-appearance half extents (the ego's from its
    actor entry, its pose where it has none); ties go to the earlier actor in file order.
    Without an actors file at the collision frame, the latest earlier analysed frame.
    """
    log = judging.log
    cf_ms = log.metadata.collision_frame * judging.frame_ms
    ts = cf_ms
    if ts not in log.actors:
        earlier = [t for t in log.unique_frames if t < cf_ms and t in log.actors]
        judging.ctx.report(
            log.file_of("actors", cf_ms),
            "collision partner",
            "no actors file at collision_frame; used the latest earlier analysed frame",
            cf_ms,
        )
        if not earlier:
            return None
        ts = earlier[-1]
    ego = ego_box(judging, ts)
    if ego is None:
        judging.ctx.report(log.file_of("actors", ts), "collision partner", "no ego box", ts)
        return None
    return nearest_actor(judging, ts, ego)


def ego_box(judging: CorrectedContext, ts: int) -> tuple[FloatArray, float] | None:
    """The ego's box centre (2,) and yaw at ts: its actor entry, else its pose."""
    state = judging.actor_state(judging.ego_id, ts) if judging.ego_id is not None else None
    if state is not None:
        return state
    pose = judging.log.pose.get(ts)
    return None if pose is None else (np.array([pose.x, pose.y]), pose.yaw)


def other_rows(judging: CorrectedContext, ts: int) -> list[int]:
    """Rows of the actors file at ts the partner is chosen from: non-ego actors with an
    extent, each id's first row, in file order (ties go to the earlier one)."""
    actors = judging.log.actors.get(ts)
    if actors is None:
        return []
    extents = judging.log.actor_extents
    return [
        r
        for r, actor_id in enumerate(actors.ids)
        if actor_id != judging.ego_id and actor_id in extents and actors.index[actor_id] == r
    ]


def nearest_actor(judging: CorrectedContext, ts: int, ego: tuple[FloatArray, float]) -> str | None:
    """The non-ego actor with the smallest signed box distance to the ego box at ts."""
    rows = other_rows(judging, ts)
    if not rows:
        return None
    actors = judging.log.actors[ts]
    extents = judging.log.actor_extents
    half = np.array([extents[actors.ids[r]][:2] for r in rows])
    dist = box_signed_distance(
        ego[0],
        judging.ego_half,
        np.asarray(ego[1]),
        actors.location[rows, :2],
        half,
        actors.rotation[rows, 2],
    )
    dist = np.where(np.isnan(dist), np.inf, dist)
    if not np.isfinite(dist).any():
        return None
    return actors.ids[rows[int(np.argmin(dist))]]


_ATTRIBUTE = "_corrected_context"


def corrected_context(ctx: RunContext) -> CorrectedContext:
    """The :class:`CorrectedContext` of ``ctx``, created on first use and kept on it."""
    found = ctx.__dict__.get(_ATTRIBUTE)
    if isinstance(found, CorrectedContext):
        return found
    made = CorrectedContext(ctx)
    ctx.__dict__[_ATTRIBUTE] = made
    return made
