"""Warps of an SD-GPI wire: the same model with its transitions moved, widened, its stroke and stress dependence
scaled (a hotter wire for the bench, a wire recalibrated from a wrist's own angle by commissioning).

Every tanh of Eqs. 3.21-3.22 is k0 tanh(k1 T + k2) + k3, and on each load section of Eqs. 4.4-4.5 every k_i is a
quadratic of the load m. A :class:`Warp` changes the k_i so that each stays such a quadratic: the warped wire is an
SD-GPI that the plant, the compensator and ``hysteresis.yaml`` take as it is.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from sma_wrist.core.errors import ParameterError
from sma_wrist.core.hysteresis.sdgpi import EnvelopeSections, SDGPIParams

#: the load [kgf per wire] about which the stress dependence is scaled: the wrist's working load (0.75-0.9 kgf)
REFERENCE_LOAD_KGF = 0.8


@dataclass(frozen=True)
class Warp:
    """A transform of the SD-GPI's tanh coefficients (Eqs. 3.21-3.22, 4.4-4.5).

    ``heating_shift_C`` / ``cooling_shift_C``: the heating branch (the lower envelope gamma_l, the b set, and the
    memoryless c set) and the cooling branch (gamma_r, the a set, and the d set) transform this much hotter [degC]:
    k2 -> k2 - k1 dT. ``width_scale`` s: every transition s times wider about its own centre -k2/k1:
    (k1, k2) -> (k1, k2) / s. ``stroke_scale`` g: the mirrored elongation y_m g times as large about ``y_ref_mm``:
    (k0, k3) -> g (k0, k3), thresholds r_j -> g r_j with the density's decay tau -> tau / g (the same weights
    p(r_j), Eq. 3.23; the play operator, Eq. 3.19, is positively homogeneous), k_f -> k_f - (1 - g) y_ref (Eq. 4.2:
    the wire keeps its length where y_m = y_ref). ``stress_scale`` k: the load moves the transformation k times as
    much about ``load_kgf``: the wire at load m is the original at m0 + k (m - m0) (the Clausius-Clapeyron slope of
    its transition temperatures times k; the section edges moved to match, none below 0: a wire carries no
    compression).
    """

    heating_shift_C: float = 0.0
    cooling_shift_C: float = 0.0
    width_scale: float = 1.0
    stroke_scale: float = 1.0
    stress_scale: float = 1.0
    y_ref_mm: float = 0.0
    load_kgf: float = REFERENCE_LOAD_KGF


def _remap_load(s: np.ndarray, k: float, m0: float) -> np.ndarray:
    """Quadratics s0 m^2 + s1 m + s2 (last axis) of the load m evaluated at m0 + k (m - m0), as quadratics of m."""
    c = m0 * (1.0 - k)
    s0, s1, s2 = s[..., 0], s[..., 1], s[..., 2]
    return np.stack([s0 * k * k, (2.0 * s0 * c + s1) * k, (s0 * c + s1) * c + s2], axis=-1)


def warped_wire(params: SDGPIParams, warp: Warp) -> SDGPIParams:
    """``params`` under ``warp`` (:class:`Warp`); the valid range's top moves up with the larger shift."""
    w = warp
    if not (w.width_scale > 0 and w.stroke_scale > 0 and w.stress_scale > 0):
        raise ParameterError(f'width, stroke and stress scales must be > 0, got {w}')
    env = params.envelopes
    edges = np.asarray(env.edges_kg, dtype=float)
    a, b = env.a.copy(), env.b.copy()
    if w.stress_scale != 1.0:
        a, b = _remap_load(a, w.stress_scale, w.load_kgf), _remap_load(b, w.stress_scale, w.load_kgf)
        edges = w.load_kgf + (edges - w.load_kgf) / w.stress_scale
        keep = np.r_[edges[1:] > 0.0, True]  # sections wholly at negative load dropped, the first clipped at 0
        first = max(int(np.argmax(keep)), 0)
        first = min(first, edges.size - 2)
        edges, a, b = edges[first:].copy(), a[first:], b[first:]
        edges[0] = max(edges[0], 0.0)
    c, d = params.c.copy(), params.d.copy()
    # the coefficient index k_i last: a[s, i, :] holds the load quadratic of a_i on section s (views, edited in place)
    sets = (np.moveaxis(a, 1, -1), np.moveaxis(b, 1, -1), c, d)
    for k, shift in zip(sets, (w.cooling_shift_C, w.heating_shift_C, w.heating_shift_C, w.cooling_shift_C)):
        k[..., 2] -= shift * k[..., 1]
        k[..., 1:3] /= w.width_scale
        k[..., 0:4:3] *= w.stroke_scale
    lo, hi = params.T_valid
    return dataclasses.replace(
        params,
        envelopes=EnvelopeSections(edges, a, b),
        c=c,
        d=d,
        tau=params.tau / w.stroke_scale,
        c_thr=params.c_thr * w.stroke_scale,
        k_f=params.k_f - (1.0 - w.stroke_scale) * w.y_ref_mm,
        T_valid=(lo, hi + max(w.heating_shift_C, w.cooling_shift_C, 0.0)),
        name=f'{params.name}, warped',
    )


__all__ = ['REFERENCE_LOAD_KGF', 'Warp', 'warped_wire']
