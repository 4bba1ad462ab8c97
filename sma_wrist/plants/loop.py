"""One wrist's controllers, as the node graph composes them, on any plant of the family.

The nodes' core objects in the nodes' order, without transport: per 10 ms tick the plant is
advanced under the TEM commands in force and measured (its own sensors, or the project's
sensor model plus noise); tem_controller's :class:`~sma_wrist.core.tem_control.TemLoop` samples
the measured temperatures against the desired temperatures of the previous tick (the graph
delivers the temperatures before the compensator has answered); adaptive_controller's
:class:`~sma_wrist.core.joint_controller.JointController` and, in inverse mode,
hysteresis_compensator's :class:`~sma_wrist.core.compensation.MuscleCompensator` (memory from
the measured temperatures and stresses) give the next desired temperatures.

Perturbed project plants (:func:`perturbed_plant`): transition temperatures shifted, stroke
scaled (the SD-GPI envelopes, exactly), TEM gain, muscle-face losses and ambient through
:func:`sma_wrist.core.model_extensions.plant_params`; thermocouple lag (the same exact
first-order discretisation as model_extensions.SensorChain) and noise, potentiometer noise.

Used by test_offmodel.py and for the off-model figures of docs/control.md
(``python -m sma_wrist.plants.loop``).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np
from numpy.typing import NDArray

from sma_wrist.core import model_extensions as mx
from sma_wrist.core import thermal as th
from sma_wrist.core.compensation import MuscleCompensator
from sma_wrist.core.default_params import default_sdgpi
from sma_wrist.core.hysteresis import EnvelopeSections, SDGPIParams
from sma_wrist.core.joint_controller import JointController, JointControllerParams
from sma_wrist.core.metrics import SEED_PERIOD_S, tracking_metrics
from sma_wrist.core.plant import PlantParams, WristPlant
from sma_wrist.core.tem_control import DriveLimits, TemControlParams, TemLoop
from sma_wrist.core.trajectory import SEED_AMPLITUDE_RAD, make_trajectory

FloatArray = NDArray[np.float64]
TICK_S = 0.01
#: a command counts as heating above +REVERSAL_BAND_V and as cooling below -REVERSAL_BAND_V
REVERSAL_BAND_V = 1.0
#: time constant of the velocity estimate from the measured angle [s]
VELOCITY_FILTER_S = 0.05


def shifted_sdgpi(p: SDGPIParams, shift_C: float = 0.0, stroke_scale: float = 1.0) -> SDGPIParams:
    """The SD-GPI with every transition temperature moved by shift_C and the stroke scaled.

    Envelopes k0 tanh(k1 T + k2) + k3 (Eq. 3.21): a shift replaces k2 by k2 - k1 shift; with
    the default set's k0 = amp = (S + 2 r_bar) / 2 and k3 = k_f + r_bar - amp, a stroke S -> s S
    gives amp' = s amp + (1 - s) r_bar, k3' = k_f + r_bar - amp'. Both act on the per-section
    quadratics of the load linearly, so the result is exact on every section.
    """
    env = p.envelopes
    r_bar = float(p.weights @ p.thresholds)
    out = []
    for q in (env.a.copy(), env.b.copy()):
        q[:, 2] = q[:, 2] - shift_C * q[:, 1]
        amp = stroke_scale * q[:, 0]
        amp[:, 2] += (1.0 - stroke_scale) * r_bar
        q[:, 0] = amp
        q[:, 3] = -amp
        q[:, 3, 2] += p.k_f + r_bar
        out.append(q)
    c, d = p.c.copy(), p.d.copy()
    c[2] -= shift_C * c[1]
    d[2] -= shift_C * d[1]
    return dataclasses.replace(p, envelopes=EnvelopeSections(env.edges_kg.copy(), out[0], out[1]), c=c, d=d,
                               name=f'{p.name}, shift {shift_C:+g} degC, stroke x{stroke_scale:g}')


@dataclass(frozen=True)
class Perturbation:
    """How a plant differs from the controllers' model (zeros: the nominal plant)."""

    shift_C: float = 0.0  # transition temperatures
    stroke_scale: float = 1.0
    tem_gain_err: float = 0.0
    loss_scale_err: float = 0.0
    ambient_offset_C: float = 0.0
    tc_lag_s: float = 0.0
    tc_noise_C: float = 0.0
    pot_noise_rad: float = 0.0
    seed: int = 0


class SensedPlant:
    """The project's plant with a perturbed model and real-sensor effects on what is measured."""

    def __init__(self, pert: Perturbation, payload_kg: float) -> None:
        base = PlantParams(hysteresis=shifted_sdgpi(default_sdgpi(), pert.shift_C, pert.stroke_scale)
                           if (pert.shift_C, pert.stroke_scale) != (0.0, 1.0) else default_sdgpi())
        params = mx.plant_params({'tem_gain_err': pert.tem_gain_err, 'loss_scale_err': pert.loss_scale_err,
                                  'ambient_offset_C': pert.ambient_offset_C}, base)
        self.plant = WristPlant(params, payload_kg=payload_kg)
        self.pert = pert
        self.a_T = math.exp(-TICK_S / pert.tc_lag_s) if pert.tc_lag_s > 0 else 0.0
        self.T_tc: FloatArray | None = None
        self.rng = np.random.default_rng(pert.seed)

    def advance(self, u: FloatArray, n: int) -> None:
        self.plant.advance(u[None, :], n)

    def measure(self) -> tuple[FloatArray, float, FloatArray]:
        T = self.plant.muscle_temperature_C[0]
        self.T_tc = T.copy() if self.T_tc is None else self.a_T * self.T_tc + (1.0 - self.a_T) * T
        Tm = self.T_tc + self.pert.tc_noise_C * self.rng.standard_normal(2)
        q = float(self.plant.state.q[0]) + self.pert.pot_noise_rad * self.rng.standard_normal()
        return Tm, q, self.plant.wire_stress_Pa[0]


class PhaseFractionWrist:
    """Adapter of :class:`~sma_wrist.plants.phase_fraction.PhaseFractionPlant` (its own sensors)."""

    def __init__(self, payload_kg: float, **params: Any) -> None:
        from sma_wrist.plants.phase_fraction import PhaseFractionParams, PhaseFractionPlant
        self.plant = PhaseFractionPlant(PhaseFractionParams(**params), payload_kg=payload_kg)

    def advance(self, u: FloatArray, n: int) -> None:
        self.plant.advance(u[None, :], n)

    def measure(self) -> tuple[FloatArray, float, FloatArray]:
        T, q = self.plant.measure()
        # the wrist has no stress sensor: hardware_bridge publishes a model estimate; here the true
        # stress stands in for it (the estimate's error is not what this loop measures)
        return T[0], float(q[0]), self.plant.wire_stress_Pa[0]


def reach(pert: Perturbation, payload_kg: float, T_window_C: tuple[float, float] = (20.0, 80.0)) -> tuple[float, float]:
    """(lowest, highest) angle [rad] a perturbed project wrist holds with its muscle temperatures
    imposed inside the controllers' window (one muscle hot, the other cold, both ways round,
    each approached along its branch; WristPlant.step_mechanics, no heat balance). A reference
    outside it cannot be tracked by any controller: its excess is a floor under the max error."""
    lo, hi = T_window_C
    plant = SensedPlant(dataclasses.replace(pert, tc_lag_s=0.0, tc_noise_C=0.0, pot_noise_rad=0.0),
                        payload_kg).plant
    T0 = float(plant.muscle_temperature_C[0, 0])
    n = 3000
    for T in np.linspace(T0, hi, n):
        plant.step_mechanics(np.array([[T, lo]]))
    for _ in range(n):
        plant.step_mechanics(np.array([[hi, lo]]))
    top = float(plant.state.q[0])
    for k in range(n):
        f = k / n
        plant.step_mechanics(np.array([[hi - (hi - lo) * f, lo + (hi - lo) * f]]))
    for _ in range(n):
        plant.step_mechanics(np.array([[lo, hi]]))
    return float(plant.state.q[0]), top


def reach_floor_pct(pert: Perturbation, payload_kg: float, q_range: tuple[float, float] = (0.0, 1.048)) -> float:
    """Least max error [% of the range] any controller can have on the Sec. 6.1 sine (:func:`reach`)."""
    bottom, top = reach(pert, payload_kg)
    miss = max(q_range[1] - top, bottom - q_range[0], 0.0)
    return 100.0 * miss / (q_range[1] - q_range[0])


@dataclass
class LoopResult:
    max_error_pct: float
    rms_error_pct: float
    reversals_per_s: float  # TEM command sign changes per second (band +-REVERSAL_BAND_V), worse TEM
    t: FloatArray
    q: FloatArray
    q_d: FloatArray
    T: FloatArray
    T_d: FloatArray
    u: FloatArray


def reversals_per_s(u: FloatArray, dt: float, band_V: float = REVERSAL_BAND_V) -> float:
    """Sign changes per second of each TEM command, counted between the bands +-band_V (a
    command inside the band keeps the last sign); the larger of the two TEMs."""
    worst = 0.0
    for col in np.asarray(u).T:
        sign = np.where(col > band_V, 1, np.where(col < -band_V, -1, 0))
        s = sign[sign != 0]
        worst = max(worst, float(np.count_nonzero(np.diff(s))) / (col.size * dt))
    return worst


def run_loop(plant: Any, mode: str, duration_s: float = 126.0,
             params: JointControllerParams | None = None, window_s: float = SEED_PERIOD_S,
             tem_params: TemControlParams = TemControlParams(rate_filter_s=0.05, target_filter_s=0.5),
             shift_gain_per_s: float = 1.0,
             on_tick: Callable[[float], None] | None = None) -> LoopResult:
    """The graph's loop (module docstring) for ``duration_s`` on ``plant`` (advance/measure);
    metrics over the last ``window_s`` (the last full cycle of the Sec. 6.1 sine)."""
    params = dataclasses.replace(params or JointControllerParams(), mode=mode)
    law = JointController(params)
    comp = MuscleCompensator(default_sdgpi(), T_range_C=(params.temperature_min_C, params.temperature_max_C),
                             shift_gain_per_s=shift_gain_per_s) if mode == 'inverse_adaptive' else None
    drive = DriveLimits()
    hold = th.ThermalParams()
    tem = TemLoop(dataclasses.replace(hold, u_min_V=drive.boost_min_V, u_max_V=drive.boost_max_V),
                  tem_params, drive, hold, 85.0)
    ref = make_trajectory('sine')
    steps = int(round(duration_s / TICK_S))
    rec = np.empty((steps, 9))
    u = np.zeros(2)
    T_d: FloatArray | None = None
    started = False
    q_prev = None
    qdot = 0.0
    for k in range(steps):
        plant.advance(u, 10)
        t = (k + 1) * TICK_S
        T, q, stress = plant.measure()
        res = tem.sample(t, T, T_d)
        if res is not None:
            u = res.command_V.copy()
        qd_d = ref(np.array(t))
        q_d, qdot_d, qddot_d = float(qd_d[0]), float(qd_d[1]), float(qd_d[2])
        # velocity as a driver without a tachometer gets it: filtered difference of the angle
        qdot = 0.0 if q_prev is None else (VELOCITY_FILTER_S * qdot + q - q_prev) / (VELOCITY_FILTER_S + TICK_S)
        q_prev = q
        cmd = law.update(q, qdot, q_d, qdot_d, qddot_d, TICK_S, muscle_temperature_C=T)
        if comp is not None:
            if not started:
                comp.reset(T, stress)
                started = True
            comp.track(T, stress, law.strain_at(q), TICK_S)
            T_d = comp(cmd.strain_desired, stress, commit=False).temperature_C
        else:
            T_d = cmd.temperature_desired_C
        rec[k] = (t, q, q_d, T[0], T[1], T_d[0], T_d[1], u[0], u[1])
        if on_tick is not None:
            on_tick(t)
    t, qq, qr = rec[:, 0], rec[:, 1], rec[:, 2]
    last = t >= t[-1] - window_s
    m = tracking_metrics(t[last], qq[last], qr[last], reference_range_rad=2.0 * SEED_AMPLITUDE_RAD, period_s=None)
    return LoopResult(m.max_error_pct, m.rms_error_pct, reversals_per_s(rec[last][:, 7:9], TICK_S), t, qq, qr,
                      rec[:, 3:5], rec[:, 5:7], rec[:, 7:9])


#: the off-model cases of docs/control.md: name -> plant factory (payload -> plant)
_SENSORS = dict(tc_lag_s=0.2, tc_noise_C=0.2, pot_noise_rad=0.003)
CASES: dict[str, Callable[[float], Any]] = {
    'nominal': lambda m: SensedPlant(Perturbation(), m),
    'sensors': lambda m: SensedPlant(Perturbation(**_SENSORS), m),
    'T+10': lambda m: SensedPlant(Perturbation(shift_C=10.0), m),
    'T+5': lambda m: SensedPlant(Perturbation(shift_C=5.0), m),
    'T-10': lambda m: SensedPlant(Perturbation(shift_C=-10.0), m),
    'stroke x0.7': lambda m: SensedPlant(Perturbation(stroke_scale=0.7), m),
    'stroke x1.3': lambda m: SensedPlant(Perturbation(stroke_scale=1.3), m),
    'TEM gain -30%': lambda m: SensedPlant(Perturbation(tem_gain_err=-0.3), m),
    'TEM gain +30%': lambda m: SensedPlant(Perturbation(tem_gain_err=0.3), m),
    'losses +30%': lambda m: SensedPlant(Perturbation(loss_scale_err=0.3), m),
    'losses -30%': lambda m: SensedPlant(Perturbation(loss_scale_err=-0.3), m),
    'ambient +5': lambda m: SensedPlant(Perturbation(ambient_offset_C=5.0), m),
    'ambient -5': lambda m: SensedPlant(Perturbation(ambient_offset_C=-5.0), m),
    'mixed A': lambda m: SensedPlant(Perturbation(5.0, 0.85, -0.15, 0.15, 3.0, seed=1, **_SENSORS), m),
    'mixed B': lambda m: SensedPlant(Perturbation(-5.0, 1.15, 0.15, -0.15, -3.0, seed=2, **_SENSORS), m),
    'phase_fraction': lambda m: PhaseFractionWrist(m),
}
MODES = ('inverse_adaptive', 'direct_adaptive', 'pid')


def _main(argv: list[str] | None = None) -> None:  # pragma: no cover - the report quoted in docs/control.md
    import argparse
    import json
    import sys
    import time
    ap = argparse.ArgumentParser(description='the three controllers on off-model plants (docs/control.md)')
    ap.add_argument('--cases', default=','.join(CASES))
    ap.add_argument('--modes', default=','.join(MODES))
    ap.add_argument('--payloads', default='0.3')
    ap.add_argument('--duration', type=float, default=126.0)
    ap.add_argument('--legacy', action='store_true',
                    help='the controllers before issue 14: no target prefilter, no temperature-axis adaptation')
    ap.add_argument('--json', action='store_true')
    a = ap.parse_args(argv)
    kw: dict[str, Any] = {}
    if a.legacy:
        kw = {'tem_params': TemControlParams(rate_filter_s=0.05), 'shift_gain_per_s': 0.0}
    rows = []
    for case in a.cases.split(','):
        for mode in a.modes.split(','):
            for m in (float(x) for x in a.payloads.split(',')):
                wall = time.perf_counter()
                r = run_loop(CASES[case](m), mode, a.duration, **kw)
                rows.append({'case': case, 'mode': mode, 'payload_kg': m, 'max_error_pct': r.max_error_pct,
                             'rms_error_pct': r.rms_error_pct, 'reversals_per_s': r.reversals_per_s})
                if not a.json:
                    print(f'| {case} | {mode} | {m:g} | {r.max_error_pct:.2f} | {r.rms_error_pct:.2f} | '
                          f'{r.reversals_per_s:.2f} |  ({time.perf_counter() - wall:.1f} s)', flush=True)
    if a.json:
        json.dump(rows, sys.stdout, indent=1)


if __name__ == '__main__':  # pragma: no cover
    _main()
