"""sma-wrist diagnose on effects it was not designed on.

A clean closed-loop run of the node graph (pid, 0.3 kg) is recorded once per test run;
:mod:`sma_wrist.diagnose.distort` then rewrites it the way a real sensor, driver or wire
would (without the diagnosis' own extension code) and the diagnosis must name the right
subsystem. Each of the first five tests reproduces a failure of a diagnosis without the per-channel
sensor and driver effects (the verdict it gave then is in the test's docstring).
"""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

from sma_wrist.diagnose import bound_tolerance, diagnose_run
from sma_wrist.diagnose import distort as ds
from sma_wrist.diagnose import effects as fx
from sma_wrist.diagnose.data import load_run

RUN_S = 60.0


@pytest.fixture(scope='module')
def clean_run(tmp_path_factory):
    """A clean 60 s closed-loop recording (pid), loaded."""
    from sma_wrist.diagnose.bench import record_clean_runs

    bags = record_clean_runs(str(tmp_path_factory.mktemp('independent')), ('pid',), RUN_S)
    return load_run(bags['pid'])


def _diagnose(run, kind=None, channel=None, value=0.0, noise_T=0.1, noise_q=1e-3, seed=3):  # type: ignore[no-untyped-def]
    d = ds.Distortion(kind, channel, value, '') if kind else None
    return diagnose_run(ds.apply(run, d, noise_T, noise_q, seed))


def _values(res) -> dict[str, float]:  # type: ignore[no-untyped-def]
    return {k: v['value'] for k, v in res.parameters.items()}


@pytest.mark.parametrize('noise_T,noise_q', [(0.1, 1e-3), (0.3, 3e-3)])
def test_ordinary_sensor_noise_is_no_false_alarm(clean_run, noise_T, noise_q):
    """Before: 'unexplained discrepancy in mechanics' (0.3 degC) and 'friction' (0.1 degC): the
    thermocouple noise driving the hysteresis replay came out as a structured angle residual."""
    res = _diagnose(clean_run, noise_T=noise_T, noise_q=noise_q)
    assert not res.discrepancy, res.summary
    assert res.confidence >= 0.9


def test_realistic_sensors_read_back_from_a_bag_are_no_false_alarm(clean_run, tmp_path):
    """White noise, quantisation, mains hum and a 0.7 Hz line (distort.realistic), written with jittered stamps and
    dropped samples and read back. Before: 'unexplained discrepancy in mechanics' (angle residual 1.75 x its noise
    level): the interpolation onto the analysis grid hid 40 % of the thermocouple noise from the noise estimate, so
    the noise the replay is driven by was simulated too weak."""
    from sma_wrist.diagnose import testdata as td

    bag = td.write_run_bag(
        ds.realistic(clean_run, seed=11), tmp_path / 'b', {'stamp_jitter_s': 1e-3, 'drop_rate': 1e-3}
    )
    res = diagnose_run(load_run(bag))
    assert not res.discrepancy and not res.unexplained, res.summary
    assert res.residual_stats['mechanics']['nominal']['rms_over_noise'] < 1.4


def test_noise_levels_of_a_series_interpolated_between_jittered_stamps():
    """On the grid the noise is averaged between neighbours (its std drops by ~0.82); what a smoothing lets through
    is the sensor's own level."""
    rng = np.random.default_rng(4)
    t = np.arange(20000) * 0.01 + rng.normal(0.0, 1e-3, 20000)
    x = 40.0 + 10.0 * np.sin(0.2 * t) + rng.normal(0.0, 0.3, t.size)
    grid = np.arange(t[0], t[-1], 0.0100011)  # the median step of the stamps, not their nominal one
    y = np.interp(grid, t, x)
    noise = y - (40.0 + 10.0 * np.sin(0.2 * grid))
    assert fx.noise_sigma(y) == pytest.approx(np.std(noise), rel=0.05)
    assert fx.noise_density_sigma(y) == pytest.approx(0.3, rel=0.05)


NAMED = [
    # before: actuator_delay (90 s run) / sensor_lag (60 s run); the thermal channel alone cannot tell
    ('thermocouple delay', ('delay', 'T', 1.0), 'sensor', 'temp_sensor_delay', ('temp_delay_1_s', 'temp_delay_2_s')),
    # the mirror case: commands applied late (plant re-simulated) are not blamed on the sensors
    ('late drive', ('command_delay', 'u', 0.4), 'actuator', 'actuator_delay', ('command_delay_s',)),
    # before: hysteresis_drift (wire fatigue) with 84-87 % held-out gain
    (
        'thermocouple drift',
        ('drift', 'T', 30.0),
        'sensor',
        'temp_sensor_drift',
        ('temp_drift_1_C_per_h', 'temp_drift_2_C_per_h'),
    ),
    # an actuator effect shows in the thermal channel but not between temperatures and angle
    ('driver dead zone', ('dead_zone', 'u', 2.0), 'actuator', 'tem_dead_zone', ('tem_dead_zone_V',)),
]


@pytest.mark.parametrize('effect,subsystem,cause,params', [c[1:] for c in NAMED], ids=[c[0] for c in NAMED])
def test_sensor_and_actuator_effects_are_named_in_their_subsystem(clean_run, effect, subsystem, cause, params):
    res = _diagnose(clean_run, *effect)
    assert res.subsystem == subsystem and res.cause == cause, res.summary
    for k in params:
        assert _values(res)[k] == pytest.approx(effect[2], rel=0.15), k


def test_offset_on_one_thermocouple_is_named_on_that_channel(clean_run):
    """Before: recalibrate_mechanics (pre-load, payload 0.45 kg) -- a wrong subsystem."""
    res = _diagnose(clean_run, 'offset', 'T1', 3.0)
    assert res.subsystem == 'sensor' and res.cause == 'temp_sensor_offsets', res.summary
    v = _values(res)
    assert v['temp_offset_1_C'] == pytest.approx(3.0, rel=0.15) and abs(v['temp_offset_2_C']) < 0.3


def test_wire_transitions_drifting_over_the_run_are_named_in_the_hysteresis(clean_run):
    """The wires transforming 6 degC hotter by the end of the run (fatigue), made by the sweep's perturbed wire,
    not by the diagnosis' drift-per-cycle extension: the wire subsystem, with a drift that moves them hotter."""
    d = ds.Distortion('transition_drift', 'plant', 6.0, 'degC', ramp_s=RUN_S)
    assert d.subsystem == 'hysteresis'
    res = diagnose_run(ds.apply(clean_run, d, 0.1, 1e-3, 3))
    assert res.discrepancy and res.subsystem == 'hysteresis' and res.cause == 'hysteresis_drift', res.summary
    assert _values(res)['hyst_drift_C_per_cycle'] > 0


def test_wires_that_transform_hotter_from_the_start_are_named_a_transition_shift(clean_run):
    """Fatigue that has happened: the wires transform 4 degC hotter throughout (the sweep's perturbed wire, not the
    diagnosis' extension), as in a monitor window cut after a wire drift ended. Before: an unexplained discrepancy in
    the mechanics (the drift is nominal where the data begin), with recalibrate_mechanics' payload 0.6 kg too heavy
    as the best fit."""
    d = ds.Distortion('transition_drift', 'plant', 4.0, 'degC')
    res = diagnose_run(ds.apply(clean_run, d, 0.1, 1e-3, 3))
    assert res.discrepancy and res.subsystem == 'hysteresis' and res.cause == 'hysteresis_shift', res.summary
    assert _values(res)['hyst_shift_C'] == pytest.approx(4.0, rel=0.15)


def test_a_fit_on_its_bound_is_never_reported_as_the_value(clean_run):
    """Off-model heat balance (Peltier, Joule and exchanger losses 40-70 % off; no sensor fault).
    Before: recalibrate_thermal with ambient_offset_C = 15 degC, the upper bound, as the value."""
    res = _diagnose(clean_run, 'thermal_physics', 'plant', 2.0)
    assert res.discrepancy and res.subsystem == 'thermal', res.summary
    assert res.bound_hits and 'larger than the catalogue allows' in res.summary
    for k, v in res.parameters.items():
        i = fx.INDEX[k]
        lo, hi, nom = fx.LOWER[i], fx.UPPER[i], v['nominal']
        assert all(abs(v['value'] - b) > bound_tolerance(lo, hi, nom, b) for b in (lo, hi)), k


def test_generator_reproduces_the_recording_and_does_not_use_the_extension_code(clean_run):
    T, q = ds.resimulate(clean_run)
    assert np.sqrt(np.mean((T - clean_run.T) ** 2)) < 1e-6 and np.sqrt(np.mean((q - clean_run.q) ** 2)) < 1e-6
    # the generator's own code imports nothing of the model it tests
    tree = ast.parse(Path(ds.__file__).read_text())
    imported = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    imported |= {f'{n.module}.{a.name}' for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) for a in n.names}
    own = {'model_extensions', 'effects', 'kernels', 'fit', 'testdata'}
    assert not [m for m in imported if own & set(m.split('.'))], imported


def test_sensor_chain_per_channel_matches_the_replay():
    from sma_wrist.core.plant import extensions as mx

    dt = 0.01
    t = np.arange(3000) * dt
    T = np.stack([40 + 20 * np.sin(0.1 * t), 40 - 20 * np.sin(0.13 * t)], axis=1)
    v = {
        'temp_offset_1_C': 1.2,
        'temp_offset_2_C': -0.7,
        'temp_gain_err_1': 0.05,
        'temp_gain_err_2': -0.04,
        'temp_delay_1_s': 0.337,
        'temp_delay_2_s': 0.05,
        'temp_lag_1_s': 2.0,
        'temp_lag_2_s': 0.5,
        'temp_drift_1_C_per_h': 20.0,
        'temp_drift_2_C_per_h': -8.0,
        'temp_offset_C': 0.3,
    }
    chain = mx.SensorChain(v, dt, 0.524)
    got = np.array([chain.temperatures(x) for x in T])
    np.testing.assert_allclose(got, fx.thermocouples(T, fx.theta(**v), dt), atol=1e-9)
