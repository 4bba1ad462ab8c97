"""Back-stepping adaptive joint controller (seed Sec. 5.2.2, Eqs. 5.22-5.37; gains Tables 5.5, 6.1).

Plant model of the law (Eq. 5.23, friction neglected, signs as in Eq. 5.31)::

    qddot = (R/I) [(beta_01 v_1 - d_1) - (beta_02 v_2 - d_2)] - phi theta,   phi = g l cos(q) / I

theta is the payload mass (kg), beta_0i = b_i X_0 the unknown gain from muscle i's command
v_i (N, deviation from the pre-load) to its force (Eq. 5.22), d_i the bounded compensation
error (Eq. 5.21). Errors (Eq. 5.24)::

    z1 = q - q_d,   alpha1 = -C1 z1,   z2 = qdot - qdot_d - alpha1,   alpha1_dot = -C1 (qdot - qdot_d)

Control (Eq. 5.32), with s(z2) = sgn(z2) or the boundary layer tanh(z2 / eps)::

    v_ic = -C2 z2 - z1 + alpha1_dot + qddot_d + phi theta_hat - 2 s(z2) D_hat_bi
    v_1  = +I / (2 R beta_hat_01) v_1c,   v_2 = -I / (2 R beta_hat_02) v_2c

Desired muscle forces F_i = F_pre + v_i, clipped to [F_min, F_max]; delta F = F_1 - F_2.

Adaptive laws (Eq. 5.37 corrected so that Eqs. 5.33-5.36 hold; doc/explanation/controllers.md)::

    theta_hat_dot  = -Gamma_a phi z2                   (5.37 prints +; with Eq. 5.33's -phi theta~ it must be -)
    beta_hat_0i_dot = Gamma_bi z2 v_ic / (2 beta_hat_0i)   (5.37 divides by the unknown beta~_0i)
    D_hat_bi_dot   = Gamma_Di z2 s(z2)                  (= Gamma_Di |z2| for sgn; 5.37's minus on D_b2 is wrong)

D_bi is the bound of (R/I)|d_i| in rad/s^2 (the units v_ic has). All estimates are projected
onto boxes (parameters), adaptation is frozen where the forces saturate (anti-windup), and
the estimates are integrated with the controller's own dt by semi-implicit Euler: the laws
use this sample's errors, the output uses the updated estimates.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sma_wrist.core.control import adaptive_kernel
from sma_wrist.core.errors import ModelInputError, ParameterError, check_finite, format_choices

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

Mode = Literal['inverse_adaptive', 'direct_adaptive']
Robust = Literal['tanh', 'sign']
MODES = ('inverse_adaptive', 'direct_adaptive')
ROBUST = ('tanh', 'sign')
KGF_N = 9.80665
N_WIRES = 140


@dataclass(frozen=True)
class ControlGeometry:
    """Geometry the law needs (Table 5.4 and Chapter 2).

    - r_eff_m: chain force -> output torque arm: sprocket pitch radius 7.96e-3 m / step-up 3
      (Table 5.4's 0.75e-3 m would hold only 0.17 kg with 140 wires; doc/explanation/controllers.md).
    - joint_inertia_kgm2: I_w of Table 5.4.
    - known_payload_kg: payload whose inertia M l^2 is added to I_w when it is known (0 = unknown).
    """

    r_eff_m: float = 7.96e-3 / 3.0
    joint_inertia_kgm2: float = 1.04346e-4
    lever_m: float = 0.09
    g_m_s2: float = 9.81
    known_payload_kg: float = 0.0

    def __post_init__(self) -> None:
        for name in ('r_eff_m', 'joint_inertia_kgm2', 'lever_m', 'g_m_s2'):
            _positive(name, getattr(self, name))
        if not (math.isfinite(self.known_payload_kg) and self.known_payload_kg >= 0):
            raise ParameterError(f'known_payload_kg = {self.known_payload_kg!r} is outside the valid range [0, inf)')

    @property
    def inertia_kgm2(self) -> float:
        """I = I_w + M_known l^2 used in phi and in v_i."""
        return self.joint_inertia_kgm2 + self.known_payload_kg * self.lever_m**2


def _positive(name: str, v: float) -> None:
    if not (isinstance(v, (int, float, np.integer, np.floating)) and math.isfinite(v) and v > 0):
        raise ParameterError(f'{name} = {v!r} is outside the valid range (0, inf)')


def _nonneg(name: str, v: float) -> None:
    if not (isinstance(v, (int, float, np.integer, np.floating)) and math.isfinite(v) and v >= 0):
        raise ParameterError(f'{name} = {v!r} is outside the valid range [0, inf)')


def _interval(name: str, b: tuple[float, float], lo_min: float = -math.inf, strict_lo: bool = False) -> None:
    ok = len(b) == 2 and all(math.isfinite(x) for x in b) and b[0] <= b[1]
    ok = ok and (b[0] > lo_min if strict_lo else b[0] >= lo_min)
    if not ok:
        raise ParameterError(
            f'{name} = {b!r} must be (lo, hi), finite, lo <= hi, lo {">" if strict_lo else ">="} {lo_min:g}'
        )


@dataclass(frozen=True)
class AdaptiveParams:
    """Gains, bounds and limits.

    mode: 'inverse_adaptive' adapts theta, beta_01/02, D_b1/b2 (Table 6.1 col. 1);
        'direct_adaptive' adapts theta only, beta_hat and D_hat stay at their initial values
        (Sec. 5.2.2 simulation, Table 6.1 col. 2).
    robust: 'tanh' (default; boundary layer of width boundary_layer_rad_s keeps a 1 kHz loop
        from chattering the muscle forces, at the price of an O(eps) residual) or 'sign' (Eq. 5.32).
    Force defaults: 140 wires x (0.70, 0.775, 0.85) kgf = (961, 1064, 1167) N: the per-wire
        working range of the superelastic plateau, so |delta F| <= 206 N (0.6 kg at 0.09 m).
    """

    mode: Mode = 'inverse_adaptive'
    c1: float = 3.0
    c2: float = 6.5
    gamma_a: float = 0.01
    gamma_b1: float = 0.05
    gamma_b2: float = 0.05
    gamma_d1: float = 0.01
    gamma_d2: float = 0.01
    robust: Robust = 'tanh'
    boundary_layer_rad_s: float = 0.01
    theta0_kg: float = 0.0
    theta_bounds_kg: tuple[float, float] = (0.0, 1.5)
    beta0: float = 1.0
    beta_bounds: tuple[float, float] = (0.2, 5.0)
    d0_rad_s2: float = 0.0
    d_bounds_rad_s2: tuple[float, float] = (0.0, 1000.0)
    preload_N: float = N_WIRES * 0.775 * KGF_N
    force_min_N: float = N_WIRES * 0.70 * KGF_N
    force_max_N: float = N_WIRES * 0.85 * KGF_N
    geometry: ControlGeometry = field(default_factory=ControlGeometry)

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ParameterError(f'mode = {self.mode!r} is not one of {format_choices(MODES)}')
        if self.robust not in ROBUST:
            raise ParameterError(f'robust = {self.robust!r} is not one of {format_choices(ROBUST)}')
        _positive('c1', self.c1)
        _positive('c2', self.c2)
        for name in ('gamma_a', 'gamma_b1', 'gamma_b2', 'gamma_d1', 'gamma_d2'):
            _nonneg(name, getattr(self, name))
        _positive('boundary_layer_rad_s', self.boundary_layer_rad_s)
        _interval('theta_bounds_kg', self.theta_bounds_kg)
        _interval('beta_bounds', self.beta_bounds, 0.0, strict_lo=True)  # beta_hat divides v_i
        _interval('d_bounds_rad_s2', self.d_bounds_rad_s2, 0.0)
        for name, v, b in (
            ('theta0_kg', self.theta0_kg, self.theta_bounds_kg),
            ('beta0', self.beta0, self.beta_bounds),
            ('d0_rad_s2', self.d0_rad_s2, self.d_bounds_rad_s2),
        ):
            if not (math.isfinite(v) and b[0] <= v <= b[1]):
                raise ParameterError(f'{name} = {v!r} is outside its bounds [{b[0]:g}, {b[1]:g}]')
        if not (
            math.isfinite(self.force_min_N)
            and math.isfinite(self.force_max_N)
            and self.force_min_N <= self.preload_N <= self.force_max_N
            and self.force_min_N < self.force_max_N
        ):
            raise ParameterError(
                f'force limits must satisfy force_min_N <= preload_N <= force_max_N, min < max; got '
                f'({self.force_min_N!r}, {self.preload_N!r}, {self.force_max_N!r}) N'
            )

    @classmethod
    def paper_table_6_1(cls, mode: Mode = 'inverse_adaptive', **overrides: object) -> AdaptiveParams:
        """Experiment gains, Table 6.1: inverse adaptive (col. 1) or direct adaptive (col. 2)."""
        if mode == 'inverse_adaptive':
            base = cls(
                mode=mode, c1=3.0, c2=6.5, gamma_a=0.01, gamma_b1=0.05, gamma_b2=0.05, gamma_d1=0.01, gamma_d2=0.01
            )
        elif mode == 'direct_adaptive':
            base = cls(mode=mode, c1=3.0, c2=5.5, gamma_a=0.05, gamma_b1=0.0, gamma_b2=0.0, gamma_d1=0.0, gamma_d2=0.0)
        else:
            raise ParameterError(f'mode = {mode!r} is not one of {format_choices(MODES)}')
        return replace(base, **overrides)  # type: ignore[arg-type]

    @classmethod
    def paper_table_5_5(cls, **overrides: object) -> AdaptiveParams:
        """Simulation gains, Table 5.5: C1 = C2 = 2, Gamma_a = 1, theta adapted only."""
        base = cls(
            mode='direct_adaptive', c1=2.0, c2=2.0, gamma_a=1.0, gamma_b1=0.0, gamma_b2=0.0, gamma_d1=0.0, gamma_d2=0.0
        )
        return replace(base, **overrides)  # type: ignore[arg-type]


@dataclass
class AdaptiveState:
    """Estimates per scenario: theta_hat (n,) kg, beta_hat (n, 2), d_hat (n, 2) rad/s^2 (muscle 1, 2)."""

    theta_hat: FloatArray
    beta_hat: FloatArray
    d_hat: FloatArray

    def copy(self) -> AdaptiveState:
        return AdaptiveState(self.theta_hat.copy(), self.beta_hat.copy(), self.d_hat.copy())


@dataclass(frozen=True)
class ControlOutput:
    """One controller evaluation for n scenarios (all arrays shape (n,) unless noted).

    force_1_N, force_2_N: desired muscle forces at the chain after the limits.
    delta_force_N: force_1_N - force_2_N (what the limits let through).
    delta_force_request_N: v_1 - v_2 before the limits.
    saturated: a force limit was hit (adaptation frozen for that scenario this step).
    """

    force_1_N: FloatArray
    force_2_N: FloatArray
    delta_force_N: FloatArray
    delta_force_request_N: FloatArray
    saturated: BoolArray
    z1: FloatArray
    z2: FloatArray
    v_c: FloatArray  # (n, 2) virtual accelerations v_1c, v_2c, rad/s^2
    theta_hat: FloatArray
    beta_hat: FloatArray  # (n, 2)
    d_hat: FloatArray  # (n, 2)


#: the law's inputs in the order of its stacked rows, with their units (error messages)
INPUTS = (('q', 'rad'), ('qdot', 'rad/s'), ('q_d', 'rad'), ('qdot_d', 'rad/s'), ('qddot_d', 'rad/s^2'))


class AdaptiveController:
    """Back-stepping adaptive controller for n independent scenarios (vectorised).

    ``update`` takes arrays broadcastable to (n,) and returns :class:`ControlOutput`.
    """

    def __init__(self, params: AdaptiveParams | None = None, n: int = 1, theta0_kg: ArrayLike | None = None) -> None:
        self.params = params if params is not None else AdaptiveParams()
        if not (isinstance(n, (int, np.integer)) and n >= 1):
            raise ParameterError(f'n = {n!r} is outside the valid range [1, inf)')
        self.n = int(n)
        self._theta0 = theta0_kg
        self._k: tuple[AdaptiveParams, FloatArray] | None = None  # (params, packed kernel constants)
        self.reset()

    def reset(self) -> None:
        """Estimates back to their initial values."""
        p = self.params
        th0 = np.broadcast_to(
            np.asarray(p.theta0_kg if self._theta0 is None else self._theta0, float), (self.n,)
        ).copy()
        lo, hi = p.theta_bounds_kg
        if np.any(~np.isfinite(th0)) or np.any(th0 < lo) or np.any(th0 > hi):
            raise ParameterError(f'theta0_kg = {th0!r} is outside its bounds [{lo:g}, {hi:g}]')
        self.state = AdaptiveState(th0, np.full((self.n, 2), p.beta0), np.full((self.n, 2), p.d0_rad_s2))

    def update(
        self, q: ArrayLike, qdot: ArrayLike, q_d: ArrayLike, qdot_d: ArrayLike, qddot_d: ArrayLike, dt: float
    ) -> ControlOutput:
        """Advance the estimates by dt (s) with this sample and return the desired forces.

        q, qdot: measured angle (rad) and rate (rad/s); q_d, qdot_d, qddot_d: reference
        (sma_wrist.core.control.trajectory). Raises ModelInputError on non-finite input or dt <= 0.
        """
        if not (isinstance(dt, (int, float, np.integer, np.floating)) and math.isfinite(dt) and dt > 0):
            raise ModelInputError('dt', dt, '(0, inf)', 's')
        raw = (q, qdot, q_d, qdot_d, qddot_d)
        if self.n == 1 and all(type(x) is float and math.isfinite(x) for x in raw):
            stacked = np.array(raw).reshape(5, 1)  # one wrist, finite floats: the node's every sample
        else:
            try:
                stacked = np.empty((5, self.n))
                for i, x in enumerate(raw):
                    stacked[i] = x  # broadcasts scalars and (n,) arrays alike
            except (ValueError, TypeError):
                shapes = [np.shape(x) for x in raw]
                raise ModelInputError(
                    'shapes of (q, qdot, q_d, qdot_d, qddot_d)', shapes, f'broadcastable to ({self.n},)'
                ) from None
            if not np.isfinite(stacked).all():
                for (name, unit), x in zip(INPUTS, raw):
                    check_finite(name, x, unit)  # raises, naming the first non-finite input
        out = self._kernel_step(stacked, dt)
        st = self.state
        return ControlOutput(
            force_1_N=out[:, 0],
            force_2_N=out[:, 1],
            delta_force_N=out[:, 0] - out[:, 1],
            delta_force_request_N=out[:, 2],
            saturated=out[:, 7] != 0.0,
            z1=out[:, 3],
            z2=out[:, 4],
            v_c=out[:, 5:7],
            theta_hat=st.theta_hat.copy(),
            beta_hat=st.beta_hat.copy(),
            d_hat=st.d_hat.copy(),
        )

    def update_stacked(self, x: FloatArray, dt: float) -> FloatArray:
        """:meth:`update` on inputs already stacked as (5, n) rows q, qdot, q_d, qdot_d, qddot_d (units as
        there): the same checks on the rows and the same step, returning the kernel's (n, OUT_LEN) output
        (forces in columns 0-1, the saturated flag in 7) without the ControlOutput record (the sweep's bank,
        every tick)."""
        if not (math.isfinite(dt) and dt > 0):
            raise ModelInputError('dt', dt, '(0, inf)', 's')
        if not np.isfinite(x).all():
            for (name, unit), row in zip(INPUTS, x):
                check_finite(name, row, unit)  # raises, naming the first non-finite input
        return self._kernel_step(x, dt)

    def _kernel_step(self, stacked: FloatArray, dt: float) -> FloatArray:
        """Eqs. 5.24, 5.32, 5.37 per scenario on checked inputs (adaptive_kernel: compiled with numba, else
        plain Python), the estimates in place."""
        p = self.params
        st = self.state
        if self._k is None or self._k[0] is not p:
            self._k = (p, adaptive_kernel.pack(p))
        out = np.empty((self.n, adaptive_kernel.OUT_LEN))
        adaptive_kernel.update(stacked, float(dt), st.theta_hat, st.beta_hat, st.d_hat, self._k[1], out)
        return out


__all__ = ['ControlGeometry', 'AdaptiveParams', 'AdaptiveState', 'ControlOutput', 'AdaptiveController']
