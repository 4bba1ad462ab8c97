"""Signal operations shared by the model's users: sensor effects applied to, or fitted on, simulated series."""

from __future__ import annotations

from typing import Any

import numpy as np


def first_order(x: np.ndarray, tau: Any, dt: float, linear: bool = False) -> np.ndarray:
    """First-order lag dy/dt = (x - y) / tau of time constant ``tau`` [s] along axis 0, x[0] at rest; ``tau`` <= 0
    returns x. Exact discretisation for x held over each interval [t_k-1, t_k) at x[k] (y_k = a y_k-1 + (1 - a) x_k,
    a = exp(-dt / tau)), or with ``linear`` for x linear between the samples (y_k = a y_k-1 + b1 x_k + b0 x_k-1,
    b1 = 1 - c (1 - a), b0 = c (1 - a) - a, c = tau / dt): a sampled smooth signal, whose held form lags a ramp by
    a dt / (1 - a) instead of tau (0.10 s for tau 0.2 s at dt 0.25 s). A complex ``tau`` (a complex-step
    derivative) gives the complex filter."""
    if np.real(tau) <= 0:
        return x
    a = np.exp(-dt / tau)
    a = float(a) if np.isrealobj(a) else complex(a)
    from scipy.signal import lfilter

    if linear:
        g = tau / dt * (1 - a)
        b, r = [1 - g, g - a], g  # r: the state at rest per unit input (y = x at rest)
    else:
        b, r = [1 - a], a
    zi = (r * x[0])[None] if x.ndim > 1 else np.array([r * x[0]])
    y, _ = lfilter(b, [1, -a], x, axis=0, zi=zi)
    return y


__all__ = ['first_order']
