"""Benchmark section ``sweep``: closed loops per second, vectorised sweep vs the node graph, side by side.

Both run the same loops (the three modes on nominal and sampled plants, ``duration`` s each):
the graph one loop at a time on the embedded runtime (sma_wrist.closed_loop, no recording),
the sweep as one vectorised simulation of all its loops. Interleaved and best of ``repeats``
(a shared machine's speed drifts by 2x over minutes).
"""
from __future__ import annotations

import time
from typing import Any

from sma_wrist.core.control.joint_controller import MODES


def bench_sweep(quick: bool = False, repeats: int = 2) -> dict[str, Any]:
    from sma_wrist import runtime
    runtime.activate()
    from sma_wrist.closed_loop import run_closed_loop
    from sma_wrist.plants.spread import sample
    from sma_wrist.sweep.simulate import Case, simulate
    duration = 5.0 if quick else 30.0
    n_plants = 4 if quick else 32
    cases = [Case(len(MODES) * i + j, m, s) for i, s in enumerate(sample(n_plants, seed=1)) for j, m in enumerate(MODES)]
    simulate(cases[:3], 1.0)  # numba cache load / compile outside the timing
    for m in MODES:
        run_closed_loop(m, 0.3, 0.5)
    graph_rates, sweep_rates = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for m in MODES:  # one loop per mode on the graph
            run_closed_loop(m, 0.3, duration)
        graph_rates.append(len(MODES) / (time.perf_counter() - t0))
        t0 = time.perf_counter()
        simulate(cases, duration)
        sweep_rates.append(len(cases) / (time.perf_counter() - t0))
    g, s = max(graph_rates), max(sweep_rates)
    return {'sim_time_per_loop_s': duration, 'sweep_loops': len(cases), 'repeats': repeats,
            'graph_loops_per_s': g, 'sweep_loops_per_s': s, 'ratio': s / g,
            'ratio_range': [min(sweep_rates) / max(graph_rates), max(sweep_rates) / min(graph_rates)],
            'sweep_us_per_loop_tick': 1e6 / (s * duration * 100.0),
            'graph_us_per_loop_tick': 1e6 / (g * duration * 100.0)}
