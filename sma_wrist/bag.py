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

from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from struct import Struct
from typing import Any

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

    def __init__(self, path: str | Path, problem: str, salvaged: BagData | None = None) -> None:
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

    return Qos(
        QosHistory(int(qos.history)),
        int(qos.depth),
        QosReliability(int(qos.reliability)),
        QosDurability(int(qos.durability)),
        t(qos.deadline),
        t(qos.lifespan),
        QosLiveliness(int(qos.liveliness)),
        t(qos.liveliness_lease_duration),
        bool(qos.avoid_ros_namespace_conventions),
    )


def make_humble_compatible(bag_dir: str | Path) -> None:
    """Rewrite metadata.yaml of a rosbags v8 bag as rosbag2 metadata version 5 (Humble)."""
    meta_path = Path(bag_dir) / 'metadata.yaml'
    # the file rosbags just wrote: libyaml's parser where PyYAML has it (the same mapping, ~30 ms less per bag)
    doc = yaml.load(meta_path.read_text(), Loader=getattr(yaml, 'CSafeLoader', yaml.SafeLoader))
    info = doc['rosbag2_bagfile_information']
    if info.get('version', 0) not in (5, 8):
        raise BagError(bag_dir, f'metadata version {info.get("version")} cannot be down-converted')
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


#: an MCAP Message record's head (opcode 0x05, record length, channel id, sequence 0, log and publish time):
#: the bytes rosbags' McapWriter.write puts before the CDR payload, packed in one call
_MCAP_MESSAGE_HEAD = Struct('<BQHIQQ')
_MCAP_MESSAGE_FIELDS = _MCAP_MESSAGE_HEAD.size - 9  # record length without the payload
#: the chunk size at which rosbags' McapWriter closes a chunk [bytes]
_MCAP_CHUNK_BYTES = 2**20


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

    #: write message records straight into the MCAP writer's pending chunk (:meth:`_write_direct`); False (or a
    #: writer this recorder does not know): rosbags' ``Writer.write``
    direct: bool = True

    def __init__(
        self,
        path: str | Path,
        topics: Iterable[str] | None = None,
        *,
        context: Any = None,
        flush_every: int = 2000,
        humble_compatible: bool = True,
        clock_ns: Callable[[], int] | None = None,
    ) -> None:
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
    def start(self) -> BagRecorder:
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
        self.direct = self.direct and _direct_writable(self._writer)
        self._remove_tap = ctx.graph.add_tap(self._tap, self.topics)
        return self

    def __enter__(self) -> BagRecorder:
        return self.start() if self._writer is None else self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def _connection(self, topic: Any) -> tuple[Any, Any]:
        from sma_wrist.runtime.fastcdr import encoder_for
        from sma_wrist.runtime.messages import TYPESTORE

        qos = [_rosbags_qos(p.qos_profile) for p in topic.publishers[:1]]
        conn = self._writer.add_connection(
            topic.name, topic.msg_type._TYPE, typestore=TYPESTORE, offered_qos_profiles=qos
        )
        entry = self._conns[topic.name] = (conn, encoder_for(topic.msg_type._TYPE))
        self.counts[topic.name] = 0
        return entry

    def _tap(self, topic: Any, msg: Any, t_ns: int) -> None:
        entry = self._conns.get(topic.name)
        if entry is None:
            entry = self._connection(topic)
        conn, encode = entry
        t = self._clock_ns() if self._clock_ns is not None else t_ns
        data = topic.cdr(msg, encode)
        if self.direct:
            self._write_direct(conn, t, data)
        else:
            self._writer.write(conn, t, data)
        self.count += 1
        self.counts[topic.name] += 1
        if self.flush_every:
            self._since_flush += 1
            if self._since_flush >= self.flush_every:
                self.flush()

    def _write_direct(self, conn: Any, t: int, data: bytes) -> None:
        """What rosbags' ``Writer.write`` and ``McapWriter.write`` do for an uncompressed-message
        bag, with the record head packed in one call: the same bytes and indexes (test_bag), a third of
        the recorder's per-message cost (``sma-wrist bench --section speed``). The connection was
        added by this recorder, so Writer.write's check that it is known is skipped."""
        w = self._writer
        st = w.storage
        cid = conn.id
        if t < st.message_start_time:
            st.message_start_time = t
        if t > st.message_end_time:
            st.message_end_time = t
        st.channel_stats[cid] += 1
        ch = st.chunk
        if t < ch.message_start_time:
            ch.message_start_time = t
        if t > ch.message_end_time:
            ch.message_end_time = t
        bio = ch.bio
        ch.msgs[cid].append((t, bio.tell()))
        bio.write(_MCAP_MESSAGE_HEAD.pack(5, _MCAP_MESSAGE_FIELDS + len(data), cid, 0, t, t))
        bio.write(data)
        if bio.tell() > _MCAP_CHUNK_BYTES:
            st.close_chunk()
        w.counts[cid] += 1
        if t < w.min_timestamp:
            w.min_timestamp = t
        if t > w.max_timestamp:
            w.max_timestamp = t

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


def _direct_writable(writer: Any) -> bool:
    """Whether :meth:`BagRecorder._write_direct` knows this writer: rosbags' MCAP storage with the
    attributes it keeps per message, and no per-message compression (else ``Writer.write`` is used)."""
    from rosbags.rosbag2.enums import CompressionMode
    from rosbags.rosbag2.storage_mcap import McapWriter

    st = getattr(writer, 'storage', None)
    return (
        type(st) is McapWriter
        and getattr(writer, 'compression_mode', None) == CompressionMode.NONE
        and all(hasattr(st, a) for a in ('message_start_time', 'message_end_time', 'channel_stats', 'chunk'))
        and all(hasattr(st.chunk, a) for a in ('message_start_time', 'message_end_time', 'bio', 'msgs'))
        and all(hasattr(writer, a) for a in ('counts', 'min_timestamp', 'max_timestamp'))
    )


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
    #: what is wrong with a closed bag that reads only in part (a damaged chunk, messages that do not decode):
    #: which parts, how many messages are lost, when; '' for an intact bag
    damage: str = ''

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


@dataclass
class _MetaCounts:
    """What metadata.yaml says a bag holds, to check a read against (absent: all empty)."""

    total: int | None = None
    per_file: dict[str, int] = field(default_factory=dict)
    topics: list[tuple[str, str]] = field(default_factory=list)  # (name, type) in metadata.yaml's order


def _meta_counts(p: Path, meta: dict[str, Any] | None = None) -> _MetaCounts:
    """metadata.yaml's message counts of a bag directory (``meta``: its mapping, if already read), if it has a
    usable one."""
    try:
        meta = _metadata(p) if meta is None else meta
        listed = meta.get('topics_with_message_count') or []
        return _MetaCounts(
            sum(int(t['message_count']) for t in listed),
            {Path(str(f['path'])).name: int(f['message_count']) for f in meta.get('files') or []},
            [(str(t['topic_metadata']['name']), str(t['topic_metadata']['type'])) for t in listed],
        )
    except (OSError, yaml.YAMLError, _NotMetadata, KeyError, TypeError, ValueError):
        return _MetaCounts()


def _salvage_file(
    file: Path, topics: frozenset[str] | None = None, meta: _MetaCounts | None = None
) -> tuple[list[tuple[str, str, int, bytes]], str]:
    """(messages, problem) of one storage file, MCAP or SQLite as its first bytes say."""
    with open(file, 'rb') as f:
        head = f.read(16)
    if head == SQLITE_MAGIC or file.suffix == '.db3':  # a .db3 whose header is destroyed is still page-scanned
        meta = meta or _MetaCounts()
        return salvage_db3(file, topics, meta.per_file.get(file.name), meta.topics)
    return salvage_mcap(file, topics)


def iter_mcap(file: str | Path) -> Iterator[tuple[str, str, int, bytes]]:
    """(topic, msgtype, log_time_ns, cdr bytes) of an MCAP file via the `mcap` library's
    indexed reader (raises on a truncated file)."""
    from mcap.reader import make_reader

    with open(file, 'rb') as f:
        reader = make_reader(f)
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            yield channel.topic, schema.name if schema else '', message.log_time, message.data


def _mcap_summary(data: bytes) -> Any:
    """The summary section of a closed MCAP file (the `mcap` library's ``Summary``: chunk indexes, statistics,
    channels), None if the file has none or it does not read."""
    import io

    from mcap.reader import SeekingReader

    try:
        return SeekingReader(io.BytesIO(data), validate_crcs=False).get_summary()
    except Exception:  # noqa: BLE001 - a damaged footer or summary: the file is read without it
        return None


def _message_index(data: bytes, index: Any) -> list[tuple[int, int, int]]:
    """(offset in the chunk's records, channel id, log time) of every message a chunk's MessageIndex records list,
    by offset; [] where they do not read."""
    entries: list[tuple[int, int, int]] = []
    for cid, off in index.message_index_offsets.items():
        if data[off : off + 1] != b'\x07' or int.from_bytes(data[off + 9 : off + 11], 'little') != cid:
            return []
        n = int.from_bytes(data[off + 11 : off + 15], 'little')
        if off + 15 + n > len(data) or n % 16:
            return []
        raw = data[off + 15 : off + 15 + n]
        entries.extend(
            (int.from_bytes(raw[i + 8 : i + 16], 'little'), cid, int.from_bytes(raw[i : i + 8], 'little'))
            for i in range(0, n, 16)
        )
    return sorted(entries)


def salvage_mcap(
    file: str | Path, topics: frozenset[str] | None = None
) -> tuple[list[tuple[str, str, int, bytes]], str]:
    """Read an MCAP file record by record without its index, keeping every complete
    message (of ``topics``, default all) -- also those at the start of a chunk cut off by
    truncation (uncompressed chunks, as BagRecorder writes them).  Returns (messages in file
    order, problem); problem is '' for a clean, closed file.

    Damage inside a closed file is found and counted, not read as data: a chunk whose records do not match its
    CRC (``uncompressed_crc``; 0, as rosbags writes it, means none was computed) is left out whole; a chunk whose
    records do not parse keeps the messages its MessageIndex records vouch for (a message's header and the next
    one's are where and what the index says), and a record that does not parse between chunks is skipped up to the
    next chunk the summary's chunk index lists. The problem names each damaged chunk, the messages lost and their
    time span; without a CRC, damage inside a message's bytes is found only if it no longer decodes.

    It is also :func:`read_bag`'s fast path for closed bags: one pass over the bytes, about 2x
    faster than rosbags' indexed reader on a run bag. A file with compressed chunks (``ros2 bag
    record``'s ``zstd_fast`` / ``zstd_small`` storage presets) is read by the `mcap` library's
    stream reader instead (:func:`_stream_mcap`), which decompresses them."""
    import bisect
    import zlib

    data = Path(file).read_bytes()
    out: list[tuple[str, str, int, bytes]] = []
    schemas: dict[int, str] = {}
    channels: dict[int, tuple[str, int]] = {}
    keep: dict[int, tuple[str, str]] = {}  # channel id -> (topic, type) of a wanted channel
    if data[:8] != MCAP_MAGIC:
        return out, 'the file is empty (0 bytes)' if not data else 'not an MCAP file (bad magic)'
    state = {'footer': False, 'problem': ''}
    summary: Any = None  # read only once something is wrong: the healthy path stays one pass
    damage: list[str] = []
    lost_times: list[int] = []

    def get_summary() -> Any:
        nonlocal summary
        if summary is None:
            summary = _mcap_summary(data) or False
        return summary

    by_offset: dict[int, Any] = {}

    def chunk_index(pos: int) -> Any:
        """The summary's index entry of the chunk at ``pos``, None if there is none."""
        if not by_offset:
            s = get_summary()
            by_offset.update({c.chunk_start_offset: c for c in s.chunk_indexes} if s else {-1: None})
        return by_offset.get(pos)

    starts: list[int] = []

    def next_chunk(pos: int) -> int:
        """The offset of the first chunk the summary lists after ``pos`` (0: none)."""
        if not starts:
            s = get_summary()
            starts.extend(sorted(c.chunk_start_offset for c in s.chunk_indexes) if s else [-1])
        i = bisect.bisect_right(starts, pos)
        return starts[i] if i < len(starts) else 0

    def s16(b: bytes, o: int) -> tuple[int, int]:
        return int.from_bytes(b[o : o + 2], 'little'), o + 2

    def string(b: bytes, o: int) -> tuple[str, int]:
        n = int.from_bytes(b[o : o + 4], 'little')
        if o + 4 + n > len(b):
            raise ValueError('string runs past the end of its record')
        return b[o + 4 : o + 4 + n].decode(), o + 4 + n

    def message(buf: bytes, pos: int, end: int) -> None:
        cid = buf[pos + 9] | buf[pos + 10] << 8
        if cid in keep:
            topic, msgtype = keep[cid]
            out.append((topic, msgtype, int.from_bytes(buf[pos + 15 : pos + 23], 'little'), buf[pos + 31 : end]))
        elif topics is None:  # a message before its channel (damaged file): keep what is known
            topic, sid = channels.get(cid, ('', 0))
            out.append(
                (topic, schemas.get(sid, ''), int.from_bytes(buf[pos + 15 : pos + 23], 'little'), buf[pos + 31 : end])
            )

    def records(buf: bytes, pos: int, where: str) -> None:
        size = len(buf)
        top = where == 'file'
        while pos < size:
            op = buf[pos]
            length = int.from_bytes(buf[pos + 1 : pos + 9], 'little')
            end = pos + 9 + length
            bad = pos + 9 > size or end > size or op == 0 or 0x10 <= op < 0x80
            if (
                top
                and not bad
                and op != 0x06
                and (ci := chunk_index(next_chunk(pos - 1))) is not None
                and ci.chunk_start_offset < end
            ):  # a record overlapping the next chunk: its length is damaged
                bad = True
            if top and bad and state['footer'] is False and (resume := next_chunk(pos)):
                # a record that does not parse between chunks of a closed file: go on at the next indexed chunk
                damage.append(f'bytes {pos}..{resume} do not parse as records (skipped)')
                pos = resume
                continue
            if pos + 9 > size:
                state['problem'] = f'{where}: truncated record header at offset {pos}'
                return
            if op == 0x05 and end <= size and length >= 22:
                message(buf, pos, end)  # the bulk of the file: only the wanted channels' bytes are copied
                pos = end
                continue
            body = buf[pos + 9 : end]
            if len(body) < length:
                if op == 0x06:  # chunk: read what is left of it
                    chunk(body, pos, complete=False)
                state['problem'] = state['problem'] or f'{where}: truncated record (opcode 0x{op:02x}) at offset {pos}'
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
                if top:
                    ci = chunk_index(pos) if summary else None
                    if ci is not None and ci.chunk_length != length + 9:
                        raise ValueError(f'chunk at offset {pos} is not as long as the index says')
                chunk(body, pos)
            elif op == 0x02:
                state['footer'] = True
                return
            elif op == 0x01 and where != 'file':
                raise ValueError(f'a header record inside {where}')
            pos += 9 + length

    class Compressed(Exception):
        pass

    def span(times: list[int]) -> str:
        s = get_summary()
        t0 = s.statistics.message_start_time if s and s.statistics else 0
        return f't {(min(times) - t0) / 1e9:.3f}..{(max(times) - t0) / 1e9:.3f} s' if times else 'times unknown'

    def chunk(body: bytes, pos: int, complete: bool = True) -> None:
        crc = int.from_bytes(body[24:28], 'little')
        comp, o = string(body, 28)
        if comp:
            raise Compressed
        recs = body[o + 8 : o + 8 + int.from_bytes(body[o : o + 8], 'little')]
        start = len(out)
        if not complete:  # cut off by truncation: every complete message before the cut
            records(recs, 0, f'chunk at offset {pos}')
            return
        if crc and zlib.crc32(recs) != crc:  # damaged, and nothing says where: none of its messages is trusted
            ci = chunk_index(pos)
            entries = _message_index(data, ci) if ci is not None else []
            times = [t for _, cid, t in entries if topics is None or cid in keep]
            lost_times.extend(times)
            damage.append(
                f'chunk at offset {pos} does not match its CRC: '
                f'{len(times) if entries else "all its"} messages lost ({span(times)})'
            )
            return
        saved = state['problem']
        try:
            records(recs, 0, f'chunk at offset {pos}')
            broken = state['problem']
        except (ValueError, UnicodeDecodeError) as exc:
            broken = str(exc)
        state['problem'] = saved
        if not broken:
            return
        # records that do not parse inside a complete chunk: keep the messages its index vouches for
        broken = broken.removeprefix(f'chunk at offset {pos}: ')
        prefix = out[start:]
        del out[start:]
        ci = chunk_index(pos)
        entries = _message_index(data, ci) if ci is not None else []
        if not entries:  # no index to go by: the messages before the break, but the last (damage may start in it)
            out.extend(prefix[:-1])
            damage.append(
                f'chunk at offset {pos} is damaged ({broken}); no message index: the messages after '
                f'{len(prefix) - 1} of it are lost'
            )
            return
        ok = []
        for off, cid, t in entries:
            length = int.from_bytes(recs[off + 1 : off + 9], 'little')
            ok.append(
                recs[off : off + 1] == b'\x05'
                and off + 9 + length <= len(recs)
                and length >= 22
                and int.from_bytes(recs[off + 9 : off + 11], 'little') == cid
                and int.from_bytes(recs[off + 15 : off + 23], 'little') == t
            )
        lost = []
        for k, (off, cid, t) in enumerate(entries):
            # the next message's header must be intact too: damage that starts in this one's bytes breaks it
            if ok[k] and (ok[k + 1] if k + 1 < len(entries) else True):
                if cid in keep or topics is None:
                    message(recs, off, off + 9 + int.from_bytes(recs[off + 1 : off + 9], 'little'))
            elif cid in keep or topics is None:
                lost.append(t)
        lost_times.extend(lost)
        damage.append(f'chunk at offset {pos} is damaged ({broken}): {len(lost)} messages lost ({span(lost)})')

    try:
        records(data, 8, 'file')
    except (ValueError, UnicodeDecodeError) as exc:
        state['problem'] = state['problem'] or f'corrupt record: {exc}'
    except Compressed:
        del data
        return _stream_mcap(file, topics)
    problem = state['problem']
    if damage:
        s = get_summary()
        stats = s.statistics if s else None
        total = (
            ''
            if stats is None
            else (f' of {sum(n for cid, n in stats.channel_message_counts.items() if topics is None or cid in keep)}')
        )
        problem = '; '.join(
            [f'MCAP data is damaged: {len(out)}{total} messages read', *damage] + ([problem] if problem else [])
        )
    elif problem:
        problem = f'MCAP data is truncated or corrupt after {len(out)} messages ({problem})'
    elif not state['footer']:
        problem = f'MCAP file has no footer (recording was not closed) after {len(out)} messages'
    return out, problem


def _stream_mcap(
    file: str | Path, topics: frozenset[str] | None = None
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


def salvage_db3(
    file: str | Path,
    topics: frozenset[str] | None = None,
    expected: int | None = None,
    guess_topics: list[tuple[str, str]] | None = None,
) -> tuple[list[tuple[str, str, int, bytes]], str]:
    """Read a rosbag2 SQLite file (``.db3``) through its own ``topics`` and ``messages`` tables, without
    metadata.yaml: (messages of ``topics``, default all, in recording order, problem); problem is '' for a
    file read to its end. Humble's and Jazzy's schemas (and earlier ones) share these two tables.

    A file cut short (a copy or a disk that ran out) is refused whole by SQLite ("database disk image is
    malformed": its header promises more pages). It is then read from a temporary copy whose header gives the
    pages that are there. Where SQLite still stops early (the cut took b-tree interior pages: it then reads
    nothing past them), gives fewer rows than ``expected`` (metadata.yaml's count for this file), or cannot read
    the file at all (header destroyed), the file is scanned page by page (:func:`_scan_db3`) for the rows that
    are physically there. Without a readable ``topics`` table the topic ids are named after ``guess_topics``
    (metadata.yaml's topics, in its order: rosbags' writer gives ids in that order) where their messages decode
    as that type, and the problem says so. Messages compressed by rosbag2 (``--compression-mode message``, zstd)
    are not decoded here: reported as a problem."""
    import contextlib
    import sqlite3
    import tempfile

    file = Path(file)
    with open(file, 'rb') as f:
        head = f.read(100)
    notes: list[str] = []
    rows: dict[int, tuple[int, int, bytes]] = {}  # message id -> (topic id, timestamp, data): read by SQLite
    names: dict[int, tuple[str, str]] = {}
    sqlite_ok = False
    if head[:16] != SQLITE_MAGIC or len(head) < 100:
        if file.suffix != '.db3':
            return [], 'not a SQLite file (bad magic)'
        notes.append('the SQLite header is destroyed (bad magic)')
    else:
        page = int.from_bytes(head[16:18], 'big')
        page = 65536 if page == 1 else page
        promised, size = int.from_bytes(head[28:32], 'big'), file.stat().st_size
        # SQLite trusts the header's page count only while its "version-valid-for" equals the change counter
        trusted = head[92:96] == head[24:28]
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
                try:
                    names = {int(i): (str(n), str(t)) for i, n, t in con.execute('SELECT id, name, type FROM topics')}
                    for i, tid, t, data in con.execute(
                        'SELECT id, topic_id, timestamp, data FROM messages ORDER BY id'
                    ):
                        rows[int(i)] = (int(tid), int(t), bytes(data))
                    sqlite_ok = True
                finally:
                    con.close()
            except sqlite3.Error as exc:
                notes.append(f'SQLite stopped after {len(rows)} messages ({exc})')
    short = expected is not None and len(rows) < expected
    if sqlite_ok and short:
        notes.append(f'SQLite reads {len(rows)} of the {expected} messages metadata.yaml lists for it')
    scanned = ''
    if not sqlite_ok or short:
        # what SQLite cannot reach may still be on the pages that are there
        wal = file.with_name(file.name + '-wal')
        scan = _scan_db3(file.read_bytes(), wal.read_bytes() if wal.is_file() else None)
        found = sum(1 for i in scan.messages if i not in rows)
        for i, r in scan.messages.items():
            rows.setdefault(i, r)
        scanned = f'a page-by-page scan found {found} more'
        if scan.lost:
            scanned += (
                f'; {len(scan.lost)} messages (t {scan.lost[0] / 1e9:.3f} .. {scan.lost[-1] / 1e9:.3f} s) are '
                f'lost with their overflow pages'
            )
        if not names:
            names = scan.topics
        if not names and rows:
            names = _guess_topic_ids(rows, guess_topics or [])
            scanned += '; the topics table is lost: ' + (
                "topic names guessed from metadata.yaml (its order, checked by decoding each id's first message)"
                if names
                else 'the messages cannot be named (no metadata.yaml topics match them) and are not read'
            )
        notes.append(scanned)
    out: list[tuple[str, str, int, bytes]] = []
    for i in sorted(rows):
        tid, t, data = rows[i]
        topic, msgtype = names.get(tid, ('', ''))
        if topics is not None and topic not in topics:
            continue
        if data[:4] == ZSTD_MAGIC:
            notes.append('compressed messages (zstd) cannot be salvaged')
            break
        out.append((topic, msgtype, t, data))
    problem = '; '.join(notes)
    return out, (f'SQLite data is truncated or corrupt ({problem})' if problem else '')


def _guess_topic_ids(
    rows: dict[int, tuple[int, int, bytes]], topics: list[tuple[str, str]]
) -> dict[int, tuple[str, str]]:
    """Topic id -> (name, type) when the ``topics`` table is lost: id k is metadata.yaml's k-th topic, kept only if
    every id's first message decodes as that type ({} when any does not: a wrong guess would misfile data)."""
    from sma_wrist.runtime.fastcdr import decoder_for

    first: dict[int, bytes] = {}
    for tid, _, data in rows.values():
        first.setdefault(tid, data)
    guess = {k + 1: topics[k] for k in range(len(topics))}
    try:
        for tid, data in first.items():
            decoder_for(guess[tid][1])(data)
    except Exception:  # noqa: BLE001 - an id out of range, an unknown type or bytes that are not that type
        return {}
    return guess


# --------------------------------------------------------------------------- SQLite page scan
# SQLite's file format (https://www.sqlite.org/fileformat2.html), read without SQLite: a file whose b-tree interior
# pages are gone (cut short, a damaged header) still holds its rows on the leaf pages that are there.
_DB3_LEAF, _DB3_INTERIOR = 0x0D, 0x05  # table b-tree page types
_SERIAL_SIZE = (0, 1, 2, 3, 4, 6, 8, 8, 0, 0)  # bytes of the fixed-size serial types 0..9


def _varint(b: bytes, o: int) -> tuple[int, int]:
    """SQLite's big-endian varint (1-9 bytes) at ``b[o]``: (value, offset after it)."""
    c = b[o]
    if c < 0x80:  # the common case: one byte
        return c, o + 1
    v = 0
    for i in range(8):
        c = b[o + i]
        v = (v << 7) | (c & 0x7F)
        if c < 0x80:
            return v, o + i + 1
    return (v << 8) | b[o + 8], o + 9


def _record(payload: bytes) -> list[Any]:
    """The values of one SQLite record (header of serial types, then the values); ValueError if it is not one."""
    hsize, o = _varint(payload, 0)
    if not 0 < hsize <= len(payload):
        raise ValueError('record header runs past the payload')
    values: list[Any] = []
    p = hsize
    while o < hsize:
        t, o = _varint(payload, o)
        if t >= 12:
            n = (t - 12) >> 1
            v: Any = payload[p : p + n] if t % 2 == 0 else payload[p : p + n].decode()
        elif t in (10, 11):
            raise ValueError('reserved serial type')
        else:
            n = _SERIAL_SIZE[t]
            if t == 7:
                v = float(np.frombuffer(payload[p : p + 8], '>f8')[0]) if p + 8 <= len(payload) else 0.0
            else:
                v = None if t == 0 else t - 8 if t >= 8 else int.from_bytes(payload[p : p + n], 'big', signed=True)
        p += n
        values.append(v)
    if o != hsize or p != len(payload):
        raise ValueError('record sizes do not add up to its payload')
    return values


def _message_head(local: bytes) -> int | None:
    """The timestamp of a ``messages`` row from the first bytes of its record (its blob may be cut off), None if the
    record is not of that shape (id, topic_id, timestamp, data)."""
    try:
        hsize, o = _varint(local, 0)
        types = []
        while o < hsize and len(types) < 5:
            t, o = _varint(local, o)
            types.append(t)
    except IndexError:
        return None
    if (
        len(types) != 4
        or types[0] > 6
        or not (1 <= types[1] <= 6 and 1 <= types[2] <= 6)
        or types[3] < 12
        or types[3] % 2
    ):
        return None
    p = hsize + _SERIAL_SIZE[types[0]] + _SERIAL_SIZE[types[1]]
    return int.from_bytes(local[p : p + _SERIAL_SIZE[types[2]]], 'big', signed=True)


@dataclass
class _Db3Scan:
    """What a page scan of a rosbag2 SQLite file found."""

    messages: dict[int, tuple[int, int, bytes]]  # message id -> (topic id, timestamp, data)
    topics: dict[int, tuple[str, str]]  # topic id -> (name, type)
    lost: list[int] = field(default_factory=list)  # timestamps of rows whose overflow pages are missing
    page_size: int = 0


def _db3_page_size(data: bytes) -> int:
    """The page size of a SQLite file whose header is destroyed: the smallest power of two at whose multiples most
    slots hold a b-tree page header (a larger size also fits them, a smaller one does not)."""
    for size in (512, 1024, 2048, 4096, 8192, 16384, 32768, 65536):
        slots = range(size, len(data) - size + 1, size)
        if not slots:
            break
        ok = sum(
            1
            for o in slots
            if data[o] in (2, 5, 10, 13)
            and data[o + 7] < 128
            and int.from_bytes(data[o + 3 : o + 5], 'big') * 2 + 8 <= size
        )
        if ok >= 0.6 * len(slots):
            return size
    return 0


def _scan_db3(data: bytes, wal: bytes | None = None) -> _Db3Scan:
    """Every row of rosbag2's ``messages`` and ``topics`` tables on the table-leaf pages physically in ``data`` (and in
    the frames of a ``-wal`` file), told from other tables' rows by their shape. Rows on pages the ``messages``
    b-tree still reaches come first, then other pages, then free-list pages (stale copies); de-duplicated by id."""
    header_ok = data[:16] == SQLITE_MAGIC and len(data) >= 100
    if header_ok:
        size = int.from_bytes(data[16:18], 'big')
        size = 65536 if size == 1 else size
        usable = size - data[20]
    else:
        size = usable = _db3_page_size(data)
    scan = _Db3Scan({}, {}, page_size=size)
    if size < 512:
        return scan
    npages = len(data) // size
    pages: dict[int, bytes] = {}  # page number (from 1) -> newest image in the write-ahead log
    if wal and len(wal) >= 32 and header_ok and int.from_bytes(wal[8:12], 'big') == size:
        for o in range(32, len(wal) - 24 - size + 1, 24 + size):
            if wal[o + 8 : o + 16] == wal[16:24]:  # the frame's salt is this log's: not a leftover of an older one
                pages[int.from_bytes(wal[o : o + 4], 'big')] = wal[o + 24 : o + 24 + size]
        npages = max([npages, *pages])

    def page(n: int) -> bytes | None:
        if n in pages:
            return pages[n]
        return data[(n - 1) * size : n * size] if 1 <= n and n * size <= len(data) else None

    max_local = usable - 35  # payloads up to this size are whole on their leaf page
    min_local = (usable - 12) * 32 // 255 - 23

    def cells(pg: bytes, hdr: int) -> Iterator[tuple[int, bytes | None, bytes]]:
        """(rowid, payload or None if its overflow pages are missing, local part) of a table leaf page's cells."""
        n = int.from_bytes(pg[hdr + 3 : hdr + 5], 'big')
        for i in range(n):
            off = int.from_bytes(pg[hdr + 8 + 2 * i : hdr + 10 + 2 * i], 'big')
            if not hdr + 8 + 2 * n <= off < usable:
                continue
            try:
                plen, o = _varint(pg, off)
                rowid, o = _varint(pg, o)
            except IndexError:
                continue
            if plen <= max_local:
                if o + plen <= usable:
                    yield rowid, pg[o : o + plen], pg[o : o + plen]
                continue
            local = min_local + (plen - min_local) % (usable - 4)
            local = local if local <= max_local else min_local
            if o + local + 4 > usable:
                continue
            parts, got = [pg[o : o + local]], local
            nxt = int.from_bytes(pg[o + local : o + local + 4], 'big')
            for _ in range(plen // (usable - 4) + 1):  # an overflow chain is never longer: no loop on garbage
                ov = page(nxt) if nxt else None
                if ov is None or got >= plen:
                    break
                parts.append(ov[4 : 4 + min(usable - 4, plen - got)])
                got += len(parts[-1])
                nxt = int.from_bytes(ov[:4], 'big')
            yield rowid, (b''.join(parts) if got == plen else None), parts[0]

    # the messages table's root page (sqlite_schema on page 1) and the leaves its b-tree still reaches
    reachable: list[int] = []
    free: set[int] = set()
    if header_ok:
        try:
            root = next(
                (
                    int(r[3])
                    for _, p, _ in cells(data[:size], 100)
                    if p is not None
                    for r in [_record(p)]
                    if len(r) == 5 and r[0] == 'table' and r[1] == 'messages'
                ),
                0,
            )
        except (ValueError, UnicodeDecodeError, IndexError):
            root = 0
        stack, seen = [root] if root else [], set()
        while stack:
            n = stack.pop()
            pg = page(n)
            if n in seen or pg is None:
                continue
            seen.add(n)
            if pg[0] == _DB3_LEAF:
                reachable.append(n)
            elif pg[0] == _DB3_INTERIOR:
                k = int.from_bytes(pg[3:5], 'big')
                kids = [
                    int.from_bytes(pg[o : o + 4], 'big')
                    for o in (int.from_bytes(pg[12 + 2 * i : 14 + 2 * i], 'big') for i in range(k))
                    if o + 4 <= size
                ]
                stack.extend(reversed([*kids, int.from_bytes(pg[8:12], 'big')]))
        trunk = int.from_bytes(data[32:36], 'big')
        while trunk and trunk not in free and (pg := page(trunk)) is not None:  # free-list trunk pages
            free.add(trunk)
            count = min(int.from_bytes(pg[4:8], 'big'), (usable - 8) // 4)
            free.update(int.from_bytes(pg[8 + 4 * i : 12 + 4 * i], 'big') for i in range(count))
            trunk = int.from_bytes(pg[:4], 'big')
    first = set(reachable)
    order = reachable + [n for n in range(1, npages + 1) if n not in first and n not in free] + sorted(free)
    msgs = scan.messages
    lost: dict[int, int] = {}
    for n in order:
        pg = page(n)
        hdr = 100 if n == 1 else 0
        if pg is None or len(pg) < size or pg[hdr] != _DB3_LEAF:
            continue
        for rowid, payload, local in cells(pg, hdr):
            if payload is None:  # a message cut off from its overflow pages: lost, but counted with its time
                t = _message_head(local)
                if t is not None:
                    lost.setdefault(rowid, t)
                continue
            try:
                r = _record(payload)
            except (ValueError, UnicodeDecodeError, IndexError):
                continue
            if (
                len(r) == 4
                and isinstance(r[1], int)
                and isinstance(r[2], int)
                and isinstance(r[3], bytes)
                and (r[0] is None or r[0] == rowid)
            ):
                msgs.setdefault(rowid, (r[1], r[2], r[3]))
            elif (
                len(r) in (5, 6)
                and all(isinstance(v, str) for v in r[1:])
                and r[1].startswith('/')
                and (r[0] is None or r[0] == rowid)
            ):  # topics(id, name, type, serialization_format, qos[, hash])
                scan.topics.setdefault(rowid, (r[1], r[2]))
    scan.lost = sorted(t for i, t in lost.items() if i not in msgs)
    return scan


def _to_bagdata(rows: Iterable[tuple[str, str, int, bytes]]) -> tuple[BagData, str]:
    """(decoded messages, problem): a message that does not decode (damaged bytes, an unknown type) is left out and
    counted in the problem ('' when every one decodes), never dropped without a word."""
    from sma_wrist.runtime.fastcdr import decoder_for

    times: dict[str, list[int]] = {}
    msgs: dict[str, list[Any]] = {}
    decoders: dict[str, Any] = {}
    bad: dict[str, int] = {}
    for topic, msgtype, t, data in rows:
        try:
            decode = decoders.get(msgtype)
            if decode is None:
                decode = decoders[msgtype] = decoder_for(msgtype)
            m = decode(data)
        except Exception:  # noqa: BLE001 - a damaged message (or unknown type) is counted, not a crash
            bad[topic or '(unnamed)'] = bad.get(topic or '(unnamed)', 0) + 1
            continue
        times.setdefault(topic, []).append(t)
        msgs.setdefault(topic, []).append(m)
    problem = ''
    if bad:
        problem = (
            f'{sum(bad.values())} messages could not be decoded and were left out ('
            + ', '.join(f'{k}: {v}' for k, v in sorted(bad.items()))
            + ')'
        )
    return {k: (np.asarray(times[k], dtype=np.int64), msgs[k]) for k in times}, problem


def _salvage(p: Path) -> tuple[BagData, str]:
    """Every message that can be read from a bag's storage files, and what is wrong with them; the count read is
    set against metadata.yaml's where there is one."""
    rows: list[tuple[str, str, int, bytes]] = []
    problems = []
    files = _storage_files(p)
    if not files:
        return {}, 'no .mcap or .db3 file in the bag directory'
    meta = _meta_counts(p) if p.is_dir() else _MetaCounts()
    for f in files:
        r, problem = _salvage_file(f, None, meta)
        rows.extend(r)
        if problem:
            problems.append(f'{f.name}: {problem}')
    rows.sort(key=lambda r: r[2])
    data, undecoded = _to_bagdata(rows)
    if undecoded:
        problems.append(undecoded)
    got = sum(len(v[1]) for v in data.values())
    if problems and meta.total is not None and got < meta.total:
        problems.append(f'{got} of the {meta.total} messages metadata.yaml lists are read: {meta.total - got} lost')
    return data, '; '.join(problems)


def _read_closed(p: Path, wanted: frozenset[str] | None) -> tuple[BagData | None, str]:
    """read_bag's fast path: a closed bag of MCAP files (BagRecorder's, in one pass each: :func:`salvage_mcap`) or
    of SQLite files (``ros2 bag record`` on Humble: :func:`salvage_db3`), its message counts checked against
    metadata.yaml. (data, '') when all is well; (None, problem) when a file is damaged (truncated, a chunk or page
    that does not read, a message that does not decode): only a salvage can say more, rosbags' reader would read
    the damaged bytes as messages; (None, '') for anything else (another storage, counts that differ): read_bag
    then uses rosbags' reader and its error reporting."""
    try:
        meta = _metadata(p)
        suffix = STORAGE_SUFFIX.get(meta.get('storage_identifier'))
        files = _storage_files(p, [suffix]) if suffix else []
        if not files:
            return None, ''
        expected = sum(
            int(t['message_count'])
            for t in meta['topics_with_message_count']
            if wanted is None or t['topic_metadata']['name'] in wanted
        )
    except (OSError, yaml.YAMLError, _NotMetadata, KeyError, TypeError, ValueError):
        return None, ''
    rows: list[tuple[str, str, int, bytes]] = []
    counts = _meta_counts(p, meta)
    for f in files:
        r, problem = _salvage_file(f, wanted, counts)
        if problem:
            return None, f'{f.name}: {problem}'
        rows.extend(r)
    if len(rows) != expected:
        return None, ''
    rows.sort(key=lambda r: r[2])  # stable, and linear on a recording already in time order
    data, undecoded = _to_bagdata(rows)
    return (None, undecoded) if undecoded else (data, '')


def read_bag(path: str | Path, topics: Iterable[str] | None = None, *, salvage: bool = False) -> BagData:
    """All messages of a bag: ``{topic: (t_ns int64 array, [messages])}`` in time order.

    Raises BagError if the bag is missing, truncated or corrupt (``.salvaged`` holds what
    could be read); with ``salvage=True`` returns the salvaged messages instead.
    """
    from rosbags.rosbag2 import Reader

    p = _bag_dir(path)
    wanted = None if topics is None else set(topics)

    def select(data: BagData) -> BagData:
        return data if wanted is None else {k: v for k, v in data.items() if k in wanted}

    problem = damage = ''
    if p.is_dir() and (p / 'metadata.yaml').exists():
        fast, damage = _read_closed(p, None if wanted is None else frozenset(wanted))
        if fast is not None:
            return fast
        try:
            if damage:  # rosbags would read a damaged chunk's bytes as messages: the salvage below says what is lost
                raise _Damaged
            _metadata(p)  # rosbags' own error for an empty file is a bare TypeError
            with Reader(p) as reader:
                conns = [c for c in reader.connections if wanted is None or c.topic in wanted]
                rows = [(c.topic, c.msgtype, t, bytes(raw)) for c, t, raw in reader.messages(connections=conns)]
                expected = sum(c.msgcount for c in conns)
            if len(rows) != expected:
                problem = f'metadata.yaml lists {expected} messages but the storage holds {len(rows)}'
            else:
                data, undecoded = _to_bagdata(rows)
                if not undecoded:
                    return select(data)
                damage = undecoded  # the salvage below reads the same messages and names those that do not decode
        except _Damaged:
            pass
        except _NotMetadata as exc:
            problem = str(exc)
        except Exception as exc:  # noqa: BLE001 - rosbags raises several error types
            problem = f'{type(exc).__name__}: {exc}'
    elif p.is_dir():
        problem = 'metadata.yaml is missing (the recording was not closed; `ros2 bag reindex` rebuilds it)'
    data, salvage_problem = _salvage(p)
    salvage_problem = salvage_problem or damage
    if not problem:
        if not salvage_problem:
            return select(data)  # a bare, complete .mcap or .db3 file
        problem = salvage_problem
    elif salvage_problem:
        problem = f'{problem}; {salvage_problem}'
    if salvage:
        return select(data)
    raise BagError(p, problem, select(data))


class _Damaged(Exception):
    """read_bag's fast path found a file damaged: skip rosbags' reader."""


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
            info = BagInfo(
                path=str(p),
                version=int(meta['version']),
                storage=str(meta['storage_identifier']),
                message_count=reader.message_count,
                start_ns=reader.start_time if reader.message_count else 0,
                end_ns=reader.end_time - 1 if reader.message_count else 0,
            )
            for c in reader.connections:
                prev = info.topics.get(c.topic)
                info.topics[c.topic] = TopicSummary(c.msgtype, c.msgcount + (prev.count if prev else 0))
            # touch the storage index so a truncated .mcap is reported here too
            for _ in reader.messages(connections=reader.connections[:1]):
                break
    except BagError:
        raise
    except Exception as exc:  # noqa: BLE001
        data, problem = _salvage(p)
        why = str(exc) if isinstance(exc, _NotMetadata) else f'{type(exc).__name__}: {exc}'
        raise BagError(p, why + (f'; {problem}' if problem else ''), data) from None
    # the summary above is metadata.yaml's and the index's: read every message to find damage they do not show
    info.damage = _salvage(p)[1]
    return info
