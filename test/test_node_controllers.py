"""trajectory_generator, tem_controller and hysteresis_compensator on the embedded runtime."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sma_wrist.runtime.launch import Runtime
from sma_wrist.sweep.simulate import STROKE_GAIN_PER_S


def test_trajectory_generator_publishes_the_seed_sine_with_derivatives(probe_factory):
    """Without a soft start the reference is the Sec. 6.1 sine from its first tick, measured angle or not."""
    from sma_wrist.nodes.trajectory_generator import TrajectoryGenerator

    with Runtime(params={'/trajectory_generator': {'soft_start_s': 0.0}}) as rt:
        probe = probe_factory(rt, ('/wrist/reference',))
        rt.add(TrajectoryGenerator)
        rt.run_until(20.0, until='steady')
    ref = probe.got['/wrist/reference']
    t = np.array([m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec for m in ref])
    q = np.array([m.position[0] for m in ref])
    qd = np.array([m.velocity[0] for m in ref])
    qdd = np.array([m.effort[0] for m in ref])
    t0 = t[0]
    np.testing.assert_allclose(q, 0.524 + 0.524 * np.sin(0.1 * (t - t0)), atol=1e-12)
    np.testing.assert_allclose(qd, 0.0524 * np.cos(0.1 * (t - t0)), atol=1e-12)
    np.testing.assert_allclose(qdd, -0.00524 * np.sin(0.1 * (t - t0)), atol=1e-12)
    assert len(ref) == pytest.approx(2001, abs=1)


def test_trajectory_generator_starts_from_the_measured_angle_and_joins_the_sine(probe_factory):
    """A soft start (sma-wrist run's 30 s): nothing is published before a measured angle; the first reference is that angle, at
    rest; it joins the sine smoothly (rate and acceleration the derivatives of the angle) and is the sine itself
    from soft_start_s on."""
    from sma_wrist.core.control.trajectory import RUN_SOFT_START_S as SOFT_START_S
    from sma_wrist.nodes.trajectory_generator import TrajectoryGenerator
    from sma_wrist.runtime.rclpy import logging as rlog

    said = []
    remove = rlog.add_sink(lambda sev, name, msg, t: said.append(msg) if name == 'trajectory_generator' else None)
    with Runtime(params={'/trajectory_generator': {'soft_start_s': SOFT_START_S}}) as rt, rlog.silenced():
        probe = probe_factory(rt, ('/wrist/reference',))
        node = rt.add(TrajectoryGenerator)
        rt.run_until(1.5, until='steady')
        assert probe.got['/wrist/reference'] == []  # no angle yet: no reference, and the reason said once
        assert sum('no /wrist/joint_states yet' in m for m in said) == 1
        probe.every(0.01, '/wrist/joint_states', position=[0.2], velocity=[0.0], effort=[0.0])
        rt.run_until(1.5 + SOFT_START_S + 10.0, until='steady')
    remove()
    ref = probe.got['/wrist/reference']
    t = np.array([m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec for m in ref])
    q, qd, qdd = (np.array([getattr(m, f)[0] for m in ref]) for f in ('position', 'velocity', 'effort'))
    s = t - t[0]
    assert q[0] == 0.2 and qd[0] == 0.0 and qdd[0] == 0.0 and node.start_rad == 0.2
    after = s >= SOFT_START_S
    np.testing.assert_allclose(q[after], 0.524 + 0.524 * np.sin(0.1 * s[after]), atol=1e-12)
    np.testing.assert_allclose(np.gradient(q, s), qd, atol=2e-5)  # 10 ms central differences of a smooth blend
    np.testing.assert_allclose(np.gradient(qd, s), qdd, atol=2e-5)
    assert np.all(np.abs(qd[~after]) < 0.2)  # no jump: the 0.32 rad to the sine's start taken over 30 s


def test_trajectory_parameter_changes_are_validated_against_the_angle_limits():
    from rclpy.parameter import Parameter

    from sma_wrist.nodes.trajectory_generator import TrajectoryGenerator

    with Runtime() as rt:
        node = rt.add(TrajectoryGenerator)
        (too_big,) = node.set_parameters([Parameter('sine.amplitude_rad', value=0.9)])
        (shape,) = node.set_parameters([Parameter('shape', value='square')])
        (step,) = node.set_parameters([Parameter('shape', value='step')])
    assert not too_big.successful and 'angle limits' in too_big.reason
    assert not shape.successful and 'not one of' in shape.reason
    assert step.successful and type(node.trajectory).__name__ == 'Step'


def test_bad_params_file_value_stops_the_node_with_a_reason(tmp_path):
    from sma_wrist.core.errors import SmaWristError
    from sma_wrist.nodes.trajectory_generator import TrajectoryGenerator

    f = tmp_path / 'p.yaml'
    f.write_text('trajectory_generator:\n  ros__parameters:\n    shape: triangle\n')
    with Runtime(['--ros-args', '--params-file', str(f)]) as rt:
        with pytest.raises(SmaWristError, match="shape = 'triangle' is not one of"):
            rt.add(TrajectoryGenerator)


def _tem_run(probe_factory, T_meas, T_des, seconds=1.0, stop_meas_after=None):
    from sma_wrist.nodes.tem_controller import TemController

    with Runtime() as rt:
        probe = probe_factory(rt, ('/wrist/tem_1/command', '/wrist/tem_2/command'))
        node = rt.add(TemController)
        timers = [probe.every(0.01, f'/wrist/muscle_{i}/temperature', temperature=T_meas[i - 1]) for i in (1, 2)]
        for i in (1, 2):
            probe.every(0.01, f'/wrist/muscle_{i}/temperature_desired', temperature=T_des[i - 1])
        rt.run_until(seconds, until='steady')
        if stop_meas_after is not None:
            for t in timers:
                t.cancel()
            rt.run_until(seconds + stop_meas_after, until='steady')
    u1 = [m.data for m in probe.got['/wrist/tem_1/command']]
    u2 = [m.data for m in probe.got['/wrist/tem_2/command']]
    return probe, node, u1, u2


def test_tem_controller_heats_the_cold_muscle_and_cools_the_hot_one_within_limits(probe_factory):
    _, node, u1, u2 = _tem_run(probe_factory, (30.0, 60.0), (50.0, 40.0))
    assert u1[-1] > 0.5 and u2[-1] < -0.5
    assert max(u1) <= 24.0 and min(u2) >= -24.0  # driver rating


def test_tem_controller_holds_back_a_layer_whose_faces_would_leave_the_window(probe_factory):
    # muscle 1 at 79 degC asks for full heating towards 85: held back below the driver rating (the
    # heat balance predicts its face past 80 degC), while the cold layer 2 may boost
    probe, node, u1, u2 = _tem_run(probe_factory, (79.0, 30.0), (85.0, 20.0), seconds=0.3)
    assert max(u1) < 24.0
    assert min(u2) == -24.0
    assert any('clipped' in m for _, _, m in probe.diagnostics())
    cold, _, v1, _ = _tem_run(probe_factory, (40.0, 30.0), (79.0, 20.0), seconds=0.3)
    assert max(v1) == 24.0


def test_tem_controller_fixed_switch_falls_back_to_hold_limits_when_a_face_is_hot(probe_factory):
    """predictive_protection false: the hold limits once a face passes protect_above_C."""
    from rclpy.parameter import Parameter

    from sma_wrist.nodes.tem_controller import TemController

    with Runtime() as rt:
        probe = probe_factory(rt, ('/wrist/tem_1/command',))
        node = rt.add(TemController)
        assert node.set_parameters([Parameter('predictive_protection', value=False)])[0].successful
        assert node.set_parameters([Parameter('face_max_C', value=40.0)])[0].successful
        (good,) = node.set_parameters([Parameter('face_min_C', value=39.0)])
        assert good.successful
        (bad,) = node.set_parameters([Parameter('face_min_C', value=40.0)])
        assert not bad.successful and 'below face_max_C' in bad.reason
        assert node.set_parameters([Parameter('face_max_C', value=80.0)])[0].successful
        for i, T in ((1, 76.0), (2, 30.0)):
            probe.every(0.01, f'/wrist/muscle_{i}/temperature', temperature=T)
        for i, T in ((1, 79.0), (2, 20.0)):
            probe.every(0.01, f'/wrist/muscle_{i}/temperature_desired', temperature=T)
        rt.run_until(0.3, until='steady')
    u1 = [m.data for m in probe.got['/wrist/tem_1/command']]
    assert 0.0 < max(u1) <= 13.0


def test_tem_controller_times_its_law_by_the_measurement_stamps(probe_factory):
    """Under use_sim_time the node clock may not have moved between two samples (found under
    ROS 2 Humble: 'controller time step = 0.0 s', TEMs off); the stamps the plant put on the
    measurements give the step, and a repeated stamp leaves the command in force."""
    from builtin_interfaces.msg import Time
    from std_msgs.msg import Header

    from sma_wrist.nodes.tem_controller import TemController

    with Runtime() as rt:
        probe = probe_factory(rt, ('/wrist/tem_1/command',))
        rt.add(TemController)
        for i in (1, 2):
            probe.every(0.01, f'/wrist/muscle_{i}/temperature_desired', temperature=50.0)
        rt.run_until(0.05, until='steady')
        for k, stamp in enumerate((1.00, 1.00, 1.01)):  # the second sample repeats the first's stamp
            for i in (1, 2):
                probe.publish(
                    f'/wrist/muscle_{i}/temperature',
                    temperature=40.0,
                    header=Header(stamp=Time(sec=int(stamp), nanosec=int(round(stamp % 1 * 1e9)))),
                )
            rt.run_until(0.06 + 0.01 * k, until='steady')
    assert len(probe.got['/wrist/tem_1/command']) == 2  # one per distinct stamp
    assert not any('law failed' in m for _, _, m in probe.diagnostics())


def test_tem_controller_watchdog_switches_off_on_stale_temperatures_and_reports(probe_factory):
    probe, node, u1, u2 = _tem_run(probe_factory, (30.0, 60.0), (50.0, 40.0), stop_meas_after=1.0)
    assert u1[-1] == 0.0 and u2[-1] == 0.0
    assert any('TEMs off' in m and level == 2 for _, level, m in probe.diagnostics())


def test_tem_controller_over_temperature_blocks_heating(probe_factory):
    probe, node, u1, _ = _tem_run(probe_factory, (88.0, 40.0), (95.0, 40.0))
    assert u1[-1] <= 0.0
    assert any('heating blocked' in m for _, _, m in probe.diagnostics())


def test_tem_controller_rejects_implausible_temperatures(probe_factory):
    _, node, u1, _ = _tem_run(probe_factory, (math.inf, 40.0), (50.0, 40.0), seconds=0.3)
    assert node.rejected_inputs > 0
    assert all(u == 0.0 for u in u1)  # never a measurement of muscle 1: nothing to act on


def test_compensator_node_matches_the_core_inverse(probe_factory):
    from sma_wrist.core.hysteresis.compensation import MuscleCompensator
    from sma_wrist.core.hysteresis.default_params import default_sdgpi
    from sma_wrist.core.hysteresis.muscle import MuscleGeometry
    from sma_wrist.nodes.hysteresis_compensator import HysteresisCompensator

    g = MuscleGeometry()
    stress = g.stress_Pa(np.array([0.8, 0.7]))
    strain = np.array([2.0, 2.4]) / g.wire_length_mm
    with Runtime() as rt:
        probe = probe_factory(rt, ('/wrist/muscle_1/temperature_desired', '/wrist/muscle_2/temperature_desired'))
        rt.add(HysteresisCompensator)
        for i in (1, 2):
            probe.publish(f'/wrist/muscle_{i}/temperature', temperature=40.0)
            probe.publish(f'/wrist/muscle_{i}/stress', data=float(stress[i - 1]))
        rt.run_until(0.01, until='steady')
        for i in (1, 2):
            probe.publish(f'/wrist/muscle_{i}/strain_desired', data=float(strain[i - 1]))
            probe.publish(f'/wrist/muscle_{i}/stress_desired', data=float(stress[i - 1]))
        rt.run_until(0.02, until='steady')
    ref = MuscleCompensator(default_sdgpi())
    ref.reset(np.array([40.0, 40.0]), stress)
    expected = ref(strain, stress).temperature_C
    got = [probe.got[f'/wrist/muscle_{i}/temperature_desired'][-1].temperature for i in (1, 2)]
    np.testing.assert_allclose(got, expected, atol=1e-9)
    assert 20.0 <= min(got) and max(got) <= 80.0


@pytest.mark.parametrize('order', ['in_order', 'interleaved'])
def test_compensator_pairs_one_cycles_targets_whatever_their_arrival_order(probe_factory, order):
    """Under ROS the four target topics of one cycle arrive in any order and the next
    cycle's first ones can overtake this cycle's last; the inverse must see each cycle's own set."""
    from rclpy.parameter import Parameter

    from sma_wrist.core.hysteresis.muscle import MuscleGeometry
    from sma_wrist.nodes.hysteresis_compensator import HysteresisCompensator

    g = MuscleGeometry()
    stress = g.stress_Pa(np.array([0.8, 0.7]))
    cycles = [np.array([2.0, 2.4]) / g.wire_length_mm, np.array([2.6, 1.8]) / g.wire_length_mm]
    msgs = [
        (k, f'/wrist/muscle_{i}/{kind}_desired', float((cycles[k] if kind == 'strain' else stress)[i - 1]))
        for k in (0, 1)
        for kind in ('strain', 'stress')
        for i in (1, 2)
    ]
    if order == 'interleaved':  # cycle 1's strains overtake cycle 0's stresses; stress_2 before stress_1
        msgs = [msgs[0], msgs[1], msgs[4], msgs[5], msgs[3], msgs[2], msgs[7], msgs[6]]
    with Runtime() as rt:
        probe = probe_factory(rt, ('/wrist/muscle_1/temperature_desired', '/wrist/muscle_2/temperature_desired'))
        rt.add(
            HysteresisCompensator,
            parameter_overrides=[
                Parameter('stress_source', value='desired'),
                Parameter('memory_source', value='commanded'),
                Parameter('temperature_source', value='thermocouple'),
            ],
        )
        for i in (1, 2):
            probe.publish(f'/wrist/muscle_{i}/temperature', temperature=40.0)
            probe.publish(f'/wrist/muscle_{i}/stress', data=float(stress[i - 1]))
        rt.run_until(0.01, until='steady')
        for _, topic, v in msgs:
            probe.publish(topic, data=v)
            rt.spin_for(0.001, until='steady')
        rt.run_until(0.05, until='steady')
    got = [[m.temperature for m in probe.got[f'/wrist/muscle_{i}/temperature_desired']] for i in (1, 2)]
    assert len(got[0]) == len(got[1]) == 2  # one output per cycle
    from sma_wrist.core.hysteresis.compensation import MuscleCompensator
    from sma_wrist.core.hysteresis.default_params import default_sdgpi

    ref = MuscleCompensator(default_sdgpi())
    ref.reset(np.array([40.0, 40.0]), stress)
    expected = [ref(c, stress).temperature_C for c in cycles]
    np.testing.assert_allclose(np.array(got).T, expected, atol=1e-9)


@pytest.mark.parametrize('memory_source', ['measured', 'commanded'])
def test_compensator_memory_follows_the_measured_or_the_commanded_temperature(probe_factory, memory_source):
    """A wire that did not follow its first command: the second answer differs by where the memory is."""
    from rclpy.parameter import Parameter

    from sma_wrist.core.hysteresis.compensation import MuscleCompensator
    from sma_wrist.core.hysteresis.default_params import default_sdgpi
    from sma_wrist.core.hysteresis.muscle import MuscleGeometry
    from sma_wrist.nodes.hysteresis_compensator import HysteresisCompensator

    g = MuscleGeometry()
    stress = g.stress_Pa(np.array([0.8, 0.8]))
    first = np.array([1.0, 1.0]) / g.wire_length_mm  # contract: heat
    second = np.array([1.1, 1.1]) / g.wire_length_mm  # a little back
    with Runtime() as rt:
        probe = probe_factory(rt, ('/wrist/muscle_1/temperature_desired',))
        node = rt.add(
            HysteresisCompensator, parameter_overrides=[Parameter('temperature_source', value='thermocouple')]
        )
        assert node.set_parameters([Parameter('memory_source', value=memory_source)])[0].successful
        for i in (1, 2):
            probe.publish(f'/wrist/muscle_{i}/temperature', temperature=40.0)  # and it stays there
            probe.publish(f'/wrist/muscle_{i}/stress', data=float(stress[i - 1]))
        rt.run_until(0.01, until='steady')
        for k, target in enumerate((first, second)):
            for i in (1, 2):
                probe.publish(f'/wrist/muscle_{i}/strain_desired', data=float(target[i - 1]))
                probe.publish(f'/wrist/muscle_{i}/stress_desired', data=float(stress[i - 1]))
            rt.run_until(0.02 + 0.01 * k, until='steady')
    got = [m.temperature for m in probe.got['/wrist/muscle_1/temperature_desired']]
    ref = MuscleCompensator(default_sdgpi())
    ref.reset(np.array([40.0, 40.0]), stress)
    if memory_source == 'measured':
        answers = []
        for target in (first, second):
            ref.observe(np.array([40.0, 40.0]), stress)
            answers.append(ref(target, stress, commit=False).temperature_C[0])
        assert 40.0 < answers[1] < answers[0]  # still heating, a little less
    else:
        answers = [ref(target, stress).temperature_C[0] for target in (first, second)]
        assert answers[1] < answers[0] - 10.0  # the committed memory says: cool across the gap
    np.testing.assert_allclose(got[-2:], answers, atol=1e-9)


def _logged(node) -> list[str]:
    """The lines ``node`` logs from now on, whatever their severity."""
    logged: list[str] = []

    class Log:
        def info(self, m: str) -> None:
            logged.append(m)

        warning = error = info

    node.get_logger = lambda: Log()
    return logged


def test_flapping_condition_is_published_every_change_but_logged_at_most_every_10_s(probe_factory):
    from diagnostic_msgs.msg import DiagnosticStatus

    from sma_wrist.nodes.common import LOG_THROTTLE_S
    from sma_wrist.nodes.tem_controller import TemController

    with Runtime() as rt:
        probe = probe_factory(rt)
        node = rt.add(TemController)
        logged = _logged(node)
        for k in range(20):  # a command touching its limit every other tick
            node.diagnose('flap', DiagnosticStatus.WARN if k % 2 == 0 else DiagnosticStatus.OK, f'state {k % 2}')
            rt.run_until(0.1 * (k + 1), until='steady')
        rt.run_until(2.0 + LOG_THROTTLE_S, until='steady')
        node.diagnose('flap', DiagnosticStatus.WARN, 'state 0')
        node.diagnose('fault', DiagnosticStatus.ERROR, 'e1')
        node.diagnose('fault', DiagnosticStatus.ERROR, 'e2')
        node.diagnose('fault', DiagnosticStatus.ERROR, 'e3')
        rt.run_until(2.2 + LOG_THROTTLE_S, until='steady')
        node.diagnose('fault', DiagnosticStatus.OK, 'clear')
        rt.run_until(2.3 + LOG_THROTTLE_S, until='steady')
    flap = [s for s in probe.diagnostics() if s[0].endswith('flap')]
    assert len(flap) == 21  # /diagnostics sees every change
    assert len([s for s in probe.diagnostics() if s[0].endswith('fault')]) == 4
    # the first problem and its end, then the state 10 s on with the count of changes not logged
    assert logged[:2] == ['flap: state 0', 'flap: state 1'] and logged[2].startswith('flap: state 0 (18 more changes')
    # an error's onset and its end are always logged, the changing text in between is not
    assert logged[3:] == ['fault: e1', 'fault: clear (2 more changes in the last 10 s, see /diagnostics)']


def test_the_end_of_a_logged_problem_is_always_logged(probe_factory):
    """The TEMs off for 0.23 s at start-up: plant_sim's WARN "no fresh command on tem_1, tem_2: TEM off" was logged,
    and its "commands fresh" 0.23 s later fell in the 10 s throttle, so the console read as if they stayed off.
    The throttle may drop repeats of a problem, never the return to normal after a problem it logged."""
    from diagnostic_msgs.msg import DiagnosticStatus

    from sma_wrist.nodes.tem_controller import TemController

    with Runtime() as rt:
        probe_factory(rt)
        node = rt.add(TemController)
        logged = _logged(node)
        node.diagnose('command', DiagnosticStatus.OK, 'commands fresh')  # the first state: OK, not published
        for t, level, text in (
            (4.5, DiagnosticStatus.WARN, 'TEM off'),
            (4.73, DiagnosticStatus.OK, 'commands fresh'),
            (5.0, DiagnosticStatus.WARN, 'TEM off'),
            (5.1, DiagnosticStatus.OK, 'commands fresh'),
        ):
            rt.run_until(t, until='steady')
            node.diagnose('command', level, text)
    # the second problem was a repeat inside the throttle: neither it nor its end was logged
    assert logged == ['command: TEM off', 'command: commands fresh']


def _compensator_answers(
    probe_factory, stress: np.ndarray, msgs: list[tuple[str, dict]], overrides=()
) -> tuple[np.ndarray, int]:
    """hysteresis_compensator fed the measured stresses, then msgs one by one: its answers (n, 2) [degC]
    and its count of rejected inputs."""
    from sma_wrist.nodes.hysteresis_compensator import HysteresisCompensator

    with Runtime() as rt:
        probe = probe_factory(rt, ('/wrist/muscle_1/temperature_desired', '/wrist/muscle_2/temperature_desired'))
        node = rt.add(HysteresisCompensator, parameter_overrides=list(overrides))
        for i in (1, 2):
            probe.publish(f'/wrist/muscle_{i}/stress', data=float(stress[i - 1]))
        rt.spin_for(0.001, until='steady')
        for topic, fields in msgs:
            probe.publish(topic, **fields)
            rt.spin_for(0.0005, until='steady')
        rejected = node.rejected_inputs
    got = np.array([[m.temperature for m in probe.got[f'/wrist/muscle_{i}/temperature_desired']] for i in (1, 2)]).T
    return got, rejected


@pytest.mark.parametrize('order', ['in_order', 'shuffled'])
def test_compensator_memory_takes_every_measured_tick_by_stamp_whatever_the_arrival_order(probe_factory, order):
    """The memory and the adapted axis follow the measured ticks (temperatures + angle
    paired by header stamp) one by one: the same answers as the core tracking every tick, when a
    tick's parts arrive in any order, the next tick's first part overtakes this cycle's targets, and
    an old sample arrives late (taking 'the latest' at each cycle's targets mixed ticks)."""
    from builtin_interfaces.msg import Time
    from rclpy.parameter import Parameter
    from std_msgs.msg import Header

    from sma_wrist.core.control.joint_controller import bundle_strain
    from sma_wrist.core.hysteresis.compensation import MuscleCompensator
    from sma_wrist.core.hysteresis.default_params import default_sdgpi
    from sma_wrist.core.hysteresis.muscle import MuscleGeometry
    from sma_wrist.core.plant.wrist import PlantParams

    g, plant = MuscleGeometry(), PlantParams()
    stress = g.stress_Pa(np.array([0.8, 0.7]))
    n = 30
    k = np.arange(n)
    T = np.stack(
        [45.0 + 25.0 * np.sin(np.pi * k / 20), 60.0 - 15.0 * np.sin(np.pi * k / 20)], axis=1
    )  # turns at k = 10
    q = 0.5 + 0.3 * np.sin(np.pi * k / 20)
    strain = np.stack([bundle_strain(plant, x + 0.02) for x in q])

    def stamp(j: int) -> Header:
        return Header(stamp=Time(sec=1 + j // 100, nanosec=(j % 100) * 10_000_000))

    def T_msg(j: int, i: int) -> tuple[str, dict]:
        return f'/wrist/muscle_{i}/temperature', {'header': stamp(j), 'temperature': float(T[j, i - 1])}

    def q_msg(j: int) -> tuple[str, dict]:
        return '/wrist/joint_states', {
            'header': stamp(j),
            'name': ['wrist'],
            'position': [float(q[j])],
            'velocity': [0.0],
            'effort': [0.0],
        }

    def targets(j: int) -> list[tuple[str, dict]]:
        return [
            (f'/wrist/muscle_{i}/{kind}_desired', {'data': float((strain[j] if kind == 'strain' else stress)[i - 1])})
            for kind in ('strain', 'stress')
            for i in (1, 2)
        ]

    msgs: list[tuple[str, dict]] = []
    for j in range(n):
        if order == 'in_order':
            msgs += [T_msg(j, 1), T_msg(j, 2), q_msg(j)] + targets(j)
        else:  # the angle first, T_1 of this tick overtaken by the next one's, an old T_2 late
            msgs += (
                [q_msg(j), T_msg(j, 2)]
                + ([T_msg(0, 1)] if j == 0 else [])
                + ([T_msg(j + 1, 1)] if j + 1 < n else [])
                + ([T_msg(j - 3, 2)] if j >= 3 else [])
                + targets(j)
            )
    got, _ = _compensator_answers(probe_factory, stress, msgs, [Parameter('temperature_source', value='thermocouple')])
    # the node's default: the inverse's window moves with each wire's shift
    ref = MuscleCompensator(
        default_sdgpi(),
        shift_gain_per_s=2.0,
        shift_limit_C=15.0,
        window_follows_shift=True,
        stroke_gain_per_s=STROKE_GAIN_PER_S,
    )
    ref.reset(T[0], stress)
    expected = []
    for j in range(n):
        if j:
            ref.track(T[j], stress, bundle_strain(plant, q[j]), 0.01)
        expected.append(ref(strain[j], stress, commit=False).temperature_C)
    assert got.shape == (n, 2)
    assert np.ptp(got[:, 0]) > 5.0  # the answers move (the test would see a mixed tick)
    np.testing.assert_allclose(got, expected, atol=1e-9)


@pytest.mark.parametrize('order', ['in_order', 'command_overtakes_the_angle'])
def test_compensator_observer_takes_the_command_of_the_previous_tick(probe_factory, order):
    """temperature_source observer: the memory follows MuscleTemperatureObserver's estimate, driven over
    each tick by the (unstamped) command tem_controller sent after the previous tick, also when that
    command arrives before the tick's angle; a NaN command is rejected and changes nothing."""
    from builtin_interfaces.msg import Time
    from rclpy.parameter import Parameter
    from std_msgs.msg import Header

    from sma_wrist.core.control.joint_controller import bundle_strain
    from sma_wrist.core.control.tem import MuscleTemperatureObserver, TemperatureObserverParams
    from sma_wrist.core.hysteresis.compensation import MuscleCompensator
    from sma_wrist.core.hysteresis.default_params import default_sdgpi
    from sma_wrist.core.hysteresis.muscle import MuscleGeometry
    from sma_wrist.core.plant.wrist import PlantParams
    from sma_wrist.nodes.hysteresis_compensator import OBSERVER_THERMAL

    g, plant = MuscleGeometry(), PlantParams()
    stress = g.stress_Pa(np.array([0.8, 0.7]))
    n = 25
    k = np.arange(n)
    T = np.stack([45.0 + 20.0 * np.sin(np.pi * k / 20), 60.0 - 15.0 * np.sin(np.pi * k / 20)], axis=1)
    u = np.stack([12.0 * np.cos(np.pi * k / 10), -8.0 + 0.5 * k], axis=1)  # [V], sent after tick k
    q = 0.5 + 0.3 * np.sin(np.pi * k / 20)
    strain = np.stack([bundle_strain(plant, x + 0.02) for x in q])

    def stamp(j: int) -> Header:
        return Header(stamp=Time(sec=1 + j // 100, nanosec=(j % 100) * 10_000_000))

    msgs: list[tuple[str, dict]] = []
    for j in range(n):
        temps = [
            (f'/wrist/muscle_{i}/temperature', {'header': stamp(j), 'temperature': float(T[j, i - 1])}) for i in (1, 2)
        ]
        angle = [
            (
                '/wrist/joint_states',
                {'header': stamp(j), 'name': ['wrist'], 'position': [float(q[j])], 'velocity': [0.0], 'effort': [0.0]},
            )
        ]
        cmds = [(f'/wrist/tem_{i}/command', {'data': float(u[j, i - 1])}) for i in (1, 2)]
        if j == 5:
            cmds.insert(0, ('/wrist/tem_1/command', {'data': float('nan')}))
        targets = [
            (f'/wrist/muscle_{i}/{kind}_desired', {'data': float((strain[j] if kind == 'strain' else stress)[i - 1])})
            for kind in ('strain', 'stress')
            for i in (1, 2)
        ]
        msgs += temps + (angle + cmds if order == 'in_order' else cmds + angle) + targets
    got, rejected = _compensator_answers(
        probe_factory, stress, msgs, [Parameter('temperature_source', value='observer')]
    )
    obs = MuscleTemperatureObserver(OBSERVER_THERMAL, TemperatureObserverParams())
    raw = MuscleCompensator(
        default_sdgpi(),
        shift_gain_per_s=2.0,
        shift_limit_C=15.0,
        window_follows_shift=True,
        stroke_gain_per_s=STROKE_GAIN_PER_S,
    )
    ref = MuscleCompensator(
        default_sdgpi(),
        shift_gain_per_s=2.0,
        shift_limit_C=15.0,
        window_follows_shift=True,
        stroke_gain_per_s=STROKE_GAIN_PER_S,
    )
    expected, thermocouple = [], []
    for j in range(n):
        est = obs.update(T[j : j + 1], u[j - 1 : j] if j else np.zeros((1, 2)), 0.01)[0]
        if j:
            ref.track(est, stress, bundle_strain(plant, q[j]), 0.01)
            raw.track(T[j], stress, bundle_strain(plant, q[j]), 0.01)
        else:
            ref.reset(est, stress)
            raw.reset(T[j], stress)
        expected.append(ref(strain[j], stress, commit=False).temperature_C)
        thermocouple.append(raw(strain[j], stress, commit=False).temperature_C)
    assert got.shape == (n, 2) and rejected == 1
    assert np.max(np.abs(np.array(expected) - thermocouple)) > 0.5  # the estimate is not the thermocouple
    np.testing.assert_allclose(got, expected, atol=1e-9)


def test_compensator_takes_the_tem_commands_only_while_its_observer_runs():
    """With the thermocouple the commands are not needed: no subscription (two deliveries per tick less);
    switching the observer (the default) on and off at run time subscribes and unsubscribes."""
    from rclpy.parameter import Parameter

    from sma_wrist.nodes.hysteresis_compensator import HysteresisCompensator

    def command_subs(node) -> set[str]:
        return {s.topic_name for s in node.subscriptions if '/command' in s.topic_name}

    with Runtime() as rt:
        node = rt.add(HysteresisCompensator)
        default = command_subs(node)
        node.set_parameters([Parameter('temperature_source', value='thermocouple')])
        off = command_subs(node)
        node.set_parameters([Parameter('temperature_source', value='observer')])
        on_again = command_subs(node)
    assert default == on_again == {'/wrist/tem_1/command', '/wrist/tem_2/command'}
    assert off == set()


def test_compensator_observer_runs_the_thermal_file_and_refuses_a_bad_one(tmp_path):
    """thermal_file: the observer runs the identified heat balance tem_controller loads (saturating at
    the driver rating), and a missing file stops the node with its path (only with the observer on)."""
    import dataclasses

    from sma_wrist.core.errors import SmaWristError
    from sma_wrist.core.thermal.heat_balance import ThermalParams
    from sma_wrist.core.thermal.params_file import write_thermal_file
    from sma_wrist.nodes.hysteresis_compensator import OBSERVER_THERMAL, HysteresisCompensator

    weak = dataclasses.replace(ThermalParams(), input_per_volt=0.7 * ThermalParams().input_per_volt)
    f = write_thermal_file(tmp_path / 'tems.yaml', weak, {'note': 'test'}, header='test')
    observer = {'temperature_source': 'observer'}
    with Runtime(params={'/hysteresis_compensator': {**observer, 'thermal_file': str(f)}}) as rt:
        thermal = rt.add(HysteresisCompensator).observer.thermal
    assert thermal.input_per_volt == weak.input_per_volt != OBSERVER_THERMAL.input_per_volt
    assert (thermal.u_min_V, thermal.u_max_V) == (OBSERVER_THERMAL.u_min_V, OBSERVER_THERMAL.u_max_V)
    missing = str(tmp_path / 'missing.yaml')
    with Runtime(params={'/hysteresis_compensator': {**observer, 'thermal_file': missing}}) as rt:
        with pytest.raises(SmaWristError, match='missing.yaml'):
            rt.add(HysteresisCompensator)
    with Runtime(
        params={'/hysteresis_compensator': {'temperature_source': 'thermocouple', 'thermal_file': missing}}
    ) as rt:
        assert rt.add(HysteresisCompensator).observer is None  # the thermocouple needs no heat balance


def test_compensator_observer_parameters_are_validated_with_a_reason():
    from rclpy.parameter import Parameter

    from sma_wrist.nodes.hysteresis_compensator import HysteresisCompensator

    with Runtime() as rt:
        node = rt.add(HysteresisCompensator)
        (name,) = node.set_parameters([Parameter('temperature_source', value='kalman')])
        (negative,) = node.set_parameters([Parameter('observer.correction_s', value=-0.1)])
        ok = node.set_parameters(
            [Parameter('temperature_source', value='observer'), Parameter('observer.tc_lag_s', value=0.1)]
        )
        on = node.observer is not None and node.observer.params.tc_lag_s == 0.1
        (commanded,) = node.set_parameters([Parameter('memory_source', value='commanded')])
    assert not name.successful and 'not one of' in name.reason
    assert not negative.successful and 'correction_s' in negative.reason
    assert all(r.successful for r in ok) and on
    assert not commanded.successful and "needs memory_source 'measured'" in commanded.reason


def test_compensator_hands_its_stroke_gain_to_the_core() -> None:
    """hysteresis_compensator's stroke_gain_per_s (doc/explanation/controllers.md) reaches
    MuscleCompensator; the default (0.5 /s, doc/explanation/controllers.md) is the sweep's STROKE_GAIN_PER_S."""
    from rclpy.parameter import Parameter

    from sma_wrist.nodes.hysteresis_compensator import HysteresisCompensator

    declared = {p.name: p for p in HysteresisCompensator.PARAMS}['stroke_gain_per_s']
    assert declared.default == STROKE_GAIN_PER_S == 0.5 and declared.range == (0.0, 20.0)
    with Runtime() as rt:
        node = rt.add(HysteresisCompensator, parameter_overrides=[Parameter('stroke_gain_per_s', value=1.5)])
        assert node.comp.stroke_gain_per_s == 1.5


def test_compensator_warns_while_a_learnt_shift_sits_on_its_limit(probe_factory):
    """A joint held on its stop (-0.1 rad) with both wires at 55 degC, the measurement the measured
    Flexinol run starts from (doc/explanation/controllers.md): the strain there
    is the chain's, not the wire's, muscle 1's shift runs to its limit in under 4 s, and /diagnostics
    says so once (WARN naming the wire); with the adaptation off nothing is reported."""
    from builtin_interfaces.msg import Time
    from rclpy.parameter import Parameter
    from std_msgs.msg import Header

    from sma_wrist.core.control.joint_controller import bundle_strain
    from sma_wrist.core.hysteresis.muscle import MuscleGeometry
    from sma_wrist.core.plant.wrist import PlantParams
    from sma_wrist.nodes.hysteresis_compensator import HysteresisCompensator

    stress = MuscleGeometry().stress_Pa(np.array([0.8, 0.7]))
    rest = bundle_strain(PlantParams(), 0.5)

    def run(
        gain: float,
        hold: bool = False,
        q: float = -0.1,
        stress=stress,
        n: int = 400,  # type: ignore[no-untyped-def]
        in_range: bool = True,
        temp: float = 55.0,
    ):
        with Runtime() as rt:
            probe = probe_factory(rt, ('/diagnostics',))
            node = rt.add(
                HysteresisCompensator,
                parameter_overrides=[
                    Parameter('temperature_source', value='thermocouple'),
                    Parameter('shift_gain_per_s', value=gain),
                    Parameter('hold_shift_on_stop', value=hold),
                    Parameter('hold_shift_outside_load_range', value=in_range),
                ],
            )
            for i in (1, 2):
                probe.publish(f'/wrist/muscle_{i}/stress', data=float(stress[i - 1]))
            for j in range(n):  # 4 s at 100 Hz
                header = Header(stamp=Time(sec=1 + j // 100, nanosec=(j % 100) * 10_000_000))
                for i in (1, 2):
                    probe.publish(f'/wrist/muscle_{i}/temperature', header=header, temperature=temp)
                probe.publish(
                    '/wrist/joint_states', header=header, name=['wrist'], position=[q], velocity=[0.0], effort=[0.0]
                )
                for kind, v in (('strain', rest), ('stress', stress)):
                    for i in (1, 2):
                        probe.publish(f'/wrist/muscle_{i}/{kind}_desired', data=float(v[i - 1]))
                rt.spin_for(0.0005, until='steady')
            shift = node.comp.shift_C.copy()
        return [s for m in probe.got['/diagnostics'] for s in m.status if s.name.endswith(': adaptation')], shift

    warned, shift = run(2.0)
    assert shift[0] == 15.0 and abs(shift[1]) < 15.0
    assert len(warned) == 1 and warned[0].level == b'\x01'  # WARN, once
    assert 'of muscle 1 at the +-15 degC limit' in warned[0].message and 'muscle 2' not in warned[0].message
    assert run(0.0)[0] == []
    # hold_shift_on_stop (doc/explanation/controllers.md): both taut and the joint off its stops, the shift still learns;
    # on the stop (-0.35 rad), or standing still with muscle 2 slack, it holds
    assert run(2.0, hold=True, n=100)[1][0] > 3.0
    assert np.all(run(2.0, hold=True, q=-0.35, n=100)[1] == 0.0)
    assert np.all(run(2.0, hold=True, stress=stress * [1.0, 0.0], n=100)[1] == 0.0)
    # hold_shift_outside_load_range (doc/explanation/controllers.md; off by default): the
    # measured Flexinol wrist's start, muscle 1 at 14 MPa and muscle 2 slack, below the model's 0.2-1.5 kgf
    low = MuscleGeometry().stress_Pa(np.array([0.07, 0.0]))
    assert np.all(run(2.0, stress=low, n=100)[1] == 0.0)
    # ungated the shift moves (at 50 degC: at the clipped 0.2 kgf the model's loop is flat from ~55 degC on, and
    # a flat loop moves no shift, doc/explanation/controllers.md)
    assert np.all(run(2.0, stress=low, n=100, temp=50.0)[1] == 0.0)
    assert np.abs(run(2.0, stress=low, n=100, in_range=False, temp=50.0)[1]).max() > 1.0


def test_a_runtime_parameter_change_keeps_what_the_tems_online_estimate_has_learnt():
    """tem_controller and hysteresis_compensator rebuild their loop / observer on a runtime parameter change; the
    online TEM estimate (thermal_adaptation) and the heat balance they run on stay: learning restarts nowhere."""
    from rclpy.parameter import Parameter

    from sma_wrist.core.thermal.online import scaled_constants
    from sma_wrist.nodes.hysteresis_compensator import HysteresisCompensator
    from sma_wrist.nodes.tem_controller import TemController

    theta = np.array([0.8, 1.2, 2.0])
    with Runtime() as rt:
        tem = rt.add(TemController)
        est = tem.loop.estimator
        tem.loop.use_estimate(theta)
        coef = tem.loop._coef.copy()
        assert tem.set_parameters([Parameter('gain_per_s', value=2.0)])[0].successful
        assert tem.loop.estimator is est and np.array_equal(tem.loop.theta_used, theta)
        np.testing.assert_array_equal(tem.loop._coef, coef)
        comp = rt.add(HysteresisCompensator)
        est = comp.estimator
        rows = scaled_constants(comp.observer.thermal, theta[None])
        comp.observer.coef_rows = rows
        assert comp.set_parameters([Parameter('shift_gain_per_s', value=1.0)])[0].successful
        assert comp.estimator is est
        np.testing.assert_array_equal(comp.observer.coef_rows, rows)
    assert est is not None and not np.array_equal(
        coef, scaled_constants(tem.loop.base_thermal, np.array([[1.0, 1.0, 0.0]]))[0]
    )


def test_tem_controller_reports_its_chatter_guard_on_diagnostics(probe_factory):
    """Targets that swing between 20 and 60 degC every 0.2 s reverse the TEMs 5 times a second: with the guard at
    1 /s over 2 s the node switches its rate filter and says so (WARN 'chatter'); with the guard off it never does."""
    from rclpy.parameter import Parameter

    from sma_wrist.nodes.tem_controller import TemController

    for limit in (1.0, 0.0):
        with Runtime() as rt:
            probe = probe_factory(rt, ('/wrist/tem_1/command',))
            node = rt.add(TemController)
            assert all(
                r.successful
                for r in node.set_parameters(
                    [
                        Parameter('chatter_guard.limit_per_s', value=limit),
                        Parameter('chatter_guard.window_s', value=2.0),
                    ]
                )
            )
            for i in (1, 2):
                probe.every(0.01, f'/wrist/muscle_{i}/temperature', temperature=40.0)
            for k in range(400):
                for i in (1, 2):
                    probe.publish(f'/wrist/muscle_{i}/temperature_desired', temperature=60.0 if (k // 20) % 2 else 20.0)
                rt.run_until(0.01 * (k + 1), until='steady')
            chatter = [(level, m) for name, level, m in probe.diagnostics() if 'chatter' in name or 'change sign' in m]
            assert node.loop.chattering == (limit > 0)
        if limit > 0:
            assert any(level == 1 and 'rate filter 0.2 s' in m for level, m in chatter), chatter
        else:
            assert chatter == [], chatter


def test_plant_sim_reports_a_wire_held_at_the_wire_models_load_bound(probe_factory, monkeypatch):
    """The SD-GPI load solve searches up to MuscleGeometry.max_load_kgf (3 kgf, ~600 MPa) and holds a wire there
    (the plant's 'overload' flag); from then on the motion is the bound's, not the wire's. plant_sim says so (ERROR
    'wire_load'). With the bound at 0.8 kgf, both muscles heated at +24 V (co-contraction) pull past it within
    20 s; with the real bound the same drive stays inside it (~1 kgf) and the node raises nothing."""
    from sma_wrist.core.hysteresis.muscle import MuscleGeometry
    from sma_wrist.core.plant.wrist import PlantParams
    from sma_wrist.nodes import plant_sim

    real = PlantParams.from_files.__func__  # plant_sim builds its plant with it
    for bound in (0.8, MuscleGeometry().max_load_kgf):
        monkeypatch.setattr(
            PlantParams,
            'from_files',
            classmethod(
                lambda cls, *a, bound=bound, **kw: real(cls, *a, muscle=MuscleGeometry(max_load_kgf=bound), **kw)
            ),
        )
        with Runtime() as rt:
            probe = probe_factory(rt, (), sim_time=True)
            node = rt.add(plant_sim.PlantSim)
            for k in range(2000):
                probe.publish('/wrist/tem_1/command', data=24.0)
                probe.publish('/wrist/tem_2/command', data=24.0)
                rt.run_until(0.01 * (k + 1), until='steady')
            load = [(level, m) for name, level, m in probe.diagnostics() if 'wire_load' in name]
        peak_kgf = float(node.plant.state.load_kgf.max())
        if bound < 1.0:
            assert any(level == 2 and '0.8 kgf' in m for level, m in load), load
        else:
            assert 0.8 < peak_kgf < 1.5 and load == [], (peak_kgf, load)


@pytest.mark.parametrize(
    'executable, waits_for',
    [
        ('trajectory_generator', '/clock'),
        ('adaptive_controller', 'the reference (/wrist/reference) and the joint state'),
        ('hysteresis_compensator', 'the desired strains and stresses (/wrist/muscle_{1,2}/strain_desired'),
        ('tem_controller', 'desired muscle temperatures (/wrist/muscle_{1,2}/temperature, temperature_desired)'),
    ],
)
def test_a_controller_node_says_at_start_what_it_waits_for(executable, waits_for):
    """Started with `ros2 run`, the four controller nodes printed nothing until their inputs came: one INFO line at
    start now names the node's key settings and what it waits for."""
    from sma_wrist.closed_loop import ros_args
    from sma_wrist.runtime.launch_file import node_class
    from sma_wrist.runtime.rclpy import logging as rlog

    records: list[tuple[object, str]] = []
    remove = rlog.add_sink(lambda sev, name, msg, t: records.append((sev, msg)) if name == executable else None)
    try:
        with rlog.silenced(), Runtime(ros_args(), params={'/**': {'use_sim_time': True}}) as rt:
            rt.add(node_class(executable))
    finally:
        remove()
    assert len(records) == 1, records
    severity, line = records[0]
    assert severity == rlog.LoggingSeverity.INFO and line.startswith(f'{executable}: ')
    assert 'waiting for /clock (use_sim_time)' in line and waits_for in line, line


def _controller_watchdog(probe_factory, reference_from_s: float | None, reference_until_s: float, seconds: float):
    """adaptive_controller fed joint states every 10 ms from t = 0.045 s, and the reference every 10 ms from
    ``reference_from_s`` (None: never) until ``reference_until_s``: its watchdog statuses as (time [s], level,
    message), time of the node's clock."""
    from sma_wrist.nodes.adaptive_controller import AdaptiveController

    js = {'position': [0.1], 'velocity': [0.0]}
    ref = {'position': [0.1], 'velocity': [0.0], 'effort': [0.0]}
    seen: list[tuple[float, int, str]] = []
    with Runtime() as rt:
        probe = probe_factory(rt)
        node = rt.add(AdaptiveController)
        diagnose = node.diagnose

        def spy(key, level, message, *a, **kw):
            if key == 'watchdog':
                seen.append((node.now_ns() * 1e-9, level[0], message))
            diagnose(key, level, message, *a, **kw)

        node.diagnose = spy
        rt.run_until(0.045, until='steady')
        probe.publish('/wrist/joint_states', **js)  # the first joint state, 5 ms before the watchdog's first tick
        joint = probe.every(0.01, '/wrist/joint_states', **js)
        reference = None
        if reference_from_s is not None:
            rt.run_until(reference_from_s, until='steady')
            reference = probe.every(0.01, '/wrist/reference', **ref)
        rt.run_until(reference_until_s, until='steady')
        if reference is not None:
            reference.cancel()
        rt.run_until(seconds, until='steady')
        joint.cancel()
    return seen


def test_adaptive_controller_watchdog_is_quiet_while_the_first_reference_follows_the_first_joint_state(
    probe_factory,
):
    """trajectory_generator's soft start publishes its first reference only once it has a measured angle: at every
    start the controller has a joint state before it has a reference. The watchdog took the reference it had not
    received yet for a stale one and logged "no fresh reference: output stopped" at the start of every hardware
    run (0.11-0.14 s, cleared 0.04 s later). A reference that follows within stale_timeout_s is none of that; one
    that stops mid-run still is."""
    seen = _controller_watchdog(probe_factory, 0.07, 1.0, 1.5)
    assert not [s for s in seen if s[0] < 1.0 and s[1] != 0], seen  # the start included
    errors = [s for s in seen if s[1] == 2]
    assert errors, seen  # the reference stopped at 1.0 s: reported ...
    t, _, message = errors[0]
    assert message == 'no fresh reference: output stopped'
    assert 1.25 < t <= 1.25 + 0.05 + 1e-6, seen  # ... one stale_timeout_s later, at the watchdog's next tick


def test_adaptive_controller_watchdog_reports_a_reference_that_never_comes(probe_factory):
    seen = _controller_watchdog(probe_factory, None, 0.0, 0.5)
    errors = [s for s in seen if s[1] == 2]
    assert errors and errors[0][2] == 'no fresh reference: output stopped', seen
    assert 0.045 + 0.25 < errors[0][0] <= 0.045 + 0.25 + 0.05 + 1e-6, seen  # stale_timeout_s after the joint state
