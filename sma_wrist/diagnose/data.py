"""Load a bag recorded per msg_defs/topics.yaml into aligned arrays, with input checks.

The diagnosis needs, on one uniform time grid:

* ``u``  (K, 2) TEM drive commands [V] (``/wrist/tem_{1,2}/command``, std_msgs/Float64),
  zero-order held: the command stamped at t_k drives the plant over [t_k, t_k+1)
  (plant_sim's convention: it publishes the state at t_k, the controller answers at t_k,
  the plant integrates it until t_k+1). Where the bag has the drive the device read back
  (``/wrist/tem_drive_applied``, hardware_bridge), that is ``u`` instead, held the same way: on hardware a
  command takes effect after the graph's delay, which its stamp (the window it answers) does not say;
* ``T``  (K, 2) muscle temperatures [degC] (``/wrist/muscle_{1,2}/temperature``);
* ``q``  (K,) wrist angle [rad] (``/wrist/joint_states`` position of joint ``wrist``);
* ``payload_kg`` (``/wrist/payload``, latched std_msgs/Float64);
* ``thermal_x0`` the heat-balance state at t = 0 where the bag has the TEMs' exchanger-face temperatures
  (``/wrist/tem_{1,2}/face_temperature``): a run that starts with warm faces (after an excitation) is replayed from
  where it was, not from rest.

Measurements (and the read-back drive) are stamped with their header stamp when it is set (acquisition time),
else with the bag's log time; commands with the log time. Problems are either fixed and
reported in ``Run.warnings`` (NaNs dropped, unsorted or duplicate stamps sorted/removed,
Kelvin temperatures or degree angles converted, gaps: the longest gap-free stretch is
analysed) or raised as :class:`DiagnoseInputError` naming the problem and what is needed.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from sma_wrist.bag import BagError, read_bag
from sma_wrist.contract import IMPOSSIBLE, ContractError, Recording, joint_positions
from sma_wrist.core.errors import SmaWristError

TOPICS = {
    'u1': '/wrist/tem_1/command',
    'u2': '/wrist/tem_2/command',
    'T1': '/wrist/muscle_1/temperature',
    'T2': '/wrist/muscle_2/temperature',
    'joint': '/wrist/joint_states',
    'payload': '/wrist/payload',
}
#: the drive the TEMs got as the device read it back (sensor_msgs/JointState, effort [V] of tem_1 / tem_2, stamped
#: in device time from where it held): preferred to the commands where a bag has it
DRIVE_TOPIC = '/wrist/tem_drive_applied'
DRIVE_NAMES = ('tem_1', 'tem_2')
#: the TEMs' exchanger-face temperatures (sensor_msgs/Temperature, degC; the T2 faces of Eq. 4.14), muscle order
FACE_TOPICS = ('/wrist/tem_1/face_temperature', '/wrist/tem_2/face_temperature')
#: a face sample this far [s] from the analysed stretch's start is no start state
FACE_START_TOLERANCE_S = 1.0
#: an exchanger-face or muscle temperature outside this range [degC] is no start state (another unit, a fault)
START_RANGE_C = (-40.0, 150.0)
MIN_DURATION_S = 30.0
DEFAULT_PAYLOAD_KG = 0.3
MAX_COMMAND_V = 30.0
#: an applied drive this far [V] from the command held at the same grid sample differs from it: well above the
#: protocol's 1 mV steps, well below any drive that heats
DRIVE_DIFF_V = 0.01
#: gaps up to this long [s] are bridged (and masked); longer ones cut the run
MAX_BRIDGE_S = 5.0
#: a temperature repeated exactly for longer than this [s] while its TEM is driven harder than STALE_DRIVE_V [V]
#: (mean |u|) is a stale sensor (a converter chip repeats its reading for ~0.1 s)
STALE_S = 5.0
STALE_DRIVE_V = 2.0


class DiagnoseInputError(SmaWristError):
    """The bag cannot be diagnosed; the message says what is wrong and what is needed."""


@dataclass
class Run:
    """One run on a uniform grid. Any of u, T, q may be None when its topics are missing."""

    t: np.ndarray  # (K,) s from the start of the analysed stretch
    dt: float
    u: np.ndarray | None
    T: np.ndarray | None
    q: np.ndarray | None
    payload_kg: float
    t0_s: float = 0.0  # bag time of t = 0
    #: (K,) False where a short gap was bridged (interpolated / held): left out of the residuals
    valid: np.ndarray | None = None
    warnings: list[str] = field(default_factory=list)
    source: str = ''
    #: heat-balance state at t = 0 [degC] (2 layers, 2 faces: muscle, exchanger), when known from a replay that
    #: ran before the stretch (a live monitor's twin); None: the exchanger faces start at rest, right for a run
    #: that starts from rest, not for a window cut from the middle of one
    thermal_x0: np.ndarray | None = None
    #: where the replay's exchanger faces start: 'rest', 'measured' (the bag's face temperatures, FACE_TOPICS) or
    #: 'twin' (a live monitor's replay before the window)
    thermal_start: str = 'rest'
    #: the first settle_s [s] only settle the replays' memory (the wires' hysteresis, the joint): neither fitted nor
    #: scored; the train / held-out split is over the rest. 0: the usual 5 s burn-in
    settle_s: float = 0.0
    #: where ``u`` comes from: 'applied' (the device's read-back, DRIVE_TOPIC) or 'commanded' (the commands)
    drive: str = 'commanded'
    #: with the applied drive: the grid samples where it differed from the command held there (by over DRIVE_DIFF_V
    #: on either TEM: the graph's delay, the device's watchdog, a safety cut or clip); None: not compared
    drive_differs: int | None = None

    @property
    def n(self) -> int:
        return int(self.t.size)

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0]) if self.n else 0.0


def _stamp_ns(msg: Any) -> int:
    h = getattr(msg, 'header', None)
    if h is None:
        return 0
    return int(h.stamp.sec) * 10**9 + int(h.stamp.nanosec)


def _series(
    name: str, t_log: np.ndarray, msgs: list[Any], kind: str, warnings: list[str], joint_name: str | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """(t [s], values) of one topic, cleaned: NaNs dropped, sorted, de-duplicated."""
    if kind == 'temperature':
        vals = np.array([float(m.temperature) for m in msgs])
    elif kind == 'joint':
        vals = np.array(joint_positions(msgs, joint_name))
    elif kind in DRIVE_NAMES:  # one TEM's read-back drive out of DRIVE_TOPIC's JointState
        vals = np.array([_effort(m, kind) for m in msgs])
    else:
        vals = np.array([float(m.data) for m in msgs])
    stamped = kind in ('temperature', 'joint', *DRIVE_NAMES)
    stamps = np.array([_stamp_ns(m) for m in msgs], dtype=np.int64) if stamped else None
    t = (stamps if stamps is not None and np.all(stamps > 0) else np.asarray(t_log, np.int64)).astype(float) * 1e-9
    bad = ~np.isfinite(vals)
    if bad.any():
        warnings.append(
            f'{name}: {int(bad.sum())} of {vals.size} samples are NaN/inf and were dropped '
            f'(need finite values; the gaps they leave are handled like missing samples)'
        )
        t, vals = t[~bad], vals[~bad]
    # a glitch no sensor of this wrist can give, in any unit the checks below recognise (K, degF, degrees): one
    # 1e300 overflowed the fit ('internal error'), one 1e6 rad refused the whole bag as 'not radians'
    wild = np.abs(vals) > IMPOSSIBLE.get(kind, IMPOSSIBLE['float'])  # sma_wrist.contract.IMPOSSIBLE
    if wild.any():
        warnings.append(
            f'{name}: {int(wild.sum())} of {vals.size} samples beyond +-{IMPOSSIBLE[kind]:g} (up to '
            f'{np.abs(vals[wild]).max():.3g}) are no measurement of this wrist and were dropped'
        )
        t, vals = t[~wild], vals[~wild]
    if t.size > 1 and np.any(np.diff(t) < 0):
        warnings.append(
            f'{name}: stamps are not sorted ({int((np.diff(t) < 0).sum())} steps back in time); '
            f'samples were sorted by stamp (need monotonic header stamps)'
        )
        o = np.argsort(t, kind='stable')
        t, vals = t[o], vals[o]
    if t.size > 1 and np.any(np.diff(t) == 0):
        dup = np.r_[np.diff(t) == 0, False]
        warnings.append(f'{name}: {int(dup.sum())} duplicate stamps; the last sample of each stamp was kept')
        t, vals = t[~dup], vals[~dup]
    return t, vals


def _effort(msg: Any, name: str) -> float:
    """The effort of joint ``name`` in a JointState (NaN where it has none: dropped as a missing sample)."""
    names = list(msg.name)
    i = names.index(name) if name in names else DRIVE_NAMES.index(name)
    return float(msg.effort[i]) if len(msg.effort) > i else float('nan')


def _without_frozen(
    key: str, temp: tuple[np.ndarray, np.ndarray], drive: tuple[np.ndarray, np.ndarray], warnings: list[str]
) -> tuple[np.ndarray, np.ndarray]:
    """The temperature series without the samples of a sensor that stopped: one value repeated exactly for more
    than STALE_S while its TEM was driven (mean |u| over STALE_DRIVE_V). Such a stretch is no measurement; it
    was fitted as one (a frozen thermocouple moved identify's hold limits, and diagnose called it an
    unexplained discrepancy). Left as a gap, the usual gap rules apply. A quiet, quantised sensor at rest
    repeats its value too, so an idle TEM is no sign."""
    t, v = temp
    if t.size < 3:
        return temp
    change = np.r_[True, v[1:] != v[:-1]]
    starts = np.flatnonzero(change)
    ends = np.r_[starts[1:], t.size] - 1
    keep = np.ones(t.size, bool)
    tu, vu = drive
    for a, b in zip(starts, ends):
        if t[b] - t[a] <= STALE_S:
            continue
        inside = (tu >= t[a]) & (tu <= t[b])
        if not inside.any() or float(np.mean(np.abs(vu[inside]))) <= STALE_DRIVE_V:
            continue
        keep[a + 1 : b + 1] = False
        warnings.append(
            f'{TOPICS[key]}: the same value {v[a]:.4g} for {t[b] - t[a]:.1f} s while its TEM was driven '
            f'(mean |u| {np.mean(np.abs(vu[inside])):.1f} V): a stale sensor? Those samples are left out'
        )
    return (t[keep], v[keep]) if not keep.all() else temp


def _longest_gap_free(t: np.ndarray, dt: float) -> tuple[float, float, int, list[tuple[float, float]]]:
    """(start, end, number of long gaps, short gaps) of the longest stretch without a gap
    longer than MAX_BRIDGE_S; gaps over 5 samples but at most MAX_BRIDGE_S are returned as
    (from, to) intervals to bridge."""
    d = np.diff(t)
    long_gaps = np.flatnonzero(d > max(MAX_BRIDGE_S, 5.0 * dt))
    edges = np.r_[0, long_gaps + 1, t.size]
    lengths = [t[e - 1] - t[s] for s, e in zip(edges[:-1], edges[1:])]
    i = int(np.argmax(lengths))
    a, b = edges[i], edges[i + 1]
    short = [(float(t[k]), float(t[k + 1])) for k in np.flatnonzero(d[a : b - 1] > 5.0 * dt) + a]
    return float(t[a]), float(t[b - 1]), int(long_gaps.size), short


def load_run(path: str | Path, max_rate_hz: float = 100.0, recording: Recording | None = None) -> Run:
    """Read and align a bag; raises DiagnoseInputError when nothing usable remains. ``recording``: how a bag of
    another rig names the contract's topics and the joint."""
    rec = recording or Recording()
    warnings: list[str] = []
    p = Path(path)
    if not p.exists():
        raise DiagnoseInputError(
            f'{p}: no such bag (need a rosbag2 directory with metadata.yaml and .mcap, or an .mcap file)'
        )
    try:
        data = read_bag(p, rec.recorded([*TOPICS.values(), DRIVE_TOPIC, *FACE_TOPICS]))
    except BagError as exc:
        if not exc.salvaged:
            raise DiagnoseInputError(f'{p}: cannot read the bag: {exc.problem}') from None
        warnings.append(
            f'bag damaged ({exc.problem}); analysing the {sum(len(v[1]) for v in exc.salvaged.values())} '
            f'messages that could be salvaged'
        )
        data = exc.salvaged
    except Exception as exc:  # noqa: BLE001 - anything rosbags raises
        raise DiagnoseInputError(f'{p}: cannot read the bag: {type(exc).__name__}: {exc}') from None
    data = rec.as_contract(data)

    series: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    drive = 'commanded'
    applied = drive_series(data, warnings)
    if applied is not None and all(s[0].size for s in applied.values()):
        series.update(applied)  # the commands' stamps are the windows they answer, not when the drive took effect
        drive = 'applied'
    kinds = {
        'u1': 'float',
        'u2': 'float',
        'T1': 'temperature',
        'T2': 'temperature',
        'joint': 'joint',
        'payload': 'float',
    }
    for key, topic in TOPICS.items():
        if key in series:
            continue
        if topic in data and len(data[topic][1]):
            try:
                s = _series(topic, data[topic][0], data[topic][1], kinds[key], warnings, rec.joint)
            except ContractError as exc:
                raise DiagnoseInputError(f'{topic}: {exc}') from None
            except (AttributeError, TypeError, ValueError) as exc:
                raise DiagnoseInputError(
                    f'{topic}: unexpected message content ({exc}); the contract type is required (msg_defs/topics.yaml)'
                ) from None
            if s[0].size:
                series[key] = s
    run = run_from_series(series, str(p), warnings, max_rate_hz)
    run.drive = drive
    if drive == 'applied':
        run.drive_differs = commands_differ(run, data, rec.joint)
    faces = face_series(data, warnings)
    if faces is not None and run.T is not None:
        why = start_at_faces(run, faces)
        if why:
            warnings.append(f'{why}; the exchanger faces start at rest')
    return run


def drive_series(data: dict[str, Any], warnings: list[str]) -> dict[str, tuple[np.ndarray, np.ndarray]] | None:
    """{'u1', 'u2': (t [s], volts)} of the drive the device read back (DRIVE_TOPIC in a bag's ``data``, cleaned as
    every topic, stamped where each value began to hold), or None when the bag has none; DiagnoseInputError for
    messages that are no JointState with the TEMs' efforts."""
    if DRIVE_TOPIC not in data or not len(data[DRIVE_TOPIC][1]):
        return None
    try:
        return {
            k: _series(DRIVE_TOPIC, *data[DRIVE_TOPIC], name, warnings) for k, name in zip(('u1', 'u2'), DRIVE_NAMES)
        }
    except (AttributeError, TypeError, ValueError) as exc:
        raise DiagnoseInputError(
            f'{DRIVE_TOPIC}: unexpected message content ({exc}); the contract type is required (msg_defs/topics.yaml)'
        ) from None


def zero_order_hold(t: np.ndarray, v: np.ndarray, grid: np.ndarray, before: float | None = None) -> np.ndarray:
    """``v`` (stamped ``t`` [s], sorted) held from each stamp to the next, at ``grid`` [s]: a command drives from its
    stamp on. Before the first stamp: ``before``, or the first value when None."""
    i = np.searchsorted(t, grid + 1e-7, side='right') - 1
    out = v[np.clip(i, 0, v.size - 1)]
    return out if before is None else np.where(i >= 0, out, before)


def commands_differ(run: Run, data: dict[str, Any], joint_name: str | None = None) -> int | None:
    """How many of ``run``'s grid samples had an applied drive (``run.u``, the read-back) other than the TEM
    commands in a bag's ``data`` held there (by over DRIVE_DIFF_V on either TEM); None when the bag has no usable
    commands to compare with. What cleaning the commands finds is not warned about: the replay did not run on them."""
    if run.u is None:
        return None
    held = []
    for key in ('u1', 'u2'):
        topic = TOPICS[key]
        if topic not in data or not len(data[topic][1]):
            return None
        try:
            t, v = _series(topic, data[topic][0], data[topic][1], 'float', [], joint_name)
        except (AttributeError, TypeError, ValueError):
            return None
        if not t.size:
            return None
        # before the first command the device drove nothing: zero, as plant_sim and the device start
        held.append(zero_order_hold(t, v, run.t0_s + run.t, before=0.0))
    return int(np.count_nonzero(np.any(np.abs(run.u - np.stack(held, axis=1)) > DRIVE_DIFF_V, axis=1)))


def face_series(data: dict[str, Any], warnings: list[str]) -> list[tuple[np.ndarray, np.ndarray]] | None:
    """The exchanger faces' (t [s], degC) per TEM from FACE_TOPICS in a bag's ``data``, or None (with a warning when
    the topics are there but unusable)."""
    if not all(tp in data and len(data[tp][1]) for tp in FACE_TOPICS):
        return None
    out = []
    for tp in FACE_TOPICS:
        try:
            out.append(_series(tp, data[tp][0], data[tp][1], 'temperature', warnings))
        except (AttributeError, TypeError, ValueError) as exc:
            warnings.append(f'{tp}: unexpected message content ({exc}); the exchanger faces start at rest')
            return None
    return out


def start_at_faces(run: Run, faces: Sequence[tuple[np.ndarray, np.ndarray]]) -> str:
    """Start ``run``'s heat-balance replay where the exchanger faces were measured (``faces``: (t [s], degC) per TEM,
    interpolated to the run's start ``t0_s``) and the muscles at their first samples: ``thermal_x0`` (2 muscles,
    [muscle face (Eq. 4.13), exchanger face (Eq. 4.14)]) [degC], ``thermal_start`` 'measured'. Returns '' when it
    did, else why not (nothing changed)."""
    if run.T is None:
        return 'no muscle temperatures'
    out = []
    for tp, (t, v) in zip(FACE_TOPICS, faces):
        if not (np.abs(t - run.t0_s) <= FACE_START_TOLERANCE_S).any():
            return f'{tp}: no sample within {FACE_START_TOLERANCE_S:g} s of the analysed start'
        f = float(np.interp(run.t0_s, t, v))
        if not (START_RANGE_C[0] < f < START_RANGE_C[1]):
            return f'{tp}: {f:g} is no exchanger-face temperature in degC'
        out.append(f)
    run.thermal_x0 = np.stack([run.T[0], np.array(out)], axis=1)
    run.thermal_start = 'measured'
    return ''


def run_from_series(
    series: dict[str, tuple[np.ndarray, np.ndarray]], source: str, warnings: list[str], max_rate_hz: float = 100.0
) -> Run:
    """Align cleaned series {key of TOPICS: (t [s], values)} into a Run, with the unit, stale-sensor and gap
    checks of :func:`load_run`; the same path for a bag and for the samples a live monitor buffered."""
    p = source
    have_u = 'u1' in series and 'u2' in series
    have_T = 'T1' in series and 'T2' in series
    have_q = 'joint' in series
    missing = [TOPICS[k] for k in ('u1', 'u2', 'T1', 'T2', 'joint') if k not in series]
    if missing:
        what = []
        if not have_u:
            what.append(
                'without TEM commands the thermal replay (commands -> temperatures) and the whole chain are skipped'
            )
        if not have_T:
            what.append('without muscle temperatures the thermal and hysteresis replays are skipped')
        if not have_q:
            what.append('without the joint angle only the thermal subsystem can be checked')
        warnings.append(f'missing topic(s) {", ".join(missing)}: ' + '; '.join(what))
    usable = (have_T and (have_u or have_q)) or (have_u and have_q)
    if not usable:
        raise DiagnoseInputError(
            f'{p}: nothing to compare: found {sorted(TOPICS[k] for k in series) or "no contract topics"}; need the '
            f'TEM commands {TOPICS["u1"]}, {TOPICS["u2"]} (std_msgs/Float64, V) with the muscle temperatures '
            f'{TOPICS["T1"]}, {TOPICS["T2"]} (sensor_msgs/Temperature, degC), and/or {TOPICS["joint"]} '
            f'(sensor_msgs/JointState, rad); a bag that names them otherwise: --topic CONTRACT=RECORDED'
        )

    # units
    if have_T:
        for k in ('T1', 'T2'):
            t, v = series[k]
            med = float(np.median(v))
            if med > 150.0 and 200.0 < med < 450.0:
                warnings.append(
                    f'{TOPICS[k]}: median {med:.1f} looks like Kelvin; converted to degC (-273.15). '
                    f'The contract (sensor_msgs/Temperature) is degC'
                )
                series[k] = (t, v - 273.15)
            elif not (-40.0 < med < 150.0):
                raise DiagnoseInputError(
                    f'{TOPICS[k]}: median temperature {med:g} is not a muscle temperature in '
                    f'degC (expected about 15-90 degC)'
                )
    if have_q:
        t, v = series['joint']
        if np.nanmax(np.abs(v)) > 2 * np.pi:
            if np.nanmax(np.abs(v)) < 400:
                warnings.append(
                    f'{TOPICS["joint"]}: angles up to {np.nanmax(np.abs(v)):.0f} look like degrees; '
                    f'converted to rad (the contract is rad, REP-103)'
                )
                series['joint'] = (t, np.deg2rad(v))
            else:
                raise DiagnoseInputError(f'{TOPICS["joint"]}: angles up to {np.nanmax(np.abs(v)):g} are not radians')
    if have_u:
        for k in ('u1', 'u2'):
            mx = float(np.max(np.abs(series[k][1])))
            if mx > MAX_COMMAND_V:
                raise DiagnoseInputError(
                    f'{TOPICS[k]}: commands up to {mx:g} are not volts (the TEM drive is '
                    f'within +-{MAX_COMMAND_V:g} V; mV or a duty cycle in % ?)'
                )

    if have_T and have_u:
        for k, ku in (('T1', 'u1'), ('T2', 'u2')):
            series[k] = _without_frozen(k, series[k], series[ku], warnings)

    # grid: the measurement stamps of the reference topic
    ref_key = 'joint' if have_q else 'T1'
    t_ref = series[ref_key][0]
    if t_ref.size < 3:
        raise DiagnoseInputError(
            f'{TOPICS[ref_key]}: only {t_ref.size} samples; need at least {MIN_DURATION_S:g} s of data'
        )
    dt_med = float(np.median(np.diff(t_ref)))
    bridged: list[tuple[float, float]] = []
    lo = max(series[k][0][0] for k in series if k != 'payload')
    hi = min(series[k][0][-1] for k in series if k != 'payload')
    for k in series:
        if k == 'payload':
            continue
        tk = series[k][0]
        sel = tk[(tk >= lo) & (tk <= hi)]
        if sel.size < 2:
            continue
        d = float(np.median(np.diff(tk))) if tk.size > 1 else dt_med
        a, b, n_gaps, short = _longest_gap_free(sel, max(d, dt_med))
        if n_gaps:
            warnings.append(
                f'{TOPICS[k]}: {n_gaps} gap(s) longer than {MAX_BRIDGE_S:g} s; only the longest '
                f'stretch {a - t_ref[0]:.1f}-{b - t_ref[0]:.1f} s is analysed (the replay needs '
                f'continuous inputs)'
            )
        if short:
            warnings.append(
                f'{TOPICS[k]}: {len(short)} gap(s) of up to {max(y - x for x, y in short):.2f} s were '
                f'bridged (interpolated, commands held) and are left out of the residuals'
            )
            bridged.extend(short)
        lo, hi = max(lo, a), min(hi, b)
    if hi - lo < MIN_DURATION_S:
        raise DiagnoseInputError(
            f'{p}: only {max(hi - lo, 0):.1f} s of overlapping, gap-free data; need at least {MIN_DURATION_S:g} s '
            f'(better several minutes with the muscles cycling through their transitions)'
            + ''.join(f'. {w}' for w in warnings if 'stale sensor' in w)
        )
    step = max(1, int(round((1.0 / max_rate_hz) / dt_med)))
    dt = dt_med * step
    grid = np.arange(lo, hi + 1e-9, dt)

    def interp(key: str) -> np.ndarray:
        t, v = series[key]
        return np.interp(grid, t, v)

    def hold(key: str) -> np.ndarray:
        return zero_order_hold(*series[key], grid)

    u = np.stack([hold('u1'), hold('u2')], axis=1) if have_u else None
    T = np.stack([interp('T1'), interp('T2')], axis=1) if have_T else None
    q = interp('joint') if have_q else None
    if 'payload' in series:
        pv = series['payload'][1]
        payload = float(pv[0])
        if np.ptp(pv) > 1e-9:
            warnings.append(
                f'/wrist/payload changed during the run ({pv.min():g}-{pv.max():g} kg); the first value '
                f'{payload:g} kg is used'
            )
        if not (0.0 <= payload <= 2.0):
            raise DiagnoseInputError(f'/wrist/payload = {payload:g} is not a payload in kg (0-2 kg)')
    else:
        payload = DEFAULT_PAYLOAD_KG
        warnings.append(
            f'/wrist/payload missing: assuming the plant default {DEFAULT_PAYLOAD_KG} kg (record the latched '
            f'/wrist/payload, std_msgs/Float64 kg); a payload mismatch may then be reported'
        )
    valid = np.ones(grid.size, bool)
    for x, y in bridged:
        valid[(grid > x) & (grid < y)] = False
    return Run(
        t=grid - grid[0],
        dt=dt,
        u=u,
        T=T,
        q=q,
        payload_kg=payload,
        t0_s=float(grid[0]),
        warnings=warnings,
        source=source,
        valid=valid,
    )
