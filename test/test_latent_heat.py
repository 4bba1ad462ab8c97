"""The wires' latent heat in the model's heat balance (Eq. P.4, PeltierParams.latent_C): the diagnosis' replay and
commissioning's refit of the Peltier form, against the emulated phase-fraction wrist (sma_wrist/plants/
phase_fraction.py), which releases its wires' latent heat into the muscle nodes; its own TEM and wire values in the
model's Peltier form and phase-fraction wire."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from sma_wrist.core.hysteresis.phase_fraction import PhaseFractionWire
from sma_wrist.core.plant.wrist import PlantParams
from sma_wrist.core.thermal import peltier as pe
from sma_wrist.diagnose import effects as fx
from sma_wrist.diagnose.data import Run
from sma_wrist.plants.phase_fraction import ScenarioPhaseFraction
from sma_wrist.plants.spread import Scenario

DT = 0.01
LAG_S = 0.2  # the emulator's thermocouple lag


def _emulate(period_s: float = 40.0, seconds: float = 80.0, heat_V: float = 20.0, cool_V: float = -12.0):
    """An open-loop run of the emulator (1 ms steps, commands held over 10 ms samples) heating each muscle in turn,
    each half ``period_s``: (run with its lagged, noise-free thermocouples, the true fractions, the plant)."""
    K = int(seconds / DT) + 1
    t = np.arange(K) * DT
    first = (t // (period_s / 2)) % 2 == 0
    u = np.stack([np.where(first, heat_V, cool_V), np.where(first, cool_V, heat_V)], axis=1)
    plant = ScenarioPhaseFraction([Scenario(payload_kg=0.45)], PlantParams(dt=DT / 10), tc_lag_s=LAG_S)
    plant.advance(np.zeros((1, 2)), 2000)  # its thermocouples start off their nodes: 2 s at rest to meet them
    s = plant.state
    Tc, faces, xi, q = np.empty((K, 2)), np.empty((K, 2)), np.empty((K, 2)), np.empty(K)
    for k in range(K):
        if k:
            plant.advance(u[k - 1][None], 10)
        Tc[k], faces[k], xi[k], q[k] = s.thermocouple[0], s.thermal[0, :, 1], plant.martensite_fraction[0], s.q[0]
    run = Run(t=t, dt=DT, u=u, T=Tc, q=q, payload_kg=0.45, thermal_x0=np.stack([Tc[0], faces[0]], 1))
    run.thermal_start = 'measured'
    run.faces = faces  # the exchanger faces [degC], as a bag's face thermocouples read them
    return run, xi, plant


@pytest.fixture(scope='module')
def emulated():
    """Both muscles' wires transformed in turn."""
    return _emulate()


def model_of(plant, latent_C=None, wire=True) -> PlantParams:
    """The emulator's TEMs in the Peltier form (its resistance scaled to the form's, Eq. P.1-P.3's invariance) and
    its wire as the model's phase-fraction wire; latent_C default: its own, H m / C_m [degC]."""
    p = plant.pf_params[0]
    w, tem, g = p.wire, p.tem, p.muscle
    a = tem.resistance_ohm / pe.DATASHEET_RESISTANCE_OHM
    layer = pe.PeltierLayer(
        seebeck_V_per_K=tem.seebeck_V_per_K,
        conductance_W_per_K=tem.conductance_W_per_K * a,
        muscle_capacity_J_per_K=tem.muscle_capacity_J_per_K * a,
        exchanger_capacity_J_per_K=tem.exchanger_capacity_J_per_K * a,
        muscle_loss_W_per_K=tem.muscle_loss_W_per_K * a,
        exchanger_loss_W_per_K=tem.exchanger_loss_W_per_K * a,
        ambient_C=tem.ambient_C,
        coolant_C=tem.coolant_C,
    )
    if latent_C is None:
        mass = g.n_wires * g.wire_area_m2 * g.wire_length_mm * 1e-3 * w.density_kg_m3
        latent_C = (w.latent_J_per_kg * mass / tem.muscle_capacity_J_per_K,) * 2
    keys = {f.name for f in dataclasses.fields(PhaseFractionWire)} & {f.name for f in dataclasses.fields(w)}
    pfw = PhaseFractionWire(**{k: getattr(w, k) for k in keys}, offset_mm=0.0, law='brinson')
    return PlantParams(
        dt=DT, heat_balance=pe.PeltierParams(layers=(layer, layer), latent_C=latent_C), wire=pfw if wire else None
    )


def model(run, params) -> fx.ExtendedModel:
    nominal = fx.NOMINAL.copy()
    nominal[fx.INDEX['temp_lag_s']] = LAG_S
    return fx.ExtendedModel(run, params, nominal=nominal)


def rms(m: fx.ExtendedModel) -> np.ndarray:
    """Per thermocouple RMS [degC] of the nominal thermal replay against the readings, after 5 s."""
    err = m.thermal_measured(m.nominal[None])[:, 0] - m.run.T
    return np.sqrt((err[500:] ** 2).mean(axis=0))


def test_the_replay_with_latent_heat_reproduces_an_emulated_run_that_has_it(emulated) -> None:
    run, xi, plant = emulated
    assert xi.min() < 0.1 and xi.max() > 0.99  # both wires transform (the latent heat acts)
    with_latent = model(run, model_of(plant))
    without = model(run, model_of(plant, latent_C=(0.0, 0.0)))
    # the fractions from the replay on the lagged readings are the emulator's
    np.testing.assert_allclose(with_latent.latent_fraction(), xi, atol=0.01)
    assert without.latent_fraction() is None
    e_with, e_without = rms(with_latent), rms(without)
    # measured: 0.0066/0.0065 degC with it, 0.34/0.12 without (the emulator integrates at 1 ms, the replay at 10)
    assert np.all(e_with < 0.015), e_with
    assert np.all(e_without > 10 * e_with), (e_without, e_with)


def test_the_replay_without_latent_heat_is_unchanged_bit_for_bit(emulated) -> None:
    run, _, plant = emulated
    rows = np.stack([fx.NOMINAL] * 2)
    rows[1, fx.INDEX['tem_gain_err']] = 0.1
    rows[:, fx.INDEX['temp_lag_s']] = LAG_S
    free = model(run, model_of(plant, latent_C=(0.0, 0.0))).thermal_true(rows)
    # an SD-GPI wire has no fraction to carry a latent heat: the replay leaves it out
    sdgpi = model(run, model_of(plant, latent_C=(0.8, 0.8), wire=False))
    assert sdgpi.latent_fraction() is None
    np.testing.assert_array_equal(sdgpi.thermal_true(rows), free)
    # the latent heat of one muscle's node moves only that node (the form's muscle-muscle coupling is 0 here)
    one = model(run, model_of(plant, latent_C=(0.0, 0.8))).thermal_true(rows)
    np.testing.assert_array_equal(one[:, :, 0], free[:, :, 0])
    assert np.abs(one[:, :, 1] - free[:, :, 1]).max() > 0.2


def test_commissioning_refits_the_heat_balance_with_the_latent_heat_and_hands_it_over(tmp_path, monkeypatch):
    from sma_wrist.commission import refine as rf
    from sma_wrist.commission.identification import (
        MECH_DT_S,
        THERMAL_DT_S,
        FractionFit,
        HeatBalanceRefinement,
        WireRefinement,
    )
    from sma_wrist.core.hysteresis.wire_file import save_wire_file
    from sma_wrist.core.joint.dynamics import JointParams
    from sma_wrist.core.thermal import identification as ti
    from sma_wrist.core.thermal.params_file import load_heat_balance_file, write_heat_balance_file
    from sma_wrist.diagnose import data

    # the excitation: slow relays; the defaults run and, held out, the commissioned run: faster ones, all through
    # the transformations
    exc, _, plant = _emulate(40.0, 120.0)
    runs = {'defaults': _emulate(30.0, 90.0, 19.0, -11.0)[0], 'commissioned': _emulate(24.0, 72.0, 18.0, -10.0)[0]}
    truth = model_of(plant)
    # handed over first: the emulator's own form without the latent heat (what it leaves out is the test)
    first_hb = dataclasses.replace(truth.heat_balance, latent_C=(0.0, 0.0))
    hb_file = write_heat_balance_file(tmp_path / 'heat_balance.yaml', first_hb)
    wire_file = save_wire_file(tmp_path / 'wire.yaml', truth.wire)
    params = tmp_path / 'wrist_params.yaml'
    coulomb = JointParams().coulomb_Nm
    params.write_text(
        'plant_sim:\n  ros__parameters:\n    wire_file: wire.yaml\n    heat_balance_file: heat_balance.yaml\n'
        f'    payload_kg: 0.45\n    model.temp_lag_s: {LAG_S}\n    model.coulomb_Nm: {coulomb}\n'
    )
    # the excitation's records on commissioning's grids (the relays switch on both): thermal 0.25 s, angle 0.05 s
    i_rec = np.arange(0, exc.n - 1, int(round(THERMAL_DT_S / DT)))
    records = [
        ti.ThermalRecord(
            f'fit, TEM {m + 1}', THERMAL_DT_S, exc.u[i_rec, m], np.c_[exc.T[i_rec, m], exc.faces[i_rec, m]], layer=m
        )
        for m in (0, 1)
    ]
    i_mech = np.arange(0, exc.n, int(round(MECH_DT_S / DT)))
    mech = Run(t=exc.t[i_mech], dt=MECH_DT_S, u=None, T=exc.T[i_mech], q=exc.q[i_mech], payload_kg=0.45)
    fit = FractionFit(truth.wire, coulomb, 0.45, 0.0, [], LAG_S)
    rest = tuple(float(x) for x in pe.rest_state(first_hb, 1)[0, 0])
    ctx = WireRefinement(mech, 0, mech.n, fit, {}, 0.2, wire_file, 0.0)
    ctx.thermal = HeatBalanceRefinement(records, [0.0, 0.0], rest, 0.01, hb_file, first_hb)
    # the runs as their bags: the muscle thermocouples, the drive and the exchanger faces' thermocouples
    import sma_wrist.bag

    monkeypatch.setattr(data, 'load_run', lambda bag: runs[bag])
    monkeypatch.setattr(sma_wrist.bag, 'read_bag', lambda path, topics=None: {'bag': str(path)})
    monkeypatch.setattr(
        data, 'face_series', lambda d, w: [(runs[d['bag']].t, runs[d['bag']].faces[:, m]) for m in (0, 1)]
    )

    res = rf.refine_heat_balance(ctx, fit, 'commissioned', 'defaults', 5.0, params)
    h = res['heldout']
    assert res['refined'], res
    # the emulator's 0.777 degC per full transformation, found through its 0.2 s thermocouple lag (measured: 0.7765,
    # 0.7789; held out 0.0056/0.0057 degC RMS against 0.13/0.035 without the latent heat)
    np.testing.assert_allclose(res['latent_C'], 0.777, atol=0.01)
    assert max(h['latent']) < 0.3 * min(h['first']), h
    handed = load_heat_balance_file(hb_file)
    assert handed.latent_C == pytest.approx(res['latent_C'], abs=1e-4)

    # handed over its own form with the latent heat, the refit is no better beyond the noise: nothing rewritten
    before = write_heat_balance_file(hb_file, truth.heat_balance).read_text()
    ctx.thermal = HeatBalanceRefinement(records, [0.0, 0.0], rest, 0.01, hb_file, truth.heat_balance)
    res = rf.refine_heat_balance(ctx, fit, 'commissioned', 'defaults', 5.0, params)
    assert not res['refined'] and 'stays' in res['why'], res
    assert hb_file.read_text() == before
