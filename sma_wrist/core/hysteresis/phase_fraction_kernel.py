"""Compiled load solve of a phase-fraction wire bundle (:mod:`sma_wrist.core.hysteresis.phase_fraction`, Eqs. 1-4b).

Scalar per-wire code compiled by numba when present (:mod:`sma_wrist.core.jit`); the numpy reference is
:class:`sma_wrist.core.hysteresis.phase_fraction.PhaseFractionMuscle` (same operations, test_phase_fraction_wire).
``wc``: the constant row of :meth:`sma_wrist.core.hysteresis.phase_fraction.PhaseFractionWire.packed`; ``mem``: one
wire's memory (5,) xi, xi_h, x_h, xi_c, x_c. The plant kernel and the diagnosis' replay call :func:`solve_load` and :func:`commit` once per bundle and step.
"""

from __future__ import annotations

import math

from sma_wrist.core.jit import _jit, _jit_inline


@_jit_inline
def _major(x, lo, hi):  # pragma: no cover - compiled
    """(f, df/dx) of a cosine branch (Eq. 2): 1 below lo, 0 above hi."""
    if x <= lo:
        return 1.0, 0.0
    if x >= hi:
        return 0.0, 0.0
    w = hi - lo
    ph = math.pi * ((x - lo) / w)
    return 0.5 * (1.0 + math.cos(ph)), -0.5 * math.pi / w * math.sin(ph)


@_jit_inline
def fraction(wc, T, sig, mem):  # pragma: no cover - compiled
    """(xi, d xi / d sigma) of Eq. 3 against frozen memory."""
    C_M, C_A = wc[4], wc[5]
    x_a = T - (sig - wc[13]) / C_A
    x_m = T - (sig - wc[13]) / C_M
    xi_p, xi_h, x_h, xi_c, x_c = mem[0], mem[1], mem[2], mem[3], mem[4]
    H = 1.0
    dH = 0.0
    if x_a > x_h + 1e-9:  # phase_fraction.X_EPS
        fa, dfa = _major(x_a, wc[2], wc[3])
        fh, _ = _major(x_h, wc[2], wc[3])
        den_h = max(fh, 1e-12)
        h = xi_h * fa / den_h
        if h < 1.0:
            H = h
            dH = -xi_h * dfa / den_h / C_A
    Cb = 0.0
    dC = 0.0
    if x_m < x_c - 1e-9:
        fm, dfm = _major(x_m, wc[0], wc[1])
        fc, _ = _major(x_c, wc[0], wc[1])
        den_c = max(1.0 - fc, 1e-12)
        Cb = 1.0 - (1.0 - xi_c) * (1.0 - fm) / den_c
        dC = -(1.0 - xi_c) * dfm / den_c / C_M
    if H < xi_p:
        upper, d_up = H, dH
    else:
        upper, d_up = xi_p, 0.0
    if Cb > 0.0:
        lower, d_lo = Cb, dC
    else:
        lower, d_lo = 0.0, 0.0
    if lower > upper:
        xi, dxi = lower, d_lo
    else:
        xi, dxi = upper, d_up
    if xi <= 0.0:
        return 0.0, 0.0
    if xi >= 1.0:
        return 1.0, 0.0
    return xi, dxi


@_jit_inline
def elongation(wc, T, m, mem):  # pragma: no cover - compiled
    """(y [mm], dy/dm [mm/kgf]) of Eq. 4 at per-wire load m [kgf] against frozen memory."""
    per_kgf = wc[15]
    sig = m * per_kgf
    xi, dxi = fraction(wc, T, sig, mem)
    S_A, S_M, eps_L, s_s, s_f = wc[7], wc[8], wc[6], wc[9], wc[10]
    brinson = wc[17] != 0.0  # phase_fraction.LAWS: 0 Eq. 4 (linear ramp, Reuss), 1 Eq. 4b (cosine ramp, Voigt)
    if sig <= s_s:
        d, dd = 0.0, 0.0
    elif sig >= s_f:
        d, dd = 1.0, 0.0
    elif brinson:
        ph = math.pi * ((sig - s_s) / (s_f - s_s))
        d, dd = 0.5 * (1.0 - math.cos(ph)), 0.5 * math.pi * math.sin(ph) / (s_f - s_s)
    else:
        d, dd = (sig - s_s) / (s_f - s_s), 1.0 / (s_f - s_s)
    if brinson:
        E_A, E_M = 1.0 / S_A, 1.0 / S_M
        E = E_A + xi * (E_M - E_A)
        el, d_el_sig, d_el_xi = sig / E, 1.0 / E, -sig * (E_M - E_A) / (E * E)
    else:
        S = S_A + xi * (S_M - S_A)
        el, d_el_sig, d_el_xi = sig * S, S, sig * (S_M - S_A)
    eps = el + eps_L * d * xi + wc[11] * (T - wc[12])
    deps = d_el_sig + eps_L * dd * xi + (d_el_xi + eps_L * d) * dxi
    L = wc[14]
    return L * eps - wc[16], L * deps * per_kgf


@_jit_inline
def solve_load(wc, T, y_geo, mem, m_guess, m_max, tol, max_it):  # pragma: no cover - compiled
    """rtsafe of PhaseFractionMuscle.solve_load for one bundle: (m, dy/dm, residual); the memory is not changed."""
    m = min(max(m_guess, 0.0), m_max)
    lo = 0.0
    hi = m_max
    y, dy = elongation(wc, T, m, mem)
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
        y, dy = elongation(wc, T, m, mem)
        res = y - y_geo
        if done:
            break
    return m, dy, res


@_jit_inline
def commit(wc, T, m, mem):  # pragma: no cover - compiled
    """Advance one wire's memory to (T, m), in place (Eq. 3)."""
    sig = m * wc[15]
    xi, _ = fraction(wc, T, sig, mem)
    if xi < mem[0] - 1e-9:  # transformed on heating: the next cooling branch starts here (phase_fraction.XI_EPS)
        mem[3] = xi
        mem[4] = T - (sig - wc[13]) / wc[4]
    elif xi > mem[0] + 1e-9:
        mem[1] = xi
        mem[2] = T - (sig - wc[13]) / wc[5]
    mem[0] = xi


@_jit_inline
def cooled(wc, T, m, mem):  # pragma: no cover - compiled
    """One wire's memory cooled from hot to (T, m), in place (phase_fraction.cooled_memory)."""
    f, _ = _major(T - (m * wc[15] - wc[13]) / wc[4], wc[0], wc[1])
    mem[0] = f
    mem[1] = 1.0
    mem[2] = -1.0e3
    mem[3] = 0.0
    mem[4] = 1.0e3


@_jit
def solve_and_commit(wc, T, y_geo, mem, m_guess, m_max, tol, max_it, out):  # pragma: no cover - compiled
    """For N wires: solve each load (T, y_geo, m_guess (N,), mem (N, 5)), commit the memory in place; out (N, 3):
    load [kgf], dy/dm [mm/kgf], residual [mm]. What the tests compare with the numpy reference."""
    for i in range(T.size):
        m, dy, res = solve_load(wc, T[i], y_geo[i], mem[i], m_guess[i], m_max, tol, max_it)
        commit(wc, T[i], m, mem[i])
        out[i, 0] = m
        out[i, 1] = dy
        out[i, 2] = res
