"""N-scenario paths of the per-wrist compositions the nodes run: the joint controller and the TEM loop.

The laws themselves are vectorised in core (AdaptiveController, PID, InverseCompensator, the
plant); the two compositions around them run one wrist per object. These are the same
computations for N wrists in lockstep (same reference, same sample times), checked against the
one-wrist objects by test_sweep (``JointControllerBank`` == ``JointController``,
``TemLoopBank`` == ``TemLoop``, sample by sample).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sma_wrist.core.control import tem_kernel
from sma_wrist.core.control.adaptive import AdaptiveController
from sma_wrist.core.control.joint_controller import (
    REVERSAL_STEP_RAD,
    JointControllerParams,
    output_filter_step,
    reference_ahead,
    time_to_meet,
)
from sma_wrist.core.control.pid import PID
from sma_wrist.core.control.tem import (
    CHATTER_LIMIT_PER_S,
    CHATTER_RATE_FILTER_S,
    CHATTER_WINDOW_S,
    RANGE_REFRESH_S,
    ChatterGuard,
    DriveLimits,
    TemControlParams,
    TemLoop,
    target_prefilter,
)
from sma_wrist.core.errors import ModelInputError
from sma_wrist.core.jit import _jit
from sma_wrist.core.plant.wrist import PlantParams
from sma_wrist.core.thermal import heat_balance as th
from sma_wrist.core.thermal.online import OnlineThermalParams, ThermalScaleEstimator

FloatArray = NDArray[np.float64]


@_jit
def _reversal_lead_many(
    q, q_d, qdot_d, qddot_d, lead_s, step, hold_on, hold_q, hold_after, target
):  # pragma: no cover - compiled
    """JointController._reversal_lead for each wrist j, compiled (q and its reference q_d, qdot_d, qddot_d (n,)
    [rad, rad/s, rad/s^2]): target[j] = the angle whose strain is asked for; hold_on, hold_q, hold_after (n,) the
    latch per wrist, in place."""
    for j in range(q.shape[0]):
        r, rd = q_d[j], qdot_d[j]
        e = r - q[j]
        s_meet, after = time_to_meet(e, rd, qddot_d[j])
        turns = after != math.copysign(1.0, rd) or (abs(e) > step and after != math.copysign(1.0, e))
        if not hold_on[j] and s_meet < 2.0 * lead_s and turns:
            hold_on[j] = True
            hold_q[j] = q[j] + after * step
            hold_after[j] = after
        target[j] = r
        if hold_on[j]:
            turned = rd * hold_after[j] > 0
            if (turned and (r - hold_q[j]) * hold_after[j] >= 0) or (not turned and after != hold_after[j]):
                hold_on[j] = False
            else:
                target[j] = hold_q[j]


@_jit
def _temperature_map(deviation, mid, lo, hi, flag, T, saturated):  # pragma: no cover - compiled
    """JointController's temperatures in direct_adaptive mode, per wrist j and muscle i:
    T[j, i] = mid + deviation[j, i] clipped to [lo, hi] [degC] (deviation = the filtered (F - F_pre) / k);
    saturated[j] = the law's flag[j] or a clipped T. numpy's element-wise operations in their order."""
    for j in range(deviation.shape[0]):
        sat = flag[j]
        for i in range(2):
            t = mid + deviation[j, i]
            tc = min(max(t, lo), hi)
            T[j, i] = tc
            sat = sat or tc != t
        saturated[j] = sat


class JointControllerBank:
    """:class:`sma_wrist.core.control.joint_controller.JointController` for n wrists of one mode.

    ``update`` returns (force (n, 2) [N] or None, strain (n, 2), T_d (n, 2) [degC] or None,
    saturated (n,)), what the one-wrist object returns per wrist.
    """

    def __init__(self, params: JointControllerParams, n: int, plant: PlantParams | None = None) -> None:
        self.params = params
        self.plant = plant or PlantParams()
        self.n = n
        p = params
        self.adaptive = AdaptiveController(replace(p.adaptive, mode=p.mode), n) if p.mode != 'pid' else None
        self.pid = PID(p.pid, n) if p.mode == 'pid' else None
        # the bank's adaptive inputs (5, n), filled in place each tick (AdaptiveController.update_stacked)
        self._x = np.empty((5, n))
        # strain_at's constants read once (the properties are recomputed on every access); the same operations
        j = self.plant.joint
        self._mm_per_rad, self._q_neutral = 1e3 * j.r_eff_m, j.q_neutral_rad
        self._e0, self._wire_mm = self.plant.preload_elongation_mm, self.plant.muscle.wire_length_mm
        self.hold_on = np.zeros(n, np.bool_)
        self.hold_q = np.zeros(n)
        self.hold_after = np.zeros(n)
        self._target = np.zeros(n)
        self.u_filtered: FloatArray | None = None  # the output filter's state (output_filter_s), (n,) or (n, 2) [degC]

    def strain_at(self, q: FloatArray) -> FloatArray:
        """(n, 2) bundle strains at angles q (Eq. 4.17)."""
        # JointParams.chain_displacement_mm: 1e3 r_eff (q - q_neutral), in its order of operations
        x = self._mm_per_rad * (np.asarray(q, float) - self._q_neutral)
        e0 = self._e0
        out = np.empty(np.shape(x) + (2,))  # [e0 - x, e0 + x] / L without np.stack's per-call cost
        np.subtract(e0, x, out=out[..., 0])
        np.add(e0, x, out=out[..., 1])
        out /= self._wire_mm
        return out

    def _strain_rows(self, q: FloatArray) -> FloatArray:
        """(n, 2): each wrist's bundle strains at its reference angle q (n,)."""
        x = self._mm_per_rad * (q - self._q_neutral)  # strain_at's operations element by element: the same numbers
        out = np.empty((self.n, 2))
        out[:, 0] = (self._e0 - x) / self._wire_mm
        out[:, 1] = (self._e0 + x) / self._wire_mm
        return out

    def update(
        self, q: FloatArray, qdot: FloatArray, q_d: ArrayLike, qdot_d: ArrayLike, qddot_d: ArrayLike, dt: float
    ) -> tuple[FloatArray | None, FloatArray, FloatArray | None, NDArray[np.bool_]]:
        """One control step of every wrist; the reference (q_d, qdot_d, qddot_d) is one for all or (n,), one per
        wrist (each starts from its own angle: trajectory_generator's soft start)."""
        p = self.params
        q_d, qdot_d, qddot_d = (np.broadcast_to(np.asarray(v, float), (self.n,)) for v in (q_d, qdot_d, qddot_d))
        lo, hi = p.temperature_min_C, p.temperature_max_C
        q_now = q_d  # the desired strain stays the one at q_d(t), as JointController's
        if p.reference_lead_s > 0:
            q_d, qdot_d = reference_ahead(q_d, qdot_d, qddot_d, p.reference_lead_s)
        if self.pid is not None:
            o = self.pid.update(q, q_d, dt)
            self.u_filtered = u = output_filter_step(self.u_filtered, o.u, dt, p.output_filter_s)
            T = np.stack([p.temperature_mid_C + u, p.temperature_mid_C - u], axis=-1)
            Tc = np.minimum(np.maximum(T, lo), hi)  # np.clip, without its dispatch cost
            return None, self._strain_rows(q_now), Tc, o.saturated | (Tc != T).any(axis=1)
        assert self.adaptive is not None
        x = self._x
        x[0], x[1], x[2], x[3], x[4] = q, qdot, q_d, qdot_d, qddot_d
        out = self.adaptive.update_stacked(x, dt)
        force, saturated = out[:, :2], out[:, 7] != 0.0  # ControlOutput's force_1_N, force_2_N and saturated
        if p.mode == 'inverse_adaptive':
            _reversal_lead_many(
                np.ascontiguousarray(q, float),
                np.ascontiguousarray(q_d),
                np.ascontiguousarray(qdot_d),
                np.ascontiguousarray(qddot_d),
                float(p.reversal_lead_s),
                REVERSAL_STEP_RAD,
                self.hold_on,
                self.hold_q,
                self.hold_after,
                self._target,
            )
            return force, self.strain_at(self._target), None, saturated
        Tc, sat_T = np.empty((self.n, 2)), np.empty(self.n, np.bool_)
        self.u_filtered = output_filter_step(
            self.u_filtered, (force - p.adaptive.preload_N) / p.force_per_degC_N, dt, p.output_filter_s
        )
        _temperature_map(self.u_filtered, p.temperature_mid_C, lo, hi, saturated, Tc, sat_T)
        return force, self._strain_rows(q_now), Tc, sat_T


@_jit
def _control_many(
    x,
    rate,
    T_d_prev,
    rng,
    command,
    flags,
    T_meas,
    T_d,
    dt_obs,
    dt_law,
    has_prev,
    refresh,
    th_coef,
    cfg,
    candidates,
    status,
):  # pragma: no cover - compiled
    """tem_kernel.control_sample for each wrist j (row j of every state array, of th_coef and of cfg: the chatter
    guard sets a wrist's rate filter), its work arrays allocated once."""
    scratch = tem_kernel.sample_scratch()
    for j in range(x.shape[0]):
        status[j] = tem_kernel.control_sample_into(
            x[j],
            rate[j],
            T_d_prev[j],
            rng[j],
            command[j],
            flags[j],
            T_meas[j],
            T_d[j],
            dt_obs,
            dt_law,
            has_prev,
            refresh,
            th_coef[j],
            cfg[j],
            candidates,
            scratch,
        )


@dataclass(frozen=True)
class TemLoopSpec:
    """What tem_controller builds its TemLoop from (nodes/tem_controller.py ``_build_loop``): the law's heat
    balance (saturating at the driver rating), its gains and filters, the drive limits and protection, the
    hold limits' heat balance and the muscles' over-temperature limit [degC]."""

    thermal: th.ThermalParams
    params: TemControlParams
    drive: DriveLimits
    hold: th.ThermalParams
    max_muscle_C: float


class TemLoopBank:
    """:class:`sma_wrist.core.control.tem.TemLoop` (tem_controller's per-sample work) for n wrists
    sampled together. The constants are a one-wrist TemLoop's, built as the node builds them."""

    def __init__(
        self,
        n: int,
        thermal: th.ThermalParams,
        params: TemControlParams,
        drive: DriveLimits,
        hold: th.ThermalParams,
        max_muscle_C: float,
        online: OnlineThermalParams | None = None,
    ) -> None:
        one = TemLoop(thermal, params, drive, hold, max_muscle_C, compiled=True)
        self.n, self.thermal, self.drive, self.params, self.hold = n, thermal, drive, params, hold
        self.max_muscle_C = float(max_muscle_C)  # a bank on another heat balance (plants.oracle) keeps it
        self._coef, self._cfg, self._candidates = one._coef, one._cfg, one._candidates
        self.cfg_rows = np.tile(self._cfg, (n, 1))  # per wrist: the chatter guard switches its rate filter
        self.guard = None if one.guard is None else ChatterGuard(n, params.chatter_limit_per_s, params.chatter_window_s)
        # per wrist: the heat balance each wrist's observer and law integrate (the online estimate's, if on)
        self.coef_rows = np.tile(self._coef, (n, 1))
        self.estimator = None if online is None else ThermalScaleEstimator(thermal, n, online)
        self.estimated = False  # True once the estimate has replaced the model (TemLoop.theta_used set)
        self.observer = np.repeat(one.observer, n, axis=0)  # (n, 2 layers, 2 faces)
        self.rate, self.T_d_prev, self.rng = np.zeros((n, 2, 2)), np.zeros((n, 2, 2)), np.zeros((n, 2, 2))
        self.command_V = np.zeros((n, 2))
        self.T_d_filtered: FloatArray | None = None  # target prefilter (TemLoop._prefilter), (n, 2)
        self.T_d_slope = np.zeros((n, 2))
        self.flags = np.zeros((n, 2), np.int64)
        self.status = np.zeros(n, np.int64)
        self.t_last: float | None = None
        self.t_law: float | None = None
        self.range_t: float | None = None

    @classmethod
    def like_node(
        cls,
        n: int,
        params: TemControlParams | None = None,
        online: OnlineThermalParams | None = None,
        spec: TemLoopSpec | None = None,
    ) -> TemLoopBank:
        """With tem_controller's defaults and config/wrist.yaml (nodes/tem_controller.py: gain 1/s, rate filter
        0.05 s, target prefilter 0.5 s, driver rating, hold limits, 85 degC); test_plants' graph agreement
        checks they still are. ``spec``: the node's loop as its parameters built it instead
        (:func:`sma_wrist.sweep.graph_params.loop_settings`); ``params`` replaces the law's parameters (gain, filters)."""
        spec = spec or default_tem_spec()
        return cls(n, spec.thermal, params or spec.params, spec.drive, spec.hold, spec.max_muscle_C, online)

    def sample(self, t: float, T_meas: FloatArray, T_d: FloatArray | None) -> FloatArray:
        """Commands (n, 2) [V] in force after a sample at t [s] (TemLoop.sample; T_d None: TEMs off)."""
        dt = None if self.t_last is None else t - self.t_last
        if dt is not None and dt <= 0:
            return self.command_V
        self.t_last = t
        dt_obs = 0.0 if dt is None else min(dt, self.thermal.dt_max_s)
        if T_d is None:
            if dt_obs > 0:  # TemLoop._observe's compiled step, each wrist on its own heat balance
                tem_kernel.observer_step_rows(self.observer, self.command_V, dt_obs, self.coef_rows)
            self.observer[:, :, 0] = T_meas
            self.command_V = np.zeros((self.n, 2))
            self.T_d_filtered = None
            self._after(t, T_meas)
            return self.command_V
        self.T_d_filtered, self.T_d_slope = target_prefilter(
            self.params.target_filter_s, self.T_d_filtered, self.T_d_slope, T_d, dt
        )
        T_d = self.T_d_filtered
        refresh = self.drive.predictive and (self.range_t is None or not 0 <= t - self.range_t < RANGE_REFRESH_S)
        has_prev = self.t_law is not None
        dt_law = t - self.t_law if has_prev else 0.0
        _control_many(
            self.observer,
            self.rate,
            self.T_d_prev,
            self.rng,
            self.command_V,
            self.flags,
            np.ascontiguousarray(T_meas, float),
            np.ascontiguousarray(T_d, float),
            dt_obs,
            dt_law,
            has_prev,
            refresh,
            self.coef_rows,
            self.cfg_rows,
            self._candidates,
            self.status,
        )
        if self.status.any():
            raise ModelInputError('TEM command', float('nan'), '(finite numbers)', 'V')
        self.t_law = t
        if refresh:
            self.range_t = t
        self._after(t, T_meas)
        return self.command_V

    def _after(self, t: float, T_meas: FloatArray) -> None:
        """TemLoop._after for every wrist: the chatter guard, then the online estimate."""
        if self.guard is not None:
            changed = self.guard.update(t, self.command_V)
            if changed.any():
                self.cfg_rows[changed, 1] = self.params.rate_filter_for(self.guard.engaged[changed])
        self._learn(t, T_meas)

    def _learn(self, t: float, T_meas: FloatArray) -> None:
        """The online heat-balance estimate takes the sample and the commands now in force."""
        if self.estimator is not None and self.estimator.sample(t, T_meas, self.command_V) and self.estimator.ready:
            self.coef_rows = self.estimator.constants()
            self.estimated = True


def default_tem_spec() -> TemLoopSpec:
    """tem_controller's loop with its defaults (config/wrist.yaml)."""
    hold = th.ThermalParams()
    drive = DriveLimits()
    return TemLoopSpec(
        replace(hold, u_min_V=drive.boost_min_V, u_max_V=drive.boost_max_V),
        TemControlParams(
            gain_per_s=1.0,
            rate_filter_s=0.05,
            target_filter_s=0.5,
            chatter_limit_per_s=CHATTER_LIMIT_PER_S,
            chatter_window_s=CHATTER_WINDOW_S,
            chatter_rate_filter_s=CHATTER_RATE_FILTER_S,
        ),
        drive,
        hold,
        85.0,
    )


__all__ = ['JointControllerBank', 'TemLoopBank', 'TemLoopSpec', 'default_tem_spec']
