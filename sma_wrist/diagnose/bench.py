"""Benchmark of the diagnosis: accuracy over many hidden-effect runs, and the wall time of a
10-minute, 100 Hz bag (``sma-wrist bench --section diagnose``).

Accuracy: every catalogue effect at random magnitudes and seeds (:mod:`.testdata`), plus
clean runs. A case is *correct* when the named cause is the injected one; the magnitude
error is the largest relative error over the injected parameters; a *false alarm* is a
clean run reported as a discrepancy.
"""
from __future__ import annotations

import os
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import numpy as np

from sma_wrist.diagnose import effects as fx
from sma_wrist.diagnose import testdata as td


def _case(args: tuple[str, int, float]) -> dict[str, Any]:
    from sma_wrist.diagnose import diagnose_run
    effect, seed, duration = args
    truth = td.simulate(effect, seed=seed, duration_s=duration)
    t0 = time.perf_counter()
    res = diagnose_run(td.run_from_truth(truth))
    wall = time.perf_counter() - t0
    rel = [abs(res.parameters[k]['value'] - v) / abs(v) for k, v in truth.params.items()
           if res.cause == effect and k in res.parameters]
    return {'effect': effect, 'seed': seed, 'cause': res.cause, 'discrepancy': res.discrepancy,
            'unexplained': res.unexplained, 'gain_pct': res.gain_pct,
            'magnitude_rel_err': max(rel) if rel else None, 'wall_s': wall}


def accuracy(seeds_per_effect: int = 3, clean_runs: int = 10, duration_s: float = 240.0, workers: int = 2,
             first_seed: int = 1000) -> dict[str, Any]:
    """Diagnose many synthetic runs in parallel processes; accuracy, false alarms, magnitude error."""
    cases = [(e.id, first_seed + i, duration_s) for e in fx.CATALOGUE for i in range(seeds_per_effect)]
    cases += [('none', first_seed + 500 + i, duration_s) for i in range(clean_runs)]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=workers) as ex:
        rows = list(ex.map(_case, cases))
    wall = time.perf_counter() - t0
    eff = [r for r in rows if r['effect'] != 'none']
    clean = [r for r in rows if r['effect'] == 'none']
    mags = np.array([r['magnitude_rel_err'] for r in eff if r['magnitude_rel_err'] is not None])
    wrong = [f"{r['effect']}(seed {r['seed']})->{r['cause']}" for r in eff if r['cause'] != r['effect']]
    per_effect = {e.id: sum(r['cause'] == e.id for r in eff if r['effect'] == e.id) / seeds_per_effect
                  for e in fx.CATALOGUE}
    return {
        'cases': len(rows), 'duration_per_run_s': duration_s, 'workers': workers, 'wall_s': wall,
        'cause_accuracy': sum(r['cause'] == r['effect'] for r in eff) / max(len(eff), 1),
        'magnitude_within_15pct': float(np.mean(mags <= 0.15)) if mags.size else None,
        'magnitude_rel_err_median': float(np.median(mags)) if mags.size else None,
        'magnitude_rel_err_max': float(np.max(mags)) if mags.size else None,
        'positive_gain': sum(r['gain_pct'] > 0 for r in eff if r['cause'] == r['effect']) / max(len(eff), 1),
        'false_alarm_rate': sum(r['discrepancy'] for r in clean) / max(len(clean), 1),
        'unexplained_flag_rate_on_correct': (sum(r['unexplained'] for r in eff if r['cause'] == r['effect'])
                                             / max(sum(r['cause'] == r['effect'] for r in eff), 1)),
        'diagnose_wall_s_per_run_median': float(np.median([r['wall_s'] for r in rows])),
        'per_effect_accuracy': per_effect, 'misses': wrong,
    }


def ten_minute_bag(duration_s: float = 600.0, effect: str = 'thermal_coupling', seed: int = 7) -> dict[str, Any]:
    """Wall time of ``diagnose`` on a recorded 100 Hz bag (loading included), one process."""
    from sma_wrist.diagnose import diagnose
    with tempfile.TemporaryDirectory() as d:
        bag = os.path.join(d, 'measured')
        truth = td.make_bag(bag, effect, seed=seed, duration_s=duration_s)
        t0 = time.perf_counter()
        res = diagnose(bag)
        wall = time.perf_counter() - t0
    return {'run_s': duration_s, 'rate_hz': 1.0 / truth.dt, 'samples': int(truth.t.size), 'wall_s': wall,
            'cause_found': res.cause == effect}


def bench_diagnose(quick: bool = False) -> dict[str, Any]:
    if quick:
        return {'accuracy': accuracy(seeds_per_effect=1, clean_runs=2, duration_s=120.0),
                'bag': ten_minute_bag(duration_s=120.0)}
    return {'accuracy': accuracy(), 'bag': ten_minute_bag()}
