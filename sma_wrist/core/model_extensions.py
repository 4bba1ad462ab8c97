"""Parametric extensions of the nominal wrist model: the effects ``sma-wrist diagnose`` can name.

One table (:data:`PARAMS`) defines every extension parameter (name, unit, nominal value,
bounds, meaning). The diagnosis fits them (:mod:`sma_wrist.diagnose.effects`), writes the
fitted ones as ``model.<name>`` into a params file, and ``plant_sim`` declares the same
``model.<name>`` parameters and simulates them, so an extended model found in measured
data can be run in the closed loop. At the nominal values the plant is the plain one.

Where each effect acts (docs/diagnose.md has the equations)::

    commands --delay--> TEM heat balance (gain, loss, Joule, coupling, ambient)--> T_true
    T_true --thermocouple (first-order lag, offset)--> T_measured
    T_true --wire lag, cycle drift--> T_wire --SD-GPI + joint (payload, friction, pre-load)--> q
    q --backlash (play), potentiometer (delay, offset, gain)--> q_measured

:func:`plant_params` folds the thermal and joint parameters into a
:class:`~sma_wrist.core.plant.PlantParams`; :class:`SensorChain` is the measurement part.
The command delay, wire lag, cycle drift and ambient drift are not simulated by the plant
(:data:`REPLAY_ONLY`): the diagnosis' replay models them, plant_sim refuses them.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Mapping

import numpy as np

from sma_wrist.core.errors import ParameterError
from sma_wrist.core.plant import PlantParams


@dataclass(frozen=True)
class ExtensionParam:
    name: str
    unit: str
    nominal: float
    lower: float
    upper: float
    typical: float  # scale of a typical effect (finite-difference step x 20, grid span)
    description: str


PARAMS: tuple[ExtensionParam, ...] = (
    ExtensionParam('tem_gain_err', '1', 0.0, -0.6, 1.0, 0.1, 'relative error of the TEM drive gain input_per_volt'),
    ExtensionParam('loss_scale_err', '1', 0.0, -0.6, 1.5, 0.1,
                   'relative error of the muscle-face heat loss (K_Tinf, K_T, K_inf)'),
    ExtensionParam('joule_scale_err', '1', 0.0, -0.9, 2.0, 0.2, 'relative error of the Joule term K_R'),
    ExtensionParam('ambient_offset_C', 'degC', 0.0, -15.0, 15.0, 1.0, 'constant ambient/coolant temperature offset'),
    ExtensionParam('ambient_drift_C_per_h', 'degC/h', 0.0, -60.0, 60.0, 5.0, 'linear ambient/coolant temperature drift'),
    ExtensionParam('coupling_per_s', '1/s', 0.0, 0.0, 0.2, 0.01,
                   'heat conductance between the muscle faces / heat capacity'),
    ExtensionParam('command_delay_s', 's', 0.0, 0.0, 1.0, 0.02,
                   'the TEM drive applies a command this long after it was sent (link, driver, host latency)'),
    ExtensionParam('temp_offset_C', 'degC', 0.0, -10.0, 10.0, 0.5, 'thermocouple offset (both channels)'),
    ExtensionParam('temp_lag_s', 's', 0.0, 0.0, 20.0, 1.0, 'thermocouple first-order time constant'),
    ExtensionParam('hyst_lag_s', 's', 0.0, 0.0, 60.0, 3.0, 'wire temperature lags the measured one (rate-dependent loops)'),
    ExtensionParam('hyst_drift_C_per_cycle', 'degC/cycle', 0.0, -10.0, 10.0, 1.0,
                   'transition temperatures move with the cycle count (functional fatigue)'),
    ExtensionParam('payload_err_kg', 'kg', 0.0, -0.5, 1.0, 0.1, 'true payload minus the recorded /wrist/payload'),
    ExtensionParam('coulomb_Nm', 'N m', 0.004, 0.0, 0.3, 0.02, 'Coulomb friction moment (static = 1.5 x Coulomb)'),
    ExtensionParam('viscous_Nms', 'N m s', 0.15, 0.0, 20.0, 1.0, 'viscous damping of the joint'),
    ExtensionParam('preload_err_mm', 'mm', 0.0, -1.0, 1.0, 0.05, 'bundle pre-load elongation error'),
    ExtensionParam('backlash_rad', 'rad', 0.0, 0.0, 0.3, 0.02, 'total play between chain and output shaft'),
    ExtensionParam('angle_delay_s', 's', 0.0, 0.0, 3.0, 0.2, 'potentiometer / acquisition delay'),
    ExtensionParam('angle_offset_rad', 'rad', 0.0, -0.5, 0.5, 0.02, 'potentiometer offset'),
    ExtensionParam('angle_gain_err', '1', 0.0, -0.5, 0.5, 0.03, 'potentiometer gain error about q_neutral'),
)
BY_NAME = {p.name: p for p in PARAMS}
NOMINAL = {p.name: p.nominal for p in PARAMS}
#: the nominal joint's static / Coulomb friction ratio (0.006 / 0.004 N m)
STATIC_PER_COULOMB = 1.5
#: effects the diagnosis replays but the plant does not simulate
REPLAY_ONLY = ('hyst_lag_s', 'hyst_drift_C_per_cycle', 'ambient_drift_C_per_h', 'command_delay_s')


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
    the Joule scaling both faces' K_R, the ambient offset shifts both faces' ambients.
    Raises ParameterError for a :data:`REPLAY_ONLY` effect away from nominal.
    """
    v = check(values)
    p = base or PlantParams()
    if v == NOMINAL:
        return p  # bit-identical to the plain plant
    off = [k for k in REPLAY_ONLY if v[k] != NOMINAL[k]]
    if off:
        raise ParameterError(f'model extension(s) {", ".join(f"{k} = {v[k]:g}" for k in off)} are replayed by '
                             f'sma-wrist diagnose but not simulated by the plant (docs/diagnose.md)')
    tp = p.thermal
    ls, js = 1.0 + v['loss_scale_err'], 1.0 + v['joule_scale_err']
    amb = tp.effective_ambient_C
    mf = dataclasses.replace(tp.muscle_face, K_T_inf=tp.muscle_face.K_T_inf * ls, K_T=tp.muscle_face.K_T * ls,
                             K_inf=tp.muscle_face.K_inf * ls, K_R=tp.muscle_face.K_R * js)
    xf = dataclasses.replace(tp.exchanger_face, K_R=tp.exchanger_face.K_R * js)
    tp = dataclasses.replace(tp, muscle_face=mf, exchanger_face=xf,
                             input_per_volt=tp.input_per_volt * (1.0 + v['tem_gain_err']),
                             coupling_per_s=v['coupling_per_s'],
                             ambient_C=(amb[0] + v['ambient_offset_C'], amb[1] + v['ambient_offset_C']))
    jp = dataclasses.replace(p.joint, coulomb_Nm=v['coulomb_Nm'], static_Nm=STATIC_PER_COULOMB * v['coulomb_Nm'],
                             viscous_Nms=v['viscous_Nms'])
    return dataclasses.replace(p, thermal=tp, joint=jp, preload_elongation_mm=p.preload_elongation_mm + v['preload_err_mm'])


class SensorChain:
    """What the sensors make of the true state, sampled every ``dt`` [s] (plant_sim's publish tick).

    Thermocouples: first-order lag ``temp_lag_s`` (exact discretisation) plus ``temp_offset_C``.
    Potentiometer: backlash (play of width ``backlash_rad``), delay ``angle_delay_s`` (linear
    interpolation between ticks), then ``q + angle_offset_rad + angle_gain_err (q - q_neutral)``.
    """

    def __init__(self, values: Mapping[str, float], dt: float, q_neutral_rad: float) -> None:
        v = check(values)
        self.v = v
        self.dt = float(dt)
        self.q_neutral = float(q_neutral_rad)
        self.a_T = float(np.exp(-dt / v['temp_lag_s'])) if v['temp_lag_s'] > 0 else 0.0
        s = v['angle_delay_s'] / dt
        self.delay_i, self.delay_f = int(np.floor(s)), float(s - np.floor(s))
        self._buf = np.zeros(self.delay_i + 2)
        self._T: np.ndarray | None = None
        self._play: float | None = None
        self._n = 0

    @property
    def identity(self) -> bool:
        return all(self.v[k] == NOMINAL[k] for k in
                   ('temp_lag_s', 'temp_offset_C', 'backlash_rad', 'angle_delay_s', 'angle_offset_rad', 'angle_gain_err'))

    def temperatures(self, T_true: np.ndarray) -> np.ndarray:
        T = np.asarray(T_true, float)
        self._T = T.copy() if self._T is None else self.a_T * self._T + (1.0 - self.a_T) * T
        return self._T + self.v['temp_offset_C']

    def angle(self, q_true: float) -> float:
        h = 0.5 * self.v['backlash_rad']
        self._play = q_true if self._play is None else min(max(self._play, q_true - h), q_true + h)
        b = self._buf
        if self._n == 0:
            b[:] = self._play
        b[1:] = b[:-1].copy()
        b[0] = self._play
        self._n += 1
        y = (1.0 - self.delay_f) * b[self.delay_i] + self.delay_f * b[self.delay_i + 1]
        return float(y + self.v['angle_offset_rad'] + self.v['angle_gain_err'] * (y - self.q_neutral))
