"""Estimates the bridge publishes for quantities the wrist does not measure.

The device measures temperatures and the angle only. The per-wire stress (what
plant_sim publishes from its state) is **estimated** here with the plant's own
SD-GPI wire-load solve (sma_wrist.core.hysteresis.muscle.MuscleModel) at the measured muscle
temperatures and the bundle elongations the measured angle implies (Eq. 4.17), with the
play memory tracked across calls exactly as WristPlant does. The estimate is as good as
the model (doc/explanation/model.md); on the emulator it reproduces the plant's stress up to sensor
noise. The wire is stiff, so a stress solved from measured temperatures and angle multiplies
their noise (and noise that flips a temperature's direction moves the SD-GPI between its
branches): the solve takes them through :class:`InputFilter`, a random-walk Kalman filter whose
measurement noise is each window's own spread, so clean sensors pass unfiltered and noisy ones
are smoothed (the published measurements are not filtered). Velocity is a least-squares
slope over the samples of one publish window, low-pass filtered.
"""

from __future__ import annotations

import numpy as np

from sma_wrist.core.joint.dynamics import G
from sma_wrist.core.plant.wrist import PlantParams, WristPlant


class InputFilter:
    """Scalar random-walk Kalman filter per channel (T1 [degC], T2 [degC], q [rad]).

    Each true value wanders as a random walk of ``drift`` per sqrt(s) (process noise drift**2 dt);
    each measurement comes with its variance (for a window mean: the samples' variance / n). A
    measurement without variance is taken as it is; the noisier it is against the drift, the longer
    the filter's memory (steady gain K = (-l + sqrt(l**2 + 4 l)) / 2, l = drift**2 dt / variance).
    """

    def __init__(self, drift: tuple[float, float, float]) -> None:
        self.set_drift(drift)
        self.x: np.ndarray | None = None
        self.P = np.zeros(3)

    def set_drift(self, drift: tuple[float, float, float]) -> None:
        d = np.asarray(drift, float)
        if d.shape != (3,) or not np.all(d > 0):  # NaN fails too
            raise ValueError(f'drift must be three numbers > 0 (degC, degC, rad per sqrt(s)), got {drift!r}')
        self.q_c = d**2

    def update(self, z: np.ndarray, variance: np.ndarray, dt_s: float) -> np.ndarray:
        """The filtered (T1, T2, q) after measurement z with the given variances, dt_s [s] after the last."""
        z = np.asarray(z, float)
        R = np.maximum(np.asarray(variance, float), 0.0)
        if self.x is None:
            self.x, self.P = z.copy(), R.copy()
            return self.x
        P = self.P + self.q_c * max(dt_s, 0.0)
        K = np.divide(P, P + R, out=np.ones(3), where=P + R > 0)
        self.x = self.x + K * (z - self.x)
        self.P = (1.0 - K) * P
        return self.x


class StressEstimator:
    """Model-based wire stress [Pa] and muscle torque [N m] from measured T [degC] and q [rad].

    ``drift`` (degC, degC, rad per sqrt(s)) sets :class:`InputFilter` on (T1, T2, q) before the solve;
    None: the measurements as they are.
    """

    def __init__(
        self,
        params: PlantParams | None = None,
        payload_kg: float = 0.3,
        drift: tuple[float, float, float] | None = None,
    ) -> None:
        self.filter = None if drift is None else InputFilter(drift)
        self.params = params or PlantParams()
        plant = WristPlant(self.params, payload_kg=payload_kg)  # rest state: memory, loads
        s = plant.state
        self.muscles = plant.muscles
        self.w = s.w.copy()
        self.heating = s.heating.copy()
        self.T_prev = s.T_prev.copy()
        self.load_kgf = s.load_kgf.copy()

    def update(
        self,
        T1_C: float,
        T2_C: float,
        q_rad: float,
        dt_s: float = 0.01,
        variance: tuple[float, float, float] = (0.0, 0.0, 0.0),
    ) -> tuple[float, float, float]:
        """(stress 1 [Pa], stress 2 [Pa], net muscle torque [N m]); inputs must be finite, ``dt_s`` [s]
        is the time since the previous call, ``variance`` that of each input [degC^2, degC^2, rad^2]."""
        p = self.params
        x = np.array([T1_C, T2_C, q_rad], float)
        if self.filter is not None:
            x = self.filter.update(x, np.asarray(variance, float), dt_s)
        lo, hi = p.hysteresis.T_valid
        T = np.clip(x[:2], lo, hi)
        dT = T - self.T_prev
        self.heating[dT > 0] = True
        self.heating[dT < 0] = False
        self.T_prev = T
        q = float(np.clip(x[2], p.joint.q_min_rad, p.joint.q_max_rad))
        xc = p.joint.chain_displacement_mm(np.array([q]))
        y_geo = np.concatenate([p.preload_elongation_mm - xc, p.preload_elongation_mm + xc])
        sol = self.muscles.solve_load(T, y_geo, self.w, self.heating, self.load_kgf, p.load_tolerance_mm)
        self.w = sol.memory
        self.load_kgf = sol.load_kgf
        stress = p.muscle.stress_Pa(sol.load_kgf)
        torque = p.muscle.n_wires * G * p.joint.r_eff_m * float(sol.load_kgf[0] - sol.load_kgf[1])
        return float(stress[0]), float(stress[1]), torque


def slope(t: np.ndarray, y: np.ndarray) -> tuple[float, float, float]:
    """Least-squares line through (t, y): (value at t[-1], slope, that value's variance from the
    residuals); fewer than three points or no spread in t -> a variance of 0 (unknown)."""
    if t.size < 2:
        return float(y[-1]), 0.0, 0.0
    tm = t.mean()
    dt = t - tm
    den = float(dt @ dt)
    if den <= 0:
        return float(y.mean()), 0.0, 0.0
    b = float(dt @ (y - y.mean())) / den
    end = float(y.mean() + b * (t[-1] - tm))
    if t.size < 3:
        return end, b, 0.0
    r = y - (y.mean() + b * dt)
    s2 = float(r @ r) / (t.size - 2)
    return end, b, s2 * (1.0 / t.size + (t[-1] - tm) ** 2 / den)


__all__ = ['InputFilter', 'StressEstimator', 'slope']
