"""Benchmarks as numbers: ``sma-wrist bench [--json] [--quick] [--section NAME ...]``.

Every section is a function ``(quick: bool) -> dict`` registered under a name in
:data:`SECTIONS` (use the :func:`section` decorator); :func:`run` calls the requested ones in
one process and returns ``{'meta': ..., name: result, ...}``. Other engineers add sections
('graph', 'experiment', 'diagnose', 'bridge') the same way: define the function in their
module and register it here, importing lazily inside it so a section costs nothing unless run.

Section 'plant' measures, in one run, the plant's steps per second:

* ``per_sample``: :class:`sma_wrist.core.plant.WristPlant` with one wrist (the node's path);
* ``batched``: the same class with >= 256 wrists (plant-steps/s = wrists x steps / s);
* ``plain``: :class:`PlainWrist`, a straightforward pure-Python (``math``) implementation of
  the *same* step for one wrist, written as the reference: no numpy, one scalar per quantity,
  the textbook four-stage RK4, the same bracketed Newton load solve, the same joint update.
  It is the yardstick for the ratios ``batched/plain`` and ``per_sample/plain`` and, through
  ``test/test_plant.py``, an independent check of the numpy plant's numbers.
"""
from __future__ import annotations

import argparse
import bisect
import json
import math
import os
import platform
import sys
import time
from typing import Callable

import numpy as np

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
    """One wrist stepped in plain Python: the reference implementation of WristPlant.step.

    Same equations, same parameters (read from :class:`PlantParams`), same initial state
    (taken from ``WristPlant(params, payload_kg).state``: the set-up is shared, the step is
    written independently). See docs/model.md for the equations.
    """

    def __init__(self, params: object | None = None, payload_kg: float = 0.3) -> None:
        from sma_wrist.core.plant import PlantParams, WristPlant

        p = params or PlantParams()
        s = WristPlant(p, payload_kg=payload_kg).state
        self.p = p
        tp = p.thermal
        self.ipv = tp.input_per_volt
        self.u_lim = (tp.u_min_V, tp.u_max_V)
        self.k_at, self.k_t = tp._k_at.tolist(), tp._k_t.tolist()
        self.k_tinf, self.k_tc = tp._k_tinf.tolist(), tp._k_tc.tolist()
        self.k_r, self.k_inf = tp._k_r.tolist(), tp._k_inf.tolist()
        self.coupling = tp.coupling_per_s
        h = p.hysteresis
        self.edges = h.envelopes.edges_kg.tolist()
        self.a = h.envelopes.a.tolist()
        self.b = h.envelopes.b.tolist()
        self.c, self.d = h.c.tolist(), h.d.tolist()
        self.p0, self.k_f = h.p0, h.k_f
        self.r = h.thresholds.tolist()
        self.wts = h.weights.tolist()
        self.m_lo, self.m_hi = h.load_range
        self.T_valid = h.T_valid
        g = p.muscle
        self.scale, self.c_el = g.length_scale, g.elastic_mm_per_kgf
        self.m_max = g.max_load_kgf
        self.n_wires = g.n_wires
        j = p.joint
        self.j = j
        self.R = j.r_eff_m
        self.inertia = j.joint_inertia_kgm2 + payload_kg * j.lever_m ** 2
        self.payload = payload_kg
        self.faces = [s.thermal[0, layer].tolist() for layer in range(2)]  # [[muscle, exchanger], ...]
        self.q, self.qd = float(s.q[0]), float(s.qd[0])
        self.w = [s.w[i].tolist() for i in range(2)]
        self.heating = [bool(s.heating[i]) for i in range(2)]
        self.T_prev = [float(s.T_prev[i]) for i in range(2)]
        self.m = [float(s.load_kgf[i]) for i in range(2)]

    @property
    def T1(self) -> float:
        return self.faces[0][0]

    def _dT(self, T: list[float], i: float, other_muscle: float) -> list[float]:
        out = []
        for f in range(2):
            own, oth = T[f], T[1 - f]
            d = self.k_r[f] * i * i + (self.k_at[f] * own + self.k_t[f] * oth) * i \
                - self.k_tinf[f] * own + self.k_tc[f] * oth + self.k_inf[f]
            if f == 0 and self.coupling:
                d += self.coupling * (other_muscle - own)
            out.append(d)
        return out

    def _thermal(self, u1: float, u2: float, h: float) -> None:
        cur = [-self.ipv * u1, -self.ipv * u2]
        if self.coupling:  # couples the layers: integrate all four faces together
            def f(x: list[list[float]]) -> list[list[float]]:
                return [self._dT(x[L], cur[L], x[1 - L][0]) for L in range(2)]
            x0 = self.faces
            k1 = f(x0)
            k2 = f([[x0[L][i] + 0.5 * h * k1[L][i] for i in range(2)] for L in range(2)])
            k3 = f([[x0[L][i] + 0.5 * h * k2[L][i] for i in range(2)] for L in range(2)])
            k4 = f([[x0[L][i] + h * k3[L][i] for i in range(2)] for L in range(2)])
            self.faces = [[x0[L][i] + h / 6.0 * (k1[L][i] + 2 * k2[L][i] + 2 * k3[L][i] + k4[L][i])
                           for i in range(2)] for L in range(2)]
            return
        for L in range(2):
            x = self.faces[L]
            i = cur[L]
            k1 = self._dT(x, i, 0.0)
            k2 = self._dT([x[0] + 0.5 * h * k1[0], x[1] + 0.5 * h * k1[1]], i, 0.0)
            k3 = self._dT([x[0] + 0.5 * h * k2[0], x[1] + 0.5 * h * k2[1]], i, 0.0)
            k4 = self._dT([x[0] + h * k3[0], x[1] + h * k3[1]], i, 0.0)
            self.faces[L] = [x[n] + h / 6.0 * (k1[n] + 2.0 * k2[n] + 2.0 * k3[n] + k4[n]) for n in range(2)]

    def _elongation(self, T: float, m: float, w: list[float], y0: float) -> tuple[float, float, list[float]]:
        mc = min(max(m, self.m_lo), self.m_hi)
        k = min(max(bisect.bisect_right(self.edges, mc) - 1, 0), len(self.edges) - 2)
        gam, dgam = [], []
        for s in (self.a[k], self.b[k]):  # gamma_r (a set), gamma_l (b set), Eqs. 3.21, 4.4-4.5
            c = [(q2 * mc + q1) * mc + q0 for q2, q1, q0 in s]
            dc = [2.0 * q2 * mc + q1 for q2, q1, _ in s]
            t = math.tanh(c[1] * T + c[2])
            gam.append(c[0] * t + c[3])
            dgam.append(dc[0] * t + c[0] * (1.0 - t * t) * (dc[1] * T + dc[2]) + dc[3])
        ym, dym, w_now = y0, 0.0, []
        for wj, rj, pj in zip(w, self.r, self.wts):  # Eq. 3.19 against frozen memory
            lower, upper = gam[1] - rj, gam[0] + rj
            if wj < lower:
                v, dym = lower, dym + pj * dgam[1]
            elif wj > upper:
                v, dym = upper, dym + pj * dgam[0]
            else:
                v = wj
            w_now.append(v)
            ym += pj * v
        if not (self.m_lo < m < self.m_hi):
            dym = 0.0
        return (self.scale * (self.k_f - ym) + self.c_el * m,
                self.c_el - self.scale * dym, w_now)

    def _solve(self, i: int, T: float, y_geo: float) -> float:
        tol = self.p.load_tolerance_mm
        cset = self.c if self.heating[i] else self.d
        y0 = self.p0 * (cset[0] * math.tanh(cset[1] * T + cset[2]) + cset[3])
        m = min(max(self.m[i], 0.0), self.m_max)
        lo, hi = 0.0, self.m_max
        y, dy, w_now = self._elongation(T, m, self.w[i], y0)
        res = y - y_geo
        for _ in range(60):
            if abs(res) <= tol:
                break
            if res > 0:
                hi = m
            else:
                lo = m
            if hi - lo < 1e-12:
                break
            newton = m - res / dy
            m = newton if lo < newton < hi else 0.5 * (lo + hi)
            y, dy, w_now = self._elongation(T, m, self.w[i], y0)
            res = y - y_geo
        self.w[i] = w_now
        self.m[i] = m
        return dy

    def step(self, u1: float, u2: float) -> None:
        lo, hi = self.u_lim
        u1, u2 = min(max(u1, lo), hi), min(max(u2, lo), hi)
        p, j = self.p, self.j
        self._thermal(u1, u2, p.dt)
        x = 1e3 * self.R * (self.q - j.q_neutral_rad)
        y_geo = (p.preload_elongation_mm - x, p.preload_elongation_mm + x)
        compliance = []
        for i in range(2):
            T = min(max(self.faces[i][0], self.T_valid[0]), self.T_valid[1])
            if T > self.T_prev[i]:
                self.heating[i] = True
            elif T < self.T_prev[i]:
                self.heating[i] = False
            self.T_prev[i] = T
            compliance.append(self._solve(i, T, y_geo[i]))
        ngr = self.n_wires * 9.81 * self.R
        torque = ngr * (self.m[0] - self.m[1])
        stiffness = ngr * 1e3 * self.R * (1.0 / compliance[0] + 1.0 / compliance[1])
        # Eq. 4.18, linearly implicit Euler (joint.joint_step)
        q, qd, dt = self.q, self.qd, p.dt
        tau = torque - self.payload * 9.81 * j.lever_m * math.cos(q)
        at_rest = abs(qd) < j.stick_velocity_rad_s
        sign = (lambda v: (v > 0) - (v < 0))
        direction = sign(tau) if at_rest else sign(qd)
        h_i = dt / self.inertia
        qd_new = (qd + h_i * (tau - direction * j.coulomb_Nm)) / (1.0 + h_i * (j.viscous_Nms + dt * stiffness))
        stuck = at_rest and abs(tau) <= j.static_Nm
        reversed_ = (not at_rest) and sign(qd_new) != sign(qd) and abs(tau) <= j.static_Nm + j.coulomb_Nm
        if stuck or reversed_:
            qd_new = 0.0
        q_new = q + dt * qd_new
        if q_new < j.q_min_rad or q_new > j.q_max_rad:
            q_new, qd_new = min(max(q_new, j.q_min_rad), j.q_max_rad), 0.0
        self.q, self.qd = q_new, qd_new


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
    from sma_wrist.core.plant import PlantParams, WristPlant

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
    return {
        **compiled,
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
    from sma_wrist.core import plant_kernel
    from sma_wrist.core.plant import WristPlant

    if not plant_kernel.AVAILABLE:
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


# -------------------------------------------------------------------------------- driver

def run(sections: list[str] | None = None, quick: bool = False) -> dict:
    """Run the named sections (all registered ones by default) and return their results."""
    names = list(SECTIONS) if not sections else list(sections)
    unknown = [n for n in names if n not in SECTIONS]
    if unknown:
        raise ValueError(f'unknown benchmark section(s) {unknown}; known: {sorted(SECTIONS)}')
    out: dict = {'meta': {'python': platform.python_version(), 'numpy': np.__version__,
                          'machine': platform.machine(), 'cpu_count': os.cpu_count(), 'quick': quick}}
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
    a = ap.parse_args(argv)
    json.dump(run(a.section, quick=a.quick), sys.stdout, indent=2)
    sys.stdout.write('\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
