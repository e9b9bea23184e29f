"""ROS 2 messages of the logs: definitions, construction and CDR serialisation via `rosbags`.

Every channel of a navcosim log is a ROS 2 message (``cdr`` encoding, ``ros2msg`` schema) so
Foxglove, ``ros2 bag``, rosbags and @mcap/core read the whole file.
Standard messages are ROS 2 Humble's, serialised by a rosbags type store that holds only those a log
is made of (`LOG_TYPES`; rosbags' whole Humble store, hundreds of types, costs ~0.2 s to import,
and is loaded only when a message outside them is asked for). The messages a run writes at its
start (the maps, the plan, the goal, the obstacles, the scan's template, a bumper) have layouts
fixed by their few strings and sequences: `make` builds them as plain `Message` objects and
`serialize` packs them with `struct` (`_PACKERS`; the tests compare every byte with rosbags'), so a
run neither imports rosbags (~8 ms) nor generates its classes and serialisers (~12 ms); every other
message, and the schemas of types outside `LOG_TYPES`, go through rosbags (`TYPESTORE`, made on
first use). Each component's signals get one
generated struct, ``navcosim_msgs/msg/<Component>Signals``: a ``builtin_interfaces/Time stamp``
followed by one ``float64`` per variable, so every record of a channel has the same size and
NumPy loads a whole channel with one ``frombuffer``.
"""

from __future__ import annotations

import functools
import keyword
import math
import re
import struct
import sys
from types import ModuleType

import numpy as np

SIGNALS_PACKAGE = "navcosim_msgs"
CDR_HEADER = b"\x00\x01\x00\x00"  # CDR little-endian encapsulation, options 0
SIGNAL_STAMP_BYTES = 8  # builtin_interfaces/Time: int32 sec, uint32 nanosec
SIGNAL_VALUES_OFFSET = len(CDR_HEADER) + SIGNAL_STAMP_BYTES  # float64 fields start 8-aligned after it
SEPARATOR = "=" * 80
# Channel metadata of a `/signals/<component>` channel, read back by `cosim.logs`.
SIGNAL_NAMES_KEY = "navcosim.signal_names"  # JSON list of the original variable names
SIGNAL_UNITS_KEY = "navcosim.signal_units"  # JSON list of their units ("" for none), same order
SIGNAL_INPUTS_KEY = "navcosim.signal_inputs"  # how many of the first names are inputs (step channels)
COMPONENT_KEY = "navcosim.component"
# Channel metadata of a `/text_signals/<component>` channel (String and Binary variables).
TEXT_COMPONENT_KEY = "navcosim.text_component"
TEXT_NAMES_KEY = "navcosim.text_names"  # JSON list of the original variable names
TEXT_TYPES_KEY = "navcosim.text_types"  # JSON list of their FMI types, "String" or "Binary"
TEXT_INPUTS_KEY = "navcosim.text_inputs"  # how many of the first names are inputs

_TIME_DEFINITION = "int32 sec\nuint32 nanosec\n"
_stamp = struct.Struct("<iI")


def new_typestore():
    """A fresh rosbags type store (ROS 2 Humble); callers register their own custom types in it."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_HUMBLE)


# The ROS 2 Humble messages a navcosim log is made of, with every message they contain, as in
# rosbags' Humble store (`tests/record/test_ros_conventions.py` compares them): "type name" fields and
# "type NAME=value" constants; `T[N]` is an array of N, `T[]` a sequence.
LOG_TYPES = {
    "builtin_interfaces/msg/Time": "int32 sec; uint32 nanosec",
    "builtin_interfaces/msg/Duration": "int32 sec; uint32 nanosec",
    "std_msgs/msg/Header": "builtin_interfaces/msg/Time stamp; string frame_id",
    "std_msgs/msg/ColorRGBA": "float32 r; float32 g; float32 b; float32 a",
    "geometry_msgs/msg/Point": "float64 x; float64 y; float64 z",
    "geometry_msgs/msg/Quaternion": "float64 x; float64 y; float64 z; float64 w",
    "geometry_msgs/msg/Vector3": "float64 x; float64 y; float64 z",
    "geometry_msgs/msg/Pose": "geometry_msgs/msg/Point position; geometry_msgs/msg/Quaternion orientation",
    "geometry_msgs/msg/PoseStamped": "std_msgs/msg/Header header; geometry_msgs/msg/Pose pose",
    "geometry_msgs/msg/PoseWithCovariance": "geometry_msgs/msg/Pose pose; float64[36] covariance",
    "geometry_msgs/msg/Twist": "geometry_msgs/msg/Vector3 linear; geometry_msgs/msg/Vector3 angular",
    "geometry_msgs/msg/TwistWithCovariance": "geometry_msgs/msg/Twist twist; float64[36] covariance",
    "geometry_msgs/msg/Transform": (
        "geometry_msgs/msg/Vector3 translation; geometry_msgs/msg/Quaternion rotation"
    ),
    "geometry_msgs/msg/TransformStamped": (
        "std_msgs/msg/Header header; string child_frame_id; geometry_msgs/msg/Transform transform"
    ),
    "tf2_msgs/msg/TFMessage": "geometry_msgs/msg/TransformStamped[] transforms",
    "nav_msgs/msg/Odometry": (
        "std_msgs/msg/Header header; string child_frame_id; geometry_msgs/msg/PoseWithCovariance pose; "
        "geometry_msgs/msg/TwistWithCovariance twist"
    ),
    "nav_msgs/msg/Path": "std_msgs/msg/Header header; geometry_msgs/msg/PoseStamped[] poses",
    "nav_msgs/msg/MapMetaData": (
        "builtin_interfaces/msg/Time map_load_time; float32 resolution; uint32 width; uint32 height; "
        "geometry_msgs/msg/Pose origin"
    ),
    "nav_msgs/msg/OccupancyGrid": "std_msgs/msg/Header header; nav_msgs/msg/MapMetaData info; int8[] data",
    "sensor_msgs/msg/LaserScan": (
        "std_msgs/msg/Header header; float32 angle_min; float32 angle_max; float32 angle_increment; "
        "float32 time_increment; float32 scan_time; float32 range_min; float32 range_max; "
        "float32[] ranges; float32[] intensities"
    ),
    "sensor_msgs/msg/CompressedImage": "std_msgs/msg/Header header; string format; uint8[] data",
    "visualization_msgs/msg/UVCoordinate": "float32 u; float32 v",
    "visualization_msgs/msg/MeshFile": "string filename; uint8[] data",
    "visualization_msgs/msg/Marker": (
        "int32 ARROW=0; int32 CUBE=1; int32 SPHERE=2; int32 CYLINDER=3; int32 LINE_STRIP=4; "
        "int32 LINE_LIST=5; int32 CUBE_LIST=6; int32 SPHERE_LIST=7; int32 POINTS=8; "
        "int32 TEXT_VIEW_FACING=9; int32 MESH_RESOURCE=10; int32 TRIANGLE_LIST=11; int32 ADD=0; "
        "int32 MODIFY=0; int32 DELETE=2; int32 DELETEALL=3; "
        "std_msgs/msg/Header header; string ns; int32 id; int32 type; int32 action; "
        "geometry_msgs/msg/Pose pose; geometry_msgs/msg/Vector3 scale; std_msgs/msg/ColorRGBA color; "
        "builtin_interfaces/msg/Duration lifetime; bool frame_locked; geometry_msgs/msg/Point[] points; "
        "std_msgs/msg/ColorRGBA[] colors; string texture_resource; sensor_msgs/msg/CompressedImage texture; "
        "visualization_msgs/msg/UVCoordinate[] uv_coordinates; string text; string mesh_resource; "
        "visualization_msgs/msg/MeshFile mesh_file; bool mesh_use_embedded_materials"
    ),
    "visualization_msgs/msg/MarkerArray": "visualization_msgs/msg/Marker[] markers",
    "sensor_msgs/msg/Imu": (
        "std_msgs/msg/Header header; geometry_msgs/msg/Quaternion orientation; "
        "float64[9] orientation_covariance; geometry_msgs/msg/Vector3 angular_velocity; "
        "float64[9] angular_velocity_covariance; geometry_msgs/msg/Vector3 linear_acceleration; "
        "float64[9] linear_acceleration_covariance"
    ),
    "std_msgs/msg/Bool": "bool data",
}


def _field_type(text: str):
    """rosbags' description of a field type written as in `LOG_TYPES`."""
    from rosbags.interfaces import Nodetype

    if text.endswith("]"):
        element, _, size = text[:-1].partition("[")
        kind = Nodetype.ARRAY if size else Nodetype.SEQUENCE
        return (kind, (_field_type(element), int(size or 0)))
    if "/" in text:
        return (Nodetype.NAME, text)
    return (Nodetype.BASE, (text, 0))


def log_fielddefs() -> dict:
    """`LOG_TYPES` as rosbags' type definitions (what `Typestore.register` takes)."""
    definitions = {}
    for typename, text in LOG_TYPES.items():
        constants, fields = [], []
        for entry in text.split("; "):
            kind, _, name = entry.partition(" ")
            name, equals, value = name.partition("=")
            if equals:
                constants.append((name, kind, int(value)))
            else:
                fields.append((name, _field_type(kind)))
        definitions[typename] = (constants, fields)
    return definitions


def _sizes(generate, prefix: str):
    def make(fields, typename, store):
        function, size = generate(fields, store)
        return {f"getsize_{prefix}": function, f"size_{prefix}": size}

    return make


def _log_typestore():
    """rosbags' type store of `LOG_TYPES`, making each type's class (`_LazyTypes`) and functions
    (`_LazyMsgdef`) as they are used (rosbags' stock store where its internals are not as expected)."""
    try:  # rosbags' generators (internal): where they are not as expected, the stock store is used
        from dataclasses import fields as dataclass_fields

        from rosbags.interfaces import Msgdef
        from rosbags.serde import cdr, ros1
        from rosbags.typesys.base import normalize_fieldname
        from rosbags.typesys.codegen import generate_python_code
        from rosbags.typesys.store import Typestore

        makers = {
            **dict.fromkeys(("getsize_cdr", "size_cdr"), _sizes(cdr.generate_getsize_cdr, "cdr")),
            **dict.fromkeys(("getsize_ros1", "size_ros1"), _sizes(ros1.generate_getsize_ros1, "ros1")),
            "serialize_cdr_le": lambda f, t, s: {"serialize_cdr_le": cdr.generate_serialize_cdr(f, s, "le")},
            "serialize_cdr_be": lambda f, t, s: {"serialize_cdr_be": cdr.generate_serialize_cdr(f, s, "be")},
            "deserialize_cdr_le": lambda f, t, s: {
                "deserialize_cdr_le": cdr.generate_deserialize_cdr(f, s, "le")
            },
            "deserialize_cdr_be": lambda f, t, s: {
                "deserialize_cdr_be": cdr.generate_deserialize_cdr(f, s, "be")
            },
            "serialize_ros1": lambda f, t, s: {"serialize_ros1": ros1.generate_serialize_ros1(f, s)},
            "deserialize_ros1": lambda f, t, s: {"deserialize_ros1": ros1.generate_deserialize_ros1(f, s)},
            "getsize_ros1_to_cdr": lambda f, t, s: {
                "getsize_ros1_to_cdr": ros1.generate_ros1_to_cdr(f, t, s, copy=False)
            },
            "ros1_to_cdr": lambda f, t, s: {"ros1_to_cdr": ros1.generate_ros1_to_cdr(f, t, s, copy=True)},
            "getsize_cdr_to_ros1": lambda f, t, s: {
                "getsize_cdr_to_ros1": ros1.generate_cdr_to_ros1(f, t, s, copy=False)
            },
            "cdr_to_ros1": lambda f, t, s: {"cdr_to_ros1": ros1.generate_cdr_to_ros1(f, t, s, copy=True)},
        }
        lazy = {field.name for field in dataclass_fields(Msgdef)} == {"name", "fields", "cls", *makers}
    except (ImportError, AttributeError, TypeError):
        lazy = False
    if not lazy:
        from rosbags.typesys import Stores, get_typestore

        store = get_typestore(Stores.EMPTY)
        store.register(log_fielddefs())
        return store

    class _LazyMsgdef:
        """A rosbags `Msgdef` whose 13 generated functions (CDR and ROS 1, each endianness, sizes
        and conversions) are made one by one on first use, not all at once: generating every
        function of a Marker and what it contains cost ~0.1 s."""

        def __init__(self, store, typename: str) -> None:
            self.name = typename
            self.fields = [(normalize_fieldname(name), desc) for name, desc in store.fielddefs[typename][1]]
            self._store = store

        def __getattr__(self, attribute: str):  # called for what is not made yet
            if attribute == "cls":  # the class too: serialising a type's empty sequence needs no class
                self.cls = self._store.types[self.name]
                return self.cls
            if attribute not in makers:
                raise AttributeError(attribute)
            made = makers[attribute](self.fields, self.name, self._store)
            for name, value in made.items():
                setattr(self, name, value)
            return made[attribute]

    class _LazyTypes(dict):
        """A type store's `types`: each registered type's class (rosbags' generated dataclass, made
        by rosbags' code generator as `register` makes it) is made on first use, one type at a time."""

        def __init__(self, fielddefs: dict) -> None:
            super().__init__()
            self._fielddefs = fielddefs

        def __missing__(self, typename: str):
            if typename not in self._fielddefs:
                raise KeyError(typename)
            module = ModuleType("rosbags.usertypes")
            sys.modules[module.__name__] = module  # as `Typestore.register` does (dataclasses looks it up)
            exec(generate_python_code({typename: self._fielddefs[typename]}), module.__dict__)  # noqa: S102
            made = self[typename] = getattr(module, typename.replace("/", "__"))
            return made

        def __contains__(self, typename: object) -> bool:
            return dict.__contains__(self, typename) or typename in self._fielddefs

        def get(self, typename: str, default=None):
            return self[typename] if typename in self else default

    class _LogTypestore(Typestore):
        """rosbags' type store, making each type's class (`_LazyTypes`) and functions
        (`_LazyMsgdef`) as they are used."""

        def __init__(self) -> None:
            super().__init__()
            self.types = _LazyTypes(self.fielddefs)

        def get_msgdef(self, typename: str):
            if typename not in self.cache:
                self.cache[typename] = _LazyMsgdef(self, typename)
            return self.cache[typename]

    store = _LogTypestore()
    store.fielddefs.update(log_fielddefs())  # what `register` records of them; classes on first use
    return store


_stores: dict[str, object] = {}  # "log": `TYPESTORE`; "humble": rosbags' whole Humble store


def _typestore():
    """`TYPESTORE`, made on first use."""
    store = _stores.get("log")
    if store is None:
        store = _stores["log"] = _log_typestore()
    return store


def __getattr__(name: str):
    # `TYPESTORE`: rosbags' type store of `LOG_TYPES` (and of the Humble types `_known` adds), made
    # on first use: a run that writes only `_PACKERS`' messages never imports rosbags.
    if name == "TYPESTORE":
        return _typestore()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _known(typename: str) -> str:
    """`typename`, after registering it (and what it contains) from rosbags' Humble store into
    `TYPESTORE` when it is not one of `LOG_TYPES`; an unknown name is left for rosbags to refuse."""
    if typename in LOG_TYPES:
        return typename
    store = _typestore()
    if typename not in store.fielddefs:
        from rosbags.interfaces import Nodetype

        humble = _stores.get("humble")
        if humble is None:
            humble = _stores["humble"] = new_typestore()
        wanted, pending = {}, [typename]
        while pending:
            name = pending.pop()
            if name in wanted or name in store.fielddefs or name not in humble.fielddefs:
                continue
            wanted[name] = humble.fielddefs[name]
            for _, description in wanted[name][1]:
                while description[0] in (Nodetype.ARRAY, Nodetype.SEQUENCE):
                    description = description[1][0]
                if description[0] == Nodetype.NAME:
                    pending.append(description[1])
        if wanted:
            store.register(wanted)
    return typename


def split_time(t_ns: int) -> tuple[int, int]:
    """(sec, nanosec) of a time in nanoseconds, as builtin_interfaces/Time holds it."""
    sec, nanosec = divmod(int(t_ns), 1_000_000_000)
    return sec, nanosec


# --- names -----------------------------------------------------------------------------------


def field_name(name: str) -> str:
    """A valid ROS 2 field name for a variable name (lowercase, [a-z][a-z0-9_]*, no '__', no
    trailing '_'); `waypoints[3,1]` -> `waypoints_3_1`, `Steering.Angle` -> `steering_angle`."""
    text = re.sub(r"([a-z0-9])([A-Z])", r"\1_\2", name)
    text = re.sub(r"[^a-z0-9]+", "_", text.lower()).strip("_")
    text = re.sub(r"_+", "_", text)
    if not text:
        text = "value"
    if not text[0].isalpha():
        text = "v_" + text
    if keyword.iskeyword(text):
        # rosbags and mcap-ros2-support build Python classes from the schema
        text += "_value"
    return text


def field_names(names: list[str]) -> list[str]:
    """Unique ROS 2 field names for `names`, in order; clashes get a numeric suffix."""
    used: set[str] = {"stamp"}
    fields = []
    for name in names:
        base = field_name(name)
        candidate, counter = base, 2
        while candidate in used:
            candidate = f"{base}_{counter}"
            counter += 1
        used.add(candidate)
        fields.append(candidate)
    return fields


def signals_type_name(component: str) -> str:
    """`pure_pursuit` -> `navcosim_msgs/msg/PurePursuitSignals`."""
    words = re.split(r"[^A-Za-z0-9]+", component)
    camel = "".join(word[:1].upper() + word[1:] for word in words if word)
    if not camel or not camel[0].isalpha():
        camel = "Component" + camel
    return f"{SIGNALS_PACKAGE}/msg/{camel}Signals"


# --- definitions ----------------------------------------------------------------------------


def signals_definition(fields: list[str]) -> str:
    """ros2msg schema text of a signals struct, with the Time dependency appended as ROS 2 does."""
    body = "builtin_interfaces/Time stamp\n" + "".join(f"float64 {field}\n" for field in fields)
    return f"{body}{SEPARATOR}\nMSG: builtin_interfaces/Time\n{_TIME_DEFINITION}"


def text_type_name(component: str) -> str:
    """`pure_pursuit` -> `navcosim_msgs/msg/PurePursuitText`."""
    return signals_type_name(component).removesuffix("Signals") + "Text"


def text_definition(fields: list[str], fmi_types: list[str]) -> str:
    """ros2msg schema text of a text struct: a String is a `string`, a Binary a `uint8[]`."""
    body = "builtin_interfaces/Time stamp\n" + "".join(
        f"{'string' if fmi_type == 'String' else 'uint8[]'} {field}\n"
        for field, fmi_type in zip(fields, fmi_types, strict=True)
    )
    return f"{body}{SEPARATOR}\nMSG: builtin_interfaces/Time\n{_TIME_DEFINITION}"


def text_payload(t_ns: int, values: list[str | bytes]) -> bytes:
    """CDR bytes of a text struct: a string is its UTF-8 bytes and a NUL after a uint32 length that
    counts the NUL, a uint8[] its bytes after a uint32 count; each uint32 4-aligned (from the end
    of the encapsulation header)."""
    body = bytearray(_stamp.pack(*split_time(t_ns)))
    for value in values:
        data = value.encode() + b"\0" if isinstance(value, str) else bytes(value)
        body += b"\0" * (-len(body) % 4)
        body += struct.pack("<I", len(data)) + data
    return CDR_HEADER + bytes(body)


def message_definition(typename: str) -> str:
    """ros2msg schema text of a standard message (with its dependencies), as rosbags'
    `generate_msgdef(typename, ros_version=2)` writes it: made from `LOG_TYPES` for theirs, by rosbags
    for any other."""
    if typename not in LOG_TYPES:
        return _typestore().generate_msgdef(_known(typename), ros_version=2)[0]
    used: list[str] = []  # the types it contains, in the order rosbags lists them

    def visit(name: str) -> None:
        for kind, _ in _log_fields(name)[1]:
            element = kind.partition("[")[0]
            if "/" in element and element not in used:
                used.append(element)
                visit(element)

    visit(typename)
    sections = [f"{SEPARATOR}\nMSG: {_short_name(name)}\n{_definition_body(name)}" for name in used]
    return _definition_body(typename) + "".join(sections)


def _short_name(typename: str) -> str:
    """`pkg/msg/Type` -> `pkg/Type`, as a ros2msg schema names a type."""
    return typename.replace("/msg/", "/")


def _definition_body(typename: str) -> str:
    """The ros2msg lines of one type of `LOG_TYPES`: its constants, then its fields."""
    constants, fields = _log_fields(typename)
    lines = [f"{kind} {name}={value}" for name, kind, value in constants]
    lines += [f"{_short_name(kind)} {name}" for kind, name in fields]
    return "".join(f"{line}\n" for line in lines)


@functools.cache
def _log_fields(typename: str) -> tuple[list[tuple[str, str, int]], list[tuple[str, str]]]:
    """The constants (name, type, value) and the fields (type, name) of a type of `LOG_TYPES`, as
    written there (read-only: made once per type)."""
    constants, fields = [], []
    for entry in LOG_TYPES[typename].split("; "):
        kind, _, name = entry.partition(" ")
        name, equals, value = name.partition("=")
        if equals:
            constants.append((name, kind, int(value)))
        else:
            fields.append((kind, name))
    return constants, fields


def register_definition(typestore, typename: str, definition: str) -> None:
    """Register a ros2msg schema text (main type and the `MSG:` sections) into `typestore`."""
    from rosbags.typesys import get_types_from_msg

    sections = definition.split(SEPARATOR + "\n")
    types = dict(get_types_from_msg(sections[0], typename))
    for section in sections[1:]:
        head, _, body = section.partition("\n")
        name = head.removeprefix("MSG:").strip()
        parts = name.split("/")
        if len(parts) == 2:
            name = f"{parts[0]}/msg/{parts[1]}"
        if name not in typestore.types:
            types.update(get_types_from_msg(body, name))
    typestore.register({name: value for name, value in types.items() if name not in typestore.types})


# --- construction --------------------------------------------------------------------------


class Message:
    """A message of a type of `LOG_TYPES` as `make` builds it: its fields (in the order of the
    definition; a Python keyword gets a trailing `_`, as in rosbags' classes) as attributes, its
    constants as class attributes, its type name in `__msgtype__`; equal to a message of the same
    type with equal fields. rosbags serialises it as one of its own classes (it reads the fields)."""

    __slots__ = ()
    __msgtype__ = ""

    def __init__(self, *values, **fields) -> None:
        names = self.__slots__
        if len(values) > len(names):
            raise TypeError(f"{type(self).__name__}() takes {len(names)} fields, got {len(values)}")
        given = dict(zip(names, values, strict=False))
        for name, value in fields.items():
            if name not in names or name in given:
                raise TypeError(f"{type(self).__name__}() got an unexpected or repeated field {name!r}")
            given[name] = value
        if len(given) != len(names):
            missing = ", ".join(name for name in names if name not in given)
            raise TypeError(f"{type(self).__name__}() is missing the fields {missing}")
        for name in names:
            object.__setattr__(self, name, given[name])

    def __eq__(self, other):
        if type(other) is not type(self):
            return NotImplemented
        return tuple(getattr(self, name) for name in self.__slots__) == tuple(
            getattr(other, name) for name in other.__slots__
        )

    __hash__ = None

    def __repr__(self) -> str:
        fields = ", ".join(f"{name}={getattr(self, name)!r}" for name in self.__slots__)
        return f"{type(self).__name__}({fields})"

    def __reduce__(self):  # pickled by its type's name: the classes are made on first use
        return _message, (self.__msgtype__, tuple(getattr(self, name) for name in self.__slots__))


def _message(typename: str, values: tuple) -> Message:
    """The message of `typename` with these field values (unpickling a `Message`)."""
    return _types[typename](*values)


class _MessageClasses(dict):
    """The `Message` class of each type of `LOG_TYPES`, made on first use (no generated code)."""

    def __missing__(self, typename: str):
        constants, fields = _log_fields(typename)
        names = tuple(name + "_" if keyword.iskeyword(name) else name for _, name in fields)
        attributes = {"__slots__": names, "__msgtype__": typename, "__module__": __name__}
        attributes.update((name, value) for name, _, value in constants)
        made = self[typename] = type(typename.replace("/", "__"), (Message,), attributes)
        return made


_types = _MessageClasses()


def time_msg(t_ns: int):
    return _types["builtin_interfaces/msg/Time"](*split_time(t_ns))


def header(t_ns: int, frame_id: str = "map"):
    return _types["std_msgs/msg/Header"](stamp=time_msg(t_ns), frame_id=frame_id)


def quaternion(yaw: float):
    """Rotation about z by `yaw` [rad]."""
    return _types["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2.0), w=math.cos(yaw / 2.0))


def yaw_of(orientation) -> float:
    """Yaw [rad] of a quaternion message (rotation about z)."""
    q = orientation
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def path_poses(message) -> np.ndarray:
    """A nav_msgs/Path's poses as N x 3: x, y [m] and heading [rad] (the yaw of each orientation).
    A run writes a grid planner's path with each pose facing the next one and a Hybrid A* path with
    the vehicle's heading, which points backwards along the path where the car reverses."""
    return np.array(
        [(p.pose.position.x, p.pose.position.y, yaw_of(p.pose.orientation)) for p in message.poses],
        dtype=float,
    ).reshape(-1, 3)


def point(x: float, y: float, z: float = 0.0):
    return _types["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=float(z))


def pose(x: float, y: float, yaw: float, z: float = 0.0):
    return _types["geometry_msgs/msg/Pose"](position=point(x, y, z), orientation=quaternion(yaw))


def vector3(x: float = 0.0, y: float = 0.0, z: float = 0.0):
    return _types["geometry_msgs/msg/Vector3"](x=float(x), y=float(y), z=float(z))


def twist(v: float, omega: float):
    """Planar twist: v [m/s] along x of the body, omega [rad/s] about z."""
    return _types["geometry_msgs/msg/Twist"](linear=vector3(v), angular=vector3(0.0, 0.0, omega))


def pose_stamped(t_ns: int, x: float, y: float, yaw: float, frame_id: str = "map"):
    return _types["geometry_msgs/msg/PoseStamped"](header=header(t_ns, frame_id), pose=pose(x, y, yaw))


def color(r: float, g: float, b: float, a: float = 1.0):
    return _types["std_msgs/msg/ColorRGBA"](r=r, g=g, b=b, a=a)


def laser_scan(
    t_ns: int,
    frame_id: str,
    angle_min: float,
    increment: float,
    ranges,
    scan_time: float,
    range_min: float,
    range_max: float,
):
    """A sensor_msgs/LaserScan of float32 `ranges` [m] on the grid angle_min + i * increment [rad],
    no intensities (REP-117: +inf no return within range, NaN a bin no beam falls in)."""
    return make(
        "sensor_msgs/msg/LaserScan",
        header=header(t_ns, frame_id),
        angle_min=angle_min,
        angle_max=angle_min + increment * (len(ranges) - 1),
        angle_increment=increment,
        time_increment=0.0,
        scan_time=scan_time,
        range_min=range_min,
        range_max=range_max,
        ranges=ranges,
        intensities=np.zeros(0, dtype=np.float32),
    )


def make(typename: str, **fields):
    """A message of a standard type from keyword fields: a `Message` for a type of `LOG_TYPES`,
    else an instance of rosbags' class of that type."""
    if typename in LOG_TYPES:
        return _types[typename](**fields)
    return _typestore().types[_known(typename)](**fields)


def serialize(message, typename: str) -> bytes:
    """CDR bytes (little endian, with encapsulation header) of a message: packed by `_PACKERS` for
    a `Message` of their types whose fields hold what rosbags expects (arrays of the field's
    dtype), else by rosbags (which raises for fields it cannot serialise)."""
    packer = _PACKERS.get(typename)
    if packer is not None and getattr(message, "__msgtype__", None) == typename and _LITTLE:
        try:
            data = packer(message)
        except (struct.error, TypeError, AttributeError, ValueError, OverflowError):
            data = None  # as rosbags would have it: its serialisation says what is wrong
        if data is not None:
            return data
    return bytes(_typestore().serialize_cdr(message, _known(typename)))


# --- packers: the messages a run writes at its start, without rosbags ----------------------
# CDR (the encoding rosbags writes): each primitive aligned to its size, counted from the end of
# the 4-byte encapsulation header, with zero bytes; a string is a uint32 length counting a closing
# NUL, its UTF-8 bytes and the NUL; a sequence a uint32 count and its elements (a primitive
# sequence's data aligned to its element only when it has any). `_PACKERS[typename](message)`
# returns None when a field is not what rosbags expects (an array of another dtype), and rosbags
# serialises it.
_LITTLE = sys.byteorder == "little"  # rosbags' `serialize_cdr` writes the machine's byte order
_I32_PAIR = struct.Struct("<iI")
_U32 = struct.Struct("<I")
_POSE = struct.Struct("<7d")


class _Cdr:
    """CDR bytes under construction (after the encapsulation header)."""

    __slots__ = ("data",)

    def __init__(self) -> None:
        self.data = bytearray(CDR_HEADER)

    def align(self, size: int) -> None:
        self.data += bytes(-(len(self.data) - len(CDR_HEADER)) % size)

    def pack(self, layout: struct.Struct, size: int, *values) -> None:
        self.align(size)
        self.data += layout.pack(*values)

    def string(self, text: str) -> None:
        encoded = text.encode()
        self.pack(_U32, 4, len(encoded) + 1)
        self.data += encoded + b"\0"

    def header(self, header) -> None:
        self.pack(_I32_PAIR, 4, header.stamp.sec, header.stamp.nanosec)
        self.string(header.frame_id)

    def pose(self, pose) -> None:
        position, orientation = pose.position, pose.orientation
        q = (orientation.x, orientation.y, orientation.z, orientation.w)
        self.pack(_POSE, 8, position.x, position.y, position.z, *q)

    def array(self, values, dtype: str) -> bool:
        """A primitive sequence of `dtype`; False (nothing written) when `values` is not a NumPy
        array of that dtype."""
        if not isinstance(values, np.ndarray) or values.dtype != np.dtype(dtype) or values.ndim != 1:
            return False
        self.pack(_U32, 4, len(values))
        if len(values):
            self.align(values.itemsize)
            self.data += values.tobytes()
        return True

    def messages(self, items, write) -> None:
        """A sequence of messages, each written by `write(item)`."""
        self.pack(_U32, 4, len(items))
        for item in items:
            write(item)

    def result(self) -> bytes:
        return bytes(self.data)


def _pack_pose_stamped(message) -> bytes:
    out = _Cdr()
    out.header(message.header)
    out.pose(message.pose)
    return out.result()


def _pack_path(message) -> bytes:
    out = _Cdr()
    out.header(message.header)

    def pose_stamped(item) -> None:
        out.header(item.header)
        out.pose(item.pose)

    out.messages(message.poses, pose_stamped)
    return out.result()


_GRID_INFO = struct.Struct("<fII")


def _pack_occupancy_grid(message) -> bytes | None:
    out, info = _Cdr(), message.info
    out.header(message.header)
    out.pack(_I32_PAIR, 4, info.map_load_time.sec, info.map_load_time.nanosec)
    out.pack(_GRID_INFO, 4, info.resolution, info.width, info.height)
    out.pose(info.origin)
    return out.result() if out.array(message.data, "i1") else None


_SCAN_FIELDS = struct.Struct("<7f")


def _pack_laser_scan(message) -> bytes | None:
    out, m = _Cdr(), message
    out.header(m.header)
    out.pack(
        _SCAN_FIELDS, 4,
        m.angle_min, m.angle_max, m.angle_increment, m.time_increment, m.scan_time, m.range_min, m.range_max,
    )  # fmt: skip
    if not (out.array(m.ranges, "<f4") and out.array(m.intensities, "<f4")):
        return None
    return out.result()


_BOOL = struct.Struct("<?")
_MARKER_IDS = struct.Struct("<iii")
_VECTOR3 = struct.Struct("<3d")
_COLOR = struct.Struct("<4f")
_UV = struct.Struct("<2f")


def _pack_bool(message) -> bytes:
    return CDR_HEADER + _BOOL.pack(message.data)


def _pack_marker_array(message) -> bytes | None:
    out = _Cdr()
    complete = True

    def marker(m) -> None:
        nonlocal complete
        out.header(m.header)
        out.string(m.ns)
        out.pack(_MARKER_IDS, 4, m.id, m.type, m.action)
        out.pose(m.pose)
        out.pack(_VECTOR3, 8, m.scale.x, m.scale.y, m.scale.z)
        out.pack(_COLOR, 4, m.color.r, m.color.g, m.color.b, m.color.a)
        out.pack(_I32_PAIR, 4, m.lifetime.sec, m.lifetime.nanosec)
        out.pack(_BOOL, 1, m.frame_locked)
        out.messages(m.points, lambda p: out.pack(_VECTOR3, 8, p.x, p.y, p.z))
        out.messages(m.colors, lambda c: out.pack(_COLOR, 4, c.r, c.g, c.b, c.a))
        out.string(m.texture_resource)
        out.header(m.texture.header)
        out.string(m.texture.format)
        complete = out.array(m.texture.data, "u1") and complete
        out.messages(m.uv_coordinates, lambda uv: out.pack(_UV, 4, uv.u, uv.v))
        out.string(m.text)
        out.string(m.mesh_resource)
        out.string(m.mesh_file.filename)
        complete = out.array(m.mesh_file.data, "u1") and complete
        out.pack(_BOOL, 1, m.mesh_use_embedded_materials)

    out.messages(message.markers, marker)
    return out.result() if complete else None


_PACKERS = {
    "geometry_msgs/msg/PoseStamped": _pack_pose_stamped,
    "nav_msgs/msg/Path": _pack_path,
    "nav_msgs/msg/OccupancyGrid": _pack_occupancy_grid,
    "sensor_msgs/msg/LaserScan": _pack_laser_scan,
    "std_msgs/msg/Bool": _pack_bool,
    "visualization_msgs/msg/MarkerArray": _pack_marker_array,
}


# --- hot paths: fixed-layout messages packed directly --------------------------------------
# The run loop writes poses and velocity commands at every control step; building rosbags
# dataclasses for them costs ~40 us per pose. Their CDR layout is fixed (the frame names are
# constants), so they are packed with precomputed structs; tests compare the bytes with rosbags.
# CDR aligns each primitive to its size, counted from the end of the 4-byte encapsulation header.
# REP-105 frames: map -> odom -> base_link. Odometry here has no drift, so map -> odom is the
# identity and odom -> base_link is the true pose.
MAP_FRAME = "map"
ODOM_FRAME = "odom"
ROBOT_FRAME = "base_link"
_MAP = b"map\0"
_ODOM = b"odom\0"
_ROBOT = b"base_link\0"
_pose_stamped = struct.Struct("<iII4s7d")  # stamp, frame_id "map", Pose (8-aligned at 16)
_twist = struct.Struct("<6d")
# 2 transforms: [stamp, "map", "odom", pad to 32, 7d] then [stamp, "odom", "base_link", pad to 128, 7d].
TF_HEAD = "<IiII4sI5s3x"
TF_SECOND = "<IiII4sI5s3x7diII5s3xI10s6x"
_tf_message = struct.Struct(TF_SECOND + "7d")
ODOMETRY_HEAD = "<iII5s3xI10s6x"  # stamp, "odom", "base_link", pad to 40, then the Pose
_odometry_head = struct.Struct(ODOMETRY_HEAD + "7d")
_zero_covariance = bytes(36 * 8)


def pose_stamped_cdr(t_ns: int, x: float, y: float, yaw: float) -> bytes:
    """geometry_msgs/PoseStamped in frame "map" at the planar pose (x, y [m], yaw [rad])."""
    sec, nanosec = split_time(t_ns)
    qz, qw = math.sin(yaw / 2.0), math.cos(yaw / 2.0)
    return CDR_HEADER + _pose_stamped.pack(sec, nanosec, 4, _MAP, x, y, 0.0, 0.0, 0.0, qz, qw)


def twist_cdr(v: float, omega: float) -> bytes:
    """geometry_msgs/Twist: v [m/s] along body x, omega [rad/s] about z."""
    return CDR_HEADER + _twist.pack(v, 0.0, 0.0, 0.0, 0.0, omega)


def tf_cdr(t_ns: int, x: float, y: float, yaw: float) -> bytes:
    """tf2_msgs/TFMessage with map -> odom (identity) and odom -> base_link (the pose)."""
    sec, nanosec = split_time(t_ns)
    qz, qw = math.sin(yaw / 2.0), math.cos(yaw / 2.0)
    identity = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
    return CDR_HEADER + _tf_message.pack(
        2, sec, nanosec, 4, _MAP, 5, _ODOM, *identity,
        sec, nanosec, 5, _ODOM, 10, _ROBOT, x, y, 0.0, 0.0, 0.0, qz, qw,
    )  # fmt: skip


def odometry_cdr(t_ns: int, x: float, y: float, yaw: float, v: float, omega: float) -> bytes:
    """nav_msgs/Odometry: pose in "odom" of child "base_link", twist in "base_link", zero covariances."""
    sec, nanosec = split_time(t_ns)
    qz, qw = math.sin(yaw / 2.0), math.cos(yaw / 2.0)
    head = _odometry_head.pack(sec, nanosec, 5, _ODOM, 10, _ROBOT, x, y, 0.0, 0.0, 0.0, qz, qw)
    return CDR_HEADER + head + _zero_covariance + _twist.pack(v, 0.0, 0.0, 0.0, 0.0, omega) + _zero_covariance


def signals_payload(t_ns: int, values: np.ndarray) -> bytes:
    """CDR bytes of a signals struct: header, stamp, then the float64 values packed (8-aligned)."""
    return CDR_HEADER + _stamp.pack(*split_time(t_ns)) + values.tobytes()


def pattern_offsets(data: bytes, pattern: bytes) -> list[int]:
    """Every offset of `pattern` in `data`: where a byte template made once with sentinel values
    (a stamp, a coordinate) is patched for each message."""
    found, at = [], data.find(pattern)
    while at >= 0:
        found.append(at)
        at = data.find(pattern, at + 1)
    return found
