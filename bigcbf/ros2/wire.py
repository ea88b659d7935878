"""ROS 2 on the wire without ROS: topic names, DDS type names and CDR, as rmw_cyclonedds puts them on DDS.

A ROS 2 topic ``/scan`` is the DDS topic ``rt/scan`` (services use ``rq/``/``rr/``, which we do not need); a ROS 2
message type ``sensor_msgs/msg/LaserScan`` is the DDS type ``sensor_msgs::msg::dds_::LaserScan_``; a message is
plain (XCDR1) CDR, little-endian, with the 4-byte encapsulation header ``00 01 00 00``, exactly what rosbags'
``serialize_cdr`` writes for the same message (tests/ros2/test_wire.py compares them byte for byte).

The IDL classes of the cyclonedds binding are generated here from rosbags' ROS 2 Humble type store (the same
definitions our MCAP logs embed, :mod:`bigcbf.logio.msgdefs`), so every standard message is available without
writing its IDL by hand; the standard messages we use are the same in Humble and Jazzy. ``from_dict`` builds a
message from the plain dicts of :mod:`bigcbf.logio.convert`; messages read off the wire are attribute objects
like rosbags' (``convert.laser_scan``, ``convert.odometry_state`` and ``convert.twist_u`` read both).

No MuJoCo, no cyclonedds at import time (``idl_class`` loads the binding).
"""
from __future__ import annotations

from functools import lru_cache

from ..errors import UserError

#: ROS 2's prefix of topic names on DDS ("ROS topic")
TOPIC_PREFIX = "rt"

#: rosbags' base type names -> cyclonedds.idl.types attribute names (None: a Python type)
_BASE = {"bool": None, "byte": "byte", "char": "uint8", "int8": "int8", "uint8": "uint8", "int16": "int16",
         "uint16": "uint16", "int32": "int32", "uint32": "uint32", "int64": "int64", "uint64": "uint64",
         "float32": "float32", "float64": "float64", "octet": "byte"}


def dds_topic(ros_topic: str) -> str:
    """A ROS 2 topic name (``/scan``, ``/ns/odom``) -> its DDS topic name (``rt/scan``, ``rt/ns/odom``)."""
    check_topic(ros_topic)
    return f"{TOPIC_PREFIX}{ros_topic}"


def check_topic(name: str, what: str = "topic") -> str:
    """A fully qualified ROS 2 topic name (``/`` then letters, digits, ``_`` and ``/``), else UserError."""
    import re

    if not isinstance(name, str) or not re.fullmatch(r"(/[A-Za-z_][A-Za-z0-9_]*)+", name):
        raise UserError(f"{what}: {name!r} is not a ROS 2 topic name (e.g. /cmd_vel: '/' then letters, digits "
                        "and '_')")
    return name


def dds_type(msgtype: str) -> str:
    """``pkg/msg/Type`` -> ``pkg::msg::dds_::Type_`` (the type name rmw_cyclonedds and rmw_fastrtps register)."""
    pkg, kind, name = msgtype.split("/")
    return f"{pkg}::{kind}::dds_::{name}_"


@lru_cache(maxsize=None)
def idl_class(msgtype: str):
    """The cyclonedds IDL class of a ROS 2 message type (``sensor_msgs/msg/LaserScan``), built from rosbags'
    field definitions; nested types are built on the way."""
    from cyclonedds.idl import make_idl_struct

    from ..logio.msgdefs import typestore

    store = typestore()
    if msgtype not in store.fielddefs:
        raise UserError(f"unknown ROS 2 message type {msgtype!r}")
    _, fields = store.fielddefs[msgtype]
    annotations = {name: _field_type(desc) for name, desc in fields}
    cls = make_idl_struct(msgtype.replace("/", "_"), dds_type(msgtype), annotations)
    cls.__ros_type__ = msgtype
    return cls


def _field_type(desc):
    """A rosbags field description (nodetype, detail) -> a cyclonedds annotation."""
    from cyclonedds.idl import types

    kind, detail = int(desc[0]), desc[1]
    if kind == 1:                                            # BASE: (name, string bound)
        name, bound = detail
        if name == "string":
            return types.bounded_str[bound] if bound else str
        if name == "bool":
            return bool
        if name not in _BASE:
            raise UserError(f"ROS 2 base type {name!r} is not supported on the wire")
        return getattr(types, _BASE[name])
    if kind == 2:                                            # NAME: a nested message
        return idl_class(detail)
    inner, n = detail
    if kind == 3:                                            # ARRAY: fixed length
        return types.array[_field_type(inner), n]
    return types.sequence[_field_type(inner), n] if n else types.sequence[_field_type(inner)]   # SEQUENCE


def from_dict(msgtype: str, message: dict):
    """A message (a dict shaped like ``msgtype``, as :mod:`bigcbf.logio.convert` builds them) -> its IDL object."""
    cls = idl_class(msgtype)
    return _build(cls, message)


def _build(cls, value):
    import dataclasses

    kwargs = {}
    for f in dataclasses.fields(cls):
        if f.name not in value:              # a field the dict leaves out: its default (as the MCAP encoder does)
            kwargs[f.name] = _default(_field_desc(cls, f.name))
            continue
        v = value[f.name]
        sub = _nested(cls, f.name)
        if sub is not None:
            v = _build(sub, v)
        elif isinstance(v, list) and v and isinstance(v[0], dict):
            item = _item_class(cls, f.name)
            v = [_build(item, x) for x in v]
        kwargs[f.name] = v
    return cls(**kwargs)


def _default(desc):
    """The default value of a field (ROS 2's: zero, empty string, empty sequence, zeros of an array)."""
    kind, detail = int(desc[0]), desc[1]
    if kind == 1:
        return "" if detail[0] == "string" else (False if detail[0] == "bool" else
                                                 (0.0 if detail[0].startswith("float") else 0))
    if kind == 2:
        cls = idl_class(detail)
        import dataclasses
        return cls(**{f.name: _default(_field_desc(cls, f.name)) for f in dataclasses.fields(cls)})
    if kind == 3:
        return [_default(detail[0]) for _ in range(detail[1])]
    return []


@lru_cache(maxsize=None)
def _field_desc(cls, name: str):
    from ..logio.msgdefs import typestore

    return dict(typestore().fielddefs[cls.__ros_type__][1])[name]


def _nested(cls, name: str):
    kind, detail = _field_desc(cls, name)
    return idl_class(detail) if int(kind) == 2 else None


def _item_class(cls, name: str):
    kind, detail = _field_desc(cls, name)
    inner = detail[0]
    return idl_class(inner[1]) if int(inner[0]) == 2 else None


def encode(obj) -> bytes:
    """An IDL message object -> its CDR bytes as ROS 2 sends them (XCDR1, little-endian, header included)."""
    from cyclonedds.idl._support import Endianness

    return obj.serialize(endianness=Endianness.Little, use_version_2=False)


def decode(msgtype: str, data: bytes):
    """CDR bytes (header included) of ``msgtype`` -> its IDL object."""
    return idl_class(msgtype).deserialize(data, has_header=True)      # the header names XCDR1
