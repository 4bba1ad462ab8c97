"""Mode composition of the joint controller (what adaptive_controller publishes)."""
from __future__ import annotations

import numpy as np
import pytest

from sma_wrist.core.errors import ParameterError
from sma_wrist.core.joint_controller import JointController, JointControllerParams
from sma_wrist.core.plant import PlantParams


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
    for _ in range(50):
        c = jc.update(0.3, 0.0, 0.6, 0.0, 0.0, 0.01)
    assert c.info['beta_hat_1'] == c.info['beta_hat_2'] == 1.0
    assert c.info['theta_hat_kg'] != 0.0


@pytest.mark.parametrize('kw', [dict(mode='mpc'), dict(temperature_mid_C=90.0), dict(force_per_degC_N=0.0),
                                dict(temperature_min_C=float('nan'))])
def test_bad_parameters_are_refused(kw):
    with pytest.raises(ParameterError):
        JointControllerParams(**kw)
