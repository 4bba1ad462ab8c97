"""Compiled replay kernels for the diagnosis: thermal and mechanics of the wrist plant,
vectorised over N parameter scenarios with per-scenario parameters.

The arithmetic is that of :mod:`sma_wrist.core.plant.kernel` (thermal RK4 of Eqs. 4.13-4.14,
the SD-GPI wire-load solve, the joint of Eq. 4.18); its private load solve is reused so
the numbers are the plant's. What the plant kernel cannot do and this module adds:

* mechanics from *prescribed* muscle temperatures (the plant's ``step_mechanics``, compiled),
* per-scenario thermal coefficients, ambient drift, joint friction, payload and pre-load,
  so candidate effects and finite-difference Jacobians are one call.

test_diagnose checks both kernels against :class:`sma_wrist.core.plant.wrist.WristPlant`, test_diagnose_kernels the
mechanics replay against its step (``step_mechanics``) and its own plain-Python source.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from typing import TYPE_CHECKING

import numpy as np

from sma_wrist.core.hysteresis import kernel as hk
from sma_wrist.core.hysteresis import phase_fraction_kernel as pfk
from sma_wrist.core.jit import _jit as _jit_switch
from sma_wrist.core.jit import _jit_inline, kernel_array
from sma_wrist.core.joint.kernel import joint_step_one
from sma_wrist.core.plant.kernel import pack_constants
from sma_wrist.core.plant.wrist import PlantParams
from sma_wrist.core.thermal import kernel as tk

if TYPE_CHECKING:
    from sma_wrist.core.hysteresis.phase_fraction import PhaseFractionWire

_jit = _jit_switch  # numba.njit(cache=True, nogil=True) when numba is installed
_envelopes = hk._envelopes

#: indices in the per-scenario thermal coefficient rows (pack_thermal)
TH_IPV, TH_COUPLING = 0, 1
#: per-scenario joint rows: coulomb, viscous, static, preload_mm, payload_kg
J_COULOMB, J_VISCOUS, J_STATIC, J_PRELOAD, J_PAYLOAD = 0, 1, 2, 3, 4


@_jit_inline
def _rk4_layers(x, u0, u1, coef, ambient_shift, dt, k1, k2, k3, k4, tmp):  # pragma: no cover - compiled
    """One RK4 step of both layers (2 x 2 faces) in place; ambient_shift [degC] moves K_inf (the Peltier form's
    ambients where coef carries it, thermal.kernel.heat_balance_constants)."""
    for stage in range(4):
        if stage == 0:
            for l in range(2):
                for f in range(2):
                    tmp[l, f] = x[l, f]
            out = k1
        elif stage == 1:
            for l in range(2):
                for f in range(2):
                    tmp[l, f] = x[l, f] + 0.5 * dt * k1[l, f]
            out = k2
        elif stage == 2:
            for l in range(2):
                for f in range(2):
                    tmp[l, f] = x[l, f] + 0.5 * dt * k2[l, f]
            out = k3
        else:
            for l in range(2):
                for f in range(2):
                    tmp[l, f] = x[l, f] + dt * k3[l, f]
            out = k4
        ipv = coef[0]
        coupling = coef[1]
        if coef.shape[0] > tk.N_COEF and coef[tk.P_FLAG] != 0.0:  # the Peltier form (Eqs. P.1-P.3)
            for l in range(2):
                ul = u0 if l == 0 else u1
                dm, dx = tk.peltier_rate_layer(
                    tmp[l, 0],
                    tmp[l, 1],
                    ul,
                    ul * ul,
                    coef,
                    tk.P_LAYER + tk.N_PELTIER_LAYER * l,
                    coef[tk.P_GAIN],
                    coef[tk.P_JOULE],
                    ambient_shift,
                )
                if coupling != 0.0:
                    dm += coupling * (tmp[1 - l, 0] - tmp[l, 0])
                out[l, 0] = dm
                out[l, 1] = dx
            continue
        for l in range(2):
            cur = -ipv * coef[14 + l] * (u0 if l == 0 else u1)
            for f in range(2):
                o = 1 - f
                b = 2 + 6 * f
                d = (
                    (coef[b + 4] * cur + coef[b] * tmp[l, f] + coef[b + 1] * tmp[l, o]) * cur
                    - coef[b + 2] * tmp[l, f]
                    + coef[b + 3] * tmp[l, o]
                    + coef[b + 5]
                    + (coef[b + 2] - coef[b + 3]) * ambient_shift
                )
                if f == 0 and coupling != 0.0:
                    d += coupling * (tmp[1 - l, 0] - tmp[l, 0])
                out[l, f] = d
    for l in range(2):
        for f in range(2):
            x[l, f] += dt / 6.0 * (k1[l, f] + 2.0 * k2[l, f] + 2.0 * k3[l, f] + k4[l, f])


@_jit
def thermal_sim(u, dt, substeps, coef, x0, drift_per_s, latent, xi, out_T, out_X):  # pragma: no cover - compiled
    """Muscle temperatures under sampled commands.

    u (K, 2) [V] held from sample k to k+1 (already clipped); coef (N, 16) (or (N, 37), the Peltier form) as
    plant_kernel.pack_constants' th_coef; x0 (N, 2, 2) initial faces; drift_per_s (N,)
    ambient shift rate [degC/s] of both faces; latent (2,) [degC] the wires' latent heat per muscle node and xi
    (K, 2) the muscles' martensite fractions at the samples (Eq. P.4: each sub-step of interval k adds
    latent (xi[k] - xi[k-1]) / substeps to the muscle node; a muscle with latent 0 is left alone, bit for bit);
    out_T (K, N, 2) muscle faces at the samples, out_X (N, 2, 2) the final state.
    """
    K = u.shape[0]
    N = coef.shape[0]
    h = dt / substeps
    x = np.empty((2, 2))
    k1 = np.empty((2, 2))
    k2 = np.empty((2, 2))
    k3 = np.empty((2, 2))
    k4 = np.empty((2, 2))
    tmp = np.empty((2, 2))
    for j in range(N):
        for l in range(2):
            for f in range(2):
                x[l, f] = x0[j, l, f]
        out_T[0, j, 0] = x[0, 0]
        out_T[0, j, 1] = x[1, 0]
        t = 0.0
        for k in range(1, K):
            for _s in range(substeps):
                _rk4_layers(x, u[k - 1, 0], u[k - 1, 1], coef[j], drift_per_s[j] * t, h, k1, k2, k3, k4, tmp)
                for l in range(2):
                    if latent[l] != 0.0:
                        x[l, 0] += latent[l] * (xi[k, l] - xi[k - 1, l]) / substeps
                t += h
            out_T[k, j, 0] = x[0, 0]
            out_T[k, j, 1] = x[1, 0]
        for l in range(2):
            for f in range(2):
                out_X[j, l, f] = x[l, f]


@_jit_inline
def _solve_pair(T1, T2, yg1, yg2, w, w_now, ym1, ym2, load, stacked, edges, r, p, mech, c8, s8):  # pragma: no cover
    """Both bundles' wire loads (rtsafe of muscle.MuscleModel.solve_load, hk._solve_load_into's operations for each
    bundle) in lockstep: (m1, dy1, m2, dy2). w_now, c8, s8: (2, n_op), (2, 8), (2, 8) scratch, a row per bundle.

    A load solve is a chain of dependent steps (elongation, its tanh, the Newton quotient), so one bundle at a time
    leaves the CPU waiting on each link; the two bundles at one angle are independent, and interleaving their
    iterations lets their chains overlap: the same numbers bit for bit, the replay 1.34x and a diagnosis 1.39x
    faster (doc/explanation/diagnosis.md).
    """
    scale, c_el, k_f, m_lo, m_hi, m_max, tol = mech[1], mech[2], mech[3], mech[4], mech[5], mech[6], mech[7]
    max_it = int(mech[8])
    el = hk._elongation
    m1 = min(max(load[0], 0.0), m_max)
    m2 = min(max(load[1], 0.0), m_max)
    lo1 = lo2 = 0.0
    hi1 = hi2 = m_max
    y1, dy1 = el(T1, m1, w[0], w_now[0], ym1, stacked, edges, r, p, m_lo, m_hi, scale, c_el, k_f, c8[0], s8[0])
    y2, dy2 = el(T2, m2, w[1], w_now[1], ym2, stacked, edges, r, p, m_lo, m_hi, scale, c_el, k_f, c8[1], s8[1])
    res1 = y1 - yg1
    res2 = y2 - yg2
    on1 = on2 = True
    for _ in range(max_it):
        # each bundle's step exactly as hk._solve_load_into's loop; a bundle that has stopped stays put
        if on1 and abs(res1) <= tol:
            on1 = False
        if on2 and abs(res2) <= tol:
            on2 = False
        if not (on1 or on2):
            break
        if on1:
            if res1 > 0:
                hi1 = m1
            else:
                lo1 = m1
            newton = m1 - res1 / dy1
            done1 = (hi1 - lo1) < 1e-12
            m1 = newton if (lo1 < newton < hi1) else 0.5 * (lo1 + hi1)
        if on2:
            if res2 > 0:
                hi2 = m2
            else:
                lo2 = m2
            newton = m2 - res2 / dy2
            done2 = (hi2 - lo2) < 1e-12
            m2 = newton if (lo2 < newton < hi2) else 0.5 * (lo2 + hi2)
        if on1:
            y1, dy1 = el(T1, m1, w[0], w_now[0], ym1, stacked, edges, r, p, m_lo, m_hi, scale, c_el, k_f, c8[0], s8[0])
            res1 = y1 - yg1
            if done1:
                on1 = False
        if on2:
            y2, dy2 = el(T2, m2, w[1], w_now[1], ym2, stacked, edges, r, p, m_lo, m_hi, scale, c_el, k_f, c8[1], s8[1])
            res2 = y2 - yg2
            if done2:
                on2 = False
    return m1, dy1, m2, dy2


@_jit_inline
def _loads(T1, T2, q, w, w_now, load, compliance, y_mem1, y_mem2, preload, commit, stacked, edges, r, p, mech, c8, s8):
    """Solve both bundles' loads at angle q (:func:`_solve_pair`); returns (torque, stiffness) and, if commit,
    stores the memory, loads and compliances. w_now, c8, s8: the caller's (2, n_op), (2, 8), (2, 8) scratch
    (a fresh set per solve was ~a fifth of the replay)."""
    n_g_r, r_eff, q_neutral = mech[14], mech[15], mech[16]
    x_mm = 1e3 * r_eff * (q - q_neutral)
    m1, dy1, m2, dy2 = _solve_pair(
        T1, T2, preload - x_mm, preload + x_mm, w, w_now, y_mem1, y_mem2, load, stacked, edges, r, p, mech, c8, s8
    )
    if commit:
        for i in range(w_now.shape[1]):
            w[0, i] = w_now[0, i]
            w[1, i] = w_now[1, i]
        load[0] = m1
        load[1] = m2
        compliance[0] = dy1
        compliance[1] = dy2
    # the sums in the plant's order (muscle 1, then muscle 2)
    torque = 0.0
    torque += n_g_r * m1
    torque += -n_g_r * m2
    inv_c = 0.0
    inv_c += 1.0 / dy1
    inv_c += 1.0 / dy2
    return torque, n_g_r * 1e3 * r_eff * inv_c


@_jit_inline
def _memoryless(T, heating, mem_c, mem_d, p0):  # pragma: no cover - compiled
    if heating:
        return p0 * (mem_c[0] * math.tanh(mem_c[1] * T + mem_c[2]) + mem_c[3])
    return p0 * (mem_d[0] * math.tanh(mem_d[1] * T + mem_d[2]) + mem_d[3])


@_jit
def mechanics_sim(
    T, dt, substeps, jrow, stacked, edges, r, p, mem_c, mem_d, mech, joint, resync, out_q, out_qd, out_load
):  # pragma: no cover - compiled
    """Angle from prescribed muscle temperatures (WristPlant.step_mechanics, compiled).

    T (K, N, 2) [degC] per scenario; temperatures are interpolated linearly inside a sample
    interval when substeps > 1 (substeps = 1: the plant's step at the sample's temperature).
    jrow (N, 5): coulomb [N m], viscous [N m s], static [N m], pre-load elongation [mm],
    payload [kg]. The start is WristPlant.rest_state's: memory cooled from hot at T[0], loads
    from 0.8 kgf, static equilibrium by bisection. resync (K,) [rad]: where finite, the joint is
    set to that angle at rest at the end of sample k and the wires committed there (a replay
    restarted after a step the model does not make). Outputs (K, N), (K, N), (K, N, 2) [kgf].
    """
    K = T.shape[0]
    N = T.shape[1]
    n_op = r.size
    h = dt / substeps
    p0, T_lo, T_hi = mech[9], mech[10], mech[11]
    lever = joint[1]
    q_min, q_max, g = joint[7], joint[8], joint[9]
    w = np.empty((2, n_op))
    w_now = np.empty((2, n_op))
    heating = np.zeros(2, np.bool_)
    T_prev = np.empty(2)
    load = np.empty(2)
    compliance = np.ones(2)
    c8 = np.empty((2, 8))
    s8 = np.empty((2, 8))
    for j in range(N):
        coulomb, viscous, static, preload, payload = jrow[j, 0], jrow[j, 1], jrow[j, 2], jrow[j, 3], jrow[j, 4]
        # this scenario's joint for the plant's own step (plant_kernel.joint_step_one)
        jj = joint.copy()
        jj[2] = coulomb
        jj[3] = viscous
        jj[4] = static
        # --- rest state: memory at the upper bound (cooled from hot) at m = 0.8 kgf
        for side in range(2):
            T0 = min(max(T[0, j, side], T_lo), T_hi)
            c, s = _envelopes(stacked, edges, min(max(0.8, mech[4]), mech[5]))
            g_r = c[0] * math.tanh(c[1] * T0 + c[2]) + c[3]
            for i in range(n_op):
                w[side, i] = g_r + r[i]
            heating[side] = False
            T_prev[side] = T0
            load[side] = 0.8
        T1, T2 = T_prev[0], T_prev[1]
        ym1 = _memoryless(T1, False, mem_c, mem_d, p0)
        ym2 = _memoryless(T2, False, mem_c, mem_d, p0)
        lo = q_min
        hi = q_max
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            tau, _s = _loads(
                T1, T2, mid, w, w_now, load, compliance, ym1, ym2, preload, False, stacked, edges, r, p, mech, c8, s8
            )
            tau -= payload * g * lever * math.cos(mid)
            if tau > 0:
                lo = mid
            else:
                hi = mid
        q = 0.5 * (lo + hi)
        _loads(T1, T2, q, w, w_now, load, compliance, ym1, ym2, preload, True, stacked, edges, r, p, mech, c8, s8)
        qd = 0.0
        out_q[0, j] = q
        out_qd[0, j] = 0.0
        out_load[0, j, 0] = load[0]
        out_load[0, j, 1] = load[1]
        for k in range(1, K):
            for s in range(substeps):
                frac = (s + 1.0) / substeps
                Ts0 = T[k - 1, j, 0] + frac * (T[k, j, 0] - T[k - 1, j, 0])
                Ts1 = T[k - 1, j, 1] + frac * (T[k, j, 1] - T[k - 1, j, 1])
                Ts0 = min(max(Ts0, T_lo), T_hi)
                Ts1 = min(max(Ts1, T_lo), T_hi)
                for side in range(2):
                    Tn = Ts0 if side == 0 else Ts1
                    if Tn > T_prev[side]:
                        heating[side] = True
                    elif Tn < T_prev[side]:
                        heating[side] = False
                    T_prev[side] = Tn
                ym1 = _memoryless(Ts0, heating[0], mem_c, mem_d, p0)
                ym2 = _memoryless(Ts1, heating[1], mem_c, mem_d, p0)
                torque, stiffness = _loads(
                    Ts0, Ts1, q, w, w_now, load, compliance, ym1, ym2, preload, True, stacked, edges, r, p, mech, c8, s8
                )
                q, qd = joint_step_one(q, qd, torque, stiffness, payload, h, jj)
            if not math.isnan(resync[k]):
                q = resync[k]
                qd = 0.0
                _loads(
                    Ts0, Ts1, q, w, w_now, load, compliance, ym1, ym2, preload, True, stacked, edges, r, p, mech, c8, s8
                )
            out_q[k, j] = q
            out_qd[k, j] = qd
            out_load[k, j, 0] = load[0]
            out_load[k, j, 1] = load[1]


# compiled once and called, not inlined like _loads: its two load solves inline the wire law's Newton iteration, and
# three inlined copies in pf_mechanics_sim made it the costliest kernel to compile (cold cache, measured: 80-93 s of
# CPU inlined, 24-27 s called; a replay of 8 runs x 3000 steps ~0.1 s either way, identical to the bit). It stores
# nothing, so it takes no commit flag: numba compiles a called kernel once per literal argument, and a
# ``commit`` passed as True and as False compiled it twice (~9 s of CPU each on a cold cache)
@_jit
def _pf_solve(T1, T2, q, mem, load, preload, wc, mech):  # pragma: no cover - compiled
    """Both phase-fraction bundles' loads at angle q against memory ``mem`` (2, 5), from the guesses ``load``
    (:func:`sma_wrist.core.hysteresis.phase_fraction_kernel.solve_load`): (m1, dy1, m2, dy2), loads [kgf] and
    compliances [mm/kgf]; stores nothing."""
    m_max, tol, max_it = mech[6], mech[7], int(mech[8])
    r_eff, q_neutral = mech[15], mech[16]
    x_mm = 1e3 * r_eff * (q - q_neutral)
    m1, dy1, _r1 = pfk.solve_load(wc, T1, preload - x_mm, mem[0], load[0], m_max, tol, max_it)
    m2, dy2, _r2 = pfk.solve_load(wc, T2, preload + x_mm, mem[1], load[1], m_max, tol, max_it)
    return m1, dy1, m2, dy2


@_jit_inline
def _pf_commit(wc, T1, T2, m1, dy1, m2, dy2, mem, load, compliance):  # pragma: no cover - compiled
    """Store what :func:`_pf_solve` found: both wires' memory at their loads, the loads and compliances."""
    pfk.commit(wc, T1, m1, mem[0])
    pfk.commit(wc, T2, m2, mem[1])
    load[0] = m1
    load[1] = m2
    compliance[0] = dy1
    compliance[1] = dy2


@_jit_inline
def _pf_torque(m1, dy1, m2, dy2, mech):  # pragma: no cover - compiled
    """:func:`_loads`' (torque [N m], stiffness [N m/rad]) of the phase-fraction bundles' loads and compliances."""
    n_g_r, r_eff = mech[14], mech[15]
    torque = 0.0
    torque += n_g_r * m1
    torque += -n_g_r * m2
    inv_c = 0.0
    inv_c += 1.0 / dy1
    inv_c += 1.0 / dy2
    return torque, n_g_r * 1e3 * r_eff * inv_c


@_jit
def pf_mechanics_sim(
    T, dt, substeps, jrow, wc, mech, joint, resync, out_q, out_qd, out_load, out_xi
):  # pragma: no cover - compiled
    """:func:`mechanics_sim` with phase-fraction wires (``wc``: PhaseFractionWire.packed): the same rest state
    (wires cooled from hot at T[0], loads from 0.8 kgf, static equilibrium by bisection), the same sub-steps, joint
    rows, joint step and restarts (``resync``); only the wire differs. out_xi (K, N, 2): the wires' martensite
    fractions at the samples (what the heat balance's latent heat, Eq. P.4, follows)."""
    K = T.shape[0]
    N = T.shape[1]
    h = dt / substeps
    T_lo, T_hi = mech[10], mech[11]
    lever = joint[1]
    q_min, q_max, g = joint[7], joint[8], joint[9]
    mem = np.empty((2, 5))
    load = np.empty(2)
    compliance = np.ones(2)
    for j in range(N):
        coulomb, viscous, static, preload, payload = jrow[j, 0], jrow[j, 1], jrow[j, 2], jrow[j, 3], jrow[j, 4]
        jj = joint.copy()
        jj[2] = coulomb
        jj[3] = viscous
        jj[4] = static
        for side in range(2):
            pfk.cooled(wc, min(max(T[0, j, side], T_lo), T_hi), 0.8, mem[side])
            load[side] = 0.8
        T1 = min(max(T[0, j, 0], T_lo), T_hi)
        T2 = min(max(T[0, j, 1], T_lo), T_hi)
        lo = q_min
        hi = q_max
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            m1, dy1, m2, dy2 = _pf_solve(T1, T2, mid, mem, load, preload, wc, mech)
            tau, _s = _pf_torque(m1, dy1, m2, dy2, mech)
            tau -= payload * g * lever * math.cos(mid)
            if tau > 0:
                lo = mid
            else:
                hi = mid
        q = 0.5 * (lo + hi)
        m1, dy1, m2, dy2 = _pf_solve(T1, T2, q, mem, load, preload, wc, mech)
        _pf_commit(wc, T1, T2, m1, dy1, m2, dy2, mem, load, compliance)
        qd = 0.0
        out_q[0, j] = q
        out_qd[0, j] = 0.0
        out_load[0, j, 0] = load[0]
        out_load[0, j, 1] = load[1]
        out_xi[0, j, 0] = mem[0, 0]
        out_xi[0, j, 1] = mem[1, 0]
        for k in range(1, K):
            for s in range(substeps):
                frac = (s + 1.0) / substeps
                Ts0 = min(max(T[k - 1, j, 0] + frac * (T[k, j, 0] - T[k - 1, j, 0]), T_lo), T_hi)
                Ts1 = min(max(T[k - 1, j, 1] + frac * (T[k, j, 1] - T[k - 1, j, 1]), T_lo), T_hi)
                m1, dy1, m2, dy2 = _pf_solve(Ts0, Ts1, q, mem, load, preload, wc, mech)
                _pf_commit(wc, Ts0, Ts1, m1, dy1, m2, dy2, mem, load, compliance)
                torque, stiffness = _pf_torque(m1, dy1, m2, dy2, mech)
                q, qd = joint_step_one(q, qd, torque, stiffness, payload, h, jj)
            if not math.isnan(resync[k]):
                q = resync[k]
                qd = 0.0
                m1, dy1, m2, dy2 = _pf_solve(Ts0, Ts1, q, mem, load, preload, wc, mech)
                _pf_commit(wc, Ts0, Ts1, m1, dy1, m2, dy2, mem, load, compliance)
            out_q[k, j] = q
            out_qd[k, j] = qd
            out_load[k, j, 0] = load[0]
            out_load[k, j, 1] = load[1]
            out_xi[k, j, 0] = mem[0, 0]
            out_xi[k, j, 1] = mem[1, 0]


class Constants:
    """The plant's constant arrays for the kernels, from a PlantParams."""

    def __init__(self, params: PlantParams | None = None) -> None:
        self.params = params or PlantParams()
        # the SD-GPI's arrays always (a phase-fraction plant's replay still packs its joint and heat balance so)
        sdgpi = dataclasses.replace(self.params, wire=None) if self.params.wire is not None else self.params
        th_coef, mech, stacked, edges, r, p, mem_c, mem_d, joint = pack_constants(sdgpi)
        self.th_coef = th_coef
        self.mech = np.concatenate([mech, [self.params.joint.q_neutral_rad]])
        self.stacked, self.edges, self.r, self.p = stacked, edges, r, p
        self.mem_c, self.mem_d, self.joint = mem_c, mem_d, joint
        jp = self.params.joint
        self.joint_row = np.array(
            [jp.coulomb_Nm, jp.viscous_Nms, jp.static_Nm, self.params.preload_elongation_mm, jp.payload_kg]
        )
        self.u_limits = (self.params.thermal.u_min_V, self.params.thermal.u_max_V)
        hb = self.params.heat_balance
        #: the wires' latent heat per muscle node [degC per full transformation] (PeltierParams.latent_C, Eq. P.4)
        self.latent_C = np.array(hb.latent_C if hb is not None else (0.0, 0.0))
        self._sdgpi_mech = self.mech
        self._pack_wire()

    def _pack_wire(self) -> None:
        """The phase-fraction wire's constant row (``self.wire``) and validity window [degC] (mech 10-11) where the
        plant's wire is one (PlantParams.wire); else None and the SD-GPI's window."""
        self.mech = self._sdgpi_mech.copy()
        self.wire = None
        wire = self.params.wire
        if wire is not None:
            mg = self.params.muscle
            self.wire = wire.packed(mg.wire_length_mm, mg.wire_area_m2)
            self.mech[10], self.mech[11] = wire.T_valid

    def with_wire(self, wire: PhaseFractionWire | None) -> Constants:
        """These constants for the plant with another wire (PlantParams.wire: a phase-fraction wire, or None for the
        SD-GPI of ``hysteresis``), the same as ``Constants(dataclasses.replace(params, wire=wire))``: only the wire's
        row and window are packed again; the SD-GPI's, heat balance's and joint's arrays are shared (read-only)."""
        out = copy.copy(self)
        out.params = dataclasses.replace(self.params, wire=wire)
        out._pack_wire()
        return out

    @property
    def has_latent(self) -> bool:
        """Whether the heat balance follows the wires' transformation (Eq. P.4): a latent heat and a phase-fraction
        wire whose martensite fraction carries it (the SD-GPI has none)."""
        return self.wire is not None and bool(np.any(self.latent_C != 0.0))

    def thermal(
        self,
        u: np.ndarray,
        dt: float,
        coef: np.ndarray,
        x0: np.ndarray,
        drift_per_s: np.ndarray,
        substeps: int = 1,
        xi: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """(K, N, 2) muscle temperatures and the (N, 2, 2) final state; see :func:`thermal_sim`. ``xi`` (K, 2): the
        muscles' martensite fractions at the samples, the latent heat's input (Eq. P.4) where :attr:`has_latent`;
        None leaves the latent heat out."""
        u = np.ascontiguousarray(np.clip(u, *self.u_limits), dtype=float)
        coef = np.ascontiguousarray(np.atleast_2d(coef), dtype=float)
        n = coef.shape[0]
        out = np.empty((u.shape[0], n, 2))
        X = np.empty((n, 2, 2))
        latent = self.latent_C if xi is not None and self.has_latent else np.zeros(2)
        xi = np.zeros((u.shape[0], 2)) if xi is None else np.asarray(xi, dtype=float)[: u.shape[0]]
        if xi.shape != (u.shape[0], 2):
            raise ValueError(f'martensite fractions of shape {xi.shape} for {u.shape[0]} samples of 2 muscles')
        thermal_sim(
            u,
            float(dt),
            int(substeps),
            coef,
            kernel_array(np.broadcast_to(x0, (n, 2, 2))),
            kernel_array(np.broadcast_to(drift_per_s, (n,))),
            kernel_array(latent),
            kernel_array(xi),
            out,
            X,
        )
        return out, X

    def mechanics(
        self, T: np.ndarray, dt: float, jrow: np.ndarray, substeps: int = 1, resync: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(q, qd, load) for T (K, N, 2); see :func:`mechanics_sim` (:func:`pf_mechanics_sim` for a phase-fraction
        wire). ``resync`` (K,) [rad], NaN where free: angles the replay restarts from (default: none)."""
        if self.wire is not None:
            return self._pf_replay(T, dt, jrow, substeps, resync)[:3]
        T = np.ascontiguousarray(T, dtype=float)
        k, n = T.shape[:2]
        jrow = kernel_array(np.broadcast_to(jrow, (n, 5)))  # whatever the caller's shape: (5,) or (n, 5)
        resync = _resync_array(resync, k)
        q = np.empty((k, n))
        qd = np.empty((k, n))
        load = np.empty((k, n, 2))
        mechanics_sim(
            T,
            float(dt),
            int(substeps),
            jrow,
            self.stacked,
            self.edges,
            self.r,
            self.p,
            self.mem_c,
            self.mem_d,
            self.mech,
            self.joint,
            resync,
            q,
            qd,
            load,
        )
        return q, qd, load

    def martensite_fraction(
        self, T: np.ndarray, dt: float, jrow: np.ndarray, substeps: int = 1, resync: np.ndarray | None = None
    ) -> np.ndarray:
        """(K, N, 2) the phase-fraction wires' martensite fractions of the mechanics replay (:meth:`mechanics`) from
        T (K, N, 2) [degC]; the SD-GPI has none (ValueError)."""
        if self.wire is None:
            raise ValueError('the SD-GPI wire has no martensite fraction (PlantParams.wire is None)')
        return self._pf_replay(T, dt, jrow, substeps, resync)[3]

    def _pf_replay(
        self, T: np.ndarray, dt: float, jrow: np.ndarray, substeps: int, resync: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(q, qd, load, xi) of :func:`pf_mechanics_sim` for T (K, N, 2) and joint rows (5,) or (N, 5)."""
        T = np.ascontiguousarray(T, dtype=float)
        k, n = T.shape[:2]
        jrow = kernel_array(np.broadcast_to(jrow, (n, 5)))  # whatever the caller's shape: (5,) or (n, 5)
        q, qd, load, xi = np.empty((k, n)), np.empty((k, n)), np.empty((k, n, 2)), np.empty((k, n, 2))
        pf_mechanics_sim(
            T,
            float(dt),
            int(substeps),
            jrow,
            self.wire,
            self.mech,
            self.joint,
            _resync_array(resync, k),
            q,
            qd,
            load,
            xi,
        )
        return q, qd, load, xi


def _resync_array(resync: np.ndarray | None, k: int) -> np.ndarray:
    """The kernels' (k,) restart angles [rad] (NaN: none) from an optional longer or equal array."""
    if resync is None:
        return np.full(k, np.nan)
    resync = np.asarray(resync, dtype=float)
    if resync.shape[0] < k:
        raise ValueError(f'restart angles for {resync.shape[0]} samples, the replay has {k}')
    return kernel_array(resync[:k])
