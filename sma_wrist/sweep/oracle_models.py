"""The closed loop given the plant's own models (a diagnosis, not a controller): what ``simulate(..., oracle=...)``
swaps in, and what ``python -m sma_wrist.plants.oracle`` measures with it (doc/explanation/controllers.md). Here, below both the sweep engine and that study, so neither imports the other's module to reach them.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

from sma_wrist.core.control.joint_controller import JointControllerParams
from sma_wrist.core.errors import ParameterError
from sma_wrist.core.hysteresis.compensation import MuscleCompensator
from sma_wrist.core.plant.wrist import PlantParams
from sma_wrist.plants.spread import Scenario, scenario_params
from sma_wrist.sweep.laws import TemLoopBank

#: the models the loop can be given the plant's own of (:func:`check`)
SWITCHES = ('hysteresis', 'thermal', 'payload', 'sensors')


def check(switches: Sequence[str], plant: str = 'sdgpi', scenarios: Sequence[Scenario] = ()) -> None:
    """ParameterError unless ``switches`` are known names of :data:`SWITCHES`, the plant is the project's
    (``sdgpi``: the only one whose models are the controllers' kind) and ``scenarios`` are one plant."""
    if isinstance(switches, str):
        raise ParameterError(f'oracle: a sequence of switch names, not the string {switches!r}')
    bad = sorted(set(switches) - set(SWITCHES))
    if bad:
        raise ParameterError(f'oracle: unknown switch(es) {", ".join(map(repr, bad))}; known: {", ".join(SWITCHES)}')
    if plant != 'sdgpi':
        raise ParameterError(f"oracle: the plant's own models exist for the project's plant (sdgpi), not {plant!r}")
    if len({dataclasses.replace(s, noise_seed=0) for s in scenarios}) > 1:
        raise ParameterError(
            'oracle: the loops need one model per plant; run one plant (scenario) at a time '
            '(sma_wrist.plants.loop.run_cases does)'
        )


def own_compensator(built: MuscleCompensator, scenario: Scenario, base: PlantParams | None = None) -> MuscleCompensator:
    """The compensator ``built`` (window, geometry) on the plant's own SD-GPI, adaptation off."""
    own = scenario_params(scenario, base).hysteresis
    return MuscleCompensator(own, built.geometry, T_range_C=built.T_range_C)


def own_tem_bank(built: Any, scenario: Scenario, base: PlantParams | None = None) -> Any:
    """A :class:`~sma_wrist.sweep.laws.TemLoopBank` like ``built`` on the plant's own heat balance
    (command limits: ``built``'s law and hold limits)."""
    own = scenario_params(scenario, base).thermal
    law = dataclasses.replace(own, u_min_V=built.thermal.u_min_V, u_max_V=built.thermal.u_max_V)
    hold = dataclasses.replace(
        own, u_min_V=built.hold.u_min_V, u_max_V=built.hold.u_max_V, tem_hold_limits_V=built.hold.tem_hold_limits_V
    )
    return TemLoopBank(built.n, law, built.params, built.drive, hold, built.max_muscle_C)


def knows_payload(params: JointControllerParams, payload_kg: float) -> JointControllerParams:
    """``params`` whose adaptive law knows the payload [kg]: theta_hat starts at it and holds (Gamma_a = 0),
    its inertia in I (ControlGeometry.known_payload_kg)."""
    a = params.adaptive
    return dataclasses.replace(
        params,
        adaptive=dataclasses.replace(
            a,
            theta0_kg=float(payload_kg),
            gamma_a=0.0,
            geometry=dataclasses.replace(a.geometry, known_payload_kg=float(payload_kg)),
        ),
    )


__all__ = ['SWITCHES', 'check', 'own_compensator', 'own_tem_bank', 'knows_payload']
