"""Parametric extensions of the nominal wrist model: the effects ``sma-wrist diagnose`` can name.

One table (:data:`PARAMS`) defines every extension parameter (name, unit, nominal value,
bounds, meaning). The diagnosis fits them (:mod:`sma_wrist.diagnose.effects`), writes the
fitted ones as ``model.<name>`` into a params file, and ``plant_sim`` declares the same
``model.<name>`` parameters and simulates them, so an extended model found in measured
data can be run in the closed loop. At the nominal values the plant is the plain one.

Where each effect acts (doc/explanation/diagnosis.md has the equations)::

    commands --delay--> TEM heat balance (gain, loss, Joule, coupling, ambient)--> T_true
    commands --TEM driver (dead zone, saturation below the rating)--> applied drive
    T_true --thermocouple i (lag, delay, gain, offset, drift; per channel)--> T_measured
    T_true --wire lag, transition shift, cycle drift--> T_wire --SD-GPI + joint (payload, friction, pre-load)--> q
    q --backlash (play), potentiometer (delay, lag, offset, gain, drift)--> q_measured

:func:`plant_params` folds the thermal and joint parameters into a
:class:`~sma_wrist.core.plant.wrist.PlantParams`; :class:`SensorChain` is the measurement part.
The command delay, TEM driver dead zone and saturation, wire lag, cycle drift and ambient
drift are not simulated by the plant
(:data:`REPLAY_ONLY`): the diagnosis' replay models them, plant_sim refuses them.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from sma_wrist.core.errors import ParameterError
from sma_wrist.core.plant.wrist import PlantParams


@dataclass(frozen=True)
class ExtensionParam:
    name: str
    unit: str
    nominal: float
    lower: float
    upper: float
    typical: float  # scale of a typical effect (finite-difference step x 20, grid span)
    description: str


#: every extension parameter: name, unit, nominal value, bounds, typical effect size, meaning
PARAMS: tuple[ExtensionParam, ...] = (
    ExtensionParam('tem_gain_err', '1', 0.0, -0.6, 1.0, 0.1, 'relative error of the TEM drive gain input_per_volt'),
    ExtensionParam(
        'loss_scale_err', '1', 0.0, -0.6, 1.5, 0.1, 'relative error of the muscle-face heat loss (K_Tinf, K_T, K_inf)'
    ),
    ExtensionParam('joule_scale_err', '1', 0.0, -0.9, 2.0, 0.2, 'relative error of the Joule term K_R'),
    ExtensionParam('ambient_offset_C', 'degC', 0.0, -15.0, 15.0, 1.0, 'constant ambient/coolant temperature offset'),
    ExtensionParam(
        'ambient_drift_C_per_h', 'degC/h', 0.0, -60.0, 60.0, 5.0, 'linear ambient/coolant temperature drift'
    ),
    ExtensionParam(
        'coupling_per_s', '1/s', 0.0, 0.0, 0.2, 0.01, 'heat conductance between the muscle faces / heat capacity'
    ),
    ExtensionParam(
        'command_delay_s',
        's',
        0.0,
        0.0,
        1.0,
        0.02,
        'the TEM drive applies a command this long after it was sent (link, driver, host latency)',
    ),
    ExtensionParam('temp_offset_C', 'degC', 0.0, -10.0, 10.0, 0.5, 'thermocouple offset (both channels)'),
    ExtensionParam('temp_lag_s', 's', 0.0, 0.0, 20.0, 1.0, 'thermocouple first-order time constant'),
    ExtensionParam(
        'hyst_lag_s', 's', 0.0, 0.0, 60.0, 3.0, 'wire temperature lags the measured one (rate-dependent loops)'
    ),
    ExtensionParam(
        'hyst_drift_C_per_cycle',
        'degC/cycle',
        0.0,
        -10.0,
        10.0,
        1.0,
        'transition temperatures move with the cycle count (functional fatigue)',
    ),
    ExtensionParam(
        'hyst_shift_C',
        'degC',
        0.0,
        -15.0,
        15.0,
        1.0,
        'the wires transform this much hotter (> 0) or colder than the model: transition temperatures shifted',
    ),
    ExtensionParam('payload_err_kg', 'kg', 0.0, -0.5, 1.0, 0.1, 'true payload minus the recorded /wrist/payload'),
    ExtensionParam('coulomb_Nm', 'N m', 0.004, 0.0, 0.3, 0.02, 'Coulomb friction moment (static = 1.5 x Coulomb)'),
    ExtensionParam('viscous_Nms', 'N m s', 0.15, 0.0, 20.0, 1.0, 'viscous damping of the joint'),
    ExtensionParam('preload_err_mm', 'mm', 0.0, -1.0, 1.0, 0.05, 'bundle pre-load elongation error'),
    ExtensionParam('backlash_rad', 'rad', 0.0, 0.0, 0.3, 0.02, 'total play between chain and output shaft'),
    ExtensionParam('angle_delay_s', 's', 0.0, 0.0, 3.0, 0.2, 'potentiometer / acquisition delay'),
    ExtensionParam('angle_offset_rad', 'rad', 0.0, -0.5, 0.5, 0.02, 'potentiometer offset'),
    ExtensionParam('angle_gain_err', '1', 0.0, -0.5, 0.5, 0.03, 'potentiometer gain error about q_neutral'),
    # per-channel sensor chain: each thermocouple on its own, the potentiometer's lag and drift
    ExtensionParam('temp_offset_1_C', 'degC', 0.0, -10.0, 10.0, 0.5, 'thermocouple 1 offset (muscle 1 only)'),
    ExtensionParam('temp_offset_2_C', 'degC', 0.0, -10.0, 10.0, 0.5, 'thermocouple 2 offset (muscle 2 only)'),
    ExtensionParam('temp_gain_err_1', '1', 0.0, -0.3, 0.3, 0.02, 'thermocouple 1 gain error about TEMP_GAIN_REF_C'),
    ExtensionParam('temp_gain_err_2', '1', 0.0, -0.3, 0.3, 0.02, 'thermocouple 2 gain error about TEMP_GAIN_REF_C'),
    ExtensionParam(
        'temp_delay_1_s', 's', 0.0, 0.0, 3.0, 0.2, 'thermocouple 1 reading is the temperature this long ago'
    ),
    ExtensionParam(
        'temp_delay_2_s', 's', 0.0, 0.0, 3.0, 0.2, 'thermocouple 2 reading is the temperature this long ago'
    ),
    ExtensionParam('temp_lag_1_s', 's', 0.0, 0.0, 20.0, 1.0, 'thermocouple 1 first-order time constant'),
    ExtensionParam('temp_lag_2_s', 's', 0.0, 0.0, 20.0, 1.0, 'thermocouple 2 first-order time constant'),
    ExtensionParam('temp_drift_1_C_per_h', 'degC/h', 0.0, -60.0, 60.0, 5.0, 'thermocouple 1 reading drifts linearly'),
    ExtensionParam('temp_drift_2_C_per_h', 'degC/h', 0.0, -60.0, 60.0, 5.0, 'thermocouple 2 reading drifts linearly'),
    ExtensionParam('angle_lag_s', 's', 0.0, 0.0, 3.0, 0.2, 'potentiometer first-order time constant (RC filter)'),
    ExtensionParam('angle_drift_rad_per_h', 'rad/h', 0.0, -1.0, 1.0, 0.05, 'potentiometer reading drifts linearly'),
    # actuator: what the TEM driver makes of a command
    ExtensionParam(
        'tem_dead_zone_V',
        'V',
        0.0,
        0.0,
        10.0,
        0.5,
        'TEM driver dead zone: |command| below it gives 0 V, above it the output is |command| - dead zone',
    ),
    ExtensionParam(
        'tem_headroom_V', 'V', 0.0, 0.0, 20.0, 2.0, 'the TEM driver saturates this far below the nominal drive limit'
    ),
)
BY_NAME = {p.name: p for p in PARAMS}
NOMINAL = {p.name: p.nominal for p in PARAMS}
#: the nominal joint's static / Coulomb friction ratio (0.006 / 0.004 N m)
STATIC_PER_COULOMB = 1.5
#: effects the diagnosis replays but the plant does not simulate
REPLAY_ONLY = (
    'hyst_lag_s',
    'hyst_drift_C_per_cycle',
    'ambient_drift_C_per_h',
    'command_delay_s',
    'tem_dead_zone_V',
    'tem_headroom_V',
)
#: thermocouple gain errors scale the reading about this temperature [degC] (the cold junction, room)
TEMP_GAIN_REF_C = 25.0
#: the per-channel sensor parameters of thermocouple i: offset, gain error, delay, lag, drift
TEMP_CHANNEL_KEYS = {
    i: (f'temp_offset_{i}_C', f'temp_gain_err_{i}', f'temp_delay_{i}_s', f'temp_lag_{i}_s', f'temp_drift_{i}_C_per_h')
    for i in (1, 2)
}
SENSOR_KEYS = (
    (
        'temp_lag_s',
        'temp_offset_C',
        'backlash_rad',
        'angle_delay_s',
        'angle_offset_rad',
        'angle_gain_err',
        'angle_lag_s',
        'angle_drift_rad_per_h',
    )
    + TEMP_CHANNEL_KEYS[1]
    + TEMP_CHANNEL_KEYS[2]
)


def drive(u: np.ndarray, dead_zone_V: float, headroom_V: float, u_max_V: float) -> np.ndarray:
    """What a TEM driver with a dead zone and an early saturation applies for commands u [V]."""
    if dead_zone_V > 0:
        u = np.sign(u) * np.maximum(np.abs(u) - dead_zone_V, 0.0)
    if headroom_V > 0:
        lim = max(u_max_V - headroom_V, 0.0)
        u = np.clip(u, -lim, lim)
    return u


def check(values: Mapping[str, float]) -> dict[str, float]:
    """All extension values (nominal where not given), validated against :data:`PARAMS`."""
    out = dict(NOMINAL)
    for k, v in values.items():
        if k not in BY_NAME:
            raise ParameterError(f'unknown model extension {k!r}; known: {", ".join(BY_NAME)}')
        p = BY_NAME[k]
        if not (np.isfinite(v) and p.lower <= v <= p.upper):
            raise ParameterError(f'model extension {k} = {v!r} {p.unit} is outside [{p.lower}, {p.upper}]')
        out[k] = float(v)
    return out


def plant_params(values: Mapping[str, float], base: PlantParams | None = None) -> PlantParams:
    """``base`` (default PlantParams()) with the thermal and joint extensions folded in.

    Same arithmetic as the diagnosis' replay coefficients (diagnose.effects.thermal_coef):
    loss scaling multiplies the muscle face's K_Tinf, K_T and K_inf (ambient unchanged),
    the Joule scaling both faces' K_R, the ambient offset shifts both faces' ambients, the transition shift moves the
    wire's SD-GPI along the temperature axis. A Peltier-form heat balance (``base.heat_balance``) gets the same effects
    as their Peltier counterparts (core.thermal.peltier.PeltierParams.scaled, diagnose.effects.peltier_coef).
    Raises ParameterError for a :data:`REPLAY_ONLY` effect away from nominal.
    """
    v = check(values)
    p = base or PlantParams()
    if v == NOMINAL:
        return p  # bit-identical to the plain plant
    off = [k for k in REPLAY_ONLY if v[k] != NOMINAL[k]]
    if off:
        raise ParameterError(
            f'model extension(s) {", ".join(f"{k} = {v[k]:g}" for k in off)} are replayed by '
            f'sma-wrist diagnose but not simulated by the plant (doc/explanation/diagnosis.md)'
        )
    tp = dataclasses.replace(
        p.thermal.scaled(
            1.0 + v['tem_gain_err'], 1.0 + v['loss_scale_err'], 1.0 + v['joule_scale_err'], v['ambient_offset_C']
        ),
        coupling_per_s=v['coupling_per_s'],
    )
    hb = p.heat_balance
    if hb is not None:  # the model's heat balance in the Peltier form: the same effects, its counterparts
        hb = dataclasses.replace(
            hb.scaled(
                1.0 + v['tem_gain_err'], 1.0 + v['loss_scale_err'], 1.0 + v['joule_scale_err'], v['ambient_offset_C']
            ),
            coupling_per_s=hb.coupling_per_s + v['coupling_per_s'],  # on top of the form's own (its file's)
        )
    jp = dataclasses.replace(
        p.joint,
        coulomb_Nm=v['coulomb_Nm'],
        static_Nm=STATIC_PER_COULOMB * v['coulomb_Nm'],
        viscous_Nms=v['viscous_Nms'],
    )
    hy = p.hysteresis
    if v['hyst_shift_C'] != 0.0:
        # the SD-GPI's envelopes and memory curves moved along the temperature axis: the wire at T is the model's
        # wire at T - shift (the replay's T_wire = T - hyst_shift_C)
        from sma_wrist.core.hysteresis.warp import Warp, warped_wire

        s = v['hyst_shift_C']
        hy = dataclasses.replace(
            warped_wire(hy, Warp(s, s)), T_valid=hy.T_valid, name=f'{hy.name} shifted {s:+.2f} degC'
        )
    return dataclasses.replace(
        p,
        thermal=tp,
        heat_balance=hb,
        joint=jp,
        hysteresis=hy,
        preload_elongation_mm=p.preload_elongation_mm + v['preload_err_mm'],
    )


class SensorChain:
    """What the sensors make of the true state, sampled every ``dt`` [s] (plant_sim's publish tick).

    Thermocouple i: first-order lag ``temp_lag_s`` then ``temp_lag_i_s`` (exact
    discretisation), delay ``temp_delay_i_s``, gain error ``temp_gain_err_i`` about
    :data:`TEMP_GAIN_REF_C`, offset ``temp_offset_C + temp_offset_i_C`` and drift
    ``temp_drift_i_C_per_h`` x time since the first sample.
    Potentiometer: backlash (play of width ``backlash_rad``), delay ``angle_delay_s`` (linear
    interpolation between ticks), first-order lag ``angle_lag_s``, then
    ``q + angle_offset_rad + angle_gain_err (q - q_neutral)`` plus ``angle_drift_rad_per_h`` x time.
    """

    def __init__(self, values: Mapping[str, float], dt: float, q_neutral_rad: float) -> None:
        v = check(values)
        self.v = v
        self.dt = float(dt)
        self.q_neutral = float(q_neutral_rad)
        self.a_T = _lag_factor(v['temp_lag_s'], dt)
        self.a_Ti = np.array([_lag_factor(v[f'temp_lag_{i}_s'], dt) for i in (1, 2)])
        self.a_q = _lag_factor(v['angle_lag_s'], dt)
        self._q_delay = _Delay(v['angle_delay_s'], dt)
        self._T_delay = [_Delay(v[f'temp_delay_{i}_s'], dt) for i in (1, 2)]
        self._gain = np.array([v[f'temp_gain_err_{i}'] for i in (1, 2)])
        self._offset = v['temp_offset_C'] + np.array([v[f'temp_offset_{i}_C'] for i in (1, 2)])
        self._drift = np.array([v[f'temp_drift_{i}_C_per_h'] for i in (1, 2)]) / 3600.0
        self._T: np.ndarray | None = None
        self._Ti: np.ndarray | None = None
        self._play: float | None = None
        self._q_lag: float | None = None
        self._n_T = 0
        self._n_q = 0

    @property
    def identity(self) -> bool:
        return all(self.v[k] == NOMINAL[k] for k in SENSOR_KEYS)

    def temperatures(self, T_true: np.ndarray) -> np.ndarray:
        T = np.asarray(T_true, float)
        self._T = T.copy() if self._T is None else self.a_T * self._T + (1.0 - self.a_T) * T
        self._Ti = self._T.copy() if self._Ti is None else self.a_Ti * self._Ti + (1.0 - self.a_Ti) * self._T
        y = np.array([d.push(x) for d, x in zip(self._T_delay, self._Ti)])
        t = self._n_T * self.dt
        self._n_T += 1
        return TEMP_GAIN_REF_C + (1.0 + self._gain) * (y - TEMP_GAIN_REF_C) + self._offset + self._drift * t

    def angle(self, q_true: float) -> float:
        h = 0.5 * self.v['backlash_rad']
        self._play = q_true if self._play is None else min(max(self._play, q_true - h), q_true + h)
        y = self._q_delay.push(self._play)
        self._q_lag = y if self._q_lag is None else self.a_q * self._q_lag + (1.0 - self.a_q) * y
        y = self._q_lag
        t = self._n_q * self.dt
        self._n_q += 1
        return float(
            y
            + self.v['angle_offset_rad']
            + self.v['angle_gain_err'] * (y - self.q_neutral)
            + self.v['angle_drift_rad_per_h'] / 3600.0 * t
        )


def _lag_factor(tau: float, dt: float) -> float:
    return float(np.exp(-dt / tau)) if tau > 0 else 0.0


class _Delay:
    """x(t - delay) of a sampled signal, linear interpolation between ticks, held at the first value."""

    def __init__(self, delay: float, dt: float) -> None:
        s = delay / dt
        self.i, self.f = int(np.floor(s)), float(s - np.floor(s))
        self.buf = np.zeros(self.i + 2)
        self.n = 0

    def push(self, x: float) -> float:
        b = self.buf
        if self.n == 0:
            b[:] = x
        b[1:] = b[:-1].copy()
        b[0] = x
        self.n += 1
        return float((1.0 - self.f) * b[self.i] + self.f * b[self.i + 1])
