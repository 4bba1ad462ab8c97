"""sma-wrist sweep: the N-wrist compositions equal the one-wrist ones, the vectorised loops agree with
the node graph, chunking and Dask change nothing, bad input and Ctrl-C (doc/howto/sweep.md)."""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sma_wrist.core.control.joint_controller import MODES, JointController, JointControllerParams
from sma_wrist.core.control.tem import TemLoop
from sma_wrist.core.errors import ModelInputError, ParameterError, SmaWristError
from sma_wrist.core.hysteresis.default_params import default_sdgpi
from sma_wrist.plants.spread import Scenario, sample
from sma_wrist.sweep.laws import JointControllerBank, TemLoopBank
from sma_wrist.sweep.run import (
    SweepConfig,
    add_reach_floors,
    format_table,
    make_cases,
    parse_perturbations,
    run_sweep,
    split_chunks,
    summarise,
)
from sma_wrist.sweep.simulate import Case, sign_changes_per_s, simulate


@pytest.mark.parametrize('mode', MODES)
def test_joint_controller_bank_equals_one_wrist_objects(mode: str) -> None:
    rng = np.random.default_rng(1)
    n = 4
    bank = JointControllerBank(JointControllerParams(mode=mode), n)
    ones = [JointController(JointControllerParams(mode=mode)) for _ in range(n)]
    q = 0.5 + 0.2 * rng.standard_normal(n)
    for k in range(400):  # 4 s at 100 Hz around a reversal of the Sec. 6.1 sine
        t = 14.0 + 0.01 * k
        q_d, qd_d, qdd_d = 0.524 + 0.524 * np.sin(0.1 * t), 0.0524 * np.cos(0.1 * t), -0.00524 * np.sin(0.1 * t)
        q = q + 0.003 * rng.standard_normal(n)
        qdot = rng.standard_normal(n) * 0.05
        force, strain, T, sat = bank.update(q, qdot, q_d, qd_d, qdd_d, 0.01)
        for j, c in enumerate(ones):
            cmd = c.update(float(q[j]), float(qdot[j]), q_d, qd_d, qdd_d, 0.01)
            np.testing.assert_array_equal(strain[j], cmd.strain_desired)
            assert sat[j] == cmd.saturated
            if mode == 'inverse_adaptive':
                np.testing.assert_array_equal(force[j], cmd.force_N)
            else:
                np.testing.assert_array_equal(T[j], cmd.temperature_desired_C)


@pytest.mark.parametrize('mode', MODES)
def test_joint_controller_bank_rejects_non_finite_input(mode: str) -> None:
    """The bank checks its inputs once per call (not per law object): a NaN angle is named, not used."""
    bank = JointControllerBank(JointControllerParams(mode=mode), 3)
    q = np.array([0.5, np.nan, 0.5])
    with pytest.raises(ModelInputError, match='q ='):
        bank.update(q, np.zeros(3), 0.5, 0.0, 0.0, 0.01)
    if mode != 'pid':
        with pytest.raises(ModelInputError, match='qdot ='):
            bank.update(np.full(3, 0.5), np.array([0.0, np.inf, 0.0]), 0.5, 0.0, 0.0, 0.01)
        with pytest.raises(ModelInputError, match='dt'):
            bank.update(np.full(3, 0.5), np.zeros(3), 0.5, 0.0, 0.0, 0.0)


def test_tem_loop_bank_equals_one_wrist_loops() -> None:
    rng = np.random.default_rng(2)
    n = 3
    bank = TemLoopBank.like_node(n)
    ref = TemLoopBank.like_node(1)  # the constants as the node builds them
    assert ref.params.target_filter_s > 0  # the node's prefilter is part of what is compared
    ones = [TemLoop(ref.thermal, ref.params, ref.drive, ref.hold, 85.0, compiled=True) for _ in range(n)]
    T = np.full((n, 2), 30.0)
    for k in range(600):
        t = 0.01 * k
        T = T + 0.05 * rng.standard_normal((n, 2))
        T_d = None if k < 3 else np.clip(45.0 + 20.0 * np.sin(0.2 * t + np.arange(n)[:, None]) + 0.0 * T, 20, 80)
        u = bank.sample(t, T, T_d).copy()
        for j, loop in enumerate(ones):
            res = loop.sample(t, T[j], None if T_d is None else T_d[j])
            np.testing.assert_array_equal(u[j], res.command_V)


def test_sign_changes_count_flips_outside_the_deadband() -> None:
    u = np.array([5.0, 5.0, -5.0, 0.5, -0.5, 5.0, 5.0, -5.0, 0.0, 0.0, 5.0])[:, None]
    # + + - (0.5 -0.5 carry -) + + - (0 0 carry -) +: 4 flips over 10 intervals of 0.1 s
    assert sign_changes_per_s(u, 0.1)[0] == pytest.approx(4.0)
    assert sign_changes_per_s(np.full((10, 1), 3.0), 0.1)[0] == 0.0


def test_loops_do_not_depend_on_their_chunk() -> None:
    sc = sample(3, seed=4)
    cases = [Case(i, m, s) for i, (s, m) in enumerate(zip(sc, MODES))]
    together, _ = simulate(cases, 3.0)
    alone = [simulate([c], 3.0)[0][0] for c in cases]
    for a, b in zip(together, alone):
        assert a == b


def test_chunks_follow_the_work_and_the_workers() -> None:
    loops = list(range(400))
    sizes = lambda chunk, workers: [len(c) for c in split_chunks(loops, chunk, workers)]  # noqa: E731
    assert sizes(192, 1) == [134, 134, 132]  # at most 192, no short last chunk
    assert sizes(192, 2) == [100] * 4  # every worker as many chunks
    assert sizes(500, 2) == [200, 200]  # at least one chunk per worker
    assert sizes(192, 1000) == [1] * 400
    assert [x for c in split_chunks(loops, 7, 3) for x in c] == loops  # every loop once, in order
    assert split_chunks([], 192, 2) == []
    with pytest.raises(ParameterError, match='chunk = 0'):
        split_chunks(loops, 0)


def test_bad_input_gives_clear_errors() -> None:
    with pytest.raises(ParameterError, match='N = 0'):
        SweepConfig(n_plants=0)
    with pytest.raises(ParameterError, match="unknown perturbation 'stiffness'"):
        parse_perturbations(['stiffness=1:2'])
    with pytest.raises(ParameterError, match='outside the model'):
        parse_perturbations(['stroke_scale=0.1:1.2'])
    with pytest.raises(ParameterError, match='controllers'):
        SweepConfig(controllers=('bang_bang',))
    with pytest.raises(ParameterError, match=r'^controllers \(an empty name: a stray comma\?\): choose'):
        SweepConfig(controllers=('pid', '', ''))  # --controllers pid,,
    with pytest.raises(ParameterError, match='named twice'):
        SweepConfig(controllers=('pid', 'pid'))
    with pytest.raises(ParameterError, match='no closed loops'):
        simulate([], 1.0)
    with pytest.raises(ParameterError, match='reach floor is computed on the project'):
        SweepConfig(plant='phase_fraction', reach=True)


def test_cli_reports_bad_input_without_traceback() -> None:
    env = {**os.environ, 'PYTHONPATH': os.getcwd()}
    for args, text in (
        (['--plants', '0'], 'N = 0'),
        (['--perturb', 'foo=1'], "unknown perturbation 'foo'"),
        (['--perturb', 'temp_lag_s=0:5'], 'outside the model'),
    ):
        p = subprocess.run(
            [sys.executable, '-m', 'sma_wrist', 'sweep', *args], capture_output=True, text=True, env=env, timeout=120
        )
        assert p.returncode == 2 and text in p.stderr and 'Traceback' not in p.stderr


@pytest.mark.parametrize(
    'argv',
    [
        ['sweep', '--seed', '-1'],
        ['experiment', '--family-seed', '-1'],
        ['experiment', '--workers', '-3'],
        ['emulate-device', '--seed', '-1'],
    ],
)
def test_negative_seeds_and_worker_counts_are_refused_by_the_parser(argv, capsys) -> None:
    """A negative seed reached numpy's SeedSequence (ValueError traceback after the set-up), a negative
    --workers the process pool; both are usage errors naming the option, exit 2, before anything runs."""
    from sma_wrist.cli import build_parser

    with pytest.raises(SystemExit) as e:
        build_parser().parse_args(argv)
    assert e.value.code == 2 and f'argument {argv[1]}: {argv[2]!r} must be >= 0' in capsys.readouterr().err


def test_an_output_path_that_cannot_be_made_is_a_clear_error(tmp_path) -> None:
    """sweep --out, run --bag, experiment --out under a regular file: the path and the reason, exit 2, before
    any loop runs (a traceback from mkdir before)."""
    (tmp_path / 'file').write_text('')
    under_file = str(tmp_path / 'file' / 'out')
    for args in (
        [
            'sweep',
            '--plants',
            '1',
            '--controllers',
            'pid',
            '--duration',
            '2',
            '--no-nominal',
            '--quiet',
            '--out',
            under_file,
        ],
        ['run', '--duration', '0.5', '--bag', under_file],
        ['experiment', '--duration', '0.5', '--payloads', '0.3', '--out', under_file],
    ):
        p = subprocess.run(
            [sys.executable, '-m', 'sma_wrist', *args],
            capture_output=True,
            text=True,
            env={**os.environ, 'PYTHONPATH': os.getcwd()},
            timeout=120,
        )
        assert p.returncode == 2 and f'error: cannot use {under_file}' in p.stderr, (args, p.stderr[-500:])
        assert 'Traceback' not in p.stderr


def test_an_output_folder_that_is_a_file_is_named_without_the_run_only_bag_hint(tmp_path, capsys) -> None:
    """experiment --out FILE told the user to 'choose a new --bag directory', an option it does not have."""
    from sma_wrist.cli import main

    f = tmp_path / 'file'
    f.write_text('')
    assert main(['experiment', '--duration', '0.5', '--payloads', '0.3', '--family', '0', '--out', str(f)]) == 2
    err = capsys.readouterr().err
    assert err == f'error: {f} already exists\n'


def test_an_os_error_without_a_path_keeps_its_traceback(monkeypatch) -> None:
    """main turns a user's unusable path into one line; an OSError that names no path is a defect, not hidden."""
    import argparse

    from sma_wrist import cli

    def boom(_: argparse.Namespace) -> int:
        raise OSError('no path')

    class Parser:
        def parse_args(self, argv):  # type: ignore[no-untyped-def]
            return argparse.Namespace(func=boom)

    monkeypatch.setattr(cli, 'build_parser', Parser)
    with pytest.raises(OSError, match='no path'):
        cli.main([])


def test_ctrl_c_keeps_finished_chunks(tmp_path) -> None:
    cfg = SweepConfig(n_plants=2, controllers=('pid',), duration_s=2.0, chunk=2, nominal=True)
    calls = []

    def progress(done: float) -> None:
        calls.append(done)
        if done > 2:  # the first chunk (2 loops) is written: Ctrl-C during the second
            raise KeyboardInterrupt

    res = run_sweep(cfg, tmp_path, progress=progress)
    assert res.interrupted
    lines = (tmp_path / 'results.jsonl').read_text().splitlines()
    assert len(lines) == 2 == len(res.rows)
    assert json.loads((tmp_path / 'sweep.json').read_text())['interrupted'] is True


def test_sweep_writes_table_json_and_plots(tmp_path) -> None:
    cfg = SweepConfig(n_plants=3, controllers=('direct_adaptive', 'pid'), duration_s=2.0, chunk=4)
    res = run_sweep(cfg, tmp_path)
    n = len(make_cases(cfg))
    assert len(res.rows) == n == 3 * 2 + 3 * 2
    assert [r['index'] for r in res.rows] == list(range(n))
    data = json.loads((tmp_path / 'sweep.json').read_text())
    assert {s['group'] for s in data['summary']} == {'nominal', 'spread'}
    assert 'spread' in (tmp_path / 'table.txt').read_text()
    pytest.importorskip('matplotlib')
    for f in ('cdf.png', 'heatmap.png'):
        assert (tmp_path / f).stat().st_size > 1000


def test_each_loop_reports_the_highest_stress_its_wires_carried() -> None:
    """wire_stress_max_MPa is the plant's own wire stress (plant_sim's /wrist/muscle_i/stress), its highest over
    every tick of the run: replaying the recorded commands on a fresh plant gives the same peak; the summary's
    worst is the rows' largest."""
    from sma_wrist.core.plant.wrist import PlantParams
    from sma_wrist.plants import make_plant
    from sma_wrist.sweep.simulate import TICK_S

    cases = [
        Case(0, 'pid', Scenario(payload_kg=0.1), 'nominal'),
        Case(1, 'inverse_adaptive', Scenario(payload_kg=0.6), 'nominal'),
        Case(2, 'pid', Scenario(payload_kg=0.6, stroke_scale=0.8), 'spread'),
    ]
    rows, tr = simulate(cases, 8.0, record=True)
    wrists = make_plant('sdgpi', [c.scenario for c in cases], PlantParams())
    steps = int(round(TICK_S / wrists.params.dt))
    peak = np.zeros(len(cases))
    for u in tr.command_V:
        peak = np.maximum(peak, wrists.wire_stress_Pa.max(axis=1))
        wrists.advance(u, steps)
    got = np.array([r['wire_stress_max_MPa'] for r in rows])
    np.testing.assert_allclose(got, peak * 1e-6, rtol=1e-12)
    np.testing.assert_array_equal([r['angle_step_max_rad'] for r in rows], np.abs(np.diff(tr.q, axis=0)).max(axis=0))
    assert 100.0 < got.min() and got[1] > got[0]  # a pre-loaded pair; the heavier payload pulls harder
    worst = {(s['group'], s['controller']): s['worst_wire_stress_max_MPa'] for s in summarise(rows)}
    assert worst == {('nominal', 'pid'): got[0], ('nominal', 'inverse_adaptive'): got[1], ('spread', 'pid'): got[2]}
    assert f'{got[1]:5.0f}' in format_table(summarise(rows))


def test_a_loop_that_holds_a_wire_at_the_models_load_bound_is_marked_not_physics() -> None:
    """overload_s: the time the plant held a wire's load at MuscleGeometry.max_load_kgf (plant_sim's 'wire_load'
    ERROR). With the bound lowered to 0.8 kgf the inverse mode's loop crosses it (its pair runs near 1 kgf); at
    the real 3 kgf it does not, and the table says which loops left the model."""
    from sma_wrist.core.hysteresis.muscle import MuscleGeometry
    from sma_wrist.core.plant.wrist import PlantParams

    cases = [Case(0, 'inverse_adaptive', Scenario(payload_kg=0.6), 'nominal')]
    low = PlantParams(muscle=MuscleGeometry(max_load_kgf=0.8))
    rows_low, _ = simulate(cases, 40.0, base=low)
    rows, _ = simulate(cases, 40.0)
    assert rows[0]['overload_s'] == 0.0 and 0.0 < rows_low[0]['overload_s'] < 40.0
    assert rows_low[0]['wire_stress_max_MPa'] == pytest.approx(float(MuscleGeometry().stress_Pa(0.8)) * 1e-6, rel=1e-6)
    assert 'not physics: 1 nominal inverse_adaptive' in format_table(summarise(rows_low))
    assert 'not physics' not in format_table(summarise(rows))


def test_dask_cluster_gives_the_single_process_numbers(tmp_path) -> None:
    distributed = pytest.importorskip('distributed')
    cfg = SweepConfig(n_plants=2, controllers=('pid', 'direct_adaptive'), duration_s=2.0, chunk=3, nominal=False)
    local = run_sweep(cfg)
    # in-process workers: the scheduler, task graph and transfer are the real ones, start-up ~1 s
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None) as lc:
        remote = run_sweep(cfg, tmp_path, scheduler=lc.scheduler_address)
    assert remote.rows == local.rows


def test_worker_processes_give_the_single_process_numbers(tmp_path) -> None:
    cfg = SweepConfig(n_plants=2, controllers=('pid', 'direct_adaptive'), duration_s=2.0, chunk=8, nominal=False)
    local = run_sweep(cfg)
    done: list[float] = []
    # 4 loops over 2 processes: the chunk is cut to 2 loops so both get one
    forked = run_sweep(cfg, tmp_path, progress=done.append, workers=2)
    assert forked.rows == local.rows and done[-1] == 4 and len(done) == 2
    assert len((tmp_path / 'results.jsonl').read_text().splitlines()) == 4
    with pytest.raises(ParameterError, match='workers'):
        run_sweep(cfg, workers=-1)


def test_reach_floors_split_the_family_into_plants_a_controller_can_track_and_the_rest() -> None:
    """--reach: a wire 10 degC hotter than the model holds the joint short of the sine's top inside
    20-80 degC (doc/explanation/controllers.md: floor 33.9 % at 0.3 kg), one 5 degC hotter nearly reaches it (3.6 %):
    each plant's floor once, on every controller's row, and the summary over the plants under 15 %
    (rows as the sweep writes them; the loops' errors are made up, the floors are computed)."""
    from sma_wrist.plants.spread import Scenario

    rows = []
    for shift, err in ((10.0, 40.0), (5.0, 6.0)):
        for c in ('pid', 'inverse_adaptive'):
            rows.append(
                {
                    'index': len(rows),
                    'group': 'spread',
                    'controller': c,
                    'max_error_pct': err + len(rows),
                    'rms_error_pct': 1.0,
                    'sign_changes_per_s': 1.0,
                    **Scenario(transition_shift_C=shift, payload_kg=0.3, temp_noise_C=0.0).to_dict(),
                }
            )
            rows[-1]['temp_noise_C'] = 0.1 * len(rows)  # sensors differ per row: the same plant all the same
    add_reach_floors(rows)
    hot, warm = rows[0]['reach_floor_pct'], rows[2]['reach_floor_pct']
    assert rows[1]['reach_floor_pct'] == hot and rows[3]['reach_floor_pct'] == warm
    assert hot > 25.0 and warm < 10.0
    pid = next(s for s in summarise(rows) if s['controller'] == 'pid')
    assert pid['loops'] == 2 and pid['reachable_loops'] == 1
    assert pid['reachable']['median_max_error_pct'] == 8.0 and pid['reachable']['share_under_15_pct'] == 1.0
    assert 'reach floor is under 15 %' in format_table(summarise(rows))


def _identified_wrist_params(tmp_path: Path) -> Path:
    """A user's params file as `sma-wrist identify` writes it (a wire 4 degC hotter than the built-in one, TEMs 10 %
    stronger with 15 % less loss), plus tuned laws in three nodes and a change that only paces the wall clock."""
    import yaml

    from sma_wrist.core.hysteresis.params_file import save_hysteresis
    from sma_wrist.core.thermal.heat_balance import ThermalParams
    from sma_wrist.core.thermal.params_file import write_thermal_file
    from sma_wrist.identify.wrist import shifted_wire, wrist_params

    wire, tems = tmp_path / 'hysteresis.yaml', tmp_path / 'thermal.yaml'
    save_hysteresis(wire, shifted_wire(default_sdgpi(), 4.0))
    write_thermal_file(tems, ThermalParams().scaled(gain=1.1, losses=0.85))
    nodes, _ = wrist_params(wire, shifted_wire(default_sdgpi(), 4.0), tems, preload_mm=2.1)
    tuned = {
        'adaptive_controller': {'reversal_lead_s': 2.0, 'pid.kp': 300.0, 'adaptive.c1': 4.0},
        # a chatter guard that engages within the test's 6 s (the default's 2.5 /s over 20 s would not)
        'tem_controller': {
            'gain_per_s': 1.5,
            'target_filter_s': 0.3,
            'chatter_guard.limit_per_s': 0.4,
            'chatter_guard.window_s': 1.0,
            'chatter_guard.rate_filter_s': 0.3,
        },
        'hysteresis_compensator': {'shift_gain_per_s': 1.5, 'observer.correction_s': 0.25},
        'plant_sim': {'real_time_factor': 2.0},
    }
    for node, values in tuned.items():
        nodes.setdefault(node, {}).update(values)
    f = tmp_path / 'wrist_params.yaml'
    f.write_text(yaml.safe_dump({n: {'ros__parameters': v} for n, v in nodes.items()}))
    return f


@pytest.mark.parametrize('mode', ['pid', 'inverse_adaptive'])
def test_a_params_file_reaches_the_sweep_as_it_reaches_the_graph(mode: str, tmp_path: Path) -> None:
    """`sma-wrist sweep --params-file`: an identified wire and TEMs and tuned laws, in the node graph (the file on
    the command line, a perturbed plant) and in the sweep (graph_params.loop_settings): the same TEM commands and
    measured angles to the last bit over 6 s, and not the loop of config/wrist.yaml alone."""
    from sma_wrist.closed_loop import run_closed_loop
    from sma_wrist.sweep.graph_params import loop_settings
    from sma_wrist.sweep.simulate import Case, simulate

    f = _identified_wrist_params(tmp_path)
    sc = Scenario(
        payload_kg=0.4,
        transition_shift_C=-3.0,
        stroke_scale=0.9,
        tem_gain_scale=1.1,
        heat_loss_scale=0.9,
        ambient_offset_C=2.0,
        temp_noise_C=0.1,
        temp_lag_s=0.1,
        angle_noise_rad=0.002,
        noise_seed=7,
    )
    extra = {
        '/plant_sim': {
            'plant': 'sdgpi',
            'scenario.noise_seed': sc.noise_seed,
            **{f'scenario.{k}': v for k, v in sc.to_dict().items() if k not in ('payload_kg', 'noise_seed')},
        }
    }
    run = run_closed_loop(mode, sc.payload_kg, 6.0, tmp_path / 'bag', params_files=[f], extra_params=extra).run
    settings = loop_settings([f])
    assert settings.changed['plant_sim']['hysteresis_file'] == str(tmp_path / 'hysteresis.yaml')
    assert settings.changed['tem_controller']['gain_per_s'] == 1.5
    _, tr = simulate([Case(0, mode, sc)], 6.0, record=True, **settings.kwargs)
    k, kc = np.rint(run.t / 0.01).astype(int), np.rint(run.command_t / 0.01).astype(int)
    assert np.max(np.abs(run.q - tr.q_measured[k, 0])) <= 1e-12
    np.testing.assert_array_equal(run.command_V, tr.command_V[kc, 0])
    _, plain = simulate([Case(0, mode, sc)], 6.0, record=True)
    assert np.max(np.abs(plain.command_V[kc, 0] - run.command_V)) > 1e-2  # the file reached the loop
    if mode == 'pid':  # no sign change in its first 6 s: nothing for the guard to count
        return
    unguarded = dict(
        settings.kwargs,
        tem_loop=dataclasses.replace(
            settings.kwargs['tem_loop'],
            params=dataclasses.replace(settings.kwargs['tem_loop'].params, chatter_limit_per_s=0.0),
        ),
    )
    _, free = simulate([Case(0, mode, sc)], 6.0, record=True, **unguarded)
    assert np.max(np.abs(free.command_V[kc, 0] - run.command_V)) > 1e-2  # and its guard engaged in both


def test_the_sweep_refuses_what_it_cannot_honour_and_names_it(tmp_path: Path) -> None:
    """A parameter the sweep's loops cannot take is refused, never swept at the default in silence: the seed's
    composition (stress and memory sources), the mode (--controllers), a misspelt name, a bad value (the node's own
    refusal), pre-loads the nodes do not share; and the CLI says so without a traceback."""
    import yaml

    from sma_wrist.sweep.graph_params import loop_settings

    def params(nodes: dict) -> Path:
        f = tmp_path / f'p{len(list(tmp_path.iterdir()))}.yaml'
        f.write_text(yaml.safe_dump({n: {'ros__parameters': v} for n, v in nodes.items()}))
        return f

    with pytest.raises(ParameterError, match=r'stress_source = .desired. .*memory_source = .commanded.'):
        loop_settings([Path(__file__).parent.parent / 'config' / 'paper_table_6_1.yaml'])
    with pytest.raises(ParameterError, match=r'adaptive_controller.mode .*--controllers'):
        loop_settings([params({'adaptive_controller': {'mode': 'pid'}})])
    with pytest.raises(ParameterError, match=r'gain_per_sec under tem_controller'):
        loop_settings([params({'tem_controller': {'gain_per_sec': 2.0}})])
    with pytest.raises(ParameterError, match=r'tem_controller: invalid parameters: face_min_C = 40.0 must be below'):
        loop_settings([params({'tem_controller': {'face_min_C': 40.0, 'face_max_C': 40.0}})])
    with pytest.raises(ParameterError, match=r'TemController: invalid parameter face_max_C: .*out of range'):
        loop_settings([params({'tem_controller': {'face_max_C': 20.0}})])
    with pytest.raises(ParameterError, match=r'preload_elongation_mm differs'):
        loop_settings([params({'plant_sim': {'preload_elongation_mm': 2.5}})])
    # a commissioned phase-fraction model wire: the sampled plants perturb an SD-GPI, so the key is named and refused
    from sma_wrist.core.hysteresis.phase_fraction import PhaseFractionWire
    from sma_wrist.core.hysteresis.wire_file import save_wire_file

    wire = save_wire_file(tmp_path / 'wire.yaml', PhaseFractionWire())
    with pytest.raises(ParameterError, match=r'plant_sim.wire_file = .*not a phase-fraction wire'):
        loop_settings([params({'plant_sim': {'wire_file': str(wire)}})])
    with pytest.raises(ParameterError, match=r'no such file'):
        loop_settings([tmp_path / 'missing.yaml'])
    (tmp_path / 'broken.yaml').write_text('tem_controller:\n  ros__parameters:\n    gain_per_s: [1.0\n')
    with pytest.raises(SmaWristError, match=r'broken.yaml: invalid YAML'):
        loop_settings([tmp_path / 'broken.yaml'])
    with pytest.raises(
        ParameterError, match=r"TemController: invalid parameter.*'gain_per_s'.*expecting type 'DOUBLE'"
    ):
        loop_settings([params({'tem_controller': {'gain_per_s': 'fast'}})])
    with pytest.raises(ParameterError, match=r'thermal_adaptation'):
        loop_settings([params({'tem_controller': {'thermal_adaptation.apply_after_s': 20.0}})])
    out = subprocess.run(
        [
            sys.executable,
            '-m',
            'sma_wrist',
            'sweep',
            '--plants',
            '1',
            '--duration',
            '2',
            '--quiet',
            '--out',
            str(tmp_path / 'sw'),
            '--params-file',
            str(params({'plant_sim': {'payload_kg': 0.5}})),
        ],
        capture_output=True,
        text=True,
    )
    assert out.returncode == 2 and 'Traceback' not in out.stderr, out.stderr
    assert 'plant_sim.payload_kg = 0.5' in out.stderr and '--payloads' in out.stderr
    assert not (tmp_path / 'sw' / 'results.jsonl').exists()  # refused before any loop ran


def test_a_sweep_with_a_params_file_runs_it_in_every_worker_and_records_it(tmp_path: Path) -> None:
    """The graph's settings travel to the worker processes (and, the same way, to Dask's): the loops are those of
    one process with the same file, differ from the defaults', and sweep.json names what the file changed."""
    import yaml

    f = tmp_path / 'tuned.yaml'
    f.write_text(
        yaml.safe_dump(
            {
                'tem_controller': {'ros__parameters': {'gain_per_s': 2.0}},
                'adaptive_controller': {'ros__parameters': {'pid.kp': 250.0}},
            }
        )
    )
    cfg = SweepConfig(
        n_plants=2,
        controllers=('pid', 'inverse_adaptive'),
        duration_s=8.0,
        chunk=8,
        nominal=False,
        params_files=(str(f),),
    )
    one = run_sweep(cfg)
    forked = run_sweep(cfg, tmp_path / 'out', workers=2)
    assert forked.rows == one.rows
    plain = run_sweep(dataclasses.replace(cfg, params_files=()))
    assert all(a['rms_error_pct'] != b['rms_error_pct'] for a, b in zip(one.rows, plain.rows))
    data = json.loads((tmp_path / 'out' / 'sweep.json').read_text())
    assert data['parameters_changed'] == {
        'tem_controller': {'gain_per_s': 2.0},
        'adaptive_controller': {'pid.kp': 250.0},
    }
    assert data['config']['params_files'] == [str(f)]
    # reading the files leaves the process's logging as it was (a --log-level for the nodes would set it for good)
    from sma_wrist.runtime.rclpy import logging as rlog

    assert rlog.get_logger_effective_level('') == rlog.LoggingSeverity.INFO and rlog.stream_output


def test_an_experiment_refuses_a_params_file_its_family_cannot_honour_before_any_run(tmp_path: Path) -> None:
    """`sma-wrist experiment --family N --params-file F`: the family honours F as the graph runs do, so a file the
    sweep cannot honour stops the experiment before its first run, not after them."""
    from sma_wrist.experiment import run_experiment

    paper = Path(__file__).parent.parent / 'config' / 'paper_table_6_1.yaml'
    with pytest.raises(ParameterError, match='stress_source'):
        run_experiment(['pid'], [0.3], tmp_path / 'exp', duration_s=2.0, params_files=[str(paper)], family=1)
    assert not (tmp_path / 'exp').exists()


def test_an_experiment_reads_its_params_files_for_the_family_once(tmp_path: Path, monkeypatch) -> None:
    """experiment --family N --params-file F checks F for the family before its runs and hands the family's sweep
    what it read: the nodes are built once for F, not twice, and the family still runs with F."""
    import io

    import yaml

    from sma_wrist.experiment import run_experiment
    from sma_wrist.sweep import graph_params

    f = tmp_path / 'tuned.yaml'
    f.write_text(yaml.safe_dump({'tem_controller': {'ros__parameters': {'gain_per_s': 2.0}}}))
    calls = []
    real = graph_params.loop_settings
    monkeypatch.setattr(graph_params, 'loop_settings', lambda *a, **k: calls.append(a) or real(*a, **k))
    run_experiment(
        ['pid'],
        [0.3],
        tmp_path / 'exp',
        duration_s=2.0,
        params_files=[str(f)],
        family=1,
        workers=1,
        plots=False,
        log=io.StringIO(),
    )
    assert len(calls) == 1
    data = json.loads((tmp_path / 'exp' / 'family' / 'sweep.json').read_text())
    assert data['parameters_changed'] == {'tem_controller': {'gain_per_s': 2.0}}


def test_the_sweep_reads_a_tick_as_a_node_reads_its_header_stamp() -> None:
    """core.stamps.stamp_seconds (the sweep's ticks, hysteresis_compensator's estimate) equals sec + 1e-9 nanosec of
    the header a node receives (WristNode.stamp_s) for every stamp, and is not ns * 1e-9, which the laws'
    differences would see in the last bits."""
    from rclpy.time import Time

    from sma_wrist.core.stamps import stamp_seconds

    ns = np.random.default_rng(0).integers(0, 200 * 10**9, 2000).tolist() + [10**9, 126 * 10**9 + 10**7]
    for n in ns:
        st = Time(nanoseconds=n).to_msg()
        assert stamp_seconds(n) == st.sec + 1e-9 * st.nanosec
    assert sum(stamp_seconds(n) != n * 1e-9 for n in ns) > 100


def test_a_params_files_soft_start_reaches_the_sweeps_loops(tmp_path: Path) -> None:
    """trajectory_generator's soft_start_s in a params file is the sweep loops' (not refused, not dropped), and it
    changes where their references start."""
    from sma_wrist.sweep.graph_params import loop_settings
    from sma_wrist.sweep.simulate import Case, simulate

    f = tmp_path / 'p.yaml'
    f.write_text('trajectory_generator:\n  ros__parameters:\n    soft_start_s: 5.0\n')
    settings = loop_settings([f])
    assert settings.kwargs['soft_start_s'] == 5.0 and settings.changed == {
        'trajectory_generator': {'soft_start_s': 5.0}
    }
    _, soft = simulate([Case(0, 'pid', Scenario(payload_kg=0.3))], 6.0, record=True, **settings.kwargs)
    _, plain = simulate([Case(0, 'pid', Scenario(payload_kg=0.3))], 6.0, record=True, soft_start_s=0.0)
    assert abs(soft.q_d[1, 0] - soft.q_measured[1, 0]) < 1e-12 and abs(plain.q_d[1, 0] - 0.524) < 1e-12
    assert soft.q_d[-1, 0] == plain.q_d[-1, 0]  # joined: the sine itself after 5 s
