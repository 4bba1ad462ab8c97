"""The wrist's temperature windows for an identified wire (doc/howto/identify_wire.md).

The controllers' temperature parameters were tuned for the built-in wire (transitions
~30-80 degC at the wrist's working load): the compensator asks for 20-80 degC, the adaptive
controller's band is 20-50-80 degC, tem_controller stops heating a muscle above 85 degC and
plant_sim reports one above 90 degC. A wire that transforms elsewhere needs all of them
moved. :func:`operating_window` places the window around the wire's own transitions with
the built-in wire's margins (M_f - 14.8 degC .. A_f + 2.5 degC at 0.8 kgf, the transitions
as :func:`sma_wrist.identify.loops.transitions` measures them), so the built-in wire gives
exactly today's defaults; :func:`wrist_params` turns it into a ROS params file for every
node. The TEMs limit how hot a muscle can get: the muscle is a TEM face, and no face may
leave the TEMs' operating window (``window_C`` of the thermal model; 0-80 degC for the
seed's TEMs, doc/explanation/model.md): a window beyond it is reported, with what the TEMs would
need, never silently clipped.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np

from sma_wrist.core.errors import ParameterError
from sma_wrist.core.hysteresis.sdgpi import SDGPIParams, simulate
from sma_wrist.core.hysteresis.warp import Warp, warped_wire
from sma_wrist.identify.loops import transitions

#: load [kgf] per wire at which the windows are placed: the seed's working band is 0.75-0.9 kgf
WRIST_LOAD_KGF = 0.8
#: today's defaults, which :func:`wrist_params` reproduces for the built-in wire
DEFAULT_WINDOW_C = (20.0, 80.0)
TEM_MUSCLE_MARGIN_C = 5.0  # tem_controller max_muscle_temperature_C 85 = window top + 5
PLANT_MUSCLE_MARGIN_C = 10.0  # plant_sim max_muscle_temperature_C 90 = window top + 10
#: upper bounds of the nodes' temperature parameters (their descriptors)
NODE_MAX_C = 120.0
#: hardware_bridge's max_muscle_temperature_C default: on a device the TEMs are cut off above it (a safety limit)
BRIDGE_MUSCLE_CUTOFF_C = 90.0


def shifted_wire(params: SDGPIParams, dT_C: float) -> SDGPIParams:
    """The same wire transforming ``dT_C`` degC higher (a synthetic hot wire for tests and the bench).

    Every tanh of Eqs. 3.21-3.22, k0 tanh(k1 T + k2) + k3, becomes k0 tanh(k1 (T - dT) + k2):
    k2 -> k2 - k1 dT, per load polynomial of Eqs. 4.4-4.5 (k1 and k2 are polynomials of the
    load, so is their combination); the valid range's top moves up with it. The special case of
    :func:`warped_wire` with one shift for both directions.
    """
    return dataclasses.replace(warped_wire(params, Warp(dT_C, dT_C)), name=f'{params.name}, {dT_C:+g} degC')


def wire_transitions(params: SDGPIParams, load_kgf: float = WRIST_LOAD_KGF) -> dict[str, float]:
    """M_f and A_f [degC] of the model's major loop at ``load_kgf`` (clipped into its load range).

    One heating-cooling sweep over the model's valid temperature range from the cooled state
    (Eqs. 3.19-3.24, 4.4-4.6); the 90 % points of the branches (loops.LEVELS).
    """
    lo, hi = params.T_valid
    m = float(np.clip(load_kgf, *params.load_range))
    T = np.r_[np.linspace(lo, hi, 400), np.linspace(hi, lo, 400)]
    y = simulate(params, T, m, branch='cooling')
    tr = transitions(T, y, 'heating')
    if not (np.isfinite(tr['A_f']) and np.isfinite(tr['M_f'])):
        raise ParameterError(
            f'{params.name}: no complete transformation within its valid range {lo:g}-{hi:g} '
            f'degC at {m:g} kgf; the wire model cannot place a temperature window'
        )
    return {'A_f': tr['A_f'], 'M_f': tr['M_f'], 'load_kgf': m}


def _margins() -> tuple[float, float]:
    from sma_wrist.core.hysteresis.default_params import default_sdgpi

    tr = wire_transitions(default_sdgpi())
    return tr['M_f'] - DEFAULT_WINDOW_C[0], DEFAULT_WINDOW_C[1] - tr['A_f']


def operating_window(params: SDGPIParams, load_kgf: float = WRIST_LOAD_KGF) -> tuple[float, float]:
    """(lowest, highest) muscle temperature [degC] the controllers may ask for on this wire.

    M_f minus and A_f plus the built-in wire's margins (the window the controllers were tuned
    with), inside the model's valid range.
    """
    below, above = _margins()
    tr = wire_transitions(params, load_kgf)
    lo, hi = params.T_valid
    return float(max(tr['M_f'] - below, lo)), float(min(tr['A_f'] + above, hi))


def wrist_params(
    hysteresis_file: str | Path,
    params: SDGPIParams,
    thermal_file: str | Path | None = None,
    tem_window_C: tuple[float, float] | None = None,
    preload_mm: float | None = None,
) -> tuple[dict[str, dict[str, Any]], list[str]]:
    """(ROS parameters per node, problems) to run the wrist on this wire.

    ``tem_window_C``: the TEMs' operating window (the thermal file's ``window_C``; default
    the seed's 0-80 degC). A problem is any window the TEMs or the nodes cannot give; the
    parameters are still returned so the user sees what would be needed. ``preload_mm``: the
    chain's pre-load elongation; None calibrates it for this wire (:func:`wire_preload`).
    """
    from sma_wrist.core.plant.wrist import PlantParams
    from sma_wrist.core.thermal.heat_balance import ThermalParams

    lo, hi = operating_window(params)
    face = tem_window_C if tem_window_C is not None else ThermalParams().window_C
    problems = []
    if hi > face[1]:
        problems.append(
            f'the wire needs its muscle at up to {hi:.0f} degC (A_f + margin) but the TEMs work only '
            f'up to {face[1]:g} degC (the muscle is a TEM face): use TEMs rated for >= {hi + 15:.0f} degC '
            'and give their heat balance as thermal_file (sma-wrist identify thermal, window_C)'
        )
    if lo < face[0]:
        problems.append(f'the wire needs its muscle down to {lo:.0f} degC but the TEMs work only from {face[0]:g} degC')
    if hi > BRIDGE_MUSCLE_CUTOFF_C:  # not written: a safety limit is the device owner's to raise
        problems.append(
            f'on hardware, hardware_bridge cuts the TEMs off above max_muscle_temperature_C '
            f"{BRIDGE_MUSCLE_CUTOFF_C:g} degC, below this wire's window top {hi:.0f} degC: raise it on "
            'your device only if the wire, its crimps and the TEMs are rated for that (not written here)'
        )
    if hi + TEM_MUSCLE_MARGIN_C > NODE_MAX_C:
        problems.append(
            f"the window top {hi:.0f} degC + {TEM_MUSCLE_MARGIN_C:g} exceeds the nodes' limit {NODE_MAX_C:g} degC"
        )
    if preload_mm is None:
        try:
            preload_mm = wire_preload(params, thermal_file, (lo, hi))
        except ParameterError as e:  # the built-in pre-load stays; the user sees why
            preload_mm = PlantParams.preload_elongation_mm
            problems.append(f'pre-load: {e}; kept the built-in {preload_mm:g} mm')
    f = str(hysteresis_file)
    lo_a, hi_a = float(np.clip(lo, 0.0, NODE_MAX_C)), float(np.clip(hi, 0.0, NODE_MAX_C))  # the node's bounds
    out: dict[str, dict[str, Any]] = {
        # the plant only reports above its threshold: capped at the parameter's bound, not a problem
        'plant_sim': {
            'hysteresis_file': f,
            'max_muscle_temperature_C': round(min(hi + PLANT_MUSCLE_MARGIN_C, NODE_MAX_C), 1),
            'preload_elongation_mm': preload_mm,
        },
        'hysteresis_compensator': {
            'hysteresis_file': f,
            'temperature_min_C': round(lo, 1),
            'temperature_max_C': round(hi, 1),
            'preload_elongation_mm': preload_mm,
        },
        'adaptive_controller': {
            'temperature_min_C': round(lo_a, 1),
            'temperature_max_C': round(hi_a, 1),
            'temperature_mid_C': round(0.5 * (lo_a + hi_a), 1),
            'preload_elongation_mm': preload_mm,
        },
        'tem_controller': {'max_muscle_temperature_C': round(min(hi + TEM_MUSCLE_MARGIN_C, NODE_MAX_C), 1)},
        # on a device: the wire behind hardware_bridge's stress estimate (the compensator's input there)
        'hardware_bridge': {'hysteresis_file': f, 'preload_elongation_mm': preload_mm},
    }
    if thermal_file is not None:
        out['plant_sim']['thermal_file'] = str(thermal_file)
        # the compensator's temperature observer runs the TEMs' heat balance too (temperature_source observer)
        out['hysteresis_compensator']['thermal_file'] = str(thermal_file)
        out['tem_controller'].update(
            {
                'thermal_file': str(thermal_file),
                'face_min_C': float(face[0]),
                'face_max_C': float(min(face[1], NODE_MAX_C)),
            }
        )
    return out, problems


def wire_preload(params: SDGPIParams, thermal_file: str | Path | None, window_C: tuple[float, float]) -> float:
    """The chain's pre-load elongation [mm] for this wire (core/plant/preload.py, the built-in 1.98 mm's calibration):
    +-30 deg about q_neutral reachable at 0-0.7 kg with the muscles between what the TEMs hold at their command
    limits (the thermal file's heat balance, else Table 4.9's) inside the controllers' window ``window_C``."""
    from sma_wrist.core.plant.preload import calibrate_preload, reachable_window
    from sma_wrist.core.plant.wrist import PlantParams
    from sma_wrist.core.thermal.heat_balance import ThermalParams
    from sma_wrist.core.thermal.params_file import load_thermal_file

    thermal = load_thermal_file(thermal_file) if thermal_file else ThermalParams()
    return calibrate_preload(PlantParams(hysteresis=params), reachable_window(thermal, window_C))


def write_wrist_params(path: str | Path, nodes: dict[str, dict[str, Any]], problems: list[str]) -> Path:
    """The ROS params file (``sma-wrist run --params-file``, ``ros2 launch ... params_file:=``)."""
    import yaml

    head = [
        'sma_wrist parameters for an identified wire (sma-wrist identify; doc/howto/identify_wire.md).',
        "Temperature windows placed around the wire's transitions with the built-in wire's margins;",
        'the chain pre-load (preload_elongation_mm) calibrated for the wire like the built-in 1.98 mm.',
    ]
    head += [f'PROBLEM: {p}' for p in problems]
    doc = {node: {'ros__parameters': values} for node, values in nodes.items()}
    p = Path(path)
    p.write_text(''.join(f'# {h}\n' for h in head) + yaml.safe_dump(doc, sort_keys=False, default_flow_style=False))
    return p


def rated_tems(top_C: float) -> Any:
    """Table 4.9's heat balance on TEMs rated up to ``top_C`` (window 0..top_C degC) with hold limits to match.

    An assumption for the bench: high-temperature TEMs with the seed's heat balance; a real
    set-up gives its own identified thermal file. The hold limits are the largest constant
    commands that keep every face inside the window (thermal.characterise_constant_commands).
    """
    from sma_wrist.core.thermal import heat_balance as th

    p = dataclasses.replace(th.ThermalParams(), window_C=(0.0, float(top_C)))
    ch = th.characterise_constant_commands(p, span_V=30.0, resolution_V=0.05, horizon_s=1500.0, dt=1.0)
    return p.with_limits(float(np.ceil(2 * ch.cooling_max_V) / 2), float(np.floor(2 * ch.heating_max_V) / 2))
