"""The oracle diagnosis (sma_wrist.plants.oracle): the closed loops given the plant's own models.

doc/explanation/controllers.md has the family's figures
(126 s); these are short runs that check each switch reaches what it names and nothing else.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sma_wrist.core.control.joint_controller import JointControllerParams
from sma_wrist.core.errors import ParameterError
from sma_wrist.core.hysteresis.compensation import MuscleCompensator
from sma_wrist.core.hysteresis.default_params import default_sdgpi
from sma_wrist.plants import oracle
from sma_wrist.plants.loop import CASES, run_cases
from sma_wrist.plants.spread import Scenario, scenario_params
from sma_wrist.sweep.laws import JointControllerBank, TemLoopBank
from sma_wrist.sweep.simulate import Case, simulate


def test_oracle_switches_are_validated() -> None:
    sc = Scenario()
    with pytest.raises(ParameterError, match="unknown switch.*'wire'"):
        simulate([Case(0, 'pid', sc)], 1.0, oracle=('wire',))
    with pytest.raises(ParameterError, match='not the string'):
        simulate([Case(0, 'pid', sc)], 1.0, oracle='thermal')
    with pytest.raises(ParameterError, match='one model per plant'):
        simulate([Case(0, 'pid', sc), Case(1, 'pid', Scenario(transition_shift_C=5.0))], 1.0, oracle=('thermal',))
    with pytest.raises(ParameterError, match='sdgpi'):
        simulate([Case(0, 'pid', sc)], 1.0, plant='phase_fraction', oracle=('sensors',))


def test_oracle_models_are_the_plants_own() -> None:
    """The compensator inverts exactly the SD-GPI the plant steps and learns nothing; the TEM bank integrates
    exactly the plant's heat balance (TEM gain, losses, ambient) with the law's command limits."""
    sc = Scenario(
        transition_shift_C=-7.0, stroke_scale=1.2, tem_gain_scale=0.75, heat_loss_scale=1.25, ambient_offset_C=4.0
    )
    own = scenario_params(sc)
    built_tem = TemLoopBank.like_node(3)
    tem = oracle.own_tem_bank(built_tem, sc)
    for law, limits in ((tem.thermal, built_tem.thermal), (tem.hold, built_tem.hold)):
        assert law.input_per_volt == own.thermal.input_per_volt == 0.75 * built_tem.thermal.input_per_volt
        assert law.muscle_face == own.thermal.muscle_face and law.effective_ambient_C == own.thermal.effective_ambient_C
        assert (law.u_min_V, law.u_max_V) == (limits.u_min_V, limits.u_max_V)
    assert tem.max_muscle_C == built_tem.max_muscle_C and tem.n == 3
    comp = oracle.own_compensator(MuscleCompensator(default_sdgpi(), shift_gain_per_s=2.0, stroke_gain_per_s=1.0), sc)
    h = own.hysteresis
    assert comp.params.k_f == h.k_f and comp.params.name == h.name
    for got, want in ((comp.params.envelopes.a, h.envelopes.a), (comp.params.c, h.c), (comp.params.d, h.d)):
        assert np.array_equal(got, want)
    assert comp.shift_gain_per_s == 0.0 and comp.stroke_gain_per_s == 0.0


def test_thermal_oracle_acts_only_where_the_heat_balance_differs() -> None:
    """The controllers' heat balance is the nominal plant's: there the TEM oracle is the as-built loop,
    bit-exact; with 30 % more losses and a 5 degC warmer ambient the loop changes (from 2.8 s on: the
    commands saturate while the muscles first heat)."""
    for sc, equal in ((Scenario(), True), (Scenario(heat_loss_scale=1.3, ambient_offset_C=5.0), False)):
        cases = [Case(0, 'inverse_adaptive', sc), Case(1, 'pid', sc)]
        a, b = (simulate(cases, 4.0, record=True, oracle=o)[1] for o in ((), ('thermal',)))
        assert a is not None and b is not None
        assert np.array_equal(a.command_V, b.command_V) == equal
        if equal:
            assert np.array_equal(a.q, b.q)


def test_payload_oracle_reaches_the_adaptive_law_only() -> None:
    """The inverse loop has no payload model (its compensator takes the desired strain and the measured
    stress): a known payload leaves it bit-exact; the adaptive law's forces (direct_adaptive's) change."""
    sc = Scenario(payload_kg=0.55)
    a, b = (simulate([Case(0, 'inverse_adaptive', sc)], 3.0, record=True, oracle=o)[1] for o in ((), ('payload',)))
    assert a is not None and b is not None
    assert np.array_equal(a.command_V, b.command_V) and np.array_equal(a.q, b.q)
    params = JointControllerParams(mode='direct_adaptive')
    known = oracle.knows_payload(params, 0.55)
    assert known.adaptive.theta0_kg == 0.55 and known.adaptive.gamma_a == 0.0
    forces = [
        JointControllerBank(p, 1).update(np.array([0.6]), np.full(1, 0.1), 0.6, 0.1, 0.0, 0.01)[0]
        for p in (params, known)
    ]
    assert not np.allclose(forces[0], forces[1])


def test_sensors_oracle_reads_the_true_angle() -> None:
    """On noisy sensors the measured angle the controllers read is the true one (measured error = true
    error), and the loop changes; without the oracle they differ."""
    sc = CASES['sensors'](0.3).scenario
    as_built, true = (simulate([Case(0, 'pid', sc)], 3.0, window_s=2.0, oracle=o)[0][0] for o in ((), ('sensors',)))
    assert true['max_error_measured_pct'] == true['max_error_pct']
    assert as_built['max_error_measured_pct'] != as_built['max_error_pct']


def test_own_sdgpi_tracks_a_colder_wire_without_learning() -> None:
    """Transitions 10 degC lower: the compensator on the plant's own SD-GPI, adaptation off, tracks (7.7 %
    measured over the last 10 s of 25 s); the as-built compensator with its adaptation off does not (166 %).
    The reference starts at its first value: 25 s of a soft start would be the muscles' warm-up alone."""
    case = CASES['T-10'](0.3)
    own, blind = (
        run_cases(
            [(case, 'inverse_adaptive')],
            25.0,
            window_s=10.0,
            oracle=o,
            shift_gain_per_s=0.0,
            stroke_gain_per_s=0.0,
            soft_start_s=0.0,
        )[0].max_error_pct
        for o in (('hysteresis',), ())
    )
    assert own < 10.0
    assert blind > 50.0


def test_summary_counts_the_family_and_its_reachable_plants() -> None:
    rows = [
        {'group': 'spread', 'plant_index': i, 'variant': 'reach', 'reach_floor_pct': f}
        for i, f in enumerate((0.0, 2.0, 20.0))
    ]
    rows += [
        {
            'group': 'spread',
            'plant_index': i,
            'variant': v,
            'controller': 'inverse_adaptive',
            'max_error_pct': e,
            **Scenario().to_dict(),
        }
        for v, errs in (('as_built', (5.0, 12.0, 40.0)), ('all', (3.0, 6.0, 30.0)))
        for i, e in enumerate(errs)
    ]
    rows += [
        {
            'group': 'nominal',
            'plant_index': 0,
            'variant': 'as_built',
            'controller': 'inverse_adaptive',
            'max_error_pct': 2.5,
            **Scenario().to_dict(),
        }
    ]
    s = {r['variant']: r for r in oracle.summary(rows)}
    assert s['as_built']['median'] == 12.0 and s['as_built']['under_15'] == pytest.approx(2 / 3)
    assert s['as_built']['n_reachable'] == 2 and s['as_built']['median_reachable'] == 8.5
    assert s['all']['under_8_reachable'] == 1.0 and s['as_built']['nominal'] == [2.5]
    assert s['all']['nominal'] == []


def test_a_cut_results_file_is_named_not_read_as_data(tmp_path: Path) -> None:
    path = tmp_path / 'oracle.jsonl'
    path.write_text('{"group": "spread", "plant_index": 0, "variant": "reach", "reach_floor_pct": 1.0}\n{"group": "spr')
    with pytest.raises(ParameterError, match=r'oracle.jsonl:2: not a JSON row'):
        oracle.load(path)
    path.write_text('[1, 2]\n')
    with pytest.raises(ParameterError, match=r':1: not a row'):
        oracle.load(path)
