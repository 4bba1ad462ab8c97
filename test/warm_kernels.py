"""Compile the package's numba kernels before the test workers start (``python test/warm_kernels.py PART``).

Under ``pytest -n 2`` both workers compile the kernels they meet on a cold cache at the same time, so each
kernel is compiled twice. conftest.py runs the parts below side by side once, before the workers start,
and the workers then load the cache. Each part drives the public entry points on tiny inputs; a kernel a
part misses is compiled by the first test that needs it, as before. Nothing here is asserted.
"""

from __future__ import annotations

import sys

import numpy as np


def closed_loops() -> None:
    """The sweep engine on both plants in every mode, plant_sim's plant, the node laws' own kernels, the
    identification's Jacobian and solver."""
    from sma_wrist.core.control import adaptive_kernel, pid, tem_kernel
    from sma_wrist.core.control.joint_controller import JointController
    from sma_wrist.core.hysteresis.identification import simulate_jac
    from sma_wrist.core.hysteresis.trf import trf_solve
    from sma_wrist.core.plant.wrist import WristPlant
    from sma_wrist.sweep.simulate import simulate

    simulate(_cases(), 0.05)
    simulate(_cases(), 0.05, plant='phase_fraction')
    WristPlant().advance(np.zeros((1, 2)), 5)
    WristPlant().advance_segments(np.zeros((2, 1, 2)), np.array([5, 5]))  # the twin monitor's batches
    tem_kernel.warm_up()
    adaptive_kernel.warm_up()
    pid.warm_up()
    c = JointController()
    for k in range(3):
        c.update(0.5, 0.0, 0.5 + 0.01 * k, 0.01, 0.0, 0.01)
    T = np.linspace(30.0, 80.0, 20)
    simulate_jac(np.concatenate([T, T[::-1]]), np.full(20, 0.1), n=3)
    trf_solve(lambda x: (x - 1.0, np.eye(2)), np.zeros(2), np.full(2, -5.0), np.full(2, 5.0), 5)


def _cases() -> list:
    from sma_wrist.plants.spread import Scenario
    from sma_wrist.sweep.simulate import Case

    noisy = dict(temp_lag_s=0.2, temp_noise_C=0.2, angle_noise_rad=0.003)
    return [
        Case(0, 'inverse_adaptive', Scenario(payload_kg=0.3)),
        Case(1, 'direct_adaptive', Scenario(payload_kg=0.3, transition_shift_C=-3.0, stroke_scale=1.1, **noisy)),
        Case(2, 'pid', Scenario(payload_kg=0.3, tem_gain_scale=0.9, **noisy)),
    ]


def replays() -> None:
    """The diagnosis's synthetic runs and its replays (as much CPU as the other part, measured on a cold cache:
    the two run side by side)."""
    from sma_wrist.diagnose import diagnose_run
    from sma_wrist.diagnose.testdata import run_from_truth, simulate

    diagnose_run(run_from_truth(simulate('none', seed=0, duration_s=4.0)), candidates=['backlash', 'tem_mismatch'])


PARTS = {'closed_loops': closed_loops, 'replays': replays}

if __name__ == '__main__':
    PARTS[sys.argv[1]]()
