"""hardware_bridge's wiring parameters (calibration.tem_sign, tem_channel_map, thermocouple_map) and the reversed
potentiometer's calibration, on an emulated device wired wrong: with the parameters the topics carry muscle i's
temperature and the TEM command i heats muscle i, as on a device wired as doc/explanation/protocol.md says."""

from __future__ import annotations

import numpy as np
import pytest

from sma_wrist.hw.calibration import Calibration
from sma_wrist.hw.emulator import DeviceEmulator, EmulatorConfig

TOPICS = ('/wrist/joint_states', '/wrist/muscle_1/temperature', '/wrist/muscle_2/temperature', '/clock')


@pytest.fixture
def wired(tmp_path, ros_shutdown, probe_factory):
    """(emulator, bridge, probe): a device wired per ``cfg``, the bridge with ``params``, TEM 1 commanded 8 V."""
    from sma_wrist.runtime.launch import Runtime

    made = []

    def make(cfg: dict, params: dict):
        from sma_wrist.nodes.hardware_bridge import HardwareBridge

        emu = DeviceEmulator(EmulatorConfig(noise_counts=1.0, time_scale=2.0, **cfg), link=str(tmp_path / 'wrist'))
        emu.start()
        rt = Runtime(params={'/hardware_bridge': {'port': emu.link, **params}})
        made.append((emu, rt))
        bridge = rt.add(HardwareBridge)
        probe = probe_factory(rt, TOPICS, sim_time=True)
        probe.every(0.01, '/wrist/tem_1/command', data=8.0)
        probe.every(0.01, '/wrist/tem_2/command', data=0.0)
        rt.run_until(3.0, until='sim')
        return emu, bridge, probe

    yield make
    for emu, rt in made:
        rt.close()
        emu.stop()


ALL_SWAPPED = {
    'tem_polarity_swapped': (False, True),
    'tem_channels_swapped': True,
    'thermocouples_swapped': True,
    'angle_reversed': True,
}
CORRECTED = {
    'calibration.tem_sign': [
        1,
        -1,
    ],  # muscle 1's TEM on output 2; muscle 2's on output 1, reversed 'calibration.tem_channel_map': [2, 1],
    'calibration.thermocouple_map': [2, 1],
    'calibration.angle_gain_rad_per_count': Calibration().reversed_angle().angle_gain_rad_per_count,
    'calibration.angle_offset_rad': Calibration().reversed_angle().angle_offset_rad,
}


@pytest.mark.parametrize('case', ['documented wiring', 'every fault, corrected'])
def test_the_wiring_parameters_undo_a_wrongly_wired_device(wired, case):
    emu, bridge, probe = wired(*(({}, {}) if case == 'documented wiring' else (ALL_SWAPPED, CORRECTED)))
    T_true = emu.plant.muscle_temperature_C[0]
    assert T_true[0] > T_true[1] + 1.0  # TEM 1's command heated muscle 1 (whatever output it left on)
    T1 = probe.got['/wrist/muscle_1/temperature'][-1].temperature
    T2 = probe.got['/wrist/muscle_2/temperature'][-1].temperature
    assert abs(T1 - T_true[0]) < 0.3 and abs(T2 - T_true[1]) < 0.3
    assert abs(probe.got['/wrist/joint_states'][-1].position[0] - float(emu.plant.state.q[0])) < 2e-3
    assert emu.stats.max_abs_command_V == pytest.approx(8.0)


def test_without_the_parameters_the_wrongly_wired_device_is_cooled_and_misread(wired):
    emu, bridge, probe = wired(ALL_SWAPPED, {})
    T_true = emu.plant.muscle_temperature_C[0]
    assert T_true[1] < T_true[0] - 1.0  # the command meant for muscle 1 cooled muscle 2 (output 1 -> TEM 2, reversed)
    assert abs(probe.got['/wrist/muscle_1/temperature'][-1].temperature - T_true[1]) < 0.3  # reads muscle 2's


def test_a_wiring_parameter_that_is_no_wiring_is_refused(ros_shutdown, tmp_path):
    from sma_wrist.core.errors import SmaWristError
    from sma_wrist.nodes.hardware_bridge import HardwareBridge
    from sma_wrist.runtime.launch import Runtime

    for bad, named in (
        ({'calibration.tem_sign': [1, 0]}, 'tem_sign'),
        ({'calibration.tem_channel_map': [1, 1]}, 'tem_channel_map'),
        ({'calibration.thermocouple_map': [1, 2, 3]}, 'thermocouple_map'),
    ):
        rt = Runtime(params={'/hardware_bridge': {'port': str(tmp_path / 'none'), **bad}})
        try:
            with pytest.raises(SmaWristError, match=named):
                rt.add(HardwareBridge)
        finally:
            rt.close()


def test_a_wiring_parameter_changes_at_run_time(wired):
    from rclpy.parameter import Parameter

    emu, bridge, probe = wired({'thermocouples_swapped': True}, {})
    assert bridge.set_parameters([Parameter('calibration.thermocouple_map', value=[2, 1])])[0].successful
    assert not bridge.set_parameters([Parameter('calibration.thermocouple_map', value=[2, 2])])[0].successful
    assert bridge.wiring.thermocouple_map == (2, 1)
    adc = (100, 200, 300, 400, 500)
    assert bridge.wiring.muscle_counts(adc) == (200, 100, 300, 400, 500)
    assert np.allclose(
        bridge.cal.to_physical(bridge.wiring.muscle_counts(adc))[0][:2], bridge.cal.to_physical(adc)[0][1::-1]
    )


def test_a_closed_loop_on_a_polarity_swapped_device_tracks_with_tem_sign(tmp_path, ros_shutdown):
    """`sma-wrist run --hardware` on a device whose TEM 1 leads are swapped, with calibration.tem_sign [-1, 1]: the
    loop tracks as on a device wired right. Over 25-40 s of a 40 s direct_adaptive run (measured 2026-11-29, loaded
    machine): wired right 14.6 / 4.6 % max / RMS of the reference range; swapped without the parameter 71.8 / 42.5 %.
    """
    import subprocess
    import sys

    from sma_wrist.closed_loop import run_closed_loop
    from sma_wrist.runs import load_run

    link = str(tmp_path / 'wrist')
    proc = subprocess.Popen(
        [
            sys.executable,
            '-m',
            'sma_wrist.cli',
            'emulate-device',
            '--port',
            link,
            '--time-scale',
            '1.5',
            '--swap-tem-polarity',
            '1',
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        proc.stdout.readline()
        run_closed_loop(
            'direct_adaptive',
            0.3,
            40.0,
            tmp_path / 'hw',
            hardware=True,
            extra_params={'/hardware_bridge': {'port': link, 'calibration.tem_sign': [-1, 1]}},
        )
    finally:
        proc.terminate()
        out = proc.communicate(timeout=10)[0]
    run = load_run(tmp_path / 'hw')
    sel = (run.t >= 25.0) & (run.t <= 40.0)
    e = np.abs(run.q[sel] - run.q_d[sel]) / 1.048 * 100.0  # % of the Sec. 6.1 reference range
    assert sel.sum() > 1000 and e.max() < 30.0 and np.sqrt(np.mean(e**2)) < 10.0, (e.max(), np.sqrt(np.mean(e**2)))
    assert 'largest |drive| 24 V' in out  # the device did get the loop's commands
