"""The bring-up's numerical decisions (sma_wrist/commission/detect.py) and the wiring map they produce
(sma_wrist/hw/calibration.py Wiring), on synthetic step responses: no device, no plant."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from sma_wrist.commission import detect as D
from sma_wrist.hw.calibration import Calibration, Wiring
from sma_wrist.hw.protocol import ADC_MAX

HEAT, FACE = 1.1, -1.0  # a healthy TEM's pulse: its muscle warms, its face cools [degC]


def responses(polarity=(1, 1), channels_swapped=False, thermocouples_swapped=False, rng=None, noise=0.01):
    """(muscle (2, 2), face (2, 2)) step changes of a wrist wired so, as the pulses see them (identity wiring)."""
    muscle, face = np.zeros((2, 2)), np.zeros((2, 2))
    for k in range(2):
        tem = 1 - k if channels_swapped else k  # the TEM (= its muscle) that command k reaches
        reading = 1 - tem if thermocouples_swapped else tem
        muscle[k, reading] = polarity[tem] * HEAT
        face[k, tem] = polarity[tem] * FACE
    if rng is not None:
        muscle += rng.normal(0, noise, (2, 2))
        face += rng.normal(0, noise, (2, 2))
    return muscle, face


def kinds(found):
    return sorted((f.kind, f.channel) for f in found.faults)


def test_step_change_sees_the_step_and_not_the_drift_left_by_an_earlier_pulse():
    rng = np.random.default_rng(0)
    t = np.arange(0, 5, 1e-3)
    drift = -0.05 * t  # cooling back after an earlier pulse
    step = np.where(t >= 2.0, 0.6 * (t - 2.0), 0.0)  # a ramp while driven, 2..4 s
    y = 27.0 + drift + np.where(t > 4.0, 1.2, step) + rng.normal(0, 0.01, len(t))
    c = D.step_change(t, y, 2.0, 4.0, baseline_s=1.0, tail_s=0.3)
    assert abs(c.change - 0.6 * 1.85) < 0.02  # the ramp at the tail's mean time, the drift removed
    assert 0 < c.stderr < 0.005
    with pytest.raises(ValueError, match='too few samples'):
        D.step_change(t[:10], y[:10], 2.0, 4.0)


def test_noise_level_is_the_spread_about_a_line():
    rng = np.random.default_rng(1)
    t = np.linspace(0, 2, 2000)
    assert abs(D.noise_level(t, 5.0 + 3.0 * t + rng.normal(0, 0.2, len(t))) - 0.2) < 0.01
    assert D.noise_level(t, 3.0 * t) < 1e-9


def test_a_wrist_wired_as_documented_has_no_fault():
    rng = np.random.default_rng(2)
    for _ in range(50):
        found = D.classify_pulses(*responses(rng=rng), 0.15, 0.15)
        assert not found.faults and found.wiring() == Wiring()


@pytest.mark.parametrize(
    'polarity,channels,thermocouples',
    list(itertools.product([(1, 1), (-1, 1), (1, -1), (-1, -1)], [False, True], [False, True])),
)
def test_each_wiring_fault_is_named_and_its_fix_undoes_it(polarity, channels, thermocouples):
    found = D.classify_pulses(*responses(polarity, channels, thermocouples), 0.15, 0.15)
    expected = [('tem_polarity', m + 1) for m in range(2) if polarity[m] < 0]
    expected += [('tem_channels_swapped', None)] * channels + [('thermocouples_swapped', None)] * thermocouples
    assert kinds(found) == sorted(expected)
    fixed = Wiring().then(found.wiring())
    for f in found.faults:  # every fix names its bridge parameter, with the corrected wiring's value
        ((key, value),) = f.params.items()
        assert fixed.params()[key] == value and key in f.fix
    # through the corrected wiring the same wrist answers as one wired as documented
    again = D.classify_pulses(*_through(fixed, polarity, channels, thermocouples), 0.15, 0.15, current=fixed)
    assert not again.faults


def _through(w: Wiring, polarity, channels_swapped, thermocouples_swapped):
    """The pulses' responses through wiring ``w`` (the host-side map) on a wrist wired so."""
    muscle, face = np.zeros((2, 2)), np.zeros((2, 2))
    for k in range(2):
        out = w.tem_channel_map[k] - 1  # command k leaves on this driver output, with this sign
        tem = 1 - out if channels_swapped else out
        sign = w.tem_sign[k] * polarity[tem]
        adc = 1 - tem if thermocouples_swapped else tem  # the ADC channel of that muscle's thermocouple
        reading = w.thermocouple_map.index(adc + 1)  # the host's reading of that channel
        muscle[k, reading] = sign * HEAT
        face[k, tem] = sign * FACE
    return muscle, face


def test_swapped_tem_channels_and_swapped_thermocouples_differ_by_the_faces():
    """Both give the same muscle responses (the other muscle's reading moves); the faces tell them apart."""
    m1, f1 = responses(channels_swapped=True)
    m2, f2 = responses(thermocouples_swapped=True)
    assert np.array_equal(m1, m2) and not np.array_equal(f1, f2)
    assert kinds(D.classify_pulses(m1, f1, 0.15, 0.15)) == [('tem_channels_swapped', None)]
    assert kinds(D.classify_pulses(m2, f2, 0.15, 0.15)) == [('thermocouples_swapped', None)]


def test_a_dead_tem_a_frozen_reading_and_a_response_below_the_floor():
    muscle, face = responses()
    muscle[1], face[1] = 0.01, 0.0
    assert kinds(D.classify_pulses(muscle, face, 0.15, 0.15)) == [('tem_no_response', 2)]
    muscle, face = responses()
    muscle[:, 0] = 0.0
    found = D.classify_pulses(muscle, face, 0.15, 0.15, frozen=np.array([True, False]))
    assert kinds(found) == [('sensor_frozen', 1)] and not found.complete
    found = D.classify_pulses(muscle, face, 0.15, 0.15)  # not frozen, just not moving: the sensor sits off the wire
    assert kinds(found) == [('muscle_sensor_no_response', 1)]
    muscle, face = responses()
    assert kinds(D.classify_pulses(muscle * 0.1, face, 0.15, 0.15)) == [
        ('muscle_sensor_no_response', 1),
        ('muscle_sensor_no_response', 2),
    ]
    muscle, face = responses()
    face[:] = 0.0  # the faces decide the TEM; without them a swap could not be told from the other
    assert kinds(D.classify_pulses(muscle, face, 0.15, 0.15)) == [
        ('face_sensor_no_response', 1),
        ('face_sensor_no_response', 2),
    ]


def test_a_response_needs_to_dominate_the_other_channel():
    muscle, face = responses()
    muscle[0, 1] = 0.5  # the other muscle warmed half as much: no clear answer
    found = D.classify_pulses(muscle, face, 0.15, 0.15)
    assert kinds(found) == [('muscle_sensor_no_response', 1)]


def test_angle_direction():
    rev = {'calibration.angle_gain_rad_per_count': -1e-4, 'calibration.angle_offset_rad': 3.2767}
    ok = D.angle_direction([0.01, -0.01], [True, True], [False, False], 75.0, [60.0, 50.0], rev)
    assert ok.sign == 1 and not ok.faults
    bad = D.angle_direction([-0.01, 0.01], [True, True], [False, False], 75.0, [60.0, 50.0], rev)
    assert bad.sign == -1 and [f.kind for f in bad.faults] == ['angle_reversed'] and bad.faults[0].params == rev
    assert 'calibration.angle_offset_rad: 3.2767' in bad.faults[0].fix
    one = D.angle_direction([0.01, 0.0], [True, False], [False, False], 75.0, [60.0, 58.0], rev)
    assert one.sign == 1 and not one.faults  # a muscle that stalled below the limit decides nothing
    broken = D.angle_direction([0.0, -0.01], [False, True], [True, False], 75.0, [75.2, 50.0], rev)
    assert broken.sign == 1 and [(f.kind, f.channel) for f in broken.faults] == [('muscle_not_moving', 1)]
    same = D.angle_direction([0.01, 0.01], [True, True], [False, False], 75.0, [60.0, 50.0], rev)
    assert same.sign is None and [f.kind for f in same.faults] == ['angle_inconsistent']


def test_wiring_maps_commands_and_readings_and_composes():
    w = Wiring((-1, 1), (2, 1), (2, 1))
    assert w.device_command(3.0, 5.0) == (5.0, -3.0)  # muscle 1's TEM on output 2, its leads swapped
    assert w.muscle_counts((10, 20, 30, 40, 50)) == (20, 10, 30, 40, 50)
    assert w.channel_order() == [1, 0, 2, 3, 4]
    assert Wiring().then(w) == w and w.then(Wiring()) == w
    assert Wiring.from_params(w.params()) == w
    assert Wiring((0, 1)).problem() and Wiring(tem_channel_map=(1, 1)).problem() and Wiring().problem() is None


def test_a_reversed_potentiometer_calibration_reads_the_true_angle():
    cal = Calibration()
    for q in (-0.3, 0.0, 0.08, 1.2):
        counts = cal.to_counts(np.zeros(4), q)
        counts[4] = ADC_MAX - counts[4]  # what a reversed potentiometer reads
        assert abs(cal.reversed_angle().to_physical(counts)[1] - q) < 1e-9
    assert cal.reversed_angle().reversed_angle() == cal
