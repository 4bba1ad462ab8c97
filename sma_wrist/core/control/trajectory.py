"""Desired joint angle generators q_d(t) with analytic derivatives (seed Sec. 6.1).

Every generator is a frozen dataclass; calling it on a time array returns the tuple
``(q_d, qdot_d, qddot_d)`` in rad, rad/s, rad/s^2, each with the shape of ``t``. The
back-stepping law (Eq. 5.32) needs qdot_d and qddot_d, so every generator has bounded,
analytic first and second derivatives where that is possible (``step`` with
``rise_time_s = 0`` and the corners of ``ramp`` are the documented exceptions).

Default: the Sec. 6.1 experiment ``q_d = 0.524 + 0.524 sin(0.1 t)`` rad. It peaks at
1.048 rad, 0.6 mrad above pi/3 (the seed rounds 30 deg to 0.524 rad), so the default angle
limits are [0, 1.05] rad rather than [0, 1.047].

A run does not start on q_d(0): :class:`SoftStart` joins any of them from the wrist's measured
angle over a few seconds (trajectory_generator's ``soft_start_s``).

Use :func:`make_trajectory` to build one from a name and keyword arguments (node
parameters); it raises :class:`~sma_wrist.core.errors.ParameterError` naming the bad value and the valid range.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sma_wrist.core.errors import ParameterError, check_finite, format_choices

FloatArray = NDArray[np.float64]
Sample = tuple[FloatArray, FloatArray, FloatArray]

DEFAULT_ANGLE_LIMITS_RAD: tuple[float, float] = (0.0, 1.05)
SEED_OFFSET_RAD = 0.524
SEED_AMPLITUDE_RAD = 0.524
SEED_OMEGA_RAD_S = 0.1
#: the soft start ``sma-wrist run`` gives trajectory_generator [s] (the node's own default is 0: the measured figures
#: of the experiment, sweep and benchmarks are of runs that start on the shape). The muscles start at ambient and
#: the wrist cannot move until the TEMs have warmed one to its transformation (~11 s at 0.3 kg); the
#: inverse_adaptive demo's whole-run max error was 60 / 40 / 32 / 31 % with 20 / 25 / 30 / 35 s (0.3 kg, first
#: 70 s), the sine's own start 0.44 rad away 87 %: 30 s is the shortest on that floor
RUN_SOFT_START_S = 30.0


def smoothstep(t: FloatArray, duration_s: float) -> Sample:
    """The quintic s = 10x^3 - 15x^4 + 6x^5, x = t / duration_s clipped to [0, 1], and its time derivatives.

    s rises from 0 to 1 with zero rate and acceleration at both ends: ds/dt = 30 x^2 (1 - x)^2 / T,
    d2s/dt2 = 60 x (1 - x)(1 - 2x) / T^2 (T = duration_s > 0), both 0 outside (0, T).
    """
    T = duration_s
    x = np.clip(t / T, 0.0, 1.0)
    inside = (t > 0.0) & (t < T)
    s = x**3 * (10 - 15 * x + 6 * x * x)
    ds = np.where(inside, 30 * x * x * (1 - x) ** 2, 0.0)
    dds = np.where(inside, 60 * x * (1 - x) * (1 - 2 * x), 0.0)
    return s, ds / T, dds / (T * T)


def soft_start(reference: Sample, t: ArrayLike, start_rad: ArrayLike, duration_s: float) -> Sample:
    """A reference sample r(t) joined smoothly from the angle start_rad over duration_s [s].

    q_d = q_0 + s (r - q_0),  q_d' = s' (r - q_0) + s r',  q_d'' = s'' (r - q_0) + 2 s' r' + s r''
    with s the quintic :func:`smoothstep` of t over duration_s: q_d starts at q_0 at rest (t <= 0) and is r
    itself, to the last bit, from t = duration_s on. ``start_rad`` may be an array (one start per wrist, the
    sweep's loops); ``t`` and ``reference`` are then shared or of the same shape. duration_s = 0: r as it is.
    """
    r, rd, rdd = reference
    if duration_s == 0.0:
        return r, rd, rdd
    tt = np.asarray(t, dtype=float)
    q0 = np.asarray(start_rad, dtype=float)
    s, ds, dds = smoothstep(tt, duration_s)
    gap = r - q0
    done = tt >= duration_s
    return (
        np.where(done, r, q0 + s * gap),
        np.where(done, rd, ds * gap + s * rd),
        np.where(done, rdd, dds * gap + 2.0 * ds * rd + s * rdd),
    )


class Trajectory(Protocol):
    def __call__(self, t: ArrayLike) -> Sample: ...

    def bounds(self) -> tuple[float, float]: ...


def _time(t: ArrayLike) -> FloatArray:
    """Time as a float array; NaN/inf raise ModelInputError (an input, not a parameter)."""
    if type(t) is float:  # the node's every sample: check the float, not a 0-d array (~2 us)
        check_finite('t', t, 's')
        return np.asarray(t)
    arr = np.asarray(t, dtype=float)
    check_finite('t', arr, 's')
    return arr


def _finite(
    name: str, value: float, lo: float = -math.inf, hi: float = math.inf, unit: str = '', lo_open: bool = False
) -> None:
    ok = isinstance(value, (int, float, np.integer, np.floating)) and math.isfinite(value)
    ok = ok and (value > lo if lo_open else value >= lo) and value <= hi
    if not ok:
        lb = '(' if lo_open else '['
        u = f' {unit}' if unit else ''
        raise ParameterError(f'{name} = {value!r}{u} is outside the valid range {lb}{lo:g}, {hi:g}]')


@dataclass(frozen=True)
class Sine:
    """q_d = offset + amplitude sin(omega t + phase) (Sec. 6.1 with the defaults)."""

    offset_rad: float = SEED_OFFSET_RAD
    amplitude_rad: float = SEED_AMPLITUDE_RAD
    omega_rad_s: float = SEED_OMEGA_RAD_S
    phase_rad: float = 0.0

    def __post_init__(self) -> None:
        _finite('offset_rad', self.offset_rad, unit='rad')
        _finite('amplitude_rad', self.amplitude_rad, 0.0, unit='rad')
        _finite('omega_rad_s', self.omega_rad_s, 0.0, unit='rad/s', lo_open=True)
        _finite('phase_rad', self.phase_rad, unit='rad')

    @property
    def period_s(self) -> float:
        return 2.0 * math.pi / self.omega_rad_s

    def bounds(self) -> tuple[float, float]:
        return self.offset_rad - self.amplitude_rad, self.offset_rad + self.amplitude_rad

    def __call__(self, t: ArrayLike) -> Sample:
        tt = _time(t)
        ph = self.omega_rad_s * tt + self.phase_rad
        a, w = self.amplitude_rad, self.omega_rad_s
        return self.offset_rad + a * np.sin(ph), a * w * np.cos(ph), -a * w * w * np.sin(ph)


@dataclass(frozen=True)
class Step:
    """Step from initial_rad to final_rad at t_step_s.

    rise_time_s > 0 replaces the jump by the quintic smoothstep s = 10x^3 - 15x^4 + 6x^5
    (x = (t - t_step)/rise_time), whose velocity and acceleration are continuous and bounded:
    |qdot| <= 1.875 dq / rise, |qddot| <= 5.774 dq / rise^2. rise_time_s = 0 gives the ideal
    step with zero derivatives everywhere (its impulses are not representable).
    """

    initial_rad: float = 0.0
    final_rad: float = 0.524
    t_step_s: float = 1.0
    rise_time_s: float = 1.0

    def __post_init__(self) -> None:
        _finite('initial_rad', self.initial_rad, unit='rad')
        _finite('final_rad', self.final_rad, unit='rad')
        _finite('t_step_s', self.t_step_s, unit='s')
        _finite('rise_time_s', self.rise_time_s, 0.0, unit='s')

    def bounds(self) -> tuple[float, float]:
        return min(self.initial_rad, self.final_rad), max(self.initial_rad, self.final_rad)

    def __call__(self, t: ArrayLike) -> Sample:
        tt = _time(t)
        dq = self.final_rad - self.initial_rad
        if self.rise_time_s == 0.0:
            q = np.where(tt >= self.t_step_s, self.final_rad, self.initial_rad).astype(float)
            return q, np.zeros_like(q), np.zeros_like(q)
        T = self.rise_time_s
        s, ds, dds = smoothstep(tt - self.t_step_s, T)
        return self.initial_rad + dq * s, dq * ds, dq * dds


@dataclass(frozen=True)
class Ramp:
    """Constant-rate move from start_rad (held until t_start_s) to end_rad, then hold.

    qddot_d is 0 everywhere (the two velocity corners are impulses, not represented);
    use ``step`` with a rise time when a bounded acceleration matters.
    """

    start_rad: float = 0.0
    end_rad: float = 1.047
    rate_rad_s: float = 0.0873  # 5 deg/s, the Sec. 1.5.1 / 6 speed requirement
    t_start_s: float = 0.0

    def __post_init__(self) -> None:
        _finite('start_rad', self.start_rad, unit='rad')
        _finite('end_rad', self.end_rad, unit='rad')
        _finite('rate_rad_s', self.rate_rad_s, 0.0, unit='rad/s', lo_open=True)
        _finite('t_start_s', self.t_start_s, unit='s')

    def bounds(self) -> tuple[float, float]:
        return min(self.start_rad, self.end_rad), max(self.start_rad, self.end_rad)

    def __call__(self, t: ArrayLike) -> Sample:
        tt = _time(t)
        dq = self.end_rad - self.start_rad
        duration = abs(dq) / self.rate_rad_s
        x = np.clip(tt - self.t_start_s, 0.0, duration)
        sgn = math.copysign(1.0, dq) if dq else 0.0
        q = self.start_rad + sgn * self.rate_rad_s * x
        moving = (tt > self.t_start_s) & (tt < self.t_start_s + duration)
        return q, np.where(moving, sgn * self.rate_rad_s, 0.0), np.zeros_like(q)


@dataclass(frozen=True)
class SineSweep:
    """Linear chirp q_d = offset + amplitude sin(psi(t)) from omega0 to omega1 over duration_s.

    psi(t) = omega0 t + (omega1 - omega0) t^2 / (2 duration) for 0 <= t <= duration; after that
    the frequency stays omega1 with a continuous phase, before 0 it is omega0. Derivatives are
    analytic: psi' = omega(t), psi'' = (omega1 - omega0)/duration inside the sweep.
    """

    offset_rad: float = SEED_OFFSET_RAD
    amplitude_rad: float = SEED_AMPLITUDE_RAD
    omega0_rad_s: float = 0.05
    omega1_rad_s: float = 0.5
    duration_s: float = 200.0

    def __post_init__(self) -> None:
        _finite('offset_rad', self.offset_rad, unit='rad')
        _finite('amplitude_rad', self.amplitude_rad, 0.0, unit='rad')
        _finite('omega0_rad_s', self.omega0_rad_s, 0.0, unit='rad/s')
        _finite('omega1_rad_s', self.omega1_rad_s, 0.0, unit='rad/s')
        _finite('duration_s', self.duration_s, 0.0, unit='s', lo_open=True)

    def bounds(self) -> tuple[float, float]:
        return self.offset_rad - self.amplitude_rad, self.offset_rad + self.amplitude_rad

    def __call__(self, t: ArrayLike) -> Sample:
        tt = _time(t)
        w0, w1, T = self.omega0_rad_s, self.omega1_rad_s, self.duration_s
        k = (w1 - w0) / T
        tc = np.clip(tt, 0.0, T)
        psi = w0 * tc + 0.5 * k * tc * tc + w0 * np.minimum(tt, 0.0) + w1 * np.maximum(tt - T, 0.0)
        w = np.where(tt < 0, w0, np.where(tt > T, w1, w0 + k * tc))
        dw = np.where((tt >= 0) & (tt <= T), k, 0.0)
        a = self.amplitude_rad
        s, c = np.sin(psi), np.cos(psi)
        return self.offset_rad + a * s, a * w * c, a * (dw * c - w * w * s)


@dataclass(frozen=True)
class Constant:
    """q_d = value_rad, zero derivatives."""

    value_rad: float = SEED_OFFSET_RAD

    def __post_init__(self) -> None:
        _finite('value_rad', self.value_rad, unit='rad')

    def bounds(self) -> tuple[float, float]:
        return self.value_rad, self.value_rad

    def __call__(self, t: ArrayLike) -> Sample:
        tt = _time(t)
        q = np.full(tt.shape, float(self.value_rad))
        return q, np.zeros_like(q), np.zeros_like(q)


@dataclass(frozen=True)
class SoftStart:
    """``reference`` joined from the wrist's measured angle start_rad over duration_s (:func:`soft_start`).

    A run then starts where the wrist is instead of a step of the reference's first value away from it
    (the Sec. 6.1 sine starts at 0.524 rad, the wrist rests near 0.08 rad at 0.3 kg), so its error over the
    whole run measures tracking, not the start-up transient.
    """

    reference: Any
    start_rad: float
    duration_s: float

    def __post_init__(self) -> None:
        _finite('start_rad', self.start_rad, unit='rad')
        _finite('duration_s', self.duration_s, 0.0, unit='s')

    def bounds(self) -> tuple[float, float]:
        lo, hi = self.reference.bounds()
        return min(lo, self.start_rad), max(hi, self.start_rad)  # q_d lies between q_0 and r(t)

    def __call__(self, t: ArrayLike) -> Sample:
        tt = _time(t)
        return soft_start(self.reference(tt), tt, self.start_rad, self.duration_s)


GENERATORS: dict[str, type] = {
    'sine': Sine,
    'step': Step,
    'ramp': Ramp,
    'sine_sweep': SineSweep,
    'constant': Constant,
}


def make_trajectory(
    name: str = 'sine', angle_limits_rad: tuple[float, float] = DEFAULT_ANGLE_LIMITS_RAD, **kwargs: Any
) -> Trajectory:
    """Build a generator by name and check its whole range lies inside angle_limits_rad.

    Raises ParameterError for an unknown name or keyword, a bad value, or a trajectory that
    leaves the joint's angle limits (the message names the value and the valid range).
    """
    if name not in GENERATORS:
        raise ParameterError(f'trajectory name = {name!r} is not one of {format_choices(GENERATORS)}')
    lo, hi = angle_limits_rad
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise ParameterError(f'angle_limits_rad = {angle_limits_rad!r} must be two finite numbers with lo < hi')
    cls = GENERATORS[name]
    valid = {f.name for f in fields(cls)}
    unknown = set(kwargs) - valid
    if unknown:
        raise ParameterError(f'{name}: unknown parameter(s) {sorted(unknown)}; valid: {format_choices(valid)}')
    traj: Trajectory = cls(**kwargs)
    bmin, bmax = traj.bounds()
    if bmin < lo or bmax > hi:
        bad = bmin if bmin < lo else bmax
        raise ParameterError(f'{name}: q_d reaches {bad:g} rad, outside the angle limits [{lo:g}, {hi:g}] rad')
    return traj


__all__ = [
    'Sine',
    'Step',
    'Ramp',
    'SineSweep',
    'Constant',
    'SoftStart',
    'Trajectory',
    'make_trajectory',
    'soft_start',
    'smoothstep',
    'GENERATORS',
    'DEFAULT_ANGLE_LIMITS_RAD',
    'RUN_SOFT_START_S',
]
