"""The model's second wire family, the phase-fraction wire (sma_wrist/core/hysteresis/phase_fraction.py): its compiled
kernel against the numpy reference, its minor loops, its fit from the angle alone (own model), the rule that hands it
over, and the ``wire_file`` that carries it to plant_sim and the diagnosis."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from sma_wrist.commission.identification import builtin_transitions, choose_model_wire, fit_phase_fraction_wire
from sma_wrist.core.errors import ParameterError
from sma_wrist.core.hysteresis import phase_fraction as pf
from sma_wrist.core.hysteresis import phase_fraction_kernel as pk
from sma_wrist.core.hysteresis.default_params import default_sdgpi
from sma_wrist.core.hysteresis.wire_file import load_wire_file, save_wire_file
from sma_wrist.core.plant.wrist import PlantParams

AREA = math.pi * 0.25 * 0.25e-3**2
DT = 0.05


def _histories(n: int, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Temperatures and bundle elongations (k, n) that reverse inside the transformations (minor loops)."""
    t = np.arange(k)[:, None] * DT
    T = 45.0 + 35.0 * np.sin(2 * np.pi * t / (10.0 + 2.0 * np.arange(n))) + 3.0 * np.sin(2 * np.pi * t / 3.3)
    y = np.broadcast_to(1.2 + 0.5 * np.sin(2 * np.pi * t / 7.0), T.shape).copy()
    return T, y


@pytest.mark.parametrize('law', pf.LAWS)
def test_the_compiled_load_solve_is_the_numpy_reference(law):
    muscle = pf.PhaseFractionMuscle(pf.PhaseFractionWire(law=law), 83.0, AREA, 3.0)
    T, y = _histories(5, 1000)
    mem = pf.cooled_memory(muscle.wc, T[0], np.full(5, 0.8))
    mem_k, m, m_k = mem.copy(), np.full(5, 0.8), np.full(5, 0.8)
    out = np.empty((5, 3))
    seen = set()
    for k in range(T.shape[0]):
        s = muscle.solve_load(T[k], y[k], mem, m)
        pk.solve_and_commit(muscle.wc, T[k], y[k], mem_k, m_k, 3.0, 1e-7, 60, out)
        mem, m, m_k = s.memory, s.load_kgf, out[:, 0].copy()
        assert np.array_equal(m, m_k) and np.array_equal(mem, mem_k)
        assert np.array_equal(s.compliance_mm_per_kgf, out[:, 1])
        seen.update(np.round(mem[:, pf.XI], 1))
    assert min(seen) <= 0.3 and max(seen) >= 0.9  # the histories go through the transformations


def test_the_published_law_is_brinsons_cosine_detwinning_and_voigt_modulus():
    """Eq. 4b against Eq. 4 at one state: the elastic strain sigma / (E_A + xi (E_M - E_A)) and the oriented share
    (1 - cos(pi u)) / 2, written out here from Brinson 1993; and the slope the load solve uses is the strain's."""
    w = pf.PhaseFractionWire(law='brinson')
    wc = w.packed(83.0, AREA)
    T, m = np.array([58.0]), np.array([0.75])
    mem = pf.cooled_memory(wc, np.array([20.0]), m)  # martensite, heating on the major branch
    y, dy, xi = pf.elongation(wc, T, m, mem)
    sig = m[0] * pf.G / (AREA * 1e6)
    u = (sig - w.sigma_s_MPa) / (w.sigma_f_MPa - w.sigma_s_MPa)
    assert 0.0 < u < 1.0 and 0.0 < xi[0] < 1.0  # inside the ramp and the transformation: every term counts
    E = 1e3 * (w.E_A_GPa + xi[0] * (w.E_M_GPa - w.E_A_GPa))
    eps = sig / E + w.eps_L * 0.5 * (1.0 - math.cos(math.pi * u)) * xi[0] + w.alpha_per_C * (T[0] - w.T_ref_C)
    assert y[0] == pytest.approx(83.0 * eps - w.offset_mm, rel=1e-12)
    assert y[0] != pytest.approx(pf.elongation(pf.PhaseFractionWire().packed(83.0, AREA), T, m, mem)[0][0], rel=1e-3)
    h = 1e-6
    num = (pf.elongation(wc, T, m + h, mem)[0] - pf.elongation(wc, T, m - h, mem)[0]) / (2 * h)
    assert dy[0] == pytest.approx(num[0], rel=1e-5)


def test_a_reversal_inside_the_transformation_starts_a_minor_loop_without_a_jump():
    wire = pf.PhaseFractionWire()
    up = np.linspace(20.0, 0.5 * (wire.A_s_C + wire.A_f_C) + 4.0, 300)  # heated part of the way through
    T = np.r_[up, up[::-1], up]
    y, xi = pf.simulate(wire, T, 0.8)
    k = up.size
    assert 0.1 < xi[k - 1] < 0.9
    assert np.max(np.abs(np.diff(xi))) < 0.02  # continuous through both reversals
    assert np.all(np.diff(xi[:k]) <= 1e-12) and np.all(np.diff(xi[k : 2 * k]) >= -1e-12)  # falls heating, rises cooling
    # heated again, the minor loop's heating branch starts where the cooling stopped and stays below the major one
    major = pf.simulate(wire, up, 0.8)[1]
    assert np.all(xi[2 * k :] >= major - 1e-12)


def test_the_fit_recovers_a_phase_fraction_wire_and_payload_from_the_angle_alone():
    from sma_wrist.diagnose import effects as fx
    from sma_wrist.diagnose.data import Run

    t = np.arange(0.0, 300.0, DT)
    # relays and sines of the excitation's kind: each muscle through its transformation and back, partly
    ph = 2 * np.pi * t / 60.0
    T = np.c_[46.0 + 32.0 * np.sin(ph) + 6.0 * np.sin(3.1 * ph), 46.0 - 32.0 * np.sin(ph) + 6.0 * np.cos(2.3 * ph)]
    i_held = int(240.0 / DT)
    truth = pf.PhaseFractionWire(
        M_f_C=44.0, M_s_C=58.0, A_s_C=61.0, A_f_C=77.0, C_M_MPa_per_C=9.0, C_A_MPa_per_C=9.0, eps_L=0.045
    )
    run = Run(t=t, dt=DT, u=None, T=T, q=np.zeros(t.size), payload_kg=0.4)
    row = fx.NOMINAL.copy()
    row[fx.INDEX['coulomb_Nm']] = 0.01
    q = fx.ExtendedModel(run, PlantParams(dt=0.01, wire=truth)).angle_measured(row[None], None, 'measured')[:, 0]
    start = {k: v + 3.0 for k, v in builtin_transitions(default_sdgpi()).items()} | {'coulomb_Nm': 0.0}
    fit = fit_phase_fraction_wire(dataclasses.replace(run, q=q, payload_kg=0.3), i_held, start)
    w = fit.wire
    assert fit.at_bounds == []
    for k in ('A_s_C', 'A_f_C', 'M_s_C', 'M_f_C'):
        assert getattr(w, k) == pytest.approx(getattr(truth, k), abs=1.5), k
    assert w.C_M_MPa_per_C == pytest.approx(9.0, rel=0.2)
    assert w.eps_L == pytest.approx(0.045, rel=0.1)
    assert fit.payload_kg == pytest.approx(0.4, abs=0.05)
    assert fit.fit_rms_rad < 3e-3


def test_the_phase_fraction_wire_is_the_model_only_where_it_beats_every_sd_gpi_candidate_beyond_the_noise():
    rms = {'built-in': 249.0, 'shifted': 199.0, 'warped': 41.0}
    ok = {'built-in': True, 'shifted': True, 'warped': True}
    assert choose_model_wire(20.0, False, rms, ok, 1.0)
    assert not choose_model_wire(40.5, False, rms, ok, 1.0)  # within the noise of the warp
    assert not choose_model_wire(20.0, True, rms, ok, 1.0)  # a value at its bound
    # a warp at its bound is no candidate: the phase-fraction wire then needs to beat the shifted one only
    assert choose_model_wire(100.0, False, rms, ok | {'warped': False}, 1.0)


def test_wire_yaml_round_trips_and_a_malformed_one_is_refused_naming_the_key(tmp_path):
    from sma_wrist.plant_model import PlantModelFileError, read_plant_model

    wire = pf.PhaseFractionWire(A_s_C=61.5, C_A_MPa_per_C=11.0, offset_mm=0.9)
    path = save_wire_file(tmp_path / 'wire.yaml', wire, {'source': 'test'})
    assert load_wire_file(path) == wire
    assert PlantParams.from_files(wire_file=path).wire == wire
    text = path.read_text()
    (tmp_path / 'typo.yaml').write_text(text.replace('A_s_C:', 'A_start_C:'))
    with pytest.raises(ParameterError, match='A_start_C'):
        load_wire_file(tmp_path / 'typo.yaml')
    (tmp_path / 'order.yaml').write_text(text.replace('A_s_C: 61.5', 'A_s_C: 99.0'))
    with pytest.raises(ParameterError, match='A_s < A_f'):
        PlantParams.from_files(wire_file=tmp_path / 'order.yaml')
    (tmp_path / 'form.yaml').write_text(text.replace('form: phase_fraction', 'form: preisach'))
    with pytest.raises(ParameterError, match='form must be one of phase_fraction'):
        load_wire_file(tmp_path / 'form.yaml')
    # the constitutive law: written, read back, a file without it the linear one, a bad one refused naming it
    assert 'law: linear' in text
    brinson = save_wire_file(tmp_path / 'brinson.yaml', dataclasses.replace(wire, law='brinson'))
    assert load_wire_file(brinson) == dataclasses.replace(wire, law='brinson') != wire
    (tmp_path / 'nolaw.yaml').write_text(text.replace('law: linear\n', ''))
    assert load_wire_file(tmp_path / 'nolaw.yaml') == wire
    (tmp_path / 'law.yaml').write_text(text.replace('law: linear', 'law: cosine'))
    with pytest.raises(ParameterError, match='law must be one of linear, brinson'):
        load_wire_file(tmp_path / 'law.yaml')
    # the diagnosis' and the twin's plant model: a params file whose plant_sim names a bad wire_file
    params = tmp_path / 'p.yaml'
    params.write_text('plant_sim:\n  ros__parameters:\n    wire_file: order.yaml\n')
    model = read_plant_model(params)
    assert model.wire_file == str((tmp_path / 'order.yaml').resolve())
    with pytest.raises(PlantModelFileError, match='wire_file|A_s < A_f'):
        model.base()
    params.write_text('plant_sim:\n  ros__parameters:\n    wire_file: wire.yaml\n')
    assert read_plant_model(params).base().wire == wire


def test_the_plant_and_the_diagnosis_replay_step_the_same_phase_fraction_wrist():
    from sma_wrist.core.plant.wrist import WristPlant
    from sma_wrist.diagnose.kernels import Constants

    p = PlantParams(dt=0.01, wire=pf.PhaseFractionWire())
    plant = WristPlant(p, payload_kg=0.3)
    t = np.arange(0.0, 30.0, 0.01)
    T = np.c_[45.0 + 30.0 * np.sin(2 * np.pi * t / 20.0), 45.0 - 30.0 * np.sin(2 * np.pi * t / 20.0)]
    T[0] = plant.state.T_prev
    q = np.array([plant.step_mechanics(T[k][None]).q[0] for k in range(1, t.size)])
    c = Constants(p)
    q_k = c.mechanics(T[:, None, :], 0.01, np.r_[c.joint_row[:4], 0.3][None], 1)[0][1:, 0]
    assert np.ptp(q_k) > 0.5
    assert np.max(np.abs(q - q_k)) < 1e-12


def test_a_replay_with_another_wire_is_that_of_a_model_built_with_it():
    """ExtendedModel.with_wire, what the wire fit replays at each evaluation, against a model built from scratch:
    bit for bit, from noisy (smoothed) temperatures, after the first model has replayed (its cache) and for the
    SD-GPI too (the wire None); the first model keeps its own wire."""
    from sma_wrist.diagnose import effects as fx
    from sma_wrist.diagnose.data import Run

    t = np.arange(0.0, 60.0, DT)
    ph = 2 * np.pi * t / 30.0
    T = np.c_[50.0 + 30.0 * np.sin(ph), 50.0 - 30.0 * np.sin(ph)] + np.random.default_rng(5).normal(0, 0.1, (t.size, 2))
    run = Run(t=t, dt=DT, u=None, T=T, q=np.zeros(t.size), payload_kg=0.4)
    row = fx.NOMINAL.copy()[None]
    other = pf.PhaseFractionWire(M_f_C=40.0, M_s_C=55.0, A_s_C=60.0, A_f_C=80.0, law='brinson')
    model = fx.ExtendedModel(run, PlantParams(dt=0.01, wire=pf.PhaseFractionWire()))
    assert model.T_noise > fx.SMOOTH_ABOVE_C  # the smoothed temperatures drive the replay
    own = model.angle_measured(row)
    for wire in (other, None):
        swapped = model.with_wire(wire)
        built = fx.ExtendedModel(run, PlantParams(dt=0.01, wire=wire))
        assert swapped.consts.params == built.consts.params
        assert np.array_equal(swapped.consts.mech, built.consts.mech)
        q = swapped.angle_measured(row)
        assert np.array_equal(q, built.angle_measured(row))
        assert np.max(np.abs(q - own)) > 0.01  # another wire, another angle [rad]
    assert np.array_equal(model.angle_measured(row), own)
    assert np.array_equal(model.with_wire(None).with_wire(pf.PhaseFractionWire()).angle_measured(row), own)


def test_the_compiled_plant_steps_a_phase_fraction_wrist_as_the_numpy_path():
    from sma_wrist.core import jit
    from sma_wrist.core.plant.wrist import WristPlant

    if not jit.AVAILABLE:
        pytest.skip('numba is not installed: the plant has only its numpy path')
    wire = pf.PhaseFractionWire()
    plants = [WristPlant(PlantParams(wire=wire, engine=e, dt=0.01), payload_kg=[0.2, 0.5]) for e in ('auto', 'numpy')]
    cmds = np.array([[[20.0, -8.0], [16.0, -10.0]], [[-10.0, 18.0], [-6.0, 22.0]], [[24.0, -24.0], [0.0, 10.0]]])
    for u in cmds:
        for plant in plants:
            plant.advance(u, 1500)
        a, b = (pl.state for pl in plants)
        assert np.allclose(a.q, b.q, rtol=0, atol=1e-9) and np.allclose(a.load_kgf, b.load_kgf, rtol=0, atol=1e-9)
        assert np.allclose(a.w, b.w, rtol=0, atol=1e-9) and np.allclose(a.thermal, b.thermal, rtol=0, atol=1e-9)
    assert np.ptp(a.w[:, pf.XI]) > 0.3  # the wires transformed
    # the twin's batched segments are the same steps
    seg = WristPlant(PlantParams(wire=wire, dt=0.01), payload_kg=[0.2, 0.5])
    _, q, _ = seg.advance_segments(cmds, np.array([1500, 1500, 1500]))
    assert np.allclose(q[-1], plants[0].state.q, rtol=0, atol=1e-12)


def test_the_twin_monitor_simulates_the_wire_its_params_file_names(tmp_path):
    from sma_wrist.monitor.twin import load_model

    wire = pf.PhaseFractionWire(A_s_C=60.0)
    save_wire_file(tmp_path / 'wire.yaml', wire)
    params = tmp_path / 'wrist_params.yaml'
    params.write_text('plant_sim:\n  ros__parameters:\n    wire_file: wire.yaml\n    model.coulomb_Nm: 0.02\n')
    model = load_model(params_file=str(params))
    assert model.params.wire == wire and model.params.joint.coulomb_Nm == 0.02
    assert 'wire_file' in model.description
