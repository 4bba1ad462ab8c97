"""Fitting and held-out scoring of catalogue candidates (scipy least_squares, bounded).

Channels (replays): ``thermal`` commands -> temperatures (both muscles), ``mechanics``
measured temperatures + payload -> angle, ``chain`` commands -> angle (used as the angle
channel only when temperatures are missing). Each channel's residual is scaled by its
nominal training SSE, so a fit weighs the channels' *relative* improvements equally.

Split: samples after a 5 s burn-in up to 60 % of the run train; the rest is held out in
``N_SEGMENTS`` contiguous segments (bootstrap). Held-out score of a candidate::

    L = sum_channels log(SSE_test,candidate / SSE_test,nominal) + LAMBDA * n_params

(lower is better; nominal has L = 0).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from sma_wrist.diagnose import effects as fx

TRAIN_FRACTION = 0.6
BURN_IN_S = 5.0
N_SEGMENTS = 10
LAMBDA = 0.01  # held-out log-SSE penalty per fitted parameter
MAX_FIT_SAMPLES = 12000  # residual samples per channel in a fit (evenly subsampled)

THERMAL_EFFECT_PARAMS = {'tem_gain_err', 'loss_scale_err', 'joule_scale_err', 'ambient_offset_C',
                         'ambient_drift_C_per_h', 'coupling_per_s'}
TEMP_SENSOR_PARAMS = {'temp_offset_C', 'temp_lag_s'}


def channels_of(effect: fx.Effect, available: list[str]) -> list[str]:
    """Channels a candidate changes (among the available ones)."""
    ps = set(effect.params)
    out = []
    if 'thermal' in available and ps & (THERMAL_EFFECT_PARAMS | TEMP_SENSOR_PARAMS):
        out.append('thermal')
    if 'mechanics' in available and (ps - THERMAL_EFFECT_PARAMS):
        out.append('mechanics')
    if 'chain' in available and (ps - TEMP_SENSOR_PARAMS):
        out.append('chain')
    return out


def noise_sigma(x: np.ndarray, lsb: float = 0.0) -> float:
    """White-noise std of a smooth signal from its second differences (robust, MAD)."""
    d2 = np.diff(x, 2, axis=0).ravel()
    if d2.size < 10:
        return float(np.std(x)) or 1.0
    mad = np.median(np.abs(d2 - np.median(d2))) * 1.4826
    return float(max(mad / np.sqrt(6.0), lsb / np.sqrt(12.0), 1e-9))


@dataclass
class Fit:
    effect: fx.Effect
    row: np.ndarray  # full parameter vector
    score: float = 0.0  # held-out L
    log_ratio: dict[str, float] = field(default_factory=dict)
    sse_test: dict[str, np.ndarray] = field(default_factory=dict)  # per segment
    train_cost: float = 0.0
    nfev: int = 0
    success: bool = True
    message: str = ''

    def values(self) -> dict[str, float]:
        return {k: float(self.row[fx.INDEX[k]]) for k in self.effect.params}


class Evaluator:
    """Predictions, residuals and held-out statistics of one run."""

    def __init__(self, model: fx.ExtendedModel) -> None:
        self.model = model
        run = model.run
        self.run = run
        ch = []
        if run.u is not None and run.T is not None:
            ch.append('thermal')
        if run.T is not None and run.q is not None:
            ch.append('mechanics')
        if run.u is not None and run.q is not None and run.T is None:
            ch.append('chain')
        self.channels = ch
        K = run.n
        self.i0 = min(int(BURN_IN_S / run.dt), K // 10)
        self.i_train = int(TRAIN_FRACTION * K)
        self.seg_edges = np.linspace(self.i_train, K, N_SEGMENTS + 1).astype(int)
        self.sigma = {}
        if run.T is not None:
            self.sigma['thermal'] = noise_sigma(run.T, 200.0 / 2 ** 16)
        if run.q is not None:
            self.sigma['mechanics'] = self.sigma['chain'] = noise_sigma(run.q, 2 * np.pi / 2 ** 16)
        self.nominal = fx.NOMINAL.copy()
        ntr = self.i_train - self.i0
        self.sub = max(1, ntr // MAX_FIT_SAMPLES)
        self.pred_nom = self.predict(self.nominal[None])
        self.w = {}
        for c in ch:
            r = self.residual(c, self.pred_nom[c][:, 0])[self.i0:self.i_train:self.sub]
            self.w[c] = 1.0 / np.sqrt(max(float(np.sum(r ** 2)), 1e-30))
        self.sse_nom = {c: self.segment_sse(c, self.pred_nom[c][:, 0]) for c in ch}

    # -- predictions -----------------------------------------------------------------
    def predict(self, rows: np.ndarray, channels: list[str] | None = None, upto: int | None = None
                ) -> dict[str, np.ndarray]:
        out = {}
        for c in channels or self.channels:
            if c == 'thermal':
                out[c] = self.model.thermal_measured(rows, upto)
            elif c == 'mechanics':
                out[c] = self.model.angle_measured(rows, upto, 'measured')
            else:
                out[c] = self.model.angle_measured(rows, upto, 'chain')
        return out

    def measured(self, c: str) -> np.ndarray:
        return self.run.T if c == 'thermal' else self.run.q

    def residual(self, c: str, pred: np.ndarray) -> np.ndarray:
        meas = self.measured(c)
        return meas[: pred.shape[0]] - pred

    def segment_sse(self, c: str, pred: np.ndarray) -> np.ndarray:
        r = self.residual(c, pred)
        r2 = r ** 2 if r.ndim == 1 else (r ** 2).sum(axis=1)
        e = self.seg_edges
        return np.array([r2[a:b].sum() for a, b in zip(e[:-1], e[1:])])

    # -- fitting -------------------------------------------------------------------------
    def _train_residuals(self, rows: np.ndarray, chans: list[str]) -> np.ndarray:
        """(N, M) stacked weighted training residuals for parameter rows."""
        pred = self.predict(rows, chans, upto=self.i_train)
        blocks = []
        for c in chans:
            meas = self.measured(c)[self.i0:self.i_train:self.sub]
            p = pred[c][self.i0:self.i_train:self.sub]
            r = (meas[:, None] - p) if p.ndim == 2 else (meas[:, None, :] - p).transpose(0, 2, 1).reshape(meas.shape[0] * 2, -1)
            blocks.append(self.w[c] * r)
        return np.concatenate(blocks, axis=0).T

    def fit(self, effect: fx.Effect, max_nfev: int = 12) -> Fit:
        chans = channels_of(effect, self.channels)
        idx = [fx.INDEX[k] for k in effect.params]
        lo, hi, typ = fx.LOWER[idx], fx.UPPER[idx], fx.TYPICAL[idx]
        base = self.nominal.copy()
        nfev = 0

        def rows_for(X: np.ndarray) -> np.ndarray:
            R = np.repeat(base[None], X.shape[0], axis=0)
            R[:, idx] = X
            return R

        # start: the best of a coarse grid along each parameter (one batched replay)
        x0 = base[idx].copy()
        grid = [x0]
        for i in range(len(idx)):
            for s in (-4, -2, -1, -0.5, 0.5, 1, 2, 4):
                x = x0.copy()
                x[i] = np.clip(x0[i] + s * typ[i], lo[i], hi[i])
                grid.append(x)
        G = np.unique(np.array(grid), axis=0)
        R = self._train_residuals(rows_for(G), chans)
        nfev += G.shape[0]
        x_start = G[int(np.argmin((R ** 2).sum(axis=1)))]
        cache: dict[bytes, np.ndarray] = {}

        def fun(x: np.ndarray) -> np.ndarray:
            nonlocal nfev
            key = np.round(x, 12).tobytes()
            if key not in cache:
                cache[key] = self._train_residuals(rows_for(x[None]), chans)[0]
                nfev += 1
            return cache[key]

        def jac(x: np.ndarray) -> np.ndarray:
            nonlocal nfev
            h = 0.03 * typ
            X = [x]
            for i in range(len(idx)):
                xi = x.copy()
                xi[i] = x[i] + h[i] if x[i] + h[i] <= hi[i] else x[i] - h[i]
                X.append(xi)
            X = np.array(X)
            Rb = self._train_residuals(rows_for(X), chans)
            nfev += X.shape[0]
            cache[np.round(x, 12).tobytes()] = Rb[0]
            return np.stack([(Rb[i + 1] - Rb[0]) / (X[i + 1, i] - x[i]) for i in range(len(idx))], axis=1)

        x_start = np.clip(x_start, lo + 1e-12, hi - 1e-12)
        try:
            res = least_squares(fun, x_start, jac=jac, bounds=(lo, hi), x_scale=typ, max_nfev=max_nfev,
                                xtol=1e-4, ftol=1e-5, method='trf')
            x, ok, msg, cost = res.x, bool(res.success), str(res.message), float(res.cost)
        except Exception as exc:  # noqa: BLE001 - a failed fit is a result, not a crash
            x, ok, msg, cost = x_start, False, f'{type(exc).__name__}: {exc}', float('nan')
        f = Fit(effect, rows_for(x[None])[0], train_cost=cost, nfev=nfev, success=ok, message=msg)
        return self.score(f)

    def score(self, f: Fit) -> Fit:
        pred = self.predict(f.row[None])
        L = 0.0
        for c in self.channels:
            s = self.segment_sse(c, pred[c][:, 0])
            f.sse_test[c] = s
            lr = float(np.log(max(s.sum(), 1e-300) / max(self.sse_nom[c].sum(), 1e-300)))
            f.log_ratio[c] = lr
            L += lr
        f.score = L + LAMBDA * len(f.effect.params)
        return f

    # -- statistics -----------------------------------------------------------------------
    def gain(self, f: Fit, c: str, n_boot: int = 1000, seed: int = 0) -> dict[str, float]:
        """Held-out RMS before/after on channel c, gain %, and its bootstrap over segments."""
        a, b = self.sse_nom[c], f.sse_test[c]
        n = (self.run.n - self.i_train) * (2 if c == 'thermal' else 1)
        before, after = float(np.sqrt(a.sum() / n)), float(np.sqrt(b.sum() / n))
        rng = np.random.default_rng(seed)
        idx = rng.integers(0, a.size, (n_boot, a.size))
        g = 100.0 * (1.0 - np.sqrt(b[idx].sum(axis=1) / np.maximum(a[idx].sum(axis=1), 1e-300)))
        return {'rmse_before': before, 'rmse_after': after, 'gain_pct': 100.0 * (1.0 - after / before) if before else 0.0,
                'gain_pct_p05': float(np.percentile(g, 5)), 'gain_pct_p95': float(np.percentile(g, 95)),
                'gain_pct_std': float(np.std(g))}
