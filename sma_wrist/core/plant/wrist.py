"""The coupled wrist plant: TEM drive -> temperatures -> wire loads -> joint angle.

One step of length dt (doc/explanation/model.md):

1. TEM heat balance (Eqs. 4.13-4.14, :mod:`sma_wrist.core.thermal.heat_balance`, or the Peltier form's
   Eqs. P.1-P.3, :mod:`sma_wrist.core.thermal.peltier`), RK4, from the drive commands of both layers -> muscle
   temperatures T_i.
2. Chain kinematics (Eq. 4.17) -> bundle elongations y_1 = e0 - x, y_2 = e0 + x,
   x = R_eff (q - q_neutral).
3. Per-wire loads m_i from the SD-GPI elongation-load relation against frozen memory
   (:class:`sma_wrist.core.hysteresis.muscle.MuscleModel`), then the memory is committed.
4. Joint (Eq. 4.18): torque (F_1 - F_2) R_eff with F_i = N_w m_i g, linearly implicit
   Euler with the bundles' stiffness from the load solve.
5. Latent heat (Peltier form, Eq. P.4, a phase-fraction wire only): muscle node i moves by
   latent_C_i (xi_i,new - xi_i,old) [degC], xi_i the martensite fraction committed in step 3 (the
   step's integral of latent_C dxi/dt, taken once the fraction is known: it falls on heating, so
   the node absorbs heat, and rises on cooling, releasing it).

Everything is vectorised over N scenarios (payloads, commands, initial states); both
muscles of all scenarios are stacked on one axis (2N) so each numpy call serves all.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sma_wrist.core import jit
from sma_wrist.core.errors import ModelInputError, ParameterError, check_finite, check_range
from sma_wrist.core.hysteresis.default_params import default_sdgpi
from sma_wrist.core.hysteresis.muscle import MuscleGeometry, MuscleModel
from sma_wrist.core.hysteresis.phase_fraction import XI, PhaseFractionMuscle, PhaseFractionWire, cooled_memory
from sma_wrist.core.hysteresis.sdgpi import SDGPIParams, play_bounds
from sma_wrist.core.joint.dynamics import G, JointParams, joint_step
from sma_wrist.core.plant import kernel as plant_kernel
from sma_wrist.core.thermal import heat_balance as th
from sma_wrist.core.thermal import peltier as pe

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class PlantParams:
    """Everything that defines the simulated wrist."""

    hysteresis: SDGPIParams = field(default_factory=default_sdgpi)
    #: the model's wire where it is not the SD-GPI: a phase-fraction wire (``wire_file``, form ``phase_fraction``);
    #: None: the SD-GPI of ``hysteresis``. The compensator inverts ``hysteresis`` either way
    wire: PhaseFractionWire | None = None
    muscle: MuscleGeometry = field(default_factory=MuscleGeometry)
    joint: JointParams = field(default_factory=JointParams)
    #: TEM heat balance; the plant clips commands at the *driver rating* (+-24 V), not at the
    #: heat balance's hold limits (-12/+13 V), which the TEM controller enforces only while a
    #: face is hot (tem_control.DriveLimits, doc/explanation/model.md).
    thermal: th.ThermalParams = field(default_factory=lambda: th.ThermalParams().with_limits(-24.0, 24.0))
    #: the model's heat balance where it is not Table 4.9's form: a Peltier two-node form per layer
    #: (:mod:`sma_wrist.core.thermal.peltier`, ``heat_balance_file``); ``thermal`` then keeps the command limits
    #: and the window. None: ``thermal``'s Eqs. 4.13-4.14.
    heat_balance: pe.PeltierParams | None = None
    #: Bundle elongation at q_neutral [mm], set by the pre-load calibration of Sec. 2.2.3:
    #: with it the +-30 deg range is reachable up to ~0.7 kg at 0.09 m in the TEM-reachable window (doc/explanation/model.md).
    preload_elongation_mm: float = 1.98
    dt: float = 1e-3  # plant step [s]
    load_tolerance_mm: float = 1e-7  # residual of the wire-load solve (muscle.py Eq. 1)
    max_muscle_temperature_C: float = 90.0  # beyond: over-temperature flag
    #: 'auto': WristPlant.advance uses the compiled kernel (plant_kernel) when numba is
    #: installed; 'numpy': always the numpy path. Same numbers either way (test_plant_kernel).
    engine: str = 'auto'

    def __post_init__(self) -> None:
        if not (0 < self.dt <= 0.01):
            raise ModelInputError('plant step dt', self.dt, '(0, 0.01]', 's')
        if self.engine not in ('auto', 'numpy'):
            raise ModelInputError('plant engine', self.engine, "{'auto', 'numpy'}")
        if not (0 < self.load_tolerance_mm <= 1e-3):
            raise ModelInputError('load_tolerance_mm', self.load_tolerance_mm, '(0, 1e-3]', 'mm')

    @classmethod
    def from_files(
        cls,
        hysteresis_file: str | Path | None = None,
        thermal_file: str | Path | None = None,
        heat_balance_file: str | Path | None = None,
        wire_file: str | Path | None = None,
        **fields: Any,
    ) -> PlantParams:
        """The wrist with the wire of ``hysteresis_file`` (``sma-wrist identify hysteresis``; empty: the built-in set)
        and the TEMs of ``thermal_file`` (``identify thermal``; empty: Table 4.9), still clipped at the driver rating,
        their heat balance that of ``heat_balance_file`` where given (the Peltier form, ``sma-wrist commission``;
        empty: Table 4.9's form of the thermal file); ``wire_file``: the model's wire where it is not that SD-GPI
        (``wire.yaml`` of ``sma-wrist commission``, form ``phase_fraction``; empty: the SD-GPI); ``fields``: the
        other fields. What plant_sim, hardware_bridge and diagnose build from their parameters."""
        from sma_wrist.core.hysteresis.params_file import hysteresis_params

        if wire_file:
            from sma_wrist.core.hysteresis.wire_file import load_wire_file

            fields = {**fields, 'wire': load_wire_file(wire_file)}
        p = cls(hysteresis=hysteresis_params(hysteresis_file or None), **fields)
        if thermal_file:  # identified TEMs; the plant still clips at the driver rating
            from sma_wrist.core.thermal.params_file import load_thermal_file

            lim = p.thermal
            p = replace(p, thermal=load_thermal_file(thermal_file).with_limits(lim.u_min_V, lim.u_max_V))
        if heat_balance_file:
            from sma_wrist.core.thermal.params_file import load_heat_balance_file

            p = replace(p, heat_balance=load_heat_balance_file(heat_balance_file))
        return p

    def rest_thermal(self, n: int) -> FloatArray:
        """Zero-drive faces (n, 2, 2) [degC] of the model's heat balance (Table 4.9's form or ``heat_balance``)."""
        if self.heat_balance is not None:
            return pe.rest_state(self.heat_balance, n)
        return th.rest_state(self.thermal, n)

    def latent_heat_C(self) -> FloatArray | None:
        """The muscle nodes' latent heat (2,) [degC per full transformation] the plant applies (Eq. P.4,
        ``heat_balance.latent_C``, layer i under muscle i); None where there is none (Table 4.9's form or latent_C
        0). Raises ParameterError where it is set and the wire is the SD-GPI: that wire has no martensite fraction
        whose change would carry the heat, and a plant that dropped the term would not be the model its file names."""
        hb = self.heat_balance
        if hb is None or not any(hb.latent_C):
            return None
        if self.wire is None:
            raise ParameterError(
                f'heat balance latent_C = [{hb.latent_C[0]:g}, {hb.latent_C[1]:g}] degC needs a phase-fraction wire: '
                "the latent heat moves a muscle node by latent_C per change of its wire's martensite fraction "
                '(Eq. P.4), and the SD-GPI wire has no fraction; name a wire_file (form phase_fraction) or set '
                'latent_C to [0, 0] in the heat balance file'
            )
        return np.array(hb.latent_C, dtype=float)

    def thermal_step(self, state: FloatArray, command_V: FloatArray, dt: float) -> FloatArray:
        """One RK4 step of the model's heat balance, commands (N, 2) in range [V] (th.step or peltier.step)."""
        if self.heat_balance is not None:
            return pe.step(self.heat_balance, state, command_V, dt)
        return th.step(self.thermal, state, command_V, dt, validate=False)


@dataclass
class PlantState:
    """State of N wrists."""

    t: float
    thermal: FloatArray
    q: FloatArray  # (N,) rad
    qd: FloatArray  # (N,) rad/s
    w: FloatArray  # (2N, n) play memory; rows [muscle 1 of all scenarios, then muscle 2]
    heating: BoolArray  # (2N,)
    T_prev: FloatArray  # (2N,)
    load_kgf: FloatArray  # (2N,) per-wire load
    compliance: FloatArray  # (2N,) mm/kgf
    payload_kg: FloatArray  # (N,)
    flags: dict[str, BoolArray] = field(default_factory=dict)

    def copy(self) -> PlantState:
        return PlantState(
            self.t,
            self.thermal.copy(),
            self.q.copy(),
            self.qd.copy(),
            self.w.copy(),
            self.heating.copy(),
            self.T_prev.copy(),
            self.load_kgf.copy(),
            self.compliance.copy(),
            self.payload_kg.copy(),
            {k: v.copy() for k, v in self.flags.items()},
        )


def _within(u: FloatArray, lo: float, hi: float) -> bool:
    """Every element of u in [lo, hi] (False for NaN). A wrist's two commands are checked as
    floats: numpy's min and max cost ~3 us on two numbers, called every tick."""
    if u.size <= 8:
        return all(lo <= v <= hi for v in u.ravel().tolist())
    return bool(u.min() >= lo and u.max() <= hi)  # NaN propagates into both


#: PlantState arrays plant_kernel.step_many advances in place, in its argument order
KERNEL_STATE = ('thermal', 'q', 'qd', 'w', 'heating', 'T_prev', 'load_kgf', 'compliance', 'payload_kg')


class WristPlant:
    """N simulated wrists stepped together. See the module docstring for the step."""

    def __init__(self, params: PlantParams | None = None, payload_kg: ArrayLike = 0.3, n: int | None = None) -> None:
        self.params = params or PlantParams()
        payload = np.atleast_1d(np.asarray(payload_kg, dtype=float))
        if n is not None:
            payload = np.broadcast_to(payload, (n,)).copy()
        check_range('payload', payload, 0.0, 2.0, 'kg')
        self.n = payload.size
        self.muscles = MuscleModel(self.params.hysteresis, self.params.muscle)
        #: the phase-fraction bundles where the model's wire is one (PlantParams.wire); their memory (2N, 5) is
        #: ``state.w`` (the compiled step: plant_kernel.fraction_step_segments)
        self.fraction = None
        #: (params, their latent_heat_C()): the muscle nodes' latent heat (2,) [degC] of Eq. P.4 or None; asked here
        #: so that a plant whose wire cannot carry it is refused before it runs
        self._latent = (self.params, self.params.latent_heat_C())
        if self.params.wire is not None:
            mg = self.params.muscle
            self.fraction = PhaseFractionMuscle(self.params.wire, mg.wire_length_mm, mg.wire_area_m2, mg.max_load_kgf)
        self._kernel_constants: tuple[PlantParams, tuple[np.ndarray, ...]] | None = None
        self._kernel_arrays: tuple[np.ndarray, ...] | None = None  # state arrays checked for the kernel
        self.state = self.rest_state(payload)
        if self._compiled:
            # the first compiled step loads (or compiles) the kernel: 0.1-0.3 s from numba's cache.
            # Pay it here, not in the first step of a loop that runs against a clock (the device
            # emulator's thread, a plant_sim under ROS): one step on a copy, then the state is restored
            start = self.state.copy()
            self.advance(np.zeros((self.n, 2)), 1)
            self.state = start

    @property
    def _compiled(self) -> bool:
        """Whether :meth:`advance` steps in the compiled kernel (numba installed, engine 'auto')."""
        return jit.AVAILABLE and self.params.engine == 'auto'

    # ----------------------------------------------------------------- set-up
    def rest_state(self, payload_kg: FloatArray, q0: ArrayLike | None = None) -> PlantState:
        """Wrists at thermal rest (zero drive), cooled from hot, at static equilibrium (or q0)."""
        p = self.params
        n = payload_kg.size
        thermal = p.rest_thermal(n)
        T = th.muscle_temperature(p.thermal, thermal).T.reshape(-1)  # (2N,)
        m0 = np.full(2 * n, 0.8)
        if self.fraction is not None:
            T = np.minimum(np.maximum(T, p.wire.T_valid[0]), p.wire.T_valid[1])
            memory = cooled_memory(self.fraction.wc, T, m0)
        else:
            memory = play_bounds(p.hysteresis, T, m0)[1].copy()
        state = PlantState(
            0.0,
            thermal,
            np.full(n, p.joint.q_neutral_rad),
            np.zeros(n),
            memory,
            np.zeros(2 * n, bool),
            T.copy(),
            m0,
            np.ones(2 * n),
            payload_kg.copy(),
        )
        if q0 is None:
            state.q = self._static_equilibrium(state)
        else:
            state.q = np.broadcast_to(np.asarray(q0, float), (n,)).copy()
        self._update_loads(state, T, commit=True)
        state.flags = self._no_flags(n)
        return state

    def _no_flags(self, n: int) -> dict[str, BoolArray]:
        return {k: np.zeros(n, bool) for k in ('command_saturated', 'over_temperature', 'slack', 'overload', 'at_stop')}

    def _static_equilibrium(self, state: PlantState) -> FloatArray:
        """Angle where muscle torque balances gravity, by bisection (torque falls with q)."""
        jp = self.params.joint
        lo = np.full(self.n, jp.q_min_rad)
        hi = np.full(self.n, jp.q_max_rad)
        T = state.T_prev
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            state.q = mid
            tau = self._update_loads(state, T, commit=False)[0] - jp.gravity_torque(mid, state.payload_kg)
            lo = np.where(tau > 0, mid, lo)
            hi = np.where(tau > 0, hi, mid)
        return 0.5 * (lo + hi)

    # ------------------------------------------------------------------ step
    def _update_loads(
        self, state: PlantState, T: FloatArray, commit: bool
    ) -> tuple[FloatArray, FloatArray, BoolArray, BoolArray]:
        """Solve the wire loads at the current angle; returns (torque, stiffness, slack, overload)."""
        p = self.params
        x = p.joint.chain_displacement_mm(state.q)
        y_geo = np.concatenate([p.preload_elongation_mm - x, p.preload_elongation_mm + x])
        if self.fraction is not None:
            sol = self.fraction.solve_load(T, y_geo, state.w, state.load_kgf, self.params.load_tolerance_mm)
        else:
            sol = self.muscles.solve_load(
                T, y_geo, state.w, state.heating, state.load_kgf, self.params.load_tolerance_mm
            )
        if commit:
            state.w = sol.memory  # the memory at the root: what MuscleModel.commit would give
            state.load_kgf = sol.load_kgf
            state.compliance = sol.compliance_mm_per_kgf
        return self._torque_and_stiffness(sol.load_kgf, sol.compliance_mm_per_kgf) + (
            sol.slack[: self.n] | sol.slack[self.n :],
            sol.overload[: self.n] | sol.overload[self.n :],
        )

    def _torque(self, load: FloatArray) -> FloatArray:
        """(N,) net muscle torque [N m] of the stacked (2N,) wire loads [kgf]: N g R_eff (m1 - m2)."""
        p = self.params
        return p.muscle.n_wires * G * p.joint.r_eff_m * (load[: self.n] - load[self.n :])

    def _torque_and_stiffness(self, load: FloatArray, compliance: FloatArray) -> tuple[FloatArray, FloatArray]:
        p = self.params
        n_g_r = p.muscle.n_wires * G * p.joint.r_eff_m
        c1, c2 = compliance[: self.n], compliance[self.n :]
        torque = self._torque(load)
        # d tau/dq = -N g R_eff (R_mm / c1 + R_mm / c2) with R_mm = dx/dq in mm/rad
        stiffness = n_g_r * 1e3 * p.joint.r_eff_m * (1.0 / c1 + 1.0 / c2)
        return torque, stiffness

    def _commands(self, command_V: ArrayLike) -> tuple[np.ndarray, np.ndarray | None]:
        """Commands (N, 2) [V] clipped to the TEM limits, and per wrist whether one was clipped (None:
        none was, the common case kept cheap). Non-finite commands raise ModelInputError."""
        tp = self.params.thermal
        u = np.asarray(command_V, dtype=float)
        if u.shape != (self.n, 2):
            u = np.broadcast_to(u, (self.n, 2))
        if _within(u, tp.u_min_V, tp.u_max_V):
            return u, None
        check_finite('TEM command', u, 'V')
        uc = np.minimum(np.maximum(u, tp.u_min_V), tp.u_max_V)
        return uc, (uc != u).any(axis=1)

    def step(self, command_V: ArrayLike) -> PlantState:
        """Advance all wrists by dt under TEM drive commands of shape (N, 2) [V].

        Commands beyond the TEM limits are clipped and flagged (``flags['command_saturated']``),
        non-finite commands raise ModelInputError.
        """
        p = self.params
        s = self.state
        u, clipped = self._commands(command_V)
        if self._latent[0] is not p:
            self._latent = (p, p.latent_heat_C())
        latent = self._latent[1]
        xi_old = None if latent is None else s.w[:, XI].copy()
        # command in range, dt checked by PlantParams (<= 0.01 s < dt_max_s), state finite by construction
        s.thermal = p.thermal_step(s.thermal, u, p.dt)
        self._mechanics(s.thermal[:, :, th.MUSCLE_FACE].T.reshape(-1))
        if xi_old is not None:  # step 5 (Eq. P.4): the wires' fractions are committed, rows muscle 1 then muscle 2
            s.thermal[:, :, th.MUSCLE_FACE] += latent * (s.w[:, XI] - xi_old).reshape(2, self.n).T
        if clipped is not None:
            s.flags['command_saturated'] = clipped
        return s

    def advance(self, command_V: ArrayLike, n_steps: int = 1) -> PlantState:
        """``n_steps`` steps under one held command (N, 2) [V], as :meth:`step` in a loop.

        With numba installed (and ``engine='auto'``) the steps run in the compiled kernel of
        :mod:`sma_wrist.core.plant.kernel` (~1 us per wrist-step instead of ~0.3 ms); flags
        are ORed over the steps. This is what the plant_sim node calls once per tick.
        """
        p = self.params
        if not self._compiled:
            flags = self._no_flags(self.n)
            for _ in range(n_steps):
                s = self.step(command_V)
                for k, v in s.flags.items():
                    flags[k] = flags[k] | v
            s.flags = flags
            return s
        s = self.state
        uc, clipped = self._commands(command_V)
        uc = jit.kernel_array(uc)  # whatever the caller passed (a read-only or broadcast array)
        if clipped is None:
            clipped = np.zeros(self.n, bool)
        if self._kernel_constants is None or self._kernel_constants[0] is not p:
            self._kernel_constants = (p, plant_kernel.pack_constants(p))
        arrays = (s.thermal, s.q, s.qd, s.w, s.heating, s.T_prev, s.load_kgf, s.compliance, s.payload_kg)
        if self._kernel_arrays is None or any(a is not b for a, b in zip(arrays, self._kernel_arrays)):
            # the kernel writes the state in place: it needs its own writeable, C-ordered arrays
            for name, a in zip(KERNEL_STATE, arrays):
                setattr(s, name, jit.kernel_array(a, a.dtype))
            self._kernel_arrays = arrays = tuple(getattr(s, name) for name in KERNEL_STATE)
        flags = np.zeros((self.n, 4), bool)
        if self.fraction is not None:
            out = np.empty((1, self.n, 2, 2)), np.empty((1, self.n)), np.empty((1, self.n))
            steps = np.array([int(n_steps)], dtype=np.int64)
            plant_kernel.fraction_step_segments(steps, uc[None], *arrays, flags, *self._kernel_constants[1], *out)
        else:
            plant_kernel.step_many(int(n_steps), uc, *arrays, flags, *self._kernel_constants[1])
        s.t += n_steps * p.dt
        s.flags = {
            'command_saturated': clipped,
            'over_temperature': flags[:, 0],
            'slack': flags[:, 1],
            'overload': flags[:, 2],
            'at_stop': flags[:, 3],
        }
        return s

    def advance_segments(
        self, commands_V: FloatArray, n_steps: np.ndarray
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """K segments at once: ``n_steps[k]`` steps under commands ``commands_V[k]`` (N, 2) [V], as :meth:`advance`
        in a loop (commands clipped to the TEM limits; flags ORed over the segments, the last segment's without
        numba). Returns the state after each segment:
        thermal (K, N, 2, 2) [degC], q (K, N) [rad], qd (K, N) [rad/s]."""
        p = self.params
        tp = p.thermal
        u = np.ascontiguousarray(np.broadcast_to(np.asarray(commands_V, dtype=float), (len(n_steps), self.n, 2)))
        if not np.isfinite(u).all():
            check_finite('TEM command', u, 'V')
        clipped = (u < tp.u_min_V) | (u > tp.u_max_V)
        u = np.minimum(np.maximum(u, tp.u_min_V), tp.u_max_V)
        K = u.shape[0]
        if K == 0:
            return np.empty((0, self.n, 2, 2)), np.empty((0, self.n)), np.empty((0, self.n))
        thermal = np.empty((K, self.n, 2, 2))
        q = np.empty((K, self.n))
        qd = np.empty((K, self.n))
        if not self._compiled:
            for k in range(K):
                s = self.advance(u[k], int(n_steps[k]))
                thermal[k], q[k], qd[k] = s.thermal, s.q, s.qd
            s.flags['command_saturated'] = clipped.any(axis=(0, 2))
            return thermal, q, qd
        s = self.state
        self.advance(u[0], 0)  # the kernel's constants and writeable state arrays, as advance prepares them
        flags = np.zeros((self.n, 4), bool)
        steps = np.ascontiguousarray(n_steps, dtype=np.int64)
        kernel = plant_kernel.fraction_step_segments if self.fraction is not None else plant_kernel.step_segments
        kernel(steps, u, *self._kernel_arrays, flags, *self._kernel_constants[1], thermal, q, qd)
        s.t += int(steps.sum()) * p.dt
        s.flags = {
            'command_saturated': clipped.any(axis=(0, 2)),
            'over_temperature': flags[:, 0],
            'slack': flags[:, 1],
            'overload': flags[:, 2],
            'at_stop': flags[:, 3],
        }
        return thermal, q, qd

    def step_mechanics(self, muscle_temperature_C: ArrayLike) -> PlantState:
        """Advance loads and joint by dt at given (N, 2) muscle temperatures (steps 2-4).

        Used by :meth:`step`, and on its own to replay recorded temperatures through the
        hysteresis and joint without the thermal model (model-discrepancy replay).
        Non-finite temperatures raise ModelInputError; temperatures above
        ``max_muscle_temperature_C`` are flagged (``over_temperature``) and beyond the
        hysteresis model's validity window they are clamped to it (and flagged).
        """
        T = np.broadcast_to(np.asarray(muscle_temperature_C, dtype=float), (self.n, 2)).T.reshape(-1)
        if not np.isfinite(T.sum()):
            check_finite('muscle temperature', T, 'degC')
        return self._mechanics(T)

    def _mechanics(self, T: FloatArray) -> PlantState:
        """Steps 2-4 for stacked (2N,) muscle temperatures (muscle 1 of all scenarios, then muscle 2)."""
        p = self.params
        s = self.state
        n = self.n
        hot = T > p.max_muscle_temperature_C
        t_lo, t_hi = p.hysteresis.T_valid if p.wire is None else p.wire.T_valid
        if T.min() < t_lo or T.max() > t_hi:
            T = np.minimum(np.maximum(T, t_lo), t_hi)
        dT = T - s.T_prev
        heating = s.heating.copy()
        heating[dT > 0] = True
        heating[dT < 0] = False
        s.heating = heating
        s.T_prev = T
        torque, stiffness, slack, overload = self._update_loads(s, T, commit=True)
        jp = p.joint
        s.q, s.qd, _ = joint_step(jp, s.q, s.qd, torque, stiffness, s.payload_kg, p.dt)
        s.t += p.dt
        s.flags = {
            'command_saturated': np.zeros(n, bool),
            'over_temperature': hot[:n] | hot[n:],
            'slack': slack,
            'overload': overload,
            'at_stop': (s.q <= jp.q_min_rad) | (s.q >= jp.q_max_rad),
        }
        return s

    # --------------------------------------------------------------- outputs
    @property
    def muscle_temperature_C(self) -> FloatArray:
        """(N, 2) muscle temperatures."""
        return th.muscle_temperature(self.params.thermal, self.state.thermal)

    @property
    def wire_stress_Pa(self) -> FloatArray:
        """(N, 2) per-wire stresses."""
        return self.params.muscle.stress_Pa(self.state.load_kgf.reshape(2, -1).T)

    @property
    def muscle_torque_Nm(self) -> FloatArray:
        """(N,) net muscle torque at the output shaft."""
        return self._torque(self.state.load_kgf)

    def simulate(self, commands_V: ArrayLike, record_every: int = 1) -> dict[str, FloatArray]:
        """Open-loop run under a command history of shape (K, N, 2) or (K, 2); returns recorded arrays."""
        u = np.asarray(commands_V, dtype=float)
        if u.ndim == 2:
            u = u[:, None, :]
        k_total = u.shape[0]
        rows = range(0, k_total, record_every)
        out = {
            k: np.empty((len(rows),) + shape)
            for k, shape in (
                ('t', ()),
                ('q', (self.n,)),
                ('qd', (self.n,)),
                ('T', (self.n, 2)),
                ('stress', (self.n, 2)),
            )
        }
        j = 0
        for k in range(k_total):
            self.step(u[k])
            if k % record_every == 0:
                out['t'][j] = self.state.t
                out['q'][j] = self.state.q
                out['qd'][j] = self.state.qd
                out['T'][j] = self.muscle_temperature_C
                out['stress'][j] = self.wire_stress_Pa
                j += 1
        return out
