"""The compiled per-sample plant (plant_kernel, numba) gives the numpy path's numbers."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from sma_wrist.core import jit
from sma_wrist.core.errors import ModelInputError
from sma_wrist.core.plant import kernel as plant_kernel
from sma_wrist.core.plant.wrist import PlantParams, WristPlant


def _pair(payload, **kw):
    fast = WristPlant(PlantParams(**kw), payload_kg=payload)
    ref = WristPlant(PlantParams(engine='numpy', **kw), payload_kg=payload)
    return fast, ref


@pytest.mark.parametrize('thermal_coupling', [0.0, 0.02])
def test_advance_matches_numpy_steps_under_random_commands(thermal_coupling):
    payload = np.linspace(0.1, 0.6, 4)
    fast, ref = _pair(payload)
    if thermal_coupling:
        for pl in (fast, ref):
            pl.params = replace(pl.params, thermal=replace(pl.params.thermal, coupling_per_s=thermal_coupling))
    rng = np.random.default_rng(1)
    worst = 0.0
    for _ in range(20):
        u = rng.uniform(-14.0, 15.0, (4, 2))  # also beyond the limits: clipped and flagged alike
        a = fast.advance(u, 50)
        flags = {k: np.zeros(4, bool) for k in a.flags}
        for _ in range(50):
            for k, v in ref.step(u).flags.items():
                flags[k] |= v
        for name in ('q', 'qd', 'thermal', 'load_kgf', 'w', 'T_prev'):
            worst = max(worst, float(np.abs(getattr(a, name) - getattr(ref.state, name)).max()))
        np.testing.assert_array_equal(a.heating, ref.state.heating)
        for k in ('command_saturated', 'over_temperature', 'slack', 'overload'):
            np.testing.assert_array_equal(a.flags[k], flags[k], err_msg=k)
    assert worst < 1e-9
    assert fast.state.t == pytest.approx(ref.state.t)


def test_advance_rejects_non_finite_commands():
    pl = WristPlant()
    with pytest.raises(ModelInputError, match='TEM command'):
        pl.advance(np.array([[np.nan, 0.0]]), 10)


def test_kernel_is_compiled_where_numba_is_installed():
    pytest.importorskip('numba')
    assert jit.AVAILABLE
    assert hasattr(plant_kernel.step_many, 'py_func')
