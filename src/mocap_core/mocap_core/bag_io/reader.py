"""Read rosbag2 bags (MCAP or SQLite storage) and single ``.mcap`` files as raw CDR bytes.

A *bag* here is what ``ros2 bag record`` writes: a folder with ``metadata.yaml`` and one or more
``.mcap`` files. :class:`BagReader` also opens

- a single ``.mcap`` file (a rosbag2 MCAP copied out of its folder, or one written by another
  MCAP tool with the ``ros2`` profile and ``cdr`` encoding),
- a folder that has ``.mcap`` files but no ``metadata.yaml``, and
- an ``.mcap`` file whose summary/footer is missing because the recorder was killed: rosbags
  cannot index such a file, so it is read sequentially with the ``mcap`` package instead and
  every complete message before the damage is returned (a note is added to ``reader.warnings``).

Messages stay serialised (:class:`BagMessage` ``.data``); time stamps are integer nanoseconds
of the bag's (receive) clock.
"""

from __future__ import annotations

import heapq
import os
import struct
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

from rosbags.interfaces import Qos
from rosbags.rosbag2 import Reader, ReaderError

from .errors import BagError
from .qos import parse_qos_text
from .typestore import canonical_msgtype

if TYPE_CHECKING:
    from collections.abc import Iterable, Iterator

__all__ = ['BagMessage', 'BagReader', 'TopicInfo']

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


class _TopicAcc:
    """Per-topic totals gathered while a bag's files are opened."""

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
                acc = self.topics[conn.topic] = _TopicAcc(conn.topic,
                                                          canonical_msgtype(conn.msgtype))
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
        msgtype = canonical_msgtype(schema.name) if schema is not None else ''
        acc = self.topics.get(rec.topic)
        if acc is None:
            acc = self.topics[rec.topic] = _TopicAcc(rec.topic, msgtype)
            if schema is not None and schema.data:
                acc.msgdef = bytes(schema.data).decode('utf8', 'replace')
        text = (rec.metadata or {}).get('offered_qos_profiles')
        if text:
            acc.qos.extend(parse_qos_text(text))
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
