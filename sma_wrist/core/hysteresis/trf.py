"""Bounded least squares (scipy's trust-region-reflective method) that ends in the same point on every CPU.

Why: the identification objective (a play-operator model, Eq. 3.25) is piecewise, with many local
minima, and the path of scipy's ``least_squares(method='trf')`` through it amplifies last-bit
differences: its SVD, J^T f and column norms go through BLAS/LAPACK, whose kernel (OpenBLAS's per-CPU
choice) and numpy's SIMD loops (AVX-512 or AVX2) round differently, so the same data gave different
fits on different machines (doc/howto/identify_wire.md). This is the same
algorithm (``scipy.optimize._lsq.trf.trf_bounds``, ``tr_solver='exact'``, ``x_scale='jac'``, no
loss) with two changes:

- every reduction (the SVD of the scaled, augmented Jacobian, J^T f, J p, column norms, the cost,
  the n-vector dot products and norms of the trust-region step) is a compiled loop or a Python sum
  in a fixed order: the same bits on every CPU (numba, no fastmath, so no reassociation or FMA
  contraction; the SVD is Householder QR then one-sided Jacobi on R). The rest is elementwise
  (+ - * / sqrt are correctly rounded everywhere).
- the start is rounded to :data:`QUANT_BITS` mantissa bits (:func:`quantize`), so a start that
  carries some CPU's last bits (from the callers' own arithmetic) still starts the same path.

Measured: bit-identical fits with numpy's AVX-512 or AVX2 loops, OpenBLAS's default or Haswell
kernel, and numba compiled for the host or for generic x86-64 (doc/howto/identify_wire.md).
Without numba the caller falls back to scipy's ``least_squares`` (same algorithm, CPU-dependent bits).

The loop follows SciPy's ``scipy/optimize/_lsq/trf.py`` (BSD-3-Clause; Copyright (c) 2001-2002 Enthought, Inc.
and 2003- SciPy Developers), and uses its helpers from ``scipy.optimize._lsq.common``.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

try:  # scipy's own helpers of the algorithm (a private module): should a release move them, the callers
    # fall back to least_squares (the same algorithm, CPU-dependent bits) instead of failing to import
    from scipy.optimize._lsq.common import (
        EPS,
        CL_scaling_vector,
        make_strictly_feasible,
        minimize_quadratic_1d,
        step_size_to_bound,
        update_tr_radius,
    )

    _SCIPY_HELPERS = True
except ImportError:  # pragma: no cover - depends on the scipy release
    _SCIPY_HELPERS = False

from sma_wrist.core.jit import AVAILABLE as _COMPILED
from sma_wrist.core.jit import _jit, _jit_inline

#: numba and scipy's helpers are there: the fixed-order solver runs (else scipy's least_squares)
AVAILABLE = _COMPILED and _SCIPY_HELPERS

FloatArray = NDArray[np.float64]

#: Mantissa bits kept of a start (2^-30 ~ 9.3e-10 relative): far above last-bit noise, far below
#: any parameter change that moves a fit.
QUANT_BITS = 30


def quantize(x: FloatArray, bits: int = QUANT_BITS) -> FloatArray:
    """``x`` rounded to ``bits`` mantissa bits (relative grid 2^-bits); frexp/rint/ldexp are exact on every CPU."""
    m, e = np.frexp(x)
    return np.ldexp(np.rint(np.ldexp(m, bits)), e - bits)


@_jit_inline
def _rdot(a, b, lo, hi):  # pragma: no cover - compiled
    """sum a[i] b[i] over lo <= i < hi in four interleaved partial sums, added in a fixed order: the order
    is in the source (no fastmath), so it is the same on every CPU, and the compiler can keep the four
    in one vector register (the QR's reductions ran at one add per cycle with a single sum)."""
    s0 = 0.0
    s1 = 0.0
    s2 = 0.0
    s3 = 0.0
    i = lo
    while i + 4 <= hi:
        s0 += a[i] * b[i]
        s1 += a[i + 1] * b[i + 1]
        s2 += a[i + 2] * b[i + 2]
        s3 += a[i + 3] * b[i + 3]
        i += 4
    while i < hi:
        s0 += a[i] * b[i]
        i += 1
    return (s0 + s1) + (s2 + s3)


@_jit
def _dot(a, b):  # pragma: no cover - compiled
    s = 0.0
    for i in range(a.shape[0]):
        s += a[i] * b[i]
    return s


@_jit
def _matvec(J, p):  # pragma: no cover - compiled
    m, n = J.shape
    out = np.zeros(m)
    for i in range(m):
        s = 0.0
        for j in range(n):
            s += J[i, j] * p[j]
        out[i] = s
    return out


@_jit
def _rmatvec_and_norms(J, f):  # pragma: no cover - compiled
    """J^T f and the column norms of J, each summed over rows in order."""
    m, n = J.shape
    g = np.zeros(n)
    c = np.zeros(n)
    for i in range(m):
        for j in range(n):
            g[j] += J[i, j] * f[i]
            c[j] += J[i, j] * J[i, j]
    return g, np.sqrt(c)


@_jit
def _svd_solve_data(Jh, diag_sqrt, f):  # pragma: no cover - compiled
    """(s, V, uf) of the SVD of [Jh; diag(diag_sqrt)] (m+n, n) and uf = U^T [f; 0], s descending.

    Householder QR (columns stored as rows of a transposed copy: contiguous inner loops), then
    one-sided Jacobi (Hestenes) on the n x n R; uf = U_R^T (Q^T [f; 0])[:n].
    """
    m, n = Jh.shape
    M = m + n
    A = np.zeros((n, M))  # A[j] = column j
    for i in range(m):
        for j in range(n):
            A[j, i] = Jh[i, j]
    for j in range(n):
        A[j, m + j] = diag_sqrt[j]
    b = np.zeros(M)
    for i in range(m):
        b[i] = f[i]
    v = np.empty(M)
    for k in range(n):
        nrm = math.sqrt(_rdot(A[k], A[k], k, M))
        if nrm == 0.0:
            continue
        alpha = -nrm if A[k, k] > 0 else nrm
        for i in range(k, M):
            v[i] = A[k, i]
        v[k] -= alpha
        vn = _rdot(v, v, k, M)
        if vn == 0.0:
            continue
        for j in range(k, n):
            s = 2.0 * _rdot(v, A[j], k, M) / vn
            for i in range(k, M):
                A[j, i] -= s * v[i]
        s = 2.0 * _rdot(v, b, k, M) / vn
        for i in range(k, M):
            b[i] -= s * v[i]
    U = np.zeros((n, n))  # U[j] = column j of R
    for j in range(n):
        for i in range(j + 1):
            U[j, i] = A[j, i]
    V = np.zeros((n, n))  # V[j] = column j of V
    for j in range(n):
        V[j, j] = 1.0
    for _sweep in range(100):
        rotated = False
        for p in range(n - 1):
            for q in range(p + 1, n):
                a = 0.0
                bb = 0.0
                c = 0.0
                for i in range(n):
                    a += U[p, i] * U[p, i]
                    bb += U[q, i] * U[q, i]
                    c += U[p, i] * U[q, i]
                if c == 0.0 or abs(c) <= 1e-15 * math.sqrt(a * bb):
                    continue
                rotated = True
                zeta = (bb - a) / (2.0 * c)
                t = (1.0 if zeta >= 0 else -1.0) / (abs(zeta) + math.sqrt(1.0 + zeta * zeta))
                cs = 1.0 / math.sqrt(1.0 + t * t)
                sn = cs * t
                for i in range(n):
                    up, uq = U[p, i], U[q, i]
                    U[p, i] = cs * up - sn * uq
                    U[q, i] = sn * up + cs * uq
                    vp, vq = V[p, i], V[q, i]
                    V[p, i] = cs * vp - sn * vq
                    V[q, i] = sn * vp + cs * vq
        if not rotated:
            break
    s = np.zeros(n)
    uf = np.zeros(n)
    for j in range(n):
        nj = 0.0
        for i in range(n):
            nj += U[j, i] * U[j, i]
        s[j] = math.sqrt(nj)
        if s[j] > 0.0:
            d = 0.0
            for i in range(n):
                d += U[j, i] * b[i]
            uf[j] = d / s[j]
    order = np.argsort(-s, kind='mergesort')
    Vout = np.empty((n, n))  # rows = coordinates, columns = singular vectors (as scipy's V = Vt.T)
    for jj in range(n):
        for i in range(n):
            Vout[i, jj] = V[order[jj], i]
    return s[order], Vout, uf[order]


class _DetJ:
    """J_h with a fixed-order ``dot`` for scipy's quadratic-model helpers (they call ``J.dot``)."""

    def __init__(self, J: FloatArray) -> None:
        self.J = J

    def dot(self, s: FloatArray) -> FloatArray:
        return _matvec(self.J, np.ascontiguousarray(s, dtype=np.float64))


def _quadratic(J: _DetJ, g: FloatArray, s: FloatArray, diag: FloatArray) -> float:
    """scipy's evaluate_quadratic (0.5 s^T (J^T J + diag) s + g^T s), reductions in a fixed order."""
    Js = J.dot(s)
    return 0.5 * (_dot(Js, Js) + _dot(s * diag, s)) + _dot(s, g)


def _quadratic_1d(
    J: _DetJ, g: FloatArray, s: FloatArray, diag: FloatArray, s0: FloatArray | None = None
) -> tuple[float, ...]:
    """scipy's build_quadratic_1d, reductions in a fixed order."""
    v = J.dot(s)
    a = 0.5 * (_dot(v, v) + _dot(s * diag, s))
    b = _dot(g, s)
    if s0 is None:
        return a, b
    u = J.dot(s0)
    b += _dot(u, v) + _dot(s0 * diag, s)
    c = 0.5 * _dot(u, u) + _dot(g, s0) + 0.5 * _dot(s0 * diag, s0)
    return a, b, c


def _norm(x: FloatArray) -> float:
    return math.sqrt(_dot(x, x))


def _intersect_trust_region(x: FloatArray, s: FloatArray, Delta: float) -> tuple[float, float]:
    """scipy's intersect_trust_region (|x + t s| = Delta), its dot products in a fixed order."""
    a = _dot(s, s)
    if a == 0:
        raise ValueError('`s` is zero.')
    b = _dot(x, s)
    c = _dot(x, x) - Delta**2
    if c > 0:
        raise ValueError('`x` is not within the trust region.')
    d = math.sqrt(b * b - a * c)
    q = -(b + math.copysign(d, b))
    t1, t2 = q / a, c / q
    return (t1, t2) if t1 < t2 else (t2, t1)


def _solve_lsq_trust_region(
    n: int,
    m: int,
    uf: FloatArray,
    s: FloatArray,
    V: FloatArray,
    Delta: float,
    initial_alpha: float,
    rtol: float = 0.01,
    max_iter: int = 10,
) -> tuple[FloatArray, float]:
    """scipy's solve_lsq_trust_region (More's regularised step on the SVD), norms and products in a fixed order."""

    def phi_and_derivative(alpha: float) -> tuple[float, float]:
        denom = s * s + alpha
        p_norm = _norm(suf / denom)
        return p_norm - Delta, -_dot(suf * suf / (denom * denom * denom), np.ones(n)) / p_norm

    suf = s * uf
    full_rank = bool(s[-1] > EPS * m * s[0]) if m >= n else False
    if full_rank:
        p = -_matvec(V, uf / s)
        if _norm(p) <= Delta:
            return p, 0.0
    alpha_upper = _norm(suf) / Delta
    alpha_lower = 0.0
    if full_rank:
        phi, phi_prime = phi_and_derivative(0.0)
        alpha_lower = -phi / phi_prime
    alpha = initial_alpha
    if not full_rank and initial_alpha == 0:
        alpha = max(0.001 * alpha_upper, math.sqrt(alpha_lower * alpha_upper))
    for _ in range(max_iter):
        if alpha < alpha_lower or alpha > alpha_upper:
            alpha = max(0.001 * alpha_upper, math.sqrt(alpha_lower * alpha_upper))
        phi, phi_prime = phi_and_derivative(alpha)
        if phi < 0:
            alpha_upper = alpha
        ratio = phi / phi_prime
        alpha_lower = max(alpha_lower, alpha - ratio)
        alpha -= (phi + Delta) * ratio / Delta
        if abs(phi) < rtol * Delta:
            break
    p = -_matvec(V, suf / (s * s + alpha))
    p *= Delta / _norm(p)
    return p, alpha


def _select_step(
    x: FloatArray,
    J_h: _DetJ,
    diag_h: FloatArray,
    g_h: FloatArray,
    p: FloatArray,
    p_h: FloatArray,
    d: FloatArray,
    Delta: float,
    lb: FloatArray,
    ub: FloatArray,
    theta: float,
) -> tuple[FloatArray, FloatArray, float]:
    """scipy's trf.select_step (reflective step), its quadratics in a fixed order."""
    if np.all((x + p >= lb) & (x + p <= ub)):
        return p, p_h, -_quadratic(J_h, g_h, p_h, diag_h)
    p_stride, hits = step_size_to_bound(x, p, lb, ub)
    r_h = np.copy(p_h)
    r_h[hits.astype(bool)] *= -1
    r = d * r_h
    p = p * p_stride
    p_h = p_h * p_stride
    x_on_bound = x + p
    _, to_tr = _intersect_trust_region(p_h, r_h, Delta)
    to_bound, _ = step_size_to_bound(x_on_bound, r, lb, ub)
    r_stride = min(to_bound, to_tr)
    if r_stride > 0:
        r_stride_l = (1 - theta) * p_stride / r_stride
        r_stride_u = theta * to_bound if r_stride == to_bound else to_tr
    else:
        r_stride_l, r_stride_u = 0.0, -1.0
    if r_stride_l <= r_stride_u:
        a, b, c = _quadratic_1d(J_h, g_h, r_h, diag_h, s0=p_h)
        r_stride, r_value = minimize_quadratic_1d(a, b, r_stride_l, r_stride_u, c=c)
        r_h = r_h * r_stride + p_h
        r = r_h * d
    else:
        r_value = np.inf
    p = p * theta
    p_h = p_h * theta
    p_value = _quadratic(J_h, g_h, p_h, diag_h)
    ag_h = -g_h
    ag = d * ag_h
    to_tr = Delta / _norm(ag_h)
    to_bound, _ = step_size_to_bound(x, ag, lb, ub)
    ag_stride = theta * to_bound if to_bound < to_tr else to_tr
    a, b = _quadratic_1d(J_h, g_h, ag_h, diag_h)
    ag_stride, ag_value = minimize_quadratic_1d(a, b, 0, ag_stride)
    ag_h = ag_h * ag_stride
    ag = ag * ag_stride
    if p_value < r_value and p_value < ag_value:
        return p, p_h, -p_value
    if r_value < p_value and r_value < ag_value:
        return r, r_h, -r_value
    return ag, ag_h, -ag_value


def _onto_grid(x: FloatArray, lb: FloatArray, ub: FloatArray) -> FloatArray:
    """quantize(x), keeping x where the grid point would leave the open box (TRF stays strictly inside)."""
    q = quantize(x)
    return np.where((q > lb) & (q < ub), q, x)


def trf_solve(
    fun_jac: Callable[[FloatArray], tuple[FloatArray, FloatArray]],
    x0: FloatArray,
    lb: FloatArray,
    ub: FloatArray,
    max_nfev: int,
    ftol: float = 1e-10,
    xtol: float = 1e-10,
    gtol: float = 1e-10,
) -> tuple[FloatArray, float, int, int]:
    """Minimise 0.5 |r(x)|^2 over lb < x < ub from x0: (x, cost, status, nfev), scipy's status codes.

    ``fun_jac(x) -> (r (m,), J (m, n))``; the Jacobian is only used at accepted points, as in
    scipy (which evaluates it after the residual at the same point). Requires numba (:data:`AVAILABLE`).
    """
    if not AVAILABLE:
        raise RuntimeError('trf_solve needs numba (pip install sma_wrist[fast])')
    # as least_squares: a start within 1e-10 (relative) of a bound moves that far inside
    x = _onto_grid(make_strictly_feasible(np.asarray(x0, dtype=float), lb, ub), lb, ub)
    f, J = fun_jac(x)
    J = np.ascontiguousarray(J)
    nfev = 1
    m, n = J.shape
    cost = 0.5 * _dot(f, f)
    g, scale_inv = _rmatvec_and_norms(J, f)
    scale_inv[scale_inv == 0] = 1
    scale = 1 / scale_inv
    v, dv = CL_scaling_vector(x, g, lb, ub)
    v[dv != 0] *= scale_inv[dv != 0]
    Delta = _norm(x * scale_inv / np.sqrt(v))
    if Delta == 0:
        Delta = 1.0
    alpha = 0.0
    status = None
    while True:
        v, dv = CL_scaling_vector(x, g, lb, ub)
        g_norm = float(np.max(np.abs(g * v)))
        if g_norm < gtol:
            status = 1
        if status is not None or nfev == max_nfev:
            break
        v[dv != 0] *= scale_inv[dv != 0]
        d = np.sqrt(v) * scale
        diag_h = g * dv * scale
        g_h = d * g
        Jd = J * d
        J_h = _DetJ(Jd)
        s, V, uf = _svd_solve_data(Jd, np.sqrt(diag_h), f)
        theta = max(0.995, 1 - g_norm)
        actual_reduction = -1.0
        while actual_reduction <= 0 and nfev < max_nfev:
            p_h, alpha = _solve_lsq_trust_region(n, m, uf, s, V, Delta, alpha)
            p = d * p_h
            step, step_h, predicted_reduction = _select_step(x, J_h, diag_h, g_h, p, p_h, d, Delta, lb, ub, theta)
            x_new = make_strictly_feasible(x + step, lb, ub, rstep=0)
            f_new, J_new = fun_jac(x_new)
            nfev += 1
            step_h_norm = _norm(step_h)
            if not np.all(np.isfinite(f_new)):
                Delta = 0.25 * step_h_norm
                continue
            cost_new = 0.5 * _dot(f_new, f_new)
            actual_reduction = cost - cost_new
            Delta_new, ratio = update_tr_radius(
                Delta, actual_reduction, predicted_reduction, step_h_norm, step_h_norm > 0.95 * Delta
            )
            ftol_ok = actual_reduction < ftol * cost and ratio > 0.25
            xtol_ok = _norm(step) < xtol * (xtol + _norm(x))
            status = 4 if ftol_ok and xtol_ok else 2 if ftol_ok else 3 if xtol_ok else None
            if status is not None:
                break
            alpha *= Delta / Delta_new
            Delta = Delta_new
        if actual_reduction > 0:
            x, f, cost = x_new, f_new, cost_new
            J = np.ascontiguousarray(J_new)
            g, si = _rmatvec_and_norms(J, f)
            scale_inv = np.maximum(si, scale_inv)
            scale = 1 / scale_inv
    return x, cost, (0 if status is None else status), nfev


def lstsq(A: FloatArray, b: FloatArray) -> FloatArray:
    """Least-squares solution of A x = b (A (m, n), m >= n), the same bits on every CPU with numba.

    For the fits' starting points (polynomials through per-load fits): LAPACK's answer carries the
    BLAS kernel's last bits, and a start is the one input the fit's path cannot lose. Singular
    values below 1e-13 of the largest are dropped (a minimum-norm answer, as ``rcond``).
    """
    A = np.ascontiguousarray(A, dtype=np.float64)
    b = np.ascontiguousarray(b, dtype=np.float64)
    if not AVAILABLE:
        return np.linalg.lstsq(A, b, rcond=None)[0]
    s, V, uf = _svd_solve_data(A, np.zeros(A.shape[1]), b)
    keep = s > 1e-13 * s[0] if s[0] > 0 else np.zeros(s.size, bool)
    return _matvec(V, np.where(keep, uf / np.where(keep, s, 1.0), 0.0))


def polyfit(x: FloatArray, y: FloatArray, deg: int, w: FloatArray | None = None) -> FloatArray:
    """np.polyfit (coefficients highest power first, optional weights), solved by :func:`lstsq`."""
    x = np.asarray(x, dtype=float)
    lhs = x[:, None] ** np.arange(deg, -1, -1)[None, :].astype(float)
    rhs = np.asarray(y, dtype=float)
    if w is not None:
        lhs = lhs * np.asarray(w, dtype=float)[:, None]
        rhs = rhs * w
    scale = np.array([math.sqrt(math.fsum(c * c)) for c in lhs.T])  # as np.polyfit: unit columns
    scale[scale == 0] = 1.0
    return lstsq(lhs / scale, rhs) / scale
