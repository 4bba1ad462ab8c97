"""The warped SD-GPI of commissioning (sma_wrist/core/hysteresis/warp.py, commission/identification.py): the warp's
transforms of the tanh coefficients, its fit to an angle replayed from measured temperatures, the hand-over rule,
and the file it is written to.

The fits run on a synthetic wrist: the angle the joint makes with a known warped wire, replayed from two muscle
temperature traces shaped like the excitation's (a relay cycle, a rest, a sine; held out: a slower relay cycle)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from sma_wrist.commission.identification import WARP_RANGE, choose_wire, fit_warped_wire
from sma_wrist.core.hysteresis.default_params import default_sdgpi
from sma_wrist.core.hysteresis.params_file import load_hysteresis, save_hysteresis
from sma_wrist.core.hysteresis.sdgpi import initial_state, mirrored_output, simulate
from sma_wrist.core.hysteresis.warp import Warp, warped_wire
from sma_wrist.identify.loops import transitions
from sma_wrist.identify.wrist import shifted_wire

DT = 0.05
HELD_S = 40.0


def _loop(params, load_kgf: float) -> tuple[np.ndarray, np.ndarray]:
    T = np.r_[np.linspace(0.0, 110.0, 600), np.linspace(110.0, 0.0, 600)]
    return T, simulate(params, T, load_kgf, branch='cooling')


def test_shifts_move_each_branch_and_width_widens_it_about_its_centre():
    base = default_sdgpi()
    ref = transitions(*_loop(base, 0.8), 'heating')
    w = transitions(*_loop(warped_wire(base, Warp(heating_shift_C=4.0, cooling_shift_C=-3.0)), 0.8), 'heating')
    for k in ('A_s', 'A_50', 'A_f'):
        assert w[k] == pytest.approx(ref[k] + 4.0, abs=0.3)
    for k in ('M_s', 'M_50', 'M_f'):
        assert w[k] == pytest.approx(ref[k] - 3.0, abs=0.3)
    wide = transitions(*_loop(warped_wire(base, Warp(width_scale=1.5)), 0.8), 'heating')
    assert wide['A_f'] - wide['A_s'] == pytest.approx(1.5 * (ref['A_f'] - ref['A_s']), rel=0.05)
    assert wide['A_50'] == pytest.approx(ref['A_50'], abs=0.5)
    # equal shifts are the shifted wire
    s, e = shifted_wire(base, 5.0), warped_wire(base, Warp(5.0, 5.0))
    assert np.array_equal(s.envelopes.a, e.envelopes.a) and np.array_equal(s.c, e.c) and np.array_equal(s.d, e.d)


def test_stroke_scales_the_mirrored_elongation_about_the_reference_and_stress_scales_the_load_dependence():
    base = default_sdgpi()
    T, y = _loop(base, 0.8)
    _, y2 = _loop(warped_wire(base, Warp(stroke_scale=0.7, y_ref_mm=3.0)), 0.8)
    ym, ym2 = base.k_f - y, base.k_f - y2  # Eq. 4.2 with the base's k_f: the scaled wire keeps its length at y_m = 3
    assert np.allclose(ym2 - 3.0, 0.7 * (ym - 3.0), atol=1e-9)
    # the warped wire at load m is the built-in at 0.8 + k (m - 0.8)
    k = 0.5
    soft = warped_wire(base, Warp(stress_scale=k))
    for m in (0.6, 1.0):
        assert np.allclose(_loop(soft, m)[1], _loop(base, 0.8 + k * (m - 0.8))[1], atol=1e-9)
    assert soft.load_range[0] >= 0.0  # a wire carries no compression


def test_a_warped_wire_round_trips_through_hysteresis_yaml(tmp_path):
    wire = warped_wire(default_sdgpi(), Warp(6.0, 10.0, 1.3, 0.9, 0.4, y_ref_mm=3.0))
    path = save_hysteresis(tmp_path / 'hysteresis.yaml', wire, {'wire_model': 'warped'})
    back = load_hysteresis(path)
    T = np.r_[np.linspace(20.0, 90.0, 200), np.linspace(90.0, 20.0, 200)]
    for m in (0.5, 0.8, 1.1):
        assert np.allclose(simulate(back, T, m), simulate(wire, T, m), atol=1e-12)


def _temperatures() -> tuple[np.ndarray, int]:
    """Muscle temperatures (n, 2) [degC] of a synthetic excitation and the first held-out sample."""

    def relay(T0: np.ndarray, tau: float, s: float) -> np.ndarray:
        t = np.arange(0.0, s, DT)[:, None]
        hot, cold = 78.0, 14.0
        first = np.c_[hot + (T0[0] - hot) * np.exp(-t[:, 0] / tau), cold + (T0[1] - cold) * np.exp(-t[:, 0] / tau)]
        second = np.c_[
            cold + (first[-1, 0] - cold) * np.exp(-t[:, 0] / tau), hot + (first[-1, 1] - hot) * np.exp(-t[:, 0] / tau)
        ]
        return np.r_[first, second]

    fit = relay(np.array([25.0, 25.0]), 6.0, 30.0)
    t = np.arange(0.0, 40.0, DT)
    sine = 46.0 + 30.0 * np.c_[np.sin(2 * np.pi * t / 20.0), -np.sin(2 * np.pi * t / 20.0)]
    rest = fit[-1] + (sine[0] - fit[-1]) * (1 - np.exp(-np.arange(0.0, 5.0, DT) / 1.0))[:, None]
    fit = np.r_[fit, rest, sine]
    held = relay(fit[-1], 9.0, HELD_S / 2)
    return np.r_[fit, held], fit.shape[0]


def _device(warp: Warp, payload_kg: float = 0.3) -> tuple[object, int]:
    """A Run of the synthetic excitation on a wrist whose wire is the built-in one under ``warp``."""
    from sma_wrist.core.plant.wrist import PlantParams
    from sma_wrist.diagnose import effects as fx
    from sma_wrist.diagnose.data import Run

    T, i_held = _temperatures()
    t = np.arange(T.shape[0]) * DT
    run = Run(t=t, dt=DT, u=None, T=T, q=np.zeros(t.size), payload_kg=payload_kg)
    model = fx.ExtendedModel(run, PlantParams(dt=0.01, hysteresis=warped_wire(default_sdgpi(), warp)))
    q = model.angle_measured(fx.NOMINAL[None], None, 'measured')[:, 0]
    return dataclasses.replace(run, q=q), i_held


def _y_ref() -> float:
    base = default_sdgpi()
    cold = mirrored_output(base, initial_state(base, 20.0, 0.8, branch='cooling'), 20.0)[0]
    hot = mirrored_output(base, initial_state(base, 80.0, 0.8, branch='heating'), 80.0)[0]
    return 0.5 * float(cold + hot)


START = {'shift_C': 0.0, 'coulomb_Nm': 0.004, 'preload_err_mm': 0.0}


def test_the_fit_recovers_a_known_warp_from_the_angle_alone():
    true = Warp(4.0, 7.0, 1.2, 0.9, 1.0, y_ref_mm=_y_ref())
    run, i_held = _device(true)
    wf = fit_warped_wire(run, default_sdgpi(), i_held, START, starts=(1.0,))
    w = wf.warp
    assert w.heating_shift_C == pytest.approx(4.0, abs=0.5) and w.cooling_shift_C == pytest.approx(7.0, abs=0.5)
    assert w.width_scale == pytest.approx(1.2, abs=0.05) and w.stroke_scale == pytest.approx(0.9, abs=0.05)
    assert w.stress_scale == pytest.approx(1.0, abs=0.1)
    assert wf.at_bounds == [] and wf.fit_rms_rad < 2e-3


def test_a_wire_beyond_the_warps_range_is_fitted_to_a_bound_and_not_handed_over():
    hi = WARP_RANGE['stroke_scale'][1]
    run, i_held = _device(Warp(0.0, 0.0, 1.0, 1.4 * hi, 1.0, y_ref_mm=_y_ref()))
    wf = fit_warped_wire(run, default_sdgpi(), i_held, START, starts=(1.0,), max_nfev=60)
    assert any(b.startswith('stroke_scale') for b in wf.at_bounds), wf
    # however well it replays the held-out cycle, a warp at a bound is not handed over
    assert choose_wire(300.0, 170.0, False, 40.0, bool(wf.at_bounds), 0.2) == 'shifted'


def test_the_hand_over_rule_needs_the_warp_better_than_both_others_beyond_the_noise():
    # the emulated model wrist (mrad): built-in 0.295, shift-only 2.07, warp 1.79, angle noise 0.24
    assert choose_wire(0.295, 2.07, False, 1.79, False, 0.24) == 'built-in'
    # the phase-fraction wrist: 296, 172, 42
    assert choose_wire(296.0, 172.0, False, 42.0, False, 0.18) == 'warped'
    # better than the shift-only wire by less than the noise: the simpler wire stays
    assert choose_wire(10.0, 5.0, False, 4.9, False, 0.2) == 'shifted'
    assert choose_wire(10.0, 5.0, True, 4.9, False, 0.2) == 'built-in'


class _Recording:
    """What identify_mechanics reads of a bring-up (BringUp.rec.arrays, BringUp.physical): the muscle temperatures
    and the angle as they are, from device time 0."""

    def __init__(self, t: np.ndarray, T: np.ndarray, q: np.ndarray) -> None:
        self.rec = self
        self._t, self._x = t, np.c_[T, T, q]

    def arrays(self, since: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        i = int(np.searchsorted(self._t, since))
        return self._t[i:], self._x[i:], np.zeros((self._t.size - i, 2))

    def physical(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return x[:, :4], x[:, 4]


def test_the_wire_and_joint_are_fitted_from_the_history_the_bring_up_left_in_the_wires(tmp_path):
    from sma_wrist.commission.identification import FIRST_HEATING, identify_mechanics
    from sma_wrist.core.plant.wrist import PlantParams
    from sma_wrist.diagnose import effects as fx
    from sma_wrist.diagnose.data import Run

    # the bring-up's angle step before the excitation: muscle 1 heated to 64 degC and cooled back, then muscle 2 to
    # 48 degC (each wire partly transformed): the wires still remember it when the excitation's first relay starts
    s = np.arange(0.0, 30.0, DT)

    def excursion(peak: float) -> np.ndarray:
        heated = peak + (25.0 - peak) * np.exp(-s / 6.0)
        return np.r_[heated, 25.0 + (heated[-1] - 25.0) * np.exp(-s / 4.0)]

    rest = np.full(2 * s.size, 25.0)
    before = np.r_[np.full((40, 2), 25.0), np.c_[excursion(64.0), rest], np.c_[rest, excursion(48.0)]]
    exc, i_held = _temperatures()
    T = np.r_[before, exc]
    t = np.arange(T.shape[0]) * DT
    truth = {'payload_kg': 0.4, 'coulomb_Nm': 0.004, 'preload_err_mm': 0.0}
    run = Run(t=t, dt=DT, u=None, T=T, q=np.zeros(t.size), payload_kg=truth['payload_kg'])
    q = fx.ExtendedModel(run, PlantParams(dt=0.01)).angle_measured(fx.NOMINAL[None], None, 'measured')[:, 0]
    t_fit, half = before.shape[0] * DT, int(round(30.0 / DT))  # _temperatures' relay: two 30 s half-cycles
    phases = [
        {'label': FIRST_HEATING, 'part': 'fit', 't_start_s': t_fit, 't_end_s': t_fit + half * DT},
        {
            'label': 'relay: muscle 2 heated',
            'part': 'fit',
            't_start_s': t_fit + half * DT,
            't_end_s': t_fit + 2 * half * DT,
        },
        {'label': 'sine', 'part': 'fit', 't_start_s': t_fit + 2 * half * DT, 't_end_s': t_fit + i_held * DT},
        {'label': 'relay', 'part': 'heldout', 't_start_s': t_fit + i_held * DT, 't_end_s': t[-1]},
    ]
    hyst, joint, values, _ = identify_mechanics(
        _Recording(t, T, q), tmp_path, None, phases, t_fit, t_fit + i_held * DT, t[-1]
    )
    p = joint['parameters']
    # replayed from the excitation's start in the rest state's memory, the true wire was up to 14 mrad off in the first
    # relay, and the fit made up for it with the payload, friction and pre-load (0.4038 kg, 0.00412 N m, +0.0011 mm):
    # 1.2 mrad off the held-out cycle, 43 x the angle's noise
    assert p['payload_identified'] and p['payload_kg'] == pytest.approx(truth['payload_kg'], abs=0.002), p
    assert p['coulomb_Nm'] == pytest.approx(truth['coulomb_Nm'], abs=5e-5), p
    assert hyst['parameters']['transition_shift_C'] == pytest.approx(0.0, abs=0.05), hyst['parameters']
    assert joint['heldout']['commissioned'] < 2.0 * joint['heldout']['angle_noise'], joint['heldout']
    # the wrist's wire is the model's SD-GPI: the phase-fraction wire, fitted too, does not replace it
    assert hyst['parameters']['model_wire'] == 'sdgpi' and 'wire_file' not in values, hyst['parameters']
    assert joint['heldout']['phase_fraction'] > joint['heldout']['commissioned'] + joint['heldout']['angle_noise']


def test_the_onsets_coarse_to_fine_search_finds_the_shifts_of_the_whole_grid(monkeypatch):
    """wire_shift_from_onset replays every ONSET_COARSE_STEP-th offset, then the best one's neighbours: the shifts of
    the whole 1 degC grid (a step of 1) from half the replays, at payloads around the wire's own; at its own payload
    the wire's shift."""
    import sma_wrist.commission.identification as idf
    from sma_wrist.core.plant.wrist import PlantParams
    from sma_wrist.diagnose import effects as fx
    from sma_wrist.diagnose.data import Run

    half = int(round(30.0 / DT))  # _temperatures' relay: muscle 1 heated for the first 30 s
    T = _temperatures()[0][: 2 * half]
    t = np.arange(T.shape[0]) * DT
    run = Run(t=t, dt=DT, u=None, T=T, q=np.zeros(t.size), payload_kg=0.3)
    truth = fx.NOMINAL.copy()
    truth[fx.INDEX['temp_offset_C']], truth[fx.INDEX['payload_err_kg']] = 6.0, 0.1
    q = fx.ExtendedModel(run, PlantParams(dt=0.01)).angle_measured(truth[None])[:, 0]
    model = fx.ExtendedModel(dataclasses.replace(run, q=q), PlantParams(dt=0.01))
    rows = np.repeat(fx.NOMINAL[None], 5, axis=0)
    rows[:, fx.INDEX['payload_err_kg']] = [-0.1, 0.0, 0.1, 0.2, 0.3]
    columns: list[int] = []
    replay = fx.ExtendedModel.angle_measured
    monkeypatch.setattr(fx.ExtendedModel, 'angle_measured', lambda s, r, *a: columns.append(len(r)) or replay(s, r, *a))
    shifts, replayed = {}, {}
    for step in (1, idf.ONSET_COARSE_STEP):
        monkeypatch.setattr(idf, 'ONSET_COARSE_STEP', step)
        columns.clear()
        shifts[step] = idf.wire_shift_from_onset(model, rows, t, 0.0, half * DT)
        replayed[step] = sum(columns)
    assert np.array_equal(shifts[1], shifts[3]), shifts
    assert shifts[3][2] == pytest.approx(6.0, abs=0.05) and np.all(np.diff(shifts[3]) < 0)  # heavier reads colder
    assert replayed[3] <= 0.55 * replayed[1] == 0.55 * 5 * 31, replayed
