"""Measured data the way users' files look: other exports of the same loop, malformed files, a raw multi-load export.

Every variant is written from a real measured loop (test/data/flexinol/100MPa.txt) the way
another tool would export it and must read back to the same temperatures, strains and
stresses; every malformed file must give an error naming the file and what is wrong.
doc/howto/identify_wire.md and "More measured data, as users' files look".
"""

from __future__ import annotations

import json
import zipfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from sma_wrist.cli import main as cli_main
from sma_wrist.core.errors import SmaWristError
from sma_wrist.identify.hysteresis import Options, run
from sma_wrist.identify.io import G, Units, area_mm2, read_measurement, read_table, scale_switch
from sma_wrist.identify.segment import stress_levels

DATA = Path(__file__).parent / 'data'
LOOP = DATA / 'flexinol' / '100MPa.txt'
NITIPD = DATA / 'nitipd' / 'NiTiPd_Characterization.txt'


def _quiet(msg: str) -> None:
    pass


@pytest.fixture(scope='module')
def loop() -> np.ndarray:
    """(T degC, strain, stress MPa) of the measured loop, 499 rows."""
    return np.loadtxt(LOOP, skiprows=1)


def _dc(x: float, fmt: str) -> str:
    return (fmt % x).replace('.', ',')


def _xlsx(path: Path, header: list[str], rows: np.ndarray) -> None:
    """A minimal Excel workbook (Office Open XML): header as shared strings, numbers as values."""

    def col(j: int) -> str:
        return chr(65 + j)

    sheet = ['<row r="1">' + ''.join(f'<c r="{col(j)}1" t="s"><v>{j}</v></c>' for j in range(len(header))) + '</row>']
    for i, r in enumerate(rows, start=2):
        sheet.append(
            f'<row r="{i}">'
            + ''.join(f'<c r="{col(j)}{i}"><v>{float(v)!r}</v></c>' for j, v in enumerate(r))
            + '</row>'
        )
    ns = 'xmlns="http://schemas.openxmlformats.org/spreadsheetml/2006/main"'
    with zipfile.ZipFile(path, 'w') as z:
        z.writestr('[Content_Types].xml', '<Types/>')
        z.writestr('xl/sharedStrings.xml', f'<sst {ns}>' + ''.join(f'<si><t>{h}</t></si>' for h in header) + '</sst>')
        z.writestr('xl/worksheets/sheet1.xml', f'<worksheet {ns}><sheetData>{"".join(sheet)}</sheetData></worksheet>')


def _write(name: str, d: Path, L: np.ndarray) -> tuple[Path, Units]:
    T, e, s = L.T
    t = np.arange(T.size) * 0.5
    p = d / name
    N = s * area_mm2(0.25)  # the load on a 0.25 mm wire
    if name == 'semicolon_decimal_comma_cp1252.csv':  # a European spreadsheet's CSV, with a title line
        p.write_bytes(
            (
                'Messung 7;Probe A\n\nTime [s];Temperature [°C];Strain [%];Stress [MPa]\n'
                + ''.join(
                    f'{_dc(a, "%.1f")};{_dc(b, "%.5f")};{_dc(100 * c, "%.6f")};{_dc(x, "%.4f")}\n'
                    for a, b, c, x in zip(t, T, e, s)
                )
            ).encode('cp1252')
        )
        return p, Units()
    if name == 'tab_kelvin_newton_reordered.txt':  # temperature found by its unit only
        p.write_text(
            'Force (N)\tStrain (mm/mm)\tT (K)\n'
            + ''.join(f'{n:.6f}\t{c:.8f}\t{b + 273.15:.5f}\n' for b, c, n in zip(T, e, N))
        )
        return p, Units(wire_diameter_mm=0.25)
    if name == 'grams_mm_percent_comments.csv':
        p.write_text(
            '% logger export, wire 80 mm\ntime_s,temperature_degC,displacement (mm),load (g)\n'
            + ''.join(f'{a:.1f},{b:.5f},{80 * c:.6f},{n / G * 1000:.5f}\n' for a, b, c, n in zip(t, T, e, N))
        )
        return p, Units(length_mm=80.0, wire_diameter_mm=0.25)
    if name == 'fahrenheit_psi_bom.csv':
        p.write_text(
            '\ufeffTemp (°F),Strain (%),Stress (psi)\n'
            + ''.join(f'{b * 9 / 5 + 32:.5f},{100 * c:.6f},{x / 0.00689476:.3f}\n' for b, c, x in zip(T, e, s))
        )
        return p, Units()
    if name == 'utf16_tab_decimal_comma.txt':  # Excel's "Unicode text"
        p.write_bytes(
            (
                'Temperature [°C]\tStrain [-]\tStress [MPa]\r\n'
                + ''.join(f'{_dc(b, "%.6f")}\t{_dc(c, "%.8f")}\t{_dc(x, "%.6f")}\r\n' for b, c, x in zip(T, e, s))
            ).encode('utf-16')
        )
        return p, Units()
    if name == 'mts_stars.txt':  # MTS writes **** for a channel it did not compute
        p.write_text(
            '"Test Method","x.msm"\n\n"Time (s)","Temp (C)","Stress (MPa)","Strain (mm/mm)","Flex (mm/mm)"\n'
            + ''.join(f'{a:.1f},{b:.5f},{x:.4f},{c:.8f},****\n' for a, b, c, x in zip(t, T, e, s))
        )
        return p, Units()
    if name == 'vectors.mat':
        scipy.io.savemat(p, {'Temperature_degC': T, 'Strain_pct': 100 * e, 'Stress_MPa': s})
        return p, Units()
    if name == 'matrix.mat':
        scipy.io.savemat(p, {'data': np.c_[T, e, s]})
        return p, Units()
    if name == 'workbook.xlsx':
        _xlsx(p, ['Temperature (C)', 'Strain (%)', 'Stress (MPa)'], np.c_[T, 100 * e, s])
        return p, Units()
    raise AssertionError(name)


VARIANTS = [
    'semicolon_decimal_comma_cp1252.csv',
    'tab_kelvin_newton_reordered.txt',
    'grams_mm_percent_comments.csv',
    'fahrenheit_psi_bom.csv',
    'utf16_tab_decimal_comma.txt',
    'mts_stars.txt',
    'vectors.mat',
    'matrix.mat',
    'workbook.xlsx',
]


@pytest.mark.parametrize('name', VARIANTS)
def test_other_exports_of_a_measured_loop_read_the_same(tmp_path: Path, loop: np.ndarray, name: str) -> None:
    """Each of these failed before (no numeric rows, columns not found, psi/grams/degF read as MPa/degC)."""
    p, units = _write(name, tmp_path, loop)
    m = read_measurement(p, units)
    assert m.T_C.size == loop.shape[0] and sum(m.counts.values()) == 0, m.counts
    # the written precision (5-6 digits) is all the difference
    assert np.allclose(m.T_C, loop[:, 0], atol=2e-4)
    assert np.allclose(m.strain, loop[:, 1], atol=2e-7)
    assert np.allclose(m.stress_MPa, loop[:, 2], rtol=2e-5, atol=2e-3)


@pytest.mark.parametrize(
    'header, scale',
    [
        ('Temperature (degrees C),Strain (%),Stress (N/mm2)', (1.0, 0.0, 100.0, 1.0)),
        ('Temperature [deg. C],Strain [ % ],Stress [ksi]', (1.0, 0.0, 100.0, 1 / 6.89476)),
        ('Temperatur [º C],Dehnung [-],Spannung [MPa]', (1.0, 0.0, 1.0, 1.0)),
        ('time (s),Temp. (K),Elongation (mm),Load (lbf)', (1.0, 273.15, 80.0, area_mm2(0.25) / 4.4482216)),
    ],
)
def test_header_units_as_people_write_them(
    tmp_path: Path, loop: np.ndarray, header: str, scale: tuple[float, float, float, float]
) -> None:
    kT, oT, kS, kP = scale
    cols = [loop[:, 0] * kT + oT, loop[:, 1] * kS, loop[:, 2] * kP]
    if header.startswith('time'):
        cols = [np.arange(loop.shape[0], dtype=float)] + cols
    (tmp_path / 'h.csv').write_text(
        header + '\n' + ''.join(','.join(f'{v:.10g}' for v in r) + '\n' for r in np.column_stack(cols)),
        encoding='utf-8',
    )
    names = header.split(',')
    columns = None if 'Dehnung' not in header else names  # German names: given with --columns
    m = read_measurement(tmp_path / 'h.csv', Units(length_mm=80.0, wire_diameter_mm=0.25), columns)
    assert np.allclose(m.T_C, loop[:, 0], atol=1e-6) and np.allclose(m.strain, loop[:, 1], atol=1e-9)
    assert np.allclose(m.stress_MPa, loop[:, 2], rtol=1e-8)


@pytest.mark.parametrize(
    'stamp',
    [
        lambda t: (
            f'{int(23 + (59 * 60 + 50 + t) // 3600) % 24}:{int((59 * 60 + 50 + t) % 3600 // 60):02d}:'
            f'{(50 + t) % 60:04.1f}'
        ),  # a time of day that passes midnight
        lambda t: f'2024-05-01T13:{int(t // 60):02d}:{t % 60:04.1f}',  # ISO date and time
    ],
)
def test_clock_time_stamps_are_seconds(tmp_path: Path, loop: np.ndarray, stamp: Callable[[float], str]) -> None:
    """A logger's clock column: read as seconds (before: every row unreadable), sorted, midnight unwrapped."""
    rows = [f'{stamp(0.5 * i)};{T:.6f};{e:.8f};{s:.6f}' for i, (T, e, s) in enumerate(loop)]
    rows[30], rows[31] = rows[31], rows[30]
    (tmp_path / 'c.csv').write_text('Time;Temperature (C);Strain (-);Stress (MPa)\n' + '\n'.join(rows) + '\n')
    m = read_measurement(tmp_path / 'c.csv')
    assert m.counts['unsorted_stamps'] == 1 and m.T_C.size == loop.shape[0]
    assert m.time is not None and np.allclose(np.diff(m.time), 0.5)
    assert np.allclose(m.T_C, loop[:, 0], atol=1e-6)


def test_an_export_cleaned_of_nan_duplicates_and_unsorted_rows_keeps_the_rest(tmp_path: Path, loop: np.ndarray) -> None:
    lines = ['time (s),temperature (C),strain (%),stress (MPa)'] + [
        f'{0.5 * i:.1f},{T:.5f},{100 * e:.6f},{s:.4f}' for i, (T, e, s) in enumerate(loop)
    ]
    lines[11] = '5.0,NaN,,'  # a gap
    lines.insert(21, lines[20])  # a repeated sample
    lines[31], lines[32] = lines[32], lines[31]  # out of order
    (tmp_path / 'x.csv').write_text('\n'.join(lines) + '\n')
    m = read_measurement(tmp_path / 'x.csv')
    assert m.counts == {
        'unreadable_rows': 0,
        'nan_rows': 1,
        'duplicate_rows': 1,
        'unsorted_stamps': 1,
        'temperature_spikes': 0,
    }
    assert m.T_C.size == loop.shape[0] - 1 and np.all(np.diff(m.time) > 0)


@pytest.mark.parametrize(
    'body, kept, needed',
    [
        # truncated: the last row cut mid-line
        (lambda rows: rows[:-1] + [rows[-1][:6]], 498, 'unreadable row(s) dropped, the first at line 500'),
        # text in a number column
        (lambda rows: rows[:40] + ['31.2 zero 100.1'] + rows[40:], 499, "line 42: '31.2 zero 100.1' (not a number"),
    ],
)
def test_a_damaged_row_is_dropped_and_named(
    tmp_path: Path, body: Callable[[list[str]], list[str]], kept: int, needed: str
) -> None:
    rows = LOOP.read_text().splitlines()
    (tmp_path / 'd.txt').write_text('\n'.join([rows[0]] + body(rows[1:])) + '\n')
    m = read_measurement(tmp_path / 'd.txt')
    assert m.counts['unreadable_rows'] == 1 and m.T_C.size == kept
    assert any(needed in w for w in m.warnings), m.warnings


def _mat_mismatch(p: Path) -> None:
    scipy.io.savemat(p, {'T': np.arange(10.0), 'strain': np.arange(9.0), 'stress': np.arange(10.0)})


def _mat_cells(p: Path) -> None:
    c = np.empty(2, object)
    c[0], c[1] = np.arange(5.0), np.arange(6.0)
    scipy.io.savemat(p, {'Xdata_SampTemp_degC': c, 'Ydata_TrueStrain_pct': c})


@pytest.mark.parametrize(
    'name, make, needed',
    [
        (
            'unit.csv',
            lambda p: p.write_text('Temperature (C),Strain (%),Stress (bar)\n' + '30,1,100\n' * 50),
            "unit 'bar' is not one of",
        ),
        (
            'unitT.csv',
            lambda p: p.write_text('Temperature (R),Strain (%),Stress (MPa)\n' + '30,1,100\n' * 50),
            "unit 'r' is not one of",
        ),
        (
            'one.csv',
            lambda p: p.write_text('Temperature (C),Strain (%),Stress (MPa)\n30,1,100\n'),
            'no constant stress level with >= 20 samples',
        ),
        (
            'nanT.csv',
            lambda p: p.write_text('Temperature (C),Strain (%),Stress (MPa)\n' + 'NaN,1,100\n' * 50),
            'the temperature column (Temperature (C)) has no number in any row',
        ),
        (
            'most_bad.csv',
            lambda p: p.write_text('T (C),Strain (%),Stress (MPa)\n30,1,100\n' + '30,1\n' * 50),
            '50 of 51 rows are unreadable, the first at line 3',
        ),
        ('mismatch.mat', _mat_mismatch, 'equally long numeric vectors'),
        ('cells.mat', _mat_cells, 'cell array'),
        ('broken.mat', lambda p: p.write_bytes(b'MATLAB 5.0 MAT-file' + bytes(200)), 'not a readable MATLAB .mat file'),
        (
            'cut.mat',
            lambda p: (scipy.io.savemat(p, {'T': np.arange(99.0)}), p.write_bytes(p.read_bytes()[:100])),
            'not a readable MATLAB .mat file',
        ),
        ('broken.xlsx', lambda p: p.write_bytes(b'PK\x03\x04' + bytes(100)), 'not a readable .xlsx workbook'),
        ('old.xls', lambda p: p.write_bytes(b'\xd0\xcf\x11\xe0' + bytes(100)), 'save the sheet as .xlsx or CSV'),
        ('binary.dat', lambda p: p.write_bytes(bytes(range(256)) * 4), 'a binary file, not a text table'),
    ],
)
def test_malformed_files_are_json_errors_naming_file_and_need(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], name: str, make: Callable[[Path], object], needed: str
) -> None:
    f = tmp_path / name
    make(f)
    code = cli_main(['identify', 'hysteresis', str(f), str(LOOP), str(LOOP), '--json', '--no-plots', '--no-loo'])
    doc = json.loads(capsys.readouterr().out)
    assert code == 2 and set(doc) == {'error'}
    assert doc['error'].startswith(str(f)) and needed in doc['error'], doc['error']


@pytest.mark.parametrize(
    'option, value, needed',
    [
        ('--length-mm', '-1', '--length-mm -1.0 must be a finite number > 0'),  # flipped every strain, fitted anyway
        ('--wire-diameter-mm', 'nan', '--wire-diameter-mm nan must be a finite number > 0'),  # the fit never ended
        ('--stress-mpa', 'inf', '--stress-mpa inf must be a finite number'),
        ('--stress-mpa', '-50', '--stress-mpa -50.0 must be > 0 (the tensile stress of the test)'),  # was a section
        ('--columns', '0', "--columns '0': give 2 to 4 columns T,STRAIN[,STRESS[,TIME]] (names or 0-based numbers)"),
        (
            '--columns',
            '0,,1',
            "--columns '0,,1': give 2 to 4 columns T,STRAIN[,STRESS[,TIME]] (names or 0-based numbers)",
        ),
    ],
)
def test_non_finite_or_negative_scale_options_are_json_errors(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], option: str, value: str, needed: str
) -> None:
    flex = DATA / 'flexinol'
    code = cli_main(
        [
            'identify',
            'hysteresis',
            str(flex / '50MPa.txt'),
            str(flex / '100MPa.txt'),
            str(flex / '200MPa.txt'),
            option,
            value,
            '--json',
            '--no-plots',
            '--no-loo',
            '--out',
            str(tmp_path),
        ]
    )
    doc = json.loads(capsys.readouterr().out)
    assert code == 2 and doc == {'error': needed}


def test_an_out_that_is_a_file_is_refused_before_any_fit(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """identify hysteresis / thermal --out FILE failed only at the write, after the whole fit (~15 s)."""
    from sma_wrist.core.hysteresis import identification as hid
    from sma_wrist.core.thermal import identification as tid

    def no_fit(*a: object, **k: object) -> None:
        raise AssertionError('fitted before checking --out')

    for mod, name in ((hid, 'fit_gpi'), (hid, 'fit_sdgpi'), (hid, 'fit_sdgpi_cc'), (tid, 'identify_thermal')):
        monkeypatch.setattr(mod, name, no_fit)
    f = tmp_path / 'report'
    f.write_text('mine')
    flex = DATA / 'flexinol'
    for cmd in (
        ['hysteresis', str(flex / '50MPa.txt'), str(flex / '100MPa.txt')],
        ['thermal', str(flex / '50MPa.txt')],
    ):
        assert cli_main(['identify', *cmd, '--json', '--out', str(f)]) == 2
        assert json.loads(capsys.readouterr().out) == {
            'error': f'--out {f} is a file; give a folder for the report and the params file'
        }
    assert f.read_text() == 'mine'
    # a folder under a file; an output that is an input (the measured table was overwritten by --params-out);
    # a thermal file that cannot be read (found after the fit, which had replaced hysteresis.yaml by then)
    csv = tmp_path / 'run.csv'
    csv.write_text('time,u,T1\n0,0,20\n')
    for cmd, needed in (
        (['hysteresis', str(flex / '50MPa.txt'), '--out', str(f / 'sub')], f'--out {f / "sub"}: {f} is a file'),
        (
            ['thermal', str(csv), '--out', str(tmp_path / 'o'), '--params-out', str(csv)],
            f'--params-out {csv} is the input {csv}',
        ),
        (['thermal', str(csv), '--params-out', str(tmp_path)], f'--params-out {tmp_path} is a folder'),
        (
            [
                'hysteresis',
                str(flex / '50MPa.txt'),
                str(flex / '100MPa.txt'),
                str(flex / '200MPa.txt'),
                '--thermal-file',
                str(tmp_path / 'nope.yaml'),
                '--out',
                str(tmp_path / 'o2'),
            ],
            'nope.yaml',
        ),
    ):
        assert cli_main(['identify', *cmd, '--json']) == 2
        assert needed in json.loads(capsys.readouterr().out)['error']
    assert csv.read_text() == 'time,u,T1\n0,0,20\n' and not (tmp_path / 'o2').exists()


def test_temperature_dropouts_are_dropped_and_counted_not_read(tmp_path: Path, loop: np.ndarray) -> None:
    """A logger that drops to 0 for a few samples: dropped and counted, and a kelvin file stays in kelvin."""
    m = read_measurement(NITIPD, Units(length_mm=200.0))  # the real export: its chamber channel reads 0.00 at times
    raw = read_table(NITIPD).data[:, 3]
    assert m.counts['temperature_spikes'] == 87  # of its 138 zeros; nothing else: the count of zeros drops by as many
    assert np.sum(raw == 0.0) - np.sum(m.T_C == 0.0) == 87
    assert any('sensor spikes or dropouts' in w for w in m.warnings)
    T = loop[:, 0] + 273.15
    T[[50, 51, 300]] = 0.0  # dropouts in a kelvin column; before, one zero made the whole file read as degC
    (tmp_path / 'k.txt').write_text(
        'T, strain, stress\n' + ''.join(f'{a},{b},{c}\n' for a, (b, c) in zip(T, loop[:, 1:]))
    )
    k = read_measurement(tmp_path / 'k.txt')
    assert k.counts['temperature_spikes'] == 3 and k.T_C.size == loop.shape[0] - 3
    assert np.allclose(k.T_C, np.delete(loop[:, 0], [50, 51, 300]), atol=1e-9)
    assert read_measurement(LOOP).counts['temperature_spikes'] == 0  # a real sweep is not a spike


def test_a_mat_reader_that_crashes_is_an_error_not_a_crash(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """scipy's .mat reader segfaulted on a file with a few flipped bytes: it runs in a child process."""
    from sma_wrist.identify import io

    scipy.io.savemat(tmp_path / 'x.mat', {'T': np.arange(30.0), 'strain': np.zeros(30)})
    monkeypatch.setattr(io, '_LOADMAT', 'import os; os.abort()')  # stands for the crash
    with pytest.raises(io.IdentifyInputError, match=r'x.mat: not a readable MATLAB .mat file \(the reader stopped'):
        read_measurement(tmp_path / 'x.mat')


def test_load_ramps_between_levels_in_one_file_are_not_one_level(loop: np.ndarray) -> None:
    """The raw multi-load export: ~970 ramp samples bridged the gaps and made 5 loads one (100 MPa)."""
    levels, label = stress_levels(read_measurement(NITIPD, Units(length_mm=200.0)).stress_MPa)
    assert np.allclose(levels, [22.1, 50.1, 99.9, 150.2, 199.9], atol=0.5)
    assert 900 < np.sum(label == -1) < 1100
    # a single noisy level (this loop's stress column scatters +-3 MPa) stays one level, as before
    lv, _ = stress_levels(loop[:, 2])
    assert len(lv) == 1 and abs(lv[0] - 100.0) < 0.5


def test_identify_on_measured_nitipd_multiload_export(tmp_path: Path) -> None:
    """The raw NiTiPd export (5 loads in one file), 100 MPa held out: its rows moved to a second file unchanged.

    Clausius-Clapeyron law on 22 / 50 / 150 / 200 MPa, no leave-one-load-out (~10 s). Bounds are
    the measured values (doc/howto/identify_wire.md) with margin; gauge length assumed 200 mm
    (errors in % of stroke do not depend on it).
    """
    lines = NITIPD.read_text().splitlines()
    head, rows = lines[:6], [r for r in lines[6:] if r.strip()]
    hold = [r for r in rows if abs(float(r.split(',')[5]) - 100.0) < 5.0]
    train = [r for r in rows if abs(float(r.split(',')[5]) - 100.0) >= 5.0]
    (tmp_path / 'train.txt').write_text('\n'.join(head + train) + '\n')
    (tmp_path / 'hold100.txt').write_text('\n'.join(head + hold) + '\n')
    r = run(
        Options(
            [str(tmp_path / 'train.txt')],
            [str(tmp_path / 'hold100.txt')],
            out=str(tmp_path / 'out'),
            length_mm=200.0,
            loo=False,
            plots=False,
            model='clausius-clapeyron',
        ),
        progress=_quiet,
    )
    fit = {round(d['stress_MPa']): d for d in r['fit']['per_load']}
    assert sorted(fit) == [22, 50, 150, 200]
    # measured GPI 0.90 / 0.90 / 1.68 / 1.72 %, SD-GPI 4.79 / 3.13 / 5.76 / 5.17 % of stroke
    for f in fit.values():
        assert f['gpi_rms_pct'] < 2.0 and f['sdgpi_rms_pct'] < 6.5, f
    (h,) = r['holdout']
    # measured 5.46 / 9.86 % (SD-GPI 5.27 % of stroke overall on the training loads), identical with numpy's AVX-512
    # or AVX2 loops and OpenBLAS's default or Haswell kernel (doc/howto/identify_wire.md)
    assert h['rms_pct'] < 7.0 and h['max_pct'] < 14.0, h
    # the built-in wire (30-80 degC) is far off this one (-45..+40 degC)
    assert min(b['rms_pct'] for b in r['before']['per_load']) > 25.0
    sl = r['transitions']['slopes_per_MPa']
    assert sl['measured']['A_50'] > 0.1 and sl['fitted']['A_50'] > 0.1


def test_a_folder_of_loops_is_its_tables_and_a_held_out_loop_is_never_fitted(tmp_path: Path) -> None:
    """`identify hysteresis test/data/flexinol` read "Is a directory" before; a folder is now its tables (the data
    set's README.md and LICENSE are not), and a held-out table inside it stays out of the fit."""
    from sma_wrist.identify.io import IdentifyInputError, expand_folders

    folder = DATA / 'flexinol'
    tables = [str(folder / f'{s}MPa.txt') for s in (100, 150, 172, 200, 50)]  # sorted by name
    assert expand_folders([str(folder)]) == tables
    assert expand_folders([str(folder)], exclude=[tables[3]]) == tables[:3] + tables[4:]
    assert expand_folders([str(LOOP), str(folder / 'README.md')]) == [
        str(LOOP),
        str(folder / 'README.md'),
    ]  # files as given
    (tmp_path / 'notes.md').write_text('no tables here')
    with pytest.raises(IdentifyInputError, match='a folder with no table in it'):
        expand_folders([str(tmp_path)])
    doc = run(Options([str(folder)], [tables[3]], '', loo=False, plots=False, model='quadratic'), progress=_quiet)
    fitted = sorted(round(r['stress_MPa']) for r in doc['fit']['per_load'])
    assert fitted == [50, 100, 150, 172] and [round(h['stress_MPa']) for h in doc['holdout']] == [200]


@pytest.mark.parametrize('first,second', [(1.0, 100.0), (100.0, 1.0)])
def test_a_strain_column_that_switches_between_fraction_and_percent_is_refused(
    tmp_path: Path, loop: np.ndarray, first: float, second: float
) -> None:
    """A logger switched its strain column from fraction to % (or back) halfway through the measured loop: the whole
    column was read as % (its largest value says so), the fraction half 100x too small, without a word."""
    half = len(loop) // 2
    strain = np.concatenate([first * loop[:half, 1], second * loop[half:, 1]])
    p = tmp_path / 'switched.csv'
    p.write_text(
        'temperature,strain,stress\n'
        + ''.join(f'{a:.4f},{b:.6g},{c:.3f}\n' for a, b, c in zip(loop[:, 0], strain, loop[:, 2]))
    )
    with pytest.raises(SmaWristError, match=f'strain column changes scale at row {half}'):
        read_measurement(str(p), Units())
    p.write_text('temperature,strain,stress\n' + ''.join(f'{a:.4f},{b:.6g},{c:.3f}\n' for a, b, c in loop))
    m = read_measurement(str(p), Units())  # the same loop in one unit reads
    assert np.allclose(m.strain, loop[:, 1], atol=1e-6)


def test_no_measured_column_is_taken_for_a_unit_switch() -> None:
    """Every column of every measured table in test/data (strains, temperatures, stresses, times of wires this
    project did not make, sharp NiTiHf transformations among them) is free of the switch scale_switch looks for."""
    tables = 0
    for f in sorted(DATA.rglob('*')):
        if f.suffix not in ('.txt', '.csv') or f.name in ('SOURCE.txt',):
            continue
        try:
            t = read_table(str(f))
        except SmaWristError:
            continue
        tables += 1
        for j in range(t.data.shape[1]):
            col = t.data[:, j]
            assert scale_switch(col[np.isfinite(col)]) is None, (f, j)
    assert tables >= 30
