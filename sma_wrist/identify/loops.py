"""What a loop says, measured or simulated: stroke, transition temperatures, errors.

Transition temperatures of a branch are the temperatures where the branch has covered 10 %,
50 % and 90 % of its elongation change (A_s, A_50, A_f while heating; M_s, M_50, M_f while
cooling), found at the first crossing along the branch. Errors are in % of the measured
loop's stroke (its elongation range) at that stress, as Eq. 4.3 normalises.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

LEVELS = (0.1, 0.5, 0.9)


def _crossing(T: FloatArray, y: FloatArray, level: float) -> float:
    s = np.sign(y - level)
    idx = np.nonzero(s[:-1] * s[1:] <= 0)[0]
    if idx.size == 0:
        return float('nan')
    k = int(idx[0])
    if y[k + 1] == y[k]:
        return float(T[k])
    f = (level - y[k]) / (y[k + 1] - y[k])
    return float(T[k] + f * (T[k + 1] - T[k]))


def split_branches(T: FloatArray, first_branch: str) -> tuple[slice, slice]:
    """(heating, cooling) slices of a one-cycle loop, split at its temperature extreme."""
    k = int(np.argmax(T)) if first_branch == 'heating' else int(np.argmin(T))
    first, second = slice(0, k + 1), slice(k, T.size)
    return (first, second) if first_branch == 'heating' else (second, first)


def transitions(T: FloatArray, y: FloatArray, first_branch: str) -> dict[str, float]:
    """A_s, A_50, A_f, M_s, M_50, M_f [degC] and the stroke [mm] (see the module docstring)."""
    h, c = split_branches(T, first_branch)
    out: dict[str, float] = {}
    for name, sl in (('A', h), ('M', c)):
        Tb, yb = T[sl], y[sl]
        if Tb.size < 3:
            out.update({f'{name}_s': float('nan'), f'{name}_50': float('nan'), f'{name}_f': float('nan')})
            continue
        y0, y1 = float(np.median(yb[:3])), float(np.median(yb[-3:]))
        for tag, q in zip(('s', '50', 'f'), LEVELS):
            out[f'{name}_{tag}'] = _crossing(Tb, yb, y0 + q * (y1 - y0))
    out['stroke_mm'] = float(np.ptp(y))
    return out


def errors_pct(y_model: FloatArray, y: FloatArray) -> tuple[float, float]:
    """(RMS, max) |model - measured| in % of the measured stroke."""
    e = np.asarray(y_model) - np.asarray(y)
    stroke = max(float(np.ptp(y)), 1e-12)
    return float(100 * np.sqrt(np.mean(e**2)) / stroke), float(100 * np.max(np.abs(e)) / stroke)


def slope(x: FloatArray, v: FloatArray) -> float:
    """Least-squares slope dv/dx over the finite points (nan with fewer than 2)."""
    x, v = np.asarray(x, float), np.asarray(v, float)
    ok = np.isfinite(x) & np.isfinite(v)
    if ok.sum() < 2 or np.ptp(x[ok]) == 0:
        return float('nan')
    return float(np.polyfit(x[ok], v[ok], 1)[0])
