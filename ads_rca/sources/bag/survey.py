"""What any rosbag2 bag holds, and which profile would read it: ``inspect BAG`` with no
profile.

Why a module of its own: a real vehicle's recording (hundreds of declared topics, most never
published; legacy types such as ``autoware_auto_perception_msgs``; no message definitions
before ROS 2 Iron) must be listed before anyone knows how to read it. So nothing here decodes
a message or needs a definition: topics, types, counts and times come from the storage's
own tables and indexes (:func:`ads_rca.sources.bag.storage.list_storage`), what
``ros2 bag info`` shows. A profile is judged by the bag's TYPES and message counts on its
topics: an input is mapped only when its topic is there, of a type the input accepts, with
at least one message; a profile is recommended only when its reference input and at least
one other input are mapped, never on topic names alone (a real stack declares its
perception topics whether or not perception ran). For a bag no built-in fits,
:func:`starting_profile` writes a profile from the bag's types, for the user to check.

Pure: no rclpy, no message package; the definitions are only looked up (the bag's, then
``--msg-path``'s, then Kilted's standard types), never parsed into code.
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from ads_rca.capabilities import MODEL_INPUTS
from ads_rca.contract import topics as contract_topics
from ads_rca.contract.rosmsg import normalise_type
from ads_rca.errors import InputError
from ads_rca.foundation.text import printable
from ads_rca.problems import Problem
from ads_rca.sources.bag.profiles import BUILTIN_PROFILES
from ads_rca.sources.bag.profiles.decoders import DECODERS, decoder_for
from ads_rca.sources.bag.profiles.profile import REFERENCE_INPUTS, InputSpec, Profile, load_profile
from ads_rca.sources.bag.reader import (
    BagContents,
    detect_namespace,
    disagreements,
    locate_bag,
    read_files,
)
from ads_rca.sources.bag.storage import StorageListing, TopicCount, counts_of, list_storage

#: Inputs a type alone cannot assign: a stack's output and the ground truth share their
#: types (two Detection2DArray topics), so a starting profile leaves them to the user.
TRUTH_INPUTS = ("ground_truth_2d", "predictions_gt")
#: When several types carry an input, the ones it takes first (by the type's own name, any
#: package: the legacy ``autoware_auto_*`` types are named alike).
PREFERRED_TYPES = {
    "detections_3d": ("DetectedObjects", "Detection3DArray"),
    "tracked_objects": ("TrackedObjects",),
}
#: Why an input is not mapped: its topic is not declared, or declared without messages.
NOT_IN_BAG = "not in the bag"
NO_MESSAGES = "0 messages"
#: Characters of a topic or type name shown in a line (escaped first, then cut).
NAME_CHARS = 80
#: Other candidates a starting profile lists per input.
CANDIDATES_SHOWN = 8


# --- the listing --------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class TopicInfo:
    """One declared topic: its stored type, messages, first and last log times, and where
    its type's definition comes from (``bag``, or what
    :meth:`~ads_rca.sources.bag.message_types.BagTypes.source` says: ``msg-path``,
    ``standard``, ...; ``""``: none, reading its messages needs ``--msg-path``)."""

    name: str
    type: str
    count: int
    first_ns: int | None
    last_ns: int | None
    definition: str

    @property
    def span_s(self) -> float | None:
        """Seconds from the first message to the last (None without a message)."""
        if self.first_ns is None or self.last_ns is None:
            return None
        return (self.last_ns - self.first_ns) / 1e9

    @property
    def rate_hz(self) -> float | None:
        """Messages per second over the span; None (unknown, never inf or NaN) with fewer
        than two messages or all at one time."""
        span = self.span_s
        if self.count < 2 or span is None or span <= 0:
            return None
        return (self.count - 1) / span

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "type": self.type,
            "count": self.count,
            "first_ns": self.first_ns,
            "last_ns": self.last_ns,
            "span_s": self.span_s,
            "rate_hz": self.rate_hz,
            "definition": self.definition or None,
        }


# --- profiles -----------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class InputFit:
    """How one input of a profile fares on a bag: its topic, the messages of an accepted
    type there, and why it is not mapped ("" when it is)."""

    input: str
    topic: str
    types: tuple[str, ...]
    count: int
    why: str
    #: other topics of an accepted type with messages (``--write-profile`` would map them)
    elsewhere: tuple[str, ...] = ()

    @property
    def mapped(self) -> bool:
        return not self.why

    def to_dict(self) -> dict[str, Any]:
        return {
            "topic": self.topic,
            "types": list(self.types),
            "count": self.count,
            "mapped": self.mapped,
            "why": self.why or None,
            "elsewhere": list(self.elsewhere),
        }


@dataclass(frozen=True)
class ProfileFit:
    """Which inputs of one profile a bag would give, and why the profile cannot read the
    bag at all ("" when it can)."""

    profile: str
    contract: bool
    references: tuple[str, ...]
    inputs: tuple[InputFit, ...]
    refused: str

    @property
    def mapped(self) -> tuple[str, ...]:
        return tuple(fit.input for fit in self.inputs if fit.mapped)

    @property
    def missing(self) -> tuple[str, ...]:
        return tuple(fit.input for fit in self.inputs if not fit.mapped)

    def to_dict(self) -> dict[str, Any]:
        return {
            "profile": self.profile,
            "contract": self.contract,
            "references": list(self.references),
            "mapped": list(self.mapped),
            "missing": list(self.missing),
            "refused": self.refused or None,
            "inputs": {fit.input: fit.to_dict() for fit in self.inputs},
        }


@dataclass(frozen=True)
class Recommendation:
    """The profile to read the bag with (None when no built-in fits), why, what the bag
    lacks by type, and which of its topics carry each input by type."""

    profile: str | None
    reason: str
    #: inputs no topic of the bag carries with messages, by type
    lacking: tuple[str, ...]
    #: input → topics of a type that carries it, with messages (most messages first)
    by_type: Mapping[str, tuple[str, ...]]

    def to_dict(self) -> dict[str, Any]:
        return {
            "profile": self.profile,
            "reason": self.reason,
            "lacking": list(self.lacking),
            "by_type": {name: list(found) for name, found in self.by_type.items()},
        }


# --- the survey ---------------------------------------------------------------------------


@dataclass
class BagSurvey:
    """Everything ``inspect`` says of a bag without reading a message."""

    path: str
    #: storage files, as read (split order)
    files: tuple[str, ...]
    #: per file, how its counts were found (``storage.LISTED_BY_*``)
    methods: tuple[str, ...]
    #: a usable metadata.yaml was there (it is only compared: the storage is trusted)
    metadata_yaml: bool
    topics: tuple[TopicInfo, ...]
    #: the storage files carry at least one message definition (none before Iron)
    stores_definitions: bool
    problems: list[Problem]
    fits: tuple[ProfileFit, ...] = ()
    recommendation: Recommendation | None = None

    @property
    def message_count(self) -> int:
        return sum(topic.count for topic in self.topics)

    @property
    def first_ns(self) -> int | None:
        return min((t.first_ns for t in self.topics if t.first_ns is not None), default=None)

    @property
    def last_ns(self) -> int | None:
        return max((t.last_ns for t in self.topics if t.last_ns is not None), default=None)

    @property
    def undefined_types(self) -> tuple[str, ...]:
        """Stored types nothing defines (the bag, ``--msg-path``, what ads_rca knows)."""
        return tuple(sorted({t.type for t in self.topics if not t.definition}))

    def to_dict(self) -> dict[str, Any]:
        """The JSON form (``inspect --json``): exact names, times in nanoseconds."""
        first, last = self.first_ns, self.last_ns
        return {
            "bag": {
                "path": self.path,
                "files": list(self.files),
                "listed_by": list(self.methods),
                "metadata_yaml": self.metadata_yaml,
                "stores_definitions": self.stores_definitions,
                "messages": self.message_count,
                "first_ns": first,
                "last_ns": last,
                "duration_s": None if first is None or last is None else (last - first) / 1e9,
            },
            "topics": [topic.to_dict() for topic in self.topics],
            "types_without_definition": list(self.undefined_types),
            "profiles": [fit.to_dict() for fit in self.fits],
            "recommendation": None
            if self.recommendation is None
            else self.recommendation.to_dict(),
        }


def survey_bag(
    path: str | os.PathLike[str],
    msg_path: Sequence[str | os.PathLike[str]] = (),
    profiles: Sequence[Profile] | None = None,
) -> BagSurvey:
    """List a bag (every storage file, no message kept or decoded), check metadata.yaml
    against it, and fit ``profiles`` (default: every built-in) to it. InputError only when
    no storage file can be read at all."""
    info, problems, files = locate_bag(path)
    listings: list[StorageListing] = read_files(files, info, problems, list_storage)
    declared: dict[str, str] = {}
    counts: dict[str, TopicCount] = {}
    defined: set[str] = set()
    for listing in listings:
        problems.extend(listing.problems)
        for name, msg_type in listing.topics.items():
            if declared.setdefault(name, msg_type) != msg_type:
                issue = f"type {msg_type}, another file's is {declared[name]}"
                problems.append(Problem(listing.file.name, name, issue, "the first one is listed"))
            counts[name] = counts.get(name, TopicCount()).merged(
                listing.counts.get(name, TopicCount())
            )
        defined.update(normalise_type(t) for t in listing.definitions)
    if info is not None:
        cut = any(listing.truncated for listing in listings)
        problems.extend(disagreements(info, declared, None if cut else counts))
    survey = _survey(os.fspath(path), declared, counts, defined, problems, msg_path, profiles)
    survey.files = tuple(listing.file.name for listing in listings)
    survey.methods = tuple(listing.method for listing in listings)
    survey.metadata_yaml = info is not None
    return survey


def survey_contents(
    contents: BagContents,
    msg_path: Sequence[str | os.PathLike[str]] = (),
    profiles: Sequence[Profile] | None = None,
    look_up: bool = True,
) -> BagSurvey:
    """The same survey of a bag already read whole (:func:`~ads_rca.sources.bag.reader.load_bag`:
    a command that reads the run lists the topics from the same read; ``look_up``: see
    :func:`_survey`)."""
    return _survey(
        contents.path,
        dict(contents.topics),
        counts_of(contents.messages),
        {normalise_type(t) for t in contents.definitions},
        list(contents.problems),
        msg_path,
        profiles,
        look_up,
    )


def _survey(
    path: str,
    declared: Mapping[str, str],
    counts: Mapping[str, TopicCount],
    defined: set[str],
    problems: list[Problem],
    msg_path: Sequence[str | os.PathLike[str]],
    profiles: Sequence[Profile] | None,
    look_up: bool = True,
) -> BagSurvey:
    """The survey of a listing (``look_up`` False: whether each type has a definition
    elsewhere than the bag is not looked up, which costs loading rosbags' type stores)."""
    if look_up:
        sources = _definition_sources(path, set(declared.values()), defined, msg_path, problems)
    else:
        sources = {t: "bag" if normalise_type(t) in defined else "" for t in declared.values()}
    listed: list[TopicInfo] = []
    for name, msg_type in sorted(declared.items()):
        count = counts.get(name, TopicCount())
        listed.append(
            TopicInfo(name, msg_type, count.count, count.first_ns, count.last_ns, sources[msg_type])
        )
    chosen = profiles if profiles is not None else builtin_profiles()
    fits = profile_fits(listed, chosen)
    return BagSurvey(
        path=path,
        files=(),
        methods=(),
        metadata_yaml=False,
        topics=tuple(listed),
        stores_definitions=bool(defined),
        problems=problems,
        fits=fits,
        recommendation=recommend(fits, listed),
    )


def builtin_profiles() -> list[Profile]:
    """Every built-in profile (``profiles/builtin/*.yaml``), loaded and checked."""
    return [load_profile(name) for name in BUILTIN_PROFILES]


def _definition_sources(
    path: str,
    types: Iterable[str],
    defined: set[str],
    msg_path: Sequence[str | os.PathLike[str]],
    problems: list[Problem],
) -> dict[str, str]:
    """Stored type → where its definition comes from: the bag's own, else a ``.msg`` under
    ``msg_path``, else Kilted's standard types, else "" (reading its messages would need
    ``--msg-path``). Only looked up: a listing parses no definition."""
    out = {t: "bag" for t in types if normalise_type(t) in defined}
    rest = sorted(set(types) - set(out))
    if rest:
        from ads_rca.sources.bag.message_types import BagTypes  # rosbags: only when needed

        lookup = BagTypes(path, {}, msg_path)
        for msg_type in rest:
            out[msg_type] = lookup.source(msg_type) or "" if _looks_like_type(msg_type) else ""
        problems.extend(lookup.problems)
    return out


def _looks_like_type(name: str) -> bool:
    """A ``pkg/msg/Type`` or ``pkg/Type`` name (anything else cannot have a definition)."""
    return bool(re.fullmatch(r"[A-Za-z][\w]*/(msg/)?[A-Za-z]\w*", name))


# --- fitting and recommending --------------------------------------------------------------


def _topic_of(profile: Profile, spec: InputSpec, names: list[str]) -> str:
    """Where the bag would carry ``spec``: its topic, or for the contract the same topic
    under the namespace the bag's contract topics use."""
    if not profile.contract:
        return spec.topic
    keys = {name: key for key, name in contract_topics.topic_names().items()}
    key = keys.get(spec.topic)
    if key is None:
        return spec.topic
    return contract_topics.topic_name(key, detect_namespace(names))


def profile_fits(
    listed: Sequence[TopicInfo], profiles: Sequence[Profile]
) -> tuple[ProfileFit, ...]:
    """Each profile's inputs on the bag: mapped when the topic is there, of a type the
    input accepts, with messages (a declared topic without messages gives nothing)."""
    by_name = {topic.name: topic for topic in listed}
    names = sorted(by_name)
    fits: list[ProfileFit] = []
    for profile in profiles:
        inputs: list[InputFit] = []
        for spec in profile.inputs.values():
            accepted = spec.types
            wanted = {normalise_type(t) for t in accepted}
            topic_name = _topic_of(profile, spec, names)
            topic = by_name.get(topic_name)
            if topic is None:
                why, count = NOT_IN_BAG, 0
            elif normalise_type(topic.type) not in wanted:
                why, count = f"holds {topic.type}", 0
            else:
                count = topic.count
                why = "" if count else NO_MESSAGES
            elsewhere = tuple(
                t.name
                for t in sorted(listed, key=lambda t: (-t.count, t.name))
                if why and t.count and t.name != topic_name and normalise_type(t.type) in wanted
            )
            inputs.append(InputFit(spec.input, topic_name, accepted, count, why, elsewhere))
        fits.append(
            ProfileFit(
                profile.name,
                profile.contract,
                profile.references,
                tuple(inputs),
                _refusal(profile, inputs, by_name, names),
            )
        )
    return tuple(fits)


def _refusal(
    profile: Profile, inputs: list[InputFit], by_name: Mapping[str, TopicInfo], names: list[str]
) -> str:
    """Why ``profile`` could not read the bag at all: none of its reference inputs has a
    message (nothing to time the frames by); the contract: no run/metadata message."""
    mapped = {fit.input for fit in inputs if fit.mapped}
    references = profile.references
    if not mapped & set(references):
        fit = {f.input: f for f in inputs}
        said = "; ".join(f"{r} ({shown(fit[r].topic)}: {fit[r].why})" for r in references)
        return f"no message to time the frames by: {said}"
    if profile.contract:
        metadata = contract_topics.topic_name(contract_topics.METADATA, detect_namespace(names))
        held = by_name.get(metadata)
        if held is None or held.count == 0:
            return f"no {contract_topics.METADATA} message ({shown(metadata)})"
    return ""


def carriers() -> dict[str, tuple[str, ...]]:
    """Model input → every type a decoder reads as it (the built-in types and aliases), in
    pipeline order; inputs only a recording carries (no module's rule reads them) last."""
    found: dict[str, list[str]] = {}
    for type_name, decoder in sorted(DECODERS.items()):
        for name in decoder.inputs:
            found.setdefault(name, []).append(type_name)
    order = [n for n in MODEL_INPUTS if n in found] + sorted(set(found) - set(MODEL_INPUTS))
    return {name: tuple(found[name]) for name in order}


def by_type(listed: Sequence[TopicInfo]) -> dict[str, tuple[TopicInfo, ...]]:
    """Model input → the bag's topics of a type that carries it (by the decoders), most
    messages first, then by name; topics without messages included (last)."""
    out: dict[str, list[TopicInfo]] = {name: [] for name in carriers()}
    for topic in sorted(listed, key=lambda t: (-t.count, t.name)):
        decoder = decoder_for(topic.type)
        for name in decoder.inputs if decoder is not None else ():
            out[name].append(topic)
    return {name: tuple(found) for name, found in out.items()}


def recommend(fits: Sequence[ProfileFit], listed: Sequence[TopicInfo]) -> Recommendation:
    """The profile that maps the most inputs with messages (ties: the one missing fewest of
    its own, then by name), among those that can read the bag and map at least two; none
    when no profile does, with what the bag lacks by type."""
    found = by_type(listed)
    with_messages = {name: tuple(t.name for t in ts if t.count) for name, ts in found.items()}
    lacking = tuple(name for name, ts in with_messages.items() if not ts)
    carried = {name: ts for name, ts in with_messages.items() if ts}
    usable = [fit for fit in fits if not fit.refused and len(fit.mapped) >= 2]
    if usable:
        best = min(usable, key=lambda f: (-len(f.mapped), len(f.missing), f.profile))
        reason = (
            f"{len(best.mapped)} of its inputs have messages of their types on its topics: "
            + ", ".join(best.mapped)
        )
        return Recommendation(best.profile, reason, lacking, carried)
    reason = "no built-in profile maps one of its reference inputs and another input"
    partial = [f"{f.profile} maps only {', '.join(f.mapped)}" for f in fits if f.mapped]
    reason += f": {'; '.join(partial)}" if partial else ""
    return Recommendation(None, reason, lacking, carried)


# --- a starting profile -------------------------------------------------------------------


def _preferred(name: str, type_name: str) -> bool:
    """``type_name`` is one ``name`` takes first (every type, for most inputs)."""
    wanted = PREFERRED_TYPES.get(name)
    return wanted is None or type_name.rsplit("/", 1)[-1] in wanted


def _profile_topic(name: str) -> bool:
    """A name a profile can give (absolute, no white space: the profile loader's rule)."""
    return name.startswith("/") and not any(c.isspace() for c in name)


def picks(listed: Sequence[TopicInfo]) -> dict[str, TopicInfo]:
    """Model input → the bag's topic a starting profile maps it to: by type, the topic
    with most messages (ties by name), a topic used once. Inputs take their preferred types
    first (tracked objects the TrackedObjects, detections the DetectedObjects), then any
    type that carries them; the ground-truth inputs are never picked (a type cannot tell
    the truth from the stack's output); a topic without messages, or with a name no
    profile can give, is never picked."""
    found = by_type(listed)
    chosen: dict[str, TopicInfo] = {}
    used: set[str] = set()
    for preferred_only in (True, False):
        for name, topics in found.items():
            if name in chosen or name in TRUTH_INPUTS:
                continue
            for topic in topics:
                if (
                    topic.count
                    and topic.name not in used
                    and _profile_topic(topic.name)
                    and (not preferred_only or _preferred(name, normalise_type(topic.type)))
                ):
                    chosen[name] = topic
                    used.add(topic.name)
                    break
    return {name: chosen[name] for name in found if name in chosen}


#: Without ground truth the stack's tracks are the world (docs/real-drives.md): the frames
#: follow perception, as a real stack's profile times them, not the faster localisation.
PERCEPTION_REFERENCES = ("tracked_objects", "predictions", "detections_3d")


def frame_references(chosen: Mapping[str, TopicInfo]) -> list[str]:
    """The inputs that time a starting profile's frames, in the order tried: the ground
    truth when mapped; else perception's outputs, then the first other input that can."""
    if "actors" in chosen:
        return ["actors"]
    perceived = [r for r in PERCEPTION_REFERENCES if r in chosen]
    others = [r for r in REFERENCE_INPUTS if r in chosen and r not in perceived]
    return [*perceived, *others[:1]]


def starting_profile(survey: BagSurvey, name: str) -> str:
    """A profile YAML for the bag, to be checked and edited: each input mapped to the
    topic :func:`picks` chooses with its stored type, the other candidates as comments, the
    references :func:`frame_references` gives. Loads with the profile loader
    when every picked type has a decoder (only such types are picked). InputError when the
    bag has no message of a type that could time the frames."""
    chosen = picks(survey.topics)
    references = frame_references(chosen)
    if not references:
        types = carriers()
        wanted = "; ".join(f"{r}: {', '.join(types.get(r, ()))}" for r in REFERENCE_INPUTS)
        raise InputError(
            f"{survey.path}: no profile can be started: no message of a type that times the "
            f"frames ({wanted})"
        )
    found = by_type(survey.topics)
    used = {topic.name for topic in chosen.values()}
    lines = [
        f"# A starting profile for {_comment(Path(survey.path).name)}, written by `ads-rca",
        "# inspect --write-profile` from its topics and stored types (docs/recordings.md).",
        "# Check every input: a type says what a topic can carry, not whether it is the",
        "# stack's output or the ground truth. An input: {topic, type[, frame, path]}.",
        f"profile: {_scalar(name)}",
        f"description: {_scalar('started from ' + Path(survey.path).name)}",
        f"reference: {references[0] if len(references) == 1 else _flow_list(references)}",
        "inputs:",
    ]
    for input_name, topics in found.items():
        pick = chosen.get(input_name)
        free = [t for t in topics if t.name not in used]  # no other input's topic
        if pick is not None:
            lines.append(f"  {input_name}: {_flow(pick)}")
            lines.extend(_candidates(free, "    # also"))
        elif free and input_name in TRUTH_INPUTS:
            lines.append(f"  # {input_name}: ground truth or the stack's output? set it by hand:")
            lines.extend(_candidates(free, "  #  "))
        elif free:
            lines.append(f"  # {input_name}: no topic of its types has messages:")
            lines.extend(_candidates(free, "  #  "))
    lines += [
        "# metadata:                  # run facts a bag cannot carry",
        "#   camera_loc: [x, y, z]    # the camera in the ego frame (x forward, y right, z up), m",
        "#   ego_size: [l, w, h]      # the ego's box (m): without ground truth, its clearances",
        "#   ego_box_offset: 1.345    # box centre ahead of the ego pose (m; Autoware: rear axle)",
    ]
    return "\n".join(lines) + "\n"


def _flow_list(names: Sequence[str]) -> str:
    """``[a, b]``: input names (plain words, nothing to escape)."""
    return "[" + ", ".join(names) + "]"


def _candidates(topics: Sequence[TopicInfo], prefix: str) -> list[str]:
    """Comment lines naming candidate topics (escaped and cut: never a line break)."""
    lines = [
        f"{prefix} {_comment(t.name)} ({_comment(t.type)}, {t.count} messages)"
        for t in topics[:CANDIDATES_SHOWN]
    ]
    if len(topics) > CANDIDATES_SHOWN:
        lines.append(f"{prefix} ... and {len(topics) - CANDIDATES_SHOWN} more")
    return lines


def _flow(topic: TopicInfo) -> str:
    """``{topic: ..., type: ...}`` quoted and escaped by YAML's own emitter."""
    import yaml

    value = {"topic": topic.name, "type": normalise_type(topic.type)}
    text: str = yaml.safe_dump(
        value, default_flow_style=True, width=math.inf, allow_unicode=False, sort_keys=False
    )
    return text.strip()


def _scalar(text: str) -> str:
    """A YAML double-quoted scalar (every control and non-ASCII character escaped)."""
    import yaml

    dumped: str = yaml.safe_dump(text, default_style='"', width=math.inf, allow_unicode=False)
    return dumped.splitlines()[0]


def _comment(text: str) -> str:
    """Text for a YAML comment: escaped (no line break can end the comment) and cut."""
    return shown(text)


def profile_name(path: str | os.PathLike[str]) -> str:
    """A profile name from a file name: letters, digits, ``.``, ``_`` and ``-``."""
    name = re.sub(r"[^A-Za-z0-9._-]+", "-", Path(path).stem).strip("-.")
    return name or "my-stack"


# --- text ---------------------------------------------------------------------------------


def shown(name: str, limit: int = NAME_CHARS) -> str:
    """A name from the bag for a line: control characters escaped, then cut to ``limit``
    characters (a 10 kB topic name is a name, not a screenful)."""
    text = printable(name)
    return text if len(text) <= limit else text[: limit - 1] + "…"


def _time(ns: int | None) -> str:
    """A log time as UTC date and time with nanoseconds, and the raw nanoseconds."""
    if ns is None:
        return "-"
    try:
        moment = datetime.fromtimestamp(ns // 1_000_000_000, tz=timezone.utc)
    except (OverflowError, OSError, ValueError):
        return f"{ns} ns"
    return f"{moment:%Y-%m-%d %H:%M:%S}.{ns % 1_000_000_000:09d} UTC ({ns} ns)"


def _rate(topic: TopicInfo) -> str:
    rate = topic.rate_hz
    return "-" if rate is None else f"{rate:.2f} Hz"


def _span(topic: TopicInfo) -> str:
    span = topic.span_s
    return "-" if span is None else f"{span:.3f} s"


def listing_lines(survey: BagSurvey) -> list[str]:
    """What ``ros2 bag info`` shows: the files, the time span, every topic with its type,
    messages, rate and span, and the types nothing defines. Each line escaped."""
    lines: list[str] = []
    if survey.files:
        how = "; ".join(sorted(set(survey.methods)))
        yaml_said = "metadata.yaml compared" if survey.metadata_yaml else "no metadata.yaml"
        lines.append(
            f"bag: {shown(survey.path, 200)}: {len(survey.files)} storage file(s) "
            f"({shown(', '.join(survey.files), 200)}; {yaml_said}), listed from {how}"
        )
    first, last = survey.first_ns, survey.last_ns
    with_messages = sum(1 for t in survey.topics if t.count)
    lines.append(
        f"messages: {survey.message_count} on {with_messages} of {len(survey.topics)} "
        f"declared topics"
    )
    if first is not None and last is not None:
        lines.append(f"duration: {(last - first) / 1e9:.3f} s")
        lines.append(f"start: {_time(first)}")
        lines.append(f"end:   {_time(last)}")
    lines.append(
        f"topics: {len(survey.topics)} ({len(survey.topics) - with_messages} without messages)"
    )
    rows = [(shown(t.name), shown(t.type), str(t.count), _rate(t), _span(t)) for t in survey.topics]
    if rows:
        widths = [max(len(row[i]) for row in rows) for i in range(5)]
        header = ("topic", "type", "messages", "rate", "span")
        widths = [max(w, len(h)) for w, h in zip(widths, header, strict=True)]
        lines.extend(
            f"  {row[0]:<{widths[0]}}  {row[1]:<{widths[1]}}  {row[2]:>{widths[2]}}  "
            f"{row[3]:>{widths[3]}}  {row[4]:>{widths[4]}}".rstrip()
            for row in (header, *rows)
        )
    if not survey.stores_definitions:
        lines.append(
            "definitions: the bag stores none (a sqlite3 bag recorded before ROS 2 Iron, or "
            "written without them); listing needs none"
        )
    undefined = survey.undefined_types
    if undefined:
        lines.append(
            f"types without a definition: {len(undefined)} (not in the bag, under --msg-path "
            "nor among the types ads_rca knows: reading their messages needs --msg-path DIR "
            "with DIR/<package>/msg/<Type>.msg)"
        )
        lines.extend(f"  {shown(t)}" for t in undefined)
    return lines


def profile_lines(survey: BagSurvey) -> list[str]:
    """Per profile, the inputs it would map and those it would miss (and why); then the
    recommendation, or what the bag lacks. Each line escaped."""
    lines = ["profiles (an input is mapped when its topic holds messages of a type it takes):"]
    for fit in survey.fits:
        state = f"cannot read it: {fit.refused}" if fit.refused else "can read it"
        lines.append(f"  {fit.profile}: maps {', '.join(fit.mapped) or 'nothing'}; {state}")
        absent = [m.input for m in fit.inputs if m.why == NOT_IN_BAG]
        if absent:
            lines.append(f"    not in the bag: {', '.join(absent)}")
        empty = [m.input for m in fit.inputs if m.why == NO_MESSAGES]
        if empty:
            lines.append(f"    declared, 0 messages: {', '.join(empty)}")
        lines.extend(
            f"    {m.input}: {shown(m.topic)} {shown(m.why)}"
            for m in fit.inputs
            if m.why not in ("", NOT_IN_BAG, NO_MESSAGES)
        )
        elsewhere = [f"{m.input} on {shown(m.elsewhere[0])}" for m in fit.inputs if m.elsewhere]
        if elsewhere:
            lines.append(f"    of its types elsewhere: {'; '.join(elsewhere)}")
    recommendation = survey.recommendation
    if recommendation is None:
        return lines
    if recommendation.profile is not None:
        lines.append(f"recommended: --profile {recommendation.profile} ({recommendation.reason})")
        return lines
    lines.append(f"recommended: none ({recommendation.reason})")
    types = carriers()
    if recommendation.lacking:
        lines.append("the bag holds no message of a type that carries:")
        lines.extend(
            f"  {name} ({', '.join(types.get(name, ()))})" for name in recommendation.lacking
        )
    if recommendation.by_type:
        lines.append(
            "it holds, by type: "
            + "; ".join(
                f"{name} on {shown(found[0])}"
                + (f" (+{len(found) - 1} more)" if len(found) > 1 else "")
                for name, found in recommendation.by_type.items()
            )
        )
        if any(r in recommendation.by_type for r in REFERENCE_INPUTS):
            lines.append("--write-profile FILE starts a profile of these topics for you to check")
    return lines


__all__ = [
    "BagSurvey",
    "InputFit",
    "ProfileFit",
    "Recommendation",
    "TopicInfo",
    "builtin_profiles",
    "by_type",
    "carriers",
    "listing_lines",
    "picks",
    "profile_fits",
    "profile_lines",
    "profile_name",
    "recommend",
    "shown",
    "starting_profile",
    "survey_bag",
    "survey_contents",
]
