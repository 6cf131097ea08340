"""The message types of one bag, read from the bag itself: no message package installed.

A stack's recording carries its own layouts (MCAP schemas, rosbag2's sqlite3
``message_definitions``, read by :mod:`ads_rca.sources.bag.storage`). :class:`BagTypes` turns them
into a rosbags type store for that bag alone, the first layer that defines a type winning:
the bag's own text for it (what the bytes were written with), what the bag's other texts
embed for it, ``.msg`` files under ``--msg-path`` (for an older sqlite3 bag that stores
none), the definitions shipped with the package for the types the built-in profiles read
that old recordings carry without them (``sources/bag/definitions/``: Autoware's legacy
``autoware_auto_*_msgs``, ``autoware_adapi_v1_msgs/MrmState``), Kilted's standard types. A
text is parsed when a type first needs it: a recording of a whole stack carries hundreds of
types, a diagnosis reads a few. IDL texts are read without their preprocessor lines
(``#include``), which rosbag2 stores and rosbags' parser does not take.

A definition is untrusted text, and rosbags turns a registered type into Python source that
it executes. So before anything is registered, every name in it (types, fields, constants)
must be a plain ROS name, and every type must be usable: each type it needs defined, no type
that contains itself (it would recurse for ever), nesting at most :data:`MAX_NESTING` deep,
at most :data:`MAX_UNROLLED` elements of fixed arrays of strings or messages (rosbags writes
a line of code per element), no fixed array of length 0 (a zero-size element would let a
sequence count run unbounded over no bytes), no ``inf``/``nan`` constant (rosbags would write
Python that does not run). A definition that fails is a Problem naming the bag and the type; a type
asked for that cannot be used is one :class:`~ads_rca.errors.InputError` line.

What a definition costs is bounded too, before the parser sees it: at most
:data:`~ads_rca.sources.bag.storage.MAX_DEFINITION_BYTES` of text (checked as the storage is
read), :data:`MAX_DEFINITION_LINES` lines and :data:`MAX_FIELDS` fields and constants in one
text, :data:`MAX_FIELDS` in one type's closure. rosbags' ``.msg`` parser takes ~25 µs a line,
blank or not, and the code it generates for a type grows faster than its fields: a 1 MB text
of 88,123 fields took 75 s of CPU and 1.1 GB to register, a 1 MB text of newlines 25 s to
parse. At the caps a definition costs under a second (``bench/bench_definition_bomb.py``).
The real ones are far below them: the largest stored definition measured,
``visualization_msgs/msg/InteractiveMarkerUpdate`` with every dependency and all their
comments (ROS 2 common_interfaces, 2024-11), is 15 KB in 406 lines, its closure 112 fields
and constants in 17 types nested 7 deep; Autoware's ``PredictedObjects`` (the synthesiser's
published ``.msg`` files) is 6.5 KB, 168 lines, 67 fields in 21 types, the legacy
``autoware_auto_*`` IDL shipped here 4.4 KB, 50 ``;``; the most in one type,
``type_description_interfaces/msg/FieldType``, 93 (mostly constants). So each cap is 36 times
the largest real value or more, and a stack's own types of hundreds of fields (a vehicle's
CAN report) still read.
Pure: no rclpy, and the process-wide store of the contract path (``contract.rosmsg``) is not
touched.
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Iterable, Mapping, Sequence
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rosbags.interfaces import Nodetype
from rosbags.serde import SerdeError
from rosbags.typesys import (
    Stores,
    TypesysError,
    get_types_from_idl,
    get_types_from_msg,
    get_typestore,
)

from ads_rca.contract.errors import MalformedMessage
from ads_rca.errors import InputError
from ads_rca.foundation.files import Unreadable, read_regular
from ads_rca.foundation.text import printable
from ads_rca.problems import Problem
from ads_rca.sources.bag.storage import MAX_DEFINITION_BYTES

if TYPE_CHECKING:
    from typing import TypeAlias

    from rosbags.interfaces.typing import Constdefs, Fielddefs, FieldDesc, Typesdict

    #: rosbags' (constants, fields) of one type
    TypeDef: TypeAlias = tuple[Constdefs, Fielddefs]

#: Deepest chain of nested types accepted (real messages nest at most 7 deep; rosbags'
#: generated readers recurse once per level).
MAX_NESTING = 64
#: Most lines in one definition text, each ``;`` counted as a line too (an IDL text may hold
#: every member on one line): parsing costs ~25 µs a line, so ~0.4 s at the cap (the largest
#: real text, comments included, has 406 lines).
MAX_DEFINITION_LINES = 16384
#: Most fields and constants in the types one text defines, and in the closure of one type
#: (each type once): rosbags' generated code grows faster than the fields (4,096: ~0.8 s to
#: parse, register and decode once; 16,384: ~5 s). The largest real closure has 112.
MAX_FIELDS = 4096
#: Most elements of fixed arrays of strings or messages in one type's closure: rosbags'
#: generated reader has a line of code per such element (real types have none).
MAX_UNROLLED = 1024
#: A type name after normalisation: ``package/msg/Type`` (``srv``/``action`` too).
_TYPE_NAME = re.compile(r"[a-z][a-z0-9_]*/(msg|srv|action)/[A-Za-z][A-Za-z0-9_]*\Z")
_FIELD_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*\Z")
_IDL_SEPARATOR = "=" * 80 + "\n"
#: An IDL preprocessor line (``#include "pkg/msg/Type.idl"``): rosidl's files and the
#: ``ros2idl`` definitions rosbag2 stores have them, rosbags' parser takes none.
_PREPROCESSOR = re.compile(r"^[ \t]*#[^\n]*$", re.MULTILINE)
#: An IDL annotation (``@verbatim (language="comment", text="...")``, ``@default (value=0)``):
#: no layout depends on one, and rosbags' parser takes six times as long with them
#: (possessive, so a hostile text without its parenthesis costs no backtracking).
_ANNOTATION = re.compile(r'@[A-Za-z_]\w*(?:\s*\((?:"(?:\\.|[^"\\])*+"|[^()"])*+\))?')
MSG_PATH_HINT = "give --msg-path DIR with their .msg files"
_NOT_DEFINED = "type not defined"

#: What rosbags' parsers raise on text they cannot read (IDL checks with ``assert``).
_PARSE_ERRORS = (TypesysError, AssertionError, ValueError, IndexError, KeyError, RecursionError)
#: What deserialising damaged bytes can raise (rosbags checks each length against the bytes
#: that remain, so a damaged count is refused, never allocated).
DECODE_ERRORS = (
    SerdeError,
    ValueError,
    TypeError,
    KeyError,
    IndexError,
    AssertionError,
    OverflowError,
    RecursionError,
    UnicodeDecodeError,
)


def normalise(name: str) -> str:
    """``pkg/Type`` or ``pkg/msg/Type`` → ``pkg/msg/Type`` (any other shape unchanged)."""
    parts = name.split("/")
    return f"{parts[0]}/msg/{parts[1]}" if len(parts) == 2 else name


@cache
def _kilted() -> Typesdict:
    """Kilted's standard types (rosbags' store, read once)."""
    return get_typestore(Stores.ROS2_KILTED).fielddefs


#: The definitions shipped with the package (``definitions/<pkg>/msg/<Type>.msg|.idl``).
SHIPPED_DIR = Path(__file__).resolve().parent / "definitions"


@cache
def shipped_files() -> dict[str, Path]:
    """``pkg/msg/Type`` → its shipped definition file."""
    return {
        f"{path.parent.parent.name}/msg/{path.stem}": path
        for path in sorted(SHIPPED_DIR.glob("*/msg/*"))
        if path.suffix in (".msg", ".idl")
    }


@cache
def shipped(name: str) -> TypeDef | None:
    """``name`` as the package's shipped file defines it (None: none shipped). The files
    are the packages' published text: one that does not parse is a bug, raised."""
    path = shipped_files().get(name)
    if path is None:
        return None
    text = path.read_text(encoding="utf-8")
    parsed = _types_from_idl(text) if path.suffix == ".idl" else get_types_from_msg(text, name)
    return parsed[name]


class BagTypes:
    """One bag's message types: which are defined, and decoding CDR bytes by them."""

    def __init__(
        self,
        bag: str,
        definitions: Mapping[str, tuple[str, str]],
        msg_path: str | os.PathLike[str] | Sequence[str | os.PathLike[str]] | None = None,
    ) -> None:
        self.bag = bag
        #: Definitions that could not be used (hostile or damaged text, unreadable files),
        #: said as each is first needed.
        self.problems: list[Problem] = []
        #: type → why its definition is refused (said by ``require``)
        self._refused: dict[str, str] = {}
        #: the bag's texts not parsed yet (parsed when a type needs them)
        self._texts: dict[str, tuple[str, str]] = {}
        for raw, definition in definitions.items():
            self._texts.setdefault(normalise(raw), definition)
        self._own: dict[str, TypeDef] = {}
        #: what each parsed text defines besides its own type, by the type it came with
        self._embeds: dict[str, Typesdict] = {}
        self._embedded: dict[str, TypeDef] = {}
        self._from_msg_path: dict[str, TypeDef] = {}
        #: the ``--msg-path`` folders, and type → its ``.msg`` file there that was refused
        #: and why (a type without a definition then says so, not "give --msg-path")
        self._msg_paths = _directories(msg_path)
        self._msg_path_refused: dict[str, str] = {}
        for directory in self._msg_paths:
            self._read_msg_path(directory)
        self._store = get_typestore(Stores.EMPTY)

    # --- the layers ------------------------------------------------------------------------

    def _bag_text(self, name: str) -> TypeDef | None:
        """``name`` as the bag's own text for it defines it (parsed on first use: a
        recording of a whole stack carries hundreds of types, a diagnosis needs a few);
        the dependencies the text embeds are kept too."""
        if name in self._own:
            return self._own[name]
        pending = self._texts.pop(name, None)
        if pending is None:
            return None
        parsed = self._parse(name, *pending, self.bag)
        if parsed is None:
            return None
        self._own[name] = parsed.pop(name)
        self._embeds[name] = parsed
        for dep, typedef in parsed.items():
            self._embedded.setdefault(dep, typedef)
        return self._own[name]

    def _read_msg_path(self, directory: Path) -> None:
        """``.msg`` files under ``directory``: ``DIR/<pkg>/msg/<Type>.msg``,
        ``DIR/msg/<Type>.msg`` or ``DIR/<Type>.msg`` (the package: ``DIR``'s name)."""
        if not directory.is_dir():
            raise InputError(f"--msg-path {directory}: not a directory")
        files = [
            *sorted(directory.glob("*/msg/*.msg")),
            *sorted(directory.glob("msg/*.msg")),
            *sorted(directory.glob("*.msg")),
        ]
        for file in files:
            package = file.parent.parent.name if file.parent.name == "msg" else file.parent.name
            name = f"{package}/msg/{file.stem}"
            if name in self._from_msg_path:
                continue
            data = read_regular(file, MAX_DEFINITION_BYTES)
            if isinstance(data, Unreadable):
                why = data.issue
                if why.startswith("larger than"):  # its cap is no max_file_mb
                    why = f"larger than {MAX_DEFINITION_BYTES} bytes, a definition's limit"
                self._msg_path_refused.setdefault(name, f"{file} refused ({why})")
                self.problems.append(Problem(str(file), name, why, _NOT_DEFINED))
                continue
            try:
                text = data.decode("utf-8")
            except UnicodeDecodeError as error:
                why = f"not UTF-8: {error}"
                self._msg_path_refused.setdefault(name, f"{file} refused ({why})")
                self.problems.append(Problem(str(file), name, why, _NOT_DEFINED))
                continue
            parsed = self._parse(name, "ros2msg", text, str(file))
            if parsed is not None:
                self._from_msg_path.setdefault(name, parsed[name])
            elif name in self._refused and str(file) not in self._refused[name]:
                self._refused[name] += f" (in {file})"  # which file, when the type is named

    def _parse(self, name: str, encoding: str, text: str, where: str) -> Typesdict | None:
        """The types one definition text holds, every name checked (None: refused, and
        said as a Problem naming ``where`` and the type)."""
        if not _TYPE_NAME.match(name):
            self._refuse(name, "not a message type name (package/msg/Type)", where)
            return None
        too_large = _too_large(encoding, text)
        if too_large is not None:
            self._refuse(name, too_large, where)
            return None
        try:
            if encoding == "ros2msg":
                parsed = get_types_from_msg(text, name)
            elif encoding == "ros2idl":
                parsed = _types_from_idl(text)
            else:
                self._refuse(name, f"definition in encoding {encoding!r}, not ros2msg", where)
                return None
        except _PARSE_ERRORS as error:
            detail = str(error).splitlines()[0].rstrip(": ") if str(error) else ""
            self._refuse(name, f"unreadable definition: {detail or type(error).__name__}", where)
            return None
        bad = _bad_name(parsed)
        declared = sum(_declarations(typedef) for typedef in parsed.values())
        if bad is None and declared > MAX_FIELDS:
            bad = f"its definition declares {declared} fields and constants (limit {MAX_FIELDS})"
        if bad is None and name not in parsed:
            bad = f"the text does not define {name}"
        if bad is not None:
            self._refuse(name, bad, where)
            return None
        return parsed

    def _refuse(self, name: str, reason: str, where: str | None = None) -> None:
        self._refused.setdefault(name, reason)
        self.problems.append(Problem(where or self.bag, name, reason, _NOT_DEFINED))

    def _lookup(self, name: str) -> TypeDef | None:
        """The definition that decodes ``name``: the one registered already, else the
        bag's own text for it, what another of its texts embeds, ``--msg-path``, Kilted."""
        if name in self._refused:
            return None
        found = self._store.fielddefs.get(name) or self._bag_text(name)
        if name in self._refused:  # the bag's own text, just refused: its bytes are not another's
            return None
        for layer in (self._embedded, self._from_msg_path):
            if found is None:
                found = layer.get(name)
        if found is None and _TYPE_NAME.match(name):
            found = shipped(name)
        return found if found is not None else _kilted().get(name)

    def source(self, msg_type: str) -> str | None:
        """Where ``msg_type``'s definition comes from: "bag", "msg-path", "shipped" (the
        package's ``definitions/``), "standard" (Kilted's types), or None when it has none
        (or an unusable one)."""
        name = normalise(msg_type)
        if self._lookup(name) is None:
            return None
        if name in self._own or name in self._embedded:
            return "bag"
        if name in self._from_msg_path:
            return "msg-path"
        return "shipped" if name in shipped_files() else "standard"

    def differs_from_shipped(self, msg_type: str) -> bool:
        """The definitions used for ``msg_type`` and the types it holds are not all the
        shipped ones (another layout of a type the package ships: a bag written with another
        version of its package)."""
        order, _lacks, _broken = self._check(normalise(msg_type))
        for name in order:
            own = shipped(name) if name in shipped_files() else None
            used = self._lookup(name)
            if own is not None and used is not None and used[1] != own[1]:
                return True
        return False

    # --- checking and registering ----------------------------------------------------------

    def _check(self, root: str) -> tuple[list[str], list[str], str | None]:
        """``root``'s closure (dependencies first), the types it lacks ("U (needed by
        T)"), and why it is unusable (a refused definition, a cycle, too deep, a text whose
        embedded dependency is not the one used): iterative, so a hostile chain of 1,000
        types costs no recursion."""
        order: list[str] = []
        missing: list[str] = []
        broken: str | None = self._refused.get(root)
        depth: dict[str, int] = {}
        declared = 0  # fields and constants of the closure's types so far
        lines = 0  # lines of the bag's texts parsed for it so far
        on_path: list[str] = []
        stack: list[tuple[str, int]] = [(root, 0)]  # (type, 0 = enter / 1 = leave)
        while stack and broken is None:
            name, leaving = stack.pop()
            if leaving:
                on_path.pop()
                children = _children(self._lookup(name))
                depth[name] = 1 + max((depth.get(c, 0) for c in children), default=0)
                order.append(name)
                continue
            if name in depth:
                continue
            if len(on_path) >= MAX_NESTING:
                broken = f"its types nest more than {MAX_NESTING} deep"
                break
            if name in on_path:
                cycle = " → ".join([*on_path[on_path.index(name) :], name])
                broken = f"a type contains itself ({cycle})"
                break
            lines += self._pending_lines(name)
            if lines > MAX_DEFINITION_LINES:
                broken = f"its types' definitions hold more than {MAX_DEFINITION_LINES} lines"
                break
            typedef = self._lookup(name)
            declared += _declarations(typedef)
            if declared > MAX_FIELDS:
                broken = f"its types hold more than {MAX_FIELDS} fields and constants"
                break
            if typedef is None:
                if name in self._refused:
                    why = self._refused[name]
                    broken = why if name == root else f"{name}: {why}"
                elif name != root:
                    parent = on_path[-1] if on_path else root
                    missing.append(f"{name} (needed by {parent})")
                else:
                    missing.append(name)
                depth[name] = 0
                continue
            on_path.append(name)
            stack.append((name, 1))
            stack.extend((child, 0) for child in reversed(_children(typedef)))
        unrolled = sum(_unrolled(self._lookup(name)) for name in order)
        if broken is None and unrolled > MAX_UNROLLED:
            broken = (
                f"its fixed arrays of strings or messages hold {unrolled} elements "
                f"(limit {MAX_UNROLLED})"
            )
        for name in order if broken is None else []:
            for dep, typedef in self._embeds.get(name, {}).items():
                used = self._lookup(dep)
                if used is not None and used[1] != typedef[1]:
                    broken = f"{name} embeds a definition of {dep} other than the one used"
        return order, sorted(set(missing)), broken

    def _pending_lines(self, name: str) -> int:
        """The lines of the bag's text for ``name`` that looking it up would parse (0: none
        to parse, or one refused unparsed, which says why itself)."""
        pending = self._texts.get(name)
        if pending is None or name in self._store.fielddefs or _too_large(*pending) is not None:
            return 0
        return _lines(pending[1])

    def lacking(self, types: Iterable[str]) -> tuple[list[str], list[str]]:
        """What keeps ``types`` from being decoded: the types without a definition ("T",
        or "U (needed by T)"), and the unusable ones ("T: why"). Both empty: all can be."""
        missing: list[str] = []
        unusable: list[str] = []
        for msg_type in types:
            name = normalise(msg_type)
            _order, lacks, broken = self._check(name)
            missing.extend(lacks)
            if broken is not None:
                unusable.append(f"{name}: {broken}")
        return list(dict.fromkeys(missing)), list(dict.fromkeys(unusable))

    def require(self, types: Iterable[str], topics: Mapping[str, str] | None = None) -> None:
        """Make ``types`` decodable, or raise one InputError naming every type that is
        not (and suggesting ``--msg-path`` for those the bag does not define). ``topics``
        (topic → stored type): the topics to name beside an unusable type."""
        wanted = [normalise(t) for t in types]
        missing, unusable = self.lacking(wanted)
        said = [f"unusable definition of {_on_topics(entry, topics)}" for entry in unusable]
        if missing:
            listed = ", ".join(missing)
            said.insert(
                0, f"no definition for {listed} (the bag carries none; {self._hint(missing)})"
            )
        if said:
            raise InputError(printable(f"{self.bag}: " + "; ".join(said)))
        for name in wanted:
            self._register(name)

    def _hint(self, missing: list[str]) -> str:
        """Where the definitions of ``missing`` ("T" or "U (needed by T)") could come from:
        the ``.msg`` files under ``--msg-path`` that were refused and why, the types none
        there defines, or ``--msg-path`` when none was given."""
        names = [entry.split(" ", 1)[0] for entry in missing]
        said = [self._msg_path_refused[n] for n in names if n in self._msg_path_refused]
        absent = [n for n in names if n not in self._msg_path_refused]
        if absent and self._msg_paths:
            folders = ", ".join(map(str, self._msg_paths))
            said.append(f"no .msg file for {', '.join(absent)} under --msg-path {folders}")
        elif absent:
            said.append(MSG_PATH_HINT)
        return "; ".join(said)

    def _register(self, name: str) -> None:
        """Register ``name`` and its closure with this bag's store (once)."""
        if name in self._store.fielddefs:
            return
        order, _lacks, _broken = self._check(name)
        new = {
            n: typedef
            for n in order
            if n not in self._store.fielddefs and (typedef := self._lookup(n)) is not None
        }
        try:
            self._store.register(new)
        except TypesysError as error:
            reason = str(error).splitlines()[0]
            self._refuse(name, reason)
            raise InputError(
                printable(f"{self.bag}: unusable definition of {name}: {reason}")
            ) from None

    def decode(self, data: bytes | memoryview, msg_type: str) -> Any:
        """The rosbags message object of CDR ``data`` (MalformedMessage naming why, when
        the bytes are not one; InputError when the type has no usable definition)."""
        name = normalise(msg_type)
        if name not in self._store.fielddefs:
            self.require([name])
        try:
            return self._store.deserialize_cdr(data, name)
        except DECODE_ERRORS as error:
            detail = str(error).splitlines()[0] if str(error) else type(error).__name__
            raise MalformedMessage(f"cannot decode this {name}: {detail}") from error


def _on_topics(entry: str, topics: Mapping[str, str] | None) -> str:
    """``T: why`` as ``T (topic /a, /b): why`` with the topics stored as ``T``."""
    name, _, why = entry.partition(": ")
    on = sorted(topic for topic, stored in (topics or {}).items() if normalise(stored) == name)
    if not on:
        return entry
    shown = ", ".join(on[:3]) + (f" and {len(on) - 3} more" if len(on) > 3 else "")
    return f"{name} ({'topic' if len(on) == 1 else 'topics'} {shown}): {why}"


def _directories(
    msg_path: str | os.PathLike[str] | Sequence[str | os.PathLike[str]] | None,
) -> list[Path]:
    if msg_path is None:
        return []
    if isinstance(msg_path, (str, os.PathLike)):
        return [Path(msg_path)]
    return [Path(p) for p in msg_path]


def _types_from_idl(text: str) -> Typesdict:
    """Types of an ``ros2idl`` definition: one IDL text, or rosbag2's concatenation of
    them (each after a separator line and an ``IDL: pkg/msg/Type`` header)."""
    if not text.startswith(_IDL_SEPARATOR + "IDL: "):
        return get_types_from_idl(_plain_idl(text))
    parsed: Typesdict = {}
    for part in text.split(_IDL_SEPARATOR)[1:]:
        header, _, idl = part.partition("\n")
        if not header.startswith("IDL: "):
            raise TypesysError(f"an IDL part starts with {header[:40]!r}, not 'IDL: '")
        parsed.update(get_types_from_idl(_plain_idl(idl)))
    return parsed


def _plain_idl(text: str) -> str:
    """An IDL text without preprocessor lines and annotations (what rosbags' parser reads
    of it: the modules, constants and structs)."""
    return _ANNOTATION.sub("", _PREPROCESSOR.sub("", text))


def _named(desc: FieldDesc) -> tuple[str | None, bool, int | None]:
    """What a field holds: the type it names (itself or as its elements' type; None for
    base types), whether its elements are read one by one (messages, strings: rosbags
    unrolls a fixed array of them), and its fixed array length (None: not a fixed array)."""
    nodetype, spec = desc
    if isinstance(spec, str):
        return spec, True, None
    inner, size = spec
    if isinstance(inner, str):  # a base type: (name, string bound)
        return None, inner in ("string", "wstring"), None
    fixed = size if nodetype == Nodetype.ARRAY else None
    element = inner[1]
    if isinstance(element, str):
        return element, True, fixed
    return None, element[0] in ("string", "wstring"), fixed


def _unrolled(typedef: TypeDef | None) -> int:
    """Elements of a type's fixed arrays of strings or messages (numbers are read whole)."""
    fields = typedef[1] if typedef is not None else []
    return sum(
        fixed
        for _field, desc in fields
        for _named_type, one_by_one, fixed in [_named(desc)]
        if one_by_one and fixed is not None
    )


def _lines(text: str) -> int:
    """Lines of a definition text, each ``;`` counted as one more (what parsing it costs)."""
    return text.count("\n") + text.count(";") + 1


def _too_large(encoding: str, text: str) -> str | None:
    """Why a definition text is too large to parse (None: it is not), told from the text
    alone: its ``.msg`` declarations (lines that are not blank, comments or rosbag2's
    separators), then its lines."""
    if encoding == "ros2msg":
        declared = sum(
            1
            for line in text.splitlines()
            if (kept := line.strip()) and not kept.startswith(("#", "MSG:", "=" * 80))
        )
        if declared > MAX_FIELDS:
            return f"its definition declares {declared} fields and constants (limit {MAX_FIELDS})"
    lines = _lines(text)
    if lines > MAX_DEFINITION_LINES:
        return f"its definition has {lines} lines (limit {MAX_DEFINITION_LINES})"
    return None


def _declarations(typedef: TypeDef | None) -> int:
    """Fields and constants of one type (0: none known)."""
    return 0 if typedef is None else len(typedef[0]) + len(typedef[1])


def _children(typedef: TypeDef | None) -> list[str]:
    """The types a type's fields name (directly, or as array/sequence elements)."""
    fields = typedef[1] if typedef is not None else []
    return list(dict.fromkeys(n for _f, desc in fields if (n := _named(desc)[0]) is not None))


def _bad_name(parsed: Typesdict) -> str | None:
    """The first name in ``parsed`` that is not a plain ROS name, a fixed array of length
    0 or a constant that is not a finite number, said; None when there is none."""
    for name, (consts, fields) in parsed.items():
        if not _TYPE_NAME.match(name):
            return f"it defines a type named {name!r}"
        for const, _type, value in consts:
            if not _FIELD_NAME.match(const):
                return f"{name} has a constant named {const!r}"
            if isinstance(value, float) and not math.isfinite(value):
                return f"{name}.{const} is {value}"  # rosbags would write it as Python code
        for field, desc in fields:
            named, _one_by_one, fixed = _named(desc)
            if not _FIELD_NAME.match(field):
                return f"{name} has a field named {field!r}"
            if fixed is not None and fixed < 1:
                return f"{name}.{field} is a fixed array of length {fixed}"
            if named is not None and not _TYPE_NAME.match(named):
                return f"{name}.{field} refers to a type named {named!r}"
    return None
