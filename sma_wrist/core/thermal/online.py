"""Online estimate of a TEM's drive gain, muscle-face losses and ambient (Eqs. 4.13-4.15) in closed loop.

The TEM law (Eqs. 5.44-5.47) and its observer integrate Table 4.9's heat balance. A real module's
drive gain, its losses to the air and the coolant temperature differ from it by tens of percent
and degrees (the off-model family's ranges: +-30 %, +-30 %, +-5 degC), and with the plant's own heat balance the
inverse mode's median max error over the family falls from 12.8 to 8.0 % (``plants.oracle``,
variant ``thermal``, seed 2). The loop has what it takes to learn them: the commands it sends and
the thermocouples it reads. Per wrist, the scales

    theta = (g, s, a):  input_per_volt x g;  the muscle face's K_Tinf, K_T, K_inf x s;
                        both faces' ambient + a [degC]                              (Eqs. 4.13-4.15)

are the three numbers ``sma_wrist.core.plant.extensions.plant_params`` perturbs (``tem_gain_err``,
``loss_scale_err``, ``ambient_offset_C``), estimated by an extended Kalman filter on windows of
``window_s``: from the faces at the window's start (the muscle face from the thermocouple, its lag
undone with the slope of the last samples; the exchanger face the estimator's own prediction), the
recorded commands drive the heat balance (RK4 at the samples' steps) and a first-order
thermocouple (``tc_lag_s``); the residuals are the measured minus predicted junction temperature,
averaged over ``avg_s`` at ``points`` times in the window, per muscle; the Jacobian is by finite
differences (three more runs of the same window). Both muscles of a wrist share theta. Random-walk
process noise lets it follow a drift; every scale stays in :data:`BOUNDS`.

Units: temperatures degC, commands V, times s. Vectorised over wrists (N); one wrist in a node.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from sma_wrist.core.errors import ParameterError
from sma_wrist.core.jit import AVAILABLE
from sma_wrist.core.thermal import heat_balance as th
from sma_wrist.core.thermal import kernel as thermal_kernel
from sma_wrist.core.thermal.kernel import N_COEF, thermal_constants

FloatArray = NDArray[np.float64]

#: (low, high) of g, s [1] and a [degC]: the extensions' validity ranges
BOUNDS = np.array([[0.5, 1.5], [0.5, 1.5], [-10.0, 10.0]])
#: finite-difference steps of g, s, a for the Jacobian
STEPS = np.array([0.02, 0.02, 0.5])
NOMINAL_THETA = np.array([1.0, 1.0, 0.0])
#: a longer time between two samples breaks the window [s]: the commands in force over it are not known
MAX_GAP_S = 0.5


@dataclass(frozen=True)
class OnlineThermalParams:
    """Estimator settings.

    window_s: length of one prediction window [s]; points, avg_s: residual times per window and
        muscle, each an average over avg_s [s] of the samples before it; tc_lag_s: the
        thermocouple's first-order lag the prediction assumes [s]; prior_sd: prior standard
        deviation of (g, s, a); walk_sd_per_sqrt_s: random walk of (g, s, a) per sqrt(s);
        noise_sd_C: standard deviation of one residual (noise after averaging plus model error) [degC];
        max_step: the most one window may move (g, s, a) (a trust region: the Jacobian is a local one);
        apply_after_s: the estimate is used (``ThermalScaleEstimator.ready``) from this long after
        the first sample on [s]: the very first windows, before the loop has swept the temperatures, fit
        little; until it is used, the TEM loop's face protection predicts a stronger TEM's unmeasured hot
        faces on the model's gain (doc/explanation/controllers.md: 10 s, not 30 s).
    """

    window_s: float = 2.0
    points: int = 4
    avg_s: float = 0.3
    tc_lag_s: float = 0.1
    prior_sd: tuple[float, float, float] = (0.2, 0.2, 4.0)
    walk_sd_per_sqrt_s: tuple[float, float, float] = (0.002, 0.002, 0.02)
    noise_sd_C: float = 0.15
    max_step: tuple[float, float, float] = (0.05, 0.05, 1.0)
    apply_after_s: float = 10.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.window_s) and 0.2 <= self.window_s <= 60.0):
            raise ParameterError(f'window_s = {self.window_s!r} s must be in [0.2, 60] s')
        if not (isinstance(self.points, (int, np.integer)) and 1 <= self.points <= 50):
            raise ParameterError(f'points = {self.points!r} must be an integer in [1, 50]')
        if not (np.isfinite(self.avg_s) and 0 < self.avg_s <= self.window_s / self.points):
            raise ParameterError(f'avg_s = {self.avg_s!r} s must be in (0, window_s / points]')
        if not (np.isfinite(self.tc_lag_s) and 0 <= self.tc_lag_s <= 5.0):
            raise ParameterError(f'tc_lag_s = {self.tc_lag_s!r} s must be in [0, 5] s')
        if not (np.isfinite(self.apply_after_s) and self.apply_after_s >= 0):
            raise ParameterError(f'apply_after_s = {self.apply_after_s!r} s must be >= 0')
        for name in ('prior_sd', 'walk_sd_per_sqrt_s', 'max_step'):
            v = np.asarray(getattr(self, name), dtype=float)
            if v.shape != (3,) or not np.all(np.isfinite(v)) or np.any(v < 0):
                raise ParameterError(f'{name} = {getattr(self, name)!r} must be three finite numbers >= 0')
        if not (np.isfinite(self.noise_sd_C) and self.noise_sd_C > 0):
            raise ParameterError(f'noise_sd_C = {self.noise_sd_C!r} degC must be > 0')


def scaled_constants(base: th.ThermalParams, theta: FloatArray) -> FloatArray:
    """th_coef rows (..., N_COEF) of :func:`~sma_wrist.core.thermal.kernel.thermal_constants` for scales theta (..., 3).

    Same arithmetic as ``plant_params``: K_inf = (K_Tinf - K_T) x ambient per face (Eq. 4.15)."""
    theta = np.asarray(theta, dtype=float)
    c = np.broadcast_to(thermal_constants(base), theta.shape[:-1] + (N_COEF,)).copy()
    g, s, a = theta[..., 0], theta[..., 1], theta[..., 2]
    amb = np.asarray(base.effective_ambient_C)
    loss = np.array([base.muscle_face.loss_per_s, base.exchanger_face.loss_per_s])
    c[..., 0] *= g
    for k in (4, 5):  # muscle face K_Tinf, K_T
        c[..., k] *= s
    c[..., 7] = s * loss[0] * (amb[0] + a)
    c[..., 13] = loss[1] * (amb[1] + a)
    return c


def theta_of(base: th.ThermalParams, thermal: th.ThermalParams) -> FloatArray:
    """The scales (g, s, a) that turn ``base`` into ``thermal`` where it is such a scaling (a test's truth)."""
    g = thermal.input_per_volt / base.input_per_volt
    s = thermal.muscle_face.K_T_inf / base.muscle_face.K_T_inf
    a = thermal.effective_ambient_C[1] - base.effective_ambient_C[1]
    return np.array([g, s, a])


def _rates(x: FloatArray, u: FloatArray, c: FloatArray) -> FloatArray:
    """dT/dt of Eqs. 4.13-4.14, x (M, 2 layers, 2 faces), u (M, 2), per-row constants c (M, N_COEF)."""
    cur = -c[:, 0, None] * c[:, 14:16] * u  # (M, 2) model input I per layer (each TEM's own drive gain)
    out = np.empty_like(x)
    for f in range(2):
        b = 2 + 6 * f
        o = 1 - f
        k = c[:, b : b + 6, None]  # (M, 6, 1): K_at, K_t, K_Tinf, K_T, K_R, K_inf
        out[:, :, f] = (
            (k[:, 4] * cur + k[:, 0] * x[:, :, f] + k[:, 1] * x[:, :, o]) * cur
            - k[:, 2] * x[:, :, f]
            + k[:, 3] * x[:, :, o]
            + k[:, 5]
        )
    coupling = c[:, 1, None]
    out[:, :, 0] += coupling * (x[:, ::-1, 0] - x[:, :, 0])
    return out


def _rk4(x: FloatArray, u: FloatArray, dt: float, c: FloatArray) -> FloatArray:
    k1 = _rates(x, u, c)
    k2 = _rates(x + 0.5 * dt * k1, u, c)
    k3 = _rates(x + 0.5 * dt * k2, u, c)
    k4 = _rates(x + dt * k3, u, c)
    return x + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)


class ThermalScaleEstimator:
    """theta of N wrists from their samples (module docstring); :meth:`constants` for the TEM loop.

    Per sample: :meth:`sample` with the measured muscle temperatures and the commands in force *from*
    this sample on. True when a window closed and theta moved.
    """

    def __init__(self, base: th.ThermalParams, n: int, params: OnlineThermalParams = OnlineThermalParams()) -> None:
        if n < 1:
            raise ParameterError(f'n = {n} wrists must be >= 1')
        self.base, self.n, self.params = base, int(n), params
        self.theta = np.tile(NOMINAL_THETA, (self.n, 1))
        self.P = np.tile(np.diag(np.square(params.prior_sd)), (self.n, 1, 1))
        self.updates = 0
        self.t_first: float | None = None
        self.ready = False  # True once apply_after_s has passed: the consumer uses :meth:`constants`
        self._t: list[float] = []
        self._T: list[FloatArray] = []
        self._u: list[FloatArray] = []
        self._x0: FloatArray | None = None
        self._x_end: FloatArray | None = None  # faces at the last window's end under the estimate then
        self._recent: list[tuple[float, FloatArray]] = []  # the last samples, for the start's slope

    def constants(self) -> FloatArray:
        """(N, N_COEF) th_coef rows of the current estimate."""
        return scaled_constants(self.base, self.theta)

    def sample(self, t: float, T_meas: FloatArray, command_V: FloatArray) -> bool:
        """One sample at t [s]: T_meas (N, 2) [degC], command_V (N, 2) [V] held until the next sample.
        Only these: two consumers fed the same samples (tem_controller, hysteresis_compensator) agree."""
        # copies: a caller's command array is updated in place by the next sample
        T = np.array(T_meas, dtype=float).reshape(self.n, 2)
        u = np.array(command_V, dtype=float).reshape(self.n, 2)
        if not (np.all(np.isfinite(T)) and np.all(np.isfinite(u))) or (self._t and t - self._t[-1] > MAX_GAP_S):
            self._restart()  # a bad sample or a gap (lost data, TEMs switched off between samples) breaks the window
            return False
        self._recent.append((t, T))
        p = self.params
        if self.t_first is None:
            self.t_first = t
        self.ready = self.ready or t - self.t_first >= p.apply_after_s
        while self._recent and t - self._recent[0][0] > p.avg_s + 1e-9:
            self._recent.pop(0)
        if self._x0 is None:
            if len(self._recent) < 3:
                return False
            self._x0 = self._start()
            self._t, self._T, self._u = [t], [T], [u]
            return False
        self._t.append(t)
        self._T.append(T)
        self._u.append(u)
        if t - self._t[0] < p.window_s - 1e-9:
            return False
        moved = self._update()
        self._x0 = self._start()
        self._t, self._T, self._u = [t], [T], [u]
        return moved

    def break_window(self) -> None:
        """Forget the window in progress (the commands it recorded are no longer the ones in force, e.g. the
        TEMs were switched off between samples); the estimate so far stays."""
        self._restart()

    def _restart(self) -> None:
        self._x0, self._x_end, self._t, self._T, self._u, self._recent = None, None, [], [], [], []

    def _start(self) -> FloatArray:
        """Faces at a window's start: the muscle face is the junction reading plus lag x its slope; the
        exchanger face is the estimator's own (the last window's prediction; at first, rest at zero drive)."""
        x0 = (th.rest_state(self.base, self.n) if self._x_end is None else self._x_end).copy()
        ts = np.array([r[0] for r in self._recent])
        Ts = np.stack([r[1] for r in self._recent])  # (K, N, 2)
        tc = ts - ts.mean()
        # elementwise sums, not a BLAS product: one wrist's numbers do not depend on how many are estimated
        slope = (tc[:, None, None] * (Ts - Ts.mean(axis=0))).sum(axis=0) / max(float(np.sum(tc * tc)), 1e-12)
        x0[:, :, th.MUSCLE_FACE] = Ts[-1] + self.params.tc_lag_s * slope
        return x0

    def _predict(self, theta: FloatArray, compiled: bool | None = None) -> tuple[FloatArray, FloatArray]:
        """Junction temperatures (K, M, 2) at the window's samples for scales theta (M, 3), M = N x variants,
        and the faces (M, 2, 2) at its end. ``compiled`` (None: numba if installed) runs
        :func:`~sma_wrist.core.thermal.kernel.predict_junction` (~50x faster: a node's window costs ~0.5 ms,
        not ~25 ms in its callback); False the numpy code below, the reference."""
        m = theta.shape[0]
        reps = m // self.n
        c = scaled_constants(self.base, theta)
        if AVAILABLE if compiled is None else compiled:
            out, x_end = np.empty((len(self._t), m, 2)), np.empty((m, 2, 2))
            thermal_kernel.predict_junction(
                np.ascontiguousarray(self._x0),
                np.ascontiguousarray(self._T[0]),
                np.ascontiguousarray(np.stack(self._u)),
                np.asarray(self._t, dtype=float),
                c,
                reps,
                float(self.params.tc_lag_s),
                out,
                x_end,
            )
            return out, x_end
        x = np.repeat(self._x0, reps, axis=0)
        z = np.repeat(self._T[0], reps, axis=0)
        lag = self.params.tc_lag_s
        out = np.empty((len(self._t), m, 2))
        out[0] = z
        for k in range(1, len(self._t)):
            dt = self._t[k] - self._t[k - 1]
            x = _rk4(x, np.repeat(self._u[k - 1], reps, axis=0), dt, c)
            z = x[:, :, th.MUSCLE_FACE] if lag <= 0 else z + dt / (lag + dt) * (x[:, :, th.MUSCLE_FACE] - z)
            out[k] = z
        return out, x

    def _update(self) -> bool:
        p = self.params
        t = np.asarray(self._t)
        T = np.stack(self._T)  # (K, N, 2)
        ends = t[0] + p.window_s * np.arange(1, p.points + 1) / p.points
        masks = [(t > e - p.avg_s - 1e-9) & (t <= e + 1e-9) for e in ends]
        if any(not m.any() for m in masks):
            return False
        # theta and one finite-difference step per scale, wrist-major: rows [w0 theta, w0 +g, w0 +s, w0 +a, w1 ...]
        var = np.repeat(self.theta, 4, axis=0)
        for j in range(3):
            var[j + 1 :: 4, j] += STEPS[j]
        pred, x_end = self._predict(var)
        pred = pred.reshape(len(t), self.n, 4, 2)
        r = np.stack([T[m].mean(axis=0) - pred[m, :, 0].mean(axis=0) for m in masks], axis=1)  # (N, points, 2)
        J = np.stack(
            [
                np.stack([(pred[m, :, j + 1] - pred[m, :, 0]).mean(axis=0) / STEPS[j] for m in masks], axis=1)
                for j in range(3)
            ],
            axis=-1,
        )  # (N, points, 2, 3)
        r = r.reshape(self.n, -1)
        J = J.reshape(self.n, -1, 3)
        if not (np.all(np.isfinite(r)) and np.all(np.isfinite(J)) and np.all(np.isfinite(x_end))):
            self._x_end = None
            return False
        R = p.noise_sd_C**2 * np.eye(r.shape[1])
        S = J @ self.P @ J.transpose(0, 2, 1) + R
        K = self.P @ J.transpose(0, 2, 1) @ np.linalg.inv(S)
        step = np.clip((K @ r[:, :, None])[:, :, 0], -np.asarray(p.max_step), np.asarray(p.max_step))
        theta = self.theta + step
        self.P = (np.eye(3) - K @ J) @ self.P + np.diag(np.square(p.walk_sd_per_sqrt_s)) * (t[-1] - t[0])
        self.theta = np.clip(theta, BOUNDS[:, 0], BOUNDS[:, 1])
        self._x_end = x_end.reshape(self.n, 4, 2, 2)[:, 0]
        self.updates += 1
        return True


def with_scales(base: th.ThermalParams, theta: FloatArray) -> th.ThermalParams:
    """One wrist's ThermalParams for scales theta (3,): ``base`` as ``plant_params`` perturbs it."""
    g, s, a = (float(v) for v in theta)
    return base.scaled(gain=g, losses=s, ambient_shift_C=a)


def warm_up() -> None:
    """Compile (or load from numba's cache) the estimate's window prediction before a node spins: a throwaway
    estimator fed one short window runs the code path of the real one. On a cold cache its first window compiled
    inside tem_controller's and hysteresis_compensator's callbacks, 2 s into a run, for seconds
    (:func:`sma_wrist.core.control.tem_kernel.warm_up`)."""
    if not AVAILABLE:
        return
    est = ThermalScaleEstimator(th.ThermalParams(), 1, OnlineThermalParams(window_s=0.2, points=1, avg_s=0.1))
    T, u = np.full((1, 2), 30.0), np.zeros((1, 2))
    for k in range(25):  # three samples start the window, 0.2 s of them close it
        est.sample(0.01 * k, T + 0.01 * k, u)


__all__ = [
    'OnlineThermalParams',
    'ThermalScaleEstimator',
    'scaled_constants',
    'theta_of',
    'with_scales',
    'warm_up',
    'BOUNDS',
]
