"""sma-wrist commission's verification (sma_wrist/commission/verify.py): the node graph with hardware_bridge on the
commissioned device, defaults against the params file handed over; its JSON; Ctrl-C and a device that stops
streaming during it; and a weak but healthy wrist the bring-up must not stop.

The device is the emulated one the bring-up stepped in lockstep, then served on a pseudo-terminal (as warm as the
bring-up left it) at 250 Hz and twice wall time; the sine runs are short (a few device seconds): the numbers of a
full verification are `sma-wrist bench --section commission`'s."""

from __future__ import annotations

import dataclasses
import os
import signal
import threading
import time

import numpy as np
import pytest
import yaml

from sma_wrist.commission.device import SimDevice
from sma_wrist.commission.run import EXIT_FAULT, commission, exit_code
from sma_wrist.commission.verify import (
    CALIBRATION_KEYS,
    VerifyOptions,
    controllers_of,
    diagnosis_warning,
    run_verification,
)
from sma_wrist.hw.emulator import EmulatorConfig

RATE_HZ = 250.0
SHORT = VerifyOptions(controllers=('pid',), duration_s=5.0, diagnose=False, sim_time_scale=2.0)


def device(**cfg) -> SimDevice:
    return SimDevice(EmulatorConfig(**{'rate_hz': RATE_HZ, 'seed': 4, **cfg}))


def handed_over(out, payload_kg=0.4) -> dict:
    """What the bring-up hands the verification: a params file with the documented wiring, the report so far."""
    from sma_wrist.commission.run import write_params
    from sma_wrist.hw.calibration import Calibration, Wiring

    out.mkdir()
    cal = Calibration()
    bridge = {
        **Wiring().params(),
        'calibration.angle_gain_rad_per_count': cal.angle_gain_rad_per_count,
        'calibration.angle_offset_rad': cal.angle_offset_rad,
        'payload_kg': payload_kg,
    }
    report = out / 'commission.md'
    report.write_text('# Wrist commissioning report\n\nbring-up findings\n')
    return {
        'status': 'commissioned',
        'message': '',
        'faults': [],
        'bridge_params': bridge,
        'params_file': str(write_params(out / 'wrist_params.yaml', [], bridge)),
        'report': str(report),
        'device_time_s': 60.0,
    }


def test_the_verification_runs_the_defaults_and_the_params_file_side_by_side(tmp_path):
    """commission() after the bring-up (no excitation here: it takes minutes), with a short verification."""
    dev = device()
    (tmp_path / 'c' / 'verification' / 'pid_commissioned').mkdir(parents=True)  # an earlier commissioning's bag
    res = commission(
        tmp_path / 'c', dev, payload_kg=0.4, bring_up_only=True, verification=dataclasses.replace(SHORT, diagnose=True)
    )
    assert res['status'] == 'commissioned' and exit_code(res) == 0, (res['message'], res['faults'])
    v = res['verification']
    for which in ('default', 'commissioned'):
        m = v[which]['pid']
        assert 0 < m['rms_pct'] <= m['max_pct'] < 1000, v
    # the defaults are config/wrist.yaml's payload, the commissioned run the params file's
    assert [(r['parameters'], r['payload_kg']) for r in v['runs']] == [('commissioned', 0.4), ('default', 0.3)]
    bridge = yaml.safe_load(open(v['defaults_file']))['hardware_bridge']['ros__parameters']
    assert set(bridge) == set(CALIBRATION_KEYS)  # the bring-up's calibration, no payload, no port
    # device time: both runs counted, on top of the bring-up's
    assert all(r['device_s'] >= SHORT.duration_s for r in v['runs']) and v['device_time_s'] >= 2 * SHORT.duration_s
    assert res['device_time_s'] > 60.0 + v['device_time_s']  # the bring-up alone takes over 60 s on this wrist
    # each run from the rest temperatures the bring-up measured, the settling counted once
    assert all(r['start']['settled'] for r in v['runs']), v['runs']
    assert v['settle_s'] == pytest.approx(sum(r['start']['seconds'] for r in v['runs']), abs=0.1)
    assert v['settle_s'] < v['device_time_s'] - 2 * SHORT.duration_s
    report = open(res['report']).read()
    assert 'Angle: which way' in report  # the bring-up's sections kept, the verification's added
    assert '## Verification' in report and '| pid |' in report and '](verification/pid.png)' in report
    assert os.path.getsize(v['plots'][0]) > 10_000
    assert np.all(dev.emulator._u == 0.0)  # TEMs off at the end
    # the commissioned run recorded and diagnosed (5 s: too short for a verdict, said so; the bench has full ones)
    d = v['diagnosis']
    assert d['bag'].endswith('pid_commissioned') and ('error' in d or d['discrepancy'] in (True, False)), d
    assert os.path.isfile(os.path.join(d['bag'], 'metadata.yaml'))  # recorded afresh over the earlier folder
    # the defaults' run recorded beside it: device data the wire's refinement fits on
    assert [os.path.basename(r['bag'] or '') for r in v['runs']] == ['pid_commissioned', 'pid_defaults']
    assert os.path.isfile(os.path.join(v['runs'][1]['bag'], 'metadata.yaml'))


def test_on_a_serial_port_the_verification_runs_the_graph_on_that_port(tmp_path):
    """``--hardware PORT``: hardware_bridge on the port the bring-up used (closed by then), wall time as device time."""
    from sma_wrist.commission.bringup import BringUp
    from sma_wrist.commission.device import SerialDevice
    from sma_wrist.hw.calibration import Calibration, Wiring
    from sma_wrist.hw.emulator import DeviceEmulator

    emu = DeviceEmulator(EmulatorConfig(rate_hz=RATE_HZ, time_scale=2.0, seed=5), link=str(tmp_path / 'wrist'))
    emu.start()
    try:
        res = handed_over(tmp_path / 'c')
        dev = SerialDevice(emu.link)
        bring = BringUp(dev, Calibration(), Wiring())  # the rest temperatures each run is settled to
        dev.open()
        bring.step_link()
        bring.step_sensors()
        dev.close()
        t0 = time.monotonic()
        run_verification(res, tmp_path / 'c', dev, SHORT, bring=bring)
        wall = time.monotonic() - t0
        got = emu.stats.commands_received
        t_end = time.monotonic() + 3.0
        while not np.all(emu._u == 0.0) and time.monotonic() < t_end:  # the bridge's last 0 V, read by the device
            time.sleep(0.02)
        assert np.all(emu._u == 0.0)
    finally:
        emu.stop()
    v = res['verification']
    assert res['status'] == 'commissioned' and set(v['commissioned']) == {'pid'} and got > 100
    assert all(r['device_s'] >= SHORT.duration_s for r in v['runs'])
    assert 2 * SHORT.duration_s / 2.0 <= v['device_time_s'] <= wall + 0.1  # a real device: its wall time
    # settled through the port between the runs (the bridge had it meanwhile): the link opened again each time
    assert all(r['start']['settled'] for r in v['runs']) and bring.dev is not dev, v['runs']


def test_ctrl_c_during_the_verification_keeps_the_params_file_and_turns_the_tems_off(tmp_path):
    """A real SIGINT while the graph runs the sine: status interrupted (exit 130), the params file and report kept."""
    dev, res = device(), handed_over(tmp_path / 'c')
    old = signal.signal(signal.SIGINT, signal.default_int_handler)  # a background test run ignores SIGINT
    stop = threading.Event()

    def interrupt_when_running():
        while not stop.wait(0.05):
            if dev.emulator.link is not None and dev.emulator.device_time_s > 2.0:
                os.kill(os.getpid(), signal.SIGINT)
                return

    t = threading.Thread(target=interrupt_when_running, daemon=True)
    t.start()
    try:
        run_verification(res, tmp_path / 'c', dev, SHORT)
    finally:
        stop.set()
        signal.signal(signal.SIGINT, old)
    assert res['status'] == 'interrupted' and exit_code(res) == 130
    assert 'during the verification step' in res['message']
    assert os.path.isfile(res['params_file']) and 'bring-up findings' in open(res['report']).read()
    assert np.all(dev.emulator._u == 0.0)


def test_a_device_that_stops_streaming_during_the_verification_is_a_fault_with_the_tems_off(tmp_path, monkeypatch):
    import sma_wrist.closed_loop as cl

    monkeypatch.setattr(cl, 'DEVICE_STALL_S', 3.0)  # wall s: the run's 10 s, shortened (1 s failed once under load)
    dev, res = device(), handed_over(tmp_path / 'c')
    emu = dev.emulator
    frozen = []
    step_until = emu.step_until

    def freezing(wall_now):
        if emu.link is not None and not frozen and emu.device_time_s > 3.0:
            frozen.append(emu.device_time_s)
            emu._freeze_until = wall_now + 30.0  # no line for 30 s of wall time
        return step_until(wall_now)

    emu.step_until = freezing
    run_verification(res, tmp_path / 'c', dev, SHORT)
    assert frozen and res['status'] == 'fault' and exit_code(res) == EXIT_FAULT
    assert [f['kind'] for f in res['faults']] == ['link_lost'] and 'verification' in res['faults'][0]['message']
    assert os.path.isfile(res['params_file']) and 'Stopped:' in open(res['report']).read()
    assert np.all(emu._u == 0.0)


def test_a_weak_but_healthy_wrist_is_not_stopped_for_want_of_an_angle(tmp_path):
    """TEMs at 0.6x the model's and a wire 10 degC hotter: one muscle turns the joint only after 63 s at 20 V.
    The heating ended at 60 s and the bring-up stopped this healthy wrist with angle_not_determined. Its
    identification then needs a muscle hotter than the excitation makes it: a named stop, not a traceback."""
    dev = SimDevice(
        EmulatorConfig(
            rate_hz=100.0, plant='sdgpi', scenario={'tem_gain_scale': 0.6, 'transition_shift_C': 10.0}, seed=2
        )
    )
    res = commission(tmp_path / 'c', dev)
    assert res['steps']['angle']['angle_sign'] == 1  # the bring-up found the angle and went on
    # the excitation's relay (at most 100 s a half-cycle) heats muscle 1 of so weak a wrist only to ~64 degC, short
    # of its transformation: the identification says so and stops with the TEMs off (it raised from numpy before)
    assert [f['kind'] for f in res['faults']] == ['not_identified'], res['faults']
    assert 'did not move' in res['faults'][0]['message'] and res['status'] == 'fault'
    # the bring-up's 20 V, the excitation's sines up to the driver rating (24 V), nothing beyond
    assert dev.emulator.stats.max_abs_command_V <= 24.0 and np.all(dev.emulator._u == 0.0)


def test_the_controllers_to_verify():
    assert controllers_of(None) == ['inverse_adaptive']  # config/wrist.yaml's mode: what run uses
    assert controllers_of('all') == ['inverse_adaptive', 'direct_adaptive', 'pid']
    assert controllers_of('pid,direct_adaptive,pid') == ['pid', 'direct_adaptive']
    with pytest.raises(ValueError, match='--controllers'):
        controllers_of('pid,fuzzy')


def test_the_diagnosis_replays_the_model_the_params_file_describes(tmp_path, monkeypatch):
    """Its plant node's whole model (files, pre-load, model.* values), not only the files any node names."""
    import sma_wrist.diagnose as dg
    from sma_wrist.commission import verify as vf

    seen = {}

    def fake(bag, **kw):
        seen.update(kw)
        raise dg.DiagnoseInputError('stop here')

    monkeypatch.setattr(dg, 'diagnose', fake)
    f = tmp_path / 'wrist_params.yaml'
    f.write_text(yaml.safe_dump({'plant_sim': {'ros__parameters': {'preload_elongation_mm': 2.1}}}))
    vf.diagnosis(tmp_path / 'bag', f)
    assert seen['params_file'] == str(f) and 'hysteresis_file' not in seen


def test_the_diagnosis_scores_the_verification_run_after_its_soft_start(tmp_path, monkeypatch):
    """The wires start the run with the memory the excitation and the settling left (the nominal device: 0.067 rad
    below the replay's rest start until the first large cycle): the soft start only settles the replay's memory."""
    import sma_wrist.diagnose as dg
    from sma_wrist.commission import verify as vf

    seen = {}

    def fake(bag, **kw):
        seen.update(kw)
        raise dg.DiagnoseInputError('stop here')

    params = tmp_path / 'wrist_params.yaml'
    params.write_text('{}\n')
    monkeypatch.setattr(dg, 'diagnose', fake)
    assert vf.diagnosis(tmp_path / 'bag', params)['error'] == 'stop here'
    assert seen['settle_s'] == vf.SOFT_START_S
    vf.diagnosis(tmp_path / 'bag', params, 12.5)
    assert seen['settle_s'] == 12.5


@pytest.mark.parametrize('settle_s', [-1.0, float('nan'), float('inf')])
def test_the_diagnosis_refuses_a_settling_time_that_is_no_duration(tmp_path, settle_s):
    from sma_wrist.diagnose import DiagnoseInputError, diagnose

    with pytest.raises(DiagnoseInputError, match='settle_s'):
        diagnose(tmp_path / 'absent', settle_s=settle_s)


@pytest.mark.parametrize(
    'args,named_',
    [(['--controllers', 'fuzzy'], '--controllers'), (['--verify-s', '-1'], '--verify-s'), (['--verify-s', 'nan'], '')],
)
def test_cli_bad_verification_options_are_named(tmp_path, capsys, args, named_):
    from sma_wrist.cli import main

    assert main(['commission', '--sim', '--out', str(tmp_path / 'c'), *args]) == 2
    err = capsys.readouterr().err
    assert 'error:' in err and named_ in err and 'Traceback' not in err
    assert not (tmp_path / 'c').exists()  # refused before the device was touched


def test_a_weak_tem_face_within_its_noise_is_pulsed_again_before_it_is_called_dead():
    """The phase-fraction wrist (its exchanger on a large heat sink) with TEMs at 0.6x and 0.1 degC sensor noise: a
    3 s pulse moves a face by about the error of that estimate. It was reported as a dead face sensor."""
    from sma_wrist.commission.bringup import BringUp
    from sma_wrist.hw.calibration import Calibration, Wiring

    dev = SimDevice(
        EmulatorConfig(
            rate_hz=1000.0,  # the device's own rate: at 250 Hz the estimate's error (the floor) is twice as large
            plant='phase_fraction',
            scenario={'tem_gain_scale': 0.6, 'transition_shift_C': 10.0},
            noise_counts=25.0,
            seed=0,
        )
    )
    bring = BringUp(dev, Calibration(), Wiring())
    bring.step_link()
    bring.step_sensors()
    bring.step_pulses()  # raised Stop(face_sensor_no_response)
    p = bring.steps['tem_pulses']
    first, longer = p['first'], p['longer']
    assert min(-first['face_change_C'][0][0], -first['face_change_C'][1][1]) < first['face_response_floor_C']
    assert min(-longer['face_change_C'][0][0], -longer['face_change_C'][1][1]) > 2 * longer['face_response_floor_C']
    assert bring.faults == [] and bring.max_drive_sent_V <= 6.0


def test_a_commissioned_model_that_does_not_describe_the_loop_is_said_with_what_it_means_for_diagnose_and_monitor():
    assert diagnosis_warning(None) == ''
    clean = {'discrepancy': False, 'residual': {'thermal': {'rms': 0.07, 'rms_over_noise': 1.38}}}
    assert diagnosis_warning(clean) == ''
    off = {
        'discrepancy': True,
        'unexplained': True,
        'summary': 'unexplained discrepancy in mechanics',
        'residual': {
            'thermal': {'rms': 0.058, 'rms_over_noise': 1.11},
            'mechanics': {'rms': 0.31, 'rms_over_noise': 271.0},
        },
    }
    text = diagnosis_warning(off)
    assert 'does not describe' in text and 'twin monitor' in text
    assert 'mechanics 0.31 rad' in text and 'thermal' not in text  # only the channels with structure left
    named = dict(off, unexplained=False, summary='thermal: tem_gain_err')
    assert 'departs from (thermal: tem_gain_err)' in diagnosis_warning(named)
    # the angle off with a model wire refitted on a payload of its own: giving the payload is the remedy
    refit = {'refined': True, 'payload_given': False, 'payload_kg': 0.36}
    assert 'payload of its own, 0.36 kg' in diagnosis_warning(off, refit) and '--payload-kg' in diagnosis_warning(
        off, refit
    )
    assert '--payload-kg' not in diagnosis_warning(off, dict(refit, payload_given=True))
    assert '--payload-kg' not in diagnosis_warning(off, dict(refit, refined=False))
    thermal_only = dict(off, residual={'thermal': {'rms': 0.2, 'rms_over_noise': 4.0}})
    assert '--payload-kg' not in diagnosis_warning(thermal_only, refit)
