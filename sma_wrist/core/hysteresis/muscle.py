"""A muscle: a bundle of parallel Nitinol wires whose load follows from its elongation.

Coupling (doc/explanation/model.md): the joint angle fixes each bundle's elongation through the
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

from sma_wrist.core.hysteresis.sdgpi import SDGPIParams, memoryless

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
        return float(np.pi * 0.25 * self.wire_diameter_m**2)

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
    """Result of :meth:`MuscleModel.solve_load` for each bundle."""

    load_kgf: FloatArray  # per-wire load
    compliance_mm_per_kgf: FloatArray  # d(elongation)/d(load) at the root, > 0
    slack: NDArray[np.bool_]  # wire would need a negative load: it is slack, load 0
    overload: NDArray[np.bool_]  # root beyond max_load_kgf: load clamped there
    residual_mm: FloatArray
    memory: FloatArray  # (N, n) play memory committed at the solved load (Eq. 3.19)


class MuscleModel:
    """Elongation-load relation (1) of a wire bundle and its root solve."""

    def __init__(self, params: SDGPIParams, geometry: MuscleGeometry | None = None) -> None:
        self.params = params
        self.geometry = geometry or MuscleGeometry()
        self.m_lo, self.m_hi = params.load_range
        self._r = params.thresholds
        self._p = params.weights

    def elongation(
        self, T: FloatArray, m: FloatArray, w: FloatArray, heating: NDArray[np.bool_]
    ) -> tuple[FloatArray, FloatArray]:
        """(elongation [mm], d elongation / d m [mm/kgf]) of (1) with memory w frozen; 1-D arrays over bundles."""
        return self._elongation(T, m, w, memoryless(self.params, T, heating))[:2]

    def _elongation(
        self, T: FloatArray, m: FloatArray, w: FloatArray, y_memoryless: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """(y, dy/dm, memory committed at m) of (1) for frozen memory ``w``."""
        geo = self.geometry
        mc = np.minimum(np.maximum(m, self.m_lo), self.m_hi)
        k, dk = self.params.envelopes.coefficients_and_slopes(mc)  # (N, 2, 4): [a set, b set]
        Tc = T[:, None]
        th = np.tanh(k[:, :, 1] * Tc + k[:, :, 2])
        gamma = k[:, :, 0] * th + k[:, :, 3]  # (gamma_r, gamma_l)
        lower = gamma[:, 1:2] - self._r
        upper = gamma[:, 0:1] + self._r
        below = w < lower  # operator pushed up by the heating envelope
        above = w > upper  # operator pushed down by the cooling envelope
        w_now = np.minimum(np.maximum(w, lower), upper)
        y_m = y_memoryless + w_now @ self._p
        # d gamma/dm of k0 tanh(k1 T + k2) + k3 with every k quadratic in m (Eqs. 4.4-4.5)
        dgamma = dk[:, :, 0] * th + k[:, :, 0] * (1.0 - th * th) * (dk[:, :, 1] * Tc + dk[:, :, 2]) + dk[:, :, 3]
        dym_dm = (below @ self._p) * dgamma[:, 1] + (above @ self._p) * dgamma[:, 0]
        inside = (m > self.m_lo) & (m < self.m_hi)  # envelopes are frozen outside the calibrated loads
        y = geo.length_scale * (self.params.k_f - y_m) + geo.elastic_mm_per_kgf * m
        dy = geo.elastic_mm_per_kgf - geo.length_scale * (dym_dm * inside)
        return y, dy, w_now

    def solve_load(
        self,
        T: FloatArray,
        y_geo_mm: FloatArray,
        w: FloatArray,
        heating: NDArray[np.bool_],
        m_guess: FloatArray,
        tol_mm: float = 1e-7,
        max_iterations: int = 60,
    ) -> LoadSolution:
        """Per-wire load making (1) hold, against frozen memory ``w`` (not modified).

        Newton from ``m_guess`` safeguarded by a bracket that every evaluation narrows
        (``rtsafe``): (1) is monotone but only piecewise smooth (operators start and stop
        moving, the stress plateau is ~100x softer than the elastic branch), so a bare
        Newton step can overshoot a kink; then the bracket's midpoint is taken. Only the
        wires whose residual exceeds ``tol_mm`` are iterated, so a warm start from the
        previous step's load costs one or two evaluations. While every wire is still
        active the iteration works on the whole arrays (views, no fancy-index copies of
        the (N, n) memory); once some have converged, on the active subset.

        The memory committed at the root (Eq. 3.19 at the solved load) is returned in
        ``LoadSolution.memory``; :meth:`commit` gives the same array.
        """
        m_max = self.geometry.max_load_kgf
        m = np.minimum(np.maximum(np.asarray(m_guess, dtype=float), 0.0), m_max)
        lo = np.zeros_like(m)
        hi = np.full_like(m, m_max)
        y0 = memoryless(self.params, T, heating)  # independent of the load: once per solve
        y, dy, w_now = self._elongation(T, m, w, y0)
        res = y - y_geo_mm
        bad = np.abs(res) > tol_mm
        n_total = m.size
        active: NDArray[np.intp] | slice = slice(None) if bad.all() else np.flatnonzero(bad)
        n_active = n_total if isinstance(active, slice) else active.size
        for _ in range(max_iterations):
            if n_active == 0:
                break
            f = res[active]
            ma = m[active]
            pos = f > 0
            la = np.where(pos, lo[active], ma)
            ha = np.where(pos, ma, hi[active])
            lo[active] = la
            hi[active] = ha
            newton = ma - f / dy[active]
            inside = (newton > la) & (newton < ha)
            m_new = np.where(inside, newton, 0.5 * (la + ha))
            # a bracket collapsed onto 0 or m_max: the root is outside, the wire is slack/overloaded
            done = (ha - la) < 1e-12
            m[active] = m_new
            if isinstance(active, slice):
                y, dy, w_now = self._elongation(T, m_new, w, y0)
                res = y - y_geo_mm
                keep = (np.abs(res) > tol_mm) & ~done
                if keep.all():
                    continue
                active = np.flatnonzero(keep)
            else:
                ya, dya, wa = self._elongation(T[active], m_new, w[active], y0[active])
                y[active], dy[active], w_now[active] = ya, dya, wa
                ra = ya - y_geo_mm[active]
                res[active] = ra
                active = active[(np.abs(ra) > tol_mm) & ~done]
            n_active = active.size
        slack = (m <= 1e-9) & (res > tol_mm)
        overload = (m >= m_max - 1e-9) & (res < -tol_mm)
        return LoadSolution(m, dy, slack, overload, res, w_now)

    def commit(self, T: FloatArray, m: FloatArray, w: FloatArray) -> None:
        """Commit the play-operator memory at the solved load (Eq. 3.19), in place."""
        mc = np.minimum(np.maximum(m, self.m_lo), self.m_hi)
        k, _ = self.params.envelopes.coefficients_and_slopes(mc)
        gamma = k[:, :, 0] * np.tanh(k[:, :, 1] * T[:, None] + k[:, :, 2]) + k[:, :, 3]
        lower = gamma[:, 1:2] - self._r
        upper = gamma[:, 0:1] + self._r
        np.minimum(np.maximum(w, lower, out=w), upper, out=w)
