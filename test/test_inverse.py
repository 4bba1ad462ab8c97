"""Inverse compensation (Eqs. 5.5-5.15): exact PI inverse, SD-GPI compensator, saturation, seed corrections."""

from __future__ import annotations

from unittest import mock

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sma_wrist.core import jit
from sma_wrist.core.errors import ModelInputError, ParameterError
from sma_wrist.core.hysteresis import kernel as hysteresis_kernel
from sma_wrist.core.hysteresis.default_params import default_sdgpi
from sma_wrist.core.hysteresis.inverse import (
    InverseCompensator,
    LinearCorrection,
    composition_error,
    inverse_table_parameters,
    pi_inverse_params,
    pi_inverse_state,
    pi_series,
    table_5_1_correction,
)
from sma_wrist.core.hysteresis.sdgpi import SDGPIParams, initial_state, simulate, step


def _piecewise_monotone(rng: np.random.Generator, n_seg: int = 30) -> np.ndarray:
    ext = np.cumsum(rng.normal(0, 2, n_seg))
    return np.concatenate(
        [np.linspace(ext[i], ext[i + 1], rng.integers(2, 12), endpoint=False) for i in range(n_seg - 1)]
    )


@pytest.mark.parametrize('seed', range(5))
def test_pi_inverse_is_exact_both_ways(seed: int) -> None:
    rng = np.random.default_rng(seed)
    r = np.sort(rng.uniform(0.05, 3, 12))
    p = rng.uniform(0, 1, 12) * np.exp(-r)
    q = rng.uniform(0.2, 2)
    qh, rh, ph = pi_inverse_params(q, r, p)
    y_d = _piecewise_monotone(rng)
    v, Wh = pi_series(y_d, qh, rh, ph)
    y, _ = pi_series(v[1:], q, r, p, w0=pi_inverse_state(y_d[0], qh, Wh[0], ph))
    assert np.abs(y - y_d[1:]).max() < 1e-9
    v_in = _piecewise_monotone(rng)
    y, W = pi_series(v_in, q, r, p)
    v_back, _ = pi_series(y[1:], qh, rh, ph, w0=pi_inverse_state(v_in[0], q, W[0], p))
    assert np.abs(v_back - v_in[1:]).max() < 1e-9


def test_pi_inverse_weights_are_negative() -> None:
    """Eq. 5.11 as printed has no minus sign; the exact inverse weights are negative."""
    _, rh, ph = pi_inverse_params(1.0, [0.1, 0.2, 0.3], [0.5, 0.25, 0.125])
    assert np.all(ph < 0)
    np.testing.assert_allclose(rh, [0.1, 0.2 + 0.5 * 0.1, 0.3 + 0.5 * 0.2 + 0.25 * 0.1])
    np.testing.assert_allclose(ph[0], -0.5 / (1.5 * 1.0))


def test_compensator_hits_targets_and_flags_saturation() -> None:
    P = default_sdgpi()
    comp = InverseCompensator(P, T_range=(15.0, 85.0))
    loads = np.array([0.7, 0.8, 0.9])
    comp.reset(np.full(3, 15.0), loads)
    y_top = comp.output(loads)
    T, sat = comp(y_top - 1.0, loads)
    assert not sat.any()
    assert np.all(T > 15.0)
    np.testing.assert_allclose(comp.output(loads), y_top - 1.0, atol=1e-9)
    T, sat = comp(np.array([-50.0, 50.0, -50.0]), loads)  # unreachable both ways
    assert sat.all()
    # the reachable extreme: nothing in the range gets closer
    assert T[0] == pytest.approx(85.0, abs=3.0) and T[2] == pytest.approx(85.0, abs=3.0)
    T, sat = comp.from_strain(np.full(3, 1.5 / 80.0), loads)
    assert not sat.any()
    np.testing.assert_allclose(comp.output(loads), 1.5, atol=1e-9)


def _lagging_wire(observe: bool, n: int = 1600, dt: float = 0.05) -> float:
    """Wire whose temperature follows the command with a 1.5 s lag (at most 4 degC/s), at 0.85 kgf.

    Returns max |elongation the compensator believes - elongation of the wire| [mm].
    """
    P = default_sdgpi()
    m = np.array([0.85])
    comp = InverseCompensator(P, T_range=(20.0, 80.0))
    comp.reset([20.0], m)
    wire = initial_state(P, np.array([20.0]), m)
    T = np.array([20.0])
    belief = 0.0
    for k in range(n):
        y_d = np.array([2.0 - 1.4 * np.cos(2 * np.pi * k * dt / 40.0)])
        if observe:
            comp.observe(T, m)
            res = comp.solve(y_d, m, commit=False)
        else:
            res = comp.solve(y_d, m)
        T = T + np.clip((res.T - T) / 1.5, -4.0, 4.0) * dt
        y = step(P, wire, T, m)
        if observe:
            comp.observe(T, m)
        belief = max(belief, float(np.abs(comp.output(m) - y).max()))
    return belief


def test_observed_memory_mirrors_a_lagging_wire_and_the_committed_one_does_not() -> None:
    """Eq. 5.5 commits the command; a wire that lags it then has another memory (doc/explanation/controllers.md)."""
    assert _lagging_wire(observe=True) < 1e-9
    assert _lagging_wire(observe=False) > 0.5  # mm, of a 2.8 mm stroke (measured 3.3)


def test_observe_advances_the_memory_exactly_as_the_model_step() -> None:
    """observe (compiled where numba is present) is hysteresis.step on the measured samples."""
    P = default_sdgpi()
    rng = np.random.default_rng(3)
    m0 = np.array([0.7, 0.85, 1.0])
    comp = InverseCompensator(P, T_range=(20.0, 80.0))
    comp.reset(np.full(3, 30.0), m0)
    ref = initial_state(P, np.full(3, 30.0), m0)
    T = 30.0 + np.cumsum(rng.normal(0.0, 2.0, (400, 3)), axis=0).clip(-25, 45)
    m = m0 + 0.05 * np.sin(np.arange(400) / 17.0)[:, None]
    for k in range(400):
        comp.observe(T[k], m[k])
        step(P, ref, T[k], m[k])
    np.testing.assert_allclose(comp.state.w, ref.w, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(comp.state.heating, ref.heating)
    np.testing.assert_array_equal(comp.state.T_prev, ref.T_prev)


def test_solve_without_commit_leaves_the_memory_and_reports_what_the_answer_gives() -> None:
    P = default_sdgpi()
    loads = np.array([0.75, 0.95])
    comp = InverseCompensator(P, T_range=(20.0, 80.0))
    comp.reset(np.array([30.0, 60.0]), loads)
    before = comp.state.copy()
    res = comp.solve(np.array([1.2, 2.0]), loads, commit=False)
    np.testing.assert_array_equal(comp.state.w, before.w)
    np.testing.assert_array_equal(comp.state.T_prev, before.T_prev)
    ref = initial_state(P, np.array([30.0, 60.0]), loads)
    np.testing.assert_allclose(res.achieved_mm, step(P, ref, res.T, loads), atol=1e-12)
    np.testing.assert_allclose(res.achieved_mm[~res.saturated], np.array([1.2, 2.0])[~res.saturated], atol=1e-8)


def _numpy_path(on: bool) -> mock._patch:
    """The compensator's numpy reference (on) or, where numba is installed, its compiled path."""
    return mock.patch.object(jit, 'AVAILABLE', jit.AVAILABLE and not on)


@pytest.mark.skipif(not jit.AVAILABLE, reason='numba is not installed: there is only the numpy path')
@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.sampled_from([1, 2, 3]))
def test_compiled_observe_and_solve_agree_with_the_numpy_path(seed: int, S: int) -> None:
    """The node's 100 Hz calls, observe + solve(commit=False) compiled (one pass per wire, grid walks
    stopped once they cannot beat the other side's root), against the numpy reference on random
    memories, measurements (some outside the model's window: clipped) and targets (some
    unreachable: saturated, some needing heating, some cooling)."""
    P = default_sdgpi()
    rng = np.random.default_rng(seed)
    (lo, hi), (m_lo, m_hi) = P.T_valid, P.load_range
    T_lo = float(rng.uniform(15.0, 40.0))
    T_range = (T_lo, T_lo + float(rng.uniform(10.0, 60.0)))
    T0, m0 = rng.uniform(*T_range, S), rng.uniform(m_lo, m_hi, S)
    branch = str(rng.choice(['cooling', 'heating']))
    comps = []
    for _ in (True, False):
        comps.append(InverseCompensator(P, T_range=T_range))
        comps[-1].reset(T0, m0, branch=branch)
    T, m = T0.copy(), m0.copy()
    for k in range(60):
        T = T + rng.normal(0.0, 3.0, S)
        m = np.clip(m + rng.normal(0.0, 0.03, S), m_lo, m_hi)
        T_meas, m_meas = T.copy(), m.copy()
        if k % 7 == 3:  # outside the model's window: observe clips
            T_meas[0], m_meas[-1] = [lo - 5.0, np.inf, hi + 3.0][k % 3], [m_lo - 0.1, m_hi + 0.2][k % 2]
        y_now = comps[0].output(m)
        y_d = y_now + rng.normal(0.0, [0.05, 0.5, 3.0][k % 3], S)
        out = []
        for comp, numpy_path in zip(comps, (True, False)):
            with _numpy_path(numpy_path):
                comp.observe(T_meas, m_meas)
                out.append(comp.solve(y_d, m, commit=False))
        ref, got = out
        np.testing.assert_array_equal(got.saturated, ref.saturated)
        np.testing.assert_allclose(got.T, ref.T, rtol=0, atol=1e-6)
        np.testing.assert_allclose(got.achieved_mm, ref.achieved_mm, rtol=0, atol=1e-9)
        np.testing.assert_allclose(comps[1].state.w, comps[0].state.w, rtol=0, atol=1e-12)
        np.testing.assert_array_equal(comps[1].state.heating, comps[0].state.heating)
        np.testing.assert_array_equal(comps[1].state.T_prev, comps[0].state.T_prev)


@pytest.mark.skipif(not jit.AVAILABLE, reason='numba is not installed: there is only the numpy path')
def test_compiled_observe_and_solve_compute_the_floats_of_their_python_source() -> None:
    """The compiled one-wrist path (the residual inlined into the root search) is its own Python
    source run by the interpreter, to the bit: compiling changes no operation and no order (no
    fast-math, no fused multiply-add), so an inlining or a restructuring of calls that keeps the
    source's operations keeps the node's numbers."""
    from contextlib import ExitStack

    from sma_wrist.core.hysteresis import inverse

    P = default_sdgpi()
    m_lo, m_hi = P.load_range

    def run(interpreted: bool) -> np.ndarray:
        out = []
        with ExitStack() as stack:
            if interpreted:
                for module, names in (
                    (
                        inverse,
                        (
                            '_residual',
                            '_residual_parts',
                            '_refine',
                            '_argmin_abs',
                            '_grid_f',
                            '_interval_bounds',
                            '_side_free',
                            '_side_argmin',
                            '_nearest_root',
                            '_invert_frozen',
                            '_observe_step',
                        ),
                    ),
                    (hysteresis_kernel, ('_envelopes',)),
                ):
                    for name in names:
                        stack.enter_context(mock.patch.object(module, name, getattr(module, name).py_func))
            for seed in range(6):
                rng = np.random.default_rng(seed)
                T, m = rng.uniform(25.0, 70.0, 2), rng.uniform(m_lo, m_hi, 2)
                comp = InverseCompensator(P, T_range=(20.0, 80.0))
                comp.reset(T, m)
                for k in range(40):
                    T = T + rng.normal(0.0, 2.0, 2)
                    m = m + rng.normal(0.0, 0.03, 2)  # some outside the range: observe clips
                    comp.observe(T, m)
                    m_in = np.clip(m, m_lo, m_hi)
                    y_d = comp.output(m_in) + rng.normal(0.0, [0.05, 0.5, 3.0][k % 3], 2)  # some unreachable
                    res = comp.solve(y_d, m_in, commit=False)
                    st_ = comp.state
                    out.append(
                        np.concatenate([res.T, res.saturated, res.achieved_mm, st_.w.ravel(), st_.T_prev, st_.heating])
                    )
        return np.concatenate(out)

    compiled, interpreted = run(False), run(True)
    assert np.array_equal(compiled, interpreted), f'{np.sum(compiled != interpreted)} of {compiled.size} differ'


def _full_walk(
    T0: float, h_prev: bool, coef, w, y: float, lo: float, hi: float, G: int, tol: float, P
) -> tuple[float, bool]:
    """The search as its docstring states it, every grid point of both sides evaluated (interpreted):
    first sign change of each side refined, the nearer root, else the grid point of smallest |f|."""
    from sma_wrist.core.hysteresis import inverse

    r, wts, c, d = P.thresholds, P.weights, P.c, P.d
    res = inverse._residual.py_func
    Tg = [[T0 + (g / (G - 1.0)) * (end - T0) for g in range(G)] for end in (hi, lo)]
    f = [[res(Tg[s][g], T0, h_prev, s == 0, coef, w, y, r, wts, c, d, P.p0, P.k_f) for g in range(G)] for s in (0, 1)]
    roots = []
    for s in (0, 1):
        k = next((g for g in range(1, G) if f[s][g - 1] * f[s][g] <= 0), None)
        if k is not None:
            roots.append(
                inverse._refine.py_func(
                    Tg[s][k - 1],
                    Tg[s][k],
                    f[s][k - 1],
                    f[s][k],
                    T0,
                    h_prev,
                    s == 0,
                    coef,
                    w,
                    y,
                    r,
                    wts,
                    c,
                    d,
                    P.p0,
                    P.k_f,
                    tol,
                )
            )
        else:
            roots.append(np.nan)
    dist = [abs(x - T0) if np.isfinite(x) else np.inf for x in roots]
    if min(dist) < np.inf:
        return (roots[1] if dist[1] < dist[0] else roots[0]), False
    k0, k1 = (int(np.argmin(np.abs(f[s]))) for s in (0, 1))
    return (Tg[1][k1] if abs(f[1][k1]) < abs(f[0][k0]) else Tg[0][k0]), True


@pytest.mark.skipif(not jit.AVAILABLE, reason='numba is not installed: there is only the numpy path')
@pytest.mark.parametrize('seed', [0, 1, 2])
def test_compiled_search_skips_only_points_that_cannot_change_the_answer(seed: int) -> None:
    """The compiled search stops walking a side it has shown free of sign changes from a few points and
    looks for a saturated target's closest grid value the same way (about half the sweep's solves
    are saturated: 18 instead of 67 residuals). Its answers are the full walk's to the bit, over random
    memories, windows and targets near and far (reachable, beyond one side, beyond both)."""
    from sma_wrist.core.hysteresis import kernel as hk

    P = default_sdgpi()
    rng = np.random.default_rng(seed)
    (m_lo, m_hi) = P.load_range
    comp = InverseCompensator(P, T_range=(20.0, 80.0))
    S = 40
    T = rng.uniform(25.0, 75.0, S)
    m = rng.uniform(m_lo, m_hi, S)
    comp.reset(T, m, branch=['cooling', 'heating'][seed % 2])
    saturated = found = 0
    for k in range(6):
        T = np.clip(T + rng.normal(0.0, 6.0, S), 20.0, 80.0)
        comp.observe(T, m)
        y_d = comp.output(m) + rng.normal(0.0, [0.05, 0.5, 3.0][k % 3], S)
        lo = rng.uniform(20.0, 45.0, S)
        hi = lo + rng.uniform(1.0, 35.0, S)
        res = comp.solve(y_d, m, commit=False, window=(lo, hi))
        st_ = comp.state
        for s in range(S):
            coef, _ = hk._envelopes(*comp._kernel_params[:2], m[s])
            T0 = min(max(st_.T_prev[s], lo[s]), hi[s])
            T_ref, sat_ref = _full_walk(
                T0, bool(st_.heating[s]), coef, st_.w[s], y_d[s], lo[s], hi[s], comp.grid, comp.tol_mm, P
            )
            assert (res.T[s], bool(res.saturated[s])) == (T_ref, sat_ref), (k, s)
            saturated += sat_ref
            found += not sat_ref
    assert saturated > 20 and found > 10  # both kinds of solve were compared


@pytest.mark.parametrize('numpy_path', [True, False])
def test_bad_measurements_and_targets_raise_and_leave_the_memory(numpy_path: bool) -> None:
    P = default_sdgpi()
    m = np.array([0.8, 0.9])
    comp = InverseCompensator(P, T_range=(20.0, 80.0))
    comp.reset(np.array([40.0, 45.0]), m)
    before = comp.state.copy()
    with _numpy_path(numpy_path):
        with pytest.raises(ModelInputError, match='measured wire temperature'):
            comp.observe(np.array([np.nan, 41.0]), m)
        with pytest.raises(ModelInputError, match='measured wire load'):
            comp.observe(np.array([41.0, 41.0]), np.array([0.8, np.nan]))
        with pytest.raises(ModelInputError, match='desired elongation'):
            comp.solve(np.array([2.0, np.inf]), m, commit=False)
        with pytest.raises(ModelInputError, match='wire load m'):
            comp.solve(np.array([2.0, 2.0]), np.array([0.8, 5.0]), commit=False)
        np.testing.assert_array_equal(comp.state.w, before.w)
        np.testing.assert_array_equal(comp.state.T_prev, before.T_prev)
        np.testing.assert_array_equal(comp.state.heating, before.heating)
        T, sat = comp(2.0, 0.85)  # scalars broadcast to every wire
        assert T.shape == sat.shape == (2,)


def test_compensator_needs_reset() -> None:
    with pytest.raises(ParameterError):
        InverseCompensator(default_sdgpi())(1.0, 0.8)


def test_composition_error_numerical_is_at_root_tolerance() -> None:
    ce = composition_error(default_sdgpi(), loads=np.linspace(0.65, 1.05, 5))
    assert np.all(ce.saturated_fraction == 0)
    assert ce.max_mm.max() < 1e-8
    assert np.all(ce.range_mm > 0.3)


def test_analytic_inverse_exact_when_envelopes_coincide() -> None:
    """Eqs. 5.7-5.8 are exact for gamma_l = gamma_r = memoryless gamma (GPI = PI o gamma)."""
    g = [2.0, 0.08, -4.0, 3.0]
    P = SDGPIParams.from_gpi(g, g, g, g, rho=0.4, tau=3.0, c_thr=0.05, n=15, p0=0.5)
    comp = InverseCompensator(P, T_range=(0.0, 100.0), method='analytic')
    comp.reset([20.0], [0.0], branch='cooling')
    y0 = float(comp.output([0.0])[0])
    lo_, hi_ = 6.0 - (0.5 + P.weights.sum()) * 4.9, 6.0 - (0.5 + P.weights.sum()) * 1.1
    v = np.concatenate(
        [np.linspace(y0, lo_ + 0.5, 40), np.linspace(lo_ + 0.5, hi_ - 0.8, 30), np.linspace(hi_ - 0.8, lo_ + 1.0, 20)]
    )
    T = np.array([comp(np.array([x]), np.array([0.0]))[0][0] for x in v])
    y = simulate(P, T, 0.0, state=initial_state(P, [20.0], [0.0]))
    assert np.abs(y - v).max() < 1e-9


def test_analytic_inverse_on_default_set_is_far_off() -> None:
    """Measured: the default set's memoryless part is thermal expansion, not p0 gamma: Eq. 5.7 fails there."""
    ce = composition_error(default_sdgpi(), loads=np.array([0.8]), method='analytic')
    assert ce.rms_pct[0] > 20.0


def test_table_5_1_gain_is_far_from_one() -> None:
    """Measured: Table 5.1 with the load in kg gives gradients a_l of 0.005-0.08, offsets -0.21..1.0."""
    a, c = table_5_1_correction().gain_offset(np.array([0.65, 0.8, 1.05]))
    np.testing.assert_allclose(a, [0.0806, 0.0765, 0.0049], atol=5e-4)
    np.testing.assert_allclose(c, [-0.214, -0.132, 0.996], atol=5e-3)


def test_linear_correction_fit_roundtrip() -> None:
    loads = np.array([0.65, 0.8, 0.95, 1.05])
    a_true, c_true = 0.9 + 0.1 * loads**2, 0.2 - 0.1 * loads
    u = np.stack([np.full(4, 0.5), np.full(4, 3.0)], axis=1)
    v = a_true[:, None] * u + c_true[:, None]
    corr = LinearCorrection.fit(loads, u, v)
    np.testing.assert_allclose(corr.precompensate(v[:, 1], loads), u[:, 1], atol=1e-9)


def test_tables_5_2_5_3_give_negative_density_and_thresholds() -> None:
    """Measured: read with the load in kg, Tables 5.2-5.3 give rho < 0 and c < 0 at 700 g."""
    p = inverse_table_parameters(700)
    assert p['rho'] < 0 and p['c'] < 0
