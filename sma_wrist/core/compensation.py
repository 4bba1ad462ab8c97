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

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sma_wrist.core.errors import check_finite
from sma_wrist.core.hysteresis import SDGPIParams
from sma_wrist.core.inverse import InverseCompensator
from sma_wrist.core.muscle import MuscleGeometry

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

    def reset(self, T0_C: ArrayLike, stress_Pa: ArrayLike, branch: str = 'cooling') -> None:
        """Start the inverse's memory at measured temperatures and stresses."""
        m = self._load(np.asarray(stress_Pa, float))[0]
        self.inverse.reset(np.asarray(T0_C, float), m, branch=branch)

    def observe(self, T_C: ArrayLike, stress_Pa: ArrayLike) -> None:
        """Advance the memory with measured temperatures and stresses (InverseCompensator.observe)."""
        sigma = np.asarray(stress_Pa, float)
        check_finite('measured stress', sigma, 'Pa')
        self.inverse.observe(np.asarray(T_C, float), self._load(sigma)[0])

    def _load(self, stress_Pa: FloatArray) -> tuple[FloatArray, NDArray[np.bool_]]:
        m = self.geometry.load_kgf(stress_Pa)
        lo, hi = self.params.load_range
        return np.clip(m, lo, hi), (m < lo) | (m > hi)

    def __call__(self, strain: ArrayLike, stress_Pa: ArrayLike, *, commit: bool = True) -> CompensationResult:
        """Desired temperatures; ``commit`` advances the memory to them (Eq. 5.5), else :meth:`observe` does."""
        eps = np.asarray(strain, float)
        sigma = np.asarray(stress_Pa, float)
        check_finite('desired strain', eps)
        check_finite('desired stress', sigma, 'Pa')
        g = self.geometry
        m, clipped = self._load(sigma)
        y = (eps * g.wire_length_mm - g.elastic_mm_per_kgf * m) / g.length_scale
        res = self.inverse.solve(y, m, commit=commit)
        return CompensationResult(res.T, res.saturated, clipped, m, y)


__all__ = ['MuscleCompensator', 'CompensationResult']
