"""The residual-lag statistic (report.lag_estimate, FFT cross-correlation) against the
direct sum over lags, and on known delays of either sign."""

import numpy as np
import pytest

from sma_wrist.diagnose.report import lag_estimate


def _direct(meas: np.ndarray, model: np.ndarray, dt: float, max_lag_s: float = 3.0) -> float:
    a, b = np.diff(meas), np.diff(model)
    a, b = a - a.mean(), b - b.mean()
    m = int(max_lag_s / dt)
    lags = np.arange(-m, m + 1)
    cc = np.array([float(np.sum(a[max(k, 0) : a.size + min(k, 0)] * b[max(-k, 0) : b.size - max(k, 0)])) for k in lags])
    k = int(np.argmax(cc))
    den = cc[k - 1] - 2 * cc[k] + cc[k + 1]
    return float((lags[k] + (0.5 * (cc[k - 1] - cc[k + 1]) / den if den else 0.0)) * 0.01)


@pytest.mark.parametrize('shift', [-250, -7, 0, 12, 299])
def test_lag_estimate_matches_direct_sum_and_finds_the_delay(shift: int) -> None:
    rng = np.random.default_rng(abs(shift))
    model = np.cumsum(rng.normal(size=3000))
    meas = np.roll(model, shift) + 0.2 * rng.normal(size=3000)
    got = lag_estimate(meas, model, 0.01)
    assert got == pytest.approx(_direct(meas, model, 0.01), abs=1e-9)
    assert got == pytest.approx(shift * 0.01, abs=0.006)


def test_lag_estimate_shorter_than_the_lag_window() -> None:
    x = np.cumsum(np.random.default_rng(1).normal(size=40))
    assert lag_estimate(np.roll(x, 3), x, 0.01) == pytest.approx(0.03, abs=0.006)
