"""Stack mode's front end: a stack's messages into a monitor core, frame by frame.

The player announces frames and the run's metadata; a stack does neither. :class:`StackFeed`
does it from the stack's own topics: each message's stamp is read on arrival, the
:class:`~ads_rca.live.stamp_sync.StampSync` groups the inputs into frames of the reference
input's header stamps, and each released frame goes to the
:class:`~ads_rca.live.window.MonitorCore` as the player's would: its records, re-keyed to the
frame's stamp, then its marker (index ``round(stamp / period)``), with the inputs that did
not come marked missing. The metadata comes from the parameters (:class:`StackConfig`),
its period given or measured. A collision (``run/collision``) closes the frames before it
once the sync has released the frame at the collision (or ``input_timeout_s`` after the
collision was heard). Run facts that can be checked live are checked: an ``ego_id`` that
never appears among the actors, a measured period far from ``timesteps_per_frame``.
Pure: no rclpy; the monitor node is a thin shell over it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from ads_rca.contract.errors import MalformedMessage, NoStamp
from ads_rca.contract.stack_layouts import Decoder
from ads_rca.live.results import FrameMarker
from ads_rca.live.stack_config import StackConfig, period_to_tpf
from ads_rca.live.stamp_sync import StampSync, SyncedFrame
from ads_rca.live.window import MonitorCore
from ads_rca.model import OPTIONAL_FOLDERS, Actors, Record

#: Frames with actors after which an ``ego_id`` never seen among them is reported.
EGO_CHECK_FRAMES = 20
#: A measured period further than this (relative) from ``timesteps_per_frame`` is reported.
PERIOD_TOLERANCE = 0.1

#: Called with (folder, error text) for a message that could not be read.
SkipReport = Callable[[str, str], None]


class StackFeed:
    """Feed :meth:`add` every stack message and call :meth:`poll` on a timer."""

    def __init__(self, config: StackConfig, core: MonitorCore, skipped: SkipReport) -> None:
        self.config = config
        self.core = core
        self.skipped = skipped
        folders = {*core.folders, config.reference}
        self.sync: StampSync[Any] = StampSync(config.sync_settings(folders))
        self.expected = (config.reference, *self.sync.settings.inputs)
        self.decoders = {f: Decoder(f, config.inputs[f].layout.name) for f in self.expected}
        #: The judged modules' inputs the stack does not provide (their results say so).
        #: A stack's inputs are the seed format's folders; the optional ones of recordings
        #: (3-D objects, control) are not stack inputs, so never awaited.
        self.unprovided = tuple(
            f for f in core.folders if f not in config.inputs and f not in OPTIONAL_FOLDERS
        )
        #: Run facts found wrong while running (one line each), for /diagnostics.
        self.fact_problems: list[str] = []
        self._frames_with_actors = 0
        self._ego_seen = not config.ego_id
        self._period_checked = False
        self._origin_ms: int | None = None  # the first frame's stamp: index 0
        self._sync_said = ""  # the sync's counts as last said
        core.derived = config.derived()
        if config.ego_id:
            core.ego_id, core.ego_resolved = config.ego_id, True
        if config.timesteps_per_frame:
            core.set_metadata(config.metadata(config.timesteps_per_frame), 0.0)
            core.last_input = None  # no input yet: the stack may start much later

    def add(self, folder: str, payload: Any, now: float) -> None:
        """One received message of ``folder``'s topic (``now``: monotonic seconds)."""
        try:
            stamp = self.decoders[folder].stamp_ms(payload)
        except NoStamp:  # an empty MarkerArray: nothing seen, nothing to judge
            return
        except MalformedMessage as error:
            self.skipped(folder, str(error))
            return
        self.core.last_input = now
        self._feed(self.sync.add(folder, stamp, payload, now), now)

    def poll(self, now: float) -> None:
        """Release what timed out; close the frames before a collision once all are in."""
        self._feed(self.sync.poll(now), now)
        core = self.core
        if core.collision_frame < 0 or core.horizon_closed or core.metadata is None:
            return
        cf_ms = core.collision_frame * core.metadata.timesteps_per_frame
        released = self.sync.released_ms
        slop = self.sync.slop_ms
        waited = core.collision_at is not None and now - core.collision_at >= (
            self.config.input_timeout_s
        )
        first_held = self.sync.first_held_ms
        held_before = first_held is not None and first_held <= cf_ms + slop
        # Waited long enough, but a frame before the collision still held is still to come.
        if (released is not None and released >= cf_ms - slop) or (waited and not held_before):
            core.close_horizon()

    def sync_news(self) -> str | None:
        """One line when the stamp sync dropped or released early more than last said
        (late, duplicate, unmatched messages; frames released incomplete); else None."""
        said = self.sync.counts.text()
        if said == self._sync_said:
            return None
        self._sync_said = said
        return f"stamp sync so far: {said}"

    def flush(self, now: float) -> None:
        """Release every held frame (the node is stopping, or a test's run ended)."""
        self._feed(self.sync.flush(), now)

    # --- frames into the core ----------------------------------------------------------

    def _feed(self, frames: list[SyncedFrame[Any]], now: float) -> None:
        if not frames:
            return
        core = self.core
        if core.metadata is None:
            assert self.sync.period_ms is not None  # nothing is released before it is known
            core.set_metadata(self.config.metadata(period_to_tpf(self.sync.period_ms)), now)
        self._check_period()
        assert core.metadata is not None
        tpf = core.metadata.timesteps_per_frame
        period = self.sync.period_ms or float(tpf)
        for frame in frames:
            present = set()
            for folder, payload in frame.inputs.items():
                try:
                    record = self.decoders[folder].record(payload, tpf)
                except MalformedMessage as error:
                    self.skipped(folder, str(error))
                    continue
                present.add(folder)
                core.add_record(folder, frame.stamp_ms, record, now)
                if folder == "actors":
                    self._check_ego(record)
            if self._origin_ms is None:
                self._origin_ms = frame.stamp_ms
            index = round((frame.stamp_ms - self._origin_ms) / period)
            wanted = frozenset((*self.expected, *self.unprovided))
            core.add_marker(FrameMarker(index, frame.stamp_ms, wanted), now)

    def _check_ego(self, record: Record) -> None:
        if self._ego_seen or not isinstance(record, Actors):
            return
        if self.config.ego_id in record.index:
            self._ego_seen = True
            return
        self._frames_with_actors += 1
        if self._frames_with_actors == EGO_CHECK_FRAMES:
            self.fact_problems.append(
                f"ego_id {self.config.ego_id!r} is not among the actors of the first "
                f"{EGO_CHECK_FRAMES} frames"
            )

    def _check_period(self) -> None:
        given, measured = self.config.timesteps_per_frame, self.sync.measured_ms
        if self._period_checked or not given or measured is None:
            return
        self._period_checked = True
        if abs(measured - given) > PERIOD_TOLERANCE * given:
            self.fact_problems.append(
                f"timesteps_per_frame is {given} ms but the reference input's stamps are "
                f"{measured:g} ms apart"
            )
