"""trajectory_generator: publishes the desired wrist angle q_d(t), its rate and acceleration.

Default: the Sec. 6.1 experiment q_d = 0.524 + 0.524 sin(0.1 t) rad. Other shapes: step,
ramp, sine_sweep, constant (:mod:`sma_wrist.core.control.trajectory`). Time is the node clock
(simulated time under ``use_sim_time``), measured from the first tick, so a run starts
at t = 0 of its trajectory whenever the node comes up. It starts from the wrist's measured angle
(the first ``/wrist/joint_states`` it has, clipped to the angle limits) and joins the shape over
``soft_start_s`` (:class:`~sma_wrist.core.control.trajectory.SoftStart`); until it has that angle it publishes
nothing, and the controllers wait. ``soft_start_s: 0`` (the default; ``sma-wrist run`` sets 30 s) publishes the
shape from its first value at once.
Output: ``/wrist/reference``
(sensor_msgs/JointState: position q_d, velocity, effort = acceleration, documented in
msg_defs/topics.yaml).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

from sensor_msgs.msg import JointState
from std_msgs.msg import Header

from sma_wrist.core.control.trajectory import GENERATORS, SoftStart, Trajectory, make_trajectory
from sma_wrist.core.errors import ParameterError
from sma_wrist.nodes.common import Param, WristNode, finite, main_for

# Ranges by unit suffix for the per-shape parameters; the generators check the rest
# (e.g. amplitude >= 0) and make_trajectory checks the whole q_d stays inside the limits.
_RANGES = {'_rad_s': ((-10.0, 10.0), 'rad/s'), '_rad': ((-6.3, 6.3), 'rad'), '_s': ((0.0, 1e6), 's')}


def _shape_params() -> tuple[Param, ...]:
    """``<shape>.<field>`` for every field of every generator, defaults from the generator."""
    out = []
    for shape, cls in GENERATORS.items():
        for f in dataclasses.fields(cls):
            suffix = next(k for k in _RANGES if f.name.endswith(k))
            rng, unit = _RANGES[suffix]
            out.append(
                Param(
                    f'{shape}.{f.name}',
                    float(f.default),
                    f'{shape}: {f.name} (sma_wrist.core.control.trajectory.{cls.__name__})',
                    unit,
                    rng,
                )
            )
    return tuple(out)


class TrajectoryGenerator(WristNode):
    PARAMS = (
        Param('shape', 'sine', 'reference shape', choices=tuple(GENERATORS)),
        Param('rate_hz', 100.0, 'publishing rate', 'Hz', (1.0, 1000.0), runtime=False),
        Param('angle_min_rad', 0.0, 'lowest angle a reference may command', 'rad', (-0.35, 1.4)),
        Param('angle_max_rad', 1.05, 'highest angle a reference may command', 'rad', (-0.35, 1.4)),
        Param(
            'soft_start_s',
            0.0,
            "the reference starts at the wrist's measured angle and joins the shape "
            'over this time (quintic blend, at rest at both ends); 0: the shape from its first value at once, '
            'however far the wrist is from it',
            's',
            (0.0, 120.0),
        ),
    ) + _shape_params()

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('trajectory_generator', **kwargs)
        self.shape: Trajectory = self._build(self.p)
        self.trajectory: Trajectory = self.shape
        self.pub = self.publisher('/wrist/reference')
        self.t0_ns: int | None = None
        self.angle: float | None = None  # the latest measured angle [rad]
        self.start_rad: float | None = None  # the angle the reference started from [rad] (None: not started)
        self.waiting_since_ns: int | None = None
        self.told_waiting = False
        self.subscription('/wrist/joint_states', self._on_joint_state)
        self.timer = self.create_timer(1.0 / self.p['rate_hz'], self._tick)
        p = self.p
        shape = ', '.join(f'{k.split(".", 1)[1]} {v:g}' for k, v in p.items() if k.startswith(p['shape'] + '.'))
        self.get_logger().info(
            f'trajectory_generator: {p["shape"]} ({shape}) within [{p["angle_min_rad"]:g}, '
            f'{p["angle_max_rad"]:g}] rad on /wrist/reference at {p["rate_hz"]:g} Hz, t = 0 at its '
            'first tick' + ('; waiting for /clock (use_sim_time)' if self.get_parameter('use_sim_time').value else '')
        )

    def _build(self, p: Mapping[str, Any]) -> Trajectory:
        """The core generator for a parameter set; ParameterError names what is wrong."""
        shape = p['shape']
        prefix = shape + '.'
        kwargs = {k[len(prefix) :]: v for k, v in p.items() if k.startswith(prefix)}
        return make_trajectory(shape, (p['angle_min_rad'], p['angle_max_rad']), **kwargs)

    def validate(self, values: Mapping[str, Any]) -> str | None:
        problem = super().validate(values)
        if problem:
            return problem
        try:
            self._build(values)
        except ParameterError as e:
            return str(e)
        return None

    def apply(self, changed: Mapping[str, Any]) -> None:
        self.shape = self._build(self.p)
        self.trajectory = self._soft(self.start_rad)

    def _soft(self, start_rad: float | None) -> Trajectory:
        """The shape, joined from start_rad over soft_start_s (the shape itself without an angle or with 0 s)."""
        if start_rad is None or self.p['soft_start_s'] == 0.0:
            return self.shape
        return SoftStart(self.shape, start_rad, self.p['soft_start_s'])

    def _on_joint_state(self, msg: Any) -> None:
        if msg.position and finite(msg.position[0]):
            self.angle = msg.position[0]

    def _tick(self) -> None:
        now = self.get_clock().now()
        if self.t0_ns is None:
            if self.p['soft_start_s'] > 0.0 and self.angle is None:
                # no measured angle to start from yet: no reference, the controllers wait; said once after 1 s
                if self.waiting_since_ns is None:
                    self.waiting_since_ns = now.nanoseconds
                elif not self.told_waiting and now.nanoseconds - self.waiting_since_ns > 1e9:
                    self.told_waiting = True
                    self.get_logger().info(
                        'no /wrist/joint_states yet: the reference starts at the measured angle '
                        '(soft_start_s; 0 publishes the shape without it)'
                    )
                return
            self.t0_ns = now.nanoseconds
            if self.angle is not None:  # a reference never leaves the angle limits, its start neither
                self.start_rad = min(max(self.angle, self.p['angle_min_rad']), self.p['angle_max_rad'])
            self.trajectory = self._soft(self.start_rad)
        t = (now.nanoseconds - self.t0_ns) * 1e-9
        q, qd, qdd = (float(x) for x in self.trajectory(t))
        self.pub.publish(
            JointState(
                header=Header(stamp=now.to_msg(), frame_id=self.contract.frame_id),
                name=[self.contract.joint_name],
                position=[q],
                velocity=[qd],
                effort=[qdd],
            )
        )


def main(args: list[str] | None = None) -> int:
    return main_for(TrajectoryGenerator, args)


if __name__ == '__main__':
    raise SystemExit(main())
