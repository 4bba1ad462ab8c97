"""Per-TEM drive gains of the heat balance (ThermalParams.tem_gain, the thermal file's ``tem_gain``): one loader,
applied by every user of the heat balance (simulated plant, TEM law, observer, face protection, diagnosis replay),
and identified from each TEM's own temperatures with the rest state held (core.thermal.identification)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from sma_wrist.core.control import tem
from sma_wrist.core.errors import ParameterError
from sma_wrist.core.thermal import heat_balance as th
from sma_wrist.core.thermal import identification as ti
from sma_wrist.core.thermal.kernel import thermal_constants
from sma_wrist.core.thermal.params_file import load_thermal_file, write_thermal_file

WEAK = dataclasses.replace(th.ThermalParams(), tem_gain=(0.7, 1.0))


def test_a_thermal_file_carries_each_tems_gain_and_files_without_it_load_as_before(tmp_path: Path) -> None:
    f = write_thermal_file(tmp_path / 'weak.yaml', WEAK)
    assert 'tem_gain' in f.read_text()
    assert load_thermal_file(f).tem_gain == (0.7, 1.0)
    old = write_thermal_file(tmp_path / 'old.yaml', th.ThermalParams())
    assert 'tem_gain' not in old.read_text()  # a file of two modules alike reads as it did
    assert load_thermal_file(old).tem_gain == (1.0, 1.0)


@pytest.mark.parametrize(
    ('key', 'value', 'match'),
    [
        *[('tem_gain', v, 'tem_gain') for v in ('[0.8]', '[0.8, -1.0]', '[0.8, .nan]', '0.8')],
        # per-TEM hold limits: one pair per TEM, each bracketing 0
        *[
            ('hold_limits_V', v, 'hold_limits_V|bracket 0')
            for v in ('[[-12.0, 13.0]]', '[[-12.0, 13.0], [-12.0]]', '[[-12.0, 13.0], [5.0, 13.0]]')
        ],
    ],
)
def test_a_bad_tem_gain_or_hold_limit_is_refused_naming_the_file(
    tmp_path: Path, key: str, value: str, match: str
) -> None:
    f = write_thermal_file(tmp_path / 't.yaml', WEAK)
    text = f.read_text()
    after = {'tem_gain': 'muscle_face:', 'hold_limits_V': 'window_C:'}[key]
    f.write_text(text[: text.index(f'{key}:')] + f'{key}: {value}\n' + text[text.index(after) :])
    with pytest.raises(ParameterError, match=match) as e:
        load_thermal_file(f)
    assert str(f) in str(e.value)


def test_the_simulated_wrist_heats_through_a_weaker_tem_1_slower(tmp_path: Path) -> None:
    """plant_sim's plant (PlantParams.from_files, the compiled kernel) under the same drive on both TEMs."""
    from sma_wrist.core.plant.wrist import PlantParams, WristPlant

    f = write_thermal_file(tmp_path / 'weak.yaml', WEAK)
    rise = []
    for file in (None, f):
        plant = WristPlant(PlantParams.from_files(None, file, dt=0.01))
        T0 = np.array(plant.state.thermal)[0, :, 0]
        for _ in range(300):
            state = plant.step([[8.0, 8.0]])
        rise.append(np.asarray(state.thermal)[0, :, 0] - T0)
    same, weak = rise
    assert same[0] == pytest.approx(same[1], rel=1e-9)
    assert weak[1] == pytest.approx(same[1], rel=1e-9)  # TEM 2 as before
    assert 0.6 * weak[1] < weak[0] < 0.8 * weak[1]  # 0.7 of the heat pumped (its Joule heat 0.49)


@pytest.mark.parametrize('compiled', [False, True])
def test_the_tem_law_asks_a_weaker_tem_for_more_volts_and_its_observer_follows_it(compiled: bool) -> None:
    """Eqs. 5.44-5.47 with the same faces and targets on both layers: the same model input I, so TEM 1's command
    is TEM 2's over its gain; the observer integrates the heat balance each TEM really sees (th.step)."""
    if compiled and not tem.tem_kernel.AVAILABLE:
        pytest.skip('numba is not installed')
    T = np.array([[[40.0, 30.0], [40.0, 30.0]]])
    r = tem.feedback_linearising_command(WEAK, T, T + 0.1, 0.0, compiled=compiled)
    assert not r.saturated.any()
    assert r.command_V[0, 0] == pytest.approx(r.command_V[0, 1] / 0.7, rel=1e-12)
    assert r.current[0, 0] == pytest.approx(r.current[0, 1], rel=1e-12)
    u = np.array([[5.0, 5.0]])
    x = tem.observer_step(WEAK, T, u, 0.5, compiled=compiled)
    np.testing.assert_allclose(x, th.step(WEAK, T, u, 0.5), rtol=0, atol=1e-12)
    assert x[0, 0, 0] < x[0, 1, 0]  # the weaker TEM warms its muscle less


def test_the_diagnosis_replay_takes_each_tems_gain() -> None:
    from sma_wrist.diagnose.kernels import thermal_sim

    rng = np.random.default_rng(4)
    u = rng.uniform(-10.0, 12.0, (200, 2))
    x0 = th.rest_state(WEAK, 1)
    out_T, out_X = np.empty((200, 1, 2)), np.empty((1, 2, 2))
    thermal_sim(
        u, 0.1, 1, thermal_constants(WEAK)[None], x0.copy(), np.zeros(1), np.zeros(2), np.zeros((200, 2)), out_T, out_X
    )
    ref = th.simulate(WEAK, u[:-1], 0.1, x0)[:, 0, :, 0]
    np.testing.assert_allclose(out_T[:, 0], ref, rtol=0, atol=1e-9)


def _layers(p: th.ThermalParams, seconds: float = 300.0, dt: float = 0.25) -> list[ti.ThermalRecord]:
    """Both TEMs of ``p`` from rest under different sampled-and-held drives, one record per TEM (its layer)."""
    t = np.arange(int(seconds / dt)) * dt
    u = np.c_[11.0 * np.sin(2 * np.pi * t / 40.0), 10.0 * np.sign(np.sin(2 * np.pi * t / 70.0))]
    X = th.simulate(p, u[:-1], dt, th.rest_state(p, 1))[:, 0]
    return [ti.ThermalRecord(f'TEM {m + 1}', dt, u[:, m], X[:, m], layer=m) for m in (0, 1)]


def test_the_fit_recovers_each_tems_gain_from_its_own_temperatures() -> None:
    truth = dataclasses.replace(th.ThermalParams(), tem_gain=(0.8, 1.0))
    recs = _layers(truth)
    rest = tuple(th.rest_state(truth, 1, 1)[0, 0])
    fit = ti.fit_thermal(recs, th.ThermalParams(), faces='both', rest_C=rest, tem_gain=True)
    assert fit.params.tem_gain[0] / fit.params.tem_gain[1] == pytest.approx(0.8, abs=0.005)
    assert fit.rms_C < 0.01
    # one heat balance for both cannot: the same data leave it tenths of a degree off
    shared = ti.fit_thermal(recs, th.ThermalParams(), faces='both', rest_C=rest)
    assert shared.params.tem_gain == (1.0, 1.0) and shared.rms_C > 10 * fit.rms_C


def test_a_fit_tied_to_the_rest_state_rests_there() -> None:
    """K_inf from the measured rest state (Eqs. 4.13/4.14 at I = 0) instead of fitted: the model's zero-drive
    equilibrium is the measured one whatever the other coefficients came out as."""
    recs = _layers(th.ThermalParams(), seconds=120.0)
    rest = (26.5, 27.25)  # not the data's: the fit must keep it all the same
    fit = ti.fit_thermal(recs, th.ThermalParams(), faces='both', rest_C=rest)
    np.testing.assert_allclose(th.rest_state(fit.params, 1, 1)[0, 0], rest, rtol=0, atol=1e-9)
    with pytest.raises(ti.ThermalIdentificationError, match='both TEMs'):
        ti.fit_thermal(recs[:1], th.ThermalParams(), faces='both', tem_gain=True)


def test_hold_limits_with_per_tem_gains_are_the_ones_both_tems_hold() -> None:
    lo, hi = ti.hold_limits(dataclasses.replace(th.ThermalParams(), tem_gain=(0.7, 1.3)), resolution_V=0.5)
    weak = ti.hold_limits(dataclasses.replace(th.ThermalParams(), input_per_volt=0.4 * 0.7), resolution_V=0.5)
    strong = ti.hold_limits(dataclasses.replace(th.ThermalParams(), input_per_volt=0.4 * 1.3), resolution_V=0.5)
    assert (lo, hi) == (max(weak[0], strong[0]), min(weak[1], strong[1]))
    assert strong[1] < weak[1]


def test_the_muscle_window_both_tems_hold_is_the_weaker_ones() -> None:
    """identify's pre-load calibration places the wire within what the TEMs hold at their limits: with TEM 2 the
    weaker, its window (a weaker module neither heats nor cools its muscle as far)."""
    from sma_wrist.core.plant.preload import reachable_window

    weak_2 = dataclasses.replace(th.ThermalParams(), tem_gain=(1.0, 0.7))
    alone = reachable_window(dataclasses.replace(th.ThermalParams(), input_per_volt=0.4 * 0.7))
    assert reachable_window(weak_2) == pytest.approx(alone, abs=1e-9)
    assert alone[1] < reachable_window(th.ThermalParams())[1]


def test_each_tem_holds_its_own_limits_a_weaker_one_a_larger_drive() -> None:
    per = ti.tem_hold_limits(dataclasses.replace(th.ThermalParams(), tem_gain=(0.7, 1.0)), resolution_V=0.5)
    alone = ti.hold_limits(dataclasses.replace(th.ThermalParams(), input_per_volt=0.4 * 0.7), resolution_V=0.5)
    assert per[0] == alone  # TEM 1 characterised at its own gain
    assert per[1] == ti.hold_limits(th.ThermalParams(), resolution_V=0.5)
    assert per[0][1] > per[1][1] and per[0][0] < per[1][0]


def test_a_thermal_file_carries_each_tems_hold_limits_and_one_pair_loads_as_before(tmp_path: Path) -> None:
    weak = WEAK.with_hold_limits(((-17.0, 16.0), (-12.0, 13.0)))
    assert (weak.u_min_V, weak.u_max_V) == (-12.0, 13.0)  # what both hold
    f = write_thermal_file(tmp_path / 'weak.yaml', weak)
    back = load_thermal_file(f)
    assert back.tem_hold_limits_V == ((-17.0, 16.0), (-12.0, 13.0)) and (back.u_min_V, back.u_max_V) == (-12.0, 13.0)
    np.testing.assert_array_equal(back.layer_hold_limits()[1], [16.0, 13.0])
    old = write_thermal_file(tmp_path / 'old.yaml', WEAK)  # one pair for both TEMs, as every earlier file
    assert 'hold_limits_V:\n- -12.0\n- 13.0\n' in old.read_text()
    assert load_thermal_file(old).tem_hold_limits_V is None
    np.testing.assert_array_equal(load_thermal_file(old).layer_hold_limits()[0], [-12.0, -12.0])


@pytest.mark.parametrize('compiled', [False, True])
@pytest.mark.parametrize('predictive', [False, True])
def test_a_weaker_tem_is_not_held_to_the_stronger_ones_limits(compiled: bool, predictive: bool) -> None:
    """tem_controller's loop (TemLoop, numpy and compiled) where the hold limits act: a hot face without the
    predictive protection, and a face outside the window with it (the backstop). TEM 1 (0.7) holds 16 V heating,
    TEM 2 13 V (cooling -17 and -12 V): each gets its own."""
    hold = WEAK.with_hold_limits(((-17.0, 16.0), (-12.0, 13.0)))
    drive = tem.DriveLimits(predictive=predictive, protect_above_C=60.0, face_max_C=80.0)
    law = dataclasses.replace(hold, u_min_V=drive.boost_min_V, u_max_V=drive.boost_max_V)
    loop = tem.TemLoop(law, tem.TemControlParams(), drive, hold, 120.0, compiled=compiled)
    hot = 70.0 if not predictive else 81.0  # above protect_above_C / outside the 0-80 degC window
    loop.observer[0, :, 1] = 30.0
    for k in range(3):
        s = loop.sample(0.01 * k, np.array([hot, hot]), np.array([hot + 30.0, hot + 30.0]))
    assert s is not None
    # outside the window no drive keeps the faces in it: the one that leaves it least (full cooling), bounded by each
    # TEM's hold limits; without the predictive protection the heating asked for, bounded the same way
    np.testing.assert_array_equal(s.command_V, [-17.0, -12.0] if predictive else [16.0, 13.0])
