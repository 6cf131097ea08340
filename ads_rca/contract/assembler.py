"""Rebuilds a :class:`~ads_rca.model.RunLog` from the contract's messages, in any arrival order.

DDS gives no ordering between topics, so the assembler only collects: data messages keyed
by header stamp (first one wins, a duplicate frame re-sends the same data), frame markers by
their index, metadata and player status. :meth:`RunLogAssembler.build` converts at the end.
:meth:`RunLogAssembler.complete` says when everything the player announced has arrived, which
is how a subscriber knows it may stop. No rclpy: the same code serves tests and nodes.
"""

from __future__ import annotations

from collections import Counter
from typing import TYPE_CHECKING, Any

from ads_rca.contract import topics
from ads_rca.contract.cdr_decode import decode_string
from ads_rca.contract.convert import message_stamp_ms
from ads_rca.contract.errors import (
    DOCUMENT_ERRORS,
    CdrError,
    IncompleteRun,
    MalformedMessage,
    NoStamp,
)
from ads_rca.contract.playback import (
    FINISHED,
    INPUT_PROBLEMS_KEY,
    METADATA_DOCUMENT_KEY,
    read_document,
    read_input_problems,
)
from ads_rca.model import (
    MAX_FRAME,
    MAX_TIMESTAMP_MS,
    RunLog,
    RunMetadata,
    bounded_int,
    read_inputs,
)
from ads_rca.problems import IGNORED, Problem, ProblemLog

if TYPE_CHECKING:
    from std_msgs.msg import String

_ADDED_METADATA_KEYS = ("source", "frames", "problems", INPUT_PROBLEMS_KEY)


def metadata_from_document(document: dict[str, Any]) -> RunMetadata:
    """A metadata.json document → RunMetadata (the document kept as ``raw``); TypeError or
    ValueError for numbers the reader never gives (a frame period of 0, a frame past
    MAX_FRAME, a string)."""
    camera = (document.get("ego_config") or {}).get("camera") or {}
    loc = [float(v) for v in camera.get("camera_loc", (0.0, 0.0, 0.0))]
    return RunMetadata(
        timesteps_per_frame=bounded_int(
            document["timesteps_per_frame"], "timesteps_per_frame", 1, MAX_TIMESTAMP_MS
        ),
        camera_loc=(loc[0], loc[1], loc[2]),
        collision_frame=bounded_int(
            document.get("collision_frame", -1), "collision_frame", -MAX_FRAME, MAX_FRAME
        ),
        total_frames=bounded_int(document.get("total_frames", 0), "total_frames", 0, MAX_FRAME),
        raw=document,
        collision_known="collision_frame" in document,
    )


def run_metadata(document: dict[str, Any]) -> RunMetadata:
    """The RunMetadata a ``run/metadata`` message describes: from the exact metadata.json
    document it carries, else from its top-level keys. MalformedMessage when unusable.

    The document is anyone's: whatever reading it raises (a key missing, a list where a
    number belongs, ``Infinity`` for an integer) is what "unusable" means here."""
    exact = document.get(METADATA_DOCUMENT_KEY)
    try:
        return metadata_from_document(exact if isinstance(exact, dict) else document)
    except DOCUMENT_ERRORS as error:
        raise MalformedMessage(f"unusable run/metadata: {error!r}") from error


class RunLogAssembler:
    """Collects contract messages; builds the RunLog they describe."""

    def __init__(self) -> None:
        self.metadata_document: dict[str, Any] | None = None
        #: The problems the player's reader found in the original log (a recording keeps
        #: them, so diagnosing it judges as the original would).
        self.input_problems: list[Problem] = []
        self.source = ""
        self.status: dict[str, Any] = {}
        #: index → frame-marker document (first one wins; a looping player repeats indices).
        self.markers: dict[int, dict[str, Any]] = {}
        self.markers_received = 0
        #: topic key → how many messages the frame markers announced / have been received.
        self.expected: Counter[str] = Counter()
        self.received: Counter[str] = Counter()
        self._data: dict[str, dict[int, Any]] = {key: {} for key in topics.DATA_TOPICS}

    # --- collecting ---------------------------------------------------------------------

    def add(self, topic: str, msg: Any) -> None:
        """Any contract message by topic key (``/clock`` is counted and otherwise ignored).

        Raises MalformedMessage for a String message that cannot be read (nothing is kept)."""
        self.received[topic] += 1
        if topic == topics.METADATA:
            self._add_metadata(msg)
        elif topic == topics.FRAME:
            self._add_marker(msg)
        elif topic == topics.STATUS:
            self.status = read_document(msg)
        elif topic in self._data:
            try:
                stamp = message_stamp_ms(msg)
            except NoStamp:  # a MarkerArray without markers carries no stamp
                return
            self._data[topic].setdefault(stamp, msg)

    def add_raw(self, topic: str, data: bytes) -> None:
        """:meth:`add` for a message's serialised CDR bytes (a raw subscription's callback).

        Why: deserialising into rclpy objects costs as much as building them. Data messages
        are kept as bytes (only the stamp is read) and decoded straight into model records
        by :mod:`ads_rca.contract.cdr_decode` in :meth:`build`; String topics are decoded now.
        Objects and bytes can be mixed; for a stamp the first arrival wins either way.
        Raises MalformedMessage (CdrError for bytes that are not a message of the topic;
        nothing is kept).
        """
        from std_msgs.msg import String

        if topic in topics.TEXT_TOPICS:
            self.add(topic, String(data=decode_string(data)))
            return
        self.received[topic] += 1
        if topic in self._data:
            try:
                stamp = topics.stamp_ms(topic, data)
            except NoStamp:  # a MarkerArray without markers carries no stamp
                return
            self._data[topic].setdefault(stamp, bytes(data))

    def _add_metadata(self, msg: String) -> None:
        document = read_document(msg)
        exact = document.get(METADATA_DOCUMENT_KEY)
        if isinstance(exact, dict):
            self.metadata_document = exact
        else:
            self.metadata_document = {
                k: v for k, v in document.items() if k not in _ADDED_METADATA_KEYS
            }
        self.source = str(document.get("source", ""))
        self.input_problems = read_input_problems(document)

    def _add_marker(self, msg: String) -> None:
        document = read_document(msg)
        self.markers_received += 1
        try:
            for key in document.get("published", ()):
                self.expected[str(key)] += 1
        except TypeError as error:  # "published" is a number
            raise MalformedMessage(str(error)) from error
        index = document.get("index")
        key = int(index) if isinstance(index, int) else -self.markers_received
        self.markers.setdefault(key, document)

    # --- progress -----------------------------------------------------------------------

    @property
    def finished(self) -> bool:
        """The player said it reached the end of the log."""
        return self.status.get("state") == FINISHED

    def missing(self) -> dict[str, int]:
        """Per topic, how many announced messages have not arrived (only shortfalls)."""
        out = {
            key: self.expected[key] - self.received[key]
            for key in self.expected
            if self.received[key] < self.expected[key]
        }
        announced = int(self.status.get("frames_published", 0))
        if self.markers_received < announced:
            out[topics.FRAME] = announced - self.markers_received
        if self.metadata_document is None:
            out[topics.METADATA] = 1
        return out

    def complete(self) -> bool:
        """Finished, and every announced marker and data message has arrived."""
        return self.finished and not self.missing()

    # --- building -----------------------------------------------------------------------

    def build(self) -> RunLog:
        """The RunLog carried so far: IncompleteRun without metadata, MalformedMessage (its
        text the reader's error, which is its cause) when the metadata document or a frame
        marker describes none.

        Kept bytes that turn out not to be a message of their topic are left out and said
        as a problem of the log (message skipped)."""
        if self.metadata_document is None:
            raise IncompleteRun("no run/metadata message received")
        try:
            metadata = metadata_from_document(self.metadata_document)
            frames = tuple(
                bounded_int(self.markers[i]["stamp_ms"], "stamp_ms", 0, MAX_TIMESTAMP_MS)
                for i in sorted(i for i in self.markers if i >= 0)
            )
        except DOCUMENT_ERRORS as error:
            raise MalformedMessage(str(error)) from error
        inputs, issues = read_inputs(self.metadata_document)
        log = RunLog(
            metadata=metadata,
            frames=frames,
            source=self.source,
            problems=ProblemLog(self.input_problems),
            inputs=inputs,
        )
        for name, issue in issues:
            log.problems.add(topics.METADATA, name, issue, IGNORED, "warning")
        frame_ms = metadata.timesteps_per_frame
        for topic, by_stamp in self._data.items():
            folder = log.folder(topics.TOPIC_FOLDERS[topic])
            for stamp in sorted(by_stamp):
                item = by_stamp[stamp]
                if not isinstance(item, bytes):
                    folder[stamp] = topics.message_to_record(topic, item, frame_ms)
                    continue
                try:
                    folder[stamp] = topics.decode_record(topic, item, frame_ms)
                except CdrError as error:
                    log.problems.add(topic, "", str(error), "message skipped", timestamp_ms=stamp)
        return log
