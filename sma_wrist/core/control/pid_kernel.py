"""Scalar loop of the Sec. 6.1 PID over scenarios, compiled by numba when present.

:class:`sma_wrist.core.control.pid.PID` runs one sample for n scenarios per call; in the controller
node n = 1 at 100 Hz, where ~25 numpy calls on 1-element arrays cost ~25 us a sample. As a
loop over the scenarios it costs ~1 us compiled (the plant kernel's numba set-up,
:mod:`sma_wrist.core.plant.kernel`) and stays correct, if slower for large n, as plain Python
without numba. The equations and their order are those documented in :mod:`sma_wrist.core.control.pid`.
"""

from __future__ import annotations

import numpy as np

from sma_wrist.core.jit import AVAILABLE, _jit

__all__ = ['AVAILABLE', 'OUT_FIELDS', 'pack', 'update', 'warm_up']

#: columns of one scenario's output row (the fields of pid.PIDOutput; saturated as 0/1)
OUT_FIELDS = ('u', 'u_unsat', 'saturated', 'error', 'p_term', 'i_term', 'd_term')
P_MODE_CODES = {'plain': 0, 'p_times_rate': 1, 'p_times_abs_rate': 2}
ANTI_WINDUP_CODES = {'conditional': 0, 'back_calculation': 1, 'none': 2}


def pack(p) -> np.ndarray:  # type: ignore[no-untyped-def]
    """Constants of :func:`update` from a PIDParams."""
    return np.array(
        [
            p.kp,
            p.ki,
            p.kd,
            P_MODE_CODES[p.p_mode],
            1.0 if p.derivative_on == 'measurement' else 0.0,
            p.derivative_filter_s,
            p.output_min,
            p.output_max,
            ANTI_WINDUP_CODES[p.anti_windup],
            p.tracking_time_s,
        ],
        dtype=float,
    )


@_jit
def update(y, r, dt, has_prev, integral, e_prev, y_prev, edot, ydot, k, out):  # pragma: no cover - compiled
    """One sample for every scenario j: measured y (n,) and reference r (n,) [rad], step dt [s].
    The state (integral, previous error and measurement, filtered rates; all (n,)) is advanced
    in place; ``has_prev`` False: first sample, rates 0. out (n, 7) receives OUT_FIELDS."""
    kp, ki, kd, p_mode, on_meas, tau = k[0], k[1], k[2], int(k[3]), k[4] != 0.0, k[5]
    lo, hi, aw, t_track = k[6], k[7], int(k[8]), k[9]
    for j in range(y.shape[0]):
        e = r[j] - y[j]
        if has_prev:  # backward-Euler first-order lag on the backward difference
            edot[j] = (tau * edot[j] + (e - e_prev[j])) / (tau + dt)
            ydot[j] = (tau * ydot[j] + (y[j] - y_prev[j])) / (tau + dt)
        else:
            edot[j] = 0.0
            ydot[j] = 0.0
        e_prev[j] = e
        y_prev[j] = y[j]
        if p_mode == 0:
            P = kp * e
        elif p_mode == 1:
            P = kp * e * edot[j]
        else:
            P = kp * e * abs(edot[j])
        D = -kd * ydot[j] if on_meas else kd * edot[j]
        I = integral[j]
        u = P + I + D
        u_out = min(max(u, lo), hi)
        di = ki * e * dt
        if aw == 0:  # conditional: freeze only when integrating pushes further into the active limit
            if (u > hi and di > 0) or (u < lo and di < 0):
                di = 0.0
        elif aw == 1:
            di = di + (u_out - u) * dt / t_track
        integral[j] = I + di
        out[j, 0] = u_out
        out[j, 1] = u
        out[j, 2] = 1.0 if u != u_out else 0.0
        out[j, 3] = e
        out[j, 4] = P
        out[j, 5] = I
        out[j, 6] = D


def warm_up() -> None:
    """Compile (or load from numba's cache) :func:`update` on dummy data, before a node spins."""
    if not AVAILABLE:
        return
    z = np.zeros(1)
    k = np.array([1.0, 1.0, 1.0, 0.0, 1.0, 0.02, -1.0, 1.0, 0.0, 0.1])
    update(z, z + 0.1, 0.01, True, z.copy(), z.copy(), z.copy(), z.copy(), z.copy(), k, np.empty((1, 7)))
