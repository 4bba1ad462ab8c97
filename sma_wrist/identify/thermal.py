"""``sma-wrist identify thermal INPUT...``: Table 4.9 from measured drive voltage and temperatures.

Inputs (seed Sec. 4.3.1: one TEM driven by 12 V sines at 1/128-1 Hz, both faces logged):

* a **text table** (CSV, TSV, semicolon or whitespace separated; ``#`` comments; header
  optional) with a time column, the drive voltage and the T1 (muscle) face temperature,
  optionally the T2 (exchanger) face and a frequency column (one file holding several runs
  is split by it). Columns are found by header name (``time``/``t``, ``u``/``voltage``,
  ``T1``/``muscle``, ``T2``/``exchanger``, ``frequency``) or given with ``--columns``; units
  in brackets (``time [ms]``, ``T1 [K]``, ``u [mV]``) or ``--*-unit`` options, else detected
  with a warning (Kelvin temperatures). A ``tem`` column (1 or 2) says which of the wrist's TEMs a row
  measured (runs of both: see below);
* a **rosbag2** recorded per msg_defs/topics.yaml (plant_sim or hardware_bridge): each
  muscle is one run, ``/wrist/tem_i/command`` [V] with ``/wrist/muscle_i/temperature``
  [degC]; where the bag has the drive the device read back (``/wrist/tem_drive_applied``, hardware_bridge) that is
  the drive instead (a command takes effect after the graph's delay, which its stamp does not say; the choice of
  :func:`sma_wrist.diagnose.data.load_run`). Only the muscle face is fitted (the T1 column).

Cleaning (counted in the report): rows with NaN/unparseable cells dropped, unsorted stamps
sorted, duplicate stamps removed (last kept), gaps longer than 2 s cut (longest stretch
kept); then every run is put on one grid (``--dt``, default 0.1 s): temperatures linearly
interpolated, the drive as its mean and mean square over each interval
(:func:`~sma_wrist.core.thermal.identification.interval_means`; ``--input-hold linear`` for a
logged continuous drive, the tables' default, ``zoh`` for held commands, the bags' default).

Runs of both TEMs (a bag's two muscles, a table's tem column): each TEM's drive gain is fitted as well and
written to thermal.yaml only where it predicts the held-out data better than one shared gain (:func:`tem_gains`).

The fit and its validation are :mod:`sma_wrist.core.thermal.identification`; this module
reads, reports (markdown + PNG), and writes the params file (:mod:`sma_wrist.core.thermal.params_file`).
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import re
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sma_wrist.core.errors import SmaWristError

ROLES = ('time', 'u', 'T1', 'T2', 'frequency', 'tem')
_NAMES = {
    'time': ('t', 'time', 'times', 'timestamp', 'sec', 'secs', 'seconds', 'time_s', 'elapsed', 't_s'),
    'u': ('u', 'v', 'voltage', 'volt', 'volts', 'command', 'drive', 'input', 'u_v', 'tem_voltage', 'tem_command'),
    'T1': (
        't1',
        'temp1',
        'temperature1',
        'temperature_1',
        'temp_1',
        'muscle',
        'muscle_1',
        'nitinol1',
        'nitinol_1',
        'face1',
        'face_1',
        't_1',
        'muscle_temperature',
        'tem_face_1',
    ),
    'T2': (
        't2',
        'temp2',
        'temperature2',
        'temperature_2',
        'temp_2',
        'exchanger',
        'nitinol2',
        'nitinol_2',
        'face2',
        'face_2',
        't_2',
        'exchanger_temperature',
        'tem_face_2',
    ),
    'frequency': ('f', 'freq', 'frequency', 'f_hz', 'frequency_hz'),
    'tem': ('tem', 'tem_number', 'tem_id'),
}
TIME_UNITS = {'s': 1.0, 'sec': 1.0, 'ms': 1e-3, 'us': 1e-6, 'ns': 1e-9, 'min': 60.0}
VOLT_UNITS = {'v': 1.0, 'mv': 1e-3}
TEMP_UNITS = ('degc', 'c', 'k', 'degf', 'f')
MAX_GAP_S = 2.0
MIN_DURATION_S = 30.0
SINE_POWER_SHARE = 0.95  # of a drive's AC power in its peak, for estimate_frequency to call it a sine
MAX_VOLTS = 50.0


class ThermalInputError(SmaWristError):
    """An input cannot be used; the message names the file and what is needed."""


@dataclass
class Cleaning:
    """What cleaning did to one input file (counts)."""

    rows: int = 0
    dropped_nan: int = 0
    unsorted: int = 0
    duplicates: int = 0
    gap_cut_s: float = 0.0
    warnings: list[str] = field(default_factory=list)
    #: a bag's TEM drive: 'applied' (the device's read-back) or 'commanded' (the commands); None for a table
    drive: str | None = None


# ------------------------------------------------------------------------------ reading


def _norm(name: str) -> tuple[str, str]:
    """(normalised name, unit) of a header cell: 'Time [ms]' -> ('time', 'ms')."""
    m = re.search(r'[\[(]\s*([^\])]*)\s*[\])]', name)
    unit = m.group(1).strip().lower().replace('°', 'deg').replace(' ', '') if m else ''
    base = re.sub(r'[\[(].*?[\])]', '', name).strip().lower()
    base = re.sub(r'[^a-z0-9]+', '_', base).strip('_')
    for suffix, u in (('_ms', 'ms'), ('_degc', 'degc'), ('_mv', 'mv'), ('_k', 'k')):
        if base.endswith(suffix) and not unit and base[: -len(suffix)]:
            base, unit = base[: -len(suffix)], u
    return base, unit


def read_table(path: Path) -> tuple[list[str] | None, Any]:
    """(header or None, (rows, columns) numbers with NaN for unreadable rows) by :func:`io.read_table`."""
    from sma_wrist.identify import io

    if path.is_dir():
        raise ThermalInputError(f'{path}: is a directory but not a rosbag2 (no metadata.yaml, .mcap or .db3)')
    t = io.read_table(path, need='time, voltage, T1[, T2]', error=ThermalInputError)
    return t.header, t.data


#: the logger of test/data/tec_chamber (a real Peltier module, its README): 5 V supply, ``analogWrite`` 0-255
PWM_SUPPLY_V, PWM_FULL_DUTY = 5.0, 255.0
#: test/data/tec_chamber's columns (``rtempco_run1.csv`` has no header line)
TEC_CHAMBER_COLUMNS = ('set_c', 'oven_c', 'output', 'ambient_c')


def pwm_volts(duty: float, full_duty: float = PWM_FULL_DUTY, supply_V: float = PWM_SUPPLY_V) -> float:
    """The mean drive voltage [V] of a PWM at ``duty`` counts of ``full_duty`` from ``supply_V``: what the thermal
    model's u is when a logger recorded the duty, not the voltage (the Joule term then sees the mean, not the
    mean square, of the chopped drive: a caveat of such data, test/data/tec_chamber/README.md)."""
    return duty / full_duty * supply_V


def tec_chamber_volts(src: Path, dst: Path) -> Path:
    """One of test/data/tec_chamber's logs as a table identify thermal reads: ``u_V,oven_c,ambient_c`` with the
    PWM duty as :func:`pwm_volts` (the only conversion), still without a time column (one row per second)."""
    with Path(src).open(newline='') as f:
        rows = list(csv.reader(f))
    if rows and rows[0] == list(TEC_CHAMBER_COLUMNS):
        rows = rows[1:]
    with Path(dst).open('w') as f:
        f.write('u_V,oven_c,ambient_c\n')
        for _set_c, oven_c, output, ambient_c in rows:
            f.write(f'{pwm_volts(float(output)):.6f},{oven_c},{ambient_c}\n')
    return Path(dst)


def _roles(
    path: Path, header: list[str] | None, columns: dict[str, str] | None, ncol: int, timed: bool = True
) -> tuple[dict[str, int], dict[str, str], list[str]]:
    """Column index and header unit per role; ``timed`` False: the table has no time column (its rows are
    ``--sample-period-s`` apart), and one found is an error."""
    warnings: list[str] = []
    idx: dict[str, int] = {}
    units: dict[str, str] = {}
    normed = [_norm(h) for h in header] if header else []
    if columns:
        for role, ref in columns.items():
            if ref.lstrip('-').isdigit():
                i = int(ref)
            elif header:
                match = [k for k, h in enumerate(header) if h == ref or normed[k][0] == _norm(ref)[0]]
                if not match:
                    raise ThermalInputError(
                        f'{path}: --columns {role}={ref}: no such column; header: {", ".join(header)}'
                    )
                i = match[0]
            else:
                raise ThermalInputError(f'{path}: --columns {role}={ref}: the file has no header; give column numbers')
            if not 0 <= i < ncol:
                raise ThermalInputError(f'{path}: --columns {role}={ref}: column {i} does not exist ({ncol} columns)')
            idx[role] = i
    if header:
        for k, (base, _unit) in enumerate(normed):
            for role in ROLES:
                if role not in idx and k not in idx.values() and base in _NAMES[role]:
                    idx[role] = k
        for role in ('u', 'T1', 'T2'):  # looser: a column mentioning the role
            if role in idx:
                continue
            key = {'u': 'volt', 'T1': 'muscle', 'T2': 'exchanger'}[role]
            for k, (base, _) in enumerate(normed):
                if key in base and k not in idx.values():
                    idx[role] = k
                    break
        units = {role: normed[i][1] for role, i in idx.items()}
    elif not columns:
        first = 0 if timed else 1  # the roles' columns from the left: time, u, T1[, T2]
        if ncol < 3 - first:
            raise ThermalInputError(
                f'{path}: {ncol} column(s) and no header; need {"time, " if timed else ""}voltage, '
                'T1[, T2] (or a header naming them, or --columns)'
            )
        idx = {r: k - first for k, r in enumerate(('time', 'u', 'T1', 'T2')) if first <= k < ncol + first}
        warnings.append(
            f'{path.name}: no header; columns taken as '
            + ('time [s], ' if timed else '')
            + 'u [V], T1 [degC]'
            + (', T2 [degC]' if 'T2' in idx else '')
            + ' (name them or use --columns)'
        )
    if not timed:
        if 'time' in idx:
            raise ThermalInputError(
                f'{path}: --sample-period-s is for a table without a time column, and this one has '
                f'one ({header[idx["time"]] if header else idx["time"]}); drop the option or the '
                'column'
            )
        return idx, units, warnings
    missing = [r for r in ('time', 'u', 'T1') if r not in idx]
    if missing:
        raise ThermalInputError(
            f'{path}: no column for {", ".join(missing)}'
            + (f' in header {", ".join(header)}' if header else '')
            + '; need time [s], drive voltage u [V] and the T1 (muscle face) temperature [degC] (T2 optional); '
            'name them in the header (time, u, T1, T2) or give --columns time=0,u=1,T1=2,T2=3'
            + (
                '; a logger that writes no time, one row per fixed period: --sample-period-s S'
                if missing == ['time']
                else ''
            )
        )
    return idx, units, warnings


def _convert_time(path: Path, t: Any, unit: str) -> Any:
    if unit and unit not in TIME_UNITS:
        raise ThermalInputError(f'{path}: time unit {unit!r} is not one of {", ".join(TIME_UNITS)}')
    return t * TIME_UNITS.get(unit or 's', 1.0)


def _convert_temperature(path: Path, name: str, T: Any, unit: str, warnings: list[str]) -> Any:
    import numpy as np

    unit = unit.replace('deg', 'deg') if unit else ''
    if unit in ('k', 'kelvin'):
        return T - 273.15
    if unit in ('degf', 'f'):
        return (T - 32.0) * 5.0 / 9.0
    if unit and unit not in ('degc', 'c', 'celsius'):
        raise ThermalInputError(f'{path}: temperature unit {unit!r} of {name} is not one of degC, K, degF')
    med = float(np.median(T)) if T.size else float('nan')
    if not unit and 200.0 < med < 450.0:
        warnings.append(
            f'{path.name}: {name} median {med:.1f} looks like Kelvin; converted to degC '
            '(say so with a [K] header unit or --temperature-unit K)'
        )
        return T - 273.15
    if not -40.0 < med < 150.0:
        raise ThermalInputError(
            f'{path}: {name} median {med:g} is not a TEM face temperature in degC (expected '
            'about 0-90 degC); give the unit with --temperature-unit (degC, K, degF)'
        )
    return T


@dataclass
class Series:
    """One cleaned run before resampling (time [s], u [V], T1/T2 [degC])."""

    name: str
    t: Any
    u: Any
    T: Any  # (n, 2), NaN column when T2 is absent
    frequency_Hz: float | None
    source: str
    layer: int = 0  # the wrist's TEM the run measured (0: TEM 1, 1: TEM 2): a table's tem column


def load_table(
    path: Path,
    columns: dict[str, str] | None = None,
    units: dict[str, str] | None = None,
    sample_period_s: float | None = None,
) -> tuple[list[Series], Cleaning]:
    """Read, convert and clean one table; split by its frequency and tem columns if it has them (tem: which of the
    wrist's TEMs, 1 or 2, a row measured). ``sample_period_s``: the table has no time column, its rows are that
    many seconds apart (a logger that writes one row per period)."""
    import numpy as np

    header, data = read_table(path)
    ncol = data.shape[1]
    idx, hdr_units, warnings = _roles(path, header, columns, ncol, timed=sample_period_s is None)
    if sample_period_s is not None:  # row k at k periods: a row dropped below leaves its gap
        data = np.column_stack([data, np.arange(data.shape[0]) * float(sample_period_s)])
        idx['time'], hdr_units['time'] = ncol, 's'
        units = {k: v for k, v in (units or {}).items() if k != 'time'}
    cl = Cleaning(rows=data.shape[0], warnings=warnings)
    units = dict(units or {})
    if 'T2' in idx and not np.isfinite(data[:, idx['T2']]).any():  # a logger's unused channel: every row dropped
        warnings.append(
            f'{path.name}: the T2 column ({header[idx["T2"]] if header else idx["T2"]}) has no value in '
            'any row; fitting T1 only'
        )
        del idx['T2']
    need = [idx['time'], idx['u'], idx['T1']] + [idx[r] for r in ('T2', 'tem') if r in idx]
    bad = ~np.isfinite(data[:, need]).all(axis=1)
    cl.dropped_nan = int(bad.sum())
    if cl.dropped_nan:
        cl.warnings.append(
            f'{path.name}: {cl.dropped_nan} of {cl.rows} rows with NaN, empty or unparseable cells dropped'
        )
    data = data[~bad]
    if data.shape[0] < 10:
        raise ThermalInputError(
            f'{path}: only {data.shape[0]} complete rows; need a run of at least '
            f'{MIN_DURATION_S:g} s with time, voltage and T1 in every row'
        )
    t = _convert_time(path, data[:, idx['time']], units.get('time') or hdr_units.get('time', ''))
    vu = (units.get('u') or hdr_units.get('u', '') or 'v').lower()
    if vu not in VOLT_UNITS:
        raise ThermalInputError(f'{path}: voltage unit {vu!r} is not one of V, mV')
    u = data[:, idx['u']] * VOLT_UNITS[vu]
    if np.abs(u).max() > MAX_VOLTS:
        raise ThermalInputError(
            f'{path}: drive voltages up to {np.abs(u).max():g} are not volts (a TEM drive is '
            f'within +-{MAX_VOLTS:g} V); give --voltage-unit mV, or convert a duty cycle to volts'
        )
    T = np.full((data.shape[0], 2), np.nan)
    for f, role in enumerate(('T1', 'T2')):
        if role in idx:
            T[:, f] = _convert_temperature(
                path,
                role,
                data[:, idx[role]],
                (units.get('temperature') or hdr_units.get(role, '')).lower(),
                cl.warnings,
            )
    tem = data[:, idx['tem']] if 'tem' in idx else np.ones(t.size)
    if not np.isin(tem, (1.0, 2.0)).all():
        bad_tem = sorted({float(x) for x in tem[~np.isin(tem, (1.0, 2.0))]})[:3]
        raise ThermalInputError(
            f'{path}: the tem column says which TEM a row measured, 1 or 2; it holds {", ".join(map(repr, bad_tem))}'
        )
    freq = data[:, idx['frequency']] if 'frequency' in idx else None
    if freq is not None and not np.isfinite(freq).all():
        # a blank cell (a spreadsheet writes each block's frequency on its first row only): the row above's; an
        # empty group of NaN was an IndexError
        blank = ~np.isfinite(freq)
        last = np.maximum.accumulate(np.where(blank, -1, np.arange(freq.size)))
        freq = np.where(last >= 0, freq[np.maximum(last, 0)], np.nan)
        lead = ~np.isfinite(freq)
        cl.warnings.append(
            f'{path.name}: {int(blank.sum())} row(s) without a frequency took the one above'
            + (f'; {int(lead.sum())} before the first frequency dropped' if lead.any() else '')
        )
        t, u, T, freq, tem = t[~lead], u[~lead], T[~lead], freq[~lead], tem[~lead]
        if t.size < 10:
            raise ThermalInputError(f'{path}: no frequency in its frequency column')
    groups = [None] if freq is None else sorted(set(np.round(freq, 9).tolist()))
    tems = sorted(set(tem.tolist()))
    out = []
    for m, g in ((m, g) for m in tems for g in groups):
        sel = tem == m
        if g is not None:
            sel &= np.round(freq, 9) == g
        if not sel.any():
            continue
        ts, us, Ts = t[sel], u[sel], T[sel]
        back = int((np.diff(ts) < 0).sum())
        if back:
            o = np.argsort(ts, kind='stable')
            ts, us, Ts = ts[o], us[o], Ts[o]
            cl.unsorted += back
        dup = np.r_[np.diff(ts) == 0, False]
        if dup.any():
            cl.duplicates += int(dup.sum())
            ts, us, Ts = ts[~dup], us[~dup], Ts[~dup]
        label = (path.name if g is None else f'{path.name} f={g:g} Hz') + (f' TEM {m:g}' if len(tems) > 1 else '')
        out.append(Series(label, ts, us, Ts, None if g is None else float(g), str(path), int(m) - 1))
    if cl.unsorted:
        cl.warnings.append(f'{path.name}: {cl.unsorted} time steps back; rows sorted by time')
    if cl.duplicates:
        cl.warnings.append(f'{path.name}: {cl.duplicates} duplicate time stamps removed (last kept)')
    return out, cl


def estimate_frequency(t: Any, u: Any) -> float | None:
    """Dominant frequency of the drive [Hz] when it is a clear sine (>= 95 % of the AC power within two bins of
    the peak), else None.

    Snapped to the seed's frequencies (1/128-1 Hz) when within 3 %. Measured: the seed's sines 99.96-100 %, a
    square wave 81 %, a real PID's 25-35 degC staircase (test/data/tec_chamber) 82 % -- at the former 50 % the
    staircase was labelled "1/9400 Hz" in the report.
    """
    import numpy as np

    from sma_wrist.core.thermal.heat_balance import SEED_SINE_FREQUENCIES_HZ

    if t.size < 16:
        return None
    dt = float(np.median(np.diff(t)))
    x = u - u.mean()
    p = np.abs(np.fft.rfft(x * np.hanning(x.size))) ** 2
    if p[1:].sum() <= 0:
        return None
    k = int(np.argmax(p[1:])) + 1
    if p[max(1, k - 2) : k + 3].sum() < SINE_POWER_SHARE * p[1:].sum():
        return None
    f = k / (x.size * dt)
    for s in SEED_SINE_FREQUENCIES_HZ:
        if abs(f - s) <= 0.03 * s:
            return float(s)
    return float(f)


def to_records(series: Sequence[Series], dt: float, cleaning: Cleaning, hold: str = 'linear') -> list[Any]:
    """Resample cleaned runs onto the grid ``dt`` (module docstring) as ThermalRecords."""
    import numpy as np

    from sma_wrist.core.thermal.identification import ThermalRecord, interval_means

    out = []
    for s in series:
        t, u, T = s.t, s.u, s.T
        step = float(np.median(np.diff(t))) if t.size > 1 else 0.0
        if step > max(MAX_GAP_S, 5 * dt):  # every row a gap: 'covers only 0.0 s' said nothing of the cause
            raise ThermalInputError(
                f'{s.name}: its rows are {step:g} s apart (the time column read as '
                'seconds); a thermal log samples far faster. If the time is in ms, us or ns '
                '(ROS stamps), give --time-unit or a unit in its header, e.g. "time [ms]"'
            )
        gaps = np.flatnonzero(np.diff(t) > max(MAX_GAP_S, 5 * dt))
        if gaps.size:
            edges = np.r_[0, gaps + 1, t.size]
            lengths = [t[b - 1] - t[a] for a, b in zip(edges[:-1], edges[1:])]
            i = int(np.argmax(lengths))
            a, b = edges[i], edges[i + 1]
            cut = float(t[-1] - t[0] - (t[b - 1] - t[a]))
            cleaning.gap_cut_s += cut
            cleaning.warnings.append(
                f'{s.name}: {gaps.size} gap(s) longer than {max(MAX_GAP_S, 5 * dt):g} s; the '
                f'longest gap-free stretch ({t[a] - t[0]:.1f}-{t[b - 1] - t[0]:.1f} s) is used'
            )
            t, u, T = t[a:b], u[a:b], T[a:b]
        if t[-1] - t[0] < MIN_DURATION_S:
            raise ThermalInputError(
                f'{s.source}: {s.name} covers only {t[-1] - t[0]:.1f} s; need at least '
                f'{MIN_DURATION_S:g} s (the seed ran each frequency for several periods)'
            )
        grid = np.arange(t[0], t[-1] + 1e-9, dt)
        um, u2 = interval_means(t, u, grid, dt, hold)
        Tg = np.stack(
            [
                np.interp(grid, t, T[:, f]) if np.isfinite(T[:, f]).all() else np.full(grid.size, np.nan)
                for f in range(2)
            ],
            axis=1,
        )
        freq = s.frequency_Hz if s.frequency_Hz is not None else estimate_frequency(t, u)
        out.append(ThermalRecord(s.name, dt, um, Tg, freq, source=s.source, u2=u2, layer=s.layer))
    return out


def _is_bag(p: Path) -> bool:
    """A rosbag2 folder, or one of its storage files (MCAP, or SQLite: ``ros2 bag record`` on Humble)."""
    return p.suffix in ('.mcap', '.db3') or (
        p.is_dir() and ((p / 'metadata.yaml').exists() or any(p.glob('*.mcap')) or any(p.glob('*.db3')))
    )


def load_bag(path: Path, dt: float, hold: str = 'zoh', recording: Any = None) -> tuple[list[Any], Cleaning]:
    """Both muscles of a recorded bag as muscle-face-only runs on the grid dt.

    The bag is read on its measurement grid (sma_wrist.diagnose.data.load_run: cleaning, gaps,
    units, the device's drive read-back preferred to the commands) and the held drive averaged over each interval of
    the fit grid.
    """
    import numpy as np

    from sma_wrist.core.thermal.identification import ThermalRecord, interval_means
    from sma_wrist.diagnose.data import load_run

    run = load_run(path, max_rate_hz=1000.0, recording=recording)
    if run.u is None or run.T is None:
        raise ThermalInputError(
            f'{path}: need /wrist/tem_1/command, /wrist/tem_2/command (V) and '
            '/wrist/muscle_1/temperature, /wrist/muscle_2/temperature (degC) for identify thermal'
        )
    if run.dt > dt * (1 + 1e-6):
        raise ThermalInputError(
            f'{path}: measurements every {run.dt:g} s are coarser than the {dt:g} s grid; use --dt {run.dt:g}'
        )
    cl = Cleaning(rows=run.n, warnings=list(run.warnings), drive=run.drive)
    grid = np.arange(run.t[0], run.t[-1] - dt + 1e-9, dt)
    valid = np.interp(grid, run.t, run.valid.astype(float)) > 0.999
    recs = []
    for i in range(2):
        um, u2 = interval_means(run.t, run.u[:, i], grid, dt, hold)
        T = np.stack([np.interp(grid, run.t, run.T[:, i]), np.full(grid.size, np.nan)], axis=1)
        recs.append(
            ThermalRecord(
                f'{path.name} muscle {i + 1}',
                dt,
                um,
                T,
                estimate_frequency(run.t, run.u[:, i]),
                valid=valid,
                source=str(path),
                u2=u2,
                layer=i,  # muscle i is TEM i's face: a --base file's tem_gain applies per TEM
            )
        )
    return recs, cl


def load_inputs(
    paths: Sequence[str],
    dt: float,
    columns: dict[str, str] | None,
    units: dict[str, str],
    hold: str = 'auto',
    recording: Any = None,
    sample_period_s: float | None = None,
) -> tuple[list[Any], dict[str, dict[str, Any]], list[str]]:
    """Records from every input, the cleaning counts per file, and all warnings (``sample_period_s``: tables
    without a time column, :func:`load_table`)."""
    records: list[Any] = []
    cleaning: dict[str, dict[str, Any]] = {}
    warnings: list[str] = []
    for name in paths:
        p = Path(name)
        if not p.exists():
            raise ThermalInputError(f'{p}: no such file (need a text table or a rosbag2 directory)')
        if _is_bag(p):
            recs, cl = load_bag(p, dt, 'zoh' if hold == 'auto' else hold, recording)
        else:
            series, cl = load_table(p, columns, units, sample_period_s)
            recs = to_records(series, dt, cl, 'linear' if hold == 'auto' else hold)
        records += recs
        if _is_bag(p):  # cleaned per topic by diagnose.data.load_run; it reports what it did as warnings
            cleaning[str(p)] = {
                'rows': cl.rows,
                'dropped_nan': None,
                'unsorted': None,
                'duplicates': None,
                'gap_cut_s': None,
                'runs': len(recs),
                'counts': 'per topic, in warnings',
                'drive': cl.drive,
            }
        else:
            cleaning[str(p)] = {
                'rows': cl.rows,
                'dropped_nan': cl.dropped_nan,
                'unsorted': cl.unsorted,
                'duplicates': cl.duplicates,
                'gap_cut_s': round(cl.gap_cut_s, 3),
                'runs': len(recs),
            }
        warnings += cl.warnings
    return records, cleaning, warnings


def _distinct_names(records: list[Any], hold: list[Any]) -> tuple[list[Any], list[Any]]:
    """Runs named by their file name, except where two files share it (sn/a/data.csv, sn/b/data.csv: a rig's
    folder per serial number): those are named by the path as given. The same file given twice keeps one name."""
    import dataclasses
    from collections import defaultdict

    sources: dict[str, set[str]] = defaultdict(set)
    for r in records + hold:
        sources[Path(r.source).name].add(str(Path(r.source).resolve()))

    def named(r: Any) -> Any:
        base = Path(r.source).name
        if len(sources[base]) > 1 and r.name.startswith(base):
            return dataclasses.replace(r, name=str(r.source) + r.name[len(base) :])
        return r

    return [named(r) for r in records], [named(r) for r in hold]


# ------------------------------------------------------------------------------ report


def _params_json(params: Any) -> dict[str, dict[str, float]]:
    from sma_wrist.core.thermal.identification import FACE_KEYS, FACE_NAMES, table_of

    tab = table_of(params)
    return {FACE_NAMES[f]: {k: float(tab[f, j]) for j, k in enumerate(FACE_KEYS)} for f in range(2)}


def _freq_label(f: float | None) -> str:
    if f is None:
        return 'n/a'
    return f'1/{1 / f:g} Hz' if f < 1 else f'{f:g} Hz'


def plot_record(path: Path, rec: Any, identified: Any, default: Any, title: str) -> None:
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    import numpy as np

    t = np.arange(rec.n) * rec.dt
    faces = rec.faces
    fig, axes = plt.subplots(len(faces) + 1, 1, figsize=(9, 2.4 * (len(faces) + 1)), sharex=True)
    for ax, f in zip(axes, faces):
        ax.plot(t, rec.T[:, f], 'k', lw=0.8, label='measured')
        ax.plot(t, identified.simulated[:, f], 'C0', lw=1.0, label=f'identified ({identified.mode})')
        ax.plot(t, default.simulated[:, f], 'C3--', lw=0.8, label='default (Table 4.9)')
        if not identified.evaluated.all():
            ev = identified.evaluated
            ax.axvspan(
                t[np.argmax(ev)], t[ev.size - 1 - np.argmax(ev[::-1])], color='C0', alpha=0.06, label='scored samples'
            )
        ax.set_ylabel(f'{("T1 muscle", "T2 exchanger")[f]} [degC]')
        ax.legend(loc='upper right', fontsize=7)
    axes[-1].plot(t, rec.u, 'C2', lw=0.6)
    axes[-1].set_ylabel('u [V]')
    axes[-1].set_xlabel('t [s]')
    axes[0].set_title(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def plot_summary(path: Path, holdout: Sequence[Any], before: dict[str, Any]) -> None:
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.2))
    for i, e in enumerate(holdout):
        for k, (face, st) in enumerate(e.faces.items()):
            b = before[e.record].faces[face]['rms_C']
            ax.bar(
                i + 0.2 * k - 0.1,
                st['rms_C'],
                0.18,
                color=('C0', 'C1')[k],
                label=f'{face} held out' if i == 0 else None,
            )
            ax.plot(i + 0.2 * k - 0.1, b, 'rv', label='default model' if i == 0 and k == 0 else None)
    ax.set_xticks(range(len(holdout)))
    ax.set_xticklabels(
        [_freq_label(e.frequency_Hz) if e.frequency_Hz else e.record[-12:] for e in holdout], fontsize=7, rotation=30
    )
    ax.set_yscale('log')
    ax.set_ylabel('RMS error [degC]')
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _stat_row(e: Any, face: str, st: dict[str, float], default_rms: float | None) -> str:
    d = f'{default_rms:.3f}' if default_rms is not None else 'n/a'
    return (
        f'| {e.record} | {_freq_label(e.frequency_Hz)} | {face} | {e.mode} | {st["max_pct"]:.2f} | {st["min_pct"]:.2f} | '
        f'{st["mean_pct"]:.2f} | {st["std_pct"]:.2f} | {st["rms_C"]:.3f} | {st["max_abs_C"]:.3f} | {d} |'
    )


def write_report(
    out: Path,
    result: Any,
    records: Sequence[Any],
    holdout_recs: Sequence[Any],
    summary: dict[str, Any],
    plots: bool = True,
) -> Path:
    """thermal_identification.md with the tables and PNG plots in ``out``."""
    from sma_wrist.core.thermal.identification import FACE_KEYS, FACE_NAMES, table_of

    out.mkdir(parents=True, exist_ok=True)
    before = {e.record: e for e in result.before}
    lines = [
        '# TEM heat balance identified from measurements (seed Sec. 4.3, Tables 4.9-4.10)',
        '',
        f'Inputs: {", ".join(summary["inputs"])}'
        + (f'; held-out files: {", ".join(summary["holdout_inputs"])}' if summary['holdout_inputs'] else ''),
        f'Runs: {len(records)} fitted, {len(holdout_recs)} held-out files; grid {summary["dt_s"]:g} s; '
        f'columns fitted: {", ".join(FACE_NAMES[f] for f in result.fit.faces)}; start: {result.fit.start}; '
        f'{result.fit.nfev} simulations; wall {summary["wall_s"]:.1f} s.',
        '',
        f'Params file: `{summary["params_file"]}` (hold limits {summary["hold_limits_V"]} V).',
        '',
    ]
    if summary['warnings']:
        lines += ['## Cleaning and warnings', ''] + [f'- {w}' for w in summary['warnings']] + ['']
    lines += [
        '| file | rows | NaN rows dropped | steps back (sorted) | duplicate stamps | gap cut [s] | runs |',
        '|---|---|---|---|---|---|---|',
    ]
    for f, c in summary['cleaning'].items():
        cells = [
            c[k] if c[k] is not None else 'see warnings' for k in ('dropped_nan', 'unsorted', 'duplicates', 'gap_cut_s')
        ]
        lines.append(f'| {f} | {c["rows"]} | ' + ' | '.join(map(str, cells)) + f' | {c["runs"]} |')
    drives = {
        'applied': "the device's read-back (/wrist/tem_drive_applied)",
        'commanded': 'the commands (/wrist/tem_{1,2}/command)',
    }
    fitted = [f'- TEM drive of {f}: {drives[c["drive"]]}' for f, c in summary['cleaning'].items() if c.get('drive')]
    lines += [''] + fitted if fitted else []
    ident, default = table_of(result.fit.params), table_of(result.base)
    lines += [
        '',
        '## Table 4.9: identified vs default',
        '',
        '| parameter | T1 identified | T1 default | T2 identified | T2 default |',
        '|---|---|---|---|---|',
    ]
    for j, k in enumerate(FACE_KEYS):
        lines.append(f'| {k} | {ident[0, j]:.6g} | {default[0, j]:.6g} | {ident[1, j]:.6g} | {default[1, j]:.6g} |')
    if 1 not in result.fit.faces:
        lines += [
            '',
            'The T2 (exchanger face) column is not fitted: no run measured T2, so the base values are kept '
            'and the T1 column is identified given them (doc/howto/identify_tems.md).',
        ]
    g = summary.get('tem_gain')
    if g:
        lines += [
            '',
            "## Each TEM's drive gain",
            '',
            f"The runs cover both TEMs, so each TEM's drive gain was fitted: {_gain_sentence(g)}.",
        ]
        if g['heldout_T1_rms_C']:
            lines += [
                '',
                'Held-out muscle-face RMS per TEM [degC], each its gain fitted: '
                f'{g["heldout_T1_rms_C"]["per_tem"]}; one shared gain: {g["heldout_T1_rms_C"]["shared"]}.',
            ]
    if summary['fit'].get('sensor_lag_s') is not None:
        lines += [
            '',
            f'Fitted with one first-order lag of the temperature sensors (`--sensor-lag`): '
            f'{summary["fit"]["sensor_lag_s"]:.4g} s. Every simulated temperature below is read through it; '
            'thermal.yaml keeps the heat balance only (the lag is in its provenance).',
        ]
    lines += [
        '',
        f'## Held-out errors (form of Table 4.10; validation: {result.validation})',
        '',
        "e = measured - simulated, free-run from the measured start; % of the face's measured range in that "
        'run (Eq. 4.3). "default RMS" is Table 4.9 on the same samples.',
        '',
        '| run | frequency | face | how held out | max % | min % | mean % | std % | RMS degC | max abs degC | '
        'default RMS degC |',
        '|---|---|---|---|---|---|---|---|---|---|---|',
    ]
    for e in result.holdout:
        for face, st in e.faces.items():
            lines.append(_stat_row(e, face, st, before[e.record].faces[face]['rms_C'] if e.record in before else None))
    lines += [
        '',
        '## In-sample fit (all runs, final parameters)',
        '',
        '| run | frequency | face | mode | max % | min % | mean % | std % | RMS degC | max abs degC | '
        'default RMS degC |',
        '|---|---|---|---|---|---|---|---|---|---|---|',
    ]
    for e in result.in_sample:
        for face, st in e.faces.items():
            lines.append(_stat_row(e, face, st, before[e.record].faces[face]['rms_C']))
    if plots:
        by_name = {e.record: e for e in result.holdout}
        ins = {e.record: e for e in result.in_sample}
        lines += ['', '## Plots', '']
        if result.holdout:
            plot_summary(out / 'thermal_holdout_rms.png', result.holdout, before)
            lines += ['![held-out RMS per run](thermal_holdout_rms.png)', '']
        for i, rec in enumerate(list(records) + list(holdout_recs)):
            ev = by_name.get(rec.name) or ins[rec.name]
            name = f'thermal_run_{i + 1}.png'
            plot_record(
                out / name,
                rec,
                ev,
                before[rec.name],
                f'{rec.name} ({_freq_label(rec.frequency_Hz)}): {ev.mode} prediction vs measured',
            )
            lines += [f'![{rec.name}]({name})', '']
    lines += [
        '## Use it in the wrist',
        '',
        f'Set `thermal_file: {summary["params_file"]}` for **both** `plant_sim` and `tem_controller` '
        '(a ROS params file passed with `--params-file`); doc/howto/identify_tems.md.',
        '',
    ]
    path = out / 'thermal_identification.md'
    path.write_text('\n'.join(lines))
    return path


# ------------------------------------------------------------------------------ command


def _columns(text: str) -> dict[str, str]:
    out = {}
    for item in text.split(','):
        if '=' not in item:
            raise argparse.ArgumentTypeError(f'{item!r}: use ROLE=COLUMN, e.g. time=0,u=1,T1=2,T2=3')
        role, ref = (x.strip() for x in item.split('=', 1))
        if role not in ROLES:
            raise argparse.ArgumentTypeError(f'{role!r} is not one of {", ".join(ROLES)}')
        out[role] = ref
    return out


def register(subparsers: Any) -> argparse.ArgumentParser:
    """Add ``thermal`` to the ``identify`` sub-commands."""
    ap = subparsers.add_parser(
        'thermal',
        help='Table 4.9 heat balance from measured voltage and TEM/muscle temperatures (seed Sec. 4.3)',
        description=__doc__.split('\n\n')[0],
    )
    ap.add_argument('inputs', nargs='+', metavar='BAG|FILE', help='text tables (one run or a frequency column) or bags')
    ap.add_argument('--holdout', nargs='+', default=[], metavar='BAG|FILE', help='runs never fitted, only predicted')
    ap.add_argument('--out', default=None, metavar='DIR', help='report (markdown, PNG) and thermal.yaml here')
    ap.add_argument('--params-out', default=None, metavar='FILE', help='params file (default DIR/thermal.yaml)')
    ap.add_argument('--base', default=None, metavar='FILE', help='thermal file to start from (default Table 4.9)')
    ap.add_argument(
        '--columns', type=_columns, default=None, help='ROLE=COLUMN,... roles time, u, T1, T2, frequency, tem'
    )
    ap.add_argument(
        '--time-unit',
        choices=sorted(TIME_UNITS),
        default=None,
        help='unit of the time column (default: its header unit)',
    )
    ap.add_argument(
        '--sample-period-s',
        type=float,
        default=None,
        metavar='S',
        help='the tables have no time column: their rows are S seconds apart (a logger writing one row per period)',
    )
    ap.add_argument(
        '--temperature-unit',
        choices=('degC', 'K', 'degF'),
        default=None,
        help='unit of the temperature columns (default: their header unit, else degC)',
    )
    ap.add_argument(
        '--voltage-unit',
        choices=('V', 'mV'),
        default=None,
        help='unit of the drive voltage column (default: its header unit, else V)',
    )
    ap.add_argument('--dt', type=float, default=0.1, help='fit grid [s] (default 0.1; at most 1, the RK4 limit)')
    ap.add_argument(
        '--input-hold',
        choices=('auto', 'zoh', 'linear'),
        default='auto',
        help='how the logged voltage drove the TEM between samples (auto: linear for tables, zoh for bags)',
    )
    ap.add_argument(
        '--faces',
        choices=('auto', 'both', 'muscle'),
        default='auto',
        help='Table 4.9 columns to fit (auto: both when T2 is measured in every run)',
    )
    ap.add_argument(
        '--validation',
        choices=('auto', 'leave-one-out', 'time-split', 'none'),
        default='auto',
        help="held-out errors: each run predicted by the fit on the others, or every run's last "
        'share (--train-fraction) by the fit on the rest (auto: leave-one-out from 2 runs)',
    )
    ap.add_argument(
        '--sensor-lag',
        action='store_true',
        help='also fit one first-order lag of the temperature sensors (a thermistor on a block, a '
        "sheathed thermocouple); reported, not part of thermal.yaml's model",
    )
    ap.add_argument('--train-fraction', type=float, default=0.6, help='time-split: fitted share of every run')
    ap.add_argument('--no-plots', action='store_true', help='write no PNG plots')
    ap.add_argument('--json', action='store_true', help='print one JSON object')
    ap.add_argument('--quiet', action='store_true', help='no progress lines on stderr')
    from sma_wrist.cli_options import recording_arguments

    recording_arguments(ap)
    ap.set_defaults(func=run_cli)
    return ap


def run_cli(a: argparse.Namespace) -> int:
    """Handler of ``sma-wrist identify thermal``: exit 0, or 2 with ``error: ...`` / ``{"error": ...}``."""
    import numpy as np

    try:
        summary = identify(a)
    except (SmaWristError, ValueError, np.linalg.LinAlgError, FloatingPointError, OverflowError) as e:
        msg = str(e) if isinstance(e, SmaWristError) else f'cannot identify from these inputs: {type(e).__name__}: {e}'
        if a.json:
            print(json.dumps({'error': msg}))
        else:
            print(f'error: {msg}', file=sys.stderr)
        return 2
    if a.json:
        print(json.dumps(summary, indent=2))
    else:
        print(format_text(summary))
    return 0


def identify(a: argparse.Namespace) -> dict[str, Any]:
    """Run the whole identification for parsed arguments; returns the JSON summary."""
    t0 = time.perf_counter()
    from sma_wrist.core.thermal import heat_balance as th
    from sma_wrist.core.thermal import identification as ti
    from sma_wrist.core.thermal.params_file import load_thermal_file, write_thermal_file

    say = (lambda s: None) if (a.json or a.quiet) else (lambda s: print(f'[identify thermal] {s}', file=sys.stderr))
    units = {'time': a.time_unit, 'temperature': a.temperature_unit, 'u': a.voltage_unit}
    units = {k: v.lower() for k, v in units.items() if v}
    if not (math.isfinite(a.dt) and 0.001 <= a.dt <= 1.0):
        raise ThermalInputError(f'--dt {a.dt} must be in [0.001, 1] s (the RK4 step limit of the model)')
    from sma_wrist.identify.io import check_output_folder
    from sma_wrist.outputs import check_output_file

    inputs = [*a.inputs, *a.holdout, *([a.base] if a.base else [])]
    check_output_folder(a.out, inputs=inputs)
    check_output_file(a.params_out, '--params-out', inputs, ThermalInputError)
    base = load_thermal_file(a.base) if a.base else th.ThermalParams()
    from sma_wrist.contract import Recording

    recording = Recording.from_options(a.topic, a.joint)  # bags of another rig (tables: --columns)
    period = a.sample_period_s
    if period is not None and not (math.isfinite(period) and period > 0):
        raise ThermalInputError(f'--sample-period-s {period} must be a number of seconds > 0')
    if period is not None and a.time_unit:
        raise ThermalInputError('--time-unit is the unit of a time column; --sample-period-s says there is none')
    records, cleaning, warnings = load_inputs(a.inputs, a.dt, a.columns, units, a.input_hold, recording, period)
    hold_recs, hold_clean, hold_warn = (
        load_inputs(a.holdout, a.dt, a.columns, units, a.input_hold, recording, period) if a.holdout else ([], {}, [])
    )
    records, hold_recs = _distinct_names(records, hold_recs)
    names = [r.name for r in records + hold_recs]
    if len(set(names)) != len(names):
        raise ThermalInputError(
            'two runs have the same name (the same file given twice?): '
            + ', '.join(sorted({n for n in names if names.count(n) > 1}))
        )
    say(f'{len(records)} run(s) to fit, {len(hold_recs)} hold-out run(s), grid {a.dt:g} s')
    result = ti.identify_thermal(
        records,
        hold_recs,
        base,
        faces=a.faces,
        validation=a.validation,
        train_fraction=a.train_fraction,
        sensor_lag=a.sensor_lag,
        progress=say,
    )
    result, gains, gain_warnings = tem_gains(records, hold_recs, base, result, a, say)
    fit_warnings = _fit_warnings(result, records, hold_recs) + gain_warnings
    say('characterising the hold limits of the identified model')
    params = result.fit.params.with_hold_limits(ti.tem_hold_limits(result.fit.params))
    lo, hi = params.u_min_V, params.u_max_V
    params_path: Path | None = Path(a.params_out) if a.params_out else (Path(a.out) / 'thermal.yaml' if a.out else None)
    held = [
        {
            'run': e.record,
            'frequency_Hz': e.frequency_Hz,
            'mode': e.mode,
            **{f'{face}_rms_C': round(st['rms_C'], 4) for face, st in e.faces.items()},
            **{f'{face}_std_pct': round(st['std_pct'], 3) for face, st in e.faces.items()},
        }
        for e in result.holdout
    ]
    if params_path is not None:
        params_path.parent.mkdir(parents=True, exist_ok=True)
        write_thermal_file(
            params_path,
            params,
            {
                'tool': 'sma-wrist identify thermal',
                'date': time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime()),
                'inputs': [str(x) for x in a.inputs],
                'holdout_inputs': [str(x) for x in a.holdout],
                'grid_s': a.dt,
                'faces_fitted': [ti.FACE_NAMES[f] for f in result.fit.faces],
                **({'sensor_lag_s': round(result.fit.sensor_lag_s, 3)} if a.sensor_lag else {}),
                'validation': result.validation,
                'in_sample_rms_C': round(result.fit.rms_C, 4),
                'holdout': held,
                **({'tem_gain': {k: gains[k] for k in _GAIN_PROVENANCE}} if gains else {}),
            },
            header='sma_wrist thermal params file (TEM heat balance, seed Eqs. 4.13-4.15, Table 4.9 layout).\n'
            'Written by `sma-wrist identify thermal`. Load it in the wrist by setting the parameter\n'
            'thermal_file to this path for BOTH plant_sim and tem_controller (doc/howto/identify_tems.md).',
        )
    summary: dict[str, Any] = {
        'fit': {
            'faces_fitted': [ti.FACE_NAMES[f] for f in result.fit.faces],
            'start': result.fit.start,
            'rms_C': result.fit.rms_C,
            'simulations': result.fit.nfev,
            'message': result.fit.message,
            'sensor_lag_s': result.fit.sensor_lag_s if a.sensor_lag else None,
            'params': _params_json(params),
            'default_params': _params_json(base),
            'runs': [e.as_dict() for e in result.in_sample],
        },
        'holdout': [e.as_dict() for e in result.holdout],
        'before': [e.as_dict() for e in result.before],
        'validation': result.validation,
        'tem_gain': gains,
        'hold_limits_V': [lo, hi],
        **({'tem_hold_limits_V': [list(q) for q in params.tem_hold_limits_V]} if params.tem_hold_limits_V else {}),
        'params_file': str(params_path) if params_path else None,
        'report': None,
        'inputs': [str(x) for x in a.inputs],
        'holdout_inputs': [str(x) for x in a.holdout],
        'cleaning': {**cleaning, **hold_clean},
        'warnings': warnings + hold_warn + fit_warnings,
        'dt_s': a.dt,
    }
    summary['wall_s'] = time.perf_counter() - t0
    if a.out:
        say('writing the report')
        rep = write_report(Path(a.out), result, records, hold_recs, summary, plots=not a.no_plots)
        summary['report'] = str(rep)
    summary['wall_s'] = time.perf_counter() - t0
    return summary


#: what thermal.yaml's provenance keeps of :func:`tem_gains`' finding
_GAIN_PROVENANCE = ('fitted', 'tem1_relative_to_tem2', 'validation', 'heldout_T1_rms_C', 'noise_C', 'handed_over')


def tem_gains(
    records: Sequence[Any], hold_recs: Sequence[Any], base: Any, shared: Any, a: argparse.Namespace, say: Any
) -> tuple[Any, dict[str, Any] | None, list[str]]:
    """Each TEM's drive gain where the fitted runs cover both TEMs (a bag's two muscles, a table's tem column):
    :func:`~sma_wrist.core.thermal.identification.fit_thermal`'s ``tem_gain``, in every fit of the validation.

    Handed over (thermal.yaml's ``tem_gain``) only where it predicts the held-out muscle faces better than one
    shared gain (``shared``, the identification without it) by more than the sensors' noise, and neither TEM's
    worse by more than it: the rule ``sma-wrist commission`` hands its heat balance over by. Both are judged on
    the same held-out data: the validation chosen, except that leave-one-out becomes the time split where a TEM
    has a single run (a fit without a TEM's runs cannot know its gain). The noise is the largest white-noise std of
    the runs' muscle faces (:func:`sma_wrist.diagnose.effects.noise_sigma`).

    Returns (the identification handed over, the finding as JSON or None for runs of one TEM, warnings).
    """
    import numpy as np

    from sma_wrist.core.thermal import identification as ti
    from sma_wrist.diagnose.effects import noise_sigma

    if len({r.layer for r in records}) < 2:
        return shared, None, []
    validation = shared.validation
    if validation == 'leave-one-out' and not ti.each_tem_twice(records):
        validation = 'time-split'
    say(f"each TEM's drive gain ({validation} validation)")
    opts = dict(faces=a.faces, train_fraction=a.train_fraction, sensor_lag=a.sensor_lag, progress=say)
    found: dict[str, Any] = dict.fromkeys((*_GAIN_PROVENANCE, 'heldout_T1_rms_all_C', 'why'))
    found |= {'validation': validation, 'handed_over': False}
    try:
        per = ti.identify_thermal(records, hold_recs, base, validation=validation, tem_gain=True, **opts)
        same = (
            shared
            if validation == shared.validation
            else ti.identify_thermal(records, hold_recs, base, validation=validation, **opts)
        )
    except ti.ThermalIdentificationError as e:  # e.g. runs too short to hold a part out: the gains are not judged
        found['why'] = f'not judged on held-out data: {e}'
        try:
            gains = ti.fit_thermal(records, base, faces=a.faces, sensor_lag=a.sensor_lag, tem_gain=True).params.tem_gain
        except ti.ThermalIdentificationError:
            return shared, found, []
        found |= {'fitted': [round(g, 4) for g in gains], 'tem1_relative_to_tem2': round(gains[0] / gains[1], 4)}
        differ = ti.tem_gain_warning(gains, 'fitted, not judged: thermal.yaml keeps one gain')
        return shared, found, [differ] if differ else []
    layer = {r.name: r.layer for r in [*records, *hold_recs]}

    def rms(res: Any, tems: Sequence[int] = (0, 1)) -> float | None:
        e = [ev.faces['T1']['rms_C'] for ev in res.holdout if layer[ev.record] in tems]
        return float(np.sqrt(np.mean(np.square(e)))) if e else None

    noise = max(noise_sigma(r.T[r.valid, 0]) for r in [*records, *hold_recs])
    gains = per.fit.params.tem_gain
    per_tem = {'per_tem': [rms(per, (m,)) for m in (0, 1)], 'shared': [rms(same, (m,)) for m in (0, 1)]}
    overall = {'per_tem': rms(per), 'shared': rms(same)}
    if overall['per_tem'] is None or overall['shared'] is None:
        better, why = False, 'no held-out data to judge them by (--validation none and no --holdout)'
    else:
        worse = [m + 1 for m, (c, b) in enumerate(zip(*per_tem.values())) if c is not None and not c <= b + noise]
        better = overall['per_tem'] < overall['shared'] - noise and not worse
        why = (
            f"held out {overall['per_tem']:.3g} degC RMS (muscle faces) against one shared gain's "
            f"{overall['shared']:.3g}, the sensors' noise {noise:.2g} degC"
            + (f'; TEM {", ".join(map(str, worse))} worse beyond the noise' if worse else '')
        )
    found |= {
        'fitted': [round(g, 4) for g in gains],
        'tem1_relative_to_tem2': round(gains[0] / gains[1], 4),
        'heldout_T1_rms_C': {k: [None if x is None else round(x, 4) for x in v] for k, v in per_tem.items()},
        'heldout_T1_rms_all_C': {k: None if v is None else round(v, 4) for k, v in overall.items()},
        'noise_C': round(noise, 4),
        'handed_over': bool(better),
        'why': why,
    }
    where = (
        'thermal.yaml gives each its gain, tem_gain'
        if better
        else 'fitted; thermal.yaml keeps one gain: they predict the held-out data no better'
    )
    differ = ti.tem_gain_warning(gains, where)
    return (per if better else shared), found, [differ] if differ else []


def _gain_sentence(g: dict[str, Any]) -> str:
    """One line of :func:`tem_gains`' finding for the text output and the report."""
    fitted = 'not fitted' if g['fitted'] is None else f"TEM 1 {g['tem1_relative_to_tem2']:.4g} x TEM 2's"
    where = 'in thermal.yaml (tem_gain)' if g['handed_over'] else 'not handed over: thermal.yaml keeps one gain'
    return f'{fitted}, {where} ({g["validation"]} validation: {g["why"]})'


def _fit_warnings(result: Any, records: Sequence[Any], hold_recs: Sequence[Any]) -> list[str]:
    """What the fit's RMS does not say: it stopped before converging, the data left parameters on their bounds,
    or a run it predicts reaches temperatures or drives the fitted runs never did (its error is extrapolation).

    Measured on a real Peltier (test/data/tec_chamber): heating only and one face, the fit crept on past its
    iteration limit with K_R on its bound, and parameters from 2-10 min runs near 25 degC predicted a 25-35 degC
    staircase 3.5 degC off."""
    import numpy as np

    from sma_wrist.core.thermal.identification import FACE_NAMES

    fit, out = result.fit, []
    if not fit.converged:
        out.append(
            f'the fit {fit.message} with its error still falling: the data determine some parameters poorly '
            '(one face only, or a drive of one sign); judge the result by the held-out errors'
        )
    if fit.at_bounds:
        out.append(
            f'the data left {", ".join(fit.at_bounds)}: they do not determine it; a run that drives both '
            'ways and measures both faces would'
        )

    def span(recs: Sequence[Any], f: int) -> tuple[float, float]:
        T = np.concatenate([r.T[:, f][np.isfinite(r.T[:, f])] for r in recs] or [np.empty(0)])
        return (float(T.min()), float(T.max())) if T.size else (math.nan, math.nan)

    u_lo = min(float(r.u.min()) for r in records)
    u_hi = max(float(r.u.max()) for r in records)
    if u_lo > -0.5 or u_hi < 0.5:  # the fitted runs never drove one way: that side of the model is a guess
        side = 'cooling (u < 0)' if u_lo > -0.5 else 'heating (u > 0)'
        out.append(
            f"the fitted runs drive u only from {u_lo:+.1f} to {u_hi:+.1f} V: the model's {side} is "
            'extrapolated, and so is its hold limit on that side'
        )
    fitted = {f: span(records, f) for f in range(2)}
    for r in hold_recs:
        beyond = []
        for f in range(2):
            lo, hi = span([r], f)
            flo, fhi = fitted[f]
            margin = max(1.0, 0.1 * (fhi - flo))  # degC: a little past the fitted range is interpolation still
            if math.isfinite(lo) and math.isfinite(flo) and (lo < flo - margin or hi > fhi + margin):
                beyond.append(f'{FACE_NAMES[f]} {lo:.1f}..{hi:.1f} degC (fitted {flo:.1f}..{fhi:.1f})')
        if float(r.u.min()) < u_lo - 0.5 or float(r.u.max()) > u_hi + 0.5:
            beyond.append(f'u {r.u.min():+.1f}..{r.u.max():+.1f} V (fitted {u_lo:+.1f}..{u_hi:+.1f})')
        if beyond:
            out.append(f'hold-out run {r.name} reaches {", ".join(beyond)}: its error measures extrapolation')
    return out


def format_text(s: dict[str, Any]) -> str:
    out = [
        f'identified {", ".join(s["fit"]["faces_fitted"])} column(s) of Table 4.9 from '
        f'{len(s["fit"]["runs"])} run(s): in-sample RMS {s["fit"]["rms_C"]:.3f} degC '
        f'({s["fit"]["simulations"]} simulations, start {s["fit"]["start"]}), {s["wall_s"]:.1f} s'
        + (f'; sensor lag {s["fit"]["sensor_lag_s"]:.3g} s' if s['fit'].get('sensor_lag_s') is not None else '')
    ]
    for w in s['warnings']:
        out.append(f'warning: {w}')
    before = {e['record']: e for e in s['before']}
    if s['holdout']:
        out.append(
            f'held out ({s["validation"]}): run, frequency, face: RMS degC, std %, max|e| % (default model RMS degC)'
        )
    for e in s['holdout']:
        for face, st in e['faces'].items():
            b = before.get(e['record'], {}).get('faces', {}).get(face, {}).get('rms_C')
            out.append(
                f'  {e["record"]:<30s} {_freq_label(e["frequency_Hz"]):>10s} {face}: {st["rms_C"]:.3f}, '
                f'{st["std_pct"]:.2f} %, {st["max_abs_pct"]:.2f} %' + (f'  ({b:.3f})' if b is not None else '')
            )
    if s.get('tem_gain'):
        out.append(f"each TEM's drive gain: {_gain_sentence(s['tem_gain'])}")
    out.append(f'hold limits of the identified model: {s["hold_limits_V"][0]:+g} .. {s["hold_limits_V"][1]:+g} V')
    if s['params_file']:
        out.append(f'params file: {s["params_file"]} (set thermal_file for plant_sim and tem_controller)')
    if s['report']:
        out.append(f'report: {s["report"]}')
    return '\n'.join(out)
