"""Compiled wire-load solve of a muscle (muscle.py Eq. 1) with the SD-GPI of Eqs. 3.19-3.24, 4.1-4.6.

Scalar per-wire loops, compiled by numba when present (see :mod:`sma_wrist.core.jit`); the numpy
reference is :meth:`sma_wrist.core.hysteresis.muscle.MuscleModel.solve_load`. The plant kernel
(:mod:`sma_wrist.core.plant.kernel`) calls ``_solve_load_into`` once per muscle and step.
"""

from __future__ import annotations

import math

import numpy as np

from sma_wrist.core.jit import _jit, _jit_inline


@_jit
def _envelopes(stacked, edges, m):  # pragma: no cover - compiled
    """Coefficients (8,) and slopes (8,) [a0..a3, b0..b3] at load m (Eqs. 4.4-4.5)."""
    c = np.empty(8)
    s = np.empty(8)
    _envelopes_into(stacked, edges, m, c, s)
    return c, s


@_jit_inline
def _envelopes_into(stacked, edges, m, c, s):  # pragma: no cover - compiled
    """:func:`_envelopes` into caller-owned (8,) arrays: the load solve evaluates it 2-3 times per wire
    and step, and two heap allocations per call cost ~3x the arithmetic (~150 of ~200 ns)."""
    n_sec = edges.size - 1
    k = 0
    while k < n_sec - 1 and m >= edges[k + 1]:
        k += 1
    for j in range(8):
        q2 = stacked[k, 0, j]
        q1 = stacked[k, 1, j]
        c[j] = (q2 * m + q1) * m + stacked[k, 2, j]
        s[j] = 2.0 * q2 * m + q1


@_jit_inline
def _elongation(T, m, w, w_now, y_mem, stacked, edges, r, p, m_lo, m_hi, scale, c_el, k_f, c, s):  # pragma: no cover
    """(y, dy/dm) of muscle.py Eq. 1 against frozen memory w; w_now receives the clamped memory;
    c, s: (8,) scratch for the envelope coefficients and slopes."""
    mc = min(max(m, m_lo), m_hi)
    _envelopes_into(stacked, edges, mc, c, s)
    th_r = math.tanh(c[1] * T + c[2])
    th_l = math.tanh(c[5] * T + c[6])
    g_r = c[0] * th_r + c[3]
    g_l = c[4] * th_l + c[7]
    y_m = y_mem
    p_below = 0.0
    p_above = 0.0
    for i in range(w.size):
        lower = g_l - r[i]
        upper = g_r + r[i]
        wi = w[i]
        if wi < lower:
            p_below += p[i]
        if wi > upper:
            p_above += p[i]
        wn = min(max(wi, lower), upper)
        w_now[i] = wn
        y_m += wn * p[i]
    dg_r = s[0] * th_r + c[0] * (1.0 - th_r * th_r) * (s[1] * T + s[2]) + s[3]
    dg_l = s[4] * th_l + c[4] * (1.0 - th_l * th_l) * (s[5] * T + s[6]) + s[7]
    dym = p_below * dg_l + p_above * dg_r
    y = scale * (k_f - y_m) + c_el * m
    dy = c_el
    if m_lo < m < m_hi:
        dy -= scale * dym
    return y, dy


@_jit
def _solve_load(
    T, y_geo, w, w_now, y_mem, m_guess, stacked, edges, r, p, m_lo, m_hi, scale, c_el, k_f, m_max, tol, max_it
):  # pragma: no cover - compiled
    """rtsafe of muscle.MuscleModel.solve_load for one bundle: (m, dy, residual)."""
    return _solve_load_into(
        T,
        y_geo,
        w,
        w_now,
        y_mem,
        m_guess,
        stacked,
        edges,
        r,
        p,
        m_lo,
        m_hi,
        scale,
        c_el,
        k_f,
        m_max,
        tol,
        max_it,
        np.empty(8),
        np.empty(8),
    )


@_jit_inline
def _solve_load_into(
    T, y_geo, w, w_now, y_mem, m_guess, stacked, edges, r, p, m_lo, m_hi, scale, c_el, k_f, m_max, tol, max_it, c, s
):  # pragma: no cover - compiled
    """:func:`_solve_load` with caller-owned (8,) envelope scratch c, s (the plant step's, reused)."""
    m = min(max(m_guess, 0.0), m_max)
    lo = 0.0
    hi = m_max
    y, dy = _elongation(T, m, w, w_now, y_mem, stacked, edges, r, p, m_lo, m_hi, scale, c_el, k_f, c, s)
    res = y - y_geo
    for _ in range(max_it):
        if abs(res) <= tol:
            break
        if res > 0:
            hi = m
        else:
            lo = m
        newton = m - res / dy
        done = (hi - lo) < 1e-12
        m = newton if (lo < newton < hi) else 0.5 * (lo + hi)
        y, dy = _elongation(T, m, w, w_now, y_mem, stacked, edges, r, p, m_lo, m_hi, scale, c_el, k_f, c, s)
        res = y - y_geo
        if done:
            break
    return m, dy, res
