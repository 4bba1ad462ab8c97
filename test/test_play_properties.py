"""Property tests of the play/stop operators and the GPI model (Eqs. 3.19, 5.4, 5.17-5.19)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from sma_wrist.core.hysteresis.inverse import pi_inverse_params, pi_inverse_state, pi_series
from sma_wrist.core.hysteresis.play import play_series, stop_series
from sma_wrist.core.hysteresis.sdgpi import SDGPIParams, play_bounds, simulate

R = 0.3 * np.arange(1, 8)
finite = st.floats(-10, 10, allow_nan=False)
series = st.lists(finite, min_size=2, max_size=40)

# a GPI whose envelopes are ordered (gamma_l <= gamma_r everywhere)
GPI = SDGPIParams.from_gpi(
    [2.0, 0.1, -5.0, 2.0],
    [2.0, 0.1, -6.0, 1.5],
    [0.1, 0.05, -2.0, 0.0],
    [0.1, 0.05, -2.5, 0.0],
    rho=0.3,
    tau=2.0,
    c_thr=0.1,
    n=7,
)
temps = st.lists(st.floats(0, 100, allow_nan=False), min_size=2, max_size=40)


@given(series)
def test_play_output_within_bounds(v: list[float]) -> None:
    W = play_series(v, R)
    va = np.asarray(v)[:, None]
    assert np.all(W >= va - R - 1e-12) and np.all(W <= va + R + 1e-12)


@given(temps)
def test_gpi_play_states_within_envelope_band(T: list[float]) -> None:
    from sma_wrist.core.hysteresis.sdgpi import initial_state, step

    s = initial_state(GPI, T[0], 0.0)
    for t in T:
        step(GPI, s, np.array([t]), np.array([0.0]))
        lo, hi = play_bounds(GPI, np.array([t]), np.array([0.0]))
        assert np.all(s.w >= lo - 1e-12) and np.all(s.w <= hi + 1e-12)


@given(series, st.lists(st.integers(0, 39), max_size=10), st.integers(1, 5))
def test_rate_independence(v: list[float], repeats: list[int], k: int) -> None:
    """Repeating samples, or inserting samples on a monotone segment, leaves the outputs at the originals unchanged."""
    v = np.asarray(v)
    ref = play_series(v, R)
    # repeated samples
    idx = np.sort(np.concatenate([np.arange(v.size), np.array([i % v.size for i in repeats], dtype=int)]))
    out = play_series(v[idx], R)
    first = np.searchsorted(idx, np.arange(v.size), side='right') - 1
    np.testing.assert_allclose(out[first], ref, atol=1e-12)
    # k extra samples between each pair (linear interpolation keeps each segment monotone)
    fine = np.concatenate([np.linspace(v[i], v[i + 1], k + 1, endpoint=False) for i in range(v.size - 1)] + [v[-1:]])
    out = play_series(fine, R)
    np.testing.assert_allclose(out[:: k + 1], ref, atol=1e-12)
    # and the GPI with temperature
    T = 50 + 4 * v
    Tf = 50 + 4 * fine
    np.testing.assert_allclose(simulate(GPI, Tf, 0.0)[:: k + 1], simulate(GPI, T, 0.0), atol=1e-12)


@given(st.floats(-5, 5), st.floats(0.1, 8), st.floats(0.05, 0.95), st.floats(0.05, 0.95), finite)
def test_wiping_out(v0: float, amp: float, f1: float, f2: float, v_end_extra: float) -> None:
    """After the input exceeds the previous maximum, a minor loop inside is forgotten."""
    top = v0 + amp
    lo_minor = v0 + f1 * amp * 0.5
    hi_minor = lo_minor + f2 * (top - lo_minor)
    beyond = top + 1.0 + abs(v_end_extra)
    with_minor = np.array([v0, top, lo_minor, hi_minor, lo_minor, beyond, v0])
    without = np.array([v0, top, lo_minor, beyond, v0])
    a = play_series(with_minor, R)
    b = play_series(without, R)
    np.testing.assert_allclose(a[-2:], b[-2:], atol=1e-12)
    Ta = simulate(GPI, 50 + 2 * with_minor, 0.0)
    Tb = simulate(GPI, 50 + 2 * without, 0.0)
    np.testing.assert_allclose(Ta[-2:], Tb[-2:], atol=1e-12)


@given(series)
def test_stop_play_complementarity(v: list[float]) -> None:
    """F_r[v] = v - E_r[v] (Eq. 5.17) with matching initial states (omega_-1 = 0)."""
    v = np.asarray(v)
    F = play_series(v, R)
    E = stop_series(v, R)
    np.testing.assert_allclose(F, v[:, None] - E, atol=1e-12)


@settings(max_examples=50)
@given(series, st.floats(0.1, 3.0), st.lists(st.floats(0.0, 2.0), min_size=7, max_size=7))
def test_pi_inverse_composition(y: list[float], q: float, p: list[float]) -> None:
    """PI o PI^-1 = identity (Eqs. 5.9-5.11) from consistent initial states."""
    y = np.asarray(y)
    p = np.asarray(p)
    qh, rh, ph = pi_inverse_params(q, R, p)
    v, Wh = pi_series(y, qh, rh, ph)
    w0 = pi_inverse_state(y[0], qh, Wh[0], ph)
    yy, _ = pi_series(v[1:], q, R, p, w0=w0)
    np.testing.assert_allclose(yy, y[1:], atol=1e-9 * max(1.0, np.abs(y).max()))
