"""The chain's pre-load elongation for a wire (core/plant/preload.py, doc/explanation/model.md)
and the nodes' preload_elongation_mm parameter."""

from __future__ import annotations

import numpy as np
import pytest

from sma_wrist.core.errors import ParameterError, SmaWristError
from sma_wrist.core.plant.preload import calibrate_preload, reachable_window
from sma_wrist.core.plant.wrist import PlantParams
from sma_wrist.core.thermal.heat_balance import ThermalParams
from sma_wrist.runtime.launch import Runtime


def test_the_calibration_gives_the_built_in_pre_load_for_the_built_in_wire() -> None:
    """doc/explanation/model.md: 1.98 mm holds +-30 deg to ~0.7 kg in the TEM window 20.65-77.59 degC (narrow bracket: 3 runs)."""
    window = reachable_window(ThermalParams())
    assert window == pytest.approx((20.65, 77.59), abs=0.01)
    e0 = calibrate_preload(PlantParams(), window, bracket_mm=(1.8, 2.2), step_mm=0.2)
    assert e0 == pytest.approx(1.98, abs=0.015)  # measured 1.99: 1.98 lifts 0.7 kg to 1.0474 of 1.0476 rad


def test_the_calibration_says_what_no_pre_load_can_reach() -> None:
    with pytest.raises(ParameterError, match='lifts 1.5 kg'):
        calibrate_preload(
            PlantParams(), reachable_window(ThermalParams()), payload_kg=(0.0, 1.5), bracket_mm=(1.5, 2.5), step_mm=0.5
        )
    with pytest.raises(ParameterError, match='window lo < hi'):
        calibrate_preload(PlantParams(), (80.0, 20.0))


def test_the_nodes_take_the_pre_load_and_refuse_a_bad_one() -> None:
    from sma_wrist import runtime

    runtime.activate()
    from sma_wrist.nodes.adaptive_controller import AdaptiveController
    from sma_wrist.nodes.hysteresis_compensator import HysteresisCompensator
    from sma_wrist.nodes.plant_sim import PlantSim

    e0 = {'preload_elongation_mm': 2.4}
    with Runtime(params={f'/{n}': e0 for n in ('plant_sim', 'hysteresis_compensator', 'adaptive_controller')}) as rt:
        plant, comp, ctrl = rt.add(PlantSim), rt.add(HysteresisCompensator), rt.add(AdaptiveController)
    assert plant.sim_params.preload_elongation_mm == comp.plant.preload_elongation_mm == 2.4
    # the strain the controller asks for at q_neutral is the chain's 2.4 mm over the wire length
    assert ctrl.law.strain_at(ctrl.law.plant.joint.q_neutral_rad) == pytest.approx(2.4 / 83.0, rel=1e-3)
    with Runtime() as rt:
        assert rt.add(PlantSim).sim_params.preload_elongation_mm == 1.98
    from rclpy.exceptions import InvalidParameterValueException

    from sma_wrist.nodes.common import start_up_refusal

    for bad in (-1.0, float('nan')):
        with (
            Runtime(params={'/plant_sim': {'preload_elongation_mm': bad}}) as rt,
            pytest.raises((InvalidParameterValueException, SmaWristError), match='preload_elongation_mm') as e,
        ):
            rt.add(PlantSim)
        assert 'preload_elongation_mm' in (start_up_refusal(e.value, PlantSim) or '')  # what the user is told
    assert np.isfinite(PlantParams().preload_elongation_mm)
