"""PID joint controller of the Sec. 6.1 comparison (Table 6.1: Kp = 9, Ki = 56, Kd = 5).

Error e = q_d - q (rad). Per step of length dt, for n scenarios at once::

    u = P + I + D,   u_out = clip(u, u_min, u_max)
    P = Kp e                          p_mode 'plain'
      = Kp e edot_f                   p_mode 'p_times_rate'      (Sec. 6.1, literal)
      = Kp e |edot_f|                 p_mode 'p_times_abs_rate'  (direction-preserving reading)
    D = -Kd ydot_f  (derivative_on 'measurement', y = q: no kick on reference steps)
      =  Kd edot_f  (derivative_on 'error')
    I_{k+1} = I_k + Ki e dt  [+ (u_out - u) dt / T_t for back-calculation]

Sec. 6.1: "the PID controller is slightly modified by multiplying the proportional error
with the error rate ... to eliminate the delayed error rate when the error is zero". Read
literally the P term is Kp e edot = Kp d(e^2/2)/dt: it is zero for a constant error and
has the sign of e only while |e| grows; while e < 0 grows (edot < 0) it pushes +u, i.e.
the wrong way, and the integral alone restores. 'p_times_abs_rate' keeps the sign of e.
Both are provided; 'plain' is the default of :class:`PIDParams`, the literal variant is the
default of the :meth:`PIDParams.paper_table_6_1` preset. The seed does not say what u is
(the PID's output feeds the temperature loop); here it is in the caller's units (e.g. N of
net chain force), and the limits are in the same units.

Derivatives (edot_f, ydot_f) are backward differences through a first-order filter of time
constant tau (s/(tau s + 1), backward Euler): d_k = (tau d_{k-1} + x_k - x_{k-1}) / (tau + dt);
the first sample gives 0. Anti-windup: 'conditional' (integration stops while the output is
saturated and e would drive it further), 'back_calculation' (tracking time T_t) or 'none'.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sma_wrist.core.control import pid_kernel
from sma_wrist.core.errors import ModelInputError, ParameterError, check_finite, format_choices

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

PMode = Literal['plain', 'p_times_rate', 'p_times_abs_rate']
P_MODES = ('plain', 'p_times_rate', 'p_times_abs_rate')
D_ON = ('measurement', 'error')
ANTI_WINDUP = ('conditional', 'back_calculation', 'none')


@dataclass(frozen=True)
class PIDParams:
    """Gains (output units per rad, per rad s, per rad/s), limits and options."""

    kp: float = 9.0
    ki: float = 56.0
    kd: float = 5.0
    p_mode: PMode = 'plain'
    derivative_on: Literal['measurement', 'error'] = 'measurement'
    derivative_filter_s: float = 0.02
    output_min: float = -206.0  # N of net chain force: 140 wires x +-0.075 kgf around the pre-load
    output_max: float = 206.0
    anti_windup: Literal['conditional', 'back_calculation', 'none'] = 'conditional'
    tracking_time_s: float = 0.1

    def __post_init__(self) -> None:
        for name in ('kp', 'ki', 'kd'):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ParameterError(f'{name} = {v!r} is outside the valid range [0, inf)')
        for name, v, choices in (
            ('p_mode', self.p_mode, P_MODES),
            ('derivative_on', self.derivative_on, D_ON),
            ('anti_windup', self.anti_windup, ANTI_WINDUP),
        ):
            if v not in choices:
                raise ParameterError(f'{name} = {v!r} is not one of {format_choices(choices)}')
        if not (math.isfinite(self.derivative_filter_s) and self.derivative_filter_s >= 0):
            raise ParameterError(
                f'derivative_filter_s = {self.derivative_filter_s!r} is outside the valid range [0, inf)'
            )
        if not (math.isfinite(self.tracking_time_s) and self.tracking_time_s > 0):
            raise ParameterError(f'tracking_time_s = {self.tracking_time_s!r} is outside the valid range (0, inf)')
        if not (self.output_min < self.output_max) or math.isnan(self.output_min) or math.isnan(self.output_max):
            raise ParameterError(
                f'output limits ({self.output_min!r}, {self.output_max!r}) need output_min < output_max'
            )

    @classmethod
    def paper_table_6_1(cls, p_mode: PMode = 'p_times_rate', **overrides: object) -> PIDParams:
        """Table 6.1 PID column (Kp 9, Ki 56, Kd 5) with the Sec. 6.1 P x error-rate modification."""
        return replace(cls(kp=9.0, ki=56.0, kd=5.0, p_mode=p_mode), **overrides)  # type: ignore[arg-type]


@dataclass(frozen=True)
class PIDOutput:
    """One evaluation for n scenarios: u after the limits, its parts and the saturation flag."""

    u: FloatArray
    u_unsat: FloatArray
    saturated: BoolArray
    error: FloatArray
    p_term: FloatArray
    i_term: FloatArray  # integral state used in this output
    d_term: FloatArray


class PID:
    """Discrete PID for n independent scenarios (arrays broadcastable to (n,))."""

    def __init__(self, params: PIDParams | None = None, n: int = 1) -> None:
        self.params = params if params is not None else PIDParams()
        if not (isinstance(n, (int, np.integer)) and n >= 1):
            raise ParameterError(f'n = {n!r} is outside the valid range [1, inf)')
        self.n = int(n)
        self.reset()

    def reset(self) -> None:
        self.integral = np.zeros(self.n)
        self._has_prev = False
        self._e_prev = np.zeros(self.n)
        self._y_prev = np.zeros(self.n)
        self._edot = np.zeros(self.n)
        self._ydot = np.zeros(self.n)
        self._k: tuple[PIDParams, FloatArray] | None = None

    def update(self, q: ArrayLike, q_d: ArrayLike, dt: float) -> PIDOutput:
        """One control step: measured angle q, reference q_d (rad), step dt (s).

        The law above runs as one loop over the scenarios (:mod:`sma_wrist.core.control.pid_kernel`,
        compiled with numba when installed).
        """
        p = self.params
        if not (isinstance(dt, (int, float, np.integer, np.floating)) and math.isfinite(dt) and dt > 0):
            raise ModelInputError('dt', dt, '(0, inf)', 's')
        check_finite('q', q, 'rad')
        check_finite('q_d', q_d, 'rad')
        try:
            y = np.ascontiguousarray(np.broadcast_to(np.asarray(q, float), (self.n,)))
            r = np.ascontiguousarray(np.broadcast_to(np.asarray(q_d, float), (self.n,)))
        except ValueError:
            raise ModelInputError(
                'q.shape, q_d.shape', (np.shape(q), np.shape(q_d)), f'broadcastable to ({self.n},)'
            ) from None
        if self._k is None or self._k[0] is not p:
            self._k = (p, pid_kernel.pack(p))
        out = np.empty((self.n, len(pid_kernel.OUT_FIELDS)))
        pid_kernel.update(
            y,
            r,
            float(dt),
            self._has_prev,
            self.integral,
            self._e_prev,
            self._y_prev,
            self._edot,
            self._ydot,
            self._k[1],
            out,
        )
        self._has_prev = True
        return PIDOutput(
            u=out[:, 0],
            u_unsat=out[:, 1],
            saturated=out[:, 2] != 0.0,
            error=out[:, 3],
            p_term=out[:, 4],
            i_term=out[:, 5],
            d_term=out[:, 6],
        )


def warm_up() -> None:
    """Compile (or load from numba's cache) the kernel in both signatures a node calls, before it spins: the
    kernel's own on dummy arrays, and :meth:`PID.update`'s, which passes the angles as read-only broadcast views
    (compiled inside the loop before). Here, beside the class, so the kernel module need not import it."""
    pid_kernel.warm_up()
    PID().update(0.0, 0.1, 0.01)


__all__ = ['PIDParams', 'PIDOutput', 'PID', 'warm_up']
