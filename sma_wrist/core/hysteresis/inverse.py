"""Inverse hysteresis compensation (seed Chapter 5, Eqs. 5.5-5.15).

* :func:`pi_inverse_params`, :func:`pi_series`, :func:`pi_inverse_state`: the classical
  Prandtl-Ishlinskii model y = q v + sum_j p_j F_{r_j}[v] (Eq. 5.4) and its analytic inverse
  (Eqs. 5.9-5.11). Note the sign: the exact inverse weights are
  p_hat_j = -p_j / ((q + P_j)(q + P_{j-1})); Eq. 5.11 prints them without the minus.
* :class:`InverseCompensator`: temperature that makes the SD-GPI elongation equal a desired
  value at a given load (Eqs. 5.5-5.8), stateful, vectorised over scenarios. ``method``
  'numerical' (default) is a bracketed root on T against the frozen play memory, then the
  memory is committed; 'analytic' is Eq. 5.7-5.8 literally (PI inverse on the mirrored output,
  then gamma_l^-1 / gamma_r^-1 by direction), exact only when gamma_l = gamma_r = gamma and the
  memoryless part is p0 gamma; 'auto' uses the analytic value where it meets the target to
  ``tol`` and the numerical root elsewhere. Unreachable targets return the reachable extreme
  with ``saturated = True``.
* :class:`LinearCorrection` (Eqs. 5.12-5.14) and :func:`inverse_table_parameters` (Eq. 5.15,
  Tables 5.2-5.3): the seed's data-driven corrections, with :func:`table_5_1_correction`
  giving what the printed numbers do.
* :func:`composition_error`: |v - y(y^-1(v))| along a decaying triangle at several loads.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sma_wrist.core import jit as _jm
from sma_wrist.core.errors import ModelInputError, ParameterError, check_finite
from sma_wrist.core.hysteresis import kernel as _hk
from sma_wrist.core.hysteresis.play import play_update
from sma_wrist.core.hysteresis.sdgpi import (
    HysteresisState,
    SDGPIParams,
    initial_state,
    memoryless,
    play_bounds,
    simulate,
    step,
    tanh_envelope,
)
from sma_wrist.data import seed_tables as st

FloatArray = NDArray[np.float64]

#: Effective wire length for strain = elongation / length (Sec. 3.2.1) [mm].
WIRE_LENGTH_MM = 80.0


# ----------------------------------------------------------------------------- classical PI and its inverse


def pi_inverse_params(q: float, thresholds: ArrayLike, weights: ArrayLike) -> tuple[float, FloatArray, FloatArray]:
    """Inverse PI parameters (q_hat, r_hat, p_hat), Eqs. 5.9-5.11.

    Forward model y = q v + sum_j p_j F_{r_j}[v] with 0 < r_1 < ... < r_n, q > 0 and
    q + P_j > 0 (P_j = p_1 + ... + p_j). Then v = q_hat y + sum_j p_hat_j F_{r_hat_j}[y] with
    q_hat = 1/q (5.9), r_hat_j = q r_j + sum_{i<j} p_i (r_j - r_i) (5.10) and
    p_hat_j = -p_j / ((q + P_j)(q + P_{j-1})) (5.11 with its sign restored).
    """
    r = np.asarray(thresholds, dtype=float)
    p = np.asarray(weights, dtype=float)
    if q <= 0 or r.shape != p.shape or np.any(np.diff(r) <= 0) or r[0] < 0:
        raise ParameterError(f'PI inverse needs q > 0 and increasing r >= 0 matching p; got q={q}, r={r}')
    P = q + np.cumsum(p)
    P_prev = np.concatenate([[q], P[:-1]])
    if np.any(P <= 0):
        raise ParameterError('PI inverse needs q + P_j > 0 for every j (the loop must stay monotone)')
    r_hat = q * r + np.array([np.sum(p[:j] * (r[j] - r[:j])) for j in range(r.size)])
    p_hat = -p / (P * P_prev)
    return 1.0 / q, r_hat, p_hat


def pi_series(
    v: ArrayLike, q: float, thresholds: ArrayLike, weights: ArrayLike, w0: ArrayLike | None = None
) -> tuple[FloatArray, FloatArray]:
    """Classical PI output y = q v + sum_j p_j F_{r_j}[v] (Eqs. 5.1-5.4) and the play states (N, n).

    ``w0`` are the play states before v[0] (default: f_r(v(0), 0), Eq. 5.1).
    """
    v = np.asarray(v, dtype=float)
    r = np.asarray(thresholds, dtype=float)
    p = np.asarray(weights, dtype=float)
    check_finite('PI input v', v)
    w = np.zeros_like(r) if w0 is None else np.array(w0, dtype=float)
    W = np.empty((v.size, r.size))
    for k, vk in enumerate(v):
        w = play_update(w, vk - r, vk + r, out=w)
        W[k] = w
    return q * v + W @ p, W


def pi_inverse_state(v: float, q: float, w: ArrayLike, weights: ArrayLike) -> FloatArray:
    """Play states of the inverse PI consistent with forward states w at input v.

    w_hat_j = (q + P_{j-1}) w_j + q_j-tail, i.e. w_hat_j = (q + P_{j-1}) w_j + sum_{i>=j} p_i w_i,
    so that |y - w_hat_j| <= r_hat_j and the composition is exact from the first sample on.
    The same map with (q_hat, p_hat) gives the forward states from the inverse ones.
    """
    w = np.asarray(w, dtype=float)
    p = np.asarray(weights, dtype=float)
    P_prev = q + np.concatenate([[0.0], np.cumsum(p)[:-1]])
    tail = np.cumsum((p * w)[::-1])[::-1]  # sum_{i>=j} p_i w_i
    return P_prev * w + tail


# ----------------------------------------------------------------------------- SD-GPI inverse


def _inverse_tanh(k: FloatArray, u: FloatArray) -> tuple[FloatArray, NDArray[np.bool_]]:
    """T with k0 tanh(k1 T + k2) + k3 = u; (T clipped to the envelope's open range, in_range flag)."""
    z = (u - k[..., 3]) / k[..., 0]
    ok = np.abs(z) < 1.0
    z = np.clip(z, -1.0 + 1e-12, 1.0 - 1e-12)
    return (np.arctanh(z) - k[..., 2]) / k[..., 1], ok


def _output_frozen(
    params: SDGPIParams,
    w: FloatArray,
    T: FloatArray,
    m: FloatArray,
    heating: FloatArray,
    coefficients: tuple[FloatArray, FloatArray] | None = None,
) -> FloatArray:
    """Elongation k_f - y_m at trial temperatures T from frozen play states w (Eqs. 3.19, 4.1, 4.2).

    Broadcasts T (..., S) against w (S, n), m (S,), heating (..., S). ``coefficients``: the
    envelopes' (a, b) at m when the caller has them already.
    """
    if coefficients is None:
        lower, upper = play_bounds(params, T, np.broadcast_to(m, T.shape))
    else:
        a, b = coefficients
        r = params.thresholds
        lower = tanh_envelope(b, T)[..., None] - r
        upper = tanh_envelope(a, T)[..., None] + r
    wt = np.minimum(np.maximum(w, lower), upper)
    return params.k_f - (memoryless(params, T, heating) + wt @ params.weights)


@dataclass
class InverseResult:
    """Temperatures, saturation flags and the elongations they give (after the memory commit)."""

    T: FloatArray
    saturated: NDArray[np.bool_]
    achieved_mm: FloatArray


_F64 = np.dtype(np.float64)  # the dtype of every native float64 array (an identity test, not a comparison)


def _per_wire(x: ArrayLike, shape: tuple[int, ...]) -> FloatArray:
    """x as a float array of the memory's shape: x itself when it already is one (the node's call:
    no broadcast, no copy, the kernels only read it), else a broadcast copy."""
    if type(x) is np.ndarray and x.shape == shape and x.dtype is _F64 and x.flags.c_contiguous:
        return x
    return np.broadcast_to(np.asarray(x, float), shape).copy()


# Compiled one-wrist paths (optional numba, the set-up of sma_wrist.core.plant.kernel). The node
# calls observe + solve at 100 Hz on two wires, where numpy's per-call overhead on (2,) arrays
# was ~250 us a tick; these are the same equations as scalar loops over the wires. The numpy
# code of InverseCompensator stays the reference and the path without numba (test_inverse
# checks both agree).

# the residual is evaluated ~60 times per wire and solve: inlined into its callers (numba IR),
# it no longer passes its 13 arguments (5 arrays) on every evaluation, ~half its cost. The
# same operations in the same order: the same numbers.
_jit_inline = _jm._jit_inline


@_jit_inline
def _residual_parts(T, T0, h_prev, heat_side, coef, w, r, wts, c, d, p0):  # pragma: no cover - compiled
    """(p0 y_mem, sum of the weighted plays) of one wire at T against frozen play states w (Eqs. 3.19,
    3.21, 3.22, 4.1, 4.2): :func:`_residual` is k_f - (their sum) - y. Each is monotone in T on one
    side of T0 (one tanh; plays clamped between two envelopes moving the same way): the saturated
    search's bounds (:func:`_side_free`).

    coef: (a0..a3, b0..b3) at the wire's load (Eqs. 4.4-4.5). The memoryless part keeps the
    last direction h_prev at T = T0 and takes the side's direction heat_side elsewhere.
    """
    heat = h_prev if T == T0 else heat_side
    gl = coef[4] * math.tanh(coef[5] * T + coef[6]) + coef[7]
    gr = coef[0] * math.tanh(coef[1] * T + coef[2]) + coef[3]
    acc = 0.0
    for i in range(r.shape[0]):
        acc += min(max(w[i], gl - r[i]), gr + r[i]) * wts[i]
    if heat:
        mem = c[0] * math.tanh(c[1] * T + c[2]) + c[3]
    else:
        mem = d[0] * math.tanh(d[1] * T + d[2]) + d[3]
    return p0 * mem, acc


@_jit_inline
def _residual(T, T0, h_prev, heat_side, coef, w, y, r, wts, c, d, p0, k_f):  # pragma: no cover - compiled
    """k_f - y_m(T) - y of one wire against frozen play states w (:func:`_residual_parts`)."""
    mem, acc = _residual_parts(T, T0, h_prev, heat_side, coef, w, r, wts, c, d, p0)
    return k_f - (mem + acc) - y


@_jm._jit
def _refine(lo_T, hi_T, f_lo, f_hi, T0, h_prev, heat_side, coef, w, y, r, wts, c, d, p0, k_f, tol):  # pragma: no cover
    """Illinois regula falsi on a bracket [lo_T, hi_T] of :func:`_residual` (bisection where the
    secant stalls) to |residual| <= tol / 10; the last point evaluated."""
    x = 0.5 * (lo_T + hi_T)
    side = 0
    for _ in range(60):
        denom = f_hi - f_lo
        sec = hi_T - f_hi * (hi_T - lo_T) / denom if denom != 0 else 0.5 * (lo_T + hi_T)
        if sec > min(lo_T, hi_T) and sec < max(lo_T, hi_T):
            x = sec
        else:
            x = 0.5 * (lo_T + hi_T)
        fx = _residual(x, T0, h_prev, heat_side, coef, w, y, r, wts, c, d, p0, k_f)
        if f_lo * fx <= 0:  # root in [lo, x]; Illinois: halve the end kept twice
            if side == -1:
                f_lo = 0.5 * f_lo
            f_hi = fx
            hi_T = x
            side = -1
        else:
            if side == 1:
                f_hi = 0.5 * f_hi
            f_lo = fx
            lo_T = x
            side = 1
        if abs(fx) <= 0.1 * tol or abs(hi_T - lo_T) < 1e-12:
            break
    return x


@_jm._jit
def _argmin_abs(f):  # pragma: no cover - compiled
    """Index of the first smallest |f| (np.argmin(np.abs(f)))."""
    k = 0
    for g in range(1, f.shape[0]):
        if abs(f[g]) < abs(f[k]):
            k = g
    return k


#: rounding allowance of the saturated search's bounds [mm]: the bounds and the residuals are sums
#: of the same monotone parts, equal up to a few ulp of ~mm (1e-15); a bound decides only beyond this
BOUND_MARGIN_MM = 1e-12


@_jit_inline
def _grid_f(side, g, T0, end, h_prev, coef, w, y, r, wts, c, d, p0, k_f, Tg, f, P, A, known):  # pragma: no cover
    """f[side, g], the residual at grid point g of a side (Tg[side, g] = T0 + g / (G - 1) (end - T0)),
    evaluated once: the walk and the saturated search share the points (the same floats either way)."""
    if not known[side, g]:
        Tg[side, g] = T0 + (g / (Tg.shape[1] - 1.0)) * (end - T0)
        pm, acc = _residual_parts(Tg[side, g], T0, h_prev, side == 0, coef, w, r, wts, c, d, p0)
        P[side, g] = pm
        A[side, g] = acc
        f[side, g] = k_f - (pm + acc) - y
        known[side, g] = True
    return f[side, g]


@_jit_inline
def _interval_bounds(side, a, b, y, k_f, P, A):  # pragma: no cover - compiled
    """(lowest, highest) residual the grid points strictly between a and b of a side can have: the two
    parts are each monotone in T, so between two points each lies between its values there."""
    f_min = k_f - (max(P[side, a], P[side, b]) + max(A[side, a], A[side, b])) - y
    f_max = k_f - (min(P[side, a], P[side, b]) + min(A[side, a], A[side, b])) - y
    return f_min, f_max


@_jm._jit
def _side_free(
    side, T0, end, h_prev, coef, w, y, r, wts, c, d, p0, k_f, Tg, f, P, A, known, stack
):  # pragma: no cover - compiled
    """True when no two neighbouring grid points g-1, g >= 1 of a side change sign (what the walk would
    find), shown from a few points: an interval whose bounds (:func:`_interval_bounds`) keep one sign
    needs no point inside; others are halved. False on a sign change between two evaluated points
    (the walk then finds the first) or where the bounds do not hold (T0 on the grid after g = 0)."""
    G = Tg.shape[1]
    # the plays' sum is monotone in T when both envelopes move the same way and the weights share a sign
    if coef[0] * coef[1] * coef[4] * coef[5] < 0:
        return False
    for i in range(wts.shape[0]):
        if wts[i] * wts[0] < 0:
            return False
    _grid_f(side, 1, T0, end, h_prev, coef, w, y, r, wts, c, d, p0, k_f, Tg, f, P, A, known)
    _grid_f(side, G - 1, T0, end, h_prev, coef, w, y, r, wts, c, d, p0, k_f, Tg, f, P, A, known)
    if Tg[side, 1] == T0:  # the memoryless part switches direction at T0: no bound
        return False
    stack[0, 0], stack[0, 1] = 1, G - 1
    n = 1
    while n > 0:
        n -= 1
        a, b = stack[n, 0], stack[n, 1]
        if f[side, a] * f[side, b] <= 0:
            return False
        if b - a < 2:
            continue
        f_min, f_max = _interval_bounds(side, a, b, y, k_f, P, A)
        if f_min > BOUND_MARGIN_MM or f_max < -BOUND_MARGIN_MM:
            continue
        mid = (a + b) // 2
        _grid_f(side, mid, T0, end, h_prev, coef, w, y, r, wts, c, d, p0, k_f, Tg, f, P, A, known)
        stack[n, 0], stack[n, 1] = a, mid
        stack[n + 1, 0], stack[n + 1, 1] = mid, b
        n += 2
    return True


@_jm._jit
def _side_argmin(
    side, T0, end, h_prev, coef, w, y, r, wts, c, d, p0, k_f, Tg, f, P, A, known, stack
):  # pragma: no cover - compiled
    """_argmin_abs over a side shown free of sign changes (:func:`_side_free`: one strict sign on g >= 1),
    evaluating only the points that can hold the first smallest |f|: an interval whose bound on |f|
    exceeds the smallest |f| evaluated so far holds none."""
    G = Tg.shape[1]
    best = np.inf
    for g in range(G):
        if known[side, g]:
            best = min(best, abs(f[side, g]))
    stack[0, 0], stack[0, 1] = 1, G - 1
    n = 1
    while n > 0:
        n -= 1
        a, b = stack[n, 0], stack[n, 1]
        if b - a < 2:
            continue
        f_min, f_max = _interval_bounds(side, a, b, y, k_f, P, A)
        low = f_min if f[side, a] > 0 else -f_max  # |f| inside is at least this
        if low - BOUND_MARGIN_MM > best:
            continue
        mid = (a + b) // 2
        best = min(
            best, abs(_grid_f(side, mid, T0, end, h_prev, coef, w, y, r, wts, c, d, p0, k_f, Tg, f, P, A, known))
        )
        stack[n, 0], stack[n, 1] = a, mid
        stack[n + 1, 0], stack[n + 1, 1] = mid, b
        n += 2
    k = -1
    for g in range(G):
        if known[side, g] and (k < 0 or abs(f[side, g]) < abs(f[side, k])):
            k = g
    return k


@_jm._jit
def _nearest_root(
    T0, h_prev, coef, w, y, r, wts, c, d, p0, k_f, lo, hi, tol, Tg, f, P, A, known, stack
):  # pragma: no cover - compiled
    """(T, saturated) of one wire as :meth:`InverseCompensator._numerical` and ``_pick`` give them.

    Side 0 walks a G-point grid Tg[0] from T0 to hi (heating), side 1 Tg[1] to lo (cooling), in
    step, each to its first sign change, then refines it. A side whose next bracket starts
    farther from T0 than the other side's root stops there: its root could not be the nearer
    one, so the answer is the same as with both grids walked to their ends, for a fraction of the
    residuals when the target is close to the last temperature (the node's case).

    A target out of reach (no sign change on either side: saturated, about half the sweep's solves)
    needs the first smallest |f| of each grid. After the first step without a root, a side shown
    free of sign changes from a few points (:func:`_side_free`) stops walking, and its smallest |f|
    is found the same way (:func:`_side_argmin`): ~12 instead of 33 residuals per side, the same
    answer (the points it skips cannot change it; test_inverse compares with the full walk).
    P, A (2, G) and known (2, G) are the grid's parts and evaluated flags, stack (G, 2) work space.
    """
    G = Tg.shape[1]
    for g in range(G):
        known[0, g] = False
        known[1, g] = False
    root = np.full(2, np.nan)
    live = np.ones(2, np.bool_)
    free = np.zeros(2, np.bool_)  # a side shown to have no sign change
    for g in range(G):
        for side in range(2):
            if not live[side]:
                continue
            if g > 0 and math.isfinite(root[1 - side]) and abs(Tg[side, g - 1] - T0) > abs(root[1 - side] - T0):
                live[side] = False
                continue
            if not known[side, g]:  # _grid_f written out: numba's inlining of it here cost ~25 % (measured)
                Tg[side, g] = T0 + (g / (G - 1.0)) * ((hi if side == 0 else lo) - T0)
                pm, acc = _residual_parts(Tg[side, g], T0, h_prev, side == 0, coef, w, r, wts, c, d, p0)
                P[side, g] = pm
                A[side, g] = acc
                f[side, g] = k_f - (pm + acc) - y
                known[side, g] = True
            if g > 0 and f[side, g - 1] * f[side, g] <= 0:
                root[side] = _refine(
                    Tg[side, g - 1],
                    Tg[side, g],
                    f[side, g - 1],
                    f[side, g],
                    T0,
                    h_prev,
                    side == 0,
                    coef,
                    w,
                    y,
                    r,
                    wts,
                    c,
                    d,
                    p0,
                    k_f,
                    tol,
                )
                live[side] = False
        if g == 1 and G > 2 and live[0] and live[1]:  # no root next to T0: is the target out of reach?
            for side in range(2):
                if _side_free(
                    side,
                    T0,
                    hi if side == 0 else lo,
                    h_prev,
                    coef,
                    w,
                    y,
                    r,
                    wts,
                    c,
                    d,
                    p0,
                    k_f,
                    Tg,
                    f,
                    P,
                    A,
                    known,
                    stack,
                ):
                    free[side] = True
                    live[side] = False
        if not (live[0] or live[1]):
            break
    dist0 = abs(root[0] - T0) if math.isfinite(root[0]) else np.inf
    dist1 = abs(root[1] - T0) if math.isfinite(root[1]) else np.inf
    if math.isfinite(min(dist0, dist1)):  # nearest root: the smallest move that reaches the target
        return (root[1] if dist1 < dist0 else root[0]), False
    # saturated: the reachable grid value closest to the target
    if free[0]:
        k0 = _side_argmin(0, T0, hi, h_prev, coef, w, y, r, wts, c, d, p0, k_f, Tg, f, P, A, known, stack)
    else:
        k0 = _argmin_abs(f[0])
    if free[1]:
        k1 = _side_argmin(1, T0, lo, h_prev, coef, w, y, r, wts, c, d, p0, k_f, Tg, f, P, A, known, stack)
    else:
        k1 = _argmin_abs(f[1])
    return (Tg[1, k1] if abs(f[1, k1]) < abs(f[0, k0]) else Tg[0, k0]), True


@_jm._jit
def _invert_frozen(
    T_prev, heating, w, y_d, m, stacked, edges, r, wts, c, d, p0, k_f, lo, hi, m_lo, m_hi, G, tol, T, sat, y
):  # pragma: no cover - compiled
    """Compiled :meth:`InverseCompensator._numerical` and :func:`_output_frozen` at the answer,
    wire by wire (Eqs. 3.19-3.22, 4.1-4.5), each in its own window [lo[s], hi[s]] [degC].

    Writes T, sat and y (S,); returns False when a target is not finite or a load is not inside
    [m_lo, m_hi] (then the caller runs its input checks), the outputs being written all the same.
    """
    ok = True
    Tg = np.empty((2, G))
    f = np.empty((2, G))
    P, A, known, stack = np.empty((2, G)), np.empty((2, G)), np.empty((2, G), np.bool_), np.empty((G, 2), np.int64)
    coef, slope = np.empty(8), np.empty(8)  # once, not two heap allocations per wire
    for s in range(T_prev.shape[0]):
        if not (math.isfinite(y_d[s]) and m_lo <= m[s] <= m_hi):
            ok = False
        _hk._envelopes_into(stacked, edges, m[s], coef, slope)
        T[s], sat[s] = _nearest_root(
            min(max(T_prev[s], lo[s]), hi[s]),
            heating[s],
            coef,
            w[s],
            y_d[s],
            r,
            wts,
            c,
            d,
            p0,
            k_f,
            lo[s],
            hi[s],
            tol,
            Tg,
            f,
            P,
            A,
            known,
            stack,
        )
        # elongation at the answer against the frozen memory (the residual of target 0), the
        # memoryless part's direction from T_prev (Eq. 3.22)
        Ts = T[s]
        heat = Ts > T_prev[s] or (Ts == T_prev[s] and heating[s])
        y[s] = _residual(Ts, np.nan, heat, heat, coef, w[s], 0.0, r, wts, c, d, p0, k_f)
    return ok


@_jm._jit
def _observe_step(T, m, T_lo, T_hi, m_lo, m_hi, stacked, edges, r, w, heating, T_prev):  # pragma: no cover
    """Compiled :meth:`InverseCompensator.observe`: T and m clipped to the model's window, the
    envelopes at the clipped load (Eqs. 4.4-4.5, 3.21), the play update (Eq. 3.19) of w (S, n)
    and the direction, in place. Returns False, touching nothing, when an input is NaN."""
    S = T.shape[0]
    for s in range(S):
        if math.isnan(T[s]) or math.isnan(m[s]):
            return False
    coef, slope = np.empty(8), np.empty(8)  # once, not two heap allocations per wire
    for s in range(S):
        Ts = min(max(T[s], T_lo), T_hi)
        _hk._envelopes_into(stacked, edges, min(max(m[s], m_lo), m_hi), coef, slope)
        gl = coef[4] * math.tanh(coef[5] * Ts + coef[6]) + coef[7]
        gr = coef[0] * math.tanh(coef[1] * Ts + coef[2]) + coef[3]
        for i in range(r.shape[0]):
            w[s, i] = min(max(w[s, i], gl - r[i]), gr + r[i])
        if Ts > T_prev[s]:
            heating[s] = True
        elif Ts < T_prev[s]:
            heating[s] = False
        T_prev[s] = Ts
    return True


class InverseCompensator:
    """Stateful inverse SD-GPI compensator, Eqs. 5.5-5.8, over S independent scenarios.

    ``__call__(desired_elongation_mm, load_kgf) -> (T_desired, saturated)``: the temperature
    [degC] in ``T_range`` whose SD-GPI elongation, from the current memory and at that load,
    equals the desired one; the memory then advances to it (the compensator mirrors the
    plant's memory as long as the plant follows the commanded temperature).
    """

    def __init__(
        self,
        params: SDGPIParams,
        *,
        T_range: tuple[float, float] | None = None,
        method: str = 'numerical',
        grid: int = 33,
        tol_mm: float = 1e-9,
    ) -> None:
        if method not in ('numerical', 'analytic', 'auto'):
            raise ModelInputError('inverse method', method, "{'analytic', 'auto', 'numerical'}")
        lo, hi = T_range if T_range is not None else params.T_valid
        if not (params.T_valid[0] <= lo < hi <= params.T_valid[1]):
            raise ModelInputError('compensator T_range', (lo, hi), f'inside {params.T_valid}', 'degC')
        self.params = params
        self.T_range = (float(lo), float(hi))
        self.method = method
        self.grid = int(grid)
        self.tol_mm = float(tol_mm)
        self.state: HysteresisState | None = None
        self._pi: tuple[float, FloatArray, FloatArray] | None = None
        self._w_hat: FloatArray | None = None
        self._ym_prev: FloatArray | None = None
        self._coef_key: bytes | None = None
        self._coef: tuple[FloatArray, FloatArray] = (np.empty((0, 4)), np.empty((0, 4)))
        f64 = np.float64
        env = params.envelopes
        # the compiled paths' parameter arguments, converted once
        self._kernel_params = (
            np.ascontiguousarray(env._stacked, f64),
            np.ascontiguousarray(env.edges_kg, f64),
            _jm.kernel_array(params.thresholds, f64),
            _jm.kernel_array(params.weights, f64),
            np.ascontiguousarray(params.c, f64),
            np.ascontiguousarray(params.d, f64),
            float(params.p0),
            float(params.k_f),
        )
        self._observe_params = (*params.T_valid, *params.load_range, *self._kernel_params[:3])  # _observe_step's

    # -- memory
    def reset(self, T0: ArrayLike, load_kgf: ArrayLike, *, branch: str = 'cooling') -> None:
        """Start from the memory the plant has after a long approach to (T0, load) along ``branch``."""
        self.state = initial_state(self.params, T0, load_kgf, branch=branch)
        self._w_hat = None

    def observe(self, T: ArrayLike, load_kgf: ArrayLike) -> None:
        """Advance the memory with a measured temperature [degC] and load [kgf] (the plant's own history).

        Eq. 5.5 commits the commanded temperature, which mirrors the plant only while the plant
        follows its command. A thermal actuator lags by seconds; then the committed memory sweeps
        operators the wire never swept and the next root lands on the wrong branch (the desired
        temperature chatters between branches). Observing the measurement keeps the memory true.
        """
        st_ = self._require_state()
        T = _per_wire(T, st_.T_prev.shape)
        m = _per_wire(load_kgf, st_.T_prev.shape)
        if _jm.AVAILABLE:  # the node calls this at 100 Hz: ~100 us of numpy per call -> a few us
            heating = st_.heating.copy()
            if _observe_step(T, m, *self._observe_params, st_.w, heating, st_.T_prev):
                st_.heating = heating
                self._w_hat = None
                return
        lo, hi = self.params.T_valid
        lo_m, hi_m = self.params.load_range
        T = np.clip(T, lo, hi)  # NaN stays NaN and is reported below
        m = np.clip(m, lo_m, hi_m)
        check_finite('measured wire temperature', T, 'degC')
        check_finite('measured wire load', m, 'kgf')
        step(self.params, st_, T, m, check=False)
        self._w_hat = None

    def _coefficients(self, m: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Envelope coefficients at loads m, remembered for the last m (the numpy root search and
        the elongation at its answer share it)."""
        key = m.tobytes()
        if self._coef_key != key:
            a, b = self.params.envelopes.coefficients(m)
            self._coef = (np.ascontiguousarray(a, np.float64), np.ascontiguousarray(b, np.float64))
            self._coef_key = key
        return self._coef

    def output(self, load_kgf: ArrayLike) -> FloatArray:
        """Elongation [mm] the current memory gives at its last temperature."""
        st_ = self._require_state()
        m = np.broadcast_to(np.asarray(load_kgf, float), st_.T_prev.shape)
        return _output_frozen(self.params, st_.w, st_.T_prev, m, st_.heating)

    def _require_state(self) -> HysteresisState:
        if self.state is None:
            raise ParameterError('InverseCompensator: call reset(T0, load) before the first target')
        return self.state

    # -- the inverse
    def __call__(self, desired_elongation_mm: ArrayLike, load_kgf: ArrayLike) -> tuple[FloatArray, NDArray[np.bool_]]:
        res = self.solve(desired_elongation_mm, load_kgf)
        return res.T, res.saturated

    def from_strain(self, desired_strain: ArrayLike, load_kgf: ArrayLike) -> tuple[FloatArray, NDArray[np.bool_]]:
        """Same as calling with elongation = strain x 80 mm (Sec. 3.2.1 effective length)."""
        return self(np.asarray(desired_strain, float) * WIRE_LENGTH_MM, load_kgf)

    def solve(
        self,
        desired_elongation_mm: ArrayLike,
        load_kgf: ArrayLike,
        *,
        commit: bool = True,
        window: tuple[ArrayLike, ArrayLike] | None = None,
    ) -> InverseResult:
        """Temperatures reaching the desired elongation from the current memory.

        commit: advance the memory to the answer (Eq. 5.5, memory of the commands); False leaves
        it to :meth:`observe` and reports the elongation the answer would give. ``window``: per
        wire (lowest, highest) temperature [degC] of the search, inside ``params.T_valid``
        (None: ``T_range`` for every wire); the numerical method only.
        """
        st_ = self._require_state()
        S = st_.T_prev.shape
        y_d = _per_wire(desired_elongation_mm, S)
        m = _per_wire(load_kgf, S)
        win = self._window(window, S)
        if _jm.AVAILABLE and self.method == 'numerical' and not commit:
            # the node's call at 100 Hz: root, pick and elongation in one compiled pass; the
            # checks run (and raise) only when the kernel saw a bad target or load
            T, sat, y, ok = self._invert_compiled(y_d, m, win)
            if not ok:
                self._check_targets(y_d, m)
            return InverseResult(T, sat, y)
        self._check_targets(y_d, m)
        T_num, sat = self._numerical(y_d, m, win)
        if self.method == 'numerical':
            T = T_num
        else:
            T_an = self._analytic(y_d, m)
            if self.method == 'analytic':
                T, sat = T_an, np.zeros(S, bool)
            else:  # auto: keep the analytic value where it meets the target, else the root
                heat = np.where(T_an > st_.T_prev, True, np.where(T_an < st_.T_prev, False, st_.heating))
                ok = np.abs(_output_frozen(self.params, st_.w, T_an, m, heat) - y_d) <= max(self.tol_mm, 1e-9)
                T = np.where(ok, T_an, T_num)
        if commit:
            y = step(self.params, st_, T, m, check=False)
        else:
            heat = np.where(T > st_.T_prev, True, np.where(T < st_.T_prev, False, st_.heating))
            y = _output_frozen(self.params, st_.w, T, m, heat, self._coefficients(m))
        if self.method == 'analytic':
            sat = np.abs(y - y_d) > 1e-6
        return InverseResult(T, sat, y)

    def _check_targets(self, y_d: FloatArray, m: FloatArray) -> None:
        """Raise ModelInputError for a non-finite desired elongation or a load outside the model's range."""
        check_finite('desired elongation', y_d, 'mm')
        lo_m, hi_m = self.params.load_range
        if np.any(m < lo_m) or np.any(m > hi_m):
            bad = float(m.min() if m.min() < lo_m else m.max())
            raise ModelInputError('wire load m', bad, f'[{lo_m:g}, {hi_m:g}]', 'kgf')

    def _window(self, window: tuple[ArrayLike, ArrayLike] | None, S: tuple[int, ...]) -> tuple[FloatArray, FloatArray]:
        """Per-wire search window (lo, hi), each of the memory's shape [degC], checked inside the model's validity."""
        if window is None:
            return np.full(S, self.T_range[0]), np.full(S, self.T_range[1])
        if self.method != 'numerical':
            raise ParameterError(f'a per-wire window needs the numerical inverse, not {self.method!r}')
        lo, hi = (_per_wire(x, S) for x in window)
        v_lo, v_hi = self.params.T_valid
        if lo.size > 8:  # many wires (the sweep's bank): the same test on the arrays
            inside = bool(np.all((v_lo <= lo) & (lo < hi) & (hi <= v_hi)))
        else:  # the node's two wires: float by float, a fraction of numpy's per-call cost
            inside = all(v_lo <= a < b <= v_hi for a, b in zip(lo.ravel().tolist(), hi.ravel().tolist()))
        if not inside:  # NaN fails too
            raise ModelInputError(
                'compensator window', (lo.tolist(), hi.tolist()), f'inside {self.params.T_valid}', 'degC'
            )
        return lo, hi

    def _invert_compiled(
        self, y_d: FloatArray, m: FloatArray, window: tuple[FloatArray, FloatArray]
    ) -> tuple[FloatArray, NDArray[np.bool_], FloatArray, bool]:
        """(T, saturated, elongation at T against the frozen memory, inputs valid) from :func:`_invert_frozen`."""
        st_ = self._require_state()
        S = st_.T_prev.shape
        T, sat, y = np.empty(S), np.empty(S, np.bool_), np.empty(S)
        lo_m, hi_m = self.params.load_range
        ok = _invert_frozen(
            st_.T_prev,
            st_.heating,
            st_.w,
            y_d,
            m,
            *self._kernel_params,
            *window,
            lo_m,
            hi_m,
            self.grid,
            self.tol_mm,
            T,
            sat,
            y,
        )
        return T, sat, y, ok

    def _numerical(
        self, y_d: FloatArray, m: FloatArray, window: tuple[FloatArray, FloatArray]
    ) -> tuple[FloatArray, NDArray[np.bool_]]:
        """Bracketed root of y(T) = y_d on each side of T_prev against frozen memory; nearest root wins.

        Both sides are searched at once: a grid walking away from T_prev finds the first sign
        change, bisection refines it (y(T) is continuous on each side). Without any sign change
        the grid point closest to the target is returned and flagged saturated.
        """
        if _jm.AVAILABLE:  # same search, compiled: ~0.8 ms of numpy -> ~10 us per call
            T, sat, _, _ = self._invert_compiled(y_d, m, window)
            return T, sat
        st_ = self._require_state()
        p = self.params
        lo, hi = window
        T0 = np.clip(st_.T_prev, lo, hi)
        a, b = self._coefficients(m)  # load fixed during the solve: evaluate once
        r, wts, w = p.thresholds, p.weights, st_.w
        c, d, p0, k_f = p.c, p.d, p.p0, p.k_f
        S = y_d.size
        # columns 0..S-1 heating side, S..2S-1 cooling side
        T0s = np.concatenate([T0, T0])
        ends = np.concatenate([hi, lo])
        side_heat = np.concatenate([np.ones(S, bool), np.zeros(S, bool)])
        a2, b2, w2, y2 = (
            np.concatenate([a, a]),
            np.concatenate([b, b]),
            np.concatenate([w, w]),
            np.concatenate([y_d, y_d]),
        )
        h_prev = np.concatenate([st_.heating, st_.heating])

        def resid(T: FloatArray) -> FloatArray:  # T (..., 2S)
            heat = np.where(T == T0s, h_prev, side_heat)
            gl = b2[..., 0] * np.tanh(b2[..., 1] * T + b2[..., 2]) + b2[..., 3]
            gr = a2[..., 0] * np.tanh(a2[..., 1] * T + a2[..., 2]) + a2[..., 3]
            wt = np.minimum(np.maximum(w2, gl[..., None] - r), gr[..., None] + r)
            mem = np.where(heat, c[0] * np.tanh(c[1] * T + c[2]) + c[3], d[0] * np.tanh(d[1] * T + d[2]) + d[3])
            return k_f - (p0 * mem + wt @ wts) - y2

        cols = np.arange(2 * S)
        s = np.linspace(0.0, 1.0, self.grid)[:, None]
        Tg = T0s + s * (ends - T0s)  # (G, 2S) starting at T_prev
        f = resid(Tg)
        change = f[:-1] * f[1:] <= 0
        has = change.any(axis=0)
        k = np.argmax(change, axis=0)
        lo_T, hi_T, f_lo, f_hi = Tg[k, cols], Tg[k + 1, cols], f[k, cols], f[k + 1, cols]
        # Illinois regula falsi on the bracket (superlinear; y(T) is smooth between operator
        # kinks), stopping at the tolerance instead of a fixed 48 bisections (~7x fewer
        # residual evaluations per call at the node's 100 Hz). Bisection where the secant stalls.
        x = 0.5 * (lo_T + hi_T)
        side = np.zeros(2 * S, np.int8)
        for _ in range(60):
            denom = f_hi - f_lo
            sec = np.where(
                denom != 0, hi_T - f_hi * (hi_T - lo_T) / np.where(denom != 0, denom, 1.0), 0.5 * (lo_T + hi_T)
            )
            x = np.where((sec > np.minimum(lo_T, hi_T)) & (sec < np.maximum(lo_T, hi_T)), sec, 0.5 * (lo_T + hi_T))
            fx = resid(x)
            left = f_lo * fx <= 0  # root in [lo, x]
            # Illinois: halve the retained end's value when the same end is kept twice in a row
            f_lo = np.where(left, np.where(side == -1, 0.5 * f_lo, f_lo), fx)
            f_hi = np.where(left, fx, np.where(side == 1, 0.5 * f_hi, f_hi))
            lo_T = np.where(left, lo_T, x)
            hi_T = np.where(left, x, hi_T)
            side = np.where(left, -1, 1).astype(np.int8)
            if np.all((np.abs(fx) <= 0.1 * self.tol_mm) | ~has | (np.abs(hi_T - lo_T) < 1e-12)):
                break
        # the last evaluated point is the root estimate (|residual| <= tol/10 there)
        root = np.where(has, x, np.nan)
        return self._pick(root, has, Tg, f, T0s, cols, S)

    @staticmethod
    def _pick(
        root: FloatArray,
        has: NDArray[np.bool_],
        Tg: FloatArray,
        f: FloatArray,
        T0s: FloatArray,
        cols: NDArray[np.int_],
        S: int,
    ) -> tuple[FloatArray, NDArray[np.bool_]]:
        """Nearest root of the two sides, else the grid point closest to the target (saturated)."""
        dist = np.where(has, np.abs(root - T0s), np.inf).reshape(2, S)
        pick = np.argmin(dist, axis=0)  # nearest root: the smallest move that reaches the target
        T_root = root.reshape(2, S)[pick, np.arange(S)]
        kk = np.argmin(np.abs(f), axis=0)  # saturation: the reachable value closest to the target
        e = np.abs(f[kk, cols]).reshape(2, S)
        pe = np.argmin(e, axis=0)
        T_sat = Tg[kk, cols].reshape(2, S)[pe, np.arange(S)]
        found = np.isfinite(dist.min(axis=0))
        return np.where(found, T_root, T_sat), ~found

    def _analytic(self, y_d: FloatArray, m: FloatArray) -> FloatArray:
        """Eqs. 5.7-5.8: u = PI^-1[y_m desired] (q = p0, Eqs. 5.9-5.11), T = gamma_{l|r}^-1(u)."""
        st_ = self._require_state()
        p = self.params
        if self._pi is None:
            self._pi = pi_inverse_params(p.p0, p.thresholds, p.weights)
        q_hat, r_hat, p_hat = self._pi
        ym = p.k_f - y_d
        if self._w_hat is None:  # consistent with the forward memory: u = current envelope value
            a, b = p.envelopes.coefficients(m)
            u0 = np.where(st_.heating, tanh_envelope(b, st_.T_prev), tanh_envelope(a, st_.T_prev))
            self._w_hat = np.stack([pi_inverse_state(float(u), p.p0, w, p.weights) for u, w in zip(u0, st_.w)])
            self._ym_prev = p.p0 * u0 + st_.w @ p.weights
        self._w_hat = play_update(self._w_hat, ym[:, None] - r_hat, ym[:, None] + r_hat, out=self._w_hat)
        u = q_hat * ym + self._w_hat @ p_hat
        rising = ym > self._ym_prev  # y_m rising = contraction = heating (Eq. 5.8: v' >= 0 -> gamma_l^-1)
        self._ym_prev = ym
        a, b = p.envelopes.coefficients(m)
        T_l, _ = _inverse_tanh(b, u)
        T_r, _ = _inverse_tanh(a, u)
        return np.clip(np.where(rising, T_l, T_r), *self.T_range)


# ----------------------------------------------------------------------------- composition error


def decaying_triangle(
    y_lo: float, y_hi: float, n_cycles: int = 4, samples_per_half: int = 40, decay: float = 0.6
) -> FloatArray:
    """Desired elongation: triangles between y_hi and a trough rising towards the middle (minor loops)."""
    mid = 0.5 * (y_lo + y_hi)
    pts = [y_hi]
    amp = 1.0
    for _ in range(n_cycles):
        pts += [mid - amp * (mid - y_lo), mid + amp * (y_hi - mid)]
        amp *= decay
    out = [np.linspace(pts[i], pts[i + 1], samples_per_half, endpoint=False) for i in range(len(pts) - 1)]
    return np.concatenate(out + [np.array([pts[-1]])])


@dataclass(frozen=True)
class CompositionError:
    """|v - y(y^-1(v))| per load [mm] and as % of the desired range."""

    loads_kgf: FloatArray
    max_mm: FloatArray
    rms_mm: FloatArray
    max_pct: FloatArray
    rms_pct: FloatArray
    range_mm: FloatArray
    saturated_fraction: FloatArray


def reachable_range(
    params: SDGPIParams, loads_kgf: ArrayLike, T_range: tuple[float, float], n: int = 400
) -> tuple[FloatArray, FloatArray]:
    """(min, max) elongation along the major loop T_lo -> T_hi -> T_lo, per load."""
    m = np.atleast_1d(np.asarray(loads_kgf, float))
    lo, hi = T_range
    T = np.concatenate([np.linspace(lo, hi, n), np.linspace(hi, lo, n)])
    y = simulate(params, np.repeat(T[:, None], m.size, axis=1), m[None, :].repeat(T.size, 0), branch='cooling')
    return y.min(axis=0), y.max(axis=0)


def composition_error(
    params: SDGPIParams,
    loads: ArrayLike = np.linspace(0.65, 1.05, 9),
    *,
    T_range: tuple[float, float] = (15.0, 85.0),
    method: str = 'numerical',
    margin: float = 0.05,
    n_cycles: int = 4,
) -> CompositionError:
    """Drive a decaying triangle v (inside margin of the reachable range) through y(y^-1(v)) per load.

    The compensator starts on the cooling branch at T_range[0]; the plant (``simulate``) is
    driven by the compensator's temperatures from the same memory.
    """
    m = np.atleast_1d(np.asarray(loads, float))
    y_lo, y_hi = reachable_range(params, m, T_range)
    span = y_hi - y_lo
    V = np.stack(
        [decaying_triangle(a + margin * s, b - margin * s, n_cycles) for a, b, s in zip(y_lo, y_hi, span)], axis=1
    )
    comp = InverseCompensator(params, T_range=T_range, method=method)
    comp.reset(np.full(m.size, T_range[0]), m, branch='cooling')
    T = np.empty_like(V)
    sat = np.zeros(V.shape, bool)
    for k in range(V.shape[0]):
        T[k], sat[k] = comp(V[k], m)
    y = simulate(params, T, np.broadcast_to(m, T.shape), state=initial_state(params, np.full(m.size, T_range[0]), m))
    err = np.abs(V - y)
    rng = V.max(axis=0) - V.min(axis=0)
    rms = np.sqrt(np.mean(err**2, axis=0))
    return CompositionError(
        m, err.max(axis=0), rms, 100 * err.max(axis=0) / rng, 100 * rms / rng, rng, sat.mean(axis=0)
    )


# ----------------------------------------------------------------------------- seed corrections (Eqs. 5.12-5.15)


@dataclass(frozen=True)
class LinearCorrection:
    """v = a_l u + c_l with a_l, c_l quadratic in the load (Eqs. 5.12-5.14).

    ``p_a`` = (p_a1, p_a2, p_a3), ``p_c`` likewise; ``load_scale`` converts kgf to the unit
    the quadratics use. :meth:`precompensate` returns the command u that the fitted linear
    relation maps to the wanted v.
    """

    p_a: tuple[float, float, float]
    p_c: tuple[float, float, float]
    load_scale: float = 1.0

    def gain_offset(self, load_kgf: ArrayLike) -> tuple[FloatArray, FloatArray]:
        s = np.asarray(load_kgf, float) * self.load_scale
        return np.polyval(self.p_a, s), np.polyval(self.p_c, s)

    def precompensate(self, v: ArrayLike, load_kgf: ArrayLike) -> FloatArray:
        """The command u = (v - c_l) / a_l whose corrected output is ``v`` at ``load_kgf`` (Eqs. 5.12-5.14 inverted)."""
        a, c = self.gain_offset(load_kgf)
        return (np.asarray(v, float) - c) / a

    @classmethod
    def fit(cls, loads_kgf: ArrayLike, u_ext: ArrayLike, v_ext: ArrayLike) -> LinearCorrection:
        """Fit Eqs. 5.12-5.14: per load a line through the (u, v) max/min points, then quadratics in load.

        ``u_ext``, ``v_ext``: (L, 2) compensated outputs and desired inputs at the min and max points.
        """
        m = np.asarray(loads_kgf, float)
        u = np.asarray(u_ext, float)
        v = np.asarray(v_ext, float)
        a = (v[:, 1] - v[:, 0]) / (u[:, 1] - u[:, 0])
        c = v[:, 0] - a * u[:, 0]
        deg = min(2, m.size - 1)
        pa = np.polyfit(m, a, deg)
        pc = np.polyfit(m, c, deg)
        pad = lambda x: tuple(np.concatenate([np.zeros(3 - x.size), x]).tolist())  # noqa: E731
        return cls(pad(pa), pad(pc))  # type: ignore[arg-type]


def table_5_1_correction(load_unit_scale: float = 1.0) -> LinearCorrection:
    """Table 5.1 as a :class:`LinearCorrection` (load in kgf times ``load_unit_scale``)."""
    t = st.TABLE_5_1
    return LinearCorrection((t['p_a1'], t['p_a2'], t['p_a3']), (t['p_c1'], t['p_c2'], t['p_c3']), load_unit_scale)


def inverse_table_parameters(load_g: float, *, load_scale: float = 1e-3) -> dict[str, float]:
    """Tables 5.2-5.3 (Eq. 5.15) evaluated at a load [g], the load in g x ``load_scale`` (default kg)."""
    for (lo, hi), rows in st.TABLES_5_2_5_3.items():
        if lo <= load_g <= hi:
            s = load_g * load_scale
            return {k: float(np.polyval(v, s)) for k, v in rows.items()}
    raise ModelInputError('load', load_g, '[650, 1050]', 'g')
