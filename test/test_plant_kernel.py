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


@pytest.mark.parametrize('engine', ['auto', 'numpy'])
def test_segments_in_one_call_match_one_advance_per_segment(engine):
    payload = np.array([0.2, 0.5])
    one, each = (WristPlant(PlantParams(engine=engine), payload_kg=payload) for _ in range(2))
    rng = np.random.default_rng(2)
    u = rng.uniform(-30.0, 30.0, (12, 2, 2))  # also beyond the +-24 V limits: clipped alike
    n = rng.integers(1, 15, 12)
    thermal, q, qd = one.advance_segments(u, n)
    for k in range(12):
        s = each.advance(u[k], int(n[k]))
        np.testing.assert_allclose(thermal[k], s.thermal, atol=1e-9)
        np.testing.assert_allclose(q[k], s.q, atol=1e-9)
        np.testing.assert_allclose(qd[k], s.qd, atol=1e-9)
    np.testing.assert_array_equal(one.state.w, each.state.w)
    assert one.state.t == pytest.approx(each.state.t)
    assert one.state.flags['command_saturated'].all()
    with pytest.raises(ModelInputError, match='TEM command'):
        one.advance_segments(np.array([[[0.0, np.nan]]]), np.array([3]))


def test_advance_rejects_non_finite_commands():
    pl = WristPlant()
    with pytest.raises(ModelInputError, match='TEM command'):
        pl.advance(np.array([[np.nan, 0.0]]), 10)


def test_kernel_is_compiled_where_numba_is_installed():
    pytest.importorskip('numba')
    assert jit.AVAILABLE
    assert hasattr(plant_kernel.step_many, 'py_func')
