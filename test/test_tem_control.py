"""Feedback-linearising TEM controller (Eqs. 5.38-5.47): root choice, flags, limits, Figs. 5.24-5.28 story."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sma_wrist.core.control import tem as tc
from sma_wrist.core.errors import ModelInputError, ParameterError
from sma_wrist.core.thermal import heat_balance as th

P = th.ThermalParams()
WIDE = P.with_limits(-30.0, 30.0)  # the seed's Simulink runs had no limits; +-30 V is I = +-12, still stable
DT = 0.05
Ref = Callable[[float], tuple[np.ndarray, np.ndarray]]


def seed_sine(t: float) -> tuple[np.ndarray, np.ndarray]:
    """T_d,i = 50 + 30 sin(0.1 t + (i - 1) pi), i = 1, 2 (Sec. 5.2) and its rate."""
    ph = np.array([0.0, np.pi])
    return 50 + 30 * np.sin(0.1 * t + ph), 3.0 * np.cos(0.1 * t + ph)


def slow_sine(t: float) -> tuple[np.ndarray, np.ndarray]:
    """A sine the default limits can follow: 45 +- 20 degC at 0.02 rad/s (0.4 degC/s)."""
    ph = np.array([0.0, np.pi])
    return 45 + 20 * np.sin(0.02 * t + ph), 0.4 * np.cos(0.02 * t + ph)


def steps(t: float) -> tuple[np.ndarray, np.ndarray]:
    return np.array([60.0, 40.0]), np.zeros(2)


def run(p: th.ThermalParams, ref: Ref, mode: str, T_end: float = 400.0) -> dict[str, np.ndarray]:
    """Closed loop from rest. 'one': one module, face i tracks T_d,i, h = (1, 1). 'two': layer i's muscle tracks T_d,i."""
    T = th.rest_state(p, 1, 1 if mode == 'one' else 2)
    out: dict[str, list] = {'e': [], 'u': [], 'T': [], 'flag': []}
    for k in range(int(round(T_end / DT))):
        T_d, rate = ref(k * DT)
        if mode == 'one':
            r = tc.one_module_command(p, T, T_d[None], rate[None], tc.SEED_ONE_MODULE_WEIGHTS)
            out['e'].append(T_d - T[0, 0])
        else:
            r = tc.two_layer_command(p, T, T_d[None], rate[None])
            out['e'].append(T_d - T[0, :, 0])
        out['u'].append(r.command_V[0])
        out['flag'].append(r.any_flag[0])
        T = th.step(p, T, r.command_V, DT)
        out['T'].append(T[0])
    return {k: np.array(v) for k, v in out.items()}


def tail(x: np.ndarray, t_from: float = 200.0) -> np.ndarray:
    return x[int(round(t_from / DT)) :]


# ------------------------------------------------------------------ the story


def test_one_module_cannot_hold_two_temperatures_fig_5_24_5_25() -> None:
    """h1 = h2 = 1 on one module: large steady errors on both faces, even without command limits."""
    for ref, min_rms in ((steps, 10.0), (seed_sine, 3.0)):
        e = tail(run(WIDE, ref, 'one')['e'])
        rms = np.sqrt((e**2).mean(axis=0))
        assert np.all(rms > min_rms), (ref.__name__, rms)  # measured: step 15.4 / 14.9, sine 4.5 / 6.5 degC


def test_two_layers_track_the_seed_references_fig_5_27_5_28() -> None:
    """Two layers, h = (1, 0) each, same (wide) limits: errors below 0.02 degC after 200 s."""
    for ref in (steps, seed_sine):
        res = run(WIDE, ref, 'two')
        assert np.abs(tail(res['e'])).max() < 0.02, ref.__name__  # measured 0.011 (sine), 0 (step)
        assert not tail(res['flag']).any()
        assert np.all((res['u'] >= WIDE.u_min_V) & (res['u'] <= WIDE.u_max_V))


def test_seed_sine_needs_commands_beyond_the_physical_limits() -> None:
    """Measured: following 50 +- 30 sin(0.1 t) takes -25.6..+19.3 V and drives the exchanger face to ~106 degC."""
    res = run(WIDE, seed_sine, 'two')
    u = tail(res['u'])
    assert u.min() < P.u_min_V - 10 and u.max() > P.u_max_V + 5
    assert res['T'][:, :, th.EXCHANGER_FACE].max() > 100.0
    limited = run(P, seed_sine, 'two')
    assert tail(limited['flag']).any()  # with the default limits the shortfall is reported, not hidden
    assert np.abs(tail(limited['e'])).max() > 5.0


@pytest.mark.parametrize('ref', [steps, slow_sine])
def test_two_layers_track_within_default_limits(ref: Ref) -> None:
    res = run(P, ref, 'two')
    assert np.abs(tail(res['e'])).max() < 0.01  # measured: 0 (step), 0.0007 (slow sine)
    assert not tail(res['flag']).any()
    assert np.all((res['u'] >= P.u_min_V) & (res['u'] <= P.u_max_V))
    assert res['u'].max() == P.u_max_V  # the start-up transient does hit the limit (and is flagged)
    assert res['flag'][:100].any()
    assert not th.out_of_window(P, res['T']).any()


def test_estimated_reference_rate_tracks_too() -> None:
    ctl = tc.TemController(P, tc.TemControlParams())
    T = th.rest_state(P, 1)
    errs = []
    for k in range(int(400 / DT)):
        T_d, _ = slow_sine(k * DT)
        T_d_faces = np.stack([T_d, T[0, :, 1]], axis=-1)[None]  # exchanger targets ignored (h2 = 0)
        r = ctl.update(k * DT, T, T_d_faces)
        errs.append(T_d - T[0, :, 0])
        T = th.step(P, T, r.command_V, DT)
    assert np.abs(tail(np.array(errs))).max() < 0.02  # backward difference lags half a sample
    # without the rate feed-forward the error is the lag of a first-order loop, ~0.4 degC here
    with pytest.raises(ModelInputError):
        ctl.update((k - 1) * DT, T, T_d_faces)  # time going backwards


def test_printed_sign_of_eq_5_44_makes_the_error_grow() -> None:
    """c with +k e (Eq. 5.44 as printed) gives de/dt = +k e; with -k e (Eq. 5.42) e decays as exp(-k t)."""
    k = 0.5
    for gain, grows in ((k, False), (-k, True)):
        T = th.rest_state(P, 1, 1)
        T_d = T + np.array([[[3.0, 0.0]]])
        e0 = 3.0
        for _ in range(int(2.0 / 0.001)):  # the law is continuous-time; a short hold keeps ZOH error ~1e-4
            a, b, c = tc.quadratic_coefficients(P, T, T_d, 0.0, gain)
            I, real = tc.small_root(a, b, c)
            assert real[..., 0].all() or grows  # the growing error eventually asks for unreachable rates
            T = th.step(P.with_limits(-100, 100), T, th.command_from_input(P, I[..., 0]), 0.001, validate=False)
        e = float(T_d[0, 0, 0] - T[0, 0, 0])
        if grows:
            assert e > e0 * 1.5  # e0 exp(+1) = 8.2 while the rate is reachable
        else:
            assert e == pytest.approx(e0 * np.exp(-k * 2.0), rel=1e-3)


# --------------------------------------------------------------- root choice


@settings(max_examples=200, deadline=None)
@given(st.floats(5.0, 80.0), st.floats(5.0, 80.0), st.floats(5.0, 80.0), st.floats(-3.0, 3.0), st.floats(0.1, 5.0))
def test_chosen_root_is_a_true_inverse(T1: float, T2: float, T_d: float, rate: float, gain: float) -> None:
    """Where the root exists and is inside the limits, the plant's rate equals dT_d/dt + k e exactly."""
    T = np.array([[[T1, T2]]])
    r = tc.feedback_linearising_command(P, T, [[[T_d, T2]]], [[[rate, 0.0]]], tc.TemControlParams(gain))
    assert P.u_min_V <= r.command_V[0, 0] <= P.u_max_V
    if r.saturated[0, 0] or r.no_root[0, 0, 0]:
        return
    achieved = th.derivative(P, T, r.command_V)[0, 0, 0]
    assert achieved == pytest.approx(rate + gain * (T_d - T1), abs=1e-9)
    a, b, c = tc.quadratic_coefficients(P, T, [[[T_d, T2]]], [[[rate, 0.0]]], gain)
    roots = np.roots([a[0, 0, 0], b[0, 0, 0], c[0, 0, 0]])
    assert abs(r.face_current[0, 0, 0]) == pytest.approx(np.abs(roots).min(), rel=1e-9)
    other = roots[np.argmax(np.abs(roots))]
    if min(T1, T2) >= 15.0:  # the roots sum to -b/K_R, |b| grows with T: the other root is beyond the limits
        assert not (th.model_input(P, P.u_max_V) <= other <= th.model_input(P, P.u_min_V))


def test_root_is_continuous_along_a_target_sweep() -> None:
    """Over the targets whose rate is reachable (one interval around e = 0) the root is monotone, without jumps."""
    T = np.array([[[40.0, 30.0]]])
    T_d = np.linspace(20, 80, 6001)
    a, b, c = tc.quadratic_coefficients(
        P, np.broadcast_to(T, (6001, 1, 2)), np.stack([T_d, np.full_like(T_d, 30.0)], -1)[:, None], 0.0
    )
    I, real = tc.small_root(a, b, c)
    idx = np.flatnonzero(real[:, 0, 0])
    assert idx.size > 100 and np.all(np.diff(idx) == 1)  # one contiguous interval
    assert T_d[idx[0]] < 40.0 < T_d[idx[-1]]
    I = I[idx, 0, 0]
    assert np.all(np.diff(I) < 0)  # hotter target -> more negative I (heats T1)
    # always the branch where d(rate)/dI = 2 a I + b keeps the sign of b (the invertible side)
    assert np.all(np.sign(2 * a[idx, 0, 0] * I + b[idx, 0, 0]) == np.sign(b[idx, 0, 0]))
    assert np.abs(np.diff(I)).max() < 0.5  # the other root is > 8 away: no branch jump


def test_no_real_root_is_flagged_and_saturates_toward_the_vertex() -> None:
    T = np.array([[[50.0, 30.0], [50.0, 30.0]]])
    # layer 0 asks for -50 degC/s (unreachable), layer 1 for +50 degC/s (root exists, far beyond limits)
    r = tc.two_layer_command(P, T, [[50.0, 50.0]], [[-50.0, 50.0]])
    np.testing.assert_array_equal(r.no_root[0, :, 0], [True, False])
    assert not r.no_root[..., 1].any()  # h2 = 0: the exchanger face is not controlled, never flagged
    np.testing.assert_array_equal(r.saturated[0], [True, True])
    np.testing.assert_array_equal(r.command_V[0], [P.u_min_V, P.u_max_V])
    a, b, c = tc.quadratic_coefficients(P, T, [[[50.0, 30.0], [50.0, 30.0]]], [[[-50.0, 0.0], [50.0, 0.0]]])
    assert b[0, 0, 0] ** 2 - 4 * a[0, 0, 0] * c[0, 0, 0] < 0 <= b[0, 1, 0] ** 2 - 4 * a[0, 1, 0] * c[0, 1, 0]
    assert r.face_current[0, 0, 0] == pytest.approx(-b[0, 0, 0] / (2 * a[0, 0, 0]))


@settings(max_examples=150, deadline=None)
@given(
    st.lists(st.floats(0.0, 80.0), min_size=4, max_size=4),
    st.floats(0.0, 90.0),
    st.floats(0.0, 90.0),
    st.floats(-20.0, 20.0),
    st.floats(-20.0, 20.0),
)
def test_limits_never_exceeded_and_every_clip_reported(
    T_list: list[float], d1: float, d2: float, r1: float, r2: float
) -> None:
    T = np.array(T_list).reshape(1, 2, 2)
    r = tc.two_layer_command(P, T, [[d1, d2]], [[r1, r2]])
    assert np.all((r.command_V >= P.u_min_V) & (r.command_V <= P.u_max_V))
    wanted = th.command_from_input(P, r.face_current[..., 0])
    np.testing.assert_array_equal(r.saturated, (wanted < P.u_min_V) | (wanted > P.u_max_V))
    np.testing.assert_allclose(r.current, th.model_input(P, r.command_V))


def test_one_module_weights_sum_the_face_currents_eq_5_47() -> None:
    T = np.array([[40.0, 35.0]])
    r = tc.one_module_command(WIDE, T, [[42.0, 33.0]], [[0.0, 0.0]], (0.7, 0.4))
    assert r.current[0, 0] == pytest.approx(0.7 * r.face_current[0, 0, 0] + 0.4 * r.face_current[0, 0, 1])
    assert not r.saturated.any()


def test_typed_errors() -> None:
    T = th.rest_state(P, 1)
    with pytest.raises(ModelInputError):
        tc.two_layer_command(P, T, [[np.nan, 40.0]], [[0.0, 0.0]])
    with pytest.raises(ModelInputError):
        tc.two_layer_command(P, T, [[40.0, 40.0]], [[np.inf, 0.0]])
    bad = T.copy()
    bad[0, 0, 0] = np.nan
    with pytest.raises(ModelInputError):
        tc.two_layer_command(P, bad, [[40.0, 40.0]], [[0.0, 0.0]])
    for kw in (dict(gain_per_s=0.0), dict(gain_per_s=np.nan), dict(weights=(0.0, 0.0)), dict(rate_filter_s=-1.0)):
        with pytest.raises(ParameterError):
            tc.TemControlParams(**kw)


def test_safe_command_range_keeps_every_face_in_the_window_over_the_horizon():
    """Held for the horizon (checked with 0.05 s steps, the range was found with 1 s RK4 steps),
    the range's ends keep every face inside 0-80 degC; one volt further leaves it."""
    from sma_wrist.core.control.tem import DriveLimits, safe_command_range

    P = th.ThermalParams()
    D = DriveLimits()
    wide = th.ThermalParams().with_limits(D.boost_min_V, D.boost_max_V)
    rng = np.random.default_rng(11)
    x = np.stack([th.rest_state(P, 1)[0] for _ in range(60)])
    x = x + rng.uniform(-15.0, 50.0, x.shape)  # faces between ~10 and ~78 degC
    x = np.clip(x, 1.0, 79.0)
    lo, hi = safe_command_range(P, D, x)
    for u_end in (lo, hi):
        X = x.copy()
        peak, low = X.max(axis=-1), X.min(axis=-1)
        for _ in range(int(D.horizon_s / 0.05)):
            X = th.step(wide, X, u_end, 0.05, validate=False)
            peak, low = np.maximum(peak, X.max(axis=-1)), np.minimum(low, X.min(axis=-1))
        ok = lo <= hi  # a layer with no safe command gets the least-bad one: not checked here
        assert (peak[ok] <= D.face_max_C + 0.05).all() and (low[ok] >= D.face_min_C - 0.05).all()
    beyond = np.minimum(hi + 1.0, D.boost_max_V)
    inner = hi < D.boost_max_V - 1.0
    X, peak = x.copy(), x.max(axis=-1)
    for _ in range(3):
        X = th.step(wide, X, beyond, 1.0, validate=False)
        peak = np.maximum(peak, X.max(axis=-1))
    tight = int((peak[inner] > D.face_max_C).sum())
    assert inner.any() and tight == inner.sum()  # the upper end is the last safe volt


def test_predictive_protection_passes_a_safe_request_and_reports_a_clipped_one():
    from sma_wrist.core.control.tem import DriveLimits, protected_command

    P = th.ThermalParams()
    x = th.rest_state(P, 1)
    x[0, :, 0] = [40.0, 79.0]
    u, limited = protected_command(P, DriveLimits(), x, np.array([[24.0, 24.0]]))
    assert u[0, 0] == 24.0 and not limited[0, 0]  # far from the limit: the full boost
    assert u[0, 1] < 24.0 and limited[0, 1]  # a face at 79 degC: held back
    fixed, _ = protected_command(P, DriveLimits(predictive=False), x, np.array([[24.0, 24.0]]))
    assert fixed[0, 1] == P.u_max_V  # the old switch: hold limit above protect_above_C


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_one_wrist_kernels_agree_with_the_numpy_path(seed):
    """tem_controller's per-sample path (tem_kernel, compiled with numba) against the numpy
    reference: observer step, linearising law (roots, vertex, flags, saturation) and the
    predictive command range, on random faces, targets and rates."""
    from sma_wrist.core.control.tem import DriveLimits, observer_step, safe_command_range

    rng = np.random.default_rng(seed)
    x = th.rest_state(P, 1) + rng.uniform(-20.0, 55.0, (1, 2, 2))
    T_d = rng.uniform(0.0, 90.0, (1, 2, 2))
    rate = rng.uniform(-20.0, 20.0, (1, 2, 2))
    u = rng.uniform(P.u_min_V, P.u_max_V, (1, 2))
    for weights in ((1.0, 0.0), (0.7, 0.4)):
        params = tc.TemControlParams(gain_per_s=float(rng.uniform(0.2, 3.0)), weights=weights)
        ref = tc.feedback_linearising_command(P, x, T_d, rate, params, compiled=False)
        got = tc.feedback_linearising_command(P, x, T_d, rate, params, compiled=True)
        for name in ('command_V', 'current', 'face_current'):
            np.testing.assert_allclose(getattr(got, name), getattr(ref, name), rtol=1e-12, atol=1e-12)
        for name in ('no_root', 'saturated'):
            np.testing.assert_array_equal(getattr(got, name), getattr(ref, name))
    np.testing.assert_allclose(
        observer_step(P, x, u, 0.01, compiled=True),
        observer_step(P, x, u, 0.01, compiled=False),
        rtol=1e-13,
        atol=1e-12,
    )
    D = DriveLimits()
    for a, b in zip(safe_command_range(P, D, x, compiled=True), safe_command_range(P, D, x, compiled=False)):
        np.testing.assert_array_equal(a, b)


def test_one_wrist_kernel_rejects_non_finite_inputs_like_the_numpy_path():
    x = th.rest_state(P, 1)
    for compiled in (True, False):
        with pytest.raises(ModelInputError, match='desired temperature'):
            tc.feedback_linearising_command(P, x, [[[np.nan, 30.0]] * 2], 0.0, compiled=compiled)
        bad = x.copy()
        bad[0, 1, 0] = np.inf
        with pytest.raises(ModelInputError, match='thermal state'):
            tc.feedback_linearising_command(P, bad, 40.0, 0.0, compiled=compiled)


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**32 - 1), st.booleans())
def test_tem_loop_compiled_sample_matches_the_numpy_functions(seed, predictive):
    """TemLoop's one-call kernel (observer, rate estimate, law, protection, hot muscle) against
    the numpy functions it fuses, over 300 samples of a loop closed through the heat balance:
    irregular sample times, targets that jump, stale stretches, a muscle above the limit."""
    from sma_wrist.core.control.tem import DriveLimits, TemLoop

    rng = np.random.default_rng(seed)
    drive = DriveLimits(predictive=predictive, protect_above_C=float(rng.uniform(40.0, 75.0)))
    params = tc.TemControlParams(gain_per_s=float(rng.uniform(0.3, 3.0)), rate_filter_s=float(rng.uniform(0.0, 0.2)))
    law_limits = P.with_limits(-24.0, 24.0)
    max_muscle_C = float(rng.uniform(35.0, 70.0))
    loops = [TemLoop(law_limits, params, drive, P, max_muscle_C, compiled=c) for c in (False, True)]
    assert loops[1].compiled and not loops[0].compiled
    x = th.rest_state(P, 1) + rng.uniform(0.0, 45.0, (1, 2, 2))
    t = 0.0
    seen_hot = seen_clip = False
    T_d = np.array([40.0, 35.0])
    for k in range(300):
        t += float(rng.choice([0.01, 0.01, 0.02, 0.003]))
        if rng.random() < 0.05:
            T_d = rng.uniform(20.0, 75.0, 2)
        stale = rng.random() < 0.03
        T_meas = x[0, :, 0] + rng.normal(0.0, 0.05, 2)
        out = [loop.sample(t, T_meas, None if stale else T_d) for loop in loops]
        ref, got = out
        np.testing.assert_allclose(got.command_V, ref.command_V, rtol=1e-9, atol=1e-9)
        np.testing.assert_array_equal(got.hot, ref.hot)
        seen_hot |= bool(ref.hot.any())
        assert (ref.command_V[ref.hot] <= 0.0).all()
        np.testing.assert_array_equal(got.saturated, ref.saturated)
        seen_clip |= bool(ref.saturated.any())
        np.testing.assert_allclose(loops[1].observer, loops[0].observer, rtol=1e-10, atol=1e-9)
        x = th.step(P.with_limits(-24.0, 24.0), x, ref.command_V[None], min(0.02, P.dt_max_s))
        if k == 150 and not seen_hot:  # make sure the hot-muscle rule is exercised: heat past the limit
            x[0, 0, 0] = max_muscle_C + 2.0
            T_d = np.array([max_muscle_C + 10.0, T_d[1]])
    assert seen_hot and seen_clip
    assert loops[0].sample(t, x[0, :, 0], T_d) is None  # a repeated stamp leaves the command


def test_chatter_guard_counts_sign_changes_outside_the_band_and_switches_with_hysteresis():
    """ChatterGuard: a 1.5 Hz square wave of +-10 V (3 sign changes a second) engages a 2.5 /s guard after
    about one window; the same wave inside the +-1 V band, or at 1 change a second, never does; back at
    0.5 changes a second it releases once the rate is below half the limit."""
    dt = 0.01

    def run(guard: tc.ChatterGuard, t0: float, seconds: float, period_s: float, amplitude: float) -> list[float]:
        switched = []
        for k in range(int(round(seconds / dt))):
            t = t0 + k * dt
            u = amplitude * (1.0 if (t // (period_s / 2)) % 2 == 0 else -1.0)
            if guard.update(t, np.array([[u, 0.3]]))[0]:
                switched.append(t)
        return switched

    g = tc.ChatterGuard(1, 2.5, 20.0)
    on = run(g, 0.0, 60.0, 1 / 1.5, 10.0)
    assert len(on) == 1 and 15.0 < on[0] < 40.0 and g.engaged[0], on
    assert 2.8 < g.rate[0, 0] < 3.1 and g.rate[0, 1] == 0.0  # the second TEM stays inside the band
    off = run(g, 60.0, 120.0, 4.0, 10.0)  # 0.5 changes a second
    assert len(off) == 1 and not g.engaged[0], off
    for period, amp in ((1 / 1.5, 0.9), (2.0, 10.0)):  # inside the band; 1 change a second
        quiet = tc.ChatterGuard(1, 2.5, 20.0)
        assert run(quiet, 0.0, 120.0, period, amp) == [] and not quiet.engaged[0]
    with pytest.raises(ParameterError, match='chatter_window_s'):
        tc.TemControlParams(chatter_limit_per_s=2.0, chatter_window_s=0.0)


def test_chatter_guard_one_wrist_path_is_the_array_path():
    """update_one (tem_controller's float path) against update (the sweep's bank) on random commands with runs
    of chattering: the same rates to the bit and the same switches."""
    rng = np.random.default_rng(3)
    a, b = tc.ChatterGuard(1, 1.0, 1.0), tc.ChatterGuard(1, 1.0, 1.0)
    switches = 0
    for k in range(3000):
        t = 0.01 * k
        u = rng.normal(0.0, 8.0, 2) if (k // 500) % 2 else rng.normal(3.0, 1.5, 2)
        changed = a.update(t, u[None])[0]
        assert b.update_one(t, u) == changed
        np.testing.assert_array_equal(a.rate, b.rate)
        np.testing.assert_array_equal(a.sign, b.sign)
        assert a.engaged[0] == b.engaged[0]
        switches += changed
    assert switches >= 3  # engaged, released and engaged again


def test_engaged_chatter_guard_switches_the_rate_filter_in_both_paths():
    """TemLoop with its guard: targets that jump every 0.2 s make the commands swing; once engaged the law's
    rate filter is chatter_rate_filter_s in the compiled and the numpy path alike (the two stay equal)."""
    from sma_wrist.core.control.tem import DriveLimits, TemLoop

    params = tc.TemControlParams(
        gain_per_s=1.0,
        rate_filter_s=0.05,
        target_filter_s=0.0,
        chatter_limit_per_s=1.0,
        chatter_window_s=2.0,
        chatter_rate_filter_s=0.3,
    )
    loops = [TemLoop(P.with_limits(-24.0, 24.0), params, DriveLimits(), P, 85.0, compiled=c) for c in (False, True)]
    x = th.rest_state(P, 1) + 20.0
    engaged_at = None
    for k in range(600):
        t = 0.01 * (k + 1)
        T_d = np.array([60.0, 40.0]) if (k // 20) % 2 == 0 else np.array([40.0, 60.0])
        ref, got = (loop.sample(t, x[0, :, 0], T_d) for loop in loops)
        np.testing.assert_allclose(got.command_V, ref.command_V, rtol=1e-9, atol=1e-9)
        assert loops[0].chattering == loops[1].chattering
        if engaged_at is None and loops[1].chattering:
            engaged_at = t
        x = th.step(P.with_limits(-24.0, 24.0), x, ref.command_V[None], 0.01)
    assert engaged_at is not None and engaged_at < 3.0, engaged_at
    assert loops[1]._cfg[1] == 0.3 and loops[0].law.params.rate_filter_s == 0.3
