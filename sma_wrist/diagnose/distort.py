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
* **Plant changes of a running wrist** (:data:`PLANT_SUBSYSTEM`: TEMs weakening, a heavier payload, the ambient /
  coolant drifting, the wires' transitions drifting with fatigue) re-simulate from their onset on.
* **Plant effects outside the catalogue** re-simulate with other physics: the heat
  balance's Peltier, Joule and exchanger-face loss coefficients changed by 20-40 %
  (:data:`OFF_MODEL_THERMAL`), none of which a catalogue entry frees.

Conventions (what a parameter means): a thermocouple gain error scales the reading about
25 degC (a cold junction at room temperature), a potentiometer gain error about the
neutral angle 0.524 rad; drifts start at the first sample; a delay holds the first value.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from sma_wrist.core.plant.wrist import PlantParams, WristPlant
from sma_wrist.diagnose.data import Run

#: cold-junction (room) temperature about which a thermocouple gain error scales [degC]
GAIN_REF_C = 25.0
#: neutral angle about which a potentiometer gain error scales [rad] (JointParams.q_neutral_rad)
Q_REF_RAD = 0.524
#: off-model heat balance: (face, coefficient, factor) -- Peltier and Joule of the muscle face,
#: losses of the exchanger face; no catalogue parameter scales these alone
OFF_MODEL_THERMAL = (
    ('muscle_face', 'K_alpha_tau', 0.7),
    ('muscle_face', 'K_R', 1.3),
    ('exchanger_face', 'K_T_inf', 1.35),
    ('exchanger_face', 'K_inf', 1.35),
)


#: plant changes a running wrist undergoes (re-simulated from their onset on), and the subsystem each belongs to:
#: ``tem_weak`` the TEMs' Peltier terms (both faces) lose this fraction, ``payload`` this mass [kg] is added at the
#: lever (``/wrist/payload`` still says the old one), ``ambient_drift`` both faces' ambient / coolant temperature
#: drifts at this rate [degC/h]; ``thermal_physics`` is the off-model heat balance above
#: ``transition_drift`` the wires' transition temperatures move by this much [degC] (functional fatigue of a wire
#: cycled for long: Sec. 3.1's transformation temperatures drift with the number of cycles), reached over
#: :attr:`Distortion.ramp_s` after the onset (0: at once)
PLANT_SUBSYSTEM = {
    'thermal_physics': 'thermal',
    'tem_weak': 'thermal',
    'ambient_drift': 'thermal',
    'payload': 'joint',
    'transition_drift': 'hysteresis',
}
#: a transition drift is applied in steps of this size [degC]: each step rebuilds the wire's envelopes
DRIFT_STEP_C = 0.1


@dataclass(frozen=True)
class Distortion:
    """One effect applied to a recording."""

    kind: str  # offset | gain | delay | lag | drift | dead_zone | saturation | command_delay | PLANT_SUBSYSTEM kinds
    channel: str  # T1 | T2 | T (both thermocouples) | q | u (drive) | plant
    value: float  # in `unit`
    unit: str
    ramp_s: float = 0.0  # a plant change reaches `value` this long after its onset [s] (transition_drift only)

    @property
    def subsystem(self) -> str:
        if self.channel == 'plant':
            return PLANT_SUBSYSTEM.get(self.kind, 'thermal')
        return {'u': 'actuator'}.get(self.channel, 'sensor')

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


def weak_tem_params(fraction: float, base: PlantParams | None = None) -> PlantParams:
    """The plant whose TEMs lost `fraction` of their Peltier terms (K_alpha_tau, K_tau of both faces; Joule heating
    and losses unchanged): a module weakening with age or a failing solder joint."""
    p = base or PlantParams()
    tp = p.thermal
    faces = [
        dataclasses.replace(f, K_alpha_tau=f.K_alpha_tau * (1.0 - fraction), K_tau=f.K_tau * (1.0 - fraction))
        for f in (tp.muscle_face, tp.exchanger_face)
    ]
    return dataclasses.replace(p, thermal=dataclasses.replace(tp, muscle_face=faces[0], exchanger_face=faces[1]))


def ambient_params(shift_C: float, base: PlantParams | None = None) -> PlantParams:
    """The plant with both faces' ambient / coolant temperatures `shift_C` [degC] away from Table 4.9's."""
    p = base or PlantParams()
    amb = p.thermal.effective_ambient_C
    return dataclasses.replace(
        p, thermal=dataclasses.replace(p.thermal, ambient_C=(amb[0] + shift_C, amb[1] + shift_C))
    )


def resimulate(
    run: Run,
    params: PlantParams | None = None,
    drive: Callable[[np.ndarray], np.ndarray] | None = None,
    command_delay_s: float = 0.0,
    onset_s: float = 0.0,
    change: Callable[[WristPlant, float], None] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Open-loop plant run on the recorded commands: (T (K, 2) [degC], q (K,) [rad]) at the run's samples.

    The command recorded at sample k drives the plant until sample k+1 (plant_sim's
    convention), after `command_delay_s` and the `drive` model, which act from `onset_s` [s] on (before it the
    commands are applied as recorded). `change(plant, t_since_onset)`, if given, is called before every sample
    interval from the onset on and may change the plant's parameters or payload in place (a wrist that changes
    while it runs).
    """
    params = params or PlantParams()
    u = run.u
    i_on = int(np.searchsorted(run.t, onset_s - 1e-9))
    if command_delay_s > 0:
        late_u = np.stack([late(run.t, u[:, i], command_delay_s) for i in (0, 1)], axis=1)
        u = np.concatenate([u[:i_on], late_u[i_on:]])
    if drive is not None:
        u = np.concatenate([u[:i_on], drive(u)[i_on:]])
    plant = WristPlant(params, payload_kg=run.payload_kg)
    steps = max(1, int(round(run.dt / params.dt)))
    T = np.empty((run.n, 2))
    q = np.empty(run.n)
    T[0], q[0] = plant.muscle_temperature_C[0], plant.state.q[0]
    for k in range(run.n - 1):
        if change is not None and k >= i_on:
            change(plant, float(run.t[k] - run.t[i_on]))
        s = plant.advance(u[k][None], steps)
        T[k + 1], q[k + 1] = plant.muscle_temperature_C[0], s.q[0]
    return T, q


def transition_params(shift_C: float, base: PlantParams | None = None) -> PlantParams:
    """The plant whose wires transform `shift_C` [degC] hotter (> 0) or colder: the SD-GPI's envelopes and memory
    curves moved along the temperature axis (:func:`sma_wrist.plants.spread.perturbed_hysteresis`, the sweep's wire
    that is not the model), stroke unchanged."""
    from sma_wrist.plants.spread import perturbed_hysteresis

    p = base or PlantParams()
    return dataclasses.replace(p, hysteresis=perturbed_hysteresis(p.hysteresis, float(shift_C)))


def plant_change(
    kind: str, value: float, base: PlantParams | None = None, ramp_s: float = 0.0
) -> Callable[[WristPlant, float], None]:
    """A `change` for :func:`resimulate` (:data:`PLANT_SUBSYSTEM` kinds other than thermal_physics); `ramp_s`: a
    transition drift grows linearly to `value` over this long [s]."""
    base = base or PlantParams()
    if kind == 'transition_drift':
        from sma_wrist.core.hysteresis.muscle import MuscleModel

        cache: dict[int, PlantParams] = {}
        now = {'step': None}

        def drift(plant: WristPlant, t: float) -> None:
            frac = 1.0 if ramp_s <= 0 else min(t / ramp_s, 1.0)
            step = int(round(frac * value / DRIFT_STEP_C))
            if step != now['step']:
                now['step'] = step
                if step not in cache:
                    cache[step] = transition_params(step * DRIFT_STEP_C, base)
                # the wire state (play operators, loads) is kept: the same wire, now transforming elsewhere
                plant.params = cache[step]
                plant.muscles = MuscleModel(plant.params.hysteresis, plant.params.muscle)

        return drift
    if kind == 'tem_weak':
        weak = weak_tem_params(value, base)

        def tem(plant: WristPlant, t: float) -> None:
            plant.params = weak

        return tem
    if kind == 'payload':
        before: list[float] = []

        def payload(plant: WristPlant, t: float) -> None:
            if not before:  # the mass the wrist carried until the onset
                before.append(float(plant.state.payload_kg[0]))
            plant.state.payload_kg[:] = before[0] + value

        return payload
    if kind == 'ambient_drift':
        state = {'step': -1}

        def ambient(plant: WristPlant, t: float) -> None:
            step = int(t)  # the ambient moves in 1 s steps: re-packing the plant's constants every 10 ms is slow
            if step != state['step']:
                state['step'] = step
                plant.params = ambient_params(value / 3600.0 * step, base)

        return ambient
    raise ValueError(f'unknown plant change {kind!r}')


# ----------------------------------------------------------------------------- one case
def apply(
    run: Run,
    d: Distortion | None = None,
    noise_T_C: float = 0.0,
    noise_q_rad: float = 0.0,
    seed: int = 0,
    onset_s: float = 0.0,
) -> Run:
    """A copy of `run` with the distortion `d` (or none), beginning at `onset_s` [s of the run], and white sensor
    noise. A sensor fault that begins mid-run starts from the true reading: a drift from zero, a lag from the
    value at the onset, a delay from the onset on."""
    T = run.T.copy()
    q = run.q.copy()
    i_on = int(np.searchsorted(run.t, onset_s - 1e-9))
    t_on = run.t[i_on:]
    if d is not None:
        if d.channel == 'u':
            if d.kind == 'command_delay':
                T, q = resimulate(run, command_delay_s=d.value, onset_s=onset_s)
            else:
                T, q = resimulate(run, drive=driver(d.kind, d.value), onset_s=onset_s)
        elif d.channel == 'plant' and d.kind == 'thermal_physics':
            if onset_s > 0:
                T, q = resimulate(run, onset_s=onset_s, change=_switch(off_model_params(d.value)))
            else:
                T, q = resimulate(run, params=off_model_params(d.value))
        elif d.channel == 'plant':
            T, q = resimulate(run, onset_s=onset_s, change=plant_change(d.kind, d.value, ramp_s=d.ramp_s))
        elif d.channel == 'q':
            q[i_on:] = (
                rewrite(t_on, q[i_on:], d.kind, d.value, Q_REF_RAD)
                if d.kind != 'delay'
                else late(run.t, q, d.value)[i_on:]
            )
        else:
            for i in {'T1': (0,), 'T2': (1,), 'T': (0, 1)}[d.channel]:
                T[i_on:, i] = (
                    rewrite(t_on, T[i_on:, i], d.kind, d.value, GAIN_REF_C)
                    if d.kind != 'delay'
                    else late(run.t, T[:, i], d.value)[i_on:]
                )
    rng = np.random.default_rng(seed)
    if noise_T_C > 0:
        T = T + rng.normal(0.0, noise_T_C, T.shape)
    if noise_q_rad > 0:
        q = q + rng.normal(0.0, noise_q_rad, q.shape)
    label = (
        (
            d.id
            + f'={d.value:g}{d.unit}'
            + (f' from {onset_s:g} s' if onset_s > 0 else '')
            + (f' over {d.ramp_s:g} s' if d.ramp_s > 0 else '')
        )
        if d is not None
        else 'clean'
    )
    return dataclasses.replace(
        run,
        T=T,
        q=q,
        warnings=list(run.warnings),
        source=f'{run.source} [{label}, noise {noise_T_C:g} degC / {noise_q_rad:g} rad]',
    )


def _switch(params: PlantParams) -> Callable[[WristPlant, float], None]:
    def switch(plant: WristPlant, t: float) -> None:
        plant.params = params

    return switch


#: the realistic sensors of a real rig (the monitor's false-alarm runs): white noise, 16-bit ADC quantisation
#: (temperatures over -50..150 degC, angle over -pi..pi) and periodic interference: mains hum at 50.1 Hz sampled at
#: 100 Hz (aliased to 49.9 Hz) and a 0.7 Hz pump / fan line. Jittering stamps and dropped samples are the bag
#: writer's (testdata.write_bag's ``stamp_jitter_s``, ``drop_rate``)
REALISTIC = {
    'noise_T_C': 0.3,
    'noise_q_rad': 3e-3,
    'hum_T_C': 0.1,
    'hum_q_rad': 1e-3,
    'hum_hz': 50.1,
    'line_T_C': 0.05,
    'line_q_rad': 5e-4,
    'line_hz': 0.7,
}


def realistic(run: Run, seed: int = 0, scale: float = 1.0) -> Run:
    """`run` read through realistic sensors (:data:`REALISTIC`, amplitudes times `scale`)."""
    r = REALISTIC
    rng = np.random.default_rng(seed)
    phase = rng.uniform(0, 2 * np.pi, 4)
    t = run.t[:, None]
    T = run.T + scale * (
        rng.normal(0.0, r['noise_T_C'], run.T.shape)
        + r['hum_T_C'] * np.sin(2 * np.pi * r['hum_hz'] * t + phase[:2])
        + r['line_T_C'] * np.sin(2 * np.pi * r['line_hz'] * t + phase[2:])
    )
    q = run.q + scale * (
        rng.normal(0.0, r['noise_q_rad'], run.q.shape)
        + r['hum_q_rad'] * np.sin(2 * np.pi * r['hum_hz'] * run.t + phase[0])
        + r['line_q_rad'] * np.sin(2 * np.pi * r['line_hz'] * run.t + phase[2])
    )
    lsb_T, lsb_q = 200.0 / 2**16, 2 * np.pi / 2**16
    return dataclasses.replace(
        run,
        T=np.round(T / lsb_T) * lsb_T,
        q=np.round(q / lsb_q) * lsb_q,
        warnings=list(run.warnings),
        source=f'{run.source} [realistic sensors x{scale:g}]',
    )


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
    per = {
        'offset': 'temp_offset_{}_C',
        'gain': 'temp_gain_err_{}',
        'delay': 'temp_delay_{}_s',
        'lag': 'temp_lag_{}_s',
        'drift': 'temp_drift_{}_C_per_h',
    }
    if d.channel in ('T1', 'T2', 'T'):
        if cause == 'temp_sensor_offset':
            return ['temp_offset_C']
        if cause == 'sensor_lag':
            return ['temp_lag_s']
        return [per[d.kind].format(i) for i in ch] if d.kind in per else []
    return {
        ('q', 'offset'): ['angle_offset_rad'],
        ('q', 'gain'): ['angle_gain_err'],
        ('q', 'delay'): ['angle_delay_s'],
        ('q', 'lag'): ['angle_lag_s'],
        ('q', 'drift'): ['angle_drift_rad_per_h'],
        ('u', 'dead_zone'): ['tem_dead_zone_V'],
        ('u', 'saturation'): ['tem_headroom_V'],
        ('u', 'command_delay'): ['command_delay_s'],
    }.get((d.channel, d.kind), [])


def sweep(magnitude: int | None = None) -> list[Distortion]:
    """Every sweep entry at its weak (0), strong (1) or both (None) magnitudes."""
    out = []
    for (ch, kind), (mags, unit, _) in SWEEP.items():
        for i, v in enumerate(mags):
            if magnitude is None or magnitude == i:
                out.append(Distortion(kind, ch, v, unit))
    return out
