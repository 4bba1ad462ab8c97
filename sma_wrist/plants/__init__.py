"""Plants that are not the controllers' model: for tests, benchmarks, plant_sim and ``sma-wrist sweep``.

Registry :data:`PLANTS`: name -> factory. A factory takes the scenarios (one
:class:`~sma_wrist.plants.spread.Scenario` per wrist: payload and perturbations) and the base
:class:`~sma_wrist.core.plant.wrist.PlantParams` (dt, limits), and returns a plant with the interface
plant_sim and the sweep use: ``advance(command (N, 2) [V], n_steps)``, ``state`` (t, q, qd,
thermal, payload_kg, flags), ``muscle_temperature_C`` (N, 2), ``wire_stress_Pa`` (N, 2),
``muscle_torque_Nm`` (N,), ``params`` (thermal limits and window, dt). Sensor effects are not
the plant's: :class:`~sma_wrist.plants.spread.SensorBank` applies them to what is published.

* ``sdgpi``: the project's plant (SD-GPI wire, Eqs. 3.19-4.6) with the scenario's parameter
  spread (:mod:`sma_wrist.plants.spread`); at the nominal scenario it is the plain plant.
* ``phase_fraction``: a structurally different wire (Brinson / Liang-Rogers kind,
  sma_wrist/plants/phase_fraction.py), options ``tc_lag_s`` (its own thermocouple's lag).

Wires identified from real data: ``hysteresis_file`` (:func:`load_hysteresis`) replaces the
SD-GPI set the ``sdgpi`` plant perturbs.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from sma_wrist.core.errors import ParameterError
from sma_wrist.core.hysteresis.sdgpi import SDGPIParams
from sma_wrist.core.plant.wrist import PlantParams

PlantFactory = Callable[..., Any]


def _sdgpi(scenarios: Sequence[Any], base: PlantParams | None = None, hysteresis_file: str | None = None) -> Any:
    from sma_wrist.plants.spread import build_plant

    return build_plant(scenarios, base, load_hysteresis(hysteresis_file) if hysteresis_file else None)


def _phase_fraction(scenarios: Sequence[Any], base: PlantParams | None = None, **options: Any) -> Any:
    from sma_wrist.plants.phase_fraction import factory

    return factory(scenarios, base, **options)


#: name -> factory(scenarios, base PlantParams, **options) -> plant (see the module docstring)
PLANTS: dict[str, PlantFactory] = {'sdgpi': _sdgpi, 'phase_fraction': _phase_fraction}


def make_plant(name: str, scenarios: Sequence[Any], base: PlantParams | None = None, **options: Any) -> Any:
    """The registered plant ``name`` for the scenarios; unknown names raise ParameterError."""
    if name not in PLANTS:
        raise ParameterError(f'unknown plant {name!r}; registered: {", ".join(sorted(PLANTS))}')
    return PLANTS[name](scenarios, base, **options)


def load_hysteresis(path: str | Path) -> SDGPIParams:
    """SD-GPI parameters identified from measured data (a ``hysteresis.yaml`` from ``sma-wrist identify
    hysteresis``); ParameterError names the file and what is wrong."""
    from sma_wrist.core.hysteresis.params_file import load_hysteresis as load

    return load(path)


__all__ = ['PLANTS', 'PlantFactory', 'make_plant', 'load_hysteresis']
