"""The live view (``sma-wrist run --foxglove``): a run's topics over the Foxglove WebSocket protocol.

The served run is read by a real WebSocket client (the ``websockets`` package) speaking the subprotocol the
server offers, and compared with the bag the same run records. Runs are short and fast (--real-time-factor).
"""

from __future__ import annotations

import contextlib
import json
import socket
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from sma_wrist import cli
from sma_wrist.contract import load_contract

ROOT = Path(__file__).resolve().parents[1]
LAYOUT = ROOT / 'config' / 'foxglove' / 'wrist.json'
SUBPROTOCOL = 'foxglove.sdk.v1'  # what foxglove-sdk 0.30 offers (it refuses the older foxglove.websocket.v1)


def _values(msg: Any) -> Any:
    """A rosbags message as plain values (arrays as lists), comparable with ==."""
    if isinstance(msg, np.ndarray):
        return msg.tolist()
    if isinstance(msg, list):
        return [_values(m) for m in msg]
    if hasattr(msg, '__dataclass_fields__'):
        return {k: _values(getattr(msg, k)) for k in msg.__dataclass_fields__ if k != '__msgtype__'}
    return msg


# ------------------------------------------------------------------------------ without a server


def test_foxglove_without_the_sdk_names_the_extra_and_exits_2(monkeypatch, capsys, tmp_path):
    monkeypatch.setitem(sys.modules, 'foxglove', None)  # import foxglove -> ImportError, as when not installed
    rc = cli.main(['run', '--foxglove', '0', '--duration', '1', '--bag', str(tmp_path / 'bag'), '--quiet'])
    err = capsys.readouterr().err
    assert rc == 2
    assert "pip install 'sma_wrist[live]'" in err and 'foxglove-sdk' in err
    assert 'Traceback' not in err
    assert not (tmp_path / 'bag').exists()


@pytest.mark.parametrize('bad', ['host:port', '70000', 'localhost:-1'])
def test_a_bad_foxglove_address_is_an_argument_error(bad, capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main(['run', '--foxglove', bad])
    assert exc.value.code == 2 and 'argument --foxglove' in capsys.readouterr().err


def test_the_address_takes_host_and_port_or_port_alone():
    from sma_wrist.runtime.live import parse_address

    assert parse_address('8765') == ('127.0.0.1', 8765)
    assert parse_address('0.0.0.0:9000') == ('0.0.0.0', 9000)
    assert parse_address('[::1]:0') == ('::1', 0)
    for bad in ('host:port', '70000', ':x'):
        with pytest.raises(ValueError, match=r'\[HOST:\]PORT|\[0, 65535\]'):
            parse_address(bad)


def test_a_hardware_run_refuses_a_real_time_factor(capsys):
    rc = cli.main(['run', '--hardware', '/dev/null', '--real-time-factor', '2', '--quiet'])
    assert rc == 2 and 'the device paces a hardware run' in capsys.readouterr().err


class _Clock:
    def __init__(self, ns: int) -> None:
        self.clock = type('T', (), {'sec': ns // 1_000_000_000, 'nanosec': ns % 1_000_000_000})()


def test_the_pacer_holds_sim_time_to_the_factor():
    """0.4 s of /clock at 100 Hz through the pacer takes at least 0.4 s / factor of wall time (a lower bound
    only: a loaded machine makes it slower, never faster); unpaced it takes microseconds."""
    from sma_wrist.runtime.live import RealTimePacer

    for factor in (1.0, 4.0):
        pacer = RealTimePacer(factor)
        t0 = time.perf_counter()
        for k in range(41):
            pacer._on_clock(None, _Clock(k * 10_000_000), 0)
        assert time.perf_counter() - t0 >= 0.4 / factor - 0.003  # the last sleep may be saved up (slack_s)
    with pytest.raises(ValueError, match='must be > 0'):
        RealTimePacer(0.0)


def test_the_layout_plots_contract_topics_and_fields_that_exist():
    """Every path in the shipped Foxglove layout names a contract topic and a field of its message type; it
    shows the angle against the reference, the temperatures against the desired ones, the TEM commands, the
    twin's residuals and /diagnostics."""
    from sma_wrist.runtime.messages import TYPESTORE

    layout = json.loads(LAYOUT.read_text())
    contract = load_contract()
    paths = [p['value'] for cfg in layout['configById'].values() for p in cfg.get('paths', [])]
    for path in paths:
        topic, _, field = path.partition('.')
        assert topic in contract.topics, path
        fields = [name for name, _ in TYPESTORE.fielddefs[contract.topics[topic].type][1]]
        assert field.split('[')[0] in fields, (path, fields)
    wanted = {
        '/wrist/joint_states.position[0]',
        '/wrist/reference.position[0]',
        '/wrist/muscle_1/temperature.temperature',
        '/wrist/muscle_1/temperature_desired.temperature',
        '/wrist/muscle_2/temperature.temperature',
        '/wrist/muscle_2/temperature_desired.temperature',
        '/wrist/tem_1/command.data',
        '/wrist/tem_2/command.data',
        '/wrist/twin/residual/muscle_1/temperature.data',
        '/wrist/twin/residual/muscle_2/temperature.data',
        '/wrist/twin/residual/angle.data',
    }
    assert wanted <= set(paths), sorted(wanted - set(paths))
    diag = [cfg['topicToRender'] for key, cfg in layout['configById'].items() if key.startswith('Diagnostic')]
    assert diag and set(diag) == {'/diagnostics'}

    def panels(node: Any) -> set[str]:
        return {node} if isinstance(node, str) else panels(node['first']) | panels(node['second'])

    assert panels(layout['layout']) == set(layout['configById'])  # every configured panel is placed
    assert "'/config/foxglove'" in (ROOT / 'setup.py').read_text()  # installed with the other config


# ------------------------------------------------------------------------------ a served run

websockets_sync = pytest.importorskip('websockets.sync.client', reason='the live tests need websockets')


def _needs_sdk() -> None:
    pytest.importorskip('foxglove', reason="the live view needs foxglove-sdk (pip install 'sma_wrist[live]')")


class _Client:
    """A Foxglove WebSocket client: advertisements, subscriptions, message and time frames."""

    def __init__(self, url: str, stack: contextlib.ExitStack, rcvbuf: int | None = None) -> None:
        sock = None
        if rcvbuf is not None:  # a small receive buffer: a client that stops reading fills it at once
            host, port = url.removeprefix('ws://').rsplit(':', 1)
            sock = socket.socket()
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
            sock.connect((host, int(port)))
        self.ws = stack.enter_context(
            websockets_sync.connect(url, subprotocols=[SUBPROTOCOL], sock=sock, max_size=None, max_queue=4)
        )
        self.channels: dict[int, dict[str, Any]] = {}
        self.subs: dict[int, int] = {}  # subscription id -> channel id
        self.messages: list[tuple[str, int, bytes]] = []  # (topic, log time ns, CDR)
        self.times: list[int] = []
        self.status: list[str] = []  # the server's status messages (e.g. a refused subscription)
        self.info = json.loads(self.ws.recv(timeout=30))

    def handle(self, frame: Any) -> None:
        if isinstance(frame, str):
            msg = json.loads(frame)
            if msg['op'] == 'advertise':  # subscribe to each channel as it appears, as the Foxglove app's panels do
                first = len(self.subs) + 1
                subs = [{'id': first + i, 'channelId': c['id']} for i, c in enumerate(msg['channels'])]
                self.channels.update({c['id']: c for c in msg['channels']})
                self.subs.update({s['id']: s['channelId'] for s in subs})
                self.ws.send(json.dumps({'op': 'subscribe', 'subscriptions': subs}))
            elif msg['op'] == 'status':
                self.status.append(msg['message'])
            return
        if frame[0] == 1:  # message data: subscription id u32, log time u64, payload
            sub, t = struct.unpack_from('<IQ', frame, 1)
            self.messages.append((self.channels[self.subs[sub]]['topic'], t, bytes(frame[13:])))
        elif frame[0] == 2:  # time: u64
            self.times.append(struct.unpack_from('<Q', frame, 1)[0])

    def until_advertised(self, topics: set[str]) -> None:
        """Read (and subscribe) until these topics are advertised."""
        while not topics <= {c['topic'] for c in self.channels.values()}:
            self.handle(self.ws.recv(timeout=60))

    def read_to_the_end(self) -> None:
        from websockets.exceptions import ConnectionClosed

        try:
            while True:
                self.handle(self.ws.recv(timeout=120))
        except ConnectionClosed:
            pass


def _serve_run(tmp_path: Path, *args: str) -> tuple[subprocess.Popen, str, list[str]]:
    """Start ``sma-wrist run --foxglove 127.0.0.1:0 ...``; its URL from the line it prints first."""
    from conftest import package_env  # type: ignore[import-not-found]

    env = package_env()  # this run's copy of the package: its compiled kernels are cached
    proc = subprocess.Popen(
        [sys.executable, '-m', 'sma_wrist', 'run', '--foxglove', '127.0.0.1:0', '--quiet', *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=tmp_path,
        env=env,
    )
    lines: list[str] = []
    ready = threading.Event()

    def drain() -> None:  # the nodes' INFO lines follow on stderr: read them all, or the pipe fills
        for line in proc.stderr:
            lines.append(line)
            if line.startswith('live view: ') or line.startswith('error: '):
                ready.set()
        ready.set()

    threading.Thread(target=drain, daemon=True).start()
    assert ready.wait(120), lines
    head = next((x for x in lines if x.startswith('live view: ')), None)
    assert head is not None, ''.join(lines)
    return proc, head.split()[2], lines


def _bag_messages(bag: Path) -> tuple[dict[tuple[str, int], list[bytes]], dict[str, bytes]]:
    """{(topic, log time): [CDR, ...]} and {type name: schema text} of a rosbag2 MCAP bag."""
    from mcap.reader import make_reader

    out: dict[tuple[str, int], list[bytes]] = {}
    schemas: dict[str, bytes] = {}
    (file,) = bag.glob('*.mcap')
    with open(file, 'rb') as f:
        for schema, channel, message in make_reader(f).iter_messages():
            out.setdefault((channel.topic, message.log_time), []).append(bytes(message.data))
            schemas[schema.name] = bytes(schema.data)
    return out, schemas


def _simulated_topics() -> dict:
    """The contract's topics of the simulated graph: all but those only the hardware bridge publishes (the
    device's drive read-back)."""
    return {name: t for name, t in load_contract().topics.items() if t.publisher != 'hardware_bridge'}


def test_a_served_run_advertises_the_contract_and_sends_what_its_bag_records(tmp_path):
    """One run with the monitor (every contract topic) served live and recorded: a client sees every contract
    topic advertised with the schema the bag stores, ros2msg + cdr as foxglove_bridge serves a ROS 2 topic;
    every message it receives decodes (rosbags) to the values the bag holds for that topic at that log time,
    and the server's time is the bag's clock. Beside it, a client that stops reading and one that drops its
    connection mid-run: the run ends normally, its bag complete."""
    _needs_sdk()
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    bag = tmp_path / 'bag'
    # the twin in a worker thread: a worker process publishes the twin once it has started (seconds, more on a busy
    # machine), later than this 1 s run
    params = tmp_path / 'monitor.yaml'
    params.write_text('twin_monitor:\n  ros__parameters:\n    worker: thread\n')
    proc, url, _ = _serve_run(
        tmp_path,
        '--duration',
        '8',
        '--real-time-factor',
        '8',
        '--monitor',
        '--bag',
        str(bag),
        '--json',
        '--params-file',
        str(params),
    )
    with contextlib.ExitStack() as stack:
        stack.callback(proc.kill)
        reader, stalled, dropped = _Client(url, stack), _Client(url, stack, rcvbuf=4096), _Client(url, stack)
        assert reader.ws.subprotocol == SUBPROTOCOL and reader.info['op'] == 'serverInfo'
        assert 'time' in reader.info['capabilities']
        for c in (reader, stalled, dropped):
            c.until_advertised(set(_simulated_topics()))
        for _ in range(50):  # a few messages, then the connection is gone without a closing handshake
            dropped.handle(dropped.ws.recv(timeout=60))
        dropped.ws.socket.close()
        reader.read_to_the_end()  # the server closes when the run ends; `stalled` never reads again
        out, _ = proc.communicate(timeout=120)
    assert proc.returncode == 0, out
    assert reader.status == []  # every subscription taken
    summary = json.loads(out)
    assert summary['sim_time_s'] == pytest.approx(8.0) and summary['metrics']['rms_error_pct'] > 0

    recorded, schemas = _bag_messages(bag)
    advertised = {c['topic']: c for c in reader.channels.values()}
    simulated = _simulated_topics()
    assert set(simulated) <= set(advertised), sorted(set(simulated) - set(advertised))
    for name, topic in simulated.items():
        c = advertised[name]
        assert (c['schemaName'], c['schemaEncoding'], c['encoding']) == (topic.type, 'ros2msg', 'cdr')
        assert c['schema'].encode() == schemas[topic.type], name

    got: dict[str, int] = {}
    for topic, t, data in reader.messages:
        assert (topic, t) in recorded, (topic, t)
        typename = advertised[topic]['schemaName']
        want = [_values(store.deserialize_cdr(d, typename)) for d in recorded[topic, t]]
        assert _values(store.deserialize_cdr(data, typename)) in want, (topic, t)
        got[topic] = got.get(topic, 0) + 1
    # 8 s at 100 Hz is 800 per measurement topic; the client subscribed once the graph ran
    for name in ('/wrist/joint_states', '/wrist/muscle_1/temperature', '/wrist/tem_1/command', '/wrist/reference'):
        assert got.get(name, 0) >= 400, got
    for name in ('/wrist/twin/residual/angle', '/diagnostics', '/wrist/payload'):  # payload: latched, sent again
        assert got.get(name, 0) >= 1, got
    clock = {t for (topic, t) in recorded if topic == '/clock'}  # the time goes out with each batch (FLUSH_S)
    assert set(reader.times) <= clock and reader.times == sorted(reader.times) and len(reader.times) >= 5


def test_a_port_in_use_is_a_clear_error_before_anything_is_written(capsys, tmp_path):
    _needs_sdk()
    with socket.socket() as taken:
        taken.bind(('127.0.0.1', 0))
        taken.listen()
        port = taken.getsockname()[1]
        rc = cli.main(['run', '--foxglove', f'127.0.0.1:{port}', '--bag', str(tmp_path / 'bag'), '--quiet'])
    err = capsys.readouterr().err
    assert rc == 2 and f'cannot serve the live view on 127.0.0.1:{port}' in err and 'in use' in err, err
    assert 'choose another port' in err and 'Traceback' not in err
    assert not (tmp_path / 'bag').exists()
