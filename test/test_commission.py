"""sma-wrist commission's bring-up on emulated devices that are not the model and are wired wrong
(sma_wrist/commission, sma_wrist/hw/emulator.py's wiring faults).

Most cases run the emulated device in lockstep (SimDevice: the device's own lines and parser, no pty), so the
matrix of faults x channels x plants costs seconds, not minutes; the serial path (the bridge's link on a pty) is
tested on its own below, and so is the command line at the device's 1 kHz. The lockstep cases sample at 250 Hz: the
decisions are taken on device time, not sample counts, and it quarters their cost. The drive limit is asserted from the device's side: the largest |command| the emulator
received."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest

from sma_wrist.commission.bringup import BringUpLimits
from sma_wrist.commission.device import SerialDevice, SimDevice
from sma_wrist.commission.run import EXIT_FAULT, EXIT_OK, commission, exit_code
from sma_wrist.hw.emulator import DeviceEmulator, EmulatorConfig

LIM = BringUpLimits()
WIRING_FAULTS = {  # emulator option -> (kind, channel) commissioning must name
    'tem_polarity_1': ({'tem_polarity_swapped': (True, False)}, [('tem_polarity', 1)]),
    'tem_polarity_2': ({'tem_polarity_swapped': (False, True)}, [('tem_polarity', 2)]),
    'tem_polarity_both': ({'tem_polarity_swapped': (True, True)}, [('tem_polarity', 1), ('tem_polarity', 2)]),
    'tem_channels': ({'tem_channels_swapped': True}, [('tem_channels_swapped', None)]),
    'thermocouples': ({'thermocouples_swapped': True}, [('thermocouples_swapped', None)]),
}


RATE_HZ = 250.0


def run(tmp_path, accept_fixes=False, name='c', **cfg):
    dev = SimDevice(EmulatorConfig(**{'rate_hz': RATE_HZ, **cfg}))
    res = commission(tmp_path / name, dev, accept_fixes=accept_fixes, bring_up_only=True)
    return res, dev.emulator


def named(res):
    return [(f['kind'], f['channel']) for f in res['faults']]


def assert_stopped_safely(res, emu, limit_V):
    """TEMs off at the end, never driven beyond ``limit_V`` (the device's record), the report written."""
    assert emu.stats.max_abs_command_V <= limit_V + 1e-9
    assert np.all(emu._u == 0.0)
    assert res['report'] and open(res['report']).read().startswith('# Wrist commissioning report')


@pytest.mark.parametrize('plant', ['model', 'phase_fraction'])
@pytest.mark.parametrize('fault', list(WIRING_FAULTS))
def test_each_wiring_fault_is_named_before_any_strong_drive(tmp_path, plant, fault):
    cfg, expected = WIRING_FAULTS[fault]
    res, emu = run(tmp_path, plant=plant, **cfg)
    assert res['status'] == 'fault' and exit_code(res) == EXIT_FAULT
    assert sorted(named(res), key=str) == sorted(expected, key=str)
    assert res['params_file'] is None and all(f['fix'] and not f['fixed'] for f in res['faults'])
    assert all(f['params'] for f in res['faults'])  # each names the bridge parameter that corrects it
    # found by the 6 V pulses: nothing stronger reached the wrongly wired TEMs
    assert_stopped_safely(res, emu, LIM.pulse_V)
    assert 'angle' not in res['steps'] and res['device_time_s'] < 20.0


@pytest.mark.parametrize('plant', ['model', 'phase_fraction'])
def test_a_reversed_potentiometer_is_named_with_its_calibration(tmp_path, plant):
    res, emu = run(tmp_path, plant=plant, angle_reversed=True)
    assert named(res) == [('angle_reversed', None)] and exit_code(res) == EXIT_FAULT
    f = res['faults'][0]
    assert f['params'] == {
        'calibration.angle_gain_rad_per_count': -1e-4,
        'calibration.angle_offset_rad': pytest.approx(-3.2768 + 6.5535),
    }
    assert_stopped_safely(res, emu, LIM.max_drive_V)


@pytest.mark.parametrize('plant,wire', [('model', 1), ('model', 2), ('phase_fraction', 1)])
def test_a_muscle_that_does_not_move_when_heated_is_named(tmp_path, plant, wire):
    res, emu = run(tmp_path, plant=plant, broken_wire=wire)
    assert named(res) == [('muscle_not_moving', wire)] and exit_code(res) == EXIT_FAULT
    assert res['steps']['angle'][f'muscle_{wire}']['peak_C'] <= LIM.max_muscle_C + 0.5  # kept below the limit
    assert_stopped_safely(res, emu, LIM.max_drive_V)


HEALTHY = {
    'model seed 1 at 1 kHz': {'seed': 1, 'rate_hz': 1000.0},
    'noisy sensors': {'seed': 2, 'noise_counts': 25.0},  # 0.1 degC, 2.5 mrad per sample
    'phase-fraction wire': {'plant': 'phase_fraction', 'seed': 3},
    'wire transforming 8 degC hotter': {'plant': 'sdgpi', 'scenario': {'transition_shift_C': 8.0}},
    'wire transforming 8 degC colder': {'plant': 'sdgpi', 'scenario': {'transition_shift_C': -8.0}},
    'TEMs 0.8 x as strong': {'plant': 'sdgpi', 'scenario': {'tem_gain_scale': 0.8}, 'noise_counts': 10.0},
}


@pytest.mark.parametrize('case', list(HEALTHY))
def test_a_device_without_a_fault_is_never_reported_as_having_one(tmp_path, case):
    res, emu = run(tmp_path, **HEALTHY[case])
    assert res['faults'] == [] and res['status'] == 'commissioned' and exit_code(res) == EXIT_OK, res['faults']
    assert res['steps']['angle']['angle_sign'] == 1
    assert_stopped_safely(res, emu, LIM.max_drive_V)


def test_accepted_fixes_are_verified_and_written_for_every_fault_at_once(tmp_path):
    """All four wiring faults on one device: corrected in software, verified by the pulses again, written."""
    import yaml

    res, emu = run(
        tmp_path,
        accept_fixes=True,
        tem_polarity_swapped=(False, True),
        tem_channels_swapped=True,
        thermocouples_swapped=True,
        angle_reversed=True,
    )
    assert res['status'] == 'commissioned' and exit_code(res) == EXIT_OK
    assert sorted(named(res), key=str) == sorted(
        [
            ('tem_polarity', 2),
            ('tem_channels_swapped', None),
            ('thermocouples_swapped', None),
            ('angle_reversed', None),
        ],
        key=str,
    )
    assert all(f['fixed'] for f in res['faults'])
    assert res['steps']['tem_pulses']['verified']['muscle_change_C'][0][0] > 0.5  # through the fix: it heats
    params = yaml.safe_load(open(res['params_file']))['hardware_bridge']['ros__parameters']
    # TEM 2's leads are swapped and the channels too: muscle 2's TEM is on output 1, with the sign reversed
    assert params['calibration.tem_channel_map'] == [2, 1] and params['calibration.tem_sign'] == [1, -1]
    assert params['calibration.thermocouple_map'] == [2, 1]
    assert params['calibration.angle_gain_rad_per_count'] == -1e-4
    assert_stopped_safely(res, emu, LIM.max_drive_V)
    # the bridge takes the file as it is (every key declared, every value valid)
    from sma_wrist.commission.run import bridge_values

    assert bridge_values([res['params_file']])['calibration.tem_sign'] == [1, -1]


@pytest.mark.parametrize('stop_at_s,step', [(0.3, 'link'), (2.0, 'sensors'), (6.0, 'tem_pulses'), (20.0, 'angle')])
def test_ctrl_c_at_any_step_turns_the_tems_off_and_keeps_the_report(tmp_path, stop_at_s, step):
    dev = SimDevice(EmulatorConfig(rate_hz=RATE_HZ))
    frames = dev.frames

    def interrupted():
        if dev.emulator.device_time_s > stop_at_s:
            raise KeyboardInterrupt
        return frames()

    dev.frames = interrupted
    res = commission(tmp_path / 'c', dev, bring_up_only=True)
    assert res['status'] == 'interrupted' and exit_code(res) == 130
    assert f'during the {step} step' in res['message']
    report = open(res['report']).read()
    assert 'interrupted' in report and res['params_file'] is None
    done = ['link', 'sensors', 'tem_pulses', 'angle'][: ['link', 'sensors', 'tem_pulses', 'angle'].index(step)]
    assert all(k in res['steps'] for k in done)  # what was learnt so far is kept
    assert_stopped_safely(res, dev.emulator, LIM.max_drive_V)


def test_a_sensor_that_saturates_mid_procedure_stops_it(tmp_path):
    dev = SimDevice(EmulatorConfig(rate_hz=RATE_HZ))
    frames = dev.frames

    def saturating():
        if dev.emulator.device_time_s > 8.0:
            dev.emulator.inject('force', (2, 65535))  # TEM 1 face thermocouple open: the ADC at full scale
        return frames()

    dev.frames = saturating
    res = commission(tmp_path / 'c', dev, bring_up_only=True)
    assert named(res) == [('sensor_saturated', 3)] and 'TEM 1 face' in res['faults'][0]['message']
    assert 'sensors' in res['steps'] and exit_code(res) == EXIT_FAULT
    assert_stopped_safely(res, dev.emulator, LIM.pulse_V)


def test_a_frozen_thermocouple_is_named(tmp_path):
    dev = SimDevice(EmulatorConfig(rate_hz=RATE_HZ))
    dev.emulator.inject('force', (1, 19333))  # muscle 2's converter returns its last reading for ever
    res = commission(tmp_path / 'c', dev, bring_up_only=True)
    assert named(res) == [('sensor_frozen', 2)] and exit_code(res) == EXIT_FAULT
    assert_stopped_safely(res, dev.emulator, LIM.pulse_V)


# ----------------------------------------------------------------------------- the serial path
#: the emulator's thread shares the machine (and the test's interpreter): at load 16 a second without a line
#: happened; a wrist controller on its own microcontroller keeps the 1 s default
STALL_S = 3.0


def tems_off(emu: DeviceEmulator, wall_s: float = 3.0, watchdog: bool = False) -> bool:
    """The device got a 0 V command (or, with ``watchdog``, its watchdog cut the drive) within ``wall_s``: under
    load the emulator's thread may take a while to read the last command."""
    t_end = time.monotonic() + wall_s
    while time.monotonic() < t_end:
        if np.all(emu._u == 0.0) or (watchdog and emu.device_time_s - emu._last_cmd_t > emu.cfg.watchdog_s):
            return True
        time.sleep(0.02)
    return False


@pytest.fixture
def pty_device(tmp_path):
    made = []

    def make(**cfg) -> DeviceEmulator:
        emu = DeviceEmulator(EmulatorConfig(**cfg), link=str(tmp_path / f'wrist{len(made)}'))
        emu.start()
        made.append(emu)
        return emu

    yield make
    for e in made:
        e.stop()


def test_over_a_serial_port_a_polarity_fault_is_named_and_the_tems_left_off(tmp_path, pty_device):
    emu = pty_device(time_scale=2.0, tem_polarity_swapped=(True, False))
    res = commission(tmp_path / 'c', SerialDevice(emu.link, stall_s=STALL_S), port=emu.link, bring_up_only=True)
    assert named(res) == [('tem_polarity', 1)] and exit_code(res) == EXIT_FAULT, res['faults']
    assert res['steps']['link']['rate_hz_measured'] == pytest.approx(1000.0, rel=0.01)
    assert res['steps']['link']['device_s_per_wall_s'] > 1.2  # the device's own pace (x2), measured
    assert emu.stats.max_abs_command_V <= LIM.pulse_V and tems_off(emu)


def test_a_device_that_stops_streaming_mid_procedure_stops_it_with_the_tems_off(tmp_path, pty_device):
    emu = pty_device(time_scale=2.0)
    dev = SerialDevice(emu.link, stall_s=STALL_S)
    frames = dev.frames

    def freezing():
        if emu.device_time_s > 4.0 and not getattr(emu, '_froze', False):
            emu._froze = True
            emu.inject('freeze', 2 * STALL_S)  # wall s without a line
        return frames()

    dev.frames = freezing
    res = commission(tmp_path / 'c', dev, port=emu.link, bring_up_only=True)
    assert named(res) == [('link_lost', None)] and 'stopped streaming' in res['faults'][0]['message']
    assert exit_code(res) == EXIT_FAULT and 'sensors' in res['steps']
    assert tems_off(emu, watchdog=True)  # the zero command sent at the stop, or the device's watchdog


def test_cli_a_port_that_does_not_open_is_bad_input_with_a_report(tmp_path, capsys):
    from sma_wrist.cli import main

    code = main(['commission', '--hardware', str(tmp_path / 'absent'), '--out', str(tmp_path / 'c')])
    err = capsys.readouterr().err
    assert code == 2 and 'does not open' in err and 'Traceback' not in err
    assert 'bad_port' in (tmp_path / 'c' / 'commission.md').read_text()


def test_cli_sim_commissions_and_prints_json(tmp_path, capsys):
    from sma_wrist.cli import main

    code = main(
        ['commission', '--sim', '--out', str(tmp_path / 'c'), '--payload-kg', '0.4', '--json', '--bring-up-only']
    )
    doc = json.loads(capsys.readouterr().out)
    assert code == 0 and doc['status'] == 'commissioned' and doc['faults'] == []
    assert {'faults', 'identified', 'verification', 'params_file', 'device_time_s', 'steps', 'report'} <= set(doc)
    assert doc['identified'] == {} and doc['verification'] is None  # the bring-up only: nothing identified, verified
    assert 0 < doc['device_time_s'] < 120.0 and doc['max_drive_V'] <= LIM.max_drive_V
    assert 'payload_kg: 0.4' in open(doc['params_file']).read()


@pytest.mark.parametrize(
    'args,named_',
    [
        (['--sim', '--hardware', 'x'], 'either --hardware'),
        (['--sim', '--payload-kg', '3'], '--payload-kg'),
        (['--sim', '--heat-V', '30'], 'above the TEM driver rating'),
        (['--sim', '--params-file', 'nope.yaml'], 'no such file'),
    ],
)
def test_cli_bad_input_is_named(tmp_path, capsys, args, named_):
    from sma_wrist.cli import main

    assert main(['commission', '--out', str(tmp_path / 'c'), *args]) == 2
    err = capsys.readouterr().err
    assert named_ in err and 'Traceback' not in err


def test_a_device_on_another_protocol_version_is_named(tmp_path):
    dev = SimDevice(EmulatorConfig(rate_hz=RATE_HZ))
    emit = dev.emulator.emit

    def version_2(n):  # every line as a device of protocol version 2 sends it (valid CRCs)
        from sma_wrist.hw.protocol import encode_unchecked

        lines = emit(n).split(b'\n')[:-1]
        return b''.join(encode_unchecked(ln[1 : ln.rindex(b'*')].decode().replace(',1,', ',2,', 1)) for ln in lines)

    dev.emulator.emit = version_2
    import sma_wrist.commission.bringup as B

    old, B.HELLO_TIMEOUT_S = B.HELLO_TIMEOUT_S, 0.3
    try:
        res = commission(tmp_path / 'c', dev, bring_up_only=True)
    finally:
        B.HELLO_TIMEOUT_S = old
    assert named(res) == [('no_hello', None)] and 'protocol version 2' in res['faults'][0]['message']
    assert exit_code(res) == EXIT_FAULT


def test_ctrl_c_on_the_command_line_over_a_serial_port(tmp_path, pty_device):
    """A real SIGINT to `sma-wrist commission --hardware`: exit 130, TEMs off, the report of the steps so far."""
    import os
    import signal
    import subprocess
    import sys

    emu = pty_device(time_scale=2.0)
    env = {**os.environ, 'PYTHONPATH': os.pathsep.join(sys.path)}
    proc = subprocess.Popen(
        [
            sys.executable,
            '-m',
            'sma_wrist',
            'commission',
            '--hardware',
            emu.link,
            '--out',
            str(tmp_path / 'c'),
            '--stall-s',
            str(STALL_S),
        ],
        stderr=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        env=env,
        # as a terminal's foreground job: a test run started in the background inherits SIGINT ignored, and Python
        # then keeps ignoring it, so the interrupt under test would never arrive
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    try:
        for line in proc.stderr:
            if 'step: tem_pulses' in line:
                break
        time.sleep(1.0)  # inside the pulses
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130 and 'Traceback' not in err, (proc.returncode, out, err)
    assert 'interrupted during the tem_pulses step' in out and 'TEMs off' in err
    report = (tmp_path / 'c' / 'commission.md').read_text()
    assert 'Sensors at rest' in report and 'muscle_1' in report
    assert tems_off(emu) and emu.stats.max_abs_command_V <= LIM.pulse_V
