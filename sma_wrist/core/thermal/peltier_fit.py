"""Identification of the Peltier heat-balance form (Eqs. P.1-P.3, :mod:`sma_wrist.core.thermal.peltier`) per layer.

The same data and the same error as Table 4.9's fit (:mod:`sma_wrist.core.thermal.identification`): measured runs
(:class:`~sma_wrist.core.thermal.identification.ThermalRecord`, the drive's interval means and mean squares, each
run's ``layer``), simulation error of the free-run prediction from the measured start, every run-face weighted
alike, Table 4.10's statistics. Here:

* **per layer**: each TEM's module gets its own vector, fitted on that TEM's runs (the runs' ``layer``); a layer
  without runs keeps the base's. Per-layer parameters take the place of Table 4.9's per-TEM drive gain (a gain
  would trade with S and the capacities, peltier's module docstring).
* **free parameters**: S, K, C_m, C_x, h_m, h_x on a log scale (all positive), T_amb and T_cool in degC, or, given
  the measured rest faces ``rest_C``, T_amb and T_cool tied to them (:func:`sma_wrist.core.thermal.peltier.ambients_for_rest`; minutes of
  data do not tell a small loss from a far ambient). R is fixed at the base's (the form's one unidentifiable scale).
* **solver**: scipy's ``least_squares`` (trf, bounds), Jacobian by forward differences on the log scale, all its
  simulations one call of the compiled kernel (:func:`sma_wrist.core.thermal.kernel.peltier_simulate_runs`).
* **sensor lag** (``sensor_lag_s``, fixed, not fitted): the muscle thermocouple's first-order lag
  (:func:`sma_wrist.core.thermal.identification.muscle_lagged`, scipy's compiled recursive filter over all the
  kernel's parameter rows at once): the muscle node is fitted as the thermocouple reads it, so a model that lags
  its node by the same ``temp_lag_s`` predicts the measurement (fitted to the lagged reading directly, the node
  would carry the lag twice).
* **latent heat** (``fractions``, optional): each run's martensite fraction of its muscle's wire at its samples, the
  input of the wires' latent heat (Eq. P.4); given, each fitted layer's ``latent_C`` is free too (linear, in
  [0, :data:`~sma_wrist.core.thermal.peltier.LATENT_MAX_C`]), the fraction's steps added to the muscle node after each
  step of the simulation (the compiled kernel's forcing). The fractions are an input, not simulated: a wire model's
  replay on the measured temperatures (:func:`sma_wrist.commission.refine.refine_heat_balance`).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from sma_wrist.core.thermal import identification as ti
from sma_wrist.core.thermal import kernel as tk
from sma_wrist.core.thermal import peltier as pe

FloatArray = NDArray[np.float64]

#: fitted entries of a layer's vector (indices into peltier.LAYER_KEYS): log-scaled, then the ambients (degC)
LOG_IDX = (0, 2, 3, 4, 5, 6)
AMBIENT_IDX = (7, 8)
#: the fitted entries' names (all but the resistance, the form's fixed scale)
FITTED_KEYS = tuple(pe.LAYER_KEYS[i] for i in LOG_IDX + AMBIENT_IDX)
_LOG_LO = np.log([1e-3, 1e-3, 1.0, 1.0, 1e-3, 1e-3])
_LOG_HI = np.log([1.0, 20.0, 1e4, 1e5, 50.0, 500.0])
_AMB_LO, _AMB_HI = -20.0, 120.0
_FD_STEP = 1e-6


def fraction_steps(records: Sequence[ti.ThermalRecord], fractions: Sequence[FloatArray] | None) -> FloatArray:
    """(K, R) each run's martensite fraction change over each step (0 past its end, and everywhere without
    ``fractions``), the latent heat's forcing of the compiled kernel."""
    K = max(r.n for r in records)
    d = np.zeros((K, len(records)))
    if fractions is not None:
        if len(fractions) != len(records):
            raise ti.ThermalIdentificationError(f'{len(fractions)} martensite fractions for {len(records)} runs')
        for j, (r, xi) in enumerate(zip(records, fractions)):
            xi = np.asarray(xi, dtype=float)
            if xi.shape != (r.n,) or not np.all(np.isfinite(xi)):
                raise ti.ThermalIdentificationError(f'{r.name}: need a finite martensite fraction per sample')
            d[: r.n - 1, j] = np.diff(xi)
    return d


@dataclass
class PeltierFit:
    """Result of :func:`fit_peltier`."""

    params: pe.PeltierParams
    layers: tuple[int, ...]  # the layers fitted (others: the base's)
    rms_C: float  # in-sample RMS over run-faces [degC]
    nfev: int
    wall_s: float
    at_bounds: tuple[str, ...] = ()
    rest_C: tuple[float, float] | None = None
    sensor_lag_s: float = 0.0  # the muscle thermocouple's lag [s] the fit read the muscle node through


def simulate_records(
    params: pe.PeltierParams,
    records: Sequence[ti.ThermalRecord],
    base_rest: FloatArray | None = None,
    sensor_lag_s: float = 0.0,
    fractions: Sequence[FloatArray] | None = None,
) -> list[FloatArray]:
    """Free-run simulation (K_r, 2) [degC] of each record under its layer's vector, from its measured start (an
    unmeasured exchanger face from the muscle face and ``params``' rest offset, ti.start_states); the muscle face
    as a thermocouple of first-order lag ``sensor_lag_s`` [s] reads it (ti.muscle_lagged; 0: the node). With the
    runs' martensite ``fractions`` (module docstring) the layers' latent heat ``params.latent_C`` acts."""
    u, u2, _, _ = ti._pad(records)
    rest = pe.rest_state(params, 1, 2)[0, 0] if base_rest is None else base_rest
    T0 = ti.start_states(records, None, rest)
    coef = params.coef(2)[[r.layer for r in records]][None]
    latent = np.array([[params.latent_C[r.layer] if fractions is not None else 0.0 for r in records]])
    out = np.empty((u.shape[0], 1, len(records), 2))
    with np.errstate(all='ignore'):
        tk.peltier_simulate_runs(
            np.ascontiguousarray(coef),
            u,
            u2,
            np.ascontiguousarray(T0),
            records[0].dt,
            latent,
            fraction_steps(records, fractions),
            out,
        )
        out = ti.muscle_lagged(out, sensor_lag_s, records[0].dt)
    return [out[: r.n, 0, j] for j, r in enumerate(records)]


def evaluate(
    params: pe.PeltierParams,
    records: Sequence[ti.ThermalRecord],
    mode: str,
    masks: Sequence[FloatArray] | None = None,
    settle_s: float = 30.0,
    sensor_lag_s: float = 0.0,
    fractions: Sequence[FloatArray] | None = None,
) -> list[ti.RecordEvaluation]:
    """Table 4.10 statistics per run and measured face of the free-run prediction (as ti.evaluate), the muscle face
    as a thermocouple of lag ``sensor_lag_s`` [s] reads it; ``fractions``: as :func:`simulate_records`."""
    sims = simulate_records(params, records, sensor_lag_s=sensor_lag_s, fractions=fractions)
    out = []
    for j, r in enumerate(records):
        ev = r.valid.copy()
        ev[0] = False
        if ti.EXCHANGER not in r.faces:
            ev[: int(round(settle_s / r.dt))] = False
        if masks is not None:
            ev &= np.asarray(masks[j], bool)
        if not ev.any():
            raise ti.ThermalIdentificationError(f'{r.name}: no samples left to evaluate')
        faces = {
            ti.FACE_NAMES[f]: ti.error_statistics(r.T[:, f], sims[j][:, f], ev, span_C=float(np.ptp(r.T[r.valid, f])))
            for f in r.faces
        }
        out.append(ti.RecordEvaluation(r.name, r.frequency_Hz, mode, faces, sims[j], ev))
    return out


class _LayerProblem:
    """Residuals of one layer's runs as a function of its free vector (module docstring)."""

    def __init__(
        self,
        records: Sequence[ti.ThermalRecord],
        base: pe.PeltierLayer,
        masks: Sequence[FloatArray] | None,
        settle_s: float,
        rest_C: tuple[float, float] | None,
        sensor_lag_s: float = 0.0,
        fractions: Sequence[FloatArray] | None = None,
        latent_C: float = 0.0,
    ) -> None:
        self.records = records
        self.latent_free = fractions is not None
        self.latent_C = latent_C
        self.dxi = fraction_steps(records, fractions)
        self.lag = sensor_lag_s
        self.base = base.vector()
        self.rest_C = rest_C
        self.dt = records[0].dt
        self.u, self.u2, self.T, mask = ti._pad(records)
        if masks is not None:
            for j, (r, m) in enumerate(zip(records, masks)):
                mask[: r.n, j] &= np.asarray(m, bool)[:, None]
        for j, r in enumerate(records):
            if ti.EXCHANGER not in r.faces:
                mask[: int(round(settle_s / r.dt)), j] = False
        mask[0] = False
        if not mask.any():
            raise ti.ThermalIdentificationError('no training samples left (runs too short for the settle time?)')
        self.mask = mask
        self.w = ti._weights(mask)
        rest = pe.steady_state_coef(self.base, 0.0)
        self.T0 = np.ascontiguousarray(ti.start_states(records, None, rest))
        self.Tm = np.where(mask, self.T, 0.0)
        n = len(LOG_IDX) + (0 if rest_C is not None else 2)
        self.lo = np.r_[_LOG_LO, [_AMB_LO] * (n - 6), [0.0] * self.latent_free]
        self.hi = np.r_[_LOG_HI, [_AMB_HI] * (n - 6), [pe.LATENT_MAX_C] * self.latent_free]

    def vectors(self, x: FloatArray) -> FloatArray:
        """(P, N_LAYER) layer vectors of free rows x (P, n)."""
        v = np.tile(self.base, (x.shape[0], 1))
        v[:, LOG_IDX] = np.exp(x[:, : len(LOG_IDX)])
        if self.rest_C is None:
            v[:, AMBIENT_IDX] = x[:, len(LOG_IDX) : len(LOG_IDX) + 2]
        else:
            ta, tc = pe.ambients_for_rest(v, self.rest_C)
            v[:, 7], v[:, 8] = ta, tc
        return v

    def latent(self, x: FloatArray) -> FloatArray:
        """(P,) the latent heat [degC] of free rows x (P, n): the last entry where free, else the base's."""
        return x[:, -1] if self.latent_free else np.full(x.shape[0], self.latent_C)

    def free(self, layer: pe.PeltierLayer, latent_C: float = 0.0) -> FloatArray:
        v = layer.vector()
        x = np.log(v[list(LOG_IDX)])
        x = x if self.rest_C is not None else np.r_[x, v[list(AMBIENT_IDX)]]
        return np.r_[x, [latent_C] * self.latent_free]

    def residuals_many(self, x: FloatArray) -> FloatArray:
        """(P, M) weighted residuals of free rows x (P, n)."""
        x = np.atleast_2d(x)
        v = self.vectors(x)
        R = len(self.records)
        coef = np.ascontiguousarray(np.repeat(v[:, None, :], R, axis=1))
        latent = np.ascontiguousarray(np.repeat(self.latent(x)[:, None], R, axis=1))
        out = np.empty((self.u.shape[0], v.shape[0], R, 2))
        with np.errstate(all='ignore'):
            tk.peltier_simulate_runs(coef, self.u, self.u2, self.T0, self.dt, latent, self.dxi, out)
            out = ti.muscle_lagged(out, self.lag, self.dt)
            res = (out - self.Tm[:, None]) * self.w[None, None]
        r = np.moveaxis(res, 1, 0)[:, self.mask]
        return np.where(np.isfinite(r), r, 1e3)  # a run-away parameter set: a large, finite residual

    def residuals(self, x: FloatArray) -> FloatArray:
        return self.residuals_many(x[None])[0]

    def jacobian(self, x: FloatArray) -> FloatArray:
        n = x.size
        X = np.tile(x, (n + 1, 1))
        h = _FD_STEP * np.maximum(np.abs(x), 1.0)
        X[1 + np.arange(n), np.arange(n)] += h
        r = self.residuals_many(X)
        return ((r[1:] - r[0]) / h[:, None]).T


def fit_peltier(
    records: Sequence[ti.ThermalRecord],
    base: pe.PeltierParams | None = None,
    *,
    masks: Sequence[FloatArray] | None = None,
    settle_s: float = 30.0,
    rest_C: tuple[float, float] | None = None,
    max_nfev: int = 200,
    sensor_lag_s: float = 0.0,
    fractions: Sequence[FloatArray] | None = None,
) -> PeltierFit:
    """Fit each layer's Peltier vector (Eqs. P.1-P.3) to its runs by simulation-error least squares (module
    docstring). ``masks``: per-run training samples; ``rest_C``: the measured (muscle, exchanger) rest faces
    [degC] the ambients are tied to; ``sensor_lag_s``: the muscle thermocouple's known first-order lag [s] (the
    model's ``temp_lag_s``; module docstring); ``fractions``: each run's martensite fraction (K_r,), which frees each
    fitted layer's latent heat ``latent_C`` (Eq. P.4, from the base's). Raises ThermalIdentificationError when the
    data cannot support the fit."""
    from scipy.optimize import least_squares

    t0 = time.perf_counter()
    if not records:
        raise ti.ThermalIdentificationError('no runs to fit')
    for r in records:
        if float(np.ptp(r.u)) < 0.5:
            raise ti.ThermalIdentificationError(
                f'{r.name}: the drive voltage hardly changes (range {np.ptp(r.u):.3g} V); '
                'identification needs an exciting input'
            )
    if rest_C is not None and not all(math.isfinite(t) for t in rest_C):
        raise ti.ThermalIdentificationError(f'rest temperatures {rest_C!r} must be finite degC')
    if not (math.isfinite(sensor_lag_s) and sensor_lag_s >= 0):
        raise ti.ThermalIdentificationError(f'muscle thermocouple lag {sensor_lag_s!r} s must be >= 0')
    params = base or pe.PeltierParams()
    fitted = tuple(sorted({r.layer for r in records}))
    names = [pe.LAYER_KEYS[i] for i in LOG_IDX] + (
        [] if rest_C is not None else [pe.LAYER_KEYS[i] for i in AMBIENT_IDX]
    )
    cost, n_res, nfev, at_bounds = 0.0, 0, 0, []
    for layer in fitted:
        idx = [j for j, r in enumerate(records) if r.layer == layer]
        prob = _LayerProblem(
            [records[j] for j in idx],
            params.layers[layer],
            None if masks is None else [masks[j] for j in idx],
            settle_s,
            rest_C,
            sensor_lag_s,
            None if fractions is None else [fractions[j] for j in idx],
            params.latent_C[layer],
        )
        x0 = np.clip(prob.free(params.layers[layer], params.latent_C[layer]), prob.lo + 1e-9, prob.hi - 1e-9)
        sol = least_squares(
            prob.residuals,
            x0,
            jac=prob.jacobian,
            bounds=(prob.lo, prob.hi),
            method='trf',
            x_scale='jac',
            max_nfev=max_nfev,
        )
        nfev += int(sol.nfev)
        r = prob.residuals(sol.x)
        cost += float(r @ r)
        n_res += 1
        params = params.with_layer(layer, pe.PeltierLayer.from_vector(prob.vectors(sol.x[None])[0]))
        if prob.latent_free:
            latent = list(params.latent_C)
            latent[layer] = float(np.clip(sol.x[-1], 0.0, pe.LATENT_MAX_C))
            params = dataclasses.replace(params, latent_C=tuple(latent))
        tol = 1e-6 * (prob.hi - prob.lo)
        at_bounds += [
            f'TEM {layer + 1} {k} = {math.exp(v) if i < len(LOG_IDX) else v:.4g}'
            for i, (k, v, a, b, e) in enumerate(zip(names, sol.x, prob.lo, prob.hi, tol))
            if v <= a + e or v >= b - e
        ]
    return PeltierFit(
        params,
        fitted,
        math.sqrt(cost / n_res),
        nfev,
        time.perf_counter() - t0,
        tuple(at_bounds),
        rest_C,
        sensor_lag_s,
    )


def leave_one_out(
    records: Sequence[ti.ThermalRecord],
    base: pe.PeltierParams | None = None,
    settle_s: float = 30.0,
    sensor_lag_s: float = 0.0,
) -> list[ti.RecordEvaluation]:
    """Each run predicted by the fit on the others of its layer (as ti.identify_thermal's leave-one-out), fitted and
    predicted through the muscle thermocouple's lag ``sensor_lag_s`` [s]."""
    out = []
    for j, r in enumerate(records):
        others = [q for i, q in enumerate(records) if i != j and q.layer == r.layer]
        if not others:
            raise ti.ThermalIdentificationError(f'{r.name}: leave-one-out needs another run of TEM {r.layer + 1}')
        f = fit_peltier(others, base, settle_s=settle_s, sensor_lag_s=sensor_lag_s)
        out += evaluate(f.params, [r], 'leave-one-out', settle_s=settle_s, sensor_lag_s=sensor_lag_s)
    return out


__all__ = ['PeltierFit', 'fit_peltier', 'evaluate', 'simulate_records', 'leave_one_out', 'fraction_steps']
