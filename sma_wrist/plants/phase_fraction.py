"""A wrist whose wires are NOT the controllers' model: a phase-fraction (martensite fraction) wire.

A structurally different benchmark plant, written from the
literature rather than from this project's SD-GPI, its Table 4.9 heat balance or its sensors.
It drives the same joint (Eq. 4.18, :func:`sma_wrist.core.plant.kernel.joint_step_one`) and
the same chain geometry (Eq. 4.17, 140 wires of 0.25 mm x 83 mm, pre-load elongation
1.98 mm), and exposes the plant interface the closed loop uses (``advance(command_V, n)``,
``muscle_temperature_C``, ``wire_stress_Pa``, ``state.q``), plus :meth:`measure`: what the
thermocouples and the potentiometer report.

Wire (per wire; Liang-Rogers cosine kinetics with Brinson's stress-dependent
transformation temperatures; stresses sigma in MPa, temperatures in degC):

* effective temperatures (Clausius-Clapeyron): x_A = T - (sigma - sigma_ref) / C_A for the
  reverse (martensite -> austenite) transformation, x_M = T - (sigma - sigma_ref) / C_M for the
  forward one; the four transformation temperatures M_f < M_s < A_s < A_f hold at sigma_ref;
* major branches (Liang & Rogers 1990): martensite fraction on heating
  f_A(x) = (1 + cos(pi (x - A_s) / (A_f - A_s))) / 2 on [A_s, A_f] (1 below, 0 above), on cooling
  f_M(x) = (1 + cos(pi (x - M_f) / (M_s - M_f))) / 2 on [M_f, M_s] (1 below, 0 above);
* minor loops (reversal-point scaling, the rule of Ikuta / Bekker & Brinson): each branch
  passes through the point where the other direction last transformed,
  heating bound xi_H = xi_a f_A(x_A) / f_A(x_a), cooling bound 1 - xi_C = (1 - xi_c)(1 - f_M(x_M)) /
  (1 - f_M(x_c)), and xi = max(min(xi_prev, xi_H), xi_C): xi only falls along a heating branch and
  only rises along a cooling one, and stays between the major branches;
* constitutive law (Brinson 1993, with its modulus rule; detwinning as a reversible ramp):
  eps = sigma / E(xi) + eps_L g(sigma) xi + alpha (T - T_ref), E(xi) = E_A + xi (E_M - E_A),
  g(sigma) the oriented share of the martensite, a cosine ramp from sigma_s to sigma_f
  (Brinson's critical detwinning stresses): martensite under little stress gives little
  strain, which is what lets the cold, pre-loaded pair hold the joint;
* latent heat: a fraction change d xi releases H m_wires d xi of heat into the muscle node.

eps(sigma) is strictly increasing at fixed T and memory, so the wire stress for the strain
the chain imposes is a unique root (bisection), then the memory is committed there.

TEM (per layer, its own lumped two-node model, not Eqs. 4.13-4.14): a Peltier module driven
by a voltage u (positive heats the muscle face), current I = (u - S (T_m - T_x)) / R (Seebeck
back-EMF), heat into the muscle node S I T_m[K] + I^2 R / 2 - K (T_m - T_x) - h_m (T_m - T_amb),
into the exchanger node -S I T_x[K] + I^2 R / 2 + K (T_m - T_x) - h_x (T_x - T_cool); node heat
capacities C_m (muscle bundle + ceramic + spreader), C_x (exchanger). Parameters of a
12-15 V / 6 A class module (S 0.05 V/K, R 2.4 ohm, K 0.5 W/K), not Table 4.9.

Sensors: thermocouple = first-order lag of the muscle node (``tc_lag_s``) plus white noise
(``tc_noise_C``) per reading; potentiometer = the angle plus white noise (``pot_noise_rad``);
seeded.

Everything is vectorised over N scenarios, each with its own parameters (a list of
:class:`PhaseFractionParams`), in one compiled loop (numba when installed, else plain Python).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sma_wrist.core.errors import ModelInputError, ParameterError, check_finite, check_range
from sma_wrist.core.hysteresis.muscle import MuscleGeometry
from sma_wrist.core.jit import _jit
from sma_wrist.core.joint.dynamics import G, JointParams
from sma_wrist.core.joint.kernel import joint_step_one

FloatArray = NDArray[np.float64]
KELVIN = 273.15


@dataclass(frozen=True)
class WireParams:
    """NiTi actuator wire, phase-fraction model (module docstring). Temperatures at sigma_ref."""

    M_f_C: float = 42.0
    M_s_C: float = 54.0
    A_s_C: float = 58.0
    A_f_C: float = 72.0
    sigma_ref_MPa: float = 130.0  # stress at which the four temperatures hold (the pair's pre-load)
    C_M_MPa_per_C: float = 8.0  # Clausius-Clapeyron slope of the forward transformation (Brinson 1993: 8)
    C_A_MPa_per_C: float = 10.0  # of the reverse one (literature 7-14)
    E_A_GPa: float = 70.0
    E_M_GPa: float = 30.0
    eps_L: float = 0.04  # maximum recoverable (transformation) strain
    sigma_s_MPa: float = 70.0  # detwinning starts (Brinson's sigma_s^cr is 100 MPa at M_s)
    sigma_f_MPa: float = 170.0  # detwinning complete (Brinson: 170 MPa)
    alpha_per_C: float = 11e-6  # thermal expansion
    T_ref_C: float = 20.0
    latent_J_per_kg: float = 19e3  # transformation enthalpy (NiTi 15-25 J/g)
    density_kg_m3: float = 6450.0

    def __post_init__(self) -> None:
        if not (self.M_f_C < self.M_s_C <= self.A_s_C < self.A_f_C):
            raise ParameterError(
                f'transformation temperatures need M_f < M_s <= A_s < A_f, got '
                f'{self.M_f_C}, {self.M_s_C}, {self.A_s_C}, {self.A_f_C} degC'
            )
        for name in ('C_M_MPa_per_C', 'C_A_MPa_per_C', 'E_A_GPa', 'E_M_GPa', 'eps_L', 'density_kg_m3'):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ParameterError(f'{name} = {v!r} must be > 0')
        if not 0 <= self.sigma_s_MPa < self.sigma_f_MPa:
            raise ParameterError(f'need 0 <= sigma_s < sigma_f, got {self.sigma_s_MPa}, {self.sigma_f_MPa} MPa')
        if not self.eps_L < 0.1:
            raise ParameterError(f'eps_L = {self.eps_L} is beyond any NiTi wire (< 0.1)')


@dataclass(frozen=True)
class PeltierParams:
    """One TEM layer and its two thermal nodes (module docstring); SI units, degC."""

    seebeck_V_per_K: float = 0.05
    resistance_ohm: float = 2.4
    conductance_W_per_K: float = 0.5
    muscle_capacity_J_per_K: float = 90.0
    muscle_loss_W_per_K: float = 0.6
    exchanger_capacity_J_per_K: float = 400.0
    exchanger_loss_W_per_K: float = 9.0  # to the coolant through the heat sink
    ambient_C: float = 24.0
    coolant_C: float = 26.0
    u_limit_V: float = 24.0  # driver rating: commands are clipped here

    def __post_init__(self) -> None:
        for name in (
            'seebeck_V_per_K',
            'resistance_ohm',
            'conductance_W_per_K',
            'muscle_capacity_J_per_K',
            'muscle_loss_W_per_K',
            'exchanger_capacity_J_per_K',
            'exchanger_loss_W_per_K',
            'u_limit_V',
        ):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ParameterError(f'{name} = {v!r} must be > 0')


@dataclass(frozen=True)
class SensorParams:
    """What the sensors add: thermocouple lag and noise, potentiometer noise (seeded)."""

    tc_lag_s: float = 0.2
    tc_noise_C: float = 0.2
    pot_noise_rad: float = 0.003
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ('tc_lag_s', 'tc_noise_C', 'pot_noise_rad'):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ParameterError(f'{name} = {v!r} must be >= 0')


@dataclass(frozen=True)
class PhaseFractionParams:
    wire: WireParams = field(default_factory=WireParams)
    tem: PeltierParams = field(default_factory=PeltierParams)
    sensor: SensorParams = field(default_factory=SensorParams)
    muscle: MuscleGeometry = field(default_factory=MuscleGeometry)
    joint: JointParams = field(default_factory=JointParams)
    preload_elongation_mm: float = 1.98  # same chain calibration as the project's plant
    dt: float = 1e-3

    def __post_init__(self) -> None:
        if not 0 < self.dt <= 2e-3:
            raise ParameterError(f'dt = {self.dt!r} s must be in (0, 0.002] (explicit heat balance, stiff wires)')


#: column indices of the per-scenario constant table (pack)
_WIRE = (
    'M_f',
    'M_s',
    'A_s',
    'A_f',
    'sig_ref',
    'C_M',
    'C_A',
    'E_A',
    'E_M',
    'eps_L',
    'sig_s',
    'sig_f',
    'alpha',
    'T_ref',
    'latent_J',
    'L_mm',
    'area_MPa_N',
)
_TEM = ('S', 'R', 'K', 'C_m', 'h_m', 'C_x', 'h_x', 'T_amb', 'T_cool', 'u_lim', 'e0_mm', 'r_eff', 'n_wires', 'dt')


def pack(params: Sequence[PhaseFractionParams]) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(wire (N, 17), tem (N, 14), joint (N, 10)) constant tables of :func:`step_many`."""
    wires, tems, joints = [], [], []
    for p in params:
        w, t, g, j = p.wire, p.tem, p.muscle, p.joint
        area = g.wire_area_m2
        mass = g.n_wires * area * g.wire_length_mm * 1e-3 * w.density_kg_m3
        wires.append(
            [
                w.M_f_C,
                w.M_s_C,
                w.A_s_C,
                w.A_f_C,
                w.sigma_ref_MPa,
                w.C_M_MPa_per_C,
                w.C_A_MPa_per_C,
                w.E_A_GPa * 1e3,
                w.E_M_GPa * 1e3,
                w.eps_L,
                w.sigma_s_MPa,
                w.sigma_f_MPa,
                w.alpha_per_C,
                w.T_ref_C,
                w.latent_J_per_kg * mass,
                g.wire_length_mm,
                area * 1e6,
            ]
        )
        tems.append(
            [
                t.seebeck_V_per_K,
                t.resistance_ohm,
                t.conductance_W_per_K,
                t.muscle_capacity_J_per_K,
                t.muscle_loss_W_per_K,
                t.exchanger_capacity_J_per_K,
                t.exchanger_loss_W_per_K,
                t.ambient_C,
                t.coolant_C,
                t.u_limit_V,
                p.preload_elongation_mm,
                j.r_eff_m,
                float(g.n_wires),
                p.dt,
            ]
        )
        joints.append(
            [
                j.joint_inertia_kgm2,
                j.lever_m,
                j.coulomb_Nm,
                j.viscous_Nms,
                j.static_Nm,
                j.stick_velocity_rad_s,
                j.q_neutral_rad,
                j.q_min_rad,
                j.q_max_rad,
                G,
            ]
        )
    return np.array(wires), np.array(tems), np.array(joints)


# ----------------------------------------------------------------------------- wire kinetics
@_jit
def major_heating(x, A_s, A_f):  # pragma: no cover - compiled
    """Martensite fraction on the major heating branch at effective temperature x (Liang-Rogers)."""
    if x <= A_s:
        return 1.0
    if x >= A_f:
        return 0.0
    return 0.5 * (1.0 + math.cos(math.pi * (x - A_s) / (A_f - A_s)))


@_jit
def major_cooling(x, M_f, M_s):  # pragma: no cover - compiled
    """Martensite fraction on the major cooling branch at effective temperature x."""
    if x <= M_f:
        return 1.0
    if x >= M_s:
        return 0.0
    return 0.5 * (1.0 + math.cos(math.pi * (x - M_f) / (M_s - M_f)))


@_jit
def fraction(T, sig, xi_prev, xi_h, x_h, xi_c, x_c, wc):  # pragma: no cover - compiled
    """(xi, x_A, x_M) at temperature T [degC] and stress sig [MPa] from the frozen memory:
    heating anchor (x_h, xi_h), cooling anchor (x_c, xi_c), previous fraction xi_prev."""
    x_a = T - (sig - wc[4]) / wc[6]
    x_m = T - (sig - wc[4]) / wc[5]
    # each branch bounds xi only on its own side of its anchor (a heating branch above x_h, a
    # cooling branch below x_c); elsewhere the other direction's branch decides
    upper = 1.0
    if x_a > x_h:
        den_h = max(major_heating(x_h, wc[2], wc[3]), 1e-12)
        upper = min(xi_h * major_heating(x_a, wc[2], wc[3]) / den_h, 1.0)
    lower = 0.0
    if x_m < x_c:
        den_c = max(1.0 - major_cooling(x_c, wc[0], wc[1]), 1e-12)
        lower = 1.0 - (1.0 - xi_c) * (1.0 - major_cooling(x_m, wc[0], wc[1])) / den_c
    xi = max(min(xi_prev, upper), max(lower, 0.0))
    return min(max(xi, 0.0), 1.0), x_a, x_m


@_jit
def strain(T, sig, xi, wc):  # pragma: no cover - compiled
    """Brinson's constitutive law with reversible detwinning, eps(sigma [MPa], xi, T)."""
    s_s, s_f = wc[10], wc[11]
    if sig <= s_s:
        g = 0.0
    elif sig >= s_f:
        g = 1.0
    else:
        g = 0.5 * (1.0 - math.cos(math.pi * (sig - s_s) / (s_f - s_s)))
    modulus = wc[7] + xi * (wc[8] - wc[7])
    return sig / modulus + wc[9] * g * xi + wc[12] * (T - wc[13])


@_jit
def solve_stress(T, eps, xi_prev, xi_h, x_h, xi_c, x_c, wc):  # pragma: no cover - compiled
    """Wire stress [MPa] at which the wire's strain equals eps (bisection: eps(sigma) increases),
    with the fraction there and d eps / d sigma [1/MPa]; 0 MPa for a slack wire."""
    lo, hi = 0.0, 2000.0
    xi, _, _ = fraction(T, lo, xi_prev, xi_h, x_h, xi_c, x_c, wc)
    if strain(T, lo, xi, wc) >= eps:  # slack: the chain asks for less than the unloaded wire
        sig = 0.0
    else:
        for _ in range(48):
            mid = 0.5 * (lo + hi)
            xm, _, _ = fraction(T, mid, xi_prev, xi_h, x_h, xi_c, x_c, wc)
            if strain(T, mid, xm, wc) < eps:
                lo = mid
            else:
                hi = mid
        sig = 0.5 * (lo + hi)
    xi, _, _ = fraction(T, sig, xi_prev, xi_h, x_h, xi_c, x_c, wc)
    h = 0.05
    xi2, _, _ = fraction(T, sig + h, xi_prev, xi_h, x_h, xi_c, x_c, wc)
    de = (strain(T, sig + h, xi2, wc) - strain(T, sig, xi, wc)) / h
    return sig, xi, max(de, 1e-9)


@_jit
def _wire_step(i, T, eps, xi, xi_h, x_h, xi_c, x_c, sig, wc):  # pragma: no cover - compiled
    """Solve wire i (stacked index) at T, eps and commit its memory; returns (d xi, d eps/d sigma)."""
    s, x_new, de = solve_stress(T, eps, xi[i], xi_h[i], x_h[i], xi_c[i], x_c[i], wc)
    d = commit(i, T, s, xi, xi_h, x_h, xi_c, x_c, wc)
    sig[i] = s
    return d, de


@_jit
def commit(i, T, sig, xi, xi_h, x_h, xi_c, x_c, wc):  # pragma: no cover - compiled
    """Advance wire i's memory to (T, sig): the new fraction, and the anchor of the branch the
    other direction will start from if the wire transformed; returns the change of xi."""
    x_new, x_a, x_m = fraction(T, sig, xi[i], xi_h[i], x_h[i], xi_c[i], x_c[i], wc)
    d = x_new - xi[i]
    if d < 0.0:  # transformed on heating: the next cooling branch starts here
        xi_c[i], x_c[i] = x_new, x_m
    elif d > 0.0:
        xi_h[i], x_h[i] = x_new, x_a
    xi[i] = x_new
    return d


def fraction_path(T_C: ArrayLike, sigma_MPa: ArrayLike, wire: WireParams | None = None) -> FloatArray:
    """Martensite fraction along a temperature and stress history [degC, MPa] of one wire that
    starts cooled from hot (full martensite on the major cooling branch): the kinetics alone,
    without the chain (for checks and plots)."""
    wc = pack([PhaseFractionParams(wire=wire or WireParams())])[0][0]
    T = np.asarray(T_C, float).ravel()
    sig = np.broadcast_to(np.asarray(sigma_MPa, float), T.shape)
    xi, xi_h, x_h, xi_c, x_c = np.zeros(1), np.ones(1), np.full(1, -1e3), np.zeros(1), np.full(1, 1e3)
    out = np.empty(T.size)
    for k in range(T.size):
        commit(0, T[k], sig[k], xi, xi_h, x_h, xi_c, x_c, wc)
        out[k] = xi[0]
    return out


def isobaric_loops(
    stresses_MPa: Sequence[float],
    wire: WireParams | None = None,
    *,
    T_range_C: tuple[float, float] = (20.0, 110.0),
    step_C: float = 0.1,
    cycles: int = 2,
    noise: tuple[float, float, float] = (0.1, 2e-5, 1.0),
    seed: int = 7,
) -> dict[float, FloatArray]:
    """What a test rig measures on this wire: isobaric loops (temperature cycled between T_range_C in steps of
    step_C [degC], ``cycles`` times, at each constant stress), as SMA-REACT's and maestrolab's data were measured.

    Returns {stress [MPa]: (K, 3) columns temperature [degC], strain [-], stress [MPa]} with the rig's noise
    (thermocouple degC, extensometer strain, load cell MPa; seeded); ``write_isobaric_loops`` writes them as
    files ``sma-wrist identify hysteresis`` reads. The wire starts cold (fully martensite)."""
    check_range('rig temperature step', step_C, 1e-3, 5.0, 'degC')
    lo, hi = T_range_C
    if not lo < hi:
        raise ParameterError(f'T_range_C = {T_range_C!r} must rise')
    up = np.arange(lo, hi, step_C)
    T = np.tile(np.concatenate([up, up[::-1]]), int(cycles))
    wc = pack([PhaseFractionParams(wire=wire or WireParams())])[0][0]
    rng = np.random.default_rng(seed)
    out = {}
    for s in stresses_MPa:
        xi = fraction_path(T, float(s), wire)
        eps = np.array([strain(Tk, float(s), xk, wc) for Tk, xk in zip(T, xi)])
        out[float(s)] = np.column_stack(
            [
                T + rng.normal(0.0, noise[0], T.size),
                eps + rng.normal(0.0, noise[1], T.size),
                float(s) + rng.normal(0.0, noise[2], T.size),
            ]
        )
    return out


def write_isobaric_loops(folder: str | Path, loops: dict[float, FloatArray]) -> list[Path]:
    """One ``<stress>MPa.txt`` per loop (header ``Temperature Strain Stress``, as test/data/flexinol's)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    files = []
    for s, a in loops.items():
        f = folder / f'{s:g}MPa.txt'
        np.savetxt(f, a, fmt=['%.4f', '%.7f', '%.3f'], header='Temperature Strain Stress', comments='')
        files.append(f)
    return files


@_jit
def _tem_rates(Tm, Tx, u, tc):  # pragma: no cover - compiled
    """(dT_m/dt, dT_x/dt) [degC/s] of one layer under drive voltage u [V] (module docstring)."""
    S, R, K = tc[0], tc[1], tc[2]
    current = (u - S * (Tm - Tx)) / R
    joule = 0.5 * current * current * R
    cond = K * (Tm - Tx)
    q_m = S * current * (Tm + KELVIN) + joule - cond - tc[4] * (Tm - tc[7])
    q_x = -S * current * (Tx + KELVIN) + joule + cond - tc[6] * (Tx - tc[8])
    return q_m / tc[3], q_x / tc[5]


@_jit
def step_many(
    n_steps, u, Tn, Ttc, xi, xi_h, x_h, xi_c, x_c, sig, q, qd, payload, flags, wire, tem, joint, tc_gain
):  # pragma: no cover - compiled
    """Advance N wrists by n_steps under held commands u (N, 2) [V], in place.

    Tn (N, 2 layers, 2 nodes: muscle, exchanger) [degC]; Ttc (N, 2) thermocouple states; per
    wire, stacked [muscle 1 of all wrists, then muscle 2] (2N,): xi, heating anchor (xi_h, x_h),
    cooling anchor (xi_c, x_c), stress sig [MPa]; q, qd, payload (N,); flags (N, 3) out: slack,
    at_stop, command clipped (ORed). wire, tem, joint: :func:`pack` tables, one row per wrist;
    tc_gain (N,): 1 - exp(-dt / tc_lag) of each wrist's thermocouples (1: no lag).
    """
    n = q.size
    for _ in range(n_steps):
        for j in range(n):
            wc, tc, jc = wire[j], tem[j], joint[j]
            dt = tc[13]
            for layer in range(2):
                v = u[j, layer]
                if v > tc[9] or v < -tc[9]:
                    v = min(max(v, -tc[9]), tc[9])
                    flags[j, 2] = True
                dm, dx = _tem_rates(Tn[j, layer, 0], Tn[j, layer, 1], v, tc)
                Tn[j, layer, 0] += dt * dm
                Tn[j, layer, 1] += dt * dx
            e0, r_eff, n_w = tc[10], tc[11], tc[12]
            L_mm, area = wc[15], wc[16]
            x_mm = 1e3 * r_eff * (q[j] - jc[6])
            torque = 0.0
            inv = 0.0
            for side in range(2):
                i = j + side * n
                eps = (e0 - x_mm if side == 0 else e0 + x_mm) / L_mm
                d, de = _wire_step(i, Tn[j, side, 0], eps, xi, xi_h, x_h, xi_c, x_c, sig, wc)
                Tn[j, side, 0] += wc[14] * d / tc[3]  # latent heat: A -> M (d > 0) releases heat
                if sig[i] <= 0.0:
                    flags[j, 0] = True
                f = n_w * area * sig[i]  # N (area in mm^2, sigma in MPa)
                torque += r_eff * f if side == 0 else -r_eff * f
                inv += 1.0 / de  # d sigma / d eps [MPa]
            # -d torque/dq = r_eff n A (d sigma/d eps) (d eps/dq), d eps/dq = 1e3 r_eff / L_mm per wire
            stiffness = r_eff * n_w * area * inv * 1e3 * r_eff / L_mm
            q[j], qd[j] = joint_step_one(q[j], qd[j], torque, stiffness, payload[j], dt, jc)
            if q[j] <= jc[7] or q[j] >= jc[8]:
                flags[j, 1] = True
        for j in range(n):  # thermocouples: first-order lag of the muscle node, exact over dt
            for side in range(2):
                Ttc[j, side] += tc_gain[j] * (Tn[j, side, 0] - Ttc[j, side])


@_jit
def torque_at(j, n, qj, Tn, xi, xi_h, x_h, xi_c, x_c, wire, tem, joint):  # pragma: no cover - compiled
    """Net muscle torque [N m] of wrist j at angle qj against its frozen memory (nothing committed)."""
    wc, tc = wire[j], tem[j]
    x_mm = 1e3 * tc[11] * (qj - joint[j, 6])
    torque = 0.0
    for side in range(2):
        i = j + side * n
        eps = (tc[10] - x_mm if side == 0 else tc[10] + x_mm) / wc[15]
        s, _, _ = solve_stress(Tn[j, side, 0], eps, xi[i], xi_h[i], x_h[i], xi_c[i], x_c[i], wc)
        f = tc[12] * wc[16] * s
        torque += tc[11] * f if side == 0 else -tc[11] * f
    return torque


@_jit
def thermal_rest(Tn, tem, seconds, dt):  # pragma: no cover - compiled
    """Both layers of every wrist relaxed at 0 V for ``seconds`` (explicit Euler, dt [s]), in place."""
    for j in range(Tn.shape[0]):
        for _ in range(int(seconds / dt)):
            for layer in range(2):
                dm, dx = _tem_rates(Tn[j, layer, 0], Tn[j, layer, 1], 0.0, tem[j])
                Tn[j, layer, 0] += dt * dm
                Tn[j, layer, 1] += dt * dx


@dataclass
class PhaseFractionState:
    """State of N wrists (arrays the kernel advances in place)."""

    t: float
    thermal: FloatArray  # (N, 2 layers, 2 nodes: muscle, exchanger) [degC]
    thermocouple: FloatArray  # (N, 2) lagged muscle temperatures, before noise [degC]
    xi: FloatArray  # (2N,) martensite fraction, stacked [muscle 1 of all wrists, then muscle 2]
    xi_h: FloatArray  # (2N,) heating anchor: fraction ...
    x_h: FloatArray  # ... and effective temperature x_A where the wire last transformed on cooling
    xi_c: FloatArray  # (2N,) cooling anchor: fraction ...
    x_c: FloatArray  # ... and x_M where it last transformed on heating
    stress_MPa: FloatArray  # (2N,)
    q: FloatArray  # (N,) rad
    qd: FloatArray  # (N,) rad/s
    payload_kg: FloatArray  # (N,)
    flags: dict[str, NDArray[np.bool_]] = field(default_factory=dict)


class PhaseFractionPlant:
    """N wrists with phase-fraction wires and Peltier layers, stepped together (module docstring).

    ``params``: one :class:`PhaseFractionParams` for all wrists, or one per wrist.
    """

    def __init__(
        self,
        params: PhaseFractionParams | Sequence[PhaseFractionParams] | None = None,
        payload_kg: ArrayLike = 0.3,
        n: int | None = None,
    ) -> None:
        payload = np.atleast_1d(np.asarray(payload_kg, dtype=float))
        if n is not None:
            payload = np.broadcast_to(payload, (n,)).copy()
        check_range('payload', payload, 0.0, 2.0, 'kg')
        self.n = payload.size
        if params is None or isinstance(params, PhaseFractionParams):
            plist = [params or PhaseFractionParams()] * self.n
        else:
            plist = list(params)
            if len(plist) != self.n:
                raise ParameterError(f'{len(plist)} parameter sets for {self.n} wrists')
        self.params = plist
        self.wire, self.tem, self.joint = pack(plist)
        dts = {p.dt for p in plist}
        if len(dts) != 1:
            raise ParameterError(f'all wrists must share one step dt, got {sorted(dts)}')
        self.dt = dts.pop()
        self.tc_gain = np.array(
            [1.0 if p.sensor.tc_lag_s == 0 else -math.expm1(-self.dt / p.sensor.tc_lag_s) for p in plist]
        )
        self.tc_noise = np.array([p.sensor.tc_noise_C for p in plist])
        self.pot_noise = np.array([p.sensor.pot_noise_rad for p in plist])
        self.rng = np.random.default_rng([p.sensor.seed for p in plist])
        self.state = self.rest_state(payload)

    def rest_state(self, payload_kg: FloatArray) -> PhaseFractionState:
        """Wrists at thermal rest (0 V), wires cooled from hot (major cooling branch), joint at static
        equilibrium (bisection on the torque balance)."""
        n = payload_kg.size
        Tn = np.empty((n, 2, 2))
        Tn[:, :, 0] = self.tem[:, 7:8]
        Tn[:, :, 1] = self.tem[:, 8:9]
        thermal_rest(Tn, self.tem, 1500.0, 0.05)
        big = 1e3
        s = PhaseFractionState(
            0.0,
            Tn,
            Tn[:, :, 0].copy(),
            np.zeros(2 * n),
            np.ones(2 * n),
            np.full(2 * n, -big),
            np.zeros(2 * n),
            np.full(2 * n, big),
            np.zeros(2 * n),
            np.zeros(n),
            np.zeros(n),
            payload_kg.astype(float).copy(),
        )
        jp = self.joint
        lo, hi = jp[:, 7].copy(), jp[:, 8].copy()
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            for j in range(n):
                tau = torque_at(
                    j, n, mid[j], s.thermal, s.xi, s.xi_h, s.x_h, s.xi_c, s.x_c, self.wire, self.tem, self.joint
                ) - payload_kg[j] * G * jp[j, 1] * math.cos(mid[j])
                if tau > 0:
                    lo[j] = mid[j]
                else:
                    hi[j] = mid[j]
        s.q = 0.5 * (lo + hi)
        # commit the wires at that angle (one step of zero length in time: dt steps of 0 V)
        self.state = s
        flags = np.zeros((n, 3), bool)
        t0 = s.t
        step_many(
            1,
            np.zeros((n, 2)),
            s.thermal,
            s.thermocouple,
            s.xi,
            s.xi_h,
            s.x_h,
            s.xi_c,
            s.x_c,
            s.stress_MPa,
            s.q,
            s.qd,
            s.payload_kg,
            flags,
            self.wire,
            self.tem,
            self.joint,
            self.tc_gain,
        )
        s.t, s.qd[:] = t0, 0.0
        s.flags = self._flags(flags)
        return s

    @staticmethod
    def _flags(f: NDArray[np.bool_]) -> dict[str, NDArray[np.bool_]]:
        return {'slack': f[:, 0].copy(), 'at_stop': f[:, 1].copy(), 'command_saturated': f[:, 2].copy()}

    def advance(self, command_V: ArrayLike, n_steps: int = 1) -> PhaseFractionState:
        """``n_steps`` plant steps under one held command (N, 2) [V] (positive heats a muscle);
        commands beyond the driver rating are clipped (flag ``command_saturated``)."""
        u = np.ascontiguousarray(np.broadcast_to(np.asarray(command_V, dtype=float), (self.n, 2)))
        check_finite('TEM command', u, 'V')
        s = self.state
        flags = np.zeros((self.n, 3), bool)
        step_many(
            int(n_steps),
            u,
            s.thermal,
            s.thermocouple,
            s.xi,
            s.xi_h,
            s.x_h,
            s.xi_c,
            s.x_c,
            s.stress_MPa,
            s.q,
            s.qd,
            s.payload_kg,
            flags,
            self.wire,
            self.tem,
            self.joint,
            self.tc_gain,
        )
        s.t += n_steps * self.dt
        s.flags = self._flags(flags)
        if not np.isfinite(s.q).all():
            raise ModelInputError('phase-fraction plant angle', float('nan'), '(finite numbers)', 'rad')
        return s

    # ------------------------------------------------------------------ outputs
    @property
    def muscle_temperature_C(self) -> FloatArray:
        """(N, 2) true muscle (node) temperatures."""
        return self.state.thermal[:, :, 0].copy()

    @property
    def wire_stress_Pa(self) -> FloatArray:
        """(N, 2) per-wire stresses."""
        return 1e6 * self.state.stress_MPa.reshape(2, -1).T

    @property
    def martensite_fraction(self) -> FloatArray:
        """(N, 2) martensite fraction of each muscle's wires."""
        return self.state.xi.reshape(2, -1).T.copy()

    @property
    def muscle_torque_Nm(self) -> FloatArray:
        """(N,) net muscle torque at the output shaft."""
        f = self.tem[:, 12] * self.wire[:, 16] * self.state.stress_MPa.reshape(2, -1)
        return self.tem[:, 11] * (f[0] - f[1])

    def measure(self) -> tuple[FloatArray, FloatArray]:
        """(thermocouple readings (N, 2) [degC], potentiometer angles (N,) [rad]): the lagged
        temperatures and the angle, each with a fresh draw of its sensor's white noise."""
        T = self.state.thermocouple + self.tc_noise[:, None] * self.rng.standard_normal((self.n, 2))
        q = self.state.q + self.pot_noise * self.rng.standard_normal(self.n)
        return T, q


# ----------------------------------------------------------------------------- the registry's adapter
class ScenarioPhaseFraction(PhaseFractionPlant):
    """The phase-fraction wrists of N scenarios with the interface plant_sim and the sweep use
    (:mod:`sma_wrist.plants`): ``advance``, ``state`` (t, q, qd, thermal, payload_kg, flags incl.
    ``over_temperature`` and ``command_saturated``), ``muscle_temperature_C``, ``wire_stress_Pa``,
    ``muscle_torque_Nm``, ``params`` (the base PlantParams: limits, window, dt).

    Sensors: the wire's own thermocouple is part of this plant: ``muscle_temperature_C`` is what
    its junction reads, the muscle node through its first-order lag (``SensorParams.tc_lag_s``,
    0.2 s unless ``tc_lag_s`` is given), integrated at the plant step. The scenario's sensor
    fields then act on what is published, as for every registered plant
    (:class:`~sma_wrist.plants.spread.SensorBank`): ``temp_lag_s`` a further lag in series,
    ``temp_noise_C`` / ``angle_noise_rad`` the only noise (this plant's own noise is off here, so
    a scenario's ``noise_seed`` is the one stream). The true node temperature is
    :attr:`node_temperature_C`.

    The scenario's plant axes map onto this wire's own parameters (not the SD-GPI's):
    ``transition_shift_C`` adds to M_f, M_s, A_s, A_f; ``stroke_scale`` scales eps_L;
    ``tem_gain_scale`` the Peltier coefficient (Seebeck S: heat pumped per ampere);
    ``heat_loss_scale`` the muscle node's loss to ambient; ``ambient_offset_C`` the ambient and
    coolant temperatures; ``payload_kg`` the joint's load.
    """

    def __init__(self, scenarios: Sequence[Any], base: Any = None, tc_lag_s: float | None = None) -> None:
        from dataclasses import replace

        from sma_wrist.core.plant.wrist import PlantParams

        base = base or PlantParams()
        one = PhaseFractionParams(dt=base.dt)
        lag = one.sensor.tc_lag_s if tc_lag_s is None else float(tc_lag_s)
        plist = []
        for sc in scenarios:
            w, t = one.wire, one.tem
            d = sc.transition_shift_C
            wire = replace(
                w,
                M_f_C=w.M_f_C + d,
                M_s_C=w.M_s_C + d,
                A_s_C=w.A_s_C + d,
                A_f_C=w.A_f_C + d,
                eps_L=w.eps_L * sc.stroke_scale,
            )
            tem = replace(
                t,
                seebeck_V_per_K=t.seebeck_V_per_K * sc.tem_gain_scale,
                muscle_loss_W_per_K=t.muscle_loss_W_per_K * sc.heat_loss_scale,
                ambient_C=t.ambient_C + sc.ambient_offset_C,
                coolant_C=t.coolant_C + sc.ambient_offset_C,
            )
            plist.append(
                replace(one, wire=wire, tem=tem, sensor=SensorParams(tc_lag_s=lag, tc_noise_C=0.0, pot_noise_rad=0.0))
            )
        if not plist:
            raise ParameterError('no scenarios: the phase-fraction plant needs at least one wrist')
        self.base = base
        super().__init__(plist, payload_kg=[sc.payload_kg for sc in scenarios])
        self.state.flags = self._with_limits(self.state.flags)

    @property
    def params(self) -> Any:  # type: ignore[override]
        """The base PlantParams (limits, TEM window, dt) plant_sim reads and may replace."""
        return self.base

    @params.setter
    def params(self, value: Any) -> None:
        if isinstance(value, list):  # PhaseFractionPlant.__init__ stores its parameter sets here
            self.pf_params = value
        else:
            self.base = value

    def _with_limits(self, flags: dict[str, NDArray[np.bool_]]) -> dict[str, NDArray[np.bool_]]:
        hot = (self.state.thermal[:, :, 0] > self.base.max_muscle_temperature_C).any(axis=1)
        return {**flags, 'over_temperature': hot, 'overload': np.zeros(self.n, bool)}

    def advance(self, command_V: ArrayLike, n_steps: int = 1) -> PhaseFractionState:
        s = super().advance(command_V, n_steps)
        s.flags = self._with_limits(s.flags)
        return s

    @property
    def muscle_temperature_C(self) -> FloatArray:
        """(N, 2) what the thermocouple junctions read (lagged muscle nodes, no noise) [degC]."""
        return self.state.thermocouple.copy()

    @property
    def node_temperature_C(self) -> FloatArray:
        """(N, 2) the true muscle node temperatures [degC]."""
        return self.state.thermal[:, :, 0].copy()


def factory(scenarios: Sequence[Any], base: Any = None, **options: Any) -> ScenarioPhaseFraction:
    """The registry's factory (:data:`sma_wrist.plants.PLANTS` ``phase_fraction``); option ``tc_lag_s``."""
    bad = set(options) - {'tc_lag_s'}
    if bad:
        raise ParameterError(f'phase_fraction plant: unknown option(s) {", ".join(sorted(bad))}; known: tc_lag_s')
    return ScenarioPhaseFraction(scenarios, base, **options)


__all__ = [
    'WireParams',
    'PeltierParams',
    'SensorParams',
    'PhaseFractionParams',
    'PhaseFractionPlant',
    'ScenarioPhaseFraction',
    'factory',
    'PhaseFractionState',
    'fraction_path',
    'major_heating',
    'major_cooling',
    'fraction',
    'strain',
    'solve_stress',
    'isobaric_loops',
    'write_isobaric_loops',
]
