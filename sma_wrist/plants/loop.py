"""The controllers on named off-model plants: doc/explanation/controllers.md's "Feedback off-model" cases.

A thin layer over the sweep engine (:func:`sma_wrist.sweep.simulate.simulate`, which equals the
node graph to the last bit, test_plants): :data:`CASES` names plants of the family
(:class:`~sma_wrist.plants.spread.Scenario` on a registered plant), :func:`run_loop` runs one
of them under one mode, :func:`run_cases` runs many in one vectorised call per plant, and
:func:`reach_floor_pct` gives the least max error any controller can have on a case (the angle
range the wrist reaches inside the controllers' temperature window).

Used by test_offmodel.py and for the off-model figures of doc/explanation/controllers.md
(``python -m sma_wrist.plants.loop``; ``sma-wrist sweep`` samples the whole family).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from sma_wrist.core.control.tem import TemControlParams, TemperatureObserverParams
from sma_wrist.core.errors import ParameterError
from sma_wrist.core.metrics import SEED_PERIOD_S
from sma_wrist.core.plant.wrist import PlantParams, WristPlant
from sma_wrist.core.thermal.online import OnlineThermalParams
from sma_wrist.plants.spread import Scenario, perturbed_hysteresis, scenario_params
from sma_wrist.sweep.simulate import (
    CHATTER_DEADBAND_V,
    SHIFT_GAIN_PER_S,
    Case,
    Trace,
    check_true_temperature,
    sign_changes_per_s,
    simulate,
)

#: a command counts as heating above +REVERSAL_BAND_V and as cooling below -REVERSAL_BAND_V
REVERSAL_BAND_V = CHATTER_DEADBAND_V

#: the SD-GPI with shifted transition temperatures and scaled stroke (one construction: spread's)
shifted_sdgpi = perturbed_hysteresis


@dataclass(frozen=True)
class OffModelCase:
    """A named plant: a registered plant (sma_wrist.plants) and its scenario."""

    plant: str
    scenario: Scenario


def reach(
    case: OffModelCase, T_window_C: tuple[float, float] = (20.0, 80.0), base: PlantParams | None = None
) -> tuple[float, float]:
    """(lowest, highest) angle [rad] a perturbed project wrist holds with its muscle temperatures
    imposed inside the controllers' window (one muscle hot, the other cold, both ways round,
    each approached along its branch; WristPlant.step_mechanics, no heat balance). A reference
    outside it cannot be tracked by any controller: its excess is a floor under the max error.
    ``base``: the plant the scenario perturbs (e.g. an identified wire's; None: the built-in one)."""
    if case.plant != 'sdgpi':
        raise ParameterError(f"reach is computed on the project's plant (sdgpi), not {case.plant!r}")
    lo, hi = T_window_C
    plant = WristPlant(scenario_params(case.scenario, base), payload_kg=case.scenario.payload_kg)
    T0 = float(plant.muscle_temperature_C[0, 0])
    n = 3000
    for T in np.linspace(T0, hi, n):
        plant.step_mechanics(np.array([[T, lo]]))
    for _ in range(n):
        plant.step_mechanics(np.array([[hi, lo]]))
    top = float(plant.state.q[0])
    for k in range(n):
        f = k / n
        plant.step_mechanics(np.array([[hi - (hi - lo) * f, lo + (hi - lo) * f]]))
    for _ in range(n):
        plant.step_mechanics(np.array([[lo, hi]]))
    return float(plant.state.q[0]), top


def reach_floor_pct(
    case: OffModelCase,
    q_range: tuple[float, float] = (0.0, 1.048),
    T_window_C: tuple[float, float] = (20.0, 80.0),
    base: PlantParams | None = None,
) -> float:
    """Least max error [% of the range] any controller can have on the Sec. 6.1 sine (:func:`reach` inside the
    controllers' window ``T_window_C`` [degC] on the plant ``base`` perturbs): a static floor; what TEM schedules
    reach in time is :mod:`sma_wrist.plants.dynamic_reach`'s."""
    bottom, top = reach(case, T_window_C, base)
    miss = max(q_range[1] - top, bottom - q_range[0], 0.0)
    return 100.0 * miss / (q_range[1] - q_range[0])


@dataclass
class LoopResult:
    max_error_pct: float
    rms_error_pct: float
    reversals_per_s: float  # TEM command sign changes per second (band +-REVERSAL_BAND_V), worse TEM
    row: dict[str, Any]  # the sweep's result row
    trace: Trace | None = None


def reversals_per_s(u: Any, dt: float, band_V: float = REVERSAL_BAND_V) -> float:
    """Sign changes per second of the TEM commands u (K, 2) sampled every dt [s], counted between the
    bands +-band_V (a command inside the band keeps the last sign); the larger of the two TEMs
    (:func:`sma_wrist.sweep.simulate.sign_changes_per_s`)."""
    return float(np.max(sign_changes_per_s(np.asarray(u, float), dt, band_V)))


def _result(row: dict[str, Any], trace: Trace | None = None) -> LoopResult:
    return LoopResult(row['max_error_pct'], row['rms_error_pct'], row['sign_changes_per_s'], row, trace)


def run_cases(
    cases: Sequence[tuple[OffModelCase, str]],
    duration_s: float = 126.0,
    window_s: float = SEED_PERIOD_S,
    tem_params: TemControlParams | None = None,
    shift_gain_per_s: float = SHIFT_GAIN_PER_S,
    on_tick: Callable[[float], None] | None = None,
    true_temperature: Sequence[str] = (),
    compensator_observer: TemperatureObserverParams | None = TemperatureObserverParams(),
    oracle: Sequence[str] = (),
    **compensator: Any,
) -> list[LoopResult]:
    """(case, mode) pairs as closed loops of the sweep engine, one vectorised run per plant; results in order.
    ``true_temperature``, ``compensator_observer``, ``compensator`` (``window_follows_shift``,
    ``stroke_gain_per_s``): as in
    :func:`~sma_wrist.sweep.simulate.simulate`. ``oracle`` (a diagnosis, :mod:`sma_wrist.plants.oracle`):
    the loops with the plant's own models, one run per scenario (each needs its own models)."""
    out: list[LoopResult | None] = [None] * len(cases)
    # with an oracle a run holds one scenario (sensor noise streams aside), else one registered plant
    group = (lambda c: (c.plant, replace(c.scenario, noise_seed=0))) if oracle else (lambda c: c.plant)
    for key in dict.fromkeys(group(c) for c, _ in cases):
        idx = [i for i, (c, _) in enumerate(cases) if group(c) == key]
        plant = cases[idx[0]][0].plant
        rows, _ = simulate(
            [Case(i, cases[i][1], cases[i][0].scenario) for i in idx],
            duration_s,
            plant,
            on_tick=on_tick,
            window_s=window_s,
            tem_params=tem_params,
            shift_gain_per_s=shift_gain_per_s,
            true_temperature=true_temperature,
            compensator_observer=compensator_observer,
            oracle=oracle,
            **compensator,
        )
        for i, row in zip(idx, rows):
            out[i] = _result(row)
    return [r for r in out if r is not None]


def run_loop(
    case: OffModelCase,
    mode: str,
    duration_s: float = 126.0,
    window_s: float = SEED_PERIOD_S,
    tem_params: TemControlParams | None = None,
    shift_gain_per_s: float = SHIFT_GAIN_PER_S,
    record: bool = False,
    on_tick: Callable[[float], None] | None = None,
    true_temperature: Sequence[str] = (),
    compensator_observer: TemperatureObserverParams | None = TemperatureObserverParams(),
    **compensator: Any,
) -> LoopResult:
    """One case under one mode (the node graph's loop, :mod:`sma_wrist.sweep.simulate`) for ``duration_s``;
    metrics over the last ``window_s`` (the last full cycle of the Sec. 6.1 sine). ``tem_params`` /
    ``shift_gain_per_s``: the laws' parameters (default: the nodes'); ``true_temperature``,
    ``compensator_observer``, ``compensator``: as in :func:`run_cases`."""
    rows, trace = simulate(
        [Case(0, mode, case.scenario)],
        duration_s,
        case.plant,
        record=record,
        on_tick=on_tick,
        window_s=window_s,
        tem_params=tem_params,
        shift_gain_per_s=shift_gain_per_s,
        true_temperature=true_temperature,
        compensator_observer=compensator_observer,
        **compensator,
    )
    return _result(rows[0], trace)


#: the off-model cases of doc/explanation/controllers.md: name -> (payload [kg] -> case). Sensors: thermocouple lag
#: 0.2 s and noise 0.2 degC, potentiometer noise 3 mrad; the phase-fraction wrist has its own 0.2 s
#: thermocouple lag and gets the same noise
_SENSORS = dict(temp_lag_s=0.2, temp_noise_C=0.2, angle_noise_rad=0.003)
_PF_NOISE = dict(temp_noise_C=0.2, angle_noise_rad=0.003)


def _sd(**kw: Any) -> Callable[[float], OffModelCase]:
    return lambda m: OffModelCase('sdgpi', Scenario(payload_kg=m, **kw))


CASES: dict[str, Callable[[float], OffModelCase]] = {
    'nominal': _sd(),
    'sensors': _sd(**_SENSORS),
    'T+10': _sd(transition_shift_C=10.0),
    'T+5': _sd(transition_shift_C=5.0),
    'T-10': _sd(transition_shift_C=-10.0),
    'stroke x0.7': _sd(stroke_scale=0.7),
    'stroke x1.3': _sd(stroke_scale=1.3),
    'TEM gain -30%': _sd(tem_gain_scale=0.7),
    'TEM gain +30%': _sd(tem_gain_scale=1.3),
    'losses +30%': _sd(heat_loss_scale=1.3),
    'losses -30%': _sd(heat_loss_scale=0.7),
    'ambient +5': _sd(ambient_offset_C=5.0),
    'ambient -5': _sd(ambient_offset_C=-5.0),
    'mixed A': _sd(
        transition_shift_C=5.0,
        stroke_scale=0.85,
        tem_gain_scale=0.85,
        heat_loss_scale=1.15,
        ambient_offset_C=3.0,
        noise_seed=1,
        **_SENSORS,
    ),
    'mixed B': _sd(
        transition_shift_C=-5.0,
        stroke_scale=1.15,
        tem_gain_scale=1.15,
        heat_loss_scale=0.85,
        ambient_offset_C=-3.0,
        noise_seed=2,
        **_SENSORS,
    ),
    'phase_fraction': lambda m: OffModelCase('phase_fraction', Scenario(payload_kg=m, **_PF_NOISE)),
}
MODES = ('inverse_adaptive', 'direct_adaptive', 'pid')


def _main(
    argv: list[str] | None = None,
) -> None:  # pragma: no cover - the report quoted in doc/explanation/controllers.md
    import argparse
    import json
    import sys
    import time

    ap = argparse.ArgumentParser(
        description='the three controllers on off-model plants (doc/explanation/controllers.md)'
    )
    ap.add_argument('--cases', default=','.join(CASES))
    ap.add_argument('--modes', default=','.join(MODES))
    ap.add_argument('--payloads', default='0.3')
    ap.add_argument('--duration', type=float, default=126.0)
    ap.add_argument(
        '--legacy',
        action='store_true',
        help='the controllers without their off-model features: no target prefilter, no temperature-axis adaptation, '
        'the compensator on the thermocouples',
    )
    ap.add_argument(
        '--without-observer',
        action='store_true',
        help='the compensator without its observer (doc/explanation/controllers.md): on the thermocouples, its '
        'window not following the shift, the axis adapting at 1 /s',
    )
    ap.add_argument(
        '--thermocouple',
        action='store_true',
        help='the compensator reads the thermocouples (hysteresis_compensator temperature_source '
        'thermocouple) instead of the observer',
    )
    ap.add_argument(
        '--before-lead',
        action='store_true',
        help='direct_adaptive and pid as before their reference leads (doc/explanation/'
        'controllers.md): laws on q_d(t), direct map 1 N/degC',
    )
    ap.add_argument(
        '--before-direct-map',
        action='store_true',
        help='direct_adaptive with its temperature map before the proportional band (doc/explanation/'
        'controllers.md): 3 N/degC, no output filter',
    )
    ap.add_argument(
        '--true-temperature',
        default='',
        metavar='CONSUMERS',
        help='diagnosis: comma list of compensator,tem that read the true muscle temperature instead '
        'of the thermocouple (doc/explanation/controllers.md)',
    )
    ap.add_argument(
        '--observer',
        default='',
        metavar='CORRECTION_S,LAG_S',
        help="the observer's parameters (hysteresis_compensator observer.*; default 0.33,0.2)",
    )
    ap.add_argument(
        '--stroke-gain',
        type=float,
        default=None,
        metavar='PER_S',
        help="hysteresis_compensator's stroke_gain_per_s (0: the model's stroke; default the node's)",
    )
    ap.add_argument(
        '--hold-shift-on-stop',
        choices=('on', 'off'),
        help="hysteresis_compensator's hold_shift_on_stop (default the node's)",
    )
    ap.add_argument(
        '--hold-shift-outside-load-range',
        choices=('on', 'off'),
        help="hysteresis_compensator's hold_shift_outside_load_range (default the node's)",
    )
    ap.add_argument(
        '--oracle',
        default='',
        metavar='SWITCHES',
        help="diagnosis: comma list of hysteresis,thermal,payload,sensors: the loop given the plant's "
        'own model(s) (doc/explanation/controllers.md)',
    )
    ap.add_argument(
        '--thermal-adaptation',
        choices=('on', 'off'),
        help="tem_controller's and hysteresis_compensator's thermal_adaptation (default the nodes')",
    )
    ap.add_argument('--json', action='store_true')
    a = ap.parse_args(argv)
    kw: dict[str, Any] = {}
    if a.legacy:
        kw = {'tem_params': TemControlParams(rate_filter_s=0.05), 'shift_gain_per_s': 0.0}
    if a.legacy or a.without_observer:
        kw.update(compensator_observer=None, window_follows_shift=False, stroke_gain_per_s=0.0, online_thermal=None)
    if a.thermal_adaptation is not None:
        kw['online_thermal'] = OnlineThermalParams() if a.thermal_adaptation == 'on' else None
    if a.stroke_gain is not None:
        kw['stroke_gain_per_s'] = a.stroke_gain
    if a.hold_shift_on_stop is not None:
        kw['hold_shift_on_stop'] = a.hold_shift_on_stop == 'on'
    if a.hold_shift_outside_load_range is not None:
        kw['hold_shift_outside_load_range'] = a.hold_shift_outside_load_range == 'on'
    if a.without_observer:
        kw['shift_gain_per_s'] = 1.0
    if a.thermocouple:
        kw['compensator_observer'] = None
    if a.before_lead:
        kw['controller_overrides'] = {
            'pid_reference_lead_s': 0.0,
            'direct_reference_lead_s': 0.0,
            'force_per_degC_N': 1.0,
            'direct_output_filter_s': 0.0,
        }
    if a.before_direct_map:
        kw['controller_overrides'] = {'force_per_degC_N': 3.0, 'direct_output_filter_s': 0.0}

    def names(option: str, value: str, check: Callable[[Sequence[str]], None]) -> tuple[str, ...]:
        """A comma list of names, checked; a bad one ends the program with the option's name."""
        items = tuple(value.split(','))
        try:
            check(items)
        except ParameterError as e:
            ap.error(f'{option}: {e}')
        return items

    if a.true_temperature:
        kw['true_temperature'] = names('--true-temperature', a.true_temperature, check_true_temperature)
    if a.oracle:
        from sma_wrist.sweep.oracle_models import check as check_oracle

        kw['oracle'] = names('--oracle', a.oracle, check_oracle)
    if a.observer:
        try:
            kw['compensator_observer'] = TemperatureObserverParams(*(float(x) for x in a.observer.split(',')))
        except (ValueError, TypeError, ParameterError) as e:
            ap.error(f'--observer {a.observer!r}: {e}')
    names = a.cases.split(',')
    bad = [c for c in names if c not in CASES]
    if bad:
        ap.error(f'unknown case(s) {", ".join(bad)}; known: {", ".join(CASES)}')
    keys = [(c, mode, float(m)) for c in names for mode in a.modes.split(',') for m in a.payloads.split(',')]
    wall = time.perf_counter()
    last = [0.0]

    def tick(t: float) -> None:
        if t - last[0] >= 10.0 and not a.json:
            last[0] = t
            print(f'  {t:5.0f} / {a.duration:g} s simulated ({time.perf_counter() - wall:.0f} s)', file=sys.stderr)

    results = run_cases([(CASES[c](m), mode) for c, mode, m in keys], a.duration, on_tick=tick, **kw)
    rows = [
        {
            'case': c,
            'mode': mode,
            'payload_kg': m,
            'max_error_pct': r.max_error_pct,
            'rms_error_pct': r.rms_error_pct,
            'reversals_per_s': r.reversals_per_s,
        }
        for (c, mode, m), r in zip(keys, results)
    ]
    if a.json:
        json.dump(rows, sys.stdout, indent=1)
        return
    for r in rows:
        print(
            f'| {r["case"]} | {r["mode"]} | {r["payload_kg"]:g} | {r["max_error_pct"]:.2f} | '
            f'{r["rms_error_pct"]:.2f} | {r["reversals_per_s"]:.2f} |'
        )
    print(f'({len(rows)} loops in {time.perf_counter() - wall:.1f} s)', file=sys.stderr)


if __name__ == '__main__':  # pragma: no cover
    _main()
