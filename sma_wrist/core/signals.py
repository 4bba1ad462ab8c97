"""Signal operations shared by the model's users: sensor effects applied to, or fitted on, simulated series."""

from __future__ import annotations

from typing import Any

import numpy as np


def first_order(x: np.ndarray, tau: Any, dt: float) -> np.ndarray:
    """First-order lag of time constant ``tau`` [s] along axis 0 (exact discretisation for a held input), x[0] at
    rest; ``tau`` <= 0 returns x. A complex ``tau`` (a complex-step derivative) gives the complex filter."""
    if np.real(tau) <= 0:
        return x
    a = np.exp(-dt / tau)
    a = float(a) if np.isrealobj(a) else complex(a)
    from scipy.signal import lfilter

    zi = (a * x[0])[None] if x.ndim > 1 else np.array([a * x[0]])
    y, _ = lfilter([1 - a], [1, -a], x, axis=0, zi=zi)
    return y


__all__ = ['first_order']
