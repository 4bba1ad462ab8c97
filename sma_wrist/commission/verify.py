"""Verification: the Sec. 6.1 sine in closed loop on the commissioned wrist, with its params file and with the
defaults, from the same start, side by side; the commissioned run diagnosed against the commissioned model.

The loop is the node graph ``sma-wrist run --hardware`` runs (:func:`sma_wrist.closed_loop.run_closed_loop`,
hardware_bridge on the device's port, run's 30 s soft start), once per controller and parameter set:

* **default**: config/wrist.yaml with only the bring-up's bridge calibration (the wiring and the angle): what the
  wrist would run with had nobody commissioned it;
* **commissioned**: the params file handed over (``wrist_params.yaml``), run first of the two. Where it gives the
  graph's nodes the same values as the defaults (the built-in model handed over: the same hysteresis and heat
  balance, window, pre-load and payload), the two are one run, said so (``identical_parameters``).

**The same start** (:func:`settle`): before each run the muscles are brought back to the temperature they had at
rest when the bring-up began (the TEMs cooling or heating them, within the bring-up's drive limits) and held
there until the angle no longer moves: a wrist at ambient, as a first ``sma-wrist run`` finds it. Without it the
second run of a pair started from where the first left the muscles. The wires' hysteresis still remembers which
muscle was heated last (the built-in wire: 0.013 rad after muscle 2 was heated to 76 degC and brought back, 0.090
rad after muscle 1, 0.081 rad from rest); the run's first large cycle wipes that out. The state each run started from is measured
and reported (``runs[].start``).

**Steady cycles and their spread** (:func:`cycle_metrics`, :func:`compare`): each run is the 30 s soft start and
``cycles`` full 62.8 s cycles; the soft start (the wrist leaving rest) is reported apart, the cycles each, and
the metrics compared are their mean max and RMS error in % of the reference's range. How much one cycle differs
from the next in the same run (the spread: the largest range of either side's cycles) is the resolution of the
comparison: the commissioned loop is called ``worse`` or ``better`` only where the means differ by more than it.

The commissioned run of the first controller is recorded as a bag and diagnosed
(:func:`sma_wrist.diagnose.diagnose`) against the commissioned model (the params file's ``hysteresis_file`` /
``thermal_file`` where it names them): a wrist that is its commissioned model gives no discrepancy. The soft start
only settles the replay's memory (:attr:`sma_wrist.diagnose.data.Run.settle_s`), as it is apart in the metrics:
the replay starts from the rest state, the wires from what the excitation and the settling left.

A simulated device (``--sim``: the emulated device the bring-up stepped in lockstep) is served on a
pseudo-terminal for each run, the same wrist, stepped in lockstep again for the settling between runs
(:meth:`SimDevice.serve`); a real device is settled through the same port, reopened between runs.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import shutil
import tempfile
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from sma_wrist.core.errors import ParameterError, SmaWristError
from sma_wrist.core.metrics import SEED_PERIOD_S
from sma_wrist.core.yaml_file import write_yaml_file

#: run's soft start [s] (sma_wrist.core.control.trajectory.RUN_SOFT_START_S) before the compared cycles
SOFT_START_S = 30.0
#: full cycles of the sine per run: two, so that each side has a spread (one cycle against the next)
CYCLES = 2
#: device seconds per run: the soft start, the cycles, and a margin for the graph's first samples
DURATION_S = round(SOFT_START_S + CYCLES * SEED_PERIOD_S + 2.0, 1)
CONTROLLERS = ('inverse_adaptive', 'direct_adaptive', 'pid')
#: device seconds the whole procedure may take (bring-up, excitation, identification, verification): 15 min
BUDGET_S = 900.0
#: device seconds a run takes beyond its duration (the graph's first and last samples)
RUN_OVERHEAD_S = 1.0
#: the least device time the settling before a run gets when the budget is short [s]
MIN_SETTLE_S = 15.0
DEFAULTS_FILE = 'defaults.yaml'
#: a simulated device is served by a thread of this process, which shares the interpreter with the graph: on a
#: loaded machine (load 16-20 on 2 cores) it paused the stream for more than the bridge's 0.1 s sensor timeout dozens
#: of times a run (the TEMs cut each time: 35.7 against 6.5 % max on the same nominal device), and still twice a run
#: for 0.5 s. A real device streams on its own; this one cannot fall silent but by the test's own freeze.
SIM_BRIDGE = {'sensor_timeout_s': 5.0}
#: the bridge parameters the defaults keep: what the bring-up measured of the wiring and the angle, no more
CALIBRATION_KEYS = (
    'calibration.tem_sign',
    'calibration.tem_channel_map',
    'calibration.thermocouple_map',
    'calibration.angle_gain_rad_per_count',
    'calibration.angle_offset_rad',
)


@dataclass(frozen=True)
class VerifyOptions:
    """What commissioning verifies: ``controllers`` (None: the params file's adaptive_controller mode),
    ``duration_s`` of device time per run, the diagnosis of the commissioned run, how much faster than wall
    time a simulated device is served (a real one runs in real time), and whether the wrist is settled to the
    same start before each run (:func:`settle`)."""

    controllers: tuple[str, ...] | None = None
    duration_s: float = DURATION_S
    diagnose: bool = True
    sim_time_scale: float = 2.0
    settle: bool = True


@dataclass(frozen=True)
class SettleLimits:
    """How :func:`settle` brings the wrist to its start: temperatures [degC], drives [V], device times [s]."""

    tolerance_C: float = 1.0  # each muscle within this of its rest temperature
    gain_V_per_C: float = 3.0  # the drive per degC away from it (cooling at up to the bring-up's cool_V)
    integral_V_per_C_s: float = 0.5  # ... and per degC s: the heat a warm exchanger face leaks back, held off
    heat_V: float = 6.0  # the most it heats (a muscle below its rest temperature: the bring-up's pulse drive)
    still_s: float = 2.0  # this long the muscles within the tolerance and the angle still
    still_rad: float = 0.005  # the angle's range over still_s
    timeout_s: float = 90.0  # then the run starts from where the wrist is, said so (settled: false)
    max_muscle_C: float = 90.0  # over this a muscle stops the procedure (hardware_bridge's max_muscle_temperature_C)
    max_face_C: float = 85.0  # ... a TEM face (hardware_bridge's max_tem_face_temperature_C)
    command_period_s: float = 0.02


class VerificationStopped(Exception):
    """The device stopped answering during a verification run (the TEMs were held at 0 V)."""


def controllers_of(text: str | Sequence[str] | None, params_files: Sequence[str | Path] = ()) -> list[str]:
    """The controllers to verify: ``None`` the params files' adaptive_controller mode (what ``run`` would use),
    ``'all'`` the three, else a comma-separated list; ValueError naming an unknown one."""
    if text is None:
        from sma_wrist.closed_loop import file_choices

        return [file_choices(params_files, hardware=True)[0]]
    names = text.split(',') if isinstance(text, str) else list(text)
    names = [n.strip() for n in names if n.strip()]
    if names == ['all']:
        return list(CONTROLLERS)
    bad = [n for n in names if n not in CONTROLLERS]
    if bad or not names:
        raise ValueError(f'--controllers {text!r}: all, or a comma-separated list of {", ".join(CONTROLLERS)}')
    return list(dict.fromkeys(names))


def write_defaults(path: Path, bridge_params: dict[str, Any]) -> Path:
    """The defaults' params file: only the bring-up's calibration under hardware_bridge."""
    keep = {k: bridge_params[k] for k in CALIBRATION_KEYS if k in bridge_params}
    return write_yaml_file(
        path,
        {'hardware_bridge': {'ros__parameters': keep}},
        'config/wrist.yaml with only the wiring and angle calibration the bring-up measured: the defaults the\n'
        'commissioned parameters are verified against (sma-wrist commission, doc/howto/commission.md).',
        flow_lists=True,
    )


def settle(bring: Any, lim: SettleLimits | None = None) -> dict[str, Any]:
    """Bring the wrist on ``bring``'s device (a :class:`~sma_wrist.commission.bringup.BringUp` after its bring-up)
    back to its rest: each muscle held by a PI drive at the temperature it had at rest when the bring-up began
    (cooling at up to the bring-up's ``cool_V``, heating at up to ``lim.heat_V``) until both are within
    ``lim.tolerance_C`` of it and the angle has been still for ``lim.still_s``; then 0 V. Returns the start state
    measured at the end: ``{'settled', 'seconds', 'muscle_C', 'face_C', 'angle_rad', 'target_C'}`` (the TEMs'
    exchanger faces are not waited for: the heat pumped out of a hot muscle leaves them warm for minutes; they are
    measured). The TEMs are at 0 V afterwards in every case. Stop (a bring-up limit), DeviceLost and
    KeyboardInterrupt propagate with the TEMs off."""
    lim = lim or SettleLimits()
    lim0 = bring.lim
    target = np.asarray(bring._T_start[:2], float)
    # the muscles and faces may start as hot as a closed-loop run leaves them (the controllers take a muscle up to
    # 85 degC and keep the faces in the TEMs' 0-80 degC: a muscle above 82 degC after a run on the nominal wrist
    # stopped a settling held to the excitation's 82 degC), the joint anywhere in its range: the limits are the
    # bridge's, which ran the wrist just before
    bring.lim = dataclasses.replace(
        lim0,
        max_muscle_C=max(lim0.max_muscle_C, lim.max_muscle_C),
        max_face_C=max(lim0.max_face_C, lim.max_face_C),
        max_excursion_rad=1.8,
    )
    cool_V = min(lim0.cool_V, lim0.max_drive_V)
    heat_V = min(lim.heat_V, lim0.max_drive_V)
    face_hi = lim.max_face_C - 5.0  # an exchanger face this hot takes no more heat (as the excitation's governor)
    # the samples that arrive first: the device time a run had the device for lies before them, not in the settling
    bring.set_drive(0.0, 0.0)
    bring.pump()
    t0 = bring.t
    still_since: float | None = None
    settled = False
    integral = np.zeros(2)  # [degC s]
    bring.mark('settle to the rest temperature')
    try:
        while bring.t - t0 < lim.timeout_s:
            _, adc, _ = bring.rec.arrays(bring.t - 0.1)
            temps, _ = bring.physical(adc)
            T = temps.mean(axis=0)
            off = T[:2] - target
            if np.all(np.abs(off) <= lim.tolerance_C):
                still_since = bring.t if still_since is None else still_since
                _, adc_w, _ = bring.rec.arrays(still_since)
                if float(np.ptp(bring.physical(adc_w)[1])) > lim.still_rad:
                    still_since = bring.t  # the joint still moving: its stillness starts again
                elif bring.t - still_since >= lim.still_s:
                    settled = True
                    break
            else:
                still_since = None
            u = -lim.gain_V_per_C * off - lim.integral_V_per_C_s * integral
            sat = np.clip(u, -cool_V, heat_V)
            # the integral only where the drive is not at its limit (no wind-up while cooling at full drive)
            integral += np.where(sat == u, off, 0.0) * lim.command_period_s
            sat[(sat < 0) & (T[2:] > face_hi)] = 0.0
            bring.set_drive(float(sat[0]), float(sat[1]))
            bring.hold(lim.command_period_s)
        bring.set_drive(0.0, 0.0)
        bring.hold(lim.command_period_s)  # the device has taken the 0 V (a device in lockstep takes it with a sample)
    except BaseException:
        bring.off()
        raise
    finally:
        bring.lim = lim0
    _, adc, _ = bring.rec.arrays(bring.t - 0.5)
    temps, q = bring.physical(adc)
    T = temps.mean(axis=0)
    return {
        'settled': settled,
        'seconds': round(bring.t - t0, 2),
        'target_C': [round(float(x), 2) for x in target],
        'muscle_C': [round(float(x), 2) for x in T[:2]],
        'face_C': [round(float(x), 2) for x in T[2:]],
        'angle_rad': round(float(q.mean()), 4),
    }


def cycle_metrics(run: Any, duration_s: float, soft_start_s: float = SOFT_START_S) -> dict[str, Any]:
    """Max and RMS error [% of the reference's range] of a run (:class:`sma_wrist.runs.RunData`) per full cycle of
    the sine, counted back from its end (as :func:`sma_wrist.runs.run_metrics` takes its last cycle): as many as
    ``duration_s`` holds after ``soft_start_s``, in time order; and the part before them (the soft start, the
    wrist leaving rest) apart. ``{'cycles': [{max_pct, rms_pct}, ...], 'start_up': {max_pct, rms_pct} | None}``."""
    from sma_wrist.core.metrics import tracking_metrics

    n = int(math.floor((duration_s - soft_start_s) / SEED_PERIOD_S + 1e-9))
    t = np.asarray(run.t, float)
    if t.size < 2 or n < 1 or t[-1] - t[0] < n * SEED_PERIOD_S:
        return {'cycles': [], 'start_up': None}
    span = float(np.ptp(run.q_d)) or None  # the whole run's reference range, as run_metrics takes it

    def window(lo: float, hi: float) -> dict[str, float]:
        k = (t >= lo) & (t < hi) if hi < t[-1] else t >= lo
        m = tracking_metrics(t[k], run.q[k], run.q_d[k], reference_range_rad=span, period_s=None)
        return {'max_pct': round(m.max_error_pct, 2), 'rms_pct': round(m.rms_error_pct, 2)}

    ends = [float(t[-1]) - k * SEED_PERIOD_S for k in range(n, -1, -1)]
    cycles = [window(lo, hi) for lo, hi in zip(ends[:-1], ends[1:])]
    start_up = window(float(t[0]), ends[0]) if ends[0] - t[0] >= 1.0 else None
    return {'cycles': cycles, 'start_up': start_up}


def side(cycles: Sequence[dict[str, float]]) -> dict[str, Any]:
    """One side of the comparison from its cycles: the mean max and RMS error and their spread (the range of the
    cycles; None from fewer than two)."""
    out: dict[str, Any] = {}
    for x in ('max_pct', 'rms_pct'):
        v = [c[x] for c in cycles if c.get(x) is not None]
        out[x] = round(float(np.mean(v)), 2) if v else None
        out[x.replace('_pct', '_spread_pct')] = round(float(np.ptp(v)), 2) if len(v) >= 2 else None
    out['cycles'] = len(cycles)
    return out


def compare(commissioned: dict[str, Any], default: dict[str, Any]) -> dict[str, Any]:
    """The verdict on two sides (:func:`side`): per metric the difference commissioned - defaults [points] against
    the spread (the larger of the two sides'); ``verdict`` ``worse`` where a difference exceeds its spread upwards,
    else ``better`` where one exceeds it downwards, else ``within_spread``; ``spread_unknown`` where a side has
    fewer than two cycles (one cycle per run cannot tell a gain from one run against the next)."""
    out: dict[str, Any] = {}
    worse = better = unknown = False
    for x in ('max_pct', 'rms_pct'):
        c, d = commissioned.get(x), default.get(x)
        sc, sd = commissioned.get(x.replace('_pct', '_spread_pct')), default.get(x.replace('_pct', '_spread_pct'))
        if c is None or d is None:
            unknown = True
            out[x] = {'difference': None, 'spread': None}
            continue
        spread = None if sc is None or sd is None else max(sc, sd)
        diff = round(c - d, 2)
        out[x] = {'difference': diff, 'spread': spread}
        if spread is None:
            unknown = True
        elif diff > spread:
            worse = True
        elif -diff > spread:
            better = True
    out['verdict'] = 'worse' if worse else 'better' if better else 'spread_unknown' if unknown else 'within_spread'
    return out


def graph_values(params_files: Sequence[str | Path], controller: str) -> dict[str, dict[str, Any]]:
    """The values the hardware graph's nodes (:func:`sma_wrist.closed_loop.graph_nodes`) get from their defaults,
    config/wrist.yaml and ``params_files`` (later ones win), a model file (``hysteresis_file``, ``thermal_file``)
    as the model it holds ('' the built-in one); the port aside. ParameterError for a file that does not load."""
    from sma_wrist import runtime

    runtime.activate()  # the node classes import the message types (the embedded runtime's where rclpy is absent)
    from sma_wrist.closed_loop import graph_nodes
    from sma_wrist.core.hysteresis.params_file import hysteresis_params
    from sma_wrist.core.thermal.heat_balance import ThermalParams
    from sma_wrist.core.thermal.params_file import load_thermal_file
    from sma_wrist.runtime.arguments import load_params_file
    from sma_wrist.share import share_path

    out: dict[str, dict[str, Any]] = {}
    for cls in graph_nodes(controller, hardware=True):
        name = cls.__module__.rsplit('.', 1)[-1]
        values = {p.name: p.default for p in cls.PARAMS}
        for f in [share_path('config/wrist.yaml'), *params_files]:
            for rule in load_params_file(f):
                if rule.node.strip('/') in ('**', '*', name) and rule.name in values:
                    v = rule.value
                    if rule.name in ('hysteresis_file', 'thermal_file') and v and not Path(v).is_absolute():
                        v = str(Path(f).parent / v)
                    values[rule.name] = v
        values.pop('port', None)
        if 'hysteresis_file' in values:
            values['hysteresis_file'] = hysteresis_params(values['hysteresis_file'] or None)
        if 'thermal_file' in values:
            values['thermal_file'] = (
                load_thermal_file(values['thermal_file']) if values['thermal_file'] else ThermalParams()
            )
        out[name] = values
    return out


def differences(a: dict[str, dict[str, Any]], b: dict[str, dict[str, Any]]) -> list[str]:
    """``node.parameter`` of every value that differs between two :func:`graph_values` (numbers to 1e-9)."""
    return [f'{n}.{k}' for n in a for k in a[n] if not _same(a[n][k], b.get(n, {}).get(k))]


def _same(x: Any, y: Any) -> bool:
    if dataclasses.is_dataclass(x) and dataclasses.is_dataclass(y):
        return type(x) is type(y) and all(_same(getattr(x, f.name), getattr(y, f.name)) for f in dataclasses.fields(x))
    if isinstance(x, (list, tuple, np.ndarray)) or isinstance(y, (list, tuple, np.ndarray)):
        try:
            ax, ay = np.asarray(x, float), np.asarray(y, float)
        except (TypeError, ValueError):
            return bool(np.all(np.asarray(x, object) == np.asarray(y, object)))
        return ax.shape == ay.shape and bool(np.allclose(ax, ay, rtol=1e-9, atol=1e-12, equal_nan=True))
    if isinstance(x, dict) and isinstance(y, dict):
        return x.keys() == y.keys() and all(_same(x[k], y[k]) for k in x)
    if isinstance(x, (int, float)) and isinstance(y, (int, float)) and not isinstance(x, bool):
        return math.isclose(float(x), float(y), rel_tol=1e-9, abs_tol=1e-12) or (x != x and y != y)
    return x == y


def verify(
    out: str | Path,
    serve: Callable[[], Any],
    params_file: str | Path,
    bridge_params: dict[str, Any],
    controllers: Sequence[str],
    duration_s: float = DURATION_S,
    diagnose: bool = True,
    progress: Callable[[str], None] | None = None,
    device_clock: Callable[[], float] | None = None,
    into: dict[str, Any] | None = None,
    bridge: dict[str, Any] | None = None,
    settle_to_start: Callable[[float], dict[str, Any]] | None = None,
    budget_s: float | None = None,
    refine: Callable[[Path, Path, float], dict[str, Any]] | None = None,
) -> dict[str, Any]:
    """Run the sine per controller with the defaults and with ``params_file`` on the device ``serve()`` gives
    (a context manager yielding its port, entered for each run), each run after ``settle_to_start(timeout_s)`` (the
    start state it measured; None: no settling). ``budget_s``: the device seconds the verification may take (the
    15 min of the whole procedure less what came before): where the runs fit into it, the settling before each
    run is cut short so that they all do (the start then says ``settled: false``); None, or runs that do not fit
    however short the settling (several controllers): each settling takes what it needs, up to its timeout.

    Returns ``{'default': {ctrl: side}, 'commissioned': {ctrl: side}, 'comparison': {ctrl: compare + differs},
    'identical_parameters': {ctrl: bool}, 'device_time_s', 'duration_s', 'runs': [...], 'plots': [...],
    'diagnosis': {...} | None}`` (side: :func:`side` with ``start_up``, the soft start's metrics);
    ``bridge``: hardware_bridge parameters beside the port (both parameter sets alike); ``device_clock()`` [s]:
    the device's own time (a served emulated device), else wall time counts as device time (a real one runs in
    real time). KeyboardInterrupt propagates (the bridge has left the TEMs at 0 V); VerificationStopped when the
    device stopped answering. The result is built in ``into`` (a dict of the caller's), so that what was measured
    before either is kept. ``refine(commissioned bag, defaults bag, soft start [s])``: run after the first
    controller's two recorded runs, before the diagnosis (:func:`sma_wrist.commission.refine.refine_wire`), its
    result as ``refinement``."""
    from sma_wrist import runtime

    runtime.activate()  # the embedded runtime where rclpy is absent (as sma-wrist run)
    from sma_wrist.runs import plot_runs

    folder = Path(out) / 'verification'
    folder.mkdir(parents=True, exist_ok=True)
    defaults = write_defaults(folder / DEFAULTS_FILE, bridge_params)
    progress = progress or (lambda text: None)
    clock = device_clock or time.monotonic
    t0 = clock()
    res = into if into is not None else {}
    res.update(
        {
            'default': {},
            'commissioned': {},
            'comparison': {},
            'identical_parameters': {},
            'duration_s': duration_s,
            'defaults_file': str(defaults),
            'params_file': str(params_file),
            'runs': [],
            'plots': [],
            'diagnosis': None,
            'refinement': None,
        }
    )

    def account() -> None:
        res['device_time_s'] = round(clock() - t0, 1)

    account()
    diagnosed = None
    diagnosed_soft = SOFT_START_S
    same_as = {
        ctrl: differences(graph_values([params_file], ctrl), graph_values([defaults], ctrl)) for ctrl in controllers
    }
    runs_left = sum(1 if not d else 2 for d in same_as.values())
    # the budget is kept where the runs fit into it at all: then the settling before each run gets its share of
    # what the runs leave (at least MIN_SETTLE_S), else it takes what it needs
    keep_budget = budget_s is not None and runs_left * (duration_s + RUN_OVERHEAD_S) <= budget_s

    def settle_timeout() -> float:
        if not keep_budget:
            return SettleLimits().timeout_s
        left = budget_s - (clock() - t0) - runs_left * (duration_s + RUN_OVERHEAD_S)
        return float(min(SettleLimits().timeout_s, max(MIN_SETTLE_S, left / runs_left)))

    for ctrl in controllers:
        differs = same_as[ctrl]
        same = not differs
        res['identical_parameters'][ctrl] = same
        runs = {}
        # the commissioned run first (both start from the same settled state; without the settling the second of
        # a pair started from the wrist the first left warm); parameters the same as the defaults' run once
        pairs = (('default', [defaults]),) if same else (('commissioned', [params_file]), ('default', [defaults]))
        for which, files in pairs:
            progress(f'verification: {ctrl}, {which} parameters' + (' (the same as commissioned)' if same else ''))
            start = settle_to_start(settle_timeout()) if settle_to_start is not None else None
            runs_left -= 1
            account()
            # the first controller's runs are recorded: the commissioned one is diagnosed, the defaults' one is
            # device data the refinement (sma_wrist.commission.refine) fits the wire on beside the excitation
            recorded = diagnose and ctrl == controllers[0]
            bag = folder / f'{ctrl}_{"commissioned" if which == "commissioned" or same else "defaults"}'
            bag = bag if recorded else None
            if bag is not None and bag.is_dir():
                shutil.rmtree(bag)  # an earlier commissioning into this folder: its report and params are replaced too
            payload, soft = run_settings(files)
            try:
                with serve() as port:
                    s = run_on_port(port, ctrl, files, payload, soft, duration_s, bag, bridge)
            except ParameterError:
                raise  # a value of the params file a node refuses: bad input, before the graph started
            except SmaWristError as e:
                account()
                raise VerificationStopped(f'{ctrl} with the {which} parameters: {e}') from None
            account()
            if s.interrupted:
                raise KeyboardInterrupt
            if bag is not None and (which == 'commissioned' or same):
                diagnosed, diagnosed_soft = bag, soft
            m = s.metrics or {}
            per = cycle_metrics(s.run, duration_s, soft) if s.run is not None else {'cycles': [], 'start_up': None}
            one = (
                side(per['cycles'])
                if per['cycles']
                else side([{'max_pct': _r(m.get('max_error_pct')), 'rms_pct': _r(m.get('rms_error_pct'))}])
            )
            one['start_up'] = per['start_up']
            for w in ('default', 'commissioned') if same else (which,):
                res[w][ctrl] = one
            res['runs'].append(
                {
                    'controller': ctrl,
                    'parameters': 'default and commissioned (the same)' if same else which,
                    'payload_kg': payload,
                    'device_s': round(s.sim_time_s, 2),
                    'start': start,
                    'cycles': per['cycles'],
                    'start_up': per['start_up'],
                    'window': m.get('window'),
                    'peak_command_V': _r(m.get('peak_command_V')),
                    'bag': str(bag) if bag else None,
                }
            )
            runs[which] = s.run
        res['comparison'][ctrl] = {
            **(
                {'verdict': 'identical_parameters'}
                if same
                else compare(res['commissioned'][ctrl], res['default'][ctrl])
            ),
            'differs': differs,  # what the commissioned parameters change for this controller's graph
        }
        if all(r is not None for r in runs.values()):
            png = folder / f'{ctrl}.png'
            labels = {'default': f'{ctrl}, defaults', 'commissioned': f'{ctrl}, commissioned'}
            if same:
                labels['default'] = f'{ctrl}, defaults (= commissioned)'
            order = [w for w in ('default', 'commissioned') if w in runs]
            plot_runs([runs[w] for w in order], [labels[w] for w in order], png, f'verification: {ctrl}')
            res['plots'].append(str(png))
    bags = [Path(r['bag']) for r in res['runs'] if r['bag'] and r['controller'] == controllers[0]]
    if refine is not None and len(bags) == 2:
        progress('verification: refinement of the model wire on the defaults run')
        res['refinement'] = refine(bags[0], bags[1], diagnosed_soft)
    if diagnosed is not None:
        progress('verification: diagnosis of the commissioned run')
        res['diagnosis'] = diagnosis(diagnosed, params_file, diagnosed_soft)
    return res


def run_settings(files: Sequence[str | Path]) -> tuple[float, float]:
    """(payload [kg], soft start [s]) a verification run takes from its params ``files``, as ``sma-wrist run --hardware``
    would (the soft start :data:`SOFT_START_S` where the files give none)."""
    from sma_wrist.closed_loop import file_choices, file_soft_start

    _, payload = file_choices(files, hardware=True)
    soft = file_soft_start(files)
    return payload, SOFT_START_S if soft is None else soft


def run_on_port(
    port: str,
    controller: str,
    files: Sequence[str | Path],
    payload_kg: float,
    soft_start_s: float,
    duration_s: float,
    bag: Path | None = None,
    bridge: dict[str, Any] | None = None,
) -> Any:
    """The hardware graph of ``sma-wrist run --hardware PORT`` with ``files`` for ``duration_s`` of device time,
    measured (:func:`sma_wrist.closed_loop.run_closed_loop`'s summary); ``bridge``: hardware_bridge parameters beside
    the port."""
    from sma_wrist.closed_loop import run_closed_loop

    return run_closed_loop(
        controller,
        payload_kg,
        duration_s,
        bag,
        files,
        extra_params={
            '/hardware_bridge': {**(bridge or {}), 'port': port},
            '/trajectory_generator': {'soft_start_s': soft_start_s},  # as sma-wrist run
        },
        hardware=True,
        measure=True,
    )


def run_verification(
    result: dict[str, Any],
    out: Path,
    device: Any,
    opts: VerifyOptions,
    progress: Callable[[str], None] | None = None,
    bring: Any = None,
    refinement: Any = None,
) -> None:
    """Verify the commissioned wrist on ``device`` (closed: the bring-up is over) into ``result``
    (``verification``, ``device_time_s``, and ``status`` / ``message`` / ``faults`` when it is interrupted, the
    device stops answering or breaks a limit while settling); append its section to the report. ``bring``: the
    bring-up (:class:`~sma_wrist.commission.bringup.BringUp`) whose record gives the rest temperatures each run is
    settled to (None, or ``opts.settle`` false: no settling). ``refinement``: the identification's
    :class:`~sma_wrist.commission.identification.WireRefinement` (None: nothing to refine). The TEMs are at 0 V afterwards in
    every case."""
    from sma_wrist.commission.bringup import Stop
    from sma_wrist.commission.detect import Fault
    from sma_wrist.commission.device import DeviceLost

    v: dict[str, Any] = {}
    result['verification'] = v
    sim = hasattr(device, 'serve')
    settling = bring is not None and opts.settle and getattr(bring, '_T_start', None) is not None
    t_settle = [0.0]

    def settle_to_start(timeout_s: float) -> dict[str, Any]:
        if not sim:
            bring.dev = device.reopened()  # the bridge had the port: the bring-up's link again, for the settling
            bring.dev.open()
        try:
            start = settle(bring, dataclasses.replace(SettleLimits(), timeout_s=timeout_s))
            t_settle[0] += start['seconds']
            return start
        finally:
            bring.dev.close()

    refine = None
    if refinement is not None:
        from sma_wrist.commission.refine import refine_wire

        refine = partial(refine_wire, refinement, params_file=result['params_file'])
    try:
        ctrls = list(opts.controllers) if opts.controllers else controllers_of(None, [result['params_file']])
        with tempfile.TemporaryDirectory(prefix='sma_wrist_verify_') as tmp:
            serve = (
                (lambda: device.serve(str(Path(tmp) / 'wrist'), opts.sim_time_scale))
                if sim
                else (lambda: _port(device))
            )
            # a served device's clock counts the settling too (lockstep); a real one's is wall time
            verify(
                out,
                serve,
                result['params_file'],
                result['bridge_params'],
                ctrls,
                opts.duration_s,
                opts.diagnose,
                progress,
                (lambda: device.device_time_s) if sim else None,
                into=v,
                bridge=SIM_BRIDGE if sim else None,
                settle_to_start=settle_to_start if settling else None,
                budget_s=BUDGET_S - result['device_time_s'],
                refine=refine,
            )
        if refinement is None and v.get('diagnosis') is not None:
            v['refinement'] = {
                'refined': False,
                'why': "the model's wire is the SD-GPI of hysteresis_file: only a phase-fraction model wire is refitted",
            }
        warning = diagnosis_warning(v.get('diagnosis'), v.get('refinement'))
        if warning:
            result['warnings'].append(warning)
    except KeyboardInterrupt:
        result['status'] = 'interrupted'
        result['message'] = (
            'interrupted during the verification step: TEMs off; the params file and what was measured are kept'
        )
    except Stop as e:  # a bring-up limit broken while settling between runs
        result['status'] = 'fault'
        v['stopped'] = e.fault.message
        result['faults'].append(e.fault.to_json())
    except (VerificationStopped, DeviceLost) as e:
        result['status'] = 'fault'
        v['stopped'] = str(e)
        result['faults'].append(
            Fault(
                'link_lost',
                None,
                f'the device stopped answering during the verification ({e})',
                "check the cable, the port and the device's supply; the params file is written: verify it with "
                '`sma-wrist run --hardware PORT --params-file` or run commissioning again',
            ).to_json()
        )
    finally:
        if sim:
            device.close()  # the lockstep device's drive to 0 V (the bridge zeroed it when it closed)
        v['settle_s'] = round(t_settle[0], 1)
        result['device_time_s'] = round(result['device_time_s'] + v.get('device_time_s', 0.0), 3)
        report = Path(result['report'])
        report.write_text(report.read_text().rstrip('\n') + '\n\n' + '\n'.join(report_section(v, out)) + '\n')


@contextlib.contextmanager
def _port(device: Any) -> Iterator[str]:
    yield device.port


def diagnosis(bag: Path, params_file: str | Path, settle_s: float = SOFT_START_S) -> dict[str, Any]:
    """``sma-wrist diagnose`` of ``bag`` against the model of ``params_file``: the verdict, compact.

    The run's soft start (``settle_s`` [s]) only settles the replay's memory, as in the cycle metrics: the wires
    start the run with the hysteresis memory the excitation and the settling left (the angle at the rest
    temperatures depends on which muscle was heated last), the replay from the rest state's (both cooled from hot
    under the rest load), and the angles differ until the first large cycle has wiped that memory."""
    from sma_wrist.diagnose import DiagnoseInputError, plant_model
    from sma_wrist.diagnose import diagnose as run_diagnosis

    try:
        # the plant node's whole model (files, pre-load, friction): the commissioned wrist, not only its files
        d = run_diagnosis(bag, params_file=str(params_file), settle_s=settle_s)
        m = plant_model(str(params_file))
    except DiagnoseInputError as e:
        return {'bag': str(bag), 'error': str(e), 'discrepancy': None}
    return {
        'bag': str(bag),
        'against': {
            k: getattr(m, k) or 'built-in'
            for k in ('hysteresis_file', 'thermal_file', 'heat_balance_file', 'wire_file')
        },
        'discrepancy': d.discrepancy,
        'unexplained': d.unexplained,
        'subsystem': d.subsystem,
        'cause': d.cause,
        'confidence': round(d.confidence, 3),
        'summary': d.summary,
        # per channel the commissioned model's residual (RMS, and over the sensors' noise): how far off it is
        'residual': {
            c: {k: round(float(per['nominal'][k]), 4) for k in ('rms', 'rms_over_noise')}
            for c, per in d.residual_stats.items()
        },
    }


def diagnosis_warning(d: dict[str, Any] | None, refinement: dict[str, Any] | None = None) -> str:
    """What a discrepancy in the commissioned run's diagnosis (:func:`diagnosis`) means for the wrist's user ('' when
    there is none): the params file's model is what ``sma-wrist diagnose --params-file`` and the twin monitor judge
    the wrist against, so a model that does not describe the loop makes them report this wrist from its first run.
    Where the angle is off and the model wire was refitted with a payload of its own (``refinement``, no
    ``--payload-kg``), it says that giving the payload is the remedy: the recordings fix the wire's stresses only
    relative to the payload (doc/explanation/commissioning.md)."""
    if not d or not d.get('discrepancy'):
        return ''
    from sma_wrist.diagnose import STRUCTURE_RATIO

    structure = {
        c: r for c, r in (d.get('residual') or {}).items() if r.get('rms_over_noise', 0.0) > STRUCTURE_RATIO
    }  # the channels the diagnosis finds structure in
    off = [
        f'{c} {r["rms"]:.3g} {"degC" if c == "thermal" else "rad"} RMS, {r["rms_over_noise"]:.3g}x the noise'
        for c, r in structure.items()
    ]
    what = 'does not describe' if d.get('unexplained') else f'departs from ({d.get("summary")})'
    rf = refinement or {}
    payload = ''
    if 'mechanics' in structure and rf.get('refined') and not rf.get('payload_given') and rf.get('payload_kg'):
        payload = (
            f'; the model wire was refitted with a payload of its own, {rf["payload_kg"]:.3g} kg, and the recordings '
            "fix the wire's stresses only relative to it: if you know the wrist's payload, commission again with "
            '--payload-kg'
        )
    return (
        f'verification: the commissioned model {what} this wrist in closed loop'
        + (f' ({"; ".join(off)})' if off else '')
        + ': `sma-wrist diagnose --params-file` and the twin monitor judge the wrist against this model and will '
        'report this from its first run; read their verdicts on this wrist as departures from the commissioned '
        'model (doc/howto/commission.md#limits)' + payload
    )


def _r(x: Any) -> float | None:
    return None if x is None else round(float(x), 2)


def report_section(v: dict[str, Any], out: Path) -> list[str]:
    """The report's verification section (Markdown lines): the metrics side by side with their spread, the start
    of each run, the plots, the verdicts."""
    lines = [
        '## Verification: the Sec. 6.1 sine in closed loop, defaults against commissioned',
        '',
        f'{v["duration_s"]:g} s of device time per run: the {SOFT_START_S:g} s soft start, then full cycles of the '
        "sine. Max and RMS error in % of the reference's range, the mean of the cycles (the soft start apart), "
        '+- half their range: a difference within the larger range is within what one cycle differs from the next. '
        "Defaults: config/wrist.yaml with only the bring-up's calibration "
        f'(`{Path(v["defaults_file"]).name}`); commissioned: `{Path(v["params_file"]).name}` (run first of each '
        'pair). Before each run the muscles were brought back to the temperatures they had at rest and held there '
        f'until the angle was still ({v.get("settle_s", 0):.0f} s of device time in all). Device time of the '
        'verification: '
        f'{v.get("device_time_s", 0):.0f} s.',
        '',
        '| controller | defaults max % | defaults RMS % | commissioned max % | commissioned RMS % | verdict |',
        '|---|---|---|---|---|---|',
    ]
    for ctrl in dict.fromkeys([*v['default'], *v['commissioned']]):
        d, c = v['default'].get(ctrl, {}), v['commissioned'].get(ctrl, {})
        verdict = VERDICTS.get(v.get('comparison', {}).get(ctrl, {}).get('verdict', ''), '-')
        lines.append(f'| {ctrl} | {_pm(d, "max")} | {_pm(d, "rms")} | {_pm(c, "max")} | {_pm(c, "rms")} | {verdict} |')
    lines += [
        '',
        '| run | start: muscles, TEM faces [degC], angle [rad] (settled, seconds) | soft start max / RMS % | '
        'cycles max / RMS % |',
        '|---|---|---|---|',
    ]
    for r in v.get('runs', []):
        st = r.get('start')
        start = (
            '-'
            if not st
            else f'{st["muscle_C"][0]:.1f}, {st["muscle_C"][1]:.1f}; {st["face_C"][0]:.1f}, {st["face_C"][1]:.1f}; '
            f'{st["angle_rad"]:.3f} ({"yes" if st["settled"] else "no"}, {st["seconds"]:.0f} s)'
        )
        su = r.get('start_up') or {}
        cyc = '; '.join(f'{_f(c["max_pct"])} / {_f(c["rms_pct"])}' for c in r.get('cycles', [])) or '-'
        lines.append(
            f'| {r["controller"]}, {r["parameters"]} | {start} | {_f(su.get("max_pct"))} / '
            f'{_f(su.get("rms_pct"))} | {cyc} |'
        )
    lines.append('')
    for p in v.get('plots', []):
        rel = Path(p).relative_to(out) if Path(p).is_relative_to(out) else Path(p)
        lines += [f'![{Path(p).stem}]({rel.as_posix()})', '']
    rf = v.get('refinement')
    if rf:
        lines += [refinement_line(rf), '']
    d = v.get('diagnosis')
    if d:
        verdict = (
            d['error']
            if d.get('error')
            else 'no discrepancy'
            if not d['discrepancy']
            else f'discrepancy: {d["summary"]}'
        )
        against = ', '.join(
            f'{k.removesuffix("_file").replace("_", " ")}: `{f}`' for k, f in d.get('against', {}).items()
        )
        residual = '; '.join(
            f'{c} {r["rms"]:.4g} {"degC" if c == "thermal" else "rad"} RMS ({r["rms_over_noise"]:.3g} x noise)'
            for c, r in d.get('residual', {}).items()
        )
        lines += [
            f'Diagnosis of the commissioned run after its soft start against the commissioned model ({against}): {verdict}.'
            + (f' Residual of the commissioned model: {residual}.' if residual else ''),
            '',
        ]
        warning = diagnosis_warning(d, v.get('refinement'))
        if warning:
            lines += [f'**{warning}**', '']
    if v.get('stopped'):
        lines += [f'Stopped: {v["stopped"]}', '']
    return lines


def refinement_line(rf: dict[str, Any]) -> str:
    """What the refinement of the model wire did (:func:`sma_wrist.commission.refine.refine_wire`), one line: the
    held-out errors on the commissioned run of the first fit and of each refit, and what was handed over."""
    h = rf.get('heldout') or {}
    if not h:
        return f'Refinement of the model wire: not refitted ({rf.get("why", "")}).'
    from sma_wrist.commission.refine import candidate_label

    errors = ', '.join(
        f'{"first fit" if k == "first" else f"refit ({candidate_label(k)})"} {x:.3g}'
        for k, x in h.items()
        if k not in ('metric', 'unit')
    )
    what = f'the refit ({candidate_label(rf["refit"])}) handed over' if rf.get('refined') else 'the first fit kept'
    if rf.get('refined') and rf.get('temp_lag_s'):
        what += f", with the thermocouples' lag it found, {rf['temp_lag_s']:.3g} s (plant_sim model.temp_lag_s)"
    w = rf.get('wire') or {}
    if rf.get('refined') and 'E_A_GPa' in w:
        what += f" and the wire's moduli {w['E_A_GPa']:.3g} / {w['E_M_GPa']:.3g} GPa (austenite / martensite)"
    line = (
        'Refinement of the model wire on the excitation and the defaults run: RMS angle error of the commissioned '
        f'run (held out): {errors} mrad; {what} ({rf.get("why", "")}; {rf.get("seconds", 0):g} s of CPU).'
    )
    th = rf.get('thermal') or {}
    if th.get('heldout'):
        h = th['heldout']
        line += (
            " The heat balance refitted with the wires' latent heat (latent_C "
            f'{", ".join(f"{x:.3g}" for x in th["latent_C"])} degC, at the lag {th["temp_lag_s"]:.3g} s): RMS '
            f'thermocouple error of the commissioned run per TEM {", ".join(f"{x:.3g}" for x in h["latent"])} degC '
            f"against the first form's {', '.join(f'{x:.3g}' for x in h['first'])}; "
            + ('handed over.' if th.get('refined') else 'the first form kept.')
        )
    elif th:
        line += f" The heat balance was not refitted with the wires' latent heat ({th.get('why', '')})."
    return line


#: the verdicts as the report and the terminal say them
VERDICTS = {
    'better': 'commissioned better (beyond the spread)',
    'worse': 'commissioned WORSE (beyond the spread)',
    'within_spread': 'the same within the spread',
    'spread_unknown': 'no spread (one cycle per run): no verdict',
    'identical_parameters': 'the same parameters: run once',
}


def text_lines(v: dict[str, Any]) -> list[str]:
    """The verification for the terminal: per controller defaults -> commissioned, and the verdict."""
    out = []
    for ctrl in dict.fromkeys([*v.get('default', {}), *v.get('commissioned', {})]):
        d, c = v['default'].get(ctrl, {}), v['commissioned'].get(ctrl, {})
        verdict = VERDICTS.get(v.get('comparison', {}).get(ctrl, {}).get('verdict', ''), '')
        out.append(
            f'verification {ctrl}: max {_pm(d, "max")} -> {_pm(c, "max")} %, RMS {_pm(d, "rms")} -> '
            f'{_pm(c, "rms")} % (defaults -> commissioned): {verdict}'
        )
    if v.get('refinement'):
        out.append(refinement_line(v['refinement']))
    d = v.get('diagnosis')
    if d:
        out.append(
            'diagnosis of the commissioned run: '
            + (d['error'] if d.get('error') else 'no discrepancy' if not d['discrepancy'] else d['summary'])
        )
    return out


def _pm(side_: dict[str, Any], metric: str) -> str:
    """'mean +- half the range' of one side's metric ('mean' alone from one cycle)."""
    m, s = side_.get(f'{metric}_pct'), side_.get(f'{metric}_spread_pct')
    return _f(m) if s is None or m is None else f'{m:.2f} +- {s / 2:.2f}'


def _f(x: float | None) -> str:
    return '-' if x is None else f'{x:.2f}'


__all__ = [
    'verify',
    'settle',
    'cycle_metrics',
    'side',
    'compare',
    'graph_values',
    'differences',
    'SettleLimits',
    'diagnosis',
    'controllers_of',
    'write_defaults',
    'report_section',
    'VerificationStopped',
    'VerifyOptions',
    'run_verification',
    'text_lines',
    'refinement_line',
    'CONTROLLERS',
    'DURATION_S',
]
