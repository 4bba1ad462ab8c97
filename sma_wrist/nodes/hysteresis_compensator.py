"""hysteresis_compensator: desired muscle strain + stress -> desired muscle temperature.

Inverse SD-GPI (Eqs. 5.5-5.8) in the wrist's coordinates (:mod:`sma_wrist.core.hysteresis.compensation`).
Computes when a fresh set of all four targets (strain and stress of both muscles) has arrived
from adaptive_controller; its memory starts from the measured temperatures and stresses.
Targets the window cannot reach give the nearest reachable temperature, reported on
/diagnostics; malformed targets are rejected and counted. With the measured memory, the
measured joint angle adapts each wire's temperature axis (``shift_gain_per_s``,
:meth:`~sma_wrist.core.hysteresis.compensation.MuscleCompensator.track`, doc/explanation/controllers.md).

The memory and the axis follow the measurements sample by sample, in the order of their header
stamps: the temperatures and the angle of one plant tick are paired by stamp and advance the
memory once, whatever order they arrive in and whenever the targets arrive
(doc/explanation/runtime.md).

``temperature_source: observer`` feeds the memory and the axis with a
:class:`~sma_wrist.core.control.tem.MuscleTemperatureObserver` of the thermocouples (heat balance
Eqs. 4.13-4.14 driven by the TEM commands) instead of the raw thermocouple, as the sweep's
``compensator_observer`` does (doc/explanation/controllers.md). The commands carry
no stamp: each is filed at its arrival (the node clock, or the newest measurement stamp seen if
later) and a tick stamped t_k takes the newest command filed before t_k, the one tem_controller
computed from the previous tick. The node subscribes to the commands only while the observer is on
(two deliveries per tick less otherwise). ``thermal_file`` gives the observer the identified heat
balance tem_controller loads (the same file for both nodes, doc/howto/identify_tems.md).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from sensor_msgs.msg import Temperature

from sma_wrist.core.control.joint_controller import bundle_strain
from sma_wrist.core.control.tem import DriveLimits, MuscleTemperatureObserver, TemperatureObserverParams
from sma_wrist.core.errors import SmaWristError
from sma_wrist.core.hysteresis.compensation import MuscleCompensator, strain_informative
from sma_wrist.core.hysteresis.params_file import hysteresis_params
from sma_wrist.core.plant.wrist import PlantParams
from sma_wrist.core.stamps import stamp_seconds
from sma_wrist.core.thermal import online as thermal_online
from sma_wrist.core.thermal.heat_balance import ThermalParams
from sma_wrist.core.thermal.kernel import thermal_constants
from sma_wrist.core.thermal.online import ThermalScaleEstimator
from sma_wrist.core.thermal.params_file import load_thermal_file
from sma_wrist.nodes.common import (
    HYSTERESIS_FILE_PARAM,
    PRELOAD_PARAM,
    THERMAL_ADAPTATION_PARAMS,
    Param,
    WristNode,
    finite,
    main_for,
    online_thermal,
)

INPUTS = ('strain_1', 'strain_2', 'stress_1', 'stress_2')
#: targets of more cycles than this waiting on one topic: a message of another was lost, resynchronise
MAX_PENDING_CYCLES = 5
#: measurement ticks waiting for a missing part (a lost temperature or angle): beyond this the oldest
#: goes on without it (temperatures without the angle: the memory still follows) or is dropped
MAX_PENDING_TICKS = 5
ANGLE = 2  # slot of the angle in one tick's [T_1, T_2, angle]
#: TEM commands kept per layer for the observer: enough for MAX_PENDING_TICKS ticks waiting, with slack
MAX_COMMANDS = 4 * MAX_PENDING_TICKS


def observer_thermal(thermal_file: str = '') -> ThermalParams:
    """The observer's heat balance: ``thermal_file`` (identified, as tem_controller loads it) or Table 4.9,
    saturating at the driver rating (the commands it replays are tem_controller's, which the driver clips
    there). Raises ParameterError (with the path) for a missing or malformed file."""
    drive = DriveLimits()
    return (load_thermal_file(thermal_file) if thermal_file else ThermalParams()).with_limits(
        drive.boost_min_V, drive.boost_max_V
    )


#: the observer's heat balance without a thermal_file
OBSERVER_THERMAL = observer_thermal()


class HysteresisCompensator(WristNode):
    PARAMS = (
        Param(
            'temperature_min_C',
            20.0,
            "lowest temperature the compensator asks for (inside the wire model's valid range)",
            'degC',
            (-60.0, 400.0),
        ),
        Param(
            'temperature_max_C',
            80.0,
            "highest temperature the compensator asks for (inside the wire model's valid range)",
            'degC',
            (-60.0, 400.0),
        ),
        HYSTERESIS_FILE_PARAM,
        PRELOAD_PARAM,
        Param(
            'method',
            'numerical',
            'inverse: numerical root, literal analytic Eq. 5.7-5.8, or auto',
            choices=('numerical', 'analytic', 'auto'),
        ),
        Param(
            'stress_source',
            'measured',
            'stress that selects the load-dependent envelopes: the measured one '
            '(default, doc/explanation/controllers.md) or the desired stress from adaptive_controller (Eq. 5.5 as written)',
            choices=('measured', 'desired'),
        ),
        Param(
            'memory_source',
            'measured',
            "the inverse's hysteresis memory follows the measured temperatures "
            '(default: the plant lags its command, doc/explanation/controllers.md) or the commanded ones (Eq. 5.5 as written)',
            choices=('measured', 'commanded'),
        ),
        Param(
            'shift_gain_per_s',
            2.0,
            "memory_source measured: rate at which each wire's temperature axis follows "
            "the SD-GPI's strain prediction error at the measured angle (0 = the model's axis; doc/explanation/"
            'controllers.md)',
            '1/s',
            (0.0, 20.0),
        ),
        Param('shift_limit_C', 15.0, 'largest temperature-axis shift', 'degC', (0.0, 40.0)),
        Param(
            'hold_shift_on_stop',
            False,
            "shift_gain_per_s > 0: each wire's shift (and stroke) holds while the "
            'measured angle is on a mechanical stop, or the joint stands still with a wire slack: the angle then '
            'says nothing about the wires (doc/explanation/controllers.md)',
        ),
        Param(
            'hold_shift_outside_load_range',
            False,
            "shift_gain_per_s > 0: a wrist's shifts (and strokes) hold "
            "while either wire's measured load lies outside the SD-GPI's calibrated range (a slack or "
            'overloaded pair; doc/explanation/controllers.md; off by default: '
            '"The load-range gate, after the slope fix")',
        ),
        Param(
            'stroke_gain_per_s',
            0.5,
            "shift_gain_per_s > 0: rate at which each wire's stroke ratio (to the "
            "SD-GPI's, about its mid-stroke elongation) follows the strain prediction error on the loop's flat "
            "ends (0 = the model's stroke; doc/explanation/controllers.md)",
            '1/s',
            (0.0, 20.0),
        ),
        Param(
            'temperature_source',
            'observer',
            'temperature the memory and the axis follow: the muscle-temperature '
            'observer driven by the TEM commands (default) or the thermocouple as measured (doc/explanation/'
            'controllers.md)',
            choices=('thermocouple', 'observer'),
        ),
        Param(
            'window_follows_shift',
            True,
            'shift_gain_per_s > 0: the inverse searches the temperature window moved '
            "by each wire's shift, so its answers span the whole window on the wire's axis (doc/explanation/"
            'controllers.md)',
        ),
        Param(
            'observer.correction_s',
            TemperatureObserverParams.correction_s,
            'temperature_source observer: time constant pulling the estimate toward the thermocouple',
            's',
            (0.0, 10.0),
        ),
        Param(
            'observer.tc_lag_s',
            TemperatureObserverParams.tc_lag_s,
            'temperature_source observer: first-order lag of the thermocouple the observer assumes (0: none)',
            's',
            (0.0, 10.0),
        ),
        Param(
            'thermal_file',
            '',
            'temperature_source observer: identified TEM heat balance the observer runs '
            "(sma-wrist identify thermal; the same file as tem_controller's; empty: Table 4.9)",
            runtime=False,
        ),
        *THERMAL_ADAPTATION_PARAMS,
    )

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('hysteresis_compensator', **kwargs)
        self._build()
        self.values = dict.fromkeys(INPUTS, np.nan)
        # per input, the targets not yet used, oldest first: adaptive_controller publishes one of each
        # per cycle and each topic arrives in order, so the k-th of every queue are one cycle's set
        self.pending: dict[str, deque[float | None]] = {k: deque() for k in INPUTS}
        self.T_meas = np.full(2, np.nan)
        self.stress_meas = np.full(2, np.nan)
        # per header stamp [ns], one plant tick's [T_1, T_2, angle] not yet taken into the memory
        self.ticks: dict[int, list[float]] = {}
        self.t_tick_ns: int | None = None  # stamp of the last tick the memory took
        self.angle_seen = False  # joint_states arrive: a tick waits for its angle
        self.plant = PlantParams(preload_elongation_mm=self.p['preload_elongation_mm'])  # chain of the measured strains
        self.started = False
        self.q_prev = math.nan  # angle of the last tick the axis adapted on [rad]
        self._saturated: bool | None = None  # last state reported on /diagnostics
        self._shift_at_limit: tuple[bool, ...] = (False, False)  # per wire, last state reported on /diagnostics
        # per TEM layer, (filed at [ns], command [V]) received, oldest first (the observer's inputs)
        self.commands: list[deque[tuple[int, float]]] = [deque(maxlen=MAX_COMMANDS) for _ in (1, 2)]
        self.t_seen_ns = 0  # newest measurement stamp received
        self.pub_T = [self.publisher(f'/wrist/muscle_{i}/temperature_desired') for i in (1, 2)]
        for i in (1, 2):
            self.subscription(f'/wrist/muscle_{i}/strain_desired', lambda m, i=i: self._on_target(f'strain_{i}', m))
            self.subscription(f'/wrist/muscle_{i}/stress_desired', lambda m, i=i: self._on_target(f'stress_{i}', m))
            self.subscription(f'/wrist/muscle_{i}/temperature', lambda m, i=i: self._on_measured_T(i, m))
            self.subscription(f'/wrist/muscle_{i}/stress', lambda m, i=i: self._on_measured_stress(i, m))
        self.subscription('/wrist/joint_states', self._on_joint_state)
        self.command_subs: list[Any] = []
        self._subscribe_commands()
        p = self.p
        self.get_logger().info(
            f'hysteresis_compensator: method {p["method"]}, temperatures {p["temperature_min_C"]:g}-'
            f'{p["temperature_max_C"]:g} degC, memory from the {p["temperature_source"]} temperatures; '
            + self.waiting_for(
                'the desired strains and stresses (/wrist/muscle_{1,2}/strain_desired, '
                'stress_desired) of adaptive_controller, and the measured temperatures, stresses and '
                'joint state'
            )
        )

    def validate(self, values: Mapping[str, Any]) -> str | None:
        problem = super().validate(values)
        if problem is None and not values['temperature_min_C'] < values['temperature_max_C']:
            problem = (
                f'temperature_min_C = {values["temperature_min_C"]} must be below '
                f'temperature_max_C = {values["temperature_max_C"]}'
            )
        if problem is None and values['temperature_source'] == 'observer' and values['memory_source'] != 'measured':
            problem = (
                "temperature_source 'observer' feeds the measured memory: it needs memory_source 'measured' "
                f'(is {values["memory_source"]!r})'
            )
        if problem is None:
            try:
                lo, hi = hysteresis_params(values['hysteresis_file']).T_valid
                if values['temperature_source'] == 'observer':
                    observer_thermal(values['thermal_file'])
            except SmaWristError as e:
                return str(e)
            if values['temperature_min_C'] < lo or values['temperature_max_C'] > hi:
                problem = (
                    f'temperature window {values["temperature_min_C"]:g}-{values["temperature_max_C"]:g} degC '
                    f"leaves the wire model's valid range {lo:g}-{hi:g} degC"
                )
        return problem

    def _build(self) -> None:
        window = (self.p['temperature_min_C'], self.p['temperature_max_C'])
        wire = hysteresis_params(self.p['hysteresis_file'])
        self.comp = MuscleCompensator(
            wire,
            T_range_C=window,
            method=self.p['method'],
            shift_gain_per_s=self.p['shift_gain_per_s'],
            shift_limit_C=self.p['shift_limit_C'],
            window_follows_shift=self.p['window_follows_shift'],
            stroke_gain_per_s=self.p['stroke_gain_per_s'],
            hold_outside_load_range=self.p['hold_shift_outside_load_range'],
        )
        # one throwaway evaluation compiles the inverse's kernels (numba: seconds on a cold cache)
        # here rather than at the first sample of a running loop
        warm = MuscleCompensator(
            wire,
            T_range_C=window,
            method=self.p['method'],
            shift_gain_per_s=1.0,
            window_follows_shift=self.p['window_follows_shift'],
            stroke_gain_per_s=1.0,
            hold_outside_load_range=False,
        )  # adapts at any load: the adaptation compiles
        T_mid = 0.5 * (window[0] + window[1])
        warm.reset(np.full(2, T_mid), np.full(2, 1.2e8))
        warm.track(np.full(2, T_mid + 1.0), np.full(2, 1.2e8), np.full(2, 0.03), 0.01)
        warm(np.full(2, 0.02), np.full(2, 1.2e8), commit=False)
        old_observer = getattr(self, 'observer', None)
        self.observer = (
            None
            if self.p['temperature_source'] != 'observer'
            else MuscleTemperatureObserver(
                observer_thermal(self.p['thermal_file']),
                TemperatureObserverParams(self.p['observer.correction_s'], self.p['observer.tc_lag_s']),
            )
        )
        if self.observer is not None:  # its heat-balance step is compiled too: a throwaway observer's two samples
            warm_obs = MuscleTemperatureObserver(self.observer.thermal, self.observer.params)
            for _ in range(2):
                warm_obs.update(np.full((1, 2), T_mid), np.zeros((1, 2)), 0.01)
        # the observer's own estimate of the TEMs, fed the samples tem_controller's takes (core.thermal.online)
        online = online_thermal(self.p)
        if self.observer is not None and online is not None:
            # the estimate's window and the observer on its constants (from apply_after_s on) compile here too: on a
            # cold cache each cost seconds inside a callback, 2 s and 10 s into a run
            thermal_online.warm_up()
            warm_obs.coef_rows = thermal_constants(self.observer.thermal)[None]
            warm_obs.update(np.full((1, 2), T_mid), np.zeros((1, 2)), 0.01)
        old = getattr(self, 'estimator', None)
        if self.observer is None or online is None:
            self.estimator = None
        elif old is None:  # else a runtime change of another parameter: what has been learnt stays
            self.estimator = ThermalScaleEstimator(self.observer.thermal, 1, online)
            self.est_last: tuple[float, np.ndarray] | None = None  # (stamp [s], [T_1, T_2]) of the last tick
        elif old_observer is not None:  # ... and so does the heat balance the observer ran on
            self.observer.coef_rows = old_observer.coef_rows
        self.started = False  # re-seed the memory (and the observer) from the next measurement

    def apply(self, changed: Mapping[str, Any]) -> None:
        self._build()
        self._subscribe_commands()

    def _subscribe_commands(self) -> None:
        """Take the TEM commands while the observer runs, and only then."""
        if self.observer is not None and not self.command_subs:
            self.command_subs = [
                self.subscription(f'/wrist/tem_{i}/command', lambda m, i=i: self._on_command(i, m)) for i in (1, 2)
            ]
        elif self.observer is None and self.command_subs:
            for sub in self.command_subs:
                self.destroy_subscription(sub)
            self.command_subs = []
            for q in self.commands:
                q.clear()

    def _on_measured_T(self, i: int, msg: Any) -> None:
        if finite(msg.temperature):
            self._measured(msg, i - 1, msg.temperature)

    def _on_measured_stress(self, i: int, msg: Any) -> None:
        if finite(msg.data) and msg.data >= 0:
            self.stress_meas[i - 1] = msg.data
            if not self.started:
                self._start()

    def _on_joint_state(self, msg: Any) -> None:
        if msg.position and finite(msg.position[0]):
            self.angle_seen = True
            self._measured(msg, ANGLE, msg.position[0])

    def _on_command(self, i: int, msg: Any) -> None:
        """File one TEM command for the observer. Unstamped: it is in force from its arrival, on the
        node clock or, if the clock lags the data (sim time), after the newest measurement stamp seen."""
        if not finite(msg.data):
            self.reject_input(f'tem_{i}/command', f'non-finite command {msg.data!r} V')
            return
        self.commands[i - 1].append((max(self.now_ns(), self.t_seen_ns), msg.data))

    def _command_before(self, t_ns: int) -> np.ndarray:
        """(1, 2) commands [V] in force over the tick ending at t_ns: per layer the newest filed
        before t_ns (0 V before the first: plant_sim starts with the TEMs off)."""
        u = np.zeros((1, 2))
        for j, q in enumerate(self.commands):
            while len(q) > 1 and q[1][0] < t_ns:  # older ones are never in force again: stamps only grow
                q.popleft()
            if q and q[0][0] < t_ns:
                u[0, j] = q[0][1]
        return u

    def _stamp_ns(self, msg: Any) -> int:
        st = msg.header.stamp
        return st.sec * 1_000_000_000 + st.nanosec if st.sec or st.nanosec else self.now_ns()

    def _measured(self, msg: Any, slot: int, value: float) -> None:
        """File one measurement under its tick's stamp; take every complete tick into the memory in
        stamp order. Under ROS the temperatures, the angle and the targets of a tick arrive in any
        order: taking 'the latest' at each cycle's targets paired an angle of one tick with the
        temperatures of another and skipped the samples replaced meanwhile (a temperature reversal
        among them: a missed turning point), so the memory depended on the arrival order."""
        t = self._stamp_ns(msg)
        self.t_seen_ns = max(self.t_seen_ns, t)
        if self.t_tick_ns is not None and t <= self.t_tick_ns:
            return  # later than a newer tick already taken: the memory does not go back
        self.ticks.setdefault(t, [math.nan, math.nan, math.nan])[slot] = value
        while self.ticks:
            t0 = min(self.ticks)
            T_1, T_2, q = tick = self.ticks[t0]
            complete = T_1 == T_1 and T_2 == T_2 and (q == q or not self.angle_seen)  # x == x: not NaN
            if not complete and len(self.ticks) <= MAX_PENDING_TICKS:
                return
            del self.ticks[t0]
            if T_1 == T_1 and T_2 == T_2:
                self._take_tick(t0, tick)

    def _learn(self, t_ns: int, tick: list[float], u: np.ndarray) -> None:
        """The estimate takes the last tick with the command u (1, 2) [V] in force since it (tem_controller took
        that tick with the command it then sent); once ready and moved, the observer runs on it."""
        if self.estimator is None:
            return
        last, self.est_last = self.est_last, (stamp_seconds(t_ns), np.array(tick[:2], dtype=float))
        if last is not None and self.estimator.sample(last[0], last[1][None], u) and self.estimator.ready:
            assert self.observer is not None
            self.observer.coef_rows = self.estimator.constants()

    def _start(self) -> None:
        """Start the memory at the last measured tick once the loads are known too."""
        if finite(*self.T_meas.tolist(), *self.stress_meas.tolist()):
            self.comp.reset(self.T_meas, self.stress_meas)
            self.started = True

    def _take_tick(self, t_ns: int, tick: list[float]) -> None:
        """Advance the memory (and the adapted axis) by one measured tick."""
        dt = 0.0 if self.t_tick_ns is None else (t_ns - self.t_tick_ns) * 1e-9
        self.t_tick_ns = t_ns
        if self.observer is None:
            self.T_meas = np.array(tick[:2])
        else:
            try:
                u = self._command_before(t_ns)  # in force over the tick ending at t_ns
                self._learn(t_ns, tick, u)
                self.T_meas = self.observer.update(np.array([tick[:2]]), u, dt)[0]
            except SmaWristError as e:  # the estimate stays; this tick is not taken
                self.reject_input('observer', f'tick skipped: {e}')  # constant text: one report per fault
                return
        if not self.started:
            self._start()
            self.q_prev = tick[ANGLE]
            return
        if self.p['memory_source'] != 'measured':
            return
        try:
            if tick[ANGLE] == tick[ANGLE]:
                adapt = None
                if self.p['hold_shift_on_stop']:  # no earlier angle yet: taken as standing still
                    q_prev = self.q_prev if self.q_prev == self.q_prev else tick[ANGLE]
                    adapt = strain_informative(
                        tick[ANGLE],
                        q_prev,
                        dt,
                        self.stress_meas,
                        (self.plant.joint.q_min_rad, self.plant.joint.q_max_rad),
                    )
                self.q_prev = tick[ANGLE]
                self.comp.track(self.T_meas, self.stress_meas, bundle_strain(self.plant, tick[ANGLE]), dt, adapt)
                self._report_shift()
            else:
                self.comp.observe(self.T_meas, self.stress_meas)
        except SmaWristError as e:
            self.diagnose('inverse', DiagnosticStatus.ERROR, f'memory update failed: {e}')

    def _report_shift(self) -> None:
        """WARN on /diagnostics while a wire's learnt temperature shift sits on its limit: the model does
        not explain that wire (another wire, or a slack wire / a joint on its stop read as a temperature
        error), which on a measured wire went with the inverse mode failing (doc/explanation/
        controllers.md)."""
        lim = self.comp.shift_limit_C
        at = tuple(lim > 0 and abs(x) >= lim for x in self.comp.shift_C.tolist())
        if at == self._shift_at_limit:  # diagnose publishes on change only: skip building its values
            return
        self._shift_at_limit = at
        wires = ' and '.join(f'muscle {i + 1}' for i, a in enumerate(at) if a)
        self.diagnose(
            'adaptation',
            DiagnosticStatus.WARN if wires else DiagnosticStatus.OK,
            f'learnt temperature shift of {wires} at the +-{lim:g} degC limit: the model does not explain '
            'the wire (another wire, or slack / on a stop); direct_adaptive or pid do not depend on it'
            if wires
            else 'learnt temperature shifts inside their limits',
            {'shift_C': np.round(self.comp.shift_C, 2).tolist()},
        )

    def _on_target(self, key: str, msg: Any) -> None:
        """Collect one cycle's four targets, paired by their order on each topic, not by arrival.

        Under ROS the four topics of one cycle arrive in any order, and the next cycle's first
        targets can arrive before this cycle's last: taking 'the latest of each' mixed two cycles
        (strain of one muscle from cycle k+1 with the other's from cycle k), which at a reversal
        of the sine moved the joint. A rejected target still fills its slot,
        so the cycles stay aligned, and that cycle is skipped.
        """
        v = msg.data
        valid = finite(v) and not (key.startswith('stress') and v < 0)
        if not valid:
            self.reject_input(key + '_desired', f'{v!r} is not a valid target')
        q = self.pending[key]
        q.append(v if valid else None)
        if len(q) > MAX_PENDING_CYCLES:  # a lost message misaligned the cycles: restart from the newest
            for other in self.pending.values():
                other.clear()
            return
        if all(self.pending.values()):
            cycle = {k: self.pending[k].popleft() for k in INPUTS}
            if None not in cycle.values():
                self.values.update(cycle)
                self._compensate()

    def _compensate(self) -> None:
        # Python floats and bools where numpy would be called on (2,) arrays: each such call
        # costs ~1 us, more than the arithmetic (this runs at 100 Hz)
        v = self.values
        strain = np.array([v['strain_1'], v['strain_2']])
        if self.p['stress_source'] == 'measured' and finite(*self.stress_meas.tolist()):
            stress = self.stress_meas.copy()
        else:
            stress = np.array([v['stress_1'], v['stress_2']])
        if not self.started:
            return  # memory needs a measured starting point (_take_tick)
        try:
            res = self.comp(strain, stress, commit=self.p['memory_source'] != 'measured')
        except SmaWristError as e:
            self.diagnose('inverse', DiagnosticStatus.ERROR, f'inverse failed: {e}')
            return
        sat = any(res.saturated.tolist()) or any(res.load_clipped.tolist())
        if sat != self._saturated:  # diagnose publishes on change only: skip building its values (~10 us a tick)
            self._saturated = sat
            self.diagnose(
                'saturation',
                DiagnosticStatus.WARN if sat else DiagnosticStatus.OK,
                'target outside the reachable temperature/load window' if sat else 'targets reachable',
                {'load_kgf': np.round(res.load_kgf, 3).tolist()},
                routine=True,
            )
        stamp = self.get_clock().now().to_msg()
        for i, T in enumerate(res.temperature_C.tolist()):
            msg = Temperature(temperature=T, variance=0.0)
            msg.header.stamp = stamp
            msg.header.frame_id = f'muscle_{i + 1}'
            self.pub_T[i].publish(msg)


def main(args: list[str] | None = None) -> int:
    return main_for(HysteresisCompensator, args)


if __name__ == '__main__':
    raise SystemExit(main())
