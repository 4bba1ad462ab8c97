"""Compiled per-sample stepping of :class:`sma_wrist.core.plant.WristPlant` (optional numba).

The plant is a time recursion: at 1 kHz a node steps one wrist at a time, and numpy's
per-call overhead (~50 array operations a step) dominates a 1-wrist step. This module is
the same step written as tight scalar loops over wrists (thermal RK4, Eqs. 4.13-4.14; the
wire-load solve of muscle.py Eq. 1 with the SD-GPI of Eqs. 3.19-3.24, 4.1-4.6; the joint
of Eq. 4.18), compiled by numba when it is installed (``pip install sma_wrist[fast]``).
Without numba the plant uses its numpy path; :data:`AVAILABLE` says which.

The uncompiled Python of the same functions (``step_many.py_func``) is the "plain
per-sample Python reference loop" of the benchmark. test_plant_kernel checks the kernel
against the numpy path step by step.
"""
from __future__ import annotations

import math

import numpy as np

try:  # numba is optional: a 20-100x faster per-sample plant, same numbers
    import numba as _numba

    AVAILABLE = True
    _jit = _numba.njit(cache=True, nogil=True)
except ImportError:  # pragma: no cover - exercised where numba is absent
    AVAILABLE = False

    def _jit(f):  # type: ignore[no-untyped-def]
        f.py_func = f
        return f


@_jit
def _envelopes(stacked, edges, m):  # pragma: no cover - compiled
    """Coefficients (8,) and slopes (8,) [a0..a3, b0..b3] at load m (Eqs. 4.4-4.5)."""
    c = np.empty(8)
    s = np.empty(8)
    _envelopes_into(stacked, edges, m, c, s)
    return c, s


@_jit
def _envelopes_into(stacked, edges, m, c, s):  # pragma: no cover - compiled
    """:func:`_envelopes` into caller-owned (8,) arrays: the load solve evaluates it 2-3 times per wire
    and step, and two heap allocations per call cost ~3x the arithmetic (~150 of ~200 ns)."""
    n_sec = edges.size - 1
    k = 0
    while k < n_sec - 1 and m >= edges[k + 1]:
        k += 1
    for j in range(8):
        q2 = stacked[k, 0, j]
        q1 = stacked[k, 1, j]
        c[j] = (q2 * m + q1) * m + stacked[k, 2, j]
        s[j] = 2.0 * q2 * m + q1


@_jit
def _elongation(T, m, w, w_now, y_mem, stacked, edges, r, p, m_lo, m_hi, scale, c_el, k_f, c, s):  # pragma: no cover
    """(y, dy/dm) of muscle.py Eq. 1 against frozen memory w; w_now receives the clamped memory;
    c, s: (8,) scratch for the envelope coefficients and slopes."""
    mc = min(max(m, m_lo), m_hi)
    _envelopes_into(stacked, edges, mc, c, s)
    th_r = math.tanh(c[1] * T + c[2])
    th_l = math.tanh(c[5] * T + c[6])
    g_r = c[0] * th_r + c[3]
    g_l = c[4] * th_l + c[7]
    y_m = y_mem
    p_below = 0.0
    p_above = 0.0
    for i in range(w.size):
        lower = g_l - r[i]
        upper = g_r + r[i]
        wi = w[i]
        if wi < lower:
            p_below += p[i]
        if wi > upper:
            p_above += p[i]
        wn = min(max(wi, lower), upper)
        w_now[i] = wn
        y_m += wn * p[i]
    dg_r = s[0] * th_r + c[0] * (1.0 - th_r * th_r) * (s[1] * T + s[2]) + s[3]
    dg_l = s[4] * th_l + c[4] * (1.0 - th_l * th_l) * (s[5] * T + s[6]) + s[7]
    dym = p_below * dg_l + p_above * dg_r
    y = scale * (k_f - y_m) + c_el * m
    dy = c_el
    if m_lo < m < m_hi:
        dy -= scale * dym
    return y, dy


@_jit
def _solve_load(T, y_geo, w, w_now, y_mem, m_guess, stacked, edges, r, p, m_lo, m_hi, scale, c_el, k_f,
                m_max, tol, max_it):  # pragma: no cover - compiled
    """rtsafe of muscle.MuscleModel.solve_load for one bundle: (m, dy, residual)."""
    return _solve_load_into(T, y_geo, w, w_now, y_mem, m_guess, stacked, edges, r, p, m_lo, m_hi, scale, c_el, k_f,
                            m_max, tol, max_it, np.empty(8), np.empty(8))


@_jit
def _solve_load_into(T, y_geo, w, w_now, y_mem, m_guess, stacked, edges, r, p, m_lo, m_hi, scale, c_el, k_f,
                     m_max, tol, max_it, c, s):  # pragma: no cover - compiled
    """:func:`_solve_load` with caller-owned (8,) envelope scratch c, s (the plant step's, reused)."""
    m = min(max(m_guess, 0.0), m_max)
    lo = 0.0
    hi = m_max
    y, dy = _elongation(T, m, w, w_now, y_mem, stacked, edges, r, p, m_lo, m_hi, scale, c_el, k_f, c, s)
    res = y - y_geo
    for _ in range(max_it):
        if abs(res) <= tol:
            break
        if res > 0:
            hi = m
        else:
            lo = m
        newton = m - res / dy
        done = (hi - lo) < 1e-12
        m = newton if (lo < newton < hi) else 0.5 * (lo + hi)
        y, dy = _elongation(T, m, w, w_now, y_mem, stacked, edges, r, p, m_lo, m_hi, scale, c_el, k_f, c, s)
        res = y - y_geo
        if done:
            break
    return m, dy, res


@_jit
def _thermal_rate(x, u, th_coef, out):  # pragma: no cover - compiled
    """dT/dt (2 layers x 2 faces) of Eqs. 4.13-4.14 (thermal.rate_terms) at commands u (2,) [V]."""
    ipv = th_coef[0]
    coupling = th_coef[1]
    for l in range(2):
        cur = -ipv * u[l]
        for f in range(2):
            o = 1 - f
            b = 2 + 6 * f  # K_at, K_t, K_Tinf, K_T, K_R, K_inf of this face
            d = (th_coef[b + 4] * cur + th_coef[b] * x[l, f] + th_coef[b + 1] * x[l, o]) * cur \
                - th_coef[b + 2] * x[l, f] + th_coef[b + 3] * x[l, o] + th_coef[b + 5]
            if f == 0 and coupling != 0.0:
                d += coupling * (x[1 - l, 0] - x[l, 0])
            out[l, f] = d


@_jit
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


@_jit
def joint_step_one(qj, qdj, torque, stiffness, payload, dt, joint):  # pragma: no cover - compiled
    """One wrist's joint step, linearly implicit Euler of Eq. 4.18 (joint.joint_step): (q, q').

    torque: net muscle torque [N m]; stiffness: -d torque / dq [N m/rad]; joint (10,) as in
    :func:`step_many`. Shared by every plant whose muscles drive this joint.
    """
    I_w, lever, coulomb, viscous, static, stick_v = joint[0], joint[1], joint[2], joint[3], joint[4], joint[5]
    q_min, q_max, g = joint[7], joint[8], joint[9]
    inertia = I_w + payload * lever * lever
    tau_drive = torque - payload * g * lever * math.cos(qj)
    at_rest = abs(qdj) < stick_v
    stuck = at_rest and abs(tau_drive) <= static
    if at_rest:
        direction = 1.0 if tau_drive > 0 else (-1.0 if tau_drive < 0 else 0.0)
    else:
        direction = 1.0 if qdj > 0 else -1.0
    h_over_i = dt / inertia
    qd_new = (qdj + h_over_i * (tau_drive - direction * coulomb)) / (1.0 + h_over_i * (viscous + dt * stiffness))
    s_new = 1.0 if qd_new > 0 else (-1.0 if qd_new < 0 else 0.0)
    s_old = 1.0 if qdj > 0 else (-1.0 if qdj < 0 else 0.0)
    reversed_ = (not at_rest) and s_new != s_old and abs(tau_drive) <= static + coulomb
    if stuck or reversed_:
        qd_new = 0.0
    q_new = qj + dt * qd_new
    if q_new < q_min or q_new > q_max:
        q_new = min(max(q_new, q_min), q_max)
        qd_new = 0.0
    return q_new, qd_new


@_jit
def step_many(n_steps, u, thermal, q, qd, w, heating, T_prev, load, compliance, payload, flags,
              th_coef, mech, stacked, edges, r, p, mem_c, mem_d, joint):  # pragma: no cover - compiled
    """Advance N wrists by n_steps plant steps under held commands u (N, 2) [V], in place.

    Arrays: thermal (N, 2, 2); q, qd, payload (N,); w (2N, n) and heating, T_prev, load,
    compliance (2N,) stacked [muscle 1 of all wrists, then muscle 2] as in plant.PlantState;
    flags (N, 4) bool out: over_temperature, slack, overload, at_stop (OR over the steps).
    th_coef (14,): input_per_volt, coupling, then per face (muscle, exchanger) the six
    (K_at, K_t, K_Tinf, K_T, K_R, K_inf).
    mech (16,): dt, scale, c_el, k_f, m_lo, m_hi, m_max, tol, max_it, p0, T_lo, T_hi, T_hot,
    e0_mm, n_g_r, r_eff_m. joint (10,): I_w, lever, coulomb, viscous, static, stick_v,
    q_neutral, q_min, q_max, g.
    """
    n = q.size
    dt = mech[0]
    scale, c_el, k_f, m_lo, m_hi, m_max, tol = mech[1], mech[2], mech[3], mech[4], mech[5], mech[6], mech[7]
    max_it = int(mech[8])
    p0, T_lo, T_hi, T_hot, e0, n_g_r, r_eff = mech[9], mech[10], mech[11], mech[12], mech[13], mech[14], mech[15]
    q_neutral, q_min, q_max = joint[6], joint[7], joint[8]
    w_now = np.empty(w.shape[1])
    y0 = np.empty((2, 2))
    xs = np.empty((2, 2))
    kk = np.empty((2, 2))
    acc = np.empty((2, 2))
    env_c = np.empty(8)  # envelope scratch of the load solve
    env_s = np.empty(8)
    for _ in range(n_steps):
        for j in range(n):
            thermal_rk4(thermal[j], u[j], dt, th_coef, y0, xs, kk, acc)
            # mechanics at the new muscle temperatures
            x_mm = 1e3 * r_eff * (q[j] - q_neutral)
            torque = 0.0
            inv_c = 0.0
            for side in range(2):
                i = j + side * n
                T = thermal[j, side, 0]
                if T > T_hot:
                    flags[j, 0] = True
                T = min(max(T, T_lo), T_hi)
                if T > T_prev[i]:
                    heating[i] = True
                elif T < T_prev[i]:
                    heating[i] = False
                T_prev[i] = T
                if heating[i]:
                    y_mem = p0 * (mem_c[0] * math.tanh(mem_c[1] * T + mem_c[2]) + mem_c[3])
                else:
                    y_mem = p0 * (mem_d[0] * math.tanh(mem_d[1] * T + mem_d[2]) + mem_d[3])
                y_geo = e0 - x_mm if side == 0 else e0 + x_mm
                m, dy, res = _solve_load_into(T, y_geo, w[i], w_now, y_mem, load[i], stacked, edges, r, p, m_lo,
                                              m_hi, scale, c_el, k_f, m_max, tol, max_it, env_c, env_s)
                w[i, :] = w_now
                load[i] = m
                compliance[i] = dy
                if m <= 1e-9 and res > tol:
                    flags[j, 1] = True
                if m >= m_max - 1e-9 and res < -tol:
                    flags[j, 2] = True
                torque += n_g_r * m if side == 0 else -n_g_r * m
                inv_c += 1.0 / dy
            stiffness = n_g_r * 1e3 * r_eff * inv_c
            q[j], qd[j] = joint_step_one(q[j], qd[j], torque, stiffness, payload[j], dt, joint)
            if q[j] <= q_min or q[j] >= q_max:
                flags[j, 3] = True


def thermal_constants(tp) -> np.ndarray:  # type: ignore[no-untyped-def]
    """th_coef (14,) of :func:`step_many` from a thermal.ThermalParams."""
    faces = [[tp._k_at[f], tp._k_t[f], tp._k_tinf[f], tp._k_tc[f], tp._k_r[f], tp._k_inf[f]] for f in (0, 1)]
    return np.array([tp.input_per_volt, tp.coupling_per_s] + faces[0] + faces[1], dtype=float)


def pack_constants(params) -> tuple[np.ndarray, ...]:  # type: ignore[no-untyped-def]
    """The kernel's constant arrays from a plant.PlantParams (see :func:`step_many`)."""
    from sma_wrist.core.joint import G
    tp, hp, mg, jp = params.thermal, params.hysteresis, params.muscle, params.joint
    th_coef = thermal_constants(tp)
    m_lo, m_hi = hp.load_range
    mech = np.array([params.dt, mg.length_scale, mg.elastic_mm_per_kgf, hp.k_f, m_lo, m_hi, mg.max_load_kgf,
                     params.load_tolerance_mm, 60.0, hp.p0, hp.T_valid[0], hp.T_valid[1],
                     params.max_muscle_temperature_C, params.preload_elongation_mm,
                     mg.n_wires * G * jp.r_eff_m, jp.r_eff_m], dtype=float)
    joint = np.array([jp.joint_inertia_kgm2, jp.lever_m, jp.coulomb_Nm, jp.viscous_Nms, jp.static_Nm,
                      jp.stick_velocity_rad_s, jp.q_neutral_rad, jp.q_min_rad, jp.q_max_rad, G], dtype=float)
    env = hp.envelopes
    stacked = np.ascontiguousarray(np.concatenate([env.a, env.b], axis=1).transpose(0, 2, 1))
    return (th_coef, mech, np.ascontiguousarray(stacked), np.ascontiguousarray(env.edges_kg, dtype=float),
            np.ascontiguousarray(hp.thresholds, dtype=float), np.ascontiguousarray(hp.weights, dtype=float),
            np.ascontiguousarray(hp.c, dtype=float), np.ascontiguousarray(hp.d, dtype=float), joint)
