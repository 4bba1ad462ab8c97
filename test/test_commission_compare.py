"""How commissioning's verification compares the commissioned loop with the defaults (sma_wrist/commission/verify.py):
the metrics per cycle of the sine, the verdict against the spread of the cycles, one run where the parameters are
the defaults', the same start for every run. Synthetic runs and a stand-in for the node graph: light; the
measured comparison is `sma-wrist bench --section commission`'s."""

from __future__ import annotations

import contextlib
import dataclasses

import numpy as np
import pytest
import yaml

from sma_wrist.commission import verify as V
from sma_wrist.core.metrics import SEED_PERIOD_S
from sma_wrist.runs import RunData

RANGE = 1.048  # rad: the Sec. 6.1 sine's range


def sine_run(errors_rad, soft_start_s=30.0, start_error_rad=0.2, dt=0.05) -> RunData:
    """A run of the Sec. 6.1 sine: ``start_error_rad`` during the soft start, then a constant error per full cycle."""
    n = len(errors_rad)
    t = np.arange(0.0, soft_start_s + n * SEED_PERIOD_S + 2.0, dt)
    q_d = 0.524 + 0.524 * np.sin(0.1 * t)
    k = np.clip(np.floor((t - (t[-1] - n * SEED_PERIOD_S)) / SEED_PERIOD_S).astype(int), -1, n - 1)
    err = np.where(k < 0, start_error_rad, np.asarray(errors_rad)[np.maximum(k, 0)])
    z = np.zeros((t.size, 2))
    return RunData('synthetic', t, q_d + err, q_d, z, t, z, 0.3)


def test_each_full_cycle_is_measured_apart_from_the_soft_start():
    run = sine_run([0.01, 0.03])
    m = V.cycle_metrics(run, float(run.t[-1]))
    assert len(m['cycles']) == 2
    span = float(np.ptp(run.q_d))
    for c, e in zip(m['cycles'], (0.01, 0.03)):
        assert c['max_pct'] == pytest.approx(100 * e / span, abs=0.01)
        assert c['rms_pct'] == pytest.approx(100 * e / span, abs=0.01)
    assert m['start_up']['max_pct'] == pytest.approx(100 * 0.2 / span, abs=0.01)  # the soft start, apart
    # a run shorter than a cycle after its soft start has no cycle to compare
    assert V.cycle_metrics(sine_run([0.01]), 60.0) == {'cycles': [], 'start_up': None}


def side(*maxima, rms=None):
    return V.side([{'max_pct': m, 'rms_pct': m / 3 if rms is None else rms[i]} for i, m in enumerate(maxima)])


@pytest.mark.parametrize(
    'commissioned,default,verdict',
    [
        # means 6.0 against 5.0: one point worse, the cycles differing by 3 and 2 points: within the spread
        (side(4.5, 7.5), side(4.0, 6.0), 'within_spread'),
        # 20 against 6: beyond a spread of 2 points
        (side(19.0, 21.0), side(5.0, 7.0), 'worse'),
        (side(3.0, 3.5), side(20.0, 24.0), 'better'),
        # one cycle a side: no spread, so no verdict however far apart (one cycle against the next varied by up to
        # 14 points of max error on the same parameters)
        (side(20.0), side(6.0), 'spread_unknown'),
        # better in max, worse in RMS beyond its spread: worse wins
        (side(3.0, 3.2, rms=[4.0, 4.1]), side(20.0, 22.0, rms=[1.0, 1.1]), 'worse'),
    ],
)
def test_the_verdict_needs_a_difference_beyond_the_spread_of_the_cycles(commissioned, default, verdict):
    c = V.compare(commissioned, default)
    assert c['verdict'] == verdict, c


def test_the_spread_is_the_larger_range_of_the_two_sides():
    c = V.compare(side(10.0, 10.4), side(5.0, 8.0))  # ranges 0.4 and 3.0; difference 3.7
    assert c['max_pct'] == {'difference': 3.7, 'spread': 3.0} and c['verdict'] == 'worse'


def write(path, doc):
    path.write_text(yaml.safe_dump(doc))
    return path


def builtin_handed_over(tmp_path):
    """What commissioning hands over where nothing beat the built-in model: the built-in wire and heat balance as
    files, the windows, pre-load and payload of config/wrist.yaml (the nominal device)."""
    from sma_wrist.core.hysteresis.default_params import default_sdgpi
    from sma_wrist.core.hysteresis.params_file import save_hysteresis
    from sma_wrist.core.thermal.heat_balance import ThermalParams
    from sma_wrist.core.thermal.params_file import write_thermal_file
    from sma_wrist.identify.wrist import wrist_params

    h = save_hysteresis(tmp_path / 'hysteresis.yaml', default_sdgpi(), {'source': 'built-in'})
    th = write_thermal_file(tmp_path / 'thermal.yaml', ThermalParams())
    nodes, _ = wrist_params(h, default_sdgpi(), th, ThermalParams().window_C, preload_mm=1.98)
    nodes['hardware_bridge']['payload_kg'] = 0.3
    return nodes


def test_parameters_that_give_the_graph_the_defaults_values_are_the_same_parameters(tmp_path):
    nodes = builtin_handed_over(tmp_path)
    f = write(tmp_path / 'wrist_params.yaml', {n: {'ros__parameters': v} for n, v in nodes.items()})
    defaults = V.write_defaults(tmp_path / 'defaults.yaml', {})
    for ctrl in V.CONTROLLERS:
        assert V.differences(V.graph_values([f], ctrl), V.graph_values([defaults], ctrl)) == []
    # a window 7 degC higher (a wire transforming hotter): the controllers get other values, named
    nodes['adaptive_controller']['temperature_mid_C'] = 57.0
    nodes['hardware_bridge']['payload_kg'] = 0.45
    g = write(tmp_path / 'other.yaml', {n: {'ros__parameters': v} for n, v in nodes.items()})
    assert V.differences(V.graph_values([g], 'pid'), V.graph_values([defaults], 'pid')) == [
        'hardware_bridge.payload_kg',
        'adaptive_controller.temperature_mid_C',
    ]


class FakeGraph:
    """Stands in for run_closed_loop: records what each run got, returns a synthetic run per call."""

    def __init__(self, errors):
        self.errors = list(errors)
        self.calls = []
        self.clock = [0.0]  # device s: each run takes its duration and a second

    def __call__(self, ctrl, payload, duration, bag, files, extra_params, hardware, measure):
        from sma_wrist.closed_loop import RunSummary

        self.calls.append({'controller': ctrl, 'files': [str(f) for f in files], 'extra': extra_params})
        self.clock[0] += duration + 1.0
        run = sine_run(self.errors.pop(0))
        return RunSummary(None, ctrl, payload, duration, 1.0, 0, False, {'max_error_pct': 1.0}, run)


def verify_with(tmp_path, monkeypatch, params_file, errors, controllers=('pid',), budget_s=None):
    import sma_wrist.closed_loop as cl

    graph = FakeGraph(errors)
    monkeypatch.setattr(cl, 'run_closed_loop', graph)
    starts = []

    def settle_to_start(timeout_s):
        starts.append((len(graph.calls), timeout_s))
        graph.clock[0] += timeout_s  # the wrist never settles: each takes all it is given
        return {'settled': True, 'seconds': 1.0, 'muscle_C': [27.0, 27.0], 'face_C': [27.0, 27.0], 'angle_rad': 0.1}

    res = V.verify(
        tmp_path / 'out',
        lambda: contextlib.nullcontext('/dev/null'),
        params_file,
        {},
        list(controllers),
        duration_s=V.DURATION_S,
        diagnose=False,
        device_clock=lambda: graph.clock[0],
        settle_to_start=settle_to_start,
        budget_s=budget_s,
    )
    return res, graph, starts


def test_the_defaults_parameters_are_run_once_and_said_to_be_the_same(tmp_path, monkeypatch):
    nodes = builtin_handed_over(tmp_path)
    f = write(tmp_path / 'wrist_params.yaml', {n: {'ros__parameters': v} for n, v in nodes.items()})
    res, graph, starts = verify_with(tmp_path, monkeypatch, f, [[0.01, 0.02]])
    assert len(graph.calls) == 1 and [n for n, _ in starts] == [0]
    assert res['comparison']['pid']['verdict'] == 'identical_parameters'
    assert res['default']['pid'] == res['commissioned']['pid'] and res['default']['pid']['cycles'] == 2
    assert '(the same)' in res['runs'][0]['parameters']
    assert 'the same parameters: run once' in '\n'.join(V.report_section(res, tmp_path / 'out'))


def test_each_run_starts_settled_with_run_s_soft_start_and_is_judged_on_its_cycles(tmp_path, monkeypatch):
    f = write(tmp_path / 'wrist_params.yaml', {'adaptive_controller': {'ros__parameters': {'temperature_mid_C': 57.0}}})
    # commissioned first: cycles of 0.01 and 0.012 rad; the defaults 0.05 and 0.06 rad
    # 15 min less a 449 s bring-up and excitation: two runs of 158.7 s leave 66.8 s to settle before each
    res, graph, starts = verify_with(tmp_path, monkeypatch, f, [[0.01, 0.012], [0.05, 0.06]], budget_s=451.0)
    assert [c['files'][0].endswith(n) for c, n in zip(graph.calls, ('wrist_params.yaml', 'defaults.yaml'))] == [
        True,
        True,
    ]
    assert [n for n, _ in starts] == [0, 1]  # settled before each run, each given its share of the budget
    share = (451.0 - 2 * (V.DURATION_S + V.RUN_OVERHEAD_S)) / 2
    assert starts[0][1] == pytest.approx(share) and starts[1][1] == pytest.approx(share)
    assert res['device_time_s'] <= 451.0
    # the soft start sma-wrist run uses (the trajectory generator's own default is none)
    assert all(c['extra']['/trajectory_generator'] == {'soft_start_s': 30.0} for c in graph.calls)
    c = res['comparison']['pid']
    assert c['verdict'] == 'better' and c['differs'] == ['adaptive_controller.temperature_mid_C']
    assert res['commissioned']['pid']['max_pct'] < res['default']['pid']['max_pct']
    assert all(r['start']['settled'] and len(r['cycles']) == 2 for r in res['runs'])
    lines = V.text_lines(res)
    assert 'commissioned better (beyond the spread)' in lines[0] and '+-' in lines[0]


def test_settling_brings_a_heated_muscle_back_to_its_rest_temperature_with_the_tems_off():
    from sma_wrist.commission.bringup import BringUp
    from sma_wrist.commission.device import SimDevice
    from sma_wrist.hw.calibration import Calibration, Wiring
    from sma_wrist.hw.emulator import EmulatorConfig

    dev = SimDevice(EmulatorConfig(rate_hz=250.0, seed=3))
    bring = BringUp(dev, Calibration(), Wiring())
    bring.step_link()
    bring.step_sensors()
    rest = np.asarray(bring._T_start[:2])
    lim0 = bring.lim
    # as a closed-loop run leaves it: a muscle above the excitation's 82 degC (the controllers allow 85; a settling
    # held to 82 stopped a nominal wrist with over_temperature), the other cooled below its rest, the joint moved
    bring.lim = dataclasses.replace(lim0, max_excursion_rad=1.8, max_muscle_C=90.0, max_face_C=85.0)
    bring.set_drive(20.0, -6.0)

    def hot():
        return bring.physical(bring.rec.arrays(bring.t - 0.05)[1])[0][:, 0].mean() > 83.5

    bring.hold(120.0, hot)
    bring.lim = lim0  # the bring-up's own limits (75 degC) are what settle widens
    temps, _ = bring.physical(bring.rec.arrays(bring.t - 0.2)[1])
    assert temps.mean(axis=0)[0] > 83.0 and temps.mean(axis=0)[1] < rest[1] - 1.0
    start = V.settle(bring)
    assert start['settled'] and start['seconds'] < V.SettleLimits().timeout_s
    assert np.all(np.abs(np.asarray(start['muscle_C']) - rest) <= V.SettleLimits().tolerance_C)
    assert np.all(dev.emulator._u == 0.0) and bring.max_drive_sent_V <= 20.0
    # a limit that cannot be met in time: the start is measured and said not to be settled
    bring.set_drive(20.0, 0.0)
    bring.hold(10.0)
    quick = dataclasses.replace(V.SettleLimits(), timeout_s=2.0)
    assert V.settle(bring, quick)['settled'] is False and np.all(dev.emulator._u == 0.0)


def test_the_command_line_runs_two_cycles_a_run_by_default():
    import argparse

    from sma_wrist.cli_options import commission_arguments

    a = commission_arguments(argparse.ArgumentParser()).parse_args(['--sim', '--out', 'x'])
    assert a.verify_s == V.DURATION_S and V.cycle_metrics(sine_run([0.01, 0.01]), a.verify_s)['cycles'][1]


def test_without_a_budget_the_runs_fit_into_each_settling_takes_what_it_needs(tmp_path, monkeypatch):
    f = write(tmp_path / 'wrist_params.yaml', {'adaptive_controller': {'ros__parameters': {'temperature_mid_C': 57.0}}})
    errors = [[0.01, 0.012], [0.05, 0.06]] * 3
    _, graph, starts = verify_with(tmp_path, monkeypatch, f, errors, controllers=V.CONTROLLERS, budget_s=451.0)
    assert len(graph.calls) == 6 and {t for _, t in starts} == {V.SettleLimits().timeout_s}


def test_the_report_names_every_model_file_the_commissioned_run_was_diagnosed_against(tmp_path, monkeypatch):
    nodes = builtin_handed_over(tmp_path)
    f = write(tmp_path / 'wrist_params.yaml', {n: {'ros__parameters': v} for n, v in nodes.items()})
    res, _, _ = verify_with(tmp_path, monkeypatch, f, [[0.01, 0.02]])
    files = {
        'hysteresis_file': 'h.yaml',
        'thermal_file': 't.yaml',
        'heat_balance_file': 'hb.yaml',
        'wire_file': 'w.yaml',
    }
    res['diagnosis'] = {'discrepancy': False, 'against': files, 'residual': {}}
    text = '\n'.join(V.report_section(res, tmp_path / 'out'))
    assert 'hysteresis: `h.yaml`, thermal: `t.yaml`, heat balance: `hb.yaml`, wire: `w.yaml`' in text
