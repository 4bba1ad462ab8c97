"""Catalogue of candidate model discrepancies and the extended model that contains them all.

Every effect is a parametric extension of the nominal plant (:class:`PlantParams()`), named
by a physical mechanism and a subsystem. All effects live in one *extended model* whose
parameter vector (:data:`PARAMS`) is nominal at its default values; a candidate frees a
few of those parameters. Evaluation is batched: N parameter rows give N replays in one
kernel call (candidate grids, finite-difference Jacobians, bootstrap).

Signal chain of the extended model (doc/explanation/diagnosis.md has the equations)::

    commands u --delay, TEM driver (dead zone, saturation)--> applied drive
    drive --TEM heat balance (gain, loss, Joule, coupling, ambient offset + drift)--> T_true
    T_true --thermocouple i (lag, delay, gain, offset, drift; per channel)--> T_measured
    T_measured --inverse sensor--> T_true^ --wire lag, transition shift, cycle drift--> T_wire
    T_wire + payload --SD-GPI + joint (payload, Coulomb/static, viscous, pre-load)--> q
    q --chain backlash (play), potentiometer (delay, lag, offset, gain, drift)--> q_measured
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.signal import savgol_coeffs, savgol_filter

from sma_wrist.core.plant.extensions import PARAMS, STATIC_PER_COULOMB, TEMP_CHANNEL_KEYS, TEMP_GAIN_REF_C, drive
from sma_wrist.core.plant.wrist import PlantParams
from sma_wrist.core.signals import first_order  # noqa: F401 - the catalogue's lags, re-exported
from sma_wrist.core.thermal import kernel as tk
from sma_wrist.diagnose.kernels import Constants, _jit
from sma_wrist.diagnose.steps import angle_steps, event_samples, restarts

if TYPE_CHECKING:
    from sma_wrist.core.hysteresis.phase_fraction import PhaseFractionWire

INDEX = {p.name: i for i, p in enumerate(PARAMS)}
NOMINAL = np.array([p.nominal for p in PARAMS])
LOWER = np.array([p.lower for p in PARAMS])
UPPER = np.array([p.upper for p in PARAMS])
TYPICAL = np.array([p.typical for p in PARAMS])
#: temperatures noisier than this [degC] are smoothed before the hysteresis replay
SMOOTH_ABOVE_C = 0.01
#: smoothing window of the measured temperatures that drive the hysteresis replay [s]
SMOOTH_WINDOW_S = 0.3
#: candidate windows of the noise-matched smoothing [s] (input_noise_angle picks one)
SMOOTH_WINDOWS_S = (0.1, 0.2, 0.3, 0.6)
#: the rate window [s] where there are too few samples to choose one (:func:`rate_window`). A thermocouple lag is
#: undone by y + tau dy/dt, and a fixed 1 s fit rounded each reversal of the heating, whose peaks the wires' memory
#: keeps: on the emulated phase-fraction wrist (lag 0.2 s) the emulator's own wire replayed its lagged readings to
#: 4.1 mrad RMS from the 1 s rate and to 0.7 mrad from central differences (0.2 mrad from the true node temperatures)
RATE_WINDOW_S = 1.0
#: candidate rate windows of noisy readings [s] (:func:`rate_window` picks one, bias and noise weighted alike). On
#: the emulated phase-fraction wrist's 0.2 s-lagged readings with white noise added, the emulator's own wire replayed
#: best from 0.3 s at 0.07 degC (2.1 mrad RMS; 3.7-4.2 from 1 s) and from 0.6 s at 0.2 degC (4.2-5.0; 4.5-5.2 from 1 s)
RATE_WINDOWS_S = (0.2, 0.3, 0.6, 1.0)
#: ... and of readings below SMOOTH_ABOVE_C of noise, where central differences are the reference: an emulated ADC's
#: 0.002 degC, amplified by them, left the emulator's own wire 1.9 mrad RMS off its replay (from central differences),
#: 0.6 from 0.1 s; without noise they are best (0.3 mrad on a 10 ms grid)
RATE_WINDOWS_NOISE_FREE_S = (0.0, 0.05, 0.1)
#: the weight of a window's bias against its noise among RATE_WINDOWS_NOISE_FREE_S: the bias sits at the reversals
#: of the heating, whose peaks the wires' memory keeps, so it costs the angle more than noise of the same RMS; with
#: weight 1 the emulated ADC's case took 0.2 s of the longer list (0.9 mrad), with 4 it takes 0.1 s
RATE_BIAS_WEIGHT = 4.0
#: window of the local fit that gives a noisy run's initial temperatures [s]
START_WINDOW_S = 0.5
#: the muscle nodes' lead over their first readings is fitted over this many of the model's thermocouple lags
START_FIT_LAGS = 3.0
#: realisations of the input-noise propagation (:meth:`ExtendedModel.input_noise_angle`)
INPUT_NOISE_REALISATIONS = 2
#: the mechanics replay's own step error (first order in the step) must stay below this
#: fraction of the angle's noise level; else the replay is extrapolated to a vanishing step
STEP_ERROR_FRACTION = 0.5
#: one "cycle" of the hysteresis-drift effect: this much temperature travel (40 degC up and down)
CYCLE_TRAVEL_C = 80.0

THERMAL_KEYS = (
    'tem_gain_err',
    'loss_scale_err',
    'joule_scale_err',
    'ambient_offset_C',
    'ambient_drift_C_per_h',
    'coupling_per_s',
    'temp_offset_C',
    'command_delay_s',
    'tem_dead_zone_V',
    'tem_headroom_V',
    'temp_offset_1_C',
    'temp_offset_2_C',
    'temp_gain_err_1',
    'temp_gain_err_2',
)
#: parameters that change the drive the heat balance sees (one kernel call per distinct combination)
DRIVE_KEYS = ('command_delay_s', 'tem_dead_zone_V', 'tem_headroom_V')
MECH_KEYS = (
    (
        'temp_offset_C',
        'temp_lag_s',
        'hyst_lag_s',
        'hyst_drift_C_per_cycle',
        'hyst_shift_C',
        'payload_err_kg',
        'coulomb_Nm',
        'viscous_Nms',
        'preload_err_mm',
    )
    + TEMP_CHANNEL_KEYS[1]
    + TEMP_CHANNEL_KEYS[2]
)
_TH_IDX = [INDEX[k] for k in THERMAL_KEYS]
#: per thermocouple: indices of (offset, gain error, delay, lag, drift)
CHANNEL_IDX = tuple(tuple(INDEX[k] for k in TEMP_CHANNEL_KEYS[i]) for i in (1, 2))
_ME_IDX = [INDEX[k] for k in MECH_KEYS]


@dataclass(frozen=True)
class Effect:
    id: str
    name: str
    subsystem: str  # thermal | actuator | hysteresis | joint | sensor
    params: tuple[str, ...]
    meaning: str


CATALOGUE: tuple[Effect, ...] = (
    Effect(
        'sensor_delay',
        'angle sensor delay',
        'sensor',
        ('angle_delay_s',),
        'the measured angle is the true angle some time ago (filtering, acquisition)',
    ),
    Effect(
        'sensor_lag',
        'temperature sensor first-order lag',
        'sensor',
        ('temp_lag_s',),
        'thermocouples respond with a time constant (poor contact with the bundle)',
    ),
    Effect(
        'sensor_offset_gain',
        'angle sensor offset and gain error',
        'sensor',
        ('angle_offset_rad', 'angle_gain_err'),
        'potentiometer mis-calibrated: q_meas = q + offset + gain_err (q - q_neutral)',
    ),
    Effect(
        'temp_sensor_offset',
        'temperature sensor offset',
        'sensor',
        ('temp_offset_C',),
        'both thermocouple channels read too high/low (cold-junction error)',
    ),
    Effect(
        'ambient_drift',
        'ambient/coolant temperature drift',
        'thermal',
        ('ambient_drift_C_per_h',),
        'room or coolant temperature changes linearly during the run',
    ),
    Effect(
        'thermal_coupling',
        'thermal coupling between the muscles',
        'thermal',
        ('coupling_per_s',),
        'heat flows between the two bundles (ThermalParams.coupling_per_s)',
    ),
    Effect(
        'tem_mismatch',
        'TEM drive gain mismatch',
        'thermal',
        ('tem_gain_err',),
        'the TEM pumps more/less heat per volt than Table 4.9 with input_per_volt = 0.4',
    ),
    Effect(
        'actuator_delay',
        'TEM command delay',
        'actuator',
        ('command_delay_s',),
        'the drive applies each command late (serial link, driver, a host that falls behind)',
    ),
    Effect(
        'payload_mismatch',
        'payload mismatch',
        'joint',
        ('payload_err_kg',),
        'the mass at the lever differs from /wrist/payload',
    ),
    Effect(
        'friction',
        'Coulomb/static friction',
        'joint',
        ('coulomb_Nm',),
        'more dry friction in bearings/chain (static = 1.5 x Coulomb)',
    ),
    Effect(
        'viscous_damping', 'viscous damping', 'joint', ('viscous_Nms',), 'the joint is more/less damped than 0.15 N m s'
    ),
    Effect(
        'backlash',
        'backlash',
        'joint',
        ('backlash_rad',),
        'play between chain/sprocket and the output shaft (play operator on the angle)',
    ),
    Effect(
        'hysteresis_rate',
        'rate-dependent hysteresis',
        'hysteresis',
        ('hyst_lag_s',),
        'the wires lag the measured temperature, loops widen with the heating rate',
    ),
    Effect(
        'hysteresis_drift',
        'hysteresis drift over cycles',
        'hysteresis',
        ('hyst_drift_C_per_cycle',),
        'transition temperatures move with the number of cycles (functional fatigue)',
    ),
    Effect(
        'hysteresis_shift',
        'transition temperature shift',
        'hysteresis',
        ('hyst_shift_C',),
        'the wires transform hotter or colder than the model (fatigue that has happened, another wire or heat '
        'treatment): the angle moves at other measured temperatures, the temperatures themselves are right',
    ),
    # per-channel sensor chain and TEM driver: what a real sensor, driver or wire does
    Effect(
        'temp_sensor_offsets',
        'thermocouple offsets (per channel)',
        'sensor',
        ('temp_offset_1_C', 'temp_offset_2_C'),
        'each thermocouple reads high/low by its own amount (one bad junction, a cold-junction error on one input)',
    ),
    Effect(
        'temp_sensor_gain',
        'thermocouple gain errors (per channel)',
        'sensor',
        ('temp_gain_err_1', 'temp_gain_err_2'),
        'a thermocouple amplifier scales the reading about 25 degC (wrong type, wrong gain resistor)',
    ),
    Effect(
        'temp_sensor_delay',
        'thermocouple delays (per channel)',
        'sensor',
        ('temp_delay_1_s', 'temp_delay_2_s'),
        'a thermocouple reading is the temperature some time ago (filter, slow acquisition, buffered link)',
    ),
    Effect(
        'temp_sensor_lags',
        'thermocouple lags (per channel)',
        'sensor',
        ('temp_lag_1_s', 'temp_lag_2_s'),
        'each thermocouple responds with its own time constant (one junction loose in the bundle)',
    ),
    Effect(
        'temp_sensor_drift',
        'thermocouple drift (per channel)',
        'sensor',
        ('temp_drift_1_C_per_h', 'temp_drift_2_C_per_h'),
        'a thermocouple reading drifts linearly in time (cold-junction warming, amplifier drift)',
    ),
    Effect(
        'angle_sensor_lag',
        'potentiometer lag',
        'sensor',
        ('angle_lag_s',),
        'the angle reading responds with a first-order time constant (RC anti-alias filter)',
    ),
    Effect(
        'angle_sensor_drift',
        'potentiometer drift',
        'sensor',
        ('angle_drift_rad_per_h',),
        'the angle reading drifts linearly in time (reference voltage, temperature of the pot)',
    ),
    Effect(
        'tem_dead_zone',
        'TEM driver dead zone',
        'actuator',
        ('tem_dead_zone_V',),
        'the TEM driver gives nothing below a threshold and |command| - threshold above it',
    ),
    Effect(
        'tem_saturation',
        'TEM driver saturation',
        'actuator',
        ('tem_headroom_V',),
        'the TEM driver saturates below the nominal drive limit (weak supply, current limit)',
    ),
    Effect(
        'recalibrate_thermal',
        'thermal parameter recalibration',
        'thermal',
        ('tem_gain_err', 'loss_scale_err', 'ambient_offset_C'),
        'no new physics: Table 4.9 drive gain, heat loss and ambient refitted',
    ),
    Effect(
        'recalibrate_mechanics',
        'mechanical parameter recalibration',
        'joint',
        ('preload_err_mm', 'payload_err_kg', 'viscous_Nms'),
        'no new physics: pre-load elongation, payload and damping refitted',
    ),
)
EFFECTS = {e.id: e for e in CATALOGUE}


def theta(**kw: float) -> np.ndarray:
    """Full parameter vector: nominal except the given entries."""
    v = NOMINAL.copy()
    for k, x in kw.items():
        v[INDEX[k]] = x
    return v


# ----------------------------------------------------------------------------- helpers
def _d2_var(x: np.ndarray, lag: int) -> float:
    """Robust (MAD) variance of the second differences x[i] - 2 x[i + lag] + x[i + 2 lag] along axis 0."""
    d2 = (x[: -2 * lag] - 2.0 * x[lag:-lag] + x[2 * lag :]).ravel()
    return float((np.median(np.abs(d2 - np.median(d2))) * 1.4826) ** 2)


#: the quantisation steps the noise floors assume (:func:`noise_sigma`'s ``lsb``): a 16-bit ADC over one turn of the
#: angle potentiometer [rad] and over a 200 degC thermocouple span [degC], about the bridge's default calibration's
#: 0.1 mrad and 4 mdegC per count (:mod:`sma_wrist.hw.calibration`)
ANGLE_LSB_RAD = 2 * np.pi / 2**16
TEMP_LSB_C = 200.0 / 2**16


def noise_sigma(x: np.ndarray, lsb: float = 0.0) -> float:
    """White-noise std of a smooth signal's samples, from its second differences two samples apart (robust, MAD).

    Two apart, not adjacent: a bag's samples are interpolated onto the analysis grid between jittered stamps,
    which averages neighbours and correlates the noise of adjacent grid points; adjacent second differences then
    cancel most of it. On a 30 min pid run read through realistic sensors (0.3 degC / 3 mrad white noise, stamp
    jitter 1 ms at 100 Hz) adjacent ones gave 0.19 degC / 1.9 mrad for the 0.24 degC / 2.4 mrad on the grid."""
    if x.shape[0] < 14:
        return float(np.std(x)) or 1.0
    return float(max(np.sqrt(_d2_var(x, 2) / 6.0), lsb / np.sqrt(12.0), 1e-9))


def noise_density_sigma(x: np.ndarray, lsb: float = 0.0) -> float:
    """Std of the white noise with the same low-frequency power as the noise of a smooth signal's samples.

    What a smoothing filter (or the replays' slow physics) lets through of the noise is its low-frequency power,
    sigma^2 + 2 c1 for noise correlated over one sample (c1: covariance of neighbours, left by the interpolation
    onto the grid). With V1, V2 the variances of the second differences one and two samples apart,
    V2 = 6 sigma^2 and V1 = 6 sigma^2 - 8 c1, so sigma_lf^2 = (10 V2 / 6 - V1) / 4; for white noise sigma_lf =
    sigma; it is taken as never below sigma. On the 30 min pid run of :func:`noise_sigma` 0.305 degC / 3.05 mrad for the sensors' 0.3 degC / 3 mrad."""
    if x.shape[0] < 14:
        return noise_sigma(x, lsb)
    v2, v1 = _d2_var(x, 2), _d2_var(x, 1)
    return float(max(np.sqrt(max(10.0 * v2 / 6.0 - v1, v2 / 6.0 * 4.0) / 4.0), lsb / np.sqrt(12.0), 1e-9))


def play(x: np.ndarray, width: float) -> np.ndarray:
    """Backlash (play operator) of total width `width` along axis 0 (1-D), starting centred."""
    if width <= 0:
        return x
    return _play_1d(np.ascontiguousarray(x, dtype=float), 0.5 * width)


@_jit
def _play_1d(x, h):  # pragma: no cover - compiled
    y = np.empty_like(x)
    prev = x[0]
    y[0] = prev
    for k in range(1, x.shape[0]):
        prev = min(max(prev, x[k] - h), x[k] + h)
        y[k] = prev
    return y


def advanced(x: np.ndarray, lead: float, dt: float) -> np.ndarray:
    """x(t + lead) with linear interpolation, held at x[-1] after the end (inverse of :func:`delayed`)."""
    if lead <= 0:
        return x
    return delayed(x[::-1], lead, dt)[::-1]


def delayed(x: np.ndarray, delay: float, dt: float) -> np.ndarray:
    """x(t - delay) with linear interpolation, held at x[0] before the start."""
    if delay <= 0:
        return x
    s = delay / dt
    i = int(np.floor(s))
    f = s - i
    n = x.shape[0]
    idx0 = np.clip(np.arange(n) - i, 0, n - 1)
    idx1 = np.clip(np.arange(n) - i - 1, 0, n - 1)
    return (1 - f) * x[idx0] + f * x[idx1]


def cycle_count(T: np.ndarray, dt: float) -> np.ndarray:
    """Cycles so far per muscle: temperature travel / CYCLE_TRAVEL_C, on a 1 s-smoothed signal."""
    win = max(3, int(round(1.0 / dt)) | 1)
    Ts = savgol_filter(T, win, 1, axis=0) if T.shape[0] > win else T
    travel = np.concatenate([np.zeros((1,) + T.shape[1:]), np.cumsum(np.abs(np.diff(Ts, axis=0)), axis=0)])
    return travel / CYCLE_TRAVEL_C


def smooth_and_rate(
    T: np.ndarray, dt: float, window_s: float = 0.3, rate_window_s: float = RATE_WINDOW_S
) -> tuple[np.ndarray, np.ndarray]:
    """Zero-phase smoothed temperature (``window_s`` window) and its rate (``rate_window_s`` window; 0: central
    differences of the readings) [degC, degC/s]; a run shorter than a window keeps its readings and their central
    differences."""
    if T.shape[0] < 3:
        return T.copy(), np.gradient(T, dt, axis=0) if T.shape[0] > 1 else np.zeros_like(T)
    w_s = max(5, int(round(window_s / dt)) | 1)
    w_r = max(5, int(round(rate_window_s / dt)) | 1) if rate_window_s > 0.0 else 0
    if T.shape[0] <= max(w_s, w_r):
        return T.copy(), np.gradient(T, dt, axis=0)
    rate = np.gradient(T, dt, axis=0) if w_r == 0 else savgol_filter(T, w_r, 2, deriv=1, delta=dt, axis=0)
    return savgol_filter(T, w_s, 2, axis=0), rate


def rate_window(
    T: np.ndarray, dt: float, sigma: np.ndarray, windows: Sequence[float], bias_weight: float = 1.0
) -> float:
    """The window [s] of ``windows`` (0: central differences) whose rate of the readings T (K, C) has the smallest
    estimated error, summed over the channels, for white noise of std ``sigma`` (C,) [degC].

    The error of a window's rate is its noise, sigma^2 times the sum of its filter's squared coefficients, plus its
    bias (it rounds the rate's changes) times ``bias_weight``. The bias is estimated against the shortest window's
    rate: the mean squared difference of the two rates less what their noise alone gives (Stein-like unbiased risk).
    Windows that span the same number of samples on this grid are one candidate (the shortest named)."""
    sigma = np.asarray(sigma, float)
    # (samples, polynomial order): central differences are the slope of a line through three samples
    cand: dict[tuple[int, int], float] = {}
    for w in sorted(windows):
        key = (3, 1) if w <= 0.0 else (max(5, int(round(w / dt)) | 1), 2)
        cand.setdefault(key, float(w))
    if T.shape[0] <= max(k for k, _ in cand):
        return RATE_WINDOW_S
    keys = list(cand)
    h = [savgol_coeffs(k, o, deriv=1, delta=dt) for k, o in keys]
    r0 = savgol_filter(T, keys[0][0], keys[0][1], deriv=1, delta=dt, axis=0)
    s2 = sigma**2
    risk = []
    for (k, o), hk in zip(keys, h):
        ref = np.zeros(max(k, h[0].size))
        off = (ref.size - h[0].size) // 2
        ref[off : off + h[0].size] = h[0]
        d2 = ((savgol_filter(T, k, o, deriv=1, delta=dt, axis=0) - r0) ** 2).mean(axis=0)
        bias2 = np.maximum(d2 - s2 * float(np.sum((hk - ref) ** 2)), 0.0)
        risk.append(float(np.sum(bias_weight * bias2 + s2 * float(np.sum(hk**2)))))
    return list(cand.values())[int(np.argmin(risk))]


def thermocouples(T: np.ndarray, r: np.ndarray, dt: float) -> np.ndarray:
    """Readings (K, 2) of the thermocouples for true temperatures T (K, 2) under a parameter row:
    common lag, per-channel lag, delay, gain about TEMP_GAIN_REF_C, offsets, drift (SensorChain's order)."""
    out = np.empty_like(T)
    t = np.arange(T.shape[0]) * dt
    y = first_order(T, r[INDEX['temp_lag_s']], dt)
    for c, (ko, kg, kd, kl, kr) in enumerate(CHANNEL_IDX):
        yc = delayed(first_order(y[:, c], r[kl], dt), r[kd], dt)
        out[:, c] = (
            TEMP_GAIN_REF_C
            + (1.0 + r[kg]) * (yc - TEMP_GAIN_REF_C)
            + r[INDEX['temp_offset_C']]
            + r[ko]
            + r[kr] / 3600.0 * t
        )
    return out


# ----------------------------------------------------------------------------- model
def thermal_coef(consts: Constants, th_row: np.ndarray) -> tuple[np.ndarray, float, float]:
    """(coef (16,), ambient drift [degC/s], ambient offset [degC]) for values of THERMAL_KEYS; (37,) where the
    model's heat balance is the Peltier form (:func:`peltier_coef`)."""
    c = consts.th_coef.copy()
    v = dict(zip(THERMAL_KEYS, th_row))
    if c.size > tk.N_COEF:
        return peltier_coef(c, v)
    c[0] *= 1.0 + v['tem_gain_err']
    c[1] = v['coupling_per_s']
    ls = 1.0 + v['loss_scale_err']
    b = 2  # muscle face: K_at, K_t, K_Tinf, K_T, K_R, K_inf
    c[b + 2] *= ls
    c[b + 3] *= ls
    c[b + 5] *= ls
    for f in (0, 1):
        c[2 + 6 * f + 4] *= 1.0 + v['joule_scale_err']
    for f in (0, 1):
        bb = 2 + 6 * f
        c[bb + 5] += (c[bb + 2] - c[bb + 3]) * v['ambient_offset_C']
    return c, v['ambient_drift_C_per_h'] / 3600.0, v['ambient_offset_C']


def peltier_coef(c: np.ndarray, v: dict[str, float]) -> tuple[np.ndarray, float, float]:
    """The thermal extension effects on a Peltier-form row (thermal.kernel.heat_balance_constants), each the
    Peltier form's counterpart of its Table 4.9 meaning: ``tem_gain_err`` scales the drive (the voltage the module
    sees), ``loss_scale_err`` the muscle node's loss h_m, ``joule_scale_err`` the Joule heat, ``ambient_offset_C``
    moves T_amb and T_cool, ``ambient_drift_C_per_h`` moves both over time, ``coupling_per_s`` adds to the form's own
    muscle-muscle conductance. Returns (coef, ambient drift [degC/s], ambient offset [degC])."""
    c[tk.P_GAIN] *= 1.0 + v['tem_gain_err']
    c[tk.P_JOULE] *= 1.0 + v['joule_scale_err']
    c[1] += v['coupling_per_s']  # on top of the form's own (its file's)
    for layer in range(2):
        o = tk.P_LAYER + tk.N_PELTIER_LAYER * layer
        c[o + 5] *= 1.0 + v['loss_scale_err']
        c[o + 7] += v['ambient_offset_C']
        c[o + 8] += v['ambient_offset_C']
    return c, v['ambient_drift_C_per_h'] / 3600.0, v['ambient_offset_C']


class ExtendedModel:
    """Batched replays of one run under parameter rows of :data:`PARAMS`.

    Parameters
    ----------
    run:
        :class:`sma_wrist.diagnose.data.Run` (uniform grid, commands, temperatures, angle, payload).
    params:
        Nominal plant; default ``PlantParams()``.
    nominal:
        The row the fits start from (default :data:`NOMINAL`): a params file's ``model.*`` values
        (:func:`theta`), so that what is fitted is what that model does not describe.
    """

    def __init__(  # type: ignore[no-untyped-def]
        self, run, params: PlantParams | None = None, nominal: np.ndarray | None = None
    ) -> None:
        self.run = run
        self.nominal = NOMINAL.copy() if nominal is None else np.asarray(nominal, float).copy()
        self.consts = Constants(params or PlantParams(dt=min(run.dt, 0.01)))
        self.dt = run.dt
        self.substeps = max(1, int(np.ceil(run.dt / 0.01 - 1e-9)))
        self.extrapolate = False  # choose_mechanics_step: Richardson-extrapolate the mechanics replay
        self._rest = self.consts.params.rest_thermal(1)[0]  # (2 layers, 2 faces) of the model's heat balance
        self.T_noise = 0.0
        self.rate_window_s = RATE_WINDOW_S
        self._xi: np.ndarray | None = None  # the latent heat's martensite fractions (latent_fraction)
        self.resync: np.ndarray | None = None  # (K,) angles [rad] the mechanics replays restart from (restart_at)
        if run.T is not None:
            self.T_noise = noise_sigma(run.T)
            noise_free = self.T_noise < SMOOTH_ABOVE_C
            # noise-free (simulated, emulated) temperatures: smoothing would only distort the steep transitions (6x
            # the replay error on a plant_sim run). The rate window follows the readings' own noise (an ADC's
            # quantisation shows in it): floored at a resolution, noise-free simulated readings would look noisy and
            # lose their central differences
            sigma = [noise_density_sigma(run.T[:, c]) for c in (0, 1)]
            self.rate_window_s = (
                rate_window(run.T, run.dt, sigma, RATE_WINDOWS_NOISE_FREE_S, RATE_BIAS_WEIGHT)
                if noise_free
                else rate_window(run.T, run.dt, sigma, RATE_WINDOWS_S)
            )
            self.T_s, self.T_rate = smooth_and_rate(run.T, run.dt, SMOOTH_WINDOW_S, self.rate_window_s)
            if noise_free:
                self.T_s = run.T.copy()
            # cycles counted from where the scored data begin (after a monitor window's lead-in, Run.settle_s): a
            # drift acts from there. In a window cut after a located change that is the change, before which the
            # residuals say the wrist was its model; counted from the lead-in's start, the drift acted before the
            # change too. On an emulated wire drift (+6 degC over 60 s from 120 s, pid) the window ending 50 s after the
            # onset: 67 % of the angle misfit removed (partly explained) counted from its lead-in's start, 91 % counted
            # from its scored part's (5 s after the onset)
            self.cycles = self.from_reference(cycle_count(run.T, run.dt))
            # the thermal replay starts from the first reading: of a noisy one, the start of a
            # local quadratic fit (a single noisy sample offsets the replay for tens of seconds)
            head = smooth_and_rate(run.T[: max(50, int(5.0 / run.dt))], run.dt, START_WINDOW_S)
            self.T_start = run.T[0].copy() if noise_free else head[0][0]
            self.T_rate_start = self.start_rate()  # [degC/s], what a lagged reading trails its node by, per s of lag
        self._mech_cache: dict[tuple, tuple[np.ndarray, ...]] = {}
        self._th_cache: dict[tuple, np.ndarray] = {}

    def with_wire(self, wire: PhaseFractionWire | None) -> ExtendedModel:
        """This run's replays for the plant with another wire (PlantParams.wire; None: the SD-GPI): the same as an
        ExtendedModel of the run and ``dataclasses.replace(params, wire=wire)``, with this one's inputs (smoothed
        temperatures and rates, their noise, cycle counts, thermal start, step and smoothing choices), which do not
        depend on the wire, taken over instead of derived again; the replays' caches start empty. What a fit of the
        wire replays at each of its evaluations."""
        out = copy.copy(self)
        out.consts = self.consts.with_wire(wire)
        out._mech_cache, out._th_cache, out._xi = {}, {}, None
        return out

    def restart_at(self, samples: Sequence[int], angles_rad: Sequence[float]) -> None:
        """Restart every mechanics replay (and the latent heat's fractions) from these angles [rad], the joint at rest,
        at the end of these samples: after a step of the measured angle that the model does not make
        (:mod:`sma_wrist.diagnose.steps`), so that the rest of the run is judged from where the wrist went rather than
        from where the model stayed. The wires are committed at the new angle, as the device's were on its way
        there. No samples: no restart."""
        samples = np.asarray(samples, dtype=int)
        if samples.size == 0:
            self.resync = None
        else:
            if samples.min() < 1 or samples.max() >= self.run.n:
                raise ValueError(f'restart samples must lie in 1..{self.run.n - 1}, not {samples.tolist()}')
            self.resync = np.full(self.run.n, np.nan)
            self.resync[samples] = np.asarray(angles_rad, dtype=float)
        self._mech_cache.clear()
        self._th_cache.clear()
        self._xi = None

    def restart_after_steps(self, row: np.ndarray, i0: int, noise_rad: float, source: str = 'measured') -> list[dict]:
        """Find the steps of the measured angle that the replay under ``row`` does not make (after sample ``i0``;
        :func:`sma_wrist.diagnose.steps.angle_steps`, times from the run's start, ``noise_rad`` the angle's noise
        [rad]), restart every replay after each (:meth:`restart_at`, the readings turned into true angles under
        ``row``) and mark the steps' samples as not measured (``run.valid``: the event is named, no replay is scored
        on it). Returns the steps (none: nothing changes)."""
        run = self.run
        if run.q is None:
            return []
        q_model = self.mechanics(np.asarray(row, float)[None], None, source)[0][:, 0]
        k = q_model.shape[0]
        valid = np.ones(run.n, bool) if run.valid is None else np.asarray(run.valid, bool)
        t = run.t - run.t[0]
        steps = angle_steps(t[i0:k], run.q[i0:k], q_model[i0:], noise_rad, valid[i0:k])
        if steps:
            idx, ang = restarts(t, run.q, steps)
            self.restart_at(idx, [self.angle_unsensed(a, i, row) for i, a in zip(idx, ang, strict=True)])
            self.run = dataclasses.replace(run, valid=valid & ~event_samples(t, steps))
        return steps

    def from_reference(self, cycles: np.ndarray) -> np.ndarray:
        """Cycle counts (K, 2) relative to the first scored sample (after ``Run.settle_s``, as the fit's split)."""
        settle = getattr(self.run, 'settle_s', 0.0) or 0.0
        i = min(int(round(settle / self.dt)), cycles.shape[0] // 2)
        return cycles - cycles[i]

    # -- thermal ----------------------------------------------------------------------
    def thermal_coef(self, th_row: np.ndarray) -> tuple[np.ndarray, float, float]:
        return thermal_coef(self.consts, th_row)

    def latent_fraction(self) -> np.ndarray | None:
        """(K, 2) the muscles' martensite fractions that carry the heat balance's latent heat (Eq. P.4,
        PeltierParams.latent_C), or None where it has none (latent 0, an SD-GPI wire, no measured temperatures).

        The fractions are the phase-fraction wire's in the mechanics replay on the measured temperatures under the
        nominal row (:meth:`wire_temperature`), not on the thermal replay's own: every thermal row then shares one
        input, the thermal replay stays one call per row, and the wire's transformation is placed where the
        measurements put it. Computed once per model (and again when the smoothing of the temperatures changes).
        On the emulated phase-fraction wrist (latent 0.78 degC per full transformation, 0.2 s thermocouple lag) its
        own TEM values replayed its thermocouples to 0.26/0.29 degC RMS per TEM without the latent heat and to
        0.011/0.016 with it, the fractions taken so."""
        if not self.consts.has_latent or self.run.T is None:
            return None
        if self._xi is None:
            self._xi = self.wire_fraction(self.nominal)
        return self._xi

    def wire_fraction(self, r: np.ndarray) -> np.ndarray:
        """(K, 2) the phase-fraction wires' martensite fractions in the mechanics replay on the measured temperatures
        under the parameter row ``r`` (:meth:`wire_temperature`, the run's step); the model's wire must be one."""
        Tw = self.wire_temperature(r, self.T_s, self.T_rate, self.cycles)[:, None]
        return self.consts.martensite_fraction(Tw, self.dt, self.joint_row(r), self.substeps, self.resync)[:, 0]

    def thermal_true(self, rows: np.ndarray, upto: int | None = None) -> np.ndarray:
        """(K, N, 2) true muscle temperatures from the commands for parameter rows (N, P)."""
        run = self.run
        K = run.n if upto is None else upto
        out = np.empty((K, rows.shape[0], 2))
        todo: dict[tuple, list[int]] = {}
        for j, r in enumerate(rows):
            todo.setdefault((K,) + tuple(np.round(r[_TH_IDX], 12)), []).append(j)
        missing = [k for k in todo if k not in self._th_cache]
        if missing:
            # the muscle nodes at the start: the first readings advanced by the model's own thermocouple lags (its
            # nominal row's), which the readings had before the run began (a window cut while the muscles move
            # starts with its nodes ahead of their readings; started at the readings, the node's error decays over
            # the heat balance's minute-long time constant: a monitor window of a simulated run of the model itself
            # with a 0.1 s lag was called a thermocouple drift). A row's departure from those lags is a change within
            # the run (a monitor window is cut just before one), so it does not move the start
            lead = self.nominal[INDEX['temp_lag_s']] + self.nominal[[c[3] for c in CHANNEL_IDX]]
            coefs, drifts, x0s = [], [], []
            for key in missing:
                c, drift, off = self.thermal_coef(np.array(key[1:]))
                coefs.append(c)
                drifts.append(drift)
                kv = dict(zip(THERMAL_KEYS, key[1:]))
                T0 = (
                    self.temp_inverse_static(self.T_start + lead * self.T_rate_start, kv, 0.0)
                    if run.T is not None
                    else self._rest[:, 0]
                )
                x0s.append(self.start_state(T0, off))
            # one kernel call per distinct drive (delay, dead zone, saturation change the input itself)
            i_drive = [1 + THERMAL_KEYS.index(k) for k in DRIVE_KEYS]
            xi = self.latent_fraction()
            T = np.empty((K, len(missing), 2))
            for dk in sorted({tuple(key[i] for i in i_drive) for key in missing}):
                sel = [i for i, key in enumerate(missing) if tuple(key[i] for i in i_drive) == dk]
                u = drive(delayed(run.u, dk[0], self.dt), dk[1], dk[2], self.consts.u_limits[1])
                T[:, sel], _ = self.consts.thermal(
                    u[:K],
                    self.dt,
                    np.array(coefs)[sel],
                    np.array(x0s)[sel],
                    np.array(drifts)[sel],
                    self.substeps,
                    None if xi is None else xi[:K],
                )
            if len(self._th_cache) > 200:  # bound memory; never evict what this call returns
                for k in [k for k in self._th_cache if k not in todo][:100]:
                    del self._th_cache[k]
            for i, key in enumerate(missing):
                self._th_cache[key] = T[:, i]
        for key, js in todo.items():
            out[:, js] = self._th_cache[key][:, None]
        return out

    def start_state(self, T0: np.ndarray, off: float) -> np.ndarray:
        """The heat balance's state (2 layers, 2 faces) [degC] at the run's start: muscle nodes at T0 (2,) [degC],
        exchanger faces measured, carried over or at rest (shifted by the ambient offset ``off`` [degC])."""
        run = self.run
        x0 = self._rest.copy()
        x0[:, 1] += off  # exchanger face starts at its rest state, shifted by the ambient offset
        if getattr(run, 'thermal_start', 'rest') == 'measured':
            # the bag's face thermocouples: the faces' temperature, whatever the ambient (a device commissioned
            # after its excitation started 74-78 degC warm, and from rest its replay was 'unexplained')
            x0[:, 1] = np.asarray(run.thermal_x0)[:, 1]
        elif getattr(run, 'thermal_x0', None) is not None:
            # a window cut from a longer run: the exchanger faces are where the earlier replay left them
            # (from rest, a 45 s window of a clean run was an 'unexplained thermal discrepancy')
            x0[:, 1] += np.asarray(run.thermal_x0)[:, 1] - self._rest[:, 1]
        else:
            x0[:, 1] += T0 - self._rest[:, 0]
        x0[:, 0] = T0
        return x0

    def start_rate(self) -> np.ndarray:
        """The readings' rate at the start (2,) [degC/s] that puts the muscle nodes where the model's own replay
        meets the first START_FIT_LAGS thermocouple lags of readings: a node ahead of its reading by d (the lag times
        this rate) shows in the readings as d (1 - exp(-t / lag)) on top of the replay from the readings (least
        squares for d per muscle, the nominal row's heat balance, drive and lag; a reading at rest gives 0).

        The readings' slope over a window would be the rate only where the drive holds over it: a run that starts
        at rest and heats at full drive 0.1 s later had a 1 s local fit's slope of 0.6-0.9 degC/s at the start for a
        true 0.03-0.07, and its replay started 0.12-0.17 degC hot (0.05 degC RMS over the scored run, its own plant's
        values in the model; fitted here, 0.005)."""
        run = self.run
        r = self.nominal
        lead = r[INDEX['temp_lag_s']] + r[[c[3] for c in CHANNEL_IDX]]
        n = min(run.n, int(round(START_FIT_LAGS * float(lead.max()) / self.dt)) + 1)
        rate = np.zeros(2)
        if n < 3 or not lead.max() > 0 or run.u is None:  # without commands there is no heat-balance replay
            return rate
        kv = dict(zip(THERMAL_KEYS, r[_TH_IDX]))
        c, drift, off = self.thermal_coef(r[_TH_IDX])
        t = np.arange(n) * self.dt
        y0 = self.temp_inverse_static(self.T_start, kv, 0.0)
        u = drive(
            delayed(run.u[:n], kv['command_delay_s'], self.dt),
            kv['tem_dead_zone_V'],
            kv['tem_headroom_V'],
            self.consts.u_limits[1],
        )
        x0 = np.stack([self.start_state(y0 + e, off) for e in (np.zeros(2), np.eye(2)[0], np.eye(2)[1])])
        xi = self.latent_fraction()
        T, _ = self.consts.thermal(
            u, self.dt, np.stack([c] * 3), x0, np.full(3, drift), self.substeps, None if xi is None else xi[:n]
        )
        meas = self.temp_inverse_static(run.T[:n], kv, t)
        for ch in np.flatnonzero(lead > 0):
            # each reading from its value at the start (the lag's state is the reading, not the node); the replayed
            # node is a sampled smooth signal (linear between samples), a start offset a step at the start (held)
            base = y0[ch] + first_order(T[:, 0, ch] - y0[ch], lead[ch], self.dt, linear=True)
            sens = first_order(np.r_[0.0, T[1:, 1 + ch, ch] - T[1:, 0, ch]], lead[ch], self.dt)
            rate[ch] = float(sens @ (meas[:, ch] - base) / (sens @ sens)) / lead[ch]
        return rate

    def thermal_measured(self, rows: np.ndarray, upto: int | None = None) -> np.ndarray:
        """Predicted thermocouple readings (K, N, 2): the sensor chain of model_extensions.SensorChain."""
        T = self.thermal_true(rows, upto)
        out = np.empty_like(T)
        for j, r in enumerate(rows):
            out[:, j] = thermocouples(T[:, j], r, self.dt)
        return out

    @staticmethod
    def temp_inverse_static(T_meas: np.ndarray, v: dict, t: float | np.ndarray) -> np.ndarray:
        """True temperatures from readings through the static part of the sensor chain (offset, gain, drift)."""
        out = np.empty_like(np.asarray(T_meas, float))
        for c in (0, 1):
            ko, kg = TEMP_CHANNEL_KEYS[c + 1][:2]
            kr = TEMP_CHANNEL_KEYS[c + 1][4]
            off = v['temp_offset_C'] + v[ko] + v.get(kr, 0.0) / 3600.0 * t
            out[..., c] = (T_meas[..., c] - off - TEMP_GAIN_REF_C) / (1.0 + v[kg]) + TEMP_GAIN_REF_C
        return out

    # -- mechanics ----------------------------------------------------------------------
    def wire_temperature(
        self, r: np.ndarray, T_meas_s: np.ndarray, T_rate: np.ndarray, cycles: np.ndarray
    ) -> np.ndarray:
        """Wire temperatures from (smoothed) measured ones under a parameter row: the inverse
        sensor chain (drift, offset, gain; delay undone by a lead; lags by y + tau dy/dt), then
        the wire's own lag and cycle drift."""
        t = np.arange(T_meas_s.shape[0]) * self.dt
        T = np.empty_like(T_meas_s)
        for c, (ko, kg, kd, kl, kr) in enumerate(CHANNEL_IDX):
            g = 1.0 + r[kg]
            y = (
                T_meas_s[:, c] - r[INDEX['temp_offset_C']] - r[ko] - r[kr] / 3600.0 * t - TEMP_GAIN_REF_C
            ) / g + TEMP_GAIN_REF_C
            y_rate = (T_rate[:, c] - r[kr] / 3600.0) / g
            y, y_rate = advanced(y, r[kd], self.dt), advanced(y_rate, r[kd], self.dt)
            T[:, c] = y + (r[INDEX['temp_lag_s']] + r[kl]) * y_rate
        T = first_order(T, r[INDEX['hyst_lag_s']], self.dt)
        return T - r[INDEX['hyst_shift_C']] - r[INDEX['hyst_drift_C_per_cycle']] * cycles

    def joint_row(self, r: np.ndarray) -> np.ndarray:
        jr = self.consts.joint_row.copy()
        c = r[INDEX['coulomb_Nm']]
        jr[0] = c
        jr[1] = r[INDEX['viscous_Nms']]
        jr[2] = STATIC_PER_COULOMB * c
        jr[3] += r[INDEX['preload_err_mm']]
        jr[4] = min(max(self.run.payload_kg + r[INDEX['payload_err_kg']], 0.0), 2.0)
        return jr

    def mechanics(
        self, rows: np.ndarray, upto: int | None = None, source: str = 'measured'
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(q_true, qd, load) (K, N) / (K, N, 2) from measured temperatures ('measured') or the
        thermal model ('chain')."""
        K = self.run.n if upto is None else upto
        N = rows.shape[0]
        q = np.empty((K, N))
        qd = np.empty((K, N))
        load = np.empty((K, N, 2))
        todo: dict[tuple, list[int]] = {}
        for j, r in enumerate(rows):
            key = (source, K) + tuple(np.round(r[_ME_IDX], 12))
            if source == 'chain':
                key = key + tuple(np.round(r[_TH_IDX], 12))
            todo.setdefault(key, []).append(j)
        missing = [k for k in todo if k not in self._mech_cache]
        if missing:
            Ts, jrows = [], []
            chain_T = None
            if source == 'chain':
                chain_T = self.thermal_true(rows[[todo[k][0] for k in missing]], K)
            for i, key in enumerate(missing):
                r = rows[todo[key][0]]
                if source == 'chain':
                    Tt = chain_T[:, i]
                    Tw = (
                        first_order(Tt, r[INDEX['hyst_lag_s']], self.dt)
                        - r[INDEX['hyst_shift_C']]
                        - r[INDEX['hyst_drift_C_per_cycle']] * self.from_reference(cycle_count(Tt, self.dt))
                    )
                else:
                    Tw = self.wire_temperature(r, self.T_s[:K], self.T_rate[:K], self.cycles[:K])
                Ts.append(Tw)
                jrows.append(self.joint_row(r))
            qq, qqd, ll = self._joint_replay(np.stack(Ts, axis=1), np.array(jrows))
            for i, key in enumerate(missing):
                self._mech_cache[key] = (qq[:, i], qqd[:, i], ll[:, i])
            if len(self._mech_cache) > 400:  # bound memory; never evict what this call returns
                for k in [k for k in self._mech_cache if k not in todo][:200]:
                    del self._mech_cache[k]
        for key, js in todo.items():
            a, b, c = self._mech_cache[key]
            q[:, js] = a[:, None]
            qd[:, js] = b[:, None]
            load[:, js] = c[:, None]
        return q, qd, load

    def input_noise_angle(self, i0: int = 0, seed: int = 0) -> float:
        """Noise-matched smoothing of the driving temperatures; returns the RMS angle error
        [rad] that the thermocouple noise still puts into the mechanics replay.

        The replay is driven by the *measured* temperatures, so their noise passes through
        the hysteresis (branch switches on noisy sign changes of the rate, steep loads in the
        transitions, memory) and comes out as a structured angle residual: errors in the
        input variables, not model error. Smoothing trades that against the distortion of
        the transitions. Both are measured by simulation: the smoothed temperatures stand
        in for the truth (the shortest window), fresh noise of the estimated level per channel is added and
        smoothed with each window of :data:`SMOOTH_WINDOWS_S`, and the nominal replays are
        compared with the replay of the stand-in. The window with the smallest error drives
        the replay from here on (``self.T_s``, ``self.T_rate``, ``self.smooth_window_s``). The rates
        that undo the thermocouple lags keep the run's window (:func:`rate_window`).
        """
        run = self.run
        self.smooth_window_s = 0.0 if self.T_noise < SMOOTH_ABOVE_C else SMOOTH_WINDOW_S
        if run.T is None or self.T_noise < SMOOTH_ABOVE_C:
            return 0.0
        rng = np.random.default_rng(seed)
        sig = np.array([noise_density_sigma(run.T[:, c], TEMP_LSB_C) for c in (0, 1)])
        noise = [rng.normal(0.0, 1.0, run.T.shape) * sig for _ in range(INPUT_NOISE_REALISATIONS)]
        # the stand-in for the truth: the least smoothed (a smoother one hides the transitions'
        # distortion by smoothing: the error of a 0.3 s window came out 2x too small), at the run's rate window
        ref, ref_rate = smooth_and_rate(run.T, run.dt, SMOOTH_WINDOWS_S[0], self.rate_window_s)
        r = self.nominal
        Ts = [self.wire_temperature(r, ref, ref_rate, self.cycles)]
        for w in SMOOTH_WINDOWS_S:
            for e in noise:
                T_s, T_rate = smooth_and_rate(ref + e, run.dt, w, self.rate_window_s)
                Ts.append(self.wire_temperature(r, T_s, T_rate, self.cycles))
        q, _, _ = self.consts.mechanics(np.stack(Ts, axis=1), self.dt, self.joint_row(r), self.substeps, self.resync)
        err = ((q[i0:, 1:] - q[i0:, :1]) ** 2).mean(axis=0).reshape(len(SMOOTH_WINDOWS_S), -1).mean(axis=1)
        k = int(np.argmin(err))
        self.smooth_window_s = SMOOTH_WINDOWS_S[k]
        self.T_s, self.T_rate = smooth_and_rate(run.T, run.dt, self.smooth_window_s, self.rate_window_s)
        self._mech_cache.clear()
        if self._xi is not None:  # the latent heat's fractions follow the smoothed temperatures
            self._xi = None
            self._th_cache.clear()
        return float(np.sqrt(err[k]))

    def choose_mechanics_step(self, sigma: float, i0: int = 0) -> float:
        """Extrapolate the mechanics replay to a vanishing step when its step error is not far
        below the noise; returns the step error [rad] RMS of the plain nominal replay.

        The joint (Eq. 4.18, linearly implicit Euler) and the wire loads are integrated at the
        sample interval, so a 100 Hz replay of a plant integrated at 1 kHz (or of a real,
        continuous wrist) is off by O(dt): on a noise-free prefiltered pid run with a 0.45 kg
        payload 1.07 mrad against a 0.99 mrad replay resolution, which a 5 % lower viscous
        damping "explained" (test_diagnose, closed loop). The error is first order in the
        step, so 2 x RMS(q(h) - q(h/2)) estimates it; above :data:`STEP_ERROR_FRACTION` x
        ``sigma`` [rad] every mechanics replay becomes the Richardson extrapolation
        2 q(h/2) - q(h) (on the clean 70 s pid run: 0.79 -> 0.07 mrad RMS against the 1 kHz
        plant, where halving the step twice gives 0.14 mrad for more work).
        """
        run = self.run
        if run.T is None or run.q is None:
            return 0.0
        Tw = self.wire_temperature(self.nominal, self.T_s, self.T_rate, self.cycles)[:, None]
        jr = self.joint_row(self.nominal)
        q_h = self.consts.mechanics(Tw, self.dt, jr, self.substeps, self.resync)[0][i0:, 0]
        q_h2 = self.consts.mechanics(Tw, self.dt, jr, 2 * self.substeps, self.resync)[0][i0:, 0]
        err = 2.0 * float(np.sqrt(np.mean((q_h - q_h2) ** 2)))
        extrapolate = err > STEP_ERROR_FRACTION * sigma
        if extrapolate != self.extrapolate:
            self.extrapolate = extrapolate
            self._mech_cache.clear()
        return err

    def _joint_replay(self, T: np.ndarray, jrows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Kernel mechanics (q, qd, load) at the run's step, or extrapolated to a vanishing step."""
        out = self.consts.mechanics(T, self.dt, jrows, self.substeps, self.resync)
        if not self.extrapolate:
            return out
        fine = self.consts.mechanics(T, self.dt, jrows, 2 * self.substeps, self.resync)
        return 2.0 * fine[0] - out[0], 2.0 * fine[1] - out[1], 2.0 * fine[2] - out[2]

    def angle_sensor(self, q: np.ndarray, r: np.ndarray) -> np.ndarray:
        """Measured angle from the true one (K,) under a parameter row."""
        y = play(q, r[INDEX['backlash_rad']])
        y = delayed(y, r[INDEX['angle_delay_s']], self.dt)
        y = first_order(y, r[INDEX['angle_lag_s']], self.dt)
        qn = self.consts.params.joint.q_neutral_rad
        drift = (
            r[INDEX['angle_drift_rad_per_h']] / 3600.0 * np.arange(y.shape[0]) * self.dt
            if r[INDEX['angle_drift_rad_per_h']]
            else 0.0
        )
        return y + r[INDEX['angle_offset_rad']] + r[INDEX['angle_gain_err']] * (y - qn) + drift

    def angle_unsensed(self, y: float, i: int, r: np.ndarray) -> float:
        """The true angle [rad] whose reading at sample ``i`` is ``y`` [rad] under the row ``r``: :meth:`angle_sensor`'s
        offset, gain error and drift undone (its lag, delay and backlash are transient: a reading at rest has none)."""
        qn = self.consts.params.joint.q_neutral_rad
        drift = r[INDEX['angle_drift_rad_per_h']] / 3600.0 * i * self.dt
        return float(qn + (y - r[INDEX['angle_offset_rad']] - drift - qn) / (1.0 + r[INDEX['angle_gain_err']]))

    def angle_measured(self, rows: np.ndarray, upto: int | None = None, source: str = 'measured') -> np.ndarray:
        q, _, _ = self.mechanics(rows, upto, source)
        return np.stack([self.angle_sensor(q[:, j], r) for j, r in enumerate(rows)], axis=1)
