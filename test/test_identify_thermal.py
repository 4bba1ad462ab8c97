"""sma-wrist identify thermal: the heat-balance fit (Table 4.9) on own-model and off-model data,
the params file, the CLI's input handling, and a closed loop that loads the identified file.

Bounds are measured (doc/explanation/model.md, the heat-balance forms held out per frequency): own-model
noise-free data must come back exactly; the independent Peltier plant (sma_wrist/identify/thermal_testplant.py: back-EMF,
Kelvin Peltier term, convection law, thermocouple lag 0.15 s, noise 0.2 degC) is held out per
frequency and must beat Table 4.9 by a wide margin.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from sma_wrist.core.errors import ParameterError
from sma_wrist.core.thermal import heat_balance as th
from sma_wrist.core.thermal import identification as ti
from sma_wrist.core.thermal.params_file import load_thermal_file, write_thermal_file
from sma_wrist.identify.thermal_testplant import sine_runs

FREQS = (1 / 128, 1 / 32, 1 / 8)


def _write_csv(path: Path, rec: ti.ThermalRecord, rows: slice = slice(None)) -> Path:
    t = np.arange(rec.n) * rec.dt
    data = np.c_[t, rec.u, rec.T][rows]
    np.savetxt(path, data, delimiter=',', header='time [s],u [V],T1 [degC],T2 [degC]', comments='', fmt='%.5f')
    return path


@pytest.fixture(scope='module')
def peltier_runs() -> list[ti.ThermalRecord]:
    return sine_runs('peltier', frequencies_Hz=FREQS, duration_s=200.0, sample_dt=0.2, noise_C=0.2, lag_s=0.15, seed=3)


def _zoh_runs(p: th.ThermalParams, n: int = 400, dt: float = 0.2) -> list[ti.ThermalRecord]:
    """The own model under sampled-and-held 12 V sines (exactly the fitted model class)."""
    u = 12.0 * np.sin(2 * np.pi * np.outer(np.arange(n) * dt, FREQS))
    X = th.simulate(p, u[:-1, :, None], dt, th.rest_state(p, len(FREQS), 1))[:, :, 0]
    return [ti.ThermalRecord(f'r{j}', dt, u[:, j], X[:, j], FREQS[j]) for j in range(len(FREQS))]


def test_simulation_is_the_thermal_step_rk4() -> None:
    p = th.ThermalParams()
    recs = _zoh_runs(p)
    sims = ti.simulate_records(p, recs)
    assert max(np.abs(s - r.T).max() for s, r in zip(sims, recs)) < 1e-9


def _assert_jacobian_is_central_differences(prob: ti._Problem, x: np.ndarray) -> None:
    J = prob.jacobian(x)
    for j in (0, 4, 5, 8):
        h = 1e-6 * max(abs(x[j]), 1e-3)
        e = np.zeros_like(x)
        e[j] = h
        fd = (prob.residuals(x + e) - prob.residuals(x - e)) / (2 * h)
        assert np.allclose(J[:, j], fd, rtol=1e-5, atol=1e-9 * np.abs(fd).max())


def test_complex_step_jacobian_matches_central_differences() -> None:
    recs = sine_runs('own', frequencies_Hz=(1 / 32,), duration_s=60.0, sample_dt=0.2, noise_C=0.0, lag_s=0.0)
    prob = ti._Problem(recs, th.ThermalParams(), (0, 1), None, 30.0)
    x = ti._free_from_table(ti.table_of(th.ThermalParams()), (0, 1)) * 1.1
    _assert_jacobian_is_central_differences(prob, x)


def test_own_model_round_trip_recovers_table_4_9_from_a_wrong_start() -> None:
    truth = th.ThermalParams()
    recs = _zoh_runs(truth)
    rng = np.random.default_rng(1)
    wrong = ti.params_from_table(ti.table_of(truth) * (1 + 0.25 * rng.standard_normal((2, 6))), truth)
    fit = ti.fit_thermal(recs, wrong)
    rel = np.abs(ti.table_of(fit.params) / ti.table_of(truth) - 1)
    assert rel.max() < 1e-4  # measured ~1e-9
    assert fit.rms_C < 1e-4


def test_sensor_lag_is_recovered_with_the_table_and_its_jacobian_is_exact() -> None:
    """Own-model runs read through a 2 s sensor lag (the model class of --sensor-lag): the fit finds the lag and the
    table; without the option the table absorbs the lag and misses. The lag's complex-step column equals central
    differences."""
    from sma_wrist.core.signals import first_order

    truth = th.ThermalParams()
    recs = [dataclasses.replace(r, T=first_order(r.T, 2.0, r.dt)) for r in _zoh_runs(truth)]
    fit = ti.fit_thermal(recs, sensor_lag=True)
    assert fit.sensor_lag_s == pytest.approx(2.0, rel=1e-4) and fit.rms_C < 1e-4  # measured: exact to ~1e-9
    assert np.abs(ti.table_of(fit.params) / ti.table_of(truth) - 1).max() < 1e-3
    assert ti.fit_thermal(recs).rms_C > 100 * fit.rms_C
    prob = ti._Problem(recs, truth, (0, 1), None, 30.0, sensor_lag=True)
    x = np.r_[ti._free_from_table(ti.table_of(truth), (0, 1)), 1.5]
    h = 1e-6
    e = np.zeros_like(x)
    e[-1] = h
    fd = (prob.residuals(x + e) - prob.residuals(x - e)) / (2 * h)
    assert np.allclose(prob.jacobian(x)[:, -1], fd, rtol=1e-5, atol=1e-9 * np.abs(fd).max())
    ev = ti.evaluate(fit.params, recs, 'in-sample', sensor_lag_s=fit.sensor_lag_s)
    assert max(e.faces[f]['rms_C'] for e in ev for f in e.faces) < 1e-3


def test_a_known_muscle_thermocouple_lag_is_fitted_through_and_its_jacobian_is_exact() -> None:
    """Own-model runs whose muscle face is read through a 0.2 s thermocouple lag, the exchanger face as is (a model
    with ``temp_lag_s``): given the lag, the fit recovers the table of the node; without it the table absorbs the
    lag. The complex-step Jacobian through the lag equals central differences."""
    truth = th.ThermalParams()
    recs = [dataclasses.replace(r, T=ti.muscle_lagged(r.T[:, None], 0.2, r.dt)[:, 0]) for r in _zoh_runs(truth, n=300)]
    assert all(np.array_equal(r.T[:, 1], q.T[:, 1]) for r, q in zip(recs, _zoh_runs(truth, n=300)))
    fit = ti.fit_thermal(recs, muscle_lag_s=0.2)
    assert fit.muscle_lag_s == 0.2 and fit.rms_C < 1e-4  # measured ~1e-9
    assert np.abs(ti.table_of(fit.params) / ti.table_of(truth) - 1).max() < 1e-3
    assert ti.fit_thermal(recs).rms_C > 100 * fit.rms_C
    ev = ti.evaluate(fit.params, recs, 'in-sample', muscle_lag_s=0.2)
    assert max(e.faces[f]['rms_C'] for e in ev for f in e.faces) < 1e-3
    prob = ti._Problem(recs, truth, (0, 1), None, 30.0, muscle_lag_s=0.2)
    x = ti._free_from_table(ti.table_of(truth), (0, 1)) * 1.1
    _assert_jacobian_is_central_differences(prob, x)


def test_muscle_face_only_runs_fit_the_t1_column_and_validate_by_time_split() -> None:
    r = _zoh_runs(th.ThermalParams(), n=1200)[1]
    r = dataclasses.replace(r, T=np.c_[r.T[:, 0], np.full(r.n, np.nan)])
    res = ti.identify_thermal([r])
    assert res.validation == 'time-split' and res.fit.faces == (0,)
    assert set(res.holdout[0].faces) == {'T1'}
    assert res.holdout[0].faces['T1']['rms_C'] < 1e-3  # own model, exact exchanger column: measured ~1e-8


def test_off_model_peltier_plant_held_out_per_frequency(peltier_runs: list[ti.ThermalRecord]) -> None:
    res = ti.identify_thermal(peltier_runs)
    assert res.validation == 'leave-one-out' and len(res.holdout) == len(FREQS)
    before = {e.record: e for e in res.before}
    for e in res.holdout:
        for face, st in e.faces.items():
            default = before[e.record].faces[face]['rms_C']
            # measured (seed 3): held-out RMS 0.25-0.95 degC vs Table 4.9's 1.6-8.5 degC
            assert st['rms_C'] < 1.3, (e.record, face, st['rms_C'])
            assert st['rms_C'] < 0.5 * default, (e.record, face, st['rms_C'], default)
            assert abs(st['mean_pct']) < 6.0 and st['std_pct'] < 5.0


def test_fit_needs_an_exciting_input_and_t2_for_both_columns() -> None:
    r = sine_runs('own', frequencies_Hz=(1 / 32,), duration_s=60.0, sample_dt=0.2, noise_C=0.0, lag_s=0.0)[0]
    flat = dataclasses.replace(r, u=np.full(r.n, 3.0), u2=None)
    with pytest.raises(ti.ThermalIdentificationError, match='exciting input'):
        ti.fit_thermal([flat])
    no_t2 = dataclasses.replace(r, T=np.c_[r.T[:, 0], np.full(r.n, np.nan)])
    with pytest.raises(ti.ThermalIdentificationError, match='T2'):
        ti.fit_thermal([no_t2], faces='both')
    with pytest.raises(ti.ThermalIdentificationError, match='two runs'):
        ti.identify_thermal([r], validation='leave-one-out')


# ------------------------------------------------------------------------------ params file


def test_thermal_file_round_trip_and_hold_limits(tmp_path: Path) -> None:
    p = th.ThermalParams()
    lo, hi = ti.hold_limits(p, resolution_V=0.1)
    assert (lo, hi) == (p.u_min_V, p.u_max_V)  # the documented defaults come back: -12 / +13 V
    f = write_thermal_file(tmp_path / 'thermal.yaml', p.with_limits(lo, hi), {'note': 'x'}, header='test')
    q = load_thermal_file(f)
    assert np.allclose(ti.table_of(q), ti.table_of(p), rtol=0, atol=1e-15)
    assert (q.u_min_V, q.u_max_V, q.input_per_volt) == (lo, hi, p.input_per_volt)


@pytest.mark.parametrize(
    'text, match',
    [
        (None, 'cannot read'),
        ('a: [1, 2', 'not a YAML'),
        ('format: other\nversion: 1\n', 'not a thermal file'),
        ('format: sma_wrist/thermal\nversion: 7\n', 'version 7'),
        ('format: sma_wrist/thermal\nversion: 1\nmuscle_fase: {}\n', 'unknown key'),
        (b'\x89HDF\r\n\x1a\n\xff\xfe' * 8, 'not a UTF-8 text'),
    ],
)
def test_thermal_file_errors_name_the_file(tmp_path: Path, text: str | bytes | None, match: str) -> None:
    f = tmp_path / 'thermal.yaml'
    if isinstance(text, bytes):
        f.write_bytes(text)
    elif text is not None:
        f.write_text(text)
    with pytest.raises(ParameterError, match=match) as e:
        load_thermal_file(f)
    assert str(f) in str(e.value)


def test_thermal_file_rejects_nan_and_a_face_without_loss(tmp_path: Path) -> None:
    f = write_thermal_file(tmp_path / 't.yaml', th.ThermalParams())
    text = f.read_text()
    f.write_text(text.replace('K_R: 0.012524', 'K_R: .nan', 1))
    with pytest.raises(ParameterError, match='finite'):
        load_thermal_file(f)
    f.write_text(text.replace('K_T_inf: 0.052345', 'K_T_inf: 0.01', 1))
    with pytest.raises(ParameterError, match='loss to ambient'):
        load_thermal_file(f)


# ------------------------------------------------------------------------------ CLI


def _cli(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, dict]:
    from sma_wrist.cli import main

    code = main(['identify', 'thermal', *args, '--json'])
    out = capsys.readouterr().out
    return code, json.loads(out)


@pytest.fixture(scope='module')
def identified(peltier_runs: list[ti.ThermalRecord], tmp_path_factory: pytest.TempPathFactory) -> dict:
    """CLI run on dirty CSVs of the Peltier plant: two fitted files, the third held out."""
    d = tmp_path_factory.mktemp('identify_thermal')
    files = [_write_csv(d / f'run{j}.csv', r) for j, r in enumerate(peltier_runs)]
    lines = files[0].read_text().splitlines()
    # dirt: a NaN row, a duplicate stamp, two rows swapped
    lines.insert(20, '3.9,nan,30.0,30.0')
    lines.insert(40, lines[39])
    lines[60], lines[61] = lines[61], lines[60]
    files[0].write_text('\n'.join(lines) + '\n')
    import contextlib
    import io

    from sma_wrist.cli import main

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = main(
            [
                'identify',
                'thermal',
                str(files[0]),
                str(files[1]),
                '--holdout',
                str(files[2]),
                '--dt',
                '0.2',
                '--out',
                str(d / 'out'),
                '--json',
            ]
        )
    return {'code': code, 'json': json.loads(buf.getvalue()), 'dir': d}


def test_cli_identifies_counts_the_cleaning_and_writes_report_and_params(identified: dict) -> None:
    assert identified['code'] == 0
    s = identified['json']
    assert {'fit', 'holdout', 'params_file', 'wall_s', 'before'} <= set(s)
    c = next(v for k, v in s['cleaning'].items() if k.endswith('run0.csv'))
    assert (c['dropped_nan'], c['duplicates'], c['unsorted']) == (1, 1, 1)
    modes = [h['mode'] for h in s['holdout']]
    assert modes == ['leave-one-out', 'leave-one-out', 'holdout-file']
    held = s['holdout'][-1]
    assert held['frequency_Hz'] == pytest.approx(1 / 8)
    assert held['faces']['T1']['rms_C'] < 1.0  # measured ~0.3 (Table 4.9: 1.6)
    out = identified['dir'] / 'out'
    assert (out / 'thermal_identification.md').exists() and len(list(out.glob('*.png'))) == 4
    p = load_thermal_file(s['params_file'])
    assert (p.u_min_V, p.u_max_V) == tuple(s['hold_limits_V'])


@pytest.mark.parametrize(
    'content, match',
    [
        ('', 'empty file'),
        ('time,u\n0,1\n1,2\n', 'no column for T1'),
        ('time,u,T1\n' + ''.join(f'{k},{5000 * math.sin(k / 5)},{30 + k * 0.01}\n' for k in range(400)), 'not volts'),
        ('time,u,T1\n' + ''.join(f'{k * 0.1},{12 * math.sin(k / 5)},{30.0}\n' for k in range(100)), 'covers only'),
        ('time,u,T1\n' + ''.join(f'{k * 0.1},{12 * math.sin(k / 5)},{900.0}\n' for k in range(400)), 'not a TEM face'),
        ('time,u,T1\n' + ''.join(f'{k * 0.1},2.0,{30 + k * 0.001}\n' for k in range(400)), 'exciting input'),
        ('time,u,T1,tem\n' + ''.join(f'{k * 0.1},{12 * math.sin(k / 5)},30,3\n' for k in range(400)), 'tem column'),
    ],
)
def test_cli_bad_input_gives_json_error_and_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], content: str, match: str
) -> None:
    f = tmp_path / 'bad.csv'
    f.write_text(content)
    code, out = _cli([str(f)], capsys)
    assert code == 2 and match in out['error'] and 'bad.csv' in out['error']


def test_cli_missing_file_and_bad_columns(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, out = _cli([str(tmp_path / 'nope.csv')], capsys)
    assert code == 2 and 'no such file' in out['error']
    f = tmp_path / 'x.csv'
    f.write_text('a,b,c\n1,2,3\n')
    code, out = _cli([str(f), '--columns', 'time=a,u=b,T1=zz'], capsys)
    assert code == 2 and 'zz' in out['error']


def test_kelvin_and_millisecond_headers_are_converted(tmp_path: Path, peltier_runs: list[ti.ThermalRecord]) -> None:
    from sma_wrist.identify.thermal import load_table

    r = peltier_runs[1]
    f = tmp_path / 'k.tsv'
    t = np.arange(r.n) * r.dt * 1000.0
    np.savetxt(
        f, np.c_[t, r.u * 1000.0, r.T[:, 0] + 273.15], delimiter='\t', header='Time [ms]\tu [mV]\tT1 [K]', comments=''
    )
    series, cl = load_table(f)
    assert np.allclose(series[0].t, np.arange(r.n) * r.dt) and np.allclose(series[0].u, r.u, atol=1e-6)
    assert np.allclose(series[0].T[:, 0], r.T[:, 0], atol=1e-6) and np.isnan(series[0].T[:, 1]).all()


# ------------------------------------------------------------------------------ in the wrist


def _tem_loop(
    plant_file: str | None,
    controller_file: str | None,
    bag: Path | None = None,
    phases: tuple = (((45.0, 35.0), 40.0), ((35.0, 45.0), 40.0)),
    adapt: bool = False,
) -> list[np.ndarray]:
    """plant_sim + tem_controller on the embedded runtime, muscle targets held per phase; returns
    the measured muscle temperatures (100 Hz) and records a bag when asked. ``adapt``: tem_controller's
    thermal_adaptation (off: the law runs the file as loaded)."""
    from conftest import Probe  # type: ignore[import-not-found]

    from sma_wrist.nodes.plant_sim import PlantSim
    from sma_wrist.nodes.tem_controller import TemController
    from sma_wrist.runtime.launch import Runtime

    params: dict = {
        '/plant_sim': {'use_sim_time': False},
        '/tem_controller': {'use_sim_time': True, 'thermal_adaptation.enabled': adapt},
    }
    if plant_file:
        params['/plant_sim']['thermal_file'] = plant_file
    if controller_file:
        params['/tem_controller']['thermal_file'] = controller_file
    with Runtime(params=params) as rt:
        if bag is not None:
            rt.record(bag)
        probe = Probe(rt, ('/wrist/muscle_1/temperature', '/wrist/muscle_2/temperature'), sim_time=True)
        rt.add(PlantSim)
        rt.add(TemController)
        t = 0.0
        for targets, seconds in phases:
            timers = [
                probe.every(0.01, f'/wrist/muscle_{i}/temperature_desired', temperature=targets[i - 1]) for i in (1, 2)
            ]
            t += seconds
            rt.run_until(t, until='sim')
            for tm in timers:
                tm.cancel()
        return [np.array([m.temperature for m in probe.got[f'/wrist/muscle_{i}/temperature']]) for i in (1, 2)]


def test_identified_file_runs_in_the_closed_tem_loop_on_the_embedded_runtime(identified: dict) -> None:
    """plant_sim and tem_controller load the same identified file: the feedback-linearising loop
    holds the targets exactly; with the file in the plant only, the law's model is wrong and a
    steady error remains (measured 2e-6 vs 0.17 degC), which proves the controller loaded it. Both
    with the law on the file as loaded (thermal_adaptation off: its estimate assumes a 0.1 s
    thermocouple lag this plant has not, and moves the exact model by ~0.007 degC)."""
    f = identified['json']['params_file']
    both = _tem_loop(f, f)
    plant_only = _tem_loop(f, None)
    for T, target in zip(both, (35.0, 45.0)):
        assert np.abs(T[-500:] - target).max() < 1e-3
    assert max(np.abs(plant_only[0][-500:] - 35.0).max(), np.abs(plant_only[1][-500:] - 45.0).max()) > 0.03
    # learning the TEMs online (thermal_adaptation, off above) takes most of that error without the file:
    # measured 0.31 / 0.16 -> 0.13 / 0.045 degC (the file differs from Table 4.9 beyond the three scales it learns)
    adapted = _tem_loop(f, None, adapt=True)
    for T, off, target in zip(adapted, plant_only, (35.0, 45.0)):
        assert np.abs(T[-500:] - target).max() < 0.5 * np.abs(off[-500:] - target).max()


def test_cli_identifies_the_muscle_faces_from_a_recorded_bag(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A bag of plant_sim + tem_controller (targets switched at 40 s): each muscle is a run, only
    T1 is published, so the T1 column is fitted and each muscle predicted from the other."""
    bag = tmp_path / 'bag'
    _tem_loop(None, None, bag)
    code, s = _cli([str(bag), '--out', str(tmp_path / 'out')], capsys)
    assert code == 0, s
    assert s['fit']['faces_fitted'] == ['T1'] and s['validation'] == 'leave-one-out'
    assert [h['record'] for h in s['holdout']] == ['bag muscle 1', 'bag muscle 2']
    # a simulated wrist reads no drive back: the commands are the drive, and the report says so
    assert s['cleaning'][str(bag)]['drive'] == 'commanded'
    assert f'TEM drive of {bag}: the commands' in Path(s['report']).read_text()
    for h, b in zip(s['holdout'], s['before']):
        assert set(h['faces']) == {'T1'}
        # own-model data: Table 4.9 is the truth (measured RMS 0.0007/0.002 degC); held out by the
        # other muscle's fit: measured 0.022 / 0.0008 degC
        assert h['faces']['T1']['rms_C'] < 0.1 and b['faces']['T1']['rms_C'] < 0.01


def test_nodes_refuse_a_bad_thermal_file(tmp_path: Path) -> None:
    from sma_wrist.core.errors import SmaWristError
    from sma_wrist.nodes.tem_controller import TemController
    from sma_wrist.runtime.launch import Runtime

    with Runtime(params={'/tem_controller': {'thermal_file': str(tmp_path / 'missing.yaml')}}) as rt:
        with pytest.raises(SmaWristError, match='missing.yaml'):
            rt.add(TemController)


def test_a_frequency_column_with_blank_cells_takes_the_frequency_above(tmp_path: Path) -> None:
    """A blank frequency cell (or a frequency written on each block's first row only, as spreadsheets are often
    filled) made a run of no rows and an IndexError traceback. A blank now takes the frequency above it, rows
    before the first frequency are dropped, and the warning says how many."""
    from sma_wrist.identify.thermal import load_table

    t = np.arange(0.0, 80.0, 0.1)
    rows = [
        (0.0625 if k < t.size // 2 else 0.125, tk, 3.0 * math.sin(tk), 30.0 + math.sin(tk), 25.0)
        for k, tk in enumerate(t)
    ]
    lines = ['frequency,time,u,T1,T2'] + [','.join(f'{x:.4f}' for x in r) for r in rows]
    blank = [1, 3, 5, 200, t.size // 2 + 7]  # the first row keeps its frequency; one blank in the second block
    for i in blank:
        lines[1 + i] = lines[1 + i].split(',', 1)[1].join([',', ''])
    f = tmp_path / 'blocks.csv'
    f.write_text('\n'.join(lines) + '\n')
    series, cl = load_table(f)
    assert [s.frequency_Hz for s in series] == [0.0625, 0.125]
    assert sum(s.t.size for s in series) == t.size  # no row lost
    assert any('5 row(s) without a frequency took the one above' in w for w in cl.warnings)
    lines[1] = lines[1].split(',', 1)[1].join([',', ''])  # now rows 0 and 1 come before any frequency: dropped
    f.write_text('\n'.join(lines) + '\n')
    series, cl = load_table(f)
    assert sum(s.t.size for s in series) == t.size - 2
    assert any('2 before the first frequency dropped' in w for w in cl.warnings)


def test_a_humble_sqlite_bag_is_read_as_a_bag(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """identify thermal took a .db3 file (what `ros2 bag record` writes on Humble) for a text table ("a binary
    file") and a .db3 folder without metadata.yaml (a recorder that was killed) for no bag, while diagnose and
    compare read both. Both now identify as the MCAP bag they were converted from does."""
    import shutil

    from rosbags.rosbag2 import Reader, StoragePlugin, Writer

    from sma_wrist.cli import main
    from sma_wrist.runtime.messages import TYPESTORE as store

    bag, db3 = tmp_path / 'run', tmp_path / 'run_db3'
    assert main(['run', '--duration', '40', '--bag', str(bag), '--quiet']) == 0
    with Reader(bag) as r, Writer(db3, version=8, storage_plugin=StoragePlugin.SQLITE3) as w:
        conns = {c.id: w.add_connection(c.topic, c.msgtype, typestore=store) for c in r.connections}
        for c, t, raw in r.messages():
            w.write(conns[c.id], t, raw)
    bare = tmp_path / 'killed'
    bare.mkdir()
    shutil.copy(next(db3.glob('*.db3')), bare)
    capsys.readouterr()
    fits = []
    for source in (bag, next(db3.glob('*.db3')), bare):
        code, doc = _cli([str(source), '--dt', '0.2', '--out', str(tmp_path / f'out_{len(fits)}')], capsys)
        assert code == 0, doc
        fits.append(doc['fit']['rms_C'])
    assert fits[1] == fits[0] and fits[2] == fits[0]


def test_a_text_column_or_an_empty_t2_column_does_not_empty_the_table(tmp_path: Path) -> None:
    """A logger's status column ('OK' in every row) made every row non-numeric: "no numeric rows found", even with
    --columns. A T2 channel left empty dropped every row ("only 0 complete rows"). The text column is now read as
    no value and the empty T2 as absent, with a warning; the numbers are the same as without those columns."""
    from sma_wrist.identify.io import read_table
    from sma_wrist.identify.thermal import load_table

    t = np.arange(0.0, 60.0, 0.1)
    plain = tmp_path / 'plain.csv'
    plain.write_text('time,u,T1\n' + ''.join(f'{x:.1f},{math.sin(x):.4f},{30 + math.sin(x):.4f}\n' for x in t))
    status = tmp_path / 'status.csv'
    status.write_text(
        'time,u,T1,status\n' + ''.join(f'{x:.1f},{math.sin(x):.4f},{30 + math.sin(x):.4f},OK\n' for x in t)
    )
    empty = tmp_path / 'empty_t2.csv'
    empty.write_text('time,u,T1,T2\n' + ''.join(f'{x:.1f},{math.sin(x):.4f},{30 + math.sin(x):.4f},\n' for x in t))
    table = read_table(status)
    assert table.header == ['time', 'u', 'T1', 'status'] and np.isnan(table.data[:, 3]).all()
    np.testing.assert_array_equal(table.data[:, :3], read_table(plain).data)
    ref = load_table(plain)[0][0]
    for f in (status, empty):
        (s,), cl = load_table(f)
        np.testing.assert_array_equal(s.T, ref.T)
        np.testing.assert_array_equal(s.u, ref.u)
    assert any('T2 column (T2) has no value in any row' in w for w in load_table(empty)[1].warnings)


def test_files_of_one_name_in_two_folders_are_two_runs(
    tmp_path: Path, peltier_runs: list[ti.ThermalRecord], capsys: pytest.CaptureFixture[str]
) -> None:
    """A rig that writes a folder per wire (sn/a/data.csv, sn/b/data.csv) was refused: "two runs have the same
    name". identify hysteresis takes that layout; now thermal names those runs by their path. The same file given
    twice is still refused."""
    files = []
    for j, sub in enumerate(('a', 'b')):
        (tmp_path / sub).mkdir()
        files.append(str(_write_csv(tmp_path / sub / 'data.csv', peltier_runs[j])))
    code, doc = _cli([*files, '--dt', '0.2', '--out', str(tmp_path / 'out')], capsys)
    assert code == 0, doc
    assert sorted(r['record'] for r in doc['fit']['runs']) == sorted(files)
    code, doc = _cli([files[0], files[0], '--dt', '0.2'], capsys)
    assert code == 2 and 'two runs have the same name' in doc['error']


def test_a_time_column_in_milliseconds_is_named_as_the_likely_cause(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A time column in ms (or ns, as ROS stamps are) read as seconds made every row a gap: 'covers only 0.0 s;
    need at least 30 s'. The error now says how far apart the rows are and names --time-unit (now with ns)."""
    t = np.arange(0.0, 60.0, 0.1)
    body = ''.join(f'{x * 1e9:.0f},{math.sin(x):.4f},{30 + math.sin(x):.4f}\n' for x in t)
    f = tmp_path / 'stamps.csv'
    f.write_text('time,u,T1\n' + body)
    code, doc = _cli([str(f)], capsys)
    assert code == 2 and 'its rows are 1e+08 s apart' in doc['error'] and '--time-unit' in doc['error']
    code, doc = _cli([str(f), '--time-unit', 'ns', '--out', str(tmp_path / 'o')], capsys)
    assert code == 0, doc


def test_a_bag_with_the_drive_the_device_read_back_is_fitted_on_the_read_back(tmp_path: Path) -> None:
    """On hardware a command takes effect after the graph's delay (here 0.1 s), which its stamp does not say; a bag
    with /wrist/tem_drive_applied has the drive as it was applied, and that is what each run's u is (the fit grid's
    interval means of it), not the commands'."""
    from sma_wrist.diagnose import effects as fx
    from sma_wrist.diagnose import testdata as td
    from sma_wrist.identify.thermal import load_bag

    dt, delay, grid_dt = 0.01, 0.1, 0.1
    t = np.arange(int(40.0 / dt) + 1) * dt
    heat_1 = np.sin(2.0 * np.pi * t / 6.0 + 0.3) > 0
    u = np.stack([np.where(heat_1, 12.0, -8.0), np.where(heat_1, -8.0, 12.0)], axis=1)
    truth = td.simulate('actuator_delay', seed=4, duration_s=40.0, params={'command_delay_s': delay}, u=u)
    applied = fx.delayed(truth.u, delay, dt)
    recs, cl = load_bag(td.write_bag(truth, tmp_path / 'bag', applied=applied), grid_dt)
    assert cl.drive == 'applied'
    per = int(round(grid_dt / dt))
    for i, rec in enumerate(recs):
        n = rec.u.size
        # interval means to the midpoint rule's 22 points per interval (a 20 V step placed to 1/22 of it)
        np.testing.assert_allclose(rec.u, applied[: n * per, i].reshape(n, per).mean(axis=1), atol=20.0 / 22)
        assert np.abs(rec.u - truth.u[: n * per, i].reshape(n, per).mean(axis=1)).max() > 5.0  # not the commands


#: TEM 1's drive gain relative to TEM 2's is recovered to this: over 10 seeds of the runs below the largest error was
#: 0.0059 (std 0.002), from the sensors' noise and lag; a shared gain's compromise would be off by ~0.1
GAIN_TOLERANCE = 0.02


@pytest.mark.parametrize('tem1_gain', [0.8, 1.0])
def test_runs_of_both_tems_give_each_its_drive_gain_where_it_predicts_better(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], tem1_gain: float
) -> None:
    """One table of both TEMs (its tem column), each driven by 12 V sines at 1/32 and 1/8 Hz, both faces read through
    thermocouples (0.15 s lag, 0.2 degC noise); TEM 1 pumps tem1_gain per volt of TEM 2 (ThermalParams.tem_gain). A
    weaker TEM 1 gets its own gain in thermal.yaml, with a warning; TEMs alike keep one gain (and no tem_gain key)."""
    kw = {'frequencies_Hz': FREQS[1:], 'duration_s': 200.0, 'sample_dt': 0.2, 'noise_C': 0.2, 'lag_s': 0.15}
    runs = {
        1: sine_runs('own', params=th.ThermalParams(tem_gain=(tem1_gain, 1.0)), seed=3, **kw),
        2: sine_runs('own', seed=4, **kw),
    }
    rows = [
        np.c_[np.arange(r.n) * r.dt, r.u, r.T, np.full(r.n, r.frequency_Hz), np.full(r.n, m)]
        for m, rs in runs.items()
        for r in rs
    ]
    f = tmp_path / 'both_tems.csv'
    np.savetxt(f, np.concatenate(rows), delimiter=',', header='time,u,T1,T2,frequency,tem', comments='', fmt='%.6g')
    out = tmp_path / 'out'
    code, s = _cli([str(f), '--dt', '0.2', '--validation', 'time-split', '--no-plots', '--out', str(out)], capsys)
    assert code == 0, s
    g = s['tem_gain']
    assert g['tem1_relative_to_tem2'] == pytest.approx(tem1_gain, abs=GAIN_TOLERANCE)
    weaker = [w for w in s['warnings'] if 'less per volt' in w]
    params = load_thermal_file(out / 'thermal.yaml')
    if tem1_gain < 1.0:
        assert g['handed_over'], g['why']
        assert params.tem_gain[0] / params.tem_gain[1] == pytest.approx(tem1_gain, abs=GAIN_TOLERANCE)
        assert len(weaker) == 1 and weaker[0].startswith('TEM 1 pumps 20% less')
        assert "Each TEM's drive gain" in (out / 'thermal_identification.md').read_text()
    else:
        assert not g['handed_over'], g['why']
        top = [line for line in (out / 'thermal.yaml').read_text().splitlines() if line.startswith('tem_gain:')]
        assert params.tem_gain == (1.0, 1.0) and not top
        assert not weaker
