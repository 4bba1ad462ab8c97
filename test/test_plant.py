"""The coupled plant: joint range and capacity, step-size convergence, typed errors, flags,
and the equivalence of the batched, per-sample and plain-reference paths (doc/explanation/model.md)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sma_wrist.core.errors import ModelInputError
from sma_wrist.core.plant.preload import reachable_window, swing_range
from sma_wrist.core.plant.wrist import PlantParams, WristPlant
from sma_wrist.core.thermal import heat_balance as th

Q_LOW, Q_HIGH = 0.0, 1.048  # q_d = 0.524 +- 0.524 rad (Sec. 6.1)


def tem_window() -> tuple[float, float]:
    """Muscle temperatures the TEM reaches when held at its command limits (thermal model)."""
    return reachable_window(th.ThermalParams())


def swing(payloads: np.ndarray, T_lo: float, T_hi: float) -> tuple[np.ndarray, np.ndarray]:
    """Angle range (min, max) after the first half cycle of slow antagonistic temperature swings.

    A 10 s period: within 3.5e-4 rad of doc/explanation/model.md's 60 s at 0-0.75 kg (the margins tested are >= 6e-3 rad),
    at a sixth of the time."""
    return swing_range(PlantParams(), payloads, T_lo, T_hi, period_s=10.0)


def test_range_and_capacity_in_the_tem_window() -> None:
    """+-30 deg reachable quasi-statically at 0.6 kg (0.09 m), not at 0.75 kg (capacity ~0.7 kg)."""
    lo, hi = tem_window()
    assert 19.0 < lo < 22.0 and 76.0 < hi < 79.0
    q_min, q_max = swing(np.array([0.0, 0.3, 0.6, 0.75]), lo, hi)
    assert np.all(q_min[:3] <= Q_LOW) and np.all(q_max[:3] >= Q_HIGH)
    assert q_max[3] < Q_HIGH
    # heavier payloads reach less far up
    assert np.all(np.diff(q_max) < 0)


def trajectory(dt: float, mode: str) -> tuple[np.ndarray, np.ndarray]:
    """126 s run, sampled every 0.01 s: open loop under TEM voltages, or prescribed temperatures.

    The open-loop drive is one slow, nearly square cycle (the muscles reach ~20-60 degC and
    the joint swings ~0.2 rad; a 62.83 s sine of the same amplitude moves it by only 0.01 rad,
    the TEM time constant being ~40 s). The prescribed cycle is 30-76 degC, period 62.83 s.
    """
    plant = WristPlant(PlantParams(dt=dt), payload_kg=[0.3, 0.6])
    k_per_sample = int(round(0.01 / dt))
    n_samples = int(round(126.0 / 0.01))
    out = np.empty((n_samples, plant.n))
    T = np.empty((plant.n, 2))
    u = np.empty((plant.n, 2))
    k = 0
    for j in range(n_samples):
        for _ in range(k_per_sample):
            k += 1
            t = k * dt
            if mode == 'tem':
                u[:, 0] = 12.5 * math.tanh(3.0 * math.sin(2.0 * math.pi * t / 126.0))
                u[:, 1] = -u[:, 0]
                plant.step(u)
            else:
                ph = 0.5 * (1.0 - math.cos(2.0 * math.pi * t / 62.83))
                T[:, 0] = 30.0 + 46.0 * ph
                T[:, 1] = 30.0 + 46.0 * (1.0 - ph)
                plant.step_mechanics(T)
        out[j] = plant.state.q
    return out, plant.muscle_temperature_C


@pytest.mark.parametrize('mode', ['tem', 'temperature'])
def test_halving_the_step_changes_a_126_s_run_by_less_than_1_percent(mode: str) -> None:
    coarse, _ = trajectory(1e-2, mode)
    fine, _ = trajectory(5e-3, mode)
    span = fine.max(axis=0) - fine.min(axis=0)
    assert np.all(span > (0.15 if mode == 'tem' else 0.5))  # the run really swings the joint
    assert np.max(np.abs(coarse - fine) / span) < 0.01


def test_batched_equals_per_sample() -> None:
    payloads = np.array([0.0, 0.25, 0.5, 0.7])
    batched = WristPlant(PlantParams(), payload_kg=payloads)
    singles = [WristPlant(PlantParams(), payload_kg=m) for m in payloads]
    rng = np.random.default_rng(1)
    u = np.zeros((payloads.size, 2))
    for k in range(1500):
        if k % 100 == 0:
            u = rng.uniform(-14.0, 14.0, u.shape)
        batched.step(u)
        for i, s in enumerate(singles):
            s.step(u[i : i + 1])
    q_single = np.array([s.state.q[0] for s in singles])
    load_single = np.array([s.state.load_kgf for s in singles])
    np.testing.assert_allclose(batched.state.q, q_single, rtol=0, atol=1e-9)
    np.testing.assert_allclose(batched.state.load_kgf.reshape(2, -1).T, load_single, rtol=0, atol=1e-7)


def test_load_solve_residual_below_tolerance() -> None:
    params = PlantParams()
    plant = WristPlant(params, payload_kg=[0.1, 0.6])
    tol = params.load_tolerance_mm
    for k in range(3000):
        a = 13.0 * math.sin(2.0 * math.pi * k * 1e-3 / 1.5)
        q_solved = plant.state.q.copy()  # the loads are solved at the angle the step starts from
        plant.step([[a, -a], [-a, a]])
        if k % 250 == 0:
            s = plant.state
            x = params.joint.chain_displacement_mm(q_solved)
            y_geo = np.concatenate([params.preload_elongation_mm - x, params.preload_elongation_mm + x])
            # the relation at the committed memory and the solved load must give the geometry back
            y, dy = plant.muscles.elongation(s.T_prev, s.load_kgf, s.w, s.heating)
            assert np.max(np.abs(y - y_geo)) <= tol
            assert dy.min() > 0


def test_matches_plain_reference() -> None:
    """The numpy plant and the pure-Python reference of sma_wrist.bench agree (same model twice)."""
    from sma_wrist.bench import PlainWrist

    plant = WristPlant(PlantParams(), payload_kg=0.4)
    ref = PlainWrist(PlantParams(), payload_kg=0.4)
    for k in range(2000):
        a = 13.0 * math.sin(2.0 * math.pi * k * 1e-3 / 1.0)
        plant.step([[a, -a]])
        ref.step(a, -a)
    assert abs(plant.state.q[0] - ref.q) < 1e-8
    assert abs(plant.muscle_temperature_C[0, 0] - ref.T1) < 1e-9


# ------------------------------------------------------------------ errors and flags


@pytest.mark.parametrize('bad', [math.nan, math.inf, -math.inf])
def test_non_finite_command_raises_naming_it(bad: float) -> None:
    plant = WristPlant()
    with pytest.raises(ModelInputError, match='TEM command') as e:
        plant.step([[bad, 0.0]])
    assert 'finite' in str(e.value)


@pytest.mark.parametrize('bad', [math.nan, math.inf])
def test_non_finite_temperature_raises(bad: float) -> None:
    plant = WristPlant()
    with pytest.raises(ModelInputError, match='muscle temperature'):
        plant.step_mechanics([[30.0, bad]])


@pytest.mark.parametrize('bad', [-0.1, 2.5])
def test_bad_payload_raises_with_range(bad: float) -> None:
    with pytest.raises(ModelInputError, match=rf'payload = {bad} kg .*\[0, 2\]'):
        WristPlant(payload_kg=bad)


@pytest.mark.parametrize('bad', [math.nan, math.inf])
def test_non_finite_payload_raises(bad: float) -> None:
    with pytest.raises(ModelInputError, match=r'payload = (nan|inf) kg .*finite'):
        WristPlant(payload_kg=bad)


@pytest.mark.parametrize('bad', [0.0, -1e-3, 0.02, math.nan, math.inf])
def test_bad_dt_raises_with_range(bad: float) -> None:
    with pytest.raises(ModelInputError, match=r'dt .*\(0, 0.01\]'):
        PlantParams(dt=bad)


def test_saturation_is_flagged_not_silent() -> None:
    plant = WristPlant(payload_kg=[0.3, 0.3])
    limit = plant.params.thermal.u_max_V  # the driver rating (doc/explanation/model.md)
    s = plant.step([[limit + 1.0, 0.0], [5.0, -5.0]])
    assert s.flags['command_saturated'].tolist() == [True, False]
    s = plant.step([[5.0, -5.0], [5.0, -5.0]])
    assert not s.flags['command_saturated'].any()


def test_over_temperature_is_flagged() -> None:
    plant = WristPlant(payload_kg=[0.3, 0.3])
    s = plant.step_mechanics([[95.0, 30.0], [60.0, 30.0]])
    assert s.flags['over_temperature'].tolist() == [True, False]
    s = plant.step_mechanics([[150.0, 30.0], [60.0, 30.0]])  # beyond the model window: clamped, flagged
    assert s.flags['over_temperature'][0] and np.isfinite(s.q).all()
