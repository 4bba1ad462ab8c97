"""Plants that are not the controllers' model (sma_wrist.plants): the parameter-spread family, its
validation, the varied plant against the plain one, sensors on what is published, and the node graph
running a perturbed plant (where the sweep's loops must be the graph's, doc/howto/sweep.md)."""

from __future__ import annotations

import dataclasses
import tempfile
from pathlib import Path

import numpy as np
import pytest

from sma_wrist.core.errors import ParameterError
from sma_wrist.core.hysteresis.default_params import default_sdgpi
from sma_wrist.core.hysteresis.sdgpi import initial_state, mirrored_output
from sma_wrist.core.plant.wrist import WristPlant
from sma_wrist.plants import PLANTS, load_hysteresis, make_plant
from sma_wrist.plants.spread import FAMILY, VALIDITY, Scenario, SensorBank, perturbed_hysteresis, sample

#: a plant inside the default family, away from nominal on every axis
PERTURBED = Scenario(
    payload_kg=0.4,
    transition_shift_C=4.0,
    stroke_scale=0.9,
    tem_gain_scale=1.1,
    heat_loss_scale=0.9,
    ambient_offset_C=2.0,
    temp_noise_C=0.1,
    temp_lag_s=0.1,
    angle_noise_rad=0.002,
    noise_seed=7,
)


def test_sample_is_seeded_and_inside_the_family() -> None:
    a, b, c = sample(50, seed=3), sample(50, seed=3), sample(50, seed=4)
    assert a == b and a != c
    for name, (lo, hi) in FAMILY.items():
        v = np.array([getattr(s, name) for s in a])
        assert lo <= v.min() and v.max() <= hi and np.ptp(v) > 0.5 * (hi - lo)
    assert len({s.noise_seed for s in a}) == 50


def test_unknown_names_and_invalid_ranges_are_refused() -> None:
    with pytest.raises(ParameterError, match="unknown perturbation 'wire_color'"):
        sample(3, ranges={'wire_color': (0, 1)})
    with pytest.raises(ParameterError, match='outside the model'):
        sample(3, ranges={'transition_shift_C': (-20.0, 0.0)})
    with pytest.raises(ParameterError, match='lo <= hi'):
        sample(3, ranges={'stroke_scale': (1.2, 0.8)})
    with pytest.raises(ParameterError, match='N = 0'):
        sample(0)
    with pytest.raises(ParameterError, match='outside the model'):
        Scenario(temp_lag_s=3.0)
    with pytest.raises(ParameterError, match="unknown perturbation 'colour'"):
        Scenario.from_mapping({'colour': 1.0})
    with pytest.raises(ParameterError, match='unknown plant'):
        make_plant('brass', [Scenario()])


def test_scenario_file_round_trip_and_bad_file(tmp_path: Path) -> None:
    f = tmp_path / 'sc.json'
    import json

    f.write_text(json.dumps(PERTURBED.to_dict()))
    assert Scenario.from_file(f) == PERTURBED
    row = {**PERTURBED.to_dict(), 'index': 4, 'controller': 'pid', 'max_error_pct': 12.0}  # a results.jsonl line
    f.write_text(json.dumps(row))
    assert Scenario.from_file(f) == PERTURBED
    f.write_text(json.dumps({'stroke_scale': 0.8}))
    assert Scenario.from_file(f, {'payload_kg': 0.5}) == Scenario(stroke_scale=0.8, payload_kg=0.5)
    f.write_text('[1, 2]')
    with pytest.raises(ParameterError, match='JSON object'):
        Scenario.from_file(f)
    with pytest.raises(ParameterError, match='scenario file'):
        Scenario.from_file(tmp_path / 'missing.json')


def _transition_C(params, m: float = 0.775, branch: str = 'heating') -> float:
    """Temperature where the major loop's mirrored output crosses its mid value (heating branch)."""
    T = np.linspace(20.0, 90.0, 1401)
    y = mirrored_output(params, initial_state(params, T, m, branch=branch), T)
    mid = 0.5 * (y[0] + y[-1])
    return float(T[np.argmin(np.abs(y - mid))])


def test_transition_shift_and_stroke_act_on_the_wire() -> None:
    base = default_sdgpi()
    assert perturbed_hysteresis(base) is base
    shifted = perturbed_hysteresis(base, shift_C=7.0)
    assert _transition_C(shifted) - _transition_C(base) == pytest.approx(7.0, abs=0.1)
    T = np.array([20.0, 90.0])
    stroke = lambda p: float(np.ptp(mirrored_output(p, initial_state(p, T, 0.775, branch='heating'), T)))  # noqa: E731
    assert stroke(perturbed_hysteresis(base, stroke_scale=1.3)) == pytest.approx(1.3 * stroke(base), rel=1e-9)
    assert stroke(perturbed_hysteresis(base, stroke_scale=0.7)) == pytest.approx(0.7 * stroke(base), rel=1e-9)


def test_varied_plant_at_the_nominal_scenario_is_the_plain_plant() -> None:
    vp = make_plant('sdgpi', [Scenario()])
    wp = WristPlant(payload_kg=0.3)
    assert abs(vp.state.q[0] - wp.state.q[0]) < 1e-12
    rng = np.random.default_rng(0)
    for _ in range(200):
        u = rng.uniform(-24, 24, (1, 2))
        vp.advance(u, 10)
        wp.advance(u, 10)
    np.testing.assert_allclose(vp.state.q, wp.state.q, rtol=0, atol=1e-12)
    np.testing.assert_allclose(vp.muscle_temperature_C, wp.muscle_temperature_C, rtol=0, atol=1e-12)
    np.testing.assert_allclose(vp.wire_stress_Pa, wp.wire_stress_Pa, rtol=1e-12)


def test_each_scenario_is_its_own_plant_among_others() -> None:
    sc = sample(5, seed=1)
    many = make_plant('sdgpi', sc)
    one = make_plant('sdgpi', [sc[3]])
    u = np.tile([[8.0, -6.0]], (5, 1))
    for _ in range(100):
        many.advance(u, 10)
        one.advance(u[:1], 10)
    assert many.state.q[3] == one.state.q[0]
    assert len(set(np.round(many.state.q, 9))) == 5  # the perturbations change the wrists


def test_sensors_act_on_the_measurement_not_the_plant() -> None:
    dt = 0.01
    ideal = SensorBank([Scenario()], dt)
    T = np.array([[30.0, 40.0]])
    assert ideal.measure(T, np.array([0.5]), np.array([0.1]))[0] is T
    lagged = SensorBank([Scenario(temp_lag_s=0.2)], dt)
    lagged.measure(T, np.zeros(1), np.zeros(1))
    for _ in range(20):  # 0.2 s after a 10 degC step: 1 - 1/e of it
        Tm = lagged.measure(T + 10.0, np.zeros(1), np.zeros(1))[0]
    assert Tm[0, 0] - 30.0 == pytest.approx(10.0 * (1 - np.exp(-1.0)), rel=1e-9)
    noisy = SensorBank([Scenario(temp_noise_C=0.3, angle_noise_rad=0.003, noise_seed=5)], dt)
    got = np.array(
        [np.concatenate([x.ravel() for x in noisy.measure(T, np.array([0.5]), np.zeros(1))[:2]]) for _ in range(4000)]
    )
    assert np.std(got[:, 0]) == pytest.approx(0.3, rel=0.05) and np.std(got[:, 2]) == pytest.approx(0.003, rel=0.05)
    assert abs(np.mean(got[:, 0]) - 30.0) < 0.03
    again = SensorBank([Scenario(temp_noise_C=0.3, angle_noise_rad=0.003, noise_seed=5)], dt)
    assert np.array_equal(again.measure(T, np.array([0.5]), np.zeros(1))[0][0], got[0, :2])


def test_identified_wire_is_the_plant_s_wire_and_a_bad_file_is_refused(tmp_path: Path) -> None:
    """``hysteresis_file``: the family perturbs the identified wire, not the default."""
    from sma_wrist.core.hysteresis.params_file import save_hysteresis
    from sma_wrist.plants.spread import perturbed_hysteresis

    hot = perturbed_hysteresis(default_sdgpi(), 25.0, 1.0)  # a wire transforming 25 degC higher
    path = save_hysteresis(tmp_path / 'hysteresis.yaml', hot)
    got = make_plant('sdgpi', [Scenario()], hysteresis_file=str(path))
    plain = make_plant('sdgpi', [Scenario()])
    assert not np.allclose(got.params.hysteresis.envelopes.a, plain.params.hysteresis.envelopes.a)
    assert np.allclose(got.params.hysteresis.envelopes.a, hot.envelopes.a)
    assert np.allclose(load_hysteresis(path).envelopes.b, hot.envelopes.b)
    with pytest.raises(ParameterError, match='missing.yaml'):
        make_plant('sdgpi', [Scenario()], hysteresis_file=str(tmp_path / 'missing.yaml'))


def test_registry_lists_the_spread_family() -> None:
    assert 'sdgpi' in PLANTS
    assert {p.name for p in VALIDITY} == {f.name for f in dataclasses.fields(Scenario)} - {'noise_seed'}
    assert all(getattr(Scenario(), p.name) == p.nominal for p in VALIDITY)


@pytest.mark.parametrize('mode', ['pid', 'inverse_adaptive'])
def test_graph_runs_a_perturbed_plant_and_the_sweep_is_the_graph(mode: str) -> None:
    """plant_sim's ``plant`` + ``scenario.*`` in the node graph; the sweep's loop on the same scenario
    has the same TEM commands and measured angles to the last bit (measured over 126 s for all three
    modes on the nominal and this plant; 12 s here)."""
    from sma_wrist.closed_loop import run_closed_loop
    from sma_wrist.sweep.simulate import Case, simulate

    sc = PERTURBED
    extra = {
        '/plant_sim': {
            'plant': 'sdgpi',
            'scenario.noise_seed': sc.noise_seed,
            **{f'scenario.{k}': v for k, v in sc.to_dict().items() if k not in ('payload_kg', 'noise_seed')},
        }
    }
    with tempfile.TemporaryDirectory() as d:
        run = run_closed_loop(mode, sc.payload_kg, 12.0, Path(d) / 'bag', extra_params=extra).run
    rows, tr = simulate([Case(0, mode, sc)], 12.0, record=True)
    k = np.rint(run.t / 0.01).astype(int)
    assert np.max(np.abs(run.q - tr.q_measured[k, 0])) <= 1e-12
    assert np.max(np.abs(run.q - tr.q[k, 0])) > 1e-4  # the graph published the noisy potentiometer
    kc = np.rint(run.command_t / 0.01).astype(int)
    np.testing.assert_array_equal(run.command_V, tr.command_V[kc, 0])
    with tempfile.TemporaryDirectory() as d:
        nominal = run_closed_loop(mode, sc.payload_kg, 12.0, Path(d) / 'bag').run
    assert np.max(np.abs(nominal.q - run.q)) > 1e-3  # the perturbations reached the graph


def test_graph_with_the_temperature_observer_is_the_sweep_with_it() -> None:
    """hysteresis_compensator ``temperature_source: observer`` (its observer paired with the unstamped TEM
    commands by arrival) runs what ``simulate(..., compensator_observer=...)`` runs: same measured angles and
    TEM commands to the last bit on the perturbed plant, and not the thermocouple-fed loop (they part at
    3.5 s on this plant: 5 s here)."""
    from sma_wrist.closed_loop import run_closed_loop
    from sma_wrist.core.control.tem import TemperatureObserverParams
    from sma_wrist.sweep.simulate import Case, simulate

    sc, obs = PERTURBED, TemperatureObserverParams(correction_s=0.25, tc_lag_s=0.15)
    extra = {
        '/plant_sim': {
            'plant': 'sdgpi',
            'scenario.noise_seed': sc.noise_seed,
            **{f'scenario.{k}': v for k, v in sc.to_dict().items() if k not in ('payload_kg', 'noise_seed')},
        },
        '/hysteresis_compensator': {
            'temperature_source': 'observer',
            'observer.correction_s': obs.correction_s,
            'observer.tc_lag_s': obs.tc_lag_s,
        },
    }
    with tempfile.TemporaryDirectory() as d:
        run = run_closed_loop('inverse_adaptive', sc.payload_kg, 5.0, Path(d) / 'bag', extra_params=extra).run
    _, tr = simulate([Case(0, 'inverse_adaptive', sc)], 5.0, record=True, compensator_observer=obs)
    k, kc = np.rint(run.t / 0.01).astype(int), np.rint(run.command_t / 0.01).astype(int)
    assert np.max(np.abs(run.q - tr.q_measured[k, 0])) <= 1e-12
    np.testing.assert_array_equal(run.command_V, tr.command_V[kc, 0])
    _, raw = simulate([Case(0, 'inverse_adaptive', sc)], 5.0, record=True)
    assert np.max(np.abs(run.q - raw.q_measured[k, 0])) > 1e-5  # the observer reached the memory


@pytest.mark.parametrize('mode', ['pid', 'inverse_adaptive'])
def test_graph_learning_the_tems_online_is_the_sweep_learning_them(mode: str) -> None:
    """tem_controller and hysteresis_compensator each run their own estimate of the TEMs (thermal_adaptation, used
    after 4 s here instead of 30) on the samples they take; the sweep runs one per wrist and hands the compensator's
    observer the TEM loop's: same TEM commands and measured angles to the last bit, and not the loop without it.
    The reference starts at its first value (no soft start): in the first 10 s of a soft start pid's commands sit
    at the drive limits, where no estimate can change them."""
    from sma_wrist.closed_loop import run_closed_loop
    from sma_wrist.core.thermal.online import OnlineThermalParams
    from sma_wrist.sweep.simulate import Case, simulate

    sc = PERTURBED
    early = {'thermal_adaptation.apply_after_s': 4.0}
    extra = {
        '/plant_sim': {
            'plant': 'sdgpi',
            'scenario.noise_seed': sc.noise_seed,
            **{f'scenario.{k}': v for k, v in sc.to_dict().items() if k not in ('payload_kg', 'noise_seed')},
        },
        '/tem_controller': early,
        '/hysteresis_compensator': early,
        '/trajectory_generator': {'soft_start_s': 0.0},
    }
    with tempfile.TemporaryDirectory() as d:
        run = run_closed_loop(mode, sc.payload_kg, 10.0, Path(d) / 'bag', extra_params=extra).run
    _, tr = simulate(
        [Case(0, mode, sc)], 10.0, record=True, online_thermal=OnlineThermalParams(apply_after_s=4.0), soft_start_s=0.0
    )
    k, kc = np.rint(run.t / 0.01).astype(int), np.rint(run.command_t / 0.01).astype(int)
    assert np.max(np.abs(run.q - tr.q_measured[k, 0])) <= 1e-12
    np.testing.assert_array_equal(run.command_V, tr.command_V[kc, 0])
    _, off = simulate([Case(0, mode, sc)], 10.0, record=True, online_thermal=None, soft_start_s=0.0)
    assert np.max(np.abs(off.command_V[kc, 0] - run.command_V)) > 1e-3  # the estimate reached the commands


def test_graph_runs_the_phase_fraction_wrist_and_the_sweep_is_the_graph() -> None:
    """plant_sim ``plant:=phase_fraction`` (the structurally different wire, its own thermocouple lag
    plus the scenario's sensor noise) in the node graph for 4 s; the sweep's loop on the same plant and
    scenario gives the same measured angles and TEM commands to the last bit."""
    from sma_wrist.closed_loop import run_closed_loop
    from sma_wrist.plants import make_plant
    from sma_wrist.sweep.simulate import Case, simulate

    sc = Scenario(payload_kg=0.3, transition_shift_C=-3.0, temp_noise_C=0.1, angle_noise_rad=0.002, noise_seed=3)
    extra = {
        '/plant_sim': {
            'plant': 'phase_fraction',
            'scenario.noise_seed': sc.noise_seed,
            **{f'scenario.{k}': v for k, v in sc.to_dict().items() if k not in ('payload_kg', 'noise_seed')},
        }
    }
    with tempfile.TemporaryDirectory() as d:
        run = run_closed_loop('inverse_adaptive', sc.payload_kg, 4.0, Path(d) / 'bag', extra_params=extra).run
    assert run.t[-1] >= 3.9 and np.isfinite(run.q).all()
    rows, tr = simulate([Case(0, 'inverse_adaptive', sc)], 4.0, plant='phase_fraction', record=True)
    k = np.rint(run.t / 0.01).astype(int)
    assert np.max(np.abs(run.q - tr.q_measured[k, 0])) <= 1e-12
    kc = np.rint(run.command_t / 0.01).astype(int)
    np.testing.assert_array_equal(run.command_V, tr.command_V[kc, 0])
    # not the project's plant: the same scenario on the SD-GPI wrist moves differently
    _, sd = simulate([Case(0, 'inverse_adaptive', sc)], 4.0, plant='sdgpi', record=True)
    assert np.max(np.abs(sd.q[:, 0] - tr.q[:, 0])) > 1e-2
    # the scenario's plant axes reach this wire's own parameters
    pf = make_plant('phase_fraction', [sc, Scenario()])
    assert pf.params.dt == 1e-3
    assert pf.pf_params[0].wire.A_s_C == pf.pf_params[1].wire.A_s_C - 3.0
    with pytest.raises(ParameterError, match='unknown option'):
        make_plant('phase_fraction', [sc], None, bogus=1)
