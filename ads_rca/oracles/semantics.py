"""What a semantics mode is: one object the engine and the live nodes ask, never the name.

Why: the engine (``ads-rca diagnose``), the live monitors' windows and the aggregator must
apply the same rules of a mode — which oracles, which frames are analysed, how the ego is
identified, the effect window, the attribution, which folders each oracle reads and how far
ahead — so each rule is written once, on the mode's :class:`Semantics`, and nobody outside
the parameter and CLI layers compares ``params.semantics`` with a mode's name.

A mode is a module that exports ``SEMANTICS`` (an instance of a :class:`Semantics`
subclass); :data:`MODES` maps each name to its module, imported on first use (a run loads
only its own mode). Adding a mode: one new module, one entry here (and its parameters'
defaults in :mod:`ads_rca.params`; the mode's ``parameters`` say which it reads).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import partial
from typing import TYPE_CHECKING, Any

from ads_rca.diagnosis.verdict import Attribution, FrameResults, Module, OracleResult
from ads_rca.model import ALL_FOLDERS, FOLDERS, InputStatus, Record, RunLog
from ads_rca.params import Params

if TYPE_CHECKING:
    from ads_rca.oracles.base import RunContext

#: An oracle: one module judged at one analysed frame (pure; problems go to ``ctx``).
Oracle = Callable[["RunContext", int], OracleResult]

#: Each mode's module (it exports ``SEMANTICS``).
MODES: dict[str, str] = {
    "reference": "ads_rca.oracles.reference",
    "corrected": "ads_rca.oracles.corrected",
}

#: The ego's identity is final once every frame up to this stamp has arrived (reference
#: reads it at exactly this stamp; the live window waits for it in every mode).
EGO_ID_TIMESTAMP_MS = 50


@dataclass(frozen=True)
class Headline:
    """What a report plots over time for one module: metrics of one quantity, its limit.

    Why on the mode: which of an oracle's metrics tell why the module failed, in which unit,
    and which of its flags explain a missing value is the mode's knowledge; the report only
    draws what it is told.
    """

    #: Metric keys drawn as lines, all in :attr:`unit`; this headline is chosen when the
    #: first is present in the run.
    keys: tuple[str, ...]
    #: The quantity, for the axis label ("clearance to the partner").
    quantity: str
    #: Its unit ("m", "m/s"; "1" for a ratio).
    unit: str
    #: A parameter drawn as a horizontal level.
    threshold: str | None = None
    #: A metric holding the level the oracle applied at each frame (a derived threshold).
    limit: str | None = None
    #: The level applies to the magnitude: it is drawn at ± the value.
    both_signs: bool = False
    #: Per key, (boolean metric, value) pairs: the metric holding that value explains a
    #: frame without a value of the key.
    gates: Mapping[str, tuple[tuple[str, bool], ...]] = field(default_factory=dict)
    #: A boolean metric shaded where it is true, with its legend text.
    band: tuple[str, str] | None = None
    #: The metrics are about the collision partner (the panel names it).
    partner: bool = False


#: The critical-event rules' parameters (docs/real-drives.md): read in both modes.
EVENT_PARAMETERS = ("event_time_s", "event_decel", "event_clearance", "event_ttc_s")


class Semantics:
    """One mode's rules. Subclasses set the class attributes and override what differs."""

    #: The mode's name (``params.semantics``).
    name: str
    #: The four oracles, in pipeline order.
    oracles: Mapping[Module, Oracle]
    #: A timestamp that appears in several files is analysed once per file (else once).
    analyses_duplicates: bool = False
    #: Results depend on the collision partner (the actors at the collision frame): a
    #: later collision re-judges the frames in the window, and the verdict names the partner.
    uses_partner: bool = False
    #: A predictor's tracks are scored against the realised future where the prediction
    #: module cannot be judged (:mod:`ads_rca.sources.predictor.scores`); its look-ahead must cover
    #: ``prediction_window`` frames and its folders the raw predictions, actors and pose.
    scores_predictions: bool = False
    #: Per module, what a report plots over time (the first whose first key is present wins).
    headline: Mapping[Module, Sequence[Headline]]
    #: See :data:`EGO_ID_TIMESTAMP_MS`.
    ego_stamp_ms: int = EGO_ID_TIMESTAMP_MS
    #: The parameters this mode reads, in the order outputs list them (``thresholds`` of
    #: ``diagnose --json``, ``config/rca_<mode>.yaml``).
    parameters: tuple[str, ...]
    #: Per module, the parameters its oracle's results report in ``thresholds`` (each a
    #: subset of :attr:`parameters`; an oracle adds its own constants and derived values).
    reported: Mapping[Module, tuple[str, ...]]
    #: How the text table heads a module's two counts (the JSON's ``collision`` and
    #: ``safe``, whose names the reference fixes), and a line saying what they mean in
    #: this mode ("" when the names say it).
    count_columns: tuple[str, str] = ("collision", "safe")
    count_legend: str = ""
    #: Per module, what makes a frame fail, in a few words: the mode comparison quotes it
    #: when this mode finds no failure where another does.
    rules: Mapping[Module, str] = {}
    #: Per module, the model inputs its rule reads (``ads_rca.capabilities.MODEL_INPUTS``),
    #: as alternatives: any one set present lets the module be judged.
    requires: Mapping[Module, tuple[tuple[str, ...], ...]] = {}
    #: Per module, how it is judged when the run has no ground truth (its actors are the
    #: stack's own tracks, :mod:`ads_rca.diagnosis.perceived`): its status in words and the
    #: oracle that judges it so. A module not listed is judged as usual (against the tracks).
    without_truth: Mapping[Module, tuple[str, Oracle]] = {}

    def judged(self, log: RunLog) -> dict[Module, str]:
        """Per module: ``judged``, or ``not judged (no <input>)`` for this run's inputs."""
        from ads_rca.capabilities import input_status
        from ads_rca.diagnosis.perceived import is_perceived

        return self.judged_for(input_status(log), is_perceived(log))

    def judged_for(
        self, statuses: Mapping[str, InputStatus], perceived: bool = False
    ) -> dict[Module, str]:
        """:meth:`judged` from input statuses alone (``inspect`` asks it before reading)."""
        from ads_rca.capabilities import JUDGED, judged_modules

        verdicts = judged_modules(self.requires, statuses)
        if perceived:
            for module, (status, _) in self.without_truth.items():
                if verdicts.get(module) == JUDGED:
                    verdicts[module] = status
        return verdicts

    def judging_oracles(self, log: RunLog) -> Mapping[Module, Oracle]:
        """The oracles to run on ``log``: for a recording that lacks a module's inputs, an
        oracle that says "not judged" at every frame instead of reporting each frame's
        missing input (a running log's folders run every oracle, as the reference does)."""
        from ads_rca.capabilities import input_status, recorded
        from ads_rca.diagnosis.perceived import is_perceived

        return self.oracles_for_inputs(
            input_status(log) if recorded(log) else None, perceived=is_perceived(log)
        )

    def oracles_for_inputs(
        self, statuses: Mapping[str, InputStatus] | None, perceived: bool = False
    ) -> dict[Module, Oracle]:
        """The oracles given a recording's input statuses (None: a running log, every
        oracle); the live monitors ask it with the statuses the run metadata carries.
        ``perceived``: the run's actors are its own tracks (:attr:`without_truth`)."""
        from ads_rca.capabilities import JUDGED, judged_modules

        chosen = dict(self.oracles)
        if perceived:
            chosen.update({m: oracle for m, (_, oracle) in self.without_truth.items()})
        if statuses is None:
            return chosen
        verdicts = judged_modules(self.requires, statuses)
        return {
            module: oracle
            if verdicts.get(module, JUDGED) == JUDGED
            else partial(not_judged, module, verdicts[module], self.scores_predictions)
            for module, oracle in chosen.items()
        }

    def attribute(self, frames: Sequence[FrameResults], ctx: RunContext) -> Attribution:
        """The verdict from the analysed frames' oracle results."""
        raise NotImplementedError

    def find_ego(self, ctx: RunContext) -> str | None:
        """The ego's actor id (default: the earliest analysed frame with actors and pose)."""
        from ads_rca.oracles.base import earliest_ego

        return earliest_ego(ctx)

    #: Which frames the window holds (``{w}``: its length), for outputs.
    window_counts: str = "frames collision_frame - {w} to collision_frame"

    def window_frames(self, params: Params, frame_ms: int) -> int:
        """W: frames before the collision that belong to the effect window."""
        return params.effect_time_window

    def window_rule(self, params: Params, frame_ms: int) -> str:
        """How W follows from the parameters, with their values (outputs print it)."""
        return f"effect_time_window {params.effect_time_window}"

    def window_terms(self, params: Params, frame_ms: int) -> dict[str, int]:
        """The window in frames each parameter that sets W asks for (W is the largest)."""
        return {"effect_time_window": params.effect_time_window}

    def folders(self, module: Module) -> tuple[str, ...]:
        """The log folders (hence topics) ``module``'s oracle reads (default: every one of the
        seed format; an oracle that reads an optional folder, e.g. ``tracks_3d``, names it)."""
        return FOLDERS

    def reads_ego(self, module: Module) -> bool:
        """Whether ``module``'s oracle reads the ego's identity."""
        return True

    def lookahead_frames(
        self,
        module: Module,
        params: Params,
        records: Mapping[str, Mapping[int, Record]],
        stamp_ms: int,
        cap: int,
    ) -> int:
        """Frames after ``stamp_ms`` that ``module``'s oracle reads there.

        ``records`` are the log's records per folder (at least ``stamp_ms``'s); ``cap``
        bounds a look-ahead that depends on the data (a key reaching absurdly far).
        """
        return 0

    def rejudge_history(self, params: Params, frame_ms: int) -> int:
        """Judged frames a live window keeps to re-judge them on a later collision."""
        return 0

    def partner_id(self, ctx: RunContext) -> str | None:
        """The collision partner the results were judged against (None: not used)."""
        return None

    def judge_without_collision(self, ctx: RunContext) -> None:
        """Judge ``ctx``'s frames before any collision against a provisional partner (a
        live stack, where the collision may never come); modes without a partner ignore it."""

    def judge_against(self, ctx: RunContext, actor: str) -> None:
        """Judge ``ctx``'s frames against ``actor`` as the partner (a live stack judging
        ahead against a warned actor); modes without a partner ignore it."""

    def partner_at(self, ctx: RunContext, ts: int) -> str | None:
        """The partner frame ts was judged against: the collision partner, or before a
        collision the provisional one (None: not used, or no collision and none asked)."""
        return None

    # --- derived: the same for every mode --------------------------------------------

    def effect_window(self, params: Params, frame_ms: int) -> dict[str, Any]:
        """The effective window as outputs name it: length, which parameter set it, the
        rule with the values, the frames it holds (``effect_window`` of the JSON)."""
        w = self.window_frames(params, frame_ms)
        terms = self.window_terms(params, frame_ms)
        return {
            "frames": w,
            "ms": w * frame_ms,
            "set_by": [name for name, frames in terms.items() if frames == w],
            "rule": self.window_rule(params, frame_ms),
            "counts": self.window_counts.format(w=w),
        }

    def used(self, params: Params) -> dict[str, Any]:
        """The values of the parameters this mode reads (``thresholds`` of the outputs)."""
        return params.values(self.parameters)

    def analyses(self, duplicate: bool) -> bool:
        """Whether a frame (a duplicated timestamp's later file, when ``duplicate``) is
        analysed."""
        return self.analyses_duplicates or not duplicate

    def analysed_frames(self, log: RunLog) -> tuple[int, ...]:
        """The timestamps judged, in order."""
        return log.frames if self.analyses_duplicates else log.unique_frames

    def module_folders(self, modules: Iterable[Module]) -> tuple[str, ...]:
        """The folders any of ``modules`` reads, in :data:`~ads_rca.model.ALL_FOLDERS` order."""
        wanted = {f for m in modules for f in self.folders(m)}
        return tuple(f for f in ALL_FOLDERS if f in wanted)

    def modules_lookahead(
        self,
        modules: Iterable[Module],
        params: Params,
        records: Mapping[str, Mapping[int, Record]],
        stamp_ms: int,
        cap: int,
    ) -> int:
        """The longest look-ahead among ``modules`` at ``stamp_ms``."""
        return max(
            (self.lookahead_frames(m, params, records, stamp_ms, cap) for m in modules),
            default=0,
        )


def not_judged(module: Module, why: str, scores: bool, ctx: RunContext, ts: int) -> OracleResult:
    """The result of a module the run's inputs do not let be judged (see
    :meth:`Semantics.judging_oracles`); with ``scores`` (:attr:`Semantics.scores_predictions`)
    the scorer of what the run holds for that module still scores the frame (a predictor's
    tracks against the realised future, a model's output against the ground truth:
    :func:`ads_rca.sources.registry.scored_frame`)."""
    if not scores:
        return OracleResult(module, ts, failed=False, skipped=why)
    from ads_rca.sources.registry import scored_frame

    found = scored_frame(module, ctx.log, ts, ctx.params, ctx.scorer_state)
    return OracleResult(module, ts, False, found.metrics, found.thresholds, skipped=why)


def semantics_for(mode: str | Params) -> Semantics:
    """The :class:`Semantics` of a mode (by name, or the one ``params`` select)."""
    name = mode.semantics if isinstance(mode, Params) else mode
    found = importlib.import_module(MODES[name]).SEMANTICS
    assert isinstance(found, Semantics)
    return found
