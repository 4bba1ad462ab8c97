"""Back-stepping adaptive law (Eqs. 5.24, 5.32, 5.37 as corrected in sma_wrist.core.control.adaptive)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sma_wrist.core.control.adaptive import AdaptiveController, AdaptiveParams
from sma_wrist.core.errors import ModelInputError, ParameterError

WIDE = dict(force_min_N=0.0, force_max_N=1e6, preload_N=500.0)


def _simulate_law_model(theta_true: float, steps: int = 20000, dt: float = 1e-3, **kw):
    """The law on its own plant model (Eq. 5.23 with beta = 1, d = 0): the estimate converges."""
    p = AdaptiveParams(mode='direct_adaptive', **{**WIDE, **kw})
    c = AdaptiveController(p)
    g = p.geometry
    q, qd = 0.2, 0.0
    errs = []
    for k in range(steps):
        t = k * dt
        qr, qdr, qddr = 0.5 + 0.3 * math.sin(t), 0.3 * math.cos(t), -0.3 * math.sin(t)
        o = c.update(q, qd, qr, qdr, qddr, dt)
        acc = (
            g.r_eff_m / g.inertia_kgm2 * float(o.delta_force_N[0])
            - g.g_m_s2 * g.lever_m * math.cos(q) / g.inertia_kgm2 * theta_true
        )
        qd += dt * acc
        q += dt * qd
        errs.append(abs(q - qr))
    return c, np.array(errs)


def test_tracking_error_decays_and_payload_estimate_converges_on_the_laws_own_model():
    c, errs = _simulate_law_model(0.4, gamma_a=0.05, c1=5.0, c2=5.0)
    assert errs[-2000:].max() < 0.02 * errs[:200].max()
    assert c.state.theta_hat[0] == pytest.approx(0.4, abs=0.05)


def test_estimates_stay_in_their_boxes():
    c = AdaptiveController(AdaptiveParams(gamma_a=100.0, theta_bounds_kg=(0.0, 1.0), **WIDE))
    for _ in range(500):
        o = c.update(0.0, 0.0, 1.0, 0.0, 0.0, 0.01)
    assert 0.0 <= o.theta_hat[0] <= 1.0
    lo, hi = c.params.beta_bounds
    assert np.all((lo <= o.beta_hat) & (o.beta_hat <= hi))


def test_adaptation_is_frozen_while_the_force_limits_bind():
    c = AdaptiveController(AdaptiveParams(force_min_N=1000.0, force_max_N=1010.0, preload_N=1005.0, gamma_a=1.0))
    before = c.state.copy()
    o = c.update(0.0, 0.0, 1.0, 0.0, 0.0, 0.01)
    assert o.saturated[0]
    assert o.theta_hat[0] == before.theta_hat[0]
    assert 1000.0 <= o.force_1_N[0] <= 1010.0 and 1000.0 <= o.force_2_N[0] <= 1010.0


def test_non_finite_input_and_bad_step_are_typed_errors():
    c = AdaptiveController()
    with pytest.raises(ModelInputError, match='q_d'):
        c.update(0.0, 0.0, math.nan, 0.0, 0.0, 0.01)
    with pytest.raises(ModelInputError, match='dt'):
        c.update(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


def test_table_6_1_presets_and_validation():
    inv = AdaptiveParams.paper_table_6_1('inverse_adaptive')
    direct = AdaptiveParams.paper_table_6_1('direct_adaptive')
    assert (inv.c1, inv.c2, inv.gamma_a, inv.gamma_b1, inv.gamma_d1) == (3.0, 6.5, 0.01, 0.05, 0.01)
    assert (direct.c2, direct.gamma_a, direct.gamma_b1) == (5.5, 0.05, 0.0)
    with pytest.raises(ParameterError):
        AdaptiveParams(c1=-1.0)
    with pytest.raises(ParameterError):
        AdaptiveParams(beta_bounds=(0.0, 2.0))


@pytest.mark.parametrize('mode,robust', [('inverse_adaptive', 'tanh'), ('direct_adaptive', 'sign')])
def test_compiled_law_equals_its_plain_python_source(mode, robust):
    """adaptive_kernel.update runs compiled under numba and as plain Python without it: both give
    the same forces, flags and estimates over a random sample sequence (saturating ones included)."""
    from sma_wrist.core.control import adaptive_kernel

    rng = np.random.default_rng(3)
    p = AdaptiveParams(mode=mode, robust=robust, c1=50.0, c2=80.0, gamma_a=0.5, gamma_b1=0.3, gamma_d1=0.2)
    k = adaptive_kernel.pack(p)
    states = [[np.zeros(3), np.ones((3, 2)), np.zeros((3, 2))] for _ in range(2)]
    outs = [np.empty((3, adaptive_kernel.OUT_LEN)) for _ in range(2)]
    saturated = 0
    for _ in range(400):
        x = rng.uniform(-1.0, 1.0, (5, 3)) * np.array([[1.0], [2.0], [1.0], [0.2], [0.05]])
        for fn, st, out in zip(
            (adaptive_kernel.update, getattr(adaptive_kernel.update, 'py_func', adaptive_kernel.update)), states, outs
        ):
            fn(x, 0.01, *st, k, out)
        # same equations; libm's tanh/cos and LLVM's may differ in the last bit
        np.testing.assert_allclose(outs[0][:, :8], outs[1][:, :8], rtol=1e-12, atol=1e-12)
        for a, b in zip(*states):
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)
        saturated += int(outs[0][:, 7].sum())
    assert saturated > 0  # the anti-windup branch was exercised
