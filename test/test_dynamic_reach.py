"""The dynamic-reach schedules (sma_wrist.plants.dynamic_reach): the oracle thermostat reaches its
targets and moves the joint the way the targets say, the search keeps the best candidate, bad input is refused."""

from __future__ import annotations

import numpy as np
import pytest

import sma_wrist.plants.dynamic_reach as dr
from sma_wrist.core.errors import ParameterError


def test_thermostat_holds_the_targets_and_the_hot_muscle_wins() -> None:
    # constant targets (no slope, no hysteresis offset): muscle 1 hot / muscle 2 cold and the reverse
    up = [70.0, 0.0, 0.0, 20.0, 30.0, 0.0, 0.0, 20.0, 0.0]
    down = [30.0, 0.0, 0.0, 20.0, 70.0, 0.0, 0.0, 20.0, 0.0]
    t, q_d, q, T = dr.run_schedules(np.array([up, down]), 0.3, duration_s=30.0)
    assert t.shape == q_d.shape == q[:, 0].shape and T.shape == (t.size, 2, 2)
    # heated at the rating (~2.3 degC/s) the hot targets are held to within the thermostat's band
    assert T[-1, 0, 0] == pytest.approx(70.0, abs=1.0) and T[-1, 1, 1] == pytest.approx(70.0, abs=1.0)
    assert T[-1, 0, 1] < 45.0 and T[-1, 1, 0] < 45.0  # the cold ones cool (slowly on this Peltier)
    assert q[-1, 0] > 0.9 and q[-1, 1] < 0.1  # muscle 1 raises the joint, muscle 2 lowers it


def test_search_keeps_the_start_and_the_best_candidate(monkeypatch: pytest.MonkeyPatch) -> None:
    goal = dr.HAND_TIMED + 0.4 * dr.SPREAD
    seen = []

    def fake(cand: np.ndarray, *args: object) -> tuple[np.ndarray, np.ndarray]:
        seen.append(cand.copy())
        err = np.abs(cand - goal).sum(axis=1)
        return err, err / 2

    monkeypatch.setattr(dr, 'schedule_errors', fake)
    r = dr.search(n=16, rounds=3, seed=4)
    assert np.array_equal(seen[0][0], dr.HAND_TIMED)  # the start is always among the candidates
    everything = np.concatenate(seen)
    errors = np.abs(everything - goal).sum(axis=1)
    assert r.max_error_pct == pytest.approx(errors.min()) and r.evaluated == 48
    assert np.array_equal(r.schedule, everything[np.argmin(errors)])
    assert (everything[:, 8] >= 0).all()  # leads only


@pytest.mark.parametrize('bad', [np.zeros((2, 8)), np.full((1, 9), np.nan)])
def test_bad_schedules_are_refused(bad: np.ndarray) -> None:
    with pytest.raises(ParameterError, match='schedules must be finite'):
        dr.run_schedules(bad)


def test_errors_need_a_whole_cycle_and_search_needs_candidates() -> None:
    with pytest.raises(ParameterError, match='one reference cycle'):
        dr.schedule_errors(dr.HAND_TIMED, duration_s=30.0)
    with pytest.raises(ParameterError, match='must be >= 1'):
        dr.search(n=0)
