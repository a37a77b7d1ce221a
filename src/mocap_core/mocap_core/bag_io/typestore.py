"""Message definitions as rosbag2 stores them: the definition text and its RIHS01 type hash.

Standard Jazzy messages come from the rosbags type store (``Stores.ROS2_JAZZY``); other types
(a package of this workspace, a custom interface) are parsed from their ``.msg`` files found
through the ament index, with every nested type they name, and registered in that store.
Serialising and deserialising message payloads is done by rclpy
(:mod:`mocap_core.ros_msgs`, re-exported by :mod:`mocap_core.bag_io`).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from ..ros_msgs import MessageTypeError, normalize_msgtype
from .errors import BagError

__all__ = ['canonical_msgtype', 'message_definition']

_TYPESTORE: Any = None


def typestore() -> Any:
    """The process-wide rosbags type store (Jazzy standard messages, plus what was registered)."""
    global _TYPESTORE
    if _TYPESTORE is None:
        from rosbags.typesys import Stores, get_typestore
        _TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
    return _TYPESTORE


def canonical_msgtype(msgtype: str) -> str:
    """``pkg/msg/Name`` spelling of a type name read from a bag; unchanged if not a ROS name."""
    try:
        return normalize_msgtype(msgtype)
    except MessageTypeError:
        return msgtype


def _interface_file(pkg: str, kind: str, name: str) -> Path | None:
    """``share/<pkg>/<kind>/<name>.msg`` of the first ament prefix that has it."""
    dirs: list[Path] = []
    try:
        from ament_index_python.packages import PackageNotFoundError, get_package_share_directory
        try:
            dirs.append(Path(get_package_share_directory(pkg)))
        except (PackageNotFoundError, ValueError):
            pass
    except ImportError:
        pass
    for prefix in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep):
        if prefix:
            dirs.append(Path(prefix, 'share', pkg))
    for share in dirs:
        candidate = share / kind / f'{name}.msg'
        if candidate.is_file():
            return candidate
    return None


def _register_from_ament_index(store: Any, msgtype: str) -> None:
    """Parse ``msgtype`` and every type it nests from ``.msg`` files; register them in
    ``store``. Raises :class:`BagError` when a definition is missing or does not parse."""
    from rosbags.interfaces import Nodetype
    from rosbags.typesys import get_types_from_msg

    found: dict[str, Any] = {}
    pending = [msgtype]

    def walk(desc: Any) -> None:
        node, arg = desc
        if node == Nodetype.NAME:
            pending.append(arg)
        elif node in (Nodetype.ARRAY, Nodetype.SEQUENCE):
            walk(arg[0])

    while pending:
        name = pending.pop()
        if name in store.fielddefs or name in found:
            continue
        pkg, kind, short = name.split('/')
        path = _interface_file(pkg, kind, short)
        if path is None:
            raise BagError(
                f"no message definition for '{name}': not a standard message and no "
                f'share/{pkg}/{kind}/{short}.msg in the ament index (AMENT_PREFIX_PATH)')
        try:
            types = get_types_from_msg(path.read_text(encoding='utf8'), name)
        except Exception as exc:  # rosbags raises its own parse errors
            raise BagError(f"cannot parse {path}: {exc}") from None
        found.update(types)
        for _, desc in types[name][1]:
            walk(desc)
    store.register(found)


def message_definition(msgtype: str) -> tuple[str, str]:
    """``(definition text, RIHS01 hash)`` of a message type, as rosbag2 stores them.

    Standard Jazzy messages come from the rosbags typestore; other types from their ``.msg``
    files in the ament index.
    """
    try:
        msgtype = normalize_msgtype(msgtype)
    except MessageTypeError as exc:
        raise BagError(str(exc)) from None
    store = typestore()
    if msgtype not in store.fielddefs:
        _register_from_ament_index(store, msgtype)
    try:
        msgdef, _ = store.generate_msgdef(msgtype, ros_version=2)
        return msgdef, store.hash_rihs01(msgtype)
    except Exception as exc:
        raise BagError(f"cannot build the message definition of '{msgtype}': {exc}") from None
