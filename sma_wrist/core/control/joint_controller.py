"""Joint controller composition: what the ``adaptive_controller`` node computes each sample.

Three modes (seed Sec. 6.1, Table 6.1):

- ``inverse_adaptive``: the back-stepping adaptive law (:mod:`sma_wrist.core.control.adaptive`,
  Eqs. 5.24, 5.32, 5.37) gives desired muscle forces; with the desired strain of each
  bundle at q_d (chain kinematics, Eq. 4.17) they go to the inverse SD-GPI compensator
  (hysteresis_compensator node, Eqs. 5.5-5.8), which turns them into temperatures.
- ``direct_adaptive``: the same law with only theta adapted; without an inverse, each
  force deviation maps linearly to a temperature deviation around ``temperature_mid_C``
  with the plateau's stress-temperature slope ``force_per_degC_N`` (the hysteresis is
  treated as an unknown gain, which beta_hat absorbs in the inverse mode), low-passed by
  ``direct_output_filter_s``.
- ``pid``: the Sec. 6.1 PID (:mod:`sma_wrist.core.control.pid`) on the angle error; its output u is a
  differential temperature [degC]: T_1d = T_mid + u, T_2d = T_mid - u (muscle 1 contracts
  when heated and raises q).

All modes also return the desired strain (what the compensator needs) and never ask for
temperatures outside [temperature_min_C, temperature_max_C] (reported as saturation). The
``direct_adaptive`` and ``pid`` laws act on the reference ``direct_reference_lead_s`` /
``pid_reference_lead_s`` ahead (:func:`reference_ahead`): the TEMs' lag fed forward, which holds
their tracking on plants that are not the model (doc/explanation/controllers.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from sma_wrist.core.control.adaptive import KGF_N, N_WIRES, AdaptiveController, AdaptiveParams
from sma_wrist.core.control.pid import PID, PIDParams
from sma_wrist.core.errors import ParameterError
from sma_wrist.core.jit import _jit
from sma_wrist.core.plant.wrist import PlantParams

FloatArray = NDArray[np.float64]
Mode = Literal['inverse_adaptive', 'direct_adaptive', 'pid']
MODES = ('inverse_adaptive', 'direct_adaptive', 'pid')


def tuned_adaptive() -> AdaptiveParams:
    """Adaptive gains tuned on this project's plant (doc/explanation/controllers.md).

    The seed's Table 6.1 gains (C1 = 3, C2 = 6.5) ask for forces of ~I/R C1 C2 e ~ 9 N at
    0.5 rad of error on a joint whose muscles need tens of degC -- hundreds of N of force
    request -- to cross the hysteresis; here C1 = C2 = 400 (150 until the predictive TEM face
    protection gave the muscles more heating near their limit: 15.1 % at 0.6 kg) with slow adaptation
    (Gamma_a = 1e-4: Table 6.1's 0.01-0.05 drive theta_hat to its bounds within a second on
    this plant's phi = g l cos q / I ~ 350 /s^2/kg), forces 0.3-1.0 kgf per wire.
    """
    return AdaptiveParams(
        c1=400.0,
        c2=400.0,
        gamma_a=1e-4,
        gamma_b1=1e-4,
        gamma_b2=1e-4,
        gamma_d1=0.0,
        gamma_d2=0.0,
        preload_N=N_WIRES * 0.65 * KGF_N,
        force_min_N=N_WIRES * 0.3 * KGF_N,
        force_max_N=N_WIRES * 1.0 * KGF_N,
    )


#: how far past the measured angle the held target lies during a reversal lead [rad]; larger
#: than the mismatch between the chain's strain at q and the inverse model's, so the inverse
#: sees a clear turn (at 2e-3 rad it flipped between branches)
REVERSAL_STEP_RAD = 1e-2


@_jit
def time_to_turn(qdot_d: float, qddot_d: float) -> float:
    """Time [s] until the reference velocity crosses zero, from its local parabola (inf if it does not).

    q_d(t + s) ~ q_d + qdot_d s + qddot_d s^2 / 2 has its extremum at s* = -qdot_d / qddot_d.
    """
    if qdot_d * qddot_d < 0:
        return -qdot_d / qddot_d
    return math.inf


@_jit
def time_to_meet(error: float, qdot_d: float, qddot_d: float) -> tuple[float, float]:
    """When the reference, on its local parabola, last comes to a joint that stays where it is.

    Largest s > 0 with error + qdot_d s + qddot_d s^2 / 2 = 0 (error = q_d - q [rad]), and the
    sign of the reference velocity there: the direction the joint must move afterwards.
    (inf, 0) if the reference does not come to the joint. For a joint on the reference this is
    the far root, 2 s* (:func:`time_to_turn`); for one far behind, the time q_d needs to come
    back to it after its turn; for one beyond the coming extremum, 2 s* as well. Compiled (the
    sweep's bank calls it per wrist and tick from compiled code), scalars only.
    """
    s = -math.inf  # the largest positive root so far
    if qddot_d == 0.0:
        x = -error / qdot_d if qdot_d != 0.0 else -math.inf
        if x > 0.0:
            s = x
    else:
        disc = qdot_d * qdot_d - 2.0 * qddot_d * error
        if disc < 0.0:  # the joint lies beyond the reference's coming extremum: it turns there
            s_turn = time_to_turn(qdot_d, qddot_d)
            if math.isfinite(s_turn):
                return 2.0 * s_turn, -math.copysign(1.0, qdot_d)
            return math.inf, 0.0
        r = math.sqrt(disc)
        for x in ((-qdot_d - r) / qddot_d, (-qdot_d + r) / qddot_d):
            if x > 0.0 and x > s:  # max of the positive roots, the first of equal ones
                s = x
    if s == -math.inf:
        return math.inf, 0.0
    return s, math.copysign(1.0, qdot_d + qddot_d * s)


def reference_ahead(q_d: float, qdot_d: float, qddot_d: float, lead_s: float) -> tuple[float, float]:
    """The reference ``lead_s`` [s] ahead on its local parabola: (q_d(t + lead), qdot_d(t + lead)) [rad, rad/s].

    The TEMs need seconds to move a muscle across its hysteresis, so a law on q_d(t) acts late; for
    the Sec. 6.1 sine (omega = 0.1 rad/s) the parabola's error at 2 s is 0.524 (0.2)^3 / 6 = 0.7 mrad.
    """
    return q_d + qdot_d * lead_s + 0.5 * qddot_d * lead_s * lead_s, qdot_d + qddot_d * lead_s


def output_filter_step(y: FloatArray | None, u: FloatArray, dt: float, tau: float) -> FloatArray:
    """One backward-Euler step of the first-order low-pass 1 / (tau s + 1) [tau, dt in s] from its state y
    to the new input u (the PID's output, degC); None (the first sample) or tau 0: u itself."""
    if y is None or tau <= 0:
        return u
    return y + dt / (tau + dt) * (u - y)


def bundle_strain(plant: PlantParams, q: float) -> FloatArray:
    """Strains (elongation / wire length) of the two bundles at angle q [rad] (Eq. 4.17, muscle.py):
    y_1 = e0 - x, y_2 = e0 + x with x the chain travel from q_neutral and e0 the pre-load elongation."""
    x = float(plant.joint.chain_displacement_mm(q))
    e0 = plant.preload_elongation_mm
    return np.array([e0 - x, e0 + x]) / plant.muscle.wire_length_mm


@dataclass(frozen=True)
class JointControllerParams:
    """Mode, the laws' parameters and the temperature map of the modes without an inverse."""

    mode: Mode = 'inverse_adaptive'  # the seed's controller; under 5 % on this plant (doc/explanation/controllers.md)
    adaptive: AdaptiveParams = field(default_factory=tuned_adaptive)
    #: PID on the angle error, output in degC of differential temperature (doc/explanation/controllers.md; Kp / Ki
    #: 300 / 60 until the output filter below, doc/explanation/controllers.md)
    pid: PIDParams = field(
        default_factory=lambda: PIDParams(kp=400.0, ki=30.0, kd=0.0, output_min=-30.0, output_max=30.0)
    )
    temperature_mid_C: float = 50.0  # centre of the muscles' working band [degC]
    temperature_min_C: float = 20.0
    temperature_max_C: float = 80.0
    #: direct mode: force request per degC of temperature request [N/degC] (10 with
    #: the output filter below: the law's C1 C2 e then spans the 20-80 degC window over ~0.1 rad of
    #: error instead of ~0.03, a proportional band like the PID's; doc/explanation/
    #: controllers.md)
    force_per_degC_N: float = 10.0
    #: inverse mode: start crossing the hysteresis gap this long before the reference turns [s]
    #: (0 = the strain at q_d throughout, Eq. 5.5 as written; doc/explanation/controllers.md)
    reversal_lead_s: float = 2.75
    #: pid / direct modes: the law acts on the reference this far ahead [s] (its local parabola,
    #: :func:`reference_ahead`): the TEMs' lag, fed forward; 0 = the seed's laws on q_d(t)
    #: (doc/explanation/controllers.md)
    pid_reference_lead_s: float = 1.25
    direct_reference_lead_s: float = 1.0
    #: pid mode: first-order low-pass on the PID's output [s] (:func:`output_filter_step`): the joint's
    #: stick-slip (a ~1 Hz sawtooth of the angle error) and the potentiometer noise times Kp swung the
    #: TEMs between heating and cooling; 0 = the seed's PID output as it is (doc/explanation/controllers.md)
    pid_output_filter_s: float = 0.3
    #: direct mode: the same low-pass on the temperature request (F - F_pre) / k [s]: with k = 10 N/degC the
    #: map is a proportional band rather than a relay between 20 and 80 degC, and it passes the sensor noise
    #: and stick-slip to the TEMs (2.9 sign changes /s on the family's worst plant without the filter);
    #: 0 = the map as it is (doc/explanation/controllers.md)
    direct_output_filter_s: float = 0.1

    @property
    def reference_lead_s(self) -> float:
        """The lead of this mode's law [s] (0 in inverse_adaptive, which has its reversal lead)."""
        return {'pid': self.pid_reference_lead_s, 'direct_adaptive': self.direct_reference_lead_s}.get(self.mode, 0.0)

    @property
    def output_filter_s(self) -> float:
        """The output low-pass of this mode's temperature request [s] (0 in inverse_adaptive)."""
        return {'pid': self.pid_output_filter_s, 'direct_adaptive': self.direct_output_filter_s}.get(self.mode, 0.0)

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ParameterError(f'mode = {self.mode!r} is not one of {", ".join(MODES)}')
        for name in (
            'temperature_mid_C',
            'temperature_min_C',
            'temperature_max_C',
            'force_per_degC_N',
            'reversal_lead_s',
            'pid_reference_lead_s',
            'direct_reference_lead_s',
            'pid_output_filter_s',
            'direct_output_filter_s',
        ):
            if not math.isfinite(getattr(self, name)):
                raise ParameterError(f'{name} = {getattr(self, name)!r} must be finite')
        if not self.temperature_min_C < self.temperature_mid_C < self.temperature_max_C:
            raise ParameterError(
                f'need temperature_min_C < temperature_mid_C < temperature_max_C, got '
                f'{self.temperature_min_C}, {self.temperature_mid_C}, {self.temperature_max_C}'
            )
        if not self.force_per_degC_N > 0:
            raise ParameterError(f'force_per_degC_N = {self.force_per_degC_N!r} must be > 0')
        for name in (
            'reversal_lead_s',
            'pid_reference_lead_s',
            'direct_reference_lead_s',
            'pid_output_filter_s',
            'direct_output_filter_s',
        ):
            if not getattr(self, name) >= 0:
                raise ParameterError(f'{name} = {getattr(self, name)!r} must be >= 0')


@dataclass(frozen=True)
class JointCommand:
    force_N: FloatArray | None  # (2,) desired chain force per muscle (adaptive modes)
    strain_desired: FloatArray  # (2,) desired bundle strain at q_d
    temperature_desired_C: FloatArray | None  # (2,) in direct_adaptive and pid modes
    saturated: bool
    info: dict[str, float]


class JointController:
    """One controller of the selected mode for one wrist."""

    def __init__(self, params: JointControllerParams | None = None, plant: PlantParams | None = None) -> None:
        self.params = params or JointControllerParams()
        self.plant = plant or PlantParams()
        self.reset()

    def reset(self) -> None:
        p = self.params
        # the law's own mode decides what adapts (direct: theta only, Table 6.1)
        self.adaptive = AdaptiveController(replace(p.adaptive, mode=p.mode)) if p.mode != 'pid' else None
        self.pid = PID(p.pid) if p.mode == 'pid' else None
        self.hold: tuple[float, float] | None = None  # (held angle, direction after the turn)
        self.u_filtered: FloatArray | None = None  # the output filter's state (output_filter_s) [degC]

    def strain_at(self, q: float) -> FloatArray:
        """Bundle strains (elongation / wire length) at angle q (:func:`bundle_strain`)."""
        return bundle_strain(self.plant, q)

    def _reversal_lead(
        self, strain: FloatArray, q: float, q_d: float, qdot_d: float, qddot_d: float, info: dict[str, float]
    ) -> FloatArray:
        """Inverse mode: cross the hysteresis gap around the joint's reversal instead of after it.

        Reversing a wire's strain first needs a temperature change across the gap between its
        heating and cooling branches (~25 degC, 5-6 s at the drive limit on this plant), during
        which the joint cannot follow. The joint must reverse where the reference, coming back,
        meets it (:func:`time_to_meet`): for a joint on the reference, 2 s* after now, s* the
        time to the reference's turn; for one lagging behind (from rest, or short of a peak it
        cannot reach), later. When that meeting is less than 2 ``reversal_lead_s`` away and the
        joint must then move the other way, the target is latched just past the measured angle
        in the new direction, so the inverse answers with the far side of the gap. The latch
        holds until q_d, moving the new way, has come past it, or until the reference no longer
        comes back (it only slowed down); then q_d takes over. For a joint on the reference the
        stall is centred on the turn, where q_d moves least.
        """
        e = q_d - q
        s_meet, after = time_to_meet(e, qdot_d, qddot_d)
        info['time_to_meet_s'] = s_meet
        # a reversal: the reference turns before it meets the joint, or the joint, clearly behind
        # it, still has to go the other way first
        turns = after != math.copysign(1.0, qdot_d) or (abs(e) > REVERSAL_STEP_RAD and after != math.copysign(1.0, e))
        if self.hold is None and s_meet < 2.0 * self.params.reversal_lead_s and turns:
            self.hold = (q + after * REVERSAL_STEP_RAD, after)
        if self.hold is not None:
            q_hold, held_after = self.hold
            turned = qdot_d * held_after > 0
            if (turned and (q_d - q_hold) * held_after >= 0) or (not turned and after != held_after):
                self.hold = None
            else:
                info['reversal_hold_rad'] = q_hold
                return self.strain_at(q_hold)
        return strain

    def _clip_T(self, T: FloatArray) -> tuple[FloatArray, bool]:
        """The two temperature requests [degC] clipped to the working band, and whether either was
        (NaN stays NaN and counts as clipped). As floats: np.clip costs ~5 us on two numbers."""
        p = self.params
        lo, hi = p.temperature_min_C, p.temperature_max_C
        T1, T2 = T.tolist()
        c1, c2 = min(max(T1, lo), hi), min(max(T2, lo), hi)
        return np.array([c1, c2]), c1 != T1 or c2 != T2

    def update(
        self,
        q: float,
        qdot: float,
        q_d: float,
        qdot_d: float,
        qddot_d: float,
        dt: float,
        muscle_temperature_C: FloatArray | None = None,
    ) -> JointCommand:
        """One sample: measured q [rad], q' [rad/s]; reference q_d, q_d', q_d''; step dt [s]."""
        p = self.params
        strain = self.strain_at(q_d)
        if p.reference_lead_s > 0:
            q_d, qdot_d = reference_ahead(q_d, qdot_d, qddot_d, p.reference_lead_s)
        if self.pid is not None:
            o = self.pid.update(q, q_d, dt)
            self.u_filtered = output_filter_step(self.u_filtered, o.u, dt, p.output_filter_s)
            u = float(self.u_filtered[0])
            T, clipped = self._clip_T(np.array([p.temperature_mid_C + u, p.temperature_mid_C - u]))
            return JointCommand(
                None,
                strain,
                T,
                bool(o.saturated[0]) or clipped,
                {'error_rad': float(o.error[0]), 'u_degC': u, 'integral': float(o.i_term[0])},
            )
        assert self.adaptive is not None
        o = self.adaptive.update(q, qdot, q_d, qdot_d, qddot_d, dt)
        force = np.array([o.force_1_N[0], o.force_2_N[0]])
        info = {
            'z1_rad': float(o.z1[0]),
            'z2_rad_s': float(o.z2[0]),
            'theta_hat_kg': float(o.theta_hat[0]),
            'beta_hat_1': float(o.beta_hat[0, 0]),
            'beta_hat_2': float(o.beta_hat[0, 1]),
            'delta_force_N': float(o.delta_force_N[0]),
        }
        if p.mode == 'inverse_adaptive':
            strain = self._reversal_lead(strain, q, q_d, qdot_d, qddot_d, info)
            return JointCommand(force, strain, None, bool(o.saturated[0]), info)
        self.u_filtered = output_filter_step(
            self.u_filtered, (force - p.adaptive.preload_N) / p.force_per_degC_N, dt, p.output_filter_s
        )
        T, clipped = self._clip_T(p.temperature_mid_C + self.u_filtered)
        return JointCommand(force, strain, T, bool(o.saturated[0]) or clipped, info)


__all__ = [
    'JointController',
    'JointControllerParams',
    'JointCommand',
    'MODES',
    'bundle_strain',
    'reference_ahead',
    'output_filter_step',
]
