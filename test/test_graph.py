"""The whole node graph on the embedded runtime: tracking, bags, determinism, interrupts, CLI."""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sma_wrist.bag import bag_info, iter_mcap, read_bag
from sma_wrist.closed_loop import run_closed_loop
from sma_wrist.runs import load_run

PID_LOADS = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6)
DIRECT_LOADS = (0.1, 0.35, 0.6)
#: the inverse mode's target: under 5 % at every payload up to 0.6 kg
INVERSE_LOADS = PID_LOADS


@pytest.fixture(scope='module')
def experiment_dir(tmp_path_factory):
    """Two periods of the Sec. 6.1 reference per controller and payload, in parallel processes."""
    from sma_wrist.experiment import run_experiment

    out = tmp_path_factory.mktemp('ch6')
    with open(os.devnull, 'w') as log:
        kw = dict(duration_s=4 * math.pi / 0.1, workers=2, plots=False, log=log)
        run_experiment(['direct_adaptive'], DIRECT_LOADS, out / 'direct', family=1, **kw)  # + 1 off-model plant
        run_experiment(['inverse_adaptive', 'pid'], PID_LOADS, out / 'main', **kw)  # report of both at six loads
    return out


@pytest.fixture(scope='module')
def tracking_runs(experiment_dir):
    rows = [r for d in ('direct', 'main') for r in json.loads((experiment_dir / d / 'table.json').read_text())['runs']]
    return {(r['controller'], r['payload_kg']): r for r in rows}


def _face_errors(bag):
    """/diagnostics statuses of plant_sim saying a TEM face left its window."""
    data = read_bag(bag, ['/diagnostics'])
    msgs = data['/diagnostics'][1] if '/diagnostics' in data else []
    level = lambda st: int.from_bytes(st.level, 'little') if isinstance(st.level, bytes) else int(st.level)  # noqa: E731
    return [st.message for m in msgs for st in m.status if 'tem_faces' in st.name and level(st) == 2]


@pytest.mark.parametrize('controller', ['inverse_adaptive', 'pid'])
def test_tem_faces_stay_inside_their_window_at_the_heaviest_load(experiment_dir, controller):
    """The predictive face protection (doc/explanation/model.md): with the fixed 75 degC switch a face
    reached 84.5 degC at 0.6 kg; plant_sim reports any face outside 0-80 degC."""
    assert _face_errors(experiment_dir / 'main' / f'{controller}_0.6kg') == []


def test_experiment_report_has_every_run_and_checks_the_seed_claims(experiment_dir, tracking_runs):
    text = (experiment_dir / 'main' / 'report.md').read_text()
    for m in PID_LOADS:
        for c in ('inverse_adaptive', 'pid'):
            r = tracking_runs[(c, m)]
            assert f'| {m:g} kg | {c} | {r["max_error_pct"]:.2f} (' in text
    lowest = all(
        min(('inverse_adaptive', 'pid'), key=lambda c: tracking_runs[(c, m)]['total_abs_error_pct'])
        == 'inverse_adaptive'
        for m in PID_LOADS
    )
    claim = 'inverse_adaptive has the lowest total absolute error. Here: at '
    assert claim + ('6 of 6 loads -- agrees.' if lowest else '') in text


def test_experiment_report_puts_the_off_model_family_beside_each_nominal_figure(experiment_dir, tracking_runs):
    """Nominal and off-model figures side by side in the experiment report. The family cell of each
    payload is the sweep's own result for that sampled plant (family/results.jsonl), not the nominal run."""
    table = json.loads((experiment_dir / 'direct' / 'table.json').read_text())
    rows = [
        json.loads(line) for line in (experiment_dir / 'direct' / 'family' / 'results.jsonl').read_text().splitlines()
    ]
    text = (experiment_dir / 'direct' / 'report.md').read_text()
    assert (
        'off-model family: median / p95 / share < 15 %' in text and 'plants sampled from the off-model family' in text
    )
    assert sorted(r['payload_kg'] for r in rows) == sorted(DIRECT_LOADS) and {r['group'] for r in rows} == {'spread'}
    for cell in table['family']['cells']:
        (row,) = [r for r in rows if abs(r['payload_kg'] - cell['payload_kg']) < 1e-9]
        assert cell['plants'] == 1 and cell['median_max_error_pct'] == row['max_error_pct']
        nominal = tracking_runs[('direct_adaptive', cell['payload_kg'])]['max_error_pct']
        assert row['max_error_pct'] != nominal  # a plant that is not the model
        line = f'| {cell["payload_kg"]:g} kg | direct_adaptive | {nominal:.2f}'  # (seed) where the seed has the load
        assert any(
            ln.startswith(line)
            and ln.endswith(
                f' {row["max_error_pct"]:.2f} / {row["max_error_pct"]:.2f} / '
                f'{100 * (row["max_error_pct"] < 15):.0f} % |'
            )
            for ln in text.splitlines()
        )


@pytest.mark.parametrize(
    'controller, payload', [('pid', m) for m in PID_LOADS] + [('direct_adaptive', m) for m in DIRECT_LOADS]
)
def test_closed_loop_tracks_the_seed_sine_within_15_percent(tracking_runs, controller, payload):
    """The Sec. 6.1 requirement, on the last full cycle (the first holds the start from rest)."""
    r = tracking_runs[(controller, payload)]
    assert r['window'] == 'last_cycle'
    assert r['max_error_pct'] < 15.0, r
    assert r['peak_command_V'] <= 24.0  # driver rating


@pytest.mark.parametrize('payload', INVERSE_LOADS)
def test_inverse_adaptive_stays_under_5_percent_at_every_payload(tracking_runs, payload):
    """The inverse mode's target. Observed-memory inverse, reversal lead and predictive face protection
    (doc/explanation/controllers.md): measured 2.11-2.82 %; 6.41 % at 0.6 kg with the fixed 75 degC switch; 2.56-3.40 %
    (126 s) with the target prefilter and adapted temperature axis."""
    r = tracking_runs[('inverse_adaptive', payload)]
    assert r['window'] == 'last_cycle'
    assert r['max_error_pct'] < 5.0, r
    assert r['peak_command_V'] <= 24.0


def test_bag_round_trip_rosbags_and_mcap_agree_with_what_was_published(tmp_path):
    bag = tmp_path / 'run'
    run_closed_loop('inverse_adaptive', 0.3, 3.0, bag)
    info = bag_info(bag)
    for topic in (
        '/clock',
        '/wrist/joint_states',
        '/wrist/muscle_1/temperature',
        '/wrist/tem_1/command',
        '/wrist/reference',
        '/wrist/payload',
        '/wrist/muscle_1/stress_desired',
    ):
        assert info.topics[topic].count > 0, topic
    assert info.topics['/wrist/joint_states'].count == 301  # 100 Hz for 3 s, plus t = 0
    via_rosbags = read_bag(bag, ['/wrist/joint_states'])['/wrist/joint_states']
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    via_mcap = [
        store.deserialize_cdr(raw, msgtype)
        for f in sorted(bag.glob('*.mcap'))
        for topic, msgtype, _, raw in iter_mcap(f)
        if topic == '/wrist/joint_states'
    ]
    from mcap.reader import make_reader

    with open(next(bag.glob('*.mcap')), 'rb') as fh:
        official = [
            (ch.topic, m.log_time) for _, ch, m in make_reader(fh).iter_messages(topics=['/wrist/joint_states'])
        ]
    assert len(via_mcap) == len(via_rosbags[1]) == len(official) == 301
    q_rosbags = np.array([m.position[0] for m in via_rosbags[1]])
    q_mcap = np.array([m.position[0] for m in via_mcap])
    np.testing.assert_array_equal(q_rosbags, q_mcap)
    assert [t for _, t in official] == via_rosbags[0].tolist()


def test_same_inputs_give_a_bit_identical_bag(tmp_path):
    # same bag path both times: rosbag2 names the storage file after the bag directory,
    # and that name is inside the file's metadata record
    digests = []
    bag = tmp_path / 'run'
    for _ in range(2):
        run_closed_loop('pid', 0.2, 2.0, bag)
        files = sorted(bag.glob('*.mcap'))
        assert files
        digests.append(b''.join(f.read_bytes() for f in files) + (bag / 'metadata.yaml').read_bytes())
        shutil.rmtree(bag)
    assert digests[0] == digests[1]


def test_interrupted_run_leaves_a_readable_bag_up_to_the_interrupt(tmp_path):
    def interrupt(t, total, wall):
        if t >= 1.5:
            raise KeyboardInterrupt

    bag = tmp_path / 'cut'
    s = run_closed_loop('inverse_adaptive', 0.3, 10.0, bag, progress=interrupt)
    assert s.interrupted
    run = load_run(bag)
    assert run.t[-1] == pytest.approx(1.5, abs=0.011)
    assert s.metrics['n_samples'] == run.t.size


def _cli(*args):
    return subprocess.run([sys.executable, '-m', 'sma_wrist', *args], capture_output=True, text=True, timeout=600)


def test_cli_run_json_and_info(tmp_path):
    bag = tmp_path / 'demo'
    r = _cli(
        'run',
        '--controller',
        'direct_adaptive',
        '--payload-kg',
        '0.4',
        '--duration',
        '2',
        '--bag',
        str(bag),
        '--json',
        '--quiet',
    )
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out['payload_kg'] == 0.4 and out['metrics']['payload_kg'] == 0.4
    assert out['sim_time_s'] == pytest.approx(2.0)
    again = _cli('run', '--duration', '1', '--bag', str(bag), '--quiet')
    assert again.returncode == 2 and 'already exists' in again.stderr and 'Traceback' not in again.stderr
    info = _cli('info', str(bag), '--json')
    assert json.loads(info.stdout)['topics']['/wrist/payload']['count'] == 1


def test_cli_run_without_a_bag_measures_the_run_as_with_one(tmp_path):
    """`sma-wrist run --json` without --bag returned "metrics": {} and exit 0, with no reason: a script got nothing.
    The run is now recorded to a temporary bag, removed afterwards: the same metrics as a run kept in a bag."""
    import os

    kept = _cli('run', '--controller', 'pid', '--duration', '2', '--bag', str(tmp_path / 'kept'), '--json', '--quiet')
    scratch = tmp_path / 'tmp'
    scratch.mkdir()
    r = subprocess.run(
        [sys.executable, '-m', 'sma_wrist', 'run', '--controller', 'pid', '--duration', '2', '--json', '--quiet'],
        capture_output=True,
        text=True,
        timeout=600,
        env={**os.environ, 'TMPDIR': str(scratch)},
    )
    assert r.returncode == 0 and kept.returncode == 0, r.stderr + kept.stderr
    out, ref = json.loads(r.stdout), json.loads(kept.stdout)
    assert out['bag'] is None and out['metrics_missing'] is None and out['messages'] == ref['messages'] > 0
    assert out['metrics'] == ref['metrics'] and out['metrics']['max_error_pct'] > 0
    assert list(scratch.iterdir()) == []  # the temporary bag is gone
    text = _cli('run', '--controller', 'pid', '--duration', '2', '--quiet')
    assert text.returncode == 0 and 'max error' in text.stdout and 'no tracking metrics' not in text.stdout


def test_cli_run_interrupted_before_any_reference_says_why_it_has_no_metrics(monkeypatch, capsys):
    """A run stopped (Ctrl-C) before the trajectory published anything has no error to measure: the JSON says why,
    the exit code is 130, and no traceback."""
    from sma_wrist.cli import main
    from sma_wrist.runtime.launch import Runtime

    def interrupted(self, *args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(Runtime, 'run_until', interrupted)
    assert main(['run', '--duration', '1', '--json', '--quiet']) == 130
    out = json.loads(capsys.readouterr().out)
    assert out['interrupted'] and out['metrics'] == {}
    assert 'interrupted at 0.00 s' in out['metrics_missing'] and '/wrist/reference' in out['metrics_missing']


def test_cli_run_with_one_sample_reports_no_metrics_instead_of_zero_error(capsys):
    """A run that ended at its first joint state (0.01 s: one sample inside the reference) printed "max error 0.00 %"
    and "peak TEM command 0.00 V" as if measured: the metrics are missing with the reason, and the exit code is 2."""
    from sma_wrist.cli import main

    assert main(['run', '--duration', '0.01', '--json', '--quiet']) == 2
    out = json.loads(capsys.readouterr().out)
    assert not out['interrupted'] and out['metrics'] == {} and out['bag'] is None
    assert 'too little to measure' in out['metrics_missing'] and '1 measured angle' in out['metrics_missing']
    assert main(['run', '--duration', '0.01', '--quiet']) == 2
    text = capsys.readouterr().out
    assert 'no tracking metrics: the run ended at 0.01 s' in text and 'max error' not in text and ' V' not in text


def test_cli_compare_of_a_one_sample_bag_says_there_is_nothing_to_measure(tmp_path, capsys):
    """compare read the one-sample bag of a run that ended at its first joint state as "0.00 %" max error."""
    from sma_wrist.cli import main

    bag = tmp_path / 'one'
    assert main(['run', '--duration', '0.01', '--quiet', '--bag', str(bag)]) == 2
    capsys.readouterr()
    assert main(['compare', str(bag)]) == 2
    captured = capsys.readouterr()
    assert 'too little to measure' in captured.err and str(bag) in captured.err
    assert '0.00' not in captured.out


@pytest.mark.parametrize(
    'args, message',
    [
        (('run', '--payload-kg', 'nan'), 'outside [0, 1.5] kg'),
        (('run', '--payload-kg', '3'), 'outside [0, 1.5] kg'),
        (('run', '--duration', '-1'), 'must be a finite number > 0'),
        (('run', '--controller', 'mpc'), 'invalid choice'),
        (('info', '/nonexistent/bag'), 'error:'),
    ],
)
def test_cli_bad_input_is_a_clear_error_not_a_traceback(args, message):
    r = _cli(*args)
    assert r.returncode == 2
    assert message in r.stderr and 'Traceback' not in r.stderr


def test_floor_benchmark_runs_the_contracts_topology_every_tick():
    """The benchmark's ceiling graph has what the contract says: every periodic topic published
    once per tick and delivered to each of its subscribers (the /clock ones through sim time),
    plus the two timers (plant, trajectory) -- so its speed is the runtime's cost of this graph."""
    from sma_wrist.contract import load_contract
    from sma_wrist.runtime.bench import FLOOR_TRIGGERS, bench_contract_floor

    periodic = [t for t in load_contract().topics.values() if t.rate_hz > 0 and t.publisher in (*FLOOR_TRIGGERS, '*')]
    r = bench_contract_floor(0.5)
    assert r['published_per_tick'] == len(periodic) == 18
    # TEM commands: plant, compensator; joint states: trajectory_generator (its soft start), both controllers
    assert r['deliveries_per_tick'] == sum(len(t.subscribers) for t in periodic) == 24
    assert r['callbacks_per_tick'] == 2 + r['deliveries_per_tick']


def test_cli_parser_does_not_import_the_heavy_subcommands():
    """Every sma-wrist command builds the whole parser: it must not import scipy.signal (diagnose)
    or the plant (emulator), ~1.5 s of start-up for a command that needs neither."""
    code = (
        'import sys; from sma_wrist import cli; cli.build_parser(); '
        'print(sorted(m for m in ("scipy.signal", "sma_wrist.diagnose", "sma_wrist.core.plant.wrist") if m in sys.modules))'
    )
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == '[]'


def test_cli_run_takes_the_payload_and_mode_of_its_params_file(tmp_path):
    """config/wrist.yaml (which users copy) sets plant_sim's payload_kg and adaptive_controller's mode; `run
    --params-file` ran the options' defaults (0.3 kg, inverse_adaptive) over them and never checked their values.
    Now the file's values are used where the command line names none, checked, and the command line still wins."""
    f = tmp_path / 'mine.yaml'
    f.write_text(
        'plant_sim:\n  ros__parameters:\n    payload_kg: 0.6\nadaptive_controller:\n  ros__parameters:\n    mode: pid\n'
    )
    r = _cli('run', '--duration', '0.5', '--quiet', '--json', '--params-file', str(f))
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert (out['controller'], out['payload_kg']) == ('pid', 0.6)
    r = _cli('run', '--duration', '0.5', '--quiet', '--json', '--params-file', str(f), '--payload-kg', '0.1')
    assert json.loads(r.stdout)['payload_kg'] == 0.1 and json.loads(r.stdout)['controller'] == 'pid'
    for text, named in (
        ('plant_sim:\n  ros__parameters:\n    payload_kg: heavy\n', "payload_kg 'heavy'"),
        ('plant_sim:\n  ros__parameters:\n    payload_kg: .nan\n', 'payload_kg nan'),
        ('adaptive_controller:\n  ros__parameters:\n    mode: foo\n', "mode 'foo'"),
    ):
        f.write_text(text)
        r = _cli('run', '--duration', '0.5', '--quiet', '--params-file', str(f))
        assert r.returncode == 2 and named in r.stderr and 'Traceback' not in r.stderr, r.stderr


def test_a_params_file_naming_no_node_of_the_package_is_refused(tmp_path):
    """A misspelt node name (`plant_simm:`) was ignored by run, sweep and emulate-device, while a misspelt
    parameter name was refused: the file's values never reached a node. The package's node names are setup.py's
    console scripts."""
    import ast

    from sma_wrist.nodes.common import NODE_NAMES

    tree = ast.parse((Path(__file__).parents[1] / 'setup.py').read_text())
    nodes = next(
        n.value for n in ast.walk(tree) if isinstance(n, ast.Assign) and getattr(n.targets[0], 'id', '') == 'NODES'
    )
    assert sorted(ast.literal_eval(nodes)) == sorted(NODE_NAMES)
    f = tmp_path / 'typo.yaml'
    f.write_text('plant_simm:\n  ros__parameters:\n    payload_kg: 0.5\n')
    r = _cli('run', '--duration', '0.5', '--quiet', '--params-file', str(f))
    assert r.returncode == 2 and 'node plant_simm in' in r.stderr and 'Traceback' not in r.stderr, r.stderr
    f.write_text(
        '/wrist/plant_sim:\n  ros__parameters:\n    payload_kg: 0.5\n/**:\n  ros__parameters:\n    use_sim_time: true\n'
    )  # a namespace and a wildcard are the user's business
    assert _cli('run', '--duration', '0.5', '--quiet', '--params-file', str(f)).returncode == 0


def test_a_nominal_run_logs_no_warning_and_starts_from_the_wrists_angle(tmp_path):
    """The README's demo (inverse_adaptive, 0.3 kg) for its first 35 s, start-up and the soft start's end included:
    no WARN or ERROR line, since a console warning asks the user to act and the saturations the loop rides through
    (a command at its limit while the wrist catches up) are /diagnostics matters. The reference starts at the
    measured angle, not 0.44 rad above it at the sine's first value."""
    from sma_wrist import runtime
    from sma_wrist.runtime.rclpy import logging as rlog

    runtime.activate()
    lines = []
    remove = rlog.add_sink(lambda sev, name, msg, t: lines.append((int(sev), name, msg)))
    try:
        with rlog.silenced():
            s = run_closed_loop(
                'inverse_adaptive',
                0.3,
                35.0,
                tmp_path / 'bag',
                extra_params={'/trajectory_generator': {'soft_start_s': 30.0}},
            )  # as run sets it
    finally:
        remove()
    loud = [(name, msg) for sev, name, msg in lines if sev >= int(rlog.LoggingSeverity.WARN)]
    assert loud == []
    data = read_bag(tmp_path / 'bag', ['/diagnostics'])
    saturated = [
        st.name
        for m in data['/diagnostics'][1]
        for st in m.status
        if st.name.endswith('saturation') and int.from_bytes(st.level, 'little') == 1
    ]
    assert saturated  # the loop did saturate: /diagnostics has it, at WARN
    run = s.run
    assert abs(run.q_d[0] - run.q[0]) < 1e-3  # the soft start: the first reference is the measured angle
    k = int(np.argmax(run.t >= 30.5))  # then the sine itself (stamped one tick after its own clock)
    assert abs(run.q_d[k] - (0.524 + 0.524 * math.sin(0.1 * (run.t[k] - 0.01)))) < 1e-9


def test_cli_run_plot_writes_the_tracking_plot_and_says_what_next(tmp_path):
    """`run --plot` draws the recorded run with compare's plot (angle, error, temperatures, TEM commands) and the
    summary names the bag, the plot and the next commands; a plot it cannot write is refused before the run."""
    bag, png = tmp_path / 'demo', tmp_path / 'demo.png'
    r = _cli('run', '--duration', '2', '--bag', str(bag), '--plot', str(png), '--quiet')
    assert r.returncode == 0, r.stderr
    assert png.stat().st_size > 10000 and png.read_bytes()[:4] == b'\x89PNG'
    assert f'bag: {bag}' in r.stdout and f'plot: {png}' in r.stdout
    assert f'sma-wrist compare {bag}' in r.stdout and '--params-file' in r.stdout
    assert 'whole run' in r.stdout and 'from the measured angle with --soft-start' in r.stdout
    # without --bag the run is measured through a temporary bag, and plotted from it all the same
    unkept = tmp_path / 'unkept.png'
    r = _cli('run', '--duration', '2', '--plot', str(unkept), '--quiet')
    assert r.returncode == 0, r.stderr
    assert unkept.read_bytes()[:4] == b'\x89PNG' and f'plot: {unkept}' in r.stdout and 'bag:' not in r.stdout
    bad = _cli('run', '--duration', '1', '--quiet', '--bag', str(tmp_path / 'b'), '--plot', str(tmp_path / 'x.bogus'))
    assert bad.returncode == 2 and 'not an image format' in bad.stderr and 'Traceback' not in bad.stderr
    assert not (tmp_path / 'b').exists()  # refused before anything was recorded


def test_cli_run_takes_a_params_files_soft_start_where_the_command_line_names_none(tmp_path):
    """`run` soft-starts the reference by its own default; a params file's trajectory_generator soft_start_s
    stands where --soft-start is not given (the file is the user's choice), and --soft-start beats both."""
    from sma_wrist.runs import load_run

    params = tmp_path / 'p.yaml'
    params.write_text('trajectory_generator:\n  ros__parameters:\n    soft_start_s: 0.0\n')
    first = {}
    for name, args in (
        ('default', ()),
        ('file', ('--params-file', str(params))),
        ('option', ('--params-file', str(params), '--soft-start', '30')),
    ):
        r = _cli('run', '--duration', '2', '--quiet', '--bag', str(tmp_path / name), *args)
        assert r.returncode == 0, r.stderr
        run = load_run(tmp_path / name)
        first[name] = (float(run.q_d[0]), float(run.q[0]))
    # soft-started: the reference starts at the wrist's measured angle; without: at the sine's first value
    assert abs(first['default'][0] - first['default'][1]) < 0.02
    assert abs(first['option'][0] - first['option'][1]) < 0.02
    assert abs(first['file'][0] - first['file'][1]) > 0.1
