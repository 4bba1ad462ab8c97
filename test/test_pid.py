"""Sec. 6.1 PID: term arithmetic, P x error-rate variants, derivative filter/kick, anti-windup, closed loop."""

from __future__ import annotations

import numpy as np
import pytest

from sma_wrist.core.control.pid import PID, PIDParams
from sma_wrist.core.control.trajectory import make_trajectory
from sma_wrist.core.errors import ModelInputError, ParameterError
from sma_wrist.core.metrics import tracking_metrics

DT = 1e-3
WIDE = dict(output_min=-1e9, output_max=1e9)


def test_plain_terms_are_analytic() -> None:
    c = PID(PIDParams(kp=2.0, ki=10.0, kd=0.0, **WIDE))
    outs = [c.update(0.0, 0.1, DT) for _ in range(3)]  # constant error 0.1
    np.testing.assert_allclose([o.p_term[0] for o in outs], 0.2)
    # forward-Euler integral: the output at step k uses sum of the k previous samples
    np.testing.assert_allclose([o.i_term[0] for o in outs], [0.0, 10 * 0.1 * DT, 2 * 10 * 0.1 * DT])
    np.testing.assert_allclose(outs[2].u, 0.2 + 2e-3)


def test_derivative_filter_converges_to_the_slope_with_its_time_constant() -> None:
    tau = 0.05
    c = PID(PIDParams(kp=0.0, ki=0.0, kd=1.0, derivative_filter_s=tau, **WIDE))
    a = 0.3  # q = a t, reference 0: D = -Kd * qdot -> -a
    d = np.array([c.update(a * k * DT, 0.0, DT).d_term[0] for k in range(2000)])
    assert d[0] == 0.0  # no history on the first sample
    # backward-Euler first-order lag on a step of the slope: d_k = -a (1 - (tau/(tau+dt))^k)
    k = np.arange(2000)
    np.testing.assert_allclose(d, -a * (1 - (tau / (tau + DT)) ** k), atol=1e-12)


def test_derivative_on_measurement_has_no_setpoint_kick() -> None:
    for on, kicks in (('measurement', False), ('error', True)):
        c = PID(PIDParams(kp=0.0, ki=0.0, kd=5.0, derivative_on=on, derivative_filter_s=0.01, **WIDE))
        c.update(0.2, 0.2, DT)
        o = c.update(0.2, 0.7, DT)  # reference step of 0.5 rad, q still
        assert bool(abs(o.d_term[0]) > 10.0) is kicks  # np.bool_ is not the bool singleton


@pytest.mark.parametrize(
    'e0,slope,sign_literal,sign_abs',
    [
        (0.1, +1.0, +1, +1),  # e > 0 growing: both push +u
        (0.1, -1.0, -1, +1),  # e > 0 shrinking: literal brakes, |rate| keeps pushing
        (-0.1, -1.0, +1, -1),  # e < 0 growing: literal pushes the WRONG way (+u); |rate| pushes -u
    ],
)
def test_p_times_rate_variants_signs(e0: float, slope: float, sign_literal: int, sign_abs: int) -> None:
    for mode, sign in (('p_times_rate', sign_literal), ('p_times_abs_rate', sign_abs)):
        c = PID(PIDParams(kp=9.0, ki=0.0, kd=0.0, p_mode=mode, derivative_filter_s=0.0, **WIDE))
        c.update(0.0, e0 - slope * DT, DT)
        o = c.update(0.0, e0, DT)  # e = q_d - q with q = 0; edot = slope
        assert o.p_term[0] == pytest.approx(sign * 9.0 * abs(e0 * slope))


def test_p_times_rate_is_zero_for_a_constant_error() -> None:
    c = PID(PIDParams.paper_table_6_1(ki=0.0, kd=0.0, **WIDE))
    assert c.params.p_mode == 'p_times_rate' and c.params.kp == 9.0
    outs = [c.update(0.3, 0.5, DT) for _ in range(5)]
    assert all(o.p_term[0] == 0.0 for o in outs)
    plain = PID(PIDParams(ki=0.0, kd=0.0, **WIDE)).update(0.3, 0.5, DT)
    assert plain.p_term[0] == pytest.approx(9.0 * 0.2)


def windup_recovery(anti_windup: str) -> tuple[float, int]:
    """Hold a large error (P alone beyond the limit) for 2 s against limits +-1, then reverse it; steps until u leaves +1."""
    c = PID(PIDParams(kp=3.0, ki=5.0, kd=0.0, output_min=-1.0, output_max=1.0, anti_windup=anti_windup))
    for _ in range(2000):
        o = c.update(0.0, 0.5, DT)
        assert o.saturated[0] and o.u[0] == 1.0
    peak = float(c.integral[0])
    for k in range(20000):
        if c.update(0.0, -0.5, DT).u[0] < 1.0:
            return peak, k
    return peak, 20000


def test_anti_windup_limits_the_integral_and_speeds_recovery() -> None:
    peak_none, k_none = windup_recovery('none')
    peak_cond, k_cond = windup_recovery('conditional')
    peak_bc, k_bc = windup_recovery('back_calculation')
    assert peak_none == pytest.approx(5.0 * 0.5 * 2.0, rel=1e-3)  # wound up to Ki e T = 5
    assert peak_cond < 1.0  # integration stopped once P + I exceeded the limit
    assert peak_bc < 1.5
    assert k_cond < k_none / 5 and k_bc < k_none / 5


def test_conditional_integration_still_integrates_out_of_saturation() -> None:
    c = PID(PIDParams(kp=10.0, ki=5.0, kd=0.0, output_min=-1.0, output_max=1.0))
    c.update(0.0, 0.5, DT)  # saturated high
    i0 = c.integral[0]
    c.update(0.0, -0.5, DT)  # e < 0 drives away from the upper limit: u = -5 saturates LOW now
    assert c.integral[0] == i0  # low saturation with e < 0 also freezes
    c2 = PID(PIDParams(kp=1.0, ki=5.0, kd=0.0, output_min=-1.0, output_max=1.0))
    for _ in range(3000):
        c2.update(0.0, 0.5, DT)
    i_hi = c2.integral[0]
    c2.update(0.0, 0.4, DT)
    assert c2.integral[0] <= i_hi + 1e-12 or c2.update(0.0, -0.6, DT).u_unsat[0] < 1.0


def test_vectorised_matches_scalar_runs() -> None:
    rng = np.random.default_rng(1)
    q = rng.normal(0.5, 0.1, (200, 3))
    r = rng.normal(0.5, 0.1, (200, 3))
    p = PIDParams(output_min=-0.5, output_max=0.5, p_mode='p_times_abs_rate')
    vec = PID(p, 3)
    singles = [PID(p, 1) for _ in range(3)]
    for k in range(200):
        u = vec.update(q[k], r[k], DT).u
        for j in range(3):
            assert u[j] == singles[j].update(q[k, j], r[k, j], DT).u[0]


def test_closed_loop_on_a_quasi_static_muscle_plant() -> None:
    """tau q' = -q + k u: the angle follows the command through a thermal lag (the SMA joint is
    stiff, so its position is set by temperature, not by Newton's law on the chain force)."""
    tau, k = 5.0, 0.05
    c = PID(PIDParams.paper_table_6_1(p_mode='plain', output_min=-50.0, output_max=50.0))
    t = np.arange(0.0, 2 * 62.832, DT)
    qd = make_trajectory('sine')(t)[0]
    q = 0.524
    qs = np.empty_like(t)
    for i in range(t.size):
        o = c.update(q, qd[i], DT)
        qs[i] = q
        q += DT * (-q + k * o.u[0]) / tau
    m = tracking_metrics(t, qs, qd)
    assert m.max_abs_error_rad == pytest.approx(np.abs(qs - qd).max())
    last = np.abs(qs - qd)[t > 62.832]
    assert last.max() / 1.048 * 100 < 3.0  # < 3 % of range in the second cycle
    assert 5e4 < m.total_abs_error_pct < 1.2e5  # the Table 6.2 order of magnitude


@pytest.mark.parametrize(
    'kw,fragment',
    [
        ({'kp': -1.0}, 'kp'),
        ({'ki': float('nan')}, 'ki'),
        ({'p_mode': 'pd'}, 'p_mode'),
        ({'derivative_on': 'both'}, 'derivative_on'),
        ({'anti_windup': 'clamp'}, 'anti_windup'),
        ({'derivative_filter_s': -0.1}, 'derivative_filter_s'),
        ({'tracking_time_s': 0.0}, 'tracking_time_s'),
        ({'output_min': 1.0, 'output_max': 1.0}, 'output_min'),
    ],
)
def test_bad_parameters(kw: dict, fragment: str) -> None:
    with pytest.raises(ParameterError, match=fragment):
        PIDParams(**kw)


def test_bad_inputs() -> None:
    c = PID(n=2)
    with pytest.raises(ModelInputError, match='q = nan'):
        c.update([0.1, np.nan], 0.0, DT)
    with pytest.raises(ModelInputError, match='dt'):
        c.update(0.1, 0.0, 0.0)
    with pytest.raises(ModelInputError, match='broadcastable'):
        c.update(np.zeros(3), 0.0, DT)


class _NumpyPID:
    """The law as vectorised numpy (the implementation before pid_kernel), the test's oracle."""

    def __init__(self, p: PIDParams, n: int) -> None:
        self.p, self.n = p, n
        self.integral = np.zeros(n)
        self.e_prev = self.y_prev = None
        self.edot, self.ydot = np.zeros(n), np.zeros(n)

    def _rate(self, x, prev, d, dt):
        if prev is None:
            return np.zeros(self.n)
        tau = self.p.derivative_filter_s
        return (tau * d + (x - prev)) / (tau + dt)

    def update(self, q, q_d, dt):
        p = self.p
        y = np.broadcast_to(np.asarray(q, float), (self.n,)).copy()
        r = np.broadcast_to(np.asarray(q_d, float), (self.n,))
        e = r - y
        self.edot = self._rate(e, self.e_prev, self.edot, dt)
        self.ydot = self._rate(y, self.y_prev, self.ydot, dt)
        self.e_prev, self.y_prev = e, y
        P = {'plain': p.kp * e, 'p_times_rate': p.kp * e * self.edot, 'p_times_abs_rate': p.kp * e * np.abs(self.edot)}[
            p.p_mode
        ]
        D = -p.kd * self.ydot if p.derivative_on == 'measurement' else p.kd * self.edot
        I = self.integral.copy()
        u = P + I + D
        u_out = np.clip(u, p.output_min, p.output_max)
        di = p.ki * e * dt
        if p.anti_windup == 'conditional':
            di = np.where(((u > p.output_max) & (di > 0)) | ((u < p.output_min) & (di < 0)), 0.0, di)
        elif p.anti_windup == 'back_calculation':
            di = di + (u_out - u) * dt / p.tracking_time_s
        self.integral = I + di
        return dict(u=u_out, u_unsat=u, saturated=u != u_out, error=e, p_term=P, i_term=I, d_term=D)


@pytest.mark.parametrize('p_mode', ['plain', 'p_times_rate', 'p_times_abs_rate'])
@pytest.mark.parametrize('derivative_on', ['measurement', 'error'])
@pytest.mark.parametrize('anti_windup', ['conditional', 'back_calculation', 'none'])
def test_kernel_is_the_numpy_law_bit_for_bit(p_mode, derivative_on, anti_windup) -> None:
    """pid_kernel's loop against the vectorised numpy law, every output to the bit, for every
    option, one wrist and three, through saturation (tight limits) and irregular steps."""
    rng = np.random.default_rng(7)
    p = PIDParams(
        kp=2.0,
        ki=5.0,
        kd=0.01,
        p_mode=p_mode,
        derivative_on=derivative_on,
        anti_windup=anti_windup,
        output_min=-0.6,
        output_max=0.4,
        derivative_filter_s=0.05,
    )
    for n in (1, 3):
        got, ref = PID(p, n), _NumpyPID(p, n)
        saturated = 0
        for k in range(400):
            q, q_d = rng.normal(0.5, 0.2, n), 0.5 + 0.3 * np.sin(0.05 * k) + np.zeros(n)
            dt = float(rng.choice([1e-3, 1e-2, 3e-3]))
            if n == 1:
                q, q_d = float(q[0]), float(q_d[0])
            o, want = got.update(q, q_d, dt), ref.update(q, q_d, dt)
            for name, value in want.items():
                assert np.array_equal(getattr(o, name), value), (name, k)
            saturated += int(o.saturated.any())
        assert np.array_equal(got.integral, ref.integral)
        assert 0 < saturated < 400
