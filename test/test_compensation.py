"""The inverse in wrist coordinates undoes the plant's muscle model (muscle.py Eq. 1)."""

from __future__ import annotations

import numpy as np
import pytest

from sma_wrist.core.errors import ModelInputError
from sma_wrist.core.hysteresis.compensation import MuscleCompensator
from sma_wrist.core.hysteresis.default_params import default_sdgpi
from sma_wrist.core.hysteresis.inverse import InverseCompensator
from sma_wrist.core.hysteresis.muscle import MuscleGeometry, MuscleModel
from sma_wrist.core.hysteresis.sdgpi import initial_state


@pytest.mark.parametrize('load_kgf', [0.75, 0.8, 0.9])  # the superelastic plateau, strokes > 3 mm
def test_compensated_temperature_gives_the_desired_bundle_elongation(load_kgf):
    params, g = default_sdgpi(), MuscleGeometry()
    model = MuscleModel(params, g)
    comp = MuscleCompensator(params, g, T_range_C=(20.0, 80.0))
    m = np.full(2, load_kgf)
    T0 = np.array([40.0, 40.0])
    comp.reset(T0, g.stress_Pa(m))
    st = initial_state(params, T0, m, branch='cooling')
    y_now = model.elongation(T0, m, st.w, st.heating)[0]
    targets = y_now + np.array([-0.15, 0.1])  # mm: one muscle shortens, the other lengthens
    res = comp(targets / g.wire_length_mm, g.stress_Pa(m))
    assert not res.saturated.any()
    heating = res.temperature_C > T0
    y = model.elongation(res.temperature_C, m, st.w, heating)[0]
    np.testing.assert_allclose(y, targets, atol=1e-6)
    # shortening needs heating (contraction), lengthening needs cooling
    assert res.temperature_C[0] > T0[0] > res.temperature_C[1]


def test_unreachable_target_saturates_and_out_of_range_load_is_flagged():
    params, g = default_sdgpi(), MuscleGeometry()
    comp = MuscleCompensator(params, g)
    comp.reset(np.array([40.0, 40.0]), g.stress_Pa(np.array([0.8, 0.8])))
    res = comp(np.array([-1.0, 1.0]), g.stress_Pa(np.array([0.8, 5.0])))
    assert res.saturated.any()
    assert res.load_clipped.tolist() == [False, True]
    with pytest.raises(ModelInputError):
        comp(np.array([np.nan, 0.02]), g.stress_Pa(np.array([0.8, 0.8])))


def _wrist_sequence(n: int = 300) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(measured T, measured stress, desired strain, desired stress) of two muscles along a slow
    antagonistic swing, loads partly outside the SD-GPI's range (below, above, zero)."""
    g = MuscleGeometry()
    t = np.arange(n)[:, None] * 0.01
    phase = np.array([0.0, np.pi])
    T = 45.0 + 20.0 * np.sin(0.7 * t + phase)
    load = 0.85 + 0.5 * np.sin(1.3 * t + phase)  # kgf, 0.35-1.35: the range is narrower
    load[::37] = 0.0
    strain = (2.0 + 1.2 * np.sin(0.9 * t + phase)) / g.wire_length_mm
    return T, g.stress_Pa(load), strain, g.stress_Pa(load * 1.01)


def test_wrist_coordinates_are_the_muscle_geometry_to_the_bit() -> None:
    """Load m = sigma A / g clipped to the SD-GPI's range (MuscleGeometry.load_kgf) and the SD-GPI
    target (eps L_wire - c_el m) / (L_wire / L_model), as the node gets them, equal the geometry's
    numpy expressions bit for bit, and so does the memory observe leaves."""
    params, g = default_sdgpi(), MuscleGeometry()
    lo, hi = params.load_range
    comp = MuscleCompensator(params, g)
    ref = InverseCompensator(params, T_range=(20.0, 80.0))
    T, sigma, strain, sigma_d = _wrist_sequence()
    comp.reset(T[0], sigma[0])
    ref.reset(T[0], np.clip(g.load_kgf(sigma[0]), lo, hi))
    clipped_seen = False
    for k in range(1, len(T)):
        comp.observe(T[k], sigma[k])
        ref.observe(T[k], np.clip(g.load_kgf(sigma[k]), lo, hi))
        res = comp(strain[k], sigma_d[k], commit=False)
        m = g.load_kgf(sigma_d[k])
        np.testing.assert_array_equal(res.load_kgf, np.clip(m, lo, hi))
        np.testing.assert_array_equal(res.load_clipped, (m < lo) | (m > hi))
        y = (strain[k] * g.wire_length_mm - g.elastic_mm_per_kgf * res.load_kgf) / g.length_scale
        np.testing.assert_array_equal(res.sdgpi_elongation_mm, y)
        np.testing.assert_array_equal(res.temperature_C, ref.solve(y, res.load_kgf, commit=False).T)
        clipped_seen |= bool(res.load_clipped.any())
    np.testing.assert_array_equal(comp.inverse.state.w, ref.state.w)
    np.testing.assert_array_equal(comp.inverse.state.T_prev, ref.state.T_prev)
    assert clipped_seen
    # one stress for both muscles (broadcast): the same numbers, the load in the stress's shape
    res = comp(strain[5], sigma_d[5, 0], commit=False)
    assert res.load_kgf.shape == res.load_clipped.shape == () and res.sdgpi_elongation_mm.shape == (2,)
    np.testing.assert_array_equal(
        res.sdgpi_elongation_mm, comp(strain[5], sigma_d[5, [0, 0]], commit=False).sdgpi_elongation_mm
    )


@pytest.mark.parametrize('bad', [np.nan, np.inf, -np.inf])
def test_non_finite_strain_or_stress_is_rejected_and_leaves_the_memory(bad: float) -> None:
    params, g = default_sdgpi(), MuscleGeometry()
    comp = MuscleCompensator(params, g)
    stress = g.stress_Pa(np.array([0.8, 0.9]))
    comp.reset(np.array([40.0, 45.0]), stress)
    before = comp.inverse.state.copy()
    with pytest.raises(ModelInputError, match='measured stress'):
        comp.observe(np.array([41.0, 41.0]), np.array([stress[0], bad]))
    with pytest.raises(ModelInputError, match='desired strain'):
        comp(np.array([bad, 0.02]), stress, commit=False)
    with pytest.raises(ModelInputError, match='desired stress'):
        comp(np.array([0.02, 0.02]), np.array([bad, stress[1]]), commit=False)
    with pytest.raises(ModelInputError, match='desired stress'):  # more wires than the few-float test covers
        MuscleCompensator(params, g)(np.full(12, 0.02), np.r_[np.full(11, stress[0]), bad])
    np.testing.assert_array_equal(comp.inverse.state.w, before.w)
    np.testing.assert_array_equal(comp.inverse.state.T_prev, before.T_prev)


@pytest.mark.parametrize('seed', [0, 1])
def test_compiled_track_step_is_the_numpy_step(seed: int) -> None:
    """MuscleCompensator.track's adaptation step compiled (the node's 100 Hz call, where numba is
    installed) against its numpy reference, over random heating/cooling histories whose strains
    the model does not predict (the shift moves, some steps hit the limit)."""
    from unittest import mock

    from sma_wrist.core import jit

    if not jit.AVAILABLE:
        pytest.skip('numba is not installed: there is only the numpy path')
    g = MuscleGeometry()
    rng = np.random.default_rng(seed)
    comps = [MuscleCompensator(default_sdgpi(), shift_gain_per_s=5.0, shift_limit_C=4.0) for _ in range(2)]
    T = np.array([35.0, 60.0])
    stress = g.stress_Pa(np.array([0.8, 0.6]))
    for c in comps:
        c.reset(T, stress)
    shifts = []
    for _k in range(400):
        T = np.clip(T + rng.normal(0.0, 1.5, 2), 20.0, 80.0)
        stress = stress * (1.0 + rng.normal(0.0, 0.01, 2))
        strain = rng.uniform(0.02, 0.05, 2)
        for c, numpy_path in zip(comps, (True, False)):
            with mock.patch.object(jit, 'AVAILABLE', not numpy_path):
                c.track(T, stress, strain, 0.01)
        np.testing.assert_allclose(comps[1].shift_C, comps[0].shift_C, rtol=0, atol=1e-12)
        # not bit-equal: math.tanh and a sequential sum against numpy's tanh and matmul (~1e-14 degC)
        np.testing.assert_allclose(comps[1].inverse.state.T_prev, comps[0].inverse.state.T_prev, rtol=0, atol=1e-12)
        shifts.append(comps[0].shift_C.copy())
    shifts = np.array(shifts)
    assert np.ptp(shifts) > 1.0 and np.abs(shifts).max() == pytest.approx(4.0)  # it adapted, up to the limit


def test_many_wires_in_one_compensator_are_the_two_wire_ones_to_the_bit() -> None:
    """The sweep runs one MuscleCompensator over the wires of all its inverse-mode wrists (arrays, not
    the node's float-by-float path): track and the inverse give each wrist what its own two-wire
    compensator (the node's) gives, bit for bit, with the axis adaptation and the window following
    it, loads partly outside the SD-GPI's range, each wrist on its own phase."""
    n = 6  # 12 wires: above FLOAT_BY_FLOAT_MAX
    kw = dict(T_range_C=(20.0, 80.0), shift_gain_per_s=2.0, shift_limit_C=15.0, window_follows_shift=True)
    bank = MuscleCompensator(default_sdgpi(), **kw)
    ones = [MuscleCompensator(default_sdgpi(), **kw) for _ in range(n)]
    seqs = [[np.roll(x, 11 * j, axis=0) for x in _wrist_sequence(200)] for j in range(n)]
    strain_measured = [0.97 * s[2] for s in seqs]  # a wire the model does not predict: the shifts move
    stack = [np.concatenate([s[i][0] for s in seqs]) for i in range(4)]
    bank.reset(stack[0], stack[1])
    for c, s in zip(ones, seqs):
        c.reset(s[0][0], s[1][0])
    clipped_seen = False
    for k in range(1, 200):
        bank.track(
            np.concatenate([s[0][k] for s in seqs]),
            np.concatenate([s[1][k] for s in seqs]),
            np.concatenate([e[k - 1] for e in strain_measured]),
            0.01,
        )
        res = bank(np.concatenate([s[2][k] for s in seqs]), np.concatenate([s[3][k] for s in seqs]), commit=False)
        for j, (c, s) in enumerate(zip(ones, seqs)):
            c.track(s[0][k], s[1][k], strain_measured[j][k - 1], 0.01)
            one = c(s[2][k], s[3][k], commit=False)
            w = slice(2 * j, 2 * j + 2)
            for a, b in (
                (res.temperature_C, one.temperature_C),
                (res.saturated, one.saturated),
                (res.load_kgf, one.load_kgf),
                (res.load_clipped, one.load_clipped),
                (res.sdgpi_elongation_mm, one.sdgpi_elongation_mm),
                (bank.shift_C, c.shift_C),
            ):
                np.testing.assert_array_equal(a[w], b)
        clipped_seen |= bool(res.load_clipped.any())
    assert np.ptp(bank.shift_C) > 0.1 and clipped_seen


def test_strain_informative_holds_on_a_stop_and_while_still_with_a_slack_wire() -> None:
    """core.hysteresis.compensation.strain_informative (doc/explanation/controllers.md): per wrist, both wires."""
    from sma_wrist.core.hysteresis.compensation import strain_informative

    taut, slack = [1e8, 1e8], [1e8, 0.0]
    q = np.array([0.5, -0.35, 1.4, 0.5, 0.5, 0.5])
    q_prev = np.array([0.5, -0.35, 1.4, 0.5, 0.49, 0.5])  # the fifth moves (1 rad/s), the others stand
    stress = np.array([taut, taut, taut, slack, slack, [0.0, 5e5]])
    got = strain_informative(q, q_prev, 0.01, stress, (-0.35, 1.40))
    assert got.shape == (6, 2) and np.all(got[:, 0] == got[:, 1])
    assert got[:, 0].tolist() == [True, False, False, False, True, False]


def test_track_holds_the_shift_where_told_and_is_unchanged_elsewhere() -> None:
    """MuscleCompensator.track(adapt=...): a held wire keeps shift and stroke; the other steps as without the mask."""
    m = MuscleGeometry().stress_Pa(np.array([0.8, 0.8]))
    runs = []
    for adapt in (None, np.array([True, False])):
        comp = MuscleCompensator(default_sdgpi(), shift_gain_per_s=2.0, stroke_gain_per_s=1.0)
        comp.reset(np.full(2, 55.0), m)
        for k in range(50):
            comp.track(np.full(2, 55.0 + 0.1 * k), m, np.array([0.03, 0.03]), 0.01, adapt)
        runs.append((comp.shift_C.copy(), comp.stroke.copy()))
    (free_shift, free_stroke), (held_shift, held_stroke) = runs
    assert abs(free_shift[1]) > 0.1  # the strain disagrees with the model: the free wire's shift moves
    assert held_shift[1] == 0.0 and held_stroke[1] == 1.0
    assert held_shift[0] == free_shift[0] and held_stroke[0] == free_stroke[0]


def test_shifts_hold_while_either_wire_of_a_pair_is_outside_the_load_range() -> None:
    """MuscleCompensator(hold_outside_load_range=True) (doc/explanation/controllers.md;
    off by default since "The load-range gate, after the slope fix"): the measured Flexinol wrist starts with
    muscle 1 at 14 MPa and muscle 2 slack, below the SD-GPI's 0.2-1.5 kgf. With the gate both wires hold while
    either is out of range, on the node's (2,) and the sweep's flat (2N,) wires alike; inside the range the
    adaptation steps as without the gate; without the gate it steps everywhere."""
    geo = MuscleGeometry()
    taut = geo.stress_Pa(np.array([0.8, 0.8]))
    slack = geo.stress_Pa(np.array([0.07, 0.0]))  # 14 MPa / 0 MPa
    over = geo.stress_Pa(np.array([0.8, 1.7]))
    comp = MuscleCompensator(default_sdgpi(), shift_gain_per_s=2.0)
    assert not comp.hold_outside_load_range
    assert comp.pair_in_load_range(taut).tolist() == [True, True]
    assert comp.pair_in_load_range(slack).tolist() == [False, False]
    flat = np.concatenate([taut, over, slack, taut])  # four wrists' wires, flat as the sweep's bank has them
    assert comp.pair_in_load_range(flat).tolist() == [True, True, False, False, False, False, True, True]
    assert comp.pair_in_load_range(flat.reshape(4, 2)).tolist() == [
        [True, True],
        [False, False],
        [False, False],
        [True, True],
    ]

    def shifts(stress: np.ndarray, gate: bool) -> np.ndarray:
        c = MuscleCompensator(default_sdgpi(), shift_gain_per_s=2.0, hold_outside_load_range=gate)
        # 50-55 degC: where the model's loop has a slope at the clipped loads (at the slack pair's 0.2 kgf it
        # is flat from ~55 degC on, and a flat loop does not move the shift)
        c.reset(np.full(2, 50.0), stress)
        for k in range(50):
            c.track(np.full(2, 50.0 + 0.1 * k), stress, np.array([0.03, 0.03]), 0.01)
        return c.shift_C

    assert np.all(shifts(slack, True) == 0.0) and np.all(shifts(over, True) == 0.0)
    assert np.abs(shifts(slack, False)).max() > 0.1 and np.abs(shifts(over, False)).max() > 0.1
    assert np.array_equal(shifts(taut, True), shifts(taut, False)) and np.abs(shifts(taut, True)).max() > 0.1


@pytest.mark.parametrize('compiled', [True, False])
def test_a_wire_that_transformed_where_the_model_is_flat_moves_the_shift_only_the_right_way(compiled: bool) -> None:
    """doc/explanation/controllers.md: inside the model's loop the central difference of track's step spans
    both branches' memoryless parts (Eq. 3.22) and reads ~+0.0009 mm/degC; times the error of a wire that
    transformed where the model is flat (a family plant: 1.6 mm) it drove the shift up at ~1 degC/s, the way
    that makes the model colder still, to its limit. A wire shorter than the model predicts needs the model's
    axis hotter (shift <= 0), on the compiled and the numpy path alike."""
    from unittest import mock

    from sma_wrist.core import jit
    from sma_wrist.core.hysteresis.inverse import _output_frozen

    if compiled and not jit.AVAILABLE:
        pytest.skip('numba is not installed: there is only the numpy path')
    g = MuscleGeometry()
    stress = g.stress_Pa(np.array([0.8, 0.8]))
    comp = MuscleCompensator(default_sdgpi(), shift_gain_per_s=2.0)
    comp.reset(np.full(2, 25.0), stress)
    with mock.patch.object(jit, 'AVAILABLE', compiled):
        for T in np.arange(25.0, 40.01, 0.5):  # heated from cold to below the model's transformation
            comp.track(np.full(2, T), stress, np.full(2, 0.04), 0.01, adapt=np.zeros(2, bool))
        st = comp.inverse.state
        m = np.full(2, 0.8)
        y_model = _output_frozen(comp.params, st.w, st.T_prev, m, st.heating)
        h = 0.5
        y_pm = _output_frozen(
            comp.params, st.w, st.T_prev + np.array([[h], [-h]]), m, np.array([[True] * 2, [False] * 2])
        )
        assert np.all((y_pm[0] - y_pm[1]) / (2 * h) > 0.0)  # the artefact this test is about is there
        # a wire 1.5 mm shorter than the model (it transformed), in bundle strain (CompensationResult's inverse)
        eps = ((y_model - 1.5) * g.length_scale + g.elastic_mm_per_kgf * m) / g.wire_length_mm
        for _ in range(200):
            comp.track(np.full(2, 40.0), stress, eps, 0.01)
    assert np.all(comp.shift_C <= 0.0), comp.shift_C
