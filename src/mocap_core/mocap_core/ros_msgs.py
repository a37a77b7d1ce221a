"""Message-type helpers: type names, classes, (de)serialisation, YAML like ``ros2 topic echo``.

rclpy and the message packages are imported lazily (inside the functions), so importing this
module is cheap and works where rclpy is missing; only the functions that need rclpy fail there,
with a clear :class:`MessageTypeError`.

Type names are accepted in the three spellings ROS uses, ``sensor_msgs/msg/Image`` (canonical,
used in bags and on the graph), ``sensor_msgs/Image`` and ``sensor_msgs.msg.Image``; functions
return the canonical spelling.
"""

from __future__ import annotations

import array
import functools
import importlib
import re
import struct
import sys
from typing import Any

__all__ = [
    'MessageTypeError',
    'deserialize',
    'get_message_class',
    'header_stamp_ns',
    'message_to_dict',
    'message_to_yaml',
    'msgtype_of',
    'normalize_msgtype',
    'ns_to_stamp',
    'serialize',
    'stamp_to_ns',
    'value_to_yaml',
]

_TYPE_RE = re.compile(r'^([A-Za-z][A-Za-z0-9_]*)/(?:(msg|srv|action)/)?([A-Za-z][A-Za-z0-9_]*)$')


class MessageTypeError(ValueError):
    """An unknown, malformed or unimportable message type name."""


def normalize_msgtype(msgtype: str) -> str:
    """Return the canonical ``pkg/msg/Name`` spelling of a message type name.

    Accepts ``pkg/msg/Name``, ``pkg/Name`` and ``pkg.msg.Name``.
    """
    if not isinstance(msgtype, str):
        raise MessageTypeError(f'message type must be a string, got {type(msgtype).__name__}')
    text = msgtype.strip().replace('.', '/')
    match = _TYPE_RE.match(text)
    if not match:
        raise MessageTypeError(
            f"invalid message type '{msgtype}' (expected e.g. 'sensor_msgs/msg/Image')")
    pkg, kind, name = match.groups()
    return f'{pkg}/{kind or "msg"}/{name}'


def get_message_class(msgtype: str) -> type:
    """Import and return the Python class of a message type (e.g. ``sensor_msgs/msg/Image``).

    Raises:
        MessageTypeError: the name is malformed, or the package or the type is not installed.
    """
    canonical = normalize_msgtype(msgtype)
    pkg, kind, name = canonical.split('/')
    module_name = f'{pkg}.{kind}'
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise MessageTypeError(
            f"unknown message type '{canonical}': package '{pkg}' is not installed "
            f'({exc.__class__.__name__}: {exc})') from None
    cls = getattr(module, name, None)
    if cls is None or not hasattr(cls, 'get_fields_and_field_types'):
        raise MessageTypeError(
            f"unknown message type '{canonical}': '{pkg}' has no {kind} named '{name}'")
    return cls


def msgtype_of(msg_or_class: Any) -> str:
    """Return the canonical type name (``pkg/msg/Name``) of an rclpy message or message class."""
    cls = msg_or_class if isinstance(msg_or_class, type) else type(msg_or_class)
    if not hasattr(cls, 'get_fields_and_field_types'):
        raise MessageTypeError(f'{cls.__name__} is not a ROS message class')
    parts = cls.__module__.split('.')
    if len(parts) < 2 or parts[1] not in ('msg', 'srv', 'action'):
        raise MessageTypeError(f'cannot tell the ROS type of {cls.__module__}.{cls.__name__}')
    return f'{parts[0]}/{parts[1]}/{cls.__name__}'


def serialize(msg: Any) -> bytes:
    """Serialise an rclpy message to CDR bytes, zero-padded to a multiple of 4 bytes.

    The padding is what DDS adds to every sample it delivers between processes, so the bytes a
    live ``ros2 bag record`` stores are exactly the bytes written here: a bag written offline
    and the same messages recorded live are byte-identical, and so is play -> record of it.
    Deserialisation ignores the trailing padding."""
    from rclpy.serialization import serialize_message
    data = serialize_message(msg)
    return data + bytes(-len(data) % 4)


def deserialize(data: bytes, msgtype: str | type) -> Any:
    """Deserialise CDR bytes into an rclpy message of ``msgtype`` (a name or a class).

    Raises:
        MessageTypeError: unknown type.
        ValueError: the bytes are not a valid message of that type.
    """
    from rclpy.serialization import deserialize_message
    cls = msgtype if isinstance(msgtype, type) else get_message_class(msgtype)
    try:
        return deserialize_message(bytes(data), cls)
    except Exception as exc:  # rclpy raises a plain RuntimeError/_rclpy error on bad data
        name = msgtype if isinstance(msgtype, str) else msgtype_of(cls)
        raise ValueError(f'cannot deserialise {len(data)} bytes as {name}: {exc}') from None


def stamp_to_ns(stamp: Any) -> int:
    """Nanoseconds of a ``builtin_interfaces/Time`` (or anything with ``sec``/``nanosec``)."""
    if isinstance(stamp, dict):
        return int(stamp['sec']) * 1_000_000_000 + int(stamp['nanosec'])
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def header_stamp_ns(data: bytes, msg_type: type) -> int | None:
    """The header stamp (ns) of a serialised message whose first field is a
    ``std_msgs/Header`` (read from the CDR bytes: int32 sec, uint32 nanosec right after the
    4-byte encapsulation header); None for other types."""
    if not _header_first(msg_type):
        return None
    sec, nanosec = struct.unpack_from('<iI', data, 4)
    return sec * 1_000_000_000 + nanosec


@functools.lru_cache(maxsize=None)
def _header_first(msg_type: type) -> bool:
    fields = msg_type.get_fields_and_field_types()
    return next(iter(fields.items()), None) == ('header', 'std_msgs/Header')


def ns_to_stamp(ns: int) -> Any:
    """A ``builtin_interfaces.msg.Time`` for an integer number of nanoseconds."""
    from builtin_interfaces.msg import Time
    sec, nanosec = divmod(int(ns), 1_000_000_000)
    return Time(sec=sec, nanosec=nanosec)


# --- message -> plain data / YAML (the shape ``ros2 topic echo`` prints) -----------------------

_SEQ_RE = re.compile(r'^sequence<(.+?)(?:, ?(\d+))?>$')
_ARR_RE = re.compile(r'^(.+)\[(\d+)\]$')


def _abbreviate(value: Any, field_type: str) -> str:
    match = _ARR_RE.match(field_type)
    if match:
        return f'<array type: {match.group(1)}[{match.group(2)}]>'
    match = _SEQ_RE.match(field_type)
    inner = match.group(1) if match else field_type
    return f'<sequence type: {inner}, length: {len(value)}>'


def _is_message(value: Any) -> bool:
    return hasattr(value, 'get_fields_and_field_types')


def _convert(value: Any, field_type: str | None, truncate_length: int | None, no_arr: bool,
             no_str: bool) -> Any:
    if _is_message(value):
        return message_to_dict(value, truncate_length=truncate_length, no_arr=no_arr,
                               no_str=no_str)
    if isinstance(value, str):
        if no_str:
            return f'<string length: <{len(value)}>>'
        if truncate_length is not None and len(value) > truncate_length:
            return value[:truncate_length] + '...'
        return value
    if isinstance(value, (bytes, bytearray)):
        # 'octet'/'byte' fields: one byte -> its integer value; several -> list of integers
        if len(value) == 1 and not (field_type or '').startswith(('sequence<', )) \
                and '[' not in (field_type or ''):
            return value[0]
        value = list(value)
    numpy = sys.modules.get('numpy')
    is_array = isinstance(value, (list, tuple, array.array)) or (
        numpy is not None and isinstance(value, numpy.ndarray))
    if is_array:
        if no_arr:
            return _abbreviate(value, field_type or 'sequence<?>')
        inner_type = None
        if field_type:
            match = _SEQ_RE.match(field_type) or _ARR_RE.match(field_type)
            inner_type = match.group(1) if match else None
        items = value.tolist() if hasattr(value, 'tolist') else list(value)
        truncated = truncate_length is not None and len(items) > truncate_length
        if truncated:
            items = items[:truncate_length]
        out = [_convert(x, inner_type, truncate_length, no_arr, no_str) for x in items]
        if truncated:
            out.append('...')
        return out
    if numpy is not None and isinstance(value, numpy.generic):
        return value.item()
    return value


def message_to_dict(msg: Any, *, truncate_length: int | None = None, no_arr: bool = False,
                    no_str: bool = False) -> dict:
    """Convert an rclpy message to nested plain Python data (dicts, lists, numbers, strings).

    Fields keep their declaration order. ``truncate_length`` cuts strings and arrays longer than
    that (adding ``'...'``, like ``ros2 topic echo``), ``no_arr`` replaces arrays by a short
    description and ``no_str`` does the same for strings.
    """
    if not _is_message(msg):
        raise TypeError(f'{type(msg).__name__} is not a ROS message')
    out: dict[str, Any] = {}
    for name, field_type in msg.get_fields_and_field_types().items():
        out[name] = _convert(getattr(msg, name), field_type, truncate_length, no_arr, no_str)
    return out


def message_to_yaml(msg: Any, *, truncate_length: int | None = None, no_arr: bool = False,
                    no_str: bool = False, flow_style: bool = False) -> str:
    """YAML text of a message in the layout of ``ros2 topic echo`` (without the ``---`` line)."""
    data = message_to_dict(msg, truncate_length=truncate_length, no_arr=no_arr, no_str=no_str)
    return value_to_yaml(data, flow_style=flow_style)


def value_to_yaml(data: Any, *, flow_style: bool = False) -> str:
    """YAML text of plain data produced by :func:`message_to_dict` (keeps key order)."""
    import yaml

    if not isinstance(data, (dict, list)):
        return f'{data}\n'
    return yaml.dump(data, sort_keys=False, default_flow_style=flow_style, allow_unicode=True,
                     width=sys.maxsize)
