"""sma-wrist diagnose: effects hidden in synthetic measured data must be found blind.

Open-loop data come from :mod:`sma_wrist.diagnose.testdata` (the truth runs at a 5x finer
step than the replay, with thermocouple/potentiometer noise and 16-bit quantisation);
closed-loop data from the node graph with plant_sim's ``model.*`` extension parameters.
Each case draws its magnitude from the effect's range with a per-case seed; the
diagnosis sees only the data. The benchmark (``sma-wrist bench --section diagnose``)
runs many more cases and prints accuracy and false-alarm rate.
"""

from __future__ import annotations

import copy
import dataclasses
import json
import subprocess
import sys
import zlib
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pytest

from sma_wrist.core.errors import ParameterError
from sma_wrist.core.plant import extensions as mx
from sma_wrist.diagnose import DiagnoseInputError, diagnose, diagnose_run
from sma_wrist.diagnose import effects as fx
from sma_wrist.diagnose import testdata as td
from sma_wrist.diagnose.data import load_run

DURATION_S = 240.0


def _seed(name: str, k: int = 0) -> int:
    return zlib.crc32(f'{name}/{k}'.encode()) % 10_000


def _check_found(truth: td.Truth, res) -> None:  # type: ignore[no-untyped-def]
    assert res.discrepancy and res.cause == truth.effect, (res.summary, truth.params)
    for k, v in truth.params.items():
        got = res.parameters[k]['value']
        assert abs(got - v) <= 0.15 * abs(v), f'{k}: injected {v:.4g}, recovered {got:.4g}'
    assert res.gain_pct > 0 and res.rmse_after < res.rmse_before
    assert res.gain_ci[0] > 0  # bootstrap 5th percentile of the held-out gain


MAGNITUDES = [
    ('thermal_coupling', {'coupling_per_s': 0.008}),  # weakest of the range
    ('thermal_coupling', {'coupling_per_s': 0.1}),  # far beyond it
    ('sensor_delay', {'angle_delay_s': 0.15}),
    ('payload_mismatch', {'payload_err_kg': -0.1}),
    ('backlash', {'backlash_rad': 0.02}),
]
CLEAN_SEEDS = (11, 12, 13)
#: the catalogue without the per-channel sensor and driver effects, which are in the
#: benchmark and test_diagnose_independent (the suite stays fast)
BASE_CATALOGUE = tuple(e for e in fx.CATALOGUE if not e.id.startswith(('temp_sensor_', 'angle_sensor_', 'tem_')))
CASES = (
    [(e.id, _seed(e.id), None) for e in BASE_CATALOGUE]
    + [(e, _seed(e, 1), p) for e, p in MAGNITUDES]
    + [('none', s, None) for s in CLEAN_SEEDS]
)


def _run_case(case):  # type: ignore[no-untyped-def]
    effect, seed, params = case
    truth = td.simulate(effect, seed=seed, duration_s=DURATION_S, params=params)
    return truth, diagnose_run(td.run_from_truth(truth))


@pytest.fixture(scope='module')
def open_loop():
    """Every open-loop case diagnosed once, in two processes (the suite's biggest cost)."""
    with ProcessPoolExecutor(max_workers=2) as ex:
        return dict(zip(range(len(CASES)), ex.map(_run_case, CASES)))


@pytest.mark.parametrize('i', range(len(BASE_CATALOGUE)), ids=[e.id for e in BASE_CATALOGUE])
def test_hidden_effect_is_named_with_its_magnitude(open_loop, i):
    _check_found(*open_loop[i])


@pytest.mark.parametrize('k', range(len(MAGNITUDES)), ids=[f'{e}-{list(p.values())[0]:g}' for e, p in MAGNITUDES])
def test_several_magnitudes(open_loop, k):
    _check_found(*open_loop[len(BASE_CATALOGUE) + k])


@pytest.mark.parametrize('i', range(len(CASES)), ids=[f'{c[0]}-{c[1]}' for c in CASES])
def test_no_effect_of_the_catalogue_nor_a_clean_run_reads_as_a_step_of_the_angle(open_loop, i):
    _, res = open_loop[i]
    assert res.angle_steps == [] and 'stepped' not in res.summary, res.summary


def test_a_step_of_the_angle_is_named_with_its_time_and_size():
    # a clean run whose measured angle jumps 0.15 rad at 50 s and back at 62 s (a wire slipping in its crimp and
    # caught again, a snap and its release): nothing the model's replay does
    truth = td.simulate('none', seed=5, duration_s=90.0)
    run = td.run_from_truth(truth)
    t = run.t - run.t[0]
    run.q = run.q + 0.15 * ((t >= 50.0) & (t < 62.0))
    res = diagnose_run(run, candidates=['payload_mismatch', 'sensor_offset_gain'])
    assert res.discrepancy and 'mechanics' in res.summary, res.summary
    assert [round(s['t_s']) for s in res.angle_steps] in ([50, 62], [62, 50]), res.angle_steps
    assert all(s['step_rad'] == pytest.approx(0.15, abs=0.01) for s in res.angle_steps)
    assert all(s['model_max_rad'] < 0.15 / 2.5 for s in res.angle_steps)
    assert 'the measured angle stepped within 0.1 s (0.15' in res.summary and 'rad at 50.0 s' in res.summary


def test_the_replay_restarted_after_a_step_does_not_hide_a_potentiometer_that_jumped_for_good():
    # the replay restarts from the measured angle after a step; a wrist that did not move (the reading jumped 0.15 rad
    # at 50 s and stayed) pulls the restarted replay back to where the wires hold it: still a discrepancy
    truth = td.simulate('none', seed=5, duration_s=90.0)
    run = td.run_from_truth(truth)
    t = run.t - run.t[0]
    run.q = run.q + 0.15 * (t >= 50.0)
    res = diagnose_run(run, candidates=['payload_mismatch'])
    assert [round(s['t_s']) for s in res.angle_steps] == [50], res.angle_steps
    assert res.discrepancy and 'mechanics' in res.summary and 'restarts from the measured angle' in res.summary


@pytest.mark.parametrize('k', range(len(CLEAN_SEEDS)), ids=[f'seed{s}' for s in CLEAN_SEEDS])
def test_clean_run_is_no_false_alarm(open_loop, k):
    _, res = open_loop[len(BASE_CATALOGUE) + len(MAGNITUDES) + k]
    assert not res.discrepancy and res.cause is None and not res.unexplained, res.summary
    assert 'no significant discrepancy' in res.summary


@pytest.mark.parametrize('gain_err', [0.002, 0.01])
def test_a_fit_too_small_to_matter_is_no_discrepancy(gain_err):
    """A noise-free run of a wrist whose TEMs are 0.2 % (1 %) off the model: the fit finds tem_gain_err to the last
    digit and removes all the misfit, but a TEM within 1 % of its model is a nominal wrist. The rule named it
    ("tem_gain_err = 0.002, confidence 1.00", as a window of the nominal simulated wrist under ROS 2 did)."""
    truth = td.simulate('tem_mismatch', seed=3, duration_s=90.0, params={'tem_gain_err': gain_err})
    run = td.run_from_truth(truth)
    run.T, run.q = truth.T_true.copy(), truth.q_true.copy()  # no sensor noise: only the practical floor decides
    res = diagnose_run(run, candidates=['tem_mismatch', 'temp_sensor_offset', 'payload_mismatch'])
    assert not res.discrepancy and not res.unexplained and res.cause is None, res.summary
    assert 'within its tolerance: tem_mismatch' in res.summary
    tem = next(a for a in res.alternatives if a['cause'] == 'tem_mismatch')
    assert tem['size'] < 1.0 and tem['score'] < -1.0  # far better than nominal, and far below what matters
    assert tem['parameters']['tem_gain_err']['value'] == pytest.approx(gain_err, rel=0.1)


def test_small_departures_of_several_parameters_are_unexplained_and_the_best_small_fit_is_named():
    """A noise-free run of a wrist whose payload, pre-load and wire shift are each off by less than the practical
    floor (as a commissioning fitted to a replay that missed the wires' history left them): together they leave
    structure in the angle that no single effect removes. The verdict names the best fit and why it is not the cause;
    it read "best -, score 0.000" as if nothing had fitted."""
    params = {'payload_err_kg': 0.015, 'preload_err_mm': -0.013, 'hyst_shift_C': 0.1}
    truth = td.simulate('none', seed=3, duration_s=90.0, params=params)
    run = td.run_from_truth(truth)
    run.T, run.q = truth.T_true.copy(), truth.q_true.copy()
    res = diagnose_run(run, candidates=['payload_mismatch', 'sensor_offset_gain', 'hysteresis_shift'])
    assert res.discrepancy and res.unexplained and res.cause is None, res.summary
    pay = next(a for a in res.alternatives if a['cause'] == 'payload_mismatch')
    assert pay['size'] < 1.0 and pay['score'] < -1.0  # it fits, below the size that matters
    assert f'best payload_mismatch, score {pay["score"]:.3f}, but its fitted values are below what matters' in (
        res.summary
    )


def test_structure_outside_the_catalogue_is_reported_unexplained_not_named():
    truth = td.simulate('none', seed=5, duration_s=DURATION_S)
    run = td.run_from_truth(truth)
    run.q = run.q + 0.03 * np.sin(2 * np.pi * run.t / 17.0)  # an unmodelled periodic disturbance
    res = diagnose_run(run)
    assert res.discrepancy and res.unexplained and res.cause is None, res.summary
    assert res.correlates and 'no catalogue effect explains it' in res.summary


def test_a_wrist_of_another_wire_model_is_unexplained_and_its_figures_are_its_channels(tmp_path):
    """The phase-fraction wrist (another wire and TEM model, sma_wrist/plants/phase_fraction.py) in the node graph:
    no catalogue effect is named; the verdict's channel is the thermal one, 17-22 degC RMS off. The result printed
    the best candidate's channel's figures (mechanics, 0.33 rad) under "thermal"."""
    from sma_wrist import runtime

    runtime.activate()
    from sma_wrist.closed_loop import run_closed_loop
    from sma_wrist.diagnose import diagnose

    run_closed_loop(
        'direct_adaptive', 0.3, 40.0, tmp_path / 'pf', extra_params={'/plant_sim': {'plant': 'phase_fraction'}}
    )
    res = diagnose(tmp_path / 'pf')
    assert res.discrepancy and res.unexplained and res.cause is None, res.summary
    assert res.channel == 'thermal' and res.rmse_before > 5.0  # degC
    assert (res.rmse_before, res.rmse_after) == (
        res.channels['thermal']['rmse_before'],
        res.channels['thermal']['rmse_after'],
    )
    # the user's next step: the TEMs identified from another run of that wrist (identify thermal), replayed with
    # --thermal-file: the thermal channel comes down to the TEMs' own error, what is left is the wire's
    from sma_wrist.cli import main

    run_closed_loop(
        'direct_adaptive', 0.3, 70.0, tmp_path / 'pf_train', extra_params={'/plant_sim': {'plant': 'phase_fraction'}}
    )
    assert (
        main(
            [
                'identify',
                'thermal',
                str(tmp_path / 'pf_train'),
                '--out',
                str(tmp_path / 'tems'),
                '--no-plots',
                '--quiet',
            ]
        )
        == 0
    )
    tems = tmp_path / 'tems' / 'thermal.yaml'
    again = diagnose(tmp_path / 'pf', thermal_file=str(tems), params_out=tmp_path / 'ext.yaml')
    # 22.2 -> 6.5 degC here (from a 70 s run of the same wrist to this 40 s one)
    assert again.channels['thermal']['rmse_before'] < res.channels['thermal']['rmse_before'] / 3
    assert again.channels['mechanics']['rmse_before'] > 0.1  # rad: the wire is still not the model's
    assert f'thermal_file: {tems.resolve()}' in (tmp_path / 'ext.yaml').read_text()  # the plant it replayed


# ------------------------------------------------------------------------- bags and CLI


def test_cli_on_a_bag_json_report_and_params_file(tmp_path):
    truth = td.make_bag(tmp_path / 'measured', 'thermal_coupling', seed=_seed('cli'), duration_s=150.0)
    r = subprocess.run(
        [
            sys.executable,
            '-m',
            'sma_wrist',
            'diagnose',
            str(tmp_path / 'measured'),
            '--json',
            '--report',
            str(tmp_path / 'report'),
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    for key in (
        'discrepancy',
        'subsystem',
        'cause',
        'parameters',
        'rmse_before',
        'rmse_after',
        'gain_pct',
        'alternatives',
        'unexplained',
    ):
        assert key in out
    assert out['cause'] == 'thermal_coupling' and out['subsystem'] == 'thermal'
    assert out['parameters']['coupling_per_s']['unit'] == '1/s'
    assert out['parameters']['coupling_per_s']['value'] == pytest.approx(truth.params['coupling_per_s'], rel=0.15)
    ranked = out['alternatives']
    assert ranked[0]['cause'] == out['cause']
    assert [a['score'] for a in ranked[1:]] == sorted(a['score'] for a in ranked[1:])
    report = tmp_path / 'report'
    assert (report / 'diagnosis.md').read_text().count('thermal_coupling') >= 1
    assert len(list(report.glob('*.png'))) >= 2
    params = (report / 'extended_params.yaml').read_text()
    assert 'model.coupling_per_s' in params


def test_bag_diagnosis_equals_array_diagnosis(tmp_path):
    truth = td.make_bag(tmp_path / 'b', 'sensor_offset_gain', seed=_seed('bag'), duration_s=120.0)
    run = load_run(tmp_path / 'b')
    assert run.n == truth.t.size and run.dt == pytest.approx(0.01)
    np.testing.assert_allclose(run.T, truth.T, atol=1e-12)
    np.testing.assert_allclose(run.q, truth.q, atol=1e-12)
    np.testing.assert_allclose(run.u, truth.u, atol=1e-12)
    assert run.payload_kg == pytest.approx(truth.payload_kg)


@pytest.mark.parametrize(
    'corrupt,warning',
    [
        ({'nan_T': (3000, 40)}, 'NaN'),
        ({'kelvin': True}, 'Kelvin'),
        ({'degrees': True}, 'degrees'),
        ({'shuffle_stamps': 20}, 'not sorted'),
        ({'duplicate_stamps': 20}, 'duplicate'),
        ({'gap': (20.0, 3.0)}, 'gap'),
    ],
)
def test_flawed_bags_are_repaired_reported_and_still_diagnosed(tmp_path, corrupt, warning):
    truth = td.make_bag(tmp_path / 'b', 'sensor_offset_gain', seed=_seed('flaw'), duration_s=150.0, corrupt=corrupt)
    res = diagnose(tmp_path / 'b')
    assert any(warning in w for w in res.warnings), res.warnings
    assert res.cause == 'sensor_offset_gain', res.summary
    for k, v in truth.params.items():
        assert res.parameters[k]['value'] == pytest.approx(v, rel=0.15)


def test_a_drive_that_took_effect_after_its_commands_stamp_replays_right_from_the_devices_read_back(tmp_path):
    """On hardware a command takes effect after the graph's delay (here 0.1 s: ten windows behind), and its stamp says
    only which window it answered: replayed there, the TEMs' heat came early and a nominal wrist read as a TEM command
    delay. A bag with the drive the device read back (/wrist/tem_drive_applied) is replayed on that instead: clean."""
    dt, delay = 0.01, 0.1
    t = np.arange(int(40.0 / dt) + 1) * dt
    heat_1 = np.sin(2.0 * np.pi * t / 6.0 + 0.3) > 0  # switching every 3 s, as a closed loop's commands do
    u = np.stack([np.where(heat_1, 12.0, -8.0), np.where(heat_1, -8.0, 12.0)], axis=1)
    truth = td.simulate('actuator_delay', seed=4, duration_s=40.0, params={'command_delay_s': delay}, u=u)
    candidates = ['actuator_delay', 'sensor_lag', 'tem_mismatch']
    commanded = td.write_bag(truth, tmp_path / 'commanded')
    res = diagnose(commanded, candidates=candidates)
    assert res.drive == 'commanded' and res.cause == 'actuator_delay', res.summary  # what a bag without it says
    applied = td.write_bag(truth, tmp_path / 'applied', applied=fx.delayed(truth.u, delay, dt))
    run = load_run(applied)
    assert run.drive == 'applied' and np.array_equal(run.u, fx.delayed(truth.u, delay, dt)[: run.n])
    res = diagnose(applied, candidates=candidates)
    assert res.drive == 'applied' and not res.discrepancy, res.summary
    assert res.residual_stats['thermal']['nominal']['rms_over_noise'] < 1.2


def test_a_drive_the_device_watchdog_zeroed_replays_right_from_the_applied_drive_and_is_counted(tmp_path):
    """A host that stalls stops commanding; the device's watchdog zeroes the drive (three stretches of 0.8 s here)
    while the last command, all the commands in a bag say, goes on heating. Replayed on the commands, a nominal wrist
    is 13x the sensor noise off in its temperatures; on the drive the device applied (/wrist/tem_drive_applied), at
    the noise. The report says which drive it replayed and on how many samples it differed from the commands; a bag
    without the topic (here: the same bag with it mapped away) replays the commands as before."""
    import dataclasses

    from sma_wrist.contract import Recording
    from sma_wrist.diagnose.report import drive_replayed

    dt = 0.01
    t = np.arange(int(40.0 / dt) + 1) * dt
    heat_1 = np.sin(2.0 * np.pi * t / 6.0 + 0.3) > 0
    u = np.stack([np.where(heat_1, 12.0, -8.0), np.where(heat_1, -8.0, 12.0)], axis=1)
    applied = u.copy()
    for a in (10.0, 20.0, 30.0):
        applied[(t >= a) & (t < a + 0.8)] = 0.0  # the watchdog's zero drive
    truth = dataclasses.replace(td.simulate('none', seed=4, duration_s=40.0, u=applied), u=u)
    bag = td.write_bag(truth, tmp_path / 'bag', applied=applied)
    candidates = ['actuator_delay', 'tem_mismatch']
    res = diagnose(bag, candidates=candidates)
    assert res.drive == 'applied' and res.drive_differs == 240 and not res.discrepancy, res.summary
    assert res.residual_stats['thermal']['nominal']['rms_over_noise'] < 1.2
    assert '(240 samples where it differed from the command)' in drive_replayed(res.drive, res.drive_differs)
    without = Recording.from_options(['/wrist/tem_drive_applied=/not_recorded'])
    res = diagnose(bag, candidates=candidates, recording=without)
    assert res.drive == 'commanded' and res.drive_differs is None and res.discrepancy, res.summary
    assert res.residual_stats['thermal']['nominal']['rms_over_noise'] > 5.0
    assert 'replayed the TEM commands' in drive_replayed(res.drive, res.drive_differs)


def test_missing_angle_still_checks_the_thermal_part(tmp_path):
    td.make_bag(
        tmp_path / 'b',
        'tem_mismatch',
        seed=_seed('noq'),
        duration_s=150.0,
        corrupt={'drop_topics': ['/wrist/joint_states']},
    )
    res = diagnose(tmp_path / 'b')
    assert any('/wrist/joint_states' in w for w in res.warnings)
    assert res.cause == 'tem_mismatch' and list(res.channels) == ['thermal']


@pytest.mark.parametrize(
    'corrupt,needle',
    [
        (
            {'drop_topics': ['/wrist/muscle_1/temperature', '/wrist/muscle_2/temperature', '/wrist/joint_states']},
            'nothing to compare',
        ),
    ],
)
def test_unusable_bag_names_what_is_needed(tmp_path, corrupt, needle):
    td.make_bag(tmp_path / 'b', 'none', seed=1, duration_s=40.0, corrupt=corrupt)
    with pytest.raises(DiagnoseInputError, match=needle):
        diagnose(tmp_path / 'b')
    r = subprocess.run(
        [sys.executable, '-m', 'sma_wrist', 'diagnose', str(tmp_path / 'b')],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 2 and r.stderr.startswith('error: ') and needle in r.stderr and 'Traceback' not in r.stderr


def test_too_short_and_truncated_bags(tmp_path):
    td.make_bag(tmp_path / 'short', 'none', seed=1, duration_s=10.0)
    with pytest.raises(DiagnoseInputError, match='need at least 30 s'):
        diagnose(tmp_path / 'short')
    td.make_bag(tmp_path / 'cut', 'temp_sensor_offset', seed=_seed('cut'), duration_s=150.0)
    mcap = next((tmp_path / 'cut').glob('*.mcap'))
    data = mcap.read_bytes()
    mcap.write_bytes(data[: int(len(data) * 0.7)])  # a recorder killed mid-write
    res = diagnose(tmp_path / 'cut')
    assert any('damaged' in w or 'salvaged' in w for w in res.warnings), res.warnings
    assert res.duration_s > 60.0 and res.cause == 'temp_sensor_offset'


# ------------------------------------------------------------------------- closed loop


def _closed_loop(bag, extra=None, params_files=(), duration=70.0):  # type: ignore[no-untyped-def]
    from sma_wrist.closed_loop import run_closed_loop

    return run_closed_loop(
        'pid', 0.3, duration, bag, params_files=params_files, extra_params={'/plant_sim': extra} if extra else None
    )


@pytest.fixture(scope='module')
def nominal_closed_loop(tmp_path_factory):
    bag = tmp_path_factory.mktemp('closed_loop') / 'nominal'
    _closed_loop(bag)
    return bag


def test_clean_closed_loop_plant_sim_run_is_no_discrepancy(nominal_closed_loop):
    run = load_run(nominal_closed_loop)
    res = diagnose_run(run)
    assert not res.discrepancy, res.summary
    # the replay kernels against the real plant: thermal exact, angle within the replay resolution
    assert res.channels['thermal']['rmse_before'] < 1e-6
    assert res.channels['mechanics']['rmse_before'] < 1e-3 * np.ptp(run.q)


@pytest.mark.parametrize(
    'effect,extra',
    [
        ('sensor_offset_gain', {'model.angle_offset_rad': 0.04}),
        # default (0.5 s prefiltered) pid: named recalibrate_mechanics (viscous 0.142 vs 0.15) while the
        # 100 Hz mechanics replay's own step error (1.07 mrad) exceeded its resolution floor (0.99 mrad)
        ('payload_mismatch', {'model.payload_err_kg': 0.15}),
        ('thermal_coupling', {'model.coupling_per_s': 0.02}),
    ],
)
def test_effect_hidden_in_closed_loop_data_is_found_and_its_params_file_reproduces_the_run(
    tmp_path, nominal_closed_loop, effect, extra
):
    _closed_loop(tmp_path / 'measured', extra)
    res = diagnose(tmp_path / 'measured', params_out=tmp_path / 'extended.yaml')
    assert res.cause == effect, res.summary
    ((key, value),) = extra.items()
    assert res.parameters[key[len('model.') :]]['value'] == pytest.approx(value, rel=0.15)
    # the extended model, run in the same closed loop, reproduces the measured angle; the nominal does not
    _closed_loop(tmp_path / 'extended', params_files=[tmp_path / 'extended.yaml'])
    runs = {k: load_run(tmp_path / k) for k in ('measured', 'extended')}
    runs['nominal'] = load_run(nominal_closed_loop)
    q = {k: r.q for k, r in runs.items()}
    T = {k: r.T for k, r in runs.items()}
    err_ext = np.sqrt(np.mean((q['extended'] - q['measured']) ** 2) + np.mean((T['extended'] - T['measured']) ** 2))
    err_nom = np.sqrt(np.mean((q['nominal'] - q['measured']) ** 2) + np.mean((T['nominal'] - T['measured']) ** 2))
    assert err_ext < 0.2 * err_nom, (err_ext, err_nom)


# ------------------------------------------------------------------------- the extension parameters


def test_nominal_extension_is_the_plain_plant():
    from sma_wrist.core.plant.wrist import PlantParams

    base = PlantParams()
    assert mx.plant_params({}, base) is base
    assert mx.plant_params(dict(mx.NOMINAL), base) is base


def test_extension_values_are_checked():
    with pytest.raises(ParameterError, match='outside'):
        mx.check({'coupling_per_s': -1.0})
    with pytest.raises(ParameterError, match='unknown model extension'):
        mx.check({'coupling': 0.1})
    with pytest.raises(ParameterError, match='not simulated by the plant'):
        mx.plant_params({'hyst_lag_s': 5.0})


def test_plant_sim_refuses_a_replay_only_extension(tmp_path):
    params = tmp_path / 'p.yaml'
    params.write_text('plant_sim:\n  ros__parameters:\n    model.hyst_lag_s: 5.0\n')
    r = subprocess.run(
        [sys.executable, '-m', 'sma_wrist', 'run', '--duration', '1', '--quiet', '--params-file', str(params)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 2 and 'not simulated by the plant' in r.stderr and 'Traceback' not in r.stderr


def test_sensor_chain_matches_the_replay_sensor_model():
    dt = 0.01
    t = np.arange(3000) * dt
    q = 0.5 + 0.4 * np.sin(0.3 * t)
    T = np.stack([40 + 20 * np.sin(0.1 * t), 40 - 20 * np.sin(0.1 * t)], axis=1)
    v = {
        'angle_delay_s': 0.237,
        'backlash_rad': 0.03,
        'angle_offset_rad': 0.02,
        'angle_gain_err': -0.05,
        'temp_lag_s': 2.0,
        'temp_offset_C': 1.5,
    }
    chain = mx.SensorChain(v, dt, 0.524)
    got_q = np.array([chain.angle(x) for x in q])
    got_T = np.array([chain.temperatures(x) for x in T])
    model = fx.ExtendedModel.__new__(fx.ExtendedModel)
    model.dt = dt
    model.consts = type('C', (), {'params': type('P', (), {'joint': type('J', (), {'q_neutral_rad': 0.524})})})
    row = fx.theta(**v)
    np.testing.assert_allclose(got_q, fx.ExtendedModel.angle_sensor(model, q, row), atol=1e-12)
    np.testing.assert_allclose(got_T, fx.first_order(T, 2.0, dt) + 1.5, atol=1e-12)


def test_a_run_that_starts_with_warm_tem_faces_is_replayed_from_the_measured_faces(tmp_path):
    """A run started right after an excitation: the muscles have settled, the TEMs' exchanger faces are still ~75 degC.
    Replayed from rest that is a large thermal discrepancy outside the catalogue; a bag with the face thermocouples
    (/wrist/tem_{1,2}/face_temperature) starts the replay where the faces were: clean. Without them, as before."""
    dt = 0.01
    t = np.arange(int(60.0 / dt) + 1) * dt
    heat_1 = np.sin(2.0 * np.pi * t / 6.0 + 0.3) > 0
    u = np.stack([np.where(heat_1, 12.0, -8.0), np.where(heat_1, -8.0, 12.0)], axis=1)
    truth = td.simulate('none', seed=4, duration_s=60.0, u=u, faces_start_C=(76.0, 74.0))
    candidates = ['ambient_drift', 'thermal_coupling', 'tem_mismatch']
    faces = ['/wrist/tem_1/face_temperature', '/wrist/tem_2/face_temperature']
    blind = td.write_bag(truth, tmp_path / 'blind', corrupt={'drop_topics': faces})
    run = load_run(blind)
    assert run.thermal_start == 'rest' and run.thermal_x0 is None
    res = diagnose(blind, candidates=candidates)
    assert res.thermal_start == 'rest' and res.discrepancy, res.summary
    seen = td.write_bag(truth, tmp_path / 'seen')
    run = load_run(seen)
    assert run.thermal_start == 'measured'
    np.testing.assert_allclose(run.thermal_x0[:, 1], [76.0, 74.0], atol=0.3)  # the faces' first samples
    res = diagnose(seen, candidates=candidates)
    assert res.thermal_start == 'measured' and not res.discrepancy, res.summary
    assert res.residual_stats['thermal']['nominal']['rms_over_noise'] < 1.2


def test_a_run_with_bridged_gaps_reports_its_residual_over_the_measured_samples_only():
    """Samples where the loader bridged a short gap hold no measurement: counted as zero residual they made a
    quarter-bridged run look 15 % closer to its model than it was (the verdict compares the RMS with the noise)."""
    truth = td.simulate('temp_sensor_offsets', seed=5, duration_s=100.0)
    run = td.run_from_truth(truth)
    valid = np.ones(run.n, bool)
    for a in range(2000, run.n - 500, 1000):
        valid[a : a + 300] = False  # 3 s of every 10 bridged, as a loaded recorder leaves a run
    T = run.T.copy()
    T[~valid] = T[~valid][0]  # what the bridge held there
    gapped = dataclasses.replace(run, valid=valid, T=T)
    full = diagnose_run(run, candidates=['temp_sensor_offsets']).residual_stats['thermal']['nominal']
    part = diagnose_run(gapped, candidates=['temp_sensor_offsets']).residual_stats['thermal']['nominal']
    assert part['rms'] == pytest.approx(full['rms'], rel=0.05)
    assert part['rms_over_noise'] == pytest.approx(full['rms_over_noise'], rel=0.05)


def test_a_window_cut_while_the_muscles_move_starts_its_nodes_ahead_of_their_lagged_readings():
    # the model's thermocouples read its muscle nodes 0.5 s late; a window cut where the temperatures move fastest
    # starts its replay from the readings advanced by that lag, not from the readings (whose error would decay over
    # the heat balance's minute-long time constant: a monitor window of the model itself called a drift); a lag that
    # is not the model's (a candidate's, a change within the window) starts from the readings
    from sma_wrist.core.plant.wrist import PlantParams
    from sma_wrist.diagnose.data import Run

    lag = 0.5
    truth = td.simulate('none', seed=3, duration_s=200.0, params={'temp_lag_s': lag}, faces_start_C=(30.0, 30.0))
    rate = np.gradient(truth.T_true, truth.dt, axis=0)
    i0 = 10_000 + int(np.argmax(np.abs(rate[10_000:14_000, 0])))
    sl = slice(i0, i0 + 6000)
    window = Run(
        t=truth.t[sl] - truth.t[i0],
        dt=truth.dt,
        u=truth.u[sl],
        T=truth.T[sl],
        q=truth.q[sl],
        payload_kg=truth.payload_kg,
        thermal_x0=np.stack([truth.T[i0], truth.faces[i0]], axis=1),
        thermal_start='measured',
    )
    row = fx.theta(temp_lag_s=lag)[None]
    model = fx.ExtendedModel(window, PlantParams(dt=truth.dt), nominal=row[0])  # the lag is the model's own
    start = model.T_start.copy()
    assert (
        np.abs(model.T_start + lag * model.T_rate_start - truth.T_true[i0]).max() < 0.1 * np.abs(lag * rate[i0]).max()
    )

    def rms_first_30_s(m: fx.ExtendedModel) -> float:
        res = (
            m.thermal_measured(row)[:3000, 0]
            - fx.thermocouples(truth.T_true, fx.theta(temp_lag_s=lag), truth.dt)[sl][:3000]
        )
        return float(np.sqrt(np.mean(res**2)))

    advanced = rms_first_30_s(model)
    at_readings = fx.ExtendedModel(window, PlantParams(dt=truth.dt))  # a lag that is no part of the model: a change
    assert at_readings.thermal_true(row)[0, 0] == pytest.approx(start, abs=1e-9)
    assert np.array_equal(at_readings.T_start, start)
    assert advanced < 0.3 * rms_first_30_s(at_readings), (advanced, rms_first_30_s(at_readings))


def test_a_run_whose_drive_steps_up_just_after_its_start_starts_its_nodes_where_they_were():
    # a run from rest whose TEMs go to full drive 0.1 s in: the readings' slope over a window that takes in the step
    # is no rate the readings had at the start, and a replay started at reading + lag x that slope starts its nodes
    # hot by an error that decays over the heat balance's minute-long time constant; the start fitted through the
    # model's own replay of the first lags of readings is the nodes' rest
    from sma_wrist.core.plant.wrist import PlantParams
    from sma_wrist.diagnose.data import Run

    lag, dt = 0.2, 0.01
    u = td.commands(120.0, dt, np.random.default_rng(5))
    u[:10] = 0.0
    u[10:300] = (24.0, 20.0)
    truth = td.simulate('none', seed=5, params={'temp_lag_s': lag}, u=u, dt=dt)
    run = Run(t=truth.t, dt=dt, u=truth.u, T=truth.T, q=truth.q, payload_kg=truth.payload_kg)
    row = fx.theta(temp_lag_s=lag)[None]
    model = fx.ExtendedModel(run, PlantParams(dt=dt), nominal=row[0])
    slope = fx.smooth_and_rate(run.T[:500], dt, fx.START_WINDOW_S)[1][0]
    slope_error = np.abs(model.T_start + lag * slope - truth.T_true[0])
    assert slope_error.min() > 0.05  # the step bends the readings within the slope's window
    start_error = np.abs(model.thermal_true(row)[0, 0] - truth.T_true[0])
    assert start_error.max() < 0.2 * slope_error.min(), (start_error, slope_error)
    readings = fx.thermocouples(truth.T_true, row[0], dt)
    res = model.thermal_measured(row)[3000:, 0] - readings[3000:]
    started_on_slope = copy.copy(model)
    started_on_slope._th_cache = {}
    started_on_slope.T_rate_start = slope
    res_slope = started_on_slope.thermal_measured(row)[3000:, 0] - readings[3000:]
    assert np.sqrt(np.mean(res**2)) < 0.3 * np.sqrt(np.mean(res_slope**2))


def test_a_fit_is_on_its_bound_only_where_it_went_nearly_all_the_way_there():
    # the joint's damping: catalogue range 0-20 N m s about 0.15. A fitted 0.059 is a damping, not "the bound 0" (the
    # summary then asked for a damping below zero); 0.0005 is on the bound; a nominal on its bound is never on it
    from sma_wrist.diagnose import at_bound
    from sma_wrist.diagnose import fit as ft

    effect = next(e for e in fx.CATALOGUE if e.id == 'viscous_damping')
    i = fx.INDEX['viscous_Nms']

    def fitted(v: float, nominal: float = 0.15) -> list:
        row, nom = fx.NOMINAL.copy(), fx.NOMINAL.copy()
        row[i], nom[i] = v, nominal
        return at_bound(ft.Fit(effect, row), nom)

    assert fitted(0.059) == [] and fitted(0.3) == []
    assert [h['bound'] for h in fitted(0.0005)] == [0.0] and [h['bound'] for h in fitted(19.99)] == [20.0]
    assert fitted(0.0, nominal=0.0) == []
