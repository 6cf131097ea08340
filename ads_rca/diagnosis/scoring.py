"""A run's own figures beside the verdict, behind one protocol (:class:`Scorer`).

A run's data may give figures of its own (a dataset's benchmark scores, a predictor's
errors, what a run reports about itself): each source folder that has such figures gives a
:class:`Scorer`, and :data:`ads_rca.sources.registry.SCORERS` lists them. The engine, the
summary, the live monitors and the oracles' not-judged results ask every scorer the same
questions, so none of them names a dataset.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any, NamedTuple

if TYPE_CHECKING:
    from ads_rca.diagnosis.verdict import FrameResults, Metric
    from ads_rca.model import RunLog
    from ads_rca.params import Params


class FrameScores(NamedTuple):
    """A frame's scores: the metrics and the thresholds of a not-judged module's result."""

    metrics: dict[str, Metric]
    thresholds: dict[str, float]


class Scorer:
    """Figures a run's data gives beyond the verdict. Each method has a default that says
    nothing, so a scorer overrides only what it gives; everything here is pure and asked
    again with the same inputs gives the same answer (offline, live, in forked workers).

    :attr:`keys` are the verdict JSON keys :meth:`document` may write, in order.
    """

    keys: tuple[str, ...] = ()

    def document(
        self, log: RunLog, frames: Sequence[FrameResults], semantics: str
    ) -> dict[str, Any]:
        """The verdict JSON's entries for the run judged as ``frames`` ({} when none)."""
        return {}

    def summary_lines(self, document: Mapping[str, Any], shown: int) -> list[str]:
        """The summary's lines for the entries a verdict ``document`` holds (at most
        ``shown`` items of a list; [] when it holds none)."""
        return []

    def frame_scores(
        self, log: RunLog, timestamp_ms: int, params: Params, kept: dict[str, Any]
    ) -> FrameScores:
        """The scores of one frame whose module the verdict rules cannot judge (the module
        the registry names for this scorer); ``kept`` is this scorer's own state over the
        run's frames (one per run, shared by a live monitor's contexts). No metrics: this
        scorer has nothing for the frame."""
        return FrameScores({}, {})

    def status_text(self, metrics: Mapping[str, Metric]) -> str | None:
        """What a live status says of a frame it scored (``metrics`` of the not-judged
        result); None when they are not its scores."""
        return None
