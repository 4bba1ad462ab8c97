"""Independent effect generator: a recorded run rewritten the way a real sensor, driver or wire
would distort it.

The diagnosis' own test data (:mod:`.testdata`) inject effects through the extended model
the diagnosis fits, with the noise it assumes: a model checked against itself. This module
is written apart from that code on purpose: it imports neither
:mod:`sma_wrist.core.plant.extensions` nor :mod:`.effects`, and works on what a recording
holds.

* **Sensor effects** rewrite the recorded topics of a clean closed-loop run sample by
  sample: offset, gain, pure delay, first-order lag and linear drift, on thermocouple 1,
  thermocouple 2 (or both) and the potentiometer; then white noise on every measured
  channel. The commands and the physics are the recorded ones.
* **Actuator effects** (TEM driver dead zone, saturation below the rated limit, late
  commands) change what heats the wires, so the plant is re-simulated open loop at its
  1 kHz step on the recorded commands passed through a model of the driver
  (:func:`resimulate`, :class:`sma_wrist.core.plant.wrist.WristPlant`).
* **Plant effects outside the catalogue** re-simulate with other physics: the heat
  balance's Peltier, Joule and exchanger-face loss coefficients changed by 20-40 %
  (:data:`OFF_MODEL_THERMAL`), none of which a catalogue entry frees.

Conventions (what a parameter means): a thermocouple gain error scales the reading about
25 degC (a cold junction at room temperature), a potentiometer gain error about the
neutral angle 0.524 rad; drifts start at the first sample; a delay holds the first value.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Callable

import numpy as np

from sma_wrist.core.plant.wrist import PlantParams, WristPlant
from sma_wrist.diagnose.data import Run

#: cold-junction (room) temperature about which a thermocouple gain error scales [degC]
GAIN_REF_C = 25.0
#: neutral angle about which a potentiometer gain error scales [rad] (JointParams.q_neutral_rad)
Q_REF_RAD = 0.524
#: off-model heat balance: (face, coefficient, factor) -- Peltier and Joule of the muscle face,
#: losses of the exchanger face; no catalogue parameter scales these alone
OFF_MODEL_THERMAL = (('muscle_face', 'K_alpha_tau', 0.7), ('muscle_face', 'K_R', 1.3),
                     ('exchanger_face', 'K_T_inf', 1.35), ('exchanger_face', 'K_inf', 1.35))


@dataclass(frozen=True)
class Distortion:
    """One effect applied to a recording."""

    kind: str  # offset | gain | delay | lag | drift | dead_zone | saturation | command_delay | thermal_physics
    channel: str  # T1 | T2 | T (both thermocouples) | q | u (drive) | plant
    value: float  # in `unit`
    unit: str

    @property
    def subsystem(self) -> str:
        return {'u': 'actuator', 'plant': 'thermal'}.get(self.channel, 'sensor')

    @property
    def id(self) -> str:
        return f'{self.channel}_{self.kind}'


# ----------------------------------------------------------------------------- sensor rewrites
def lag(x: np.ndarray, tau: float, dt: float) -> np.ndarray:
    """First-order sensor response y' = (x - y) / tau, exact for a signal held over each sample."""
    if tau <= 0:
        return x.copy()
    a = np.exp(-dt / tau)
    y = np.empty_like(x)
    y[0] = x[0]
    for k in range(1, x.size):
        y[k] = a * y[k - 1] + (1.0 - a) * x[k]
    return y


def late(t: np.ndarray, x: np.ndarray, delay: float) -> np.ndarray:
    """The value the signal had `delay` seconds earlier (linear interpolation, first value held)."""
    return np.interp(t - delay, t, x, left=x[0])


def rewrite(t: np.ndarray, x: np.ndarray, kind: str, value: float, ref: float) -> np.ndarray:
    """One sensor channel x(t) as a faulty sensor reports it."""
    if kind == 'offset':
        return x + value
    if kind == 'gain':
        return ref + (1.0 + value) * (x - ref)
    if kind == 'delay':
        return late(t, x, value)
    if kind == 'lag':
        return lag(x, value, float(t[1] - t[0]))
    if kind == 'drift':
        return x + value / 3600.0 * (t - t[0])
    raise ValueError(f'unknown sensor effect {kind!r}')


# ----------------------------------------------------------------------------- re-simulation
def driver(kind: str, value: float, limit_V: float = 24.0) -> Callable[[np.ndarray], np.ndarray]:
    """A TEM driver that applies commands u (K, 2) [V] with one imperfection."""
    if kind == 'dead_zone':
        return lambda u: np.where(np.abs(u) > value, u - np.sign(u) * value, 0.0)
    if kind == 'saturation':  # value = how far below the rated limit it saturates [V]
        return lambda u: np.minimum(np.maximum(u, -(limit_V - value)), limit_V - value)
    raise ValueError(f'unknown driver effect {kind!r}')


def off_model_params(scale: float = 1.0) -> PlantParams:
    """The plant with :data:`OFF_MODEL_THERMAL` applied (factors moved toward 1 by `scale` < 1)."""
    p = PlantParams()
    tp = p.thermal
    faces = {'muscle_face': tp.muscle_face, 'exchanger_face': tp.exchanger_face}
    for face, coef, f in OFF_MODEL_THERMAL:
        faces[face] = dataclasses.replace(faces[face], **{coef: getattr(faces[face], coef) * (1.0 + scale * (f - 1.0))})
    return dataclasses.replace(p, thermal=dataclasses.replace(tp, **faces))


def resimulate(run: Run, params: PlantParams | None = None, drive: Callable[[np.ndarray], np.ndarray] | None = None,
               command_delay_s: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Open-loop plant run on the recorded commands: (T (K, 2) [degC], q (K,) [rad]) at the run's samples.

    The command recorded at sample k drives the plant until sample k+1 (plant_sim's
    convention), after `command_delay_s` and the `drive` model.
    """
    params = params or PlantParams()
    u = run.u
    if command_delay_s > 0:
        u = np.stack([late(run.t, u[:, i], command_delay_s) for i in (0, 1)], axis=1)
    if drive is not None:
        u = drive(u)
    plant = WristPlant(params, payload_kg=run.payload_kg)
    steps = max(1, int(round(run.dt / params.dt)))
    T = np.empty((run.n, 2))
    q = np.empty(run.n)
    T[0], q[0] = plant.muscle_temperature_C[0], plant.state.q[0]
    for k in range(run.n - 1):
        s = plant.advance(u[k][None], steps)
        T[k + 1], q[k + 1] = plant.muscle_temperature_C[0], s.q[0]
    return T, q


# ----------------------------------------------------------------------------- one case
def apply(run: Run, d: Distortion | None = None, noise_T_C: float = 0.0, noise_q_rad: float = 0.0,
          seed: int = 0) -> Run:
    """A copy of `run` with the distortion `d` (or none) and white sensor noise."""
    T = run.T.copy()
    q = run.q.copy()
    if d is not None:
        if d.channel == 'u':
            if d.kind == 'command_delay':
                T, q = resimulate(run, command_delay_s=d.value)
            else:
                T, q = resimulate(run, drive=driver(d.kind, d.value))
        elif d.channel == 'plant':
            T, q = resimulate(run, params=off_model_params(d.value))
        elif d.channel == 'q':
            q = rewrite(run.t, q, d.kind, d.value, Q_REF_RAD)
        else:
            for i in {'T1': (0,), 'T2': (1,), 'T': (0, 1)}[d.channel]:
                T[:, i] = rewrite(run.t, T[:, i], d.kind, d.value, GAIN_REF_C)
    rng = np.random.default_rng(seed)
    if noise_T_C > 0:
        T = T + rng.normal(0.0, noise_T_C, T.shape)
    if noise_q_rad > 0:
        q = q + rng.normal(0.0, noise_q_rad, q.shape)
    label = d.id + f'={d.value:g}{d.unit}' if d is not None else 'clean'
    return dataclasses.replace(run, T=T, q=q, warnings=list(run.warnings),
                               source=f'{run.source} [{label}, noise {noise_T_C:g} degC / {noise_q_rad:g} rad]')


#: the sweep of the benchmark: effect -> magnitudes (weak, strong) and the catalogue causes
#: counted as right. 'T' = both thermocouples.
SWEEP: dict[tuple[str, str], tuple[tuple[float, ...], str, frozenset[str]]] = {
    ('T1', 'offset'): ((1.5, 4.0), 'degC', frozenset({'temp_sensor_offsets'})),
    ('T', 'offset'): ((-1.5, -4.0), 'degC', frozenset({'temp_sensor_offset', 'temp_sensor_offsets'})),
    ('T2', 'gain'): ((0.05, 0.12), '1', frozenset({'temp_sensor_gain'})),
    ('T', 'delay'): ((0.5, 1.5), 's', frozenset({'temp_sensor_delay', 'sensor_lag', 'temp_sensor_lags'})),
    ('T1', 'lag'): ((2.0, 5.0), 's', frozenset({'temp_sensor_lags', 'temp_sensor_delay'})),
    ('T', 'drift'): ((10.0, 30.0), 'degC/h', frozenset({'temp_sensor_drift'})),
    ('T2', 'drift'): ((-10.0, -30.0), 'degC/h', frozenset({'temp_sensor_drift'})),
    ('q', 'offset'): ((0.03, 0.08), 'rad', frozenset({'sensor_offset_gain'})),
    ('q', 'gain'): ((0.05, 0.12), '1', frozenset({'sensor_offset_gain'})),
    ('q', 'delay'): ((0.2, 0.5), 's', frozenset({'sensor_delay', 'angle_sensor_lag'})),
    ('q', 'lag'): ((0.2, 0.5), 's', frozenset({'angle_sensor_lag', 'sensor_delay'})),
    ('q', 'drift'): ((0.1, 0.3), 'rad/h', frozenset({'angle_sensor_drift'})),
    ('u', 'dead_zone'): ((1.0, 3.0), 'V', frozenset({'tem_dead_zone'})),
    ('u', 'saturation'): ((8.0, 14.0), 'V', frozenset({'tem_saturation'})),
    ('u', 'command_delay'): ((0.2, 0.5), 's', frozenset({'actuator_delay'})),
    ('plant', 'thermal_physics'): ((0.6, 1.0), 'x', frozenset({'recalibrate_thermal', 'tem_mismatch'})),
}
def parameters_of(d: Distortion, cause: str | None) -> list[str]:
    """Catalogue parameters that should come back as the distortion's magnitude under `cause`."""
    ch = {'T1': ('1',), 'T2': ('2',), 'T': ('1', '2')}.get(d.channel, ())
    per = {'offset': 'temp_offset_{}_C', 'gain': 'temp_gain_err_{}', 'delay': 'temp_delay_{}_s', 'lag': 'temp_lag_{}_s',
           'drift': 'temp_drift_{}_C_per_h'}
    if d.channel in ('T1', 'T2', 'T'):
        if cause == 'temp_sensor_offset':
            return ['temp_offset_C']
        if cause == 'sensor_lag':
            return ['temp_lag_s']
        return [per[d.kind].format(i) for i in ch] if d.kind in per else []
    return {('q', 'offset'): ['angle_offset_rad'], ('q', 'gain'): ['angle_gain_err'], ('q', 'delay'): ['angle_delay_s'],
            ('q', 'lag'): ['angle_lag_s'], ('q', 'drift'): ['angle_drift_rad_per_h'],
            ('u', 'dead_zone'): ['tem_dead_zone_V'], ('u', 'saturation'): ['tem_headroom_V'],
            ('u', 'command_delay'): ['command_delay_s']}.get((d.channel, d.kind), [])


def sweep(magnitude: int | None = None) -> list[Distortion]:
    """Every sweep entry at its weak (0), strong (1) or both (None) magnitudes."""
    out = []
    for (ch, kind), (mags, unit, _) in SWEEP.items():
        for i, v in enumerate(mags):
            if magnitude is None or magnitude == i:
                out.append(Distortion(kind, ch, v, unit))
    return out
