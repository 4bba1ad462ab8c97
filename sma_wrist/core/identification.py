"""Identification of GPI / SD-GPI parameters from measured loops (seed Secs. 4.1.1, 4.2.2, Eq. 3.25).

:func:`fit_gpi` fits one load: a, b, c, d sets (Eqs. 3.21-3.22), rho, tau (Eq. 3.23), c
(Eq. 3.24), optionally p0 (Eq. 4.1), to (T, elongation) samples by bounded least squares of
Eq. 3.25, staged as in Sec. 4.1.1 (envelopes + density with the memoryless part held, then the
memoryless part alone, then everything), from several starts built from the tanh saturation
levels and 50 % temperatures of the data. :func:`fit_sdgpi` fits the SD-GPI (Eqs. 4.4-4.6):
quadratics of the load per section for a_i, b_i, shared c, d, rho, tau, c, starting from
quadratic fits of per-load GPI fits (Sec. 4.2.2).

The model is simulated by :func:`simulate_batch`, the play recursion vectorised over many
parameter sets at once, so a finite-difference Jacobian costs one batched simulation.
Conventions are those of :mod:`sma_wrist.core.hysteresis` (b set = gamma_l followed while
heating; elongation y = k_f - y_m).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import least_squares

from sma_wrist.core.errors import ModelInputError, ParameterError, check_finite
from sma_wrist.core.hysteresis import EnvelopeSections, SDGPIParams

FloatArray = NDArray[np.float64]

N_SET = 4  # coefficients per tanh set
#: Parameter layout of one GPI vector: a(4) b(4) c(4) d(4) rho tau c_thr p0.
IDX_A, IDX_B, IDX_C, IDX_D = slice(0, 4), slice(4, 8), slice(8, 12), slice(12, 16)
IDX_RHO, IDX_TAU, IDX_CTHR, IDX_P0 = 16, 17, 18, 19
N_GPI = 20


def _tanh(k: FloatArray, T: FloatArray) -> FloatArray:
    return k[..., 0] * np.tanh(k[..., 1] * T + k[..., 2]) + k[..., 3]


def simulate_batch(T: ArrayLike, theta: ArrayLike, *, n: int = 15, k_f: float = 6.0,
                   branch: str = 'cooling') -> FloatArray:
    """Elongation (N, B) for B GPI parameter vectors ``theta`` (B, 20) (layout IDX_*).

    Same recursion as :func:`sma_wrist.core.hysteresis.simulate` (Eqs. 3.19-3.24, 4.1, 4.2):
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


def gpi_vector(params: SDGPIParams, load_kgf: float) -> FloatArray:
    """The layout-IDX_* vector of an SD-GPI frozen at one load."""
    a, b = params.envelopes.coefficients(np.array(load_kgf))
    return np.concatenate([a, b, params.c, params.d, [params.rho, params.tau, params.c_thr, params.p0]])


def vector_to_params(theta: ArrayLike, *, n: int = 15, k_f: float = 6.0, name: str = 'fitted GPI') -> SDGPIParams:
    th = np.asarray(theta, dtype=float)
    return SDGPIParams.from_gpi(th[IDX_A], th[IDX_B], th[IDX_C], th[IDX_D], th[IDX_RHO], th[IDX_TAU], th[IDX_CTHR],
                                n=n, p0=float(th[IDX_P0]), k_f=k_f, name=name)


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


def _crossing_T(T: FloatArray, y: FloatArray, rising: bool) -> float:
    """Mean temperature where y crosses its mid level on rising (or falling) T samples."""
    dT = np.diff(T, prepend=T[0])
    sel = dT > 0 if rising else dT < 0
    if sel.sum() < 3:
        return float(np.mean(T))
    Ts, ys = T[sel], y[sel]
    mid = 0.5 * (ys.min() + ys.max())
    order = np.argsort(Ts)
    Ts, ys = Ts[order], ys[order]
    idx = np.nonzero(np.diff(np.sign(ys - mid)) != 0)[0]
    return float(Ts[idx].mean()) if idx.size else float(np.median(Ts))


def initial_guesses(T: FloatArray, y: FloatArray, *, n: int, k_f: float, p0: float, n_starts: int,
                    seed: int = 0) -> list[FloatArray]:
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
        k = (0.15, 0.4, 0.08, 0.25)[s % 4] * (1.0 if s < 4 else np.exp(rng.normal(0, 0.3)))
        rho, tau, c = (1.0, 1.0, 0.05) if s % 2 == 0 else (0.5, 5.0, 0.1)
        r = c * np.arange(1, n + 1)
        P = float(np.sum(rho * np.exp(-tau * r)))
        th_c = T_c + (0 if s < 4 else rng.normal(0, 3))
        th_h = T_h + (0 if s < 4 else rng.normal(0, 3))
        amp = max(hi - lo, 1e-3) / (2 * P) + r.mean()  # widen by the mean threshold so saturated ends match
        off = 0.5 * (hi + lo) / P
        a = [amp, k, -k * th_c, off]
        b = [amp, k, -k * th_h, off]
        mem = [1e-3 * (hi - lo), 0.05, -0.05 * float(np.mean(T)), 0.0]
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


def _solve(fun_batch, x0: FloatArray, free: NDArray[np.intp], lo: FloatArray, hi: FloatArray,
           max_nfev: int) -> tuple[FloatArray, float, bool]:
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
    res = least_squares(f, z0, jac=j, bounds=(lo[free], hi[free]), x_scale='jac', max_nfev=max_nfev,
                        xtol=1e-10, ftol=1e-10, gtol=1e-10)
    x[free] = res.x
    return x, float(res.cost), bool(res.status >= 0 and np.isfinite(res.cost))  # 0: budget used, still a valid fit


def fit_gpi(T: ArrayLike, y: ArrayLike, *, n: int = 15, k_f: float = 6.0, p0: float | None = 1.0,
            n_starts: int = 4, max_nfev: int = 60, seed: int = 0, branch: str = 'cooling') -> FitResult:
    """Fit a GPI at one load to a measured loop (T [degC], elongation y [mm]), Sec. 4.1.1.

    ``p0=None`` fits p0 too (it trades off against the c, d amplitudes; the seed never prints
    it). The staged fit runs from each start; the lowest final cost wins.
    """
    T = np.asarray(T, dtype=float)
    y = np.asarray(y, dtype=float)
    check_finite('identification T', T, 'degC')
    check_finite('identification y', y, 'mm')
    if T.shape != y.shape or T.ndim != 1 or T.size < 20:
        raise ModelInputError('identification samples', T.shape, '(N,) with N >= 20 and y of the same shape')
    rng_y = float(np.ptp(y))
    lo, hi = _bounds(rng_y)

    def fun_batch(X: FloatArray) -> FloatArray:
        return simulate_batch(T, X, n=n, k_f=k_f, branch=branch) - y[:, None]

    env_dens = np.r_[0:8, IDX_RHO, IDX_TAU, IDX_CTHR]
    mem = np.r_[8:16] if p0 is None else np.r_[8:16]
    every = np.r_[0:19] if p0 is not None else np.r_[0:20]
    best: tuple[float, FloatArray, bool] | None = None
    for x0 in initial_guesses(T, y, n=n, k_f=k_f, p0=1.0 if p0 is None else p0, n_starts=n_starts, seed=seed):
        x, _, _ = _solve(fun_batch, x0, env_dens, lo, hi, max_nfev)  # stage 1: memory part
        x, _, _ = _solve(fun_batch, x, mem, lo, hi, max_nfev)  # stage 2: memoryless part
        x, cost, ok = _solve(fun_batch, x, every, lo, hi, 2 * max_nfev)  # stage 3: all
        if best is None or cost < best[0]:
            best = (cost, x, ok)
    assert best is not None
    cost, x, ok = best
    resid = fun_batch(x[None])[:, 0]
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


def fit_sdgpi(T: ArrayLike, y: ArrayLike, loads_kgf: ArrayLike, edges_kgf: ArrayLike, *, n: int = 15,
              k_f: float = 6.0, p0: float = 1.0, max_nfev: int = 200, per_load_starts: int = 1) -> FitResult:
    """Fit an SD-GPI (Eqs. 4.4-4.6) to loops at several loads, Sec. 4.2.2.

    ``T``, ``y``: (N, L) samples, one column per load. Starting point: a GPI per load
    (:func:`fit_gpi`), a_i and b_i fitted by quadratics per section, shared sets averaged; then
    all quadratics and shared parameters jointly. Residual statistics pool all loads; the %
    is relative to the mean per-load range.
    """
    T = np.asarray(T, dtype=float)
    y = np.asarray(y, dtype=float)
    loads = np.asarray(loads_kgf, dtype=float)
    edges = np.asarray(edges_kgf, dtype=float)
    if T.shape != y.shape or T.ndim != 2 or T.shape[1] != loads.size:
        raise ModelInputError('SD-GPI identification samples', T.shape, f'(N, {loads.size}) for T and y')
    n_sec = edges.size - 1
    sec = np.clip(np.searchsorted(edges, loads, side='right') - 1, 0, n_sec - 1)
    for k in range(n_sec):
        if np.unique(loads[sec == k]).size < 3:
            raise ParameterError(f'section {k} ({edges[k]}-{edges[k + 1]} kgf) needs >= 3 loads for a quadratic')
    # Shared c, d, rho, tau, c from a full GPI fit at the middle load, then only the envelopes per
    # load (so a_i, b_i of different loads are comparable: the rho-amplitude trade-off is fixed).
    i_mid = int(np.argsort(loads)[loads.size // 2])
    base = fit_gpi(T[:, i_mid], y[:, i_mid], n=n, k_f=k_f, p0=p0, n_starts=per_load_starts, max_nfev=max_nfev).theta
    lo1, hi1 = _bounds(float(np.ptp(y)))
    G = np.empty((loads.size, N_GPI))
    for i in range(loads.size):
        yi, Ti = y[:, i], T[:, i]
        fb = lambda X, Ti=Ti, yi=yi: simulate_batch(Ti, X, n=n, k_f=k_f) - yi[:, None]  # noqa: E731
        G[i], _, _ = _solve(fb, base, np.r_[0:8], lo1, hi1, max_nfev)
    sa = np.zeros((n_sec, 4, 3))
    sb = np.zeros((n_sec, 4, 3))
    for k in range(n_sec):
        sel = sec == k
        for i in range(4):
            sa[k, i] = np.polyfit(loads[sel], G[sel, i], 2)
            sb[k, i] = np.polyfit(loads[sel], G[sel, 4 + i], 2)
    best_single = base
    x0 = np.concatenate([sa.ravel(), sb.ravel(), best_single[8:20]])
    P = x0.size
    mask_free = np.ones(P, bool)
    mask_free[-1] = False  # p0 fixed
    big = 1e6
    lo = np.full(P, -big)
    hi = np.full(P, big)
    _, _, rest = _sd_layout(n_sec)
    r0 = rest.start
    lo[r0 + 8:r0 + 11] = [1e-4, 0.0, 1e-4]
    hi[r0 + 8:r0 + 11] = [1e2, 2e2, 5.0]
    free = np.nonzero(mask_free)[0]

    def fun_batch(X: FloatArray) -> FloatArray:
        th = _sd_to_gpi(X, edges, loads)  # (B, L, 20)
        B = X.shape[0]
        out = np.empty((T.shape[0] * loads.size, B))
        for i in range(loads.size):
            out[i * T.shape[0]:(i + 1) * T.shape[0]] = simulate_batch(T[:, i], th[:, i], n=n, k_f=k_f) - y[:, i, None]
        return out

    x, cost, ok = _solve(fun_batch, x0, free, lo, hi, max_nfev)
    resid = fun_batch(x[None])[:, 0]
    sd = float(np.std(resid))
    mean_range = float(np.mean(np.ptp(y, axis=0)))
    sa_sl, sb_sl, rest = _sd_layout(n_sec)
    env = EnvelopeSections(edges, x[sa_sl].reshape(n_sec, 4, 3), x[sb_sl].reshape(n_sec, 4, 3))
    tail = x[rest]
    params = SDGPIParams(env, tail[0:4], tail[4:8], float(tail[8]), float(tail[9]), float(tail[10]), n=n,
                         p0=float(tail[11]), k_f=k_f, name='fitted SD-GPI')
    return FitResult(params, sd, 100 * sd / max(mean_range, 1e-12), cost, per_load_starts, ok, x)
