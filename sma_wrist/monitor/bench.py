"""Benchmark of the live model monitor: ``sma-wrist bench --section monitor`` (doc/howto/monitor.md).

* **detection**: clean closed-loop recordings (plant_sim, 0.3 kg, embedded runtime) rewritten by the independent
  effect generator (:mod:`sma_wrist.diagnose.distort`) with an effect that begins at ``ONSET_S``, at the noise of
  the diagnosis' tests (0.1 degC / 1 mrad); a case is detected when the first verdict the monitor raises names the
  right subsystem within ``DETECT_WITHIN_S`` of the onset and nothing was raised before it;
* **false alarms**: long nominal recordings per controller read through realistic sensors
  (:func:`sma_wrist.diagnose.distort.realistic`, jittering stamps and dropped samples from the bag writer), played
  through the monitor as a bag; and ``diagnose`` on the same whole bags;
* **cost**: CPU per check, the twin's CPU per second of data, the monitor's share of one core at 100 Hz input,
  and the node graph's speed with and without ``twin_monitor``.
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
#: effects of the sizes the diagnosis' tests use: (kind, channel, value, unit, subsystem)
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
    ('dead_zone', 'u', 2.0, 'V', 'actuator'),  # a driver that stops passing small commands
)


def _detect_case(args: tuple) -> dict[str, Any]:
    run, effect, seed = args
    from sma_wrist.diagnose import distort as ds
    from sma_wrist.monitor.playback import monitor_run

    kind, ch, value, unit, subsystem = effect
    r = ds.apply(run, ds.Distortion(kind, ch, value, unit), 0.1, 1e-3, seed, onset_s=ONSET_S)
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


def detection(
    runs: dict[str, Any], duration_s: float = 210.0, seeds: tuple[int, ...] = (1,), workers: int = 2
) -> dict[str, Any]:
    """Every effect of :data:`EFFECTS` x run (the first ``duration_s`` of each) x seed."""
    cases = []
    for name, run in runs.items():
        n = int(round(duration_s / run.dt)) + 1
        cut = dataclasses.replace(run, t=run.t[:n], u=run.u[:n], T=run.T[:n], q=run.q[:n], valid=None, source=name)
        cases += [(cut, e, s) for e in EFFECTS for s in seeds]
    with ProcessPoolExecutor(workers) as pool:
        rows = list(pool.map(_detect_case, cases))
    ok = sum(r['detected'] for r in rows)
    delays = [r['delay_s'] for r in rows if r['detected']]
    return {
        'cases': len(rows),
        'within_s': DETECT_WITHIN_S,
        'detected': ok,
        'rate': ok / max(len(rows), 1),
        'first_subsystem_right': sum(r['first_subsystem'] == r['subsystem'] for r in rows),
        'missed': [(r['source'], r['effect'], r['first_subsystem'], r['delay_s']) for r in rows if not r['detected']],
        'false_before_onset': sum(r['false_before_onset'] for r in rows),
        'delay_s_median': float(np.median(delays)) if delays else None,
        'delay_s_max': float(np.max(delays)) if delays else None,
        'rows': rows,
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


def graph_speed(duration_s: float = 60.0, controller: str = 'pid') -> dict[str, Any]:
    """Wall time of the node graph on the embedded runtime without and with twin_monitor (worker process)."""
    from sma_wrist import runtime

    runtime.activate()
    import rclpy

    from sma_wrist.closed_loop import run_closed_loop

    out = {}
    for label, mon in (('without', None), ('with', {'worker': 'process'}), ('without_again', None)):
        try:
            s = run_closed_loop(controller, 0.3, duration_s, None, monitor=mon)
        finally:
            rclpy.try_shutdown()
        out[f'{label}_real_time_factor'] = s.real_time_factor
        if s.monitor is not None:
            out['checks'], out['skipped_checks'] = s.monitor['checks'], s.monitor['skipped_checks']
    base = 0.5 * (out['without_real_time_factor'] + out['without_again_real_time_factor'])
    out['speed_kept'] = out['with_real_time_factor'] / base
    return out


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
    out['detection'] = detection(runs, 210.0)
    out['false_alarms'] = false_alarms(runs, with_diagnose=not quick)
    out['graph_speed'] = graph_speed(20.0 if quick else 120.0)
    fa = out['false_alarms']['rows']
    out['cost'] = {
        'check_cpu_s': float(np.mean([r['check_cpu_s'] for r in fa])),
        'core_fraction_at_100_hz': float(np.mean([r['core_fraction'] for r in fa])),
        'twin_cpu_per_s_of_data': float(np.mean([r['twin_cpu_s'] / r['duration_s'] for r in fa])),
    }
    return out
