"""Compiled joint step of Eq. 4.18 (linearly implicit Euler), numba when present.

The numpy reference is :func:`sma_wrist.core.joint.dynamics.joint_step`; every plant whose muscles
drive this joint (the SD-GPI wrist, the phase-fraction benchmark plant, diagnose's replay) calls this.
"""

from __future__ import annotations

import math

from sma_wrist.core.jit import _jit_inline


@_jit_inline
def joint_step_one(qj, qdj, torque, stiffness, payload, dt, joint):  # pragma: no cover - compiled
    """One wrist's joint step, linearly implicit Euler of Eq. 4.18 (joint.joint_step): (q, q').

    torque: net muscle torque [N m]; stiffness: -d torque / dq [N m/rad]; joint (10,) as in
    :func:`~sma_wrist.core.plant.kernel.step_many`. Shared by every plant whose muscles drive this joint.
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
