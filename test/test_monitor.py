"""The live model monitor (sma_wrist.monitor, sma-wrist monitor, twin_monitor) on effects that begin mid-run.

A clean closed-loop run of the node graph (pid, 0.3 kg, 150 s) is recorded once per session; the independent
effect generator (:mod:`sma_wrist.diagnose.distort`, which does not use the diagnosis' extension code) starts an
effect at ``ONSET_S`` and the rewritten run is written as a bag. The monitor must stay OK before the onset and name
the right subsystem after it; a nominal run read through realistic sensors must raise nothing.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sma_wrist.diagnose import distort as ds
from sma_wrist.diagnose import testdata as td
from sma_wrist.diagnose.data import load_run
from sma_wrist.monitor import Monitor, MonitorConfig, MonitorInputError, Verdict, history_text
from sma_wrist.monitor.playback import monitor_bag

RUN_S = 150.0
ONSET_S = 70.0


@pytest.fixture(scope='module')
def clean_run(tmp_path_factory):
    """A clean 150 s closed-loop recording (pid), loaded."""
    from sma_wrist.diagnose.bench import record_clean_runs

    bags = record_clean_runs(str(tmp_path_factory.mktemp('monitor')), ('pid',), RUN_S)
    return load_run(bags['pid'])


def _bag(run, path, d=None, onset=ONSET_S, realistic=False):  # type: ignore[no-untyped-def]
    if realistic:
        r = ds.realistic(run, seed=5)
        return td.write_run_bag(r, path, {'stamp_jitter_s': 1e-3, 'drop_rate': 1e-3})
    return td.write_run_bag(ds.apply(run, d, 0.1, 1e-3, 2, onset_s=onset), path)


def _cli(bag: str, *args: str) -> subprocess.CompletedProcess:
    """``sma-wrist monitor BAG ...`` run by this test run's copy of the package, in the bag's folder."""
    from conftest import package_env  # type: ignore[import-not-found]

    return subprocess.run(
        [sys.executable, '-m', 'sma_wrist', 'monitor', bag, *args],
        capture_output=True,
        text=True,
        cwd=Path(bag).parent,
        env=package_env(),
    )


def test_the_generator_starts_an_effect_at_its_onset(clean_run):
    """Before the onset the rewritten run is the recording; after it, the effect."""
    r = ds.apply(clean_run, ds.Distortion('offset', 'T1', 3.0, 'degC'), onset_s=ONSET_S)
    before = clean_run.t < ONSET_S - 1e-9
    assert np.array_equal(r.T[before], clean_run.T[before])
    assert np.allclose(r.T[~before, 0] - clean_run.T[~before, 0], 3.0)
    p = ds.apply(clean_run, ds.Distortion('payload', 'plant', 0.2, 'kg'), onset_s=ONSET_S)
    assert np.abs(p.q[before] - clean_run.q[before]).max() < 1e-6  # re-simulated: the same plant until the onset
    assert np.abs(p.q[~before] - clean_run.q[~before]).max() > 0.01  # then a heavier wrist sags
    for kind, value in (('ambient_drift', 20.0), ('tem_weak', 0.2)):  # the heat balance changes from the onset on
        h = ds.apply(clean_run, ds.Distortion(kind, 'plant', value, ''), onset_s=ONSET_S)
        assert np.abs(h.T[before] - clean_run.T[before]).max() < 1e-6
        assert np.abs(h.T[~before] - clean_run.T[~before]).max() > 0.1, kind
    # the wires' transitions drift: the temperatures are the recorded ones, the angle leaves the recording only as
    # the drift grows (ramped over 40 s)
    w = ds.apply(clean_run, ds.Distortion('transition_drift', 'plant', 6.0, 'degC', ramp_s=40.0), onset_s=ONSET_S)
    assert np.abs(w.q[before] - clean_run.q[before]).max() < 1e-6
    assert np.abs(w.T - clean_run.T).max() < 1e-6
    soon = (clean_run.t >= ONSET_S) & (clean_run.t < ONSET_S + 1.0)
    late = clean_run.t >= ONSET_S + 40.0
    assert np.abs(w.q[soon] - clean_run.q[soon]).max() < np.abs(w.q[late] - clean_run.q[late]).max()
    assert np.abs(w.q[late] - clean_run.q[late]).max() > 0.01


@pytest.mark.parametrize(
    'effect,subsystem',
    [
        (('offset', 'T1', 3.0), 'sensor'),  # a thermocouple coming loose
        (('payload', 'plant', 0.2), 'joint'),  # a heavier payload than /wrist/payload says
    ],
    ids=['thermocouple offset', 'heavier payload'],
)
def test_an_effect_beginning_mid_run_is_named_after_its_onset_and_ok_before(clean_run, tmp_path, effect, subsystem):
    bag = _bag(clean_run, tmp_path / 'bag', ds.Distortion(*effect, ''))
    out = tmp_path / 'history.csv'
    r = _cli(str(bag), '--json', '--out', str(out))
    assert r.returncode == 0, r.stderr + r.stdout
    res = json.loads(r.stdout)
    vs = res['verdicts']
    assert {'t_s', 'level', 'cause', 'subsystem', 'confidence'} <= set(vs[0])
    assert res['wall_s'] > 0
    # every check whose window ended before the onset: OK, cause and subsystem null
    early = [v for v in vs if v['t_s'] < ONSET_S]
    assert early and all(v['level'] == 'OK' and v['cause'] is None and v['subsystem'] is None for v in early), early
    raised = [v for v in vs if v['level'] == 'WARN']
    assert raised, [(v['t_s'], v['check_cause']) for v in vs]
    first = raised[0]
    assert first['subsystem'] == subsystem, first
    assert first['t_s'] - ONSET_S <= 60.0
    assert all(v['subsystem'] == subsystem for v in raised)
    assert res['onset_s'][first['cause']] >= ONSET_S
    text = out.read_text()
    assert text.splitlines()[0].startswith('t_s,level,cause,subsystem') and first['cause'] in text


def test_a_nominal_run_through_realistic_sensors_raises_nothing(clean_run, tmp_path):
    """0.3 degC / 3 mrad white noise, 16-bit quantisation, mains hum and a 0.7 Hz line, jittering stamps and
    dropped samples: no WARN, no ERROR."""
    bag = _bag(clean_run, tmp_path / 'bag', realistic=True)
    res = monitor_bag(bag)
    res.pop('_monitor')
    assert res['checks'] >= 5
    assert all(v['level'] == 'OK' for v in res['verdicts']), [
        (v['t_s'], v['level'], v['summary'][:120]) for v in res['verdicts']
    ]
    assert res['episodes'] == [] and res['onset_s'] == {}


def test_a_bag_without_the_commands_is_refused_with_what_to_record(tmp_path):
    truth = td.simulate('none', seed=1, duration_s=40.0)
    bag = td.write_bag(
        truth, tmp_path / 'no_commands', {'drop_topics': ['/wrist/tem_1/command', '/wrist/tem_2/command']}
    )
    for args in ((), ('--json',)):
        r = _cli(str(bag), *args)
        text = r.stdout + r.stderr
        assert r.returncode == 2 and 'Traceback' not in text, text
        assert '/wrist/tem_1/command' in text and 'ros2 bag record' in text
        if args:
            assert 'error' in json.loads(r.stdout)


def test_model_files_that_do_not_load_are_named(tmp_path):
    truth = td.simulate('none', seed=1, duration_s=40.0)
    bag = td.write_bag(truth, tmp_path / 'bag')
    broken = tmp_path / 'hysteresis.yaml'
    broken.write_text('not: [a wire')
    cases = [
        (('--hysteresis-file', str(tmp_path / 'missing.yaml')), 'missing.yaml: no such file'),
        (('--hysteresis-file', str(broken)), 'model files do not load'),
        (('--params-file', str(broken)), 'not a ROS 2 params file'),
        (('--out', str(tmp_path / 'history.txt')), '.csv, .json or .md'),
    ]
    for args, named in cases:
        r = _cli(str(bag), *args)
        assert r.returncode == 2 and named in r.stderr and 'Traceback' not in r.stderr, (args, r.stderr)


def test_persistence_raises_after_k_agreeing_checks_and_clears_after_k_clean_ones():
    """The rule on its own (no diagnosis): one odd check is no alarm; a changed subsystem must persist too."""
    mon = Monitor(MonitorConfig(persist_checks=2))
    ok = lambda t: Verdict(t, 'OK', None, None, 1.0)  # noqa: E731

    def warn(t, s='sensor', c='temp_sensor_offsets', p=0.9):
        return Verdict(
            t,
            'WARN',
            c,
            s,
            p,
            check_cause=c,
            check_subsystem=s,
            check_confidence=p,
        )

    seq = [
        ok(0),
        warn(15),
        ok(30),
        warn(45),
        warn(60),
        warn(75, c='temp_sensor_offset'),
        warn(90, 'joint', 'payload_mismatch'),
        warn(105),
        ok(120),
        ok(135),
    ]
    levels = [(v.level, v.subsystem) for v in (mon.decide(v) for v in seq)]
    assert levels == [
        ('OK', None),
        ('OK', None),
        ('OK', None),
        ('OK', None),
        ('WARN', 'sensor'),
        ('WARN', 'sensor'),
        ('WARN', 'sensor'),
        ('WARN', 'sensor'),
        ('WARN', 'sensor'),
        ('OK', None),
    ]
    ep = mon.episodes()
    assert len(ep) == 1 and ep[0]['onset_s'] == 45 and ep[0]['raised_s'] == 60 and ep[0]['until_s'] == 135
    assert ep[0]['causes'] == ['temp_sensor_offsets', 'temp_sensor_offset']
    md = history_text(mon.history, 'md')
    assert md.count('\n| ') == len(seq) + 1 and '| WARN | temp_sensor_offset |' in md
    # a cause named with (nearly) every bootstrap resample agreeing is raised by one check; clearing still takes two
    mon = Monitor(MonitorConfig(persist_checks=2, sure_confidence=0.95))
    levels = [mon.decide(v).level for v in (ok(0), warn(15, p=0.97), ok(30), ok(45))]
    assert levels == ['OK', 'WARN', 'WARN', 'OK']


def test_bad_monitor_settings_are_refused():
    for kw, named in (
        ({'window_s': 5.0}, 'window_s'),
        ({'check_period_s': 0.0}, 'check_period_s'),
        ({'candidates': ('friction', 'nope')}, 'nope'),
    ):
        with pytest.raises(MonitorInputError, match=named):
            MonitorConfig(**kw).check()


def test_twin_monitor_node_publishes_the_twin_the_residuals_and_the_verdict(clean_run, tmp_path):
    """The node on the embedded runtime beside a wrist whose thermocouple 1 reads 3 degC high from ONSET_S on
    (checks inline, so that every one is made on the virtual clock)."""
    from sma_wrist.bag import read_bag
    from sma_wrist.nodes.twin_monitor import TwinMonitor

    hist = tmp_path / 'verdicts.json'
    run = ds.apply(clean_run, ds.Distortion('offset', 'T1', 3.0, 'degC'), 0.1, 1e-3, 2, onset_s=ONSET_S)
    bag = td.write_run_bag(
        run,
        tmp_path / 'bag',
        nodes=[TwinMonitor],
        params={'/twin_monitor': {'use_sim_time': True, 'worker': 'inline', 'history_file': str(hist)}},
    )
    data = read_bag(
        bag,
        [
            '/diagnostics',
            '/wrist/twin/muscle_1/temperature',
            '/wrist/twin/residual/muscle_1/temperature',
            '/wrist/twin/joint_states',
            '/wrist/twin/residual/angle',
        ],
    )
    t_res, res = data['/wrist/twin/residual/muscle_1/temperature']
    t_res = (np.asarray(t_res) - t_res[0]) * 1e-9
    r = np.array([m.data for m in res])
    assert 1400 < r.size < 1600  # 10 Hz of 150 s
    assert np.abs(r[t_res < ONSET_S - 1]).max() < 0.6  # the twin is the wrist (0.1 degC noise) ...
    assert np.median(r[t_res > ONSET_S + 1]) == pytest.approx(3.0, abs=0.5)  # ... until the thermocouple moves
    assert len(data['/wrist/twin/joint_states'][1]) == r.size
    ours = [
        (
            s.level[0] if isinstance(s.level, bytes) else int(s.level),
            dict((kv.key, kv.value) for kv in s.values),
            s.message,
        )
        for m in data['/diagnostics'][1]
        for s in m.status
        if s.name == 'twin_monitor: model'
    ]
    levels = [lv for lv, _, _ in ours]
    # the verdict is repeated at 1 Hz, OK included: a healthy wrist shows that it is being watched (it published
    # nothing before its first WARN)
    ok = [
        (m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec, s.message)
        for m in data['/diagnostics'][1]
        for s in m.status
        if s.name == 'twin_monitor: model' and (s.level[0] if isinstance(s.level, bytes) else int(s.level)) == 0
    ]
    t_ok = np.array([t for t, _ in ok])
    assert np.sum(t_ok < t_ok[0] + ONSET_S - 2.0) >= 0.9 * (ONSET_S - 2.0), ok[:5]
    assert ok[0][1].startswith('watching: first check at'), ok[0]
    warn = [(vals, msg) for lv, vals, msg in ours if lv == 1]
    assert warn and warn[0][0]['subsystem'] == 'sensor', ours
    assert float(warn[0][0]['since_s']) >= ONSET_S and 'temp_offset_1_C' in warn[0][0]
    # where the check placed the change, and the checks that waited for enough data after it
    assert abs(float(warn[0][0]['change_s']) - ONSET_S) < 5.0, warn[0][0]
    assert any(vals.get('pending') == 'true' for _, vals, _ in ours) and warn[0][0]['pending'] == 'false'
    assert 2 not in levels  # never ERROR
    doc = json.loads(hist.read_text())
    assert [v['level'] for v in doc['verdicts']][0] == 'OK' and doc['episodes'][0]['subsystem'] == 'sensor'


@pytest.mark.parametrize('monitor, started', [('true', True), ('false', False)])
def test_the_sim_launch_file_starts_twin_monitor_only_when_asked(monitor, started):
    from sma_wrist.runtime.launch_file import run_launch_file
    from sma_wrist.share import share_path

    r = run_launch_file(str(share_path('launch/wrist_sim.launch.py')), {'controller': 'pid', 'monitor': monitor}, 0.3)
    assert r.reason == 'time' and r.exits == {}
    assert ('twin_monitor' in r.started) == started
    assert r.started[:4] == ['plant_sim', 'trajectory_generator', 'adaptive_controller', 'tem_controller']


def test_an_unexplained_discrepancy_is_raised_only_once_the_window_holds_no_data_from_before_it():
    """A wrist that changed inside the window fits no constant model: the checks straddling the change say
    'unexplained' before the cause can be named, and that transition is no verdict of its own."""
    cfg = MonitorConfig(persist_checks=2, window_s=45.0, settle_s=20.0, check_period_s=15.0)
    mon = Monitor(cfg)

    def un(t):
        return Verdict(
            t,
            'WARN',
            'unexplained',
            'thermal',
            1.0,
            check_cause='unexplained',
            check_subsystem='thermal',
            check_confidence=1.0,
        )

    named = lambda t: Verdict(t, 'WARN', 'temp_sensor_offsets', 'sensor', 0.9)  # noqa: E731
    out = [mon.decide(v) for v in (un(15), un(30), un(45), named(60), named(75))]
    assert [v.level for v in out] == ['OK', 'OK', 'OK', 'OK', 'WARN'] and out[-1].subsystem == 'sensor'
    assert mon.needed(un(0)) == 2 + 5  # 65 s of window at 15 s per check
    mon = Monitor(cfg)
    out = [mon.decide(un(15 * i)) for i in range(1, 9)]
    assert [v.level for v in out].index('WARN') == 6 and out[-1].cause == 'unexplained'
    # checks that come faster (a fresh change) do not shorten that wait: it is the same 90 s of unexplained checks
    mon = Monitor(cfg)
    out = [mon.decide(un(100 + 5 * i)) for i in range(19)]
    assert [v.level for v in out].index('WARN') == 18


def _events(t0: float, t1: float) -> list[tuple[str, int, float, float]]:
    """A wrist at rest, sampled at 100 Hz over [t0, t1) as twin_monitor buffers it (commands, temperatures, angle)."""
    out = []
    for k in range(int(round(t0 * 100)), int(round(t1 * 100))):
        t = k / 100.0
        out += [('u', 1, t, 2.0), ('u', 2, t, -2.0), ('T', 1, t, 25.0), ('T', 2, t, 25.0), ('q', 0, t, 0.3)]
    return out


def _answers(link, kind, n=1, timeout=90.0):  # type: ignore[no-untyped-def]
    import time

    got, t_end = [], time.monotonic() + timeout
    while len(got) < n and time.monotonic() < t_end:
        got += [a for a in link.poll() if a[0] == kind]
        time.sleep(0.02)
    return got


def test_the_worker_process_steps_the_twin_like_the_node_would_and_runs_below_the_node():
    """The twin runs in the worker process, niced worker_nice below the node, and answers a batch with the same
    prediction as the same worker in the node's callback."""
    import os

    from sma_wrist.monitor.worker import WorkerLink

    cfg = MonitorConfig()
    batch = [('p', 0, 0.0, 0.3), *_events(0.0, 2.0)]
    inline, proc = WorkerLink('inline', cfg), WorkerLink('process', cfg, nice=1)
    try:
        for link in (inline, proc):
            link.send(('feed', 1, batch, True))
        (a,) = _answers(inline, 'twin')
        (b,) = _answers(proc, 'twin')
        theirs = os.getpriority(os.PRIO_PROCESS, proc._proc.pid)
    finally:
        proc.close()
    assert theirs == min(os.nice(0) + 1, 19)
    assert a[:3] == (a[0], 1, 1.99) and b[:3] == a[:3]
    assert np.allclose(b[3], a[3], atol=1e-12) and b[4] == pytest.approx(a[4], abs=1e-12)
    assert b[6] == pytest.approx(a[6], abs=1e-12) and abs(a[6]['T1']) < 5.0  # 25 degC measured, near the twin's


def test_the_worker_process_runs_below_the_node_from_its_start():
    """The worker process is niced as soon as it is started, not once it has imported the monitor: those imports
    (about a second of CPU) at the node's priority took the graph's CPU while the worker started."""
    import os

    from sma_wrist.monitor.worker import WorkerLink

    ours = os.getpriority(os.PRIO_PROCESS, 0)
    if ours >= 19:
        pytest.skip('this process already runs at the lowest priority')
    link = WorkerLink('process', MonitorConfig(), nice=1)
    try:
        theirs = os.getpriority(os.PRIO_PROCESS, link._proc.pid)  # still importing: that takes a second
    finally:
        link.close()
    assert theirs == ours + 1


def test_handing_batches_to_a_worker_that_does_not_read_never_holds_up_the_node():
    """A worker process that stops reading (stopped here before it even started) lets the node's sends return at
    once: what the pipe cannot take waits in the node's memory, in order."""
    import os
    import signal
    import threading
    import time

    from sma_wrist.monitor.worker import WorkerLink

    link = WorkerLink('process', MonitorConfig())
    os.kill(link._proc.pid, signal.SIGSTOP)
    batches = [('feed', k, _events(float(k), k + 1.0), True) for k in range(20)]  # ~20 x 15 kB: past a pipe's 64 kB
    took: list[float] = []

    def send_all() -> None:
        for b in batches:
            t0 = time.monotonic()
            link.send(b)
            took.append(time.monotonic() - t0)

    th = threading.Thread(target=send_all, daemon=True)
    th.start()
    th.join(20)
    try:
        assert not th.is_alive() and len(took) == len(batches), 'a send waited for the worker'
        assert max(took) < 1.0 and len(link._unsent) > 100_000  # kept for later, not dropped
    finally:
        os.kill(link._proc.pid, signal.SIGCONT)
        link.close()


def test_a_check_due_while_the_last_one_runs_waits_for_it_and_the_twin_keeps_up(monkeypatch):
    """A slow check holds up neither the twin nor the samples; the check due meanwhile is not queued: it starts on
    the newest data as soon as the last one is done, and the periods without a check are counted."""
    import threading

    from sma_wrist.monitor import worker as W

    release, started = threading.Event(), []

    def slow(window, t, *a):  # type: ignore[no-untyped-def]
        started.append(t)
        assert release.wait(30)
        return Verdict(t, 'OK', None, None, 1.0)

    monkeypatch.setattr(W, 'diagnose_window', slow)
    link = W.WorkerLink('thread', MonitorConfig(window_s=45.0, settle_s=20.0, check_period_s=15.0))
    try:
        for seq, t0 in enumerate(range(0, 100), 1):  # a batch per second; the first check is due at 65 s
            link.send(('feed', seq, _events(float(t0), t0 + 1.0), True))
        twins = _answers(link, 'twin', 100)
        assert started == [65.0] and twins[-1][2] == pytest.approx(99.99)  # stepped to the end while it ran
        release.set()
        (v,) = _answers(link, 'verdict')
        link.send(('feed', 101, _events(100.0, 100.02), False))
        (v2,) = _answers(link, 'verdict')
    finally:
        release.set()
        link.close()
    assert started == [65.0, 100.0]  # not 80 and 95 (queued), nor 110 (the next period): the newest data
    assert (v[1].t_s, v2[1].t_s, v2[3]) == (65.0, 100.0, 1)  # 80 and 95 were due: one period had no check


def test_the_twin_stepped_in_batches_is_the_twin_stepped_per_sample(clean_run):
    """Queued intervals stepped in one compiled call give the states of one call per interval (to rounding)."""
    from sma_wrist.monitor.twin import Twin, load_model

    model = load_model()
    batched, single = Twin(model, 0.3), Twin(model, 0.3)
    n = 1500
    states = []
    for k in range(n):
        for tw in (batched, single):
            tw.set_command(0, float(clean_run.u[k, 0]))
            tw.set_command(1, float(clean_run.u[k, 1]))
            tw.advance_to(float(clean_run.t[k]))
        single.flush()  # one interval per call
        states.append(single.thermal_state)
    assert batched._queue_n  # still queued: nothing read them yet
    assert np.allclose(batched.temperatures_C, single.temperatures_C, atol=1e-9)
    assert batched.angle_rad == pytest.approx(single.angle_rad, abs=1e-9)
    for k in (1, 700, n - 1):
        assert np.allclose(batched.thermal_state_at(float(clean_run.t[k])), states[k], atol=1e-9)


def test_a_verdict_at_the_confidence_of_a_coin_toss_is_not_raised(monkeypatch):
    """An ambiguous verdict's confidence is capped at 0.5 (two subsystems explain the window equally well): at the
    default min_confidence 0.5 it is no alarm (a nominal 30 min pid run raised viscous_damping at exactly 0.5)."""
    import types

    import sma_wrist.diagnose as dg
    from sma_wrist.monitor import diagnose_window

    def fake(confidence):  # type: ignore[no-untyped-def]
        return types.SimpleNamespace(
            discrepancy=True,
            cause='viscous_damping',
            subsystem='joint',
            confidence=confidence,
            parameters={'viscous_Nms': {'value': 2.0}},
            gain_pct=20.0,
            summary='joint discrepancy',
            correlates=[],
            partial=None,
        )

    window = dg.Run(t=np.arange(10.0), dt=1.0, u=None, T=None, q=None, payload_kg=0.3)
    levels = {}
    for p in (0.5, 0.51):
        monkeypatch.setattr(dg, 'diagnose_run', lambda *a, p=p, **k: fake(p))
        levels[p] = diagnose_window(window, 60.0, MonitorConfig()).level
    assert levels == {0.5: 'OK', 0.51: 'WARN'}


def test_the_change_point_of_residuals_is_where_they_step_or_swing():
    """A step in one channel's mean and a swing that grows in another are placed at their block; white noise alone
    stays far below the threshold."""
    from sma_wrist.monitor import CP_THRESHOLD, change_point

    rng = np.random.default_rng(3)
    r = rng.normal(0.0, 1.0, (65, 3))
    calm = change_point(r)[1]
    assert calm < CP_THRESHOLD / 4
    step = r.copy()
    step[40:, 0] += 3.0
    assert change_point(step)[0] == 40
    swing = r.copy()
    swing[30:, 2] *= 4.0
    k, stat = change_point(swing)
    assert abs(k - 30) <= 1 and stat > 3 * calm


def _feed(mon, run, until, since=None):  # type: ignore[no-untyped-def]
    """Feed ``run``'s samples stamped up to ``until`` [s] (after ``since``: the monitor has those already)."""
    mon.payload(run.payload_kg)
    t = run.t - run.t[0]
    i0 = 0 if since is None else int(np.searchsorted(t, since, side='right'))
    for i in range(i0, int(np.searchsorted(t, until, side='right'))):
        mon.command(1, t[i], run.u[i, 0])
        mon.command(2, t[i], run.u[i, 1])
        mon.temperature(1, t[i], run.T[i, 0])
        mon.temperature(2, t[i], run.T[i, 1])
        mon.angle(t[i], run.q[i])


def test_a_window_with_a_change_in_it_is_diagnosed_after_the_change(clean_run):
    """The potentiometer slips by 0.05 rad at 70 s; the window ending 35 s later holds 30 s from before it. Fitted
    with constant parameters over the whole window, that change was named a joint effect at confidence 0.99; the
    monitor places the change in the twin's residuals and diagnoses what follows it (with settle_s before it)."""
    run = ds.apply(clean_run, ds.Distortion('offset', 'q', 0.05, 'rad'), 0.1, 1e-3, 2, onset_s=ONSET_S)
    mon = Monitor(MonitorConfig())
    t_check = ONSET_S + 35.0
    _feed(mon, run, t_check)
    w = mon.window(t_check)
    assert not isinstance(w, str), w
    assert abs(w.change_s - ONSET_S) <= 2.0  # type: ignore[union-attr]
    assert w.t0_s >= ONSET_S - 20.0 - 3.0  # type: ignore[union-attr]
    v = mon.diagnose(w, t_check)
    assert v.level == 'WARN' and v.subsystem == 'sensor', v.summary
    # 10 s after the change there is too little of it to name: the check waits and raises nothing
    mon2 = Monitor(MonitorConfig())
    _feed(mon2, run, ONSET_S + 10.0)
    p = mon2.decide(mon2.diagnose(mon2.window(ONSET_S + 10.0), ONSET_S + 10.0))
    assert p.pending and p.level == 'OK' and abs(p.change_s - ONSET_S) <= 2.0, p.summary  # type: ignore[operator]


def test_a_fresh_change_is_checked_30_s_after_it_and_then_every_5_s(clean_run):
    """A thermocouple 1 offset from 70 s: the check 20 s later places the change and waits; the next one is due 30 s
    after the change, not a check period (15 s) after the last check, and then every 5 s until it is named."""
    from sma_wrist.monitor import FRESH_PERIOD_S, MIN_AFTER_CHANGE_S

    run = ds.apply(clean_run, ds.Distortion('offset', 'T1', 3.0, 'degC'), 0.1, 1e-3, 2, onset_s=ONSET_S)
    mon = Monitor(MonitorConfig(check_period_s=15.0))
    _feed(mon, run, ONSET_S + 20.0)
    assert mon.due(ONSET_S + 20.0)
    p = mon.decide(mon.diagnose(mon.window(ONSET_S + 20.0), ONSET_S + 20.0))
    assert p.pending and abs(p.change_s - ONSET_S) <= 1.0, p.summary  # type: ignore[operator]
    first = p.change_s + MIN_AFTER_CHANGE_S  # type: ignore[operator]
    assert not mon.due(first - 1.0) and mon.due(first)
    mon.last_check = first
    assert not mon.due(first + FRESH_PERIOD_S - 1.0) and mon.due(first + FRESH_PERIOD_S)


def test_a_thermocouple_lag_is_named_35_s_after_its_onset(clean_run):
    """Thermocouple 1 lags by 4 s from 70 s. The temperatures' residuals changed, so the window is diagnosed from
    just before the change: with settle_s (20 s) before it the fitted lag acted on the lead-in too, and the check
    35 s after the onset was "unexplained, thermal" (the best fit, a 1.5 s lag, removed 43 % of the misfit)."""
    run = ds.apply(clean_run, ds.Distortion('lag', 'T1', 4.0, 's'), 0.1, 1e-3, 2, onset_s=ONSET_S)
    mon = Monitor(MonitorConfig())
    t_check = ONSET_S + 35.0
    _feed(mon, run, t_check)
    w = mon.window(t_check)
    assert not isinstance(w, str) and mon.change_thermal, w
    assert abs(w.change_s - ONSET_S) <= 1.0 and w.t0_s >= w.change_s - 3.0  # type: ignore[union-attr]
    v = mon.diagnose(w, t_check)
    assert v.level == 'WARN' and v.subsystem == 'sensor' and v.cause == 'temp_sensor_lags', v.summary
    assert v.parameters['temp_lag_1_s'] == pytest.approx(4.0, rel=0.2)


def test_answers_that_arrive_while_the_node_is_destroyed_go_to_the_history_file_not_to_a_dead_publisher(
    tmp_path,
):
    """Under rclpy, Ctrl-C shuts the context down before the node is destroyed, and a publish then raises
    ("publisher's context is invalid"): the answers the worker had sent by then are kept in the history file,
    and the node is destroyed without a traceback."""
    from sma_wrist import runtime
    from sma_wrist.nodes.twin_monitor import TwinMonitor
    from sma_wrist.runtime.launch import Runtime

    runtime.activate()
    from builtin_interfaces.msg import Time

    hist = tmp_path / 'verdicts.json'

    class Answered:
        def poll(self):
            residuals = {'T1': 0.1, 'T2': -0.1, 'q': 0.001}
            return [
                ('twin', 7, 11.9, (40.0, 30.0), 0.2, 0.0, residuals, 0.4),
                ('verdict', Verdict(12.0, 'OK', None, None, 1.0), [], 0, 0.5),
            ]

        def close(self):
            pass

    def dead(msg):
        raise RuntimeError("Failed to publish: publisher's context is invalid")

    with Runtime(params={'/twin_monitor': {'worker': 'inline', 'history_file': str(hist)}}) as rt:
        (node,) = rt.add_nodes([TwinMonitor])
        node._link.close()
        node._link = Answered()
        node._stamps[7] = Time(sec=11, nanosec=900_000_000)  # the joint state the twin answers was stamped so
        for pub in node.pub.values():
            pub.publish = dead
        node._diag_pub.publish = dead
        node.destroy_node()
    assert [v['t_s'] for v in json.loads(hist.read_text())['verdicts']] == [12.0]


def test_the_node_hands_the_worker_every_sample_in_order_in_batches_of_0_1_s():
    """The node's batches, concatenated, are every sample it took, each topic's in its order; a batch closes at the
    first joint state 0.1 s after the last batch's."""
    from sma_wrist import runtime
    from sma_wrist.nodes.twin_monitor import TwinMonitor
    from sma_wrist.runtime.launch import Runtime

    runtime.activate()
    from builtin_interfaces.msg import Time
    from rclpy.node import Node
    from sensor_msgs.msg import JointState, Temperature
    from std_msgs.msg import Float64, Header

    class Recording:
        def __init__(self):
            self.sent = []

        def send(self, msg):
            self.sent.append(msg)

        def poll(self):
            return []

        def ended(self):
            return None

        def close(self):
            pass

    n = 35
    with Runtime(params={'/twin_monitor': {'worker': 'inline', 'payload_kg': 0.4}}) as rt:
        (node,) = rt.add_nodes([TwinMonitor])
        node._link.close()
        node._link = link = Recording()
        src = rt.add(Node('src'))
        pub = {
            t: src.create_publisher(m, t, 10)
            for t, m in (
                ('/wrist/tem_1/command', Float64),
                ('/wrist/tem_2/command', Float64),
                ('/wrist/muscle_1/temperature', Temperature),
                ('/wrist/muscle_2/temperature', Temperature),
                ('/wrist/joint_states', JointState),
            )
        }
        for k in range(n):
            stamp = Time(sec=10, nanosec=10_000_000 * k)
            pub['/wrist/tem_1/command'].publish(Float64(data=float(k)))
            pub['/wrist/tem_2/command'].publish(Float64(data=-float(k)))
            for i in (1, 2):
                pub[f'/wrist/muscle_{i}/temperature'].publish(
                    Temperature(header=Header(stamp=stamp), temperature=20.0 + i + k, variance=0.0)
                )
            pub['/wrist/joint_states'].publish(
                JointState(header=Header(stamp=stamp), name=['wrist'], position=[0.001 * k], velocity=[0.0])
            )
            rt.run_until(rt.steady_ns * 1e-9 + 0.001, until='steady')
        rest = list(node._events)  # taken after the last batch: the next one's
    feeds = [m for m in link.sent if m[0] == 'feed']
    assert [m[1] for m in feeds] == list(range(1, len(feeds) + 1))
    events = [e for m in feeds for e in m[2]] + rest
    assert events[0] == ('p', 0, 0.0, 0.4)  # the payload parameter, first
    for kind, i, values in (
        ('u', 1, [float(k) for k in range(n)]),
        ('u', 2, [-float(k) for k in range(n)]),
        ('T', 1, [21.0 + k for k in range(n)]),
        ('T', 2, [22.0 + k for k in range(n)]),
    ):
        assert [e[3] for e in events if e[:2] == (kind, i)] == values
    stamps = [10.0 + 0.01 * k for k in range(n)]
    assert [e[2] for e in events if e[:2] == ('T', 1)] == pytest.approx(stamps, abs=1e-9)
    q = [e for e in events if e[0] == 'q']
    assert [e[3] for e in q] == pytest.approx([0.001 * k for k in range(n)]) and len(events) == 1 + 5 * n
    # each batch ends at a joint state; the first at the first one, then every 0.1 s of its stamps
    assert all(m[2][-1][0] == 'q' for m in feeds)
    assert [m[2][-1][2] for m in feeds] == pytest.approx([10.0, 10.1, 10.2, 10.3], abs=1e-9) and len(rest) == 4 * 5


def _delayed_warm_run():  # type: ignore[no-untyped-def]
    """40 s of a wrist whose TEMs got their commands 0.1 s late (ten windows: the graph's delay on hardware) and whose
    exchanger faces start warm (76 / 74 degC, right after an excitation): the Truth and the drive that was applied."""
    from sma_wrist.diagnose import effects as fx

    dt, delay = 0.01, 0.1
    t = np.arange(int(40.0 / dt) + 1) * dt
    heat_1 = np.sin(2.0 * np.pi * t / 6.0 + 0.3) > 0  # switching every 3 s, as a closed loop's commands do
    u = np.stack([np.where(heat_1, 12.0, -8.0), np.where(heat_1, -8.0, 12.0)], axis=1)
    truth = td.simulate(
        'actuator_delay', seed=4, duration_s=40.0, params={'command_delay_s': delay}, u=u, faces_start_C=(76.0, 74.0)
    )
    return truth, fx.delayed(truth.u, delay, dt)


def _feed_device(mon, truth, applied=None, faces=True):  # type: ignore[no-untyped-def]
    """Feed a Truth as hardware_bridge and tem_controller publish it: per window the measurements (faces too), the
    drive read back for the window before (stamped at its start), then the commands answering the window."""
    mon.payload(truth.payload_kg)
    for k, t in enumerate(truth.t):
        for i in (1, 2):
            mon.temperature(i, t, truth.T[k, i - 1])
            if faces:
                mon.face(i, t, truth.faces[k, i - 1])
        if applied is not None and k > 0:
            for i in (1, 2):
                mon.drive(i, truth.t[k - 1], applied[k - 1, i - 1])
        mon.angle(t, truth.q[k])
        for i in (1, 2):
            mon.command(i, t, truth.u[k, i - 1])


def _twin_T_residual(mon, truth, lo=0.0, hi=40.0):  # type: ignore[no-untyped-def]
    """RMS of the measured muscle temperatures minus the twin's over [lo, hi] [degC]."""
    tt, T, _ = mon.twin.predictions(lo, hi)
    meas = np.stack([np.interp(tt, truth.t, truth.T[:, i]) for i in (0, 1)], axis=1)
    return float(np.sqrt(np.mean((meas - T) ** 2)))


def test_the_twin_and_the_checks_run_on_the_drive_the_device_read_back_where_it_is_sent():
    """On hardware a command takes effect after the graph's delay, which its stamp does not say. On the commands the
    twin's temperatures were off by several times the sensor noise and the check named a TEM command delay on a
    nominal wrist; on the read-back (/wrist/tem_drive_applied) the twin follows to the noise and the check is OK.
    Without the read-back (a device that does not send it) the commands are still what the monitor runs on."""
    truth, applied = _delayed_warm_run()
    cfg = MonitorConfig(window_s=25.0, settle_s=5.0, candidates=('actuator_delay', 'sensor_lag', 'tem_mismatch'))
    commanded, readback = Monitor(cfg), Monitor(cfg)
    _feed_device(commanded, truth)
    _feed_device(readback, truth, applied)
    assert _twin_T_residual(readback, truth, 1.0) < 1.5 * td.NOISE_T_C
    assert _twin_T_residual(commanded, truth, 1.0) > 3 * td.NOISE_T_C
    t_check = 39.0
    w = readback.window(t_check)
    assert not isinstance(w, str) and w.drive == 'applied', w
    k0 = int(round(w.t0_s / truth.dt))
    np.testing.assert_array_equal(w.u[:-1], applied[k0 : k0 + w.n - 1])  # the read-back, held from its stamps
    v = readback.diagnose(w, t_check)
    assert v.level == 'OK', v.summary
    w = commanded.window(t_check)
    assert w.drive == 'commanded'  # type: ignore[union-attr]
    v = commanded.diagnose(w, t_check)
    assert v.level == 'WARN' and v.cause == 'actuator_delay', v.summary


def test_the_twin_and_each_checks_replay_start_from_the_measured_exchanger_faces():
    """A run that starts right after an excitation: the TEMs' exchanger faces are ~75 degC. A twin started at rest
    reads its muscles degrees too cold for minutes; started from /wrist/tem_{1,2}/face_temperature it follows, and a
    check's replay starts from the faces measured at its window's start."""
    truth, applied = _delayed_warm_run()
    cfg = MonitorConfig(window_s=25.0, settle_s=5.0)
    seen, blind = Monitor(cfg), Monitor(cfg)
    _feed_device(seen, truth, applied)
    _feed_device(blind, truth, applied, faces=False)
    assert _twin_T_residual(seen, truth) < 1.5 * td.NOISE_T_C
    assert _twin_T_residual(blind, truth) > 10 * td.NOISE_T_C
    w = seen.window(39.0)
    assert w.thermal_start == 'measured'  # type: ignore[union-attr]
    k0 = int(round(w.t0_s / truth.dt))  # type: ignore[union-attr]
    np.testing.assert_allclose(w.thermal_x0[:, 1], truth.faces[k0], atol=1e-9)  # type: ignore[union-attr]
    assert blind.window(39.0).thermal_start == 'twin'  # type: ignore[union-attr]


def test_twin_monitor_node_runs_on_the_read_back_and_starts_from_the_measured_faces(tmp_path):
    """The node subscribes /wrist/tem_drive_applied and /wrist/tem_{1,2}/face_temperature (embedded runtime, checks
    inline): its twin follows the wrist of the tests above to the sensor noise and its check is clean."""
    from sma_wrist.bag import read_bag
    from sma_wrist.nodes.twin_monitor import TwinMonitor

    truth, applied = _delayed_warm_run()
    hist = tmp_path / 'verdicts.json'
    params = {
        'use_sim_time': True,
        'worker': 'inline',
        'history_file': str(hist),
        'window_s': 25.0,
        'settle_s': 5.0,
        'check_period_s': 100.0,  # one check, at 30 s
        'candidates': 'actuator_delay,sensor_lag,tem_mismatch',
    }
    bag = td.write_bag(truth, tmp_path / 'bag', nodes=[TwinMonitor], params={'/twin_monitor': params}, applied=applied)
    t_res, res = read_bag(bag, ['/wrist/twin/residual/muscle_1/temperature'])[
        '/wrist/twin/residual/muscle_1/temperature'
    ]
    r = np.array([m.data for m in res])
    assert r.size > 300  # 10 Hz
    assert np.sqrt(np.mean(r**2)) < 1.5 * td.NOISE_T_C
    (v,) = json.loads(hist.read_text())['verdicts']
    assert v['level'] == 'OK' and v['check_cause'] is None, v['summary']


def test_a_coolant_drift_is_named_in_the_thermal_subsystem_45_s_after_its_onset(clean_run):
    """The coolant warms by 20 degC/h from 70 s: 45 s later the muscle temperatures are about 0.1 degC off the
    twin's, the noise level. The residuals' change point places a ramp late (here at 100 s, too recent to diagnose
    at 115 s: the check waited), and the diagnosis' held-out split named the drift 61-62 s after its onset on the
    benchmark's recordings. Fitted on the 1 s averages of the whole window (monitor/drift.py), it is named, about
    its size, and raised when two checks agree."""
    run = ds.apply(clean_run, ds.Distortion('ambient_drift', 'plant', 20.0, 'degC/h'), 0.1, 1e-3, 2, onset_s=ONSET_S)
    mon = Monitor(MonitorConfig())
    t_check = ONSET_S + 45.0
    _feed(mon, run, t_check)
    v = mon.diagnose(mon.window(t_check), t_check)
    assert v.level == 'WARN' and v.subsystem == 'thermal' and v.cause == 'ambient_drift', v.summary
    assert v.parameters['ambient_drift_C_per_h'] == pytest.approx(20.0, rel=0.5)
    # one window's fit (a slow residual of nominal realistic data once reached 7.2 standard errors): two checks
    assert v.drift_fit and mon.needed(v) == 2


def test_the_drift_fit_names_no_drift_where_one_thermocouple_changed_or_the_tems_weakened(clean_run):
    """A thermocouple offset, a thermocouple gain error and weaker TEMs move the temperatures' residuals too, but
    not as a common slow drift: the drift fit on the windows 40 s after their onsets names none of them."""
    from sma_wrist.monitor.drift import ambient_drift_fit

    for d in (
        ds.Distortion('offset', 'T1', 3.0, 'degC'),
        ds.Distortion('gain', 'T2', 0.1, '1'),
        ds.Distortion('tem_weak', 'plant', 0.2, '1'),
    ):
        mon = Monitor(MonitorConfig())
        _feed(mon, ds.apply(clean_run, d, 0.1, 1e-3, 2, onset_s=ONSET_S), ONSET_S + 40.0)
        w = mon.window(ONSET_S + 40.0)
        assert not isinstance(w, str), w
        f = ambient_drift_fit(w)
        assert f is not None and not f.named, (d, f)


def test_a_cause_that_explains_most_of_an_unexplained_misfit_is_raised_by_two_checks(monkeypatch):
    """The diagnosis calls a misfit unexplained when its best cause leaves more than 3 x the noise and removes less
    than 80 % of it: 30-40 s after TEMs lost 20 % of their Peltier terms, recalibrate_thermal removed 61-65 % of
    the thermal misfit (named at 80 % 60 s after the onset). Such a cause, removing at least half, is raised with
    its subsystem by two agreeing checks 5 s apart; one removing 42 % (a thermocouple offset's first window, where
    recalibrate_thermal was the wrong subsystem) stays unexplained, raised only after 90 s."""
    import types

    import sma_wrist.diagnose as dg

    def fake(gain_pct):  # type: ignore[no-untyped-def]
        return types.SimpleNamespace(
            discrepancy=True,
            cause=None,
            subsystem='thermal',
            confidence=1.0,
            parameters={},
            gain_pct=0.0,
            summary='unexplained discrepancy in thermal',
            correlates=[],
            partial={
                'cause': 'recalibrate_thermal',
                'subsystem': 'thermal',
                'channel': 'thermal',
                'gain_pct': gain_pct,
                'parameters': {'tem_gain_err': {'value': -0.17}},
            },
        )

    window = dg.Run(t=np.arange(10.0), dt=1.0, u=None, T=None, q=None, payload_kg=0.3)
    raised = {}
    for gain in (65.0, 42.0):
        monkeypatch.setattr(dg, 'diagnose_run', lambda *a, g=gain, **k: fake(g))
        mon = Monitor(MonitorConfig())
        for t in (120.0, 125.0, 130.0):
            v = mon.decide(mon.diagnose(window, t))
            if v.level != 'OK':
                raised[gain] = (t, v.cause, v.subsystem, v.partial)
                break
    assert raised == {65.0: (125.0, 'recalibrate_thermal', 'thermal', True)}


def test_a_worker_that_falls_behind_the_wrist_is_reported_apart_from_the_verdict(tmp_path):
    """A worker starved of CPU takes its input in order and checks in its own time: it skips no check period, and
    skipped_checks stayed 0 while its verdicts told of a wrist 35 s ago. The node says how far behind its checks are
    (``behind_s``: the newest sample received minus the end of the window last checked) in the model status and the
    verdict history, and warns on a status of its own (not a verdict on the wrist) beyond two check periods."""
    from sma_wrist import runtime
    from sma_wrist.nodes.twin_monitor import TwinMonitor
    from sma_wrist.runtime.launch import Runtime

    runtime.activate()
    from builtin_interfaces.msg import Time
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
    from rclpy.node import Node
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Header

    hist = tmp_path / 'verdicts.json'

    class Late:
        """A worker whose first verdict (the window ending at 65 s) comes when the wrist is at 100 s."""

        def __init__(self):
            self.answers = []

        def send(self, msg):
            pass

        def poll(self):
            out, self.answers = self.answers, []
            return out

        def ended(self):
            return None

        def close(self):
            pass

    statuses = []
    params = {'/twin_monitor': {'worker': 'inline', 'history_file': str(hist), 'check_period_s': 15.0}}
    with Runtime(params=params) as rt:
        (node,) = rt.add_nodes([TwinMonitor])
        node._link.close()
        node._link = late = Late()
        src = rt.add(Node('src'))
        src.create_subscription(DiagnosticArray, '/diagnostics', lambda m: statuses.extend(m.status), 10)
        joint = src.create_publisher(JointState, '/wrist/joint_states', 10)

        def at(t):
            joint.publish(JointState(header=Header(stamp=Time(sec=t)), name=['wrist'], position=[0.5], velocity=[0.0]))
            rt.run_until(rt.steady_ns * 1e-9 + 0.001, until='steady')

        def heartbeat():
            del statuses[:]
            node._heartbeat()
            rt.run_until(rt.steady_ns * 1e-9 + 0.001, until='steady')
            return {s.name: (s.level, {kv.key: kv.value for kv in s.values}, s.message) for s in statuses}

        at(0)
        at(70)
        s = heartbeat()  # no check yet, the first was due at 65 s: 5 s behind
        assert s['twin_monitor: model'][1]['behind_s'] == '5.00' and 'twin_monitor: checks' not in s
        at(100)
        late.answers.append(('verdict', Verdict(65.0, 'OK', None, None, 1.0), [], 0, 0.5))
        s = heartbeat()
        level, values, text = s['twin_monitor: model']
        assert level == DiagnosticStatus.OK and values['behind_s'] == '35.00' and values['skipped_checks'] == '0'
        level, values, text = s['twin_monitor: checks']  # 35 s > two periods of 15 s
        assert level == DiagnosticStatus.WARN and values['behind_s'] == '35.00' and 'behind the wrist' in text
        late.answers.append(('verdict', Verdict(95.0, 'OK', None, None, 1.0), [], 0, 0.5))
        s = heartbeat()  # caught up: the checks' status is OK again, the model's still OK
        assert s['twin_monitor: checks'][0] == DiagnosticStatus.OK and s['twin_monitor: model'][1]['behind_s'] == '5.00'
        node.destroy_node()
    assert [v['behind_s'] for v in json.loads(hist.read_text())['verdicts']] == [35.0, 5.0]


def test_the_verdict_history_says_how_far_behind_the_newest_sample_each_check_came():
    """Played through, every check is made at its window's end with the samples up to it: nothing behind."""
    mon = Monitor(MonitorConfig(check_period_s=1e9))
    v = mon.decide(Verdict(30.0, 'OK', None, None, 1.0))
    assert v.behind_s is None  # nothing fed yet
    mon.angle(42.5, 0.5)
    v = mon.decide(Verdict(40.0, 'OK', None, None, 1.0))
    assert v.behind_s == pytest.approx(2.5) and 'behind_s' in history_text(mon.history, 'csv').splitlines()[0]
