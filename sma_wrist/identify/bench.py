"""Benchmark section ``identify``: fit speed and quality, exact Jacobian vs the earlier fits.

Runs in a subprocess pinned to one core with single-threaded BLAS (a fit's cost on one core),
each case timed for ``method='exact'`` (today) and ``method='fd'`` (the finite-difference
fits this replaced) side by side in that process, on the same data:

* ``gpi_500``: one GPI, 500 samples of a synthetic loop (a known SD-GPI + 0.5 % noise);
* ``gpi_real``: one GPI on the measured NiTiHf loop at 300 MPa (test/data/sma_react, 400 samples);
* ``sdgpi_5_real``: the SD-GPI over the five NiTiHf stresses 50-400 MPa;
* ``gpi_1e4`` / ``sdgpi_5x1e4``: 1e4 samples per load, today's fits only (the old code's
  finite differences cost 20 simulations of 1e4 samples per Jacobian: tens of minutes).

``quick`` skips the old SD-GPI fit (minutes).

Each time is given as wall seconds (``*_s``) and this process's CPU seconds (``*_cpu_s``:
what one core costs while other jobs share the machine; the load average at start and end
is recorded). Quality is the residual in % of the stroke (and, on synthetic data, the error against the
known loop); a faster fit that fits worse would show here.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

DATA = Path(__file__).resolve().parents[2] / 'test' / 'data' / 'sma_react' / 'NiTiHf'


def _synthetic(n: int, load: float = 0.85) -> tuple[Any, Any, Any]:
    from sma_wrist.core.hysteresis.default_params import default_sdgpi
    from sma_wrist.core.hysteresis.sdgpi import simulate

    T = np.r_[np.linspace(20, 90, n // 2), np.linspace(90, 20, n - n // 2)]
    y0 = simulate(default_sdgpi(), T, load)
    y = y0 + np.random.default_rng(0).normal(0, 0.005 * np.ptp(y0), n)
    return T, y, y0


def _real(stresses: tuple[int, ...]) -> tuple[list[Any], list[Any], Any, list[str]]:
    from sma_wrist.identify.io import REF_LENGTH_MM, read_measurement, stress_to_load_kgf
    from sma_wrist.identify.segment import loops_of

    loops = [loops_of(read_measurement(DATA / f'{s}MPa.txt'))[0] for s in stresses]
    return (
        [lp.T_C for lp in loops],
        [lp.strain * REF_LENGTH_MM for lp in loops],
        np.array([stress_to_load_kgf(lp.stress_MPa) for lp in loops]),
        [lp.init_branch for lp in loops],
    )


def _timed(fn: Any) -> tuple[Any, float, float]:
    """Result, wall seconds and this process's CPU seconds (the one-core figure when others load the machine)."""
    t0, c0 = time.perf_counter(), time.process_time()
    r = fn()
    return r, time.perf_counter() - t0, time.process_time() - c0


def measure(quick: bool) -> dict[str, Any]:
    """All cases in this process (call through :func:`bench_identify` for the one-core set-up)."""
    from sma_wrist.core.hysteresis.identification import fit_gpi, fit_sdgpi, simulate_batch
    from sma_wrist.identify.hysteresis import choose_edges

    out: dict[str, Any] = {'loadavg_start': list(os.getloadavg())}
    fit_gpi(*_synthetic(60)[:2], n_starts=1, max_nfev=2)  # compile the numba kernel outside the timings

    def gpi_case(T: Any, y: Any, y0: Any | None, branch: str, methods: tuple[str, ...]) -> dict[str, Any]:
        row: dict[str, Any] = {'samples': int(T.size)}
        for m in methods:
            r, dt, cpu = _timed(lambda: fit_gpi(T, y, branch=branch, method=m))
            row[f'{m}_s'], row[f'{m}_cpu_s'] = dt, cpu
            row[f'{m}_residual_pct'] = r.residual_std_pct
            if y0 is not None:
                ys = simulate_batch(T, r.theta[None], branch=branch)[:, 0]
                row[f'{m}_error_vs_truth_pct'] = float(100 * np.std(ys - y0) / np.ptp(y0))
        if 'fd' in methods:
            row['speedup'], row['speedup_cpu'] = row['fd_s'] / row['exact_s'], row['fd_cpu_s'] / row['exact_cpu_s']
        return row

    both = ('exact', 'fd')
    T, y, y0 = _synthetic(500)
    out['gpi_500'] = gpi_case(T, y, y0, 'cooling', both)
    Ts, ys, loads, br = _real((300,))
    out['gpi_real'] = gpi_case(Ts[0], ys[0], None, br[0], both)
    T, y, y0 = _synthetic(10_000)
    out['gpi_1e4'] = gpi_case(T, y, y0, 'cooling', ('exact',))  # the old code: tens of minutes

    def sd_case(Ts: list[Any], ys: list[Any], loads: Any, br: list[str], methods: tuple[str, ...]) -> dict[str, Any]:
        edges = choose_edges(loads)
        row: dict[str, Any] = {'loads': int(loads.size), 'samples_per_load': int(np.mean([t.size for t in Ts]))}
        for m in methods:
            r, dt, cpu = _timed(lambda: fit_sdgpi(Ts, ys, loads, edges, branches=br, method=m))
            row[f'{m}_s'], row[f'{m}_cpu_s'] = dt, cpu
            row[f'{m}_residual_pct'] = r.residual_std_pct
        if 'fd' in methods:
            row['speedup'], row['speedup_cpu'] = row['fd_s'] / row['exact_s'], row['fd_cpu_s'] / row['exact_cpu_s']
        return row

    Ts, ys, loads, br = _real((50, 100, 200, 300, 400))
    out['sdgpi_5_real'] = sd_case(Ts, ys, loads, br, ('exact',) if quick else both)
    # 1e4 samples per load: the measured loops resampled along their own path (same extrema)
    Tl, yl = [], []
    for T, y in zip(Ts, ys):
        s = np.linspace(0, T.size - 1, 10_000)
        Tl.append(np.interp(s, np.arange(T.size), T))
        yl.append(np.interp(s, np.arange(T.size), y))
    out['sdgpi_5x1e4'] = sd_case(Tl, yl, loads, br, ('exact',))
    out['targets_s'] = {'gpi_500': 2.0, 'sdgpi_5': 10.0, 'per_load_1e4': 5.0}
    out['loadavg_end'] = list(os.getloadavg())
    return out


def bench_identify(quick: bool = False) -> dict[str, Any]:
    """Run :func:`measure` in a subprocess on one core with single-threaded BLAS."""
    env = dict(os.environ, OMP_NUM_THREADS='1', OPENBLAS_NUM_THREADS='1', MKL_NUM_THREADS='1', NUMBA_NUM_THREADS='1')
    cmd = [sys.executable, '-m', 'sma_wrist.identify.bench'] + (['--quick'] if quick else [])
    p = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
    if p.returncode != 0:
        raise RuntimeError(f'identify benchmark failed: {p.stderr.strip().splitlines()[-1:]}')
    return json.loads(p.stdout)


def _main() -> int:
    if hasattr(os, 'sched_setaffinity'):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[-1]})
    print(json.dumps(measure('--quick' in sys.argv[1:])))
    return 0


if __name__ == '__main__':
    raise SystemExit(_main())
