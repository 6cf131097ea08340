"""Message types read from the bag itself: real bags written with rosbags' own writer (MCAP
and sqlite3), their types registered from the published ``.msg`` files of the stacks'
packages, read back with no message package installed. A bag without definitions names every
type it lacks; ``--msg-path`` supplies them; hostile definitions are refused, one line each."""

from __future__ import annotations

import dataclasses
import os
import sqlite3
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from ads_rca.contract.errors import MalformedMessage
from ads_rca.errors import InputError
from ads_rca.sources.bag.message_types import (
    MAX_DEFINITION_LINES,
    MAX_FIELDS,
    MAX_NESTING,
    BagTypes,
)
from ads_rca.sources.bag.reader import load_bag
from ads_rca.sources.bag.storage import MAX_DEFINITION_BYTES

SYNTH_MSGS = Path(__file__).resolve().parents[1] / "ads_rca" / "synth" / "msgs"
DETECTED = "autoware_perception_msgs/msg/DetectedObjects"
COLLISION = "carla_msgs/msg/CarlaCollisionEvent"
STRING = "std_msgs/msg/String"
HINT = "(the bag carries none; give --msg-path DIR with their .msg files)"
SEP = "=" * 80 + "\n"
STORAGES = [StoragePlugin.MCAP, StoragePlugin.SQLITE3]
#: any well-formed hash: rosbags' writer stores it, our reader never checks it
HASH = "RIHS01_" + "0" * 64


def synth_store() -> Typestore:
    """Kilted plus every published .msg file the synthesiser writes recordings with."""
    store = get_typestore(Stores.ROS2_KILTED)
    types = {}
    for file in sorted(SYNTH_MSGS.glob("*/msg/*.msg")):
        name = f"{file.parent.parent.name}/msg/{file.stem}"
        types.update(get_types_from_msg(file.read_text(encoding="utf-8"), name))
    store.register(types)
    return store


STORE = synth_store()


def header(store: Typestore, sec: int) -> Any:
    stamp = store.types["builtin_interfaces/msg/Time"](sec=sec, nanosec=250_000_000)
    return store.types["std_msgs/msg/Header"](stamp=stamp, frame_id="map")


def detected_objects(sec: int) -> Any:
    """Two objects, every kind of field: nested messages, sequences, numpy arrays, floats."""
    t = STORE.types
    point = t["geometry_msgs/msg/Point"]
    objects = []
    for row in range(2):
        pose = t["geometry_msgs/msg/Pose"](
            position=point(x=10.5 + row, y=-3.25, z=0.5),
            orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.6, w=0.8),
        )
        covariance = np.arange(36, dtype=np.float64) * (row + 1) / 7
        twist = t["geometry_msgs/msg/Twist"](
            linear=t["geometry_msgs/msg/Vector3"](x=4.0 - row, y=0.125, z=0.0),
            angular=t["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.1),
        )
        kinematics = t["autoware_perception_msgs/msg/DetectedObjectKinematics"](
            pose_with_covariance=t["geometry_msgs/msg/PoseWithCovariance"](
                pose=pose, covariance=covariance
            ),
            has_position_covariance=True,
            orientation_availability=2,
            twist_with_covariance=t["geometry_msgs/msg/TwistWithCovariance"](
                twist=twist, covariance=np.zeros(36)
            ),
            has_twist=True,
            has_twist_covariance=False,
        )
        shape = t["autoware_perception_msgs/msg/Shape"](
            type=0,
            footprint=t["geometry_msgs/msg/Polygon"](
                points=[t["geometry_msgs/msg/Point32"](x=1.0, y=2.0, z=0.0)]
            ),
            dimensions=t["geometry_msgs/msg/Vector3"](x=4.5, y=1.875, z=1.5),
        )
        label = t["autoware_perception_msgs/msg/ObjectClassification"](label=1, probability=0.75)
        objects.append(
            t["autoware_perception_msgs/msg/DetectedObject"](
                existence_probability=0.5 + row / 4,
                classification=[label],
                kinematics=kinematics,
                shape=shape,
            )
        )
    return t[DETECTED](header=header(STORE, sec), objects=objects)


def collision(sec: int) -> Any:
    vector = STORE.types["geometry_msgs/msg/Vector3"](x=1.5, y=-2.0, z=0.0)
    return STORE.types[COLLISION](
        header=header(STORE, sec), other_actor_id=42, normal_impulse=vector
    )


MESSAGES = [
    ("/perception/object_recognition/detection/objects", DETECTED, detected_objects(1)),
    ("/carla/ego_vehicle/collision", COLLISION, collision(2)),
    ("/perception/object_recognition/detection/objects", DETECTED, detected_objects(3)),
]


def plain(value: Any) -> Any:
    """A rosbags message as nested builtins, arrays with their dtype (exact comparison
    across two type stores' classes)."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        fields = {f.name: plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
        return {"class": type(value).__name__, **fields}
    if isinstance(value, np.ndarray):
        return (str(value.dtype), value.tolist())
    if isinstance(value, list):
        return [plain(item) for item in value]
    return value


def write_bag(
    path: Path,
    storage: StoragePlugin,
    messages: list[tuple[str, str, Any]] = MESSAGES,
    store: Typestore = STORE,
    definitions: dict[str, str] | None = None,
) -> Path:
    """A rosbag2 bag as rosbags writes it (definitions stored); ``definitions``: type →
    the text to store instead of the store's own (the bytes are still the store's)."""
    with Writer(path, version=9, storage_plugin=storage) as writer:
        connections = {}
        for topic, msg_type, _msg in messages:
            if topic not in connections:
                text = (definitions or {}).get(msg_type)
                if text is None:
                    connections[topic] = writer.add_connection(topic, msg_type, typestore=store)
                else:
                    connections[topic] = writer.add_connection(
                        topic, msg_type, msgdef=text, rihs01=HASH
                    )
        for stamp, (topic, msg_type, msg) in enumerate(messages, start=1):
            data = b"\x00\x01\x00\x00" if msg is None else store.serialize_cdr(msg, msg_type)
            writer.write(connections[topic], stamp * 100_000_000, bytes(data))
    return path


def old_sqlite3_bag(path: Path, messages: list[tuple[str, str, Any]] = MESSAGES) -> Path:
    """A sqlite3 bag as rosbag2 before Iron wrote it: no ``message_definitions`` table."""
    write_bag(path, StoragePlugin.SQLITE3, messages)
    connection = sqlite3.connect(path / f"{path.name}.db3")
    with connection:
        connection.execute("DROP TABLE message_definitions")
        connection.execute("UPDATE schema SET schema_version = 3")
    connection.close()
    return path


@pytest.mark.parametrize("storage", STORAGES, ids=lambda s: s.name.lower())
def test_the_storage_keeps_each_types_definition(tmp_path: Path, storage: StoragePlugin) -> None:
    contents = load_bag(write_bag(tmp_path / "bag", storage))
    assert contents.definitions == {
        name: ("ros2msg", STORE.generate_msgdef(name, ros_version=2)[0])
        for name in (DETECTED, COLLISION)
    }
    assert contents.problems == []


@pytest.mark.parametrize("storage", STORAGES, ids=lambda s: s.name.lower())
def test_messages_decode_exactly_with_the_bags_own_types(
    tmp_path: Path, storage: StoragePlugin
) -> None:
    contents = load_bag(write_bag(tmp_path / "bag", storage))
    types = contents.types()
    decoded = [types.decode(m.data, m.msg_type) for m in contents.messages]
    assert [plain(d) for d in decoded] == [plain(msg) for _t, _n, msg in MESSAGES]
    assert decoded[0].objects[1].kinematics.pose_with_covariance.pose.position.x == 11.5
    assert decoded[1].other_actor_id == 42
    # the bag's own text defines the types and the dependencies it embeds
    assert [types.source(t) for t in (DETECTED, "autoware_perception_msgs/msg/Shape")] == [
        "bag",
        "bag",
    ]
    assert types.problems == []


def test_a_bag_without_definitions_names_every_type_it_lacks(tmp_path: Path) -> None:
    bag = old_sqlite3_bag(tmp_path / "old")
    contents = load_bag(bag)
    assert contents.definitions == {}
    types = contents.types()
    with pytest.raises(InputError) as error:
        types.require([DETECTED, COLLISION, "std_msgs/msg/Header"])
    assert str(error.value) == f"{bag}: no definition for {DETECTED}, {COLLISION} {HINT}"
    with pytest.raises(InputError) as error:
        types.decode(contents.messages[1].data, COLLISION)
    assert str(error.value) == f"{bag}: no definition for {COLLISION} {HINT}"
    assert types.source("std_msgs/msg/Header") == "standard"


def test_a_standard_type_needs_no_definition(tmp_path: Path) -> None:
    text = STORE.types[STRING](data="hello")
    bag = old_sqlite3_bag(tmp_path / "old", [("/chatter", STRING, text)])
    contents = load_bag(bag)
    assert contents.types().decode(contents.messages[0].data, STRING).data == "hello"


def test_msg_path_supplies_the_types_an_old_bag_lacks(tmp_path: Path) -> None:
    contents = load_bag(old_sqlite3_bag(tmp_path / "old"))
    types = contents.types(msg_path=SYNTH_MSGS)
    decoded = [types.decode(m.data, m.msg_type) for m in contents.messages]
    assert [plain(d) for d in decoded] == [plain(msg) for _t, _n, msg in MESSAGES]
    assert types.source(DETECTED) == "msg-path"
    assert types.source("std_msgs/msg/Header") == "standard"


#: layout → (where the .msg file is, the directory given), under one temporary directory
LAYOUTS = {
    "flat": ("carla_msgs", "carla_msgs"),
    "package": ("carla_msgs/msg", "carla_msgs"),
    "msg directory": ("carla_msgs/msg", "carla_msgs/msg"),
    "packages": ("carla_msgs/msg", "."),
}


@pytest.mark.parametrize("layout", sorted(LAYOUTS))
def test_msg_path_layouts_give_the_package(tmp_path: Path, layout: str) -> None:
    """``DIR/<Type>.msg`` (the package: DIR's name), ``DIR/msg/<Type>.msg``,
    ``DIR/<pkg>/msg/<Type>.msg``, and the ``msg`` directory itself."""
    contents = load_bag(old_sqlite3_bag(tmp_path / "old", [MESSAGES[1]]))
    where, given = LAYOUTS[layout]
    (tmp_path / "msgs" / where).mkdir(parents=True)
    source = SYNTH_MSGS / "carla_msgs" / "msg" / "CarlaCollisionEvent.msg"
    (tmp_path / "msgs" / where / source.name).write_bytes(source.read_bytes())
    types = contents.types(msg_path=tmp_path / "msgs" / given)
    assert types.source(COLLISION) == "msg-path"
    assert plain(types.decode(contents.messages[0].data, COLLISION)) == plain(MESSAGES[1][2])


def test_a_missing_dependency_is_named_with_the_type_needing_it(tmp_path: Path) -> None:
    bag = old_sqlite3_bag(tmp_path / "old")
    partial = tmp_path / "msgs" / "autoware_perception_msgs" / "msg"
    partial.mkdir(parents=True)
    source = SYNTH_MSGS / "autoware_perception_msgs" / "msg" / "DetectedObjects.msg"
    (partial / source.name).write_bytes(source.read_bytes())
    types = load_bag(bag).types(msg_path=tmp_path / "msgs")
    needed = f"autoware_perception_msgs/msg/DetectedObject (needed by {DETECTED})"
    with pytest.raises(InputError) as error:
        types.require([DETECTED])
    assert str(error.value) == (
        f"{bag}: no definition for {needed} (the bag carries none; no .msg file for "
        f"autoware_perception_msgs/msg/DetectedObject under --msg-path {tmp_path / 'msgs'})"
    )


#: how a ``.msg`` file under ``--msg-path`` is made unusable → what the error says of it
REFUSED_MSG_FILES = {
    "too big": f"larger than {MAX_DEFINITION_BYTES} bytes",
    "FIFO": "FIFO",
    "not UTF-8": "not UTF-8",
}


@pytest.mark.parametrize("kind", sorted(REFUSED_MSG_FILES))
def test_a_refused_msg_path_file_is_named_with_why(tmp_path: Path, kind: str) -> None:
    """A type whose only ``.msg`` under ``--msg-path`` was refused (too big, a FIFO, not
    UTF-8) names that file and why, not "give --msg-path DIR" (issue 43, item 6a)."""
    bag = old_sqlite3_bag(tmp_path / "old", [MESSAGES[1]])
    folder = tmp_path / "msgs" / "carla_msgs" / "msg"
    folder.mkdir(parents=True)
    file = folder / "CarlaCollisionEvent.msg"
    source = SYNTH_MSGS / "carla_msgs" / "msg" / file.name
    if kind == "too big":
        file.write_bytes(source.read_bytes() + b"#" * MAX_DEFINITION_BYTES)
    elif kind == "FIFO":
        os.mkfifo(file)
    else:
        file.write_bytes(source.read_bytes() + "# caf\xe9\n".encode("latin-1"))
    types = load_bag(bag).types(msg_path=tmp_path / "msgs")
    with pytest.raises(InputError) as error:
        types.require([COLLISION])
    message = str(error.value)
    assert message.startswith(f"{bag}: no definition for {COLLISION} (the bag carries none; ")
    assert f"{file} refused (" in message
    assert REFUSED_MSG_FILES[kind] in message
    assert "give --msg-path" not in message


def test_msg_path_must_be_a_directory(tmp_path: Path) -> None:
    with pytest.raises(InputError) as error:
        BagTypes("bag", {}, tmp_path / "nowhere")
    assert str(error.value) == f"--msg-path {tmp_path / 'nowhere'}: not a directory"


@pytest.mark.parametrize("storage", STORAGES, ids=lambda s: s.name.lower())
def test_the_bags_own_text_wins_over_the_standard_types(
    tmp_path: Path, storage: StoragePlugin
) -> None:
    """A stack built against another layout of a standard type: its bytes are read with
    the layout the bag carries."""
    store = get_typestore(Stores.EMPTY)
    store.register(get_types_from_msg("string data\nuint32 extra\n", STRING))
    msg = store.types[STRING](data="hello", extra=7)
    bag = write_bag(tmp_path / "bag", storage, [("/chatter", STRING, msg)], store)
    contents = load_bag(bag)
    types = contents.types()
    decoded = types.decode(contents.messages[0].data, STRING)
    assert (decoded.data, decoded.extra, types.source(STRING)) == ("hello", 7, "bag")


READING_IDL = """module demo_msgs {
  module msg {
    struct Reading {
      std_msgs::msg::Header header;
      sequence<double> values;
      string label;
    };
  };
};
"""


@pytest.mark.parametrize("storage", STORAGES, ids=lambda s: s.name.lower())
def test_an_idl_definition_is_read_too(tmp_path: Path, storage: StoragePlugin) -> None:
    """rosbag2 stores ``ros2idl`` text for types defined in IDL (the writer's own format
    detection: a separator line, then ``IDL: pkg/msg/Type``)."""
    reading = "demo_msgs/msg/Reading"
    store = get_typestore(Stores.ROS2_KILTED)
    store.register(get_types_from_idl(READING_IDL))
    msg = store.types[reading](header=header(store, 5), values=np.array([1.5, -2.0]), label="a")
    text = f"{SEP}IDL: {reading}\n{READING_IDL}"
    bag = write_bag(tmp_path / "bag", storage, [("/r", reading, msg)], store, {reading: text})
    contents = load_bag(bag)
    assert contents.definitions == {reading: ("ros2idl", text)}
    types = contents.types()
    assert plain(types.decode(contents.messages[0].data, reading)) == plain(msg)
    assert (types.source(reading), types.problems) == ("bag", [])


LEGACY_SHAPE = "autoware_auto_perception_msgs/msg/Shape"
#: rosidl's IDL of a type, as rosbag2 stores it: include lines, annotations, comments.
SHAPE_IDL = """#include "geometry_msgs/msg/Polygon.idl"

module autoware_auto_perception_msgs {
  module msg {
    module Shape_Constants {
      const uint8 BOUNDING_BOX=0;
    };
    @verbatim (language="comment", text=
      " x: the length (BOUNDING_BOX) or diameter (CYLINDER)" "\\n" " (in m)")
    struct Shape {
      /** its type */
      uint8 type;
      geometry_msgs::msg::Polygon footprint;
      @default (value=0.0)
      geometry_msgs::msg::Vector3 dimensions;
    };
  };
};
"""


def test_an_idl_definition_with_includes_and_annotations_is_read() -> None:
    types = BagTypes("bag", {LEGACY_SHAPE: ("ros2idl", f"{SEP}IDL: {LEGACY_SHAPE}\n{SHAPE_IDL}")})
    types.require([LEGACY_SHAPE])
    assert (types.source(LEGACY_SHAPE), types.problems) == ("bag", [])
    assert not types.differs_from_shipped(LEGACY_SHAPE)


def test_the_shipped_definitions_decode_the_legacy_types_an_old_bag_lacks(tmp_path: Path) -> None:
    """autoware_auto_*_msgs and MrmState need no --msg-path; a standard type stays Kilted's,
    and a definition under --msg-path wins over the shipped one."""
    types = BagTypes("bag", {})
    legacy = "autoware_auto_perception_msgs/msg/PredictedObjects"
    types.require([legacy, "autoware_adapi_v1_msgs/msg/MrmState"])
    assert types.source(legacy) == types.source(LEGACY_SHAPE) == "shipped"
    assert types.source("geometry_msgs/msg/Polygon") == "standard"
    package = tmp_path / "autoware_auto_perception_msgs" / "msg"
    package.mkdir(parents=True)
    (package / "Shape.msg").write_text("uint8 type\nfloat64 size\n")
    mine = BagTypes("bag", {}, msg_path=tmp_path)
    assert mine.source(LEGACY_SHAPE) == "msg-path" and mine.differs_from_shipped(LEGACY_SHAPE)


def test_a_type_embedding_another_layout_of_a_bag_type_is_refused() -> None:
    """Wrap's bytes hold the String its text embeds; the bag's own String has another
    layout, so Wrap cannot be decoded with it (String itself still can)."""
    wrap = "demo_msgs/msg/Wrap"
    types = BagTypes(
        "bag",
        {
            STRING: ("ros2msg", "string data\nuint32 extra\n"),
            wrap: ("ros2msg", f"std_msgs/String s\n{SEP}MSG: std_msgs/String\nstring data\n"),
        },
    )
    with pytest.raises(InputError) as error:
        types.require([wrap])
    assert str(error.value) == (
        f"bag: unusable definition of {wrap}: {wrap} embeds a definition of {STRING} other "
        "than the one used"
    )
    decoded = types.decode(b"\x00\x01\x00\x00\x02\x00\x00\x00a\x00\x00\x00\x09\x00\x00\x00", STRING)
    assert (decoded.data, decoded.extra) == ("a", 9)


def test_damaged_bytes_are_a_malformed_message(tmp_path: Path) -> None:
    contents = load_bag(write_bag(tmp_path / "bag", StoragePlugin.MCAP))
    types = contents.types()
    with pytest.raises(MalformedMessage) as error:
        types.decode(contents.messages[0].data[:60], DETECTED)
    assert str(error.value).startswith(f"cannot decode this {DETECTED}: ")
    assert "\n" not in str(error.value)


# --- hostile definitions -------------------------------------------------------------------

CHAIN = (
    "evil_msgs/N1 next\n"
    + "".join(f"{SEP}MSG: evil_msgs/N{i}\nevil_msgs/N{i + 1} next\n" for i in range(1, 1000))
    + f"{SEP}MSG: evil_msgs/N1000\nint32 x\n"
)
#: type → (definition text, the Problem said when the bag is read (None: none), why the
#: type cannot be used)
HOSTILE: dict[str, tuple[str, str | None, str]] = {
    "evil_msgs/msg/Garbage": (
        "this is not a definition !!!\n\x00",
        "unreadable definition: Could not parse",
        "unusable definition of evil_msgs/msg/Garbage: unreadable definition: Could not parse",
    ),
    "evil_msgs/msg/Dangling": (
        "nope_msgs/Missing thing\n",
        None,
        f"no definition for nope_msgs/msg/Missing (needed by evil_msgs/msg/Dangling) {HINT}",
    ),
    "evil_msgs/msg/../../../etc/passwd": (
        "int32 x\n",
        "not a message type name (package/msg/Type)",
        "unusable definition of evil_msgs/msg/../../../etc/passwd: not a message type name "
        "(package/msg/Type)",
    ),
    "evil_msgs/msg/Sneaky": (
        f"int32 x\n{SEP}MSG: Evil/msg/Bad\nint8 y\n",
        "it defines a type named 'Evil/msg/Bad'",
        "unusable definition of evil_msgs/msg/Sneaky: it defines a type named 'Evil/msg/Bad'",
    ),
    "evil_msgs/msg/N0": (
        CHAIN,
        None,
        f"unusable definition of evil_msgs/msg/N0: its types nest more than {MAX_NESTING} deep",
    ),
    "evil_msgs/msg/Tree": (
        "evil_msgs/Tree[] children\nint32 x\n",
        None,
        "unusable definition of evil_msgs/msg/Tree: a type contains itself "
        "(evil_msgs/msg/Tree → evil_msgs/msg/Tree)",
    ),
    "evil_msgs/msg/Huge": (
        f"Big[4000000000] big\n{SEP}MSG: evil_msgs/Big\nuint8 b\n",
        None,
        "unusable definition of evil_msgs/msg/Huge: its fixed arrays of strings or messages "
        "hold 4000000000 elements (limit 1024)",
    ),
    "evil_msgs/msg/Infinite": (
        "float64 HUGE=1e999\nint32 x\n",
        "evil_msgs/msg/Infinite.HUGE is inf",
        "unusable definition of evil_msgs/msg/Infinite: evil_msgs/msg/Infinite.HUGE is inf",
    ),
    "evil_msgs/msg/Fields": (
        "".join(f"int8 f{i}\n" for i in range(MAX_FIELDS + 1)),
        f"its definition declares {MAX_FIELDS + 1} fields and constants (limit {MAX_FIELDS})",
        f"unusable definition of evil_msgs/msg/Fields: its definition declares {MAX_FIELDS + 1} "
        f"fields and constants (limit {MAX_FIELDS})",
    ),
    "evil_msgs/msg/Blank": (
        "int8 x\n" + "\n" * MAX_DEFINITION_LINES,
        f"its definition has {MAX_DEFINITION_LINES + 2} lines (limit {MAX_DEFINITION_LINES})",
        f"unusable definition of evil_msgs/msg/Blank: its definition has "
        f"{MAX_DEFINITION_LINES + 2} lines (limit {MAX_DEFINITION_LINES})",
    ),
}


@pytest.mark.parametrize("storage", STORAGES, ids=lambda s: s.name.lower())
@pytest.mark.parametrize("evil", sorted(HOSTILE))
def test_a_hostile_definition_is_one_line_and_spoils_nothing_else(
    tmp_path: Path, storage: StoragePlugin, evil: str
) -> None:
    text, problem, unusable = HOSTILE[evil]
    messages = [*MESSAGES[:2], ("/evil", evil, None)]
    bag = write_bag(tmp_path / "bag", storage, messages, definitions={evil: text})
    contents = load_bag(bag)
    assert contents.definitions[evil] == ("ros2msg", text)
    types = contents.types()
    # the bag's other types are untouched, and a text nobody needs is never parsed
    decoded = [types.decode(m.data, m.msg_type) for m in contents.messages[:2]]
    assert [plain(d) for d in decoded] == [plain(msg) for _t, _n, msg in MESSAGES[:2]]
    assert types.problems == []
    with pytest.raises(InputError) as error:
        types.decode(contents.messages[2].data, evil)
    assert str(error.value) == f"{bag}: {unusable}"
    expected = [] if problem is None else [(str(bag), evil, problem)]
    assert [(p.file, p.field, p.issue) for p in types.problems] == expected


@pytest.mark.parametrize("storage", STORAGES, ids=lambda s: s.name.lower())
def test_a_definition_over_the_limit_is_reported_and_not_read(
    tmp_path: Path, storage: StoragePlugin
) -> None:
    evil = "evil_msgs/msg/Large"
    text = "int32 x\n" + "#" * MAX_DEFINITION_BYTES
    messages = [MESSAGES[1], ("/evil", evil, None)]
    bag = write_bag(tmp_path / "bag", storage, messages, definitions={evil: text})
    contents = load_bag(bag)
    assert evil not in contents.definitions
    where = "schema 2" if storage == StoragePlugin.MCAP else "message_definitions"
    issue = f"definition of {evil} has {len(text)} bytes (limit {MAX_DEFINITION_BYTES})"
    said = [(p.field, p.issue, p.action) for p in contents.problems]
    assert said == [(where, issue, "definition ignored")]
    with pytest.raises(InputError) as error:
        contents.types().require([evil])
    assert str(error.value) == f"{bag}: no definition for {evil} {HINT}"


def test_a_constant_is_data_never_code() -> None:
    """rosbags writes constants into Python source it runs: a value that looks like code
    stays a string."""
    code = "'); import os; os.exit(3) #"
    types = BagTypes("bag", {"evil_msgs/msg/C": ("ros2msg", f'string CODE="{code}"\nint32 x\n')})
    decoded = types.decode(b"\x00\x01\x00\x00\x07\x00\x00\x00", "evil_msgs/msg/C")
    assert (decoded.x, decoded.CODE) == (7, code)


# --- what a definition may cost ------------------------------------------------------------

#: The field bomb of issue 41: one 1 MB text of 88,123 fields (parsed and registered, it took
#: 80 s and 1.1 GB).
FIELD_BOMB = "".join(f"int8 f{i}\n" for i in range(88_123))


def test_a_closure_over_the_caps_is_refused_though_each_text_is_under_them() -> None:
    """Each text within the caps, the closure of a type not: refused before the rest is
    parsed or anything registered."""
    half = MAX_FIELDS // 2 + 1
    wide = {
        "evil_msgs/msg/Wide": ("ros2msg", "evil_msgs/A a\nevil_msgs/B b\n"),
        "evil_msgs/msg/A": ("ros2msg", "".join(f"int8 a{i}\n" for i in range(half))),
        "evil_msgs/msg/B": ("ros2msg", "".join(f"int8 b{i}\n" for i in range(half))),
    }
    with pytest.raises(InputError) as error:
        BagTypes("bag", wide).require(["evil_msgs/msg/Wide"])
    assert str(error.value) == (
        "bag: unusable definition of evil_msgs/msg/Wide: its types hold more than "
        f"{MAX_FIELDS} fields and constants"
    )
    parts = 5
    blank = "int8 x\n" + "\n" * (MAX_DEFINITION_LINES // parts)
    long = {f"evil_msgs/msg/L{i}": ("ros2msg", blank) for i in range(parts)}
    long["evil_msgs/msg/Long"] = (
        "ros2msg",
        "".join(f"evil_msgs/L{i} l{i}\n" for i in range(parts)),
    )
    types = BagTypes("bag", long)
    with pytest.raises(InputError) as error:
        types.require(["evil_msgs/msg/Long"])
    assert str(error.value) == (
        "bag: unusable definition of evil_msgs/msg/Long: its types' definitions hold more than "
        f"{MAX_DEFINITION_LINES} lines"
    )
    assert len(types._texts) >= 1  # the texts past the budget were never parsed


def test_an_idl_text_of_too_many_members_is_refused() -> None:
    """An IDL text may hold every member on one line: each ``;`` counts as a line, and the
    parsed members as fields."""
    members = " ".join(f"int8 f{i};" for i in range(MAX_FIELDS + 1))
    idl = f"module evil_msgs {{ module msg {{ struct Idl {{ {members} }}; }}; }};\n"
    types = BagTypes("bag", {"evil_msgs/msg/Idl": ("ros2idl", idl)})
    with pytest.raises(InputError) as error:
        types.require(["evil_msgs/msg/Idl"])
    assert str(error.value) == (
        f"bag: unusable definition of evil_msgs/msg/Idl: its definition declares "
        f"{MAX_FIELDS + 1} fields and constants (limit {MAX_FIELDS})"
    )
    one_line = " ".join(f"int8 f{i};" for i in range(MAX_DEFINITION_LINES))
    idl = f"module evil_msgs {{ module msg {{ struct Idl {{ {one_line} }}; }}; }};"
    types = BagTypes("bag", {"evil_msgs/msg/Idl": ("ros2idl", idl)})
    with pytest.raises(InputError) as error:
        types.require(["evil_msgs/msg/Idl"])
    assert str(error.value).endswith(
        f"its definition has {MAX_DEFINITION_LINES + 4} lines (limit {MAX_DEFINITION_LINES})"
    )


def test_a_msg_path_file_over_the_caps_is_refused_naming_the_file(tmp_path: Path) -> None:
    folder = tmp_path / "msgs" / "evil_msgs" / "msg"
    folder.mkdir(parents=True)
    (folder / "Bomb.msg").write_text(FIELD_BOMB, encoding="utf-8")
    types = BagTypes("bag", {}, msg_path=tmp_path / "msgs")
    reason = f"its definition declares 88123 fields and constants (limit {MAX_FIELDS})"
    assert [(p.file, p.field, p.issue) for p in types.problems] == [
        (str(folder / "Bomb.msg"), "evil_msgs/msg/Bomb", reason)
    ]
    with pytest.raises(InputError) as error:
        types.require(["evil_msgs/msg/Bomb"], {"/bomb": "evil_msgs/Bomb"})
    assert (
        str(error.value)
        == f"bag: unusable definition of evil_msgs/msg/Bomb (topic /bomb): {reason} "
        f"(in {folder / 'Bomb.msg'})"
    )


def test_a_refused_text_of_a_standard_type_is_not_replaced_by_the_standard_one() -> None:
    """The bag's bytes were written with its own text: a refused one leaves the type
    unusable, even the first time it is asked for (it was Kilted's layout then)."""
    types = BagTypes("bag", {"nav_msgs/msg/Odometry": ("ros2msg", FIELD_BOMB)})
    assert types.source("nav_msgs/msg/Odometry") is None
    with pytest.raises(InputError):
        types.require(["nav_msgs/msg/Odometry"])


def test_the_real_definitions_are_far_below_the_caps() -> None:
    """The stacks' real definitions (the synthesiser's published .msg files, the shipped
    legacy Autoware ones, Kilted's) as rosbag2 stores them, each with every dependency:
    usable, and at most a tenth of each cap."""
    from writers.autoware_bags import _closure, definition, typestore

    store = typestore()
    for name, (consts, fields) in store.fielddefs.items():
        text = definition(name)
        encoding = "ros2idl" if text.startswith(SEP + "IDL: ") else "ros2msg"
        assert BagTypes("bag", {name: (encoding, text)}).lacking([name]) == ([], []), name
        assert (text.count("\n") + text.count(";") + 1) * 10 <= MAX_DEFINITION_LINES, name
        closure = [store.fielddefs[n] for n in _closure(name)]
        declared = len(consts) + len(fields) + sum(len(c) + len(f) for c, f in closure)
        assert declared * 10 <= MAX_FIELDS, name


#: (storage, where the bomb is) of each bag the command line reads
BOMBED = {
    "mcap": (StoragePlugin.MCAP, "bag"),
    "sqlite3": (StoragePlugin.SQLITE3, "bag"),
    "msg-path": (StoragePlugin.SQLITE3, "msg-path"),
}


@pytest.mark.parametrize("command", ["inspect", "diagnose"])
@pytest.mark.parametrize("kind", sorted(BOMBED))
def test_a_field_bomb_is_one_line_through_the_command_line(
    tmp_path: Path, kind: str, command: str
) -> None:
    """A real bag whose DetectedObjects definition is the field bomb (stored in the bag, or
    in a ``--msg-path`` file beside a bag that stores none), read through the autoware
    profile by the command a user runs, its memory limited: one line naming the type and
    the topic, exit 2, within seconds (it took 80 s and 1.1 GB)."""
    from commandline import assert_clean, run_limited

    storage, where = BOMBED[kind]
    options: list[str] = []
    if where == "bag":
        bag = write_bag(tmp_path / "bag", storage, definitions={DETECTED: FIELD_BOMB})
    else:
        bag = old_sqlite3_bag(tmp_path / "bag")
        folder = tmp_path / "msgs" / "autoware_perception_msgs" / "msg"
        folder.mkdir(parents=True)
        (folder / "DetectedObjects.msg").write_text(FIELD_BOMB, encoding="utf-8")
        options = ["--msg-path", str(tmp_path / "msgs")]
    started = time.perf_counter()
    done = run_limited(command, str(bag), "--profile", "autoware", *options, timeout=30)
    elapsed = time.perf_counter() - started
    assert_clean(done, 2)
    topic = MESSAGES[0][0]
    file = "" if where == "bag" else f" (in {tmp_path / 'msgs' / Path(DETECTED + '.msg')})"
    assert done.stderr.splitlines() == [
        f"ads-rca {command}: error: {bag}: unusable definition of {DETECTED} (topic {topic}): "
        f"its definition declares 88123 fields and constants (limit {MAX_FIELDS}){file}"
    ]
    assert elapsed < 15, elapsed
