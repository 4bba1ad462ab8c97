"""Model-discrepancy diagnosis of a recorded wrist run: ``sma-wrist diagnose BAG``.

1. Replay the nominal plant on the run's recorded inputs, subsystem by subsystem
   (commands -> temperatures; measured temperatures + payload -> angle; whole chain).
2. Residual statistics per channel (RMS vs sensor noise, Ljung-Box whiteness, lag,
   correlates: time, temperature rate, sign of joint velocity, angle, load, cycles).
3. Fit every catalogue effect (:mod:`.effects`) on the first 60 % of the run, score it on
   the rest (:mod:`.fit`), pick the best, bootstrap its gain over held-out segments.
4. Output: JSON / markdown + PNG report / params file of the extended model.

See doc/explanation/diagnosis.md.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from sma_wrist.cli_options import diagnose_arguments as add_arguments
from sma_wrist.contract import ContractError, Recording
from sma_wrist.core.errors import ParameterError
from sma_wrist.core.yaml_file import write_yaml_file
from sma_wrist.diagnose import effects as fx
from sma_wrist.diagnose import fit as ft
from sma_wrist.diagnose import report as rp
from sma_wrist.diagnose import steps as st
from sma_wrist.diagnose.data import DiagnoseInputError, Run, load_run

__all__ = ['DiagnosisResult', 'DiagnoseInputError', 'diagnose', 'diagnose_run', 'main', 'nominal_plant']

#: a candidate must lower the held-out score by this much (sum of log SSE ratios; 0.2 ~ 10 % RMS)
MIN_SCORE = 0.2
#: ... and its bootstrap 5th-percentile gain on its main channel must exceed this [%]
MIN_GAIN_P05 = 2.0
#: held-out score margin (log SSE; 0.1 ~ 5 % RMS) within which fewer parameters win
PARSIMONY_LOG = 0.1
#: residual structure: RMS / white-noise sigma above this with a Ljung-Box rejection (p < 0.01)
STRUCTURE_RATIO = 1.6
#: cross-channel consistency: a cause may not make any channel it touches worse on held-out data
#: by more than this (log SSE; 0.02 ~ 1 % RMS)
CONSISTENT_LOG = 0.02
#: a fitted value within this fraction of its range from a bound (that is not its nominal
#: value) has hit the bound: the fit says "at least this much", not "this much"
BOUND_FRACTION = 0.005
#: ... and within this share of the way from its nominal value to that bound: a catalogue range can be far wider than
#: the parameter near its nominal (the joint's damping: 0-20 N m s about 0.15), where the range's fraction alone called
#: a damping fitted to 0.059 N m s "on the bound 0" and the summary asked for a damping below zero
BOUND_SHARE = 0.05
#: causes of other subsystems scoring within this (log SSE) of the named one make the verdict ambiguous
AMBIGUITY_LOG = 0.3
#: a verdict that names two subsystems is given at most this confidence
AMBIGUOUS_CONFIDENCE = 0.5
#: a cause that leaves its main channel's held-out RMS above PARTIAL_RATIO x the noise level and
#: removes less than PARTIAL_GAIN_PCT of it explains only part of the run: it is listed, not named
PARTIAL_RATIO = 3.0
PARTIAL_GAIN_PCT = 80.0
#: bootstrap resamples of the held-out segments for the confidence
N_CONFIDENCE = 500
#: practical floor: a cause is named only when some fitted parameter is at least this fraction of its catalogue
#: typical effect (``typical`` in sma_wrist/core/plant/extensions.py) away from nominal. Below it the fit is a
#: polish, not a fault: on the nominal simulated wrist under ROS 2 a window's fit said tem_gain_err = 0.002 (typical
#: 0.1) with confidence 1.00; on 30 min of a nominal pid run through realistic sensors windows fitted thermocouple
#: offsets of 0.05 degC (typical 0.5), a potentiometer offset of 1.7 mrad (typical 20) with a gain error of 0.011
#: (0.37 of typical, confidence 0.96) and a pre-load error of 0.014 mm (0.28 of typical, confidence 0.9): a quarter
#: was too low. The smallest effects the tests inject are 0.75 x typical (sma_wrist/diagnose/testdata.py RANGES)
MIN_SIZE_FRACTION = 0.5
#: ... and the fitted effect must move its main channel's held-out prediction by at least this fraction of the
#: channel's noise level (RMS): an effect that only thousands of averaged samples show is beyond what a sensor of
#: that noise can tell apart from the model
MIN_EFFECT_NOISE = 0.5
#: the measurement that separates two subsystems that explain a run almost equally well
SEPARATING_MEASUREMENT = {
    frozenset({'sensor', 'actuator'}): 'a command step test with the TEM-face temperatures (or the drive current) '
    'recorded: a late or weak drive shows at the TEM faces, a faulty thermocouple does not',
    frozenset({'sensor', 'thermal'}): 'a reference thermometer on the bundle (or an ice-point / warm-bath check of '
    'the thermocouples) against the recorded readings',
    frozenset({'sensor', 'hysteresis'}): 'a slow, nearly isothermal temperature sweep with a reference thermometer: '
    'wire physics moves the angle, a sensor fault only the reading',
    frozenset({'sensor', 'joint'}): 'a static check of the angle against a protractor or second encoder at a few '
    'positions, with and without the payload',
    frozenset({'actuator', 'thermal'}): 'a command step test with the TEM-face temperatures and the drive current '
    'recorded: the driver and the heat balance act at different points',
    frozenset({'actuator', 'hysteresis'}): 'a command step test with the TEM-face temperatures recorded',
    frozenset({'thermal', 'hysteresis'}): 'slow and fast temperature cycles: rate-dependent wires and heat-balance '
    'errors scale differently with the heating rate',
    frozenset({'hysteresis', 'joint'}): 'slow and fast cycles at two payloads: rate and load dependence separate them',
    frozenset({'thermal', 'joint'}): 'a payload step at constant temperatures',
    frozenset({'actuator', 'joint'}): 'a payload step at constant temperatures',
}


@dataclass
class DiagnosisResult:
    discrepancy: bool
    subsystem: str | None  # thermal | actuator | hysteresis | joint | sensor | None
    cause: str | None  # catalogue id
    parameters: dict[str, dict[str, Any]]
    channel: str  # channel of rmse_before/after: thermal | mechanics | chain
    rmse_before: float
    rmse_after: float
    gain_pct: float
    gain_ci: tuple[float, float]
    alternatives: list[dict[str, Any]]
    unexplained: bool
    correlates: list[dict[str, Any]]
    channels: dict[str, dict[str, float]]
    residual_stats: dict[str, dict[str, Any]]
    summary: str
    #: probability that the named subsystem (or "no discrepancy") is right: the fraction of
    #: bootstrap resamples of the held-out segments that reach the same verdict (capped when ambiguous)
    confidence: float = 0.0
    #: causes of other subsystems that explain the run almost as well (then the verdict names them too)
    ambiguous_with: list[dict[str, Any]] = field(default_factory=list)
    separating_measurement: str | None = None
    #: candidates whose fit ended on a bound of the catalogue: {cause, parameter, value, bound}
    bound_hits: list[dict[str, Any]] = field(default_factory=list)
    #: the best cause when it was significant but explained only part of its channel (PARTIAL_RATIO,
    #: PARTIAL_GAIN_PCT), so not named: {cause, subsystem, channel, gain_pct, parameters}; None otherwise
    partial: dict[str, Any] | None = None
    warnings: list[str] = field(default_factory=list)
    #: steps of the measured angle the model's replay does not make (:func:`sma_wrist.diagnose.steps.angle_steps`):
    #: ``{'t_s', 'start_s', 'end_s', 'step_rad', 'model_max_rad'}``, largest first, times from the run's start
    angle_steps: list[dict[str, Any]] = field(default_factory=list)
    source: str = ''
    duration_s: float = 0.0
    wall_s: float = 0.0
    #: the TEM drive the replays ran on: 'applied' (the device's read-back) or 'commanded' (the commands)
    drive: str = 'commanded'
    #: with the applied drive: how many samples of the run it differed from the commands (None: not compared)
    drive_differs: int | None = None
    #: where the heat-balance replay's exchanger faces started: 'measured' (the bag's face temperatures), 'rest',
    #: or 'twin' (a live monitor's replay before the window)
    thermal_start: str = 'rest'
    params_file: str | None = None
    #: the model replayed (:meth:`sma_wrist.plant_model.PlantModel.describe`): its params file, model files,
    #: pre-load and ``model.*`` values, the nominal values the fits start from
    model: str = 'the built-in model'

    def to_json(self) -> dict[str, Any]:
        d = asdict(self)
        d['gain_ci_pct'] = list(d.pop('gain_ci'))
        return _plain(d)


def _plain(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    if isinstance(x, (np.floating, float)):
        return None if not np.isfinite(x) else float(x)
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x


def _param_dict(row: np.ndarray, names: Sequence[str], nominal: np.ndarray) -> dict[str, dict[str, Any]]:
    """``names``' fitted values in ``row`` with their ``nominal``: the value of the model replayed, the row the fits
    start from (a params file's ``model.*`` values, e.g. a commissioned ``coulomb_Nm``, else the catalogue's; the
    errors such as ``preload_err_mm`` are 0 there, relative to the replayed model's pre-load)."""
    out = {}
    for k in names:
        i = fx.INDEX[k]
        p = fx.PARAMS[i]
        out[k] = {'value': float(row[i]), 'unit': p.unit, 'nominal': float(nominal[i]), 'meaning': p.description}
    return out


def _regressors(
    ev: ft.Evaluator, q_model: np.ndarray | None, load: np.ndarray | None, sl: slice
) -> dict[str, np.ndarray]:
    run, m = ev.run, ev.model
    reg: dict[str, np.ndarray] = {'time': run.t[sl]}
    if run.T is not None:
        reg['temperature rate'] = m.T_rate[sl].mean(axis=1)
        reg['cycles'] = m.cycles[sl].mean(axis=1)
        reg['temperature'] = run.T[sl].mean(axis=1)
    if q_model is not None:
        qd = np.gradient(q_model, run.dt)
        reg['sign joint velocity'] = np.sign(np.where(np.abs(qd) > 1e-3, qd, 0.0))[sl]
        reg['angle'] = q_model[sl]
    if load is not None:
        reg['load'] = (load[:, 0] - load[:, 1])[sl]
    if run.u is not None:
        reg['command 1'] = run.u[sl, 0]
        reg['command 2'] = run.u[sl, 1]
    return reg


def nominal_plant(
    run: Run, hysteresis_file: str | None = None, thermal_file: str | None = None, params_file: str | None = None
) -> Any:
    """The nominal plant a run is replayed against: the one plant_sim would run with these files (PlantParams at the
    run's step, at most 10 ms), or None for the built-in model. ``params_file``: the plain plant of its plant node
    (model files and pre-load, :func:`sma_wrist.plant_model.read_plant_model`; its ``model.*`` values are
    the diagnosis' nominal row, :func:`plant_model`); explicit ``hysteresis_file`` / ``thermal_file`` replace its."""
    if not (hysteresis_file or thermal_file or params_file):
        return None
    from sma_wrist.plant_model import PlantModelFileError

    try:
        return plant_model(params_file, hysteresis_file, thermal_file).base(dt=min(run.dt, 0.01))
    except PlantModelFileError as exc:
        raise DiagnoseInputError(str(exc)) from None


def plant_model(
    params_file: str | None = None, hysteresis_file: str | None = None, thermal_file: str | None = None
) -> Any:
    """The model a diagnosis replays (:class:`sma_wrist.plant_model.PlantModel`); DiagnoseInputError
    naming what does not load."""
    from sma_wrist.plant_model import PlantModelFileError, read_plant_model

    try:
        return read_plant_model(params_file, hysteresis_file, thermal_file)
    except PlantModelFileError as exc:
        raise DiagnoseInputError(str(exc)) from None


def diagnose_run(
    run: Run,
    report_dir: str | Path | None = None,
    params_out: str | Path | None = None,
    candidates: Sequence[str] | None = None,
    hysteresis_file: str | None = None,
    thermal_file: str | None = None,
    params_file: str | None = None,
) -> DiagnosisResult:
    """Diagnose an aligned run (see :func:`diagnose` for a bag); ``hysteresis_file``: the wire's SD-GPI;
    ``thermal_file``: the TEMs' heat balance (``sma-wrist identify thermal``); ``params_file``: a params file whose
    plant node's model (model files, pre-load, ``model.*`` values) is the nominal one, the explicit files replacing
    its; so that what is left is what that model does not describe."""
    t_start = time.perf_counter()
    pm = plant_model(params_file, hysteresis_file, thermal_file)
    model = fx.ExtendedModel(
        run, nominal_plant(run, hysteresis_file, thermal_file, params_file), nominal=fx.theta(**pm.extension)
    )
    ev = ft.Evaluator(model)
    if not ev.channels:
        raise DiagnoseInputError(
            'no channel can be replayed: need commands + temperatures, temperatures + angle, or commands + angle'
        )
    # steps of the measured angle the replay does not make (a snap, a slipping crimp): named, whatever the verdict,
    # at times from the run's start (a monitor window's too), as the summary says them; every replay then restarts
    # from the measured angle after each, so that one event does not read as a model error for the rest of the run
    # (a snap of the emulated phase-fraction pair, 0.20 rad in 0.1 s: its own wire's values replayed the run 58.7x the
    # angle's noise without the restart, 1.7x with it)
    angle_steps = []
    if 'mechanics' in ev.channels or 'chain' in ev.channels:
        source = 'measured' if 'mechanics' in ev.channels else 'chain'
        angle_steps = model.restart_after_steps(ev.nominal, ev.i0, ev.sigma['mechanics'], source)
        if angle_steps:
            run = model.run
            ev = ft.Evaluator(model)
    fits: list[ft.Fit] = []
    for e in fx.CATALOGUE:
        if candidates is not None and e.id not in candidates:
            continue
        if not ft.channels_of(e, ev.channels):
            continue
        fits.append(ev.fit(e))
    fits.sort(key=lambda f: f.score)
    # a cause is named only if its fit is an interior value that explains every channel it
    # touches (cross-channel consistency); the rest stay ranked, flagged
    bounds = {id(f): at_bound(f, ev.nominal) for f in fits}
    consistent = {
        id(f): all(f.log_ratio[c] <= CONSISTENT_LOG for c in ft.channels_of(f.effect, ev.channels)) for f in fits
    }
    large = {id(f): effect_size(f, ev.nominal) >= 1.0 for f in fits}
    eligible = [f for f in fits if consistent[id(f)] and not bounds[id(f)] and large[id(f)]]
    # parsimony: among candidates within PARSIMONY_LOG of the best held-out score, the one
    # with the fewest parameters (a recalibration of three numbers always polishes a little
    # more than the one physical effect that explains the data)
    near = [f for f in eligible if f.score <= eligible[0].score + PARSIMONY_LOG] if eligible else []
    best = min(near, key=lambda f: (len(f.effect.params), f.score)) if near else None
    fits = (
        ([best] if best is not None else [])
        + [f for f in eligible if f is not best]
        + [f for f in fits if f not in eligible]
    )

    def main_channel(f: ft.Fit) -> str:
        return min(f.log_ratio, key=lambda c: f.log_ratio[c])

    alternatives = []
    for f in fits:
        c = main_channel(f)
        g = ev.gain(f, c)
        alternatives.append(
            {
                'cause': f.effect.id,
                'subsystem': f.effect.subsystem,
                'score': round(f.score, 4),
                'channel': c,
                'gain_pct': round(g['gain_pct'], 2),
                'parameters': _param_dict(f.row, f.effect.params, ev.nominal),
                'at_bound': [h['parameter'] for h in bounds[id(f)]],
                'consistent': consistent[id(f)],
                'size': round(effect_size(f, ev.nominal), 3),
            }
        )
    channel = main_channel(best) if best else ev.channels[0]
    g_best = ev.gain(best, channel) if best else None
    # significant: beats nominal on held-out data, reliably, and the nominal misfit itself is
    # beyond the noise / replay resolution (else a fit only polishes numerical error)
    significant = bool(
        best is not None
        and best.score < -MIN_SCORE
        and g_best['gain_pct_p05'] > MIN_GAIN_P05
        and g_best['rmse_before'] > STRUCTURE_RATIO * ev.sigma[channel]
    )
    # ... and of a size that matters against the sensor noise (the parameters' practical floor is in `eligible`)
    small = [f for f in fits if consistent[id(f)] and not bounds[id(f)] and not large[id(f)] and f.score < -MIN_SCORE]
    if significant and effect_over_noise(ev, best, channel) < MIN_EFFECT_NOISE:
        significant = False
        small.append(best)
    # the best of those: the model within its practical tolerance explains the run; what it removes is no
    # discrepancy, so it is no unexplained structure either
    tolerated = None if significant or not small else min(small, key=lambda f: f.score)
    partial = bool(
        significant
        and g_best['rmse_after'] > PARTIAL_RATIO * ev.sigma[channel]
        and g_best['gain_pct'] < PARTIAL_GAIN_PCT
    )
    if partial:
        significant = False
    final_row = best.row if significant else ev.nominal
    final_fit = (
        best if significant else ev.score(ft.Fit(fx.Effect('nominal', 'nominal', '-', (), ''), ev.nominal.copy()))
    )

    # residual statistics, nominal and final, after the burn-in
    sl = slice(ev.i0, run.n)
    pred_final = ev.predict(final_row[None])
    q_nom = load_nom = None
    if 'mechanics' in ev.channels or 'chain' in ev.channels:
        src = 'measured' if 'mechanics' in ev.channels else 'chain'
        qq, _, ll = model.mechanics(ev.nominal[None], None, src)
        q_nom, load_nom = qq[:, 0], ll[:, 0]
    reg = _regressors(ev, q_nom, load_nom, sl)
    stats: dict[str, dict[str, Any]] = {}
    structure = []
    pred_tol = ev.predict(tolerated.row[None]) if tolerated is not None else {}
    for c in ev.channels:
        stats[c] = {}
        shown_preds = [('nominal', ev.pred_nom[c][:, 0]), ('extended', pred_final[c][:, 0])]
        if tolerated is not None:
            shown_preds.append(('tolerated', pred_tol[c][:, 0]))
        for which, pred in shown_preds:
            meas = ev.measured(c)
            if c == 'thermal':
                r = ev.residual(c, pred)[sl].T.ravel()
                regs = {k: np.concatenate([v, v]) for k, v in reg.items()}
                ok = np.concatenate([ev.mask[sl], ev.mask[sl]]) > 0
                s = rp.channel_stats(r, ev.sigma[c], regs, meas[sl, 0], pred[sl, 0], run.dt, ok)
            else:
                r = ev.residual(c, pred)[sl]
                s = rp.channel_stats(r, ev.sigma[c], reg, meas[sl], pred[sl], run.dt, ev.mask[sl][: r.shape[0]] > 0)
            stats[c][which] = s
        s = stats[c]['tolerated' if tolerated is not None else 'extended']
        if s['rms_over_noise'] > STRUCTURE_RATIO and not s['white']:
            structure.append(c)
    unexplained = bool(structure)
    corr = [{'channel': c, **x} for c in structure for x in stats[c]['extended']['correlates'][:3]]

    chan_gains = {c: ev.gain(final_fit, c) for c in ev.channels}
    ambiguous: list[dict[str, Any]] = []
    separating = None
    if significant:
        seen = {best.effect.subsystem}
        for f in eligible:
            if f.score <= best.score + AMBIGUITY_LOG and f.effect.subsystem not in seen and f.score < -MIN_SCORE:
                seen.add(f.effect.subsystem)
                ambiguous.append({'cause': f.effect.id, 'subsystem': f.effect.subsystem, 'score': round(f.score, 4)})
        if ambiguous:
            separating = '; '.join(
                SEPARATING_MEASUREMENT.get(
                    frozenset({best.effect.subsystem, a['subsystem']}),
                    'a dedicated excitation run of the subsystems involved',
                )
                for a in ambiguous
            )
    # fits that ended on a bound and would otherwise have been named: never reported as the value
    top_bound = [
        f
        for f in fits
        if bounds[id(f)] and f.score < -MIN_SCORE and f.score <= (best.score if significant else 0.0) - PARSIMONY_LOG
    ]
    hits = [{'cause': f.effect.id, **h} for f in top_bound[:3] for h in bounds[id(f)]]
    hit_text = ''
    if top_bound:
        hit_text = (
            '; '.join(
                f'{h["cause"]} would need {h["parameter"]} beyond its catalogue bound {h["bound"]:g}' for h in hits
            )
            + ': the effect is larger than the catalogue allows, or another cause is at work (not reported as a value)'
        )
    if significant:
        e = best.effect
        ps = ', '.join(
            f'{k} = {v["value"]:.4g} {v["unit"]}' for k, v in _param_dict(best.row, e.params, ev.nominal).items()
        )
        summary = (
            f'{e.subsystem} discrepancy: {e.name} ({e.id}; {ps}); held-out {channel} RMS '
            f'{g_best["rmse_before"]:.4g} -> {g_best["rmse_after"]:.4g} ({g_best["gain_pct"]:.1f} % better)'
        )
        rivals = [
            f.effect.id
            for f in eligible
            if f is not best and f.score <= best.score + PARSIMONY_LOG and f.effect.subsystem == best.effect.subsystem
        ]
        if rivals:
            summary += (
                f'; {", ".join(rivals)} explain(s) this run almost as well (held-out score within '
                f'{PARSIMONY_LOG}): a longer run or larger excitation would separate them'
            )
        if ambiguous:
            names = ', '.join(f'{a["cause"]} ({a["subsystem"]})' for a in ambiguous)
            summary += f'; AMBIGUOUS: {names} explain(s) it almost as well; to separate them: {separating}'
        if unexplained:
            summary += f'; structure remains in {", ".join(structure)}'
    elif unexplained:
        top = ', '.join(f'{x["regressor"]} ({x["r"]:+.2f})' for x in corr[:3])
        if best is not None:
            fitted = f'best {best.effect.id}, score {best.score:.3f}'
        elif tolerated is not None:
            # every fit that beat the model was below the practical floor, and structure remains after the best: say
            # so, not "best -" (the commissioned SD-GPI wrist's run, 5.3 x the angle's noise off its model, whose
            # payload, pre-load and wire shift were each off by less than the floor, read "best -, score 0.000")
            fitted = (
                f'best {tolerated.effect.id}, score {tolerated.score:.3f}, but its fitted values are below what '
                'matters: small departures of several parameters together, or an effect outside the catalogue'
            )
        else:
            fitted = 'no candidate fits the held-out data better than the model'
        summary = (
            f'unexplained discrepancy in {", ".join(structure)}: no catalogue effect explains it ({fitted}'
            + (f', removes only {g_best["gain_pct"]:.0f} % of the {channel} misfit' if partial else '')
            + f'); correlates: {top}'
        )
    else:
        summary = 'no significant discrepancy: the nominal model explains the run to the sensor noise and the replay resolution'
        if tolerated is not None:
            ps = ', '.join(f'{k} = {v:.3g}' for k, v in tolerated.values().items())
            summary += (
                f' (within its tolerance: {tolerated.effect.id} with {ps} would polish it, an effect below what '
                f'matters, doc/explanation/diagnosis.md)'
            )
    if hit_text:
        summary += '; ' + hit_text
    if top_bound and not significant and not unexplained:
        # a cause would explain the run only beyond its range: a discrepancy, but not a named one
        unexplained = True
        structure = [main_channel(top_bound[0])]
        summary = (
            f'unexplained discrepancy in {structure[0]}: no catalogue effect explains it within its range; ' + hit_text
        )
        hit_text = ''
    if angle_steps:
        summary += '; ' + st.describe(angle_steps)
    unnamed = unexplained and not significant
    confidence = ft.verdict_confidence(
        ev, fits if unnamed else eligible, best if significant else None, MIN_SCORE, N_CONFIDENCE, unexplained=unnamed
    )
    if ambiguous:
        confidence = min(confidence, AMBIGUOUS_CONFIDENCE)
    if significant:
        subsystem = best.effect.subsystem
    elif unexplained:
        subsystem = {'thermal': 'thermal', 'mechanics': 'hysteresis/joint', 'chain': 'chain'}[structure[0]]
    else:
        subsystem = None
    # the channel the verdict is about: the named cause's, else the one with structure left (its figures, not
    # those of the best fit's channel: the report printed mechanics' RMS under "thermal")
    shown = channel if significant else (structure[0] if structure else channel)
    res = DiagnosisResult(
        discrepancy=significant or unexplained,
        subsystem=subsystem,
        cause=best.effect.id if significant else None,
        parameters=_param_dict(best.row, best.effect.params, ev.nominal) if significant else {},
        channel=shown,
        rmse_before=g_best['rmse_before'] if significant else chan_gains[shown]['rmse_before'],
        rmse_after=g_best['rmse_after'] if significant else chan_gains[shown]['rmse_after'],
        gain_pct=g_best['gain_pct'] if significant else 0.0,
        gain_ci=(g_best['gain_pct_p05'], g_best['gain_pct_p95']) if significant else (0.0, 0.0),
        alternatives=alternatives,
        unexplained=unexplained,
        correlates=corr,
        channels=chan_gains,
        residual_stats=stats,
        summary=summary,
        confidence=round(float(confidence), 3),
        ambiguous_with=ambiguous,
        separating_measurement=separating,
        bound_hits=hits,
        partial=(
            {
                'cause': best.effect.id,
                'subsystem': best.effect.subsystem,
                'channel': channel,
                'gain_pct': g_best['gain_pct'],
                'parameters': _param_dict(best.row, best.effect.params, ev.nominal),
            }
            if partial
            else None
        ),
        warnings=list(run.warnings),
        angle_steps=angle_steps,
        source=run.source,
        duration_s=run.duration,
        drive=run.drive,
        drive_differs=run.drive_differs,
        thermal_start=run.thermal_start,
        model=pm.describe(),
    )
    if params_out is not None:
        res.params_file = str(write_params(res, params_out, run, model=pm))
    if report_dir is not None:
        d = Path(report_dir)
        d.mkdir(parents=True, exist_ok=True)
        if res.params_file is None:
            res.params_file = str(write_params(res, d / 'extended_params.yaml', run, model=pm))
        traces = {
            't': run.t[sl],
            'i_train': ev.i_train - ev.i0,
            'regressors': reg,
            'meas': {c: ev.measured(c)[sl] for c in ev.channels},
            'nominal': {c: ev.pred_nom[c][sl, 0] for c in ev.channels},
            'best': {c: pred_final[c][sl, 0] for c in ev.channels},
        }
        res.wall_s = time.perf_counter() - t_start
        rp.write_report(res, d, traces)
    res.wall_s = time.perf_counter() - t_start
    return res


def effect_size(f: ft.Fit, nominal: np.ndarray = fx.NOMINAL) -> float:
    """The largest departure of `f`'s fitted parameters from ``nominal`` (the row the fits start from), in units of
    its practical floor (:data:`MIN_SIZE_FRACTION` x the catalogue's typical effect); >= 1: a size that matters."""
    idx = [fx.INDEX[k] for k in f.effect.params]
    if not idx:
        return 0.0
    return float(np.max(np.abs(f.row[idx] - nominal[idx]) / (MIN_SIZE_FRACTION * fx.TYPICAL[idx])))


def effect_over_noise(ev: ft.Evaluator, f: ft.Fit, c: str) -> float:
    """RMS over the held-out samples of how much `f` moves channel `c`'s prediction from the nominal one, over the
    channel's noise level (dimensionless)."""
    pred = ev.predict(f.row[None], [c])[c][:, 0]
    d = ev.residual(c, ev.pred_nom[c][:, 0]) - ev.residual(c, pred)  # masked like the scores
    return float(np.sqrt(np.sum(d[ev.i_train :] ** 2) / ev.n_test(c)) / ev.sigma[c])


def bound_tolerance(lo: float, hi: float, nominal: float, bound: float) -> float:
    """How near ``bound`` (``lo`` or ``hi``, a parameter's catalogue range) a value fitted from ``nominal`` counts as
    on it: :data:`BOUND_FRACTION` of the range, and at most :data:`BOUND_SHARE` of the way from the nominal value to
    the bound (0 where the nominal value is the bound: no fit is on it)."""
    return min(BOUND_FRACTION * (hi - lo), BOUND_SHARE * abs(nominal - bound))


def at_bound(f: ft.Fit, nominal: np.ndarray = fx.NOMINAL) -> list[dict[str, Any]]:
    """The fitted parameters of `f` that ended on a catalogue bound other than their ``nominal`` value (the row the
    fits start from)."""
    out = []
    for k in f.effect.params:
        i = fx.INDEX[k]
        v, lo, hi, nom = f.row[i], fx.LOWER[i], fx.UPPER[i], nominal[i]
        for b in (lo, hi):
            tol = bound_tolerance(lo, hi, nom, b)
            if abs(v - b) <= tol and abs(nom - b) > tol:
                out.append({'parameter': k, 'value': float(v), 'bound': float(b)})
    return out


def write_params(
    res: DiagnosisResult,
    path: str | Path,
    run: Run,
    hysteresis_file: str | Path | None = None,
    thermal_file: str | Path | None = None,
    model: Any = None,
) -> Path:
    """The extended model as a ROS 2 params file for plant_sim (schema: doc/explanation/diagnosis.md).

    ``hysteresis_file``, ``thermal_file``: the wire and TEMs the diagnosis replayed; carried (absolute) so that
    the file runs the same plant instead of silently falling back to the built-in one. ``model``: the
    :class:`~sma_wrist.plant_model.PlantModel` replayed instead (its files, pre-load and ``model.*``
    values carried, the fitted values replacing its).
    """
    from sma_wrist.core.plant import extensions as mx

    # payload_kg stays the recorded one (what /wrist/payload says); a payload mismatch is the
    # model.payload_err_kg the joint carries on top of it
    params: dict[str, Any] = {'payload_kg': float(run.payload_kg)}
    if model is not None:
        hysteresis_file, thermal_file = model.hysteresis_file, model.thermal_file
    if hysteresis_file:
        params['hysteresis_file'] = str(Path(hysteresis_file).resolve())
    if thermal_file:
        params['thermal_file'] = str(Path(thermal_file).resolve())
    if model is not None and model.heat_balance_file:  # the model's heat balance in another form (Peltier)
        params['heat_balance_file'] = str(Path(model.heat_balance_file).resolve())
    if model is not None and model.wire_file:  # the model's phase-fraction wire (plant_sim's wire_file)
        params['wire_file'] = str(Path(model.wire_file).resolve())
    if model is not None and model.preload_elongation_mm is not None:
        params['preload_elongation_mm'] = model.preload_elongation_mm
    ext = dict(model.extension) if model is not None else {}
    ext.update({k: float(d['value']) for k, d in res.parameters.items()})
    params.update({f'model.{k}': v for k, v in ext.items()})
    replay_only = [k for k, v in ext.items() if k in mx.REPLAY_ONLY and v != mx.NOMINAL[k]]
    doc = {'plant_sim': {'ros__parameters': params}}
    comment = (
        f'sma-wrist diagnose: extended model of {res.source or "a run"}\n'
        f'cause: {res.cause or "none"} ({res.subsystem or "-"}); {res.summary}\n'
        f'schema: doc/explanation/diagnosis.md: plant_sim parameters, model.* as in sma_wrist/core/plant/extensions.py'
        + (
            f'\nnote: {", ".join(replay_only)} is replayed by the diagnosis but not simulated by plant_sim, '
            f'which refuses this file'
            if replay_only
            else ''
        )
    )
    return write_yaml_file(path, doc, comment, flow_lists=True)


def diagnose(
    path: str | Path,
    report_dir: str | Path | None = None,
    params_out: str | Path | None = None,
    candidates: Sequence[str] | None = None,
    hysteresis_file: str | None = None,
    thermal_file: str | None = None,
    recording: Recording | None = None,
    settle_s: float = 0.0,
    params_file: str | None = None,
) -> DiagnosisResult:
    """Diagnose the bag at `path` (``recording``: how it names the contract's topics and the joint, if otherwise);
    the first ``settle_s`` [s] only settle the replays' memory (:attr:`Run.settle_s`: a bag that starts from a
    history the replays' rest state does not hold). ``params_file``: replay the model of its plant node
    (:func:`diagnose_run`). Raises DiagnoseInputError for unusable input."""
    if not (math.isfinite(settle_s) and settle_s >= 0.0):
        raise DiagnoseInputError(f'settle_s must be a finite number of seconds >= 0, got {settle_s!r}')
    from sma_wrist.plant_model import PlantModelFileError

    try:  # a model that does not load (its files named, or their content), before the bag is read
        plant_model(params_file, hysteresis_file, thermal_file).base()
    except PlantModelFileError as exc:
        raise DiagnoseInputError(str(exc)) from None
    run = load_run(path, recording=recording)
    run.settle_s = float(settle_s)
    return diagnose_run(run, report_dir, params_out, candidates, hysteresis_file, thermal_file, params_file)


def run_cli(args: argparse.Namespace) -> int:
    """Run a parsed ``diagnose`` command line; exit 0 ok, 2 bad input, 1 internal error."""
    try:
        cands = args.candidates.split(',') if args.candidates else None
        if cands:
            unknown = [c for c in cands if c not in fx.EFFECTS]
            if unknown:
                raise DiagnoseInputError(
                    f'unknown candidate(s) {", ".join(unknown)}; catalogue: {", ".join(fx.EFFECTS)}'
                )
        from sma_wrist.outputs import check_output_file, check_output_folder

        models = [
            f
            for f in (
                getattr(args, 'hysteresis_file', None),
                getattr(args, 'thermal_file', None),
                getattr(args, 'params_file', None),
            )
            if f
        ]
        check_output_file(args.params, '--params', [args.bag, *models], DiagnoseInputError)
        check_output_folder(args.report, '--report', [args.bag, *models], DiagnoseInputError)
        recording = Recording.from_options(getattr(args, 'topic', None), getattr(args, 'joint', None))
        res = diagnose(
            args.bag,
            args.report,
            args.params,
            cands,
            getattr(args, 'hysteresis_file', None),
            getattr(args, 'thermal_file', None),
            recording,
            params_file=getattr(args, 'params_file', None),
        )
    except (DiagnoseInputError, ParameterError, ContractError) as exc:
        if args.json:
            print(json.dumps({'error': str(exc)}))
        else:
            print(f'error: {exc}', file=sys.stderr)  # every sma-wrist command's one-line form
        return 2
    except Exception as exc:  # noqa: BLE001 - the command never shows a traceback
        msg = f'internal error {type(exc).__name__}: {exc} (please report with the bag)'
        print(
            json.dumps({'error': msg}) if args.json else f'error: {msg}',
            file=sys.stderr if not args.json else sys.stdout,
        )
        return 1
    if args.json:
        print(json.dumps(res.to_json()))
        return 0
    for w in res.warnings:
        print(f'warning: {w}')
    print(res.summary)
    if res.drive == 'applied':  # a bag of commands only (every simulator bag) replays them, as it always did
        print(f'  {rp.drive_replayed(res.drive, res.drive_differs)}')
    if res.model != DiagnosisResult.model:  # a params file's or model files' model: say which
        print(f'  model replayed: {res.model}')
    for c, g in res.channels.items():
        print(f'  {c:9s} held-out RMS {g["rmse_before"]:.4g} -> {g["rmse_after"]:.4g} ({g["gain_pct"]:+.1f} %)')
    print('  ranked candidates: ' + ', '.join(f'{a["cause"]} {a["score"]:.2f}' for a in res.alternatives[:5]))
    if res.params_file:
        print(f'  extended model: {res.params_file}')
    if args.report:
        print(f'  report: {Path(args.report) / "diagnosis.md"}')
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m sma_wrist.diagnose BAG [--json] [--report DIR] [--params FILE]``."""
    ap = add_arguments(
        argparse.ArgumentParser(
            prog='sma-wrist diagnose',
            description='Locate and name the model discrepancy of a recorded run (doc/explanation/diagnosis.md).',
        )
    )
    return run_cli(ap.parse_args(list(argv) if argv is not None else None))
