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

#: Deepest chain of nested types accepted (real messages nest about 8 deep; rosbags'
#: generated readers recurse once per level).
MAX_NESTING = 64
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
        for directory in _directories(msg_path):
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
                self.problems.append(Problem(str(file), name, data.issue, _NOT_DEFINED))
                continue
            try:
                text = data.decode("utf-8")
            except UnicodeDecodeError as error:
                self.problems.append(Problem(str(file), name, f"not UTF-8: {error}", _NOT_DEFINED))
                continue
            parsed = self._parse(name, "ros2msg", text, str(file))
            if parsed is not None:
                self._from_msg_path.setdefault(name, parsed[name])

    def _parse(self, name: str, encoding: str, text: str, where: str) -> Typesdict | None:
        """The types one definition text holds, every name checked (None: refused, and
        said as a Problem naming ``where`` and the type)."""
        if not _TYPE_NAME.match(name):
            self._refuse(name, "not a message type name (package/msg/Type)", where)
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
            typedef = self._lookup(name)
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

    def require(self, types: Iterable[str]) -> None:
        """Make ``types`` decodable, or raise one InputError naming every type that is
        not (and suggesting ``--msg-path`` for those the bag does not define)."""
        wanted = [normalise(t) for t in types]
        missing, unusable = self.lacking(wanted)
        said = [f"unusable definition of {entry}" for entry in unusable]
        if missing:
            listed = ", ".join(missing)
            said.insert(0, f"no definition for {listed} (the bag carries none; {MSG_PATH_HINT})")
        if said:
            raise InputError(printable(f"{self.bag}: " + "; ".join(said)))
        for name in wanted:
            self._register(name)

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
