"""Inverse compensation in the wrist's own coordinates: bundle strain + wire stress -> temperature.

The back-stepping law asks each muscle for a force at the elongation the chain gives it
(Eq. 5.32 with Eq. 4.17); :class:`sma_wrist.core.inverse.InverseCompensator` works in the
SD-GPI's coordinates (elongation of the 80 mm model wire, per-wire load). The muscle model
(:mod:`sma_wrist.core.muscle`, Eq. 1 there) links them::

    y_bundle = (L_wire / L_model) y_SDGPI(T, m) + c_el m,     m = sigma A / g,   y_bundle = eps L_wire

so the SD-GPI target is y_SDGPI = (eps L_wire - c_el m) / (L_wire / L_model). Loads outside
the SD-GPI's calibrated range are clipped to it and reported (the inverse is undefined there).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sma_wrist.core.errors import check_finite
from sma_wrist.core.hysteresis import SDGPIParams
from sma_wrist.core.inverse import InverseCompensator
from sma_wrist.core.muscle import G, MuscleGeometry

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class CompensationResult:
    temperature_C: FloatArray  # desired muscle temperatures
    saturated: NDArray[np.bool_]  # target unreachable inside the temperature window
    load_clipped: NDArray[np.bool_]  # requested load outside the SD-GPI's calibrated range
    load_kgf: FloatArray  # per-wire load used (after clipping)
    sdgpi_elongation_mm: FloatArray  # target handed to the inverse


class MuscleCompensator:
    """Desired temperature of each muscle from its desired strain and wire stress (Eqs. 5.5-5.8)."""

    def __init__(self, params: SDGPIParams, geometry: MuscleGeometry | None = None,
                 T_range_C: tuple[float, float] = (20.0, 80.0), method: str = 'numerical') -> None:
        self.params = params
        self.geometry = geometry or MuscleGeometry()
        self.inverse = InverseCompensator(params, T_range=T_range_C, method=method)
        g = self.geometry
        # the geometry's properties as floats, read once (they are recomputed on every access)
        self._area_m2, self._wire_mm = g.wire_area_m2, float(g.wire_length_mm)
        self._c_el, self._scale = g.elastic_mm_per_kgf, g.length_scale
        self._load_range = params.load_range

    def reset(self, T0_C: ArrayLike, stress_Pa: ArrayLike, branch: str = 'cooling') -> None:
        """Start the inverse's memory at measured temperatures and stresses."""
        m = self._load(np.asarray(stress_Pa, float))[0]
        self.inverse.reset(np.asarray(T0_C, float), m, branch=branch)

    def observe(self, T_C: ArrayLike, stress_Pa: ArrayLike) -> None:
        """Advance the memory with measured temperatures and stresses (InverseCompensator.observe)."""
        sigma = np.asarray(stress_Pa, float)
        _check_finite('measured stress', sigma, 'Pa')
        # the load unclipped: observe clips it to the same range itself
        m = np.array(self._kgf(sigma))
        self.inverse.observe(np.asarray(T_C, float), m.reshape(sigma.shape) if sigma.ndim != 1 else m)

    def _kgf(self, stress_Pa: FloatArray) -> list[float]:
        """MuscleGeometry.load_kgf, m = sigma A / g, on the flattened stresses as Python floats: on
        the node's two wires a fraction of the numpy calls on (2,) arrays, the same IEEE operations."""
        area = self._area_m2
        return [s * area / G for s in stress_Pa.ravel().tolist()]

    def _load(self, stress_Pa: FloatArray) -> tuple[FloatArray, NDArray[np.bool_]]:
        """(per-wire load clipped to the SD-GPI's range, clipped flags), shaped as stress_Pa."""
        lo, hi = self._load_range
        m = self._kgf(stress_Pa)
        m_c, out = np.array([min(max(x, lo), hi) for x in m]), np.array([x < lo or x > hi for x in m], np.bool_)
        if stress_Pa.ndim != 1:
            m_c, out = m_c.reshape(stress_Pa.shape), out.reshape(stress_Pa.shape)
        return m_c, out

    def _target(self, eps: float, m: float) -> float:
        """SD-GPI elongation for bundle strain eps at load m: y = (eps L_wire - c_el m) / (L_wire / L_model)."""
        return (eps * self._wire_mm - self._c_el * m) / self._scale

    def __call__(self, strain: ArrayLike, stress_Pa: ArrayLike, *, commit: bool = True) -> CompensationResult:
        """Desired temperatures; ``commit`` advances the memory to them (Eq. 5.5), else :meth:`observe` does."""
        eps = np.asarray(strain, float)
        sigma = np.asarray(stress_Pa, float)
        _check_finite('desired strain', eps)
        _check_finite('desired stress', sigma, 'Pa')
        m, clipped = self._load(sigma)
        if eps.shape == m.shape:  # the node's call: float by float (see _load)
            y = np.array([self._target(e, x) for e, x in zip(eps.ravel().tolist(), m.ravel().tolist())])
            y = y.reshape(eps.shape) if eps.ndim != 1 else y
        else:  # broadcast shapes: the same expression on arrays
            y = self._target(eps, m)  # type: ignore[arg-type]
        res = self.inverse.solve(y, m, commit=commit)
        return CompensationResult(res.T, res.saturated, clipped, m, y)


def _check_finite(name: str, x: FloatArray, unit: str = '') -> None:
    """check_finite for a float array: a few float tests on the node's (2,) arrays (np.isfinite
    costs more than the rest of the conversion), check_finite's message on a bad value."""
    if x.size > 8 or not all(map(math.isfinite, x.ravel().tolist())):
        check_finite(name, x, unit)


__all__ = ['MuscleCompensator', 'CompensationResult']
