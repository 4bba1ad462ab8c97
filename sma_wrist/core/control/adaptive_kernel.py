"""Scalar loop of the back-stepping adaptive law over scenarios, compiled by numba when present.

:class:`sma_wrist.core.control.adaptive.AdaptiveController` runs one sample of Eqs. 5.24, 5.32 and
5.37 (as corrected there) per call, for n scenarios; in the controller node n = 1 at 100 Hz,
where ~70 numpy calls on 1-element arrays cost ~100 us a sample. Written as a loop over the
scenarios it costs ~2 us compiled (the plant kernel's numba set-up,
:mod:`sma_wrist.core.plant.kernel`), and stays correct, if slower, as plain Python without
numba. The equations and their order are those documented in sma_wrist.core.control.adaptive.
"""

from __future__ import annotations

import math

import numpy as np

from sma_wrist.core.jit import AVAILABLE, _jit

__all__ = ['AVAILABLE', 'K_LEN', 'OUT_LEN', 'pack', 'update', 'warm_up']

#: layout of the packed constants (see :func:`pack`) and of one scenario's output row
K_LEN = 22
OUT_LEN = 9  # f1, f2, dv request, z1, z2, v_c1, v_c2, saturated, (unused)


def pack(p) -> np.ndarray:  # type: ignore[no-untyped-def]
    """Constants of :func:`update` from an AdaptiveParams."""
    g = p.geometry
    adapt = 1.0 if p.mode == 'inverse_adaptive' else 0.0
    eps = p.boundary_layer_rad_s if p.robust == 'tanh' else 0.0  # 0 selects sgn(z2)
    return np.array(
        [
            p.c1,
            p.c2,
            p.gamma_a,
            p.gamma_b1,
            p.gamma_b2,
            p.gamma_d1,
            p.gamma_d2,
            eps,
            p.theta_bounds_kg[0],
            p.theta_bounds_kg[1],
            p.beta_bounds[0],
            p.beta_bounds[1],
            p.d_bounds_rad_s2[0],
            p.d_bounds_rad_s2[1],
            p.preload_N,
            p.force_min_N,
            p.force_max_N,
            g.g_m_s2 * g.lever_m,
            g.inertia_kgm2 / (2.0 * g.r_eff_m),
            adapt,
            g.inertia_kgm2,
            0.0,
        ],
        dtype=float,
    )


@_jit
def _law(base, phi, theta, s, d1, d2, b1, b2, k_v):  # pragma: no cover - compiled
    """Eq. 5.32: virtual accelerations v_1c, v_2c and muscle commands v_1, v_2 [N]."""
    vc1 = (base + phi * theta) - 2.0 * s * d1
    vc2 = (base + phi * theta) - 2.0 * s * d2
    return vc1, vc2, k_v * vc1 / b1, -k_v * vc2 / b2


@_jit
def update(x, dt, theta, beta, d, k, out):  # pragma: no cover - compiled
    """One sample for every scenario j: inputs x (5, n) = q, qdot, q_d, qdot_d, qddot_d; estimates
    theta (n,), beta (n, 2), d (n, 2) advanced in place by dt (semi-implicit Euler, projected
    onto their boxes, frozen where the forces saturate); out (n, OUT_LEN) receives the outputs."""
    c1, c2, g_a, g_b1, g_b2, g_d1, g_d2, eps = k[0], k[1], k[2], k[3], k[4], k[5], k[6], k[7]
    th_lo, th_hi, b_lo, b_hi, d_lo, d_hi = k[8], k[9], k[10], k[11], k[12], k[13]
    pre, f_lo, f_hi, gl, k_v, adapt, inertia = k[14], k[15], k[16], k[17], k[18], k[19], k[20]
    for j in range(x.shape[1]):
        q, qd, qr, qdr, qddr = x[0, j], x[1, j], x[2, j], x[3, j], x[4, j]
        # Eq. 5.24 and the alpha1 derivative from the measured rate
        z1 = q - qr
        z2 = qd - qdr + c1 * z1
        alpha1_dot = -c1 * (qd - qdr)
        phi = gl * math.cos(q) / inertia
        base = -c2 * z2 - z1 + alpha1_dot + qddr
        if eps > 0.0:
            s = math.tanh(z2 / eps)
        else:
            s = 1.0 if z2 > 0 else (-1.0 if z2 < 0 else 0.0)
        th_o, b1_o, b2_o, d1_o, d2_o = theta[j], beta[j, 0], beta[j, 1], d[j, 0], d[j, 1]
        vc1_o, vc2_o, v1_o, v2_o = _law(base, phi, th_o, s, d1_o, d2_o, b1_o, b2_o, k_v)
        # Eq. 5.37 (corrected), then projection onto the boxes
        th_n = min(max(th_o - dt * g_a * phi * z2, th_lo), th_hi)
        b1_n, b2_n, d1_n, d2_n = b1_o, b2_o, d1_o, d2_o
        if adapt != 0.0:
            b1_n = min(max(b1_o + dt * g_b1 * (z2 * vc1_o) / (2.0 * b1_o), b_lo), b_hi)
            b2_n = min(max(b2_o + dt * g_b2 * (z2 * vc2_o) / (2.0 * b2_o), b_lo), b_hi)
            d1_n = min(max(d1_o + dt * g_d1 * (z2 * s), d_lo), d_hi)
            d2_n = min(max(d2_o + dt * g_d2 * (z2 * s), d_lo), d_hi)
        vc1, vc2, v1, v2 = _law(base, phi, th_n, s, d1_n, d2_n, b1_n, b2_n, k_v)
        f1, f2 = pre + v1, pre + v2
        sat = f1 < f_lo or f1 > f_hi or f2 < f_lo or f2 > f_hi
        dv = v1 - v2
        if sat:
            # anti-windup: keep the old estimates and their command; ``saturated`` stays True
            th_n, b1_n, b2_n, d1_n, d2_n = th_o, b1_o, b2_o, d1_o, d2_o
            vc1, vc2, v1, v2 = vc1_o, vc2_o, v1_o, v2_o
            f1, f2 = pre + v1, pre + v2
            dv = v1 - v2
        theta[j], beta[j, 0], beta[j, 1], d[j, 0], d[j, 1] = th_n, b1_n, b2_n, d1_n, d2_n
        out[j, 0] = min(max(f1, f_lo), f_hi)
        out[j, 1] = min(max(f2, f_lo), f_hi)
        out[j, 2] = dv
        out[j, 3] = z1
        out[j, 4] = z2
        out[j, 5] = vc1
        out[j, 6] = vc2
        out[j, 7] = 1.0 if sat else 0.0


def warm_up() -> None:
    """Compile (or load from numba's cache) :func:`update` before a node spins (see
    :func:`sma_wrist.core.control.tem_kernel.warm_up`)."""
    if not AVAILABLE:
        return
    from sma_wrist.core.control.adaptive import AdaptiveParams

    update(
        np.zeros((5, 1)),
        0.01,
        np.zeros(1),
        np.ones((1, 2)),
        np.zeros((1, 2)),
        pack(AdaptiveParams()),
        np.empty((1, OUT_LEN)),
    )
