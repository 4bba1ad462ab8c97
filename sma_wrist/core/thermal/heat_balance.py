"""TEM + Nitinol heat balance of the two-layer wrist (seed Sec. 4.3, Eqs. 4.7-4.15, Table 4.9).

Model (Eqs. 4.13/4.14), one thermoelectric module (TEM) with faces T1, T2 and input I::

    dT1/dt = (K_at1 T1 + K_t1 T2) I - K_Tinf1 T1 + K_T1 T2 + K_R I^2 + K_inf1     (4.13)
    dT2/dt = (K_at2 T2 + K_t2 T1) I - K_Tinf2 T2 + K_T2 T1 + K_R I^2 + K_inf2     (4.14)

with the Table 4.9 columns (T1 column for Eq. 4.13, T2 column for Eq. 4.14; the table's
``K_TC`` is K_T and ``K_I`` is K_R). Temperatures in degC, time in s.

Ambient (Eq. 4.15): K_inf = k_inf T_inf / (rho Cp) and K_Tinf = (k_T + k_inf) / (rho Cp),
K_T = k_T / (rho Cp), so k_inf / (rho Cp) = K_Tinf - K_T and T_inf = K_inf / (K_Tinf - K_T):
25.596 degC for the T1 column and 31.568 degC for the T2 column (one shared K_inf was
fitted, the loss conductances differ). :class:`ThermalParams` can replace the implied
ambients (``ambient_C``) to model ambient or coolant drift; the default keeps Table 4.9's
K_inf exactly.

Arrangement (decision, doc/explanation/model.md): the final design is two layers (Fig. 5.26), one
module per muscle. Layer i carries muscle i on its **T1 face (Eq. 4.13)** -- the face the
seed's controller keeps when it sets h2 = 0 -- and the heat exchanger on its T2 face
(Eq. 4.14; T'_i of Fig. 5.26, "not in use" for control but still simulated). With Table
4.9, I > 0 cools T1 and heats T2 (the I-coefficient of Eq. 4.13 is
(K_at1 + K_t1) T ~ -0.0087 T < 0, that of Eq. 4.14 is +0.0099 T > 0).

Input (decision): the public command is a drive voltage ``u`` [V], positive heats the
muscle face, as msg_defs/topics.yaml says. The model input is ``I = -input_per_volt * u``
(``I = -input_per_volt * tem_gain[l] * u`` on layer l: two modules of one kind pump
differently per volt -- a supply lead's resistance, a thermal contact -- and commissioning
measures each; Table 4.9's faces stay shared, :class:`ThermalParams`).
The literal reading (I = u in V) cannot be what Table 4.9 was fitted to: the seed's 12 V
identification sines then run away (hundreds to thousands of degC, see ``python -m
sma_wrist.core.thermal.heat_balance``). With ``input_per_volt = 0.4`` (I in A through an effective
2.5 Ohm, the class of a 12 V / 6 A module) a 12 V command held in either direction stays
inside the 0-80 degC window, so the identification experiment is physical.

Layout: a state is an array of shape (N, L, 2): N scenarios, L layers (2 for the wrist, 1
for the seed's one-module experiment), faces [muscle (T1), exchanger (T2)], degC. A command
is (N, L) volts. Everything is vectorised over scenarios.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sma_wrist.core import jit as _jm
from sma_wrist.core.errors import ModelInputError, ParameterError, check_finite
from sma_wrist.core.thermal import kernel as _tk

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

MUSCLE_FACE = 0  # index of the T1 face (Eq. 4.13) in the last axis of a state
EXCHANGER_FACE = 1  # index of the T2 face (Eq. 4.14)


@dataclass(frozen=True)
class FaceCoefficients:
    """One column of Table 4.9: the coefficients of Eq. 4.13 (T1) or Eq. 4.14 (T2) [1/s, degC/s]."""

    K_alpha_tau: float  # (2 alpha - tau) / (2 rho Cp), multiplies T_own I
    K_tau: float  # tau / (2 rho Cp), multiplies T_other I
    K_T_inf: float  # (k_T + k_inf) / (rho Cp)
    K_T: float  # k_T / (rho Cp); the table's K_TC
    K_R: float  # R / (2 rho Cp); the table's K_I
    K_inf: float  # k_inf T_inf / (rho Cp)

    @property
    def loss_per_s(self) -> float:
        """k_inf / (rho Cp) = K_Tinf - K_T (Eq. 4.15) [1/s]."""
        return self.K_T_inf - self.K_T

    @property
    def implied_ambient_C(self) -> float:
        """T_inf = K_inf / (K_Tinf - K_T) (Eq. 4.15) [degC]."""
        return self.K_inf / self.loss_per_s


#: Table 4.9, T1 column (Eq. 4.13).
TABLE_4_9_T1 = FaceCoefficients(-0.004472, -0.004207, 0.052345, 0.028312, 0.012524, 0.615142)
#: Table 4.9, T2 column (Eq. 4.14).
TABLE_4_9_T2 = FaceCoefficients(0.006162, 0.003737, 0.056143, 0.036657, 0.012524, 0.615142)


@dataclass(frozen=True)
class ThermalParams:
    """Parameters of the two-layer TEM heat balance (Eqs. 4.13-4.15, Table 4.9) and its limits.

    Attributes
    ----------
    muscle_face, exchanger_face:
        Table 4.9 columns for the muscle (T1, Eq. 4.13) and exchanger (T2, Eq. 4.14) faces.
    input_per_volt:
        Model input I per volt of command [1/V]; I = -input_per_volt * u (u > 0 heats T1).
    u_min_V, u_max_V:
        Command limits [V] (cooling, heating); from the runaway characterisation
        (:func:`characterise_constant_commands`, doc/explanation/model.md). With ``tem_hold_limits_V`` the
        limits both TEMs hold.
    ambient_C:
        (muscle-face, exchanger-face) ambient/coolant temperatures [degC]; ``None`` keeps
        Table 4.9's K_inf (implied 25.596 / 31.568 degC).
    tem_gain:
        (TEM 1, TEM 2) drive gain relative to ``input_per_volt`` [1]: layer l's input is
        I = -input_per_volt * tem_gain[l] * u (a weaker module pumps less heat per volt, its
        Joule heat falls with the square). A one-layer model (the seed's experiment) takes
        ``tem_gain[0]``. Default (1, 1): one heat balance for both modules.
    tem_hold_limits_V:
        ((TEM 1 low, high), (TEM 2 low, high)) hold limits [V] where the TEMs' drive gains differ: a weaker TEM
        holds a larger drive, and is not held to the stronger one's (:meth:`with_hold_limits` sets them and
        u_min_V / u_max_V to what both hold); ``None``: both TEMs [u_min_V, u_max_V] (:meth:`layer_hold_limits`).
    coupling_per_s:
        Conductance between the two muscle faces over their heat capacity [1/s], adds
        coupling * (T_other_muscle - T_muscle) to Eq. 4.13 of each layer. Default 0.
    dt_max_s:
        Largest accepted RK4 step [s] (stability bound ~25 s, accuracy bound, doc/explanation/model.md).
    window_C:
        Physical window of every face [degC]; 80 degC is the TEM operating limit.
    """

    muscle_face: FaceCoefficients = TABLE_4_9_T1
    exchanger_face: FaceCoefficients = TABLE_4_9_T2
    input_per_volt: float = 0.4
    u_min_V: float = -12.0
    u_max_V: float = 13.0
    ambient_C: tuple[float, float] | None = None
    tem_gain: tuple[float, float] = (1.0, 1.0)
    tem_hold_limits_V: tuple[tuple[float, float], tuple[float, float]] | None = None
    coupling_per_s: float = 0.0
    dt_max_s: float = 1.0
    window_C: tuple[float, float] = (0.0, 80.0)
    # Per-face coefficient vectors (faces on the last axis), filled in __post_init__.
    _k_at: FloatArray = field(init=False, repr=False, compare=False)
    _k_t: FloatArray = field(init=False, repr=False, compare=False)
    _k_tinf: FloatArray = field(init=False, repr=False, compare=False)
    _k_tc: FloatArray = field(init=False, repr=False, compare=False)
    _k_r: FloatArray = field(init=False, repr=False, compare=False)
    _k_inf: FloatArray = field(init=False, repr=False, compare=False)
    _col_at: FloatArray = field(init=False, repr=False, compare=False)
    _col_t: FloatArray = field(init=False, repr=False, compare=False)
    _col_neg_tinf: FloatArray = field(init=False, repr=False, compare=False)
    _col_tc: FloatArray = field(init=False, repr=False, compare=False)
    _col_r: FloatArray = field(init=False, repr=False, compare=False)
    _col_inf: FloatArray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        for name in ('input_per_volt', 'u_min_V', 'u_max_V', 'coupling_per_s', 'dt_max_s'):
            if not np.isfinite(getattr(self, name)):
                raise ParameterError(f'{name} = {getattr(self, name)!r} must be finite')
        if not self.input_per_volt > 0:
            raise ParameterError(f'input_per_volt = {self.input_per_volt} must be > 0')
        gains = tuple(self.tem_gain)
        if len(gains) != 2 or not all(np.isfinite(g) and g > 0 for g in gains):
            raise ParameterError(f'tem_gain = {self.tem_gain!r} must be two finite numbers > 0')
        object.__setattr__(self, 'tem_gain', (float(gains[0]), float(gains[1])))
        if not self.u_min_V < 0 < self.u_max_V:
            raise ParameterError(f'command limits [{self.u_min_V}, {self.u_max_V}] V must bracket 0')
        if self.tem_hold_limits_V is not None:
            pairs = tuple(tuple(float(v) for v in pair) for pair in self.tem_hold_limits_V)
            if len(pairs) != 2 or not all(len(q) == 2 and np.isfinite(q).all() and q[0] < 0 < q[1] for q in pairs):
                raise ParameterError(
                    f'tem_hold_limits_V = {self.tem_hold_limits_V!r} must be two (low < 0 < high) pairs of finite V'
                )
            object.__setattr__(self, 'tem_hold_limits_V', pairs)
        if self.coupling_per_s < 0:
            raise ParameterError(f'coupling_per_s = {self.coupling_per_s} must be >= 0')
        if not 0 < self.dt_max_s <= 10.0:
            raise ParameterError(f'dt_max_s = {self.dt_max_s} must be in (0, 10] s (RK4 stability)')
        if not self.window_C[0] < self.window_C[1]:
            raise ParameterError(f'window_C = {self.window_C} must be increasing')
        faces = (self.muscle_face, self.exchanger_face)
        if self.ambient_C is None:
            k_inf = [f.K_inf for f in faces]  # Table 4.9 exactly
        else:
            if len(self.ambient_C) != 2 or not np.all(np.isfinite(self.ambient_C)):
                raise ParameterError(f'ambient_C = {self.ambient_C!r} must be two finite degC')
            k_inf = [f.loss_per_s * t for f, t in zip(faces, self.ambient_C)]
        for f in faces:
            if not f.loss_per_s > 0:
                raise ParameterError(f'K_Tinf - K_T = {f.loss_per_s} must be > 0 (loss to ambient)')
        set_ = object.__setattr__
        set_(self, '_k_at', np.array([f.K_alpha_tau for f in faces]))
        set_(self, '_k_t', np.array([f.K_tau for f in faces]))
        set_(self, '_k_tinf', np.array([f.K_T_inf for f in faces]))
        set_(self, '_k_tc', np.array([f.K_T for f in faces]))
        set_(self, '_k_r', np.array([f.K_R for f in faces]))
        set_(self, '_k_inf', np.array(k_inf))
        # Column vectors (2, 1) for the face-major RK4 buffers of :func:`step`.
        set_(self, '_col_at', self._k_at[:, None].copy())
        set_(self, '_col_t', self._k_t[:, None].copy())
        set_(self, '_col_neg_tinf', -self._k_tinf[:, None])
        set_(self, '_col_tc', self._k_tc[:, None].copy())
        set_(self, '_col_r', self._k_r[:, None].copy())
        set_(self, '_col_inf', self._k_inf[:, None].copy())

    @property
    def effective_ambient_C(self) -> tuple[float, float]:
        """(muscle-face, exchanger-face) ambient temperatures the model uses [degC]."""
        return (
            float(self._k_inf[0] / self.muscle_face.loss_per_s),
            float(self._k_inf[1] / self.exchanger_face.loss_per_s),
        )

    def layer_input_per_volt(self, layers: int = 2) -> FloatArray:
        """Model input per volt of each of ``layers`` layers, input_per_volt * tem_gain [1/V], shape (layers,)
        (any number of layers of one kind; two at most where the modules differ)."""
        if self.tem_gain == (1.0, 1.0):
            return np.full(layers, self.input_per_volt)
        if not 1 <= layers <= 2:
            raise ModelInputError('thermal layers with per-TEM gains', layers, '1 or 2')
        return self.input_per_volt * np.asarray(self.tem_gain[:layers], dtype=float)

    @property
    def K_inf(self) -> FloatArray:
        """Effective K_inf of both faces (Eq. 4.15) [degC/s]."""
        return self._k_inf.copy()

    def with_ambient_shift(self, shift_C: float, exchanger_shift_C: float | None = None) -> ThermalParams:
        """Copy with the ambients moved by shift_C (exchanger face by exchanger_shift_C, default same)."""
        a0, a1 = self.effective_ambient_C
        s1 = shift_C if exchanger_shift_C is None else exchanger_shift_C
        return dataclasses.replace(self, ambient_C=(a0 + shift_C, a1 + s1))

    def scaled(
        self, gain: float = 1.0, losses: float = 1.0, joule: float = 1.0, ambient_shift_C: float = 0.0
    ) -> ThermalParams:
        """Copy as another module of this kind: drive gain input_per_volt x ``gain``; the muscle face's K_Tinf,
        K_T and K_inf x ``losses`` (its ambient unchanged, Eq. 4.15); both faces' K_R x ``joule``; both faces'
        ambients + ``ambient_shift_C`` [degC]. The plant's thermal extensions (core.plant.extensions.plant_params)
        and the online estimate's scales (core.thermal.online.with_scales) are these."""
        amb = self.effective_ambient_C
        mf = dataclasses.replace(
            self.muscle_face,
            K_T_inf=self.muscle_face.K_T_inf * losses,
            K_T=self.muscle_face.K_T * losses,
            K_inf=self.muscle_face.K_inf * losses,
            K_R=self.muscle_face.K_R * joule,
        )
        xf = dataclasses.replace(self.exchanger_face, K_R=self.exchanger_face.K_R * joule)
        return dataclasses.replace(
            self,
            muscle_face=mf,
            exchanger_face=xf,
            input_per_volt=self.input_per_volt * gain,
            ambient_C=(amb[0] + ambient_shift_C, amb[1] + ambient_shift_C),
        )

    def with_limits(self, u_min_V: float, u_max_V: float) -> ThermalParams:
        """Copy with other command limits, the same for both TEMs (e.g. for characterisation beyond the defaults,
        the driver rating)."""
        return dataclasses.replace(self, u_min_V=u_min_V, u_max_V=u_max_V, tem_hold_limits_V=None)

    def with_hold_limits(self, per_tem: tuple[tuple[float, float], tuple[float, float]]) -> ThermalParams:
        """Copy with each TEM's hold limits ((low, high) [V] of TEM 1, TEM 2); the command limits become what both
        hold (the larger low, the smaller high); equal pairs are kept as one."""
        (lo1, hi1), (lo2, hi2) = ((float(a), float(b)) for a, b in per_tem)
        same = (lo1, hi1) == (lo2, hi2)
        return dataclasses.replace(
            self,
            u_min_V=max(lo1, lo2),
            u_max_V=min(hi1, hi2),
            tem_hold_limits_V=None if same else ((lo1, hi1), (lo2, hi2)),
        )

    def layer_hold_limits(self) -> tuple[FloatArray, FloatArray]:
        """(low, high) hold limits [V] of TEM 1 and TEM 2, each shape (2,): ``tem_hold_limits_V``, else
        [u_min_V, u_max_V] for both."""
        if self.tem_hold_limits_V is None:
            return np.full(2, self.u_min_V), np.full(2, self.u_max_V)
        (lo1, hi1), (lo2, hi2) = self.tem_hold_limits_V
        return np.array([lo1, lo2]), np.array([hi1, hi2])


# ----------------------------------------------------------------------- commands


def _per_layer(params: ThermalParams, x: FloatArray) -> FloatArray | float:
    """input_per_volt for commands or inputs x (..., L) (a scalar where both modules pump alike)."""
    if params.tem_gain == (1.0, 1.0) or x.ndim == 0:
        return params.input_per_volt
    return params.layer_input_per_volt(x.shape[-1])


def model_input(params: ThermalParams, command_V: ArrayLike) -> FloatArray:
    """Eq. 4.13/4.14 input I from the drive voltage u (..., L): I = -input_per_volt * tem_gain[l] * u (u > 0
    heats T1)."""
    u = np.asarray(command_V, dtype=float)
    return -_per_layer(params, u) * u


def command_from_input(params: ThermalParams, current: ArrayLike) -> FloatArray:
    """Inverse of :func:`model_input`: u = -I / (input_per_volt * tem_gain[l]) [V]."""
    i = np.asarray(current, dtype=float)
    return -i / _per_layer(params, i)


def check_command(params: ThermalParams, command_V: ArrayLike) -> None:
    """Raise ModelInputError unless every command is finite and in [u_min_V, u_max_V]."""
    u = np.asarray(command_V, dtype=float)
    check_finite('TEM command', u, 'V')
    if u.size and (u.min() < params.u_min_V or u.max() > params.u_max_V):
        bad = u.min() if u.min() < params.u_min_V else u.max()
        raise ModelInputError('TEM command', float(bad), f'[{params.u_min_V:g}, {params.u_max_V:g}]', 'V')


def saturate_command(params: ThermalParams, command_V: ArrayLike) -> tuple[FloatArray, BoolArray]:
    """Clip commands to [u_min_V, u_max_V]; returns (clipped, mask of the elements that were clipped).

    Non-finite commands are not clipped but rejected (ModelInputError): there is no
    meaningful value to clip them to.
    """
    u = np.asarray(command_V, dtype=float)
    check_finite('TEM command', u, 'V')
    clipped = np.clip(u, params.u_min_V, params.u_max_V)
    return clipped, clipped != u


# --------------------------------------------------------------------- dynamics


def rate_terms(params: ThermalParams, state: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(A, B, D) with dT/dt = A I^2 + B I + D per face (Eqs. 4.13/4.14, the form of Eq. 5.44).

    A = K_R, B = K_at T_own + K_t T_other, D = -K_Tinf T_own + K_T T_other + K_inf
    (+ the muscle-muscle coupling on the muscle faces). Shapes (2,), (N, L, 2), (N, L, 2).
    """
    T = np.asarray(state, dtype=float)
    To = T[..., ::-1]
    B = params._k_at * T + params._k_t * To
    D = params._k_tc * To - params._k_tinf * T + params._k_inf
    if params.coupling_per_s:
        D[..., MUSCLE_FACE] += params.coupling_per_s * (T[..., ::-1, MUSCLE_FACE] - T[..., MUSCLE_FACE])
    return params._k_r, B, D


def derivative(params: ThermalParams, state: ArrayLike, command_V: ArrayLike) -> FloatArray:
    """dT/dt of Eqs. 4.13/4.14 for states (N, L, 2) [degC] and commands (N, L) [V]; pure."""
    T = np.asarray(state, dtype=float)
    current = model_input(params, command_V)[..., None]
    A, B, D = rate_terms(params, T)
    return (A * current + B) * current + D


def _coefficients(params: ThermalParams, current: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """dT/dt = c_self * T + c_cross * T_other + c0 at a held input (linear in T for fixed I)."""
    i = current[..., None]
    c_self = params._k_at * i - params._k_tinf
    c_cross = params._k_t * i + params._k_tc
    c0 = params._k_r * (i * i) + params._k_inf
    if params.coupling_per_s:
        c_self[..., MUSCLE_FACE] -= params.coupling_per_s
    return c_self, c_cross, c0


def check_state(state: ArrayLike) -> FloatArray:
    """Return the state as a float array of shape (N, L, 2), or raise ModelInputError."""
    T = np.asarray(state, dtype=float)
    if T.ndim != 3 or T.shape[-1] != 2:
        raise ModelInputError('thermal state shape', T.shape, '(N, L, 2)')
    check_finite('thermal state', T, 'degC')
    return T


def check_dt(params: ThermalParams, dt: float) -> None:
    """Raise ModelInputError unless 0 < dt <= dt_max_s."""
    if not (isinstance(dt, (int, float, np.floating, np.integer)) and np.isfinite(dt) and 0 < dt <= params.dt_max_s):
        raise ModelInputError('thermal step dt', dt, f'(0, {params.dt_max_s:g}]', 's')


def _apply_M(
    out: FloatArray, tmp: FloatArray, v: FloatArray, cs: FloatArray, cc: FloatArray, coupling: float, n_layers: int
) -> None:
    """out[0:2] = M v for the face-major layout: v is (3, M) with v[2] = v[0] (so v[1:3] is v swapped)."""
    np.multiply(cs, v[0:2], out=out[0:2])
    np.multiply(cc, v[1:3], out=tmp)
    out[0:2] += tmp
    if coupling:  # muscle face of layer l receives from the muscle face of the other layer
        m = v[0].reshape(-1, n_layers)
        out[0].reshape(-1, n_layers)[...] += coupling * m[:, ::-1]


def step(
    params: ThermalParams, state: ArrayLike, command_V: ArrayLike, dt: float, *, validate: bool = True
) -> FloatArray:
    """One classical RK4 step (the seed's integrator, Sec. 4.3.2) of Eqs. 4.13/4.14.

    The command is held over the step (zero-order hold, as a DAC does), so over one step the
    model is linear in T: dT/dt = M(I) T + b(I). RK4 applied to it is exactly
    ``T + h (1 + hM/2 + (hM)^2/6 + (hM)^3/24)(M T + b)``, evaluated here in Horner form on a
    face-major buffer (fewer, contiguous numpy calls; identical to the four-stage form up to
    rounding, see test_thermal). state (N, L, 2) degC, command (N, L) V broadcastable, dt s;
    returns a new array. With ``validate`` (default) a non-finite state, a command outside the
    limits and a dt outside (0, dt_max_s] raise ModelInputError; the checks are reductions,
    cheap enough to stay on.
    """
    T = np.asarray(state, dtype=float)
    u = np.asarray(command_V, dtype=float)
    if validate:
        check_dt(params, dt)
        # min/max are NaN when any element is; the comparisons then fail into the exact check.
        lo, hi = u.min(), u.max()
        if not (lo >= params.u_min_V and hi <= params.u_max_V):
            check_command(params, u)
        if T.ndim != 3 or T.shape[-1] != 2 or not np.isfinite(T.sum()):
            check_state(T)
    if u.shape + (2,) == T.shape:  # fast path: no broadcasting needed
        if _jm.AVAILABLE and u.ndim == 2:  # the same operations compiled, wrist by wrist (kernel.step_horner)
            out = np.empty(T.shape)
            _tk.step_horner(
                np.ascontiguousarray(T),
                np.ascontiguousarray(u),
                float(dt),
                params.layer_input_per_volt(u.shape[1]),
                params._k_at,
                params._k_t,
                params._col_neg_tinf[:, 0],
                params._k_tc,
                params._k_r,
                params._k_inf,
                float(params.coupling_per_s),
                out,
            )
            return out
        shape = T.shape
    else:
        shape = np.broadcast_shapes(T.shape, u.shape + (2,))
        T = np.broadcast_to(T, shape)
        u = np.broadcast_to(u, shape[:2])
    n_layers = shape[1]
    m = shape[0] * n_layers
    i = (u * (-params.layer_input_per_volt(n_layers))).reshape(m)  # model input I per layer
    cs = params._col_at * i
    cs += params._col_neg_tinf
    cc = params._col_t * i
    cc += params._col_tc
    c0 = i * i
    c0 = params._col_r * c0
    c0 += params._col_inf
    g = params.coupling_per_s
    if g:
        cs[0] -= g
    x = np.empty((3, m))
    x[0:2] = T.reshape(m, 2).T
    x[2] = x[0]
    v = np.empty((3, m))
    w = np.empty((3, m))
    tmp = np.empty((2, m))
    _apply_M(v, tmp, x, cs, cc, g, n_layers)  # v = M x + b = f(x)
    v[0:2] += c0
    v[2] = v[0]
    for frac, src, dst in ((0.25, v, w), (1.0 / 3.0, w, x), (0.5, x, w)):
        # dst = v + frac h M src; x is free after v was formed, reuse it as a buffer
        _apply_M(dst, tmp, src, cs, cc, g, n_layers)
        dst[0:2] *= frac * dt
        dst[0:2] += v[0:2]
        dst[2] = dst[0]
    out = np.empty(shape)
    flat = out.reshape(m, 2).T
    np.multiply(w[0:2], dt, out=flat)
    flat += T.reshape(m, 2).T
    return out


def simulate(
    params: ThermalParams,
    commands_V: ArrayLike,
    dt: float,
    state0: ArrayLike | None = None,
    *,
    layers: int = 2,
    validate: bool = True,
) -> FloatArray:
    """Integrate a command history (K, N, L) or (K, L) [V]; returns temperatures (K + 1, N, L, 2).

    state0 defaults to :func:`rest_state`. Row k + 1 is the state after command k was held dt.
    """
    u = np.asarray(commands_V, dtype=float)
    if u.ndim == 2:
        u = u[:, None, :]
    if u.ndim != 3:
        raise ModelInputError('command history shape', u.shape, '(K, N, L) or (K, L)')
    if validate:
        check_dt(params, dt)
        check_command(params, u)
    T = rest_state(params, u.shape[1], u.shape[2]) if state0 is None else np.array(state0, dtype=float)
    if validate:
        check_state(T)
    out = np.empty((u.shape[0] + 1,) + np.broadcast_shapes(T.shape, u.shape[1:] + (2,)))
    out[0] = T
    for k in range(u.shape[0]):
        out[k + 1] = step(params, out[k], u[k], dt, validate=False)
    return out


# ------------------------------------------------------------ analytic results


def system_matrix(params: ThermalParams, command_V: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """(M, b) with dT/dt = M T + b for held commands (N, L): M (N, 2L, 2L), b (N, 2L).

    The flattened state orders layer-major: [layer0 muscle, layer0 exchanger, layer1 muscle, ...].
    """
    current = np.atleast_2d(model_input(params, command_V))
    n, n_layers = current.shape
    c_self, c_cross, c0 = _coefficients(params, current)
    M = np.zeros((n, 2 * n_layers, 2 * n_layers))
    for layer in range(n_layers):
        r = 2 * layer
        M[:, r, r] = c_self[:, layer, 0]
        M[:, r, r + 1] = c_cross[:, layer, 0]
        M[:, r + 1, r + 1] = c_self[:, layer, 1]
        M[:, r + 1, r] = c_cross[:, layer, 1]
        if params.coupling_per_s and n_layers == 2:
            M[:, r, 2 * (1 - layer)] += params.coupling_per_s
    return M, c0.reshape(n, 2 * n_layers)


def steady_state(params: ThermalParams, command_V: ArrayLike) -> tuple[FloatArray, BoolArray]:
    """Equilibrium M T + b = 0 under held commands (N, L) V; returns (T (N, L, 2), stable mask (N,)).

    ``stable`` is True where every eigenvalue of M has a negative real part; elsewhere the
    equilibrium exists but is never reached (the runaway of Eqs. 4.13/4.14 at large |I|).
    """
    M, b = system_matrix(params, command_V)
    T = np.linalg.solve(M, -b[..., None])[..., 0]
    stable = np.linalg.eigvals(M).real.max(axis=-1) < 0
    return T.reshape(M.shape[0], -1, 2), stable


def rest_state(params: ThermalParams, n: int, layers: int = 2) -> FloatArray:
    """Zero-drive equilibrium of n scenarios with `layers` layers, shape (n, layers, 2) [degC]."""
    T, _ = steady_state(params, np.zeros((1, layers)))
    return np.repeat(T, n, axis=0)


def muscle_temperature(params: ThermalParams, state: ArrayLike) -> FloatArray:
    """Muscle temperatures (the T1 faces, Eq. 4.13) of a state, shape (N, L) [degC]."""
    return np.asarray(state, dtype=float)[..., MUSCLE_FACE]


def over_temperature(params: ThermalParams, state: ArrayLike, limit_C: float | None = None) -> BoolArray:
    """Mask (N, L, 2) of faces above limit_C (default: the window's upper end, the TEM limit)."""
    lim = params.window_C[1] if limit_C is None else limit_C
    return np.asarray(state, dtype=float) > lim


def out_of_window(params: ThermalParams, state: ArrayLike) -> BoolArray:
    """Mask (N, L, 2) of faces outside window_C (also True for non-finite temperatures)."""
    T = np.asarray(state, dtype=float)
    lo, hi = params.window_C
    return ~((T >= lo) & (T <= hi))


# --------------------------------------------------------------- characterisation


@dataclass(frozen=True)
class ConstantCommandCharacterisation:
    """Result of :func:`characterise_constant_commands` (volts, degC)."""

    heating_max_V: float  # largest u > 0 whose trajectory stays in the window and converges
    cooling_max_V: float  # most negative u < 0 doing the same
    stable_range_V: tuple[float, float]  # where every eigenvalue of M(u) is negative
    converged_range_V: tuple[float, float]  # where the run converged at all (window ignored)
    steady_at_heating_max_C: tuple[float, float]  # (muscle, exchanger) faces
    steady_at_cooling_max_C: tuple[float, float]


def characterise_constant_commands(
    params: ThermalParams,
    span_V: float = 40.0,
    resolution_V: float = 0.01,
    horizon_s: float = 3000.0,
    dt: float = 0.5,
    converged_rate: float = 1e-3,
) -> ConstantCommandCharacterisation:
    """Find the largest constant |u| per direction that stays physical (the runaway of Eqs. 4.13/4.14).

    One module (L = 1, TEM 1's drive gain) starts at the zero-drive rest state; every u on a grid over
    [-span_V, span_V] is held for horizon_s (about 65 time constants of the slowest mode at
    rest). A command passes when every face stays inside ``params.window_C`` at every step and
    max |dT/dt| < converged_rate [degC/s] at the end. The limit is the end of the contiguous
    passing run from 0 in each direction. ``params``' own command limits are ignored.
    """
    p = params.with_limits(-2 * span_V, 2 * span_V)
    u = np.arange(-round(span_V / resolution_V), round(span_V / resolution_V) + 1) * resolution_V
    cmd = u[:, None]
    T = rest_state(p, u.size, 1)
    inside = np.ones(u.size, bool)
    with np.errstate(all='ignore'):  # runaway scenarios overflow on purpose
        for _ in range(int(round(horizon_s / dt))):
            T = step(p, T, cmd, dt, validate=False)
            inside &= ~out_of_window(p, T).any(axis=(1, 2))
        rate = np.abs(derivative(p, T, cmd)).max(axis=(1, 2))
    converged = rate < converged_rate  # NaN compares False
    good = inside & converged
    zero = int(np.flatnonzero(u == 0)[0])
    up = good[zero:]
    down = good[zero::-1]
    i_up = (np.argmin(up) if not up.all() else up.size) - 1
    i_down = (np.argmin(down) if not down.all() else down.size) - 1
    heat, cool = float(u[zero + i_up]), float(u[zero - i_down])
    _, stable = steady_state(p, cmd)
    ss, _ = steady_state(p, np.array([[heat], [cool]]))
    return ConstantCommandCharacterisation(
        heat,
        cool,
        (float(u[stable].min()), float(u[stable].max())),
        (float(u[converged].min()), float(u[converged].max())),
        (float(ss[0, 0, 0]), float(ss[0, 0, 1])),
        (float(ss[1, 0, 0]), float(ss[1, 0, 1])),
    )


#: Frequencies of the seed's identification sines (Sec. 4.3.1) [Hz].
SEED_SINE_FREQUENCIES_HZ = (1 / 128, 1 / 64, 1 / 32, 1 / 16, 1 / 8, 1 / 4, 1 / 2, 1.0)


def sine_response(
    params: ThermalParams,
    amplitude_V: float = 12.0,
    frequencies_Hz: tuple[float, ...] = SEED_SINE_FREQUENCIES_HZ,
    duration_s: float = 1024.0,
    dt: float = 0.01,
) -> dict[str, FloatArray]:
    """One module (L = 1) from rest under u = A sin(2 pi f t), the seed's Sec. 4.3.1 experiment.

    Returns per frequency the (min, max) of each face over the last 128 s (periodic steady
    state when it exists) and over the whole run, and whether the run left the window.
    Command limits are ignored (the experiment is what probes them).
    """
    p = params.with_limits(-2 * abs(amplitude_V) - 1, 2 * abs(amplitude_V) + 1)
    f = np.asarray(frequencies_Hz, dtype=float)
    T = rest_state(p, f.size, 1)
    k_total = int(round(duration_s / dt))
    k_tail = k_total - int(round(128.0 / dt))
    lo = np.full((f.size, 2), np.inf)
    hi = np.full((f.size, 2), -np.inf)
    lo_all, hi_all = lo.copy(), hi.copy()
    left = np.zeros(f.size, bool)
    with np.errstate(all='ignore'):
        for k in range(k_total):
            t_mid = k * dt  # zero-order hold of the sample at the step's start
            u = (amplitude_V * np.sin(2 * np.pi * f * t_mid))[:, None]
            T = step(p, T, u, dt, validate=False)
            faces = T[:, 0, :]
            np.minimum(lo_all, faces, out=lo_all)
            np.maximum(hi_all, faces, out=hi_all)
            left |= out_of_window(p, T).any(axis=(1, 2))
            if k >= k_tail:
                np.minimum(lo, faces, out=lo)
                np.maximum(hi, faces, out=hi)
    return {
        'frequency_Hz': f,
        'tail_min_C': lo,
        'tail_max_C': hi,
        'run_min_C': lo_all,
        'run_max_C': hi_all,
        'left_window': left,
    }


def _main() -> None:  # pragma: no cover - a report, exercised by doc/explanation/model.md
    import dataclasses as dc

    p = ThermalParams()
    print(
        f'Table 4.9 implied ambients (Eq. 4.15): T1 {p.muscle_face.implied_ambient_C:.3f} degC, T2 {p.exchanger_face.implied_ambient_C:.3f} degC'
    )
    print(
        'zero-drive rest state: muscle face {:.3f}, exchanger face {:.3f} degC'.format(
            *tuple(rest_state(p, 1, 1)[0, 0])
        )
    )
    for scale in (p.input_per_volt, 1.0):
        q = dc.replace(p, input_per_volt=scale)
        c = characterise_constant_commands(q)
        print(f'\ninput_per_volt = {scale:g} (I = -{scale:g} u); window {p.window_C} degC on every face')
        print(
            f'  largest held heating command  u = {c.heating_max_V:+.2f} V (I = {-scale * c.heating_max_V:+.3f}),'
            f' steady faces {c.steady_at_heating_max_C[0]:.2f} / {c.steady_at_heating_max_C[1]:.2f} degC'
        )
        print(
            f'  largest held cooling command  u = {c.cooling_max_V:+.2f} V (I = {-scale * c.cooling_max_V:+.3f}),'
            f' steady faces {c.steady_at_cooling_max_C[0]:.2f} / {c.steady_at_cooling_max_C[1]:.2f} degC'
        )
        print(
            f'  linearly stable for u in [{c.stable_range_V[0]:+.2f}, {c.stable_range_V[1]:+.2f}] V;'
            f' converged within 3000 s for u in [{c.converged_range_V[0]:+.2f}, {c.converged_range_V[1]:+.2f}] V'
        )
        r = sine_response(q)
        print('  12 V sine from rest, 1024 s (min/max over the run; last 128 s), muscle face T1 | exchanger face T2:')
        for i, f in enumerate(r['frequency_Hz']):
            print(
                f'    f = 1/{1 / f:<5g} Hz  T1 {r["run_min_C"][i, 0]:9.4g} .. {r["run_max_C"][i, 0]:<9.4g}'
                f' ({r["tail_min_C"][i, 0]:7.4g} .. {r["tail_max_C"][i, 0]:<7.4g})'
                f' | T2 {r["run_min_C"][i, 1]:9.4g} .. {r["run_max_C"][i, 1]:<9.4g}'
                f' ({r["tail_min_C"][i, 1]:7.4g} .. {r["tail_max_C"][i, 1]:<7.4g})'
                f'  left window: {bool(r["left_window"][i])}'
            )
    print(f'\ndefault limits: u in [{p.u_min_V:+g}, {p.u_max_V:+g}] V at input_per_volt = {p.input_per_volt:g}')
    ss, _ = steady_state(p, np.array([[p.u_max_V], [p.u_min_V]]))
    print(
        f'  steady faces at u_max: {ss[0, 0, 0]:.2f} / {ss[0, 0, 1]:.2f} degC; at u_min: {ss[1, 0, 0]:.2f} / {ss[1, 0, 1]:.2f} degC'
    )


if __name__ == '__main__':  # pragma: no cover
    _main()
