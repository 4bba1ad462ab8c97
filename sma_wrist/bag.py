"""rosbag2 (MCAP) recording from the embedded runtime, and robust reading.

Recording
---------
:class:`BagRecorder` taps publications in an embedded-runtime context (all topics or a
list) and writes them with rosbags' ``Writer`` and ``StoragePlugin.MCAP``.  The timestamp
of each message is the ROS time of the publishing node's clock at ``publish()`` (sim time
for ``use_sim_time`` nodes).

Humble compatibility: rosbags writes metadata version 8 or 9; Humble's rosbag2
(rosbag2_storage/src/rosbag2_storage/metadata_io.cpp, struct version 5) decodes any
version but reads ``offered_qos_profiles`` as a YAML *string* with integer policies
(rosbag2_transport/src/rosbag2_transport/qos.cpp, ``node["history"].as<int>()``).  Version
9 writes a YAML list with policy names, which Humble cannot parse.  We therefore write
version 8 (string, integer policies) and then rewrite ``metadata.yaml`` as version 5:
same fields minus the post-Humble keys (``type_description_hash``, ``custom_data``,
``ros_distro``).  Jazzy and rosbags read version 5 too.  The ``rosbag2`` metadata record
inside the .mcap keeps rosbags' version-8 text; Humble's MCAP plugin does not read it.

Crash safety: the writer is closed in ``finally`` blocks (``with BagRecorder(...)`` or
:meth:`sma_wrist.runtime.launch.Runtime.record`), so Ctrl-C or an exception leaves a
complete bag.  Every ``flush_every`` messages the pending MCAP chunk is written and the
file flushed, so even a killed process leaves a salvageable .mcap (no metadata.yaml).

Reading
-------
:func:`read_bag` returns ``{topic: (t_ns int64 array, [messages])}`` with rclpy-like
message objects; :func:`bag_info` summarises a bag.  Truncated or corrupt bags raise
:class:`BagError` naming the file and the problem; ``BagError.salvaged`` holds the
messages that could still be read from complete MCAP chunks (``read_bag(...,
salvage=True)`` returns them instead of raising).

Both rosbag2 storages are read: MCAP (this package's recordings, Jazzy's default) and SQLite
(``.db3``, what ``ros2 bag record`` writes on Humble by default).  A closed bag of either is read
directly (:func:`salvage_mcap`, :func:`salvage_db3`), its message counts checked against
metadata.yaml; anything else goes through rosbags' reader.  A SQLite file is read through its own
``topics`` table, so a recorder killed before it wrote metadata.yaml, a file cut short, or a
metadata.yaml whose topics do not match the storage's (rosbags then reads no message) loses only
what is really gone.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Optional

import numpy as np
import yaml

from sma_wrist.core.errors import SmaWristError

BagData = dict[str, tuple[np.ndarray, list[Any]]]

HUMBLE_METADATA_VERSION = 5
MCAP_MAGIC = b'\x89MCAP0\r\n'
SQLITE_MAGIC = b'SQLite format 3\x00'
ZSTD_MAGIC = b'\x28\xb5\x2f\xfd'  # rosbag2's message compression (``--compression-mode message``)
#: rosbag2 storage identifier -> its files' suffix
STORAGE_SUFFIX = {'mcap': '.mcap', 'sqlite3': '.db3'}


class BagError(SmaWristError):
    """A bag could not be written or read completely."""

    def __init__(self, path: str | Path, problem: str, salvaged: Optional[BagData] = None) -> None:
        self.path = str(path)
        self.problem = problem
        self.salvaged: BagData = salvaged or {}
        n = sum(len(v[1]) for v in self.salvaged.values())
        extra = f' ({n} messages salvaged)' if salvaged is not None else ''
        super().__init__(f'{self.path}: {problem}{extra}')


# --------------------------------------------------------------------------- recording
def _rosbags_qos(qos: Any) -> Any:
    from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime

    def t(d: Any) -> QosTime:
        sec, nsec = divmod(int(d.nanoseconds), 10**9)
        return QosTime(sec, nsec)

    return Qos(QosHistory(int(qos.history)), int(qos.depth), QosReliability(int(qos.reliability)),
               QosDurability(int(qos.durability)), t(qos.deadline), t(qos.lifespan),
               QosLiveliness(int(qos.liveliness)), t(qos.liveliness_lease_duration),
               bool(qos.avoid_ros_namespace_conventions))


def make_humble_compatible(bag_dir: str | Path) -> None:
    """Rewrite metadata.yaml of a rosbags v8 bag as rosbag2 metadata version 5 (Humble)."""
    meta_path = Path(bag_dir) / 'metadata.yaml'
    doc = yaml.safe_load(meta_path.read_text())
    info = doc['rosbag2_bagfile_information']
    if info.get('version', 0) not in (5, 8):
        raise BagError(bag_dir, f"metadata version {info.get('version')} cannot be down-converted")
    for key in ('custom_data', 'ros_distro'):
        info.pop(key, None)
    for t in info.get('topics_with_message_count', []):
        t['topic_metadata'].pop('type_description_hash', None)
        qos = t['topic_metadata'].get('offered_qos_profiles', '')
        if not isinstance(qos, str):
            raise BagError(bag_dir, 'offered_qos_profiles must be a string for Humble')
    info['version'] = HUMBLE_METADATA_VERSION
    tmp = meta_path.with_suffix('.yaml.tmp')
    tmp.write_text(yaml.safe_dump(doc, default_flow_style=False, sort_keys=True))
    tmp.replace(meta_path)


class BagRecorder:
    """Record publications of an embedded-runtime context into a rosbag2 MCAP bag.

    Parameters
    ----------
    path:
        Bag directory to create (must not exist).
    topics:
        Topic names to record; None records every topic (including ones created later).
    context:
        rclpy Context whose graph is tapped; default: the default context.
    flush_every:
        Write the pending MCAP chunk and flush the file every this many messages
        (0 disables; chunks are still written every 1 MiB by rosbags).
    humble_compatible:
        Rewrite metadata.yaml as version 5 on close (see module docstring).
    clock_ns:
        The recorder's clock for the log time of every message [ns] (``Runtime.record`` gives the
        sim time once /clock runs, like ``ros2 bag record --use-sim-time``); None: the
        publishing node's clock.
    """

    def __init__(self, path: str | Path, topics: Optional[Iterable[str]] = None, *,
                 context: Any = None, flush_every: int = 2000, humble_compatible: bool = True,
                 clock_ns: Optional[Callable[[], int]] = None) -> None:
        self._clock_ns = clock_ns
        self.path = Path(path)
        self.topics = None if topics is None else [t if t.startswith('/') else '/' + t for t in topics]
        self._context = context
        self.flush_every = int(flush_every)
        self.humble_compatible = humble_compatible
        self._writer: Any = None
        self._conns: dict[str, Any] = {}
        self._remove_tap: Any = None
        self.count = 0
        self.counts: dict[str, int] = {}
        self._since_flush = 0
        self.closed = False

    # -- lifecycle ---------------------------------------------------------
    def start(self) -> 'BagRecorder':
        from rosbags.rosbag2 import StoragePlugin, Writer
        from rosbags.rosbag2.errors import WriterError

        from sma_wrist.runtime.rclpy.utilities import get_default_context
        ctx = self._context if self._context is not None else get_default_context()
        if not ctx.ok():
            raise BagError(self.path, 'cannot record: the rclpy context is not initialised')
        try:
            self._writer = Writer(self.path, version=8, storage_plugin=StoragePlugin.MCAP)
            self._writer.open()
        except WriterError as exc:
            raise BagError(self.path, str(exc)) from None
        self._remove_tap = ctx.graph.add_tap(self._tap, self.topics)
        return self

    def __enter__(self) -> 'BagRecorder':
        return self.start() if self._writer is None else self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def _connection(self, topic: Any) -> tuple[Any, Any]:
        from sma_wrist.runtime.fastcdr import encoder_for
        from sma_wrist.runtime.messages import TYPESTORE
        qos = [_rosbags_qos(p.qos_profile) for p in topic.publishers[:1]]
        conn = self._writer.add_connection(topic.name, topic.msg_type._TYPE, typestore=TYPESTORE,
                                           offered_qos_profiles=qos)
        entry = self._conns[topic.name] = (conn, encoder_for(topic.msg_type._TYPE))
        self.counts[topic.name] = 0
        return entry

    def _tap(self, topic: Any, msg: Any, t_ns: int) -> None:
        entry = self._conns.get(topic.name)
        if entry is None:
            entry = self._connection(topic)
        conn, encode = entry
        t = self._clock_ns() if self._clock_ns is not None else t_ns
        self._writer.write(conn, t, encode(msg))
        self.count += 1
        self.counts[topic.name] += 1
        if self.flush_every:
            self._since_flush += 1
            if self._since_flush >= self.flush_every:
                self.flush()

    def flush(self) -> None:
        """Write the pending chunk and flush the file (salvageable after a hard kill)."""
        self._since_flush = 0
        storage = getattr(self._writer, 'storage', None)
        if storage is None:
            return
        if storage.chunk.bio.tell():
            storage.close_chunk()
        storage.bio.flush()

    def close(self) -> None:
        """Stop tapping, write the MCAP summary and metadata.yaml. Idempotent."""
        if self.closed or self._writer is None:
            return
        self.closed = True
        if self._remove_tap is not None:
            self._remove_tap()
            self._remove_tap = None
        self._writer.close()
        if self.humble_compatible:
            make_humble_compatible(self.path)


# --------------------------------------------------------------------------- reading
@dataclass
class TopicSummary:
    type: str
    count: int


@dataclass
class BagInfo:
    path: str
    version: int
    storage: str
    topics: dict[str, TopicSummary] = field(default_factory=dict)
    message_count: int = 0
    start_ns: int = 0
    end_ns: int = 0

    @property
    def duration_ns(self) -> int:
        return max(0, self.end_ns - self.start_ns)

    @property
    def duration(self) -> float:
        return self.duration_ns / 1e9


def _bag_dir(path: str | Path) -> Path:
    p = Path(path)
    if not p.exists():
        raise BagError(p, 'no such bag (directory, .mcap or .db3 file does not exist)')
    return p


def _storage_files(p: Path, suffixes: Iterable[str] = STORAGE_SUFFIX.values()) -> list[Path]:
    """The storage files of a bag directory (or the file itself) with one of ``suffixes``."""
    if p.is_file():
        return [p]
    return sorted(f for f in p.iterdir() if f.suffix in set(suffixes) and f.is_file())


def _salvage_file(file: Path, topics: Optional[frozenset[str]] = None
                  ) -> tuple[list[tuple[str, str, int, bytes]], str]:
    """(messages, problem) of one storage file, MCAP or SQLite as its first bytes say."""
    with open(file, 'rb') as f:
        head = f.read(16)
    if head == SQLITE_MAGIC:
        return salvage_db3(file, topics)
    return salvage_mcap(file, topics)


def iter_mcap(file: str | Path) -> Iterator[tuple[str, str, int, bytes]]:
    """(topic, msgtype, log_time_ns, cdr bytes) of an MCAP file via the `mcap` library's
    indexed reader (raises on a truncated file)."""
    from mcap.reader import make_reader
    with open(file, 'rb') as f:
        reader = make_reader(f)
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            yield channel.topic, schema.name if schema else '', message.log_time, message.data


def salvage_mcap(file: str | Path, topics: Optional[frozenset[str]] = None
                 ) -> tuple[list[tuple[str, str, int, bytes]], str]:
    """Read an MCAP file record by record without its index, keeping every complete
    message (of ``topics``, default all) -- also those at the start of a chunk cut off by
    truncation (uncompressed chunks, as BagRecorder writes them).  Returns (messages in file
    order, problem); problem is '' for a clean, closed file.

    It is also :func:`read_bag`'s fast path for closed bags: one pass over the bytes, about 2x
    faster than rosbags' indexed reader on a run bag. A file with compressed chunks (``ros2 bag
    record``'s ``zstd_fast`` / ``zstd_small`` storage presets) is read by the `mcap` library's
    stream reader instead (:func:`_stream_mcap`), which decompresses them."""
    data = Path(file).read_bytes()
    out: list[tuple[str, str, int, bytes]] = []
    schemas: dict[int, str] = {}
    channels: dict[int, tuple[str, int]] = {}
    keep: dict[int, tuple[str, str]] = {}  # channel id -> (topic, type) of a wanted channel
    if data[:8] != MCAP_MAGIC:
        return out, 'not an MCAP file (bad magic)'
    state = {'footer': False, 'problem': ''}

    def s16(b: bytes, o: int) -> tuple[int, int]:
        return int.from_bytes(b[o:o + 2], 'little'), o + 2

    def string(b: bytes, o: int) -> tuple[str, int]:
        n = int.from_bytes(b[o:o + 4], 'little')
        if o + 4 + n > len(b):
            raise ValueError('string runs past the end of its record')
        return b[o + 4:o + 4 + n].decode(), o + 4 + n

    def records(buf: bytes, pos: int, where: str) -> None:
        size = len(buf)
        while pos < size:
            if pos + 9 > size:
                state['problem'] = f'{where}: truncated record header at offset {pos}'
                return
            op = buf[pos]
            length = int.from_bytes(buf[pos + 1:pos + 9], 'little')
            end = pos + 9 + length
            if op == 0x05 and end <= size and length >= 22:
                # a message (the bulk of the file): channel u16, sequence u32, log and publish time u64,
                # data; only the wanted channels' bytes are copied
                cid = buf[pos + 9] | buf[pos + 10] << 8
                if cid in keep:
                    topic, msgtype = keep[cid]
                    out.append((topic, msgtype, int.from_bytes(buf[pos + 15:pos + 23], 'little'),
                                buf[pos + 31:end]))
                elif topics is None:  # a message before its channel (damaged file): keep what is known
                    topic, sid = channels.get(cid, ('', 0))
                    out.append((topic, schemas.get(sid, ''), int.from_bytes(buf[pos + 15:pos + 23], 'little'),
                                buf[pos + 31:end]))
                pos = end
                continue
            body = buf[pos + 9:end]
            if len(body) < length:
                if op == 0x06:  # chunk: read what is left of it
                    chunk(body, pos)
                state['problem'] = (state['problem'] or
                                    f'{where}: truncated record (opcode 0x{op:02x}) at offset {pos}')
                return
            if op == 0x03:
                sid, o = s16(body, 0)
                schemas[sid] = string(body, o)[0]
            elif op == 0x04:
                cid, o = s16(body, 0)
                sid, o = s16(body, o)
                channels[cid] = (string(body, o)[0], sid)
                if topics is None or channels[cid][0] in topics:
                    keep[cid] = (channels[cid][0], schemas.get(sid, ''))
            elif op == 0x06:
                chunk(body, pos)
            elif op == 0x02:
                state['footer'] = True
                return
            pos += 9 + length

    class Compressed(Exception):
        pass

    def chunk(body: bytes, pos: int) -> None:
        comp, o = string(body, 28)
        if comp:
            raise Compressed
        records(body[o + 8:], 0, f'chunk at offset {pos}')

    try:
        records(data, 8, 'file')
    except (ValueError, UnicodeDecodeError) as exc:
        state['problem'] = state['problem'] or f'corrupt record: {exc}'
    except Compressed:
        del data
        return _stream_mcap(file, topics)
    problem = state['problem']
    if problem:
        problem = f'MCAP data is truncated or corrupt after {len(out)} messages ({problem})'
    elif not state['footer']:
        problem = f'MCAP file has no footer (recording was not closed) after {len(out)} messages'
    return out, problem


def _stream_mcap(file: str | Path, topics: Optional[frozenset[str]] = None
                 ) -> tuple[list[tuple[str, str, int, bytes]], str]:
    """:func:`salvage_mcap` of a file with compressed chunks (zstd, lz4): the `mcap` library's stream reader,
    record by record without the index, up to the first record it cannot read (a chunk cut short is lost
    whole: its compressed bytes cannot be read in part)."""
    from mcap.records import Channel, Footer, Message, Schema
    from mcap.stream_reader import StreamReader
    out: list[tuple[str, str, int, bytes]] = []
    schemas: dict[int, str] = {}
    channels: dict[int, tuple[str, str]] = {}
    footer = False
    try:
        with open(file, 'rb') as f:
            for rec in StreamReader(f).records:
                if isinstance(rec, Message):
                    topic, msgtype = channels.get(rec.channel_id, ('', ''))
                    if topics is None or topic in topics:
                        out.append((topic, msgtype, rec.log_time, rec.data))
                elif isinstance(rec, Channel):
                    channels[rec.id] = (rec.topic, schemas.get(rec.schema_id, ''))
                elif isinstance(rec, Schema):
                    schemas[rec.id] = rec.name
                elif isinstance(rec, Footer):
                    footer = True
    except Exception as exc:  # noqa: BLE001 - the mcap library raises several error types on damaged data
        return out, f'MCAP data is truncated or corrupt after {len(out)} messages ({type(exc).__name__}: {exc})'
    if not footer:
        return out, f'MCAP file has no footer (recording was not closed) after {len(out)} messages'
    return out, ''


def salvage_db3(file: str | Path, topics: Optional[frozenset[str]] = None
                ) -> tuple[list[tuple[str, str, int, bytes]], str]:
    """Read a rosbag2 SQLite file (``.db3``) through its own ``topics`` and ``messages`` tables, without
    metadata.yaml: (messages of ``topics``, default all, in recording order, problem); problem is '' for a
    file read to its end. Humble's and Jazzy's schemas (and earlier ones) share these two tables.

    A file cut short (a copy or a disk that ran out) is refused whole by SQLite ("database disk image is
    malformed": its header promises more pages). It is then read from a temporary copy whose header gives the
    pages that are there, up to the first page that is not. Messages compressed by rosbag2
    (``--compression-mode message``, zstd) are not decoded here: reported as a problem."""
    import contextlib
    import sqlite3
    import tempfile
    file = Path(file)
    out: list[tuple[str, str, int, bytes]] = []
    with open(file, 'rb') as f:
        head = f.read(100)
    if head[:16] != SQLITE_MAGIC or len(head) < 100:
        return out, 'not a SQLite file (bad magic)'
    page = int.from_bytes(head[16:18], 'big')
    page = 65536 if page == 1 else page
    promised, size = int.from_bytes(head[28:32], 'big'), file.stat().st_size
    # SQLite trusts the header's page count only while its "version-valid-for" equals the change counter
    trusted = head[92:96] == head[24:28]
    notes: list[str] = []
    with contextlib.ExitStack() as stack:
        path = file
        if trusted and page >= 512 and promised * page > size:  # a copy only for a file cut short
            notes.append(f'the file is cut short: {size} of {promised * page} bytes')
            path = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix='sma_wrist_db3_'))) / file.name
            with open(file, 'rb') as src:
                data = bytearray(src.read(size - size % page))
            data[28:32] = (len(data) // page).to_bytes(4, 'big')
            path.write_bytes(data)
            del data
        try:
            con = sqlite3.connect(f'{path.resolve().as_uri()}?mode=ro', uri=True)
        except sqlite3.Error as exc:
            return out, f'SQLite file cannot be opened: {exc}'
        try:
            names = {int(i): (str(n), str(t)) for i, n, t in con.execute('SELECT id, name, type FROM topics')}
            ids = [i for i, (n, _) in names.items() if topics is None or n in topics]
            where = '' if topics is None else f" WHERE topic_id IN ({','.join(map(str, ids)) or 'NULL'})"
            for tid, t, data in con.execute(f'SELECT topic_id, timestamp, data FROM messages{where} ORDER BY id'):
                if data[:4] == ZSTD_MAGIC:
                    notes.append('compressed messages (zstd) cannot be salvaged')
                    break
                topic, msgtype = names.get(tid, ('', ''))
                out.append((topic, msgtype, int(t), bytes(data)))
        except sqlite3.DatabaseError as exc:
            notes.append(f'{exc} after {len(out)} messages')
        finally:
            con.close()
    problem = '; '.join(notes)
    return out, (f'SQLite data is truncated or corrupt ({problem})' if problem else '')


def _to_bagdata(rows: Iterable[tuple[str, str, int, bytes]]) -> BagData:
    from sma_wrist.runtime.fastcdr import decoder_for
    times: dict[str, list[int]] = {}
    msgs: dict[str, list[Any]] = {}
    decoders: dict[str, Any] = {}
    for topic, msgtype, t, data in rows:
        try:
            decode = decoders.get(msgtype)
            if decode is None:
                decode = decoders[msgtype] = decoder_for(msgtype)
            m = decode(data)
        except Exception:  # noqa: BLE001 - a damaged message (or unknown type) is skipped in salvage
            continue
        times.setdefault(topic, []).append(t)
        msgs.setdefault(topic, []).append(m)
    return {k: (np.asarray(times[k], dtype=np.int64), msgs[k]) for k in times}


def _salvage(p: Path) -> tuple[BagData, str]:
    rows: list[tuple[str, str, int, bytes]] = []
    problems = []
    files = _storage_files(p)
    if not files:
        return {}, 'no .mcap or .db3 file in the bag directory'
    for f in files:
        r, problem = _salvage_file(f)
        rows.extend(r)
        if problem:
            problems.append(f'{f.name}: {problem}')
    rows.sort(key=lambda r: r[2])
    return _to_bagdata(rows), '; '.join(problems)


def _read_closed(p: Path, wanted: Optional[frozenset[str]]) -> Optional[BagData]:
    """read_bag's fast path: a closed bag of uncompressed MCAP files (BagRecorder's, in one pass each:
    :func:`salvage_mcap`) or of SQLite files (``ros2 bag record`` on Humble: :func:`salvage_db3`), its message
    counts checked against metadata.yaml. None for anything else (another storage, compression, a damaged
    file, counts that differ): read_bag then uses rosbags' reader and its error reporting."""
    try:
        meta = _metadata(p)
        suffix = STORAGE_SUFFIX.get(meta.get('storage_identifier'))
        files = _storage_files(p, [suffix]) if suffix else []
        if not files:
            return None
        expected = sum(int(t['message_count']) for t in meta['topics_with_message_count']
                       if wanted is None or t['topic_metadata']['name'] in wanted)
    except (OSError, yaml.YAMLError, _NotMetadata, KeyError, TypeError, ValueError):
        return None
    rows: list[tuple[str, str, int, bytes]] = []
    for f in files:
        r, problem = _salvage_file(f, wanted)
        if problem:
            return None
        rows.extend(r)
    if len(rows) != expected:
        return None
    rows.sort(key=lambda r: r[2])  # stable, and linear on a recording already in time order
    return _to_bagdata(rows)


def read_bag(path: str | Path, topics: Optional[Iterable[str]] = None, *,
             salvage: bool = False) -> BagData:
    """All messages of a bag: ``{topic: (t_ns int64 array, [messages])}`` in time order.

    Raises BagError if the bag is missing, truncated or corrupt (``.salvaged`` holds what
    could be read); with ``salvage=True`` returns the salvaged messages instead.
    """
    from rosbags.rosbag2 import Reader

    p = _bag_dir(path)
    wanted = None if topics is None else set(topics)

    def select(data: BagData) -> BagData:
        return data if wanted is None else {k: v for k, v in data.items() if k in wanted}

    problem = ''
    if p.is_dir() and (p / 'metadata.yaml').exists():
        fast = _read_closed(p, None if wanted is None else frozenset(wanted))
        if fast is not None:
            return fast
        try:
            _metadata(p)  # rosbags' own error for an empty file is a bare TypeError
            with Reader(p) as reader:
                conns = [c for c in reader.connections if wanted is None or c.topic in wanted]
                rows = [(c.topic, c.msgtype, t, bytes(raw)) for c, t, raw in reader.messages(connections=conns)]
                expected = sum(c.msgcount for c in conns)
            if len(rows) != expected:
                problem = f'metadata.yaml lists {expected} messages but the storage holds {len(rows)}'
            else:
                return select(_to_bagdata(rows))
        except _NotMetadata as exc:
            problem = str(exc)
        except Exception as exc:  # noqa: BLE001 - rosbags raises several error types
            problem = f'{type(exc).__name__}: {exc}'
    elif p.is_dir():
        problem = 'metadata.yaml is missing (the recording was not closed; `ros2 bag reindex` rebuilds it)'
    data, salvage_problem = _salvage(p)
    if not problem:
        if not salvage_problem:
            return select(data)  # a bare, complete .mcap or .db3 file
        problem = salvage_problem
    elif salvage_problem:
        problem = f'{problem}; {salvage_problem}'
    if salvage:
        return select(data)
    raise BagError(p, problem, select(data))


class _NotMetadata(Exception):
    """metadata.yaml is there but is not rosbag2's (empty, another document): said so, not as a TypeError."""


def _metadata(p: Path) -> dict[str, Any]:
    """The ``rosbag2_bagfile_information`` mapping of a bag directory's metadata.yaml."""
    doc = yaml.safe_load((p / 'metadata.yaml').read_text())
    meta = doc.get('rosbag2_bagfile_information') if isinstance(doc, dict) else None
    if not isinstance(meta, dict):
        raise _NotMetadata('metadata.yaml is empty or not rosbag2 metadata (no rosbag2_bagfile_information)')
    return meta


def _bare_file_info(p: Path) -> BagInfo | None:
    """bag_info of a bare, complete .mcap or .db3 file (no rosbag2 metadata: ``version`` 0), as read_bag reads
    one; None for anything else (a directory without metadata.yaml, a damaged file)."""
    storage = {v: k for k, v in STORAGE_SUFFIX.items()}.get(p.suffix)
    if not (p.is_file() and storage):
        return None
    rows, problem = _salvage_file(p)
    if problem:
        return None
    info = BagInfo(path=str(p), version=0, storage=storage, message_count=len(rows))
    for topic, msgtype, _, _ in rows:
        prev = info.topics.get(topic)
        info.topics[topic] = TopicSummary(msgtype, 1 + (prev.count if prev else 0))
    if rows:
        t = [r[2] for r in rows]
        info.start_ns, info.end_ns = min(t), max(t)
    return info


def bag_info(path: str | Path) -> BagInfo:
    """Topics, types, counts, start/end/duration of a bag (BagError if unreadable)."""
    from rosbags.rosbag2 import Reader

    p = _bag_dir(path)
    if not (p.is_dir() and (p / 'metadata.yaml').exists()):
        bare = _bare_file_info(p)
        if bare is not None:
            return bare
        data, problem = _salvage(p)
        raise BagError(p, problem or 'metadata.yaml is missing', data)
    try:
        meta = _metadata(p)
        with Reader(p) as reader:
            info = BagInfo(path=str(p), version=int(meta['version']),
                           storage=str(meta['storage_identifier']),
                           message_count=reader.message_count,
                           start_ns=reader.start_time if reader.message_count else 0,
                           end_ns=reader.end_time - 1 if reader.message_count else 0)
            for c in reader.connections:
                prev = info.topics.get(c.topic)
                info.topics[c.topic] = TopicSummary(c.msgtype, c.msgcount + (prev.count if prev else 0))
            # touch the storage index so a truncated .mcap is reported here too
            for _ in reader.messages(connections=reader.connections[:1]):
                break
        return info
    except BagError:
        raise
    except Exception as exc:  # noqa: BLE001
        data, problem = _salvage(p)
        why = str(exc) if isinstance(exc, _NotMetadata) else f'{type(exc).__name__}: {exc}'
        raise BagError(p, why + (f'; {problem}' if problem else ''), data) from None
