"""plant_sim on the embedded runtime: drive in, measurements and /clock out, bad input handled."""

from __future__ import annotations

import math

import pytest

from sma_wrist.runtime.launch import Runtime


def _measure(
    probe_factory, command_1: float | None, seconds: float = 3.0, params: dict | None = None, bad: bool = False
):
    from sma_wrist.nodes.plant_sim import PlantSim

    with Runtime(params={'/plant_sim': params or {}}) as rt:
        probe = probe_factory(
            rt,
            (
                '/wrist/muscle_1/temperature',
                '/wrist/muscle_2/temperature',
                '/wrist/joint_states',
                '/clock',
                '/wrist/payload',
                '/wrist/muscle_1/stress',
                '/wrist/tem_1/face_temperature',
                '/wrist/tem_2/face_temperature',
            ),
        )
        node = rt.add(PlantSim)
        if command_1 is not None:
            probe.every(0.01, '/wrist/tem_1/command', data=command_1)
            probe.every(0.01, '/wrist/tem_2/command', data=0.0)
        if bad:
            probe.every(0.01, '/wrist/tem_1/command', data=math.nan)
        rt.run_until(seconds, until='steady')
        return probe, node


def test_heating_command_warms_muscle_1_and_moves_the_joint_up(probe_factory):
    idle, _ = _measure(probe_factory, 0.0)
    hot, node = _measure(probe_factory, 10.0)
    T_idle = idle.got['/wrist/muscle_1/temperature'][-1].temperature
    T_hot = hot.got['/wrist/muscle_1/temperature'][-1].temperature
    assert T_hot > T_idle + 3.0
    # muscle 2 untouched
    assert (
        abs(
            hot.got['/wrist/muscle_2/temperature'][-1].temperature
            - idle.got['/wrist/muscle_2/temperature'][-1].temperature
        )
        < 0.5
    )
    assert hot.got['/wrist/joint_states'][-1].position[0] >= idle.got['/wrist/joint_states'][-1].position[0]
    # the exchanger faces (Eq. 4.14) as a face thermocouple reads them: heating muscle 1 pumps heat out of TEM 1's
    faces = [hot.got[f'/wrist/tem_{i}/face_temperature'][-1] for i in (1, 2)]
    assert [f.temperature for f in faces] == node.plant.state.thermal[0, :, 1].tolist()
    assert (
        faces[0].header.frame_id == 'tem_1' and faces[0].header.stamp == hot.got['/wrist/joint_states'][-1].header.stamp
    )
    assert faces[0].temperature < idle.got['/wrist/tem_1/face_temperature'][-1].temperature - 1.0


def test_clock_and_stamps_follow_simulated_time_at_the_publish_rate(probe_factory):
    probe, node = _measure(probe_factory, 0.0, seconds=1.0, params={'publish_rate_hz': 50.0})
    clocks = [c.clock.sec + 1e-9 * c.clock.nanosec for c in probe.got['/clock']]
    assert clocks[0] == 0.0 and clocks[-1] == pytest.approx(1.0)
    assert len(clocks) == 51
    js = probe.got['/wrist/joint_states'][-1]
    assert js.header.stamp.sec + 1e-9 * js.header.stamp.nanosec == pytest.approx(1.0)
    assert js.name == ['wrist']
    assert probe.got['/wrist/payload'][-1].data == 0.3
    assert probe.got['/wrist/muscle_1/stress'][-1].data > 1e6  # Pa, pre-loaded wire


def test_nan_commands_are_rejected_and_reported_not_applied(probe_factory):
    probe, node = _measure(probe_factory, None, seconds=0.5, bad=True)
    assert node.rejected_inputs > 0
    assert (node.command_V == 0.0).all()
    assert any('rejected message' in m for _, _, m in probe.diagnostics())
    assert all(math.isfinite(t.temperature) for t in probe.got['/wrist/muscle_1/temperature'])


def test_stale_command_switches_the_tem_off(probe_factory):
    from sma_wrist.nodes.plant_sim import PlantSim

    with Runtime() as rt:
        probe = probe_factory(rt, ('/wrist/muscle_1/temperature',))
        rt.add(PlantSim)
        probe.publish('/wrist/tem_1/command', data=12.0)  # once, then silence
        rt.run_until(3.0, until='steady')
        diags = probe.diagnostics()
    assert any('no fresh command on tem_1' in m for _, _, m in diags)
    T = [m.temperature for m in probe.got['/wrist/muscle_1/temperature']]
    assert max(T) < T[0] + 3.0  # 12 V for 0.5 s at most, then off: no run-away heating
    assert T[-1] < max(T)


def test_out_of_range_payload_update_is_rejected_with_a_reason_and_valid_one_applies(probe_factory):
    from rclpy.parameter import Parameter

    from sma_wrist.nodes.plant_sim import PlantSim

    with Runtime() as rt:
        probe = probe_factory(rt, ('/wrist/payload',))
        node = rt.add(PlantSim)
        (bad,) = node.set_parameters([Parameter('payload_kg', value=5.0)])
        (wrong_type,) = node.set_parameters([Parameter('payload_kg', value='heavy')])
        (fixed,) = node.set_parameters([Parameter('dt_s', value=0.002)])
        (good,) = node.set_parameters([Parameter('payload_kg', value=0.5)])
        rt.run_until(0.1, until='steady')
    assert not bad.successful and 'out of range' in bad.reason
    assert not wrong_type.successful
    assert not fixed.successful and 'restart' in fixed.reason
    assert good.successful
    assert node.plant.state.payload_kg[0] == 0.5
    assert [m.data for m in probe.got['/wrist/payload']][-1] == 0.5


@pytest.mark.parametrize(
    'argv, message',
    [
        (['-p', 'payload_kg:=1'], 'invalid parameter'),  # an integer for a double (write 1.0)
        (['-p', 'payload_kg:=5.0'], 'invalid parameter'),  # outside the descriptor's range
        (['-p', 'use_sim_time:=true'], 'publishes /clock itself'),  # it would wait for its own clock
    ],
)
def test_bad_startup_parameters_exit_2_with_the_reason_not_a_traceback(capsys, argv, message):
    from sma_wrist.nodes.common import main_for
    from sma_wrist.nodes.plant_sim import PlantSim

    assert main_for(PlantSim, ['plant_sim', '--ros-args', *argv]) == 2
    out = capsys.readouterr().out
    assert out.startswith('error: ') and message in out and 'Traceback' not in out


@pytest.mark.parametrize(
    'value, message',
    [
        ('.nan', 'invalid parameter dt_s'),  # outside the descriptor's range
        ('"fast"', "Trying to set parameter 'dt_s' to 'fast'"),  # a string for a double
    ],
)
def test_sma_wrist_run_refuses_a_bad_params_file_value_with_the_reason_not_a_traceback(
    tmp_path, capsys, value, message
):
    """sma-wrist run builds the nodes in-process: rclpy's refusal must reach the user as ros2 run's one line."""
    from sma_wrist.cli import main

    f = tmp_path / 'bad.yaml'
    f.write_text(f'plant_sim:\n  ros__parameters:\n    dt_s: {value}\n')
    assert main(['run', '--duration', '1', '--quiet', '--params-file', str(f)]) == 2
    err = capsys.readouterr().err
    assert err.startswith('error: PlantSim: ') and message in err and err.count('\n') == 1, err


@pytest.mark.parametrize(
    'body, message',
    [
        ('plant_sim:\n  ros__parameters:\n    dt_s: .nan\n', 'error: PlantSim: invalid parameter dt_s'),
        (
            'plant_sim:\n  ros__parameters:\n    payload_kgs: 0.5\n',
            'error: not a parameter of the node graph (misspelt?): payload_kgs under plant_sim',
        ),
        (
            '/**:\n  ros__parameters:\n    gain: 2.0\n',
            'error: not a parameter of the node graph (misspelt?): gain under /**',
        ),
    ],
)
def test_sma_wrist_run_refuses_a_params_file_before_it_records(tmp_path, capsys, body, message):
    """A value a node refused was met only after the bag had been opened: the bag was left behind and the rerun
    failed with "already exists". A misspelt name (ROS ignores it) ran the defaults in silence, as the sweep refuses
    it. Both are now refused before anything is recorded; a name of a node that is not in this graph (the hardware
    bridge's, in a simulated run) is not this run's business."""
    from sma_wrist.cli import main

    f = tmp_path / 'params.yaml'
    f.write_text(body)
    bag = tmp_path / 'bag'
    assert main(['run', '--duration', '1', '--quiet', '--params-file', str(f), '--bag', str(bag)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(message) and err.count('\n') == 1, err
    assert not bag.exists()
    f.write_text(
        'hardware_bridge:\n  ros__parameters:\n    no_such_name: 1\nplant_sim:\n  ros__parameters:\n'
        '    payload_kg: 0.2\n'
    )
    assert main(['run', '--duration', '0.5', '--quiet', '--params-file', str(f), '--bag', str(bag)]) == 0
    assert bag.is_dir()


def test_clock_owner_refuses_use_sim_time_at_run_time(probe_factory):
    from rclpy.parameter import Parameter

    from sma_wrist.nodes.plant_sim import PlantSim

    with Runtime() as rt:
        node = rt.add(PlantSim)
        (res,) = node.set_parameters([Parameter('use_sim_time', value=True)])
    assert not res.successful and 'publishes /clock itself' in res.reason


def test_real_time_monitor_reports_the_achieved_factor_per_window():
    from sma_wrist.nodes.plant_sim import RealTimeMonitor

    m = RealTimeMonitor(window_s=5.0)
    assert m.update(0.0, 100.0) is None  # starts a window
    assert m.update(2.0, 104.0) is None  # window not over
    assert m.update(2.5, 105.0) == pytest.approx(0.5)
    assert m.update(7.5, 110.0) == pytest.approx(1.0)
    assert m.update(8.0, 50.0) is None  # clock jumped back: restart, no bogus factor


@pytest.mark.parametrize('slow', [False, True])
def test_plant_that_cannot_keep_real_time_warns_on_diagnostics(probe_factory, slow):
    """A machine too slow for real_time_factor: each tick here costs 20 ms of the (virtual) steady
    clock, later 25 ms; the timer skips missed periods as rcl's does, so the plant runs at 0.5x,
    then 0.33x. plant_sim says so on /diagnostics, once, with the factor it first saw."""
    from sma_wrist.nodes.plant_sim import PlantSim
    from sma_wrist.runtime.vclock import VCLOCK

    class SlowPlant(PlantSim):
        def _tick(self):
            super()._tick()
            if slow:  # the tick took 20 ms of wall time, later 25 ms (timer every 30 ms: 0.33x)
                VCLOCK.advance_to(VCLOCK.steady_ns + (20_000_000 if VCLOCK.steady_ns < 6e9 else 25_000_000))

    with Runtime() as rt:
        probe = probe_factory(rt, ('/clock',))
        rt.add(SlowPlant)
        rt.run_until(20.0, until='steady')
        warned = [m for _, _, m in probe.diagnostics() if 'real_time_factor' in m]
    if slow:
        # one message for a persistent condition (diagnose publishes on change), with the factor seen
        assert len(warned) == 1 and 'simulating at 0.50x' in warned[0]
    else:
        assert not warned


def test_a_phase_fraction_wire_file_is_the_simulated_wire_and_a_malformed_one_is_refused(
    probe_factory, tmp_path, capsys
):
    """plant_sim's wire_file (a commissioned wire.yaml): the plant steps that wire (its fraction falls as muscle 1
    heats); a malformed file stops the node with its name and the reason, not a traceback."""
    from sma_wrist.core.hysteresis.phase_fraction import XI, PhaseFractionWire
    from sma_wrist.core.hysteresis.wire_file import save_wire_file
    from sma_wrist.nodes.common import main_for
    from sma_wrist.nodes.plant_sim import PlantSim

    # a wire martensitic at the rest temperature (below M_f) that starts to transform just above it (A_s), so that 3 s
    # of heating transform it
    wire = save_wire_file(tmp_path / 'wire.yaml', PhaseFractionWire(A_s_C=28.0, A_f_C=45.0, M_s_C=40.0, M_f_C=30.0))
    hot, node = _measure(probe_factory, 20.0, params={'wire_file': str(wire)})
    assert node.plant.params.wire is not None
    log = capsys.readouterr()
    assert f'wire phase-fraction ({wire}), heat balance Table 4.9' in log.out + log.err  # the start-up line says so
    xi = node.plant.state.w[:, XI]
    assert xi[0] < xi[1] - 0.01 and xi[1] > 0.99  # muscle 1 heated transforms, muscle 2 does not
    bad = tmp_path / 'bad.yaml'
    bad.write_text(wire.read_text().replace('eps_L:', 'strain_L:'))
    assert main_for(PlantSim, ['plant_sim', '--ros-args', '-p', f'wire_file:={bad}']) == 2
    out = capsys.readouterr().out
    assert out.startswith('error: ') and 'bad.yaml' in out and 'strain_L' in out and 'Traceback' not in out
