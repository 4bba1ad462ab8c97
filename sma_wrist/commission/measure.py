"""How well the bring-up names wiring faults, measured on emulated devices (doc/explanation/commissioning.md).

``python3 -m sma_wrist.commission.measure [--seeds N] [--rate-hz HZ]`` runs the bring-up (in lockstep with the
emulated device) on every wiring fault alone, on each channel, on the model and the phase-fraction wrist, with
quiet (2 counts) and noisy (25 counts: 0.1 degC, 2.5 mrad) sensors; and on devices without a fault that are not
the model. It prints one JSON object: per case the faults named, the largest |drive| the device received and the
device time.
``--cases identify`` runs the whole procedure (bring-up, excitation, identification) on the devices of
:data:`IDENTIFY` and prints the identified values against the device's truth, the held-out errors of the
commissioned and the built-in model, the device time and the wall time.
``--cases prefilter`` commissions the first device of :data:`DEVICES` and runs three cycles of the sine with its params
file at each TEM target prefilter and with the defaults, on fresh devices of two sensor seeds (:func:`measure_prefilter`).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

FAULTS: dict[str, tuple[dict[str, Any], list[tuple[str, int | None]]]] = {
    'tem_polarity 1': ({'tem_polarity_swapped': (True, False)}, [('tem_polarity', 1)]),
    'tem_polarity 2': ({'tem_polarity_swapped': (False, True)}, [('tem_polarity', 2)]),
    'tem_channels_swapped': ({'tem_channels_swapped': True}, [('tem_channels_swapped', None)]),
    'thermocouples_swapped': ({'thermocouples_swapped': True}, [('thermocouples_swapped', None)]),
    'angle_reversed': ({'angle_reversed': True}, [('angle_reversed', None)]),
    'broken wire 1': ({'broken_wire': 1}, [('muscle_not_moving', 1)]),
    'broken wire 2': ({'broken_wire': 2}, [('muscle_not_moving', 2)]),
}
HEALTHY: dict[str, dict[str, Any]] = {
    'model': {},
    'phase-fraction wire': {'plant': 'phase_fraction'},
    'wire 8 degC hotter': {'plant': 'sdgpi', 'scenario': {'transition_shift_C': 8.0}},
    'wire 8 degC colder': {'plant': 'sdgpi', 'scenario': {'transition_shift_C': -8.0}},
    'TEMs 0.8 x': {'plant': 'sdgpi', 'scenario': {'tem_gain_scale': 0.8}},
    'heavy payload 0.6 kg': {'plant': 'phase_fraction', 'payload_kg': 0.6},
    # weak but healthy: the muscle turns the joint only after a minute or more at the bring-up's 20 V
    'TEMs 0.6 x, wire 10 degC hotter': {
        'plant': 'sdgpi',
        'scenario': {'tem_gain_scale': 0.6, 'transition_shift_C': 10.0},
    },
    'phase-fraction wire, TEMs 0.6 x, 10 degC hotter': {
        'plant': 'phase_fraction',
        'scenario': {'tem_gain_scale': 0.6, 'transition_shift_C': 10.0},
    },
}


#: devices for the identification (the payload is never given to commissioning): {name: (emulator config, truth)}
IDENTIFY: dict[str, tuple[dict[str, Any], dict[str, float]]] = {
    'phase-fraction wrist, wire +8 degC, TEM 1 0.8 x, 0.5 kg': (
        {
            'plant': 'phase_fraction',
            'scenario': {'transition_shift_C': 8.0},
            'tem_drive_scale': (0.8, 1.0),
            'payload_kg': 0.5,
        },
        {'transition_shift_C': 8.0, 'tem1_gain_relative_to_tem2': 0.8, 'payload_kg': 0.5},
    ),
    'phase-fraction wrist, nominal': (
        {'plant': 'phase_fraction'},
        {'transition_shift_C': 0.0, 'tem1_gain_relative_to_tem2': 1.0, 'payload_kg': 0.3},
    ),
    'phase-fraction wrist, wire +8 degC, TEM 1 0.8 x, 0.3 kg': (
        {'plant': 'phase_fraction', 'scenario': {'transition_shift_C': 8.0}, 'tem_drive_scale': (0.8, 1.0)},
        {'transition_shift_C': 8.0, 'tem1_gain_relative_to_tem2': 0.8, 'payload_kg': 0.3},
    ),
    'phase-fraction wrist, nominal, 0.5 kg': (
        {'plant': 'phase_fraction', 'payload_kg': 0.5},
        {'transition_shift_C': 0.0, 'tem1_gain_relative_to_tem2': 1.0, 'payload_kg': 0.5},
    ),
    'SD-GPI wire +8 degC, TEM 1 0.8 x, 0.5 kg': (
        {'plant': 'sdgpi', 'scenario': {'transition_shift_C': 8.0}, 'tem_drive_scale': (0.8, 1.0), 'payload_kg': 0.5},
        {'transition_shift_C': 8.0, 'tem1_gain_relative_to_tem2': 0.8, 'payload_kg': 0.5},
    ),
    'model (nominal)': ({}, {'transition_shift_C': 0.0, 'tem1_gain_relative_to_tem2': 1.0, 'payload_kg': 0.3}),
    # devices the warped wire was not designed on: another phase-fraction wire, and the built-in SD-GPI warped
    # (``wire_warp``: :class:`sma_wrist.core.hysteresis.warp.Warp` of the emulated wire, its stress dependence kept)
    'phase-fraction wrist, wire -4 degC, stroke 0.8 x, 0.35 kg': (
        {'plant': 'phase_fraction', 'scenario': {'transition_shift_C': -4.0, 'stroke_scale': 0.8}, 'payload_kg': 0.35},
        {'transition_shift_C': -4.0, 'tem1_gain_relative_to_tem2': 1.0, 'payload_kg': 0.35},
    ),
    'SD-GPI wire warped (heating +6, cooling +10 degC, width 1.3 x, stroke 0.9 x), 0.4 kg': (
        {'wire_warp': (6.0, 10.0, 1.3, 0.9, 1.0), 'payload_kg': 0.4},
        {'transition_shift_C': 8.0, 'tem1_gain_relative_to_tem2': 1.0, 'payload_kg': 0.4},
    ),
}


def emulator_config(cfg: dict[str, Any], **kw: Any) -> Any:
    """The EmulatorConfig of a device of :data:`IDENTIFY` (a ``wire_warp`` made the emulated wrist's wire)."""
    from sma_wrist.hw.emulator import EmulatorConfig

    cfg = dict(cfg)
    warp = cfg.pop('wire_warp', None)
    if warp is not None:
        from sma_wrist.core.hysteresis.default_params import default_sdgpi
        from sma_wrist.core.hysteresis.warp import Warp, warped_wire
        from sma_wrist.core.plant.wrist import PlantParams

        cfg['base'] = PlantParams(hysteresis=warped_wire(default_sdgpi(), Warp(*warp)))
    return EmulatorConfig(**cfg, **kw)


def measure_identification(rate_hz: float = 1000.0) -> dict[str, Any]:
    """The identification table of doc/howto/commission.md: per device the identified values and their truth."""
    from sma_wrist.commission.device import SimDevice
    from sma_wrist.commission.run import commission

    rows: dict[str, Any] = {}
    with tempfile.TemporaryDirectory() as d:
        for name, (cfg, truth) in IDENTIFY.items():
            t0 = time.time()
            res = commission(f'{d}/{len(rows)}', SimDevice(emulator_config(cfg, rate_hz=rate_hz)))
            ident = res.get('identified') or {}
            found = {
                'transition_shift_C': ident.get('hysteresis', {}).get('parameters', {}).get('transition_shift_C'),
                'tem1_gain_relative_to_tem2': ident.get('thermal', {})
                .get('parameters', {})
                .get('tem1_gain_relative_to_tem2'),
                'payload_kg': ident.get('joint', {}).get('parameters', {}).get('payload_kg'),
                'payload_identified': ident.get('joint', {}).get('parameters', {}).get('payload_identified'),
                # the compensator's SD-GPI candidate, and the model's wire (the SD-GPI or the phase-fraction wire)
                'wire_model': ident.get('hysteresis', {}).get('parameters', {}).get('wire_model'),
                'model_wire': ident.get('hysteresis', {}).get('parameters', {}).get('model_wire'),
                'heat_balance_form': 'peltier' if ident.get('heat_balance', {}).get('handed_over') else 'table_4_9',
                'warp': ident.get('hysteresis', {}).get('parameters', {}).get('warp'),
                'preload_elongation_mm': ident.get('joint', {}).get('parameters', {}).get('preload_elongation_mm'),
                'coulomb_Nm': ident.get('joint', {}).get('parameters', {}).get('coulomb_Nm'),
            }
            rows[name] = {
                'status': res['status'],
                'identified': found,
                'truth': truth,
                'heldout': {k: {**v['heldout'], 'handed_over': v.get('handed_over')} for k, v in ident.items()},
                'device_time_s': res['device_time_s'],
                'excitation_s': res['steps'].get('excite', {}).get('device_time_s'),
                'wall_s': round(time.time() - t0, 1),
                'warnings': res['warnings'],
            }
    return {'rate_hz': rate_hz, 'cases': rows}


def _one(cfg: dict[str, Any], out: str) -> dict[str, Any]:
    from sma_wrist.commission.device import SimDevice
    from sma_wrist.commission.run import commission
    from sma_wrist.hw.emulator import EmulatorConfig

    dev = SimDevice(EmulatorConfig(**cfg))
    res = commission(out, dev, bring_up_only=True)
    return {
        'named': [(f['kind'], f['channel']) for f in res['faults']],
        'status': res['status'],
        'device_max_drive_V': dev.emulator.stats.max_abs_command_V,
        'device_time_s': res['device_time_s'],
    }


def measure(seeds: int = 3, rate_hz: float = 1000.0, cases: str = 'all') -> dict[str, Any]:
    """The table of doc/howto/commission.md: {case: {runs, named_right, false_faults, max drive, device time}}."""
    rows: dict[str, Any] = {}
    t0 = time.time()
    with tempfile.TemporaryDirectory() as d:
        for name, (fault, expected) in FAULTS.items() if cases in ('all', 'faults') else ():
            for plant in ('model', 'phase_fraction'):
                runs = [
                    _one({'plant': plant, 'seed': s, 'rate_hz': rate_hz, 'noise_counts': noise, **fault}, d)
                    for s in range(seeds)
                    for noise in (2.0, 25.0)
                ]
                rows[f'{name}, {plant}'] = {
                    'runs': len(runs),
                    'named_right': sum(sorted(r['named'], key=str) == sorted(expected, key=str) for r in runs),
                    'max_device_drive_V': max(r['device_max_drive_V'] for r in runs),
                    'device_time_s': [min(r['device_time_s'] for r in runs), max(r['device_time_s'] for r in runs)],
                }
        for name, cfg in HEALTHY.items() if cases in ('all', 'healthy') else ():
            runs = [
                _one({'seed': s, 'rate_hz': rate_hz, 'noise_counts': noise, **cfg}, d)
                for s in range(seeds)
                for noise in (2.0, 25.0)
            ]
            rows[f'no fault, {name}'] = {
                'runs': len(runs),
                'false_faults': sum(bool(r['named']) for r in runs),
                'commissioned': sum(r['status'] == 'commissioned' for r in runs),
                'max_device_drive_V': max(r['device_max_drive_V'] for r in runs),
                'device_time_s': [min(r['device_time_s'] for r in runs), max(r['device_time_s'] for r in runs)],
            }
    return {'seeds': seeds, 'rate_hz': rate_hz, 'wall_s': round(time.time() - t0, 1), 'cases': rows}


#: the whole procedure (bring-up, verification) on these devices; none gets an option beyond its port and folder
DEVICES: dict[str, dict[str, Any]] = {
    # a wire that is not the model's, transforming 8 degC hotter, TEM 1 20 % weaker per volt, a payload of 0.45 kg
    # that the command line does not give (the params file keeps config/wrist.yaml's 0.3 kg)
    'phase-fraction wire 8 degC hotter, TEM 1 0.8x, 0.45 kg not given': {
        'plant': 'phase_fraction',
        'scenario': {'transition_shift_C': 8.0},
        'tem_drive_scale': (0.8, 1.0),
        'payload_kg': 0.45,
    },
    # the model's own wire, transforming 8 degC hotter: its top beyond what the TEMs' 80 degC reach
    'SD-GPI wire 8 degC hotter, TEM 1 0.8x, 0.5 kg not given': {
        'plant': 'sdgpi',
        'scenario': {'transition_shift_C': 8.0},
        'tem_drive_scale': (0.8, 1.0),
        'payload_kg': 0.5,
    },
    'nominal (the model)': {},
}


def whole_procedure(quick: bool = False, seed: int = 11, progress: Any = None) -> dict[str, Any]:
    """``commission`` on each of :data:`DEVICES` (the emulated device, its 1 kHz) with verification: device time,
    faults, defaults against commissioned per controller (the mean of each side's cycles and their spread, the
    verdict, what the commissioned parameters change; ``commissioned_worse``: the controllers whose verdict is
    ``worse``, beyond the spread), each run's start and cycles, the diagnosis' verdict. ``quick``: the params file's
    controller only, else all three (beyond the 15 min then: six runs)."""
    from sma_wrist.commission.device import SimDevice
    from sma_wrist.commission.run import commission
    from sma_wrist.commission.verify import CONTROLLERS, VerifyOptions
    from sma_wrist.hw.emulator import EmulatorConfig

    rows: dict[str, Any] = {}
    opts = VerifyOptions(controllers=None if quick else CONTROLLERS)
    with tempfile.TemporaryDirectory() as d:
        for k, (name, cfg) in enumerate(DEVICES.items()):
            t0 = time.time()
            dev = SimDevice(EmulatorConfig(seed=seed, **cfg))
            res = commission(f'{d}/{k}', dev, verification=opts, progress=progress)
            v = res.get('verification') or {}
            comparison = v.get('comparison', {})
            worse = [c for c, x in comparison.items() if x.get('verdict') == 'worse']
            diag = v.get('diagnosis') or {}
            rows[name] = {
                'status': res['status'],
                'device_time_s': res['device_time_s'],
                'bring_up_s': res['steps'] and round(res['device_time_s'] - v.get('device_time_s', 0.0), 1),
                'verification_s': v.get('device_time_s'),
                'faults': [(f['kind'], f['channel']) for f in res['faults']],
                'warnings': res['warnings'],
                'identified': sorted(res.get('identified') or {}),
                'default': v.get('default'),
                'commissioned': v.get('commissioned'),
                'verdict': {c: x.get('verdict') for c, x in comparison.items()},
                'differs': {c: x.get('differs') for c, x in comparison.items()},
                'commissioned_worse': worse,
                'runs': [
                    {k: r.get(k) for k in ('controller', 'parameters', 'start', 'start_up', 'cycles', 'device_s')}
                    for r in v.get('runs', [])
                ],
                'settle_s': v.get('settle_s'),
                'diagnosis': None
                if not diag
                else diag.get('error') or ('no discrepancy' if not diag['discrepancy'] else diag['summary']),
                'diagnosis_residual': diag.get('residual'),
                # the model wire's refinement on the defaults run: its held-out errors on the commissioned run
                'refinement': v.get('refinement'),
                'thermal': {
                    k: (res.get('identified') or {}).get('thermal', {}).get(k) for k in ('handed_over', 'heldout')
                }
                | {
                    k: (res.get('identified') or {}).get('thermal', {}).get('parameters', {}).get(k)
                    for k in ('tem_gain', 'hold_limits_V')
                },
                # the model's heat balance: the Peltier form where it predicts the held-out cycle better
                'heat_balance': {
                    k: (res.get('identified') or {}).get('heat_balance', {}).get(k) for k in ('handed_over', 'heldout')
                },
                'device_max_drive_V': dev.emulator.stats.max_abs_command_V,
                'wall_s': round(time.time() - t0, 1),
            }
    return rows


def loop_run(cfg: dict[str, Any], params_file: str | Path, seed: int, cycles: int = 3) -> dict[str, Any]:
    """The Sec. 6.1 sine (inverse_adaptive, run's soft start, ``cycles`` full cycles) with ``params_file`` on a
    fresh emulated device of ``cfg`` (its wrist at rest), run as the verification runs it: per cycle max / RMS
    error [%]."""
    from sma_wrist import runtime

    runtime.activate()
    from sma_wrist.commission.device import SimDevice
    from sma_wrist.commission.verify import SIM_BRIDGE, SOFT_START_S, cycle_metrics, run_on_port, run_settings
    from sma_wrist.core.metrics import SEED_PERIOD_S

    duration = round(SOFT_START_S + cycles * SEED_PERIOD_S + 2.0, 1)
    dev = SimDevice(emulator_config(cfg, seed=seed))
    dev.open()
    dev.close()
    payload, soft = run_settings([params_file])
    with tempfile.TemporaryDirectory() as tmp:
        with dev.serve(f'{tmp}/wrist', 2.0) as port:
            s = run_on_port(port, 'inverse_adaptive', [params_file], payload, soft, duration, bridge=SIM_BRIDGE)
    return cycle_metrics(s.run, duration, soft) if s.run is not None else {'cycles': [], 'start_up': None}


def measure_prefilter(
    filters: tuple[float, ...] = (0.5, 1.0, 2.0, 3.0, 4.0), seeds: tuple[int, ...] = (11, 12), progress: Any = None
) -> dict[str, Any]:
    """The prefilter table of doc/howto/commission.md: device (a) of :data:`DEVICES` commissioned (seed 11, no
    verification), then its params file with each ``tem_controller.target_filter_s`` of ``filters``, and the
    defaults, on fresh devices of each sensor seed: {parameters: {seed: cycles}}."""
    import yaml

    from sma_wrist.commission.device import SimDevice
    from sma_wrist.commission.run import commission
    from sma_wrist.commission.verify import write_defaults

    say = progress or (lambda text: None)
    cfg = next(iter(DEVICES.values()))
    rows: dict[str, Any] = {}
    with tempfile.TemporaryDirectory() as d:
        res = commission(f'{d}/a', SimDevice(emulator_config(cfg, seed=11)))
        if res['status'] != 'commissioned':
            return {'status': res['status'], 'faults': res['faults']}
        params = yaml.safe_load(Path(res['params_file']).read_text())
        files = {'defaults': str(write_defaults(Path(d) / 'defaults.yaml', res['bridge_params']))}
        for f in filters:
            p = dict(params)
            p['tem_controller'] = {
                'ros__parameters': {**params['tem_controller']['ros__parameters'], 'target_filter_s': f}
            }
            filter_file = Path(d) / f'filter_{f:g}.yaml'
            filter_file.write_text(yaml.safe_dump(p, sort_keys=False))
            files[f'commissioned, target_filter_s {f:g}'] = str(filter_file)
        for name, path in files.items():
            for seed in seeds:
                say(f'{name}, seed {seed}')
                rows.setdefault(name, {})[seed] = loop_run(cfg, path, seed)['cycles']
    return {'handed_over': params['tem_controller']['ros__parameters'].get('target_filter_s'), 'runs': rows}


def bench_commission(quick: bool = False) -> dict[str, Any]:
    """``sma-wrist bench --section commission``: the whole procedure on the devices of :data:`DEVICES`, and the
    wiring-fault matrix (:func:`measure`, one seed; 250 Hz with ``quick``)."""
    import sys

    def say(text: str) -> None:
        print(f'[commission] {text}', file=sys.stderr, flush=True)

    devices = whole_procedure(quick, progress=say)
    say('wiring-fault matrix')
    m = measure(1, 250.0 if quick else 1000.0)
    faults = [r for k, r in m['cases'].items() if not k.startswith('no fault')]
    healthy = [r for k, r in m['cases'].items() if k.startswith('no fault')]
    return {
        'devices': devices,
        'fault_matrix': {
            'named_right': f'{sum(r["named_right"] for r in faults)} / {sum(r["runs"] for r in faults)}',
            'false_faults': f'{sum(r["false_faults"] for r in healthy)} / {sum(r["runs"] for r in healthy)}',
            'max_device_drive_V': max(r['max_device_drive_V'] for r in m['cases'].values()),
            'rate_hz': m['rate_hz'],
            'cases': m['cases'],
        },
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog='python3 -m sma_wrist.commission.measure', description=__doc__.split('\n')[0])
    ap.add_argument('--seeds', type=int, default=3)
    ap.add_argument('--rate-hz', type=float, default=1000.0)
    ap.add_argument('--cases', choices=('all', 'faults', 'healthy', 'identify', 'prefilter'), default='all')
    a = ap.parse_args(argv)
    if a.cases == 'prefilter':
        doc = measure_prefilter(progress=lambda text: print(f'[prefilter] {text}', file=sys.stderr, flush=True))
    else:
        doc = measure_identification(a.rate_hz) if a.cases == 'identify' else measure(a.seeds, a.rate_hz, a.cases)
    print(json.dumps(doc, indent=1))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
