"""Commissioning's excitation and identification (sma_wrist/commission/excite.py, identification.py) on emulated
devices that are not the model: a wire transforming 8 degC hotter, TEM 1 getting 0.8 of its drive, a payload of
0.5 kg the identification is not told; the phase-fraction wrist; the nominal device.

To stay light the device is emulated in lockstep at 100 Hz, the bring-up's checks that need seconds of heating
are left to test_commission.py (here only the link and sensor steps run before the excitation, the wiring being
right), and on the nominal device the excitation is shortened (``budget_s``: its sines and rests)."""

from __future__ import annotations

import numpy as np
import pytest

from sma_wrist.commission.bringup import BringUp, Stop
from sma_wrist.commission.device import SimDevice
from sma_wrist.commission.excite import MARK, ExcitationLimits, excite, schedule
from sma_wrist.commission.identification import LOOSE_TARGET_FILTER_S, LOOSE_WIRE_MRAD, identify_wrist, loop_tuning
from sma_wrist.commission.run import bridge_values, calibration_of, commission
from sma_wrist.hw.calibration import Wiring
from sma_wrist.hw.emulator import EmulatorConfig

RATE_HZ = 100.0
BUDGET_S = 600.0  # the whole excitation (what the command uses)
SHORT_S = 420.0  # the sines and rests shortened to a third
OFF_MODEL = {
    'plant': 'sdgpi',
    'scenario': {'transition_shift_C': 8.0},
    'tem_drive_scale': (0.8, 1.0),
    'payload_kg': 0.5,
}


def brought_up(**cfg) -> tuple[BringUp, SimDevice]:
    """A BringUp on the emulated device after its link and sensor steps (the wiring as documented)."""
    dev = SimDevice(EmulatorConfig(rate_hz=RATE_HZ, **cfg))
    v = bridge_values()
    bring = BringUp(dev, calibration_of(v), Wiring.from_params(v))
    dev.open()
    bring.step_link()
    bring.step_sensors()
    return bring, dev


@pytest.fixture(scope='module')
def off_model(tmp_path_factory):
    bring, dev = brought_up(**OFF_MODEL)
    summary = excite(bring, BUDGET_S)
    return bring, dev, summary, identify_wrist(bring, tmp_path_factory.mktemp('off'), payload_kg=None)


def test_the_excitation_is_marked_split_and_within_its_limits(off_model):
    bring, dev, summary, _ = off_model
    marks = [label for _, label in bring.rec.marks if label.startswith(MARK)]
    assert len(marks) == len(schedule(BUDGET_S)) == len(summary['phases'])
    parts = [p['part'] for p in summary['phases']]
    assert parts == sorted(parts, key=lambda p: p == 'heldout') and {'fit', 'heldout'} == set(parts)
    assert summary['device_time_s'] <= BUDGET_S
    # the relays within the bring-up's largest drive, the sines up to the driver rating the closed loop uses
    relays = [p for p in schedule(BUDGET_S) if p.period_s == 0]
    assert max(abs(p.hold_V) for p in relays) <= bring.lim.max_drive_V
    assert dev.emulator.stats.max_abs_command_V == pytest.approx(ExcitationLimits().sine_V, abs=0.05)
    assert max(hi for _, hi in summary['muscle_C']) <= summary['window_C'][1]
    # the wires through their transformation, both ways: the joint swept to either side of where it rested (the
    # wire 8 degC hotter only part of the way within the TEMs' window: 0.65 rad measured)
    q0 = bring._q_start
    assert summary['angle_rad'][0] < q0 - 0.15 and summary['angle_rad'][1] > q0 + 0.15
    assert np.all(dev.emulator._u == 0.0)


def test_the_sines_drive_the_tems_as_far_as_the_loop_and_the_relays_keep_the_bring_ups_drive():
    """The closed loop drives the TEMs up to the driver rating (a third of its time at +-24 V on the phase-fraction
    wrist): a heat balance identified only up to 20 V mispredicted it (doc/howto/commission.md)."""
    phases = schedule(BUDGET_S, 20.0, 77.0, ExcitationLimits().sine_V)
    assert {p.amplitude_V for p in phases if p.period_s > 0} == {24.0}
    assert {abs(p.hold_V) for p in phases if p.until_C is not None} == {20.0, 16.0}
    with pytest.raises(ValueError, match='driver rating'):
        ExcitationLimits(sine_V=30.0)


def test_identification_recovers_the_shift_payload_and_weaker_tem(off_model):
    *_, ident = off_model
    p = ident.identified
    assert p['hysteresis']['parameters']['transition_shift_C'] == pytest.approx(8.0, abs=1.0)
    assert p['joint']['parameters']['payload_kg'] == pytest.approx(0.5, abs=0.06)
    # the SD-GPI wire: the built-in model reproduces the relay's second half too, the payload is read
    assert p['joint']['parameters']['payload_identified'] is True
    assert p['joint']['parameters']['second_onset_mismatch_C'] < 0.5
    assert p['thermal']['parameters']['tem1_gain_relative_to_tem2'] == pytest.approx(0.8, abs=0.03)
    assert any('TEM 1 pumps' in w for w in ident.warnings)
    # a shifted SD-GPI wire: the shift describes it, the warp is fitted but the simpler wire handed over
    assert p['hysteresis']['parameters']['wire_model'] == 'shifted'
    # and it stays the model's wire: the phase-fraction wire, fitted too, is no better beyond the angle's noise
    assert p['hysteresis']['parameters']['model_wire'] == 'sdgpi'
    assert 'phase_fraction_not_handed_over' in p['hysteresis']['parameters']
    assert 'wire_file' not in ident.node_params['plant_sim']


def test_the_commissioned_model_beats_the_built_in_one_on_held_out_data(off_model):
    *_, ident = off_model
    for part in ('thermal', 'hysteresis', 'joint'):
        h = ident.identified[part]['heldout']
        assert h['commissioned'] < 0.5 * h['builtin'], (part, h)
        assert ident.identified[part]['handed_over'] is True
    nodes = ident.node_params
    assert nodes['plant_sim']['payload_kg'] == pytest.approx(0.5, abs=0.06)
    assert nodes['hysteresis_compensator']['hysteresis_file'].endswith('hysteresis.yaml')
    assert nodes['tem_controller']['thermal_file'].endswith('thermal.yaml')


def test_on_the_phase_fraction_wrist_the_shift_is_found_and_the_undetermined_payload_is_said(tmp_path):
    bring, _ = brought_up(
        plant='phase_fraction', scenario={'transition_shift_C': 8.0}, tem_drive_scale=(0.8, 1.0), payload_kg=0.5
    )
    excite(bring, BUDGET_S)
    ident = identify_wrist(bring, tmp_path)
    th = ident.identified['thermal']
    # 0.8 of the voltage pumps a little more than 0.8 of the heat through this wrist's Peltier model (its Seebeck
    # back-voltage is not scaled with the drive): measured 0.85 after a bring-up, 0.88 here
    assert 0.75 < th['parameters']['tem1_gain_relative_to_tem2'] < 0.9
    assert th['heldout']['commissioned'] < 0.5 * th['heldout']['builtin']
    # the wire 8 degC hotter: found from where the angle starts to move as muscle 1 heats (the nominal wire of this
    # wrist is measured -1.4 degC from the built-in one: 6.9 here); the replay of the whole trace, fitted with the
    # joint, had it -10 degC and the payload at its bound
    hyst = ident.identified['hysteresis']
    assert 5.5 <= hyst['parameters']['transition_shift_C'] <= 10.0
    assert hyst['heldout']['commissioned'] < hyst['heldout']['builtin']
    # the SD-GPI does not describe where this wire transforms back, so its stress dependence cannot read the payload:
    # not identified, said so, the default assumed (not a compensating value handed over as a payload)
    joint = ident.identified['joint']
    assert joint['parameters']['second_onset_mismatch_C'] > 1.0
    # the phase-fraction wire, fitted with the payload and friction, predicts the held-out cycle better than every
    # SD-GPI candidate beyond the angle's noise: it becomes the model's wire (plant_sim's wire_file) and its payload
    # the one handed over, while the compensator keeps inverting the warped SD-GPI
    assert (
        hyst['parameters']['model_wire'] == 'phase_fraction' and hyst['parameters']['phase_fraction']['at_bounds'] == []
    )
    h = joint['heldout']
    assert h['phase_fraction'] < min(h['warped'], h['shift_only'], h['builtin']) - h['angle_noise']
    assert h['commissioned'] == h['phase_fraction'] and h['compensator_wire'] == h['warped']
    assert ident.node_params['plant_sim']['wire_file'].endswith('wire.yaml')
    assert ident.node_params['hysteresis_compensator']['hysteresis_file'].endswith('hysteresis.yaml')
    # the payload read with the phase-fraction wire's stress dependence: 0.596 kg measured for 0.5 (0.54 for 0.45 on
    # the 1 kHz device of doc/howto/commission.md): the wire's datum and strain trade a little with it
    assert joint['parameters']['payload_identified'] is True
    assert joint['parameters']['payload_kg'] == pytest.approx(0.5, abs=0.12)
    assert ident.node_params['plant_sim']['payload_kg'] == joint['parameters']['payload_kg']
    assert not any('the payload is not determined' in w for w in ident.warnings)
    # the shifted built-in wire misses this wire's branches and stress dependence; the warped SD-GPI (heating and
    # cooling shifts, width, stroke, stress dependence) fitted to the angle predicts the held-out cycle far better and
    # is handed over (measured 35 against 188 mrad RMS on the 1 kHz device)
    assert hyst['parameters']['wire_model'] == 'warped' and joint['handed_over']
    assert joint['heldout']['warped'] < 0.5 * joint['heldout']['shift_only']
    assert hyst['parameters']['warp']['at_bounds'] == []
    # the warped wire still misses this wire's minor loops by more than LOOSE_WIRE_MRAD: the TEM loop, which follows
    # the compensator's inverse of it, gets the slower target prefilter (loop_tuning), said in the part's parameters
    assert joint['heldout']['compensator_wire'] > LOOSE_WIRE_MRAD
    assert ident.node_params['tem_controller']['target_filter_s'] == LOOSE_TARGET_FILTER_S
    assert hyst['parameters']['loop']['target_filter_s'] == LOOSE_TARGET_FILTER_S
    # the payload given (--payload-kg): the phase-fraction fits hold it (the recordings fix the wire's stresses only
    # relative to it), and the refinement is told to hold it too
    given = identify_wrist(bring, tmp_path / 'given', payload_kg=0.5)
    pfw = given.identified['hysteresis']['parameters']['phase_fraction']
    assert pfw['payload_kg'] == 0.5 and given.identified['joint']['parameters']['payload_given'] is True
    assert given.refinement.payload_given and not ident.refinement.payload_given


def test_commission_on_the_nominal_device_identifies_values_near_the_defaults(tmp_path):
    res = commission(tmp_path / 'c', SimDevice(EmulatorConfig(rate_hz=RATE_HZ)), excite_budget_s=SHORT_S)
    assert res['status'] == 'commissioned' and res['faults'] == []
    p = res['identified']
    assert abs(p['hysteresis']['parameters']['transition_shift_C']) <= 0.5
    assert p['hysteresis']['parameters']['wire_model'] != 'warped'  # the warp is no better beyond the angle's noise
    assert p['joint']['parameters']['payload_kg'] == pytest.approx(0.3, abs=0.03)
    assert p['thermal']['parameters']['tem1_gain_relative_to_tem2'] == pytest.approx(1.0, abs=0.02)
    assert p['thermal']['heldout']['commissioned'] < 0.1  # degC: the model itself, sensor noise 0.008 degC
    text = open(res['params_file']).read()
    assert 'target_filter_s' not in text  # the loop keeps config/wrist.yaml's prefilter with the model's own wire
    assert 'thermal_file' in text and 'hysteresis_file' in text and 'calibration.tem_sign' in text
    report = open(res['report']).read()
    assert '## Identified model' in report and '![excitation.png](excitation.png)' in report
    assert res['device_time_s'] < 400.0


def test_a_muscle_over_the_window_stops_the_excitation_with_the_tems_off(tmp_path):
    bring, dev = brought_up()
    counts = dev.emulator.cfg.calibration.to_counts(np.array([83.0, 30.0, 25.0, 25.0]), 0.5)
    dev.emulator.inject('force', (0, int(counts[0])))  # muscle 1 reads 83 degC: beyond the TEMs' window
    with pytest.raises(Stop, match='muscle 1'):
        excite(bring, BUDGET_S)
    dev.frames()  # the device takes the last command (0 V) after its latency
    assert np.all(dev.emulator._u == 0.0) and bring.lim.max_muscle_C == 75.0  # the bring-up's limit restored


def test_ctrl_c_during_the_excitation_turns_the_tems_off_and_names_the_step(tmp_path):
    dev = SimDevice(EmulatorConfig(rate_hz=RATE_HZ))
    frames = dev.frames

    def interrupted():
        if dev.emulator.device_time_s > 80.0:  # the bring-up takes 66 s on this device
            raise KeyboardInterrupt
        return frames()

    dev.frames = interrupted
    res = commission(tmp_path / 'c', dev)
    assert res['status'] == 'interrupted' and 'excite' in res['message']
    assert np.all(dev.emulator._u == 0.0) and res['params_file'] is None
    assert 'excite' in open(res['report']).read()


def test_a_heat_balance_better_only_within_the_sensors_noise_is_not_handed_over(tmp_path):
    """A wrist the built-in heat balance describes to the noise (TEM 1 0.1 % weak, 8 mdegC of sensor noise): the fit
    predicts the held-out data a few mdegC better, which is no gain; the built-in is kept and the warning says why
    (with 24 V sines the nominal device's fit was handed over so, and its loop then replayed to 4x the noise)."""
    import dataclasses

    from sma_wrist.commission.identification import identify_thermal_part
    from sma_wrist.core.thermal import heat_balance as th
    from sma_wrist.core.thermal import identification as ti

    device = dataclasses.replace(th.ThermalParams(), tem_gain=(0.999, 1.0))

    def records(part: str, seconds: float, seed: int) -> list:
        t = np.arange(0.0, seconds, 0.25)
        u1 = 12.0 * np.sin(2 * np.pi * t / 30.0) + 6.0 * np.sign(np.sin(2 * np.pi * t / 11.0))
        x, T = th.rest_state(device, 1), np.empty((t.size, 2, 2))
        for k, u in enumerate(u1):
            T[k] = x[0]
            x = th.step(device, x, np.array([[u, -u]]), 0.25, validate=False)
        T += np.random.default_rng(seed).normal(0.0, 0.008, T.shape)
        return [ti.ThermalRecord(f'{part} {m}', 0.25, u1 * (1 - 2 * m), T[:, m], layer=m) for m in (0, 1)]

    rest = tuple(float(v) for v in th.rest_state(device, 1)[0, 0])
    part, params, warnings = identify_thermal_part(
        records('fit', 60.0, 1), records('held', 30.0, 2), tmp_path, rest, 0.008
    )
    h = part['heldout']
    assert h['commissioned'] < h['builtin'] < h['commissioned'] + 0.008  # better, by less than the noise
    assert part['handed_over'] is False and params == th.ThermalParams()
    assert any("no better than the built-in one beyond the sensors' noise" in w for w in warnings)


def test_the_tem_loop_gets_the_slower_target_prefilter_only_with_a_handed_over_wire_that_misses_the_angle():
    assert loop_tuning(True, 2 * LOOSE_WIRE_MRAD) == {'target_filter_s': LOOSE_TARGET_FILTER_S}
    assert loop_tuning(True, 0.5 * LOOSE_WIRE_MRAD) == {}  # a wire the model describes: config/wrist.yaml's 0.5 s
    assert loop_tuning(False, 20 * LOOSE_WIRE_MRAD) == {}  # the built-in wire handed over: the defaults' loop
    assert loop_tuning(True, float('nan')) == {}
