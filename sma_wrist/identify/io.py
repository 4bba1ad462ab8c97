"""Reading measured isobaric (constant-stress thermal cycling) tests from text tables.

A file is a CSV, TSV or whitespace table, with or without a header line (metadata lines
before it are skipped, quoted cells as instrument exports write them are accepted). Columns
are found by header name (temperature, strain/extension, stress/load, time) or given with
``columns``; units are given or detected from the header or the values, with a warning that
says what was assumed. Rows with unreadable or NaN cells, duplicated rows and out-of-order
time stamps are removed and counted, never silently.

Mapping to the model (:mod:`sma_wrist.core.hysteresis.sdgpi`): the SD-GPI is written for the seed's
test wire, elongation y in mm of an 80 mm wire (:data:`REF_LENGTH_MM`) and load m in kgf per
0.25 mm wire (:data:`REF_DIAMETER_MM`). Strain maps to y = strain * 80 mm and stress to
m = sigma * A(0.25 mm) / g, so a wire of another diameter or length is described by its
stress and strain: the identified model is the same material law.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from sma_wrist.core.errors import SmaWristError

FloatArray = NDArray[np.float64]

REF_LENGTH_MM = 80.0  # the seed's test wire (Sec. 3.2); the plant scales to its 83 mm wires
REF_DIAMETER_MM = 0.25  # Nitinol #6 wire of the wrist
G = 9.80665  # m/s^2, kgf -> N

TEMPERATURE_UNITS = ('degC', 'K')
STRAIN_UNITS = ('fraction', '%', 'mm')
STRESS_UNITS = ('MPa', 'N', 'kg', 'kgf')


class IdentifyInputError(SmaWristError):
    """A measurement file cannot be used; the message names the file and what is needed."""


def area_mm2(diameter_mm: float) -> float:
    return math.pi * diameter_mm ** 2 / 4.0


def stress_to_load_kgf(stress_MPa: FloatArray | float) -> FloatArray | float:
    """Load [kgf] on the model's 0.25 mm reference wire that gives this stress [MPa]."""
    return stress_MPa * area_mm2(REF_DIAMETER_MM) / G


def load_kgf_to_stress(load_kgf: FloatArray | float) -> FloatArray | float:
    return load_kgf * G / area_mm2(REF_DIAMETER_MM)


@dataclass
class Table:
    """Numbers of one file: (rows, columns), header names (or None), cleaning counts."""

    path: str
    data: FloatArray
    header: list[str] | None
    counts: dict[str, int] = field(default_factory=dict)


@dataclass
class Measurement:
    """Temperature [degC], strain [-], stress [MPa] and optional time of one file, cleaned."""

    path: str
    T_C: FloatArray
    strain: FloatArray
    stress_MPa: FloatArray
    time: FloatArray | None
    counts: dict[str, int]
    warnings: list[str]


_NUM = re.compile(r'^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$|^[+-]?(nan|inf)$', re.IGNORECASE)


def _split(line: str, delim: str | None) -> list[str]:
    line = line.strip().replace('""', '"')
    if len(line) >= 2 and line[0] == '"' and line[-1] == '"' and line.count('"') == 2:
        line = line[1:-1]  # a whole row quoted (MTS exports)
    cells = line.split(delim) if delim else line.split()
    return [c.strip().strip('"').strip() for c in cells]


def _is_numeric(cells: list[str]) -> bool:
    return len(cells) >= 2 and all(_NUM.match(c) for c in cells if c != '') and any(c != '' for c in cells)


def read_table(path: str | Path, need: str = 'temperature, strain and stress', error: type = IdentifyInputError) -> Table:
    """Parse a CSV / TSV / whitespace table; metadata, comment and header lines before the numbers are skipped.

    The one table reader of ``sma-wrist identify`` (hysteresis and thermal inputs): ``need``
    names the columns in its error messages, ``error`` is the exception raised. Rows that
    are not all numbers (or have another column count) become NaN rows, counted as
    ``unreadable_rows``; the caller drops and counts what it cannot use.
    """
    p = Path(path)
    try:
        text = p.read_text(encoding='utf-8', errors='replace')
    except OSError as e:
        raise error(f'{p}: cannot read the file ({e.strerror or e}); give a readable text table') from None
    lines = [ln for ln in text.splitlines() if ln.strip()]
    if not lines:
        raise error(f'{p}: empty file; a table with {need} columns is needed')
    sample = [ln for ln in lines if any(ch.isdigit() for ch in ln)][-20:]
    delim: str | None = None
    for d in ('\t', ',', ';'):
        if sample and all(d in ln for ln in sample):
            delim = d
            break
    rows = [_split(ln, delim) for ln in lines]
    first = next((i for i, r in enumerate(rows) if _is_numeric(r)), None)
    if first is None:
        raise error(f'{p}: no numeric rows found; a table of numbers ({need}) is needed')
    ncol = len(rows[first])
    header = None
    if first > 0:  # the line above the numbers, also as a '# a b c' comment (numpy.savetxt's default)
        above = _split(lines[first - 1].lstrip().lstrip('#'), delim)
        if len(above) == ncol and not _is_numeric(above):
            header = above
    body = [r for r, ln in zip(rows[first:], lines[first:]) if not ln.lstrip().startswith('#')]  # comments
    data = np.full((len(body), ncol), np.nan)
    bad = 0
    for i, r in enumerate(body):
        if len(r) != ncol or not _is_numeric(r):
            bad += 1
            continue
        data[i] = [float(c) if c != '' else np.nan for c in r]
    return Table(str(p), data, header, {'unreadable_rows': bad})


# ----------------------------------------------------------------------------- columns and units

_COLUMN_KEYS = {
    'T': ('temp', 'degc', 'kelvin'),
    'strain': ('strain', 'eps', 'extension', 'elongation', 'displacement'),
    'stress': ('stress', 'sigma', 'mpa', 'load', 'force'),
    'time': ('time',),
}


def _find(header: list[str], role: str) -> int | None:
    h = [c.lower() for c in header]
    for key in _COLUMN_KEYS[role]:
        for i, c in enumerate(h):
            if key in c and not (role == 'T' and 'time' in c):
                return i
    return None


def _resolve(spec: str, header: list[str] | None, ncol: int, path: str) -> int:
    if spec.strip().lstrip('-').isdigit():
        i = int(spec)
        if not 0 <= i < ncol:
            raise IdentifyInputError(f'{path}: column {i} does not exist (the table has {ncol} columns, 0-based)')
        return i
    if header is None:
        raise IdentifyInputError(f'{path}: column {spec!r} given by name but the table has no header; give 0-based numbers')
    for i, c in enumerate(header):
        if c.strip().lower() == spec.strip().lower():
            return i
    raise IdentifyInputError(f'{path}: no column named {spec!r}; the header has {header}')


def _unit_from_header(name: str, role: str) -> str | None:
    n = name.lower()
    if role == 'T':
        if re.search(r'\(k\)|\[k\]|kelvin|\bk\b', n):
            return 'K'
        if re.search(r'\(c\)|\[c\]|degc|°c|celsius', n):
            return 'degC'
    if role == 'strain':
        if '%' in n or 'pct' in n or 'percent' in n:
            return '%'
        if 'mm' in n and '/mm' not in n:
            return 'mm'
        if 'mm/mm' in n or '(-)' in n or '[-]' in n:
            return 'fraction'
    if role == 'stress':
        if 'mpa' in n:
            return 'MPa'
        if 'kgf' in n:
            return 'kgf'
        if '(kg)' in n or '[kg]' in n:
            return 'kg'
        if '(n)' in n or '[n]' in n or 'newton' in n:
            return 'N'
    return None


@dataclass(frozen=True)
class Units:
    """What the user said (None: detect). Lengths/diameters convert elongation and load."""

    temperature: str | None = None
    strain: str | None = None
    stress: str | None = None
    length_mm: float | None = None
    wire_diameter_mm: float | None = None


def _stress_from_name(path: str) -> float | None:
    m = re.search(r'(\d+(?:\.\d+)?)\s*mpa', Path(path).name, re.IGNORECASE)
    return float(m.group(1)) if m else None


def to_measurement(table: Table, units: Units, columns: list[str] | None = None,
                   stress_MPa: float | None = None) -> Measurement:
    """Columns and units of one table -> a cleaned :class:`Measurement` (see the module docstring)."""
    path, hdr, data = table.path, table.header, table.data
    ncol = data.shape[1]
    warn: list[str] = []
    if columns:
        idx = [_resolve(c, hdr, ncol, path) for c in columns]
        iT, iS = idx[0], idx[1]
        iP = idx[2] if len(idx) > 2 else None
        iTime = idx[3] if len(idx) > 3 else None
    elif hdr is not None:
        iT, iS, iP, iTime = (_find(hdr, r) for r in ('T', 'strain', 'stress', 'time'))
        if iT is None or iS is None:
            raise IdentifyInputError(f'{path}: no temperature and strain columns in the header {hdr}; '
                                     'give them with --columns T,STRAIN[,STRESS[,TIME]] (names or 0-based numbers)')
        if iP is not None and 'load' in hdr[iP].lower():  # prefer a stress column over a load column
            alt = next((i for i, c in enumerate(hdr) if 'stress' in c.lower()), None)
            iP = alt if alt is not None else iP
    else:
        if ncol < 2:
            raise IdentifyInputError(f'{path}: one column only; temperature and strain (and stress) are needed')
        iT, iS, iP, iTime = 0, 1, (2 if ncol > 2 else None), None
        warn.append(f'{path}: no header; assumed columns temperature, strain' + (', stress' if ncol > 2 else ''))
    name = (lambda i: hdr[i] if hdr is not None and i is not None else '')  # noqa: E731

    cols = [i for i in (iT, iS, iP, iTime) if i is not None]
    counts = dict(table.counts)
    ok = np.all(np.isfinite(data[:, cols]), axis=1)
    counts['nan_rows'] = int((~ok).sum()) - counts.get('unreadable_rows', 0)
    d = data[ok]
    if d.shape[0]:
        _, first = np.unique(d[:, cols], axis=0, return_index=True)
        keep = np.sort(first)
        counts['duplicate_rows'] = int(d.shape[0] - keep.size)
        d = d[keep]
    else:
        counts['duplicate_rows'] = 0
    time = None
    counts['unsorted_stamps'] = 0
    if iTime is not None and d.shape[0]:
        t = d[:, iTime]
        counts['unsorted_stamps'] = int(np.sum(np.diff(t) < 0))
        order = np.argsort(t, kind='stable')
        d = d[order]
        time = d[:, iTime]
    if d.shape[0] == 0:
        raise IdentifyInputError(f'{path}: no complete rows (all rows have unreadable or missing cells)')

    T = d[:, iT].astype(float)
    tu = units.temperature or _unit_from_header(name(iT), 'T')
    if tu is None:
        tu = 'K' if T.min() > 200.0 else 'degC'
        warn.append(f'{path}: temperature unit not given; {T.min():.4g}..{T.max():.4g} read as {tu} '
                    '(use --temperature-unit)')
    if tu == 'K':
        T = T - 273.15
    if T.min() < -150 or T.max() > 600:
        raise IdentifyInputError(f'{path}: temperatures {T.min():.4g}..{T.max():.4g} degC fit no SMA test; '
                                 'give --temperature-unit (degC or K) or the right --columns')

    raw = d[:, iS].astype(float)
    su = units.strain or _unit_from_header(name(iS), 'strain')
    if su is None:
        mx = float(np.max(np.abs(raw)))
        if mx <= 0.1:
            su = 'fraction'
        elif mx <= 15.0:
            su = '%'
        else:
            raise IdentifyInputError(f'{path}: strain values up to {mx:.4g} fit neither a fraction nor %; '
                                     'give --strain-unit (fraction, %, mm with --length-mm)')
        warn.append(f'{path}: strain unit not given; values up to {mx:.4g} read as {su} (use --strain-unit)')
    if su == 'mm':
        if not units.length_mm:
            raise IdentifyInputError(f'{path}: the strain column is an elongation in mm; give the gauge length with --length-mm')
        strain = raw / units.length_mm
    elif su == '%':
        strain = raw / 100.0
    else:
        strain = raw
    if np.max(np.abs(strain)) > 0.2:
        raise IdentifyInputError(f'{path}: strains up to {np.max(np.abs(strain)):.3g} (>20 %) fit no wire test; '
                                 'check --strain-unit / --length-mm / --columns')

    if iP is not None:
        sraw = d[:, iP].astype(float)
        pu = units.stress or _unit_from_header(name(iP), 'stress')
        if pu is None:
            pu = 'MPa'
            warn.append(f'{path}: stress unit not given; values {sraw.min():.4g}..{sraw.max():.4g} read as MPa '
                        '(use --stress-unit)')
        if pu == 'MPa':
            stress = sraw
        else:
            if not units.wire_diameter_mm:
                raise IdentifyInputError(f'{path}: the stress column is a load in {pu}; give --wire-diameter-mm')
            newton = sraw if pu == 'N' else sraw * G
            stress = newton / area_mm2(units.wire_diameter_mm)
    else:
        s = stress_MPa if stress_MPa is not None else _stress_from_name(path)
        if s is None:
            raise IdentifyInputError(f'{path}: no stress column; give --stress-mpa or a file name with the stress '
                                     '(e.g. "200MPa.txt")')
        if stress_MPa is None:
            warn.append(f'{path}: stress {s:g} MPa taken from the file name')
        stress = np.full(T.size, float(s))
    if np.nanmax(stress) > 3000 or np.nanmin(stress) < -50:
        raise IdentifyInputError(f'{path}: stresses {stress.min():.4g}..{stress.max():.4g} MPa fit no wire test; '
                                 'check --stress-unit / --wire-diameter-mm / --columns')
    return Measurement(path, T, strain, stress, time, counts, warn)


def read_measurement(path: str | Path, units: Units = Units(), columns: list[str] | None = None,
                     stress_MPa: float | None = None) -> Measurement:
    """:func:`read_table` then :func:`to_measurement`."""
    return to_measurement(read_table(path), units, columns, stress_MPa)
