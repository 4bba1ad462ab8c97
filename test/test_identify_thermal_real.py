"""sma-wrist identify thermal on a real Peltier module this project did not build or simulate.

test/data/tec_chamber (MIT, its README): a chamber heated by one 12706 module under a PID loop that logged one
row per second, without a time column; only the chamber's temperature and the PWM duty were recorded. What the
fit must do on it: predict the module's other runs far better than Table 4.9 does, and say what such data cannot
determine (a parameter on its bound, a fit that did not converge, a held-out run beyond the fitted range).

Bounds are the measurements of 2026-11-28 with margin (doc/howto/identify_tems.md): held-out
RMS 0.58 / 0.62 degC on runs 39 / 16 against Table 4.9's 2.05 / 2.13 degC.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

DATA = Path(__file__).parent / 'data' / 'tec_chamber'
TABLE = ['--columns', 'u=u_V,T1=oven_c', '--sample-period-s', '1', '--dt', '1']


@pytest.fixture(scope='module')
def tables(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp('tec_chamber')
    from sma_wrist.identify.thermal import tec_chamber_volts

    return {
        n: tec_chamber_volts(DATA / f'{n}.csv', d / f'{n}.csv') for n in ('run40', 'run39', 'run16', 'rtempco_run1')
    }


def test_the_logged_pwm_duty_becomes_the_mean_drive_voltage(tmp_path: Path) -> None:
    """duty / 255 x 5 V, the chamber and room temperatures as logged; rtempco_run1.csv's missing header changes nothing."""
    from sma_wrist.identify.thermal import tec_chamber_volts

    rows = '25.000,23.756,205.00,20.675\n25.000,23.754,0,20.664\n26.000,25.1,255,20.7\n'
    want = 'u_V,oven_c,ambient_c\n4.019608,23.756,20.675\n0.000000,23.754,20.664\n5.000000,25.1,20.7\n'
    for name, text in (('headed', 'set_c,oven_c,output,ambient_c\n' + rows), ('bare', rows)):
        (tmp_path / f'{name}.csv').write_text(text)
        assert tec_chamber_volts(tmp_path / f'{name}.csv', tmp_path / f'{name}_V.csv').read_text() == want, name


def _cli(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, dict]:
    from sma_wrist.cli import main

    capsys.readouterr()
    code = main(['identify', 'thermal', *args, '--json', '--no-plots'])
    return code, json.loads(capsys.readouterr().out)


def test_a_fit_on_one_real_run_predicts_the_modules_other_runs(tables, capsys, tmp_path) -> None:
    code, s = _cli(
        [
            str(tables['run40']),
            '--holdout',
            str(tables['run39']),
            str(tables['run16']),
            *TABLE,
            '--out',
            str(tmp_path / 'out'),
        ],
        capsys,
    )
    assert code == 0, s
    before = {e['record']: e['faces']['T1']['rms_C'] for e in s['before']}
    files = [e for e in s['holdout'] if e['mode'] == 'holdout-file']
    assert [e['record'] for e in files] == ['run39.csv', 'run16.csv']
    for e in files:
        rms = e['faces']['T1']['rms_C']
        assert rms < 0.75 and rms < 0.4 * before[e['record']], (e['record'], rms, before[e['record']])
    # heating only and one face: the loss term K_R is not determined, and the user is told so
    assert any('T1 K_R = 0 (lower bound)' in w for w in s['warnings']), s['warnings']
    assert any("the model's cooling (u < 0) is extrapolated" in w and 'to +4.0 V' in w for w in s['warnings'])
    assert s['fit']['message'].startswith('converged') or any('error still falling' in w for w in s['warnings'])


def test_the_chambers_sensor_lag_is_what_the_two_node_model_missed(tables, capsys, tmp_path) -> None:
    """The thermistor sits on an aluminium box the heat balance does not have: fitted with one first-order sensor
    lag (--sensor-lag), the same fit predicts the other runs markedly better (measured 0.58 / 0.62 -> 0.35 / 0.37
    degC, lag 196 s)."""
    runs = [str(tables['run40']), '--holdout', str(tables['run39']), str(tables['run16']), *TABLE]
    _, plain = _cli(runs, capsys)
    code, lagged = _cli([*runs, '--sensor-lag', '--out', str(tmp_path / 'out')], capsys)
    assert code == 0, lagged
    report = (tmp_path / 'out' / 'thermal_identification.md').read_text()
    assert f'`--sensor-lag`): {lagged["fit"]["sensor_lag_s"]:.4g} s' in report
    assert 60.0 < lagged['fit']['sensor_lag_s'] < 600.0, lagged['fit']['sensor_lag_s']
    assert plain['fit']['sensor_lag_s'] is None

    def held(s: dict) -> dict[str, float]:
        return {e['record']: e['faces']['T1']['rms_C'] for e in s['holdout'] if e['mode'] == 'holdout-file'}

    for run, rms in held(lagged).items():
        assert rms < 0.45 and rms < 0.75 * held(plain)[run], (run, rms, held(plain)[run])


def test_a_held_out_run_beyond_the_fitted_range_is_named_extrapolation(tables, capsys) -> None:
    """Short runs near 25-26 degC predicting the 25-35 degC staircase: the error that follows is extrapolation."""
    code, s = _cli(
        [str(tables[n]) for n in ('run40', 'run39', 'run16')] + ['--holdout', str(tables['rtempco_run1']), *TABLE],
        capsys,
    )
    assert code == 0, s
    said = [w for w in s['warnings'] if 'rtempco_run1.csv' in w and 'extrapolation' in w]
    assert len(said) == 1 and 'T1 24.9..35.0 degC' in said[0], s['warnings']
    # the fitted runs themselves are not named
    assert not any('hold-out run run' in w for w in s['warnings']), s['warnings']
    # a PID's staircase is no sine: no frequency (it was labelled 1/9400 Hz)
    assert [e['frequency_Hz'] for e in s['holdout'] if e['record'] == 'rtempco_run1.csv'] == [None]


def test_the_same_runs_with_a_time_column_give_the_same_fit(tables, capsys, tmp_path) -> None:
    """--sample-period-s is the time column the logger did not write: row k at k periods."""
    timed = tmp_path / 'run40_timed.csv'
    lines = tables['run40'].read_text().splitlines()
    timed.write_text('\n'.join(['time_s,' + lines[0]] + [f'{k},{x}' for k, x in enumerate(lines[1:])]) + '\n')
    code, a = _cli([str(tables['run40']), *TABLE], capsys)
    code2, b = _cli([str(timed), '--columns', 'time=time_s,u=u_V,T1=oven_c', '--dt', '1'], capsys)
    assert code == code2 == 0
    assert a['fit']['params'] == b['fit']['params'] and a['fit']['rms_C'] == b['fit']['rms_C']


@pytest.mark.parametrize(
    'extra, says',
    [
        ([], '--sample-period-s S'),  # no time column and no period: the error names the option
        (['--sample-period-s', '0'], 'must be a number of seconds > 0'),
        (['--sample-period-s', 'nan'], 'must be a number of seconds > 0'),
        (['--sample-period-s', '1', '--time-unit', 'ms'], '--time-unit is the unit of a time column'),
    ],
)
def test_a_table_without_time_needs_a_valid_period(tables, capsys, extra, says) -> None:
    code, s = _cli([str(tables['run39']), '--columns', 'u=u_V,T1=oven_c', *extra], capsys)
    assert code == 2 and says in s['error'], s


def test_a_period_for_a_table_that_has_time_is_refused(tmp_path, capsys) -> None:
    f = tmp_path / 'timed.csv'
    f.write_text('time,u,T1\n' + ''.join(f'{k},{(k % 20) / 4},{25 + k / 100}\n' for k in range(200)))
    code, s = _cli([str(f), '--sample-period-s', '1'], capsys)
    assert code == 2 and 'has one (time)' in s['error'], s


def test_a_headerless_table_with_a_period_reads_u_and_t1_from_the_left(tmp_path, capsys) -> None:
    from sma_wrist.identify.thermal import load_table

    f = tmp_path / 'bare.csv'
    f.write_text(''.join(f'{(k % 20) / 4},{25 + k / 100}\n' for k in range(200)))
    (s,), cl = load_table(f, sample_period_s=0.5)
    assert s.t[-1] == pytest.approx(99.5) and s.u[5] == pytest.approx(1.25) and s.T[1, 0] == pytest.approx(25.01)
    assert any('u [V], T1 [degC]' in w and 'time' not in w for w in cl.warnings), cl.warnings
