"""A second TEM heat-balance form: the Peltier / Seebeck two-node model, per layer (numpy reference).

Table 4.9's form (:mod:`sma_wrist.core.thermal.heat_balance`, Eqs. 4.13/4.14) is a polynomial fitted in degC with a
current proportional to the drive voltage. A Peltier module driven by a voltage instead carries the current its
back-EMF leaves, pumps heat in proportion to the absolute temperature of each junction and dissipates half its
Joule heat on each face. Per layer (one module between the muscle node m and the exchanger node x; temperatures
T in degC, T + 273.15 in K; drive u [V], positive heats the muscle)::

    I = (u - S (T_m - T_x)) / R                                                                  (P.1)
    C_m dT_m/dt =  S I (T_m + 273.15) + I^2 R / 2 - K (T_m - T_x) - h_m (T_m - T_amb)           (P.2)
    C_x dT_x/dt = -S I (T_x + 273.15) + I^2 R / 2 + K (T_m - T_x) - h_x (T_x - T_cool)          (P.3)

S the module's Seebeck coefficient [V/K], R its electrical resistance [ohm], K its thermal conductance [W/K],
C_m, C_x the nodes' heat capacities [J/K], h_m, h_x their losses to the ambient T_amb and the coolant T_cool
[W/K, degC]. Over an interval whose drive is not constant the Joule term uses the interval's mean of u^2
(``u2``): I^2 R = (u2 - 2 u S dT + (S dT)^2) / R. The muscle nodes of the two layers may exchange heat
(``coupling_per_s``, as in ThermalParams, [1/s] of the muscle node). The wires' latent heat (Eq. P.4,
``PeltierParams.latent_C``): a full transformation of a muscle's bundle (3.7 g of NiTi at 15-25 J/g, 55-92 J) moves
a ~90 J/K muscle node by ~0.8 degC. Its input, the wire's martensite fraction, is not simulated here: the diagnosis'
replay (:mod:`sma_wrist.diagnose.effects`) and the fit (:mod:`sma_wrist.core.thermal.peltier_fit`) take it from the
phase-fraction wire's replay on the measured temperatures. It is identified only through the thermocouple's lag: on
the emulated phase-fraction wrist (0.78 degC, 0.2 s lag) a latent term fitted without the lag finds 0.03 and
0.34 degC per TEM, through the lag commissioning's refinement reads 0.66 / 0.83 (doc/explanation/commissioning.md).

Identifiability (decision): only temperatures and the drive are measured, so every power (P.2, P.3) and every
heat capacity share one scale: R -> R / a, K, h_m, h_x, C_m, C_x -> a (K, h_m, h_x, C_m, C_x) leaves the
temperatures unchanged for every a (I scales by a, S I T and I^2 R by a). R is therefore not fitted but fixed at a
datasheet-like value (:data:`DATASHEET_RESISTANCE_OHM`, a 12 V / 6 A class module: V_max / I_max); the fitted
S, K, h and C are then those of a module with that resistance. With R fixed, the drive's scale is that of the
data (the voltage is measured), so S is identified; a per-TEM drive gain in front of u would trade with S and the
heat capacities (u -> g u, S -> g S, C, K, h -> g^2 (C, K, h)), so each layer has its own S instead of a gain.

Layout as in heat_balance: a state is (N, L, 2) [degC], faces [muscle, exchanger]; a command (N, L) [V].
The compiled kernel (:mod:`sma_wrist.core.thermal.kernel`, ``peltier_*``) integrates the same equations;
test_thermal_peltier holds it to this reference.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sma_wrist.core.errors import ModelInputError, ParameterError

FloatArray = NDArray[np.float64]

KELVIN = 273.15
#: the fixed scale of the form (module docstring): a 12 V / 6 A class module's V_max / I_max [ohm]
DATASHEET_RESISTANCE_OHM = 2.0
#: the per-layer vector's entries (:meth:`PeltierLayer.vector`), in order
LAYER_KEYS = (
    'seebeck_V_per_K',
    'resistance_ohm',
    'conductance_W_per_K',
    'muscle_capacity_J_per_K',
    'exchanger_capacity_J_per_K',
    'muscle_loss_W_per_K',
    'exchanger_loss_W_per_K',
    'ambient_C',
    'coolant_C',
)
N_LAYER = len(LAYER_KEYS)
#: the largest latent heat a muscle node may carry [degC per full transformation]: NiTi's 15-25 J/g over a node of
#: the bundle alone (0.5 J/(g K)) is 30-50 degC; a node with its TEM's ceramic and spreader is ~1 degC
LATENT_MAX_C = 50.0


@dataclass(frozen=True)
class PeltierLayer:
    """One module between a muscle node and an exchanger node (Eqs. P.1-P.3). Defaults: a 12 V / 6 A class module
    under a bundle of wires on a water-cooled exchanger (not fitted to anything; a start for identification)."""

    seebeck_V_per_K: float = 0.04
    resistance_ohm: float = DATASHEET_RESISTANCE_OHM
    conductance_W_per_K: float = 0.4
    muscle_capacity_J_per_K: float = 70.0
    exchanger_capacity_J_per_K: float = 300.0
    muscle_loss_W_per_K: float = 0.8
    exchanger_loss_W_per_K: float = 4.0
    ambient_C: float = 25.0
    coolant_C: float = 25.0

    def __post_init__(self) -> None:
        for k in LAYER_KEYS:
            v = getattr(self, k)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) or not np.isfinite(v):
                raise ParameterError(f'{k} = {v!r} must be a finite number')
            object.__setattr__(self, k, float(v))
        for k in LAYER_KEYS[:5]:
            if not getattr(self, k) > 0:
                raise ParameterError(f'{k} = {getattr(self, k)} must be > 0')
        for k in LAYER_KEYS[5:7]:
            if not getattr(self, k) >= 0:
                raise ParameterError(f'{k} = {getattr(self, k)} must be >= 0')

    def vector(self) -> FloatArray:
        """(N_LAYER,) the parameters in :data:`LAYER_KEYS` order."""
        return np.array([getattr(self, k) for k in LAYER_KEYS])

    @classmethod
    def from_vector(cls, v: ArrayLike) -> PeltierLayer:
        return cls(**{k: float(x) for k, x in zip(LAYER_KEYS, np.asarray(v, dtype=float))})


@dataclass(frozen=True)
class PeltierParams:
    """The Peltier form of both layers (layer 0: TEM 1 under muscle 1). ``coupling_per_s`` [1/s]: conductance
    between the two muscle nodes over the muscle node's heat capacity (as ThermalParams.coupling_per_s).
    ``drive_gain`` scales the voltage the modules see (u -> drive_gain u), ``joule_scale`` their Joule heat: both 1
    for an identified form, other values model a drifted device (:meth:`scaled`, the plant's extensions).

    ``latent_C`` (per layer) [degC]: the wires' latent heat, what a full transformation of the muscle's bundle moves
    its muscle node by (H m / C_m: transformation enthalpy x the bundle's mass over the node's heat capacity; the
    martensite fraction xi rising on cooling releases it, falling on heating absorbs it)::

        dT_m/dt += latent_C dxi/dt                                                                      (P.4)

    It needs the wire's martensite fraction (a phase-fraction wire, :mod:`sma_wrist.core.hysteresis.phase_fraction`);
    0 leaves it out."""

    layers: tuple[PeltierLayer, PeltierLayer] = (PeltierLayer(), PeltierLayer())
    coupling_per_s: float = 0.0
    drive_gain: float = 1.0
    joule_scale: float = 1.0
    latent_C: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        layers = tuple(self.layers)
        if len(layers) != 2 or not all(isinstance(x, PeltierLayer) for x in layers):
            raise ParameterError('a Peltier heat balance needs two layers (TEM 1, TEM 2)')
        object.__setattr__(self, 'layers', layers)
        if not (np.isfinite(self.coupling_per_s) and self.coupling_per_s >= 0):
            raise ParameterError(f'coupling_per_s = {self.coupling_per_s!r} must be finite and >= 0')
        for k in ('drive_gain', 'joule_scale'):
            if not (np.isfinite(getattr(self, k)) and getattr(self, k) > 0):
                raise ParameterError(f'{k} = {getattr(self, k)!r} must be finite and > 0')
        try:
            latent = tuple(float(x) for x in self.latent_C)
        except (TypeError, ValueError):
            latent = ()
        if len(latent) != 2 or not all(np.isfinite(x) and 0.0 <= x <= LATENT_MAX_C for x in latent):
            raise ParameterError(
                f'latent_C = {self.latent_C!r} must be two numbers in [0, {LATENT_MAX_C:g}] degC (TEM 1, TEM 2)'
            )
        object.__setattr__(self, 'latent_C', latent)

    def coef(self, layers: int = 2) -> FloatArray:
        """(layers, N_LAYER) per-layer vectors (one layer: TEM 1's)."""
        if not 1 <= layers <= 2:
            raise ModelInputError('Peltier layers', layers, '1 or 2')
        return np.stack([x.vector() for x in self.layers[:layers]])

    def scaled(
        self, gain: float = 1.0, losses: float = 1.0, joule: float = 1.0, ambient_shift_C: float = 0.0
    ) -> PeltierParams:
        """Copy as a drifted device, the Peltier counterpart of ThermalParams.scaled: drive gain x ``gain``, every
        muscle node's loss h_m x ``losses``, the Joule heat x ``joule``, T_amb and T_cool + ``ambient_shift_C``."""
        layers = tuple(
            dataclasses.replace(
                x,
                muscle_loss_W_per_K=x.muscle_loss_W_per_K * losses,
                ambient_C=x.ambient_C + ambient_shift_C,
                coolant_C=x.coolant_C + ambient_shift_C,
            )
            for x in self.layers
        )
        return dataclasses.replace(
            self, layers=layers, drive_gain=self.drive_gain * gain, joule_scale=self.joule_scale * joule
        )

    def with_layer(self, index: int, layer: PeltierLayer) -> PeltierParams:
        new = list(self.layers)
        new[index] = layer
        return dataclasses.replace(self, layers=tuple(new))


# --------------------------------------------------------------------------------------------------- dynamics
def derivative_coef(
    coef: ArrayLike,
    state: ArrayLike,
    command_V: ArrayLike,
    u2: ArrayLike | None = None,
    coupling_per_s: float = 0.0,
    gain: float = 1.0,
    joule: float = 1.0,
) -> FloatArray:
    """dT/dt (Eqs. P.1-P.3) [degC/s] for per-layer vectors coef (..., L, N_LAYER) (broadcast against the state),
    states (..., L, 2) [degC], commands (..., L) [V] and their interval mean squares u2 (default u^2) [V^2]; the
    drive x ``gain``, the Joule heat x ``joule`` (PeltierParams.drive_gain, joule_scale)."""
    c = np.asarray(coef, dtype=float)
    T = np.asarray(state, dtype=float)
    u = np.asarray(command_V, dtype=float)
    S, R, K, Cm, Cx, hm, hx, Ta, Tc = (c[..., i] for i in range(N_LAYER))
    Tm, Tx = T[..., 0], T[..., 1]
    d = Tm - Tx
    emf = S * d
    ug = gain * u
    u2g = ug * ug if u2 is None else gain * gain * np.asarray(u2, dtype=float)
    cur = (ug - emf) / R
    i2r = joule * (u2g - 2.0 * ug * emf + emf * emf) / R
    qm = S * cur * (Tm + KELVIN) + 0.5 * i2r - K * d - hm * (Tm - Ta)
    qx = -S * cur * (Tx + KELVIN) + 0.5 * i2r + K * d - hx * (Tx - Tc)
    dm = qm / Cm
    if coupling_per_s and T.shape[-2] == 2:
        dm = dm + coupling_per_s * (Tm[..., ::-1] - Tm)
    return np.stack([dm, qx / Cx], axis=-1)


def derivative(params: PeltierParams, state: ArrayLike, command_V: ArrayLike) -> FloatArray:
    """dT/dt (Eqs. P.1-P.3) for states (N, L, 2) [degC] under commands (N, L) [V]."""
    T = np.asarray(state, dtype=float)
    return derivative_coef(
        params.coef(T.shape[-2]), T, command_V, None, params.coupling_per_s, params.drive_gain, params.joule_scale
    )


def step_coef(
    coef: ArrayLike,
    state: ArrayLike,
    command_V: ArrayLike,
    dt: float,
    u2: ArrayLike | None = None,
    coupling_per_s: float = 0.0,
    gain: float = 1.0,
    joule: float = 1.0,
) -> FloatArray:
    """One classical RK4 step [degC] of Eqs. P.1-P.3, the drive (and its mean square u2) held over dt [s]."""
    T = np.asarray(state, dtype=float)
    a = (command_V, u2, coupling_per_s, gain, joule)
    k1 = derivative_coef(coef, T, *a)
    k2 = derivative_coef(coef, T + 0.5 * dt * k1, *a)
    k3 = derivative_coef(coef, T + 0.5 * dt * k2, *a)
    k4 = derivative_coef(coef, T + dt * k3, *a)
    return T + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


def step(params: PeltierParams, state: ArrayLike, command_V: ArrayLike, dt: float) -> FloatArray:
    """One RK4 step of states (N, L, 2) [degC] under commands (N, L) [V] held dt [s]."""
    T = np.asarray(state, dtype=float)
    if not (np.isfinite(dt) and dt > 0):
        raise ModelInputError('thermal step dt', dt, '> 0', 's')
    return step_coef(
        params.coef(T.shape[-2]), T, command_V, dt, None, params.coupling_per_s, params.drive_gain, params.joule_scale
    )


def simulate(
    params: PeltierParams, commands_V: ArrayLike, dt: float, state0: ArrayLike | None = None, layers: int = 2
) -> FloatArray:
    """Integrate commands (K, N, L) or (K, L) [V] from state0 (default :func:`rest_state`): (K + 1, N, L, 2)."""
    u = np.asarray(commands_V, dtype=float)
    if u.ndim == 2:
        u = u[:, None, :]
    if u.ndim != 3:
        raise ModelInputError('command history shape', u.shape, '(K, N, L) or (K, L)')
    T = rest_state(params, u.shape[1], u.shape[2]) if state0 is None else np.array(state0, dtype=float)
    out = np.empty((u.shape[0] + 1,) + np.broadcast_shapes(T.shape, u.shape[1:] + (2,)))
    out[0] = T
    for k in range(u.shape[0]):
        out[k + 1] = step(params, out[k], u[k], dt)
    return out


def steady_state_coef(
    coef: ArrayLike, command_V: ArrayLike, iterations: int = 60, gain: float = 1.0, joule: float = 1.0
) -> FloatArray:
    """Equilibrium faces (..., L, 2) [degC] under held commands (..., L) [V] (Newton on Eqs. P.2/P.3 with the
    2 x 2 Jacobian by central differences; no muscle-muscle coupling)."""
    c = np.asarray(coef, dtype=float)
    u = np.asarray(command_V, dtype=float)
    shape = np.broadcast_shapes(c.shape[:-1], u.shape)
    T = np.empty(shape + (2,))
    T[..., 0] = np.broadcast_to(c[..., 7], shape)
    T[..., 1] = np.broadcast_to(c[..., 8], shape)
    h = 1e-4
    for _ in range(iterations):
        f = derivative_coef(c, T, u, None, 0.0, gain, joule)
        J = np.empty(shape + (2, 2))
        for j in range(2):
            e = np.zeros(2)
            e[j] = h
            J[..., :, j] = (
                derivative_coef(c, T + e, u, None, 0.0, gain, joule)
                - derivative_coef(c, T - e, u, None, 0.0, gain, joule)
            ) / (2 * h)
        dx = np.linalg.solve(J, -f[..., None])[..., 0]
        T = T + dx
        if np.all(np.abs(dx) < 1e-10):
            break
    return T


def rest_state(params: PeltierParams, n: int, layers: int = 2) -> FloatArray:
    """Zero-drive equilibrium of n scenarios, (n, layers, 2) [degC]."""
    T = steady_state_coef(params.coef(layers), np.zeros(layers), gain=params.drive_gain, joule=params.joule_scale)
    return np.repeat(T[None], n, axis=0)


def ambients_for_rest(coef: ArrayLike, rest_C: tuple[float, float]) -> tuple[FloatArray, FloatArray]:
    """(T_amb, T_cool) [degC] that put the zero-drive equilibrium at rest_C = (muscle, exchanger) [degC] for the
    other entries of coef (..., N_LAYER): Eqs. P.2/P.3 at u = 0 solved for the ambients (linear in them)."""
    c = np.asarray(coef)
    S, R, K, _, _, hm, hx = (c[..., i] for i in range(7))
    tm, tx = rest_C
    d = tm - tx
    cur = -S * d / R
    joule = 0.5 * cur * cur * R
    qm = S * cur * (tm + KELVIN) + joule - K * d
    qx = -S * cur * (tx + KELVIN) + joule + K * d
    return tm - qm / hm, tx - qx / hx


def muscle_temperature(state: ArrayLike) -> FloatArray:
    """Muscle node temperatures (N, L) [degC] of a state (N, L, 2)."""
    return np.asarray(state, dtype=float)[..., 0]
