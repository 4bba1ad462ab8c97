"""The project's wrist with realistic parameter spread: one named perturbation set per scenario.

A :class:`Scenario` is one plant the controllers do not know: the SD-GPI wire's transition
temperatures shifted, its stroke scaled, the TEM drive gain and the muscle face's heat
losses scaled, the coolant/ambient offset, a payload the controllers are not told, and
the sensors' imperfections (thermocouple noise and first-order lag, potentiometer noise).
:func:`sample` draws N of them, seeded, from named ranges (:data:`FAMILY`, the default
family); every name and range is checked against the model's validity (:data:`VALIDITY`).

Where each perturbation acts:

* wire (:func:`perturbed_hysteresis`): the tanh envelopes of Eq. 3.21 and the memoryless sets
  of Eq. 3.22 are functions of ``k1 T + k2``; a transition shift dT replaces k2 by
  ``k2 - k1 dT`` (every load section's quadratic, Eqs. 4.4-4.5). A stroke scale s multiplies
  the mirrored output y_m about its mid-stroke value y_ref (amplitudes k0, k3, play thresholds
  r_j with the weights p(r_j) kept, Eqs. 3.23-3.24) and moves k_f by ``-(1 - s) y_ref`` so the
  pre-loaded bundle keeps its length at mid-stroke (Eq. 4.2);
* TEMs (Eqs. 4.13-4.14): the same arithmetic as the diagnosis' extension parameters
  (:func:`sma_wrist.core.plant.extensions.plant_params`: drive gain, muscle-face losses, ambient);
* joint: the payload mass (Eq. 4.18);
* sensors (:class:`SensorBank`): applied to what the plant publishes, not inside the model.

The plant of N scenarios with their own parameters is :class:`VariedPlant`: the compiled
plant step (:func:`sma_wrist.core.plant.kernel.step_many`) per scenario with its own constants.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from sma_wrist.core.errors import ParameterError, check_finite
from sma_wrist.core.hysteresis.kernel import _solve_load
from sma_wrist.core.hysteresis.muscle import MuscleModel
from sma_wrist.core.hysteresis.sdgpi import SDGPIParams, initial_state, mirrored_output, play_bounds
from sma_wrist.core.hysteresis.warp import Warp, warped_wire
from sma_wrist.core.jit import _jit, kernel_array
from sma_wrist.core.plant import extensions as mx
from sma_wrist.core.plant import kernel as plant_kernel
from sma_wrist.core.plant.wrist import PlantParams, PlantState, WristPlant
from sma_wrist.core.thermal import heat_balance as th

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Perturbation:
    """One perturbation axis: its unit, nominal value and the range where the model stays valid."""

    name: str
    unit: str
    nominal: float
    lower: float  # validity: the widest range a family may ask for
    upper: float
    description: str


#: Validity of each perturbation. Wider than the default family, narrower than where the model
#: breaks: transition shifts beyond +-15 degC put a wire's transformation outside what the TEMs
#: reach (20-80 degC working band); stroke and thermal scales of 0.5-1.5; the joint's +-30 deg
#: range holds to ~0.7 kg (doc/explanation/model.md); sensor figures of realistic hardware.
VALIDITY: tuple[Perturbation, ...] = (
    Perturbation('payload_kg', 'kg', 0.3, 0.0, 0.7, 'payload at the 0.09 m lever, unknown to the controllers'),
    Perturbation('transition_shift_C', 'degC', 0.0, -15.0, 15.0, 'shift of the wire transformation temperatures'),
    Perturbation('stroke_scale', '1', 1.0, 0.5, 1.5, "transformation stroke / the model's"),
    Perturbation('tem_gain_scale', '1', 1.0, 0.5, 1.5, "TEM drive gain (input_per_volt) / the model's"),
    Perturbation('heat_loss_scale', '1', 1.0, 0.5, 1.5, "muscle-face heat losses (K_Tinf, K_T, K_inf) / the model's"),
    Perturbation('ambient_offset_C', 'degC', 0.0, -10.0, 10.0, 'coolant/ambient temperature offset'),
    Perturbation('temp_noise_C', 'degC', 0.0, 0.0, 1.0, 'thermocouple noise, standard deviation'),
    Perturbation('temp_lag_s', 's', 0.0, 0.0, 1.0, 'thermocouple first-order time constant'),
    Perturbation('angle_noise_rad', 'rad', 0.0, 0.0, 0.01, 'potentiometer noise, standard deviation'),
)
BY_NAME = {p.name: p for p in VALIDITY}

#: the family the sweep samples by default
FAMILY: dict[str, tuple[float, float]] = {
    'payload_kg': (0.1, 0.6),
    'transition_shift_C': (-10.0, 10.0),
    'stroke_scale': (0.7, 1.3),
    'tem_gain_scale': (0.7, 1.3),
    'heat_loss_scale': (0.7, 1.3),
    'ambient_offset_C': (-5.0, 5.0),
    'temp_noise_C': (0.05, 0.3),
    'temp_lag_s': (0.0, 0.2),
    'angle_noise_rad': (0.0, 3e-3),
}

#: velocity from a measured (noisy) angle: filtered backward difference, as hardware_bridge's default
VELOCITY_FILTER_S = 0.02


@dataclass(frozen=True)
class Scenario:
    """One plant of the family: a value for every :data:`VALIDITY` axis (nominal by default)."""

    payload_kg: float = 0.3
    transition_shift_C: float = 0.0
    stroke_scale: float = 1.0
    tem_gain_scale: float = 1.0
    heat_loss_scale: float = 1.0
    ambient_offset_C: float = 0.0
    temp_noise_C: float = 0.0
    temp_lag_s: float = 0.0
    angle_noise_rad: float = 0.0
    noise_seed: int = 0  # the sensors' noise stream

    def __post_init__(self) -> None:
        for p in VALIDITY:
            v = getattr(self, p.name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and p.lower <= v <= p.upper):
                raise ParameterError(
                    f"{p.name} = {v!r} {p.unit} is outside the model's validity "
                    f'[{p.lower:g}, {p.upper:g}] ({p.description})'
                )

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any]) -> Scenario:
        """A scenario from {name: value}; unknown names raise ParameterError naming the known ones."""
        known = {f.name for f in dataclasses.fields(cls)}
        bad = [k for k in values if k not in known]
        if bad:
            raise ParameterError(f'unknown perturbation {", ".join(map(repr, bad))}; known: {", ".join(sorted(known))}')
        return cls(**{k: (int(v) if k == 'noise_seed' else float(v)) for k, v in values.items()})

    @classmethod
    def from_file(cls, path: str | Path, defaults: Mapping[str, Any] | None = None) -> Scenario:
        """A scenario from a JSON file {name: value} (a row of ``sma-wrist sweep``'s results.jsonl has them);
        axes the file does not name come from ``defaults``, then the nominal values."""
        try:
            data = json.loads(Path(path).read_text())
        except (OSError, ValueError) as e:
            raise ParameterError(f'scenario file {path}: {e}') from None
        if not isinstance(data, dict):
            raise ParameterError(f'scenario file {path}: expected a JSON object {{name: value}}')
        known = {f.name for f in dataclasses.fields(cls)}
        extra = {
            'index',
            'group',
            'controller',
            'plant',
            'max_error_pct',
            'rms_error_pct',
            'max_error_measured_pct',
            'sign_changes_per_s',
            'window',
        }  # a results.jsonl row carries its metrics too
        data = {k: v for k, v in data.items() if k in known or k not in extra}
        return cls.from_mapping({**(defaults or {}), **data})

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @property
    def sensors_ideal(self) -> bool:
        return self.temp_noise_C == 0 and self.temp_lag_s == 0 and self.angle_noise_rad == 0


def check_ranges(ranges: Mapping[str, tuple[float, float]]) -> dict[str, tuple[float, float]]:
    """Validated {name: (lo, hi)}: known names, lo <= hi, inside :data:`VALIDITY`."""
    out = {}
    for name, rng in ranges.items():
        if name not in BY_NAME:
            raise ParameterError(f'unknown perturbation {name!r}; known: {", ".join(BY_NAME)}')
        p = BY_NAME[name]
        try:
            lo, hi = (float(x) for x in rng)
        except (TypeError, ValueError):
            raise ParameterError(f'perturbation {name}: range {rng!r} must be (lo, hi)') from None
        if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
            raise ParameterError(f'perturbation {name}: range ({lo:g}, {hi:g}) needs finite lo <= hi')
        if lo < p.lower or hi > p.upper:
            raise ParameterError(
                f"perturbation {name}: range ({lo:g}, {hi:g}) {p.unit} is outside the model's "
                f'validity [{p.lower:g}, {p.upper:g}] ({p.description})'
            )
        out[name] = (lo, hi)
    return out


def sample(n: int, seed: int = 0, ranges: Mapping[str, tuple[float, float]] | None = None) -> list[Scenario]:
    """n scenarios drawn uniformly from ``ranges`` (default :data:`FAMILY`; axes not named stay nominal).

    Seeded: the same (n, seed, ranges) give the same scenarios; scenario i's sensor noise
    stream is seeded by (seed, i), so a scenario is reproducible on its own.
    """
    if not (isinstance(n, (int, np.integer)) and n >= 1):
        raise ParameterError(f'number of scenarios N = {n!r} must be an integer >= 1')
    rngs = check_ranges(FAMILY if ranges is None else ranges)
    gen = np.random.default_rng(seed)
    cols = {name: gen.uniform(lo, hi, n) if hi > lo else np.full(n, lo) for name, (lo, hi) in rngs.items()}
    return [
        Scenario(**{k: float(v[i]) for k, v in cols.items()}, noise_seed=int(seed) * 1_000_003 + i)
        for i in range(int(n))
    ]


# ------------------------------------------------------------------------------- the wire
def perturbed_hysteresis(
    base: SDGPIParams,
    shift_C: float = 0.0,
    stroke_scale: float = 1.0,
    load_kgf: float = 0.775,
    T_cold_C: float = 20.0,
    T_hot_C: float = 80.0,
) -> SDGPIParams:
    """The SD-GPI with transition temperatures shifted by ``shift_C`` [degC] and stroke scaled.

    See the module docstring; y_ref is the mirrored output's mean of the cold (cooled) and
    hot (heated) major-loop states at ``load_kgf`` (the pre-load's per-wire load).
    """
    if shift_C == 0.0 and stroke_scale == 1.0:
        return base
    s = float(stroke_scale)
    cold = initial_state(base, T_cold_C, load_kgf, branch='cooling')
    hot = initial_state(base, T_hot_C, load_kgf, branch='heating')
    y_ref = 0.5 * float(mirrored_output(base, cold, T_cold_C)[0] + mirrored_output(base, hot, T_hot_C)[0])
    return dataclasses.replace(
        warped_wire(base, Warp(shift_C, shift_C, stroke_scale=s, y_ref_mm=y_ref)),
        T_valid=base.T_valid,
        name=f'{base.name} shifted {shift_C:+.2f} degC, stroke x{s:.3f}',
    )


def scenario_params(
    sc: Scenario, base: PlantParams | None = None, hysteresis: SDGPIParams | None = None
) -> PlantParams:
    """PlantParams of one scenario (payload and sensors are not plant parameters)."""
    base = base or PlantParams()
    hp = perturbed_hysteresis(hysteresis or base.hysteresis, sc.transition_shift_C, sc.stroke_scale)
    p = mx.plant_params(
        {
            'tem_gain_err': sc.tem_gain_scale - 1.0,
            'loss_scale_err': sc.heat_loss_scale - 1.0,
            'ambient_offset_C': sc.ambient_offset_C,
        },
        base,
    )
    return p if hp is p.hysteresis else dataclasses.replace(p, hysteresis=hp)


# ------------------------------------------------------------------------------ the plant
@_jit
def _step_each(
    n_steps,
    u,
    thermal,
    q,
    qd,
    w3,
    heat2,
    T2,
    load2,
    comp2,
    payload,
    flags,
    th_coef,
    mech,
    stacked,
    edges,
    r,
    p,
    mem_c,
    mem_d,
    joint,
):  # pragma: no cover - compiled
    """plant_kernel.step_many for each scenario j with its own constants (row j of every constant);
    wire arrays scenario-major: w3 (N, 2, n), heat2, T2, load2, comp2 (N, 2)."""
    w_now, rk, env = plant_kernel.scratch(w3.shape[2])  # once, not per wrist
    for j in range(q.size):
        # reshape of a row keeps numba's C layout (a j:j+1 slice would be 'A': ~2x slower loops)
        plant_kernel.step_many_into(
            n_steps,
            u[j].reshape(1, 2),
            thermal[j].reshape(1, 2, 2),
            q[j : j + 1],
            qd[j : j + 1],
            w3[j],
            heat2[j],
            T2[j],
            load2[j],
            comp2[j],
            payload[j : j + 1],
            flags[j].reshape(1, 4),
            th_coef[j],
            mech[j],
            stacked[j],
            edges[j],
            r[j],
            p[j],
            mem_c[j],
            mem_d[j],
            joint[j],
            w_now,
            rk,
            env,
        )


@_jit
def _rest_each(q, w3, T2, load2, comp2, payload, mech, stacked, edges, r, p, mem_d, joint):  # pragma: no cover
    """WristPlant.rest_state's static equilibrium (40 bisections of muscle torque - gravity, loads
    solved against the frozen cooled memory from 0.8 kgf), then the loads committed, per scenario."""
    w_now = np.empty(w3.shape[2])
    for j in range(q.size):
        scale, c_el, k_f, m_lo, m_hi, m_max, tol = (
            mech[j, 1],
            mech[j, 2],
            mech[j, 3],
            mech[j, 4],
            mech[j, 5],
            mech[j, 6],
            mech[j, 7],
        )
        max_it = int(mech[j, 8])
        p0, e0, n_g_r, r_eff = mech[j, 9], mech[j, 13], mech[j, 14], mech[j, 15]
        lever, q_neutral, q_lo, q_hi, g = joint[j, 1], joint[j, 6], joint[j, 7], joint[j, 8], joint[j, 9]
        lo, hi = q_lo, q_hi
        for it in range(41):
            mid = 0.5 * (lo + hi)
            x_mm = 1e3 * r_eff * (mid - q_neutral)
            torque = 0.0
            for side in range(2):
                T = T2[j, side]
                y_mem = p0 * (mem_d[j, 0] * math.tanh(mem_d[j, 1] * T + mem_d[j, 2]) + mem_d[j, 3])
                y_geo = e0 - x_mm if side == 0 else e0 + x_mm
                m, dy, res = _solve_load(
                    T,
                    y_geo,
                    w3[j, side],
                    w_now,
                    y_mem,
                    load2[j, side],
                    stacked[j],
                    edges[j],
                    r[j],
                    p[j],
                    m_lo,
                    m_hi,
                    scale,
                    c_el,
                    k_f,
                    m_max,
                    tol,
                    max_it,
                )
                if it == 40:  # commit at the equilibrium
                    w3[j, side, :] = w_now
                    load2[j, side] = m
                    comp2[j, side] = dy
                torque += n_g_r * m if side == 0 else -n_g_r * m
            if it == 40:
                q[j] = mid
            elif torque - payload[j] * g * lever * math.cos(mid) > 0:
                lo = mid
            else:
                hi = mid


class VariedPlant(WristPlant):
    """N wrists, each with its own PlantParams (same dt, same number of play operators and load sections).

    Starts each wrist as :class:`WristPlant` does (thermal rest at zero drive, cooled memory, static
    equilibrium; the compiled load solve, so equal to WristPlant's start within the solve's
    tolerance) and steps all of them in one compiled call. :meth:`advance` is the only stepping
    method (the plant_sim node's). ``params`` is the first scenario's (limits, dt: shared by all).
    The wire arrays of ``state`` are scenario-major: rows [wrist 0 muscle 1, wrist 0 muscle 2,
    wrist 1 muscle 1, ...] (WristPlant stacks all muscles 1 first); use the properties.
    """

    def __init__(self, params: Sequence[PlantParams], payload_kg: Sequence[float]) -> None:
        if len(params) != len(payload_kg) or not params:
            raise ParameterError(
                f'VariedPlant needs one payload per parameter set, got {len(params)} and '
                f'{len(payload_kg)} (and at least one)'
            )
        dts = {p.dt for p in params}
        if len(dts) != 1:
            raise ParameterError(f'every scenario needs the same plant step, got {sorted(dts)} s')
        for p in params:
            if p.latent_heat_C() is not None:  # raises ParameterError: the SD-GPI has no fraction to carry it
                raise ParameterError('VariedPlant steps SD-GPI wires only: it cannot run a latent heat')
        self.params = params[0]
        self.scenario_params = list(params)
        self.n = n = len(params)
        self.muscles = MuscleModel(self.params.hysteresis, self.params.muscle)
        packed = [plant_kernel.pack_constants(p) for p in params]
        try:
            self._constants = tuple(
                np.ascontiguousarray(np.stack([c[i] for c in packed])) for i in range(len(packed[0]))
            )
        except ValueError:
            raise ParameterError(
                'scenarios differ in play operators or load sections: they cannot share one VariedPlant'
            ) from None
        payload = np.array(payload_kg, float)
        thermal = np.concatenate([th.rest_state(p.thermal, 1) for p in params])
        T2 = np.ascontiguousarray(thermal[:, :, th.MUSCLE_FACE])  # (N, 2)
        w3 = np.ascontiguousarray(
            np.stack([play_bounds(p.hysteresis, T2[j], np.full(2, 0.8))[1] for j, p in enumerate(params)])
        )
        load2, comp2, q = np.full((n, 2), 0.8), np.ones((n, 2)), np.zeros(n)
        _rest_each(
            q,
            w3,
            T2,
            load2,
            comp2,
            payload,
            self._constants[1],
            *self._constants[2:6],
            self._constants[7],
            self._constants[8],
        )
        self.state = PlantState(
            0.0,
            thermal,
            q,
            np.zeros(n),
            w3.reshape(2 * n, -1),
            np.zeros(2 * n, bool),
            T2.reshape(-1).copy(),
            load2.reshape(-1),
            comp2.reshape(-1),
            payload,
            self._no_flags(n),
        )
        self._kernel_constants = None
        self._kernel_arrays = None

    @property
    def muscle_temperature_C(self) -> FloatArray:
        return self.state.thermal[:, :, th.MUSCLE_FACE].copy()

    @property
    def wire_stress_Pa(self) -> FloatArray:
        return self.params.muscle.stress_Pa(self.state.load_kgf.reshape(-1, 2))

    @property
    def muscle_torque_Nm(self) -> FloatArray:
        m = self.state.load_kgf.reshape(-1, 2)
        return self._constants[1][:, 14] * (m[:, 0] - m[:, 1])

    def step(self, command_V: Any) -> PlantState:  # pragma: no cover - guard
        raise NotImplementedError('VariedPlant steps with advance() (compiled kernel) only')

    def advance(self, command_V: Any, n_steps: int = 1) -> PlantState:
        """``n_steps`` plant steps of every wrist under held commands (N, 2) [V] (clipped and flagged)."""
        s = self.state
        tp = self.params.thermal
        u = np.broadcast_to(np.asarray(command_V, dtype=float), (self.n, 2))
        if u.size <= 8 and all(tp.u_min_V <= v <= tp.u_max_V for v in u.ravel().tolist()):
            uc, clipped = kernel_array(u), np.zeros(self.n, bool)  # a copy of the read-only broadcast view
        else:
            check_finite('TEM command', u, 'V')
            uc = np.minimum(np.maximum(u, tp.u_min_V), tp.u_max_V)  # np.clip without its dispatch cost
            clipped = (uc != u).any(axis=1)
        n, k = self.n, s.w.shape[1]
        flags = np.zeros((n, 4), bool)
        _step_each(
            int(n_steps),
            uc,
            s.thermal,
            s.q,
            s.qd,
            s.w.reshape(n, 2, k),
            s.heating.reshape(n, 2),
            s.T_prev.reshape(n, 2),
            s.load_kgf.reshape(n, 2),
            s.compliance.reshape(n, 2),
            s.payload_kg,
            flags,
            *self._constants,
        )
        s.t += n_steps * self.params.dt
        s.flags = {
            'command_saturated': clipped,
            'over_temperature': flags[:, 0],
            'slack': flags[:, 1],
            'overload': flags[:, 2],
            'at_stop': flags[:, 3],
        }
        return s


def build_plant(
    scenarios: Sequence[Scenario], base: PlantParams | None = None, hysteresis: SDGPIParams | None = None
) -> VariedPlant:
    """The registry's factory for this family: one VariedPlant for the scenarios' wrists."""
    return VariedPlant([scenario_params(sc, base, hysteresis) for sc in scenarios], [sc.payload_kg for sc in scenarios])


# ----------------------------------------------------------------------------- the sensors
class SensorBank:
    """What the sensors of N wrists report, sampled every ``dt`` [s] (plant_sim's publish tick).

    Thermocouple: first-order lag (exact discretisation for a held input) then Gaussian noise;
    potentiometer: Gaussian noise. The velocity a real wrist gets is derived from the measured
    angle (filtered backward difference, :data:`VELOCITY_FILTER_S`) when the angle is noisy;
    with an ideal potentiometer the plant's own velocity passes (as plant_sim publishes it).
    Each scenario draws from its own stream (``noise_seed``), three normals per tick
    (T_1, T_2, q), so a scenario gives the same measurements alone or among others.
    """

    BLOCK = 1000  # ticks of noise drawn at once per scenario

    def __init__(self, scenarios: Sequence[Scenario], dt: float) -> None:
        self.dt = float(dt)
        self.n = len(scenarios)
        col = lambda name: np.array([getattr(s, name) for s in scenarios], float)  # noqa: E731
        lag = col('temp_lag_s')
        self.a_T = np.where(lag > 0, np.exp(-self.dt / np.where(lag > 0, lag, 1.0)), 0.0)[:, None]
        self.sd_T = col('temp_noise_C')[:, None]
        self.sd_q = col('angle_noise_rad')
        self.derive_velocity = self.sd_q > 0
        self.ideal = bool(all(s.sensors_ideal for s in scenarios))
        self._gens = [np.random.default_rng(s.noise_seed) for s in scenarios]
        self._noise = np.zeros((self.n, 0, 3))
        self._k = 0
        self._T: FloatArray | None = None
        self._q_prev: FloatArray | None = None
        self._qd = np.zeros(self.n)

    def _draw(self) -> FloatArray:
        if self._k >= self._noise.shape[1]:
            self._noise = np.stack([g.standard_normal((self.BLOCK, 3)) for g in self._gens])
            self._k = 0
        e = self._noise[:, self._k]
        self._k += 1
        return e

    def measure(
        self, T_true: FloatArray, q_true: FloatArray, qd_true: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """(T_measured (N, 2), q_measured (N,), qdot reported (N,)) for one tick."""
        if self.ideal:
            return T_true, q_true, qd_true
        e = self._draw()
        self._T = T_true.copy() if self._T is None else self.a_T * self._T + (1.0 - self.a_T) * T_true
        T = self._T + self.sd_T * e[:, :2]
        q = q_true + self.sd_q * e[:, 2]
        if self._q_prev is None:
            self._qd = np.zeros(self.n)
        else:
            raw = (q - self._q_prev) / self.dt
            self._qd = self._qd + self.dt / (VELOCITY_FILTER_S + self.dt) * (raw - self._qd)
        self._q_prev = q
        return T, q, np.where(self.derive_velocity, self._qd, qd_true)
