"""The inverse in wrist coordinates undoes the plant's muscle model (muscle.py Eq. 1)."""
from __future__ import annotations

import numpy as np
import pytest

from sma_wrist.core.compensation import MuscleCompensator
from sma_wrist.core.default_params import default_sdgpi
from sma_wrist.core.errors import ModelInputError
from sma_wrist.core.hysteresis import initial_state
from sma_wrist.core.muscle import MuscleGeometry, MuscleModel


@pytest.mark.parametrize('load_kgf', [0.75, 0.8, 0.9])  # the superelastic plateau, strokes > 3 mm
def test_compensated_temperature_gives_the_desired_bundle_elongation(load_kgf):
    params, g = default_sdgpi(), MuscleGeometry()
    model = MuscleModel(params, g)
    comp = MuscleCompensator(params, g, T_range_C=(20.0, 80.0))
    m = np.full(2, load_kgf)
    T0 = np.array([40.0, 40.0])
    comp.reset(T0, g.stress_Pa(m))
    st = initial_state(params, T0, m, branch='cooling')
    y_now = model.elongation(T0, m, st.w, st.heating)[0]
    targets = y_now + np.array([-0.15, 0.1])  # mm: one muscle shortens, the other lengthens
    res = comp(targets / g.wire_length_mm, g.stress_Pa(m))
    assert not res.saturated.any()
    heating = res.temperature_C > T0
    y = model.elongation(res.temperature_C, m, st.w, heating)[0]
    np.testing.assert_allclose(y, targets, atol=1e-6)
    # shortening needs heating (contraction), lengthening needs cooling
    assert res.temperature_C[0] > T0[0] > res.temperature_C[1]


def test_unreachable_target_saturates_and_out_of_range_load_is_flagged():
    params, g = default_sdgpi(), MuscleGeometry()
    comp = MuscleCompensator(params, g)
    comp.reset(np.array([40.0, 40.0]), g.stress_Pa(np.array([0.8, 0.8])))
    res = comp(np.array([-1.0, 1.0]), g.stress_Pa(np.array([0.8, 5.0])))
    assert res.saturated.any()
    assert res.load_clipped.tolist() == [False, True]
    with pytest.raises(ModelInputError):
        comp(np.array([np.nan, 0.02]), g.stress_Pa(np.array([0.8, 0.8])))
