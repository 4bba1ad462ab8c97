"""adaptive_controller: joint angle tracking (back-stepping adaptive law, or the Sec. 6.1 PID).

Thin adapter over :class:`sma_wrist.core.control.joint_controller.JointController`. Every scalar
field of the core parameter dataclasses is a declared ROS parameter with the dataclass
default: ``mode``, the composition's own fields, ``adaptive.<field>``
(:class:`~sma_wrist.core.control.adaptive.AdaptiveParams`, Eqs. 5.24, 5.32, 5.37) and
``pid.<field>`` (:class:`~sma_wrist.core.control.pid.PIDParams`). The paper's Table 6.1 gains are
the params file ``config/paper_table_6_1.yaml``.

Computes on each measured joint state (100 Hz with the default plant) with the latest
reference. In ``inverse_adaptive`` mode it publishes desired strain and stress of both
muscles for hysteresis_compensator; in ``direct_adaptive`` and ``pid`` it publishes the
desired temperatures itself. A stale or missing reference or joint state stops the
output (tem_controller then switches the TEMs off) and is reported on /diagnostics: an input
silent for more than ``stale_timeout_s``, or, from the first joint state on, a reference that has
not come within ``stale_timeout_s`` of it.
"""

from __future__ import annotations

import dataclasses
import typing
from collections.abc import Mapping
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from sensor_msgs.msg import Temperature
from std_msgs.msg import Float64, Header

from sma_wrist.core.control import adaptive_kernel
from sma_wrist.core.control.adaptive import AdaptiveParams
from sma_wrist.core.control.joint_controller import JointController as JointLaw
from sma_wrist.core.control.joint_controller import JointControllerParams, time_to_meet
from sma_wrist.core.control.pid import PIDParams
from sma_wrist.core.control.pid import warm_up as warm_up_pid
from sma_wrist.core.errors import SmaWristError
from sma_wrist.core.hysteresis.muscle import MuscleGeometry
from sma_wrist.core.plant.wrist import PlantParams
from sma_wrist.nodes.common import MUSCLE_FRAMES, PRELOAD_PARAM, Freshness, Param, WristNode, finite, main_for

DEFAULTS = JointControllerParams()


#: what ``ros2 param describe`` says of each dataclass-derived parameter: (description, unit[, range]).
#: Ranges are what a user may try on this wrist (well beyond the tuned values); the core dataclasses
#: still check what ranges cannot say (c1 > 0, force_min_N <= preload_N <= force_max_N, ...).
FIELD_DOCS: dict[str, tuple[Any, ...]] = {
    'mode': (
        'joint controller: inverse_adaptive (law + inverse SD-GPI compensator), direct_adaptive '
        '(law, force mapped to temperature) or pid (Sec. 6.1); doc/explanation/controllers.md',
        '',
    ),
    'robust': ('robust term of Eq. 5.32: tanh boundary layer or sgn', ''),
    'p_mode': ('PID proportional term on the error, or error times its rate', ''),
    'derivative_on': ('PID derivative of the measurement (no kick on reference steps) or of the error', ''),
    'anti_windup': ('PID integrator anti-windup scheme', ''),
    'c1': ('back-stepping gain C1 of z2 = e_dot + C1 e (Eq. 5.24)', '1/s', (0.0, 5000.0)),
    'c2': ('back-stepping gain C2 on z2 (Eq. 5.32)', '1/s', (0.0, 5000.0)),
    'gamma_a': ('adaptation gain of the payload estimate theta_hat (Eq. 5.37)', 'kg s^2/rad', (0.0, 10.0)),
    'gamma_b1': ('adaptation gain of beta_hat_01, muscle 1 force gain (Eq. 5.37)', 's^2/rad^2', (0.0, 10.0)),
    'gamma_b2': ('adaptation gain of beta_hat_02, muscle 2 force gain (Eq. 5.37)', 's^2/rad^2', (0.0, 10.0)),
    'gamma_d1': ('adaptation gain of D_hat_b1, compensation error bound (Eq. 5.37)', '1/s^2', (0.0, 10.0)),
    'gamma_d2': ('adaptation gain of D_hat_b2, compensation error bound (Eq. 5.37)', '1/s^2', (0.0, 10.0)),
    'boundary_layer_rad_s': ('width of the tanh boundary layer replacing sgn(z2) in Eq. 5.32', 'rad/s', (0.0, 10.0)),
    'theta0_kg': ('initial payload estimate theta_hat', 'kg', (0.0, 1.5)),
    'beta0': ('initial force-gain estimates beta_hat_0i', '1', (0.2, 5.0)),
    'd0_rad_s2': ('initial compensation-error bounds D_hat_bi', 'rad/s^2', (0.0, 1000.0)),
    'preload_N': ('muscle pre-load force F_pre around which the commands act', 'N', (0.0, 3000.0)),
    'force_min_N': ('least desired muscle force', 'N', (0.0, 3000.0)),
    'force_max_N': ('largest desired muscle force', 'N', (0.0, 3000.0)),
    'kp': ('PID proportional gain (output in degC of differential temperature per rad)', 'degC/rad', (0.0, 10000.0)),
    'ki': ('PID integral gain', 'degC/(rad s)', (0.0, 10000.0)),
    'kd': ('PID derivative gain', 'degC s/rad', (0.0, 1000.0)),
    'derivative_filter_s': ('time constant of the PID derivative filter', 's', (0.0, 10.0)),
    'output_min': ('lowest PID output (differential temperature)', 'degC', (-60.0, 0.0)),
    'output_max': ('highest PID output (differential temperature)', 'degC', (0.0, 60.0)),
    'tracking_time_s': ('back-calculation anti-windup time constant', 's', (0.0, 100.0)),
    'temperature_mid_C': ("centre of the muscles' working band (direct and PID modes)", 'degC', (0.0, 120.0)),
    'temperature_min_C': ('lowest desired muscle temperature', 'degC', (0.0, 120.0)),
    'temperature_max_C': ('highest desired muscle temperature', 'degC', (0.0, 120.0)),
    'force_per_degC_N': ('direct mode: force request per degC of temperature request', 'N/degC', (0.0, 100.0)),
    'reversal_lead_s': (
        'inverse mode: start crossing the hysteresis gap this long before the joint must '
        'reverse (doc/explanation/controllers.md; 0 = Eq. 5.5 as composed in the seed)',
        's',
        (0.0, 30.0),
    ),
    'pid_reference_lead_s': (
        "pid mode: the PID acts on the reference this far ahead, the TEMs' lag fed "
        "forward (doc/explanation/controllers.md; 0 = the seed's PID on q_d(t))",
        's',
        (0.0, 10.0),
    ),
    'direct_reference_lead_s': (
        "direct_adaptive mode: the law acts on the reference this far ahead, the TEMs' "
        "lag fed forward (doc/explanation/controllers.md; 0 = the seed's law on q_d(t))",
        's',
        (0.0, 10.0),
    ),
    'pid_output_filter_s': (
        'pid mode: time constant of a first-order low-pass on the PID output, against the '
        "joint's stick-slip reaching the TEMs (doc/explanation/controllers.md; 0 = off)",
        's',
        (0.0, 10.0),
    ),
    'direct_output_filter_s': (
        'direct_adaptive mode: time constant of a first-order low-pass on the temperature '
        'request (F - F_pre) / k, against sensor noise reaching the TEMs (doc/explanation/controllers.md; '
        '0 = off)',
        's',
        (0.0, 10.0),
    ),
}


def _fields_as_params(cls: type, prefix: str, skip: tuple[str, ...] = (), default: Any = None) -> tuple[Param, ...]:
    """A Param for every scalar (float/int/str-choice/bool) field of a parameter dataclass.

    Defaults come from ``default`` (an instance), else from the class's own defaults.
    """
    hints = typing.get_type_hints(cls)
    default = cls() if default is None else default
    out = []
    for f in dataclasses.fields(cls):
        if f.name in skip or not f.init:
            continue
        v = getattr(default, f.name)
        name = prefix + f.name
        text, unit, *limits = FIELD_DOCS.get(f.name, ('', ''))
        doc = f'{text} ({cls.__name__}.{f.name})' if text else f'{cls.__name__}.{f.name} (sma_wrist.core)'
        choices = typing.get_args(hints[f.name]) if typing.get_origin(hints[f.name]) is typing.Literal else ()
        if choices:
            out.append(Param(name, str(v), doc, unit, choices=tuple(str(c) for c in choices)))
        elif isinstance(v, bool):
            out.append(Param(name, v, doc))
        elif isinstance(v, (int, float)):
            if not limits:
                raise ValueError(f'{cls.__name__}.{f.name} has no range in FIELD_DOCS: give it one')
            out.append(Param(name, float(v), doc, unit, limits[0]))
    return tuple(out)


def _own_fields() -> tuple[Param, ...]:
    return _fields_as_params(JointControllerParams, '', skip=('adaptive', 'pid'))


class AdaptiveController(WristNode):
    PARAMS = (
        (
            Param('stale_timeout_s', 0.25, 'reference/joint-state age that stops the output', 's', (0.01, 10.0)),
            PRELOAD_PARAM,
        )
        + _own_fields()
        + _fields_as_params(AdaptiveParams, 'adaptive.', skip=('mode',), default=DEFAULTS.adaptive)
        + _fields_as_params(PIDParams, 'pid.', default=DEFAULTS.pid)
    )

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('adaptive_controller', **kwargs)
        adaptive_kernel.warm_up()  # compile before the first sample, not inside the loop
        warm_up_pid()
        time_to_meet(0.0, 0.1, -0.1)  # the reversal lead's, compiled as well
        self.chain = PlantParams(preload_elongation_mm=self.p['preload_elongation_mm'])  # the strains it asks for
        self.law = JointLaw(self._core_params(self.p), self.chain)
        self.geometry = MuscleGeometry()
        self.reference: tuple[float, float, float] | None = None
        self.T_meas = np.full(2, np.nan)
        self.t_last: float | None = None
        self.t_first_ns: int | None = None  # node clock at the first joint state: the watchdog's start [ns]
        self._saturated: bool | None = None  # last diagnosed
        self.fresh = Freshness(self, ('reference', 'joint_states'))
        self.pub_strain = [self.publisher(f'/wrist/muscle_{i}/strain_desired') for i in (1, 2)]
        self.pub_stress = [self.publisher(f'/wrist/muscle_{i}/stress_desired') for i in (1, 2)]
        self.pub_T = [self.publisher(f'/wrist/muscle_{i}/temperature_desired') for i in (1, 2)]
        self.subscription('/wrist/reference', self._on_reference)
        self.subscription('/wrist/joint_states', self._on_joint_state)
        for i in (1, 2):
            self.subscription(f'/wrist/muscle_{i}/temperature', lambda m, i=i: self._on_temperature(i, m))
        self.watchdog = self.create_timer(0.05, self._check_stale)
        p = self.p
        waits = self.waiting_for('the reference (/wrist/reference) and the joint state')
        self.get_logger().info(
            f'adaptive_controller: mode {p["mode"]}, temperatures {p["temperature_min_C"]:g}-'
            f'{p["temperature_max_C"]:g} degC, pre-load {p["preload_elongation_mm"]:g} mm; {waits} (no output until '
            f'both are fresh, none after {p["stale_timeout_s"]:g} s without one)'
        )

    # -- parameters ----------------------------------------------------------------
    @staticmethod
    def _core_params(p: Mapping[str, Any]) -> JointControllerParams:
        """Core parameter objects from the flat ROS parameters (raises ParameterError)."""

        def section(cls: type, prefix: str) -> dict[str, Any]:
            names = {f.name for f in dataclasses.fields(cls)}
            return {k[len(prefix) :]: v for k, v in p.items() if k.startswith(prefix) and k[len(prefix) :] in names}

        adaptive = AdaptiveParams(
            mode=p['mode'] if p['mode'] != 'pid' else 'inverse_adaptive', **section(AdaptiveParams, 'adaptive.')
        )
        pid = PIDParams(**section(PIDParams, 'pid.'))
        own = {
            f.name: p[f.name]
            for f in dataclasses.fields(JointControllerParams)
            if f.name not in ('adaptive', 'pid') and f.name in p
        }
        return JointControllerParams(**{**own, 'adaptive': adaptive, 'pid': pid})

    def validate(self, values: Mapping[str, Any]) -> str | None:
        problem = super().validate(values)
        if problem is None:
            try:
                self._core_params(values)
            except SmaWristError as e:
                problem = str(e)
        return problem

    def apply(self, changed: Mapping[str, Any]) -> None:
        # Gains change in place of the law; a mode change restarts the estimates.
        self.law = JointLaw(self._core_params(self.p), self.chain)

    # -- inputs ----------------------------------------------------------------------
    def _on_reference(self, msg: Any) -> None:
        try:
            q, qd, qdd = msg.position[0], msg.velocity[0], msg.effort[0]
        except IndexError:
            self.reject_input('reference', 'needs position, velocity and effort (acceleration)')
            return
        if not finite(q, qd, qdd):
            self.reject_input('reference', f'non-finite reference ({q}, {qd}, {qdd})')
            return
        self.reference = (q, qd, qdd)
        self.fresh.mark('reference')

    def _on_temperature(self, i: int, msg: Any) -> None:
        if finite(msg.temperature):
            self.T_meas[i - 1] = msg.temperature

    def _on_joint_state(self, msg: Any) -> None:
        try:
            q, qd = msg.position[0], msg.velocity[0]
        except IndexError:
            self.reject_input('joint_states', 'needs position and velocity')
            return
        if not finite(q, qd):
            self.reject_input('joint_states', f'non-finite joint state ({q}, {qd})')
            return
        self.fresh.mark('joint_states')
        if self.t_first_ns is None:
            self.t_first_ns = self.fresh.stamp_ns['joint_states']
        t = self.stamp_s(msg)
        dt, self.t_last = (None if self.t_last is None else t - self.t_last), t
        if self.reference is None or dt is None or dt <= 0:
            return
        if self.fresh.stale(self.p['stale_timeout_s']):
            return
        try:
            cmd = self.law.update(q, qd, *self.reference, dt, muscle_temperature_C=self.T_meas.copy())
        except SmaWristError as e:
            self.diagnose('law', DiagnosticStatus.ERROR, f'control law failed, output stopped: {e}')
            return
        if cmd.saturated != self._saturated:  # diagnose publishes on change only: skip building its values
            self._saturated = cmd.saturated
            self.diagnose(
                'saturation',
                DiagnosticStatus.WARN if cmd.saturated else DiagnosticStatus.OK,
                'command saturated: reference beyond what the muscles can reach'
                if cmd.saturated
                else 'command within limits',
                {k: f'{v:.4g}' for k, v in cmd.info.items()},
                routine=True,
            )
        self._publish(cmd)

    def _publish(self, cmd: Any) -> None:
        strain = cmd.strain_desired.tolist()
        for i in range(2):
            self.pub_strain[i].publish(Float64(data=strain[i]))
        if cmd.force_N is not None:
            # one wire's stress: the bundle force is shared by its parallel wires
            stress = self.geometry.stress_Pa(np.asarray(cmd.force_N) / (self.geometry.n_wires * 9.81))
            stress = stress.tolist()
            for i in range(2):
                self.pub_stress[i].publish(Float64(data=stress[i]))
        if cmd.temperature_desired_C is not None:
            stamp = self.get_clock().now().to_msg()
            T = cmd.temperature_desired_C.tolist()
            for i in range(2):
                self.pub_T[i].publish(
                    Temperature(header=Header(stamp=stamp, frame_id=MUSCLE_FRAMES[i]), temperature=T[i], variance=0.0)
                )

    def _check_stale(self) -> None:
        # Armed by the first joint state; a reference not yet received is judged by the time since then, as one
        # that stopped is by the time since its last message. trajectory_generator's soft start publishes its first
        # reference only after it has a measured angle, so the first reference always comes after the first joint
        # state; judged stale at once, it was an ERROR at the start of every hardware run (the first /clock is the
        # device's time, 0.11-0.14 s, so this timer is overdue and ran in that first instant between the two).
        stale = self.fresh.stale(self.p['stale_timeout_s'], since_ns=self.t_first_ns)
        level = DiagnosticStatus.ERROR if stale and self.t_first_ns is not None else DiagnosticStatus.OK
        self.diagnose(
            'watchdog',
            level,
            f'no fresh {", ".join(stale)}: output stopped' if level != DiagnosticStatus.OK else 'inputs fresh',
        )


def main(args: list[str] | None = None) -> int:
    return main_for(AdaptiveController, args)


if __name__ == '__main__':
    raise SystemExit(main())
