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
    """The diagnosis's synthetic runs and its replays (25 s of CPU on a cold cache, measured on a loaded machine:
    the SD-GPI replay compiled once; it was 52 s while a read-only joint row compiled it a second time)."""
    from sma_wrist.diagnose import diagnose_run
    from sma_wrist.diagnose.testdata import run_from_truth, simulate

    diagnose_run(run_from_truth(simulate('none', seed=0, duration_s=4.0)), candidates=['backlash', 'tem_mismatch'])


def model_wires() -> None:
    """The diagnosis's replay of a phase-fraction wire, which commissioning fits on every device (~13 s of CPU to
    compile; this part 26 s on a cold cache, measured on a loaded machine), the Peltier heat balance's
    simulation it fits beside it, and the TEM loop's online estimate of the heat balance."""
    from sma_wrist.core.hysteresis.phase_fraction import PhaseFractionWire
    from sma_wrist.core.plant.wrist import PlantParams, WristPlant
    from sma_wrist.core.thermal import heat_balance as th
    from sma_wrist.core.thermal import identification as ti
    from sma_wrist.core.thermal import peltier as pe
    from sma_wrist.core.thermal import peltier_fit as pf
    from sma_wrist.core.thermal.online import ThermalScaleEstimator
    from sma_wrist.diagnose import effects as fx
    from sma_wrist.diagnose.data import Run

    n = 40
    T = np.column_stack([np.linspace(25.0, 80.0, n), np.full(n, 25.0)])
    run = Run(t=0.05 * np.arange(n), dt=0.05, u=None, T=T, q=np.zeros(n), payload_kg=0.3)
    fx.ExtendedModel(run, PlantParams(dt=0.01, wire=PhaseFractionWire())).angle_measured(fx.NOMINAL[None])
    WristPlant(PlantParams(wire=PhaseFractionWire())).advance(np.zeros((1, 2)), 5)  # the plant's phase-fraction step
    pf.simulate_records(pe.PeltierParams(), [ti.ThermalRecord('warm', 0.25, np.full(n, 5.0), T, 0.0, layer=0)])
    est = ThermalScaleEstimator(th.ThermalParams(), 1)
    for k in range(400):
        est.sample(0.01 * k, np.array([[30.0 + 0.01 * k, 28.0]]), np.array([[5.0, -5.0]]))


PARTS = {'closed_loops': closed_loops, 'replays': replays, 'model_wires': model_wires}

if __name__ == '__main__':
    PARTS[sys.argv[1]]()
