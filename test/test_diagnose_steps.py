"""The steps of the measured angle that the model's replay does not make (sma_wrist/diagnose/steps.py): found with
their time and size, one per event, never in a fast but smooth motion the replay makes too, never in noise."""

from __future__ import annotations

import numpy as np
import pytest

from sma_wrist.diagnose import steps as st

DT = 0.01


def _motion(seconds: float = 60.0, speed: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """A sine of the angle the replay makes as well (``speed`` scales how fast)."""
    t = np.arange(0.0, seconds, DT)
    return t, 0.5 + 0.5 * np.sin(2 * np.pi * speed * t / 20.0)


def test_a_jump_the_replay_does_not_make_is_found_once_with_its_time_and_size():
    t, model = _motion()
    q = model + 0.2 * (t >= 30.0)
    found = st.angle_steps(t, q, model, noise_rad=1e-3)
    assert len(found) == 1
    s = found[0]
    assert s['step_rad'] == pytest.approx(0.2, abs=0.02) and 29.9 <= s['t_s'] <= 30.0
    assert s['model_max_rad'] == pytest.approx(np.max(np.abs(model[10:] - model[:-10])))
    text = st.describe(found)
    assert '0.2 rad at 29.9 s' in text or '0.2 rad at 30.0 s' in text


def test_a_fast_motion_the_replay_makes_too_is_no_step():
    t, model = _motion(speed=8.0)  # 8x faster: 0.13 rad in 0.1 s, made by the model as well
    rng = np.random.default_rng(1)
    q = model + rng.normal(0.0, 1e-3, t.size)
    assert st.angle_steps(t, q, model, noise_rad=1e-3) == []
    # the same motion 3x faster than the replay: beyond the ratio, a step
    assert st.angle_steps(t, np.interp(3 * t, t, model, period=20.0 / 8.0), model, noise_rad=1e-3)


def test_noise_alone_and_a_still_replay_are_no_step():
    # a replay that does not move: the measured noise must still be NOISE_RATIO times beyond the noise
    t = np.arange(0.0, 30.0, DT)
    rng = np.random.default_rng(2)
    q = 0.3 + rng.normal(0.0, 1e-3, t.size)
    assert st.angle_steps(t, q, np.full(t.size, 0.3), noise_rad=1e-3) == []


def test_steps_apart_are_each_named_largest_first_and_a_window_without_a_measurement_is_skipped():
    t, model = _motion()
    q = model + 0.1 * (t >= 20.0) + 0.3 * (t >= 40.0)
    found = st.angle_steps(t, q, model, noise_rad=1e-3)
    assert [round(s['step_rad'], 1) for s in found] == [0.3, 0.1]
    valid = np.ones(t.size, bool)
    valid[(t > 39.95) & (t < 40.05)] = False  # the jump falls in a gap the run bridged
    assert [round(s['step_rad'], 1) for s in st.angle_steps(t, q, model, 1e-3, valid)] == [0.1]
    assert st.describe([]) == ''


def test_a_step_restarts_the_replay_where_the_angle_went_farthest_then_where_it_settled():
    # a snap: up 0.2 rad within 0.05 s, overshooting by 0.012 rad, settling in 0.1 s (noisy readings)
    t, model = _motion()
    rng = np.random.default_rng(4)
    jump = np.clip((t - 30.0) / 0.05, 0.0, 1.0) * 0.2 + 0.012 * ((t >= 30.05) & (t < 30.1))
    q = model + jump + rng.normal(0.0, 1e-3, t.size)
    found = st.angle_steps(t, q, model, noise_rad=1e-3)
    assert len(found) == 1 and found[0]['start_s'] <= found[0]['t_s'] < found[0]['end_s'] <= 30.2
    idx, ang = st.restarts(t, q, found)
    assert len(idx) == 2 and idx[0] < idx[1]
    # first the farthest reading of the step, in its direction (the overshoot) ...
    assert 30.05 <= t[idx[0]] < 30.1 and ang[0] == q[idx[0]] == np.max(q[: idx[1] + 1][t[: idx[1] + 1] >= 29.9])
    # ... then the median of the readings from RESTART_AFTER_S past the step, at the middle one
    assert t[idx[1]] == pytest.approx(found[0]['end_s'] + st.RESTART_AFTER_S + st.RESTART_MEDIAN_S / 2, abs=DT)
    assert ang[1] == pytest.approx(model[idx[1]] + 0.2, abs=2e-3)
    # a step downwards restarts at its lowest reading
    idx_d, ang_d = st.restarts(t, -q, st.angle_steps(t, -q, -model, noise_rad=1e-3))
    assert idx_d == idx and ang_d[0] == -ang[0]
    # the event's samples, from its first window to the restart, are the ones not scored
    ev = st.event_samples(t, found)
    assert (
        ev[(t >= found[0]['start_s']) & (t <= t[idx[1]])].all()
        and ev.sum() == ((t >= found[0]['start_s']) & (t <= t[idx[1]] + 1e-9)).sum()
    )


def test_a_step_at_the_end_of_the_run_gets_no_restart():
    t, model = _motion(seconds=40.0)
    q = model + 0.2 * (t >= 39.9)
    found = st.angle_steps(t, q, model, noise_rad=1e-3)
    assert found and st.restarts(t, q, found) == ([], [])
