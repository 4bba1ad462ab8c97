"""The online estimate of the TEMs (core/thermal/online.py) on data it did not make.

The data come from the plant's heat balance with the family's perturbations (``plant_params``, the
plant's code, not the estimator's), driven by commands the estimator never chose, read through a
thermocouple the way a real one reads: a first-order junction lag and white noise.
"""

from __future__ import annotations

import numpy as np
import pytest

from sma_wrist.core.errors import ParameterError
from sma_wrist.core.thermal import heat_balance as th
from sma_wrist.core.thermal.kernel import thermal_constants
from sma_wrist.core.thermal.online import (
    OnlineThermalParams,
    ThermalScaleEstimator,
    scaled_constants,
    theta_of,
    with_scales,
)
from sma_wrist.plants.spread import Scenario, scenario_params

BASE = th.ThermalParams().with_limits(-24.0, 24.0)
DT = 0.01


def _thermocouple_run(
    thermal: th.ThermalParams, seconds: float, lag_s: float, noise_C: float, seed: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, T_meas (K, 2), u (K, 2)): both TEMs of one wrist under slow random square-ish commands (+-20 V,
    held 1-6 s), the plant's heat balance at 1 ms, a lagging noisy thermocouple sampled at 100 Hz."""
    rng = np.random.default_rng(seed)
    k = int(seconds / DT)
    u = np.empty((k, 2))
    for j in range(2):
        i = 0
        while i < k:
            n = int(rng.uniform(1.0, 6.0) / DT)
            u[i : i + n, j] = rng.uniform(-20.0, 20.0)
            i += n
    x = th.rest_state(thermal, 1)
    z = x[0, :, th.MUSCLE_FACE].copy()
    T = np.empty((k, 2))
    for i in range(k):
        T[i] = z + noise_C * rng.standard_normal(2)
        for _ in range(10):
            x = th.step(thermal, x, u[i][None], DT / 10, validate=False)
        z += DT / (lag_s + DT) * (x[0, :, th.MUSCLE_FACE] - z) if lag_s > 0 else x[0, :, th.MUSCLE_FACE] - z
    return np.arange(k) * DT, T, u


def test_the_scales_are_the_plants_perturbations_exactly():
    sc = Scenario(tem_gain_scale=0.8, heat_loss_scale=1.2, ambient_offset_C=3.0)
    plant = scenario_params(sc).thermal
    theta = theta_of(BASE, plant)
    np.testing.assert_allclose(theta, [0.8, 1.2, 3.0], atol=1e-12)
    np.testing.assert_allclose(scaled_constants(BASE, theta), thermal_constants(plant), rtol=0, atol=1e-15)
    np.testing.assert_allclose(thermal_constants(with_scales(BASE, theta)), thermal_constants(plant), atol=1e-15)


@pytest.mark.parametrize('truth', [(0.75, 1.25, 4.0), (1.25, 0.8, -3.0)])
def test_it_learns_a_weaker_or_stronger_tem_through_a_lagging_noisy_thermocouple(truth):
    plant = scenario_params(
        Scenario(tem_gain_scale=truth[0], heat_loss_scale=truth[1], ambient_offset_C=truth[2])
    ).thermal
    t, T, u = _thermocouple_run(plant, 100.0, lag_s=0.15, noise_C=0.2, seed=1)
    est = ThermalScaleEstimator(BASE, 1, OnlineThermalParams())
    u_now, T_now = np.empty((1, 2)), np.empty((1, 2))  # reused in place, as the TEM kernel reuses its command array
    for k in range(t.size):
        u_now[0], T_now[0] = u[k], T[k]
        est.sample(t[k], T_now, u_now)
    assert est.updates >= 45 and est.ready
    err = est.theta[0] - np.array(truth)
    assert abs(err[0]) < 0.03 and abs(err[1]) < 0.06 and abs(err[2]) < 1.5, est.theta
    assert np.all(np.abs(np.array(truth) - [1.0, 1.0, 0.0]) > [0.15, 0.15, 2.5])  # the start was far from it


def test_a_wrist_learns_the_same_alone_as_among_others_and_a_bad_sample_costs_one_window():
    runs = [
        _thermocouple_run(scenario_params(Scenario(tem_gain_scale=g)).thermal, 12.0, 0.1, 0.1, seed=s)
        for g, s in ((0.8, 2), (1.1, 3), (0.9, 4))
    ]
    many = ThermalScaleEstimator(BASE, 3)
    one = ThermalScaleEstimator(BASE, 1)
    for k in range(runs[0][0].size):
        many.sample(runs[0][0][k], np.stack([r[1][k] for r in runs]), np.stack([r[2][k] for r in runs]))
        one.sample(runs[1][0][k], runs[1][1][k][None], runs[1][2][k][None])
    assert one.updates == many.updates >= 4
    np.testing.assert_array_equal(one.theta[0], many.theta[1])  # bit for bit: tem_controller == the sweep
    before, n = one.theta.copy(), one.updates
    one.sample(12.0, np.array([[np.nan, 30.0]]), np.zeros((1, 2)))
    assert one.updates == n and np.array_equal(one.theta, before)


@pytest.mark.parametrize(
    'bad',
    [
        dict(window_s=0.0),
        dict(points=0),
        dict(avg_s=5.0),
        dict(tc_lag_s=-1.0),
        dict(prior_sd=(0.1, 0.1)),
        dict(max_step=(0.1, -0.1, 1.0)),
        dict(noise_sd_C=0.0),
        dict(apply_after_s=float('nan')),
    ],
)
def test_bad_settings_are_clear_errors(bad):
    with pytest.raises(ParameterError):
        OnlineThermalParams(**bad)


def test_the_compiled_window_is_the_numpy_window():
    """thermal.kernel.predict_junction (what every consumer runs with numba) against the numpy reference."""
    pytest.importorskip('numba')
    t, T, u = _thermocouple_run(scenario_params(Scenario(tem_gain_scale=0.8)).thermal, 3.0, 0.1, 0.1, seed=5)
    est = ThermalScaleEstimator(BASE, 1)
    for k in range(60):
        est.sample(t[k], T[k][None], u[k][None])
    theta = np.repeat(est.theta, 4, axis=0) + np.vstack([np.zeros(3), np.diag([0.02, 0.02, 0.5])])
    a, xa = est._predict(theta, compiled=True)
    b, xb = est._predict(theta, compiled=False)
    assert a.shape == b.shape == (len(est._t), 4, 2) and len(est._t) > 50
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-10)
    np.testing.assert_allclose(xa, xb, rtol=0, atol=1e-10)
    assert np.ptp(a[-1, :, 0]) > 1e-4  # the four scales predict four different junctions


def test_a_gap_or_tems_switched_off_between_samples_break_the_window():
    """Lost samples, or tem_controller's watchdog switching the TEMs off between samples: the commands the window
    recorded are not the ones that were in force, so the window is dropped, not fitted."""
    from sma_wrist.core.control.tem import DriveLimits, TemControlParams, TemLoop

    t, T, u = _thermocouple_run(scenario_params(Scenario(tem_gain_scale=0.8)).thermal, 6.0, 0.1, 0.1, seed=6)
    est = ThermalScaleEstimator(BASE, 1)
    for k in range(150):
        est.sample(t[k], T[k][None], u[k][None])
    assert len(est._t) > 100
    est.sample(t[150] + 1.0, T[150][None], u[150][None])  # 1 s without a sample
    assert est._t == [] and est.updates == 0
    loop = TemLoop(BASE, TemControlParams(), DriveLimits(), th.ThermalParams(), 85.0, online=OnlineThermalParams())
    for k in range(150):
        loop.sample(t[k], T[k], np.array([40.0, 40.0]))
    assert len(loop.estimator._t) > 100
    loop.off()
    assert loop.estimator._t == [] and not loop.command_V.any()


def test_a_stronger_tem_keeps_its_hot_faces_in_the_window_with_the_estimate_in_use() -> None:
    """doc/explanation/controllers.md: a family plant whose TEMs are 28 % stronger than the model (seed 1's
    plant 12), inverse mode, the first 40 s. The protection predicts the unmeasured exchanger faces with the
    loop's heat balance; on the model's gain (the estimate not yet used, apply_after_s 30 s) a face
    reached 93.8 degC and spent 15.5 s above the 80 degC window; with the estimate in use from 10 s (the default)
    the hottest face is 78.9 degC. simulate's rows report both (tem_face_max_C, tem_face_outside_s)."""
    from sma_wrist.plants.spread import sample
    from sma_wrist.sweep.simulate import Case, simulate

    sc = sample(40, seed=1)[12]  # the sweep's family (its parameters to the last digit: the loop is chaotic)
    assert sc.tem_gain_scale > 1.25
    now = simulate([Case(0, 'inverse_adaptive', sc)], 40.0)[0][0]
    late = simulate([Case(0, 'inverse_adaptive', sc)], 40.0, online_thermal=OnlineThermalParams(apply_after_s=30.0))[0][
        0
    ]
    assert now['tem_face_outside_s'] == 0.0 and now['tem_face_max_C'] < 80.0
    assert late['tem_face_outside_s'] > 5.0 and late['tem_face_max_C'] > 85.0
