"""Play recursion that records which bound last set each operator (for the exact Jacobian).

Eq. 3.19: w_j(k) = min(max(w_j(k-1), gamma_l(T_k) - r_j), gamma_r(T_k) + r_j). Every state is
therefore a copy of the bound that last clamped it, so its derivative with respect to any
parameter is that bound's derivative at that sample: :func:`play_sources_numpy` returns the states
and, per state, ``+(k+1)`` (set by the upper bound at sample k), ``-(k+1)`` (lower bound) or the
initial source. :func:`gpi_jacobian` computes the whole GPI output and Jacobian in one compiled
pass when numba is installed (extra ``fast``); otherwise the numpy loop (vectorised over
operators) of :func:`play_sources_numpy` and numpy gathers (:func:`play_jacobian_numpy`) give
the same numbers.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from sma_wrist.core.jit import AVAILABLE, _jit  # the project's one optional-numba switch


def play_sources_numpy(
    lower: NDArray[np.float64], upper: NDArray[np.float64], w0: NDArray[np.float64], s0: NDArray[np.int64]
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """States (N, n) and sources (N, n) of the play recursion; numpy loop over samples."""
    N = lower.shape[0]
    W = np.empty(lower.shape)
    src = np.empty(lower.shape, np.int64)
    w = w0.astype(float, copy=True)
    s = s0.astype(np.int64, copy=True)
    for k in range(N):
        lo = w < lower[k]
        w[lo] = lower[k][lo]
        s[lo] = -(k + 1)
        hi = w > upper[k]
        w[hi] = upper[k][hi]
        s[hi] = k + 1
        W[k] = w
        src[k] = s
    return W, src


@_jit
def _gpi_jac_compiled(T, th, n, k_f, heating_start, heat):  # pragma: no cover - compiled
    N = T.shape[0]
    Ga = np.empty((N, 4))
    Gb = np.empty((N, 4))
    gr = np.empty(N)
    gl = np.empty(N)
    y = np.empty(N)
    J = np.zeros((N, 20))
    p0, c, tau, rho = th[19], th[18], th[17], th[16]
    for k in range(N):  # envelopes (Eq. 3.21) and memoryless part (Eq. 3.22) with their gradients
        t = np.tanh(th[1] * T[k] + th[2])
        s = th[0] * (1.0 - t * t)
        gr[k] = th[0] * t + th[3]
        Ga[k, 0], Ga[k, 1], Ga[k, 2], Ga[k, 3] = t, s * T[k], s, 1.0
        t = np.tanh(th[5] * T[k] + th[6])
        s = th[4] * (1.0 - t * t)
        gl[k] = th[4] * t + th[7]
        Gb[k, 0], Gb[k, 1], Gb[k, 2], Gb[k, 3] = t, s * T[k], s, 1.0
        o = 8 if heat[k] else 12
        t = np.tanh(th[o + 1] * T[k] + th[o + 2])
        s = th[o] * (1.0 - t * t)
        mem = th[o] * t + th[o + 3]
        J[k, o], J[k, o + 1], J[k, o + 2], J[k, o + 3] = -p0 * t, -p0 * s * T[k], -p0 * s, -p0
        y[k] = k_f - p0 * mem
        J[k, 19] = -mem
    w = np.empty(n)
    src = np.empty(n, np.int64)
    e = np.empty(n)
    for j in range(n):  # Eq. 3.23 weights; initial memory on one bound at T[0]
        e[j] = np.exp(-tau * c * (j + 1))
        if heating_start:
            w[j], src[j] = gl[0] - c * (j + 1), -1
        else:
            w[j], src[j] = gr[0] + c * (j + 1), 1
    for k in range(N):  # play recursion (Eq. 3.19), each state's derivative = its source bound's
        S = 0.0
        dS_rho = 0.0
        dS_c = 0.0
        Wjp = 0.0
        for j in range(n):
            jj = j + 1.0
            v = w[j]
            lo = gl[k] - c * jj
            if v < lo:
                v = lo
                src[j] = -(k + 1)
            up = gr[k] + c * jj
            if v > up:
                v = up
                src[j] = k + 1
            w[j] = v
            pj = rho * e[j]
            S += pj * v
            dS_rho += e[j] * v
            if src[j] > 0:
                q0 = src[j] - 1
                for q in range(4):
                    J[k, q] -= pj * Ga[q0, q]
                dS_c += pj * jj
            else:
                q0 = -src[j] - 1
                for q in range(4):
                    J[k, 4 + q] -= pj * Gb[q0, q]
                dS_c -= pj * jj
            dS_c -= v * tau * jj * pj
            Wjp += v * jj * pj
        y[k] -= S
        J[k, 16] = -dS_rho
        J[k, 17] = c * Wjp
        J[k, 18] = -dS_c
    return y, J


def gpi_jacobian(
    T: NDArray[np.float64], theta: NDArray[np.float64], n: int, k_f: float, heating_start: bool, heat: NDArray[np.bool_]
) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    """Compiled elongation y (N,) [mm] and exact Jacobian (N, 20) of one GPI vector, or None without numba.

    One pass: envelopes and memoryless part (Eqs. 3.21-3.22, 4.1) with their gradients, then
    the play recursion (Eq. 3.19) with the weights of Eq. 3.23; the same numbers as the numpy
    path of :func:`sma_wrist.core.hysteresis.identification.simulate_jac` (tests compare both), without
    its per-call array overhead (most of a fit's time on 400-1000-sample loops).
    """
    if not AVAILABLE:
        return None
    return _gpi_jac_compiled(
        np.ascontiguousarray(T, dtype=np.float64),
        np.ascontiguousarray(theta, dtype=np.float64),
        int(n),
        float(k_f),
        bool(heating_start),
        np.ascontiguousarray(heat, dtype=np.bool_),
    )


def play_jacobian_numpy(
    lower: NDArray[np.float64],
    upper: NDArray[np.float64],
    w0: NDArray[np.float64],
    s0: NDArray[np.int64],
    p: NDArray[np.float64],
    jj: NDArray[np.float64],
    tau: float,
    Ga: NDArray[np.float64],
    Gb: NDArray[np.float64],
) -> tuple[NDArray[np.float64], ...]:
    """S = sum_j p_j w_j (N,) and its derivatives through the play states (Eqs. 3.19, 3.23, 3.24).

    Returns (S, dS/da (N, 4), dS/db (N, 4), dS/dc (N,), sum_j w_j j p_j (N,)); ``Ga``/``Gb`` are
    the (N, 4) gradients of gamma_r/gamma_l over their coefficient sets, ``jj`` = 1..n. The
    path without numba (:func:`gpi_jacobian` is the compiled one; tests compare both).
    """
    W, src = play_sources_numpy(lower, upper, w0, s0)
    up = src > 0
    k_src = np.abs(src) - 1
    P_up = np.where(up, p, 0.0)
    dSa = np.einsum('kj,kjq->kq', P_up, Ga[k_src])
    dSb = np.einsum('kj,kjq->kq', p - P_up, Gb[k_src])
    sign = np.where(up, 1.0, -1.0)
    Wjp = W @ (jj * p)
    dSc = (sign * p * jj).sum(axis=1) - tau * Wjp
    return W @ p, dSa, dSb, dSc, Wjp
