"""Plants that are not the controllers' model (issue 14): name -> factory of a benchmark wrist.

Each factory takes the payloads (kg, one per wrist) and returns a plant with the interface the
closed loop drives: ``advance(command_V (N, 2), n_steps)``, ``state.q``, ``muscle_temperature_C``,
``wire_stress_Pa``, ``measure()``.
"""
from __future__ import annotations

from typing import Any, Callable

import numpy as np


def _phase_fraction(payload_kg: Any, **kwargs: Any) -> Any:
    from sma_wrist.plants.phase_fraction import PhaseFractionParams, PhaseFractionPlant
    return PhaseFractionPlant(PhaseFractionParams(**kwargs) if kwargs else None, payload_kg=np.asarray(payload_kg))


PLANTS: dict[str, Callable[..., Any]] = {
    'phase_fraction': _phase_fraction,
}

__all__ = ['PLANTS']
