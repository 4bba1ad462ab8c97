"""Thermal data this project's model did not make: an independent TEM plant and sensor effects.

:class:`PeltierPlant` is a two-node lumped model of one thermoelectric module written from
first principles (not from Eqs. 4.13/4.14): faces 1 (muscle side) and 2 (heat-sink side)
with heat capacities C1, C2 [J/K]; Seebeck coefficient alpha [V/K] acting on absolute
temperature (Peltier heat alpha I T_K at each junction); Joule heat I^2 R / 2 per face with a
resistance that grows with the mean junction temperature; conduction K (T1 - T2) through the
module; heat-sink losses h (T - T_amb) plus natural convection c |T - T_amb|^1.25; and a
*voltage* drive whose current is limited by the module's back-EMF,
I = (u - alpha (T1 - T2)) / R(T). The seed's model instead has I proportional to u,
temperature in degC inside the Peltier term, constant coefficients and no convection law:
different in parameters and in structure.

:func:`sensor` applies what a thermocouple channel does: a first-order lag (0.1-0.2 s for a
bare K-type junction on a plate) and white noise, sampled by a DAQ. :func:`sine_runs`
produces the seed's Sec. 4.3.1 experiment (12 V sines, 1/128-1 Hz) on either plant.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from sma_wrist.core.thermal import heat_balance as th
from sma_wrist.core.thermal.identification import ThermalRecord, interval_means

KELVIN = 273.15


@dataclass(frozen=True)
class PeltierPlant:
    """One TEM between two heat sinks (SI units, degC). Defaults: a 12 V / 6 A class module."""

    alpha_V_per_K: float = 0.036
    R0_ohm: float = 2.3  # at 25 degC
    R_tempco_per_K: float = 0.004
    K_W_per_K: float = 0.55
    C1_J_per_K: float = 55.0  # face 1: plate, paste, wire bundle
    C2_J_per_K: float = 75.0  # face 2: plate and the heat sink's base
    h1_W_per_K: float = 1.9
    h2_W_per_K: float = 2.6
    conv1_W_per_K125: float = 0.05
    conv2_W_per_K125: float = 0.05
    ambient1_C: float = 24.0
    ambient2_C: float = 25.5

    def current(self, T: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Drive current [A] for faces T (..., 2) and voltage u (...,): back-EMF and R(T)."""
        R = self.R0_ohm * (1.0 + self.R_tempco_per_K * (0.5 * (T[..., 0] + T[..., 1]) - 25.0))
        return (u - self.alpha_V_per_K * (T[..., 0] - T[..., 1])) / R, R

    def derivative(self, T: np.ndarray, u: np.ndarray) -> np.ndarray:
        """dT/dt [degC/s]; u > 0 drives heat into face 1 (the muscle side)."""
        I, R = self.current(T, u)
        T1, T2 = T[..., 0], T[..., 1]
        joule = 0.5 * I * I * R
        cond = self.K_W_per_K * (T1 - T2)
        d1 = T1 - self.ambient1_C
        d2 = T2 - self.ambient2_C
        q1 = (
            self.alpha_V_per_K * I * (T1 + KELVIN)
            + joule
            - cond
            - self.h1_W_per_K * d1
            - self.conv1_W_per_K125 * np.sign(d1) * np.abs(d1) ** 1.25
        )
        q2 = (
            -self.alpha_V_per_K * I * (T2 + KELVIN)
            + joule
            + cond
            - self.h2_W_per_K * d2
            - self.conv2_W_per_K125 * np.sign(d2) * np.abs(d2) ** 1.25
        )
        return np.stack([q1 / self.C1_J_per_K, q2 / self.C2_J_per_K], axis=-1)

    def simulate(self, u_of_t, t_end: float, dt: float, T0: np.ndarray) -> np.ndarray:
        """RK4 with the voltage evaluated at every stage (a continuous drive): (K + 1, N, 2)."""
        n = int(round(t_end / dt))
        T = np.array(T0, dtype=float)
        out = np.empty((n + 1,) + T.shape)
        out[0] = T
        for k in range(n):
            t = k * dt
            u0, um, u1 = u_of_t(t), u_of_t(t + 0.5 * dt), u_of_t(t + dt)
            k1 = self.derivative(T, u0)
            k2 = self.derivative(T + 0.5 * dt * k1, um)
            k3 = self.derivative(T + 0.5 * dt * k2, um)
            k4 = self.derivative(T + dt * k3, u1)
            T = T + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
            out[k + 1] = T
        return out

    def rest(self, n: int) -> np.ndarray:
        """Zero-drive equilibrium of n plants (relaxed for 1200 s), (n, 2) degC."""
        T = np.tile([self.ambient1_C, self.ambient2_C], (n, 1)).astype(float)
        return self.simulate(lambda t: np.zeros(n), 1200.0, 0.5, T)[-1]


def sensor(T: np.ndarray, dt: float, lag_s: float, noise_C: float, rng: np.random.Generator) -> np.ndarray:
    """Thermocouple channel: exact first-order lag of time constant lag_s on the fine grid, then noise."""
    out = np.empty_like(T)
    a = np.exp(-dt / lag_s) if lag_s > 0 else 0.0
    y = T[0].copy()
    for k in range(T.shape[0]):
        y = a * y + (1.0 - a) * T[k]
        out[k] = y
    return out + noise_C * rng.standard_normal(T.shape) if noise_C > 0 else out


def sine_runs(
    plant: str | PeltierPlant = 'peltier',
    frequencies_Hz: Sequence[float] = th.SEED_SINE_FREQUENCIES_HZ,
    duration_s: float = 512.0,
    amplitude_V: float = 12.0,
    sample_dt: float = 0.1,
    fine_dt: float = 0.02,
    lag_s: float = 0.15,
    noise_C: float = 0.2,
    seed: int = 0,
    params: th.ThermalParams | None = None,
) -> list[ThermalRecord]:
    """The Sec. 4.3.1 experiment: u = A sin(2 pi f t) from rest, both faces logged every sample_dt.

    ``plant``: 'own' (Eqs. 4.13/4.14 with ``params``, default Table 4.9) or 'peltier' (or a
    :class:`PeltierPlant`). The drive is continuous (evaluated inside every fine step); the
    logged voltage is its sample at each logging instant.
    """
    f = np.asarray(frequencies_Hz, dtype=float)
    rng = np.random.default_rng(seed)

    def u_of_t(t: float) -> float:
        return amplitude_V * np.sin(2 * np.pi * f * t)

    stride = int(round(sample_dt / fine_dt))
    if plant == 'own':
        p = (params or th.ThermalParams()).with_limits(-2 * amplitude_V - 1, 2 * amplitude_V + 1)
        n = int(round(duration_s / fine_dt))
        T = th.rest_state(p, f.size, 1)
        fine = np.empty((n + 1, f.size, 2))
        fine[0] = T[:, 0]
        for k in range(n):  # midpoint sample of the continuous drive over each fine step
            T = th.step(p, T, u_of_t((k + 0.5) * fine_dt)[:, None], fine_dt, validate=False)
            fine[k + 1] = T[:, 0]
    else:
        pp = plant if isinstance(plant, PeltierPlant) else PeltierPlant()
        fine = pp.simulate(u_of_t, duration_s, fine_dt, pp.rest(f.size))
    meas = sensor(fine, fine_dt, lag_s, 0.0, rng)[::stride] if lag_s > 0 else fine[::stride].copy()
    if noise_C > 0:
        meas = meas + noise_C * rng.standard_normal(meas.shape)
    t = np.arange(meas.shape[0]) * sample_dt
    name = plant if isinstance(plant, str) else 'peltier'
    u = amplitude_V * np.sin(2 * np.pi * t[:, None] * f[None, :])  # what the DAQ logged
    out = []
    for j, fj in enumerate(f):  # as `identify thermal` reads a logged analog drive (--input-hold linear)
        um, u2 = interval_means(t, u[:, j], t, sample_dt, 'linear')
        out.append(ThermalRecord(f'{name} 1/{1 / fj:g} Hz', sample_dt, um, meas[:, j], float(fj), u2=u2))
    return out


def holdout_table(quick: bool = False, seed: int = 0) -> dict:
    """Held-out errors per frequency on own-model and off-model data, side by side (bench 'identify_thermal').

    The seed's experiment (12 V sines, 8 frequencies, both faces logged at 10 Hz) on four
    sources: the project's model (continuous drive, noise-free), the same with the sensor
    effects (thermocouple lag 0.15 s, noise 0.2 degC), the independent Peltier plant
    noise-free, and the Peltier plant with the sensor effects. Leave-one-frequency-out:
    every frequency is predicted by the fit on the other seven. Each row also gives the Peltier two-node form's
    held-out RMS (``*_peltier_rms_C``, :mod:`sma_wrist.core.thermal.peltier_fit`, fitted the same way): on the
    project's model it is the off-model form, on the Peltier plant Table 4.9's is.
    """
    import time as _time

    from sma_wrist.core.thermal import peltier_fit as pf
    from sma_wrist.core.thermal.identification import identify_thermal

    freqs = (1 / 128, 1 / 32, 1 / 8) if quick else th.SEED_SINE_FREQUENCIES_HZ
    duration = 128.0 if quick else 512.0
    sources = {
        'own, noise-free': ('own', 0.0, 0.0),
        'own + sensor': ('own', 0.15, 0.2),
        'peltier, noise-free': ('peltier', 0.0, 0.0),
        'peltier + sensor': ('peltier', 0.15, 0.2),
    }
    out: dict = {'frequencies_Hz': list(freqs), 'duration_s': duration, 'sources': {}}
    for label, (plant, lag, noise) in sources.items():
        recs = sine_runs(plant, freqs, duration_s=duration, lag_s=lag, noise_C=noise, seed=seed)
        t0 = _time.perf_counter()
        res = identify_thermal(recs)
        wall = _time.perf_counter() - t0
        before = {e.record: e for e in res.before}
        t1 = _time.perf_counter()
        peltier = {e.record: e for e in pf.leave_one_out(recs)}
        wall_peltier = _time.perf_counter() - t1
        rows = []
        for e in res.holdout:
            rows.append(
                {
                    'frequency_Hz': e.frequency_Hz,
                    **{f'{face}_rms_C': round(st['rms_C'], 4) for face, st in e.faces.items()},
                    **{f'{face}_std_pct': round(st['std_pct'], 3) for face, st in e.faces.items()},
                    **{f'{face}_max_abs_pct': round(st['max_abs_pct'], 3) for face, st in e.faces.items()},
                    **{f'{face}_default_rms_C': round(before[e.record].faces[face]['rms_C'], 4) for face in e.faces},
                    **{f'{face}_peltier_rms_C': round(peltier[e.record].faces[face]['rms_C'], 4) for face in e.faces},
                }
            )
        out['sources'][label] = {
            'in_sample_rms_C': round(res.fit.rms_C, 4),
            'wall_s': round(wall, 2),
            'peltier_wall_s': round(wall_peltier, 2),
            'fits': len(recs) + 1,
            'holdout': rows,
        }
    return out


def speed(quick: bool = False) -> dict:
    """Side by side on the same runs: the batched complex-step Jacobian vs forward differences with
    :func:`sma_wrist.core.thermal.heat_balance.simulate` (the plant's RK4, one parameter set per call), and the
    normal-equation Levenberg-Marquardt vs scipy's ``least_squares`` (trf) from the same start."""
    import dataclasses as dc
    import time as _time

    from scipy.optimize import least_squares

    from sma_wrist.core.thermal import identification as ti

    recs = sine_runs(
        'peltier',
        (1 / 128, 1 / 32, 1 / 8) if quick else th.SEED_SINE_FREQUENCIES_HZ,
        duration_s=128.0 if quick else 512.0,
    )
    base = th.ThermalParams()
    prob = ti._Problem(recs, base, (0, 1), None, 30.0)
    x0 = ti._free_from_table(ti.table_of(base), (0, 1))
    t0 = _time.perf_counter()
    prob._cache = None
    prob.jacobian(x0)
    t_cs = _time.perf_counter() - t0
    # forward differences through the plant's own integrator: 1 + 12 simulations of all runs
    u = np.stack([r.u for r in recs], axis=1)[:-1, :, None]
    T0 = ti.start_states(recs, base)[:, None, :]
    wide = base.with_limits(-30.0, 30.0)
    t0 = _time.perf_counter()
    for j in range(x0.size + 1):
        x = x0.copy()
        if j:
            x[j - 1] += 1e-7 * max(abs(x[j - 1]), 1e-3)
        p = dc.replace(
            ti.params_from_table(ti._table_from_free(x[None], prob.base_table, (0, 1))[0], wide),
            u_min_V=-30.0,
            u_max_V=30.0,
        )
        th.simulate(p, u, recs[0].dt, T0, layers=1, validate=False)
    t_fd = _time.perf_counter() - t0
    t0 = _time.perf_counter()
    fit = ti.fit_thermal(recs, base)
    t_lm = _time.perf_counter() - t0
    lo, hi = np.tile(ti._LOWER, 2), np.tile(ti._UPPER, 2)
    ee = ti._free_from_table(ti.equation_error_table(recs, base.input_per_volt), (0, 1))
    start = np.clip(ee if fit.start == 'equation_error' else x0, lo, hi)
    t0 = _time.perf_counter()
    sol = least_squares(prob.residuals, start, jac=prob.jacobian, bounds=(lo, hi), method='trf', x_scale='jac')
    t_trf = _time.perf_counter() - t0
    return {
        'runs': len(recs),
        'samples_per_run': recs[0].n,
        'jacobian_complex_step_batched_s': round(t_cs, 3),
        'jacobian_forward_diff_thermal_simulate_s': round(t_fd, 3),
        'jacobian_speedup': round(t_fd / t_cs, 1),
        'fit_lm_s': round(t_lm, 2),
        'fit_lm_rms_C': round(fit.rms_C, 5),
        'fit_scipy_trf_s': round(t_trf, 2),
        'fit_scipy_trf_rms_C': round(float(np.sqrt(2 * sol.cost)), 5),
        'fit_speedup': round(t_trf / t_lm, 1),
    }
