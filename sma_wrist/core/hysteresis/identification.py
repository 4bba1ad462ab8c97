"""Identification of GPI / SD-GPI parameters from measured loops (seed Secs. 4.1.1, 4.2.2, Eq. 3.25).

:func:`fit_gpi` fits one load: a, b, c, d sets (Eqs. 3.21-3.22), rho, tau (Eq. 3.23), c
(Eq. 3.24), optionally p0 (Eq. 4.1), to (T, elongation) samples by bounded least squares of
Eq. 3.25, staged as in Sec. 4.1.1 (envelopes + density with the memoryless part held, then the
memoryless part alone, then everything), from several starts built from the tanh saturation
levels and 50 % temperatures of the data. :func:`fit_sdgpi` fits the SD-GPI (Eqs. 4.4-4.6):
quadratics of the load per section for a_i, b_i, shared c, d, rho, tau, c, starting from
quadratic fits of per-load GPI fits (Sec. 4.2.2).

The fits use the exact Jacobian (:func:`simulate_jac`): every play state equals the bound
that last clamped it, so one simulation that records which sample and which bound set each
operator gives all derivatives (the play kernel is compiled by numba when installed,
:mod:`sma_wrist.core.hysteresis.identification_kernel`). ``method='fd'`` keeps the earlier forward-difference
Jacobian (:func:`simulate_batch`, one batched simulation of 20 perturbed vectors) for the
side-by-side benchmark (``sma-wrist bench --section identify``).
Conventions are those of :mod:`sma_wrist.core.hysteresis.sdgpi` (b set = gamma_l followed while
heating; elongation y = k_f - y_m).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import least_squares

from sma_wrist.core.errors import ModelInputError, ParameterError, check_finite
from sma_wrist.core.hysteresis.identification_kernel import gpi_jacobian, play_jacobian_numpy
from sma_wrist.core.hysteresis.sdgpi import EnvelopeSections, SDGPIParams
from sma_wrist.core.hysteresis.trf import AVAILABLE as TRF_AVAILABLE
from sma_wrist.core.hysteresis.trf import lstsq, polyfit, quantize, trf_solve

FloatArray = NDArray[np.float64]

N_SET = 4  # coefficients per tanh set
#: Parameter layout of one GPI vector: a(4) b(4) c(4) d(4) rho tau c_thr p0.
IDX_A, IDX_B, IDX_C, IDX_D = slice(0, 4), slice(4, 8), slice(8, 12), slice(12, 16)
IDX_RHO, IDX_TAU, IDX_CTHR, IDX_P0 = 16, 17, 18, 19
N_GPI = 20


def _tanh(k: FloatArray, T: FloatArray) -> FloatArray:
    return k[..., 0] * np.tanh(k[..., 1] * T + k[..., 2]) + k[..., 3]


def simulate_batch(
    T: ArrayLike, theta: ArrayLike, *, n: int = 15, k_f: float = 6.0, branch: str = 'cooling'
) -> FloatArray:
    """Elongation (N, B) for B GPI parameter vectors ``theta`` (B, 20) (layout IDX_*).

    Same recursion as :func:`sma_wrist.core.hysteresis.sdgpi.simulate` (Eqs. 3.19-3.24, 4.1, 4.2):
    initial memory on the ``branch`` bound at T[0]; the memoryless part keeps its direction
    while T is constant. T is (N,) shared or (N, B).
    """
    th = np.atleast_2d(np.asarray(theta, dtype=float))
    T = np.asarray(T, dtype=float)
    Tb = np.broadcast_to(T[:, None] if T.ndim == 1 else T, (T.shape[0], th.shape[0]))
    r = th[:, IDX_CTHR, None] * np.arange(1, n + 1)  # (B, n)
    p = th[:, IDX_RHO, None] * np.exp(-th[:, IDX_TAU, None] * r)
    gl = _tanh(th[None, :, IDX_B], Tb)  # (N, B)
    gr = _tanh(th[None, :, IDX_A], Tb)
    lower = gl[..., None] - r
    upper = gr[..., None] + r
    w = (upper[0] if branch == 'cooling' else lower[0]).copy()
    S = np.empty(Tb.shape)
    for k in range(Tb.shape[0]):
        np.minimum(np.maximum(w, lower[k], out=w), upper[k], out=w)
        S[k] = np.einsum('bj,bj->b', w, p)
    dT = np.diff(Tb, axis=0, prepend=Tb[:1])
    heat = np.empty(Tb.shape, dtype=bool)
    h = np.full(Tb.shape[1], branch == 'heating')
    for k in range(Tb.shape[0]):  # direction persists through flat samples
        h = np.where(dT[k] > 0, True, np.where(dT[k] < 0, False, h))
        heat[k] = h
    mem = np.where(heat, _tanh(th[None, :, IDX_C], Tb), _tanh(th[None, :, IDX_D], Tb))
    return k_f - (th[:, IDX_P0] * mem + S)


def heating_mask(T: FloatArray, branch: str = 'cooling') -> NDArray[np.bool_]:
    """Direction of the memoryless part per sample (Eq. 3.22): set by the last non-zero dT."""
    dT = np.diff(T, prepend=T[:1])
    last = np.maximum.accumulate(np.where(dT != 0, np.arange(T.size), 0))
    return np.where(last > 0, dT[last] > 0, branch == 'heating')


def _tanh_and_grad(k: FloatArray, T: FloatArray) -> tuple[FloatArray, FloatArray]:
    """k0 tanh(k1 T + k2) + k3 and its gradient (N, 4) over (k0, k1, k2, k3)."""
    t = np.tanh(k[1] * T + k[2])
    s = k[0] * (1.0 - t * t)
    return k[0] * t + k[3], np.stack([t, s * T, s, np.ones_like(T)], axis=1)


def simulate_jac(
    T: ArrayLike,
    theta: ArrayLike,
    *,
    n: int = 15,
    k_f: float = 6.0,
    branch: str = 'cooling',
    heat: NDArray[np.bool_] | None = None,
    compiled: bool = True,
) -> tuple[FloatArray, FloatArray]:
    """Elongation y (N,) [mm] of one GPI vector (layout IDX_*) and its exact Jacobian (N, 20).

    Same model as :func:`simulate_batch` (Eqs. 3.19-3.24, 4.1, 4.2). Each play state w_j is the
    bound that last clamped it (gamma_r(T_s) + r_j or gamma_l(T_s) - r_j at a sample s), so
    dw_j/dtheta is that bound's gradient at s; y = k_f - p0 gamma(T) - sum_j p_j w_j with
    p_j = rho exp(-tau c j) (Eq. 3.23) differentiates in closed form. Piecewise exact: a state
    that sits exactly on a switch has one-sided derivatives, which least squares tolerates.
    ``compiled``: one numba pass (:func:`~sma_wrist.core.hysteresis.identification_kernel.gpi_jacobian`)
    when numba is installed; False forces the numpy path (tests compare both).
    """
    T = np.asarray(T, dtype=float)
    th = np.asarray(theta, dtype=float)
    h = heating_mask(T, branch) if heat is None else heat
    if compiled:
        out = gpi_jacobian(T, th, n, k_f, branch != 'cooling', h)
        if out is not None:
            return out
    jj = np.arange(1, n + 1, dtype=float)
    r = th[IDX_CTHR] * jj
    e = np.exp(-th[IDX_TAU] * r)
    p = th[IDX_RHO] * e
    gr, Ga = _tanh_and_grad(th[IDX_A], T)
    gl, Gb = _tanh_and_grad(th[IDX_B], T)
    lower = gl[:, None] - r
    upper = gr[:, None] + r
    if branch == 'cooling':
        w0, s0 = upper[0], np.ones(n, np.int64)
    else:
        w0, s0 = lower[0], -np.ones(n, np.int64)
    S, dS_da, dS_db, dS_dc, Wjp = play_jacobian_numpy(lower, upper, w0, s0, p, jj, th[IDX_TAU], Ga, Gb)
    mc, Gc = _tanh_and_grad(th[IDX_C], T)
    md, Gd = _tanh_and_grad(th[IDX_D], T)
    mem = np.where(h, mc, md)
    p0 = th[IDX_P0]
    y = k_f - (p0 * mem + S)
    J = np.empty((T.size, N_GPI))
    J[:, IDX_A] = -dS_da
    J[:, IDX_B] = -dS_db
    J[:, IDX_C] = -p0 * h[:, None] * Gc
    J[:, IDX_D] = -p0 * (~h)[:, None] * Gd
    J[:, IDX_RHO] = (
        -S / th[IDX_RHO]
        if th[IDX_RHO] != 0
        else -play_jacobian_numpy(lower, upper, w0, s0, e, jj, th[IDX_TAU], Ga, Gb)[0]
    )
    J[:, IDX_TAU] = th[IDX_CTHR] * Wjp
    J[:, IDX_CTHR] = -dS_dc
    J[:, IDX_P0] = -mem
    return y, J


def gpi_vector(params: SDGPIParams, load_kgf: float) -> FloatArray:
    """The layout-IDX_* vector of an SD-GPI frozen at one load."""
    a, b = params.envelopes.coefficients(np.array(load_kgf))
    return np.concatenate([a, b, params.c, params.d, [params.rho, params.tau, params.c_thr, params.p0]])


def vector_to_params(theta: ArrayLike, *, n: int = 15, k_f: float = 6.0, name: str = 'fitted GPI') -> SDGPIParams:
    th = np.asarray(theta, dtype=float)
    return SDGPIParams.from_gpi(
        th[IDX_A],
        th[IDX_B],
        th[IDX_C],
        th[IDX_D],
        th[IDX_RHO],
        th[IDX_TAU],
        th[IDX_CTHR],
        n=n,
        p0=float(th[IDX_P0]),
        k_f=k_f,
        name=name,
    )


@dataclass(frozen=True)
class FitResult:
    """Outcome of an identification (Eq. 3.25 cost = 0.5 sum of squared residuals, scipy's convention)."""

    params: SDGPIParams
    residual_std_mm: float
    residual_std_pct: float  # % of the data's range (Eq. 4.3 normalisation)
    cost: float
    n_starts: int
    success: bool  # the optimiser ended without error (a used-up evaluation budget counts as success)
    theta: FloatArray


# ----------------------------------------------------------------------------- single load


def _bounds(y_range: float) -> tuple[FloatArray, FloatArray]:
    big = 1e3 * max(y_range, 1.0)
    env_lo = [1e-6, 1e-3, -300.0, -big]
    env_hi = [big, 3.0, 50.0, big]
    mem_lo = [-big, -3.0, -300.0, -big]
    mem_hi = [big, 3.0, 300.0, big]
    lo = np.array(env_lo * 2 + mem_lo * 2 + [1e-4, 0.0, 1e-4, 0.0])
    hi = np.array(env_hi * 2 + mem_hi * 2 + [1e2, 2e2, 5.0, 10.0])
    return lo, hi


def _mean(v: FloatArray) -> float:
    """Correctly rounded mean (numpy's pairwise sum follows its SIMD width)."""
    return math.fsum(v) / v.size


def _crossing_T(T: FloatArray, y: FloatArray, rising: bool) -> float:
    """Mean temperature where y crosses its mid level on rising (or falling) T samples."""
    dT = np.diff(T, prepend=T[0])
    sel = dT > 0 if rising else dT < 0
    if sel.sum() < 3:
        return _mean(T)
    Ts, ys = T[sel], y[sel]
    mid = 0.5 * (ys.min() + ys.max())
    order = np.argsort(Ts, kind='stable')  # equal temperatures keep their order (numpy's AVX-512 sort does not)
    Ts, ys = Ts[order], ys[order]
    idx = np.nonzero(np.diff(np.sign(ys - mid)) != 0)[0]
    return _mean(Ts[idx]) if idx.size else float(np.median(Ts))


def initial_guesses(
    T: FloatArray, y: FloatArray, *, n: int, k_f: float, p0: float, n_starts: int, seed: int = 0
) -> list[FloatArray]:
    """Starts from the data's tanh saturation levels (Sec. 4.1.1) and 50 % temperatures.

    The mirrored output y_m = k_f - y spans [lo, hi]; with all operators saturated the
    envelopes carry that span divided by the weight sum, so a0 = b0 = span / (2 P), a3 = b3 =
    centre / P. The heating (b) set is centred at the heating 50 % point, the cooling (a) set at
    the cooling one. Further starts vary the slopes, the density and the centres.
    """
    rng = np.random.default_rng(seed)
    ym = k_f - y
    lo, hi = float(ym.min()), float(ym.max())
    T_h = _crossing_T(T, ym, rising=True)
    T_c = _crossing_T(T, ym, rising=False)
    starts = []
    for s in range(n_starts):
        k = (0.15, 0.4, 0.08, 0.25)[s % 4] * (1.0 if s < 4 else math.exp(rng.normal(0, 0.3)))
        rho, tau, c = (1.0, 1.0, 0.05) if s % 2 == 0 else (0.5, 5.0, 0.1)
        r = c * np.arange(1, n + 1)
        P = math.fsum(rho * math.exp(-tau * v) for v in r)  # C library exp, exact sum: the same start on every CPU
        th_c = T_c + (0 if s < 4 else rng.normal(0, 3))
        th_h = T_h + (0 if s < 4 else rng.normal(0, 3))
        amp = max(hi - lo, 1e-3) / (2 * P) + r.mean()  # widen by the mean threshold so saturated ends match
        off = 0.5 * (hi + lo) / P
        a = [amp, k, -k * th_c, off]
        b = [amp, k, -k * th_h, off]
        mem = [1e-3 * (hi - lo), 0.05, -0.05 * _mean(T), 0.0]
        starts.append(np.array(a + b + mem + mem + [rho, tau, c, p0], dtype=float))
    return starts


def _jac_fd(fun_batch, x: FloatArray, free: NDArray[np.intp], lo: FloatArray, hi: FloatArray) -> FloatArray:
    """Forward-difference Jacobian over the free parameters with one batched simulation."""
    h = 1e-6 * np.maximum(np.abs(x[free]), 1e-3)
    h = np.where(x[free] + h > hi[free], -h, h)  # stay inside the bounds
    X = np.repeat(x[None], free.size + 1, axis=0)
    X[np.arange(1, free.size + 1), free] += h
    R = fun_batch(X)  # (M, free+1)
    return (R[:, 1:] - R[:, :1]) / h


def _solve(
    fun_batch, x0: FloatArray, free: NDArray[np.intp], lo: FloatArray, hi: FloatArray, max_nfev: int
) -> tuple[FloatArray, float, bool]:
    x = np.clip(x0, lo, hi)

    def f(z: FloatArray) -> FloatArray:
        xx = x.copy()
        xx[free] = z
        return fun_batch(xx[None])[:, 0]

    def j(z: FloatArray) -> FloatArray:
        xx = x.copy()
        xx[free] = z
        return _jac_fd(fun_batch, xx, free, lo, hi)

    z0 = np.clip(x[free], lo[free] + 1e-12, hi[free] - 1e-12)
    res = least_squares(
        f, z0, jac=j, bounds=(lo[free], hi[free]), x_scale='jac', max_nfev=max_nfev, xtol=1e-10, ftol=1e-10, gtol=1e-10
    )
    x[free] = res.x
    return x, float(res.cost), bool(res.status >= 0 and np.isfinite(res.cost))  # 0: budget used, still a valid fit


def _cost(r: FloatArray) -> float:
    """0.5 sum r^2, correctly rounded (math.fsum): the same bits on every CPU, so the choice between
    starts does not follow a BLAS kernel's summation order."""
    return 0.5 * math.fsum(r * r)


def _solve_exact(
    fun_jac, x0: FloatArray, free: NDArray[np.intp], lo: FloatArray, hi: FloatArray, max_nfev: int
) -> tuple[FloatArray, float, bool]:
    """As :func:`_solve` with the exact Jacobian: ``fun_jac(x) -> (residual, J over all of x)``.

    The same trust-region-reflective algorithm and tolerances as the finite-difference path (a
    bounded Levenberg-Marquardt on the normal equations was tried: it settles in the first of
    the loop's many local minima, 6x the cost TRF reaches). With numba it runs as
    :func:`~sma_wrist.core.hysteresis.trf.trf_solve`: the same fit on every CPU (scipy's
    ``least_squares`` walks a CPU-dependent path through the local minima: doc/howto/identify_wire.md
    "The same data on two CPUs"); without, scipy's ``least_squares``, which asks for the Jacobian
    at the point whose residual it just computed, so one simulation serves both.
    """
    x = quantize(np.clip(x0, lo, hi))  # starts from np.exp / LAPACK carry CPU-dependent last bits
    if TRF_AVAILABLE:

        def fj(z: FloatArray) -> tuple[FloatArray, FloatArray]:
            xx = x.copy()
            xx[free] = z
            r, J = fun_jac(xx)
            return r, J[:, free]

        x[free], _, status, _ = trf_solve(fj, x[free], lo[free], hi[free], max_nfev)
        cost = _cost(fun_jac(x)[0])
        return x, cost, bool(status >= 0 and np.isfinite(cost))  # 0: budget used, still a valid fit
    cache: dict[str, object] = {}

    def both(z: FloatArray) -> tuple[FloatArray, FloatArray]:
        if cache.get('z') is None or not np.array_equal(cache['z'], z):  # type: ignore[arg-type]
            xx = x.copy()
            xx[free] = z
            cache['z'] = z.copy()
            cache['rj'] = fun_jac(xx)
        return cache['rj']  # type: ignore[return-value]

    z0 = np.clip(x[free], lo[free] + 1e-12, hi[free] - 1e-12)
    res = least_squares(
        lambda z: both(z)[0],
        z0,
        jac=lambda z: both(z)[1][:, free],
        bounds=(lo[free], hi[free]),
        x_scale='jac',
        max_nfev=max_nfev,
        xtol=1e-10,
        ftol=1e-10,
        gtol=1e-10,
    )
    x[free] = res.x
    return x, float(res.cost), bool(res.status >= 0 and np.isfinite(res.cost))  # 0: budget used, still a valid fit


def _solve_best(
    fun_jac,
    starts: list[FloatArray],
    free: NDArray[np.intp],
    lo: FloatArray,
    hi: FloatArray,  # type: ignore[no-untyped-def]
    max_nfev: int,
    probe: float = 0.2,
) -> tuple[FloatArray, float, bool]:
    """:func:`_solve_exact` from the best of several starts: each probed with ``probe`` of the budget,
    then each continued with the rest; the lowest final cost wins (the first start on a tie).

    Why every start is continued: a probe stops at its budget, and which truncated path is lower
    after a fifth of the budget says little about where it ends (synthetic 7-load SD-GPI: the
    probe-best start ended at 0.75 % of stroke, the other at 0.62 %).
    """
    if len(starts) == 1:
        return _solve_exact(fun_jac, starts[0], free, lo, hi, max_nfev)
    n_probe = max(10, int(probe * max_nfev))
    probes = [_solve_exact(fun_jac, s0, free, lo, hi, n_probe) for s0 in starts]
    return min((_solve_exact(fun_jac, x, free, lo, hi, max_nfev - n_probe) for x, _, _ in probes), key=lambda t: t[1])


def _solver(method: str, T: FloatArray, y: FloatArray, n: int, k_f: float, branch: str):  # type: ignore[no-untyped-def]
    """(solve(x0, free, lo, hi, nfev), residual(x)) for one loop with the Jacobian ``method``."""
    if method == 'fd':

        def fun_batch(X: FloatArray) -> FloatArray:
            return simulate_batch(T, X, n=n, k_f=k_f, branch=branch) - y[:, None]

        return (
            lambda x0, free, lo, hi, nfev: _solve(fun_batch, x0, free, lo, hi, nfev),
            lambda x: fun_batch(x[None])[:, 0],
        )
    if method != 'exact':
        raise ParameterError(f"identification method must be 'exact' or 'fd', got {method!r}")
    heat = heating_mask(T, branch)

    def fun_jac(x: FloatArray) -> tuple[FloatArray, FloatArray]:
        ys, J = simulate_jac(T, x, n=n, k_f=k_f, branch=branch, heat=heat)
        return ys - y, J

    return (lambda x0, free, lo, hi, nfev: _solve_exact(fun_jac, x0, free, lo, hi, nfev), lambda x: fun_jac(x)[0])


#: Samples per load above which the fits run on a thinned copy (the play model is rate
#: independent: a thinned loop with the same temperature extrema has the same memory).
MAX_FIT_SAMPLES = 1000


def thin_indices(T: ArrayLike, max_n: int = MAX_FIT_SAMPLES) -> NDArray[np.intp]:
    """Indices of at most ~``max_n`` samples: evenly spaced ones plus every turning point of T.

    Turning points (local extrema of T) are what the play operators remember (Eq. 3.19), so
    the thinned series drives the model through the same memory states.
    """
    T = np.asarray(T, dtype=float)
    if T.size <= max_n:
        return np.arange(T.size)
    d = np.sign(np.diff(T))
    nz = np.nonzero(d)[0]
    turns = nz[1:][d[nz[1:]] != d[nz[:-1]]]  # first sample after a direction change = the extremum
    keep = np.union1d(np.linspace(0, T.size - 1, max_n).round().astype(np.intp), turns)
    return keep


def fit_gpi(
    T: ArrayLike,
    y: ArrayLike,
    *,
    n: int = 15,
    k_f: float = 6.0,
    p0: float | None = 1.0,
    n_starts: int = 4,
    max_nfev: int = 60,
    seed: int = 0,
    branch: str = 'cooling',
    method: str = 'exact',
) -> FitResult:
    """Fit a GPI at one load to a measured loop (T [degC], elongation y [mm]), Sec. 4.1.1.

    ``p0=None`` fits p0 too (it trades off against the c, d amplitudes; the seed never prints
    it). The staged fit runs from each start; the lowest final cost wins. ``method``: 'exact'
    (Jacobian of :func:`simulate_jac`) or 'fd' (the earlier finite differences, kept for the
    benchmark's side-by-side ratio).
    """
    T = np.asarray(T, dtype=float)
    y = np.asarray(y, dtype=float)
    check_finite('identification T', T, 'degC')
    check_finite('identification y', y, 'mm')
    if T.shape != y.shape or T.ndim != 1 or T.size < 20:
        raise ModelInputError('identification samples', T.shape, '(N,) with N >= 20 and y of the same shape')
    rng_y = float(np.ptp(y))
    lo, hi = _bounds(rng_y)

    solve, residual = _solver(method, T, y, n, k_f, branch)
    if method == 'exact' and T.size > MAX_FIT_SAMPLES:  # starts and stages on a thinned loop, polish on all
        keep = thin_indices(T)
        solve_all = solve
        solve, _ = _solver(method, T[keep], y[keep], n, k_f, branch)
    env_dens = np.r_[0:8, IDX_RHO, IDX_TAU, IDX_CTHR]
    mem = np.r_[8:16] if p0 is None else np.r_[8:16]
    every = np.r_[0:19] if p0 is not None else np.r_[0:20]
    best: tuple[float, FloatArray, bool] | None = None
    for x0 in initial_guesses(T, y, n=n, k_f=k_f, p0=1.0 if p0 is None else p0, n_starts=n_starts, seed=seed):
        x, _, _ = solve(x0, env_dens, lo, hi, max_nfev)  # stage 1: memory part
        x, _, _ = solve(x, mem, lo, hi, max_nfev)  # stage 2: memoryless part
        x, cost, ok = solve(x, every, lo, hi, 2 * max_nfev)  # stage 3: all
        if best is None or cost < best[0]:
            best = (cost, x, ok)
    assert best is not None
    cost, x, ok = best
    if method == 'exact' and T.size > MAX_FIT_SAMPLES:
        x, cost, ok = solve_all(x, every, lo, hi, max_nfev)
    resid = residual(x)
    sd = float(np.std(resid))
    return FitResult(vector_to_params(x, n=n, k_f=k_f), sd, 100 * sd / max(rng_y, 1e-12), cost, n_starts, ok, x)


# ----------------------------------------------------------------------------- SD-GPI across loads


def _sd_layout(n_sec: int) -> tuple[slice, slice, slice]:
    """Vector = [s_a (n_sec,4,3) | s_b (n_sec,4,3) | c(4) d(4) rho tau c_thr p0]."""
    k = n_sec * 12
    return slice(0, k), slice(k, 2 * k), slice(2 * k, 2 * k + 12)


def _sd_to_gpi(X: FloatArray, edges: FloatArray, loads: FloatArray) -> FloatArray:
    """(B, P) SD-GPI vectors -> (B, L, 20) GPI vectors at each load (Eqs. 4.4-4.5)."""
    n_sec = edges.size - 1
    sa_sl, sb_sl, rest = _sd_layout(n_sec)
    sa = X[:, sa_sl].reshape(-1, n_sec, 4, 3)
    sb = X[:, sb_sl].reshape(-1, n_sec, 4, 3)
    sec = np.clip(np.searchsorted(edges, loads, side='right') - 1, 0, n_sec - 1)
    mm = loads[None, :, None]
    qa, qb = sa[:, sec], sb[:, sec]  # (B, L, 4, 3)
    a = (qa[..., 0] * mm + qa[..., 1]) * mm + qa[..., 2]
    b = (qb[..., 0] * mm + qb[..., 1]) * mm + qb[..., 2]
    tail = np.broadcast_to(X[:, None, rest], (X.shape[0], loads.size, 12))
    return np.concatenate([a, b, tail], axis=-1)


def _columns(T: ArrayLike, y: ArrayLike, n_loads: int) -> tuple[list[FloatArray], list[FloatArray]]:
    """Per-load (T, y) sample lists from (N, L) arrays or from sequences of 1-D arrays (ragged)."""
    if isinstance(T, np.ndarray) and T.ndim == 2:
        Ta, ya = np.asarray(T, dtype=float), np.asarray(y, dtype=float)
        if Ta.shape != ya.shape or Ta.shape[1] != n_loads:
            raise ModelInputError('SD-GPI identification samples', Ta.shape, f'(N, {n_loads}) for T and y')
        return [Ta[:, i] for i in range(n_loads)], [ya[:, i] for i in range(n_loads)]
    Ts = [np.asarray(t, dtype=float) for t in T]  # type: ignore[union-attr]
    ys = [np.asarray(v, dtype=float) for v in y]  # type: ignore[union-attr]
    if len(Ts) != n_loads or len(ys) != n_loads or any(a.shape != b.shape or a.ndim != 1 for a, b in zip(Ts, ys)):
        raise ModelInputError(
            'SD-GPI identification samples', [a.shape for a in Ts], f'{n_loads} pairs of equal 1-D arrays'
        )
    return Ts, ys


def sdgpi_gpi_vectors(x: FloatArray, edges: FloatArray, loads: FloatArray) -> FloatArray:
    """(L, 20) GPI vectors of one SD-GPI vector (layout of ``_sd_layout``) at each load."""
    return _sd_to_gpi(np.asarray(x, dtype=float)[None], np.asarray(edges, dtype=float), np.asarray(loads, dtype=float))[
        0
    ]


def _per_load_envelopes(
    Ts: list[FloatArray],
    ys: list[FloatArray],
    br: list[str],
    base: FloatArray,
    order: NDArray[np.intp],
    mid: int,
    continuation: bool,
    n: int,
    k_f: float,
    lo: FloatArray,
    hi: FloatArray,
    max_nfev: int,
    method: str,
) -> FloatArray:
    """(L, 20) GPI vectors: only the a, b envelopes fitted per load, the rest held at ``base``.

    From the middle load's fit, or each from its neighbour's (continuation keeps neighbouring
    loads in one basin, so the coefficients vary smoothly with the load), Sec. 4.2.2.
    """
    G = np.empty((len(Ts), N_GPI))
    for path in (order[mid:], order[mid::-1]):
        start = base
        for i in path:
            solve_i, _ = _solver(method, Ts[i], ys[i], n, k_f, br[i])
            G[i], _, _ = solve_i(start if continuation else base, np.r_[0:8], lo, hi, max_nfev)
            start = G[i]
    return G


def fit_sdgpi(
    T: ArrayLike,
    y: ArrayLike,
    loads_kgf: ArrayLike,
    edges_kgf: ArrayLike,
    *,
    n: int = 15,
    k_f: float = 6.0,
    p0: float = 1.0,
    max_nfev: int = 200,
    per_load_starts: int = 1,
    method: str = 'exact',
    branches: list[str] | None = None,
    degrees: ArrayLike = (2, 2, 2, 2),
) -> FitResult:
    """Fit an SD-GPI (Eqs. 4.4-4.6) to loops at several loads, Sec. 4.2.2.

    ``T``, ``y``: (N, L) samples, one column per load, or L 1-D arrays (loads measured with
    different sample counts). Starting point: a GPI per load (:func:`fit_gpi`), a_i and b_i
    fitted by quadratics per section, shared sets averaged; then all quadratics and shared
    parameters jointly. Residual statistics pool all loads; the % is relative to the mean
    per-load range. ``method`` as in :func:`fit_gpi`; ``branches``: initial memory per load
    (default 'cooling' for all, see :func:`simulate_batch`); ``degrees``: polynomial degree
    in the load of (k0, k1, k2, k3) of both envelopes (Eqs. 4.4-4.5 use 2 throughout; lower
    degrees regularise, doc/howto/identify_wire.md). With 'exact' the per-load envelope fits also
    run as a continuation in load (each from its neighbour's fit) and the joint fit starts
    from both starting points, keeping the lower cost.
    """
    loads = np.asarray(loads_kgf, dtype=float)
    edges = np.asarray(edges_kgf, dtype=float)
    Ts_all, ys_all = _columns(T, y, loads.size)
    br = list(branches) if branches is not None else ['cooling'] * loads.size
    Ts, ys = Ts_all, ys_all
    if method == 'exact':  # long records are fitted on thinned loops (see thin_indices), scored on all
        keep = [thin_indices(t) for t in Ts_all]
        Ts, ys = [t[k] for t, k in zip(Ts_all, keep)], [v[k] for v, k in zip(ys_all, keep)]
    n_sec = edges.size - 1
    sec = np.clip(np.searchsorted(edges, loads, side='right') - 1, 0, n_sec - 1)
    for k in range(n_sec):
        if np.unique(loads[sec == k]).size < 3:
            raise ParameterError(f'section {k} ({edges[k]}-{edges[k + 1]} kgf) needs >= 3 loads for a quadratic')
    # Shared c, d, rho, tau, c from a full GPI fit at the middle load, then only the envelopes per
    # load (so a_i, b_i of different loads are comparable: the rho-amplitude trade-off is fixed).
    i_mid = int(np.argsort(loads, kind='stable')[loads.size // 2])
    base = fit_gpi(
        Ts[i_mid],
        ys[i_mid],
        n=n,
        k_f=k_f,
        p0=p0,
        n_starts=per_load_starts,
        max_nfev=max_nfev,
        method=method,
        branch=br[i_mid],
    ).theta
    lo1, hi1 = _bounds(float(np.ptp(np.concatenate(ys))))
    order = np.argsort(loads, kind='stable')  # repeated loads: the same order on every CPU
    mid = int(np.nonzero(order == i_mid)[0][0])
    deg = np.broadcast_to(np.asarray(degrees, dtype=int), (4,))

    def start_vector(continuation: bool) -> FloatArray:
        """Envelopes fitted per load, then polynomials of the load."""
        G = _per_load_envelopes(Ts, ys, br, base, order, mid, continuation, n, k_f, lo1, hi1, max_nfev, method)
        sa = np.zeros((n_sec, 4, 3))
        sb = np.zeros((n_sec, 4, 3))
        for k in range(n_sec):
            sel = sec == k
            for q in range(4):  # polynomial of degree deg[q] in the load; higher terms stay zero
                sa[k, q, 2 - deg[q] :] = polyfit(loads[sel], G[sel, q], deg[q])
                sb[k, q, 2 - deg[q] :] = polyfit(loads[sel], G[sel, 4 + q], deg[q])
        return np.concatenate([sa.ravel(), sb.ravel(), base[8:20]])

    # the earlier code ('fd') starts from the middle load's fit only; 'exact' also tries continuation
    starts = [start_vector(False)] + ([start_vector(True)] if method == 'exact' else [])
    x0 = starts[0]
    P = x0.size
    mask_free = np.ones(P, bool)
    mask_free[-1] = False  # p0 fixed
    sa_sl, sb_sl, rest = _sd_layout(n_sec)
    term = np.arange(3)
    for sl in (sa_sl, sb_sl):
        mask_free[sl] = np.tile((term[None, :] >= 2 - deg[:, None]).ravel(), n_sec)
    big = 1e6
    lo = np.full(P, -big)
    hi = np.full(P, big)
    sa_sl, sb_sl, rest = _sd_layout(n_sec)
    r0 = rest.start
    lo[r0 + 8 : r0 + 11] = [1e-4, 0.0, 1e-4]
    hi[r0 + 8 : r0 + 11] = [1e2, 2e2, 5.0]
    free = np.nonzero(mask_free)[0]
    offsets = np.cumsum([0] + [t.size for t in Ts])

    def fun_batch(X: FloatArray) -> FloatArray:
        th = _sd_to_gpi(X, edges, loads)  # (B, L, 20)
        out = np.empty((offsets[-1], X.shape[0]))
        for i in range(loads.size):
            out[offsets[i] : offsets[i + 1]] = (
                simulate_batch(Ts[i], th[:, i], n=n, k_f=k_f, branch=br[i]) - ys[i][:, None]
            )
        return out

    heats = [heating_mask(t, b) for t, b in zip(Ts, br)]

    def fun_jac(x: FloatArray) -> tuple[FloatArray, FloatArray]:
        th = _sd_to_gpi(x[None], edges, loads)[0]
        res = np.empty(offsets[-1])
        J = np.zeros((offsets[-1], P))
        for i in range(loads.size):
            rows = slice(offsets[i], offsets[i + 1])
            yi, Ji = simulate_jac(Ts[i], th[i], n=n, k_f=k_f, branch=br[i], heat=heats[i])
            res[rows] = yi - ys[i]
            powers = np.array([loads[i] ** 2, loads[i], 1.0])  # d a_q / d s_aq (Eqs. 4.4-4.5)
            for sl, cols in ((sa_sl, IDX_A), (sb_sl, IDX_B)):
                base_col = sl.start + sec[i] * 12
                J[rows, base_col : base_col + 12] = (Ji[:, cols, None] * powers).reshape(-1, 12)
            J[rows, rest] = Ji[:, 8:20]
        return res, J

    if method == 'fd':
        x, cost, ok = _solve(fun_batch, x0, free, lo, hi, max_nfev)
        resid = fun_batch(x[None])[:, 0]
    else:  # the joint stage gets twice the budget, as fit_gpi's last stage (cheap with the exact Jacobian)
        x, cost, ok = _solve_best(fun_jac, starts, free, lo, hi, 2 * max_nfev)
        th = _sd_to_gpi(x[None], edges, loads)[0]
        resid = np.concatenate(
            [
                simulate_batch(t, th[i][None], n=n, k_f=k_f, branch=br[i])[:, 0] - v
                for i, (t, v) in enumerate(zip(Ts_all, ys_all))
            ]
        )
    sd = float(np.std(resid))
    mean_range = float(np.mean([np.ptp(v) for v in ys_all]))
    env = EnvelopeSections(edges, x[sa_sl].reshape(n_sec, 4, 3), x[sb_sl].reshape(n_sec, 4, 3))
    tail = x[rest]
    params = SDGPIParams(
        env,
        tail[0:4],
        tail[4:8],
        float(tail[8]),
        float(tail[9]),
        float(tail[10]),
        n=n,
        p0=float(tail[11]),
        k_f=k_f,
        name='fitted SD-GPI',
    )
    return FitResult(params, sd, 100 * sd / max(mean_range, 1e-12), cost, per_load_starts, ok, x)


# ----------------------------------------------------------------------------- Clausius-Clapeyron load law

#: Parameters per envelope set of the Clausius-Clapeyron load law (:func:`cc_coefficients`).
N_CC = 10
#: Indices of the quadratic terms of amplitude and offset in one set's CC vector.
CC_QUADRATIC = (2, 9)


def cc_coefficients(z: ArrayLike, u: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Envelope coefficients (L, 4) and their Jacobian (L, 4, 10) over z at load offsets u [kgf].

    The load shifts the transformation temperatures linearly (Clausius-Clapeyron: the tanh
    centre -k2/k1 of Eq. 3.21 moves by C [degC/kgf] per kgf), the tanh slope changes linearly,
    amplitude and offset at most quadratically: with u = m - m_ref and
    z = (k0, dk0, ddk0, k1, dk1, T_c, C, k3, dk3, ddk3),
    k0 = z0 + z1 u + z2 u^2, k1 = z3 + z4 u, k2 = -k1 (T_c + C u), k3 = z7 + z8 u + z9 u^2.
    Every k_i is a polynomial of degree <= 2 in the load, i.e. exactly one section of Eqs.
    4.4-4.5 (:func:`cc_to_quadratic`), so the plant and the inverse evaluate it as any SD-GPI.
    """
    z = np.asarray(z, dtype=float)
    u = np.atleast_1d(np.asarray(u, dtype=float))
    one, u2 = np.ones_like(u), u * u
    k1 = z[3] + z[4] * u
    centre = z[5] + z[6] * u
    k = np.stack([z[0] + z[1] * u + z[2] * u2, k1, -k1 * centre, z[7] + z[8] * u + z[9] * u2], axis=1)
    J = np.zeros((u.size, 4, N_CC))
    J[:, 0, 0], J[:, 0, 1], J[:, 0, 2] = one, u, u2
    J[:, 1, 3], J[:, 1, 4] = one, u
    J[:, 2, 3], J[:, 2, 4], J[:, 2, 5], J[:, 2, 6] = -centre, -u * centre, -k1, -k1 * u
    J[:, 3, 7], J[:, 3, 8], J[:, 3, 9] = one, u, u2
    return k, J


def _quadratic_through(m: FloatArray, k: FloatArray) -> FloatArray:
    """(Q, 3) coefficients (m^2, m, 1) of the parabolas through (m_i, k[i, q]), i = 0..2 (Newton's divided
    differences: elementwise, so the written file has the same bits on every CPU; np.polyfit goes through LAPACK)."""
    d1 = (k[1] - k[0]) / (m[1] - m[0])
    d2 = ((k[2] - k[1]) / (m[2] - m[1]) - d1) / (m[2] - m[0])
    # k0 + d1 (x - m0) + d2 (x - m0)(x - m1)
    return np.stack([d2, d1 - d2 * (m[0] + m[1]), k[0] - d1 * m[0] + d2 * m[0] * m[1]], axis=1)


def cc_to_quadratic(z: ArrayLike, m_ref: float) -> FloatArray:
    """(4, 3) quadratic-in-load coefficients (s_i0 m^2 + s_i1 m + s_i2, Eqs. 4.4-4.5) of a CC law.

    Exact: every coefficient of :func:`cc_coefficients` is a polynomial of degree <= 2 in m.
    """
    m = m_ref + np.array([-1.0, 0.0, 1.0])
    k, _ = cc_coefficients(z, m - m_ref)
    return _quadratic_through(m, k)


def _chain(Jk: FloatArray, dk: FloatArray) -> FloatArray:
    """Jk (N, 4) @ dk (4, M), summed in a fixed order (a BLAS product's order follows its CPU kernel)."""
    out = Jk[:, 0, None] * dk[0]
    for q in range(1, dk.shape[0]):
        out += Jk[:, q, None] * dk[q]
    return out


def _cc_from_per_load(G: FloatArray, u: FloatArray, w: FloatArray, amp_deg: int) -> FloatArray:
    """Start of one envelope set's CC law: weighted polynomials through per-load fits (L, 4)."""

    def poly(v: FloatArray, deg: int, n_terms: int) -> list[float]:
        c = list(polyfit(u, v, deg, w=w)[::-1])
        return c + [0.0] * (n_terms - len(c))

    centre = -G[:, 2] / G[:, 1]
    return np.array(poly(G[:, 0], amp_deg, 3) + poly(G[:, 1], 1, 2) + poly(centre, 1, 2) + poly(G[:, 3], amp_deg, 3))


#: Load sections of the file a saturating law is written to (piecewise quadratic, Eqs. 4.4-4.5).
SAT_SECTIONS = 16


def sat_coefficients(z: ArrayLike, m: ArrayLike, m_ref: float) -> tuple[FloatArray, FloatArray]:
    """Envelope coefficients (L, 4) and Jacobian (L, 4, 10) of the saturating stroke law at loads m [kgf].

    As :func:`cc_coefficients` (centre T_c + C u and slope linear in u = m - m_ref) but the
    amplitude and offset saturate with the load as the transformation strain does (Lagoudas'
    H_cur(sigma) = H_max (1 - exp(-k sigma))): with g = 1 - exp(-kappa m),
    z = (k0, dk0, kappa, k1, dk1, T_c, C, k3, dk3, k0_lin), k0 = z0 + z1 g + z9 u,
    k3 = z7 + z8 g (one kappa per envelope set; the linear amplitude term carries what does
    not saturate: without it NiTiHf's in-sample residual was 15 % instead of 1.6 %).
    """
    z = np.asarray(z, dtype=float)
    m = np.atleast_1d(np.asarray(m, dtype=float))
    zc = z.copy()
    zc[[0, 1, 2, 7, 8, 9]] = 0.0
    k, J = cc_coefficients(zc, m - m_ref)
    e = np.array([math.exp(-z[2] * v) for v in m])  # the C library's exp: numpy's rounds by CPU (trf.py)
    g = 1.0 - e
    k[:, 0] = z[0] + z[1] * g + z[9] * (m - m_ref)
    k[:, 3] = z[7] + z[8] * g
    J[:, 0, :3] = np.stack([np.ones_like(m), g, z[1] * m * e], axis=1)
    J[:, 0, 9] = m - m_ref
    J[:, 3, 7:] = np.stack([np.ones_like(m), g, np.zeros_like(m)], axis=1)
    J[:, 3, 2] = z[8] * m * e
    return k, J


def _sat_from_per_load(G: FloatArray, m: FloatArray, u: FloatArray, w: FloatArray) -> FloatArray:
    """Start of one set's saturating law: kappa on a grid, amplitude/offset by weighted least squares
    (the linear amplitude term starts at 0)."""
    best: tuple[float, FloatArray] | None = None
    scale = 1.0 / max(float(np.max(m)), 1e-6)
    for kappa in scale * np.geomspace(0.5, 64.0, 15):
        # the C library's exp, fixed-order least squares and an exact sum: the same start on every CPU (trf.py)
        A = np.stack([np.ones_like(m), 1.0 - np.array([math.exp(-kappa * v) for v in m])], axis=1) * w[:, None]
        c0 = lstsq(A, G[:, 0] * w)
        c3 = lstsq(A, G[:, 3] * w)
        sse = math.fsum(
            np.r_[
                (A[:, 0] * c0[0] + A[:, 1] * c0[1] - G[:, 0] * w) ** 2,
                (A[:, 0] * c3[0] + A[:, 1] * c3[1] - G[:, 3] * w) ** 2,
            ]
        )
        if best is None or sse < best[0]:
            best = (sse, np.r_[c0, kappa, 0.0, 0.0, 0.0, 0.0, c3, 0.0])
    assert best is not None
    z = best[1]
    z[3:7] = _cc_from_per_load(G, u, w, 1)[3:7]
    return z


def sat_to_sections(z: ArrayLike, m_ref: float, edges: FloatArray) -> FloatArray:
    """(K, 4, 3) quadratics per section (Eqs. 4.4-4.5) through the saturating law at each section's ends and middle."""
    out = np.empty((edges.size - 1, 4, 3))
    for k in range(edges.size - 1):
        m3 = np.array([edges[k], 0.5 * (edges[k] + edges[k + 1]), edges[k + 1]])
        out[k] = _quadratic_through(m3, sat_coefficients(z, m3, m_ref)[0])
    return out


def fit_sdgpi_cc(
    T: ArrayLike,
    y: ArrayLike,
    loads_kgf: ArrayLike,
    *,
    n: int = 15,
    k_f: float = 6.0,
    p0: float = 1.0,
    max_nfev: int = 200,
    branches: list[str] | None = None,
    amplitude_degree: int = 1,
    amplitude_law: str = 'polynomial',
) -> FitResult:
    """SD-GPI whose load dependence is the Clausius-Clapeyron law of :func:`cc_coefficients`.

    Against the seed's free quadratics per section (Eqs. 4.4-4.5, :func:`fit_sdgpi`): the tanh
    centres move linearly with the load (a shift of the transformation temperatures, a
    physical law that stays sane between and beyond the fitted loads), slopes linearly,
    amplitudes and offsets with ``amplitude_degree`` (1 or 2); one section over all loads.
    Shared sets from the middle load's GPI as in :func:`fit_sdgpi`; two starts: polynomials
    through per-load envelope fits (continued in load, weighted by each loop's stroke: a loop
    that hardly transforms says little about its centre), and the middle load's envelopes
    shifted along those fits' centre line; joint bounded least squares with the exact
    Jacobian from both, the lower cost kept. The result is an ordinary one-section SD-GPI (``theta`` in the layout of
    :func:`sdgpi_gpi_vectors` with edges [min, max] load).
    ``amplitude_law='saturating'``: amplitudes and offsets follow :func:`sat_coefficients`
    instead (``amplitude_degree`` ignored); written as :data:`SAT_SECTIONS` quadratic sections
    (:func:`sat_to_sections`), and every error is computed on that written form.
    """
    loads = np.asarray(loads_kgf, dtype=float)
    Ts_all, ys_all = _columns(T, y, loads.size)
    if amplitude_degree not in (1, 2):
        raise ParameterError(f'amplitude_degree must be 1 or 2, got {amplitude_degree}')
    if amplitude_law not in ('polynomial', 'saturating'):
        raise ParameterError(f"amplitude_law must be 'polynomial' or 'saturating', got {amplitude_law!r}")
    sat = amplitude_law == 'saturating'
    if np.unique(loads).size < 3:
        raise ParameterError('the Clausius-Clapeyron SD-GPI needs >= 3 loads')
    br = list(branches) if branches is not None else ['cooling'] * loads.size
    keep = [thin_indices(t) for t in Ts_all]
    Ts, ys = [t[k] for t, k in zip(Ts_all, keep)], [v[k] for v, k in zip(ys_all, keep)]
    order = np.argsort(loads, kind='stable')  # repeated loads: the same order on every CPU
    i_mid = int(order[loads.size // 2])
    mid = loads.size // 2
    m_ref = float(np.mean(loads))
    u = loads - m_ref
    base = fit_gpi(Ts[i_mid], ys[i_mid], n=n, k_f=k_f, p0=p0, n_starts=1, max_nfev=max_nfev, branch=br[i_mid]).theta
    lo1, hi1 = _bounds(float(np.ptp(np.concatenate(ys))))
    stroke = np.array([np.ptp(v) for v in ys])
    # Per-load amplitudes and offsets trade off (a tanh seen on one tail only: a0 ~ a3 ~ 80 at
    # one load, 0.3 at the next), their centres do not: start from the per-load fits' polynomials
    # and from the middle load's envelopes moved along the per-load centres' straight line.
    G = _per_load_envelopes(Ts, ys, br, base, order, mid, True, n, k_f, lo1, hi1, max_nfev, 'exact')
    law_start = (
        (lambda Gs: _sat_from_per_load(Gs, loads, u, stroke))
        if sat
        else (lambda Gs: _cc_from_per_load(Gs, u, stroke, amplitude_degree))
    )
    starts = [np.concatenate([law_start(G[:, IDX_A]), law_start(G[:, IDX_B]), base[8:20]])]
    shifted = []
    for sl in (IDX_A, IDX_B):
        z = law_start(np.broadcast_to(base[sl], G[:, sl].shape).copy())
        if sat:  # constant envelopes: no saturation to see; keep a moderate kappa
            z[2] = 4.0 / max(float(loads.max()), 1e-6)
        z[5:7] = _cc_from_per_load(G[:, sl], u, stroke, 1)[5:7]
        z[5] = -base[sl][2] / base[sl][1] - z[6] * u[i_mid]  # through the middle load's own centre
        shifted.append(z)
    starts.append(np.concatenate(shifted + [base[8:20]]))
    P = 2 * N_CC + 12
    lo, hi = np.full(P, -1e6), np.full(P, 1e6)
    lo[2 * N_CC + 8 : 2 * N_CC + 11] = [1e-4, 0.0, 1e-4]
    hi[2 * N_CC + 8 : 2 * N_CC + 11] = [1e2, 2e2, 5.0]
    fixed = [P - 1]  # p0
    if sat:
        lo[[2, N_CC + 2]], hi[[2, N_CC + 2]] = 1e-3, 1e3  # kappa > 0 [1/kgf]
    elif amplitude_degree == 1:
        fixed += [k * N_CC + q for k in (0, 1) for q in CC_QUADRATIC]
    free = np.setdiff1d(np.arange(P), fixed)
    offsets = np.cumsum([0] + [t.size for t in Ts])
    heats = [heating_mask(t, b) for t, b in zip(Ts, br)]
    za, zb, rest = slice(0, N_CC), slice(N_CC, 2 * N_CC), slice(2 * N_CC, P)

    def coefficients(z: FloatArray) -> tuple[FloatArray, FloatArray]:
        return sat_coefficients(z, loads, m_ref) if sat else cc_coefficients(z, u)

    def fun_jac(x: FloatArray) -> tuple[FloatArray, FloatArray]:
        ka, Ja = coefficients(x[za])
        kb, Jb = coefficients(x[zb])
        res = np.empty(offsets[-1])
        J = np.zeros((offsets[-1], P))
        for i in range(loads.size):
            rows = slice(offsets[i], offsets[i + 1])
            th = np.concatenate([ka[i], kb[i], x[rest]])
            yi, Ji = simulate_jac(Ts[i], th, n=n, k_f=k_f, branch=br[i], heat=heats[i])
            res[rows] = yi - ys[i]
            J[rows, za] = _chain(Ji[:, IDX_A], Ja[i])
            J[rows, zb] = _chain(Ji[:, IDX_B], Jb[i])
            J[rows, rest] = Ji[:, 8:20]
        return res, J

    x, cost, ok = _solve_best(fun_jac, starts, free, lo, hi, 2 * max_nfev)
    if sat:
        edges = np.linspace(loads.min(), loads.max(), SAT_SECTIONS + 1)
        sa, sb = sat_to_sections(x[za], m_ref, edges), sat_to_sections(x[zb], m_ref, edges)
    else:
        edges = np.array([loads.min(), loads.max()])
        sa, sb = cc_to_quadratic(x[za], m_ref)[None], cc_to_quadratic(x[zb], m_ref)[None]
    theta = np.concatenate([sa.ravel(), sb.ravel(), x[rest]])
    th = _sd_to_gpi(theta[None], edges, loads)[0]
    resid = np.concatenate(
        [
            simulate_batch(t, th[i][None], n=n, k_f=k_f, branch=br[i])[:, 0] - v
            for i, (t, v) in enumerate(zip(Ts_all, ys_all))
        ]
    )
    sd = float(np.std(resid))
    tail = x[rest]
    params = SDGPIParams(
        EnvelopeSections(edges, sa, sb),
        tail[0:4],
        tail[4:8],
        float(tail[8]),
        float(tail[9]),
        float(tail[10]),
        n=n,
        p0=float(tail[11]),
        k_f=k_f,
        name='fitted SD-GPI (Clausius-Clapeyron load law' + (', saturating stroke)' if sat else ')'),
    )
    mean_range = float(np.mean([np.ptp(v) for v in ys_all]))
    return FitResult(params, sd, 100 * sd / max(mean_range, 1e-12), cost, 1, ok, theta)
