"""Tracking metrics: analytic values on known signals, the Table 6.2 total, typed errors."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sma_wrist.core import metrics as mt
from sma_wrist.core.errors import ModelInputError, ParameterError

W = 0.1
P = 2 * math.pi / W  # 62.83 s


def seed_ref(t: np.ndarray) -> np.ndarray:
    return 0.524 + 0.524 * np.sin(W * t)


def test_constant_error_gives_known_numbers() -> None:
    t = np.arange(0, 2 * P, 0.01)
    c = 0.01048  # 1 % of the 1.048 rad range
    m = mt.tracking_metrics(t, seed_ref(t) + c, seed_ref(t))
    rng = seed_ref(t).max() - seed_ref(t).min()
    assert m.reference_range_rad == pytest.approx(rng)
    assert m.max_abs_error_rad == pytest.approx(c)
    assert m.max_error_pct == pytest.approx(100 * c / rng)
    assert m.rms_error_pct == pytest.approx(100 * c / rng)
    assert m.mean_abs_error_rad == pytest.approx(c)
    # Table 6.2 definition: sum of per-sample % over one cycle resampled at 1 kHz = 62,832 samples
    n = round(P * 1000)
    assert n == 62832
    assert m.total_abs_error_pct == pytest.approx(n * 100 * c / rng, rel=1e-12)
    assert m.total_abs_error_pct == pytest.approx(62832 * 1.0, rel=2e-3)  # ~1 % each sample


def test_total_is_independent_of_the_record_rate_but_not_of_total_rate() -> None:
    c = 0.005
    t1 = np.arange(0, 1.2 * P, 0.001)
    t2 = np.arange(0, 1.2 * P, 0.05)
    m1 = mt.tracking_metrics(t1, seed_ref(t1) - c, seed_ref(t1), reference_range_rad=1.048)
    m2 = mt.tracking_metrics(t2, seed_ref(t2) - c, seed_ref(t2), reference_range_rad=1.048)
    assert m1.total_abs_error_pct == pytest.approx(m2.total_abs_error_pct, rel=1e-12)
    m3 = mt.tracking_metrics(t2, seed_ref(t2) - c, seed_ref(t2), reference_range_rad=1.048, total_rate_hz=100.0)
    assert m3.total_abs_error_pct == pytest.approx(m1.total_abs_error_pct / 10, rel=1e-3)


def test_sine_error_rms_and_mean_are_analytic() -> None:
    # e = A sin(3 w t) over whole periods: RMS A / sqrt 2, mean |e| 2 A / pi, max A
    t = np.linspace(0, P, 200001)
    A = 0.05
    qd = seed_ref(t)
    m = mt.tracking_metrics(t, qd + A * np.sin(3 * W * t), qd)
    assert m.max_abs_error_rad == pytest.approx(A, rel=1e-6)
    assert m.rms_error_rad == pytest.approx(A / math.sqrt(2), rel=1e-4)
    assert m.mean_abs_error_rad == pytest.approx(2 * A / math.pi, rel=1e-4)
    # total over the cycle = 1000 samples/s x P x mean %
    assert m.total_abs_error_pct == pytest.approx(62832 * 100 * (2 * A / math.pi) / 1.048, rel=1e-3)


def test_seed_table_6_2_scale_is_a_1khz_sum() -> None:
    # a mean error of 1.5 % over one 62.8 s cycle gives ~94,000 %, the Table 6.2 magnitude
    t = np.arange(0, P + 1, 0.001)
    qd = seed_ref(t)
    m = mt.tracking_metrics(t, qd + 0.015 * 1.048, qd)
    assert 93_000 < m.total_abs_error_pct < 95_000


def test_cycle_choice_first_vs_last() -> None:
    t = np.arange(0, 2 * P, 0.01)
    qd = seed_ref(t)
    e = np.where(t < P, 0.02, 0.01)  # transient in the first cycle
    first = mt.tracking_metrics(t, qd + e, qd, cycle='first')
    last = mt.tracking_metrics(t, qd + e, qd)
    assert first.cycle_start_s == 0.0
    assert last.cycle_start_s == pytest.approx(t[-1] - P)
    assert first.total_abs_error_pct > 1.9 * last.total_abs_error_pct


def test_short_record_has_no_total_and_to_dict() -> None:
    t = np.linspace(0, 10, 11)
    m = mt.tracking_metrics(t, seed_ref(t) + 0.01, seed_ref(t))
    assert m.total_abs_error_pct is None and m.cycle_period_s is None
    d = m.to_dict()
    assert d['total_abs_error_pct'] is None and d['n_samples'] == 11
    with pytest.raises(AttributeError):
        m.max_error_pct = 0.0  # type: ignore[misc]


@pytest.mark.parametrize(
    't,q,qd,fragment',
    [
        ([], [], [], 'len(t)'),
        ([0, 1, 2], [0, np.nan, 0], [0, 1, 2], 'q = nan'),
        ([0, 1, 2], [0, 1, 2], [0, 1, np.inf], 'q_d = inf'),
        ([0, 2, 1], [0, 1, 2], [0, 1, 2], 't[2] - t[1] = -1.0'),
        ([0, 1, 1], [0, 1, 2], [0, 1, 2], 't[2] - t[1] = 0.0'),
        ([0, 1, 2], [0, 1], [0, 1, 2], 'len(q)'),
        ([0, 1, 2], [0, 1, 2], [1, 1, 1], 'max(q_d) - min(q_d)'),
    ],
)
def test_bad_inputs_raise_typed_errors(t: list, q: list, qd: list, fragment: str) -> None:
    with pytest.raises(ModelInputError) as ei:
        mt.tracking_metrics(t, q, qd)
    assert fragment in str(ei.value)


def test_bad_options_raise_parameter_errors() -> None:
    t = np.arange(5.0)
    with pytest.raises(ParameterError, match='cycle'):
        mt.tracking_metrics(t, t, t, cycle='middle')  # type: ignore[arg-type]
    with pytest.raises(ParameterError, match='total_rate_hz'):
        mt.tracking_metrics(t, t, t, total_rate_hz=0.0)
    with pytest.raises(ParameterError, match='reference_range_rad'):
        mt.tracking_metrics(t, t, t, reference_range_rad=-1.0)
    # a constant reference is fine with an explicit range
    m = mt.tracking_metrics(t, t * 0 + 0.5 + 0.0105, t * 0 + 0.5, reference_range_rad=1.05)
    assert m.max_error_pct == pytest.approx(1.0)


def test_seed_claims_are_checked_against_the_rows_not_asserted():
    from sma_wrist.experiment import seed_claims

    rows = [
        dict(controller=c, payload_kg=m, total_abs_error_pct=t, max_error_pct=x)
        for c, m, t, x in (
            ('inverse_adaptive', 0.1, 5.0, 2.0),
            ('pid', 0.1, 9.0, 9.0),
            ('inverse_adaptive', 0.2, 7.0, 3.0),
            ('pid', 0.2, 6.0, 8.5),
            ('inverse_adaptive', 0.3, 8.0, 3.5),
            ('pid', 0.3, 10.0, 11.0),
        )
    ]
    claims = seed_claims(rows)
    assert 'inverse_adaptive has the lowest total absolute error. Here: at 2 of 3 loads -- differs.' in claims[0]
    assert 'pid has the highest total absolute error. Here: at 2 of 3 loads -- differs.' in claims[1]
    assert claims[2].endswith('-- differs.')  # 9 -> 6 -> 10 does not grow
    assert claims[3] == 'Seed: max errors 8.4-10.4 %. Here: inverse_adaptive 2.00-3.50 %; pid 8.50-11.00 %.'
    rows[3]['total_abs_error_pct'] = 9.5
    assert seed_claims(rows)[2].endswith('-- agrees.')


def test_a_run_whose_reference_does_not_move_reads_on_the_seed_sines_scale() -> None:
    """run_metrics of a set-point run (trajectory_generator shape: constant): `sma-wrist run` and `compare` failed
    after the whole run with "max(q_d) - min(q_d) = 0.0 rad is outside the valid range"; the % are now of the
    Sec. 6.1 sine's 1.048 rad and say so, and a moving reference keeps its own range."""
    from sma_wrist.runs import RunData, run_metrics

    t = np.arange(0.0, 5.0, 0.01)
    still = RunData(
        'b', t, np.full(t.size, 0.3), np.full(t.size, 0.5), np.zeros((t.size, 2)), t, np.zeros((t.size, 2)), 0.3
    )
    m = run_metrics(still)
    assert m['max_error_pct'] == pytest.approx(100 * 0.2 / 1.048) and m['range_of'].startswith('the Sec. 6.1 sine')
    moving = RunData('b', t, np.full(t.size, 0.3), 0.5 + 0.1 * t, np.zeros((t.size, 2)), t, np.zeros((t.size, 2)), 0.3)
    m = run_metrics(moving)
    assert m['range_of'] == 'the reference' and m['reference_range_rad'] == pytest.approx(0.1 * t[-1])
