"""A test for a slow ambient / coolant drift with the power of the whole window.

The diagnosis (:func:`sma_wrist.diagnose.diagnose_run`) fits its candidates on the first 60 % of a window and names
one only when the nominal model misses the held-out rest by more than 1.6 x the per-sample noise
(``STRUCTURE_RATIO``). A drift of the coolant grows from nothing: 20 degC/h moved the muscle temperatures away
from the twin's by 0.05, 0.11 and 0.16-0.18 degC 30, 45 and 60 s after its onset, against 0.1 degC of noise per
sample, so the diagnosis named it 60 s after the onset at the earliest. Averaged over 1 s the noise is a tenth of
that, and the drift's response is known in shape: the diagnosis' own ``ambient_drift`` effect (the same replay, the
same catalogue parameter), whose effect on both thermocouples is linear in the rate. This test fits that rate to
the 1 s block averages of the scored part of the window (both channels, each with its own offset: what the twin's
state at the window's start got wrong) and names the drift when

* the rate is significant: ``|z| >= DRIFT_Z`` with a standard error from the scatter left after the fit, inflated
  for its correlation from block to block;
* it is of a size that matters: at least ``MIN_SIZE_FRACTION`` (the diagnosis' practical floor) of the catalogue's
  typical drift. The diagnosis' second floor, an effect of half the per-sample noise, is not applied: a drift's
  size is its rate, and its effect is small only because it began a short while ago;
* it explains the thermocouples' slow residual: the fit removes at least ``PARTIAL_GAIN_PCT`` (80 %) of the block
  residual's variance about the offsets, and each thermocouple's own rate agrees in sign and within a factor of
  ``CHANNEL_AGREEMENT``. A thermocouple offset, gain or lag, a weaker TEM or a driver dead zone leave residuals
  that follow the temperatures' swings or one channel only, which a common drift does not explain.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: significance of the fitted rate (fitted / standard error)
DRIFT_Z = 6.0
#: each thermocouple's own fitted rate must be within this factor of the other's (and of the same sign)
CHANNEL_AGREEMENT = 3.0
#: the residuals are averaged over blocks of this length [s]
BLOCK_S = 1.0
#: the fewest blocks the test is made on
MIN_BLOCKS = 15


@dataclass
class DriftFit:
    """The fitted ambient drift of a window and whether it is named."""

    rate_C_per_h: float  # fitted ambient / coolant drift [degC/h]
    z: float  # rate / its standard error
    explained: float  # fraction of the block residual's variance (about the offsets) the drift explains
    channel_rates: tuple[float, float]  # each thermocouple's own fit [degC/h]
    blocks: int
    left_over_noise: float  # RMS of the blocks' residual after the fit / the noise of a block
    named: bool
    #: probability that the rate is at least the practical floor, from its estimate and standard error (what the
    #: diagnosis' bootstrap gives its named causes)
    confidence: float = 0.0

    def summary(self) -> str:
        return (
            f'thermal discrepancy: ambient/coolant temperature drift (ambient_drift; ambient_drift_C_per_h = '
            f'{self.rate_C_per_h:.4g} degC/h), fitted to the 1 s averages of both thermocouples over '
            f'{self.blocks} s (z = {self.z:.1f}, explains {100 * self.explained:.0f} % of their slow residual)'
        )


def _blocks(x: np.ndarray, n: int) -> np.ndarray:
    """Means of consecutive blocks of ``n`` rows of ``x`` (K, C) -> (K // n, C)."""
    b = x.shape[0] // n
    return x[: b * n].reshape(b, n, -1).mean(axis=1)


def ambient_drift_fit(run, base=None) -> DriftFit | None:  # type: ignore[no-untyped-def]
    """Fit the catalogue's ambient drift to ``run`` (a monitor window: :class:`sma_wrist.diagnose.data.Run` with
    ``settle_s`` and the twin's ``thermal_x0``) on the 1 s averages of what follows its lead-in; ``base``: the
    nominal plant (PlantParams, None: the built-in one). None when the run has no commands or temperatures, or too
    little after its lead-in."""
    from sma_wrist.diagnose import MIN_SIZE_FRACTION, PARTIAL_GAIN_PCT, PARTIAL_RATIO
    from sma_wrist.diagnose import effects as fx

    if run.u is None or run.T is None:
        return None
    n = max(1, int(round(BLOCK_S / run.dt)))
    i0 = int(round(max(getattr(run, 'settle_s', 0.0), 0.0) / run.dt))
    if (run.n - i0) // n < MIN_BLOCKS:
        return None
    key = fx.INDEX['ambient_drift_C_per_h']
    typical = float(fx.TYPICAL[key])
    model = fx.ExtendedModel(run, base)
    pred = model.thermal_measured(np.stack([fx.NOMINAL, fx.theta(ambient_drift_C_per_h=typical)]))  # (K, 2, 2)
    # the replay starts each muscle from its first reading, smoothed; what that start gets wrong decays over the
    # muscle's time constant: each channel's response to a start 1 degC off is fitted along (a nuisance)
    starts = []
    for c in (0, 1):
        m = fx.ExtendedModel(run, base)
        m.T_start = model.T_start + np.eye(2)[c]
        starts.append(_blocks(m.thermal_measured(fx.NOMINAL[None])[i0:, 0] - pred[i0:, 0], n))
    E = _blocks(run.T[i0:] - pred[i0:, 0], n)  # residual of the nominal model (B, 2)
    G = _blocks(pred[i0:, 1] - pred[i0:, 0], n)  # response to the typical drift
    ok = np.ones(E.shape[0], bool)
    if run.valid is not None:  # blocks with bridged gaps left out
        ok = _blocks(np.asarray(run.valid, float)[i0:, None], n)[:, 0] == 1.0
    B = int(ok.sum())
    if B < MIN_BLOCKS:
        return None
    one = np.ones((B, 1))
    zero = np.zeros((B, 1))
    # both channels stacked: an offset each, the two start responses, the drift (last column)
    X = np.block(
        [
            [one, zero, starts[0][ok, :1], starts[1][ok, :1], G[ok, :1]],
            [zero, one, starts[0][ok, 1:], starts[1][ok, 1:], G[ok, 1:]],
        ]
    )
    y = np.concatenate([E[ok, 0], E[ok, 1]])
    beta, *_ = np.linalg.lstsq(X, y, rcond=None)
    R = (y - X @ beta).reshape(2, B).T
    s = float(beta[-1])  # in units of the typical drift
    dof = max(2 * B - X.shape[1], 1)
    var = float(np.sum(R * R)) / dof
    # correlation of the residual from block to block (slow noise, what the model misses): the standard error of a
    # smooth regressor's coefficient grows by (1 + rho) / (1 - rho)
    rho = float(np.sum(R[1:] * R[:-1]) / max(np.sum(R * R), 1e-30))
    rho = min(max(rho, 0.0), 0.9)
    cov = np.linalg.pinv(X.T @ X)
    se = float(np.sqrt(var * (1.0 + rho) / (1.0 - rho) * cov[-1, -1]))
    z = s / se if se > 0 else 0.0
    # what the drift explains of the residual left by the offsets and the start responses
    Xn = X[:, :-1]
    bn, *_ = np.linalg.lstsq(Xn, y, rcond=None)
    rn = y - Xn @ bn
    explained = 1.0 - float(np.sum(R * R)) / max(float(np.sum(rn * rn)), 1e-30)
    per = []
    for c in (0, 1):
        Xc = X[c * B : (c + 1) * B][:, [c, 2, 3, 4]]
        bc, *_ = np.linalg.lstsq(Xc, y[c * B : (c + 1) * B], rcond=None)
        per.append(float(bc[-1]) * typical)
    rate = s * typical
    # the diagnosis' rule for a cause that explains only part of a channel (PARTIAL_RATIO, PARTIAL_GAIN_PCT), on the
    # blocks: what the fit leaves is above PARTIAL_RATIO x the noise of a block and it removed less than 80 %
    sigma_block = fx.noise_sigma(run.T, fx.TEMP_LSB_C) / np.sqrt(n)
    left = float(np.sqrt(np.mean(R * R)))
    partial = left > PARTIAL_RATIO * sigma_block and explained < PARTIAL_GAIN_PCT / 100.0
    agree = per[0] * per[1] > 0 and max(abs(per[0]), abs(per[1])) <= CHANNEL_AGREEMENT * min(abs(per[0]), abs(per[1]))
    named = bool(
        abs(z) >= DRIFT_Z
        and abs(rate) >= MIN_SIZE_FRACTION * typical
        and not partial
        and agree
        and fx.LOWER[key] < rate < fx.UPPER[key]
    )
    floor = MIN_SIZE_FRACTION * typical
    se_rate = abs(rate / z) if z else float('inf')
    confidence = 0.5 * math.erfc(-(abs(rate) - floor) / (se_rate * math.sqrt(2.0))) if math.isfinite(se_rate) else 0.0
    return DriftFit(rate, z, explained, (per[0], per[1]), B, left / sigma_block, named, round(confidence, 3))
