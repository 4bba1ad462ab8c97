"""Wrist joint: chain/sprocket kinematics and the rigid-body dynamics of Eqs. 4.16-4.18.

Kinematics (Chapter 2): both bundles pull a chain over a sprocket of pitch diameter
15.92 mm; chain stages of 1.5 and 2 step the sprocket rotation up by 3 at the output
shaft. So an output rotation dq moves the chain by R_eff dq with
R_eff = 7.96 mm / 3 = 2.653 mm, and a chain force F gives F R_eff at the output.
Muscle 1 shortens when q grows, muscle 2 lengthens (Eq. 4.17). The pre-loaded,
centred position is q_neutral.

Table 5.4's "sprocket radius" 0.75e-3 m is not used: with it 140 wires x 0.15 kgf would
hold only 0.17 kg at 0.09 m and +-30 deg would need 0.39 mm of chain; with R_eff the
0.6 kg capacity and the ~3 mm stroke both come out (doc/explanation/model.md).

Dynamics, Eq. 4.18 with payload inertia added (the seed's I_w is the bare joint)::

    (I_w + M l^2) q'' = (F1 - F2) R_eff - M g l cos q - tau_f(q', tau_drive)

Friction, Eq. 4.16's text: Coulomb + viscous while sliding, static friction holding the
joint while |tau_drive| <= tau_sf at rest.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
G = 9.81


@dataclass(frozen=True)
class JointParams:
    """Joint and payload parameters (Table 5.4, Chapter 2); SI units."""

    sprocket_pitch_radius_m: float = 15.92e-3 / 2
    step_up: float = 3.0
    joint_inertia_kgm2: float = 1.04346e-4  # I_w, Table 5.4
    lever_m: float = 0.09  # l, payload distance from the axis
    payload_kg: float = 0.3
    coulomb_Nm: float = 0.004  # M_DF, dynamic friction moment (bearings, chain)
    viscous_Nms: float = 0.15  # C_DF: chain + material damping, keeps the joint well damped
    static_Nm: float = 0.006  # tau_sf
    stick_velocity_rad_s: float = 1e-4  # |q'| below which the joint may stick
    q_neutral_rad: float = 0.524  # both bundles at their pre-load elongation here
    q_min_rad: float = -0.35  # mechanical stops
    q_max_rad: float = 1.40

    @property
    def r_eff_m(self) -> float:
        """Chain displacement per output radian [m/rad]."""
        return self.sprocket_pitch_radius_m / self.step_up

    def inertia(self, payload_kg: FloatArray | float | None = None) -> FloatArray:
        m = self.payload_kg if payload_kg is None else payload_kg
        return self.joint_inertia_kgm2 + np.asarray(m) * self.lever_m**2

    def chain_displacement_mm(self, q: FloatArray) -> FloatArray:
        """Chain travel from the neutral position, positive when muscle 1 shortens [mm]."""
        return 1e3 * self.r_eff_m * (np.asarray(q) - self.q_neutral_rad)

    def gravity_torque(self, q: FloatArray, payload_kg: FloatArray | float | None = None) -> FloatArray:
        m = self.payload_kg if payload_kg is None else payload_kg
        return np.asarray(m) * G * self.lever_m * np.cos(q)


def joint_step(
    p: JointParams,
    q: FloatArray,
    qd: FloatArray,
    tau_muscle: FloatArray,
    stiffness: FloatArray,
    payload_kg: FloatArray,
    dt: float,
) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]:
    """One linearly implicit Euler step of Eq. 4.18; returns (q, q', stuck).

    The muscle torque is a stiff spring of the angle (stiffness = -d tau_muscle / dq > 0,
    from the load solve); treating it and the viscous term implicitly keeps the step
    stable for any dt, and Coulomb/static friction is applied explicitly with a stick
    test, so the velocity never crosses zero because of friction alone.
    """
    inertia = p.inertia(payload_kg)
    tau_drive = tau_muscle - p.gravity_torque(q, payload_kg)
    at_rest = np.abs(qd) < p.stick_velocity_rad_s
    stuck = at_rest & (np.abs(tau_drive) <= p.static_Nm)
    direction = np.where(at_rest, np.sign(tau_drive), np.sign(qd))
    h_over_i = dt / inertia
    qd_new = (qd + h_over_i * (tau_drive - direction * p.coulomb_Nm)) / (
        1.0 + h_over_i * (p.viscous_Nms + dt * stiffness)
    )
    # Coulomb friction may stop the joint but never reverse it within a step.
    reversed_ = (~at_rest) & (np.sign(qd_new) != np.sign(qd)) & (np.abs(tau_drive) <= p.static_Nm + p.coulomb_Nm)
    qd_new = np.where(stuck | reversed_, 0.0, qd_new)
    q_new = q + dt * qd_new
    # Mechanical stops: inelastic.
    hit = (q_new < p.q_min_rad) | (q_new > p.q_max_rad)
    if hit.any():
        q_new = np.minimum(np.maximum(q_new, p.q_min_rad), p.q_max_rad)
        qd_new = np.where(hit, 0.0, qd_new)
    return q_new, qd_new, stuck | reversed_
