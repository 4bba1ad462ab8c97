"""plant_sim: the simulated wrist (TEM heat balance + SD-GPI muscles + joint), and the clock.

Subscribes the TEM drive commands, integrates :class:`sma_wrist.core.plant.wrist.WristPlant`
at ``dt_s`` (1 kHz), and every ``1 / publish_rate_hz`` of simulated time publishes
``/clock`` and the measurements (temperatures, per-wire stresses, joint state) stamped
with simulated time. It runs on its own (steady/system) clock with ``use_sim_time``
false: one timer period of ``1 / (publish_rate_hz * real_time_factor)`` s advances the
simulation by ``1 / publish_rate_hz``; the other nodes set ``use_sim_time:=true``.
On the embedded runtime the steady clock is virtual, so the graph runs as fast as the
CPU allows and the result does not depend on the machine.

``model.*`` parameters (nominal by default) run the extended model that
``sma-wrist diagnose`` writes as a params file (sma_wrist.core.plant.extensions): thermal
and joint deviations inside the plant, sensor effects on what is published.

``plant`` selects another registered plant (:data:`sma_wrist.plants.PLANTS`: ``sdgpi`` is the
project's wire with a parameter spread, ``phase_fraction`` a structurally different wire),
perturbed by ``scenario.*`` (or a ``scenario_file``, JSON as ``sma-wrist sweep`` writes); its
sensor effects (thermocouple noise and lag, potentiometer noise) act on what is published.

Safety: commands beyond the TEM limits are clipped (flagged on /diagnostics), NaN/inf
commands are rejected (last good command kept), a command older than
``command_timeout_s`` is replaced by 0 V (TEMs off), and a muscle above
``max_muscle_temperature_C`` is reported.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time as TimeMsg
from diagnostic_msgs.msg import DiagnosticStatus
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState, Temperature
from std_msgs.msg import Float64, Header

from sma_wrist.contract import PAYLOAD_RANGE_KG
from sma_wrist.core.errors import SmaWristError
from sma_wrist.core.plant import extensions as mx
from sma_wrist.core.plant.wrist import PlantParams, WristPlant
from sma_wrist.core.thermal.heat_balance import EXCHANGER_FACE
from sma_wrist.nodes.common import (
    HYSTERESIS_FILE_PARAM,
    MUSCLE_FRAMES,
    PRELOAD_PARAM,
    Freshness,
    Param,
    WristNode,
    finite,
    main_for,
)
from sma_wrist.plants import PLANTS
from sma_wrist.plants.spread import VALIDITY as SCENARIO_AXES

#: window over which plant_sim compares simulated time with its clock [s of node clock]
REAL_TIME_WINDOW_S = 5.0
#: an achieved factor below this fraction of real_time_factor is reported (WARN)
REAL_TIME_TOLERANCE = 0.9


class RealTimeMonitor:
    """Achieved real-time factor of a plant timed by its node clock.

    Under ROS the timer fires late when the machine cannot keep up (the embedded runtime's
    virtual clock never does): the plant then runs slower than ``real_time_factor`` while the
    controllers, on its /clock, see nothing wrong. Each window of ``window_s`` of node-clock
    time, :meth:`update` returns simulated seconds / clock seconds over that window.
    """

    def __init__(self, window_s: float = REAL_TIME_WINDOW_S) -> None:
        self.window_s = window_s
        self.start: tuple[float, float] | None = None  # (sim s, clock s) at the window's start

    def update(self, sim_s: float, clock_s: float) -> float | None:
        if self.start is None or clock_s < self.start[1]:
            self.start = (sim_s, clock_s)
            return None
        sim0, clock0 = self.start
        if clock_s - clock0 < self.window_s:
            return None
        self.start = (sim_s, clock_s)
        return (sim_s - sim0) / (clock_s - clock0)


class PlantSim(WristNode):
    OWNS_CLOCK = True
    PARAMS = (
        (
            Param('payload_kg', 0.3, 'payload mass M at the lever l = 0.09 m', 'kg', PAYLOAD_RANGE_KG),
            Param('dt_s', 1e-3, 'plant integration step', 's', (1e-4, 1e-2), runtime=False),
            Param(
                'publish_rate_hz',
                100.0,
                'rate of /clock and of the measurements, in simulated time',
                'Hz',
                (1.0, 1000.0),
                runtime=False,
            ),
            Param(
                'real_time_factor',
                1.0,
                'simulated seconds per second of the node clock (steady time)',
                '1',
                (0.01, 1000.0),
                runtime=False,
            ),
            Param(
                'initial_angle_rad',
                -1.0,
                'start angle; negative = static equilibrium at zero drive',
                'rad',
                (-1.0, 1.4),
                runtime=False,
            ),
            Param('command_timeout_s', 0.5, 'a TEM command older than this is replaced by 0 V', 's', (0.01, 60.0)),
            Param(
                'max_muscle_temperature_C', 90.0, 'muscle over-temperature threshold (reported)', 'degC', (30.0, 120.0)
            ),
            Param(
                'thermal_file',
                '',
                'identified TEM heat balance (sma-wrist identify thermal; empty: Table 4.9)',
                runtime=False,
            ),
            Param(
                'heat_balance_file',
                '',
                "the model's heat balance in the Peltier form (sma-wrist commission writes one where it predicts "
                "better; empty: Table 4.9's form of thermal_file)",
                runtime=False,
            ),
            HYSTERESIS_FILE_PARAM,
            Param(
                'wire_file',
                '',
                "the model's wire where it is not the SD-GPI of hysteresis_file: wire.yaml (form phase_fraction) "
                'from sma-wrist commission (empty: that SD-GPI)',
                runtime=False,
            ),
            PRELOAD_PARAM,
        )
        + tuple(
            # the extended model of `sma-wrist diagnose` (its params file sets these); nominal = plain plant
            Param(f'model.{e.name}', float(e.nominal), e.description, e.unit, (e.lower, e.upper), runtime=False)
            for e in mx.PARAMS
        )
        + (
            # a plant that is not the controllers' model (sma_wrist.plants); 'model' = the one above
            Param(
                'plant',
                'model',
                'simulated plant: the model (with model.*) or a registered test plant (sma_wrist.plants)',
                choices=('model',) + tuple(PLANTS),
                runtime=False,
            ),
            Param(
                'scenario_file',
                '',
                'JSON {perturbation: value} for a registered plant (overrides scenario.*)',
                runtime=False,
            ),
            Param('scenario.noise_seed', 0, "seed of the scenario's sensor noise", '', (0, 2**31 - 1), runtime=False),
        )
        + tuple(
            Param(f'scenario.{a.name}', float(a.nominal), a.description, a.unit, (a.lower, a.upper), runtime=False)
            for a in SCENARIO_AXES
            if a.name != 'payload_kg'
        )
    )

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('plant_sim', **kwargs)
        p = self.p
        ext = {e.name: p[f'model.{e.name}'] for e in mx.PARAMS}
        base = PlantParams.from_files(
            p['hysteresis_file'],
            p['thermal_file'],
            heat_balance_file=p['heat_balance_file'],
            wire_file=p['wire_file'],
            dt=p['dt_s'],
            max_muscle_temperature_C=p['max_muscle_temperature_C'],
            preload_elongation_mm=p['preload_elongation_mm'],
        )
        self.sim_params = mx.plant_params(ext, base)
        # /wrist/payload publishes payload_kg (what the user believes); the joint carries the true mass
        self.payload_err_kg = ext['payload_err_kg']
        true_payload = max(p['payload_kg'] + self.payload_err_kg, 0.0)
        q0 = None if p['initial_angle_rad'] < 0 else p['initial_angle_rad']
        self.scenario_sensors = None
        if p['plant'] != 'model':
            self.plant, self.scenario_sensors = self._test_plant(p, ext, true_payload, q0)
        else:
            self.plant = WristPlant(self.sim_params, payload_kg=true_payload)
        if q0 is not None and self.scenario_sensors is None:
            self.plant.state = self.plant.rest_state(np.array([true_payload]), q0=q0)
        self.sensors = mx.SensorChain(ext, 1.0 / p['publish_rate_hz'], self.sim_params.joint.q_neutral_rad)
        if ext != mx.NOMINAL:
            self.get_logger().info(
                'extended model: ' + ', '.join(f'{k} = {v:g}' for k, v in ext.items() if v != mx.NOMINAL[k])
            )
        self.steps_per_tick = max(1, int(round(1.0 / (p['publish_rate_hz'] * p['dt_s']))))
        self.command_V = np.zeros((1, 2))
        self.fresh = Freshness(self, ('tem_1', 'tem_2'))
        self._status: tuple[Any, ...] | None = None  # (stale, saturated, hot, faces outside, overload) last diagnosed
        self.real_time = RealTimeMonitor()
        self._slow_message: str | None = None

        self.pub_clock = self.publisher('/clock')
        self.pub_joint = self.publisher('/wrist/joint_states')
        self.pub_temp = [self.publisher(f'/wrist/muscle_{i}/temperature') for i in (1, 2)]
        self.pub_face = [self.publisher(f'/wrist/tem_{i}/face_temperature') for i in (1, 2)]
        self.pub_stress = [self.publisher(f'/wrist/muscle_{i}/stress') for i in (1, 2)]
        self.pub_payload = self.publisher('/wrist/payload')
        for i in (1, 2):
            self.subscription(f'/wrist/tem_{i}/command', lambda msg, i=i: self._on_command(i, msg))
        period = 1.0 / (p['publish_rate_hz'] * p['real_time_factor'])
        self.timer = self.create_timer(period, self._tick)
        self._publish_payload()
        self._publish_measurements()
        self.get_logger().info(
            f'plant_sim: payload {p["payload_kg"]} kg, dt {p["dt_s"]} s, {self.steps_per_tick} steps per '
            f'{1.0 / p["publish_rate_hz"]:g} s tick, start angle {float(self.plant.state.q[0]):.3f} rad; '
            # which model forms run: a commissioned params file may name the Peltier form or the phase-fraction wire
            f'wire {"phase-fraction (" + p["wire_file"] + ")" if p["wire_file"] else "SD-GPI"}, heat balance '
            f'{"Peltier (" + p["heat_balance_file"] + ")" if p["heat_balance_file"] else "Table 4.9"}'
            + self._latent_note()
        )

    def _latent_note(self) -> str:
        """The start-up line's note of the heat balance's latent heat (Eq. P.4), '' where there is none."""
        hb = self.sim_params.heat_balance
        if hb is None or not any(hb.latent_C):
            return ''
        return f" with the wires' latent heat {hb.latent_C[0]:g} / {hb.latent_C[1]:g} degC per transformation"

    def _test_plant(self, p: Mapping[str, Any], ext: Mapping[str, float], payload: float, q0: float | None) -> Any:
        """A registered plant (sma_wrist.plants) of the scenario given by scenario.* or scenario_file."""
        from sma_wrist.plants import make_plant
        from sma_wrist.plants.spread import Scenario, SensorBank

        if ext != mx.NOMINAL or q0 is not None:
            raise SmaWristError(
                f'plant {p["plant"]!r} takes its perturbations from scenario.* / scenario_file: '
                'leave model.* nominal and initial_angle_rad negative'
            )
        if p['scenario_file']:
            sc = Scenario.from_file(p['scenario_file'], {'payload_kg': payload})
        else:
            sc = Scenario.from_mapping(
                {
                    'payload_kg': payload,
                    'noise_seed': int(p['scenario.noise_seed']),
                    **{a.name: p[f'scenario.{a.name}'] for a in SCENARIO_AXES if a.name != 'payload_kg'},
                }
            )
        self.get_logger().info(f'plant {p["plant"]}: ' + ', '.join(f'{k} = {v:g}' for k, v in sc.to_dict().items()))
        return make_plant(p['plant'], [sc], self.sim_params), SensorBank([sc], 1.0 / p['publish_rate_hz'])

    # -- parameters ------------------------------------------------------------
    def apply(self, changed: Mapping[str, Any]) -> None:
        if 'payload_kg' in changed:
            self.plant.state.payload_kg[:] = max(changed['payload_kg'] + self.payload_err_kg, 0.0)
            self._publish_payload()
        if 'max_muscle_temperature_C' in changed:
            self.sim_params = replace(self.sim_params, max_muscle_temperature_C=changed['max_muscle_temperature_C'])
            self.plant.params = self.sim_params

    # -- inputs ----------------------------------------------------------------
    def _on_command(self, i: int, msg: Any) -> None:
        if not finite(msg.data):
            self.reject_input(f'tem_{i}/command', f'non-finite command {msg.data!r} V')
            return
        self.command_V[0, i - 1] = msg.data
        self.fresh.mark(f'tem_{i}')

    # -- simulation ------------------------------------------------------------
    def _tick(self) -> None:
        now_ns = self.get_clock().now().nanoseconds
        timeout_ns = self.p['command_timeout_s'] * 1e9
        stale = tuple(n for n, t in self.fresh.stamp_ns.items() if t is not None and now_ns - t > timeout_ns)
        u = self.command_V
        if stale:
            u = u.copy()
            for n in stale:
                u[0, int(n[-1]) - 1] = 0.0
        try:
            s = self.plant.advance(u, self.steps_per_tick)
        except SmaWristError as e:
            self.diagnose('model', DiagnosticStatus.ERROR, f'simulation stopped: {e}')
            self.timer.cancel()
            return
        # the TEMs' own operating window (doc/explanation/model.md), sampled at the tick: faces move over seconds
        lo, hi = self.sim_params.thermal.window_C
        faces = s.thermal[0].ravel().tolist()
        outside = not all(lo <= f <= hi for f in faces)  # NaN counts as outside
        clamped = s.flags.get(
            'overload'
        )  # a wire's load held at the wire model's bound (the phase-fraction wire has none)
        status = (
            stale,
            bool(s.flags['command_saturated'][0]),
            bool(s.flags['over_temperature'][0]),
            outside,
            clamped is not None and bool(clamped[0]),
        )
        if status != self._status:  # diagnose publishes on change only: skip building its arguments
            self._status = status
            self._diagnose_tick(*status, faces)
        self._publish_measurements()
        self._check_real_time(now_ns)

    def _diagnose_tick(
        self, stale: tuple[str, ...], saturated: bool, hot: bool, outside: bool, overload: bool, faces: list[float]
    ) -> None:
        self.diagnose(
            'command',
            DiagnosticStatus.WARN if stale else DiagnosticStatus.OK,
            f'no fresh command on {", ".join(stale)}: TEM off' if stale else 'commands fresh',
        )
        self.diagnose(
            'saturation',
            DiagnosticStatus.WARN if saturated else DiagnosticStatus.OK,
            'TEM command clipped to the drive limits' if saturated else 'commands within limits',
            {'u_min_V': self.sim_params.thermal.u_min_V, 'u_max_V': self.sim_params.thermal.u_max_V},
        )
        self.diagnose(
            'temperature',
            DiagnosticStatus.ERROR if hot else DiagnosticStatus.OK,
            f'muscle above {self.p["max_muscle_temperature_C"]} degC' if hot else 'temperatures normal',
        )
        lo, hi = self.sim_params.thermal.window_C
        self.diagnose(
            'tem_faces',
            DiagnosticStatus.ERROR if outside else DiagnosticStatus.OK,
            f'a TEM face outside its {lo:g}-{hi:g} degC window' if outside else 'TEM faces inside their window',
            {'hottest_C': f'{max(faces):.2f}', 'coldest_C': f'{min(faces):.2f}'} if outside else None,
        )
        # the SD-GPI load solve searches up to max_load_kgf; a wire that would carry more is held there, and the
        # wrist's motion from then on is the bound's, not the wire's (doc/explanation/controllers.md)
        m = self.sim_params.muscle
        bound = f'{m.max_load_kgf:g} kgf ({float(m.stress_Pa(m.max_load_kgf)) * 1e-6:.0f} MPa)'
        self.diagnose(
            'wire_load',
            DiagnosticStatus.ERROR if overload else DiagnosticStatus.OK,
            f"a wire's load reached the wire model's bound {bound}: the simulation has left the model"
            if overload
            else 'wire loads inside the wire model',
        )

    def _check_real_time(self, now_ns: int) -> None:
        achieved = self.real_time.update(self.plant.state.t, now_ns * 1e-9)
        if achieved is None:
            return
        wanted = self.p['real_time_factor']
        if achieved >= REAL_TIME_TOLERANCE * wanted:
            self._slow_message = None
            self.diagnose('real_time', DiagnosticStatus.OK, f'keeping real_time_factor {wanted:g}x')
            return
        # diagnose publishes and logs on a changed message: keep the first window's number while slow
        if self._slow_message is None:
            self._slow_message = (
                f'simulating at {achieved:.2f}x instead of real_time_factor {wanted:g}x: the '
                'machine cannot keep up (lower real_time_factor)'
            )
        self.diagnose(
            'real_time',
            DiagnosticStatus.WARN,
            self._slow_message,
            {'achieved': f'{achieved:.3f}', 'real_time_factor': f'{wanted:g}'},
        )

    def diagnostics_stamp(self) -> Any:
        """Sim time, as the measurements and /clock (its own clock is the system clock)."""
        return self._stamp()

    def _stamp(self) -> Any:
        ns = int(round(self.plant.state.t * 1e9))
        return TimeMsg(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)

    def _publish_measurements(self) -> None:
        stamp = self._stamp()
        self.pub_clock.publish(Clock(clock=stamp))
        plant = self.plant
        s = plant.state
        T = plant.muscle_temperature_C[0]
        q_meas = float(s.q[0])
        qd_meas = float(s.qd[0])
        if self.scenario_sensors is not None:
            T2, q2, qd2 = self.scenario_sensors.measure(T[None], s.q, s.qd)
            T, q_meas, qd_meas = T2[0], float(q2[0]), float(qd2[0])
        elif not self.sensors.identity:
            T = self.sensors.temperatures(T)
            q_meas = self.sensors.angle(q_meas)
        T = T.tolist()
        faces = s.thermal[0, :, EXCHANGER_FACE].tolist()
        stress = plant.wire_stress_Pa[0].tolist()
        for i in range(2):
            self.pub_temp[i].publish(
                Temperature(header=Header(stamp=stamp, frame_id=MUSCLE_FRAMES[i]), temperature=T[i], variance=0.0)
            )
            self.pub_stress[i].publish(Float64(data=stress[i]))
            # the model's exchanger face (Eq. 4.14), as the device's face thermocouple reads it: a bag of the
            # simulation carries the heat-balance state a replay starts from, as a bag of the device does
            self.pub_face[i].publish(
                Temperature(header=Header(stamp=stamp, frame_id=f'tem_{i + 1}'), temperature=faces[i], variance=0.0)
            )
        self.pub_joint.publish(
            JointState(
                header=Header(stamp=stamp, frame_id=self.contract.frame_id),
                name=[self.contract.joint_name],
                position=[q_meas],
                velocity=[qd_meas],
                effort=[float(plant.muscle_torque_Nm[0])],
            )
        )

    def _publish_payload(self) -> None:
        self.pub_payload.publish(Float64(data=float(self.p['payload_kg'])))


def main(args: list[str] | None = None) -> int:
    return main_for(PlantSim, args)


if __name__ == '__main__':
    raise SystemExit(main())
