"""The node graph's parameters in the sweep's loops: ``sma-wrist sweep --params-file``.

A user who tuned the graph (a params file for ``ros2 launch`` / ``sma-wrist run --params-file``) or
identified a wire and its TEMs (``sma-wrist identify``: hysteresis.yaml, thermal.yaml) sweeps that
graph over the family. The nodes are built on the embedded runtime from config/wrist.yaml and the
files given, as the graph starts them, so their own checks refuse a bad value with the node's
message; the sweep's laws then take what the nodes built (:func:`loop_settings`).

Not every parameter has a place in a lockstep simulation over sampled plants: a parameter the
sweep cannot honour is refused when the files set it to anything but config/wrist.yaml's value,
never dropped in silence (:data:`HONOURED`, :data:`NO_EFFECT`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from sma_wrist.core.control.adaptive import AdaptiveParams
from sma_wrist.core.control.pid import PIDParams
from sma_wrist.core.errors import ParameterError, SmaWristError
from sma_wrist.sweep.laws import TemLoopSpec

#: per node, the parameters the sweep's loops take from the files (see :func:`loop_settings`)
HONOURED: dict[str, frozenset[str]] = {
    # the sampled plants perturb this plant (--plant sdgpi only): the user's wire, TEMs, pre-load, step and
    # over-temperature flag
    'plant_sim': frozenset(
        {'hysteresis_file', 'thermal_file', 'preload_elongation_mm', 'dt_s', 'max_muscle_temperature_C'}
    ),
    # the reference is the Sec. 6.1 sine (the metrics are over its last cycle); its soft start from each wrist's angle
    'trajectory_generator': frozenset({'soft_start_s'}),
    # every law parameter; the mode is --controllers
    'adaptive_controller': frozenset(
        {
            'temperature_mid_C',
            'temperature_min_C',
            'temperature_max_C',
            'force_per_degC_N',
            'reversal_lead_s',
            'pid_reference_lead_s',
            'direct_reference_lead_s',
            'pid_output_filter_s',
            'direct_output_filter_s',
            'preload_elongation_mm',
        }
        | {f'adaptive.{f.name}' for f in dataclasses.fields(AdaptiveParams) if f.name != 'mode'}
        | {f'pid.{f.name}' for f in dataclasses.fields(PIDParams)}
    ),
    'hysteresis_compensator': frozenset(
        {
            'temperature_min_C',
            'temperature_max_C',
            'hysteresis_file',
            'preload_elongation_mm',
            'shift_gain_per_s',
            'shift_limit_C',
            'hold_shift_on_stop',
            'hold_shift_outside_load_range',
            'stroke_gain_per_s',
            'temperature_source',
            'window_follows_shift',
            'observer.correction_s',
            'observer.tc_lag_s',
            'thermal_file',
            'thermal_adaptation.enabled',
            'thermal_adaptation.apply_after_s',
            'thermal_adaptation.tc_lag_s',
        }
    ),
    'tem_controller': frozenset(
        {
            'gain_per_s',
            'rate_filter_s',
            'target_filter_s',
            'u_min_V',
            'u_max_V',
            'predictive_protection',
            'face_min_C',
            'face_max_C',
            'protection_horizon_s',
            'protect_above_C',
            'max_muscle_temperature_C',
            'thermal_file',
            'thermal_adaptation.enabled',
            'thermal_adaptation.apply_after_s',
            'thermal_adaptation.tc_lag_s',
            'chatter_guard.limit_per_s',
            'chatter_guard.window_s',
            'chatter_guard.rate_filter_s',
        }
    ),
}
#: accepted, and they change nothing in the sweep: wall-clock pacing, and watchdogs on late or lost
#: messages, which a lockstep simulation never has
NO_EFFECT: dict[str, frozenset[str]] = {
    'plant_sim': frozenset({'real_time_factor', 'command_timeout_s'}),
    'adaptive_controller': frozenset({'stale_timeout_s'}),
    'tem_controller': frozenset({'stale_timeout_s'}),
}
#: why a parameter the sweep does not honour is refused, where a better way exists
_INSTEAD = {
    ('adaptive_controller', 'mode'): 'choose the modes with --controllers',
    ('plant_sim', 'payload_kg'): 'the plants carry their sampled payloads; fix them with --payloads',
    ('plant_sim', 'plant'): 'choose the plant with --plant',
    # the sampled plants are spread around Table 4.9's form (sma_wrist.plants.spread): a Peltier-form heat balance
    # is simulated by plant_sim (sma-wrist run --params-file), not spread
    ('plant_sim', 'heat_balance_file'): "the sweep's sampled plants spread Table 4.9's form of thermal_file; "
    'the Peltier form runs in plant_sim (sma-wrist run --params-file)',
    ('hysteresis_compensator', 'method'): "the sweep's inverse is the numerical one",
    # the sampled plants perturb an SD-GPI wire (plants/spread.py); a phase-fraction model wire has no such family
    ('plant_sim', 'wire_file'): "the sweep's sampled plants perturb the SD-GPI of hysteresis_file, not a "
    'phase-fraction wire; run the commissioned model with sma-wrist run --params-file',
}
#: the pre-load three nodes must share (nodes.common.PRELOAD_PARAM)
PRELOAD_NODES = ('plant_sim', 'adaptive_controller', 'hysteresis_compensator')


def _activate() -> None:
    """The embedded runtime builds the nodes, also in a shell with ROS 2 sourced: nothing here talks to a graph."""
    from sma_wrist import runtime

    try:
        runtime.activate(force=True)
    except SmaWristError as e:  # the real rclpy is already imported in this process
        raise ParameterError(f'the nodes cannot be built to read the params files: {e}') from None


@dataclasses.dataclass
class _Built:
    """What the sweep takes from one node: its parameter values and the core objects it built from them."""

    values: dict[str, Any]
    objects: dict[str, Any]

    @classmethod
    def of(cls, node: Any) -> _Built:
        name = node.get_name()
        objects: dict[str, Any] = {}
        if name == 'plant_sim':
            objects['plant'] = node.sim_params
        elif name == 'adaptive_controller':
            objects['controller'] = node.law.params
        elif name == 'hysteresis_compensator':
            objects['compensator'], objects['observer'] = node.comp, node.observer
        elif name == 'tem_controller':  # as built, before any estimate scales it (base_*)
            loop = node.loop
            objects['tem_loop'] = TemLoopSpec(
                loop.base_thermal, loop.params, loop.drive, loop.base_hold, loop.max_muscle_C
            )
        return cls(dict(node.p), objects)


def _build_graph(params_files: Sequence[str | Path]) -> dict[str, _Built]:
    """{node name: the node} of the inverse mode's graph (it has every node), built on the embedded
    runtime from config/wrist.yaml and ``params_files``; a node that refuses its values raises
    ParameterError with the node's reason."""
    _activate()
    from sma_wrist.closed_loop import build_nodes, graph_nodes, ros_args

    for f in params_files:
        if not Path(f).is_file():
            raise ParameterError(f'params file {f}: no such file')
    return build_nodes(
        graph_nodes('inverse_adaptive'),
        ros_args(params_files),
        {'/**': {'use_sim_time': True}, '/plant_sim': {'use_sim_time': False}},
        _Built.of,
    )


def changed_parameters(params_files: Sequence[str | Path]) -> tuple[dict[str, _Built], dict[str, dict[str, Any]]]:
    """The graph's nodes built with ``params_files``, and per node the parameters whose values differ from
    config/wrist.yaml's."""
    user = _build_graph(params_files)
    from sma_wrist.nodes.common import refuse_undeclared

    refuse_undeclared(params_files, {name: set(b.values) for name, b in user.items()})
    default = _build_graph(())
    changed = {
        name: {k: v for k, v in b.values.items() if default[name].values.get(k) != v} for name, b in user.items()
    }
    return user, {k: v for k, v in changed.items() if v}


def _refusals(changed: Mapping[str, Mapping[str, Any]], plant: str) -> list[str]:
    out = []
    for node, values in changed.items():
        for k, v in values.items():
            if k in NO_EFFECT.get(node, ()):
                continue
            if k in HONOURED.get(node, ()) and not (node == 'plant_sim' and plant != 'sdgpi'):
                continue
            why = _INSTEAD.get((node, k)) or (
                f'the {plant} plant is its own model'
                if node == 'plant_sim' and k in HONOURED['plant_sim']
                else 'the sweep does not model it'
            )
            out.append(f'{node}.{k} = {v!r} ({why})')
    return out


@dataclasses.dataclass(frozen=True)
class LoopSettings:
    """:func:`sma_wrist.sweep.simulate.simulate`'s keyword arguments for a graph's parameters, and which of
    them differ from config/wrist.yaml ({node: {parameter: value}}, what a sweep's report records)."""

    kwargs: dict[str, Any]
    changed: dict[str, dict[str, Any]]


def loop_settings(params_files: Sequence[str | Path], plant: str = 'sdgpi') -> LoopSettings:
    """The sweep's loops for the graph that config/wrist.yaml and ``params_files`` set up (applied in that
    order, as ``sma-wrist run --params-file`` applies them).

    Raises ParameterError naming every parameter the files change that the sweep cannot honour, a node's
    refusal of a value, and pre-loads or TEM estimates that the nodes do not share (the sweep has one of each)."""
    user, changed = changed_parameters(params_files)
    from sma_wrist.nodes.common import online_thermal

    bad = _refusals(changed, plant)
    if bad:
        raise ParameterError(
            'sma-wrist sweep cannot honour: ' + '; '.join(bad) + '. Remove them from the params '
            'file(s), or run the graph with sma-wrist run --params-file'
        )
    preload = {n: user[n].values['preload_elongation_mm'] for n in PRELOAD_NODES}
    if len(set(preload.values())) > 1:
        raise ParameterError(
            'preload_elongation_mm differs between '
            + ', '.join(f'{n} ({v:g} mm)' for n, v in preload.items())
            + ": the graph needs one pre-load (the wire's wrist_params.yaml)"
        )
    comp, tem = user['hysteresis_compensator'].values, user['tem_controller'].values
    online = online_thermal(tem)
    if online_thermal(comp) != online:  # the sweep's compensator runs on the TEM loops' estimate
        raise ParameterError(
            'thermal_adaptation.* differ between hysteresis_compensator and tem_controller: both '
            'learn from the same samples and must have the same values'
        )
    jp = user['adaptive_controller'].objects['controller']
    mc, obs = user['hysteresis_compensator'].objects['compensator'], user['hysteresis_compensator'].objects['observer']
    out: dict[str, Any] = {
        'base': user['plant_sim'].objects['plant'] if plant == 'sdgpi' else None,
        'controller_overrides': {f.name: getattr(jp, f.name) for f in dataclasses.fields(jp) if f.name != 'mode'},
        'compensator_wire': mc.params,
        'compensator_window_C': mc.T_range_C,
        'shift_gain_per_s': mc.shift_gain_per_s,
        'shift_limit_C': mc.shift_limit_C,
        'stroke_gain_per_s': mc.stroke_gain_per_s,
        'window_follows_shift': mc.window_follows_shift,
        'hold_shift_on_stop': comp['hold_shift_on_stop'],  # the node's gate, not the compensator's
        'hold_shift_outside_load_range': mc.hold_outside_load_range,
        'compensator_observer': None if obs is None else obs.params,
        'observer_thermal': None if obs is None else obs.thermal,
        'tem_loop': user['tem_controller'].objects['tem_loop'],
        'online_thermal': online,
        'soft_start_s': user['trajectory_generator'].values['soft_start_s'],
    }
    return LoopSettings(out, changed)


def plant_params(params_files: Sequence[str | Path]) -> Any:
    """The PlantParams plant_sim builds from config/wrist.yaml and ``params_files`` (its wire, TEMs, pre-load,
    ``model.*``): what ``sma-wrist emulate-device --params-file`` puts behind the serial line."""
    built = _build_graph(params_files)
    from sma_wrist.nodes.common import refuse_undeclared  # a misspelt hysteresis_file emulated the built-in wire

    refuse_undeclared(params_files, {name: set(b.values) for name, b in built.items()})
    return built['plant_sim'].objects['plant']


__all__ = ['HONOURED', 'NO_EFFECT', 'LoopSettings', 'changed_parameters', 'loop_settings', 'plant_params']
