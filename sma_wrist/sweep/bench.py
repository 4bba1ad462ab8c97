"""Benchmark section ``sweep``: closed loops per second, vectorised sweep vs the node graph, side by side.

Both run the same kind of loops (the three modes; sampled plants in the sweep, ``duration`` s each):
the graph one loop at a time on the embedded runtime (sma_wrist.closed_loop, no recording), the
sweep as ``sma-wrist sweep`` runs it: one vectorised simulation per chunk of the default size
(single core), and one such chunk per available core in as many processes (``--workers 0``,
all cores). Interleaved and best of ``repeats`` (a shared machine's speed drifts by 2x over
minutes); the load average is printed beside the ratios, and the single-core ratio is also given
in CPU time (process time of graph and sweep, which a busy machine inflates less than wall time).
"""

from __future__ import annotations

import os
import time
from typing import Any

from sma_wrist.core.control.joint_controller import MODES


def _timed(fn: Any, *args: Any) -> tuple[float, float]:
    """(wall, CPU of this process) seconds of fn(*args)."""
    c0, w0 = time.process_time(), time.perf_counter()
    fn(*args)
    return time.perf_counter() - w0, time.process_time() - c0


def bench_sweep(quick: bool = False, repeats: int | None = None) -> dict[str, Any]:
    from sma_wrist import runtime

    runtime.activate()
    from sma_wrist.closed_loop import run_closed_loop
    from sma_wrist.plants.spread import sample
    from sma_wrist.sweep.run import SweepConfig, _run_processes, available_cores, split_chunks
    from sma_wrist.sweep.simulate import Case, simulate

    duration = 5.0 if quick else 30.0
    repeats = repeats or (2 if quick else 3)
    chunk = SweepConfig().chunk  # the most `sma-wrist sweep` puts in one simulation
    cores = available_cores()
    n_plants = -(-chunk * cores // len(MODES))
    cases = [
        Case(len(MODES) * i + j, m, s) for i, s in enumerate(sample(n_plants, seed=1)) for j, m in enumerate(MODES)
    ]
    cases = cases[: chunk * cores]
    # chunked as `sma-wrist sweep` (--workers 1) and `sma-wrist sweep --workers 0` chunk these loops
    one = split_chunks(cases, chunk, 1)[0]
    chunks = split_chunks(cases, chunk, cores)
    cfg = SweepConfig(duration_s=duration)
    from sma_wrist.runtime.rclpy import logging as rlog

    simulate(cases[:3], 1.0)  # numba cache load / compile outside the timing
    with rlog.silenced():  # the nodes' log lines are not the benchmark's output
        for m in MODES:
            run_closed_loop(m, 0.3, 0.5)

    def graph() -> None:
        with rlog.silenced():
            for m in MODES:  # one loop per mode on the graph
                run_closed_loop(m, 0.3, duration)

    load = [os.getloadavg()[0]]
    g_wall, g_cpu, s_wall, s_cpu, p_wall = [], [], [], [], []
    for _ in range(repeats):
        w, c = _timed(graph)
        g_wall.append(len(MODES) / w)
        g_cpu.append(len(MODES) / c)
        w, c = _timed(simulate, one, duration)
        s_wall.append(len(one) / w)
        s_cpu.append(len(one) / c)
        if cores > 1:
            w, _ = _timed(_run_processes, cores, chunks, cfg, lambda rows: None, None)
            p_wall.append(sum(map(len, chunks)) / w)
        load.append(os.getloadavg()[0])
    g, s = max(g_wall), max(s_wall)
    out: dict[str, Any] = {
        'sim_time_per_loop_s': duration,
        'chunk_loops': len(one),
        'repeats': repeats,
        'cores_available': cores,
        'load_average_1min': [round(x, 2) for x in load],
        'graph_loops_per_s': g,
        'sweep_loops_per_s': s,
        'ratio': s / g,
        'ratio_range': [min(s_wall) / max(g_wall), max(s_wall) / min(g_wall)],
        'ratio_cpu_time': max(s_cpu) / max(g_cpu),
        'graph_us_per_loop_tick': 1e6 / (g * duration * 100.0),
        'sweep_us_per_loop_tick': 1e6 / (s * duration * 100.0),
        'graph_cpu_us_per_loop_tick': 1e6 / (max(g_cpu) * duration * 100.0),
        'sweep_cpu_us_per_loop_tick': 1e6 / (max(s_cpu) * duration * 100.0),
    }
    if p_wall:
        p = max(p_wall)
        out.update(
            {
                'all_core_loops': sum(map(len, chunks)),
                'all_core_loops_per_s': p,
                'ratio_all_cores': p / g,
                'ratio_all_cores_range': [min(p_wall) / max(g_wall), max(p_wall) / min(g_wall)],
            }
        )
    return out
