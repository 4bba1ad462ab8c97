"""The controllers on plants that are not their model: temperature-axis adaptation of the
inverse, the TEM target prefilter, and short closed loops on perturbed and phase-fraction wrists.

Bounds are the figures measured with ``sma_wrist.plants.loop`` (1 cycle, 0.3 kg) with a margin of
about a third; doc/explanation/controllers.md has the full 126 s table.
"""

from __future__ import annotations

import functools
from dataclasses import replace

import numpy as np
import pytest

from sma_wrist.core.control.joint_controller import JointControllerParams
from sma_wrist.core.control.tem import (
    DriveLimits,
    MuscleTemperatureObserver,
    TemControlParams,
    TemLoop,
    TemperatureObserverParams,
)
from sma_wrist.core.errors import ModelInputError, ParameterError
from sma_wrist.core.hysteresis.compensation import MuscleCompensator
from sma_wrist.core.hysteresis.default_params import default_sdgpi
from sma_wrist.core.hysteresis.muscle import MuscleGeometry
from sma_wrist.core.hysteresis.sdgpi import initial_state, step
from sma_wrist.core.thermal import heat_balance as th
from sma_wrist.plants.loop import (
    CASES,
    REVERSAL_BAND_V,
    LoopResult,
    reversals_per_s,
    run_cases,
    run_loop,
    shifted_sdgpi,
)
from sma_wrist.sweep.simulate import Case, simulate

#: TEM command sign changes per second allowed (doc/explanation/controllers.md): one heating/cooling
#: cycle per time constant 1 / gain_per_s = 1 s of the TEM loop's error dynamics
REVERSALS_LIMIT_PER_S = 2.0


def _wire_run(plant_shift_C: float, gain: float, stride: int = 1) -> tuple[MuscleCompensator, list[float]]:
    """One SD-GPI wire shifted by plant_shift_C (the 'plant') heated 30 -> 75 -> 30 degC at 0.8 kgf; the
    compensator observes its temperature and the strain it has, and adapts its axis. ``stride``: every
    stride-th point of the path at stride x 0.01 s (the runs that must learn nothing need no fine path)."""
    g = MuscleGeometry()
    plant_p = shifted_sdgpi(default_sdgpi(), plant_shift_C)
    m = np.full(2, 0.8)
    stress = g.stress_Pa(m)
    T_path = np.concatenate([np.linspace(30, 75, 4500), np.linspace(75, 30, 4500)])[::stride]
    plant = initial_state(plant_p, np.full(2, 30.0), m)
    comp = MuscleCompensator(default_sdgpi(), shift_gain_per_s=gain)
    comp.reset(np.full(2, 30.0), stress)
    shifts = []
    for T in T_path:
        y = step(plant_p, plant, np.full(2, T), m)
        eps = (g.length_scale * y + g.elastic_mm_per_kgf * m) / g.wire_length_mm
        comp.track(np.full(2, T), stress, eps, 0.01 * stride)
        shifts.append(float(comp.shift_C[0]))
    return comp, shifts


def test_the_inverse_learns_a_shifted_temperature_axis() -> None:
    _, shifts = _wire_run(-6.0, 1.0)
    # on the transformation branches the model's prediction pins the shift to the plant's
    assert shifts[4499] == pytest.approx(-6.0, abs=1.0)
    assert shifts[-1] == pytest.approx(-6.0, abs=1.0)
    # on the model itself nothing is learnt
    _, same = _wire_run(0.0, 1.0, stride=10)
    assert max(abs(s) for s in same) < 0.05
    # and without adaptation the axis stays the model's
    _, off = _wire_run(-6.0, 0.0, stride=10)
    assert off == [0.0] * len(off)


def test_prefilter_follows_ramps_without_lag_and_attenuates_noise() -> None:
    hold = th.ThermalParams()
    drive = DriveLimits()
    loop = TemLoop(
        hold.with_limits(drive.boost_min_V, drive.boost_max_V),
        TemControlParams(rate_filter_s=0.05, target_filter_s=0.5),
        drive,
        hold,
        85.0,
    )
    t = np.arange(0.0, 30.0, 0.01)
    rng = np.random.default_rng(0)
    ramp = 30.0 + 1.0 * t  # 1 degC/s, faster than the sine's targets
    noise = rng.normal(0.0, 1.0, t.size)
    out = np.array(
        [loop._prefilter(np.array([r + n, r]), 0.01 if k else None) for k, (r, n) in enumerate(zip(ramp, noise))]
    )
    late = t > 10.0
    # a ramp passes without lag: within one sample's step of it (explicit Euler), where a first-order
    # filter of 0.5 s would lag by 0.5 degC
    assert np.abs(out[late, 1] - ramp[late]).max() < 0.0101
    assert np.std(out[late, 0] - ramp[late]) < 0.35  # white noise of 1 degC at 100 Hz: ~0.3 left
    first_order_lag = 0.5 * 1.0  # what a first-order filter of 0.5 s would leave on this ramp [degC]
    assert np.abs(out[late, 0] - ramp[late]).mean() < 0.5 * first_order_lag


def test_both_tem_paths_get_the_filtered_target() -> None:
    hold = th.ThermalParams()
    drive = DriveLimits()
    params = TemControlParams(rate_filter_s=0.05, target_filter_s=0.5)
    loops = [
        TemLoop(hold.with_limits(drive.boost_min_V, drive.boost_max_V), params, drive, hold, 85.0, compiled=c)
        for c in (False, True)
    ]
    rng = np.random.default_rng(1)
    T, T_d = np.array([30.0, 30.0]), np.array([40.0, 25.0])
    for k in range(300):
        T_d = T_d + rng.normal(0.0, 0.5, 2)
        T = T + 0.01 * (T_d - T) + rng.normal(0.0, 0.05, 2)
        u = [lp.sample(0.01 * (k + 1), T, T_d).command_V for lp in loops]
        assert np.allclose(u[0], u[1], rtol=0, atol=1e-9)


def test_reversal_band_is_the_documented_one() -> None:
    assert REVERSAL_BAND_V == 1.0
    u = np.zeros((1000, 2))
    u[::2, 0], u[1::2, 0] = 24.0, -24.0  # +-24 V flips at 100 Hz
    assert reversals_per_s(u, 0.01) == pytest.approx(99.9, abs=0.2)


def _one_cycle(case: str, mode: str, **kw: object):  # type: ignore[no-untyped-def]
    """One cycle of the Sec. 6.1 sine at 0.3 kg; metrics over its second half (31.4 s)."""
    return run_loop(CASES[case](0.3), mode, 62.83, window_s=31.4, **kw)


def test_inverse_mode_follows_a_wrist_with_other_transition_temperatures() -> None:
    """Transitions 10 degC below the model's: measured 5.6 % with the adapted axis, 42.7 % without."""
    adapted = _one_cycle('T-10', 'inverse_adaptive')
    assert adapted.max_error_pct < 8.0
    assert _one_cycle('T-10', 'inverse_adaptive', shift_gain_per_s=0.0).max_error_pct > 30.0


def test_target_prefilter_removes_chattering_on_noisy_sensors() -> None:
    """pid with thermocouple lag + noise and potentiometer noise: measured 2.1 sign changes a second
    (8.0 % max error) with the prefilter, 30.5 (18.2 %) without it. Without it the PID's own output filter
    (doc/explanation/controllers.md) would hide the noise: 2.26 a second; so the loop without the prefilter
    runs the PID as it was then (Kp / Ki 300 / 60, unfiltered)."""
    r = _one_cycle('sensors', 'pid')
    assert r.reversals_per_s < 1.5 * REVERSALS_LIMIT_PER_S and r.max_error_pct < 11.0
    raw = _one_cycle(
        'sensors',
        'pid',
        tem_params=TemControlParams(rate_filter_s=0.05),
        controller_overrides={
            'pid_output_filter_s': 0.0,
            'pid': replace(JointControllerParams().pid, kp=300.0, ki=60.0),
        },
    )
    assert raw.reversals_per_s > 15.0


def test_reference_lead_brings_direct_and_pid_onto_a_weaker_wire() -> None:
    """Stroke x0.7 (a wire with 30 % less stroke than the model's), one cycle at 0.3 kg: measured
    13.4 % (direct_adaptive) and 12.2 % (pid) with the reference leads (1 / 1.25 s, the defaults),
    17.7 and 17.5 % with the seed's laws on q_d(t); chattering 0.9 / 1.2 sign changes a second.
    direct_adaptive's proportional map (doc/explanation/controllers.md)
    then took it to 8.49 %, and on this wire that map alone does most of it (8.71 % without the lead), so
    direct's law on q_d(t) here is the one before both (3 N/degC, unfiltered: 17.73 %)."""
    cases = [(CASES['stroke x0.7'](0.3), m) for m in ('direct_adaptive', 'pid')]
    led = [_without_inverse('stroke x0.7')[m] for m in ('direct_adaptive', 'pid')]
    assert [r.max_error_pct < 15.0 for r in led] == [True, True]
    assert all(r.reversals_per_s < REVERSALS_LIMIT_PER_S for r in led)
    plain = run_cases(
        cases,
        62.83,
        window_s=31.4,
        controller_overrides={
            'pid_reference_lead_s': 0.0,
            'direct_reference_lead_s': 0.0,
            'force_per_degC_N': 3.0,
            'direct_output_filter_s': 0.0,
        },
    )
    assert [r.max_error_pct > 16.0 for r in plain] == [True, True]


def test_direct_proportional_map_tracks_a_weaker_wire_without_chattering() -> None:
    """direct_adaptive's temperature map (doc/explanation/controllers.md),
    one cycle at 0.3 kg: measured stroke x0.7 8.49 % and noisy sensors 0.80 sign changes a second with
    k = 10 N/degC and the 0.1 s output filter (the defaults); 13.44 % and 3.06 /s with the map before
    (3 N/degC, a relay between 20 and 80 degC for errors over ~0.03 rad); 2.32 /s with k = 10 unfiltered
    (test_joint_controller checks the filter itself)."""
    weak, noisy = (_without_inverse(c)['direct_adaptive'] for c in ('stroke x0.7', 'sensors'))
    assert weak.max_error_pct < 10.0 and noisy.reversals_per_s < REVERSALS_LIMIT_PER_S
    cases = [(CASES[c](0.3), 'direct_adaptive') for c in ('stroke x0.7', 'sensors')]
    weak_before, noisy_before = run_cases(
        cases, 62.83, window_s=31.4, controller_overrides={'force_per_degC_N': 3.0, 'direct_output_filter_s': 0.0}
    )
    assert weak_before.max_error_pct > 12.0 and noisy_before.reversals_per_s > REVERSALS_LIMIT_PER_S


@functools.cache
def _one_cycle_all(case: str, modes: tuple[str, ...]) -> dict[str, LoopResult]:
    """:func:`_one_cycle` for several modes in one vectorised run (a loop does not depend on its
    neighbours, test_sweep), computed once for the parametrised tests that read it."""
    res = run_cases([(CASES[case](0.3), m) for m in modes], 62.83, window_s=31.4)
    return dict(zip(modes, res))


@functools.cache
def _without_inverse_runs() -> dict[tuple[str, str], LoopResult]:
    """direct_adaptive and pid, one cycle (:func:`_one_cycle`), on the cases their tests read, in
    one vectorised run (the per-tick work is shared; a loop does not depend on its neighbours)."""
    keys = [(c, m) for c in ('losses +30%', 'stroke x0.7') for m in ('direct_adaptive', 'pid')] + [
        ('sensors', 'direct_adaptive')
    ]
    return dict(zip(keys, run_cases([(CASES[c](0.3), m) for c, m in keys], 62.83, window_s=31.4)))


def _without_inverse(case: str) -> dict[str, LoopResult]:
    return {m: r for (c, m), r in _without_inverse_runs().items() if c == case}


@pytest.mark.parametrize('mode, bound', [('direct_adaptive', 10.0), ('pid', 10.0)])
def test_modes_without_inverse_hold_on_other_heat_losses(mode: str, bound: float) -> None:
    """Muscle-face losses +30 %: measured 7.2 % (direct) and 7.7 % (pid), 1.1 and 1.5 sign changes a second;
    with the reference leads and the direct map's 3 N/degC 7.8 and 6.8 %, 1.1 and 1.5;
    direct with its proportional map (10 N/degC, 0.1 s filter) 7.38 %, 0.80."""
    r = _without_inverse('losses +30%')[mode]
    assert r.max_error_pct < bound and r.reversals_per_s < REVERSALS_LIMIT_PER_S


#: the phase-fraction wrist, one cycle: measured max error 39.6 / 59.6 / 47.3 % and 1.7 / 0.7 / 1.4 sign
#: changes a second; the < 15 % requirement is NOT met on this plant (doc/explanation/controllers.md): these bounds only
#: guard the figures against getting worse
PHASE_FRACTION = {'inverse_adaptive': 50.0, 'direct_adaptive': 75.0, 'pid': 60.0}


#: Known shortfall: the bounds above were set on an approximate one-wrist loop;
#: on the sweep engine, which equals the node graph to the last bit, the inverse reaches 58.2 %
#: (51-70 % over noise seeds; 58.9 % with the observer and shifted window). Strict:
#: the day a change meets the bound, this marker must go. (pid's marker went with its output filter:
#: 3.28 sign changes a second and 44.1 % before, 0.32 and 47.3 % after; doc/explanation/controllers.md.)
_SHORT = {'inverse_adaptive': 'inverse on the phase-fraction wrist: 58 % > 50 %, not yet solved'}


@pytest.mark.parametrize(
    'mode',
    [
        pytest.param(m, marks=pytest.mark.xfail(strict=True, reason=_SHORT[m])) if m in _SHORT else m
        for m in PHASE_FRACTION
    ],
)
def test_each_mode_on_the_phase_fraction_wrist(mode: str) -> None:
    r = _one_cycle_all('phase_fraction', tuple(PHASE_FRACTION))[mode]
    assert r.max_error_pct < PHASE_FRACTION[mode]
    assert r.reversals_per_s < REVERSALS_LIMIT_PER_S


def test_pid_output_filter_removes_the_stick_slip_chattering() -> None:
    """Nominal plant at 0.1 kg, noise-free, 24-30 s: the joint sticks and slips (~1.2 Hz, ~40 mrad a slip) and
    Kp times that sawtooth swung the TEMs between heating and cooling: measured 2.67 sign changes a second
    with the PID before (Kp / Ki 300 / 60, unfiltered), 2.33 with today's gains (400 / 30) unfiltered, 0.83
    with the 0.3 s output filter (the default; doc/explanation/controllers.md)."""
    case = CASES['nominal'](0.1)
    now = run_loop(case, 'pid', 30.0, window_s=6.0)
    assert now.reversals_per_s < REVERSALS_LIMIT_PER_S
    pid = JointControllerParams().pid
    for before in ({'pid_output_filter_s': 0.0, 'pid': replace(pid, kp=300.0, ki=60.0)}, {'pid_output_filter_s': 0.0}):
        assert run_loop(case, 'pid', 30.0, window_s=6.0, controller_overrides=before).reversals_per_s > 2.0


def test_true_temperature_reaches_only_the_named_consumer() -> None:
    """The diagnosis behind doc/explanation/controllers.md's "Where the thermocouple error acts" (126 s, sensors case:
    inverse 17.67 % as built, 3.34 % with the compensator on the truth, 18.86 % with the TEM loop on it):
    on noisy sensors each choice changes the loop; pid has no compensator, so 'compensator' leaves it
    bit-equal."""
    sc = CASES['sensors'](0.3).scenario
    cases = [Case(0, 'inverse_adaptive', sc), Case(1, 'pid', sc)]
    u = {
        tt: simulate(cases, 10.0, record=True, true_temperature=tt)[1].command_V
        for tt in [(), ('compensator',), ('tem',)]
    }
    assert not np.array_equal(u[('compensator',)][:, 0], u[()][:, 0])
    assert np.array_equal(u[('compensator',)][:, 1], u[()][:, 1])
    assert not np.array_equal(u[('tem',)][:, 1], u[()][:, 1])


def test_true_temperature_names_known_consumers_only() -> None:
    with pytest.raises(ParameterError, match='unknown consumer.*thermostat'):
        run_loop(CASES['nominal'](0.3), 'pid', 1.0, true_temperature=('thermostat',))


def test_observer_follows_the_muscle_through_noise_and_lag() -> None:
    """The heat balance under a heating/cooling command sequence; the thermocouple lags 0.2 s and
    adds 0.3 degC noise. The observer's error is a tenth of the raw measurement's (measured RMS
    0.040 vs 0.394 degC, lag included) and has no bias (mean 0.004 degC); exact measurements on its
    own model are reproduced exactly."""
    thermal = th.ThermalParams()
    rng = np.random.default_rng(4)
    dt, n = 0.01, 3000
    u = np.where((np.arange(n) // 500) % 2 == 0, 12.0, -12.0)[:, None] * np.array([1.0, -1.0])
    x = th.rest_state(thermal, 1)
    junction = x[0, :, 0].copy()
    obs = MuscleTemperatureObserver(thermal, TemperatureObserverParams(correction_s=0.33, tc_lag_s=0.2))
    exact = MuscleTemperatureObserver(thermal, TemperatureObserverParams(correction_s=0.33, tc_lag_s=0.0))
    err_obs, err_raw, err_exact = [], [], []
    for k in range(n):
        meas = junction + 0.3 * rng.standard_normal(2)
        est = obs.update(meas[None], u[k - 1][None] if k else np.zeros((1, 2)), dt)
        est_exact = exact.update(x[0, :, 0][None], u[k - 1][None] if k else np.zeros((1, 2)), dt)
        if k > 200:
            err_obs.append(est[0] - x[0, :, 0])
            err_raw.append(meas - x[0, :, 0])
            err_exact.append(est_exact[0] - x[0, :, 0])
        x = th.step(thermal, x, u[k][None], dt)
        junction = junction + dt / (0.2 + dt) * (x[0, :, 0] - junction)
    rms = lambda e: float(np.sqrt(np.mean(np.square(e))))  # noqa: E731
    assert rms(err_obs) < 0.15 * rms(err_raw)
    assert abs(float(np.mean(err_obs))) < 0.02
    assert rms(err_exact) < 1e-9
    with pytest.raises(ModelInputError):
        obs.update(np.array([[np.nan, 30.0]]), np.zeros((1, 2)), dt)
    with pytest.raises(ParameterError):
        TemperatureObserverParams(correction_s=-1.0)


def test_observer_in_front_of_the_compensator_recovers_the_inverse_on_noisy_sensors() -> None:
    """One cycle, sensors case (thermocouples 0.2 s + 0.2 degC, pot 3 mrad): measured 13.9 % on the
    thermocouples, 2.87 % (2.2 sign changes a second) with MuscleTemperatureObserver(0.33 s, 0.2 s) in
    front of the compensator (the true temperature there: 3.5 %); 3.38 % with the defaults
    (temperature_source observer, window following the shift, shift gain 2 /s)."""
    # the observer's own effect: without the online TEM estimate (core.thermal.online), which learns in this cycle
    assert (
        _one_cycle(
            'sensors', 'inverse_adaptive', compensator_observer=None, window_follows_shift=False, online_thermal=None
        ).max_error_pct
        > 10.0
    )
    r = _one_cycle(
        'sensors',
        'inverse_adaptive',
        compensator_observer=TemperatureObserverParams(),
        window_follows_shift=False,
        online_thermal=None,
    )
    assert r.max_error_pct < 4.0
    assert _one_cycle('sensors', 'inverse_adaptive', online_thermal=None).max_error_pct < 4.0


def test_inverse_window_follows_the_learnt_shift() -> None:
    """Transitions 10 degC below the model's, the defaults (observer, shift gain 2 /s, stroke 0.5 /s), one
    cycle at 0.3 kg: measured 2.93 % with the inverse's window moved by each wire's shift (its answers span
    20-80 degC on the wire's axis), 11.31 % without (a wire colder than the model never gets above
    80 - |shift| degC; doc/explanation/controllers.md). Mixed B (transitions -5 degC, stroke x1.15, TEM
    gain +15 %, losses -15 %, ambient -3 degC, noisy sensors) shows it less: 5.01 vs 8.09 %. Before the
    shift's slope was kept <= 0 (doc/explanation/controllers.md) mixed B read 5.61 vs 23.74 %: part of
    that was the wrong-way drift the slope's sign had caused, not the window."""
    # the window's own effect: without the online TEM estimate, which rescues a fixed window too
    assert _one_cycle('T-10', 'inverse_adaptive', online_thermal=None).max_error_pct < 5.0
    assert _one_cycle('T-10', 'inverse_adaptive', window_follows_shift=False, online_thermal=None).max_error_pct > 10.0


def test_inverse_window_per_wire_is_checked_and_used() -> None:
    """MuscleCompensator with window_follows_shift: a wire whose axis moved by -10 degC gets answers up
    to the window's top (80 degC) on its own axis, the model's window moved to 30-90 degC; a window
    outside the model's validity or a non-numerical inverse is refused with the reason."""
    geo = MuscleGeometry()
    comp = MuscleCompensator(
        default_sdgpi(), geo, T_range_C=(20.0, 80.0), shift_gain_per_s=1.0, window_follows_shift=True
    )
    stress = np.full(2, 0.9 * 9.80665 / geo.wire_area_m2)
    comp.reset(np.array([40.0, 40.0]), stress)
    comp.shift_C = np.array([-10.0, 0.0])
    # a strain far beyond the stroke: both wires saturate at their window's top
    res = comp(np.full(2, -0.2), stress, commit=False)
    assert res.saturated.all()
    np.testing.assert_allclose(res.temperature_C, [80.0, 80.0])
    fixed = MuscleCompensator(default_sdgpi(), geo, T_range_C=(20.0, 80.0), shift_gain_per_s=1.0)
    fixed.reset(np.array([40.0, 40.0]), stress)
    fixed.shift_C = np.array([-10.0, 0.0])
    np.testing.assert_allclose(fixed(np.full(2, -0.2), stress, commit=False).temperature_C, [70.0, 80.0])
    with pytest.raises(ModelInputError, match='compensator window'):
        comp.inverse.solve(np.zeros(2), np.full(2, 0.9), commit=False, window=(np.full(2, 50.0), np.full(2, 120.0)))
    analytic = MuscleCompensator(default_sdgpi(), geo, T_range_C=(20.0, 80.0), method='analytic')
    analytic.reset(np.array([40.0, 40.0]), stress)
    with pytest.raises(ParameterError, match='numerical'):
        analytic.inverse.solve(np.zeros(2), np.full(2, 0.9), window=(np.full(2, 20.0), np.full(2, 80.0)))


def _stroke_run(stroke: float, gain: float) -> MuscleCompensator:
    """One SD-GPI wire with its stroke scaled (the family's construction, ``shifted_sdgpi``) cycled
    20 -> 80 -> 20 -> 80 degC at the pre-load's 0.775 kgf in 0.1 degC steps 0.1 s apart; the compensator tracks it
    (shift 2 /s, stroke ``gain``)."""
    g = MuscleGeometry()
    plant_p = shifted_sdgpi(default_sdgpi(), 0.0, stroke)
    m = np.full(2, 0.775)
    stress = g.stress_Pa(m)
    up, down = np.linspace(20, 80, 600), np.linspace(80, 20, 600)
    plant = initial_state(plant_p, np.full(2, 20.0), m)
    comp = MuscleCompensator(default_sdgpi(), shift_gain_per_s=2.0, stroke_gain_per_s=gain)
    comp.reset(np.full(2, 20.0), stress)
    for T in np.concatenate([up, down, up]):
        y = step(plant_p, plant, np.full(2, T), m)
        eps = (g.length_scale * y + g.elastic_mm_per_kgf * m) / g.wire_length_mm
        comp.track(np.full(2, T), stress, eps, 0.1)
    return comp


def test_the_inverse_learns_a_wire_with_another_stroke() -> None:
    """Stroke x0.75 (the family spans 0.7-1.3): the stroke ratio learns part of it on the loop's ends
    (measured 0.905), the shift absorbs less of it (+3.9 degC, +5.1 without); on the model itself the ratio
    stays 1 and nothing is learnt (doc/explanation/controllers.md).

    Measured 0.69 before the shift's slope was kept <= 0 (doc/explanation/controllers.md): the wrong-way
    drift then ran the shift to +13 degC on the flat cold end and left the stroke the whole error. Now the
    cooling branch's tail near 20 degC, where the shift has a slope, takes about half of it; x1.3 reads 1.17
    (shift -4.9 degC, -9.1 without)."""
    learnt = _stroke_run(0.75, 0.5)
    assert 0.75 - 0.08 <= learnt.stroke[0] <= 0.95  # learnt the right way, at least 0.05 of the 0.25
    fixed = _stroke_run(0.75, 0.0)
    assert fixed.stroke[0] == 1.0 and abs(learnt.shift_C[0]) < abs(fixed.shift_C[0])
    larger = _stroke_run(1.3, 0.5)
    assert 1.05 <= larger.stroke[0] <= 1.3 + 0.08
    same = _stroke_run(1.0, 0.5)
    assert same.stroke[0] == pytest.approx(1.0, abs=0.01) and abs(same.shift_C[0]) < 0.05
    with pytest.raises(ParameterError, match='stroke_limits'):
        MuscleCompensator(default_sdgpi(), stroke_limits=(1.2, 2.0))
    with pytest.raises(ParameterError, match='stroke_gain_per_s'):
        MuscleCompensator(default_sdgpi(), stroke_gain_per_s=float('nan'))


def test_stroke_adaptation_fixes_a_wire_with_a_larger_stroke_in_one_cycle() -> None:
    """Stroke x1.3 at 0.3 kg, the first 47.1 s (3/4 of a cycle; max error over the last 15.7 s, the
    reference's descent): measured 2.90 % with the stroke adapting (stroke_gain_per_s 0.5 /s, the default since
    doc/explanation/controllers.md), 21.94 % with the model's stroke (stroke_gain_per_s 0; the shift
    alone learns it over the second cycle)."""
    case = CASES['stroke x1.3'](0.3)
    assert run_loop(case, 'inverse_adaptive', 47.1, window_s=15.7).max_error_pct < 4.0
    assert run_loop(case, 'inverse_adaptive', 47.1, window_s=15.7, stroke_gain_per_s=0.0).max_error_pct > 15.0


def test_the_inverse_adapts_on_a_wire_identified_from_measured_loops(tmp_path) -> None:
    """doc/explanation/controllers.md: the Flexinol wire identified from its measured
    loops (test/data/flexinol, maestrolab, MIT; TEMs rated 120 degC, identify's wrist_params.yaml) runs slack or
    below its 50-200 MPa calibration most of the time, so with the gate on its shift and stroke never adapted:
    a wire 5 degC hotter than that model, 0.3 kg, 126 s, gave 51.5 % (pid 9.7 %). With the gate off (the
    default) the shift adapts on it: 5.6 %, and 5.2 % on the identified wire itself (8.0 % gated).

    On this wire the inverse's TEM commands chatter (3.3 / 3.5 sign changes a second without tem_controller's
    chatter guard); with it (the default) 1.7 / 1.7, at 8.1 / 7.5 % (doc/explanation/controllers.md). Gated, with
    the guard: 54.1 %. (Figures with the CPU-independent fit; with the earlier
    fit of the same loops 5.2 / 5.6 % unguarded, 7.5 / 6.5 % guarded.)"""
    from pathlib import Path

    from sma_wrist.core.thermal.params_file import write_thermal_file
    from sma_wrist.identify.hysteresis import Options, run
    from sma_wrist.identify.wrist import rated_tems
    from sma_wrist.plants.spread import Scenario
    from sma_wrist.sweep.graph_params import loop_settings

    flex = Path(__file__).parent / 'data' / 'flexinol'
    tems = write_thermal_file(tmp_path / 'tems.yaml', rated_tems(120.0))
    doc = run(
        Options(
            [str(p) for p in sorted(flex.glob('*MPa.txt'))],
            out=str(tmp_path),
            loo=False,
            plots=False,
            model='saturating',
            thermal_file=str(tems),
        ),
        progress=lambda m: None,
    )
    kw = loop_settings([doc['wrist_params']['file']]).kwargs
    assert kw['hold_shift_outside_load_range'] is False  # config/wrist.yaml's default
    cases = [
        Case(0, 'inverse_adaptive', Scenario(payload_kg=0.3, noise_seed=5)),
        Case(1, 'inverse_adaptive', Scenario(payload_kg=0.3, transition_shift_C=5.0, noise_seed=5)),
    ]
    tem = kw['tem_loop']
    unguarded = {**kw, 'tem_loop': replace(tem, params=replace(tem.params, chatter_limit_per_s=0.0))}
    rows = simulate(cases, 126.0, **kw)[0] + simulate(cases, 126.0, **unguarded)[0]
    own, hotter, own_free, hotter_free = (r['max_error_pct'] for r in rows)
    flips = [r['sign_changes_per_s'] for r in rows]
    assert own_free < 7.0 and hotter_free < 8.0, (own_free, hotter_free)  # measured 5.96 / 6.11 %
    assert min(flips[2:]) > 2.5, flips  # measured 3.29 / 3.47 a second: the relay of doc/explanation/controllers.md
    assert max(flips[:2]) < REVERSALS_LIMIT_PER_S, flips  # measured 1.67 / 1.67 with the guard
    assert own < 10.0 and hotter < 9.0, (own, hotter)  # measured 8.09 / 7.50 %: the guard's price
    gated = simulate(cases[1:], 126.0, **{**kw, 'hold_shift_outside_load_range': True})[0][0]['max_error_pct']
    assert gated > 30.0, gated  # measured 54.1 % (51.5 % before the guard): no adaptation at all on this wire
