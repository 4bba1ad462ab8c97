"""The default, self-consistent SD-GPI parameter set for Nitinol #6 (0.25 mm wire).

Why a set of our own: the seed's printed GPI/SD-GPI tables do not reproduce its own
described loops (see doc/explanation/model.md). This set is built from the behaviour
Sec. 3.2 describes, written as physical load-dependent loop descriptors and then
converted *exactly* into the seed's model structure (tanh envelopes whose coefficients
are quadratics of the load on load sections, Eqs. 3.21, 4.4-4.5), so every equation of
the model is used as printed.

Loop descriptors (functions of the per-wire load m in kgf), for elongation y in mm of
the seed's 80 mm test wire:

* S(m)    transformation stroke: ~0.33 mm below the critical load, ~3.5 mm at 0.75-0.9 kgf;
* w(m)    transition width of both branches (tanh scale, degC);
* T_A(m)  centre of the heating (austenite) transition; T_M(m) centre of the cooling one.

Targets (Sec. 3.2): at 0.3-0.6 kgf A_f and M_f lie within 41-54 degC and move up ~1 degC
per 0.15 kgf; at 0.75-0.9 kgf A_f - M_f ~ 45 degC with full recovery between 20 and
76 degC; at >= 1.05 kgf the heating transition lies above the 78 degC reach, so the stroke
is small. A_f and M_f are taken as the 95 % points of the branches (tanh argument 1.47).
The transition temperatures rise with load everywhere above the critical load
(Clausius-Clapeyron), which makes elongation increase with load at fixed temperature:
the property the muscle/joint coupling relies on (doc/explanation/model.md).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sma_wrist.core.hysteresis.sdgpi import EnvelopeSections, SDGPIParams

FloatArray = NDArray[np.float64]

#: Load knots [kgf] of the default set's sections (quadratic per section, Eqs. 4.4-4.5).
KNOTS_KG = np.array(
    [
        0.20,
        0.30,
        0.40,
        0.50,
        0.55,
        0.60,
        0.625,
        0.65,
        0.675,
        0.70,
        0.725,
        0.75,
        0.775,
        0.80,
        0.85,
        0.90,
        0.925,
        0.95,
        0.975,
        1.00,
        1.05,
        1.10,
        1.20,
        1.35,
        1.50,
    ]
)

N_OPERATORS = 15  # Sec. 4.1.1: little gain beyond n = 15
C_THRESHOLD_MM = 0.02  # threshold spacing c (Eq. 3.24): gradual reversals over ~0.3 mm
TAU_PER_MM = 10.0  # density decay (Eq. 3.23)
K_F_MM = 6.0  # mirror constant (Eq. 4.2)
#: Memoryless part (Eq. 3.22) = thermal expansion of the 80 mm wire, ~0.9 um/degC, same set both ways.
MEMORYLESS = np.array([-0.1, 0.009, -0.45, 0.0])


def _logistic(x: FloatArray) -> FloatArray:
    return 0.5 * (1.0 + np.tanh(0.5 * x))


def _softplus(x: FloatArray) -> FloatArray:
    return np.logaddexp(0.0, x)


def loop_descriptors(m: ArrayLike) -> dict[str, FloatArray]:
    """Physical loop descriptors S, w, T_A, T_M at per-wire load m [kgf]."""
    m = np.asarray(m, dtype=float)
    # Onset of superelasticity between 0.62 and 0.73 kgf: sharp enough that 600 g still shows the
    # small (~0.36 mm) loop of Sec. 3.2 while 750 g shows the full one.
    s = _logistic((m - 0.675) / 0.015)
    stroke = 0.39 + (3.9 - 0.39) * s
    width = 3.0 + (8.0 - 3.0) * s
    # Below the critical load: ~1 degC per 0.15 kgf. Above it the loop opens to A_f - M_f ~ 45 degC
    # and the transitions climb steeply beyond 0.9 kgf, taking the heating branch out of reach by
    # 1.05 kgf. The cooling centre may drop only ~6 degC while the stroke grows, or elongation would
    # fall with load somewhere (a snap-through the joint coupling cannot have): (w/2) d ln S bounds it.
    base = 6.7 * (m - 0.30)
    # The climb starts past 0.9 kgf so 900 g still recovers ~3.2 mm in 20-78 degC, and takes the
    # heating branch out of reach by 1050 g.
    climb = 0.03 * 130.0 * _softplus((m - 0.96) / 0.03)
    T_M = 45.4 + base - 6.0 * s + 15.0 * s * (m - 0.75) + climb
    T_A = 49.6 + base + 15.0 * s + 15.0 * s * (m - 0.75) + climb
    return {'stroke_mm': stroke, 'width_C': width, 'T_A_C': T_A, 'T_M_C': T_M}


def _envelope_coefficients(m: FloatArray, weights: FloatArray, thresholds: FloatArray) -> tuple[FloatArray, FloatArray]:
    """(a_i(m), b_i(m)) of Eq. 3.21 reproducing the descriptors on the major loop.

    With all play operators saturated the heating branch is sum p_j (gamma_l - r_j) and the
    cooling branch sum p_j (gamma_r + r_j); weights sum to 1, so the envelope amplitude is
    widened by 2 r_bar to leave exactly the stroke S between the saturated ends.
    """
    d = loop_descriptors(m)
    r_bar = float(weights @ thresholds)
    amp = 0.5 * (d['stroke_mm'] + 2.0 * r_bar)
    offset = K_F_MM - amp + r_bar  # hot, fully austenitic end at y = 0
    w = d['width_C']
    a = np.stack([amp, 1.0 / w, -d['T_M_C'] / w, offset], axis=-1)  # gamma_r: cooling branch
    b = np.stack([amp, 1.0 / w, -d['T_A_C'] / w, offset], axis=-1)  # gamma_l: heating branch
    return a, b


def _quadratic_sections(knots: FloatArray, f) -> FloatArray:  # type: ignore[no-untyped-def]
    """Per section, the quadratic through (lo, mid, hi) of f(m) (last axes of f: (4,)).

    Continuous at the knots by construction; returns shape (K, 4, 3) for Eqs. 4.4-4.5.
    """
    lo, hi = knots[:-1], knots[1:]
    mid = 0.5 * (lo + hi)
    pts = np.stack([lo, mid, hi], axis=-1)  # (K, 3)
    vals = f(pts)  # (K, 3, 4)
    out = np.empty((knots.size - 1, 4, 3))
    for k in range(knots.size - 1):
        vander = np.vander(pts[k], 3)  # rows (m^2, m, 1)
        out[k] = np.linalg.solve(vander, vals[k]).T
    return out


@lru_cache(maxsize=1)
def default_sdgpi() -> SDGPIParams:
    """The shipped SD-GPI parameter set (Nitinol #6, 80 mm wire, loads 0.2-1.5 kgf)."""
    thresholds = C_THRESHOLD_MM * np.arange(1, N_OPERATORS + 1)
    raw = np.exp(-TAU_PER_MM * thresholds)
    rho = 1.0 / raw.sum()  # weights sum to one: the envelopes carry the stroke in mm
    weights = rho * raw
    a = _quadratic_sections(KNOTS_KG, lambda m: _envelope_coefficients(m, weights, thresholds)[0])
    b = _quadratic_sections(KNOTS_KG, lambda m: _envelope_coefficients(m, weights, thresholds)[1])
    return SDGPIParams(
        EnvelopeSections(KNOTS_KG.copy(), a, b),
        MEMORYLESS.copy(),
        MEMORYLESS.copy(),
        rho=float(rho),
        tau=TAU_PER_MM,
        c_thr=C_THRESHOLD_MM,
        n=N_OPERATORS,
        p0=1.0,
        k_f=K_F_MM,
        name='sma_wrist default (Sec. 3.2 behaviour)',
    )
