"""Bags from the embedded runtime: round trip (rosbags + mcap readers), Humble metadata,
byte-identical determinism, interrupted runs, truncated files."""
from __future__ import annotations

import json

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
        st = DiagnosticStatus(level=DiagnosticStatus.WARN, name='controller', message='ok',
                              values=[KeyValue(key='t', value=str(self.get_clock().now().nanoseconds))])
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
    assert {k: (v.type, v.count) for k, v in bare.topics.items()} == {k: (v.type, v.count) for k, v in full.topics.items()}
    assert (bare.start_ns, bare.end_ns) == (full.start_ns, full.end_ns)


def test_a_reader_that_goes_away_ends_the_cli_quietly(tmp_path):
    """`sma-wrist info BAG | head`: a closed pipe was a BrokenPipeError traceback; now exit 141, nothing on stderr."""
    import subprocess
    import sys
    bag = tmp_path / 'run'
    run_nodes([Plant, Controller], 1.0, params=PARAMS, bag=bag)
    proc = subprocess.Popen([sys.executable, '-m', 'sma_wrist.cli', 'info', str(bag)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
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


# ------------------------------------------------------------------ direct CDR of the high-rate types
from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st
from sensor_msgs.msg import Temperature  # noqa: E402
from std_msgs.msg import Header  # noqa: E402

from sma_wrist.runtime.fastcdr import decoder_for, encoder_for  # noqa: E402
from sma_wrist.runtime.messages import deserialize, serialize  # noqa: E402

_floats = st.floats(allow_nan=False, width=64)
_texts = st.text(max_size=9)
_stamps = st.tuples(st.integers(-2**31, 2**31 - 1), st.integers(0, 2**32 - 1))


def _header(stamp, frame_id):
    h = Header(frame_id=frame_id)
    h.stamp.sec, h.stamp.nanosec = stamp
    return h


_messages = st.one_of(
    st.builds(lambda x: Float64(data=x), _floats),
    st.builds(lambda s: ClockMsg(clock=_header(s, '').stamp), _stamps),
    st.builds(lambda s, f, t, v: Temperature(header=_header(s, f), temperature=t, variance=v),
              _stamps, _texts, _floats, _floats),
    st.builds(lambda s, f, n, p, v, e: JointState(header=_header(s, f), name=n, position=p, velocity=v, effort=e),
              _stamps, _texts, st.lists(_texts, max_size=3), st.lists(_floats, max_size=3),
              st.lists(_floats, max_size=3), st.lists(_floats, max_size=3)),
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
        JointState(name=['wrist'], position=[0.5], velocity=[0.1], effort=[]))
    decode = decoder_for('sensor_msgs/msg/JointState')
    for cut in (8, 20, len(data) - 4):
        with pytest.raises(Exception):
            decode(data[:cut])


def test_one_pass_reader_equals_rosbags_reader_and_falls_back_to_it(tmp_path, monkeypatch):
    """read_bag reads a closed, uncompressed MCAP bag in one pass (salvage_mcap); it must give
    what rosbags' indexed reader gives, all topics and a subset, and hand anything it does not
    handle (here: a file it reports a problem with, as for a compressed chunk) to rosbags."""
    import sma_wrist.bag as bag_mod
    bag = tmp_path / 'run'
    _run(bag)
    fast_all, fast_sub = read_bag(bag), read_bag(bag, ['/wrist/joint_states', '/clock'])
    calls = []

    def declined(*args, **kwargs):
        calls.append(args)
        return [], 'compressed chunk (zstd) at offset 8 cannot be salvaged'

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
