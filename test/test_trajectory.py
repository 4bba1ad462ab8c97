"""Trajectory generators: seed values, analytic derivatives vs finite differences, validation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sma_wrist.core.control import trajectory as tj
from sma_wrist.core.errors import ModelInputError, ParameterError

CASES = [
    ('sine', {}),
    ('sine', {'offset_rad': 0.5, 'amplitude_rad': 0.3, 'omega_rad_s': 0.7, 'phase_rad': 1.0}),
    ('step', {'initial_rad': 0.1, 'final_rad': 0.9, 't_step_s': 2.0, 'rise_time_s': 3.0}),
    ('step', {'initial_rad': 0.9, 'final_rad': 0.2, 't_step_s': 1.0, 'rise_time_s': 0.5}),
    ('ramp', {'start_rad': 0.2, 'end_rad': 0.8, 'rate_rad_s': 0.1, 't_start_s': 1.0}),
    ('sine_sweep', {'omega0_rad_s': 0.1, 'omega1_rad_s': 2.0, 'duration_s': 10.0, 'amplitude_rad': 0.4}),
    ('constant', {'value_rad': 0.3}),
]


def test_default_is_the_sec_6_1_sine() -> None:
    t = np.array([0.0, 5 * math.pi, 10 * math.pi, 15 * math.pi])  # 0.1 t = 0, pi/2, pi, 3pi/2
    q, qd, qdd = tj.make_trajectory()(t)
    np.testing.assert_allclose(q, [0.524, 1.048, 0.524, 0.0], atol=1e-12)
    np.testing.assert_allclose(qd, [0.0524, 0.0, -0.0524, 0.0], atol=1e-12)
    np.testing.assert_allclose(qdd, [0.0, -0.00524, 0.0, 0.00524], atol=1e-12)
    assert tj.Sine().period_s == pytest.approx(62.83185307)


@pytest.mark.parametrize('name,kw', CASES)
def test_derivatives_match_central_differences(name: str, kw: dict) -> None:
    traj = tj.make_trajectory(name, **kw)
    t = np.linspace(-1.0, 15.0, 3203)
    h = 1e-5
    q, qd, qdd = traj(t)
    qp, qdp, _ = traj(t + h)
    qm, qdm, _ = traj(t - h)
    # skip samples within h of a kink (ramp corners, step start/end, sweep ends)
    kinks = {
        'step': [kw.get('t_step_s', 0), kw.get('t_step_s', 0) + kw.get('rise_time_s', 0)],
        'ramp': [kw.get('t_start_s', 0), kw.get('t_start_s', 0) + 6.0],
        'sine_sweep': [0.0, kw.get('duration_s', 0)],
    }.get(name, [])
    ok = np.ones_like(t, bool)
    for tk in kinks:
        ok &= np.abs(t - tk) > 3 * h
    np.testing.assert_allclose(qd[ok], ((qp - qm) / (2 * h))[ok], atol=1e-6)
    np.testing.assert_allclose(qdd[ok], ((qdp - qdm) / (2 * h))[ok], atol=1e-5)
    assert q.shape == qd.shape == qdd.shape == t.shape


def test_vectorised_shapes_and_scalar() -> None:
    traj = tj.make_trajectory('sine')
    q, _, _ = traj(np.zeros((4, 3)))
    assert q.shape == (4, 3)
    q0, qd0, qdd0 = traj(0.0)
    assert np.ndim(q0) == 0 and float(qd0) == pytest.approx(0.0524)


def test_step_smoothing_bounds_and_endpoints() -> None:
    s = tj.Step(initial_rad=0.2, final_rad=0.8, t_step_s=1.0, rise_time_s=2.0)
    t = np.linspace(0, 5, 50001)
    q, qd, qdd = s(t)
    assert q[0] == 0.2 and q[-1] == pytest.approx(0.8)
    assert np.all(np.diff(q) >= -1e-15)  # monotone for an upward step
    assert qd.max() == pytest.approx(1.875 * 0.6 / 2.0, rel=1e-4)  # quintic peak at the midpoint
    assert np.abs(qdd).max() == pytest.approx(5.7735 * 0.6 / 4.0, rel=1e-3)
    ideal = tj.Step(initial_rad=0.2, final_rad=0.8, t_step_s=1.0, rise_time_s=0.0)
    qi, qdi, _ = ideal(np.array([0.999, 1.0, 2.0]))
    np.testing.assert_array_equal(qi, [0.2, 0.8, 0.8])
    np.testing.assert_array_equal(qdi, [0.0, 0.0, 0.0])


def test_ramp_reaches_and_holds() -> None:
    r = tj.Ramp(start_rad=0.8, end_rad=0.2, rate_rad_s=0.1, t_start_s=1.0)
    q, qd, _ = r(np.array([0.0, 1.0, 4.0, 7.5, 20.0]))  # corners (t = 1, 7) are conventions
    np.testing.assert_allclose(q, [0.8, 0.8, 0.5, 0.2, 0.2])
    np.testing.assert_allclose(qd, [0.0, 0.0, -0.1, 0.0, 0.0])


def test_sweep_instantaneous_frequency() -> None:
    sw = tj.SineSweep(offset_rad=0.5, amplitude_rad=0.2, omega0_rad_s=1.0, omega1_rad_s=3.0, duration_s=10.0)
    # at the zero crossings of sin(psi) the rate is a * omega(t)
    t = np.array([0.0, 20.0])
    _, qd, _ = sw(t)
    psi_20 = 1.0 * 10 + 0.5 * 0.2 * 100 + 3.0 * 10  # continuous phase after the sweep
    np.testing.assert_allclose(qd, [0.2 * 1.0, 0.2 * 3.0 * math.cos(psi_20)], rtol=1e-12)


@pytest.mark.parametrize(
    'name,kw,fragment',
    [
        ('circle', {}, "'circle'"),
        ('sine', {'omega_rad_s': 0.0}, 'omega_rad_s = 0.0'),
        ('sine', {'amplitude_rad': float('nan')}, 'amplitude_rad = nan'),
        ('sine', {'offset_rad': 0.8}, '1.324'),  # leaves [0, 1.05]
        ('step', {'rise_time_s': -1.0}, 'rise_time_s = -1.0'),
        ('ramp', {'rate_rad_s': 0.0}, 'rate_rad_s'),
        ('sine_sweep', {'duration_s': 0.0}, 'duration_s'),
        ('constant', {'value_rad': -0.1}, '-0.1'),
        ('sine', {'frequency': 1.0}, 'frequency'),
    ],
)
def test_factory_validation_names_the_value(name: str, kw: dict, fragment: str) -> None:
    with pytest.raises(ParameterError) as ei:
        tj.make_trajectory(name, **kw)
    assert fragment in str(ei.value)


def test_angle_limits_parameter() -> None:
    with pytest.raises(ParameterError, match=r'\[0, 1.047\]'):
        tj.make_trajectory('sine', angle_limits_rad=(0.0, 1.047))  # the seed's sine peaks at 1.048
    tj.make_trajectory('sine', amplitude_rad=0.5, angle_limits_rad=(0.0, 1.047))
    with pytest.raises(ParameterError):
        tj.make_trajectory('sine', angle_limits_rad=(1.0, 0.0))


def test_non_finite_time_is_an_input_error() -> None:
    with pytest.raises(ModelInputError, match='t = nan'):
        tj.make_trajectory('sine')(np.array([0.0, np.nan]))


@pytest.mark.parametrize('shape', ['sine', 'step', 'sine_sweep'])
def test_a_soft_start_leaves_the_angle_at_rest_and_joins_the_shape_smoothly_and_exactly(shape: str) -> None:
    """SoftStart: q_d(0) is the start angle with zero rate and acceleration; rate and acceleration are the
    derivatives of the angle throughout (a blend, not a jump); from duration_s on it is the shape to the last bit;
    its bounds hold the start angle."""
    from sma_wrist.core.control.trajectory import SoftStart, make_trajectory

    base = make_trajectory(shape)
    soft = SoftStart(base, 0.08, 20.0)
    q, qd, qdd = soft(np.array([0.0, -1.0]))
    assert list(q) == [0.08, 0.08] and list(qd) == [0.0, 0.0] and list(qdd) == [0.0, 0.0]
    t = np.linspace(0.0, 40.0, 40001)
    q, qd, qdd = soft(t)
    np.testing.assert_allclose(np.gradient(q, t), qd, atol=1e-5)
    np.testing.assert_allclose(np.gradient(qd, t), qdd, atol=1e-4)
    after = t >= 20.0
    for a, b in zip(soft(t[after]), base(t[after])):
        np.testing.assert_array_equal(a, b)
    assert soft.bounds()[0] == min(0.08, base.bounds()[0]) and np.all(q >= soft.bounds()[0] - 1e-12)
    assert np.all(q <= soft.bounds()[1] + 1e-12)


def test_a_soft_start_takes_one_start_angle_per_wrist_and_zero_length_is_the_shape() -> None:
    """soft_start on an array of start angles (the sweep's loops) gives each loop what SoftStart gives one wrist."""
    from sma_wrist.core.control.trajectory import SoftStart, make_trajectory, soft_start

    base = make_trajectory('sine')
    starts = np.array([0.0, 0.08, 0.3])
    for t in (0.0, 3.7, 19.99, 20.0, 55.0):
        many = soft_start(base(t), t, starts, 20.0)
        for j, q0 in enumerate(starts):
            for a, b in zip(many, SoftStart(base, float(q0), 20.0)(t)):
                assert a[j] == b
    for a, b in zip(soft_start(base(3.0), 3.0, starts, 0.0), base(3.0)):
        assert np.array_equal(a, b)
    with pytest.raises(ParameterError, match='duration_s'):
        SoftStart(base, 0.1, -1.0)
