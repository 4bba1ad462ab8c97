"""Identification recovers known loops from noisy data (sigma = 0.5 % of range)."""
from __future__ import annotations

import numpy as np

from sma_wrist.core.default_params import default_sdgpi
from sma_wrist.core.hysteresis import EnvelopeSections, SDGPIParams, simulate
from sma_wrist.core.identification import fit_gpi, fit_sdgpi, gpi_vector, simulate_batch
from sma_wrist.core.seed_params import sawtooth_input


def test_batch_simulation_matches_model() -> None:
    P = default_sdgpi()
    _, T, _, _ = sawtooth_input(dt=5.0, n_periods=2)
    y = simulate_batch(T, np.stack([gpi_vector(P, 0.8), gpi_vector(P, 0.7)]))
    np.testing.assert_allclose(y[:, 0], simulate(P, T, 0.8), atol=1e-12)
    np.testing.assert_allclose(y[:, 1], simulate(P, T, 0.7), atol=1e-12)


def test_fit_gpi_recovers_loop() -> None:
    P = default_sdgpi()
    _, T, _, _ = sawtooth_input(dt=2.0, n_periods=3)
    y0 = simulate(P, T, 0.8)
    rng = np.random.default_rng(1)
    y = y0 + rng.normal(0, 0.005 * np.ptp(y0), T.size)
    r = fit_gpi(T, y, n_starts=3)
    assert r.success and r.n_starts == 3
    assert r.residual_std_pct < 1.0
    y_fit = simulate(r.params, T, 0.0)
    assert 100 * np.std(y_fit - y0) / np.ptp(y0) < 0.5  # the loop itself, not just the noisy data


def test_fit_sdgpi_recovers_loops_across_loads() -> None:
    D = default_sdgpi()
    edges = np.array([0.65, 0.8, 1.05])
    sa, sb = np.zeros((2, 4, 3)), np.zeros((2, 4, 3))
    for k in range(2):
        mm = np.linspace(edges[k], edges[k + 1], 7)
        a, b = D.envelopes.coefficients(mm)
        for i in range(4):
            sa[k, i] = np.polyfit(mm, a[:, i], 2)
            sb[k, i] = np.polyfit(mm, b[:, i], 2)
    truth = SDGPIParams(EnvelopeSections(edges, sa, sb), D.c, D.d, D.rho, D.tau, D.c_thr, p0=1.0)
    _, T, _, _ = sawtooth_input(dt=4.0, n_periods=2)
    loads = np.array([0.65, 0.7, 0.75, 0.8, 0.85, 0.95, 1.05])
    TT = np.repeat(T[:, None], loads.size, 1)
    mm = np.broadcast_to(loads, TT.shape)
    Y = simulate(truth, TT, mm)
    rng = np.random.default_rng(2)
    Yn = Y + rng.normal(0, 1, Y.shape) * 0.005 * np.ptp(Y, axis=0)
    r = fit_sdgpi(TT, Yn, loads, edges)
    assert r.residual_std_pct < 1.0
    Yf = simulate(r.params, TT, mm)
    assert 100 * np.std(Yf - Y) / np.mean(np.ptp(Y, axis=0)) < 0.5
