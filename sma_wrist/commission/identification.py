"""Identification from the wrist's own sensors after the excitation (:mod:`sma_wrist.commission.excite`).

Inputs are what the device measures: the commands sent (``bring.rec.u``), the muscle and exchanger-face
temperatures and the angle; the wires' stresses are not measured. Three parts, each fitted on the excitation's
``fit`` phases and validated on its ``heldout`` phases against the built-in model on the same data:

* **thermal**: the TEM heat balance (Eqs. 4.13/4.14, Table 4.9's columns) by simulation-error least squares
  (:func:`sma_wrist.core.thermal.identification.fit_thermal`), both faces measured. One fit over both layers is
  ``thermal.yaml`` (the nodes take one heat balance for both TEMs); each layer is also fitted alone, and the
  drive gain of TEM 1 relative to TEM 2 (TEM 1's data under TEM 2's heat balance with input_per_volt scaled)
  says whether one TEM is weaker. Held out: RMS muscle-face error [degC] of the free-run prediction.
* **hysteresis**: the built-in SD-GPI shifted in temperature (:func:`sma_wrist.identify.wrist.shifted_wire`). The
  shift is the temperature offset of the diagnosis' mechanics replay (:class:`sma_wrist.diagnose.effects.
  ExtendedModel`: the angle predicted from the measured temperatures, T_wire = T_measured - offset, which for the
  SD-GPI is exactly the shifted wire), fitted with the joint below. The stroke and the stress dependence stay the
  built-in's: without measured stresses the excitation spans only the loads pre-load and payload give, and a
  stroke scale of 0.7-1.0 changed the phase-fraction wrist's held-out error by under 4 %. Written as
  ``hysteresis.yaml``.
* **joint**: payload, Coulomb friction and pre-load elongation, fitted with the shift by the diagnosis' fit
  (:class:`sma_wrist.diagnose.fit.Evaluator`, trained on the fit phases); a payload given on the command line is
  taken as known. Held out: RMS angle error [mrad] of the replay from the measured temperatures.

A part is handed over (into the node parameters) only where it predicts the held-out data better than the built-in
model, and the heat balance only if it holds the TEMs in their window, the wire and joint only with no fitted value
at its bound; else the built-in part with a warning.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.optimize import minimize_scalar

from sma_wrist.commission.bringup import BringUp
from sma_wrist.core.errors import SmaWristError
from sma_wrist.core.thermal import heat_balance as th
from sma_wrist.core.thermal import identification as ti

THERMAL_DT_S = 0.25  # grid of the heat-balance records [s]: 48 samples a period of the fastest sine (12 s)
MECH_DT_S = 0.05  # grid of the angle replay [s]
MECH_STEP_S = 0.01  # the replay's plant step [s]
MIN_SWEEP_RAD = 0.05  # the joint must move at least this much in the excitation for the wire and joint [rad]
SHIFT_BOUND_C = 10.0  # the diagnosis' temperature-offset bound: a larger shift is re-centred once
#: the layers' drive gains differ by more than this: the one heat balance of thermal.yaml averages two TEMs
LAYER_GAIN_TOLERANCE = 0.1


class IdentificationError(SmaWristError):
    """The excitation's data cannot identify a part (the message says why)."""


@dataclass
class Identified:
    """What :func:`identify_wrist` found: per part parameters, held-out errors and the file written; the node
    parameters to merge into ``wrist_params.yaml``; the report's figures; warnings."""

    identified: dict[str, dict[str, Any]]
    node_params: dict[str, dict[str, Any]]
    figures: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)


def _phases(bring: BringUp) -> tuple[list[dict[str, Any]], float, float, float]:
    """(phases, start of the excitation, start of its held-out part, end) [s of device time]."""
    ex = bring.steps.get('excite')
    if not ex or not ex.get('phases'):
        raise IdentificationError('no excitation was recorded: identification needs the excite step first')
    ph = ex['phases']
    held = [p for p in ph if p['part'] == 'heldout']
    if not held or held[0] is ph[0]:
        raise IdentificationError('the excitation has no fit part before its held-out part')
    return ph, ph[0]['t_start_s'], held[0]['t_start_s'], ph[-1]['t_end_s']


def _signals(bring: BringUp, t0: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(t, temperatures (n, 4) [degC] in muscle order, angle (n,) [rad], drive per muscle (n, 2) [V]) from t0 on."""
    t, adc, u = bring.rec.arrays(t0)
    temps, q = bring.physical(adc)
    return t, temps, q, u


# ------------------------------------------------------------------------------------------------ thermal
def _records(t: np.ndarray, temps: np.ndarray, u: np.ndarray, a: float, b: float, part: str) -> list[ti.ThermalRecord]:
    """One ThermalRecord per TEM layer over [a, b): the drive's interval means, both faces measured."""
    dt = THERMAL_DT_S
    grid = np.arange(a, b - dt, dt)
    out = []
    for m in (0, 1):
        um, u2 = ti.interval_means(t, u[:, m], grid, dt, 'zoh')
        T = np.column_stack([np.interp(grid, t, temps[:, m]), np.interp(grid, t, temps[:, 2 + m])])
        out.append(ti.ThermalRecord(f'{part}, TEM {m + 1}', dt, um, T, u2=u2))
    return out


def _muscle_rms(params: th.ThermalParams, records: list[ti.ThermalRecord]) -> float:
    """RMS muscle-face error [degC] of the free-run predictions of ``records`` (each from its measured start)."""
    ev = ti.evaluate(params, records, 'heldout', settle_s=0.0)
    return float(np.sqrt(np.mean([e.faces['T1']['rms_C'] ** 2 for e in ev])))


def relative_gain(params: th.ThermalParams, record: ti.ThermalRecord) -> float:
    """The drive gain that makes ``params`` (input_per_volt scaled) fit ``record``'s muscle face best: one TEM's data
    under another TEM's heat balance gives the first's gain relative to the second's."""

    def cost(g: float) -> float:
        p = dataclasses.replace(params, input_per_volt=params.input_per_volt * g)
        s = ti.simulate_records(p, [record])[0]
        return float(np.mean((s[:, 0] - record.T[:, 0]) ** 2))

    return float(minimize_scalar(cost, bounds=(0.3, 2.0), method='bounded', options={'xatol': 1e-3}).x)


def identify_thermal_part(
    fit: list[ti.ThermalRecord], held: list[ti.ThermalRecord], out: Path
) -> tuple[dict[str, Any], th.ThermalParams, list[str]]:
    """The heat balance of both layers (written as ``thermal.yaml``) and of each alone; held-out errors."""
    from sma_wrist.core.thermal.params_file import write_thermal_file

    warnings: list[str] = []
    builtin = th.ThermalParams()
    both = ti.fit_thermal(fit, builtin, faces='both')
    params = both.params
    usable = ''
    try:
        lo, hi = ti.hold_limits(params)
        params = params.with_limits(lo, hi)
    except ti.ThermalIdentificationError as e:
        usable = str(e)
    layers = [ti.fit_thermal([r], builtin, faces='both') for r in fit]
    g1 = relative_gain(layers[1].params, fit[0])
    g2 = relative_gain(layers[0].params, fit[1])
    gain_1_to_2 = math.sqrt(g1 / g2)  # both directions: symmetric in the two fits' errors
    if abs(gain_1_to_2 - 1.0) > LAYER_GAIN_TOLERANCE:
        weaker = 1 if gain_1_to_2 < 1 else 2
        warnings.append(
            f'thermal: TEM {weaker} pumps {abs(1 - min(gain_1_to_2, 1 / gain_1_to_2)):.0%} less per volt than the '
            'other; thermal.yaml holds one heat balance for both (the nodes take one), fitted to both: check '
            f'TEM {weaker} (its supply lead, its thermal contact) if the difference is not intended'
        )
    rms = {
        'commissioned': _muscle_rms(params, held),
        'builtin': _muscle_rms(builtin, held),
        'per_layer': float(np.sqrt(np.mean([_muscle_rms(f.params, [r]) ** 2 for f, r in zip(layers, held)]))),
    }
    prov = {
        'source': 'sma-wrist commission: excitation of the wrist on its own sensors (fit phases)',
        'fit_rms_C': round(both.rms_C, 4),
        'heldout_muscle_rms_C': round(rms['commissioned'], 4),
        'builtin_heldout_muscle_rms_C': round(rms['builtin'], 4),
        'tem1_gain_relative_to_tem2': round(gain_1_to_2, 4),
    }
    # handed over where it predicts the held-out cycle better and holds the TEMs in their window at some drive
    # (tem_controller's hold limits come from it)
    better = rms['commissioned'] < rms['builtin'] and not usable
    if not better:
        why = (
            usable
            if usable
            else f'it predicts the held-out cycle no better than the built-in one ({rms["commissioned"]:.3g} '
            f'against {rms["builtin"]:.3g} degC RMS)'
        )
        warnings.append(f'thermal: the built-in heat balance is handed over: {why}')
    path = write_thermal_file(
        out / 'thermal.yaml',
        params if better else builtin,
        prov if better else {**prov, 'source': 'built-in (the identified heat balance was not handed over)'},
        header='TEM heat balance identified by sma-wrist commission',
    )
    for m, f in enumerate(layers):
        write_thermal_file(out / f'thermal_tem{m + 1}.yaml', f.params, {'source': f'TEM {m + 1} alone'})
    if both.at_bounds:
        warnings.append(f'thermal: parameters on a bound (not determined by the data): {", ".join(both.at_bounds)}')
    part = {
        'parameters': {
            'muscle_face': {k: float(getattr(params.muscle_face, k)) for k in ti.FACE_KEYS},
            'exchanger_face': {k: float(getattr(params.exchanger_face, k)) for k in ti.FACE_KEYS},
            'hold_limits_V': [params.u_min_V, params.u_max_V],
            'tem1_gain_relative_to_tem2': round(gain_1_to_2, 4),
            'heldout_rms_C_each_layer_alone': round(rms['per_layer'], 4),
        },
        'heldout': {
            'metric': 'RMS muscle-face temperature error, free-run prediction from the commands',
            'unit': 'degC',
            'commissioned': round(rms['commissioned'], 4),
            'builtin': round(rms['builtin'], 4),
        },
        'file': str(path),
        'handed_over': better,
    }
    return part, params if better else builtin, warnings


# ------------------------------------------------------------------------------------------------ wire, joint
def identify_mechanics(
    bring: BringUp, out: Path, payload_kg: float | None, t_fit: float, t_held: float, t_end: float
) -> tuple[dict[str, Any], dict[str, Any], dict[str, Any], list[str]]:
    """(hysteresis part, joint part, values for the node params, warnings)."""
    from sma_wrist.core.hysteresis.default_params import default_sdgpi
    from sma_wrist.core.hysteresis.params_file import save_hysteresis
    from sma_wrist.core.plant.wrist import PlantParams
    from sma_wrist.diagnose import effects as fx
    from sma_wrist.diagnose.data import DEFAULT_PAYLOAD_KG, Run
    from sma_wrist.diagnose.fit import Evaluator
    from sma_wrist.identify.wrist import shifted_wire

    warnings: list[str] = []
    t, temps, q, _ = _signals(bring, t_fit)
    dt = MECH_DT_S
    grid = np.arange(t_fit, t_end - dt, dt)
    T = np.column_stack([np.interp(grid, t, temps[:, m]) for m in (0, 1)])
    qg = np.interp(grid, t, q)
    if np.ptp(qg) < MIN_SWEEP_RAD:
        raise IdentificationError(
            f'the joint moved only {np.ptp(qg):.3f} rad during the excitation (muscles '
            f'{T.min():.0f}-{T.max():.0f} degC): the wire and joint cannot be identified; check that the wires pull '
            'the joint, or a wire transforming beyond the TEMs window'
        )
    prior_kg = payload_kg if payload_kg is not None else DEFAULT_PAYLOAD_KG
    run = Run(t=grid - grid[0], dt=dt, u=None, T=T, q=qg, payload_kg=prior_kg)
    i_held = int(round((t_held - t_fit) / dt))
    base = default_sdgpi()
    builtin_model = fx.ExtendedModel(run, PlantParams(dt=MECH_STEP_S, hysteresis=base))
    pred = builtin_model.angle_measured(fx.NOMINAL[None], None, 'measured')[:, 0]
    # the wire's shift is the mechanics replay's temperature offset (T_wire = T_measured - offset: exactly the SD-GPI
    # shifted by it, shifted_wire), fitted with the joint by the diagnosis' fit on the fit phases; beyond the
    # offset's bound the wire is re-centred once and fitted again
    params = ('temp_offset_C', 'coulomb_Nm', 'preload_err_mm') + (('payload_err_kg',) if payload_kg is None else ())
    eff = fx.Effect('commission', 'wire and joint recalibration', 'joint', params, 'shift, payload, friction, pre-load')
    shift0 = 0.0
    for _ in range(2):
        wire = shifted_wire(base, shift0)
        model = fx.ExtendedModel(run, PlantParams(dt=MECH_STEP_S, hysteresis=wire))
        ev = Evaluator(model, train_until=i_held)
        fitted = ev.fit(eff, max_nfev=15)
        off = float(fitted.row[fx.INDEX['temp_offset_C']])
        if abs(off) < 0.8 * SHIFT_BOUND_C:
            break
        shift0 += off
    shift = round(shift0 + off, 1)  # finer than the thermocouples' accuracy is noise
    wire = shifted_wire(base, shift)
    model = fx.ExtendedModel(run, PlantParams(dt=MECH_STEP_S, hysteresis=wire))
    row = fitted.row.copy()
    row[fx.INDEX['temp_offset_C']] = 0.0
    rows = np.stack([fx.NOMINAL, row])
    p_wire, p_all = model.angle_measured(rows, None, 'measured').T
    held = slice(i_held, None)

    def rms_mrad(p: np.ndarray) -> float:
        return float(1e3 * np.sqrt(np.mean((qg[held] - p[held]) ** 2)))

    builtin_rms = rms_mrad(pred)
    v = fitted.values()
    preload_mm = PlantParams().preload_elongation_mm + v['preload_err_mm']
    payload = run.payload_kg + v.get('payload_err_kg', 0.0)
    hpath = save_hysteresis(
        out / 'hysteresis.yaml',
        dataclasses.replace(wire, name=f'{base.name}, commissioned ({shift:+.1f} degC)'),
        {
            'source': 'sma-wrist commission: angle against the measured muscle temperatures (fit phases)',
            'transition_shift_C': round(shift, 3),
            'stroke': 'built-in',
            'stress_dependence': 'built-in (stresses are not measured on the device)',
        },
    )
    hyst = {
        'parameters': {
            'transition_shift_C': round(shift, 3),
            'stroke': 'built-in',
            'stress_dependence': 'built-in',
        },
        'heldout': {
            'metric': 'RMS angle error, replay from the measured temperatures (built-in joint)',
            'unit': 'mrad',
            'commissioned': round(rms_mrad(p_wire), 3),
            'builtin': round(builtin_rms, 3),
        },
        'file': str(hpath),
    }
    joint = {
        'parameters': {
            'payload_kg': round(payload, 4),
            'payload_given': payload_kg is not None,
            'coulomb_Nm': round(v['coulomb_Nm'], 5),
            'preload_elongation_mm': round(preload_mm, 4),
        },
        'heldout': {
            'metric': 'RMS angle error, replay from the measured temperatures (commissioned wire and joint)',
            'unit': 'mrad',
            'commissioned': round(rms_mrad(p_all), 3),
            'builtin': round(builtin_rms, 3),
        },
        'file': None,
    }
    on_bound = [
        f'{k} = {fitted.row[fx.INDEX[k]]:.3g}'
        for k in params
        if k != 'coulomb_Nm'  # friction at 0 is a value (a free joint), not a model at its end
        and (
            fitted.row[fx.INDEX[k]] <= fx.LOWER[fx.INDEX[k]] + 1e-6
            or fitted.row[fx.INDEX[k]] >= fx.UPPER[fx.INDEX[k]] - 1e-6
        )
    ]
    # handed over only where it predicts the held-out cycle better than the built-in model with every fitted value
    # inside its range: a parameter at its bound is the fit compensating what the model cannot describe (on a wrist
    # the SD-GPI and joint model do not fit), not a measurement, and would mislead the controllers
    better = joint['heldout']['commissioned'] < joint['heldout']['builtin'] and not on_bound
    hyst['handed_over'] = joint['handed_over'] = better
    if better:
        values = {'payload_kg': payload, 'coulomb_Nm': v['coulomb_Nm'], 'preload_mm': preload_mm, 'wire': wire}
    else:
        why = (
            f'{", ".join(on_bound)} at the end of the range the fit allows: the built-in wire and joint model '
            'do not describe this wrist'
            if on_bound
            else 'the recalibrated model predicts the held-out cycle no better than the built-in one '
            f'({joint["heldout"]["commissioned"]:.3g} against {joint["heldout"]["builtin"]:.3g} mrad RMS)'
        )
        warnings.append(
            f'wire and joint: {why}; the built-in wire, pre-load and friction are handed over'
            + ('' if payload_kg is not None else f', with the payload {prior_kg:g} kg (give --payload-kg)')
        )
        values = {
            'payload_kg': prior_kg,
            'coulomb_Nm': float(fx.NOMINAL[fx.INDEX['coulomb_Nm']]),
            'preload_mm': PlantParams().preload_elongation_mm,
            'wire': base,
        }
        hpath = save_hysteresis(
            out / 'hysteresis.yaml', base, {'source': 'built-in (the recalibration was not handed over)'}
        )
        hyst['file'] = str(hpath)
    return hyst, joint, values, warnings


# ------------------------------------------------------------------------------------------------ all parts
def identify_wrist(bring: BringUp, out: Path, payload_kg: float | None = None) -> Identified:
    """Identify the thermal, hysteresis and joint parts from the excitation recorded in ``bring``; write
    ``thermal.yaml`` and ``hysteresis.yaml`` into ``out``; return them with their held-out errors and the node
    parameters for ``wrist_params.yaml``."""
    from sma_wrist.identify.wrist import wrist_params

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    ph, t_fit, t_held, t_end = _phases(bring)
    t, temps, q, u = _signals(bring, t_fit)
    fit = _records(t, temps, u, t_fit, t_held, 'fit')
    held = _records(t, temps, u, t_held, t_end, 'held out')
    thermal, thermal_params, warnings = identify_thermal_part(fit, held, out)
    hyst, joint, values, w2 = identify_mechanics(bring, out, payload_kg, t_fit, t_held, t_end)
    warnings += w2
    nodes, problems = wrist_params(
        hyst['file'], values['wire'], thermal['file'], thermal_params.window_C, preload_mm=values['preload_mm']
    )
    warnings += [f'wrist parameters: {p}' for p in problems]
    nodes.setdefault('plant_sim', {}).update(
        {'payload_kg': round(values['payload_kg'], 4), 'model.coulomb_Nm': round(values['coulomb_Nm'], 5)}
    )
    nodes.setdefault('hardware_bridge', {})['payload_kg'] = round(values['payload_kg'], 4)
    parts = {'thermal': thermal, 'hysteresis': hyst, 'joint': joint}
    figures = _figures(bring, out, t_fit, t_held, thermal_params, values)
    return Identified(parts, nodes, figures, warnings)


def _figures(
    bring: BringUp, out: Path, t_fit: float, t_held: float, thermal: th.ThermalParams, values: dict[str, Any]
) -> list[str]:
    """excitation.png: the drive, temperatures and angle of the excitation, the held-out part shaded."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    t, temps, q, u = _signals(bring, t_fit)
    fig, ax = plt.subplots(3, 1, figsize=(9, 7), sharex=True)
    ax[0].plot(t, u[:, 0], label='muscle 1 drive')
    ax[0].plot(t, u[:, 1], label='muscle 2 drive')
    ax[0].set_ylabel('drive [V]')
    for m in (0, 1):
        ax[1].plot(t, temps[:, m], label=f'muscle {m + 1}')
        ax[1].plot(t, temps[:, 2 + m], '--', label=f'TEM {m + 1} face')
    ax[1].set_ylabel('temperature [degC]')
    ax[2].plot(t, q, 'k')
    ax[2].set_ylabel('angle [rad]')
    ax[2].set_xlabel('device time [s]')
    for a in ax:
        a.axvspan(t_held, t[-1], color='0.9', zorder=0)
    for a in ax[:2]:
        a.legend(fontsize=7, loc='upper left')
    ax[0].set_title('excitation (shaded: held out from every fit)')
    fig.tight_layout()
    fig.savefig(out / 'excitation.png', dpi=80)
    plt.close(fig)
    return ['excitation.png']


__all__ = ['identify_wrist', 'Identified', 'IdentificationError', 'relative_gain']
