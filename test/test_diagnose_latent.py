"""The diagnosis' heat-balance replay with the wires' latent heat (Eq. P.4, PeltierParams.latent_C), against the
emulated phase-fraction wrist (sma_wrist/plants/phase_fraction.py), which releases its wires' latent heat into the
muscle nodes: its own TEM and wire values in the model's Peltier form and phase-fraction wire."""

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


@pytest.fixture(scope='module')
def emulated():
    """An open-loop run of the emulator (1 ms steps, commands held over 10 ms samples) that transforms both
    muscles' wires in turn: (run with its lagged, noise-free thermocouples, the true fractions, the plant)."""
    K = int(80.0 / DT) + 1
    t = np.arange(K) * DT
    first = (t // 20.0) % 2 == 0
    u = np.stack([np.where(first, 20.0, -12.0), np.where(first, -12.0, 20.0)], axis=1)
    plant = ScenarioPhaseFraction([Scenario(payload_kg=0.45)], PlantParams(dt=DT / 10), tc_lag_s=LAG_S)
    s = plant.state
    Tc, faces, xi, q = np.empty((K, 2)), np.empty((K, 2)), np.empty((K, 2)), np.empty(K)
    for k in range(K):
        if k:
            plant.advance(u[k - 1][None], 10)
        Tc[k], faces[k], xi[k], q[k] = s.thermocouple[0], s.thermal[0, :, 1], plant.martensite_fraction[0], s.q[0]
    run = Run(t=t, dt=DT, u=u, T=Tc, q=q, payload_kg=0.45, thermal_x0=np.stack([Tc[0], faces[0]], 1))
    run.thermal_start = 'measured'
    return run, xi, plant


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
    # measured: 0.0067/0.0063 degC with it, 0.33/0.23 without (the emulator integrates at 1 ms, the replay at 10)
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
