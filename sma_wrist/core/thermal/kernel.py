"""Compiled TEM + Nitinol heat balance (seed Eqs. 4.13-4.14): classical RK4 on both layers.

Scalar loops compiled by numba when present (:mod:`sma_wrist.core.jit`); the numpy reference is
:mod:`sma_wrist.core.thermal.heat_balance` (``rate_terms``). Shared by the plant kernel and the TEM
control kernel, so the plant and the TEM law's model integrate the same numbers.

The Peltier form (Eqs. P.1-P.3, numpy reference :mod:`sma_wrist.core.thermal.peltier`) rides on the same
coefficient vector: :func:`heat_balance_constants` appends a flag, a drive gain, a Joule scale and both layers'
Peltier vectors to the 16 Table 4.9 entries (``N_COEF_PELTIER``), and :func:`thermal_rk4` integrates that
form where the flag is set. The TEM control kernel always gets Table 4.9's 16 (its linearisation).
"""

from __future__ import annotations

import numpy as np

from sma_wrist.core.jit import _jit, _jit_inline

#: Peltier entries of a coefficient vector after the 16 of Table 4.9: flag (1: the Peltier form), drive gain, Joule
#: scale, then both layers' vectors (peltier.LAYER_KEYS order)
P_FLAG, P_GAIN, P_JOULE, P_LAYER = 16, 17, 18, 19
N_PELTIER_LAYER = 9
N_COEF_PELTIER = P_LAYER + 2 * N_PELTIER_LAYER


@_jit_inline
def peltier_rate_layer(tm, tx, u, u2, c, o, gain, joule, shift):  # pragma: no cover - compiled
    """(dT_m/dt, dT_x/dt) [degC/s] of Eqs. P.1-P.3 (peltier.derivative_coef) for one layer whose vector starts at
    c[o]: faces tm, tx [degC], drive u [V] (x gain) with interval mean square u2 [V^2] (x gain^2), the Joule heat x
    joule, both ambients + shift [degC]."""
    S, R, K = c[o], c[o + 1], c[o + 2]
    d = tm - tx
    emf = S * d
    ug = gain * u
    cur = (ug - emf) / R
    i2r = joule * (gain * gain * u2 - 2.0 * ug * emf + emf * emf) / R
    qm = S * cur * (tm + 273.15) + 0.5 * i2r - K * d - c[o + 5] * (tm - c[o + 7] - shift)
    qx = -S * cur * (tx + 273.15) + 0.5 * i2r + K * d - c[o + 6] * (tx - c[o + 8] - shift)
    return qm / c[o + 3], qx / c[o + 4]


@_jit_inline
def _thermal_rate(x, u, th_coef, out):  # pragma: no cover - compiled
    """dT/dt (2 layers x 2 faces) of Eqs. 4.13-4.14 (thermal.rate_terms) at commands u (2,) [V]; of Eqs. P.1-P.3
    where th_coef carries the Peltier form (:func:`heat_balance_constants`)."""
    ipv = th_coef[0]
    coupling = th_coef[1]
    if th_coef.shape[0] > N_COEF and th_coef[P_FLAG] != 0.0:
        for l in range(2):
            dm, dx = peltier_rate_layer(
                x[l, 0],
                x[l, 1],
                u[l],
                u[l] * u[l],
                th_coef,
                P_LAYER + N_PELTIER_LAYER * l,
                th_coef[P_GAIN],
                th_coef[P_JOULE],
                0.0,
            )
            if coupling != 0.0:
                dm += coupling * (x[1 - l, 0] - x[l, 0])
            out[l, 0] = dm
            out[l, 1] = dx
        return
    for l in range(2):
        cur = -ipv * th_coef[14 + l] * u[l]
        for f in range(2):
            o = 1 - f
            b = 2 + 6 * f  # K_at, K_t, K_Tinf, K_T, K_R, K_inf of this face
            d = (
                (th_coef[b + 4] * cur + th_coef[b] * x[l, f] + th_coef[b + 1] * x[l, o]) * cur
                - th_coef[b + 2] * x[l, f]
                + th_coef[b + 3] * x[l, o]
                + th_coef[b + 5]
            )
            if f == 0 and coupling != 0.0:
                d += coupling * (x[1 - l, 0] - x[l, 0])
            out[l, f] = d


@_jit_inline
def thermal_rk4(x, u, dt, th_coef, y0, xs, kk, acc):  # pragma: no cover - compiled
    """One classical RK4 step of Eqs. 4.13-4.14 on both layers, x (2, 2) [degC] in place, command
    u (2,) [V] held over dt [s]; y0, xs, kk, acc are (2, 2) scratch arrays."""
    for l in range(2):
        for f in range(2):
            y0[l, f] = x[l, f]
            xs[l, f] = y0[l, f]
            acc[l, f] = 0.0
    for stage in range(4):
        _thermal_rate(xs, u, th_coef, kk)
        wgt = 1.0 if (stage == 0 or stage == 3) else 2.0
        frac = 1.0 if stage == 2 else 0.5
        for l in range(2):
            for f in range(2):
                acc[l, f] += wgt * kk[l, f]
                xs[l, f] = y0[l, f] + frac * dt * kk[l, f]
    for l in range(2):
        for f in range(2):
            x[l, f] = y0[l, f] + dt / 6.0 * acc[l, f]


#: length of a th_coef vector: input_per_volt, coupling, six coefficients per face, the two TEMs' drive gains
N_COEF = 16


def thermal_constants(tp) -> np.ndarray:  # type: ignore[no-untyped-def]
    """th_coef (16,) of :func:`~sma_wrist.core.plant.kernel.step_many` from a thermal.ThermalParams:
    input_per_volt, coupling, per face (muscle, exchanger) K_at, K_t, K_Tinf, K_T, K_R, K_inf, then tem_gain (2,)
    (layer l's input is -th_coef[0] * th_coef[14 + l] * u)."""
    faces = [[tp._k_at[f], tp._k_t[f], tp._k_tinf[f], tp._k_tc[f], tp._k_r[f], tp._k_inf[f]] for f in (0, 1)]
    return np.array([tp.input_per_volt, tp.coupling_per_s] + faces[0] + faces[1] + list(tp.tem_gain), dtype=float)


def heat_balance_constants(tp, peltier=None) -> np.ndarray:  # type: ignore[no-untyped-def]
    """th_coef of the plant: :func:`thermal_constants` of a thermal.ThermalParams (Table 4.9's form), with a
    peltier.PeltierParams the Peltier form appended (``N_COEF_PELTIER``: flag, its drive gain and Joule scale,
    both layers' vectors; its muscle-muscle coupling in entry 1)."""
    c = thermal_constants(tp)
    if peltier is None:
        return c
    c[1] = peltier.coupling_per_s
    return np.concatenate([c, [1.0, peltier.drive_gain, peltier.joule_scale], peltier.coef(2).reshape(-1)])


@_jit
def peltier_simulate_runs(coef, u, u2, T0, dt, latent, dxi, out):  # pragma: no cover - compiled
    """RK4 of Eqs. P.1-P.3 for parameter sets and runs: coef (P, R, N_PELTIER_LAYER) (each run its layer's vector),
    drive u and its interval mean square u2 (K, R) held over each step of dt [s], from T0 (R, 2) [degC]; out
    (K, P, R, 2): row 0 T0, row k + 1 after u[k]. peltier.step_coef is the reference. The wires' latent heat (Eq.
    P.4): latent (P, R) [degC per full transformation] of each parameter set and run, dxi (K, R) each run's martensite
    fraction change over step k, added to the muscle node after the step (latent 0: left out, bit for bit)."""
    K, R = u.shape
    P = coef.shape[0]
    k1, k2, k3, k4 = np.empty(2), np.empty(2), np.empty(2), np.empty(2)
    for p in range(P):
        for r in range(R):
            c = coef[p, r]
            tm, tx = T0[r, 0], T0[r, 1]
            out[0, p, r, 0], out[0, p, r, 1] = tm, tx
            for k in range(K - 1):
                uk, u2k = u[k, r], u2[k, r]
                k1[0], k1[1] = peltier_rate_layer(tm, tx, uk, u2k, c, 0, 1.0, 1.0, 0.0)
                k2[0], k2[1] = peltier_rate_layer(
                    tm + 0.5 * dt * k1[0], tx + 0.5 * dt * k1[1], uk, u2k, c, 0, 1.0, 1.0, 0.0
                )
                k3[0], k3[1] = peltier_rate_layer(
                    tm + 0.5 * dt * k2[0], tx + 0.5 * dt * k2[1], uk, u2k, c, 0, 1.0, 1.0, 0.0
                )
                k4[0], k4[1] = peltier_rate_layer(tm + dt * k3[0], tx + dt * k3[1], uk, u2k, c, 0, 1.0, 1.0, 0.0)
                tm = tm + dt / 6.0 * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0])
                tx = tx + dt / 6.0 * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1])
                if latent[p, r] != 0.0:
                    tm += latent[p, r] * dxi[k, r]
                out[k + 1, p, r, 0], out[k + 1, p, r, 1] = tm, tx


@_jit_inline
def _apply_m(out, x, cs, cc, coupling):  # pragma: no cover - compiled
    """out = M x of one wrist, x and out (L, 2): heat_balance._apply_M's operations in its order."""
    n_layers = x.shape[0]
    for l in range(n_layers):
        out[l, 0] = cs[l, 0] * x[l, 0] + cc[l, 0] * x[l, 1]
        out[l, 1] = cs[l, 1] * x[l, 1] + cc[l, 1] * x[l, 0]
    if coupling != 0.0:  # muscle face of layer l receives from the muscle face of the other layer
        for l in range(n_layers):
            out[l, 0] += coupling * x[n_layers - 1 - l, 0]


@_jit
def step_horner(T, u, dt, ipv, k_at, k_t, neg_k_tinf, k_tc, k_r, k_inf, coupling, out):  # pragma: no cover
    """heat_balance.step (Eqs. 4.13-4.14, RK4 in Horner form on the model linear over the step) for
    T (N, L, 2) [degC] under u (N, L) [V] held dt [s], into out: the same operations in the same order
    as its numpy code, wrist by wrist, so the same numbers (test_thermal) without ~40 numpy calls.
    ipv (L,): input per volt of each layer; k_*: the per-face coefficient vectors (2,) of ThermalParams."""
    n_layers = u.shape[1]
    cs, cc, c0 = np.empty((n_layers, 2)), np.empty((n_layers, 2)), np.empty((n_layers, 2))
    v, a, b = np.empty((n_layers, 2)), np.empty((n_layers, 2)), np.empty((n_layers, 2))
    h = (0.25 * dt, (1.0 / 3.0) * dt, 0.5 * dt)
    for j in range(u.shape[0]):
        for l in range(n_layers):
            i = u[j, l] * (-ipv[l])  # model input I
            for f in range(2):
                cs[l, f] = k_at[f] * i + neg_k_tinf[f]
                cc[l, f] = k_t[f] * i + k_tc[f]
                c0[l, f] = k_r[f] * (i * i) + k_inf[f]
            if coupling != 0.0:
                cs[l, 0] = cs[l, 0] - coupling
        x = T[j]
        _apply_m(v, x, cs, cc, coupling)  # v = M x + b = f(x)
        for l in range(n_layers):
            for f in range(2):
                v[l, f] += c0[l, f]
        _apply_m(a, v, cs, cc, coupling)  # a = v + h/4 M v
        for l in range(n_layers):
            for f in range(2):
                a[l, f] = a[l, f] * h[0] + v[l, f]
        _apply_m(b, a, cs, cc, coupling)  # b = v + h/3 M a
        for l in range(n_layers):
            for f in range(2):
                b[l, f] = b[l, f] * h[1] + v[l, f]
        _apply_m(a, b, cs, cc, coupling)  # a = v + h/2 M b
        for l in range(n_layers):
            for f in range(2):
                out[j, l, f] = (a[l, f] * h[2] + v[l, f]) * dt + x[l, f]


@_jit
def predict_junction(x0, z0, us, ts, coef, reps, lag, out, x_end):  # pragma: no cover - compiled
    """The online estimate's window (core.thermal.online, ``ThermalScaleEstimator._predict``): per row m of
    coef (M, 16) (wrist m // reps), the faces from x0[w] (N, 2, 2) under the commands us[k - 1, w] (K, N, 2)
    held over the sample steps of ts (K,) [s] (RK4, :func:`thermal_rk4`), the muscle face seen through a
    first-order thermocouple of lag [s] from z0[w] (N, 2); out (K, M, 2) the junction, x_end (M, 2, 2) the
    faces at the end. The numpy path there is the reference (test_thermal_online)."""
    x = np.empty((2, 2))
    y0, xs, kk, acc = np.empty((2, 2)), np.empty((2, 2)), np.empty((2, 2)), np.empty((2, 2))
    z = np.empty(2)
    for m in range(coef.shape[0]):
        w = m // reps
        for l in range(2):
            z[l] = z0[w, l]
            out[0, m, l] = z[l]
            for f in range(2):
                x[l, f] = x0[w, l, f]
        for k in range(1, ts.shape[0]):
            dt = ts[k] - ts[k - 1]
            thermal_rk4(x, us[k - 1, w], dt, coef[m], y0, xs, kk, acc)
            for l in range(2):
                if lag <= 0.0:
                    z[l] = x[l, 0]
                else:
                    z[l] = z[l] + dt / (lag + dt) * (x[l, 0] - z[l])
                out[k, m, l] = z[l]
        for l in range(2):
            for f in range(2):
                x_end[m, l, f] = x[l, f]
