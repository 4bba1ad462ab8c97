"""Compiled per-sample stepping of :class:`sma_wrist.core.plant.wrist.WristPlant` (optional numba).

The plant is a time recursion: at 1 kHz a node steps one wrist at a time, and numpy's
per-call overhead (~50 array operations a step) dominates a 1-wrist step. This module is
the same step written as tight scalar loops over wrists (thermal RK4, Eqs. 4.13-4.14; the
wire-load solve of muscle.py Eq. 1 with the SD-GPI of Eqs. 3.19-3.24, 4.1-4.6; the joint
of Eq. 4.18), compiled by numba when it is installed (``pip install sma_wrist[fast]``).
Without numba the plant uses its numpy path; ``AVAILABLE`` says which.

The uncompiled Python of the same functions (``step_many_into.py_func``) is the "plain
per-sample Python reference loop" of the benchmark. test_plant_kernel checks the kernel
against the numpy path step by step.
"""

from __future__ import annotations

import math

import numpy as np

from sma_wrist.core.hysteresis import phase_fraction_kernel as pfk
from sma_wrist.core.hysteresis.kernel import _solve_load_into
from sma_wrist.core.jit import _jit, _jit_inline, kernel_array
from sma_wrist.core.joint.kernel import joint_step_one
from sma_wrist.core.thermal.kernel import heat_balance_constants, thermal_rk4


@_jit
def step_many(
    n_steps,
    u,
    thermal,
    q,
    qd,
    w,
    heating,
    T_prev,
    load,
    compliance,
    payload,
    flags,
    th_coef,
    mech,
    stacked,
    edges,
    r,
    p,
    mem_c,
    mem_d,
    joint,
):  # pragma: no cover - compiled
    """Advance N wrists by n_steps plant steps under held commands u (N, 2) [V], in place.

    Arrays: thermal (N, 2, 2); q, qd, payload (N,); w (2N, n) and heating, T_prev, load,
    compliance (2N,) stacked [muscle 1 of all wrists, then muscle 2] as in plant.PlantState;
    flags (N, 4) bool out: over_temperature, slack, overload, at_stop (OR over the steps).
    th_coef (16,): input_per_volt, coupling, then per face (muscle, exchanger) the six
    (K_at, K_t, K_Tinf, K_T, K_R, K_inf); (37,) with the Peltier form appended (thermal.kernel.heat_balance_constants).
    mech (16,): dt, scale, c_el, k_f, m_lo, m_hi, m_max, tol, max_it, p0, T_lo, T_hi, T_hot,
    e0_mm, n_g_r, r_eff_m. joint (10,): I_w, lever, coulomb, viscous, static, stick_v,
    q_neutral, q_min, q_max, g.
    """
    w_now, rk, env = scratch(w.shape[1])
    step_many_into(
        n_steps,
        u,
        thermal,
        q,
        qd,
        w,
        heating,
        T_prev,
        load,
        compliance,
        payload,
        flags,
        th_coef,
        mech,
        stacked,
        edges,
        r,
        p,
        mem_c,
        mem_d,
        joint,
        w_now,
        rk,
        env,
    )


@_jit
def step_segments(
    n_steps,
    u,
    thermal,
    q,
    qd,
    w,
    heating,
    T_prev,
    load,
    compliance,
    payload,
    flags,
    th_coef,
    mech,
    stacked,
    edges,
    r,
    p,
    mem_c,
    mem_d,
    joint,
    thermal_out,
    q_out,
    qd_out,
):  # pragma: no cover - compiled
    """:func:`step_many` over K segments in one call: segment k holds commands u[k] (N, 2) [V] for n_steps[k] plant
    steps; the state after each segment goes to thermal_out[k] (N, 2, 2), q_out[k], qd_out[k] (N,). A twin
    replaying measured commands (one per 10 ms sample) pays numba's call overhead once per batch, not per sample."""
    w_now, rk, env = scratch(w.shape[1])
    for k in range(n_steps.size):
        step_many_into(
            n_steps[k],
            u[k],
            thermal,
            q,
            qd,
            w,
            heating,
            T_prev,
            load,
            compliance,
            payload,
            flags,
            th_coef,
            mech,
            stacked,
            edges,
            r,
            p,
            mem_c,
            mem_d,
            joint,
            w_now,
            rk,
            env,
        )
        thermal_out[k] = thermal
        q_out[k] = q
        qd_out[k] = qd


@_jit_inline
def scratch(n_play):  # pragma: no cover - compiled
    """Work arrays of :func:`step_many_into`: w_now (n_play,), RK4 stages (4, 2, 2), envelope (2, 8)."""
    return np.empty(n_play), np.empty((4, 2, 2)), np.empty((2, 8))


@_jit_inline
def step_many_into(
    n_steps,
    u,
    thermal,
    q,
    qd,
    w,
    heating,
    T_prev,
    load,
    compliance,
    payload,
    flags,
    th_coef,
    mech,
    stacked,
    edges,
    r,
    p,
    mem_c,
    mem_d,
    joint,
    w_now,
    rk,
    env,
):  # pragma: no cover - compiled
    """:func:`step_many` with caller-owned work arrays (:func:`scratch`): a caller stepping wrists one
    call at a time (VariedPlant, per scenario) allocates them once, not per wrist and tick."""
    n = q.size
    dt = mech[0]
    scale, c_el, k_f, m_lo, m_hi, m_max, tol = mech[1], mech[2], mech[3], mech[4], mech[5], mech[6], mech[7]
    max_it = int(mech[8])
    p0, T_lo, T_hi, T_hot, e0, n_g_r, r_eff = mech[9], mech[10], mech[11], mech[12], mech[13], mech[14], mech[15]
    q_neutral, q_min, q_max = joint[6], joint[7], joint[8]
    y0, xs, kk, acc = rk[0], rk[1], rk[2], rk[3]
    env_c, env_s = env[0], env[1]  # envelope coefficients and slopes of the load solve
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
                m, dy, res = _solve_load_into(
                    T,
                    y_geo,
                    w[i],
                    w_now,
                    y_mem,
                    load[i],
                    stacked,
                    edges,
                    r,
                    p,
                    m_lo,
                    m_hi,
                    scale,
                    c_el,
                    k_f,
                    m_max,
                    tol,
                    max_it,
                    env_c,
                    env_s,
                )
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


@_jit
def fraction_step_segments(
    n_steps,
    u,
    thermal,
    q,
    qd,
    w,
    heating,
    T_prev,
    load,
    compliance,
    payload,
    flags,
    th_coef,
    mech,
    wc,
    latent,
    joint,
    thermal_out,
    q_out,
    qd_out,
):  # pragma: no cover - compiled
    """:func:`step_segments` of a wrist whose wires are phase-fraction wires (PlantParams.wire; ``wc`` its
    PhaseFractionWire.packed row, ``w`` (2N, 5) their memory, :mod:`sma_wrist.core.hysteresis.phase_fraction_kernel`):
    the same thermal RK4, chain, flags and joint step as :func:`step_many_into`, the wire's load solve in place of the
    SD-GPI's. heating and T_prev are kept as the numpy path keeps them (the wire does not read them). latent (2,)
    [degC]: the muscle nodes' latent heat (Eq. P.4, PlantParams.latent_heat_C; 0: none), applied once the wire's
    fraction is committed, as WristPlant.step does."""
    rk = np.empty((4, 2, 2))
    y0, xs, kk, acc = rk[0], rk[1], rk[2], rk[3]
    n = q.size
    dt = mech[0]
    m_max, tol, max_it = mech[6], mech[7], int(mech[8])
    T_lo, T_hi, T_hot, e0, n_g_r, r_eff = mech[10], mech[11], mech[12], mech[13], mech[14], mech[15]
    q_neutral, q_min, q_max = joint[6], joint[7], joint[8]
    for seg in range(n_steps.size):
        for _ in range(n_steps[seg]):
            for j in range(n):
                thermal_rk4(thermal[j], u[seg, j], dt, th_coef, y0, xs, kk, acc)
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
                    y_geo = e0 - x_mm if side == 0 else e0 + x_mm
                    xi_old = w[i, 0]
                    m, dy, res = pfk.solve_load(wc, T, y_geo, w[i], load[i], m_max, tol, max_it)
                    pfk.commit(wc, T, m, w[i])
                    if latent[side] != 0.0:
                        thermal[j, side, 0] += latent[side] * (w[i, 0] - xi_old)
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
        thermal_out[seg] = thermal
        q_out[seg] = q
        qd_out[seg] = qd


def pack_constants(params) -> tuple[np.ndarray, ...]:  # type: ignore[no-untyped-def]
    """The kernel's constant arrays from a plant.PlantParams (see :func:`step_many`; for a phase-fraction wire
    :func:`fraction_step_segments`'s th_coef, mech, wc, latent, joint)."""
    from sma_wrist.core.joint.dynamics import G

    tp, hp, mg, jp = params.thermal, params.hysteresis, params.muscle, params.joint
    th_coef = heat_balance_constants(tp, params.heat_balance)
    m_lo, m_hi = hp.load_range
    mech = np.array(
        [
            params.dt,
            mg.length_scale,
            mg.elastic_mm_per_kgf,
            hp.k_f,
            m_lo,
            m_hi,
            mg.max_load_kgf,
            params.load_tolerance_mm,
            60.0,
            hp.p0,
            hp.T_valid[0],
            hp.T_valid[1],
            params.max_muscle_temperature_C,
            params.preload_elongation_mm,
            mg.n_wires * G * jp.r_eff_m,
            jp.r_eff_m,
        ],
        dtype=float,
    )
    joint = np.array(
        [
            jp.joint_inertia_kgm2,
            jp.lever_m,
            jp.coulomb_Nm,
            jp.viscous_Nms,
            jp.static_Nm,
            jp.stick_velocity_rad_s,
            jp.q_neutral_rad,
            jp.q_min_rad,
            jp.q_max_rad,
            G,
        ],
        dtype=float,
    )
    if params.wire is not None:
        mech[10], mech[11] = params.wire.T_valid
        latent = params.latent_heat_C()
        latent = np.zeros(2) if latent is None else latent
        return th_coef, mech, params.wire.packed(mg.wire_length_mm, mg.wire_area_m2), latent, joint
    env = hp.envelopes
    stacked = np.ascontiguousarray(np.concatenate([env.a, env.b], axis=1).transpose(0, 2, 1))
    return (
        th_coef,
        mech,
        np.ascontiguousarray(stacked),
        np.ascontiguousarray(env.edges_kg, dtype=float),
        kernel_array(hp.thresholds),
        kernel_array(hp.weights),
        np.ascontiguousarray(hp.c, dtype=float),
        np.ascontiguousarray(hp.d, dtype=float),
        joint,
    )
