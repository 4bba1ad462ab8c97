"""Feedback-linearising TEM temperature controller (seed Sec. 5.2, Eqs. 5.38-5.47).

Per face f of a module, Eqs. 4.13/4.14 are quadratic in the model input I
(:func:`sma_wrist.core.thermal.heat_balance.rate_terms`)::

    dT_f/dt = K_R I^2 + B_f I + D_f,
    B_f = K_at T_f + K_t T_other,   D_f = -K_Tinf T_f + K_T T_other + K_inf       (5.38-5.40)

Asking for the closed loop de/dt + k e = 0 with e = T_d - T (Eq. 5.42; the seed has k = 1,
here ``gain_per_s``) means dT_f/dt = dT_d/dt + k e (Eq. 5.41), so I is a root of (Eq. 5.44-5.45)::

    a I^2 + b I + c = 0,   a = K_R,  b = B_f,  c = D_f - k (T_d - T_f) - dT_d/dt.

Eq. 5.44 as printed has ``- T_1 + T_1d`` in c_1, i.e. ``+ k e``: with it the error obeys
de/dt = +e and grows. Eqs. 5.41-5.43 have the sign used here (test_tem_control checks the
closed loop). Eq. 5.38 also swaps alpha_1/alpha_2 between its rows; the Table 4.9 column of
each face settles that.

Root (Eq. 5.46): the smaller-magnitude root, computed as c / q with
q = -(b + sign(b) sqrt(b^2 - 4ac)) / 2 (no cancellation). It is the branch that tends to the
linear inverse -c/b as K_R -> 0, is continuous wherever b != 0 (b keeps its sign on the
whole physical window: it vanishes only near T = 0 degC), and lies on the side of the parabola
where dT/dt is monotone in I with the sign of b, so it is a true local inverse. The two
roots sum to -b/K_R (|b|/K_R = 0.69 T on the T1 face, 0.79 T on T2 at uniform T), so for
faces above ~15 degC the other root lies outside the command limits (test_tem_control).
When b^2 < 4ac no input reaches the demanded rate; the controller then takes the vertex
-b / (2a), the input that comes closest, and flags ``no_root``. Every command is then clipped
to the thermal command limits and flagged ``saturated``: nothing is clipped silently.

Modes (Eq. 5.47): one module with I = h1 I_1 + h2 I_2 (the seed's Figs. 5.23-5.25, h = (1, 1)),
or two layers, one controller per layer with h = (1, 0) acting on the muscle face
(Figs. 5.26-5.28). Commands come out in volts, u = -I / input_per_volt, positive heats the
muscle (T1) face (doc/explanation/model.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sma_wrist.core.control import tem_kernel
from sma_wrist.core.errors import ModelInputError, ParameterError, check_finite
from sma_wrist.core.jit import kernel_array
from sma_wrist.core.thermal import heat_balance as th
from sma_wrist.core.thermal import kernel as thermal_kernel
from sma_wrist.core.thermal.online import OnlineThermalParams, ThermalScaleEstimator, scaled_constants, with_scales

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

TWO_LAYER_WEIGHTS = (1.0, 0.0)
SEED_ONE_MODULE_WEIGHTS = (1.0, 1.0)


@dataclass(frozen=True)
class TemControlParams:
    """Controller parameters.

    - gain_per_s: k of the error dynamics de/dt + k e = 0 (Eq. 5.42; the seed uses 1) [1/s].
    - weights: (h1, h2) of Eq. 5.47 on the (muscle/T1, exchanger/T2) faces; (1, 0) = two layers.
    - rate_filter_s: time constant of the first-order filter on the estimated dT_d/dt [s]
      (only :class:`TemController` estimates; 0 = raw backward difference).
    - target_filter_s: 1 / omega of a prefilter on the desired temperatures [s] (only
      :class:`TemLoop`; 0 = none): the critically damped tracking filter
      (2 omega s + omega^2) / (s + omega)^2, which follows a ramp without lag (a first-order
      filter of the same time constant lags it by that time, 2.5 % of the sine's range at
      0.5 s). The muscle follows its target with the error dynamics' time constant
      1 / gain_per_s; target content faster than that (sensor noise amplified by the joint
      law, the inverse's jumps between branches) cannot move the muscle, only reverse the
      TEM (doc/explanation/controllers.md).
    - chatter_limit_per_s: the chatter guard (only :class:`TemLoop` and the sweep's bank; 0 = off,
      :class:`ChatterGuard`): a wrist whose TEM commands change sign more often than this
      [1/s], averaged over ``chatter_window_s`` [s], runs its rate filter at
      ``chatter_rate_filter_s`` [s] until the rate falls below half the limit.
    """

    gain_per_s: float = 1.0
    weights: tuple[float, float] = TWO_LAYER_WEIGHTS
    rate_filter_s: float = 0.0
    target_filter_s: float = 0.0
    chatter_limit_per_s: float = 0.0
    chatter_window_s: float = 20.0
    chatter_rate_filter_s: float = 0.2

    def __post_init__(self) -> None:
        if not (np.isfinite(self.gain_per_s) and self.gain_per_s > 0):
            raise ParameterError(f'gain_per_s = {self.gain_per_s!r} must be finite and > 0')
        if len(self.weights) != 2 or not np.all(np.isfinite(self.weights)) or not any(self.weights):
            raise ParameterError(f'weights = {self.weights!r} must be two finite numbers, not both 0')
        if not (np.isfinite(self.rate_filter_s) and self.rate_filter_s >= 0):
            raise ParameterError(f'rate_filter_s = {self.rate_filter_s!r} must be finite and >= 0')
        if not (np.isfinite(self.target_filter_s) and self.target_filter_s >= 0):
            raise ParameterError(f'target_filter_s = {self.target_filter_s!r} must be finite and >= 0')
        if not (np.isfinite(self.chatter_limit_per_s) and self.chatter_limit_per_s >= 0):
            raise ParameterError(f'chatter_limit_per_s = {self.chatter_limit_per_s!r} must be finite and >= 0')
        if not (np.isfinite(self.chatter_window_s) and self.chatter_window_s > 0):
            raise ParameterError(f'chatter_window_s = {self.chatter_window_s!r} must be finite and > 0')
        if not (np.isfinite(self.chatter_rate_filter_s) and self.chatter_rate_filter_s >= 0):
            raise ParameterError(f'chatter_rate_filter_s = {self.chatter_rate_filter_s!r} must be finite and >= 0')

    def rate_filter_for(self, engaged: ArrayLike) -> FloatArray:
        """The rate filter [s] of a wrist whose chatter guard is ``engaged`` (a bool, or one per wrist)."""
        return np.where(engaged, self.chatter_rate_filter_s, self.rate_filter_s)


#: commands inside +-this band keep the last sign: the chattering metric's band [V] (doc/explanation/controllers.md
#: "Chattering metric and limit"; sweep.simulate.sign_changes_per_s counts with it)
CHATTER_DEADBAND_V = 1.0
#: tem_controller's chatter guard (``chatter_guard.*``): engaged above 2.5 sign changes a second over ~20 s,
#: a quarter above the 2 /s limit the guard serves (the built-in wire's nominal loops run at 1.7 /s and
#: pass 2 /s for a while on their first cycles; 2 /s over 10 s switched them in, at 5.1-5.7 % error instead
#: of 2.7-3.8 %); its rate filter 0.2 s (doc/explanation/controllers.md)
CHATTER_LIMIT_PER_S, CHATTER_WINDOW_S, CHATTER_RATE_FILTER_S = 2.5, 20.0, 0.2


class ChatterGuard:
    """Sign changes of n wrists' TEM commands per second, and which wrists chatter (TemControlParams.chatter_*).

    Per TEM, a sign change (commands inside +-CHATTER_DEADBAND_V keep the last sign) adds 1 / window to an
    exponentially forgetting rate r [1/s] (time constant ``window_s``): r is the sign changes per second
    of the last ~window. A wrist is ``engaged`` from the sample one of its TEMs' r exceeds ``limit_per_s``
    until both are below half of it. Why a rate filter then: on a steep measured wire the inverse's answer
    relays across the loop's gap, and the law's feed-forward of dT_d/dt turns each relay step into a
    full-scale swing (doc/explanation/controllers.md); a 0.2 s filter on that estimate halves the
    swings there, but costs the built-in wire's nominal tracking, so it is only switched in where the
    commands chatter.
    """

    def __init__(self, n: int, limit_per_s: float, window_s: float) -> None:
        self.limit_per_s, self.window_s = float(limit_per_s), float(window_s)
        self.sign = np.zeros((n, 2))  # last sign outside the band, 0 before the first
        self.rate = np.zeros((n, 2))  # [1/s]
        self.engaged = np.zeros(n, bool)
        self.t_last: float | None = None

    def _decay(self, t: float) -> float:
        """The rates' forgetting factor since the last sample (the C library's exp: one scalar for every wrist)."""
        dt = 0.0 if self.t_last is None else t - self.t_last
        self.t_last = t
        return math.exp(-dt / self.window_s)

    def update(self, t: float, command_V: FloatArray) -> BoolArray:
        """Take the commands (n, 2) [V] in force from t [s] on; returns the wrists whose state changed."""
        s = np.where(np.abs(command_V) > CHATTER_DEADBAND_V, np.sign(command_V), 0.0)
        flip = (s != 0.0) & (self.sign != 0.0) & (s != self.sign)
        self.sign = np.where(s != 0.0, s, self.sign)
        self.rate = self.rate * self._decay(t) + flip / self.window_s
        worst = self.rate.max(axis=1)
        now = np.where(self.engaged, worst >= 0.5 * self.limit_per_s, worst > self.limit_per_s)
        changed = now != self.engaged
        self.engaged = now
        return changed

    def update_one(self, t: float, command_V: FloatArray) -> bool:
        """:meth:`update` for one wrist (n = 1), commands (2,), in Python floats with the same operations:
        tem_controller's path, where numpy's per-call cost on (1, 2) arrays was ~12 us a sample (measured)."""
        decay = self._decay(t)
        worst = 0.0
        for k, u in enumerate(command_V.tolist()):
            s = (1.0 if u > 0.0 else -1.0) if abs(u) > CHATTER_DEADBAND_V else 0.0
            last = float(self.sign[0, k])
            flip = s != 0.0 and last != 0.0 and s != last
            if s != 0.0:
                self.sign[0, k] = s
            r = float(self.rate[0, k]) * decay + (1.0 if flip else 0.0) / self.window_s
            self.rate[0, k] = r
            worst = max(worst, r)
        was = bool(self.engaged[0])
        now = worst >= 0.5 * self.limit_per_s if was else worst > self.limit_per_s
        self.engaged[0] = now
        return now != was


@dataclass
class TemControlResult:
    """One controller evaluation for N scenarios and L layers."""

    command_V: FloatArray  # (N, L) drive voltage after saturation, positive heats the T1 face
    current: FloatArray  # (N, L) model input I = -input_per_volt * tem_gain[l] * command_V
    face_current: FloatArray  # (N, L, 2) I_1, I_2 of Eq. 5.46 before weighting and saturation
    no_root: BoolArray  # (N, L, 2) demanded rate unreachable (vertex used); False where the weight is 0
    saturated: BoolArray  # (N, L) command clipped to the limits

    @property
    def any_flag(self) -> BoolArray:
        """(N, L) True where the linearising law could not be applied as is."""
        return self.saturated | self.no_root.any(axis=-1)


def quadratic_coefficients(
    thermal: th.ThermalParams, state: ArrayLike, T_d: ArrayLike, T_d_rate: ArrayLike, gain_per_s: float = 1.0
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(a, b, c) of a I^2 + b I + c = 0 per face (Eqs. 5.44-5.45, sign of e as in Eq. 5.42).

    state, T_d, T_d_rate: (N, L, 2) degC, degC, degC/s (broadcastable to the state).
    """
    T = np.asarray(state, dtype=float)
    A, B, D = th.rate_terms(thermal, T)
    c = D - gain_per_s * (np.asarray(T_d, dtype=float) - T) - np.asarray(T_d_rate, dtype=float)
    return np.broadcast_to(A, T.shape), B, c


def small_root(a: ArrayLike, b: ArrayLike, c: ArrayLike) -> tuple[FloatArray, BoolArray]:
    """Smaller-magnitude real root of a x^2 + b x + c (a > 0) and a mask of where it exists (Eq. 5.46).

    Where b^2 < 4ac the vertex -b / (2a) is returned (closest approach) and the mask is False.
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    c = np.asarray(c, dtype=float)
    disc = b * b - 4.0 * a * c
    real = disc >= 0
    sgn = np.where(b >= 0, 1.0, -1.0)
    q = -0.5 * (b + sgn * np.sqrt(np.maximum(disc, 0.0)))
    # q = 0 only when b = c = 0; a near-zero q gives an infinite root, which the callers clip to
    # the drive limits and report as saturation
    with np.errstate(divide='ignore', invalid='ignore', over='ignore'):
        root = np.where(q != 0, c / np.where(q != 0, q, 1.0), 0.0)
        vertex = -b / (2.0 * a)
    return np.where(real, root, vertex), real


def _one_wrist(state: FloatArray, compiled: bool | None) -> bool:
    """Whether a call on ``state`` goes to the compiled one-wrist kernels (tem_kernel): one
    scenario of two layers and numba present (``compiled=None``), or forced (True/False)."""
    if compiled is None:
        return tem_kernel.AVAILABLE and state.shape == (1, 2, 2)
    return compiled and state.shape == (1, 2, 2)


def _kernel_constants(thermal: th.ThermalParams) -> FloatArray:
    coef = _KERNEL_CONSTANTS.get(id(thermal))
    if coef is None or coef[0] is not thermal:
        coef = _KERNEL_CONSTANTS[id(thermal)] = (thermal, thermal_kernel.thermal_constants(thermal))
    return coef[1]


#: id(ThermalParams) -> (params, th_coef); params are frozen, so the packed constants stay valid
_KERNEL_CONSTANTS: dict[int, tuple[th.ThermalParams, FloatArray]] = {}


def feedback_linearising_command(
    thermal: th.ThermalParams,
    state: ArrayLike,
    T_d: ArrayLike,
    T_d_rate: ArrayLike,
    params: TemControlParams = TemControlParams(),
    *,
    compiled: bool | None = None,
) -> TemControlResult:
    """Eqs. 5.44-5.47 for N scenarios of L modules: per-face roots, weighted sum, saturation.

    state (N, L, 2) degC; T_d and T_d_rate broadcastable to it (degC, degC/s), one target per
    face (faces with weight 0 are ignored, but must be finite). Raises ModelInputError on
    non-finite inputs. One wrist of two layers runs in :func:`~sma_wrist.core.control.tem_kernel.linearising_command`
    when numba is installed (``compiled``: None = that choice, False = numpy here).
    """
    T = th.check_state(state)
    T_d = np.broadcast_to(np.asarray(T_d, dtype=float), T.shape)
    rate = np.broadcast_to(np.asarray(T_d_rate, dtype=float), T.shape)
    check_finite('desired temperature', T_d, 'degC')
    check_finite('desired temperature rate', rate, 'degC/s')
    if _one_wrist(T, compiled):
        command, face = np.empty((1, 2)), np.empty((1, 2, 2))
        no_root, saturated = np.empty((1, 2, 2), bool), np.empty((1, 2), bool)
        if not tem_kernel.linearising_command(
            kernel_array(T[0]),
            kernel_array(T_d[0]),
            kernel_array(rate[0]),
            _kernel_constants(thermal),
            float(params.gain_per_s),
            np.asarray(params.weights, dtype=float),
            thermal.u_min_V,
            thermal.u_max_V,
            command[0],
            face[0],
            no_root[0],
            saturated[0],
        ):
            raise ModelInputError('TEM command', float('nan'), '(finite numbers)', 'V')
        return TemControlResult(command, th.model_input(thermal, command), face, no_root, saturated)
    a, b, c = quadratic_coefficients(thermal, T, T_d, rate, params.gain_per_s)
    face_current, real = small_root(a, b, c)
    h = np.asarray(params.weights, dtype=float)
    current = face_current @ h  # Eq. 5.47
    command, saturated = th.saturate_command(thermal, th.command_from_input(thermal, current))
    return TemControlResult(command, th.model_input(thermal, command), face_current, ~real & (h != 0), saturated)


def observer_step(
    thermal: th.ThermalParams, state: ArrayLike, command_V: ArrayLike, dt: float, *, compiled: bool | None = None
) -> FloatArray:
    """The controller's observer between samples: faces (N, L, 2) [degC] after the commands
    (N, L) [V] in force were held for dt [s] (thermal.step, RK4 of Eqs. 4.13-4.14; inputs are
    the controller's own, already checked). One wrist runs in :func:`~sma_wrist.core.control.tem_kernel.observer_step`
    when numba is installed (``compiled`` as in :func:`feedback_linearising_command`)."""
    T = np.asarray(state, dtype=float)
    if _one_wrist(T, compiled):
        x = np.array(T[0])
        tem_kernel.observer_step(
            x,
            np.ascontiguousarray(np.asarray(command_V, dtype=float).reshape(2)),
            float(dt),
            _kernel_constants(thermal),
        )
        return x[None]
    return th.step(thermal, T, command_V, dt, validate=False)


@dataclass(frozen=True)
class TemperatureObserverParams:
    """:class:`MuscleTemperatureObserver`'s parameters.

    correction_s: time constant with which the estimate is pulled toward the measurement [s]
        (the innovation gain per sample is dt / (correction_s + dt)); between samples the heat
        balance under the commands in force carries it.
    tc_lag_s: first-order lag of the thermocouple the observer assumes [s] (0: none); the
        estimate is of the muscle, the measurement of the junction behind it.
    """

    correction_s: float = 0.33
    tc_lag_s: float = 0.2

    def __post_init__(self) -> None:
        for name in ('correction_s', 'tc_lag_s'):
            v = getattr(self, name)
            if not (np.isfinite(v) and 0.0 <= v <= 10.0):
                raise ParameterError(f'{name} = {v!r} s must be in [0, 10] s')


class MuscleTemperatureObserver:
    """Muscle temperatures of N wrists estimated from noisy, lagged thermocouples (Luenberger).

    State: the faces (N, 2 layers, 2) of the heat balance (Eqs. 4.13-4.14, the controllers'
    ThermalParams) and the junction temperature z (N, 2). Per sample, with the commands (N, 2) [V]
    in force since the previous one held for dt [s]:

        x <- RK4 step of the heat balance (:func:`observer_step`),
        z <- z + dt / (tc_lag_s + dt) (x_muscle - z),                 (thermocouple lag)
        r = T_meas - z,  x_muscle += L r,  z += L r,  L = dt / (correction_s + dt).

    Unlike a filter of the measurement alone it neither lags the muscle nor overshoots it: the
    motion between samples is the heat balance's, driven by the commands, so the path the SD-GPI
    memory observes is one a wire can take (doc/explanation/controllers.md).
    The first sample initialises it at the measurement (exchanger faces at rest).
    """

    def __init__(
        self, thermal: th.ThermalParams, params: TemperatureObserverParams = TemperatureObserverParams()
    ) -> None:
        self.thermal = thermal
        self.params = params
        self.faces: FloatArray | None = None  # (N, 2, 2) degC
        self.junction: FloatArray | None = None  # (N, 2) degC
        # (N, 16) per-wrist heat balances (the online estimate's, core.thermal.online); None: ``thermal`` for all
        self.coef_rows: FloatArray | None = None

    def update(self, T_meas: ArrayLike, command_V: ArrayLike, dt: float) -> FloatArray:
        """One sample: measured junction temperatures (N, 2) [degC], commands (N, 2) [V] held over the
        last dt [s]; returns the estimated muscle temperatures (N, 2) [degC]. Raises ModelInputError on
        a non-finite measurement or command (the estimate is then unchanged)."""
        T = np.asarray(T_meas, dtype=float)
        u = np.asarray(command_V, dtype=float)
        check_finite('measured muscle temperature', T, 'degC')
        check_finite('TEM command', u, 'V')
        if self.faces is None or self.junction is None or self.faces.shape[0] != T.shape[0]:
            self.faces = th.rest_state(self.thermal, T.shape[0])
            self.faces[:, :, th.MUSCLE_FACE] = T
            self.junction = T.copy()
            return T.copy()
        if not (np.isfinite(dt) and dt > 0):
            raise ModelInputError('observer time step', dt, '(0, inf)', 's')
        if self.coef_rows is None:
            faces = observer_step(self.thermal, self.faces, u, min(dt, self.thermal.dt_max_s), compiled=False)
        else:  # row by row: a wrist's numbers do not depend on how many are observed together
            faces = self.faces.copy()
            tem_kernel.observer_step_rows(
                faces, np.ascontiguousarray(u), min(dt, self.thermal.dt_max_s), np.ascontiguousarray(self.coef_rows)
            )
        muscle = faces[:, :, th.MUSCLE_FACE]
        p = self.params
        z = self.junction + dt / (p.tc_lag_s + dt) * (muscle - self.junction)
        gain = dt / (p.correction_s + dt)
        r = T - z
        muscle += gain * r
        self.faces, self.junction = faces, z + gain * r
        return muscle.copy()


def two_layer_command(
    thermal: th.ThermalParams, state: ArrayLike, T_d_muscle: ArrayLike, T_d_rate: ArrayLike, gain_per_s: float = 1.0
) -> TemControlResult:
    """Two layers (Fig. 5.26): one controller per layer on its muscle face, h = (1, 0).

    state (N, L, 2); T_d_muscle and T_d_rate (N, L) desired muscle temperatures and rates.
    """
    T = th.check_state(state)
    T_d = np.array(T, dtype=float)  # exchanger-face targets are unused (h2 = 0): e = 0 there
    T_d[..., th.MUSCLE_FACE] = T_d_muscle
    rate = np.zeros_like(T)
    rate[..., th.MUSCLE_FACE] = T_d_rate
    return feedback_linearising_command(thermal, T, T_d, rate, TemControlParams(gain_per_s, TWO_LAYER_WEIGHTS))


def one_module_command(
    thermal: th.ThermalParams,
    state: ArrayLike,
    T_d_faces: ArrayLike,
    T_d_rate: ArrayLike,
    weights: tuple[float, float] = SEED_ONE_MODULE_WEIGHTS,
    gain_per_s: float = 1.0,
) -> TemControlResult:
    """The seed's first plan (Fig. 5.23): one module, targets on both faces, I = h1 I_1 + h2 I_2.

    state (N, 1, 2) or (N, 2); T_d_faces and T_d_rate (N, 2) targets of the (T1, T2) faces.
    """
    T = np.asarray(state, dtype=float)
    if T.ndim == 2:
        T = T[:, None, :]
    T_d = np.asarray(T_d_faces, dtype=float)
    rate = np.asarray(T_d_rate, dtype=float)
    return feedback_linearising_command(
        thermal,
        T,
        T_d.reshape(T_d.shape[:-1] + (1, 2)) if T_d.ndim == 2 else T_d,
        rate.reshape(rate.shape[:-1] + (1, 2)) if rate.ndim == 2 else rate,
        TemControlParams(gain_per_s, tuple(weights)),
    )


class TemController:
    """Stateful wrapper: keeps the previous target to estimate dT_d/dt when it is not given.

    The estimate is the backward difference (T_d(t) - T_d(t_prev)) / (t - t_prev), filtered by
    a first-order lag of ``params.rate_filter_s``; it is 0 on the first call.
    """

    def __init__(self, thermal: th.ThermalParams, params: TemControlParams = TemControlParams()) -> None:
        self.thermal = thermal
        self.params = params
        self.reset()

    def reset(self) -> None:
        self._t_prev: float | None = None
        self._T_d_prev: FloatArray | None = None
        self._rate: FloatArray | None = None

    def estimate_rate(self, t: float, T_d: FloatArray) -> FloatArray:
        """Update and return the filtered dT_d/dt estimate (same shape as T_d)."""
        if self._t_prev is None or self._T_d_prev is None or self._T_d_prev.shape != T_d.shape:
            raw = np.zeros_like(T_d)
            self._rate = raw
        else:
            dt = t - self._t_prev
            if not (np.isfinite(dt) and dt > 0):
                raise ModelInputError('controller time step', dt, '(0, inf)', 's')
            raw = (T_d - self._T_d_prev) / dt
            alpha = dt / (self.params.rate_filter_s + dt)
            assert self._rate is not None
            self._rate = self._rate + alpha * (raw - self._rate)
        self._t_prev = t
        self._T_d_prev = T_d.copy()
        return self._rate

    def update(self, t: float, state: ArrayLike, T_d: ArrayLike, T_d_rate: ArrayLike | None = None) -> TemControlResult:
        """Command for state (N, L, 2) and per-face targets T_d (N, L, 2) at time t [s].

        With weights (1, 0) the exchanger-face targets are ignored; pass anything finite.
        """
        T = th.check_state(state)
        T_d_arr = np.array(np.broadcast_to(np.asarray(T_d, dtype=float), T.shape))
        check_finite('desired temperature', T_d_arr, 'degC')
        rate = self.estimate_rate(t, T_d_arr) if T_d_rate is None else T_d_rate
        return feedback_linearising_command(self.thermal, T, T_d_arr, rate, self.params)


def _story(
    thermal: th.ThermalParams,
    mode: str,
    reference: str,
    duration_s: float = 400.0,
    dt: float = 0.05,
    trace: bool = False,
) -> dict[str, Any]:
    """Closed loop from rest as in Sec. 5.2; returns error and command statistics after 200 s.

    With ``trace`` also the time series: 't' (K,), 'T' and 'T_d' (K, 2) muscle temperatures.
    """
    ph = np.array([0.0, np.pi])
    refs = {
        'step 60/40': lambda t: (np.array([60.0, 40.0]), np.zeros(2)),
        'seed sine 50+-30, 0.1 rad/s': lambda t: (50 + 30 * np.sin(0.1 * t + ph), 3.0 * np.cos(0.1 * t + ph)),
        'slow sine 45+-20, 0.02 rad/s': lambda t: (45 + 20 * np.sin(0.02 * t + ph), 0.4 * np.cos(0.02 * t + ph)),
    }
    ref = refs[reference]
    T = th.rest_state(thermal, 1, 1 if mode == 'one module' else 2)
    k_tail = int(round(200.0 / dt))
    e_max = np.zeros(2)
    e_sq = np.zeros(2)
    u_lo, u_hi, T_hi, flagged = np.inf, -np.inf, -np.inf, 0
    K = int(round(duration_s / dt))
    tr_T, tr_Td = np.empty((K, 2)), np.empty((K, 2))
    for k in range(K):
        T_d, rate = ref(k * dt)
        tr_Td[k] = T_d
        tr_T[k] = T[0, 0] if mode == 'one module' else T[0, :, th.MUSCLE_FACE]  # faces of one module, or muscle faces
        if mode == 'one module':
            r = one_module_command(thermal, T, T_d[None], rate[None], SEED_ONE_MODULE_WEIGHTS)
            e = T_d - T[0, 0]
        else:
            r = two_layer_command(thermal, T, T_d[None], rate[None])
            e = T_d - T[0, :, th.MUSCLE_FACE]
        T = th.step(thermal, T, r.command_V, dt)
        T_hi = max(T_hi, float(T.max()))
        if k >= k_tail:
            e_max = np.maximum(e_max, np.abs(e))
            e_sq += e * e
            u_lo, u_hi = min(u_lo, float(r.command_V.min())), max(u_hi, float(r.command_V.max()))
            flagged += int(r.any_flag.any())
    n = int(round(duration_s / dt)) - k_tail
    rms = np.sqrt(e_sq / n)
    out: dict[str, Any] = {
        'max_e1': e_max[0],
        'max_e2': e_max[1],
        'rms_e1': rms[0],
        'rms_e2': rms[1],
        'u_min': u_lo,
        'u_max': u_hi,
        'T_max': T_hi,
        'flagged_fraction': flagged / n,
    }
    if trace:
        out.update(t=np.arange(K) * dt, T=tr_T, T_d=tr_Td)
    return out


def _main() -> None:  # pragma: no cover - the report quoted in doc/explanation/model.md
    default = th.ThermalParams()
    wide = default.with_limits(-30.0, 30.0)
    print('Closed loop from rest, k = 1 /s, dt = 0.05 s, statistics over 200-400 s')
    print(
        f'{"limits":>10} {"mode":>11} {"reference":>29} | max|e1| max|e2| rms e1 rms e2 [degC]'
        ' | u range [V] | max face T | flagged'
    )
    for name, p in (('+-30 V', wide), ('default', default)):
        for mode in ('one module', 'two layers'):
            for ref in ('step 60/40', 'seed sine 50+-30, 0.1 rad/s', 'slow sine 45+-20, 0.02 rad/s'):
                s = _story(p, mode, ref)
                print(
                    f'{name:>10} {mode:>11} {ref:>29} | {s["max_e1"]:7.3f} {s["max_e2"]:7.3f} {s["rms_e1"]:6.3f}'
                    f' {s["rms_e2"]:6.3f} | {s["u_min"]:+6.2f} {s["u_max"]:+6.2f} | {s["T_max"]:7.2f}'
                    f' | {s["flagged_fraction"]:.2f}'
                )


if __name__ == '__main__':  # pragma: no cover
    _main()


@dataclass(frozen=True)
class DriveLimits:
    """Transient drive limits with face protection (doc/explanation/model.md).

    The thermal model's ``u_min_V``/``u_max_V`` are *hold* limits: a command held forever
    keeps every face inside the window. A temperature controller never holds its extreme
    command; it may drive up to the driver rating (``boost_*``) as long as the faces stay
    inside the TEM's operating window.

    predictive (default): a command is allowed when the heat balance, started from the
    (observed) faces with that command held for ``horizon_s``, keeps every face of its layer
    inside [``face_min_C``, ``face_max_C``]; otherwise the allowed command nearest to the request
    is sent. The fixed switch it replaces (hold limits once a face passes ``protect_above_C``)
    let faces reach 84.5 degC for 24 s of a 252 s run (thermal inertia after the switch) and
    cut the authority the sine's peak needs (doc/explanation/controllers.md). A layer with a face already
    outside the window gets the hold limits regardless (the backstop when the model is wrong).
    predictive=False: the fixed switch at ``protect_above_C``.
    """

    boost_min_V: float = -24.0
    boost_max_V: float = 24.0
    protect_above_C: float = 75.0
    predictive: bool = True
    face_min_C: float = 0.0
    face_max_C: float = 80.0
    horizon_s: float = 3.0

    def __post_init__(self) -> None:
        if not (
            np.isfinite(self.boost_min_V) and np.isfinite(self.boost_max_V) and self.boost_min_V < 0 < self.boost_max_V
        ):
            raise ParameterError(f'boost limits ({self.boost_min_V!r}, {self.boost_max_V!r}) V must bracket 0')
        if not np.isfinite(self.protect_above_C):
            raise ParameterError(f'protect_above_C = {self.protect_above_C!r} must be finite')
        if not (np.isfinite(self.face_min_C) and np.isfinite(self.face_max_C) and self.face_min_C < self.face_max_C):
            raise ParameterError(
                f'face window ({self.face_min_C!r}, {self.face_max_C!r}) degC must be finite, min < max'
            )
        if not (np.isfinite(self.horizon_s) and 0 < self.horizon_s <= 30.0):
            raise ParameterError(f'horizon_s = {self.horizon_s!r} must be in (0, 30] s')


#: candidate commands tried by the predictive protection, as fractions of the boost range (1 V steps at +-24 V)
_CANDIDATES = np.linspace(0.0, 1.0, 49)  # includes 0 V


def _held_faces_inside(
    thermal: th.ThermalParams, limits: DriveLimits, T: FloatArray, U: FloatArray
) -> tuple[BoolArray, FloatArray]:
    """Hold each command of U (K, N, L) for the horizon from faces T (N, L, 2): (inside (K, N, L),
    how far the faces leave the window [degC])."""
    K = U.shape[0]
    X = np.broadcast_to(T, (K,) + T.shape).reshape(-1, T.shape[-2], 2)
    Uf = np.ascontiguousarray(U).reshape(-1, T.shape[-2])
    n = max(1, int(np.ceil(limits.horizon_s / thermal.dt_max_s)))
    hi_T, lo_T = X.max(axis=-1), X.min(axis=-1)
    for _ in range(n):
        X = th.step(thermal, X, Uf, limits.horizon_s / n, validate=False)
        hi_T, lo_T = np.maximum(hi_T, X.max(axis=-1)), np.minimum(lo_T, X.min(axis=-1))
    excess = (np.maximum(hi_T - limits.face_max_C, 0.0) + np.maximum(limits.face_min_C - lo_T, 0.0)).reshape(U.shape)
    return excess == 0.0, excess


def safe_command_range(
    thermal: th.ThermalParams, limits: DriveLimits, state: ArrayLike, *, compiled: bool | None = None
) -> tuple[FloatArray, FloatArray]:
    """(lo, hi) [V], shape (N, L): the commands that, held for the horizon from the faces in
    ``state`` (N, L, 2), keep every face of their layer inside the window (1 V grid over the boost
    range). Where none does, both are the command that leaves the window least. One wrist of two
    layers runs in :func:`~sma_wrist.core.control.tem_kernel.held_command_range` when numba is installed (``compiled`` as
    in :func:`feedback_linearising_command`)."""
    T = np.asarray(state, dtype=float)
    cand = limits.boost_min_V + _CANDIDATES * (limits.boost_max_V - limits.boost_min_V)
    if _one_wrist(T, compiled):
        lo, hi = np.empty((1, 2)), np.empty((1, 2))
        n = max(1, int(np.ceil(limits.horizon_s / thermal.dt_max_s)))
        tem_kernel.held_command_range(
            np.ascontiguousarray(T[0]),
            cand,
            float(limits.horizon_s),
            n,
            float(limits.face_min_C),
            float(limits.face_max_C),
            _kernel_constants(thermal),
            lo[0],
            hi[0],
        )
        return lo, hi
    wide = replace(thermal, u_min_V=limits.boost_min_V, u_max_V=limits.boost_max_V)
    U = np.broadcast_to(cand[:, None, None], (cand.size,) + T.shape[:-1])
    safe, excess = _held_faces_inside(wide, limits, T, U)
    lo = np.where(safe, U, np.inf).min(axis=0)
    hi = np.where(safe, U, -np.inf).max(axis=0)
    least = np.take_along_axis(U, np.argmin(excess, axis=0)[None], 0)[0]
    none = ~safe.any(axis=0)
    return np.where(none, least, lo), np.where(none, least, hi)


def protected_command(
    thermal: th.ThermalParams,
    limits: DriveLimits,
    state: ArrayLike,
    command_V: ArrayLike,
    command_range: tuple[FloatArray, FloatArray] | None = None,
) -> tuple[FloatArray, BoolArray]:
    """Clip (N, L) commands so the faces of each layer stay in the TEM's window (DriveLimits).

    state: (N, L, 2) face temperatures [degC]. ``command_range``: a recent
    :func:`safe_command_range` to reuse (the faces move over seconds; tem_controller refreshes
    it at 10 Hz, ~1 ms each, and clips every 100 Hz command to it); computed here if None.
    Returns (command, limited) where ``limited`` marks commands that were changed.
    """
    T = np.asarray(state, dtype=float)
    u = np.asarray(command_V, dtype=float)
    # each TEM's hold limits (a weaker TEM holds a larger drive), within the driver rating
    hold_lo, hold_hi = (v[: T.shape[-2]] for v in thermal.layer_hold_limits())
    hold_lo, hold_hi = np.maximum(hold_lo, limits.boost_min_V), np.minimum(hold_hi, limits.boost_max_V)
    if not limits.predictive:
        hot = (T > limits.protect_above_C).any(axis=-1)
        lo = np.where(hot, hold_lo, limits.boost_min_V)
        hi = np.where(hot, hold_hi, limits.boost_max_V)
        out = np.minimum(np.maximum(u, lo), hi)
        return out, out != u
    lo, hi = command_range if command_range is not None else safe_command_range(thermal, limits, T)
    out = np.minimum(np.maximum(u, lo), hi)
    # backstop: a face already outside the window -> hold limits for that layer
    outside = ((T > limits.face_max_C) | (T < limits.face_min_C)).any(axis=-1)
    out = np.where(outside, np.minimum(np.maximum(out, hold_lo), hold_hi), out)
    return out, out != u


#: how often TemLoop recomputes the predictive command range [s] (the faces move over seconds)
RANGE_REFRESH_S = 0.1


@dataclass
class TemSample:
    """What one TemLoop sample decided for the two layers."""

    command_V: FloatArray  # (2,) drive commands to send [V]
    saturated: BoolArray  # (2,) the law's command was clipped (driver rating or face protection)
    hot: BoolArray  # (2,) the muscle is above max_muscle_C: heating blocked


def target_prefilter(
    tau: float, y: FloatArray | None, v: FloatArray, T_d: ArrayLike, dt: float | None
) -> tuple[FloatArray, FloatArray]:
    """One sample of the desired temperatures' tracking prefilter (TemControlParams.target_filter_s
    = tau [s]): e = T_d - y, y' = v + 2 omega e, v' = omega^2 e, explicit Euler over the sample's
    dt [s]; its first sample (y None) passes unchanged. Returns (y [degC], v [degC/s]), any shape
    (one wrist's (2,), a sweep's (n, 2)); tau 0: T_d unchanged."""
    T_d = np.asarray(T_d, dtype=float)
    if tau <= 0.0:
        return T_d, v
    if y is None or dt is None or not np.isfinite(y).all():
        return T_d.copy(), np.zeros_like(T_d)
    w = 1.0 / tau
    h = min(dt, 0.5 * tau)  # a long gap does not make the explicit step unstable
    e = T_d - y
    return y + h * (v + 2.0 * w * e), v + h * w * w * e


class TemLoop:
    """One wrist's TEM control per measurement, as tem_controller runs it (two layers, h = (1, 0)).

    Per sample at time t [s] with measured muscle temperatures T_meas (2,) [degC]:

    1. observer: the heat balance (Eqs. 4.13-4.14) stepped from the last sample under the
       command in force (:func:`observer_step`, at most ``thermal.dt_max_s``), its muscle faces
       then set to T_meas (only the muscle face is measured);
    2. the linearising law (:class:`TemController`, Eqs. 5.44-5.47) toward T_d (2,), with the
       estimated dT_d/dt;
    3. face protection (:func:`protected_command`, range refreshed every RANGE_REFRESH_S);
    4. a muscle above ``max_muscle_C`` may only be cooled.

    Without targets (``T_d`` None: stale or missing) the TEMs are switched off (0 V); :meth:`off`
    does the same from outside (watchdog). ``compiled`` (None: numba if installed) runs steps 1-4
    as one call of :func:`~sma_wrist.core.control.tem_kernel.control_sample`; False runs the numpy functions named above,
    which stay the reference (test_tem_control compares the two over closed-loop sequences).
    """

    def __init__(
        self,
        thermal: th.ThermalParams,
        params: TemControlParams,
        drive: DriveLimits,
        hold: th.ThermalParams,
        max_muscle_C: float,
        *,
        compiled: bool | None = None,
        online: OnlineThermalParams | None = None,
    ) -> None:
        if tuple(params.weights) != TWO_LAYER_WEIGHTS:
            raise ParameterError(f'TemLoop runs two layers, weights {TWO_LAYER_WEIGHTS}; got {params.weights!r}')
        self.thermal, self.params, self.drive, self.hold = thermal, params, drive, hold
        self.max_muscle_C = float(max_muscle_C)
        self.compiled = tem_kernel.AVAILABLE if compiled is None else bool(compiled)  # True without numba: plain Python
        self.law = TemController(thermal, params)
        self.observer = th.rest_state(thermal, 1)  # (1, 2 layers, 2 faces)
        self.command_V = np.zeros(2)  # in force since the last sample
        self.t_last: float | None = None
        self.command_range: tuple[FloatArray, FloatArray] | None = None
        self.range_t: float | None = None
        self.T_d_filtered: FloatArray | None = None  # target prefilter (target_filter_s): output ...
        self.T_d_slope = np.zeros(2)  # ... and its integrator [degC/s]
        # compiled path: the law's rate state as arrays the kernel updates in place
        self._rate, self._T_d_prev, self._rng = np.zeros((2, 2)), np.zeros((2, 2)), np.zeros((2, 2))
        self._flags = np.zeros(2, np.int64)
        self._T_meas, self._T_d = np.zeros(2), np.zeros(2)
        self._coef = _kernel_constants(thermal)
        # the online heat-balance estimate (core.thermal.online): once it is used, the observer, law and
        # protection integrate it (``thermal``, ``hold`` and the kernel's constants); None: Table 4.9 / the file
        self.base_thermal, self.base_hold = thermal, hold
        self.estimator = None if online is None else ThermalScaleEstimator(thermal, 1, online)
        self.theta_used: FloatArray | None = None  # the estimate's scales the loop runs on (None: the model's)
        self._candidates = drive.boost_min_V + _CANDIDATES * (drive.boost_max_V - drive.boost_min_V)
        #: the chatter guard (TemControlParams.chatter_*; None: off); engaged, the law's rate filter is
        #: params.chatter_rate_filter_s
        self.guard = (
            ChatterGuard(1, params.chatter_limit_per_s, params.chatter_window_s)
            if params.chatter_limit_per_s > 0
            else None
        )
        self._cfg = np.array(
            [
                params.gain_per_s,
                params.rate_filter_s,
                *params.weights,
                thermal.u_min_V,
                thermal.u_max_V,
                float(drive.predictive),
                drive.horizon_s,
                max(1, int(np.ceil(drive.horizon_s / thermal.dt_max_s))),
                drive.face_min_C,
                drive.face_max_C,
                drive.protect_above_C,
                drive.boost_min_V,
                drive.boost_max_V,
                *hold.layer_hold_limits()[0],
                *hold.layer_hold_limits()[1],
                self.max_muscle_C,
            ],
            dtype=float,
        )

    def off(self) -> FloatArray:
        """Switch the TEMs off: 0 V is the command in force from now on (the online estimate's window in
        progress recorded another: it is dropped)."""
        self.command_V = np.zeros(2)
        if self.estimator is not None:
            self.estimator.break_window()
        return self.command_V

    def sample(self, t: float, T_meas: ArrayLike, T_d: ArrayLike | None) -> TemSample | None:
        """One sample (steps 1-4 above); None for a repeated or out-of-order t (command unchanged).

        Raises ModelInputError (command in force unchanged) if the law cannot produce a finite
        command; the caller decides (tem_controller switches off).
        """
        dt = None if self.t_last is None else t - self.t_last
        if dt is not None and dt <= 0:
            return None
        self.t_last = t
        dt_obs = 0.0 if dt is None else min(dt, self.thermal.dt_max_s)
        if T_d is None:
            self._observe(T_meas, dt_obs)
            self.T_d_filtered = None
            self.command_V = np.zeros(2)  # off from this sample on (not off(): this sample records it)
            out = TemSample(self.command_V, np.zeros(2, bool), np.zeros(2, bool))
            self._after(t, T_meas)
            return out
        T_d = self._prefilter(T_d, dt)
        refresh = self.drive.predictive and (self.range_t is None or not 0 <= t - self.range_t < RANGE_REFRESH_S)
        if self.compiled:
            out = self._sample_compiled(t, T_meas, T_d, dt_obs, refresh)
            self._after(t, T_meas)
            return out
        self._observe(T_meas, dt_obs)
        res = self.law.update(t, self.observer, np.stack([T_d, T_d], axis=-1)[None])
        if refresh:
            self.command_range = safe_command_range(self.hold, self.drive, self.observer, compiled=False)
            self.range_t = t
        u_prot, limited = protected_command(self.hold, self.drive, self.observer, res.command_V, self.command_range)
        hot = np.asarray(T_meas, dtype=float) > self.max_muscle_C
        self.command_V = np.where(hot, np.minimum(u_prot[0], 0.0), u_prot[0])
        out = TemSample(self.command_V, res.saturated[0] | limited[0], hot)
        self._after(t, T_meas)
        return out

    def _after(self, t: float, T_meas: ArrayLike) -> None:
        """After a sample: the chatter guard takes the command in force, the online estimate the sample."""
        if self.guard is not None and self.guard.update_one(t, self.command_V):
            self._guarded_rate_filter()
        self._learn(t, T_meas)

    def _guarded_rate_filter(self) -> None:
        """The rate filter the guard's state asks for, in the compiled law's constants and the numpy law's."""
        rf = float(self.params.rate_filter_for(self.chattering))
        self._cfg[1] = rf
        self.law.params = replace(self.law.params, rate_filter_s=rf)

    def take_guard_state(self, old: TemLoop) -> None:
        """Continue ``old``'s chatter guard's count (a loop rebuilt for new parameters), judged under this loop's
        limits at old's last sample (a zero-length step: nothing decays, no sign change)."""
        if self.guard is None or old.guard is None:
            return
        for name in ('sign', 'rate', 't_last'):
            setattr(self.guard, name, getattr(old.guard, name))
        if old.guard.t_last is not None and self.guard.update_one(old.guard.t_last, self.command_V):
            self._guarded_rate_filter()

    @property
    def chattering(self) -> bool:
        """Whether the chatter guard is engaged (its rate filter in use)."""
        return self.guard is not None and bool(self.guard.engaged[0])

    def _learn(self, t: float, T_meas: ArrayLike) -> None:
        """The online estimate takes the sample and the command now in force; once it is ready and has
        moved, the loop's models are its (:mod:`sma_wrist.core.thermal.online`)."""
        est = self.estimator
        if (
            est is None
            or not est.sample(t, np.asarray(T_meas, dtype=float)[None], self.command_V[None])
            or not est.ready
        ):
            return
        self.use_estimate(est.theta[0])

    def use_estimate(self, theta: ArrayLike) -> None:
        """Observer, law and protection on the heat balance scaled by theta = (g, s, a) (core.thermal.online)."""
        theta = np.array(theta, dtype=float)
        self._coef = scaled_constants(self.base_thermal, theta[None])[0]
        self.thermal = with_scales(self.base_thermal, theta)
        self.hold = with_scales(self.base_hold, theta)
        self.law.thermal = self.thermal
        self.theta_used = theta

    def _prefilter(self, T_d: ArrayLike, dt: float | None) -> FloatArray:
        """The desired temperatures through the tracking prefilter (:func:`target_prefilter`);
        both paths get the filtered target."""
        self.T_d_filtered, self.T_d_slope = target_prefilter(
            self.params.target_filter_s, self.T_d_filtered, self.T_d_slope, T_d, dt
        )
        return self.T_d_filtered

    def _observe(self, T_meas: ArrayLike, dt_obs: float) -> None:
        if dt_obs > 0 and self.compiled:  # the kernel's constants: the estimate's once used
            tem_kernel.observer_step(
                self.observer[0], np.ascontiguousarray(self.command_V, dtype=float), dt_obs, self._coef
            )
        elif dt_obs > 0:
            self.observer = observer_step(
                self.thermal, self.observer, self.command_V[None, :], dt_obs, compiled=self.compiled
            )
        self.observer[0, :, 0] = T_meas

    def _sample_compiled(self, t: float, T_meas: ArrayLike, T_d: ArrayLike, dt_obs: float, refresh: bool) -> TemSample:
        law = self.law
        has_prev = law._t_prev is not None
        dt_law = t - law._t_prev if has_prev else 0.0
        self._T_meas[:] = T_meas
        self._T_d[:] = T_d
        command = self.command_V.copy()
        status = tem_kernel.control_sample(
            self.observer[0],
            self._rate,
            self._T_d_prev,
            self._rng,
            command,
            self._flags,
            self._T_meas,
            self._T_d,
            dt_obs,
            dt_law,
            has_prev,
            refresh,
            self._coef,
            self._cfg,
            self._candidates,
        )
        if status != tem_kernel.OK:
            if status == tem_kernel.BAD_STATE:
                check_finite('thermal state', self.observer, 'degC')
            if status == tem_kernel.BAD_TARGET:
                check_finite('desired temperature', self._T_d, 'degC')
            raise ModelInputError('TEM command', float('nan'), '(finite numbers)', 'V')
        if not has_prev:  # the law's state, seen where the numpy path keeps it
            law._T_d_prev, law._rate = self._T_d_prev[None], self._rate[None]
        law._t_prev = t
        if refresh:
            self.command_range = (self._rng[0][None].copy(), self._rng[1][None].copy())
            self.range_t = t
        self.command_V = command
        f = self._flags
        return TemSample(command, (f & (tem_kernel.SATURATED | tem_kernel.LIMITED)) != 0, (f & tem_kernel.HOT) != 0)
