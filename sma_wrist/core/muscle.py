"""A muscle: a bundle of parallel Nitinol wires whose load follows from its elongation.

Coupling (docs/model.md): the joint angle fixes each bundle's elongation through the
chain; each wire's load m is the one at which the material elongation equals it::

    scale * y_SDGPI(T, m; memory) + c_el * m = y_geo        (1)

with y_SDGPI the SD-GPI elongation (Eqs. 4.1-4.6, mirror Eq. 4.2) of the 80 mm test wire
scaled to the bundle's 83 mm length (scale = 83/80), and c_el m the linear-elastic stretch.
Outside the calibrated load range the SD-GPI envelopes are frozen at the range edge and
only the elastic term varies, so (1) is strictly increasing in m (the default parameter
set makes y_SDGPI non-decreasing in m, Clausius-Clapeyron) and has one root.

The root is found against frozen operator memory by a safeguarded Newton iteration
(bracket [0, m_max], bisection when a Newton step leaves it), warm-started from the
previous load, then the memory update is committed at the root. All functions are
vectorised over any number of wires-bundles (scenarios x muscles flattened on axis 0).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from sma_wrist.core.hysteresis import SDGPIParams, memoryless, tanh_envelope

FloatArray = NDArray[np.float64]
G = 9.81  # m/s^2


@dataclass(frozen=True)
class MuscleGeometry:
    """Bundle geometry (Secs. 2.1.1, 2.1.3, 3.2.1)."""

    n_wires: int = 140
    wire_diameter_m: float = 0.25e-3
    wire_length_mm: float = 83.0  # exposed length of each wire in the wrist
    model_length_mm: float = 80.0  # effective length of the wire the SD-GPI describes
    youngs_modulus_Pa: float = 60e9  # between martensite (~30 GPa) and austenite (~75 GPa)
    max_load_kgf: float = 3.0  # search bracket; far beyond the ~1.5 kgf wire rating

    @property
    def wire_area_m2(self) -> float:
        return float(np.pi * 0.25 * self.wire_diameter_m ** 2)

    @property
    def length_scale(self) -> float:
        """Elongation of the bundle's wires per unit SD-GPI elongation (strain is preserved)."""
        return self.wire_length_mm / self.model_length_mm

    @property
    def elastic_mm_per_kgf(self) -> float:
        """Linear-elastic stretch of one wire per kgf [mm/kgf]."""
        return G * self.wire_length_mm / (self.youngs_modulus_Pa * self.wire_area_m2)

    def stress_Pa(self, load_kgf: FloatArray) -> FloatArray:
        """Wire stress for a per-wire load."""
        return np.asarray(load_kgf) * G / self.wire_area_m2

    def load_kgf(self, stress_Pa: FloatArray) -> FloatArray:
        """Per-wire load for a wire stress."""
        return np.asarray(stress_Pa) * self.wire_area_m2 / G


@dataclass
class LoadSolution:
    """Result of :func:`solve_load` for each bundle."""

    load_kgf: FloatArray  # per-wire load
    compliance_mm_per_kgf: FloatArray  # d(elongation)/d(load) at the root, > 0
    slack: NDArray[np.bool_]  # wire would need a negative load: it is slack, load 0
    overload: NDArray[np.bool_]  # root beyond max_load_kgf: load clamped there
    residual_mm: FloatArray


class MuscleModel:
    """Elongation-load relation (1) of a wire bundle and its root solve."""

    def __init__(self, params: SDGPIParams, geometry: MuscleGeometry | None = None) -> None:
        self.params = params
        self.geometry = geometry or MuscleGeometry()
        self.m_lo, self.m_hi = params.load_range
        self._r = params.thresholds
        self._p = params.weights

    def elongation(self, T: FloatArray, m: FloatArray, w: FloatArray, heating: NDArray[np.bool_]) -> tuple[FloatArray, FloatArray]:
        """(elongation [mm], d elongation / d m [mm/kgf]) of (1) with memory w frozen."""
        geo = self.geometry
        env = self.params.envelopes
        mc = np.clip(m, self.m_lo, self.m_hi)
        inside = (m > self.m_lo) & (m < self.m_hi)
        a, b = env.coefficients(mc)
        da, db = env.coefficient_slopes(mc)
        ua = a[:, 1] * T + a[:, 2]
        ub = b[:, 1] * T + b[:, 2]
        ta, tb = np.tanh(ua), np.tanh(ub)
        gamma_r = a[:, 0] * ta + a[:, 3]
        gamma_l = b[:, 0] * tb + b[:, 3]
        lower = gamma_l[:, None] - self._r
        upper = gamma_r[:, None] + self._r
        below = w < lower  # operator pushed up by the heating envelope
        above = w > upper  # operator pushed down by the cooling envelope
        w_now = np.minimum(np.maximum(w, lower), upper)
        y_m = memoryless(self.params, T, heating) + w_now @ self._p
        # d gamma/dm of k0 tanh(k1 T + k2) + k3 with every k quadratic in m (Eqs. 4.4-4.5)
        dgr = da[:, 0] * ta + a[:, 0] * (1.0 - ta * ta) * (da[:, 1] * T + da[:, 2]) + da[:, 3]
        dgl = db[:, 0] * tb + b[:, 0] * (1.0 - tb * tb) * (db[:, 1] * T + db[:, 2]) + db[:, 3]
        dym_dm = (below @ self._p) * dgl + (above @ self._p) * dgr
        y = geo.length_scale * (self.params.k_f - y_m) + geo.elastic_mm_per_kgf * m
        dy = geo.length_scale * np.where(inside, -dym_dm, 0.0) + geo.elastic_mm_per_kgf
        return y, dy

    def solve_load(self, T: FloatArray, y_geo_mm: FloatArray, w: FloatArray, heating: NDArray[np.bool_],
                   m_guess: FloatArray, iterations: int = 4) -> LoadSolution:
        """Per-wire load making (1) hold, against frozen memory ``w`` (not modified)."""
        m_max = self.geometry.max_load_kgf
        lo = np.zeros_like(m_guess)
        hi = np.full_like(m_guess, m_max)
        m = np.clip(m_guess, 0.0, m_max)
        for _ in range(iterations):
            y, dy = self.elongation(T, m, w, heating)
            f = y - y_geo_mm
            pos = f > 0
            hi = np.where(pos, m, hi)
            lo = np.where(pos, lo, m)
            step = m - f / dy
            ok = (step > lo) & (step < hi)
            m = np.where(ok, step, 0.5 * (lo + hi))
        y, dy = self.elongation(T, m, w, heating)
        res = y - y_geo_mm
        slack = (m <= 1e-9) & (res > 0)
        overload = (m >= m_max - 1e-9) & (res < 0)
        return LoadSolution(m, dy, slack, overload, res)

    def commit(self, T: FloatArray, m: FloatArray, w: FloatArray) -> None:
        """Commit the play-operator memory at the solved load (Eq. 3.19), in place."""
        mc = np.clip(m, self.m_lo, self.m_hi)
        a, b = self.params.envelopes.coefficients(mc)
        lower = tanh_envelope(b, T)[:, None] - self._r
        upper = tanh_envelope(a, T)[:, None] + self._r
        np.minimum(np.maximum(w, lower, out=w), upper, out=w)
