"""Write rosbag2 bags with MCAP (or SQLite) storage, readable by ``ros2 bag``, Foxglove and
rosbags.

Messages are appended as serialised CDR bytes with integer-nanosecond time stamps, so copying a
bag through :class:`~mocap_core.bag_io.BagReader` and :class:`BagWriter` is byte-identical;
:meth:`BagWriter.write_msg` serialises an rclpy message first (rclpy imported then). Each topic
stores its message definition, RIHS01 type hash and the publishers' offered QoS.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import Any

from rosbags.rosbag2 import StoragePlugin, Writer, WriterError

from ..ros_msgs import MessageTypeError, msgtype_of, normalize_msgtype, serialize
from .errors import BagError
from .qos import qos_list
from .typestore import message_definition

__all__ = ['BagWriter']

_MAX_TIME = 2**63 - 1
_BAG_FILE_SUFFIXES = ('.mcap', '.db3', '.zstd', '.db3-shm', '.db3-wal', '.db3-journal')


def _remove_old_bag(path: Path) -> None:
    if path.is_file() or path.is_symlink():
        if path.suffix in ('.mcap', '.db3'):
            path.unlink()
            return
        raise BagError(f"'{path}' exists and is not a bag; refusing to overwrite it")
    entries = list(path.iterdir())
    foreign = [p.name for p in entries
               if not (p.is_file() and (p.name in ('metadata.yaml', 'metadata.yaml.tmp')
                                        or p.name.endswith(_BAG_FILE_SUFFIXES)))]
    if foreign:
        raise BagError(
            f"'{path}' exists and holds non-bag files ({', '.join(sorted(foreign)[:3])}); "
            'refusing to delete it')
    shutil.rmtree(path)


class BagWriter:
    """Write a rosbag2 bag with MCAP storage (readable by ``ros2 bag``, Foxglove, rosbags).

    Usage::

        with BagWriter('out_bag') as bag:
            bag.add_topic('/mocap/skeleton/urdf', 'std_msgs/msg/String', qos=transient_local)
            bag.write('/mocap/skeleton/urdf', stamp_ns, cdr_bytes)
            bag.write_msg('/mocap/world/odom', stamp_ns, odom_msg)   # serialises with rclpy

    The bag is finished (summary and metadata.yaml written) when the ``with`` block ends, also
    when it ends with an exception, so what was written is kept.
    """

    def __init__(self, path: str | os.PathLike[str], *, overwrite: bool = False,
                 storage: str = 'mcap') -> None:
        self.path = Path(path)
        plugins = {'mcap': StoragePlugin.MCAP, 'sqlite3': StoragePlugin.SQLITE3}
        if storage not in plugins:
            raise BagError(f"unknown storage '{storage}' (use one of: {', '.join(plugins)})")
        if self.path.exists() or self.path.is_symlink():
            if not overwrite:
                raise BagError(f"output bag '{self.path}' already exists")
            _remove_old_bag(self.path)
        self._writer: Writer | None = Writer(self.path, version=Writer.VERSION_LATEST,
                                             storage_plugin=plugins[storage])
        try:
            self._writer.open()
        except (WriterError, OSError) as exc:
            self._writer = None
            raise BagError(f"cannot create bag '{self.path}': {exc}") from None
        self._conns: dict[str, Any] = {}
        self._types: dict[str, str] = {}
        self.message_count = 0

    @property
    def topics(self) -> dict[str, str]:
        """Topic name -> message type of the topics added so far."""
        return dict(self._types)

    def add_topic(self, topic: str, msgtype: str, qos: Any = None, *, msgdef: str | None = None,
                  type_hash: str | None = None, serialization_format: str = 'cdr') -> None:
        """Declare a topic. Adding the same topic again with the same type is a no-op.

        Args:
            topic: fully qualified name ('/x/y').
            msgtype: 'pkg/msg/Name' (also 'pkg/Name').
            qos: the publishers' offered QoS, stored in the metadata so that a player can
                offer the same (e.g. transient-local): an rclpy ``QoSProfile``, a rosbags
                ``Qos``, a rosbag2 metadata dict or YAML text, or a list of those.
            msgdef, type_hash: the stored definition and RIHS01 hash, e.g. copied from
                :class:`TopicInfo`; looked up from the type name when not given.
        """
        writer = self._require_open()
        if not isinstance(topic, str) or not topic.startswith('/'):
            raise BagError(f"topic name must be absolute (start with '/'), got {topic!r}")
        try:
            msgtype = normalize_msgtype(msgtype)
        except MessageTypeError as exc:
            raise BagError(str(exc)) from None
        if topic in self._types:
            if self._types[topic] != msgtype:
                raise BagError(
                    f"topic '{topic}' was added as {self._types[topic]}, not {msgtype}")
            return
        offered = qos_list(qos)
        if not msgdef or not type_hash:
            try:
                msgdef, type_hash = message_definition(msgtype)
            except BagError:
                if not msgdef or not type_hash:
                    raise
        try:
            self._conns[topic] = writer.add_connection(
                topic, msgtype, msgdef=msgdef, rihs01=type_hash,
                serialization_format=serialization_format, offered_qos_profiles=offered)
        except WriterError as exc:
            raise BagError(f"cannot add topic '{topic}': {exc}") from None
        self._types[topic] = msgtype

    def write(self, topic: str, timestamp_ns: int, data: bytes | bytearray | memoryview) -> None:
        """Append one serialised (CDR) message to an added topic."""
        writer = self._require_open()
        conn = self._conns.get(topic)
        if conn is None:
            raise BagError(f"topic '{topic}' was not added to bag '{self.path}' (add_topic first)")
        if not isinstance(data, (bytes, bytearray, memoryview)):
            raise BagError(
                f"data for '{topic}' must be bytes, got {type(data).__name__} (use write_msg)")
        timestamp_ns = int(timestamp_ns)
        if not 0 <= timestamp_ns <= _MAX_TIME:
            raise BagError(f'time stamp out of range: {timestamp_ns}')
        writer.write(conn, timestamp_ns, bytes(data))
        self.message_count += 1

    def write_msg(self, topic: str, timestamp_ns: int, msg: Any, qos: Any = None) -> None:
        """Serialise an rclpy message and append it; adds the topic on first use."""
        if topic not in self._conns:
            try:
                self.add_topic(topic, msgtype_of(msg), qos)
            except MessageTypeError as exc:
                raise BagError(str(exc)) from None
        self.write(topic, timestamp_ns, serialize(msg))

    def _require_open(self) -> Writer:
        if self._writer is None:
            raise BagError(f"bag '{self.path}' is closed")
        return self._writer

    def close(self) -> None:
        """Finish the bag (MCAP summary + metadata.yaml). Safe to call twice."""
        writer, self._writer = self._writer, None
        if writer is None:
            return
        try:
            writer.close()
        except Exception as exc:
            try:
                writer.abort()
            except Exception:
                pass
            raise BagError(f"cannot finish bag '{self.path}': {exc}") from None

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:
        if getattr(self, '_writer', None) is not None:
            try:
                self.close()
            except Exception:
                pass
