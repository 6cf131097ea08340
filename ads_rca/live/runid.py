"""A run's identity on the wire, and the filter that keeps one node on one run.

Why: two graphs on one DDS domain and namespace see each other's topics, and a node that
mixed them would judge, attribute or record another run's data. Every JSON message of a
run carries ``"run": <id>`` (the player's ``run_id``; ``run/metadata``, ``run/frame``,
``player/status``, ``metrics/*``, the verdict) and every ``/diagnostics`` status of the
graph a ``run`` key/value. The common_interfaces data messages (Odometry, MarkerArray,
MultiDOFJointTrajectory) have no free field, so they are attributed by their writer: with a
DDS rmw the publisher GID is the writer GUID, whose first 12 bytes are the participant's
GUID prefix, shared by every publisher of the player's process. A node therefore accepts a
data message only from the participant that sent its run's player messages.

A node given a ``run_id`` accepts that run only; without one it locks onto the first run it
hears of. Messages that carry no run at all (hand-made tools, older players) are accepted
while no run is known, so a single-run graph behaves as before.

Pure Python: no rclpy import (``MessageInfo`` is a plain dict); a node subscribes to its
run's ready topic with :func:`ads_rca.ros.nodemain.subscribe_ready`.
"""

from __future__ import annotations

import re
import uuid
from collections.abc import Mapping
from typing import Any

from ads_rca.errors import ConfigError

#: The JSON field (and diagnostic key) that names the run.
RUN_KEY = "run"

#: rmw implementations whose publisher GID starts with the participant's 12-byte GUID
#: prefix (RTPS GUIDs). Others (e.g. rmw_zenoh) hash each entity: no data filtering there.
PREFIX_RMWS = frozenset(
    {"rmw_fastrtps_cpp", "rmw_fastrtps_dynamic_cpp", "rmw_cyclonedds_cpp", "rmw_connextdds"}
)
PREFIX_BYTES = 12


#: What a run id may be: it becomes part of a topic name (``run/ready_<id>``).
RUN_ID_PATTERN = re.compile(r"[A-Za-z0-9_]{1,64}")


def checked_run_id(value: str) -> str:
    """A ``run_id`` parameter as given ("" = none), or ConfigError (one line) when it could
    not be part of a topic name."""
    if value and not RUN_ID_PATTERN.fullmatch(value):
        raise ConfigError(
            f"run_id must be 1 to 64 letters, digits or '_' (it names a topic), got {value!r}"
        )
    return value


def new_run_id() -> str:
    """A fresh run identity (random, so two runs started at once never share one)."""
    return uuid.uuid4().hex[:16]


def writer_prefix(info: Mapping[str, Any] | None) -> bytes | None:
    """The sending participant's GUID prefix from a subscription's MessageInfo, or None
    when the rmw's GIDs do not identify the participant (or there is no GID)."""
    gid = info.get("publisher_gid") if info else None
    if not isinstance(gid, Mapping) or gid.get("implementation_identifier") not in PREFIX_RMWS:
        return None
    data = gid.get("data")
    if not isinstance(data, bytes | bytearray) or len(data) < PREFIX_BYTES:
        return None
    return bytes(data[:PREFIX_BYTES])


def document_run(document: Mapping[str, Any]) -> str | None:
    """The run a JSON document names (None: it names none)."""
    run = document.get(RUN_KEY)
    return run if isinstance(run, str) and run else None


class RunFilter:
    """Decides which messages belong to this node's run.

    ``run_id`` "" locks onto the first run named by a message passed to :meth:`accept`.
    The participant of the first accepted message that :meth:`accept` is told came from
    the player (``player=True``) becomes the only source of data messages.
    """

    def __init__(self, run_id: str = "") -> None:
        self.run = run_id or None
        self.given = bool(run_id)
        self.player: bytes | None = None
        self.rejected = 0

    def accept(
        self,
        document: Mapping[str, Any],
        info: Mapping[str, Any] | None = None,
        player: bool = False,
    ) -> bool:
        """A JSON message: True if it belongs to our run (locking onto it if none yet)."""
        run = document_run(document)
        if run is None:
            ok = self.run is None
        elif self.run is None:
            self.run, ok = run, True
        else:
            ok = run == self.run
        if not ok:
            self.rejected += 1
            return False
        if player and run is not None and self.player is None:
            self.player = writer_prefix(info)
        return True

    def accept_run(self, run: str) -> bool:
        """A run named outside JSON (a diagnostic key): ours, or any while none is known."""
        ok = self.run is None or run == self.run
        self.rejected += not ok
        return ok

    def accept_data(self, info: Mapping[str, Any] | None) -> bool:
        """A data message: True unless its writer is not our player's participant."""
        if self.player is None:
            return True
        prefix = writer_prefix(info)
        ok = prefix is None or prefix == self.player
        self.rejected += not ok
        return ok
