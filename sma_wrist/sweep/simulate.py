"""N closed loops in one vectorised simulation: the node graph's computation, wrists in lockstep.

Per 100 Hz tick t_k (the graph's publish rate; plant_sim's dt_s steps in between), in the
order the graph's messages flow (sma_wrist/nodes):

1. the plant's state is measured (:class:`~sma_wrist.plants.spread.SensorBank`: thermocouple
   lag and noise, potentiometer noise);
2. the TEM loops sample the measured temperatures with the desired temperatures of the
   previous tick (tem_controller, :class:`~sma_wrist.sweep.laws.TemLoopBank`);
3. the joint controllers (adaptive_controller, :class:`~sma_wrist.sweep.laws.JointControllerBank`)
   and, in inverse_adaptive mode, the inverse compensator (hysteresis_compensator:
   :class:`~sma_wrist.core.hysteresis.compensation.MuscleCompensator` over all its wrists, memory
   observing the measured temperatures and stresses, each wire's temperature axis tracking the
   strain at the measured angle) give the next desired temperatures, which the TEM loops
   prefilter (tem_controller's target_filter_s) at their next sample;
4. the plant advances to t_k+1 under these commands, all wrists in one compiled call
   (:func:`sma_wrist.plants.make_plant`).

The nodes see plant_sim's first measurements at t_1 (t_0 is published before they subscribe),
so the TEM loops start at t_1 and the joint controllers, which difference two joint states,
at t_2, with the reference of the previous tick (trajectory_generator's clock starts at t_1).
With this order a loop is the graph's sample by sample (test_sweep: same commands and
angles to the last bit on the nominal and a perturbed plant).

Metrics per loop as ``sma-wrist run`` reports them (sma_wrist.runs.run_metrics): max and RMS
angle error over the last full reference cycle in % of the reference range, on the true angle
and on the measured one (what a bag holds), and the TEM commands' sign changes per second.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from sma_wrist.core.control.joint_controller import MODES, JointControllerParams
from sma_wrist.core.control.tem import (
    CHATTER_DEADBAND_V,
    MuscleTemperatureObserver,
    TemControlParams,
    TemperatureObserverParams,
)
from sma_wrist.core.control.trajectory import make_trajectory, soft_start
from sma_wrist.core.errors import ParameterError
from sma_wrist.core.hysteresis.compensation import MuscleCompensator, strain_informative
from sma_wrist.core.hysteresis.default_params import default_sdgpi
from sma_wrist.core.hysteresis.sdgpi import SDGPIParams
from sma_wrist.core.metrics import SEED_PERIOD_S
from sma_wrist.core.plant.wrist import PlantParams
from sma_wrist.core.stamps import stamp_seconds
from sma_wrist.core.thermal.heat_balance import ThermalParams, out_of_window
from sma_wrist.core.thermal.online import OnlineThermalParams
from sma_wrist.plants import make_plant
from sma_wrist.plants.spread import Scenario, SensorBank
from sma_wrist.sweep.laws import JointControllerBank, TemLoopBank, TemLoopSpec

FloatArray = NDArray[np.float64]

TICK_S = 0.01  # the graph's publish and control rate (config/wrist.yaml publish_rate_hz, rate_hz)
ANGLE_LIMITS_RAD = (0.0, 1.05)  # trajectory_generator's angle_min_rad / angle_max_rad
SHIFT_GAIN_PER_S = 2.0  # hysteresis_compensator's shift_gain_per_s default (config/wrist.yaml)
STROKE_GAIN_PER_S = 0.5  # hysteresis_compensator's stroke_gain_per_s default (config/wrist.yaml)
SHIFT_LIMIT_C = 15.0  # hysteresis_compensator's shift_limit_C default (config/wrist.yaml)
HOLD_SHIFT_ON_STOP = False  # hysteresis_compensator's hold_shift_on_stop default (config/wrist.yaml)
#: hysteresis_compensator's hold_shift_outside_load_range default (config/wrist.yaml)
HOLD_SHIFT_OUTSIDE_LOAD_RANGE = False
#: the laws that can be given the true muscle temperatures in :func:`simulate` (a diagnosis)
TRUE_TEMPERATURE_CONSUMERS = ('compensator', 'tem')


@dataclass(frozen=True)
class Case:
    """One closed loop: a plant scenario under one controller mode."""

    index: int
    controller: str
    scenario: Scenario
    group: str = 'spread'  # 'spread' (sampled plant) or 'nominal' (the controllers' own model)

    def __post_init__(self) -> None:
        if self.controller not in MODES:
            raise ParameterError(f'controller {self.controller!r} is not one of {", ".join(MODES)}')


@dataclass
class Trace:
    """Recorded series of a chunk (for the agreement test and plots): (K,) times, (K, n) angles and references
    (each loop's reference starts at its own wrist's angle)."""

    t: FloatArray
    q_d: FloatArray
    q: FloatArray
    q_measured: FloatArray
    command_V: FloatArray  # (K, n, 2)
    extra: dict[str, Any] = field(default_factory=dict)


def sign_changes_per_s(u: FloatArray, dt: float, deadband: float = CHATTER_DEADBAND_V) -> FloatArray:
    """Sign changes per second of each command column of u (K, ...) sampled every dt [s].

    Commands within +-deadband carry the previous sign (a + 0 - sequence is one change), as in tem_controller's
    chatter guard (core.control.tem.ChatterGuard): a law settling about 0 V flips sign without moving heat;
    chattering is the driver swinging between heating and cooling.
    """
    s = np.where(np.abs(u) > deadband, np.sign(u), 0.0)
    # carry the last nonzero sign forward through zeros
    idx = np.where(s != 0, np.arange(s.shape[0]).reshape((-1,) + (1,) * (s.ndim - 1)), 0)
    np.maximum.accumulate(idx, axis=0, out=idx)
    carried = np.take_along_axis(s, idx, axis=0)
    changes = (carried[1:] * carried[:-1] < 0).sum(axis=0)
    return changes / (dt * max(s.shape[0] - 1, 1))


def loop_metrics(
    t: FloatArray, q_d: FloatArray, q: FloatArray, q_meas: FloatArray, u: FloatArray, period_s: float = SEED_PERIOD_S
) -> list[dict[str, float]]:
    """Per loop: run_metrics' figures over the last full cycle (whole run if shorter), in % of each loop's reference
    range over the run, as a bag's. ``q_d``: (K,) one reference for every loop, or (K, n) one per loop."""
    ref = q_d.reshape(q_d.shape[0], -1)  # (K, 1) or (K, n): broadcasts against (K, n)
    rng = ref.max(axis=0) - ref.min(axis=0)
    if np.any(rng <= 0):
        raise ParameterError('the reference does not move: no error in % of its range')
    last = t >= t[-1] - period_s if t[-1] - t[0] >= period_s else np.ones(t.size, bool)
    e = np.abs(q[last] - ref[last]) * (100.0 / rng)
    em = np.abs(q_meas[last] - ref[last]) * (100.0 / rng)
    chat = sign_changes_per_s(u[last], t[1] - t[0])  # (n, 2)
    out = []
    for j in range(q.shape[1]):
        out.append(
            {
                'max_error_pct': float(e[:, j].max()),
                'rms_error_pct': float(np.sqrt(np.mean(e[:, j] ** 2))),
                'max_error_measured_pct': float(em[:, j].max()),
                'sign_changes_per_s': float(chat[j].max()),
                'window': 'last_cycle' if last.sum() < t.size else 'whole_run',
            }
        )
    return out


def _stamp_s(t: float) -> float:
    """Plant time [s] as the nodes see it: a header stamp (integer ns) read back as sec + 1e-9 nanosec.
    The laws' decisions on time differences (TEM range refresh every 0.1 s, dt) then match the graph's."""
    return stamp_seconds(int(round(t * 1e9)))


def check_true_temperature(consumers: Sequence[str]) -> None:
    """ParameterError naming any of ``consumers`` that is not in :data:`TRUE_TEMPERATURE_CONSUMERS`."""
    bad = sorted(set(consumers) - set(TRUE_TEMPERATURE_CONSUMERS))
    if bad:
        raise ParameterError(
            f'true_temperature: unknown consumer(s) {", ".join(bad)}; known: {", ".join(TRUE_TEMPERATURE_CONSUMERS)}'
        )


def simulate(
    cases: Sequence[Case],
    duration_s: float = 126.0,
    plant: str = 'sdgpi',
    base: PlantParams | None = None,
    record: bool = False,
    on_tick: Callable[[float], None] | None = None,
    window_s: float = SEED_PERIOD_S,
    tem_params: TemControlParams | None = None,
    shift_gain_per_s: float = SHIFT_GAIN_PER_S,
    true_temperature: Sequence[str] = (),
    compensator_observer: TemperatureObserverParams | None = TemperatureObserverParams(),
    window_follows_shift: bool = True,
    stroke_gain_per_s: float = STROKE_GAIN_PER_S,
    hold_shift_on_stop: bool = HOLD_SHIFT_ON_STOP,
    hold_shift_outside_load_range: bool = HOLD_SHIFT_OUTSIDE_LOAD_RANGE,
    controller_overrides: Mapping[str, Any] | None = None,
    oracle: Sequence[str] = (),
    online_thermal: OnlineThermalParams | None = OnlineThermalParams(),
    compensator_wire: SDGPIParams | None = None,
    compensator_window_C: tuple[float, float] = (20.0, 80.0),
    shift_limit_C: float = SHIFT_LIMIT_C,
    tem_loop: TemLoopSpec | None = None,
    observer_thermal: ThermalParams | None = None,
    soft_start_s: float = 0.0,
) -> tuple[list[dict[str, Any]], Trace | None]:
    """Run the closed loops of ``cases`` together; returns one result row per case (and the traces).

    Metrics over the last ``window_s`` [s]; over the whole run, the plant's TEM faces: ``tem_face_max_C`` the
    hottest [degC], ``tem_face_outside_s`` the time any face of the wrist was outside the TEM's window
    (``base.thermal.window_C``, 0-80 degC, as plant_sim's ``tem_faces`` diagnostic) [s], sampled at every tick;
    ``wire_stress_max_MPa`` the highest stress either wire of the wrist carried at a tick [MPa] (plant_sim's
    ``/wrist/muscle_{1,2}/stress``; doc/explanation/controllers.md); ``overload_s`` the time
    a wire's load was held at the wire model's bound (``MuscleGeometry.max_load_kgf``, plant_sim's ``wire_load``
    diagnostic) [s]: there the loop has left the model and its figures are not physics; ``angle_step_max_rad`` the
    largest change of the true angle over one tick [rad] (the built-in family's are 0.0055 at most: larger ones are
    snap-throughs or a load solve at its bound). The laws are the nodes' defaults; ``tem_params``
    (tem_controller's gain, rate and target filters) and ``shift_gain_per_s``
    (hysteresis_compensator's axis adaptation, 0 = off) change them, e.g. to measure the
    controllers without their target prefilter and axis adaptation (``python -m sma_wrist.plants.loop --legacy``).

    ``true_temperature``: a diagnosis, not a controller -- the named consumers (``'compensator'``,
    ``'tem'``) read the plant's true muscle temperatures instead of the thermocouples' (lag,
    noise; on the phase-fraction wrist also its own thermocouple's lag), which bounds what a
    perfect temperature observer in that place could give (doc/explanation/controllers.md).
    ``compensator_observer``: the compensator reads a :class:`MuscleTemperatureObserver` of the
    thermocouples driven by the TEM commands: the node graph with hysteresis_compensator's
    ``temperature_source: observer`` (the default) and the same ``observer.*`` parameters; None: the
    thermocouples themselves (``temperature_source: thermocouple``). ``window_follows_shift``:
    hysteresis_compensator's parameter of that name; ``stroke_gain_per_s`` its stroke adaptation (0 = off),
    ``hold_shift_on_stop`` its gate on the adaptation (core.hysteresis.compensation.strain_informative),
    ``hold_shift_outside_load_range`` the one on the pair's load range (``MuscleCompensator.pair_in_load_range``).
    ``controller_overrides``: adaptive_controller's parameters other than its defaults
    ({JointControllerParams field: value}, e.g. the reference leads).

    ``online_thermal``: tem_controller's and hysteresis_compensator's ``thermal_adaptation`` (the online estimate
    of each wrist's TEMs, :mod:`sma_wrist.core.thermal.online`; None = off).

    The node graph's other parameters, as :func:`sma_wrist.sweep.graph_params.loop_settings` reads them from
    params files (``sma-wrist sweep --params-file``): ``base`` plant_sim's plant (its wire, TEMs, pre-load and
    step); ``compensator_wire``, ``compensator_window_C`` and ``shift_limit_C`` hysteresis_compensator's SD-GPI
    (None: the built-in set), temperature window [degC] and shift limit [degC]; ``observer_thermal`` its
    observer's heat balance (None: the TEM loops' model); ``tem_loop`` tem_controller's loop
    (:class:`~sma_wrist.sweep.laws.TemLoopSpec`; None: its defaults).

    ``soft_start_s``: trajectory_generator's: each loop's reference starts at its wrist's angle measured at t_1
    and joins the Sec. 6.1 sine over this time [s] (0, the node's default: the sine from its first value).

    ``oracle``: a diagnosis, not a controller -- the named models of the loop are the plant's own
    (:data:`sma_wrist.sweep.oracle_models.SWITCHES`: ``'hysteresis'``, ``'thermal'``, ``'payload'``,
    ``'sensors'``; doc/explanation/controllers.md); every case must then be on
    the one ``sdgpi`` scenario."""
    check_true_temperature(true_temperature)
    if not cases:
        raise ParameterError('no closed loops to simulate (N = 0)')
    orc: Any = None
    if oracle:  # lazily: plants.oracle runs this engine
        from sma_wrist.sweep import oracle_models

        orc = oracle_models
        orc.check(oracle, plant, [c.scenario for c in cases])
        if 'sensors' in oracle:
            true_temperature = TRUE_TEMPERATURE_CONSUMERS
    if not (math.isfinite(duration_s) and duration_s >= 2 * TICK_S):
        raise ParameterError(f'duration {duration_s!r} s must be >= {2 * TICK_S} s')
    base = base or PlantParams()
    n = len(cases)
    scen = [c.scenario for c in cases]
    wrists = make_plant(plant, scen, base)
    steps = max(1, int(round(TICK_S / base.dt)))
    sensors = SensorBank(scen, TICK_S)
    traj = make_trajectory('sine', ANGLE_LIMITS_RAD)
    groups = {}
    for mode in MODES:
        idx = np.array([i for i, c in enumerate(cases) if c.controller == mode], dtype=np.intp)
        if idx.size:
            over = dict(controller_overrides or {})
            if 'adaptive' in over:  # the adaptive law's mode follows the group's, as adaptive_controller sets it
                over['adaptive'] = dataclasses.replace(
                    over['adaptive'], mode=mode if mode != 'pid' else 'inverse_adaptive'
                )
            jp = JointControllerParams(mode=mode, **over)
            if orc is not None and 'payload' in oracle:
                jp = orc.knows_payload(jp, scen[0].payload_kg)
            groups[mode] = (idx, JointControllerBank(jp, idx.size, base))
    comp = None
    if 'inverse_adaptive' in groups:
        # hysteresis_compensator's defaults (config/wrist.yaml): the measured angle adapts each wire's axis
        comp = MuscleCompensator(
            compensator_wire or default_sdgpi(),
            T_range_C=compensator_window_C,
            shift_gain_per_s=shift_gain_per_s,
            shift_limit_C=shift_limit_C,
            window_follows_shift=window_follows_shift,
            stroke_gain_per_s=stroke_gain_per_s,
            hold_outside_load_range=hold_shift_outside_load_range,
        )
        if orc is not None and 'hysteresis' in oracle:
            comp = orc.own_compensator(comp, scen[0], base)
    comp_started = False
    t_track_ns = 0  # stamp of the last measured tick the compensator's memory took [ns]
    q_track = np.zeros(0)  # the measured angles of that tick [rad]
    t_obs_ns = 0  # stamp of the last measured tick the observer took [ns]
    tem = TemLoopBank.like_node(n, tem_params, online_thermal, tem_loop)
    if orc is not None and 'thermal' in oracle:
        tem = orc.own_tem_bank(tem, scen[0], base)
    # the TEM loops' heat-balance model, the one tem_controller's observer integrates
    observer = (
        None
        if compensator_observer is None
        else MuscleTemperatureObserver(observer_thermal or tem.thermal, compensator_observer)
    )
    k_total = int(round(duration_s / TICK_S)) + 1
    t_rec = np.empty(k_total)
    q_rec, qm_rec, u_rec = np.empty((k_total, n)), np.empty((k_total, n)), np.empty((k_total, n, 2))
    qd_rec = np.empty((k_total, n))
    q_start = None  # each wrist's angle trajectory_generator starts its reference from [rad]
    T_d: FloatArray | None = None
    # the TEMs' faces as the plant has them (no node sees the exchanger faces): hottest, and time outside their
    # window, as plant_sim's tem_faces diagnostic judges it (doc/explanation/controllers.md)
    face_max, face_outside = np.full(n, -np.inf), np.zeros(n)
    stress_max = np.zeros(n)  # the wires' highest stress over the run [Pa]: what a co-contraction costs the wire
    overload = np.zeros(n)  # time a wire's load was held at the wire model's bound [s]: no physics there
    t_last = 0.0
    tick_ns = int(round(TICK_S * 1e9))
    for k in range(k_total):
        s = wrists.state
        t = _stamp_s(s.t)
        dt_law, t_last = t - t_last, t
        t_rec[k] = t
        T_m, q_m, qdot_m = sensors.measure(wrists.muscle_temperature_C, s.q.copy(), s.qd.copy())
        if orc is not None and 'sensors' in oracle:
            T_m, q_m, qdot_m = wrists.muscle_temperature_C, s.q.copy(), s.qd.copy()
        T_tem = T_comp = T_m
        if observer is not None and k >= 1:  # the commands in force over the last tick: u of the previous one
            # dt from the stamps, as hysteresis_compensator's observer takes it
            t_ns = int(round(s.t * 1e9))
            if tem.estimated:  # hysteresis_compensator's own estimate: the TEM loop's as of the last tick's sample
                observer.coef_rows = tem.coef_rows
            T_comp = observer.update(T_m, u_rec[k - 1] if k >= 2 else np.zeros((n, 2)), (t_ns - t_obs_ns) * 1e-9)
            t_obs_ns = t_ns
        if true_temperature:  # a plant with its own thermocouple (phase fraction) also has the node's
            T_true = getattr(wrists, 'node_temperature_C', wrists.muscle_temperature_C)
            T_tem = T_true if 'tem' in true_temperature else T_m
            if 'compensator' in true_temperature:
                T_comp = T_true
        stress = wrists.wire_stress_Pa
        np.maximum(stress_max, stress.max(axis=1), out=stress_max)
        q_rec[k], qm_rec[k] = s.q, q_m
        # plant_sim publishes t = 0 before the others subscribe: the TEM loop starts at the first tick
        u = tem.sample(t, T_tem, T_d) if k >= 1 else np.zeros((n, 2))
        # trajectory_generator's clock starts at its first tick (t_1): the reference stamped t_k is
        # q_d(t_k - t_1); the controller at t_k still holds the one stamped t_k-1
        now_ns = int(round(s.t * 1e9))
        # q_d(t_k - t_1); the controller at t_k still holds the one stamped t_k-1. It starts from the angle
        # measured at t_1 (trajectory_generator's soft start)
        if k == 1:
            q_start = np.minimum(np.maximum(q_m, ANGLE_LIMITS_RAD[0]), ANGLE_LIMITS_RAD[1])
        t_ref, t_law = (now_ns - tick_ns) * 1e-9, (now_ns - 2 * tick_ns) * 1e-9
        qd_rec[k] = traj(t_ref)[0] if q_start is None else soft_start(traj(t_ref), t_ref, q_start, soft_start_s)[0]
        if k >= 2:  # (n,) each: one reference per loop
            q_d, qdot_d, qddot_d = (
                np.broadcast_to(x, (n,)) for x in soft_start(traj(t_law), t_law, q_start, soft_start_s)
            )
        if comp is not None and k >= 1:
            # hysteresis_compensator's memory and axis take every measured tick (its first, t_1, starts
            # them), dt from the stamps, before the cycle's targets arrive
            idx, bank = groups['inverse_adaptive']
            stress_g, T_g = stress[idx].ravel(), T_comp[idx].ravel()
            if not comp_started:
                comp.reset(T_g, stress_g)
                comp_started = True
            else:
                dt_track = (now_ns - t_track_ns) * 1e-9
                adapt = (
                    None
                    if not hold_shift_on_stop
                    else strain_informative(
                        q_m[idx], q_track, dt_track, stress[idx], (base.joint.q_min_rad, base.joint.q_max_rad)
                    ).ravel()
                )
                comp.track(T_g, stress_g, bank.strain_at(q_m[idx]).ravel(), dt_track, adapt)
            t_track_ns, q_track = now_ns, q_m[idx]
        if k >= 2:  # the controller's first joint state is t_1 (t_0 is published before it subscribes); dt needs two
            T_new = np.empty((n, 2))
            for idx, bank in groups.values():
                force, strain, T_g, _ = bank.update(q_m[idx], qdot_m[idx], q_d[idx], qdot_d[idx], qddot_d[idx], dt_law)
                if T_g is not None:
                    T_new[idx] = T_g
                    continue
                assert comp is not None and force is not None
                # the compensator's compiled paths take flat wire arrays: (n, 2) -> (2n,)
                T_new[idx] = comp(strain.ravel(), stress[idx].ravel(), commit=False).temperature_C.reshape(-1, 2)
            T_d = T_new
        u_rec[k] = u
        wrists.advance(u, steps)
        clamped = wrists.state.flags.get('overload')  # the phase-fraction wire has no bound
        if clamped is not None:
            overload += TICK_S * clamped
        faces = wrists.state.thermal
        face_max = np.maximum(face_max, faces.max(axis=(1, 2)))
        face_outside += TICK_S * out_of_window(base.thermal, faces).any(axis=(1, 2))
        if on_tick is not None and k % 100 == 0:
            on_tick(t)
    # as a bag is measured (runs.run_metrics): joint states from the first reference (t_1) on
    rows = loop_metrics(t_rec[1:], qd_rec[1:], q_rec[1:], qm_rec[1:], u_rec[1:], window_s)
    step_max = np.abs(np.diff(q_rec, axis=0)).max(axis=0)  # the largest true-angle step of a tick [rad]: snaps
    out = [
        {
            'index': c.index,
            'group': c.group,
            'controller': c.controller,
            'plant': plant,
            **c.scenario.to_dict(),
            **m,
            'tem_face_max_C': float(face_max[j]),
            'tem_face_outside_s': float(face_outside[j]),
            'wire_stress_max_MPa': float(stress_max[j]) * 1e-6,
            'overload_s': float(overload[j]),
            'angle_step_max_rad': float(step_max[j]),
        }
        for j, (c, m) in enumerate(zip(cases, rows))
    ]
    trace = Trace(t_rec, qd_rec, q_rec, qm_rec, u_rec) if record else None
    return out, trace


__all__ = [
    'Case',
    'Trace',
    'simulate',
    'loop_metrics',
    'sign_changes_per_s',
    'TICK_S',
    'CHATTER_DEADBAND_V',
    'SHIFT_GAIN_PER_S',
    'TRUE_TEMPERATURE_CONSUMERS',
    'check_true_temperature',
]
