"""Benchmark of the live model monitor: ``sma-wrist bench --section monitor`` (doc/explanation/monitor.md).

* **detection**: clean closed-loop recordings (plant_sim, 0.3 kg, embedded runtime) rewritten by the independent
  effect generator (:mod:`sma_wrist.diagnose.distort`) with an effect that begins at ``ONSET_S``, at the noise of
  the diagnosis' tests (0.1 degC / 1 mrad); a case is detected when the first verdict the monitor raises names the
  right subsystem within ``DETECT_WITHIN_S`` of the onset and nothing was raised before it;
* **emulated detection**: the same on a device that changes while it runs: ``sma-wrist emulate-device --effect``
  (:data:`EMULATED_EFFECTS`, onset at ``EMULATED_ONSET_S`` of device time) and ``sma-wrist run --hardware PORT
  --monitor verdicts.json`` on it, in real time, the verdicts file read back; a case in which a check period passed
  without a check (``skipped_checks``: the check worker starved of CPU by a busy machine) is flagged ``starved`` and
  left out of the ``valid`` summary; ``worker_core_fraction``: the worker process' CPU per second of device time;
* **false alarms**: long nominal recordings per controller read through realistic sensors
  (:func:`sma_wrist.diagnose.distort.realistic`, jittering stamps and dropped samples from the bag writer), played
  through the monitor as a bag; and ``diagnose`` on the same whole bags;
* **cost**: CPU per check, the twin's CPU per second of data, the monitor's share of one core at 100 Hz input,
  its own work per sample (:func:`twin_cost`), and the node graph's speed with and without ``twin_monitor``
  (:func:`graph_speed`: interleaved pairs, median ratio).
"""

from __future__ import annotations

import dataclasses
import os
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import numpy as np

#: when the effects begin [s of the run]
ONSET_S = 90.0
#: the right subsystem must be raised this soon after the onset [s]
DETECT_WITHIN_S = 60.0
#: the effects a running wrist undergoes (sensor offset, gain and lag; TEMs weaker; payload; ambient / coolant drift;
#: wire transition drift), each of the size the diagnosis' tests use (test_diagnose_independent.py, and the top of
#: testdata.RANGES where those draw it at random): (kind, channel, value, unit, subsystem)
EFFECTS = (
    ('offset', 'T1', 3.0, 'degC', 'sensor'),  # a thermocouple coming loose
    ('offset', 'q', 0.05, 'rad', 'sensor'),  # the potentiometer slipping on its shaft
    ('gain', 'T2', 0.1, '1', 'sensor'),
    ('gain', 'q', 0.1, '1', 'sensor'),
    ('lag', 'T1', 4.0, 's', 'sensor'),  # a thermocouple losing contact with the wire
    ('lag', 'q', 0.4, 's', 'sensor'),
    ('tem_weak', 'plant', 0.2, '1', 'thermal'),  # a TEM weakening
    ('payload', 'plant', 0.2, 'kg', 'joint'),  # a heavier payload than /wrist/payload says
    ('ambient_drift', 'plant', 20.0, 'degC/h', 'thermal'),  # coolant warming up
    ('transition_drift', 'plant', 6.0, 'degC', 'hysteresis'),  # the wires transforming hotter (fatigue), ramped
)
#: measured and reported beside EFFECTS, not counted in its rate: a driver that stops passing small commands (an
#: actuator effect outside the list of changes a running wrist undergoes)
EXTRA_EFFECTS = (('dead_zone', 'u', 2.0, 'V', 'actuator'),)
#: how long a transition drift takes to reach its size [s] (fatigue is gradual; the diagnosis' test ramps it over
#: its 60 s run)
RAMP_S = 60.0


def _detect_case(args: tuple) -> dict[str, Any]:
    run, effect, seed = args
    from sma_wrist.diagnose import distort as ds
    from sma_wrist.monitor.playback import monitor_run

    kind, ch, value, unit, subsystem = effect
    ramp = RAMP_S if kind == 'transition_drift' else 0.0
    r = ds.apply(run, ds.Distortion(kind, ch, value, unit, ramp_s=ramp), 0.1, 1e-3, seed, onset_s=ONSET_S)
    c0 = time.process_time()
    res = monitor_run(r)
    cpu = time.process_time() - c0
    res.pop('_monitor')
    ep = res['episodes']
    early = [e for e in ep if e['raised_s'] < ONSET_S]
    first = next((e for e in ep if e['raised_s'] >= ONSET_S), None)
    delay = first['raised_s'] - ONSET_S if first else None
    return {
        'effect': f'{ch}_{kind}={value:g}{unit}',
        'subsystem': subsystem,
        'source': run.source,
        'raised': [(e['subsystem'], e['causes'], e['onset_s'], e['raised_s']) for e in ep],
        'first_subsystem': first['subsystem'] if first else None,
        'delay_s': delay,
        'detected': bool(first and not early and first['subsystem'] == subsystem and delay <= DETECT_WITHIN_S),
        'false_before_onset': bool(early),
        'checks': res['checks'],
        'check_cpu_s': res['check_cpu_s'],
        'cpu_s': cpu,
        'duration_s': res['duration_s'],
        'verdicts': [
            (v['t_s'], v['level'], v['subsystem'], v['check_cause'], v['check_subsystem'], v['check_confidence'])
            for v in res['verdicts']
        ],
    }


def _detected(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """What a set of detection cases (``detected``, ``delay_s``, ``false_before_onset`` per row) adds up to."""
    ok = sum(r['detected'] for r in rows)
    delays = [r['delay_s'] for r in rows if r['detected']]
    return {
        'cases': len(rows),
        'detected': ok,
        'rate': ok / max(len(rows), 1),
        'false_before_onset': sum(bool(r.get('false_before_onset')) for r in rows),
        'delay_s_median': float(np.median(delays)) if delays else None,
        'delay_s_max': float(np.max(delays)) if delays else None,
        'rows': rows,
    }


def detection(
    runs: dict[str, Any],
    duration_s: float = ONSET_S + DETECT_WITHIN_S + 5.0,
    seeds: tuple[int, ...] = (1,),
    workers: int = 2,
    effects: tuple[tuple, ...] = EFFECTS,
    extra: tuple[tuple, ...] = EXTRA_EFFECTS,
) -> dict[str, Any]:
    """Every effect of ``effects`` x run (the first ``duration_s`` of each) x seed; the ``extra`` effects are measured
    alike and summed apart (``extra``: not in the rate)."""
    cases = []
    for name, run in runs.items():
        n = int(round(duration_s / run.dt)) + 1
        cut = dataclasses.replace(run, t=run.t[:n], u=run.u[:n], T=run.T[:n], q=run.q[:n], valid=None, source=name)
        cases += [(cut, e, s) for e in effects + extra for s in seeds]
    with ProcessPoolExecutor(workers) as pool:
        rows = list(pool.map(_detect_case, cases))
    extra_ids = {f'{ch}_{kind}={value:g}{unit}' for kind, ch, value, unit, _ in extra}
    listed = [r for r in rows if r['effect'] not in extra_ids]

    def missed(rs: list[dict[str, Any]]) -> list[tuple]:
        return [(r['source'], r['effect'], r['first_subsystem'], r['delay_s']) for r in rs if not r['detected']]

    out = {
        **_detected(listed),
        'within_s': DETECT_WITHIN_S,
        'first_subsystem_right': sum(r['first_subsystem'] == r['subsystem'] for r in listed),
        'missed': missed(listed),
    }
    rest = [r for r in rows if r['effect'] in extra_ids]
    if rest:
        out['extra'] = {**_detected(rest), 'missed': missed(rest)}
    return out


#: effects the emulated device starts (``emulate-device --effect SPEC@ONSET``; its own code, not the model's
#: extensions nor the generator's), of the sizes above, and the subsystem that must be named
EMULATED_EFFECTS = (
    ('offset:T1:3', 'sensor'),  # a thermocouple coming loose
    ('offset:q:0.05', 'sensor'),  # the potentiometer slipping on its shaft
    ('gain:T2:0.1', 'sensor'),
    ('lag:T1:4', 'sensor'),  # a thermocouple losing contact with the wire
    ('tem_weak:plant:0.2', 'thermal'),  # the TEMs weakening
    ('payload:plant:0.2', 'joint'),  # a heavier payload than /wrist/payload says
    ('ambient_drift:plant:20', 'thermal'),  # coolant warming up
    ('transition_drift:plant:6', 'hysteresis'),  # the wires transforming hotter (fatigue), over EMULATED_RAMP_S
)
#: device time of the onset [s]: the run starts a few seconds after the device boots, and its first check comes
#: settle_s + window_s (65 s) later, so that several checks see the wrist before the change
EMULATED_ONSET_S = 120.0
#: how long the transition drift takes to reach its size [s] (fatigue is gradual)
EMULATED_RAMP_S = RAMP_S


def _child_env() -> dict[str, str]:
    """The environment of the processes a benchmark starts: this checkout's sma_wrist first."""
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    return {**os.environ, 'PYTHONPATH': os.pathsep.join(filter(None, (root, os.environ.get('PYTHONPATH'))))}


def emulated_case(
    spec: str | None,
    subsystem: str | None,
    directory: str,
    controller: str = 'pid',
    onset_s: float = EMULATED_ONSET_S,
    duration_s: float = 210.0,
    seed: int = 0,
    monitor: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """One case: ``sma-wrist emulate-device --effect SPEC@ONSET`` (no effect for ``spec`` None) and
    ``sma-wrist run --hardware PORT --monitor verdicts.json`` on it, as a user runs them; the verdicts file read back.

    ``monitor``: twin_monitor parameters other than its defaults (a params file given to ``run``). Times are the
    device's (the run's clock is the device's: its stamps, from the bridge's first sample). Detected: the first verdict raised after
    the onset names ``subsystem`` within ``DETECT_WITHIN_S`` of it, the first check it rests on came after the onset,
    and nothing was raised before the onset."""
    import json
    import signal
    import subprocess
    import sys

    os.makedirs(directory, exist_ok=True)
    port = os.path.join(directory, 'port')
    hist = os.path.join(directory, 'verdicts.json')
    env = _child_env()
    emu_args = ['--port', port, '--seed', str(seed)]
    run_args = []
    if monitor:
        import yaml

        params = os.path.join(directory, 'monitor.yaml')
        with open(params, 'w') as f:
            yaml.safe_dump({'twin_monitor': {'ros__parameters': dict(monitor)}}, f)
        run_args = ['--params-file', params]
    if spec:
        ramp = f'+{EMULATED_RAMP_S:g}' if spec.startswith('transition_drift') else ''
        emu_args += ['--effect', f'{spec}@{onset_s:g}{ramp}']
    emu = subprocess.Popen(
        [sys.executable, '-m', 'sma_wrist', 'emulate-device', *emu_args],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=env,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    out: dict[str, Any] = {'effect': spec or 'none', 'subsystem': subsystem, 'controller': controller}
    try:
        assert emu.stdout is not None
        for _ in range(5):  # the banner, then the port path
            if emu.stdout.readline().strip() == port:
                break
        c0 = time.time()
        r = subprocess.run(
            [sys.executable, '-m', 'sma_wrist', 'run', '--hardware', port, '--controller', controller]
            + ['--duration', f'{duration_s:g}', '--monitor', hist, '--json', '--quiet', *run_args],
            capture_output=True,
            text=True,
            env=env,
        )
        out['wall_s'] = time.time() - c0
    finally:
        emu.terminate()
        try:
            emu.wait(10)
        except subprocess.TimeoutExpired:  # a niced emulator on a busy machine may not get to end in time
            emu.kill()
            emu.wait()
    if r.returncode != 0 or not os.path.exists(hist):
        out['error'] = (r.stderr.strip().splitlines() or [f'exit {r.returncode}'])[-1]
        out['detected'] = False
        return out
    summary = json.loads(r.stdout)
    doc = json.loads(open(hist).read())
    vs, ep = doc['verdicts'], doc['episodes']
    out['checks_s'] = (vs[0]['t_s'], vs[-1]['t_s']) if vs else None  # device time of the first and last check
    out['checks'] = len(vs)
    out['skipped_checks'] = summary['monitor']['skipped_checks']
    # the worker process' CPU (the twin and the checks) per second of device time: the monitor's cost at 100 Hz
    out['worker_core_fraction'] = summary['monitor'].get('worker_cpu_s', 0.0) / max(summary['sim_time_s'], 1e-9)
    out['sim_time_s'] = summary['sim_time_s']
    m = summary.get('metrics') or {}
    out['metrics'] = {k: m[k] for k in ('max_error_pct_all', 'rms_error_pct_all') if k in m}
    early = [e for e in ep if e['raised_s'] < onset_s]
    first = next((e for e in ep if e['raised_s'] >= onset_s), None)
    out['checks_before_onset'] = sum(v['t_s'] < onset_s for v in vs)
    out['raised'] = [(e['subsystem'], e['causes'], e['onset_s'], e['raised_s']) for e in ep]
    out['first_subsystem'] = first['subsystem'] if first else None
    out['delay_s'] = first['raised_s'] - onset_s if first else None
    out['false_before_onset'] = bool(early)
    out['detected'] = bool(
        subsystem
        and first
        and not early
        and first['subsystem'] == subsystem
        and first['onset_s'] >= onset_s  # the checks that raised it saw the change, not a misfit from before it
        and out['delay_s'] <= DETECT_WITHIN_S
        and out['checks_before_onset'] > 0
    )
    # a check period that passed without a check, or a worker that fell behind the device so far that its last check
    # is more than two periods before the run's end (starved of CPU: it takes its input in order and checks in its
    # own time, so it skips nothing and makes one check in a 210 s run at load 11): the case measured the machine's
    # load, not the monitor's detection
    from sma_wrist.monitor import BEHIND_PERIODS, MonitorConfig

    period = float((monitor or {}).get('check_period_s', MonitorConfig.check_period_s))
    out['behind_s'] = summary['monitor']['behind_s']  # at the run's end
    out['starved'] = out['skipped_checks'] > 0 or not vs or out['behind_s'] > BEHIND_PERIODS * period
    out['verdicts'] = [(v['t_s'], v['level'], v['subsystem'], v['check_cause'], v['check_confidence']) for v in vs]
    return out


def emulated_detection(
    effects: tuple[tuple[str, str], ...] = EMULATED_EFFECTS, controller: str = 'pid', parallel: int = 1
) -> dict[str, Any]:
    """Every effect of :data:`EMULATED_EFFECTS` on the emulated device (real time, 1 kHz), through
    ``sma-wrist run --hardware --monitor``; ``parallel`` cases at once (each is a device, a graph and a check
    worker: on a loaded machine the graph falls behind the device)."""
    from concurrent.futures import ThreadPoolExecutor

    with tempfile.TemporaryDirectory(prefix='sma_wrist_emulated_') as d, ThreadPoolExecutor(parallel) as pool:
        rows = list(
            pool.map(
                lambda ie: emulated_case(ie[1][0], ie[1][1], os.path.join(d, str(ie[0])), controller),
                enumerate(effects),
            )
        )
    fr = [r['worker_core_fraction'] for r in rows if 'worker_core_fraction' in r]
    return {
        **_detected(rows),
        'failed_runs': sum('error' in r for r in rows),
        'skipped_checks': sum(r.get('skipped_checks', 0) for r in rows),
        # the cases that ran through with every check made: the valid measure of detection
        'valid': _detected([r for r in rows if 'error' not in r and not r.get('starved')]) | {'rows': None},
        'worker_core_fraction': float(np.mean(fr)) if fr else None,
    }


def _nominal_case(args: tuple) -> dict[str, Any]:
    name, run, seed, directory, with_diagnose = args
    from sma_wrist.diagnose import distort as ds
    from sma_wrist.diagnose import testdata as td
    from sma_wrist.monitor.playback import monitor_bag

    bag = os.path.join(directory, f'realistic_{name}_{seed}')
    td.write_run_bag(ds.realistic(run, seed=seed), bag, {'stamp_jitter_s': 1e-3, 'drop_rate': 1e-3})
    c0 = time.process_time()
    res = monitor_bag(bag)
    cpu = time.process_time() - c0
    mon = res.pop('_monitor')
    out = {
        'controller': name,
        'duration_s': res['duration_s'],
        'checks': res['checks'],
        'warn_checks': sum(v['level'] != 'OK' for v in res['verdicts']),
        'episodes': res['episodes'],
        'check_level_not_ok': sum(v['check_cause'] is not None for v in res['verdicts']),
        'check_cpu_s': res['check_cpu_s'],
        'cpu_s': cpu,
        'wall_s': res['wall_s'],
        'twin_cpu_s': cpu - sum(v.check_cpu_s for v in mon.history),
        'verdicts': [
            (v['t_s'], v['level'], v['subsystem'], v['check_cause'], v['check_subsystem'], v['check_confidence'])
            for v in res['verdicts']
        ],
    }
    out['core_fraction'] = cpu / out['duration_s']
    if with_diagnose:
        from sma_wrist.diagnose import diagnose

        c0 = time.process_time()
        d = diagnose(bag)
        out['diagnose'] = {
            'discrepancy': d.discrepancy,
            'confidence': d.confidence,
            'summary': d.summary,
            'cpu_s': time.process_time() - c0,
        }
    return out


def false_alarms(runs: dict[str, Any], seed: int = 11, with_diagnose: bool = True, workers: int = 2) -> dict[str, Any]:
    """Each run (a nominal recording) through realistic sensors, as a bag, through the monitor (and diagnose)."""
    with tempfile.TemporaryDirectory() as d, ProcessPoolExecutor(workers) as pool:
        rows = list(pool.map(_nominal_case, [(n, r, seed, d, with_diagnose) for n, r in runs.items()]))
    return {
        'runs': len(rows),
        'per_controller': {
            r['controller']: {
                'minutes': r['duration_s'] / 60.0,
                'checks': r['checks'],
                'false_alarm_episodes': len(r['episodes']),
                'diagnose_whole_bag': r.get('diagnose', {}).get('summary'),
            }
            for r in rows
        },
        'monitor_false_alarms': sum(len(r['episodes']) for r in rows),
        'diagnose_false_alarms': sum(bool(r.get('diagnose', {}).get('discrepancy')) for r in rows),
        'hours': sum(r['duration_s'] for r in rows) / 3600.0,
        'rows': rows,
    }


def graph_speed(
    duration_s: float = 300.0, controller: str = 'pid', pairs: int = 3, monitor: dict[str, Any] | None = None
) -> dict[str, Any]:
    """Speed of the node graph on the embedded runtime (simulated time per wall second) without and with
    twin_monitor (its defaults: checks in a worker process), in ``pairs`` interleaved pairs of runs (without, with,
    without, with, ...) so that a machine shared with other work loads both alike; the speed kept is the median of
    each pair's ratio. Beside it the graph process' CPU per simulated second (the nodes, twin_monitor's own work
    with them; not the worker's) and ``cpu_speed_kept``, its ratio without / with: what the node costs the graph's
    thread, which a loaded machine's scheduling does not blur as it does the wall ratio. Also the checks made and
    skipped (a check still running when the next is due waits). A short run of each first: the imports of the
    monitor's modules in the graph's process (about 2 s, once per process) are not counted against the first pair."""
    from sma_wrist import runtime

    runtime.activate()
    import rclpy

    from sma_wrist.closed_loop import run_closed_loop

    def with_monitor() -> dict[str, Any]:
        return {'worker': 'process', **(monitor or {})}

    for mon in (None, with_monitor()):
        try:
            run_closed_loop(controller, 0.3, 2.0, None, monitor=mon)
        finally:
            rclpy.try_shutdown()
    rows = []
    for _ in range(pairs):
        row: dict[str, Any] = {}
        for label, mon in (('without', None), ('with', with_monitor())):
            c0 = time.process_time()
            try:
                s = run_closed_loop(controller, 0.3, duration_s, None, monitor=mon)
            finally:
                rclpy.try_shutdown()
            row[f'{label}_real_time_factor'] = s.real_time_factor
            row[f'{label}_main_cpu_ms_per_s'] = 1e3 * (time.process_time() - c0) / max(s.sim_time_s, 1e-9)
            row[f'{label}_load'] = os.getloadavg()[0]
            if s.monitor is not None:
                row['checks'], row['skipped_checks'] = s.monitor['checks'], s.monitor['skipped_checks']
        row['ratio'] = row['with_real_time_factor'] / row['without_real_time_factor']
        row['cpu_ratio'] = row['without_main_cpu_ms_per_s'] / row['with_main_cpu_ms_per_s']
        rows.append(row)
    med = {k: float(np.median([r[k] for r in rows])) for k in rows[0]}
    return {
        'duration_s': duration_s,
        'pairs': pairs,
        'speed_kept': med['ratio'],
        'speed_kept_each': [r['ratio'] for r in rows],
        'cpu_speed_kept': med['cpu_ratio'],
        'cpu_speed_kept_each': [r['cpu_ratio'] for r in rows],
        'main_cpu_ms_per_s': {'without': med['without_main_cpu_ms_per_s'], 'with': med['with_main_cpu_ms_per_s']},
        'load': [
            min(min(r['without_load'], r['with_load']) for r in rows),
            max(max(r['without_load'], r['with_load']) for r in rows),
        ],
        'rows': rows,
    }


def twin_cost(run: Any, repeats: int = 3) -> dict[str, Any]:
    """The monitor's own work per sample, without checks: a recording fed sample by sample (two commands, two
    temperatures, an angle at each stamp) as twin_monitor feeds it, the twin's predictions read at 10 Hz (best of
    ``repeats``, CPU time)."""
    from sma_wrist.monitor import Monitor, MonitorConfig

    best = float('inf')
    for _ in range(repeats):
        m = Monitor(MonitorConfig(check_period_s=1e9))
        m.payload(run.payload_kg)
        t, u, T, q = run.t.tolist(), run.u.tolist(), run.T.tolist(), run.q.tolist()
        c0 = time.process_time()
        for k in range(len(t)):
            m.command(1, t[k], u[k][0])
            m.command(2, t[k], u[k][1])
            m.temperature(1, t[k], T[k][0])
            m.temperature(2, t[k], T[k][1])
            m.angle(t[k], q[k])
            if k % 10 == 0:
                m.residuals()
        best = min(best, time.process_time() - c0)
    return {'us_per_sample': 1e6 * best / len(t), 'core_fraction_at_100_hz': best / max(run.duration, 1e-9)}


def bench_monitor(quick: bool = False) -> dict[str, Any]:
    """The benchmark section: detection, false alarms over 30 min per controller, cost."""
    from sma_wrist.diagnose.bench import CONTROLLERS, record_clean_runs
    from sma_wrist.diagnose.data import load_run

    long_s = 240.0 if quick else 1800.0
    directory = os.environ.get('SMA_WRIST_BENCH_DIR', tempfile.mkdtemp(prefix='sma_wrist_monitor_'))
    ctrls = ('pid',) if quick else CONTROLLERS
    bags = record_clean_runs(directory, ctrls, long_s)
    runs = {c: load_run(b) for c, b in bags.items()}
    out: dict[str, Any] = {'recordings': {c: f'{long_s:g} s closed loop, plant_sim 0.3 kg' for c in ctrls}}
    out['detection'] = detection(runs, ONSET_S + DETECT_WITHIN_S + 5.0)
    out['emulated_detection'] = emulated_detection(EMULATED_EFFECTS[:2] if quick else EMULATED_EFFECTS)
    out['false_alarms'] = false_alarms(runs, with_diagnose=not quick)
    out['graph_speed'] = graph_speed(120.0 if quick else 300.0, pairs=1 if quick else 5)
    fa = out['false_alarms']['rows']
    out['cost'] = {
        'check_cpu_s': float(np.mean([r['check_cpu_s'] for r in fa])),
        'core_fraction_at_100_hz': float(np.mean([r['core_fraction'] for r in fa])),
        'twin_cpu_per_s_of_data': float(np.mean([r['twin_cpu_s'] / r['duration_s'] for r in fa])),
        'feeding': twin_cost(next(iter(runs.values()))),
    }
    return out
