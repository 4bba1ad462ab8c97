"""Estimates the bridge publishes for quantities the wrist does not measure.

The device measures temperatures and the angle only. The per-wire stress (what
plant_sim publishes from its state) is **estimated** here with the plant's own
SD-GPI wire-load solve (sma_wrist.core.hysteresis.muscle.MuscleModel) at the measured muscle
temperatures and the bundle elongations the measured angle implies (Eq. 4.17), with the
play memory tracked across calls exactly as WristPlant does. The estimate is as good as
the model (docs/model.md); on the emulator it reproduces the plant's stress up to sensor
noise. Velocity is a least-squares slope over the samples of one publish window, low-pass
filtered.
"""
from __future__ import annotations

import numpy as np

from sma_wrist.core.joint.dynamics import G
from sma_wrist.core.plant.wrist import PlantParams, WristPlant


class StressEstimator:
    """Model-based wire stress [Pa] and muscle torque [N m] from measured T [degC] and q [rad]."""

    def __init__(self, params: PlantParams | None = None, payload_kg: float = 0.3) -> None:
        self.params = params or PlantParams()
        plant = WristPlant(self.params, payload_kg=payload_kg)  # rest state: memory, loads
        s = plant.state
        self.muscles = plant.muscles
        self.w = s.w.copy()
        self.heating = s.heating.copy()
        self.T_prev = s.T_prev.copy()
        self.load_kgf = s.load_kgf.copy()

    def update(self, T1_C: float, T2_C: float, q_rad: float) -> tuple[float, float, float]:
        """(stress 1 [Pa], stress 2 [Pa], net muscle torque [N m]); inputs must be finite."""
        p = self.params
        lo, hi = p.hysteresis.T_valid
        T = np.clip(np.array([T1_C, T2_C], float), lo, hi)
        dT = T - self.T_prev
        self.heating[dT > 0] = True
        self.heating[dT < 0] = False
        self.T_prev = T
        q = float(np.clip(q_rad, p.joint.q_min_rad, p.joint.q_max_rad))
        x = p.joint.chain_displacement_mm(np.array([q]))
        y_geo = np.concatenate([p.preload_elongation_mm - x, p.preload_elongation_mm + x])
        sol = self.muscles.solve_load(T, y_geo, self.w, self.heating, self.load_kgf, p.load_tolerance_mm)
        self.w = sol.memory
        self.load_kgf = sol.load_kgf
        stress = p.muscle.stress_Pa(sol.load_kgf)
        torque = p.muscle.n_wires * G * p.joint.r_eff_m * float(sol.load_kgf[0] - sol.load_kgf[1])
        return float(stress[0]), float(stress[1]), torque


def slope(t: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Least-squares line through (t, y): (value at t[-1], slope); one point -> (y, 0)."""
    if t.size < 2:
        return float(y[-1]), 0.0
    tm = t.mean()
    dt = t - tm
    den = float(dt @ dt)
    if den <= 0:
        return float(y.mean()), 0.0
    b = float(dt @ (y - y.mean())) / den
    return float(y.mean() + b * (t[-1] - tm)), b


__all__ = ['StressEstimator', 'slope']
