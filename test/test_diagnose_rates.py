"""The temperature rates the replays undo a thermocouple lag with (T = y + tau dy/dt): central differences or a
local fit whose window follows the readings' noise (effects.rate_window)."""

from functools import lru_cache

import numpy as np
import pytest

from sma_wrist.diagnose import effects as fx
from sma_wrist.diagnose.data import Run

DT = 0.01
TAU = 0.2


@lru_cache(maxsize=1)
def _heating_cycles(seconds: float = 120.0) -> tuple[np.ndarray, np.ndarray]:
    """A muscle node driven by relay heating and cooling (sharp reversals of its rate, as a TEM loop gives) and what
    a thermocouple with a TAU lag reads of it, on a 1 ms grid, returned on the DT grid: (node, reading) (K, 2)."""
    h = 1e-3
    t = np.arange(0.0, seconds, h)
    drive = np.column_stack([np.sign(np.sin(2 * np.pi * t / 9.0)), np.sign(np.sin(2 * np.pi * t / 13.0 + 1.0))])
    node = np.empty_like(drive)
    y = np.empty_like(drive)
    T = np.array([50.0, 60.0])
    r = T.copy()
    for k in range(t.size):
        T += h * (4.0 * drive[k] - 0.05 * (T - 55.0))
        r += h / TAU * (T - r)
        node[k], y[k] = T, r
    step = int(round(DT / h))
    node, y = node[::step], y[::step]
    node.flags.writeable = y.flags.writeable = False  # shared by the tests
    return node, y


def _model(T: np.ndarray) -> fx.ExtendedModel:
    t = np.arange(T.shape[0]) * DT
    return fx.ExtendedModel(Run(t=t, dt=DT, u=None, T=T, q=None, payload_kg=0.3))


def _undone(m: fx.ExtendedModel) -> np.ndarray:
    row = fx.NOMINAL.copy()
    row[fx.INDEX['temp_lag_s']] = TAU
    return m.wire_temperature(row, m.T_s, m.T_rate, np.zeros_like(m.T_s))


def test_noise_free_readings_have_their_lag_undone_at_every_reversal() -> None:
    node, y = _heating_cycles()
    m = _model(y)
    assert m.rate_window_s <= 0.05  # central differences or the shortest fit
    err = np.abs(_undone(m) - node)[50:-50]
    # the lag itself: the readings trail the node by up to tau x 4 degC/s
    assert np.abs(y - node)[50:-50].max() > 0.5
    # a 1 s local fit's rate rounds each reversal and leaves tenths of a degree at the peaks, which set the wires'
    # memory: the chosen rate undoes the lag at least ten times closer
    m.T_rate = fx.smooth_and_rate(y, DT, 0.3, 1.0)[1]
    assert err.max() < 0.1 * np.abs(_undone(m) - node)[50:-50].max(), err.max()


@pytest.mark.parametrize('sigma', [0.02, 0.07, 0.2, 0.5])
def test_rate_window_is_near_the_best_for_the_noise(sigma: float) -> None:
    node, y = _heating_cycles()
    rng = np.random.default_rng(int(sigma * 100))
    T = y + rng.normal(0.0, sigma, y.shape)
    true_rate = np.gradient(y, DT, axis=0)
    err = {}
    for w in fx.RATE_WINDOWS_S:
        rate = fx.smooth_and_rate(T, DT, 0.3, w)[1]
        err[w] = float(np.sqrt(np.mean((rate - true_rate)[200:-200] ** 2)))
    got = fx.rate_window(T, DT, np.full(2, sigma), fx.RATE_WINDOWS_S)
    assert err[got] <= 1.3 * min(err.values()), (got, err)
    # and the model of a noisy run uses it
    assert _model(T).rate_window_s == got


def test_rate_window_grows_with_the_noise() -> None:
    node, y = _heating_cycles()
    rng = np.random.default_rng(3)
    e = rng.normal(0.0, 1.0, y.shape)
    got = [fx.rate_window(y + s * e, DT, np.full(2, s), fx.RATE_WINDOWS_S) for s in (0.01, 0.1, 1.0)]
    assert got == sorted(got) and got[0] < got[-1], got
