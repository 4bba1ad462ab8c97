"""Reading measured isobaric (constant-stress thermal cycling) tests from text tables.

A file is a CSV, TSV or whitespace table, with or without a header line (metadata lines
before it are skipped, quoted cells as instrument exports write them are accepted). Columns
are found by header name (temperature, strain/extension, stress/load, time) or given with
``columns``; units are given or detected from the header or the values, with a warning that
says what was assumed. Rows with unreadable or NaN cells, duplicated rows and out-of-order
time stamps are removed and counted, never silently, and so are temperature samples that
jump away from their neighbours and back (logger dropouts, :func:`temperature_spikes`).

Mapping to the model (:mod:`sma_wrist.core.hysteresis.sdgpi`): the SD-GPI is written for the seed's
test wire, elongation y in mm of an 80 mm wire (:data:`REF_LENGTH_MM`) and load m in kgf per
0.25 mm wire (:data:`REF_DIAMETER_MM`). Strain maps to y = strain * 80 mm and stress to
m = sigma * A(0.25 mm) / g, so a wire of another diameter or length is described by its
stress and strain: the identified model is the same material law.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import NDArray

from sma_wrist.core.errors import SmaWristError

FloatArray = NDArray[np.float64]

REF_LENGTH_MM = 80.0  # the seed's test wire (Sec. 3.2); the plant scales to its 83 mm wires
REF_DIAMETER_MM = 0.25  # Nitinol #6 wire of the wrist
G = 9.80665  # m/s^2, kgf -> N

TEMPERATURE_UNITS = ('degC', 'K', 'degF')
STRAIN_UNITS = ('fraction', '%', 'mm')
STRESS_UNITS = ('MPa', 'psi', 'ksi', 'N', 'lbf', 'kg', 'kgf', 'g')
#: stress units -> MPa, load units -> N (a load needs the wire diameter)
_TO_MPA = {'MPa': 1.0, 'psi': 0.00689476, 'ksi': 6.89476}
_TO_N = {'N': 1.0, 'lbf': 4.4482216, 'kg': G, 'kgf': G, 'g': G / 1000.0}
#: cells that mean "no value" in instrument and spreadsheet exports (MTS writes ****)
_MISSING = {'', '****', '***', '**', '--', '---', 'n/a', 'na', '#n/a', 'null', 'none', '#value!', '#div/0!'}


class IdentifyInputError(SmaWristError):
    """A measurement file cannot be used; the message names the file and what is needed."""


def check_output_folder(out: str | None, flag: str = '--out', inputs: Sequence[str] = ()) -> None:
    """IdentifyInputError if ``out`` cannot be the output folder (sma_wrist.outputs): found before the fit, not
    after it (~15 s)."""
    from sma_wrist.outputs import check_output_folder as check

    check(out, flag, inputs, IdentifyInputError)


def area_mm2(diameter_mm: float) -> float:
    return math.pi * diameter_mm**2 / 4.0


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
    first_bad: str | None = None  # 'line N: <text>' of the first unreadable row, for the warning


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
_DECIMAL_COMMA = re.compile(r'^[+-]?\d+,\d+([eE][+-]?\d+)?$')


def _split(line: str, delim: str | None) -> list[str]:
    line = line.strip().replace('""', '"')
    if len(line) >= 2 and line[0] == '"' and line[-1] == '"' and line.count('"') == 2:
        line = line[1:-1]  # a whole row quoted (MTS exports)
    cells = line.split(delim) if delim else line.split()
    cells = [c.strip().strip('"').strip() for c in cells]
    if delim != ',':  # decimal commas (European spreadsheet exports: ';' or tab between cells)
        cells = [c.replace(',', '.') if _DECIMAL_COMMA.match(c) else c for c in cells]
    return cells


#: clock stamps of data loggers: hh:mm[:ss[.f]], optionally after an ISO date ('2024-05-01 13:45:07.5')
_CLOCK = re.compile(r'^(?:(\d{4})-(\d{2})-(\d{2})[ T])?(\d{1,2}):(\d{2})(?::(\d{2}(?:\.\d*)?))?$')


def _is_number(c: str) -> bool:
    return bool(_NUM.match(c) or _CLOCK.match(c))


def _is_numeric(cells: list[str], text_columns: frozenset[int] = frozenset()) -> bool:
    """Every cell a number or "no value", at least two numbers; cells of ``text_columns`` are not looked at."""
    kept = [c for j, c in enumerate(cells) if j not in text_columns]
    return (
        len(kept) >= 2
        and all(_is_number(c) or c.lower() in _MISSING for c in kept)
        and sum(_is_number(c) for c in kept) >= 2
    )


def _text_columns(rows: list[list[str]]) -> frozenset[int]:
    """Columns of the table's data rows (the most common width among rows with two numbers or more) that hold
    text in most rows: a logger's status column ('OK'), a comment. Their cells are read as NaN, so one such
    column does not make every row unreadable."""
    wide = [r for r in rows if sum(_is_number(c) for c in r) >= 2]
    if not wide:
        return frozenset()
    widths = [len(r) for r in wide]
    ncol = max(set(widths), key=widths.count)
    data = [r for r in wide if len(r) == ncol]
    text = frozenset(
        j for j in range(ncol) if sum(not (_is_number(r[j]) or r[j].lower() in _MISSING) for r in data) > len(data) / 2
    )
    return text if len(text) <= ncol - 2 else frozenset()


def _cell(c: str) -> float:
    """A number; a clock stamp in seconds (since midnight, or since 1970 with its date); else NaN."""
    if _NUM.match(c):
        return float(c)
    m = _CLOCK.match(c)
    if m is None:
        return np.nan
    y, mo, d, h, mi, sec = m.groups()
    t = int(h) * 3600.0 + int(mi) * 60.0 + float(sec or 0.0)
    if y is not None:
        import datetime

        t += (datetime.date(int(y), int(mo), int(d)) - datetime.date(1970, 1, 1)).days * 86400.0
    return t


def _decode(raw: bytes) -> str:
    """Text of a file: UTF-16 or UTF-8 by its byte-order mark, else UTF-8, else Windows-1252 (Excel's CSV)."""
    if raw[:2] in (b'\xff\xfe', b'\xfe\xff'):
        return raw.decode('utf-16', errors='replace')
    try:
        return raw.decode('utf-8-sig')
    except UnicodeDecodeError:
        return raw.decode('cp1252', errors='replace')


def _xlsx_lines(p: Path, error: type) -> list[list[str]]:
    """Cells of the first worksheet of an Excel .xlsx workbook (the Office Open XML zip), row by row."""
    import xml.etree.ElementTree as ET
    import zipfile

    ns = '{http://schemas.openxmlformats.org/spreadsheetml/2006/main}'
    try:
        with zipfile.ZipFile(p) as z:
            names = z.namelist()
            shared: list[str] = []
            if 'xl/sharedStrings.xml' in names:
                for si in ET.fromstring(z.read('xl/sharedStrings.xml')).iter(ns + 'si'):
                    shared.append(''.join(t.text or '' for t in si.iter(ns + 't')))
            sheets = sorted(n for n in names if re.match(r'xl/worksheets/sheet\d+\.xml$', n))
            if not sheets:
                raise error(f'{p}: an .xlsx workbook without worksheets')
            root = ET.fromstring(z.read(sheets[0]))
    except (zipfile.BadZipFile, ET.ParseError, KeyError) as e:
        raise error(f'{p}: not a readable .xlsx workbook ({e}); save it as .xlsx or export a CSV') from None
    rows = []
    for row in root.iter(ns + 'row'):
        cells: dict[int, str] = {}
        for c in row.iter(ns + 'c'):
            ref = re.match(r'([A-Z]+)', c.get('r', ''))
            col = sum((ord(ch) - 64) * 26**k for k, ch in enumerate(reversed(ref.group(1)))) - 1 if ref else len(cells)
            v = c.find(ns + 'v')
            t = c.get('t')
            if t == 'inlineStr':
                text = ''.join(x.text or '' for x in c.iter(ns + 't'))
            elif v is None or v.text is None:
                text = ''
            elif t == 's':
                text = shared[int(v.text)]
            else:
                text = v.text
            cells[col] = text.strip()
        if cells:
            rows.append([cells.get(i, '') for i in range(max(cells) + 1)])
    return rows


#: run in a child process: scipy's C reader of .mat files can crash the process (segfault) on a
#: damaged file (seen with a few flipped bytes), which no ``except`` catches
_LOADMAT = """
import pickle, sys
import scipy.io
try:
    m = scipy.io.loadmat(sys.argv[1], squeeze_me=True)
    r = {k: v for k, v in m.items() if not k.startswith('__')}
except NotImplementedError:
    r = 'v7.3'
except Exception as e:
    r = 'error: ' + str(e)
pickle.dump(r, sys.stdout.buffer)
"""


def _mat_table(p: Path, error: type) -> Table:
    """A MATLAB .mat file: one numeric matrix (columns as in a text table) or equally long vectors named by column."""
    import pickle
    import subprocess
    import sys

    try:
        proc = subprocess.run([sys.executable, '-c', _LOADMAT, str(p)], capture_output=True, timeout=300, check=False)
    except subprocess.TimeoutExpired:
        raise error(f'{p}: reading the .mat file took over 300 s; export a CSV') from None
    if proc.returncode != 0:
        raise error(
            f'{p}: not a readable MATLAB .mat file (the reader stopped with exit code {proc.returncode}: '
            f'{proc.stderr.decode(errors="replace").strip()[-200:] or "a crash"})'
        )
    items = pickle.loads(proc.stdout)  # our own child's answer (numpy arrays), not the file's bytes
    if items == 'v7.3':
        raise error(f'{p}: a MATLAB v7.3 (HDF5) .mat file; save it with save(..., "-v7") or export a CSV')
    if isinstance(items, str):
        raise error(f'{p}: not a readable MATLAB .mat file ({items[len("error: ") :]})')
    num = {
        k: np.asarray(v, float)
        for k, v in items.items()
        if isinstance(v, np.ndarray) and v.dtype.kind in 'fiu' and v.size > 1
    }
    vectors = {k: v for k, v in num.items() if v.ndim == 1}
    lengths = {v.size for v in vectors.values()}
    if len(vectors) >= 2 and len(lengths) == 1:
        names = list(vectors)
        return Table(str(p), np.column_stack([vectors[k] for k in names]), names, {'unreadable_rows': 0})
    mats = {k: v for k, v in num.items() if v.ndim == 2 and min(v.shape) >= 2}
    if len(mats) == 1:
        (v,) = mats.values()
        return Table(str(p), v if v.shape[0] >= v.shape[1] else v.T, None, {'unreadable_rows': 0})
    found = (
        ', '.join(
            f'{k} ({type(v).__name__} {getattr(v, "shape", "")}, '
            f'{"cell array" if getattr(v, "dtype", None) is not None and v.dtype == object else "numeric"})'
            for k, v in items.items()
        )
        or 'nothing'
    )
    raise error(
        f'{p}: a .mat file needs one numeric matrix (a column per quantity) or equally long numeric '
        f'vectors named by quantity; it holds {found}. Cell arrays of curves: save one stress per file'
    )


#: the suffixes a folder given as input is searched for (:func:`expand_folders`); "" is a plain file name
TABLE_SUFFIXES = ('.txt', '.csv', '.tsv', '.dat', '.xlsx', '.mat')


def expand_folders(paths: Sequence[str], exclude: Sequence[str] = (), error: type = IdentifyInputError) -> list[str]:
    """Each folder among ``paths`` replaced by the tables in it (:data:`TABLE_SUFFIXES`, sorted by name; a
    data set's README.md and LICENSE are not tables), files kept as given. A table of a folder that is
    also in ``exclude`` (the held-out files) is left out, so a held-out loop is never fitted. A folder
    without tables is an error: the user named it, so nothing in it is silently skipped."""
    held = {Path(f).resolve() for f in exclude}
    out: list[str] = []
    for a in paths:
        p = Path(a)
        if not p.is_dir():
            out.append(a)
            continue
        found = sorted(
            str(f)
            for f in p.iterdir()
            if f.is_file()
            and not f.name.startswith('.')
            and f.suffix.lower() in TABLE_SUFFIXES
            and f.resolve() not in held
        )
        if not found:
            raise error(
                f'{p}: a folder with no table in it to fit (looked for '
                f'{", ".join(TABLE_SUFFIXES)} files, held-out ones left out); give the tables or their folder'
            )
        out.extend(found)
    return out


def read_table(
    path: str | Path, need: str = 'temperature, strain and stress', error: type = IdentifyInputError
) -> Table:
    """Parse a CSV / TSV / semicolon / whitespace table, an .xlsx workbook or a MATLAB .mat file.

    The one table reader of ``sma-wrist identify`` (hysteresis and thermal inputs): ``need``
    names the columns in its error messages, ``error`` is the exception raised. Metadata,
    comment ('#', '%') and header lines before the numbers are skipped; decimal commas are
    read where cells are split by ';', tabs or spaces; cells an export writes for "no
    value" (empty, '****', 'n/a', ...) are NaN. Rows that are not all numbers (or have another
    column count) become NaN rows, counted as ``unreadable_rows`` with the first one in
    ``first_bad``; the caller drops and counts what it cannot use.
    """
    p = Path(path)
    if p.suffix.lower() == '.mat':
        if not p.is_file():
            raise error(f'{p}: cannot read the file (no such file); give a readable table')
        return _mat_table(p, error)
    if p.suffix.lower() in ('.xls', '.ods'):
        raise error(f'{p}: {p.suffix} workbooks are not read; save the sheet as .xlsx or CSV')
    try:
        raw = p.read_bytes()
    except OSError as e:
        raise error(f'{p}: cannot read the file ({e.strerror or e}); give a readable text table') from None
    if raw[:4] == b'PK\x03\x04':  # a zip: an .xlsx workbook, whatever its name
        cell_rows = _xlsx_lines(p, error)
        numbered = [(i + 1, '\t'.join(r)) for i, r in enumerate(cell_rows) if any(c for c in r)]
        delim: str | None = '\t'
    else:
        if b'\x00' in raw[:4096] and raw[:2] not in (b'\xff\xfe', b'\xfe\xff'):
            raise error(f'{p}: a binary file, not a text table; export {need} as CSV')
        numbered = [(i + 1, ln) for i, ln in enumerate(_decode(raw).splitlines()) if ln.strip()]
        delim = None
    lines = [ln for _, ln in numbered]
    if not lines:
        raise error(f'{p}: empty file; a table with {need} columns is needed')
    if delim is None:
        sample = [ln for ln in lines if any(ch.isdigit() for ch in ln)][-20:]
        for d in ('\t', ';', ','):  # ';' before ',': a ';' table may have decimal commas
            if sample and all(d in ln for ln in sample):
                delim = d
                break
    rows = [_split(ln, delim) for ln in lines]
    text_cols = _text_columns(rows)
    first = next((i for i, r in enumerate(rows) if _is_numeric(r, text_cols)), None)
    if first is None:
        raise error(f'{p}: no numeric rows found; a table of numbers ({need}) is needed')
    ncol = len(rows[first])
    header = None
    if first > 0:  # the line above the numbers, also as a '# a b c' comment (numpy.savetxt's default)
        above = _split(lines[first - 1].lstrip().lstrip('#%'), delim)
        if len(above) == ncol and not _is_numeric(above):
            header = above
    body = [
        (n, r, ln) for (n, ln), r in zip(numbered[first:], rows[first:]) if not ln.lstrip().startswith(('#', '%'))
    ]  # comments
    data = np.full((len(body), ncol), np.nan)
    bad = 0
    first_bad = None
    for i, (n, r, ln) in enumerate(body):
        if len(r) != ncol or not _is_numeric(r, text_cols):
            bad += 1
            if first_bad is None:
                first_bad = (
                    f'line {n}: {ln.strip()[:60]!r} ({len(r)} cells, {ncol} expected)'
                    if len(r) != ncol
                    else f'line {n}: {ln.strip()[:60]!r} (not a number in every column)'
                )
            continue
        data[i] = [np.nan if j in text_cols else _cell(c) for j, c in enumerate(r)]
    for j in range(ncol):  # times of day without a date: a run past midnight goes on counting
        if any(_CLOCK.match(r[j]) and not r[j][:4].isdigit() for _, r, _ in body[:50] if len(r) == ncol):
            col = data[:, j]
            ok = np.isfinite(col)
            col[ok] += 86400.0 * np.cumsum(np.r_[0.0, np.diff(col[ok]) < -43200.0])
    return Table(str(p), data, header, {'unreadable_rows': bad}, first_bad)


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
    if role == 'T':  # 'T (K)', or a thermocouple channel named by the logger ('_COM1 (C)'): its unit says it
        bare = [re.sub(r'[\[(].*?[\])]', '', c).strip().lower() for c in header]
        return next(
            (i for i, c in enumerate(header) if bare[i] in ('t', 'theta') or _bracket_unit(c) in _UNIT_WORDS['T']), None
        )
    return None


def _resolve(spec: str, header: list[str] | None, ncol: int, path: str) -> int:
    if spec.strip().lstrip('-').isdigit():
        i = int(spec)
        if not 0 <= i < ncol:
            raise IdentifyInputError(f'{path}: column {i} does not exist (the table has {ncol} columns, 0-based)')
        return i
    if header is None:
        raise IdentifyInputError(
            f'{path}: column {spec!r} given by name but the table has no header; give 0-based numbers'
        )
    for i, c in enumerate(header):
        if c.strip().lower() == spec.strip().lower():
            return i
    raise IdentifyInputError(f'{path}: no column named {spec!r}; the header has {header}')


#: unit words in a header's brackets, per role -> unit name (None: dimensionless, read by value)
_UNIT_WORDS: dict[str, dict[str, str | None]] = {
    'T': {
        'c': 'degC',
        '°c': 'degC',
        'degc': 'degC',
        'celsius': 'degC',
        'k': 'K',
        'kelvin': 'K',
        'f': 'degF',
        '°f': 'degF',
        'degf': 'degF',
        'fahrenheit': 'degF',
    },
    'strain': {
        '%': '%',
        'pct': '%',
        'percent': '%',
        'mm': 'mm',
        'mm/mm': 'fraction',
        'm/m': 'fraction',
        'in/in': 'fraction',
        '-': 'fraction',
        '1': 'fraction',
        '': None,
    },
    'stress': {
        'mpa': 'MPa',
        'n/mm2': 'MPa',
        'n/mm^2': 'MPa',
        'n/mm²': 'MPa',
        'psi': 'psi',
        'ksi': 'ksi',
        'n': 'N',
        'newton': 'N',
        'lbf': 'lbf',
        'kg': 'kg',
        'kgf': 'kgf',
        'g': 'g',
    },
    'time': {},
}


def _bracket_unit(name: str) -> str | None:
    """The unit written in the last (...) or [...] of a header name, lower case, or None."""
    m = re.findall(r'[\[(]\s*([^\])]*?)\s*[\])]', name)
    if not m:
        return None
    # 'deg. C', 'degrees C', '° C', 'º C' (the ordinal sign Windows keyboards give) -> 'degc', '°c'
    return m[-1].lower().replace('\u00ba', '°').replace('degrees', 'deg').replace('.', '').replace(' ', '')


def _unit_from_header(name: str, role: str, path: str = '') -> str | None:
    """Unit of a column from its header name; an unknown unit in brackets is an error (never read silently)."""
    n = name.lower()
    b = _bracket_unit(name)
    if b is not None and role in ('T', 'strain', 'stress'):
        if b in _UNIT_WORDS[role]:
            return _UNIT_WORDS[role][b]
        raise IdentifyInputError(
            f'{path}: column {name!r}: unit {b!r} is not one of {", ".join(k for k in _UNIT_WORDS[role] if k)}; '
            f'give --{ {"T": "temperature", "strain": "strain", "stress": "stress"}[role] }-unit'
        )
    if role == 'T':
        if re.search(r'kelvin|\bk\b', n):
            return 'K'
        if re.search(r'degc|°c|celsius', n):
            return 'degC'
        if re.search(r'degf|°f|fahrenheit', n):
            return 'degF'
    if role == 'strain':
        if '%' in n or 'pct' in n or 'percent' in n:
            return '%'
        if 'mm/mm' in n:
            return 'fraction'
        if 'mm' in n:
            return 'mm'
    if role == 'stress':
        if 'mpa' in n:
            return 'MPa'
        if 'kgf' in n:
            return 'kgf'
        if 'newton' in n:
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


def temperature_spikes(
    T: FloatArray, half_window: int = 10, floor: float = 1.0, n_sigma: float = 3.5
) -> NDArray[np.bool_]:
    """Samples where a temperature channel jumps away from its neighbours and back (Hampel filter).

    Loggers drop out to 0 (or a rail) for a few samples: the chamber thermocouple of the NiTiPd
    export (test/data/nitipd) reads 0.00 for 1-6 samples at -1.5..-7.4 degC, which pulls the
    strain to a vertical line at 0 degC. A sample is a spike when it is further than
    max(``floor``, ``n_sigma`` robust standard deviations) from the median of the 2 x
    ``half_window`` + 1 samples around it [same unit as T]; ramps and turning points move the
    median and widen the spread with them: no sample of the SMA-REACT or Flexinol loops is
    flagged (with 3.5 sigma; 87 of the NiTiPd export's 138 zeros are, the others lie within
    ~1-4 degC of the air's temperature, where the spread of the zeros around them hides them).
    """

    T = np.asarray(T, float)
    if T.size < 2 * half_window + 1:
        return np.zeros(T.size, bool)
    W = sliding_window_view(np.pad(T, half_window, mode='edge'), 2 * half_window + 1)
    med = np.median(W, axis=1)
    mad = 1.4826 * np.median(np.abs(W - med[:, None]), axis=1)
    return np.abs(T - med) > np.maximum(floor, n_sigma * mad)


def scale_switch(
    x: FloatArray, factor: float = 100.0, limit: float = 0.1, block: int = 25
) -> tuple[int, float, float] | None:
    """(row, largest |x| before, after) where a column goes on in a unit ``factor`` times another (a logger
    switched its strain from fraction to %, or back, mid-file), else None.

    Such a row is a jump far larger than any step of the ``block`` rows before it, that lands where the previous
    value times ``factor`` would (within the steps of the ``block`` rows after it), and the column stays within
    ``limit`` on one side of it only (a strain fraction is under 0.1; in % it goes beyond). A measured column
    changes smoothly, and a transformation's jump neither multiplies the value it starts from nor changes the
    range a unit allows."""
    n = x.size
    if n < 2 * block + 2:
        return None
    for reverse in (False, True):  # % -> fraction is fraction -> % read backwards
        y = x[::-1] if reverse else x
        a = np.abs(y)
        step = np.abs(np.diff(y))
        k = np.arange(block, n - 1 - block)  # the jump y[k] -> y[k + 1]
        W = sliding_window_view(step, block)
        small_before = np.maximum.accumulate(a)[k] <= limit
        large_after = np.maximum.accumulate(a[::-1])[::-1][k + 1] > limit
        hit = (
            small_before
            & large_after
            & (step[k] > 30.0 * W[k - block].max(axis=1))
            & (np.abs(y[k + 1] - factor * y[k]) <= 3.0 * W[k + 1].max(axis=1))
        )
        if hit.any():
            j = int(k[np.argmax(hit)])
            before, after = float(a[: j + 1].max()), float(a[j + 1 :].max())
            return (n - 1 - j, after, before) if reverse else (j + 1, before, after)
    return None


def to_measurement(
    table: Table, units: Units, columns: list[str] | None = None, stress_MPa: float | None = None
) -> Measurement:
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
            raise IdentifyInputError(
                f'{path}: no temperature and strain columns in the header {hdr}; '
                'give them with --columns T,STRAIN[,STRESS[,TIME]] (names or 0-based numbers)'
            )
        if iP is not None and 'load' in hdr[iP].lower():  # prefer a stress column over a load column
            alt = next((i for i, c in enumerate(hdr) if 'stress' in c.lower()), None)
            iP = alt if alt is not None else iP
    else:
        if ncol < 2:
            raise IdentifyInputError(f'{path}: one column only; temperature and strain (and stress) are needed')
        iT, iS, iP, iTime = 0, 1, (2 if ncol > 2 else None), None
        warn.append(f'{path}: no header; assumed columns temperature, strain' + (', stress' if ncol > 2 else ''))
    name = lambda i: hdr[i] if hdr is not None and i is not None else ''  # noqa: E731

    cols = [i for i in (iT, iS, iP, iTime) if i is not None]
    for role, i in (('temperature', iT), ('strain', iS), ('stress', iP), ('time', iTime)):
        if i is not None and data.shape[0] and not np.isfinite(data[:, i]).any():
            raise IdentifyInputError(
                f'{path}: the {role} column ({name(i) or i}) has no number in any row; '
                'give the right one with --columns T,STRAIN[,STRESS[,TIME]]'
            )
    counts = dict(table.counts)
    bad = counts.get('unreadable_rows', 0)
    if bad and table.first_bad:
        if bad > data.shape[0] // 2:
            raise IdentifyInputError(
                f'{path}: {bad} of {data.shape[0]} rows are unreadable, the first at '
                f'{table.first_bad}; a table of numbers with the same columns in every row '
                'is needed'
            )
        warn.append(f'{path}: {bad} unreadable row(s) dropped, the first at {table.first_bad}')
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

    spike = temperature_spikes(d[:, iT])
    counts['temperature_spikes'] = int(spike.sum())
    if spike.any():
        warn.append(
            f'{path}: {int(spike.sum())} temperature sample(s) dropped as sensor spikes or dropouts '
            f'(e.g. row {int(np.argmax(spike)) + 1} of the cleaned table reads {d[np.argmax(spike), iT]:.4g} '
            'between its neighbours)'
        )
        d = d[~spike]
        time = d[:, iTime] if time is not None else None
    T = d[:, iT].astype(float)
    tu = units.temperature or _unit_from_header(name(iT), 'T', path)
    if tu is None:
        tu = 'K' if T.min() > 200.0 else 'degC'
        warn.append(
            f'{path}: temperature unit not given; {T.min():.4g}..{T.max():.4g} read as {tu} (use --temperature-unit)'
        )
    if tu == 'K':
        T = T - 273.15
    elif tu == 'degF':
        T = (T - 32.0) * 5.0 / 9.0
    if T.min() < -150 or T.max() > 600:
        raise IdentifyInputError(
            f'{path}: temperatures {T.min():.4g}..{T.max():.4g} degC fit no SMA test; '
            'give --temperature-unit (degC or K) or the right --columns'
        )

    raw = d[:, iS].astype(float)
    su = units.strain or _unit_from_header(name(iS), 'strain', path)
    if su is None:
        switch = scale_switch(raw)
        if switch is not None:  # read by its largest value, the fraction half would be 100x too small
            row, before, after = switch
            raise IdentifyInputError(
                f'{path}: the strain column changes scale at row {row} of the cleaned table (up to {before:.3g} '
                f'before, {after:.3g} after): a fraction and a % in one file? Split the file, or give --strain-unit '
                'if the change is real'
            )
        mx = float(np.max(np.abs(raw)))
        if mx <= 0.1:
            su = 'fraction'
        elif mx <= 15.0:
            su = '%'
        else:
            raise IdentifyInputError(
                f'{path}: strain values up to {mx:.4g} fit neither a fraction nor %; '
                'give --strain-unit (fraction, %, mm with --length-mm)'
            )
        warn.append(f'{path}: strain unit not given; values up to {mx:.4g} read as {su} (use --strain-unit)')
    if su == 'mm':
        if not units.length_mm:
            raise IdentifyInputError(
                f'{path}: the strain column is an elongation in mm; give the gauge length with --length-mm'
            )
        strain = raw / units.length_mm
    elif su == '%':
        strain = raw / 100.0
    else:
        strain = raw
    if np.max(np.abs(strain)) > 0.2:
        raise IdentifyInputError(
            f'{path}: strains up to {np.max(np.abs(strain)):.3g} (>20 %) fit no wire test; '
            'check --strain-unit / --length-mm / --columns'
        )

    if iP is not None:
        sraw = d[:, iP].astype(float)
        pu = units.stress or _unit_from_header(name(iP), 'stress', path)
        if pu is None:
            pu = 'MPa'
            warn.append(
                f'{path}: stress unit not given; values {sraw.min():.4g}..{sraw.max():.4g} read as MPa '
                '(use --stress-unit)'
            )
        if pu in _TO_MPA:
            stress = sraw * _TO_MPA[pu]
        else:
            if not units.wire_diameter_mm:
                raise IdentifyInputError(f'{path}: the stress column is a load in {pu}; give --wire-diameter-mm')
            stress = sraw * _TO_N[pu] / area_mm2(units.wire_diameter_mm)
    else:
        s = stress_MPa if stress_MPa is not None else _stress_from_name(path)
        if s is None:
            raise IdentifyInputError(
                f'{path}: no stress column; give --stress-mpa or a file name with the stress (e.g. "200MPa.txt")'
            )
        if stress_MPa is None:
            warn.append(f'{path}: stress {s:g} MPa taken from the file name')
        stress = np.full(T.size, float(s))
    if np.nanmax(stress) > 3000 or np.nanmin(stress) < -50:
        raise IdentifyInputError(
            f'{path}: stresses {stress.min():.4g}..{stress.max():.4g} MPa fit no wire test; '
            'check --stress-unit / --wire-diameter-mm / --columns'
        )
    return Measurement(path, T, strain, stress, time, counts, warn)


def read_measurement(
    path: str | Path, units: Units = Units(), columns: list[str] | None = None, stress_MPa: float | None = None
) -> Measurement:
    """:func:`read_table` then :func:`to_measurement`."""
    return to_measurement(read_table(path), units, columns, stress_MPa)
