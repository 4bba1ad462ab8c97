"""Benchmarks as numbers: ``sma-wrist bench [--json] [--quick] [--section NAME ...]``.

Every section is a function ``(quick: bool) -> dict`` registered under a name in
:data:`SECTIONS` (use the :func:`section` decorator); :func:`run` calls the requested ones in
one process and returns ``{'meta': ..., name: result, ...}``. Other engineers add sections
('graph', 'experiment', 'diagnose', 'bridge') the same way: define the function in their
module and register it here, importing lazily inside it so a section costs nothing unless run.

Section 'plant' measures, in one run, the plant's steps per second:

* ``per_sample``: :class:`sma_wrist.core.plant.wrist.WristPlant` with one wrist (the node's path);
* ``batched``: the same class with >= 256 wrists (plant-steps/s = wrists x steps / s);
* ``plain``: :class:`PlainWrist`, the plant kernel's scalar-loop source run as plain Python
  (uncompiled): the textbook four-stage RK4, the same bracketed Newton load solve, the same
  joint update. It is the yardstick for the ratios ``batched/plain`` and ``per_sample/plain``
  and, through ``test/test_plant.py``, a check of the numpy plant's numbers;
* ``compiled_*``: the same kernel compiled by numba (optional extra ``fast``), as
  ``WristPlant.advance`` uses it.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from sma_wrist.outputs import BENCH_OUT_HELP, bench_png

SectionFn = Callable[[bool], dict]
#: name -> callable(quick) returning a JSON-serialisable dict
SECTIONS: dict[str, SectionFn] = {}


def section(name: str) -> Callable[[SectionFn], SectionFn]:
    """Register a benchmark section under ``name``."""

    def deco(fn: SectionFn) -> SectionFn:
        SECTIONS[name] = fn
        return fn

    return deco


# ------------------------------------------------------------------ the plain reference


class PlainWrist:
    """One wrist stepped by plain Python: the uncompiled source of the plant kernel.

    :func:`sma_wrist.core.plant.kernel.step_many_into` is written as scalar loops; its
    ``py_func`` (the function before numba compiles it, or the function itself without
    numba) is the plain per-sample Python reference loop: same equations, no numpy
    vectorisation, no compilation. Set-up (parameters, initial state) comes from
    :class:`WristPlant`; test_plant checks the numpy plant against it.
    """

    def __init__(self, params: object | None = None, payload_kg: float = 0.3) -> None:
        from sma_wrist.core.plant import kernel as plant_kernel
        from sma_wrist.core.plant.wrist import PlantParams, WristPlant

        p = params or PlantParams()
        s = WristPlant(p, payload_kg=payload_kg).state  # type: ignore[arg-type]
        self._state = [
            np.array(x, copy=True, order='C')
            for x in (s.thermal, s.q, s.qd, s.w, s.heating, s.T_prev, s.load_kgf, s.compliance, s.payload_kg)
        ]
        self._flags = np.zeros((1, 4), bool)
        self._consts = plant_kernel.pack_constants(p)
        self._u = np.zeros((1, 2))
        self._lim = (p.thermal.u_min_V, p.thermal.u_max_V)  # type: ignore[attr-defined]
        self._step = plant_kernel.step_many_into.py_func
        self._scratch = plant_kernel.scratch.py_func(self._state[3].shape[1])

    @property
    def q(self) -> float:
        return float(self._state[1][0])

    @property
    def T1(self) -> float:
        return float(self._state[0][0, 0, 0])

    def step(self, u1: float, u2: float) -> None:
        lo, hi = self._lim
        self._u[0, 0] = min(max(u1, lo), hi)
        self._u[0, 1] = min(max(u2, lo), hi)
        self._step(1, self._u, *self._state, self._flags, *self._consts, *self._scratch)


# ----------------------------------------------------------------------- plant section


def _command(k: int, dt: float) -> float:
    """A drive that keeps the wrist moving: 13 V sine of 2 s period."""
    return 13.0 * math.sin(2.0 * math.pi * k * dt / 2.0)


def _time_steps(step: Callable[[int], None], n_steps: int, repeats: int) -> float:
    """Best-of-``repeats`` wall time per step [s] over n_steps steps."""
    best = math.inf
    k0 = 0
    for _ in range(repeats):
        t0 = time.perf_counter()
        for k in range(k0, k0 + n_steps):
            step(k)
        best = min(best, (time.perf_counter() - t0) / n_steps)
        k0 += n_steps
    return best


@section('plant')
def bench_plant(quick: bool = False) -> dict:
    """Plant steps per second: per-sample, batched (>= 256 wrists) and the plain reference."""
    from sma_wrist.core.plant.wrist import PlantParams, WristPlant

    params = PlantParams()
    dt = params.dt
    n_single, n_batch, repeats = (300, 60, 2) if quick else (3000, 400, 3)
    batch_sizes = (256,) if quick else (256, 4096)

    single = WristPlant(params, payload_kg=0.3)
    u1 = np.zeros((1, 2))

    def step_single(k: int) -> None:
        a = _command(k, dt)
        u1[0, 0] = a
        u1[0, 1] = -a
        single.step(u1)

    per_sample = 1.0 / _time_steps(step_single, n_single, repeats)

    plain = PlainWrist(params, payload_kg=0.3)

    def step_plain(k: int) -> None:
        a = _command(k, dt)
        plain.step(a, -a)

    plain_rate = 1.0 / _time_steps(step_plain, n_single, repeats)

    batched: dict[str, float] = {}
    for n in batch_sizes:
        plant = WristPlant(params, payload_kg=np.linspace(0.0, 0.6, n))
        phase = np.linspace(0.0, 1.0, n)
        u = np.empty((n, 2))

        def step_batch(k: int) -> None:
            a = 13.0 * np.sin(2.0 * np.pi * (k * dt / 2.0 + phase))
            u[:, 0] = a
            u[:, 1] = -a
            plant.step(u)

        steps = max(20, n_batch * 256 // n)
        batched[str(n)] = n / _time_steps(step_batch, steps, repeats)
    compiled = _bench_compiled(params, n_single, repeats)
    best_batched = max(batched.values())
    best_path = 'numpy'
    if compiled.get('compiled_batched_256_plant_steps_per_s', 0.0) > best_batched:
        best_batched, best_path = compiled['compiled_batched_256_plant_steps_per_s'], 'compiled'
    return {
        **compiled,
        'best_batched_plant_steps_per_s': best_batched,
        'best_batched_path': best_path,
        'dt_s': dt,
        'per_sample_steps_per_s': per_sample,
        'per_sample_real_time_factor': per_sample * dt,
        'plain_reference_steps_per_s': plain_rate,
        'batched_plant_steps_per_s': batched,
        'ratio_batched_over_plain': best_batched / plain_rate,
        'ratio_per_sample_over_plain': per_sample / plain_rate,
    }


def _bench_compiled(params: object, n_steps: int, repeats: int) -> dict:
    """WristPlant.advance through the optional numba kernel (plant_kernel), when installed."""
    from sma_wrist.core import jit
    from sma_wrist.core.plant.wrist import WristPlant

    if not jit.AVAILABLE:
        return {'compiled_available': False}
    dt = params.dt  # type: ignore[attr-defined]
    out: dict = {'compiled_available': True}
    for n, key in ((1, 'compiled_per_sample_steps_per_s'), (256, 'compiled_batched_256_plant_steps_per_s')):
        plant = WristPlant(params, payload_kg=np.linspace(0.0, 0.6, n))  # type: ignore[arg-type]
        u = np.empty((n, 2))
        plant.advance(np.zeros((n, 2)), 1)  # compile / load the cache outside the timing

        def step(k: int, plant: WristPlant = plant, u: np.ndarray = u) -> None:
            a = _command(k, dt)
            u[:, 0] = a
            u[:, 1] = -a
            plant.advance(u, 1)

        out[key] = n / _time_steps(step, n_steps if n == 1 else max(20, n_steps // 10), repeats)
    plant = WristPlant(params, payload_kg=0.3)  # type: ignore[arg-type]
    plant.advance(np.zeros((1, 2)), 10)
    t0 = time.perf_counter()
    ticks = max(10, n_steps // 10)
    for k in range(ticks):  # the node's use: one call per 100 Hz tick of 10 steps
        a = _command(10 * k, dt)
        plant.advance(np.array([[a, -a]]), 10)
    out['compiled_tick_of_10_steps_per_s'] = 10 * ticks / (time.perf_counter() - t0)
    return out


@section('graph')
def bench_graph(quick: bool = False) -> dict:
    """The node graph on the embedded runtime (sma_wrist.closed_loop.bench_graph)."""
    from sma_wrist.closed_loop import bench_graph as run_graph

    return run_graph(quick)


@section('experiment')
def bench_experiment(quick: bool = False) -> dict:
    """Wall time of the Chapter 6 experiment (3 controllers x 6 payloads, two periods, 2 workers)."""
    import tempfile

    from sma_wrist.experiment import run_experiment

    ctrls = ['inverse_adaptive', 'direct_adaptive', 'pid']
    loads = [0.1, 0.6] if quick else [0.1, 0.2, 0.3, 0.4, 0.5, 0.6]
    duration = 10.0 if quick else 4 * math.pi / 0.1
    with tempfile.TemporaryDirectory() as d, open(os.devnull, 'w') as log:
        t = run_experiment(ctrls, loads, d, duration_s=duration, workers=2, plots=False, log=log)
    return {'runs': len(t['runs']), 'sim_time_per_run_s': duration, 'wall_s_total': t['wall_s'], 'workers': 2}


@section('diagnose')
def bench_diagnose(quick: bool = False) -> dict:
    """Diagnosis accuracy over hidden-effect runs and the wall time on a 10-minute 100 Hz bag."""
    from sma_wrist.diagnose.bench import bench_diagnose as run_diagnose

    return run_diagnose(quick)


@section('diagnose_full')
def bench_diagnose_full(quick: bool = False) -> dict:
    """The diagnose section at full size: independent effects at three noise levels."""
    from sma_wrist.diagnose.bench import bench_diagnose as run_diagnose

    return run_diagnose(quick, full=True)


@section('monitor')
def bench_monitor(quick: bool = False) -> dict:
    """The live model monitor: detection of effects beginning mid-run, false alarms over 30 min per controller,
    CPU cost and the graph's speed with it (doc/explanation/monitor.md)."""
    from sma_wrist.monitor.bench import bench_monitor as run_monitor

    return run_monitor(quick)


@section('live')
def bench_live(quick: bool = False) -> dict:
    """The live view's cost to a run: with a server, and with a client that stopped reading, over none
    (doc/explanation/runtime.md, the live view)."""
    from sma_wrist.closed_loop import bench_live as run_live

    return run_live(quick)


@section('bridge')
def bench_bridge(quick: bool = False) -> dict:
    """1 kHz sample streaming emulator -> pty -> bridge link: loss, reordering, latency percentiles."""
    from sma_wrist.hw.bench import bench_bridge as run_bridge

    return run_bridge(5.0 if quick else 600.0)


@section('identify')
def bench_identify(quick: bool = False) -> dict:
    """GPI / SD-GPI fit time and quality, exact Jacobian vs the earlier finite differences, one core."""
    from sma_wrist.identify.bench import bench_identify as run_identify

    return run_identify(quick)


@section('sweep')
def bench_sweep(quick: bool = False) -> dict:
    """Closed loops per second: the vectorised sweep vs the node graph, side by side (doc/howto/sweep.md)."""
    from sma_wrist.sweep.bench import bench_sweep as run_sweep_bench

    return run_sweep_bench(quick)


@section('identify_thermal')
def bench_identify_thermal(quick: bool = False) -> dict:
    """Held-out Table 4.10 errors per frequency: own model vs the independent Peltier plant (doc/explanation/model.md)."""
    from sma_wrist.identify.thermal_testplant import holdout_table, speed

    return {'speed': speed(quick), **holdout_table(quick)}


@section('identify_wrist')
def bench_identify_wrist(quick: bool = False) -> dict:
    """A wire transforming at 55-98 degC, windows from identify/wrist.py: seed TEMs vs TEMs rated 120 degC (doc/howto/identify_wire.md)."""
    from sma_wrist.identify.wrist_runs import hot_wire_runs

    return hot_wire_runs(
        ('inverse_adaptive',) if quick else ('inverse_adaptive', 'direct_adaptive', 'pid'),
        progress=lambda m: print(f'[identify_wrist] {m}', file=sys.stderr, flush=True),
        png=bench_png('identify_wrist.png'),
    )


@section('measured_wire')
def bench_measured_wire(quick: bool = False) -> dict:
    """The measured Flexinol wire (test/data/flexinol, a source checkout) identified and run in the graph
    on TEMs rated 120 degC; direct and pid also without their reference leads (doc/howto/identify_wire.md)."""
    from sma_wrist.core.errors import SmaWristError
    from sma_wrist.identify.wrist_runs import measured_wire_runs

    data = Path(__file__).resolve().parent.parent / 'test' / 'data' / 'flexinol'
    files = sorted(data.glob('*MPa.txt'))
    if not files:
        raise SmaWristError(f"the measured-wire benchmark reads the source checkout's {data}: not found")
    return measured_wire_runs(
        files,
        ('inverse_adaptive',) if quick else ('inverse_adaptive', 'direct_adaptive', 'pid'),
        progress=lambda m: print(f'[measured_wire] {m}', file=sys.stderr, flush=True),
        png=bench_png('measured_wire.png'),
    )


@section('commission')
def bench_commission(quick: bool = False) -> dict:
    """sma-wrist commission on an emulated wrist that is not the model and on the nominal one (device time, faults,
    verification defaults vs commissioned, diagnosis), and the wiring-fault matrix (doc/howto/commission.md)."""
    from sma_wrist.commission.measure import bench_commission as run_commission

    return run_commission(quick)


@section('speed')
def bench_speed(quick: bool = False) -> dict:
    """What repeated work costs: a recorded graph run with the recorder's direct MCAP records against rosbags'
    ``Writer.write`` (old/new ratio of interleaved runs), and the diagnosis of one synthetic run with its
    mechanics replay's cost per scenario and sample."""
    import tempfile

    from sma_wrist import runtime
    from sma_wrist.bag import BagRecorder
    from sma_wrist.closed_loop import run_closed_loop
    from sma_wrist.diagnose import diagnose_run
    from sma_wrist.diagnose import testdata as td
    from sma_wrist.diagnose.kernels import Constants

    runtime.activate()
    repeats = 3 if quick else 5
    duration = 10.0 if quick else 60.0

    def recorded(direct: bool) -> float:
        BagRecorder.direct = direct
        try:
            with tempfile.TemporaryDirectory() as d:
                t0 = time.perf_counter()
                run_closed_loop('pid', 0.3, duration, Path(d) / 'bag')
                return time.perf_counter() - t0
        finally:
            BagRecorder.direct = True

    def plain() -> float:
        t0 = time.perf_counter()
        run_closed_loop('pid', 0.3, duration)
        return time.perf_counter() - t0

    run_closed_loop('pid', 0.3, 0.5)  # imports, numba cache load
    walls: dict[str, list[float]] = {'writer': [], 'direct': [], 'plain': []}
    for i in range(repeats):  # interleaved, the order alternating: a shared machine's speed drifts
        order = ('writer', 'direct', 'plain') if i % 2 == 0 else ('plain', 'direct', 'writer')
        for name in order:
            walls[name].append(plain() if name == 'plain' else recorded(name == 'direct'))
    med = {k: float(np.median(v)) for k, v in walls.items()}
    out: dict = {
        'graph_sim_time_s': duration,
        'repeats': repeats,
        'graph_recorded_wall_s_writer': med['writer'],
        'graph_recorded_wall_s_direct': med['direct'],
        'graph_wall_s_unrecorded': med['plain'],
        'graph_recorded_ratio_writer_over_direct': med['writer'] / med['direct'],
        'recording_cost_ratio_writer_over_direct': (med['writer'] - med['plain'])
        / max(med['direct'] - med['plain'], 1e-9),
    }
    # the diagnosis of one run, as the live monitor and the benchmarks repeat it
    run = td.run_from_truth(td.simulate('thermal_coupling', seed=3, duration_s=60.0 if quick else 240.0))
    diagnose_run(run)  # numba cache load
    calls = []
    mechanics = Constants.mechanics

    def counted(self, T, dt, jrow, substeps=1):  # type: ignore[no-untyped-def]
        t0 = time.perf_counter()
        res = mechanics(self, T, dt, jrow, substeps)
        calls.append((T.shape[0] * T.shape[1] * substeps, time.perf_counter() - t0))
        return res

    diag = []
    Constants.mechanics = counted  # type: ignore[method-assign]
    try:
        for _ in range(repeats):
            t0 = time.perf_counter()
            diagnose_run(run)
            diag.append(time.perf_counter() - t0)
    finally:
        Constants.mechanics = mechanics  # type: ignore[method-assign]
    steps = sum(c[0] for c in calls)
    out.update(
        diagnose_run_s=run.n * run.dt,
        diagnose_wall_s_median=float(np.median(diag)),
        mechanics_calls_per_diagnosis=len(calls) / repeats,
        mechanics_wall_share=sum(c[1] for c in calls) / sum(diag),
        mechanics_us_per_scenario_step=1e6 * sum(c[1] for c in calls) / max(steps, 1),
    )
    return out


# -------------------------------------------------------------------------------- driver


def run(sections: list[str] | None = None, quick: bool = False, out: str | Path | None = None) -> dict:
    """Run the named sections (all registered ones by default) and return their results.

    ``out``: the folder for the sections' figures and files (``$SMA_WRIST_BENCH_DIR`` while they run, which
    :func:`sma_wrist.outputs.bench_png` reads); None keeps ``$SMA_WRIST_BENCH_DIR``, else ``runs/bench``.
    Checked before any section runs, not after minutes of work."""
    names = list(SECTIONS) if not sections else list(sections)
    unknown = [n for n in names if n not in SECTIONS]
    if unknown:
        from sma_wrist.core.errors import ParameterError

        raise ParameterError(f'unknown benchmark section(s) {unknown}; known: {sorted(SECTIONS)}')
    if out is None:
        return _run(names, quick)
    from sma_wrist.outputs import check_output_folder

    check_output_folder(out)
    saved = os.environ.get('SMA_WRIST_BENCH_DIR')
    os.environ['SMA_WRIST_BENCH_DIR'] = str(out)
    try:
        return _run(names, quick)
    finally:
        if saved is None:
            del os.environ['SMA_WRIST_BENCH_DIR']
        else:
            os.environ['SMA_WRIST_BENCH_DIR'] = saved


def _run(names: list[str], quick: bool) -> dict:
    out: dict = {
        'meta': {
            'python': platform.python_version(),
            'numpy': np.__version__,
            'machine': platform.machine(),
            'cpu_count': os.cpu_count(),
            'quick': quick,
        }
    }
    for name in names:
        t0 = time.perf_counter()
        result = dict(SECTIONS[name](quick))
        result['wall_s'] = time.perf_counter() - t0
        out[name] = result
    return out


def format_text(result: dict) -> str:
    """Human-readable lines ``section.key = value``."""
    lines = []
    for name, res in result.items():
        for key, val in res.items():
            if isinstance(val, float):
                val = f'{val:.4g}'
            elif isinstance(val, dict):
                val = ', '.join(f'{k}: {v:.4g}' if isinstance(v, float) else f'{k}: {v}' for k, v in val.items())
            lines.append(f'{name}.{key} = {val}')
    return '\n'.join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog='python -m sma_wrist.bench', description=__doc__.splitlines()[0])
    ap.add_argument('--section', action='append', choices=sorted(SECTIONS), help='run only these sections')
    ap.add_argument('--quick', action='store_true', help='short runs')
    ap.add_argument('--json', action='store_true', help='print JSON (default)')
    ap.add_argument('--out', metavar='DIR', help=BENCH_OUT_HELP)
    a = ap.parse_args(argv)
    json.dump(run(a.section, quick=a.quick, out=a.out), sys.stdout, indent=2)
    sys.stdout.write('\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
