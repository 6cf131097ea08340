"""Stack mode's collisions from ground truth, on a stack's own topics.

When ``detect_collisions`` is on, the aggregator finds the collisions itself: the ego pose
and the actors' boxes, framed by their header stamps as the monitors frame them
(:class:`~ads_rca.live.stamp_sync.StampSync`, the same inputs' layouts and decoders), go
through :class:`~ads_rca.live.collision_detect.CollisionDetector` frame by frame. Each
collision found is numbered and said as the ``run/collision`` document, flagged
``derived``. Pure: no rclpy.
"""

from __future__ import annotations

from typing import Any

from ads_rca.contract.errors import MalformedMessage, NoStamp
from ads_rca.contract.stack_layouts import Decoder
from ads_rca.errors import ConfigError
from ads_rca.live.collision_detect import Collision, CollisionDetector
from ads_rca.live.stack_config import StackConfig, period_to_frame_ms
from ads_rca.live.stack_feed import SkipReport
from ads_rca.live.stamp_sync import StampSync, SyncedFrame
from ads_rca.model import Actors, EgoPose

_INPUTS = ("pose", "actors")


class CollisionFeed:
    """Feed the ego pose and actor messages; collisions come out as frames are released."""

    def __init__(self, config: StackConfig, skipped: SkipReport) -> None:
        missing = [f for f in _INPUTS if f not in config.inputs]
        if missing:
            raise ConfigError(
                "detect_collisions needs the ego pose and the actors; the stack provides no "
                + ", ".join(missing)
            )
        self.config = config
        self.sync: StampSync[Any] = StampSync(config.sync_settings(_INPUTS, reference="pose"))
        self.decoders = {f: Decoder(f, config.inputs[f].layout.name) for f in _INPUTS}
        self.detector: CollisionDetector | None = None
        self.skipped = skipped  # (folder, error text) of a message that cannot be read

    @property
    def topics(self) -> dict[str, str]:
        return {f: self.config.inputs[f].topic for f in _INPUTS}

    def add(self, folder: str, payload: Any, now: float) -> list[Collision]:
        try:
            stamp = self.decoders[folder].stamp_ms(payload)
        except NoStamp:
            return []
        except MalformedMessage as error:
            self.skipped(folder, str(error))
            return []
        return self._detect(self.sync.add(folder, stamp, payload, now))

    def poll(self, now: float) -> list[Collision]:
        return self._detect(self.sync.poll(now))

    def _detect(self, frames: list[SyncedFrame[Any]]) -> list[Collision]:
        if not frames:
            return []
        if self.detector is None:
            assert self.sync.period_ms is not None  # nothing is released before it is known
            frame_ms = self.config.timesteps_per_frame or period_to_frame_ms(self.sync.period_ms)
            self.detector = CollisionDetector(frame_ms, self.config.ego_id or None)
        found: list[Collision] = []
        for frame in frames:
            records: dict[str, Any] = {}
            for folder, payload in frame.inputs.items():
                try:
                    records[folder] = self.decoders[folder].record(payload, self.detector.frame_ms)
                except MalformedMessage as error:
                    self.skipped(folder, str(error))
            pose, actors = records.get("pose"), records.get("actors")
            found += self.detector.update(
                frame.stamp_ms,
                pose if isinstance(pose, EgoPose) else None,
                actors if isinstance(actors, Actors) else None,
            )
        return found


def collision_document(collision: Collision) -> dict[str, Any]:
    """The ``run/collision`` document of a detected collision (frame rounded to a frame)."""
    return {
        "frame": round(collision.frame),
        "stamp_ms": collision.timestamp_ms,
        "number": collision.number,
        "actor_id": collision.actor_id,
        "depth_m": round(collision.depth_m, 6),
        "derived": True,
    }
