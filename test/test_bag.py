"""Bags from the embedded runtime: round trip (rosbags + mcap readers), Humble metadata,
byte-identical determinism, interrupted runs, truncated files."""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
import pytest
import yaml

from sma_wrist import runtime

runtime.activate()

import rclpy  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.time import Time  # noqa: E402
from rosgraph_msgs.msg import Clock as ClockMsg  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Float64  # noqa: E402

from sma_wrist.bag import BagError, bag_info, iter_mcap, read_bag  # noqa: E402
from sma_wrist.runtime.launch import run_nodes  # noqa: E402
from sma_wrist.runtime.messages import TYPESTORE, from_rosbags  # noqa: E402


@pytest.fixture(autouse=True)
def _shutdown():
    yield
    rclpy.try_shutdown()


class Plant(Node):
    def __init__(self):
        super().__init__('plant')
        self.t = 0
        self.clock_pub = self.create_publisher(ClockMsg, '/clock', 10)
        self.js_pub = self.create_publisher(JointState, '/wrist/joint_states', 10)
        self.create_timer(0.01, self.step)

    def step(self):
        self.t += 10_000_000
        self.clock_pub.publish(ClockMsg(clock=Time(nanoseconds=self.t).to_msg()))
        js = JointState(name=['wrist'], position=[self.t * 1e-9], velocity=[1.0], effort=[0.0])
        js.header.stamp = self.get_clock().now().to_msg()
        js.header.frame_id = 'wrist_base'
        self.js_pub.publish(js)


class Controller(Node):
    """use_sim_time node: commands from joint states, diagnostics at 1 Hz."""

    fail_at = None

    def __init__(self):
        super().__init__('controller')
        self.cmd = self.create_publisher(Float64, '/wrist/tem_1/command', 10)
        self.diag = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.create_subscription(JointState, '/wrist/joint_states', self.on_js, 10)
        self.create_timer(1.0, self.report)

    def on_js(self, msg):
        if self.fail_at is not None and msg.position[0] >= self.fail_at:
            raise RuntimeError('controller blew up')
        self.cmd.publish(Float64(data=-2.0 * msg.position[0]))

    def report(self):
        st = DiagnosticStatus(
            level=DiagnosticStatus.WARN,
            name='controller',
            message='ok',
            values=[KeyValue(key='t', value=str(self.get_clock().now().nanoseconds))],
        )
        self.diag.publish(DiagnosticArray(status=[st]))


PARAMS = {'/controller': {'use_sim_time': True}}


def _run(path, duration=2.0):
    return run_nodes([Plant, Controller], duration, params=PARAMS, bag=path)


def test_round_trip_with_rosbags_and_mcap_readers(tmp_path):
    bag = tmp_path / 'run'
    res = _run(bag)
    assert res.sim_ns == 2_000_000_000 and res.recorded > 0
    data = read_bag(bag)
    t, js = data['/wrist/joint_states']
    assert len(js) == 200 and js[0].name == ['wrist'] and js[-1].position == [pytest.approx(2.0)]
    assert list(t[:2]) == [10_000_000, 20_000_000]
    tc, cmds = data['/wrist/tem_1/command']
    assert len(cmds) == 200 and cmds[-1].data == pytest.approx(-4.0)
    assert list(tc) == list(t)  # controller stamps with sim time == plant time here
    td, diags = data['/diagnostics']
    assert list(td) == [1_000_000_000, 2_000_000_000]
    assert diags[0].status[0].level == DiagnosticStatus.WARN

    # independent reader: the mcap library, CDR decoded by rosbags' typestore
    mcap_file = next(bag.glob('*.mcap'))
    rows = list(iter_mcap(mcap_file))
    by_topic = {}
    for topic, msgtype, t_ns, raw in rows:
        by_topic.setdefault(topic, []).append((t_ns, from_rosbags(TYPESTORE.deserialize_cdr(raw, msgtype))))
    assert [m for _, m in sorted(by_topic['/wrist/joint_states'], key=lambda r: r[0])] == js
    assert len(by_topic['/clock']) == 200

    info = bag_info(bag)
    assert info.topics['/wrist/joint_states'].type == 'sensor_msgs/msg/JointState'
    assert info.topics['/clock'].count == 200
    assert info.start_ns == 0  # parameter events during construction, at t = 0
    assert info.message_count == sum(len(v[1]) for v in data.values())


def test_metadata_is_humble_readable(tmp_path):
    bag = tmp_path / 'run'
    _run(bag, 0.1)
    meta = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert meta['version'] == 5
    assert meta['storage_identifier'] == 'mcap'
    for topic in meta['topics_with_message_count']:
        tm = topic['topic_metadata']
        assert 'type_description_hash' not in tm
        qos = tm['offered_qos_profiles']
        assert isinstance(qos, str)  # Humble reads it with as<std::string>()
        if qos:
            prof = yaml.safe_load(qos)[0]
            assert isinstance(prof['history'], int) and isinstance(prof['reliability'], int)
    assert meta['files'][0]['path'].endswith('.mcap')


def test_identical_runs_give_identical_mcap_bytes(tmp_path):
    # same bag name in two places: the name is part of the embedded metadata record
    _run(tmp_path / 'a' / 'run', 1.0)
    _run(tmp_path / 'b' / 'run', 1.0)
    a = (tmp_path / 'a' / 'run' / 'run.mcap').read_bytes()
    b = (tmp_path / 'b' / 'run' / 'run.mcap').read_bytes()
    assert len(a) > 10_000 and a == b
    ma = (tmp_path / 'a' / 'run' / 'metadata.yaml').read_text()
    mb = (tmp_path / 'b' / 'run' / 'metadata.yaml').read_text()
    assert ma == mb


def test_direct_message_records_are_the_rosbags_writers_bytes(tmp_path, monkeypatch):
    """The recorder packs MCAP message records itself; the bag must be the one rosbags' Writer.write
    writes (same records, chunk boundaries, indexes and statistics), several chunks long."""
    from sma_wrist import bag as bagmod

    monkeypatch.setattr(bagmod, '_MCAP_CHUNK_BYTES', 4096)  # many chunks in a short run
    direct = []
    write_direct = bagmod.BagRecorder._write_direct

    def spy(self, *args):
        direct.append(1)
        return write_direct(self, *args)

    monkeypatch.setattr(bagmod.BagRecorder, '_write_direct', spy)
    _run(tmp_path / 'a' / 'run', 1.0)
    n_direct = len(direct)
    monkeypatch.setattr(bagmod.BagRecorder, 'direct', False)
    monkeypatch.setattr('rosbags.rosbag2.storage_mcap.McapWriter.write', _chunked_write(4096))
    _run(tmp_path / 'b' / 'run', 1.0)
    assert n_direct > 200 and len(direct) == n_direct  # the first bag written directly, the second by rosbags
    a = (tmp_path / 'a' / 'run' / 'run.mcap').read_bytes()
    b = (tmp_path / 'b' / 'run' / 'run.mcap').read_bytes()
    assert len(bagmod._mcap_summary(a).chunk_indexes) > 5
    assert a == b
    meta_a = (tmp_path / 'a' / 'run' / 'metadata.yaml').read_text()
    assert meta_a == (tmp_path / 'b' / 'run' / 'metadata.yaml').read_text()


def _chunked_write(limit):
    """rosbags' McapWriter.write with its 1 MiB chunk limit lowered to ``limit`` bytes."""
    from rosbags.rosbag2.storage_mcap import McapWriter

    original = McapWriter.write

    def write(self, connection, timestamp, data):
        bio = self.chunk.bio
        original_close = self.close_chunk
        before = len(self.chunks)
        original(self, connection, timestamp, data)
        if len(self.chunks) == before and bio.tell() > limit:
            original_close()

    return write


def test_exception_during_run_leaves_readable_bag(tmp_path, monkeypatch):
    monkeypatch.setattr(Controller, 'fail_at', 0.5)
    bag = tmp_path / 'crash'
    with pytest.raises(RuntimeError, match='blew up'):
        _run(bag)
    data = read_bag(bag)
    t, js = data['/wrist/joint_states']
    assert js[-1].position[0] == pytest.approx(0.5)  # everything up to the failure
    assert len(data['/wrist/tem_1/command'][1]) == 49


def test_keyboard_interrupt_leaves_readable_bag(tmp_path):
    bag = tmp_path / 'ctrlc'
    count = {'n': 0}

    def interrupt():
        count['n'] += 1
        if count['n'] > 300:
            raise KeyboardInterrupt
        return False

    with pytest.raises(KeyboardInterrupt):
        run_nodes([Plant, Controller], 5.0, params=PARAMS, bag=bag, stop_when=interrupt)
    info = bag_info(bag)
    assert info.topics['/clock'].count >= 40  # everything up to the interrupt


def test_truncated_bag_raises_bag_error_with_salvage(tmp_path):
    bag = tmp_path / 'run'
    run_nodes([Plant, Controller], 3.0, params=PARAMS, bag=bag)
    full = read_bag(bag)
    mcap_file = next(bag.glob('*.mcap'))
    raw = mcap_file.read_bytes()
    mcap_file.write_bytes(raw[: len(raw) * 2 // 3])
    with pytest.raises(BagError) as err:
        read_bag(bag)
    assert str(mcap_file.name) in str(err.value) or str(bag) in str(err.value)
    assert 'truncated' in str(err.value) or 'corrupt' in str(err.value)
    salvaged = err.value.salvaged['/wrist/joint_states'][1]
    assert 0 < len(salvaged) < len(full['/wrist/joint_states'][1])
    assert salvaged == full['/wrist/joint_states'][1][: len(salvaged)]
    assert read_bag(bag, salvage=True)['/wrist/joint_states'][1] == salvaged
    with pytest.raises(BagError):
        bag_info(bag)


def test_unclosed_recording_is_salvageable(tmp_path):
    """A hard kill leaves no metadata.yaml; flushed chunks are still readable."""
    from sma_wrist.runtime.launch import Runtime

    bag = tmp_path / 'killed'
    with Runtime(params=PARAMS) as rt:
        rec = rt.record(bag, flush_every=100)
        rt.add_nodes([Plant, Controller])
        rt.run_until(1.0)
        rec.flush()
        rt.recorders.remove(rec)  # simulate a kill: never closed
        rec._remove_tap()
    assert not (bag / 'metadata.yaml').exists()
    with pytest.raises(BagError, match='metadata.yaml is missing') as err:
        read_bag(bag)
    assert len(err.value.salvaged['/wrist/joint_states'][1]) == 100
    rec._writer.storage.bio.close()  # what the OS does with a killed process's file


@pytest.mark.parametrize('meta', ['', '- a list\n', 'other: 1\n'])
def test_a_metadata_file_that_is_not_rosbag2_is_named_and_the_messages_salvaged(tmp_path, meta):
    """An empty (or foreign) metadata.yaml beside a good .mcap: read_bag and bag_info say what is wrong with it
    (it was "TypeError: 'NoneType' object is not subscriptable") and keep every message."""
    bag = tmp_path / 'run'
    run_nodes([Plant, Controller], 1.0, params=PARAMS, bag=bag)
    full = read_bag(bag)
    (bag / 'metadata.yaml').write_text(meta)
    for read in (read_bag, bag_info):
        with pytest.raises(BagError, match='metadata.yaml is empty or not rosbag2 metadata') as err:
            read(bag)
        assert 'TypeError' not in str(err.value)
    assert err.value.salvaged['/wrist/joint_states'][1] == full['/wrist/joint_states'][1]


def test_info_summarises_a_bare_complete_mcap_as_compare_reads_it(tmp_path):
    """bag_info refused a bare .mcap ("metadata.yaml is missing (N messages salvaged)") that read_bag and compare
    read whole; it now gives the same topics and counts as the bag's metadata, version 0 (no metadata)."""
    bag = tmp_path / 'run'
    run_nodes([Plant, Controller], 1.0, params=PARAMS, bag=bag)
    full = bag_info(bag)
    bare = bag_info(next(bag.glob('*.mcap')))
    assert (bare.version, full.version) == (0, 5) and bare.message_count == full.message_count
    assert {k: (v.type, v.count) for k, v in bare.topics.items()} == {
        k: (v.type, v.count) for k, v in full.topics.items()
    }
    assert (bare.start_ns, bare.end_ns) == (full.start_ns, full.end_ns)


def test_a_reader_that_goes_away_ends_the_cli_quietly(tmp_path):
    """`sma-wrist info BAG | head`: a closed pipe was a BrokenPipeError traceback; now exit 141, nothing on stderr."""
    import subprocess
    import sys

    bag = tmp_path / 'run'
    run_nodes([Plant, Controller], 1.0, params=PARAMS, bag=bag)
    proc = subprocess.Popen(
        [sys.executable, '-m', 'sma_wrist.cli', 'info', str(bag)], stdout=subprocess.PIPE, stderr=subprocess.PIPE
    )
    proc.stdout.close()  # before the command has written anything: its first print meets a closed pipe
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=60) == 141 and err == ''


def test_missing_bag_and_garbage_are_typed_errors(tmp_path):
    with pytest.raises(BagError, match='does not exist'):
        read_bag(tmp_path / 'nope')
    d = tmp_path / 'garbage'
    d.mkdir()
    (d / 'metadata.yaml').write_text('rosbag2_bagfile_information: {version: 5}\n')
    (d / 'garbage.mcap').write_bytes(b'not an mcap file')
    with pytest.raises(BagError) as err:
        read_bag(d)
    assert str(d) in str(err.value)


def test_record_topic_subset(tmp_path):
    bag = tmp_path / 'subset'
    run_nodes([Plant, Controller], 0.5, params=PARAMS, bag=bag, topics=['/clock', 'wrist/joint_states'])
    assert set(read_bag(bag)) == {'/clock', '/wrist/joint_states'}


class Reuser(Node):
    """Publishes one Float64 object again and again, changing it in between (rclpy allows it)."""

    def __init__(self):
        super().__init__('reuser')
        self.pub = self.create_publisher(Float64, '/wrist/tem_1/command', 10)
        self.msg = Float64(data=0.0)
        self.create_timer(0.01, self.step)

    def step(self):
        self.msg.data += 1.0
        self.pub.publish(self.msg)


def test_taps_share_one_encoding_per_publication_and_a_changed_message_is_encoded_again(tmp_path):
    """The bag recorder and the live view both take a publication's CDR bytes: encoded once for both, and never
    taken from an earlier publication of the same (since changed) object."""
    from sma_wrist.runtime.launch import Runtime

    calls = []

    def counting(msg):
        calls.append(msg.data)
        return serialize(msg)

    seen = []
    bag = tmp_path / 'reused'
    with Runtime() as rt:
        rec = rt.record(bag)
        rt.add_nodes([Reuser])
        rt.context.graph.add_tap(lambda topic, msg, t: seen.append(topic.cdr(msg, counting)), ['/wrist/tem_1/command'])
        rt.run_until(0.1)
        rec.close()
    values = [deserialize(b, 'std_msgs/msg/Float64').data for b in seen]
    assert values == [float(i) for i in range(1, len(values) + 1)] and len(values) >= 9
    assert calls == []  # the recorder (first tap) encoded each publication; the second tap reused its bytes
    assert [m.data for m in read_bag(bag)['/wrist/tem_1/command'][1]][: len(values)] == values


# ------------------------------------------------------------------ direct CDR of the high-rate types
from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402
from sensor_msgs.msg import Temperature  # noqa: E402
from std_msgs.msg import Header  # noqa: E402

from sma_wrist.runtime.fastcdr import decoder_for, encoder_for  # noqa: E402
from sma_wrist.runtime.messages import deserialize, serialize  # noqa: E402

_floats = st.floats(allow_nan=False, width=64)
_texts = st.text(max_size=9)
_stamps = st.tuples(st.integers(-(2**31), 2**31 - 1), st.integers(0, 2**32 - 1))


def _header(stamp, frame_id):
    h = Header(frame_id=frame_id)
    h.stamp.sec, h.stamp.nanosec = stamp
    return h


_messages = st.one_of(
    st.builds(lambda x: Float64(data=x), _floats),
    st.builds(lambda s: ClockMsg(clock=_header(s, '').stamp), _stamps),
    st.builds(
        lambda s, f, t, v: Temperature(header=_header(s, f), temperature=t, variance=v),
        _stamps,
        _texts,
        _floats,
        _floats,
    ),
    st.builds(
        lambda s, f, n, p, v, e: JointState(header=_header(s, f), name=n, position=p, velocity=v, effort=e),
        _stamps,
        _texts,
        st.lists(_texts, max_size=3),
        st.lists(_floats, max_size=3),
        st.lists(_floats, max_size=3),
        st.lists(_floats, max_size=3),
    ),
)


@settings(max_examples=300, deadline=None)
@given(_messages)
def test_direct_cdr_is_byte_identical_to_rosbags(msg):
    """The recorder's struct packers write the typestore's bytes (alignment after odd-length
    frame ids and names, no padding before an empty sequence) and read them back."""
    data = encoder_for(msg._TYPE)(msg)
    assert data == serialize(msg)
    assert decoder_for(msg._TYPE)(data) == deserialize(data, msg._TYPE) == msg


def test_direct_cdr_decoder_rejects_cut_messages():
    data = encoder_for('sensor_msgs/msg/JointState')(
        JointState(name=['wrist'], position=[0.5], velocity=[0.1], effort=[])
    )
    decode = decoder_for('sensor_msgs/msg/JointState')
    for cut in (8, 20, len(data) - 4):
        with pytest.raises(struct.error):
            decode(data[:cut])


def test_one_pass_reader_equals_rosbags_reader_and_falls_back_to_it(tmp_path, monkeypatch):
    """read_bag reads a closed, uncompressed MCAP bag in one pass (salvage_mcap); it must give
    what rosbags' indexed reader gives, all topics and a subset, and hand anything it does not
    handle (here: a read whose counts are not metadata.yaml's) to rosbags. A file it finds damaged
    is not handed on: rosbags would read a damaged chunk's bytes as messages
    (test_a_corrupt_mcap_chunk_*)."""
    import sma_wrist.bag as bag_mod

    bag = tmp_path / 'run'
    _run(bag)
    fast_all, fast_sub = read_bag(bag), read_bag(bag, ['/wrist/joint_states', '/clock'])
    calls = []

    def declined(*args, **kwargs):
        calls.append(args)
        return [], ''

    monkeypatch.setattr(bag_mod, 'salvage_mcap', declined)
    slow_all, slow_sub = read_bag(bag), read_bag(bag, ['/wrist/joint_states', '/clock'])
    assert calls  # the fast path was tried and declined
    for fast, slow in ((fast_all, slow_all), (fast_sub, slow_sub)):
        assert fast.keys() == slow.keys()
        for topic in fast:
            assert list(fast[topic][0]) == list(slow[topic][0]) and fast[topic][1] == slow[topic][1], topic
    assert set(fast_sub) == {'/wrist/joint_states', '/clock'}


def test_one_pass_reader_checks_counts_against_metadata(tmp_path):
    """A metadata.yaml that promises more messages than the file holds is not trusted by the fast
    path: the rosbags path reports the mismatch as a BagError with what could be salvaged."""
    bag = tmp_path / 'run'
    _run(bag)
    meta = bag / 'metadata.yaml'
    doc = yaml.safe_load(meta.read_text())
    doc['rosbag2_bagfile_information']['topics_with_message_count'][0]['message_count'] += 5
    meta.write_text(yaml.safe_dump(doc))
    with pytest.raises(BagError, match='metadata|messages'):
        read_bag(bag)


ROSBAG2_DATA = Path(__file__).parent / 'data' / 'rosbag2'  # recorded by ROS 2's rosbag2 (README.md there)


@pytest.mark.parametrize('storage', ['talker_sqlite3', 'talker_mcap'])
def test_bags_recorded_by_rosbag2_are_read_whole(storage):
    """Two bags of ROS 2's talker example as rosbag2 wrote them: a SQLite file of today's schema whose topic ids are
    not metadata.yaml's order, and an MCAP file with zstd chunks. read_bag raised "metadata.yaml lists 20 messages
    but the storage holds 0" for both (rosbags' reader finds none); ``ros2 bag`` reads them whole, and so must we."""
    bag = ROSBAG2_DATA / storage
    data = read_bag(bag)
    assert [m.data for m in data['/topic'][1]] == [f'Hello, world! {i}' for i in range(10)]
    assert [m.msg for m in data['/rosout'][1]] == [f"Publishing: 'Hello, world! {i}'" for i in range(10)]
    assert all(np.diff(data['/topic'][0]) > 0)
    assert set(read_bag(bag, ['/topic'])) == {'/topic'}
    info = bag_info(bag)
    assert {k: v.count for k, v in info.topics.items()} == {'/topic': 10, '/rosout': 10, '/parameter_events': 0}
    assert info.storage == {'talker_sqlite3': 'sqlite3', 'talker_mcap': 'mcap'}[storage]


def test_bags_recorded_by_rosbag2_without_metadata_are_salvaged_whole(tmp_path):
    """A recording in three SQLite files and no metadata.yaml (what a killed ``ros2 bag record`` leaves on Humble,
    whose default storage is SQLite) was "no .mcap file in the bag directory (0 messages salvaged)": every message
    was declared lost. Now each file is read through its own tables; the bag is named damaged, with the way to
    rebuild its metadata, and nothing is lost."""
    import sqlite3

    bag = ROSBAG2_DATA / 'unindexed_sqlite3'
    files = sorted(bag.glob('*.db3'))
    counts = [sqlite3.connect(f).execute('SELECT count(*) FROM messages').fetchone()[0] for f in files]
    with pytest.raises(BagError, match=r'metadata.yaml is missing .*ros2 bag reindex') as err:
        read_bag(bag)
    t, msgs = err.value.salvaged['/chatter']
    assert len(msgs) == sum(counts) == 3177 and all(np.diff(t) >= 0)
    assert {m.data for m in msgs} == {'test'}
    assert len(read_bag(bag, salvage=True)['/chatter'][1]) == 3177
    # one file of it on its own is a bare, complete file: read and summarised without complaint
    assert len(read_bag(files[0])['/chatter'][1]) == counts[0]
    info = bag_info(files[0])
    assert (info.version, info.storage, info.topics['/chatter'].count) == (0, 'sqlite3', counts[0])


def test_a_sqlite_file_cut_short_keeps_the_messages_before_the_cut(tmp_path):
    """SQLite refuses a file shorter than its header says ("database disk image is malformed") before it reads one
    row; a bag copied off a full disk kept nothing. Salvage reads it from a copy whose header gives its real length,
    and keeps every message before the first missing page, in order. The compressed MCAP bag cut short gives what
    its complete chunks hold and says it is damaged."""
    src = ROSBAG2_DATA / 'unindexed_sqlite3' / 'multiple_files_0.db3'
    full = read_bag(src)['/chatter'][1]
    cut = tmp_path / 'cut'
    cut.mkdir()
    raw = src.read_bytes()
    (cut / src.name).write_bytes(raw[: len(raw) * 6 // 10])
    with pytest.raises(BagError, match='cut short') as err:
        read_bag(cut)
    kept = err.value.salvaged['/chatter'][1]
    assert 0 < len(kept) < len(full) and kept == full[: len(kept)]
    with pytest.raises(BagError, match='cut short'):
        bag_info(cut)
    (cut / src.name).write_bytes(raw[:5000])  # not even the tables' pages
    with pytest.raises(BagError, match='truncated or corrupt'):
        read_bag(cut)
    mcap_cut = tmp_path / 'mcap_cut'
    mcap_cut.mkdir()
    raw = (ROSBAG2_DATA / 'talker_mcap' / 'talker.mcap').read_bytes()
    (mcap_cut / 'talker.mcap').write_bytes(raw[: len(raw) // 3])
    with pytest.raises(BagError, match='truncated or corrupt|no footer'):
        read_bag(mcap_cut)


def test_a_run_in_the_sqlite_storage_reads_as_in_mcap(tmp_path):
    """A run bag in Humble's default storage (rewritten by rosbags' SQLite writer) gives the same messages as the
    MCAP bag it was made from, topic by topic."""
    from rosbags.rosbag2 import Reader, StoragePlugin, Writer

    bag, db3 = tmp_path / 'run', tmp_path / 'run_db3'
    _run(bag, 1.0)
    with Reader(bag) as r, Writer(db3, version=8, storage_plugin=StoragePlugin.SQLITE3) as w:
        conns = {c.id: w.add_connection(c.topic, c.msgtype, typestore=TYPESTORE) for c in r.connections}
        for c, t, raw in r.messages():
            w.write(conns[c.id], t, raw)
    assert next(db3.glob('*.db3')).read_bytes()[:16] == b'SQLite format 3\x00'
    a, b = read_bag(bag), read_bag(db3)
    assert a.keys() == b.keys() and '/wrist/joint_states' in a
    for topic in a:
        assert list(a[topic][0]) == list(b[topic][0]) and a[topic][1] == b[topic][1], topic


def _rewrite(src, dst, change):
    """Copy the bag src to dst, each message of a topic passed as change(topic, k, msg) (k counts that topic's
    messages from 1); a message change returns is written in place of the original (None: unchanged)."""
    from rosbags.rosbag2 import Reader, Writer

    seen: dict[str, int] = {}
    with Reader(src) as r, Writer(dst, version=8) as w:
        conns = {c.id: w.add_connection(c.topic, c.msgtype, typestore=TYPESTORE) for c in r.connections}
        for c, t, raw in r.messages():
            seen[c.topic] = k = seen.get(c.topic, 0) + 1
            m = change(c.topic, k, TYPESTORE.deserialize_cdr(raw, c.msgtype))
            w.write(conns[c.id], t, raw if m is None else TYPESTORE.serialize_cdr(m, c.msgtype))


def test_a_joint_state_with_several_joints_is_read_by_the_wrists_name(tmp_path):
    """compare and load_run took position[0] of every JointState: on a robot's /joint_states that lists another joint
    first they measured that joint, and a message without positions was an IndexError traceback. They now read the
    contract's joint ('wrist') by name, as diagnose did, and skip a message without its position."""
    from sma_wrist.cli import main
    from sma_wrist.runs import load_run, run_metrics

    bag, other = tmp_path / 'run', tmp_path / 'robot'
    assert main(['run', '--duration', '3', '--bag', str(bag), '--quiet']) == 0

    def elbow_first(topic, k, m):
        if topic != '/wrist/joint_states':
            return None
        if k % 50 == 7:  # a driver's message without positions
            m.name, m.position = ['elbow', 'wrist'], np.array([], dtype=float)
        else:  # another joint listed first
            m.name, m.position = ['elbow', 'wrist'], np.array([9.9, m.position[0]])
            m.velocity, m.effort = np.array([0.0, m.velocity[0]]), np.array([0.0, m.effort[0]])
        return m

    _rewrite(bag, other, elbow_first)
    a, b = load_run(bag), load_run(other)
    assert 0 < b.q.size < a.q.size and np.all(b.q < 2.0)
    np.testing.assert_array_equal(b.q, a.q[np.isin(a.t, b.t)])
    # the elbow's 9.9 rad would be ~1600 % of this run's reference range
    assert run_metrics(b)['max_error_pct'] == pytest.approx(run_metrics(a)['max_error_pct'], rel=0.02)


@pytest.mark.parametrize(
    'fault, named',
    [
        ('nan', 'no joint state has a finite position'),
        ('wall', 'different clocks'),
        ('zero', 'the header stamps of /wrist/joint_states do not advance'),
    ],
)
def test_compare_names_joint_states_it_cannot_pair_with_the_reference(tmp_path, capsys, fault, named):
    """A potentiometer that sends only NaN, joint states stamped on the wall clock while the reference is on sim
    time: compare ended in an IndexError traceback. Joint states all stamped 0 (a driver that does not stamp them):
    compare printed the error of one sample (4.5 % for a run at 99 %) and exit 0. Now an error that says which."""
    from sma_wrist.cli import main

    bag, bad = tmp_path / 'run', tmp_path / 'bad'
    assert main(['run', '--duration', '2', '--bag', str(bag), '--quiet']) == 0

    def fault_in(topic, k, m):
        if topic != '/wrist/joint_states':
            return None
        if fault == 'nan':
            m.position = np.array([np.nan])
        elif fault == 'wall':
            m.header.stamp.sec += 1_700_000_000
        else:
            m.header.stamp.sec, m.header.stamp.nanosec = 0, 0
        return m

    _rewrite(bag, bad, fault_in)
    capsys.readouterr()
    assert main(['compare', str(bad)]) == 2
    err = capsys.readouterr().err
    assert named in err and 'Traceback' not in err, err


def test_compare_says_a_bag_is_truncated_and_refuses_a_folder_as_plot(tmp_path, capsys):
    """compare read a truncated bag up to its cut and printed its metrics as if it were the whole run;
    --plot DIR wrote DIR.png beside the folder. Now a warning naming the damage, and an error."""
    from sma_wrist.cli import main

    bag = tmp_path / 'run'
    assert main(['run', '--duration', '2', '--bag', str(bag), '--quiet']) == 0
    mcap_file = next(bag.glob('*.mcap'))
    raw = mcap_file.read_bytes()
    mcap_file.write_bytes(raw[: len(raw) // 2])
    capsys.readouterr()
    assert main(['compare', str(bag)]) == 0
    err = capsys.readouterr().err
    assert err.startswith(f'warning: {bag}: ') and 'truncated' in err and 'its metrics cover only the' in err, err
    assert main(['compare', str(bag), '--json']) == 0
    assert 'truncated' in json.loads(capsys.readouterr().out)[0]['damaged']
    assert main(['compare', str(bag), '--plot', str(tmp_path)]) == 2
    assert capsys.readouterr().err.startswith(f'error: --plot {tmp_path} is a folder')
    assert not tmp_path.with_suffix('.png').exists()


def test_diagnose_and_compare_check_where_they_write_before_reading(tmp_path, capsys):
    """diagnose --params BAG/metadata.yaml replaced the bag's metadata (the bag was then unreadable); --params DIR
    and --report FILE were 'internal error' tracebacks after the diagnosis; compare --plot x.txt a matplotlib
    traceback after every bag was read. Each is now refused first, naming the option."""
    from sma_wrist.cli import main

    bag = tmp_path / 'run'
    assert main(['run', '--duration', '2', '--bag', str(bag), '--quiet']) == 0
    meta = (bag / 'metadata.yaml').read_bytes()
    note = tmp_path / 'note.txt'
    note.write_text('mine')
    capsys.readouterr()
    for args, needed in (
        (['diagnose', str(bag), '--params', str(bag / 'metadata.yaml')], 'is inside the input'),
        (['diagnose', str(bag), '--params', str(tmp_path)], 'is a folder'),
        (['diagnose', str(bag), '--report', str(note)], 'is a file'),
        (['compare', str(bag), '--plot', str(tmp_path / 'cmp.txt')], 'not an image format'),
    ):
        assert main(args) == 2, args
        err = capsys.readouterr().err
        assert needed in err and 'internal error' not in err and 'Traceback' not in err, err
    assert (bag / 'metadata.yaml').read_bytes() == meta and note.read_text() == 'mine'
    assert not (tmp_path / 'cmp.txt').exists()


def test_a_nan_command_is_no_peak_and_compare_json_stays_json(tmp_path, capsys):
    """One NaN TEM command in a bag made compare's peak command NaN, and --json wrote a bare NaN, which no strict
    JSON reader takes. The peak is now over the finite commands."""
    from sma_wrist.cli import main

    bag, bad = tmp_path / 'run', tmp_path / 'bad'
    assert main(['run', '--duration', '2', '--bag', str(bag), '--quiet']) == 0

    def one_nan(topic, k, m):
        if topic == '/wrist/tem_1/command' and k == 50:
            m.data = float('nan')
            return m
        return None

    _rewrite(bag, bad, one_nan)
    capsys.readouterr()
    assert main(['compare', str(bag), str(bad), '--json']) == 0
    rows = json.loads(capsys.readouterr().out, parse_constant=lambda c: pytest.fail(f'{c} in the JSON'))
    assert rows[1]['peak_command_V'] == rows[0]['peak_command_V'] > 0


def test_one_impossible_sample_is_dropped_not_a_crash_or_a_refused_bag(tmp_path, capsys):
    """One temperature of 1e300 (a glitch) overflowed diagnose's fit: 'internal error OverflowError'; one angle
    of 1e6 rad refused the whole bag as 'not radians'. Such samples are now dropped and counted, as NaNs are,
    and the diagnosis runs on the rest."""
    from sma_wrist.cli import main

    bag, bad = tmp_path / 'run', tmp_path / 'bad'
    assert main(['run', '--duration', '40', '--bag', str(bag), '--quiet']) == 0

    def glitch(topic, k, m):
        if k != 700 or topic not in ('/wrist/joint_states', '/wrist/muscle_2/temperature'):
            return None
        if topic == '/wrist/joint_states':
            m.position = np.array([1e6])
        else:
            m.temperature = 1e300
        return m

    _rewrite(bag, bad, glitch)
    capsys.readouterr()
    assert main(['diagnose', str(bad)]) == 0
    out = capsys.readouterr()
    assert 'internal error' not in out.err + out.out
    for topic, value in (('/wrist/muscle_2/temperature', '1e+300'), ('/wrist/joint_states', '1e+06')):
        assert f'{topic}: 1 of' in out.out and f'(up to {value}) are no measurement of this wrist' in out.out
    # compare read the 1e6 rad as an angle: a 1e8 % max error without a word
    assert main(['compare', str(bag), str(bad), '--json']) == 0
    out = capsys.readouterr()
    clean, glitched = json.loads(out.out)
    assert glitched['max_error_pct'] == pytest.approx(clean['max_error_pct'], rel=0.05)
    assert 'joint states with angles beyond +-400 (up to 1e+06) are no measurement' in out.err


def test_a_thermocouple_that_stops_while_its_tem_is_driven_is_named_stale(tmp_path, capsys):
    """A muscle thermocouple frozen at its last value (a stale sensor) was fitted as a measurement: diagnose said
    'unexplained discrepancy', identify thermal moved the TEMs' hold limits. A value repeated for over 5 s while
    the TEM is driven is now left out as a gap and named; the same bag unfrozen has no such warning."""
    from sma_wrist.cli import main

    bag, bad = tmp_path / 'run', tmp_path / 'bad'
    assert main(['run', '--duration', '75', '--bag', str(bag), '--quiet']) == 0
    frozen = {}

    def freeze(topic, k, m):
        if topic != '/wrist/muscle_1/temperature' or m.header.stamp.sec < 40:
            return None
        m.temperature = frozen.setdefault('T', m.temperature)
        return m

    _rewrite(bag, bad, freeze)
    capsys.readouterr()
    assert main(['diagnose', str(bag)]) == 0
    assert 'stale sensor' not in capsys.readouterr().out
    assert main(['diagnose', str(bad)]) == 0
    out = capsys.readouterr().out
    assert f'/wrist/muscle_1/temperature: the same value {frozen["T"]:.4g} for 35.0 s while its TEM was driven' in out
    # the 40 s before it are the model's own run again: nothing to find (the frozen stretch was 'unexplained')
    assert 'a stale sensor? Those samples are left out' in out and 'no significant discrepancy' in out


def _run_db3(tmp_path, duration, page_size=None):
    """A run bag rewritten in the SQLite storage (rosbags' writer, as test_a_run_in_the_sqlite_storage_reads_as_in_mcap),
    optionally re-paged by SQLite itself: with 512-byte pages a short run has a three-level messages b-tree whose
    interior pages lie all over the file, as a long run's do with 4096-byte pages."""
    import sqlite3

    from rosbags.rosbag2 import Reader, StoragePlugin, Writer

    bag, db3 = tmp_path / 'run', tmp_path / 'run_db3'
    _run(bag, duration)
    with Reader(bag) as r, Writer(db3, version=8, storage_plugin=StoragePlugin.SQLITE3) as w:
        conns = {c.id: w.add_connection(c.topic, c.msgtype, typestore=TYPESTORE) for c in r.connections}
        for c, t, raw in r.messages():
            w.write(conns[c.id], t, raw)
    if page_size:
        con = sqlite3.connect(next(db3.glob('*.db3')))
        con.execute(f'PRAGMA page_size = {page_size}')
        con.execute('VACUUM')
        con.close()
    return db3


def _pairs(data):
    """{topic: {t_ns: [messages]}} of read_bag's result, to look messages up by topic and time."""
    out = {}
    for topic, (t, msgs) in data.items():
        for ti, m in zip(t.tolist(), msgs):
            out.setdefault(topic, {}).setdefault(ti, []).append(m)
    return out


@pytest.mark.parametrize('cut', ['30%', '50%', '80%', 'page boundary', 'mid-page'])
def test_a_sqlite_file_cut_short_keeps_every_message_on_the_pages_that_are_left(tmp_path, cut):
    """A db3 cut where the messages b-tree's interior pages are gone gave 0 messages (SQLite cannot reach a leaf
    without them; a 40 s run bag cut at 50 %). The pages that are there are now scanned: nearly every message on a
    leaf page that survived is read, each identical to the intact read, in time order, and the error counts what
    is lost against metadata.yaml."""
    import shutil
    import sqlite3

    db3 = _run_db3(tmp_path, 3.0, page_size=512)
    full = read_bag(db3)
    total = sum(len(v[1]) for v in full.values())
    file = next(db3.glob('*.db3'))
    raw = file.read_bytes()
    page = 512
    size = {
        '30%': len(raw) * 3 // 10,
        '50%': len(raw) // 2,
        '80%': len(raw) * 8 // 10,
        'page boundary': len(raw) // 2 // page * page,
        'mid-page': len(raw) // 2 // page * page + page // 2 + 7,
    }[cut]
    # SQLite's own account of the intact file: the messages on leaf pages wholly before the cut
    con = sqlite3.connect(file)
    leaves = con.execute("SELECT pageno, ncell FROM dbstat WHERE name = 'messages' AND pagetype = 'leaf'").fetchall()
    con.close()
    surviving = sum(c for n, c in leaves if n * page <= size)
    cut_bag = tmp_path / 'cut'
    shutil.copytree(db3, cut_bag)
    (cut_bag / file.name).write_bytes(raw[:size])
    with pytest.raises(BagError, match='cut short') as err:
        read_bag(cut_bag)
    assert f'of the {total} messages metadata.yaml lists are read' in str(err.value) and 'lost' in str(err.value)
    got = err.value.salvaged
    n = sum(len(v[1]) for v in got.values())
    assert 0.95 * surviving <= n <= surviving, (n, surviving)
    ref = _pairs(full)
    for topic, (t, msgs) in got.items():
        assert np.all(np.diff(t) >= 0), topic
        for ti, m in zip(t.tolist(), msgs):
            assert m in ref[topic][ti], (topic, ti)
    assert read_bag(cut_bag, salvage=True).keys() == got.keys()


def test_a_sqlite_file_whose_header_is_destroyed_is_named_and_read_page_by_page(tmp_path):
    """Zeroed first bytes of a db3 (its header and the schema's start) went to the MCAP reader as 'not an MCAP
    file'; the pages after them are intact. Now a BagError names the destroyed header and salvages every message
    by a page scan with the page size guessed from the pages; garbage named .db3 is a BagError too."""
    db3 = _run_db3(tmp_path, 1.0)
    full = read_bag(db3)
    file = next(db3.glob('*.db3'))
    raw = bytearray(file.read_bytes())
    raw[:100] = bytes(100)
    file.write_bytes(bytes(raw))
    with pytest.raises(BagError, match='SQLite header is destroyed') as err:
        read_bag(db3)
    got = err.value.salvaged
    assert got.keys() == full.keys()
    for topic in full:
        assert list(got[topic][0]) == list(full[topic][0]) and got[topic][1] == full[topic][1], topic
    with pytest.raises(BagError, match='SQLite header is destroyed'):
        bag_info(db3)
    (db3 / file.name).write_bytes(b'\x07' * 5000)
    for read in (read_bag, bag_info):
        with pytest.raises(BagError, match='SQLite header is destroyed'):
            read(db3)


def test_a_corrupt_mcap_chunk_is_named_and_the_intact_chunks_read_whole(tmp_path, capsys):
    """5000 bytes overwritten inside one chunk of a closed run bag: `info` called it healthy and compare read what
    rosbags' reader made of it without a word. bag_info and `sma-wrist info` now name the damaged chunk, the
    messages lost and when; read_bag raises BagError with the count, its salvage holding every message of the other
    chunks, identical to the intact read, and none from the damaged bytes."""
    import io
    import random
    import shutil

    from mcap.exceptions import EndOfFile
    from mcap.reader import SeekingReader
    from mcap.records import Chunk, Message
    from mcap.stream_reader import StreamReader

    from sma_wrist.cli import main
    from sma_wrist.runtime.launch import Runtime

    good, bad = tmp_path / 'run', tmp_path / 'bad'
    with Runtime(params=PARAMS) as rt:  # a chunk every 200 messages, several chunks in 3 s
        rt.record(good, flush_every=200)
        rt.add_nodes([Plant, Controller])
        rt.run_until(3.0)
    full = read_bag(good)
    total = sum(len(v[1]) for v in full.values())
    mcap_file = next(good.glob('*.mcap'))
    raw = bytearray(mcap_file.read_bytes())
    with open(mcap_file, 'rb') as f:
        summary = SeekingReader(f).get_summary()
    chunks = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    assert len(chunks) >= 4
    target = chunks[2]
    # the messages of the target chunk in the intact file: (topic, log time, bytes)
    topic_of, inside, n = {c.id: c.topic for c in summary.channels.values()}, [], 0
    with open(mcap_file, 'rb') as f:
        records = [r for r in StreamReader(f, emit_chunks=True).records if isinstance(r, Chunk)]
    for rec in records:
        n += 1
        if n == 3:
            try:  # the chunk's records end without a footer: the stream reader says so by EndOfFile
                for m in StreamReader(io.BytesIO(rec.data), skip_magic=True).records:
                    if isinstance(m, Message):
                        inside.append((topic_of.get(m.channel_id), m.log_time, m.data))
            except EndOfFile:
                pass
    assert inside and target.message_start_time == min(t for _, t, _ in inside)
    body = target.chunk_start_offset + 80  # past the chunk's own header: inside its records
    assert target.chunk_length > 5000 + 160
    rng = random.Random(7)
    raw[body : body + 5000] = bytes(rng.randrange(256) for _ in range(5000))
    shutil.copytree(good, bad)
    (bad / mcap_file.name).write_bytes(bytes(raw))

    info = bag_info(bad)
    assert f'chunk at offset {target.chunk_start_offset}' in info.damage and 'lost' in info.damage
    assert bag_info(good).damage == ''
    with pytest.raises(BagError) as err:
        read_bag(bad)
    got = err.value.salvaged
    n_got = sum(len(v[1]) for v in got.values())
    assert 0 < total - n_got <= len(inside)
    assert f'{n_got} of the {total} messages metadata.yaml lists are read: {total - n_got} lost' in err.value.problem
    assert f'{total - n_got} messages lost' in err.value.problem  # the chunk's own account agrees
    # every message of the other chunks is there, identical; what is left of the damaged chunk is intact too
    damaged = {}
    for topic, t, _ in inside:
        damaged[(topic, t)] = damaged.get((topic, t), 0) + 1
    for topic, (t, msgs) in full.items():
        g_t, g_m = (list(got[topic][0]), got[topic][1]) if topic in got else ([], [])
        j = 0
        for ti, m in zip(t.tolist(), msgs):
            if j < len(g_m) and g_t[j] == ti and g_m[j] == m:
                j += 1
            else:
                assert damaged.get((topic, ti), 0) > 0, (topic, ti)  # only the damaged chunk's messages are missing
        assert j == len(g_m), topic  # nothing else was read, in time order
    capsys.readouterr()
    assert main(['info', str(bad)]) == 1
    out = capsys.readouterr()
    assert 'DAMAGED' in out.out and f'chunk at offset {target.chunk_start_offset}' in out.err
    assert main(['info', str(good)]) == 0
