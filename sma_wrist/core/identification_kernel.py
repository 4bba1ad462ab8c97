"""Play recursion that records which bound last set each operator (for the exact Jacobian).

Eq. 3.19: w_j(k) = min(max(w_j(k-1), gamma_l(T_k) - r_j), gamma_r(T_k) + r_j). Every state is
therefore a copy of the bound that last clamped it, so its derivative with respect to any
parameter is that bound's derivative at that sample: :func:`play_sources_numpy` returns the states
and, per state, ``+(k+1)`` (set by the upper bound at sample k), ``-(k+1)`` (lower bound) or the
initial source. :func:`play_jacobian` accumulates the derivatives in the same pass, compiled
by numba when installed (extra ``fast``); otherwise the numpy loop (vectorised over
operators) of :func:`play_sources_numpy` and numpy gathers give the same numbers.
"""
from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from sma_wrist.core.plant_kernel import AVAILABLE, _jit  # the project's one optional-numba switch


def play_sources_numpy(lower: NDArray[np.float64], upper: NDArray[np.float64], w0: NDArray[np.float64],
                       s0: NDArray[np.int64]) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
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
def _play_jac_compiled(lower, upper, w0, s0, p, jj, tau, Ga, Gb):  # pragma: no cover - compiled
    N, n = lower.shape
    S = np.zeros(N)
    dSa = np.zeros((N, 4))
    dSb = np.zeros((N, 4))
    dSc = np.zeros(N)
    Wrp = np.zeros(N)  # sum_j w_j j p_j (= -dS/dtau / c)
    w = w0.copy()
    s = s0.copy()
    for k in range(N):
        for j in range(n):
            v = w[j]
            if v < lower[k, j]:
                v = lower[k, j]
                s[j] = -(k + 1)
            if v > upper[k, j]:
                v = upper[k, j]
                s[j] = k + 1
            w[j] = v
            pj = p[j]
            S[k] += pj * v
            if s[j] > 0:
                src = s[j] - 1
                for q in range(4):
                    dSa[k, q] += pj * Ga[src, q]
                dSc[k] += pj * jj[j]
            else:
                src = -s[j] - 1
                for q in range(4):
                    dSb[k, q] += pj * Gb[src, q]
                dSc[k] -= pj * jj[j]
            dSc[k] -= v * tau * jj[j] * pj
            Wrp[k] += v * jj[j] * pj
    return S, dSa, dSb, dSc, Wrp


def play_jacobian(lower: NDArray[np.float64], upper: NDArray[np.float64], w0: NDArray[np.float64],
                  s0: NDArray[np.int64], p: NDArray[np.float64], jj: NDArray[np.float64], tau: float,
                  Ga: NDArray[np.float64], Gb: NDArray[np.float64]) -> tuple[NDArray[np.float64], ...]:
    """S = sum_j p_j w_j (N,) and its derivatives through the play states (Eqs. 3.19, 3.23, 3.24).

    Returns (S, dS/da (N, 4), dS/db (N, 4), dS/dc (N,), sum_j w_j j p_j (N,)); ``Ga``/``Gb`` are
    the (N, 4) gradients of gamma_r/gamma_l over their coefficient sets, ``jj`` = 1..n. Compiled
    when numba is installed; otherwise :func:`play_sources_numpy` and numpy gathers.
    """
    if AVAILABLE:
        S, dSa, dSb, dSc, Wjp = _play_jac_compiled(
            np.ascontiguousarray(lower), np.ascontiguousarray(upper), np.ascontiguousarray(w0, dtype=np.float64),
            np.ascontiguousarray(s0, dtype=np.int64), np.ascontiguousarray(p), np.ascontiguousarray(jj), float(tau),
            np.ascontiguousarray(Ga), np.ascontiguousarray(Gb))
        return S, dSa, dSb, dSc, Wjp
    return play_jacobian_numpy(lower, upper, w0, s0, p, jj, tau, Ga, Gb)


def play_jacobian_numpy(lower: NDArray[np.float64], upper: NDArray[np.float64], w0: NDArray[np.float64],
                        s0: NDArray[np.int64], p: NDArray[np.float64], jj: NDArray[np.float64], tau: float,
                        Ga: NDArray[np.float64], Gb: NDArray[np.float64]) -> tuple[NDArray[np.float64], ...]:
    """:func:`play_jacobian` with the numpy loop (the path without numba; tests compare both)."""
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
