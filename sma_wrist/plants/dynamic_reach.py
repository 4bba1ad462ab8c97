"""Dynamic reach: how well ANY schedule of full-authority TEM drive follows the Sec. 6.1 sine on a plant.

:func:`sma_wrist.plants.loop.reach_floor_pct` bounds the max error statically (the angle range the
wrist holds inside the controllers' temperature window). A wrist can hold the whole range and
still not follow the sine in time: its TEMs heat and cool at finite rates, its wires cross a
hysteresis gap at every reversal, and a wire may snap through (the phase-fraction wrist's cold
antagonist detwins as its stress rises). This module measures that dynamic limit with
schedules that know what no controller knows -- the true muscle temperatures (no thermocouple
lag or noise) and the reference's future -- and drive the TEMs at the rating (+-24 V, no TEM law):

    T_i*(t) = max(a_i + b_i d_i(q_d(t + L)) + h_i s(t + L),  f_i)        [degC]
    u_i(t)  = clip(K (T_i*(t) - T_i(t)), -u_max, u_max)                [V], K = 20 V/degC

with d_1(q) = q - q_lo (muscle 1 raises q), d_2(q) = q_hi - q, s = +1 while the reference rises
and -1 while it falls for muscle 1 (the hysteresis: heating branch above the cooling one; the
sign reversed for muscle 2), f_i the idle floor (each muscle held just below its transformation
when idle) and L the lead. The nine numbers (a, b, h, f per muscle, L) are searched (random search
around a hand-timed start, then around the best), all candidates as one vectorised plant
(:func:`search`). The best schedule's max error over the last cycle is the "dynamic reach"
figure of doc/explanation/controllers.md: an open-loop schedule, so not a
strict bound, but one that a model-free controller reading thermocouples does not beat easily.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from sma_wrist.core.control.trajectory import make_trajectory
from sma_wrist.core.errors import ParameterError
from sma_wrist.core.metrics import SEED_PERIOD_S
from sma_wrist.plants import make_plant
from sma_wrist.plants.spread import Scenario
from sma_wrist.sweep.simulate import loop_metrics

FloatArray = NDArray[np.float64]

#: the schedule's numbers, in the columns of a (N, 9) array
FIELDS = ('a1_C', 'b1_C_per_rad', 'h1_C', 'f1_C', 'a2_C', 'b2_C_per_rad', 'h2_C', 'f2_C', 'lead_s')
#: a hand-timed start on the phase-fraction wrist at 0.3 kg (its wires contract from ~60 degC and are
#: through at ~72 degC; they re-form martensite from ~56 to ~44 degC): heating branch a + h, cooling a - h
HAND_TIMED = np.array([53.0, 11.0, 7.0, 44.0, 53.0, 11.0, 7.0, 44.0, 2.0])
#: the search's box around the start (+-)
SPREAD = np.array([8.0, 6.0, 5.0, 8.0, 8.0, 6.0, 5.0, 8.0, 2.0])
THERMOSTAT_V_PER_C = 20.0
Q_RANGE = (0.0, 1.048)  # the Sec. 6.1 sine's range [rad]
TICK_S = 0.01


@dataclass
class ReachResult:
    """The best schedule (FIELDS) and its max / RMS error [% of the range] over the last cycle."""

    schedule: FloatArray
    max_error_pct: float
    rms_error_pct: float
    evaluated: int


def run_schedules(
    schedules: FloatArray,
    payload_kg: float = 0.3,
    plant: str = 'phase_fraction',
    duration_s: float = 126.0,
    u_max_V: float = 24.0,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Each schedule (N, 9) (FIELDS) driving one wrist of an N-wrist plant for ``duration_s`` [s]:
    (t (K,) [s], q_d (K,) [rad], q (K, N) [rad], true muscle temperatures (K, N, 2) [degC]) every tick."""
    sch = np.atleast_2d(np.asarray(schedules, float))
    if sch.ndim != 2 or sch.shape[1] != len(FIELDS) or not np.isfinite(sch).all():
        raise ParameterError(f'schedules must be finite (N, {len(FIELDS)}) rows of {", ".join(FIELDS)}')
    if not duration_s >= TICK_S:
        raise ParameterError(f'duration {duration_s!r} s must be >= {TICK_S} s')
    n = sch.shape[0]
    wrists = make_plant(plant, [Scenario(payload_kg=payload_kg)] * n)
    # the true node temperature where the plant has its own thermocouple (phase fraction): an oracle

    def T_true() -> FloatArray:
        return getattr(wrists, 'node_temperature_C', wrists.muscle_temperature_C)

    steps = max(1, int(round(TICK_S / wrists.params.dt)))
    traj = make_trajectory('sine', (0.0, 1.05))
    lo, hi = Q_RANGE
    a, b, h, f = sch[:, [0, 4]], sch[:, [1, 5]], sch[:, [2, 6]], sch[:, [3, 7]]
    lead = sch[:, 8]
    k_total = int(round(duration_s / TICK_S))
    t = np.arange(k_total) * TICK_S
    q_d = np.asarray(traj(t)[0], float)
    q, T = np.empty((k_total, n)), np.empty((k_total, n, 2))
    for k in range(k_total):
        q_ahead, qdot_ahead = (np.asarray(x, float) for x in traj(t[k] + lead)[:2])
        s = np.where(qdot_ahead >= 0, 1.0, -1.0)
        d = np.stack([q_ahead - lo, hi - q_ahead], axis=1)
        target = np.maximum(a + b * d + h * np.stack([s, -s], axis=1), f)
        T[k] = T_true()
        u = np.clip(THERMOSTAT_V_PER_C * (target - T[k]), -u_max_V, u_max_V)
        q[k] = wrists.state.q
        wrists.advance(u, steps)
    return t, q_d, q, T


def schedule_errors(
    schedules: FloatArray,
    payload_kg: float = 0.3,
    plant: str = 'phase_fraction',
    duration_s: float = 126.0,
    u_max_V: float = 24.0,
) -> tuple[FloatArray, FloatArray]:
    """(max, RMS) error [% of the reference range] of each schedule (N, 9) over the last cycle: the true
    angle against q_d (:func:`sma_wrist.sweep.simulate.loop_metrics`, as every closed loop is measured)."""
    if not duration_s >= SEED_PERIOD_S:
        raise ParameterError(f'duration {duration_s!r} s must cover one reference cycle ({SEED_PERIOD_S:.1f} s)')
    t, q_d, q, _ = run_schedules(schedules, payload_kg, plant, duration_s, u_max_V)
    rows = loop_metrics(t, q_d, q, q, np.zeros(q.shape + (2,)))
    return np.array([r['max_error_pct'] for r in rows]), np.array([r['rms_error_pct'] for r in rows])


def search(
    payload_kg: float = 0.3,
    n: int = 48,
    rounds: int = 2,
    seed: int = 0,
    plant: str = 'phase_fraction',
    duration_s: float = 126.0,
    start: FloatArray | None = None,
    progress: Callable[[str], None] | None = None,
) -> ReachResult:
    """Random search of the schedule (module docstring): ``rounds`` rounds of ``n`` candidates, each round
    around the best so far within a box that halves every round; the start is always evaluated."""
    if not (n >= 1 and rounds >= 1):
        raise ParameterError(f'n = {n!r} and rounds = {rounds!r} must be >= 1')
    rng = np.random.default_rng(seed)
    best = np.array(HAND_TIMED if start is None else start, float)
    best_max, best_rms, total = np.inf, np.inf, 0
    for r in range(rounds):
        box = SPREAD / 2**r
        cand = best + box * rng.uniform(-1.0, 1.0, (n, len(FIELDS)))
        cand[0] = best
        cand[:, 8] = np.maximum(cand[:, 8], 0.0)  # a lead, not a lag
        mx, rms = schedule_errors(cand, payload_kg, plant, duration_s)
        total += n
        j = int(np.argmin(mx))
        if mx[j] < best_max:
            best, best_max, best_rms = cand[j].copy(), float(mx[j]), float(rms[j])
        if progress is not None:
            progress(f'round {r + 1}/{rounds}: best max error {best_max:.2f} % ({total} schedules)')
    return ReachResult(best, best_max, best_rms, total)


def plot(results: dict[float, ReachResult], path: str, plant: str = 'phase_fraction', mode: str | None = 'pid') -> None:
    """PNG: per payload, the best schedule's angle and muscle temperatures over the last cycle, next to the
    reference and (``mode``) that controller's closed loop on the same plant (:func:`sma_wrist.plants.loop.run_loop`)."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    from sma_wrist.plants.loop import CASES, OffModelCase, run_loop

    fig, axes = plt.subplots(2, len(results), figsize=(4.2 * len(results), 6), sharex=True, squeeze=False)
    for col, (m, r) in enumerate(sorted(results.items())):
        t, q_d, q, T = run_schedules(r.schedule[None], m, plant)
        last = t >= t[-1] - SEED_PERIOD_S
        ax = axes[0, col]
        ax.plot(t[last], q_d[last], 'k--', lw=1, label='q_d')
        ax.plot(t[last], q[last, 0], 'C0', label=f'best schedule ({r.max_error_pct:.1f} %)')
        if mode is not None:
            case = CASES[plant](m) if plant in CASES else OffModelCase(plant, Scenario(payload_kg=m))
            lp = run_loop(case, mode, record=True)
            assert lp.trace is not None
            keep = lp.trace.t >= lp.trace.t[-1] - SEED_PERIOD_S
            ax.plot(lp.trace.t[keep], lp.trace.q[keep, 0], 'C3', lw=0.8, label=f'{mode} ({lp.max_error_pct:.1f} %)')
        ax.set_title(f'{plant}, {m:g} kg')
        ax.set_ylabel('angle [rad]')
        ax.legend(fontsize=7, loc='upper right')
        ax = axes[1, col]
        ax.plot(t[last], T[last, 0, 0], 'C1', label='muscle 1 (raises q)')
        ax.plot(t[last], T[last, 0, 1], 'C2', label='muscle 2')
        ax.set_ylabel('true muscle temperature [degC]')
        ax.set_xlabel('t [s]')
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _main(
    argv: list[str] | None = None,
) -> None:  # pragma: no cover - the figure quoted in doc/explanation/controllers.md
    import argparse
    import sys
    import time

    ap = argparse.ArgumentParser(description='dynamic reach of the Sec. 6.1 sine (module docstring)')
    ap.add_argument('--plant', default='phase_fraction')
    ap.add_argument('--payloads', default='0.1,0.3,0.6')
    ap.add_argument('--n', type=int, default=48, help='candidates per round')
    ap.add_argument('--rounds', type=int, default=3)
    ap.add_argument('--seed', type=int, default=0)
    ap.add_argument(
        '--start',
        default='',
        metavar='V1,...,V9',
        help=f'the schedule the search starts from ({",".join(FIELDS)}; default the hand-timed one)',
    )
    ap.add_argument('--plot', default='', metavar='PNG', help='draw the best schedules next to pid')
    a = ap.parse_args(argv)
    start = None
    if a.start:
        try:
            start = np.array([float(x) for x in a.start.split(',')])
        except ValueError as e:
            ap.error(f'--start: {e}')
        if start.shape != (len(FIELDS),) or not np.isfinite(start).all():
            ap.error(f'--start needs {len(FIELDS)} finite numbers: {",".join(FIELDS)}')
    try:
        payloads = [float(x) for x in a.payloads.split(',')]
    except ValueError as e:
        ap.error(f'--payloads: {e}')
    results = {}
    for m in payloads:
        wall = time.perf_counter()
        r = search(
            m,
            a.n,
            a.rounds,
            a.seed,
            a.plant,
            start=start,
            progress=lambda s: print(f'  {m:g} kg {s} ({time.perf_counter() - wall:.0f} s)', file=sys.stderr),
        )
        results[m] = r
        print(
            f'| {a.plant} | {m:g} | {r.max_error_pct:.2f} | {r.rms_error_pct:.2f} | {r.evaluated} | '
            + ', '.join(f'{k}={v:.2f}' for k, v in zip(FIELDS, r.schedule))
            + ' |',
            flush=True,
        )
    if a.plot:
        plot(results, a.plot, a.plant)
        print(f'plot: {a.plot}', file=sys.stderr)


if __name__ == '__main__':  # pragma: no cover
    _main()
