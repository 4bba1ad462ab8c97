"""Run the wrist's node graph on the embedded runtime, record a bag, measure it.

The embedded counterpart of ``ros2 launch sma_wrist wrist_sim.launch.py`` + ``ros2 bag
record -a``: the same node classes, the same params files (config/wrist.yaml, then the
user's), the same per-node overrides the launch file sets (use_sim_time, payload_kg, mode).
The runtime must be active before this module is imported (``sma_wrist.cli`` does it).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

from sma_wrist.contract import PAYLOAD_RANGE_KG
from sma_wrist.core.errors import SmaWristError
from sma_wrist.runtime.launch import Runtime
from sma_wrist.share import share_path

T = TypeVar('T')

CONTROLLERS = ('inverse_adaptive', 'direct_adaptive', 'pid')


@dataclass
class RunSummary:
    bag: str | None
    controller: str
    payload_kg: float
    sim_time_s: float
    wall_s: float
    messages_recorded: int
    interrupted: bool
    metrics: dict[str, Any] = field(default_factory=dict)
    run: Any = None  # sma_wrist.runs.RunData read back from the bag (what the metrics came from)
    metrics_missing: str = ''  # why ``metrics`` is empty although the run was measured ('' when it is not)
    monitor: dict[str, Any] | None = None  # twin_monitor's checks and last verdict (run_closed_loop(monitor=...))

    @property
    def real_time_factor(self) -> float:
        return self.sim_time_s / self.wall_s if self.wall_s > 0 else float('inf')


class NothingToMeasure(SmaWristError):
    """A run that ended normally with too little in its bag to measure (``summary.metrics_missing`` says why): no
    metric is made up from it. ``summary``: the run as it was, for ``sma-wrist run`` to print."""

    def __init__(self, summary: RunSummary) -> None:
        super().__init__(f'no tracking metrics: {summary.metrics_missing}')
        self.summary = summary


#: a hardware run whose device time has not advanced for this long (wall) [s] is stopped
DEVICE_STALL_S = 10.0


class _Stall:
    """``stop_when`` for hardware runs: True once device (sim) time stood still for ``limit_s`` of wall time."""

    def __init__(self, rt: Runtime, limit_s: float) -> None:
        self.rt, self.limit_s = rt, limit_s
        self.last_ns: int | None = None
        self.since = time.monotonic()
        self.stalled = False

    def __call__(self) -> bool:
        now, sim = time.monotonic(), self.rt.sim_ns
        if sim != self.last_ns:
            self.last_ns, self.since = sim, now
        elif now - self.since > self.limit_s:
            self.stalled = True
        return self.stalled


def graph_nodes(controller: str, hardware: bool = False) -> list[type]:
    """Node classes of the closed loop, plant (or bridge) first so it owns time from t = 0."""
    if controller not in CONTROLLERS:
        raise ValueError(f'controller {controller!r} is not one of {", ".join(CONTROLLERS)}')
    from sma_wrist.nodes.adaptive_controller import AdaptiveController
    from sma_wrist.nodes.hysteresis_compensator import HysteresisCompensator
    from sma_wrist.nodes.tem_controller import TemController
    from sma_wrist.nodes.trajectory_generator import TrajectoryGenerator

    if hardware:
        from sma_wrist.nodes.hardware_bridge import HardwareBridge as Source
    else:
        from sma_wrist.nodes.plant_sim import PlantSim as Source
    nodes: list[type] = [Source, TrajectoryGenerator, AdaptiveController]
    if controller == 'inverse_adaptive':
        nodes.append(HysteresisCompensator)
    nodes.append(TemController)
    return nodes


def ros_args(params_files: Sequence[str | Path] = ()) -> list[str]:
    args = ['--ros-args', '--params-file', str(share_path('config/wrist.yaml'))]
    for f in params_files:
        args += ['--params-file', str(f)]
    return args


def file_choices(params_files: Sequence[str | Path], hardware: bool = False) -> tuple[str, float]:
    """(controller mode, payload [kg]) the params files give the graph (after config/wrist.yaml, merged as rcl
    merges them): what ``run`` uses where the command line names neither. ``run --params-file`` with a file's
    ``payload_kg: 0.6`` ran 0.3 kg, the option's default, and never checked the file's value."""
    from sma_wrist.runtime.arguments import overrides_for, parse_ros_args

    args = [parse_ros_args(ros_args(params_files))]
    source = '/hardware_bridge' if hardware else '/plant_sim'
    mode = overrides_for('/adaptive_controller', args).get('mode', 'inverse_adaptive')
    payload = overrides_for(source, args).get('payload_kg', 0.3)
    where = ', '.join(map(str, params_files)) or 'config/wrist.yaml'
    if mode not in CONTROLLERS:
        raise SmaWristError(f'adaptive_controller mode {mode!r} ({where}) is not one of {", ".join(CONTROLLERS)}')
    lo, hi = PAYLOAD_RANGE_KG
    if isinstance(payload, bool) or not isinstance(payload, (int, float)) or not lo <= payload <= hi:
        raise SmaWristError(f'{source[1:]} payload_kg {payload!r} ({where}) must be a number in [{lo:g}, {hi:g}] kg')
    return mode, float(payload)


def file_soft_start(params_files: Sequence[str | Path]) -> float | None:
    """trajectory_generator's ``soft_start_s`` as the user's params files set it, None where none does (the
    package's config/wrist.yaml is not asked: its value is the node's default, which ``run`` replaces)."""
    if not params_files:
        return None
    from sma_wrist.runtime.arguments import overrides_for, parse_ros_args

    args = [parse_ros_args(['--ros-args', *(a for f in params_files for a in ('--params-file', str(f)))])]
    value = overrides_for('/trajectory_generator', args).get('soft_start_s')
    return None if value is None else float(value)


def overrides(
    controller: str, payload_kg: float, source: str = 'plant_sim', extra: dict[str, dict[str, Any]] | None = None
) -> dict[str, dict[str, Any]]:
    """What the launch file sets on top of the params files."""
    out: dict[str, dict[str, Any]] = {
        '/**': {'use_sim_time': True},
        f'/{source}': {'use_sim_time': False, 'payload_kg': float(payload_kg)},
        '/adaptive_controller': {'mode': controller},
    }
    for k, v in (extra or {}).items():
        out.setdefault(k, {}).update(v)
    return out


def build_nodes(
    nodes: Sequence[type], args: Sequence[str], params: dict[str, dict[str, Any]], take: Callable[[Any], T]
) -> dict[str, T]:
    """{node name: ``take(node)``} of ``nodes`` built, not run, on a throwaway embedded runtime with ``args`` and
    ``params``, their start-up lines silenced; a node that refuses its values raises ParameterError with its reason
    (ros2 run's). How ``run`` checks a params file and ``sweep`` reads one."""
    from sma_wrist.nodes.common import add_or_refuse
    from sma_wrist.runtime.rclpy import logging as rlog

    out: dict[str, T] = {}
    with rlog.silenced(), Runtime(list(args), params=params) as rt:
        for cls in nodes:
            node = add_or_refuse(rt, cls)
            out[node.get_name()] = take(node)
    return out


def check_params(
    nodes: Sequence[type], args: Sequence[str], params_files: Sequence[str | Path], params: dict[str, dict[str, Any]]
) -> None:
    """Build ``nodes`` (:func:`build_nodes`) before anything is recorded: a value a node refuses, or a key of
    ``params_files`` that no node of the graph declares (ROS ignores it, so a misspelt name would run the defaults in
    silence), is a ParameterError. A refusal met only when the run started left its bag behind, which then blocked
    the rerun ("already exists")."""
    from sma_wrist.nodes.common import refuse_undeclared

    refuse_undeclared(params_files, build_nodes(nodes, args, params, lambda n: set(n.get_parameters_by_prefix(''))))


def run_closed_loop(
    controller: str = 'inverse_adaptive',
    payload_kg: float = 0.3,
    duration_s: float = 126.0,
    bag: str | Path | None = None,
    params_files: Sequence[str | Path] = (),
    extra_params: dict[str, dict[str, Any]] | None = None,
    topics: Sequence[str] | None = None,
    progress: Callable[[float, float, float], None] | None = None,
    hardware: bool = False,
    delivery: Any = None,
    measure: bool = False,
    monitor: dict[str, Any] | None = None,
    live: Any = None,
    real_time_factor: float | None = None,
) -> RunSummary:
    """Run the graph for ``duration_s`` of simulated time; metrics are read back from the bag.

    ``measure`` without a ``bag``: record to a temporary bag, removed afterwards, for the metrics (``sma-wrist run``
    without --bag printed none). ``monitor``: also run twin_monitor with these parameter overrides ({} for its
    defaults); its last verdict and how many checks it made and skipped are in ``RunSummary.monitor``.
    ``live``: a :class:`sma_wrist.runtime.live.LiveServer` that serves the graph's topics (attached before the
    nodes, started once they are built, stopped at the end); ``real_time_factor``: hold simulated time to this multiple of real time (None: as fast as possible).
    ``progress(t_sim, duration, wall)`` is called about every 1 % of the run. Ctrl-C stops the run; the bag is
    closed with everything up to the interrupt and the summary says so (and ``metrics_missing`` why there are
    none, when it holds no reference yet). A run that ended normally with too little recorded to measure (one
    sample) raises :class:`NothingToMeasure`. On hardware (the device's clock counts from its boot) the run lasts
    ``duration_s`` from the first /clock the graph sees.
    """
    import contextlib
    import tempfile

    kept = bag is not None
    with (
        tempfile.TemporaryDirectory(prefix='sma_wrist_run_') if measure and not kept else contextlib.nullcontext(None)
    ) as tmp:
        if tmp is not None:
            bag = Path(tmp) / 'bag'
        try:
            summary = _run(
                controller,
                payload_kg,
                duration_s,
                bag,
                params_files,
                extra_params,
                topics,
                progress,
                hardware,
                delivery,
                kept,
                monitor,
                live,
                real_time_factor,
            )
        except NothingToMeasure as exc:
            if not kept:  # the temporary bag is gone with its folder
                exc.summary.bag = None
            raise
    if not kept:
        summary.bag = None
    return summary


def _run(
    controller: str,
    payload_kg: float,
    duration_s: float,
    bag: str | Path | None,
    params_files: Sequence[str | Path],
    extra_params: dict[str, dict[str, Any]] | None,
    topics: Sequence[str] | None,
    progress: Callable[[float, float, float], None] | None,
    hardware: bool,
    delivery: Any,
    kept: bool,
    monitor: dict[str, Any] | None,
    live: Any = None,
    real_time_factor: float | None = None,
) -> RunSummary:
    """:func:`run_closed_loop` with its bag (or none); ``kept``: the bag is the user's, not a temporary one."""
    source = 'hardware_bridge' if hardware else 'plant_sim'
    nodes = graph_nodes(controller, hardware)
    if monitor is not None:
        from sma_wrist.nodes.twin_monitor import TwinMonitor

        nodes.append(TwinMonitor)
        extra_params = {**(extra_params or {}), '/twin_monitor': dict(monitor)}
    if params_files:  # all but hardware_bridge (graph_nodes puts the source first), which would open its port
        check_params(
            nodes[1:] if hardware else nodes,
            ros_args(params_files),
            params_files,
            overrides(controller, payload_kg, source, extra_params),
        )
    wall0 = time.perf_counter()
    interrupted = stalled = False
    recorded = 0
    sim_s = 0.0
    with Runtime(
        ros_args(params_files), params=overrides(controller, payload_kg, source, extra_params), delivery=delivery
    ) as rt:
        if bag is not None:
            rec = rt.record(bag, topics)
        if live is not None:  # before the nodes, as the recorder: the latched payload is published at start-up
            rt.serve_live(live)
        if real_time_factor is not None:
            rt.pace(real_time_factor)
        from sma_wrist.nodes.common import add_or_refuse

        # a value a node refuses (a params file's): its reason, not rclpy's traceback
        built = [add_or_refuse(rt, cls) for cls in nodes]
        if live is not None:  # the nodes' topics advertised, then the server opened
            live.start()
        source_node = built[0]
        monitor_node = built[-1] if monitor is not None else None
        chunk = max(duration_s / 100.0, 0.01)
        t = 0.0
        stall = _Stall(rt, DEVICE_STALL_S) if hardware else None
        # sim time the run starts at [s]: plant_sim's clock starts at 0 when the loop spins. hardware_bridge's counts
        # from the first sample after it opened the port, and the device streams on while the nodes after it are
        # built (28 s on a cold numba cache, their kernels compiling): the first /clock the graph sees is that far
        # in, and a run ending at device time duration_s ended there with one sample. So: from the first /clock.
        start_s: float | None = None if hardware else 0.0
        try:
            if start_s is None:
                rt.run_until(0.0, until='sim', stop_when=stall)  # returns at the first /clock
                if rt.sim_ns is not None:
                    start_s = rt.sim_ns / 1e9
            while start_s is not None and t < duration_s - 1e-12:
                t = min(duration_s, t + chunk)
                rt.run_until(start_s + t, until='sim', stop_when=stall)
                if stall is not None and stall.stalled:
                    break
                if progress is not None:
                    progress(t, duration_s, time.perf_counter() - wall0)
        except KeyboardInterrupt:
            interrupted = True
        stalled = stall is not None and stall.stalled
        device_s = (rt.sim_ns or 0) / 1e9
        sim_s = device_s - (start_s or 0.0)  # of the run, not of the device
        monitor_out = None
        if monitor_node is not None:
            monitor_node.collect()  # the verdicts the worker sent since the last sample
            v = monitor_node.verdict
            monitor_out = {
                'checks': len(monitor_node.history),
                'skipped_checks': monitor_node.skipped_checks,
                'behind_s': monitor_node.behind_s(),
                'worker': monitor_node.p['worker'],
                'worker_cpu_s': monitor_node.worker_cpu_s,
                'verdict': v.to_json() if v is not None else None,
                'episodes': monitor_node.episodes,
            }
        why = source_node.why_no_data() if stalled else ''
        if bag is not None:
            recorded = rec.count
    if stalled:
        raise SmaWristError(
            f'no data from the device for {DEVICE_STALL_S:g} s (wall) at {device_s:.2f} s of device time: check '
            f"hardware_bridge's port, that the device is powered and streaming (doc/explanation/protocol.md); TEMs were "
            f'held at 0 V'
            + (f'; the bag {bag} holds everything up to here' if kept else '')
            + (f'. What the bridge saw: {why}' if why else '')
        )
    summary = RunSummary(
        str(bag) if bag is not None else None,
        controller,
        float(payload_kg),
        sim_s,
        time.perf_counter() - wall0,
        recorded,
        interrupted,
    )
    summary.monitor = monitor_out
    if bag is not None:
        from sma_wrist.bag import BagError
        from sma_wrist.runs import load_run, run_metrics, unmeasurable

        try:
            summary.run = load_run(bag)
        except BagError as exc:
            missing = exc.problem
        else:
            missing = unmeasurable(summary.run)
        if missing:  # never a metric from nothing: one sample read "max error 0.00 %"
            summary.metrics_missing = (
                f'interrupted at {sim_s:.2f} s before there was an error to measure: {missing}'
                if interrupted
                else f'the run ended at {sim_s:.2f} s with nothing to measure: {missing}'
            )
            if not interrupted:  # a run that ended normally and left nothing to measure is a fault
                raise NothingToMeasure(summary)
        else:
            summary.metrics = run_metrics(summary.run)
    return summary


def print_progress(t: float, total: float, wall: float) -> None:
    """Progress on stderr: one line updated in place on a terminal, a line per 10 % in a log."""
    rtf = t / wall if wall > 0 else float('inf')
    text = f'[sma-wrist] {t:7.1f} / {total:.1f} s simulated ({100 * t / total:5.1f} %, {rtf:6.1f}x real time)'
    if sys.stderr.isatty():
        sys.stderr.write('\r' + text + ('\n' if t >= total else ''))
    else:
        step = total / 10.0
        if int(t / step + 1e-9) != int((t - total / 100.0) / step + 1e-9) or t >= total:
            sys.stderr.write(text + '\n')
    sys.stderr.flush()


__all__ = [
    'CONTROLLERS',
    'RunSummary',
    'graph_nodes',
    'build_nodes',
    'check_params',
    'run_closed_loop',
    'print_progress',
    'ros_args',
    'overrides',
]


def bench_graph(quick: bool = False, repeats: int = 3) -> dict[str, Any]:
    """Real-time factor of the full graph (100 Hz control, 1 kHz plant) with and without recording,
    and the runtime's per-message cost (embedded runtime; run in a fresh process by sma-wrist bench).

    ``floor_*``: the same topology with nodes that only publish (runtime.bench.bench_contract_floor),
    the ceiling for any node implementation; ``nodes_us_per_tick`` is what the real nodes add to it.
    Each figure is the best of ``repeats`` interleaved runs (a shared machine's speed drifts by 2x
    over minutes; the best run is the one least disturbed), ``*_range`` the worst and best.
    """
    import tempfile

    from sma_wrist import runtime
    from sma_wrist.runtime.bench import bench_contract_floor

    runtime.activate()
    duration = 10.0 if quick else 60.0
    floors = [bench_contract_floor(duration) for _ in range(repeats)]
    floor = min(floors, key=lambda f: f['us_per_tick'])
    out: dict[str, Any] = {
        'sim_time_s': duration,
        'repeats': repeats,
        'floor_real_time_factor': floor['real_time_factor'],
        'floor_real_time_factor_range': [min(f['real_time_factor'] for f in floors), floor['real_time_factor']],
        'floor_us_per_tick': floor['us_per_tick'],
        'floor_messages_per_tick': floor['published_per_tick'],
        'floor_deliveries_per_tick': floor['deliveries_per_tick'],
    }
    for controller in ('direct_adaptive', 'inverse_adaptive'):
        run_closed_loop(controller, 0.3, 0.5)  # imports, numba cache load
        plain, recorded = [], []
        for _ in range(repeats):
            plain.append(run_closed_loop(controller, 0.3, duration))
            with tempfile.TemporaryDirectory() as d:
                recorded.append(run_closed_loop(controller, 0.3, duration, Path(d) / 'bag'))
        s = min(plain, key=lambda r: r.wall_s)
        r = min(recorded, key=lambda r: r.wall_s)
        out[f'{controller}_real_time_factor'] = s.real_time_factor
        out[f'{controller}_real_time_factor_range'] = [min(x.real_time_factor for x in plain), s.real_time_factor]
        out[f'{controller}_nodes_us_per_tick'] = 1e6 * s.wall_s / (duration * 100.0) - floor['us_per_tick']
        out[f'{controller}_recorded_real_time_factor'] = r.real_time_factor
        out[f'{controller}_recorded_real_time_factor_range'] = [
            min(x.real_time_factor for x in recorded),
            r.real_time_factor,
        ]
        out[f'{controller}_messages_per_sim_s'] = r.messages_recorded / duration
        out[f'{controller}_recording_cost_us_per_message'] = 1e6 * (r.wall_s - s.wall_s) / max(r.messages_recorded, 1)
    return out


def _stalled_client(url: str, topics: set[str], stack: Any, done: Any) -> None:
    """A WebSocket client (``websockets``) that subscribes to ``topics`` as they are advertised, then reads nothing
    more: its receive queue holds 4 messages and its socket buffer 4 KiB, so the server's queue for it fills and
    the server drops its oldest messages. ``done`` is set once it has subscribed."""
    import json
    import socket

    from websockets.sync.client import connect

    host, port = url.removeprefix('ws://').rsplit(':', 1)
    sock = socket.socket()
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    sock.connect((host, int(port)))
    ws = stack.enter_context(connect(url, subprotocols=['foxglove.sdk.v1'], sock=sock, max_queue=4))
    seen: set[str] = set()
    n = 0
    while not topics <= seen:
        frame = ws.recv(timeout=60)
        msg = json.loads(frame) if isinstance(frame, str) else {}
        if msg.get('op') == 'advertise':
            subs = [{'id': n + i + 1, 'channelId': c['id']} for i, c in enumerate(msg['channels'])]
            n += len(subs)
            seen |= {c['topic'] for c in msg['channels']}
            ws.send(json.dumps({'op': 'subscribe', 'subscriptions': subs}))
    done.set()


#: a client in its own process that subscribes to every channel and reads until the server closes (bench_live)
_READER = """
import json, sys
from websockets.sync.client import connect
with connect(sys.argv[1], subprotocols=['foxglove.sdk.v1'], max_size=None) as ws:
    n = 0
    try:
        for frame in ws:
            msg = json.loads(frame) if isinstance(frame, str) else {}
            if msg.get('op') == 'advertise':
                subs = [{'id': n + i + 1, 'channelId': c['id']} for i, c in enumerate(msg['channels'])]
                n += len(subs)
                ws.send(json.dumps({'op': 'subscribe', 'subscriptions': subs}))
    except Exception:
        pass
"""


def _serve(topics: set[str], stack: Any, client: str | None) -> Any:
    """A LiveServer on a free port in ``stack``; once it listens, ``client`` connects: None, ``'reading'`` (a
    process of its own that reads everything) or ``'stalled'`` (:func:`_stalled_client`, a thread)."""
    import subprocess
    import threading

    from sma_wrist.runtime.live import LiveServer

    done = threading.Event()

    def connect_client(server: Any) -> None:
        if client == 'reading':
            proc = subprocess.Popen([sys.executable, '-c', _READER, server.url])
            stack.callback(proc.wait, 10.0)
            stack.callback(proc.terminate)
            done.set()
        elif client == 'stalled':
            thread = threading.Thread(target=_stalled_client, args=(server.url, topics, stack, done), daemon=True)
            thread.start()
            stack.callback(thread.join, 5.0)

    live = stack.enter_context(LiveServer('127.0.0.1', 0, announce=connect_client))
    live.subscribed = done
    return live


def bench_live(quick: bool = False, repeats: int = 5) -> dict[str, Any]:
    """What the live view (``run --foxglove``) costs an unpaced run: interleaved runs of the closed loop without a
    server (``plain``), with a server and no client, with a client that reads everything (its own process), and
    with a client that subscribed to every topic and then stopped reading (:func:`_stalled_client`).

    Two measures per run, each the best of ``repeats`` (the least disturbed run) over ``plain``'s: the wall time,
    and the CPU time of the thread that runs the graph (the taps, the encoding, the hand-over to the server's
    queues). On a shared machine the load moves one run's wall time by a factor of several; the CPU time much
    less. ``stalled_over_reading_*``: what a client that stops reading costs over one that reads: the server
    drops its oldest messages instead of waiting for it. (foxglove-sdk also drops a client that has left 1024 of
    its control messages unread, the time broadcast with each /clock among them.)"""
    try:
        import foxglove  # noqa: F401
        import websockets.sync.client  # noqa: F401
    except ImportError as exc:
        return {'skipped': f"needs foxglove-sdk and websockets ({exc}): pip install 'sma_wrist[test]'"}
    import contextlib

    from sma_wrist import runtime
    from sma_wrist.contract import load_contract

    runtime.activate()
    duration = 10.0 if quick else 30.0
    controller = 'inverse_adaptive'
    topics = {t for t in load_contract().topics if not t.startswith('/wrist/twin/')}  # the graph without the monitor

    def timed(client: str | None = None, serve: bool = True) -> tuple[float, float]:
        with contextlib.ExitStack() as stack:
            live = _serve(topics, stack, client) if serve else None
            cpu0 = time.thread_time()
            summary = run_closed_loop(controller, 0.3, duration, live=live)
            cpu = time.thread_time() - cpu0
            if client is not None and not live.subscribed.wait(5.0):
                raise RuntimeError(f'the {client} benchmark client did not subscribe')
        return summary.wall_s, cpu

    run_closed_loop(controller, 0.3, 0.5)  # imports, numba cache load
    cases = {'plain': (None, False), 'no_client': (None, True), 'reading': ('reading', True)}
    cases['stalled'] = ('stalled', True)
    runs: dict[str, list[tuple[float, float]]] = {k: [] for k in cases}
    for _ in range(repeats):
        for case, (client, serve) in cases.items():
            runs[case].append(timed(client, serve))
    wall = {k: min(w for w, _ in v) for k, v in runs.items()}
    cpu = {k: min(c for _, c in v) for k, v in runs.items()}
    out: dict[str, Any] = {
        'controller': controller,
        'sim_time_s': duration,
        'repeats': repeats,
        'plain_wall_s': wall['plain'],
        'plain_real_time_factor': duration / wall['plain'],
    }
    for case in ('no_client', 'reading', 'stalled'):
        out[f'{case}_wall_ratio'] = wall[case] / wall['plain']
        out[f'{case}_cpu_ratio'] = cpu[case] / cpu['plain']
    out['stalled_over_reading_wall_ratio'] = wall['stalled'] / wall['reading']
    out['stalled_over_reading_cpu_ratio'] = cpu['stalled'] / cpu['reading']
    out['wall_s_ranges'] = {k: [min(w for w, _ in v), max(w for w, _ in v)] for k, v in runs.items()}
    out['cpu_s_ranges'] = {k: [min(c for _, c in v), max(c for _, c in v)] for k, v in runs.items()}
    return out
