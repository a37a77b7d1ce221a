"""Read and write rosbag2 bags (MCAP storage) as raw CDR bytes.

A *bag* here is what ``ros2 bag record`` writes: a folder with ``metadata.yaml`` and one or more
``.mcap`` files. :class:`BagReader` also opens

- a single ``.mcap`` file (a rosbag2 MCAP copied out of its folder, or one written by another
  MCAP tool with the ``ros2`` profile and ``cdr`` encoding),
- a folder that has ``.mcap`` files but no ``metadata.yaml``, and
- an ``.mcap`` file whose summary/footer is missing because the recorder was killed: rosbags
  cannot index such a file, so it is read sequentially with the ``mcap`` package instead and
  every complete message before the damage is returned (a note is added to ``reader.warnings``).

Everything is kept as serialised bytes, so copying a bag through :class:`BagReader` and
:class:`BagWriter` is byte-identical. Deserialising is a separate step
(:func:`mocap_core.ros_msgs.deserialize`).

This module needs only ``rosbags`` (and ``mcap`` for the fallback); rclpy is imported lazily by
the few helpers that build rclpy objects (:meth:`BagWriter.write_msg`, :func:`adapted_qos`).
"""

from __future__ import annotations

import heapq
import os
import shutil
import struct
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2 import Reader, ReaderError, StoragePlugin, Writer, WriterError
from rosbags.rosbag2.metadata import dump_qos_v9, parse_qos

from .ros_msgs import (
    MessageTypeError,
    deserialize,
    get_message_class,
    message_to_dict,
    message_to_yaml,
    msgtype_of,
    normalize_msgtype,
    serialize,
    stamp_to_ns,
)

if TYPE_CHECKING:
    from collections.abc import Iterable, Iterator, Sequence

__all__ = [
    'BagError',
    'BagMessage',
    'BagReader',
    'BagWriter',
    'TopicInfo',
    'adapted_qos',
    'deserialize',
    'get_message_class',
    'message_definition',
    'message_to_dict',
    'message_to_yaml',
    'qos_to_bag',
    'qos_to_dicts',
    'stamp_to_ns',
]

_NS = 1_000_000_000
_MAX_TIME = 2**63 - 1


class BagError(Exception):
    """A bag cannot be read or written; the message is one line that says what and why."""

    def __init__(self, message: str) -> None:
        super().__init__(' '.join(str(message).split()))


class TopicInfo(NamedTuple):
    """One topic of a bag."""

    name: str
    msgtype: str  # canonical, e.g. 'sensor_msgs/msg/Image'
    count: int
    qos: list[Qos] | None  # offered QoS profiles as recorded (rosbags ``Qos``), None if none
    msgdef: str | None = None  # message definition text as stored (ros2msg or ros2idl)
    type_hash: str | None = None  # 'RIHS01_...' as stored
    serialization_format: str = 'cdr'


class BagMessage(NamedTuple):
    """One message of a bag, still serialised."""

    topic: str
    msgtype: str
    timestamp_ns: int  # the bag's (receive) time stamp
    data: bytes


# --- QoS -----------------------------------------------------------------------------------------

def _enum(enum_cls: Any, value: Any, unknown: Any) -> Any:
    if isinstance(value, enum_cls):
        return value
    raw = getattr(value, 'value', value)
    if isinstance(raw, str):
        return enum_cls.__members__.get(raw.upper(), unknown)
    try:
        return enum_cls(int(raw))
    except (TypeError, ValueError):
        return unknown


def _qtime(value: Any) -> QosTime:
    if isinstance(value, QosTime):
        return value
    if isinstance(value, dict):
        return QosTime(int(value['sec']), int(value['nsec']))
    ns = getattr(value, 'nanoseconds', value)  # rclpy Duration or int ns
    sec, nsec = divmod(int(ns), _NS)
    return QosTime(sec, nsec)


def qos_to_bag(qos: Any) -> Qos:
    """Convert one QoS profile to the rosbags ``Qos`` stored in bag metadata.

    Accepts a rosbags ``Qos``, an rclpy ``QoSProfile`` (e.g. from
    ``node.get_publishers_info_by_topic``) or a dict in rosbag2 metadata form.
    """
    if isinstance(qos, Qos):
        return qos
    if isinstance(qos, dict):
        parsed = parse_qos([qos])  # type: ignore[list-item]
        return parsed[0]
    try:
        return Qos(
            _enum(QosHistory, qos.history, QosHistory.UNKNOWN),
            int(qos.depth),
            _enum(QosReliability, qos.reliability, QosReliability.UNKNOWN),
            _enum(QosDurability, qos.durability, QosDurability.UNKNOWN),
            _qtime(qos.deadline),
            _qtime(qos.lifespan),
            _enum(QosLiveliness, qos.liveliness, QosLiveliness.UNKNOWN),
            _qtime(qos.liveliness_lease_duration),
            bool(qos.avoid_ros_namespace_conventions),
        )
    except AttributeError as exc:
        raise BagError(f'cannot use {type(qos).__name__} as a QoS profile: {exc}') from None


def _qos_list(qos: Any) -> list[Qos]:
    if qos is None:
        return []
    if isinstance(qos, str):
        try:
            return parse_qos(qos)
        except (ReaderError, KeyError, TypeError) as exc:
            raise BagError(f'invalid offered QoS profiles text: {exc}') from None
    if isinstance(qos, (list, tuple)) and not isinstance(qos, Qos):
        return [qos_to_bag(x) for x in qos]
    return [qos_to_bag(qos)]


def qos_to_dicts(qos: Sequence[Qos] | None) -> list[dict]:
    """QoS profiles in the dict form of rosbag2 (version 9) metadata."""
    return [dict(x) for x in dump_qos_v9(list(qos or []))]


def adapted_qos(offers: Sequence[Any] | None, *, depth: int = 100) -> Any:
    """An rclpy ``QoSProfile`` compatible with all ``offers`` (publishers' offered QoS).

    Like rosbag2: reliable unless some offer is best effort, transient-local only when every
    offer is transient-local, keep-last with at least ``depth`` (or the largest offered depth).
    ``offers`` may be rosbags ``Qos`` (from a bag) or rclpy profiles (from the graph).
    """
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    bag_offers = [qos_to_bag(x) for x in (offers or [])]
    reliability = ReliabilityPolicy.RELIABLE
    durability = DurabilityPolicy.VOLATILE
    if bag_offers:
        if any(x.reliability == QosReliability.BEST_EFFORT for x in bag_offers):
            reliability = ReliabilityPolicy.BEST_EFFORT
        if all(x.durability == QosDurability.TRANSIENT_LOCAL for x in bag_offers):
            durability = DurabilityPolicy.TRANSIENT_LOCAL
        depth = max([depth] + [x.depth for x in bag_offers if x.history == QosHistory.KEEP_LAST])
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=max(1, int(depth)),
                      reliability=reliability, durability=durability)


# --- message definitions -------------------------------------------------------------------------

_TYPESTORE: Any = None


def _typestore() -> Any:
    global _TYPESTORE
    if _TYPESTORE is None:
        from rosbags.typesys import Stores, get_typestore
        _TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
    return _TYPESTORE


def _interface_file(pkg: str, kind: str, name: str) -> Path | None:
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
    store = _typestore()
    if msgtype not in store.fielddefs:
        _register_from_ament_index(store, msgtype)
    try:
        msgdef, _ = store.generate_msgdef(msgtype, ros_version=2)
        return msgdef, store.hash_rihs01(msgtype)
    except Exception as exc:
        raise BagError(f"cannot build the message definition of '{msgtype}': {exc}") from None


# --- reading ------------------------------------------------------------------------------------

class _TopicAcc:
    def __init__(self, name: str, msgtype: str) -> None:
        self.name = name
        self.msgtype = msgtype
        self.count = 0
        self.qos: list[Qos] = []
        self.msgdef: str | None = None
        self.type_hash: str | None = None
        self.fmt = 'cdr'

    def info(self) -> TopicInfo:
        return TopicInfo(self.name, self.msgtype, self.count, list(self.qos) or None,
                         self.msgdef, self.type_hash, self.fmt)


def _canonical(msgtype: str) -> str:
    try:
        return normalize_msgtype(msgtype)
    except MessageTypeError:
        return msgtype


class _RosbagsSource:
    """A bag folder or a single .mcap/.db3 file opened with rosbags (indexed access)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        try:
            reader = Reader(path)
        except FileNotFoundError as exc:
            raise ReaderError(str(exc)) from None
        reader.open()
        self.reader = reader
        self.count = reader.message_count
        self.start = reader.start_time if self.count else None
        self.end = reader.end_time - 1 if self.count else None
        self.ros_distro = reader.ros_distro
        self.topics: dict[str, _TopicAcc] = {}
        for conn in reader.connections:
            acc = self.topics.get(conn.topic)
            if acc is None:
                acc = self.topics[conn.topic] = _TopicAcc(conn.topic, _canonical(conn.msgtype))
            acc.count += conn.msgcount
            ext = conn.ext
            acc.qos.extend(getattr(ext, 'offered_qos_profiles', []) or [])
            acc.fmt = getattr(ext, 'serialization_format', 'cdr')
            if conn.msgdef.data and acc.msgdef is None:
                acc.msgdef = conn.msgdef.data
            if conn.digest and acc.type_hash is None:
                acc.type_hash = conn.digest

    def messages(self, topics: set[str] | None, start: int | None,
                 stop: int | None) -> Iterator[BagMessage]:
        conns = [c for c in self.reader.connections if topics is None or c.topic in topics]
        if not conns:
            return
        names = {c.id: (c.topic, self.topics[c.topic].msgtype) for c in conns}
        for conn, timestamp, data in self.reader.messages(conns, start=start, stop=stop):
            topic, msgtype = names[conn.id]
            yield BagMessage(topic, msgtype, timestamp, bytes(data))

    def close(self) -> None:
        if self.reader.is_open:
            self.reader.close()


class _StreamSource:
    """An .mcap file read sequentially with the ``mcap`` package (no index, maybe truncated)."""

    def __init__(self, path: Path) -> None:
        from mcap.exceptions import InvalidMagic

        self.path = path
        self.ros_distro = None
        self.topics: dict[str, _TopicAcc] = {}
        self.channels: dict[int, tuple[str, str]] = {}
        self.count = 0
        self.start: int | None = None
        self.end: int | None = None
        self.ordered = True
        self.damage: str | None = None
        last = -1
        schemas: dict[int, Any] = {}
        try:
            for rec in self._records():
                kind = type(rec).__name__
                if kind == 'Schema':
                    schemas[rec.id] = rec
                elif kind == 'Channel':
                    self._add_channel(rec, schemas)
                elif kind == 'Message' and rec.channel_id in self.channels:
                    topic, _ = self.channels[rec.channel_id]
                    self.topics[topic].count += 1
                    self.count += 1
                    t = rec.log_time
                    self.start = t if self.start is None else min(self.start, t)
                    self.end = t if self.end is None else max(self.end, t)
                    if t < last:
                        self.ordered = False
                    last = t
        except InvalidMagic:
            raise _NotMcapError(f"'{path}' is not an MCAP file (bad magic bytes)") from None
        except _stream_errors() as exc:
            if not self.channels:
                raise BagError(f"cannot read '{path}': {exc.__class__.__name__} {exc}") from None
            self.damage = str(exc) or exc.__class__.__name__

    def _records(self) -> Iterator[Any]:
        from mcap.stream_reader import StreamReader

        with self.path.open('rb') as stream:
            reader = StreamReader(stream, record_size_limit=1 << 31)
            yield from reader.records

    def _add_channel(self, rec: Any, schemas: dict[int, Any]) -> None:
        if rec.id in self.channels or rec.message_encoding != 'cdr':
            return  # not a ROS 2 message stream: nothing we can publish or decode
        schema = schemas.get(rec.schema_id)
        msgtype = _canonical(schema.name) if schema is not None else ''
        acc = self.topics.get(rec.topic)
        if acc is None:
            acc = self.topics[rec.topic] = _TopicAcc(rec.topic, msgtype)
            if schema is not None and schema.data:
                acc.msgdef = bytes(schema.data).decode('utf8', 'replace')
        text = (rec.metadata or {}).get('offered_qos_profiles')
        if text:
            try:
                acc.qos.extend(parse_qos(text))
            except (ReaderError, KeyError, TypeError):
                pass
        self.channels[rec.id] = (rec.topic, acc.msgtype)

    def messages(self, topics: set[str] | None, start: int | None,
                 stop: int | None) -> Iterator[BagMessage]:
        def selected() -> Iterator[BagMessage]:
            try:
                for rec in self._records():
                    if type(rec).__name__ != 'Message' or rec.channel_id not in self.channels:
                        continue
                    topic, msgtype = self.channels[rec.channel_id]
                    t = rec.log_time
                    if (topics is not None and topic not in topics) or \
                            (start is not None and t < start) or (stop is not None and t >= stop):
                        continue
                    yield BagMessage(topic, msgtype, t, bytes(rec.data))
            except _stream_errors():
                return  # the damaged tail was reported when the file was opened

        if self.ordered:
            yield from selected()
        else:
            yield from sorted(selected(), key=lambda m: m.timestamp_ns)

    def close(self) -> None:
        pass


class _NotMcapError(BagError):
    pass


def _stream_errors() -> tuple[type[BaseException], ...]:
    from mcap.exceptions import McapError
    return (McapError, struct.error, EOFError, ValueError, KeyError, IndexError,
            UnicodeDecodeError, OSError)


class BagReader:
    """Read a rosbag2 bag (folder with metadata.yaml + .mcap) or a single .mcap file.

    Usage::

        with BagReader('my_bag') as bag:
            for name, info in bag.topics.items():
                print(name, info.msgtype, info.count)
            for msg in bag.messages(['/camera/image_raw']):
                ...  # msg.topic, msg.msgtype, msg.timestamp_ns, msg.data (bytes)

    Raises :class:`BagError` (one-line message) for a missing path, a path that is not a bag,
    and unreadable or corrupt files.
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        self.warnings: list[str] = []
        self.storage_id = 'mcap'
        self.files: list[Path] = []
        self._sources: list[Any] = []
        if self.path.name == 'metadata.yaml' and self.path.is_file():
            self.path = self.path.parent
        if not self.path.exists():
            raise BagError(f"bag '{path}' does not exist")
        try:
            self._open()
        except BagError:
            self.close()
            raise
        except PermissionError as exc:
            self.close()
            raise BagError(f"cannot read bag '{path}': permission denied ({exc.filename})") \
                from None
        self._topics = self._merge_topics()

    # opening
    def _open(self) -> None:
        path = self.path
        if path.is_dir():
            meta = path / 'metadata.yaml'
            mcaps = sorted(p for p in path.glob('*.mcap') if p.is_file())
            if meta.is_file():
                try:
                    source = _RosbagsSource(path)
                except (ReaderError, OSError, KeyError, TypeError, ValueError) as exc:
                    if not mcaps:
                        raise BagError(f"cannot read bag '{path}': {exc}") from None
                    self.warnings.append(
                        f"'{meta}' or its files are unusable ({exc}); reading the .mcap files "
                        'directly')
                    for file in mcaps:
                        self._open_file(file)
                else:
                    self._sources.append(source)
                    self.storage_id, self.files = self._metadata_files(meta)
                return
            if not mcaps:
                raise BagError(
                    f"'{path}' is not a bag: it has no metadata.yaml and no .mcap file")
            self.warnings.append(f"'{path}' has no metadata.yaml; reading its .mcap files")
            for file in mcaps:
                self._open_file(file)
            return
        if path.suffix not in ('.mcap', '.db3'):
            raise BagError(
                f"'{path}' is not a bag: expected a rosbag2 folder (with metadata.yaml) or an "
                '.mcap file')
        self._open_file(path)

    def _metadata_files(self, meta: Path) -> tuple[str, list[Path]]:
        import yaml
        try:
            info = yaml.safe_load(meta.read_text(encoding='utf8'))['rosbag2_bagfile_information']
            storage = str(info.get('storage_identifier') or 'mcap')
            files = [Path(x) for x in info.get('relative_file_paths') or []]
        except Exception:  # rosbags already validated it; this is only for display
            storage, files = 'mcap', sorted(p.relative_to(self.path)
                                            for p in self.path.glob('*.mcap'))
        return storage, files

    def _open_file(self, file: Path) -> None:
        if file.suffix == '.db3':
            try:
                self._sources.append(_RosbagsSource(file))
            except (ReaderError, OSError) as exc:
                raise BagError(f"cannot read bag '{file}': {exc}") from None
            self.storage_id = 'sqlite3'
            self.files.append(Path(file.name))
            return
        try:
            self._sources.append(_RosbagsSource(file))
        except (ReaderError, OSError, KeyError, TypeError, ValueError) as exc:
            try:
                source = _StreamSource(file)
            except _NotMcapError:
                raise
            except BagError:
                raise BagError(f"cannot read bag '{file}': {exc}") from None
            if source.damage:
                self.warnings.append(
                    f"'{file}' is damaged or incomplete ({exc}); recovered {source.count} "
                    f'messages before: {source.damage}')
            else:
                self.warnings.append(f"'{file}' has no usable index ({exc}); read sequentially")
            self._sources.append(source)
        self.files.append(Path(file.name))

    def _merge_topics(self) -> dict[str, TopicInfo]:
        merged: dict[str, _TopicAcc] = {}
        for source in self._sources:
            for name, acc in source.topics.items():
                into = merged.get(name)
                if into is None:
                    into = merged[name] = _TopicAcc(name, acc.msgtype)
                    into.msgdef, into.type_hash, into.fmt = acc.msgdef, acc.type_hash, acc.fmt
                elif into.msgtype != acc.msgtype:
                    self.warnings.append(
                        f"topic '{name}' has two types ({into.msgtype}, {acc.msgtype}); "
                        f'reporting {into.msgtype}')
                into.count += acc.count
                for q in acc.qos:
                    into.qos.append(q)
        return {name: merged[name].info() for name in sorted(merged)}

    # properties
    @property
    def topics(self) -> dict[str, TopicInfo]:
        """Topic name -> :class:`TopicInfo`, sorted by name."""
        return dict(self._topics)

    @property
    def message_count(self) -> int:
        return sum(s.count for s in self._sources)

    @property
    def start_ns(self) -> int:
        """Time stamp of the first message (0 for an empty bag)."""
        starts = [s.start for s in self._sources if s.start is not None]
        return min(starts) if starts else 0

    @property
    def end_ns(self) -> int:
        """Time stamp of the last message (0 for an empty bag)."""
        ends = [s.end for s in self._sources if s.end is not None]
        return max(ends) if ends else 0

    @property
    def duration_ns(self) -> int:
        """``end_ns - start_ns`` (what ``ros2 bag info`` shows as Duration)."""
        return self.end_ns - self.start_ns

    @property
    def ros_distro(self) -> str | None:
        for source in self._sources:
            if source.ros_distro:
                return str(source.ros_distro)
        return None

    @property
    def size_bytes(self) -> int:
        """Total size of the bag's files on disk."""
        if self.path.is_file():
            return self.path.stat().st_size
        return sum(p.stat().st_size for p in self.path.iterdir() if p.is_file())

    # reading
    def check_topics(self, topics: Iterable[str] | str | None) -> set[str] | None:
        """Validate requested topic names; ``None`` means all. Raises BagError for unknown ones."""
        if topics is None:
            return None
        wanted = {topics} if isinstance(topics, str) else set(topics)
        unknown = sorted(wanted - set(self._topics))
        if unknown:
            raise BagError(
                f"topic{'s' if len(unknown) > 1 else ''} {', '.join(repr(t) for t in unknown)} "
                f"not in bag '{self.path}' (it has: {', '.join(self._topics) or 'no topics'})")
        return wanted

    def messages(self, topics: Iterable[str] | str | None = None, start_ns: int | None = None,
                 end_ns: int | None = None) -> Iterator[BagMessage]:
        """Yield :class:`BagMessage` in time order (ties in file order).

        Args:
            topics: only these topics (``None``: all); unknown names raise :class:`BagError`.
            start_ns: only messages stamped at or after this time.
            end_ns: only messages stamped before this time.
        """
        wanted = self.check_topics(topics)
        return self._iter(wanted, start_ns, end_ns)

    def _iter(self, wanted: set[str] | None, start: int | None,
              stop: int | None) -> Iterator[BagMessage]:
        streams = [s.messages(wanted, start, stop) for s in self._sources]
        merged = streams[0] if len(streams) == 1 else heapq.merge(
            *streams, key=lambda m: m.timestamp_ns)
        try:
            yield from merged
        except ReaderError as exc:
            raise BagError(f"cannot read bag '{self.path}': {exc}") from None
        except (OSError, struct.error) as exc:
            raise BagError(f"cannot read bag '{self.path}': {exc.__class__.__name__} {exc}") \
                from None

    def close(self) -> None:
        sources, self._sources = self._sources, []
        for source in sources:
            try:
                source.close()
            except Exception:  # closing must not hide the real error
                pass

    def __enter__(self) -> BagReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f'BagReader({str(self.path)!r}, {self.message_count} messages)'


# --- writing ------------------------------------------------------------------------------------

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
        offered = _qos_list(qos)
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
