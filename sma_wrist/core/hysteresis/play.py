"""Play and stop operators: the memory elements of the Prandtl-Ishlinskii family.

All operators here are rate independent: their output depends on the sequence of
input extrema, not on how fast the input moves between them. Every update is a
clamp of the previous operator state between two bounds, which is why the whole
module reduces to :func:`play_update` plus the bounds each operator uses.

Shapes: the last axis of an operator state is the operator index j (thresholds r_j);
leading axes are free (scenarios). Time is handled by the ``*_series`` helpers,
which loop over samples (the operator recursion is inherently sequential) but are
vectorised over thresholds and scenarios.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sma_wrist.core.errors import ModelInputError, check_finite

FloatArray = NDArray[np.float64]


def play_update(w: FloatArray, lower: ArrayLike, upper: ArrayLike, out: FloatArray | None = None) -> FloatArray:
    """One step of a (generalized) play operator: ``max(lower, min(upper, w))``.

    This is f(v, w) of Eq. 5.4 with lower = v - r, upper = v + r, and
    f^gamma_lr(T, w) of Eq. 3.19 with lower = gamma_l(T) - r, upper = gamma_r(T) + r.
    ``lower <= upper`` is the caller's responsibility (it holds for r >= 0 and
    gamma_l <= gamma_r).
    """
    return np.minimum(np.maximum(w, lower, out=out), upper, out=out)


def play_series(v: ArrayLike, thresholds: ArrayLike, w0: ArrayLike | None = None) -> FloatArray:
    """Classical play operators F_r[v] (Eqs. 5.1-5.4) for a sampled input.

    Parameters
    ----------
    v : array_like, shape (N,)
        Input samples.
    thresholds : array_like, shape (n,)
        Thresholds r_j >= 0.
    w0 : array_like, shape (n,), optional
        Initial operator states; default ``f_r(v(0), 0)`` (Eq. 5.1).

    Returns
    -------
    numpy.ndarray, shape (N, n)
        Operator outputs.
    """
    v = np.asarray(v, dtype=float)
    r = np.asarray(thresholds, dtype=float)
    check_finite('play input v', v)
    if np.any(r < 0):
        raise ModelInputError('play threshold r', float(r.min()), '[0, inf)')
    w = np.zeros_like(r) if w0 is None else np.array(w0, dtype=float)
    out = np.empty((v.size, r.size))
    for k, vk in enumerate(v):
        w = play_update(w, vk - r, vk + r)
        out[k] = w
    return out


def stop_update(e: FloatArray, dv: ArrayLike, thresholds: ArrayLike) -> FloatArray:
    """One step of the stop operator, Eqs. 5.18-5.19: ``E = e_r(dv + E_prev)``.

    e_r(v) = min(r, max(-r, v)). The stop and play operators are complementary:
    F_r[v] = v - E_r[v] (Eq. 5.17).
    """
    r = np.asarray(thresholds, dtype=float)
    return np.minimum(r, np.maximum(-r, e + dv))


def stop_series(v: ArrayLike, thresholds: ArrayLike, e0: ArrayLike | None = None) -> FloatArray:
    """Stop operators E_r[v] (Eqs. 5.18-5.19) for a sampled input, shape (N, n).

    ``e0`` is the initial stop state; the default ``e_r(v(0))`` corresponds to
    omega_{-1} = 0 in Eq. 5.18.
    """
    v = np.asarray(v, dtype=float)
    r = np.asarray(thresholds, dtype=float)
    check_finite('stop input v', v)
    e = np.minimum(r, np.maximum(-r, v[0])) if e0 is None else np.array(e0, dtype=float)
    out = np.empty((v.size, r.size))
    out[0] = e
    for k in range(1, v.size):
        e = stop_update(e, v[k] - v[k - 1], r)
        out[k] = e
    return out
