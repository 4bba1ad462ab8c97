"""The diagnosis' compiled mechanics replay against its own source run as Python (its loops interpreted, the
inlined helpers called as functions: the structure of the path without numba), and a batch of scenarios
against the same scenarios one by one."""

from __future__ import annotations

import numpy as np
import pytest

from sma_wrist.core import jit
from sma_wrist.diagnose import kernels

K, DT = 200, 0.01


def _inputs(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Muscle temperatures (K, n, 2) through heating and cooling (with a reversal, so the hysteresis
    memory and the branch switches are exercised) and joint rows with different friction, pre-load and payload."""
    t = np.arange(K) * DT
    rng = np.random.default_rng(3)
    T = np.empty((K, n, 2))
    for j in range(n):
        T[:, j, 0] = 45.0 + 30.0 * np.sin(2.0 * t + 0.3 * j) + rng.normal(0.0, 0.05, K)
        T[:, j, 1] = 45.0 - 30.0 * np.sin(2.0 * t + 0.3 * j) + rng.normal(0.0, 0.05, K)
    jrow = np.repeat(kernels.Constants().joint_row[None], n, axis=0)
    jrow[:, 0] *= np.linspace(0.5, 2.0, n)  # coulomb
    jrow[:, 3] += np.linspace(-0.2, 0.2, n)  # pre-load [mm]
    jrow[:, 4] = np.linspace(0.1, 0.6, n)  # payload [kg]
    return T, jrow


def _replay(
    fn, T: np.ndarray, jrow: np.ndarray, substeps: int, resync: np.ndarray | None = None
) -> tuple[np.ndarray, ...]:
    c = kernels.Constants()
    k, n = T.shape[:2]
    q, qd, load = np.empty((k, n)), np.empty((k, n)), np.empty((k, n, 2))
    resync = np.full(k, np.nan) if resync is None else resync
    fn(T, DT, substeps, jrow, c.stacked, c.edges, c.r, c.p, c.mem_c, c.mem_d, c.mech, c.joint, resync, q, qd, load)
    return q, qd, load


@pytest.mark.parametrize('substeps', [1, 2])
def test_compiled_mechanics_replay_agrees_with_its_plain_python_source(substeps):
    T, jrow = _inputs(2)
    compiled = _replay(kernels.mechanics_sim, T, jrow, substeps)
    plain = _replay(kernels.mechanics_sim.py_func, T, jrow, substeps)
    assert np.ptp(compiled[0]) > 0.05  # the joint moves (rad)
    for a, b in zip(compiled, plain):
        # same operations; only libm's and LLVM's tanh may differ in the last bit
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12)
    if not jit.AVAILABLE:
        assert kernels.mechanics_sim.py_func is kernels.mechanics_sim


def test_a_batch_of_scenarios_replays_each_scenario_bit_for_bit():
    """The kernel's scratch (memory, loads, envelope coefficients) is reused across scenarios and sides:
    nothing of one scenario may leak into the next."""
    T, jrow = _inputs(4)
    batch = _replay(kernels.mechanics_sim, T, jrow, 1)
    for j in (3, 1):
        alone = _replay(kernels.mechanics_sim, np.ascontiguousarray(T[:, j : j + 1]), jrow[j : j + 1], 1)
        for a, b in zip(batch, alone):
            assert np.array_equal(a[:, j], b[:, 0])


@pytest.mark.parametrize('j', [0, 2])
def test_mechanics_replay_is_the_plants_own_step(j):
    """The replay of prescribed temperatures is WristPlant.step_mechanics (the numpy path) from the plant's rest
    state, with this scenario's friction, pre-load and payload: the two bundles' loads solved together in the kernel
    are the plant's bundle-by-bundle solve."""
    from dataclasses import replace

    from sma_wrist.core.plant.wrist import PlantParams, WristPlant

    T, jrow = _inputs(3)
    base = PlantParams(dt=DT, engine='numpy')
    jp = replace(base.joint, coulomb_Nm=jrow[j, 0], viscous_Nms=jrow[j, 1], static_Nm=jrow[j, 2])
    plant = WristPlant(replace(base, joint=jp, preload_elongation_mm=jrow[j, 3]), payload_kg=jrow[j, 4])
    T = T[:, j : j + 1].copy()
    T[0, 0] = plant.state.T_prev  # the replay starts where the plant rests (cooled from hot, static equilibrium)
    q, qd, load = _replay(kernels.mechanics_sim, T, jrow[j : j + 1], 1)
    ref = np.empty((K, 3))
    ref[0] = plant.state.q[0], plant.state.qd[0], 0.0
    for k in range(1, K):
        s = plant.step_mechanics(T[k])
        ref[k] = s.q[0], s.qd[0], s.load_kgf[0]
    assert np.ptp(q[:, 0]) > 0.05  # the joint moves (rad)
    np.testing.assert_allclose(q[:, 0], ref[:, 0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(qd[:, 0], ref[:, 1], rtol=0, atol=1e-12)
    np.testing.assert_allclose(load[1:, 0, 0], ref[1:, 2], rtol=1e-12, atol=0)


@pytest.mark.parametrize('wire', ['sd-gpi', 'phase-fraction'])
def test_a_restart_sets_the_angle_at_rest_and_the_replay_goes_on_from_there(wire):
    """Restart angles (a replay restarted after a step of the measured angle): none at all is the free replay to the
    bit; up to the restart the replay is the free one, at it the angle is the given one with the joint at rest, and
    after it the replay moves on from there (towards its equilibrium, from the new angle)."""
    from sma_wrist.core.hysteresis.phase_fraction import PhaseFractionWire

    T, jrow = _inputs(1)
    c = kernels.Constants() if wire == 'sd-gpi' else kernels.Constants().with_wire(PhaseFractionWire())
    free = c.mechanics(T, DT, jrow, 1)
    assert all(np.array_equal(a, b) for a, b in zip(free, c.mechanics(T, DT, jrow, 1, np.full(K, np.nan))))
    k = 120
    target = free[0][k, 0] + 0.1
    resync = np.full(K, np.nan)
    resync[k] = target
    q, qd, _ = c.mechanics(T, DT, jrow, 1, resync)
    assert np.array_equal(q[:k], free[0][:k])
    assert q[k, 0] == target and qd[k, 0] == 0.0
    assert abs(q[k + 1, 0] - target) < abs(free[0][k + 1, 0] - target) - 0.05
    with pytest.raises(ValueError, match='restart angles for 10 samples'):
        c.mechanics(T, DT, jrow, 1, np.full(10, np.nan))
