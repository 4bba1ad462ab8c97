"""``sma-wrist sweep``: closed loops over sampled plants x controllers x payloads, in chunks.

Each chunk is one vectorised simulation (:func:`sma_wrist.sweep.simulate.simulate`); a loop's
result depends only on its own case (seeded scenario, own noise stream), so the chunking, the
order and the machine (``--workers``: local processes; ``--scheduler``: a Dask distributed cluster)
do not change any number.
Results are appended to ``results.jsonl`` as each chunk finishes, so Ctrl-C keeps them; the
summary (``sweep.json``, ``table.txt``, ``cdf.png``, ``heatmap.png``) is written from whatever
finished.
"""

from __future__ import annotations

import contextlib
import json
import math
import multiprocessing
import os
import sys
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from sma_wrist.core.control.joint_controller import MODES
from sma_wrist.core.errors import ParameterError, SmaWristError
from sma_wrist.plants import PLANTS
from sma_wrist.plants.spread import BY_NAME, FAMILY, VALIDITY, Scenario, check_ranges, sample
from sma_wrist.sweep.simulate import Case, simulate

if TYPE_CHECKING:  # graph_params builds nodes: imported where it is used
    from sma_wrist.sweep.graph_params import LoopSettings

#: the seed's requirement (max error under 15 %) and the share of the family asked to meet it
LIMIT_PCT = 15.0
SHARE = 0.95
NOMINAL_PAYLOADS = (0.1, 0.3, 0.6)


@dataclass(frozen=True)
class SweepConfig:
    """What to sweep. ``payloads`` None: each plant's sampled payload; else every plant at each."""

    n_plants: int = 20
    seed: int = 0
    controllers: tuple[str, ...] = MODES
    payloads: tuple[float, ...] | None = None
    duration_s: float = 126.0
    plant: str = 'sdgpi'
    ranges: dict[str, tuple[float, float]] = field(default_factory=lambda: dict(FAMILY))
    chunk: int = 192  # most loops per simulation: its per-tick Python (~0.45 ms) spread over more loops
    nominal: bool = True  # also the nominal plant per controller at NOMINAL_PAYLOADS, side by side
    heatmap_axes: tuple[str, str] = ('transition_shift_C', 'stroke_scale')
    #: also each plant's reach floor (:func:`sma_wrist.plants.loop.reach_floor_pct`, ~5-7 s of CPU per plant):
    #: the least max error any controller can have on it, and the figures over the plants where it is < 15 %
    reach: bool = False
    #: ROS params files of the node graph applied after config/wrist.yaml, as ``sma-wrist run --params-file``
    #: (:mod:`sma_wrist.sweep.graph_params`: what the sweep cannot honour is refused)
    params_files: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if not (isinstance(self.n_plants, int) and self.n_plants >= 1):
            raise ParameterError(f'number of plants N = {self.n_plants!r} must be an integer >= 1')
        bad = list(
            dict.fromkeys(
                repr(c) if c else '(an empty name: a stray comma?)' for c in self.controllers if c not in MODES
            )
        )
        if bad or not self.controllers:
            raise ParameterError(f'controllers {", ".join(bad) or "(none)"}: choose from {", ".join(MODES)}')
        if len(set(self.controllers)) != len(self.controllers):  # each loop would run twice under one name
            raise ParameterError(f'controllers {", ".join(self.controllers)}: a controller is named twice')
        if self.plant not in PLANTS:
            raise ParameterError(f'unknown plant {self.plant!r}; registered: {", ".join(sorted(PLANTS))}')
        if not (math.isfinite(self.duration_s) and self.duration_s >= 1.0):
            raise ParameterError(f'duration {self.duration_s!r} s must be >= 1 s')
        if not (isinstance(self.chunk, int) and self.chunk >= 1):
            raise ParameterError(f'chunk = {self.chunk!r} must be an integer >= 1')
        check_ranges(self.ranges)
        lo, hi = BY_NAME['payload_kg'].lower, BY_NAME['payload_kg'].upper
        for m in self.payloads or ():
            if not (math.isfinite(m) and lo <= m <= hi):
                raise ParameterError(f"payload {m!r} kg is outside the model's validity [{lo:g}, {hi:g}] kg")
        for a in self.heatmap_axes:
            if a not in BY_NAME:
                raise ParameterError(f'heat-map axis {a!r} is not a perturbation; known: {", ".join(BY_NAME)}')
        if self.reach and self.plant != 'sdgpi':
            raise ParameterError(f"the reach floor is computed on the project's plant (sdgpi), not {self.plant!r}")


def parse_perturbations(items: Sequence[str]) -> dict[str, tuple[float, float]]:
    """``name=lo:hi`` or ``name=value`` items -> ranges (validated by check_ranges)."""
    out: dict[str, tuple[float, float]] = {}
    for item in items:
        name, sep, rng = item.partition('=')
        if not sep:
            raise ParameterError(f'perturbation {item!r}: write name=lo:hi or name=value')
        parts = rng.split(':')
        try:
            vals = [float(x) for x in parts]
        except ValueError:
            raise ParameterError(f'perturbation {item!r}: {rng!r} is not a number or lo:hi') from None
        if len(vals) not in (1, 2):
            raise ParameterError(f'perturbation {item!r}: write name=lo:hi or name=value')
        out[name.strip()] = (vals[0], vals[-1])
    return check_ranges(out)


def make_cases(cfg: SweepConfig) -> list[Case]:
    """The sweep's closed loops, in a fixed order: sampled plants x payloads x controllers, then nominal ones."""
    cases: list[Case] = []
    for sc in sample(cfg.n_plants, cfg.seed, cfg.ranges):
        for m in cfg.payloads or (sc.payload_kg,):
            for c in cfg.controllers:
                cases.append(Case(len(cases), c, replace(sc, payload_kg=float(m))))
    if cfg.nominal:
        for m in cfg.payloads or NOMINAL_PAYLOADS:
            for c in cfg.controllers:
                cases.append(Case(len(cases), c, Scenario(payload_kg=float(m)), 'nominal'))
    return cases


def run_chunk(
    cases: Sequence[Case], duration_s: float, plant: str, settings: dict[str, Any] | None = None
) -> list[dict[str, Any]]:
    """One chunk: what a local loop or a Dask worker runs (``settings``: the graph's parameters,
    :func:`sma_wrist.sweep.graph_params.loop_settings`)."""
    return simulate(cases, duration_s, plant, **(settings or {}))[0]


class Progress:
    """A progress bar on stderr: in place on a terminal, a line per 10 % in a log."""

    def __init__(self, total_loops: int, stream: Any = None) -> None:
        self.total, self.stream, self.t0, self._last = total_loops, stream or sys.stderr, time.perf_counter(), -1

    def __call__(self, done_loops: float) -> None:
        f = min(done_loops / self.total, 1.0)
        wall = time.perf_counter() - self.t0
        eta = f'{wall * (1 - f) / f:6.1f} s' if f > 0 else '     ?'
        bar = '#' * int(30 * f)
        text = f'[sweep] |{bar:<30}| {100 * f:5.1f} % of {self.total} loops, {wall:6.1f} s, eta {eta}'
        if self.stream.isatty():
            self.stream.write('\r' + text + ('\n' if f >= 1 else ''))
        elif int(10 * f) != self._last:
            self._last = int(10 * f)
            self.stream.write(text + '\n')
        self.stream.flush()


@dataclass
class SweepResult:
    config: SweepConfig
    rows: list[dict[str, Any]]
    interrupted: bool
    wall_s: float
    summary: list[dict[str, Any]] = field(default_factory=list)
    files: dict[str, str] = field(default_factory=dict)
    #: per node, the parameters the params files set to other values than config/wrist.yaml's
    parameters_changed: dict[str, dict[str, Any]] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        cfg = asdict(self.config)
        return {
            'config': cfg,
            'parameters_changed': self.parameters_changed,
            'interrupted': self.interrupted,
            'wall_s': self.wall_s,
            'loops': len(self.rows),
            'summary': self.summary,
            'files': self.files,
            'rows': self.rows,
        }


def available_cores() -> int:
    """CPUs this process may run on (its affinity mask where the OS has one, not the machine's count)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - macOS, Windows
        return os.cpu_count() or 1


def split_chunks(cases: Sequence[Case], chunk: int, workers: int = 1) -> list[list[Case]]:
    """The loops cut into simulations: at most ``chunk`` loops each, as many chunks as a multiple of
    ``workers`` (every worker runs as many), sizes equal within one loop (no short last chunk running alone).

    Why this size: a simulation's Python costs ~0.45 ms per tick whatever its size, so larger chunks
    spread it over more loops (CPU per loop-tick, doc/howto/sweep.md: ~15.2 us at 96 loops, ~13.6 at 192, ~13.5
    at 288); the cost is ~1 MB of memory per 126 s loop and, on Ctrl-C, the unfinished chunk's loops."""
    if not (isinstance(chunk, int) and chunk >= 1 and isinstance(workers, int) and workers >= 1):
        raise ParameterError(f'chunk = {chunk!r} and workers = {workers!r} must be integers >= 1')
    if not cases:
        return []
    n_chunks = -(-len(cases) // chunk)
    n_chunks = -(-n_chunks // workers) * workers
    size = -(-len(cases) // min(n_chunks, len(cases)))
    return [list(cases[i : i + size]) for i in range(0, len(cases), size)]


def run_sweep(
    cfg: SweepConfig,
    out_dir: str | Path | None = None,
    scheduler: str | None = None,
    progress: Callable[[float], None] | None = None,
    workers: int = 1,
    settings: LoopSettings | None = None,
) -> SweepResult:
    """Run the sweep (locally, or on the Dask cluster at ``scheduler``); Ctrl-C keeps finished chunks.

    ``workers`` > 1: the chunks run in that many local processes (0: one per available core), as
    :func:`split_chunks` cuts them (on Dask: chunks of ``cfg.chunk`` loops). ``settings``: what
    :func:`~sma_wrist.sweep.graph_params.loop_settings` already read from ``cfg.params_files`` for ``cfg.plant``
    (a caller that checked the files first, ``experiment --family``; None: read them here)."""
    if not (isinstance(workers, int) and workers >= 0):
        raise ParameterError(f'workers = {workers!r} must be an integer >= 0 (0: one per available core)')
    workers = workers or available_cores()
    if not cfg.params_files:
        settings = None
    elif settings is None:  # before any loop runs: a parameter the sweep cannot honour stops it here
        from sma_wrist.sweep.graph_params import loop_settings

        settings = loop_settings(cfg.params_files, cfg.plant)
    kwargs: dict[str, Any] = {} if settings is None else settings.kwargs  # simulate's: the graph's parameters
    cases = make_cases(cfg)
    chunks = split_chunks(cases, cfg.chunk, 1 if scheduler else workers)
    out = Path(out_dir) if out_dir is not None else None
    jsonl = None
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        jsonl = (out / 'results.jsonl').open('w')
    rows: list[dict[str, Any]] = []
    t0 = time.perf_counter()
    interrupted = False

    def keep(chunk_rows: list[dict[str, Any]]) -> None:
        rows.extend(chunk_rows)
        if jsonl is not None:
            for r in chunk_rows:
                jsonl.write(json.dumps(r) + '\n')
            jsonl.flush()

    try:
        if scheduler:
            _run_dask(scheduler, chunks, cfg, keep, progress, kwargs)
        elif workers > 1 and len(chunks) > 1:
            _run_processes(min(workers, len(chunks)), chunks, cfg, keep, progress, kwargs)
        else:
            done = 0
            for chunk in chunks:
                tick = (
                    None
                    if progress is None
                    else (lambda t, d=done, n=len(chunk): progress(d + n * min(t / cfg.duration_s, 1.0)))
                )
                keep(simulate(chunk, cfg.duration_s, cfg.plant, on_tick=tick, **kwargs)[0])
                done += len(chunk)
                if progress is not None:
                    progress(done)
    except KeyboardInterrupt:
        interrupted = True
    finally:
        if jsonl is not None:
            jsonl.close()
    rows.sort(key=lambda r: r['index'])
    if cfg.reach and not interrupted:
        try:
            add_reach_floors(
                rows, workers if not scheduler else 1, None if progress is None else _reach_progress, kwargs
            )
        except KeyboardInterrupt:  # the loops' rows stay, with the floors computed so far
            interrupted = True
    res = SweepResult(
        cfg,
        rows,
        interrupted,
        time.perf_counter() - t0,
        parameters_changed={} if settings is None else _json_values(settings.changed),
    )
    res.summary = summarise(rows)
    if out is not None:
        res.files = write_outputs(res, out)
    return res


def _collect(
    completed: Iterable[Any], keep: Callable[[list[dict[str, Any]]], None], progress: Callable[[float], None] | None
) -> None:
    """Keep each chunk's rows as its future completes (local processes or Dask), progress in loops done."""
    done = 0
    for fut in completed:
        rows = fut.result()
        keep(rows)
        done += len(rows)
        if progress is not None:
            progress(done)


@contextlib.contextmanager
def _process_pool(workers: int) -> Iterator[Any]:
    """A pool of ``workers`` local processes, forked where the OS can (the compiled kernels come along).
    Ctrl-C or a failed task inside the block drops the queued tasks; what finished was kept by the block."""
    from concurrent.futures import ProcessPoolExecutor

    ctx = multiprocessing.get_context('fork' if 'fork' in multiprocessing.get_all_start_methods() else 'spawn')
    pool = ProcessPoolExecutor(workers, mp_context=ctx)
    try:
        yield pool
    except BaseException:
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown()


def _json_values(changed: dict[str, dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Parameter values as JSON has them (a ROS array parameter may be a tuple or an array)."""

    def plain(v: Any) -> Any:
        return v.tolist() if isinstance(v, np.ndarray) else list(v) if isinstance(v, tuple) else v

    return {node: {k: plain(v) for k, v in values.items()} for node, values in changed.items()}


def _run_processes(
    workers: int,
    chunks: list[list[Case]],
    cfg: SweepConfig,
    keep: Callable[[list[dict[str, Any]]], None],
    progress: Callable[[float], None] | None,
    settings: dict[str, Any] | None = None,
) -> None:
    """The chunks in ``workers`` local processes (:func:`_process_pool`)."""
    from concurrent.futures import as_completed

    with _process_pool(workers) as pool:
        _collect(
            as_completed([pool.submit(run_chunk, ch, cfg.duration_s, cfg.plant, settings) for ch in chunks]),
            keep,
            progress,
        )


def _run_dask(
    address: str,
    chunks: list[list[Case]],
    cfg: SweepConfig,
    keep: Callable[[list[dict[str, Any]]], None],
    progress: Callable[[float], None] | None,
    settings: dict[str, Any] | None = None,
) -> None:
    try:
        from dask.distributed import Client, as_completed
    except ImportError:
        raise SmaWristError('--scheduler needs Dask: pip install "sma_wrist[dask]"') from None
    try:
        client = Client(address, timeout='10s')
    except (OSError, TimeoutError, ValueError) as e:
        raise SmaWristError(f'cannot reach the Dask scheduler at {address}: {e}') from None
    try:
        futures = [client.submit(run_chunk, ch, cfg.duration_s, cfg.plant, settings, pure=False) for ch in chunks]
        try:
            _collect(as_completed(futures), keep, progress)
        except KeyboardInterrupt:
            client.cancel(futures)
            raise
    finally:
        client.close()


def _reach_progress(done: int, total: int) -> None:
    sys.stderr.write(f'[sweep] reach floors: {done} / {total} plants\n')
    sys.stderr.flush()


#: the axes that act on the sensors, not the plant: a reach floor does not depend on them
SENSOR_AXES = ('temp_noise_C', 'temp_lag_s', 'angle_noise_rad')


def _reach_floor(scenario: Scenario, settings: dict[str, Any] | None = None) -> float:
    from sma_wrist.plants.loop import OffModelCase, reach_floor_pct

    over = (settings or {}).get('controller_overrides') or {}
    window = (over.get('temperature_min_C', 20.0), over.get('temperature_max_C', 80.0))  # adaptive_controller's
    return reach_floor_pct(OffModelCase('sdgpi', scenario), T_window_C=window, base=(settings or {}).get('base'))


def add_reach_floors(
    rows: list[dict[str, Any]],
    workers: int = 1,
    progress: Callable[[int, int], None] | None = None,
    settings: dict[str, Any] | None = None,
) -> None:
    """``reach_floor_pct`` into each row, computed once per plant (its scenario: payload and plant axes),
    in ``workers`` local processes; a floor does not depend on the controller or the sensors. Each plant's
    rows get their floor as it finishes, so Ctrl-C keeps the floors computed; ``progress(done, total)``
    after each plant. ``settings``: the graph's parameters (:func:`sma_wrist.sweep.graph_params.loop_settings`):
    the plant the scenarios perturb and the controllers' temperature window."""
    axes = [p.name for p in VALIDITY if p.name not in SENSOR_AXES]
    rows_of: dict[tuple[float, ...], list[dict[str, Any]]] = {}  # plant -> its rows, in order
    for r in rows:
        rows_of.setdefault(tuple(r[a] for a in axes), []).append(r)
    plants = list(rows_of)
    done = 0

    def put(k: tuple[float, ...], floor: float) -> None:
        nonlocal done
        for r in rows_of[k]:
            r['reach_floor_pct'] = floor
        done += 1
        if progress is not None:
            progress(done, len(plants))

    scen = {k: Scenario(**dict(zip(axes, k))) for k in plants}
    if workers <= 1 or len(plants) <= 1:
        for k in plants:
            put(k, _reach_floor(scen[k], settings))
        return
    from concurrent.futures import as_completed

    with _process_pool(min(workers, len(plants))) as pool:
        futures = {pool.submit(_reach_floor, scen[k], settings): k for k in plants}
        for fut in as_completed(futures):
            put(futures[fut], fut.result())


def error_stats(max_error_pct: Sequence[float]) -> dict[str, float]:
    """Median / 95th percentile / worst of a set of loops' max errors [%] and the share under 15 %."""
    e = np.asarray(max_error_pct, dtype=float)
    return {
        'median_max_error_pct': float(np.median(e)),
        'p95_max_error_pct': float(np.percentile(e, 95)),
        'worst_max_error_pct': float(e.max()),
        'share_under_15_pct': float(np.mean(e < LIMIT_PCT)),
    }


def summarise(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per (group, controller): loops, median / 95th percentile / worst max error, share under 15 %,
    median and worst TEM sign changes per second, median and worst of each loop's highest wire stress."""
    out = []
    for group in ('nominal', 'spread'):
        for c in MODES:
            sel = [r for r in rows if r['group'] == group and r['controller'] == c]
            if not sel:
                continue
            ch = np.array([r['sign_changes_per_s'] for r in sel])
            row = {
                'group': group,
                'controller': c,
                'loops': len(sel),
                **error_stats([r['max_error_pct'] for r in sel]),
                'median_rms_error_pct': float(np.median([r['rms_error_pct'] for r in sel])),
                'median_sign_changes_per_s': float(np.median(ch)),
                'worst_sign_changes_per_s': float(ch.max()),
            }
            if all('wire_stress_max_MPa' in r for r in sel):  # rows of an older sweep may not have it
                st = np.array([r['wire_stress_max_MPa'] for r in sel])
                row.update(median_wire_stress_max_MPa=float(np.median(st)), worst_wire_stress_max_MPa=float(st.max()))
            if all('overload_s' in r for r in sel):
                row['overloaded_loops'] = sum(r['overload_s'] > 0 for r in sel)
            if sel and all('reach_floor_pct' in r for r in sel):
                ok = [r['max_error_pct'] for r in sel if r['reach_floor_pct'] < LIMIT_PCT]
                row['reachable_loops'] = len(ok)
                row['reachable'] = error_stats(ok) if ok else None
            out.append(row)
    return out


def format_table(summary: Sequence[dict[str, Any]]) -> str:
    head = (
        f'{"plants":8} {"controller":17} {"loops":>5} {"median":>7} {"p95":>7} {"worst":>7} {"<15%":>6} '
        f'{"flips/s":>8} {"MPa":>5}'
    )
    lines = [head, '-' * len(head)]
    for s in summary:
        mpa = s.get('worst_wire_stress_max_MPa')
        lines.append(
            f'{s["group"]:8} {s["controller"]:17} {s["loops"]:5d} {s["median_max_error_pct"]:6.2f}% '
            f'{s["p95_max_error_pct"]:6.2f}% {s["worst_max_error_pct"]:6.2f}% '
            f'{100 * s["share_under_15_pct"]:5.0f}% {s["median_sign_changes_per_s"]:8.2f} '
            + ('    -' if mpa is None else f'{mpa:5.0f}')
        )
    lines.append(
        'max error over the last reference cycle, % of the reference range (true angle); '
        'flips/s: median TEM command sign changes per second; MPa: the highest wire stress of any loop '
        '(doc/explanation/controllers.md)'
    )
    over = [s for s in summary if s.get('overloaded_loops')]
    if over:
        which = ', '.join(f'{s["overloaded_loops"]} {s["group"]} {s["controller"]}' for s in over)
        lines.append(
            f"not physics: {which} loop(s) held a wire at the wire model's load bound (overload_s in results.jsonl)"
        )
    reach = [s for s in summary if 'reachable_loops' in s]
    if reach:
        lines += [
            '',
            'plants whose reach floor is under 15 % (the rest: no controller can track the sine on them '
            "inside the controllers' temperature window):",
            f'{"plants":8} {"controller":17} {"loops":>5} {"median":>7} {"p95":>7} {"<15%":>6}',
        ]
        for s in reach:
            r = s['reachable']
            lines.append(
                f'{s["group"]:8} {s["controller"]:17} {s["reachable_loops"]:5d} '
                + (
                    f'{r["median_max_error_pct"]:6.2f}% {r["p95_max_error_pct"]:6.2f}% {100 * r["share_under_15_pct"]:5.0f}%'
                    if r
                    else '      -       -      -'
                )
            )
    return '\n'.join(lines)


def write_outputs(res: SweepResult, out: Path) -> dict[str, str]:
    files = {'results': str(out / 'results.jsonl'), 'json': str(out / 'sweep.json'), 'table': str(out / 'table.txt')}
    (out / 'table.txt').write_text(format_table(res.summary) + '\n')
    try:
        files.update(plot(res, out))
    except ImportError:
        pass  # matplotlib is the 'plot' extra: the text and JSON are written regardless
    (out / 'sweep.json').write_text(json.dumps(res.to_json(), indent=1))
    return files


def plot(res: SweepResult, out: Path) -> dict[str, str]:
    """cdf.png (CDF of max error per controller, spread vs nominal) and heatmap.png (median max error
    over the two heat-map axes, one panel per controller)."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    rows = res.rows
    ctrls = [c for c in MODES if any(r['controller'] == c for r in rows)]
    if not rows:
        return {}
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for k, c in enumerate(ctrls):
        e = np.sort([r['max_error_pct'] for r in rows if r['controller'] == c and r['group'] == 'spread'])
        if e.size:
            ax.step(e, np.arange(1, e.size + 1) / e.size, where='post', color=f'C{k}', label=f'{c} (spread, {e.size})')
        nom = [r['max_error_pct'] for r in rows if r['controller'] == c and r['group'] == 'nominal']
        if nom:
            ax.plot(nom, np.full(len(nom), 1.02), 'v', color=f'C{k}', label=f'{c} nominal plant')
    ax.axvline(LIMIT_PCT, color='k', ls='--', lw=1, label='15 % (seed requirement)')
    ax.axhline(SHARE, color='grey', ls=':', lw=1)
    ax.set_xscale('log')
    ax.set_xlabel('max error over the last cycle [% of reference range]')
    ax.set_ylabel('share of plants')
    ax.set_title(f'sma-wrist sweep: {res.config.plant}, {res.config.n_plants} plants, seed {res.config.seed}')
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, loc='lower right')
    fig.tight_layout()
    fig.savefig(out / 'cdf.png', dpi=110)
    plt.close(fig)
    xa, ya = res.config.heatmap_axes
    spread = [r for r in rows if r['group'] == 'spread']
    fig, axes = plt.subplots(1, max(len(ctrls), 1), figsize=(4.2 * max(len(ctrls), 1), 3.8), squeeze=False)
    for ax, c in zip(axes[0], ctrls):
        sel = [r for r in spread if r['controller'] == c]
        x = np.array([r[xa] for r in sel])
        y = np.array([r[ya] for r in sel])
        e = np.array([r['max_error_pct'] for r in sel])
        if x.size == 0:
            continue
        nb = 5
        xe = np.linspace(x.min(), x.max() + 1e-12, nb + 1)
        ye = np.linspace(y.min(), y.max() + 1e-12, nb + 1)
        grid = np.full((nb, nb), np.nan)
        ix, iy = np.clip(np.digitize(x, xe) - 1, 0, nb - 1), np.clip(np.digitize(y, ye) - 1, 0, nb - 1)
        for i in range(nb):
            for j in range(nb):
                m = (ix == i) & (iy == j)
                if m.any():
                    grid[j, i] = np.median(e[m])
        im = ax.pcolormesh(xe, ye, grid, cmap='viridis_r', vmin=0, vmax=max(30.0, float(np.nanmax(grid))))
        ax.set_xlabel(f'{xa} [{BY_NAME[xa].unit}]')
        ax.set_ylabel(f'{ya} [{BY_NAME[ya].unit}]')
        ax.set_title(f'{c}: median max error [%]', fontsize=9)
        fig.colorbar(im, ax=ax)
    fig.tight_layout()
    fig.savefig(out / 'heatmap.png', dpi=110)
    plt.close(fig)
    return {'cdf': str(out / 'cdf.png'), 'heatmap': str(out / 'heatmap.png')}


__all__ = [
    'SweepConfig',
    'SweepResult',
    'make_cases',
    'run_sweep',
    'run_chunk',
    'available_cores',
    'parse_perturbations',
    'split_chunks',
    'error_stats',
    'summarise',
    'format_table',
    'Progress',
    'add_reach_floors',
]
