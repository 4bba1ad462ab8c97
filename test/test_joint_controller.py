"""Mode composition of the joint controller (what adaptive_controller publishes)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sma_wrist.core.control.joint_controller import (
    REVERSAL_STEP_RAD,
    JointController,
    JointControllerParams,
    reference_ahead,
    time_to_meet,
    time_to_turn,
)
from sma_wrist.core.errors import ParameterError
from sma_wrist.core.plant.wrist import PlantParams


def test_desired_strain_follows_the_chain_kinematics():
    plant = PlantParams()
    jc = JointController(JointControllerParams(mode='pid'), plant)
    e0, L = plant.preload_elongation_mm, plant.muscle.wire_length_mm
    np.testing.assert_allclose(jc.strain_at(plant.joint.q_neutral_rad), [e0 / L, e0 / L])
    up = jc.strain_at(plant.joint.q_neutral_rad + 0.5)
    x = 1e3 * plant.joint.r_eff_m * 0.5
    np.testing.assert_allclose(up * L, [e0 - x, e0 + x])  # muscle 1 shortens as q grows


@pytest.mark.parametrize('mode', ['pid', 'direct_adaptive'])
def test_angle_below_reference_heats_muscle_1_and_cools_muscle_2(mode):
    jc = JointController(JointControllerParams(mode=mode))
    c = None
    for _ in range(5):
        c = jc.update(0.3, 0.0, 0.6, 0.0, 0.0, 0.01)
    assert c.temperature_desired_C[0] > 50.0 > c.temperature_desired_C[1]
    jc2 = JointController(JointControllerParams(mode=mode))
    for _ in range(5):
        d = jc2.update(0.9, 0.0, 0.6, 0.0, 0.0, 0.01)
    assert d.temperature_desired_C[0] < 50.0 < d.temperature_desired_C[1]


def test_inverse_mode_hands_forces_and_strain_to_the_compensator():
    jc = JointController(JointControllerParams(mode='inverse_adaptive'))
    c = jc.update(0.3, 0.0, 0.6, 0.0, 0.0, 0.01)
    assert c.temperature_desired_C is None
    assert c.force_N[0] > c.force_N[1]  # more pull on muscle 1 to raise q
    assert c.strain_desired.shape == (2,)


def test_temperature_requests_stay_in_the_window_and_saturation_is_reported():
    p = JointControllerParams(mode='pid', temperature_min_C=30.0, temperature_max_C=70.0)
    jc = JointController(p)
    c = jc.update(-0.3, 0.0, 1.0, 0.0, 0.0, 0.01)  # huge error
    assert c.saturated
    assert 30.0 <= c.temperature_desired_C.min() and c.temperature_desired_C.max() <= 70.0


def test_direct_mode_adapts_only_theta():
    jc = JointController(JointControllerParams(mode='direct_adaptive'))
    for _ in range(50):  # a small error: a saturated force would freeze all adaptation (anti-windup)
        c = jc.update(0.5999, 0.0, 0.6, 0.0, 0.0, 0.01)
    assert not c.saturated
    assert c.info['beta_hat_1'] == c.info['beta_hat_2'] == 1.0
    assert c.info['theta_hat_kg'] != 0.0


def test_time_to_turn_of_the_seed_sine_is_its_time_to_the_extremum():
    w, a = 0.1, 0.524
    for t_left in (0.5, 2.0, 2.75, 4.0):
        phase = math.pi / 2 - w * t_left  # t_left seconds before the top
        s = time_to_turn(a * w * math.cos(phase), -a * w * w * math.sin(phase))
        # the local parabola of a sine turns at tan(w t_left) / w: within 3 % of t_left up to 2.75 s
        assert s == pytest.approx(math.tan(w * t_left) / w, rel=1e-12)
        assert abs(s - t_left) < (0.03 * t_left if t_left <= 2.75 else 0.06 * t_left)
    assert time_to_turn(0.05, 0.0) == math.inf  # ramp: no turn
    assert time_to_turn(-0.05, -0.01) == math.inf  # moving away from the last turn


def test_time_to_meet_a_joint_on_behind_or_beyond_the_reference():
    qd, qdd = 0.02, -0.01  # rising, top in s* = 2 s, 0.02 rad above q_d
    s, after = time_to_meet(0.0, qd, qdd)
    assert s == pytest.approx(4.0) and after == -1.0  # on the reference: 2 s*, then downwards
    s, after = time_to_meet(0.5, qd, qdd)  # 0.5 rad behind: q_d turns and comes back to it later
    assert s == pytest.approx(2.0 + math.sqrt(2 * 0.52 / 0.01)) and after == -1.0
    s, after = time_to_meet(-0.05, qd, qdd)  # above the coming top: it turns there
    assert s == pytest.approx(4.0) and after == -1.0
    assert time_to_meet(0.1, 0.02, 0.0) == (math.inf, 0.0)  # a ramp running away from the joint
    s, after = time_to_meet(-0.1, 0.02, 0.0)  # a ramp catching up with a joint ahead of it
    assert s == pytest.approx(5.0) and after == 1.0


def test_joint_far_behind_is_not_held_at_the_turn_but_before_the_reference_comes_back():
    """From rest at 0.05 rad: the first top passes, the hold comes when q_d returns towards q."""
    jc = JointController(JointControllerParams(mode='inverse_adaptive', reversal_lead_s=2.75))
    q, held = 0.05, []
    for t in np.arange(0.0, 50.0, 0.01):
        q_d = 0.524 + 0.524 * math.sin(0.1 * t)
        jc.update(q, 0.0, q_d, 0.0524 * math.cos(0.1 * t), -0.00524 * math.sin(0.1 * t), 0.01)
        held.append((t, jc.hold is not None, q_d))
    t_held = [t for t, h, _ in held if h]
    assert min(t_held) > 5 * math.pi + 5.0  # not around the top at 15.7 s
    q_d_at_start = next(q_d for t, h, q_d in held if h)
    assert q_d_at_start - q < 0.35  # but on the way back, shortly before q_d reaches the joint


def _sine_run(lead_s, t_end=90.0, dt=0.01):
    """Inverse mode on the seed sine with the joint on the reference; (t, q_d, strain target) per sample."""
    jc = JointController(JointControllerParams(mode='inverse_adaptive', reversal_lead_s=lead_s))
    rows = []
    for t in np.arange(0.0, t_end, dt):
        q_d = 0.524 + 0.524 * math.sin(0.1 * t)
        c = jc.update(
            q_d, 0.0524 * math.cos(0.1 * t), q_d, 0.0524 * math.cos(0.1 * t), -0.00524 * math.sin(0.1 * t), dt
        )
        rows.append((t, q_d, c.strain_desired.copy(), jc.strain_at(q_d)))
    return rows


def test_reversal_lead_latches_a_target_past_the_angle_around_each_turn_only():
    lead = 2.75
    rows = _sine_run(lead)
    jc = JointController(JointControllerParams(mode='inverse_adaptive'))
    held = np.array([not np.allclose(s, s_qd) for _, _, s, s_qd in rows])
    t = np.array([r[0] for r in rows])
    turns = (5 * math.pi, 15 * math.pi)  # top at 15.7 s, bottom at 47.1 s
    for t_turn, after in zip(turns, (-1.0, 1.0)):
        near = (t > t_turn - 5) & (t < t_turn + 5)
        t_held = t[near & held]
        # starts when the parabola's time to the turn drops below the lead
        assert t_held.min() == pytest.approx(t_turn - math.atan(0.1 * lead) / 0.1, abs=0.015)
        assert t_held.max() > t_turn  # lasts until q_d has passed the hold point after the turn
        k = np.flatnonzero(near & held)[0]
        q_start = rows[k][1]
        # the held strain is that of an angle one step past q in the direction after the turn
        np.testing.assert_allclose(rows[k][2], jc.strain_at(q_start + after * REVERSAL_STEP_RAD), rtol=1e-9)
    assert not held[(t < turns[0] - lead) | ((t > turns[0] + 5) & (t < turns[1] - lead))].any()


def test_reversal_hold_releases_when_the_reference_only_slows_down_and_not_at_once_when_ahead():
    jc = JointController(JointControllerParams(mode='inverse_adaptive', reversal_lead_s=2.0))
    # rising towards a top 1 s ahead, the joint 0.015 rad above q_d: latched 0.01 below q, which
    # q_d has not reached yet -- but it has not turned either, so the hold stays
    c = jc.update(0.53, 0.0, 0.515, 0.02, -0.02, 0.01)
    assert jc.hold is not None
    np.testing.assert_allclose(c.strain_desired, jc.strain_at(0.53 - REVERSAL_STEP_RAD))
    c = jc.update(0.53, 0.0, 0.52, 0.01, -0.02, 0.01)
    np.testing.assert_allclose(c.strain_desired, jc.strain_at(0.53 - REVERSAL_STEP_RAD))
    # the reference re-accelerates upwards (an inflection, no turn): released, q_d again
    c = jc.update(0.53, 0.0, 0.525, 0.01, 0.02, 0.01)
    assert jc.hold is None
    np.testing.assert_allclose(c.strain_desired, jc.strain_at(0.525))


def test_reversal_lead_zero_is_the_strain_at_q_d_throughout():
    assert all(np.allclose(s, s_qd) for _, _, s, s_qd in _sine_run(0.0, t_end=50.0))


@pytest.mark.parametrize(
    'kw',
    [
        dict(mode='mpc'),
        dict(temperature_mid_C=90.0),
        dict(force_per_degC_N=0.0),
        dict(temperature_min_C=float('nan')),
        dict(reversal_lead_s=-1.0),
        dict(pid_reference_lead_s=-0.5),
        dict(direct_reference_lead_s=float('inf')),
        dict(pid_output_filter_s=-0.1),
        dict(pid_output_filter_s=float('nan')),
        dict(direct_output_filter_s=-0.1),
        dict(direct_output_filter_s=float('inf')),
    ],
)
def test_bad_parameters_are_refused(kw):
    with pytest.raises(ParameterError):
        JointControllerParams(**kw)


def test_reference_ahead_is_the_sine_ahead_and_each_mode_uses_its_own_lead():
    """reference_ahead on the Sec. 6.1 sine q_d = 0.524 (1 + sin(0.1 t)): the parabola 1.5 s ahead is
    the sine there to within the Taylor remainder. A pid / direct law with its lead equals the one without lead fed
    the reference ahead; the inverse mode ignores both leads (it has its reversal lead)."""
    a, w = 0.524, 0.1
    for t in (0.0, 7.0, 15.7, 40.0):
        q_d, qd, qdd = a + a * math.sin(w * t), a * w * math.cos(w * t), -a * w * w * math.sin(w * t)
        ahead, ahead_dot = reference_ahead(q_d, qd, qdd, 1.5)
        # Taylor remainders: a (w tau)^3 / 6 = 0.47 mrad and a w^3 tau^2 / 2 = 0.59 mrad/s
        assert ahead == pytest.approx(a + a * math.sin(w * (t + 1.5)), abs=a * (w * 1.5) ** 3 / 6)
        assert ahead_dot == pytest.approx(a * w * math.cos(w * (t + 1.5)), abs=a * w**3 * 1.5**2 / 2)
    for mode, lead in (('pid', 1.25), ('direct_adaptive', 1.0)):
        led = JointController(JointControllerParams(mode=mode))
        assert led.params.reference_lead_s == lead
        plain = JointController(JointControllerParams(mode=mode, pid_reference_lead_s=0.0, direct_reference_lead_s=0.0))
        for k in range(20):
            q, ref = 0.3 + 0.001 * k, (0.5, 0.05, -0.005)
            c = led.update(q, 0.0, *ref, 0.01)
            d = plain.update(q, 0.0, *reference_ahead(*ref, lead), ref[2], 0.01)
            np.testing.assert_array_equal(c.temperature_desired_C, d.temperature_desired_C)
            np.testing.assert_array_equal(c.strain_desired, led.strain_at(ref[0]))  # strain at q_d(t) still
    inv = [
        JointController(
            JointControllerParams(mode='inverse_adaptive', pid_reference_lead_s=x, direct_reference_lead_s=x)
        )
        for x in (0.0, 3.0)
    ]
    assert inv[1].params.reference_lead_s == 0.0
    for _ in range(20):
        c0, c1 = (jc.update(0.3, 0.0, 0.5, 0.05, -0.005, 0.01) for jc in inv)
        np.testing.assert_array_equal(c0.force_N, c1.force_N)


def test_pid_output_filter_is_a_first_order_lag_on_the_pid_output():
    """pid_output_filter_s = tau: after an error step the temperature request follows Kp e with
    1 - (tau / (tau + dt))^k (backward Euler); tau 0 gives the PID's output itself. No integral (ki 0) so the
    PID's own output is Kp e throughout."""
    from sma_wrist.core.control.pid import PIDParams

    pid = PIDParams(kp=300.0, ki=0.0, kd=0.0, output_min=-30.0, output_max=30.0)
    tau, dt = 0.3, 0.01
    lagged, plain = (
        JointController(JointControllerParams(mode='pid', pid=pid, pid_reference_lead_s=0.0, pid_output_filter_s=x))
        for x in (tau, 0.0)
    )
    for jc in (lagged, plain):
        for _ in range(10):
            jc.update(0.5, 0.0, 0.5, 0.0, 0.0, dt)
    for k in range(1, 31):
        c, d = lagged.update(0.5, 0.0, 0.52, 0.0, 0.0, dt), plain.update(0.5, 0.0, 0.52, 0.0, 0.0, dt)
        assert d.temperature_desired_C[0] == pytest.approx(50.0 + 6.0)
        assert c.temperature_desired_C[0] == pytest.approx(50.0 + 6.0 * (1 - (tau / (tau + dt)) ** k))
        assert c.temperature_desired_C[0] + c.temperature_desired_C[1] == pytest.approx(100.0)


def test_direct_output_filter_is_a_first_order_lag_on_the_temperature_map():
    """direct_output_filter_s = tau: after an error step the temperature request follows the map's
    T_mid + (F - F_pre) / k with 1 - (tau / (tau + dt))^k (backward Euler); tau 0 gives the map itself, bit for
    bit as before the filter existed. theta_hat frozen (gamma_a 0) so the law's force is constant after the step."""
    from dataclasses import replace

    from sma_wrist.core.control.joint_controller import tuned_adaptive

    law = replace(tuned_adaptive(), gamma_a=0.0)
    tau, dt = 0.1, 0.01
    lagged, plain = (
        JointController(
            JointControllerParams(
                mode='direct_adaptive', adaptive=law, direct_reference_lead_s=0.0, direct_output_filter_s=x
            )
        )
        for x in (tau, 0.0)
    )
    assert lagged.params.output_filter_s == tau and JointControllerParams(mode='pid').output_filter_s == 0.3
    for jc in (lagged, plain):
        for _ in range(10):
            jc.update(0.5, 0.0, 0.5, 0.0, 0.0, dt)
    for k in range(1, 31):
        c, d = lagged.update(0.5, 0.0, 0.55, 0.0, 0.0, dt), plain.update(0.5, 0.0, 0.55, 0.0, 0.0, dt)
        mapped = 50.0 + (d.force_N - law.preload_N) / plain.params.force_per_degC_N
        np.testing.assert_array_equal(d.temperature_desired_C, mapped)  # unfiltered: the map, clipped to nothing
        assert 60.0 < mapped[0] < 80.0  # 0.05 rad inside the window: a proportional band (k 3: 102 degC, clipped)
        np.testing.assert_allclose(c.temperature_desired_C, 50.0 + (mapped - 50.0) * (1 - (tau / (tau + dt)) ** k))
