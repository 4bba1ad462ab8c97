"""A second wire family for the model: martensite phase-fraction kinetics (the form ``phase_fraction``).

Where the SD-GPI (:mod:`sma_wrist.core.hysteresis.sdgpi`) describes a wire's elongation by play operators, this
family describes the wire by its martensite fraction xi (0: austenite, 1: martensite) and a constitutive law. Per
wire, stress sigma [MPa] (sigma = m g / A of the per-wire load m [kgf]), temperature T [degC]:

* Clausius-Clapeyron (Brinson 1993, Eq. 11): the transformation temperatures move with the stress, here about a
  reference stress sigma_ref (the working load, so that the temperatures and the slopes do not trade):
  x_A = T - (sigma - sigma_ref) / C_A for the reverse (martensite -> austenite) transformation,
  x_M = T - (sigma - sigma_ref) / C_M for the forward one;  (1)
* major branches, cosine kinetics (Liang & Rogers 1990, Eqs. 12-13): martensite fraction on heating
  f_A(x) = (1 + cos(pi (x - A_s) / (A_f - A_s))) / 2 on [A_s, A_f] (1 below, 0 above), on cooling
  f_M(x) = (1 + cos(pi (x - M_f) / (M_s - M_f))) / 2 on [M_f, M_s] (1 below, 0 above);  (2)
* minor loops, scaled at the reversal point (Ikuta, Tsukamoto & Hirose 1991; Bekker & Brinson 1997): a heating
  branch starts where the last cooling transformation stopped, (x_h, xi_h), and is the major heating branch scaled
  through it, a cooling branch likewise from (x_c, xi_c):
  H(x_A) = xi_h f_A(x_A) / f_A(x_h) for x_A > x_h (else 1),
  C(x_M) = 1 - (1 - xi_c) (1 - f_M(x_M)) / (1 - f_M(x_c)) for x_M < x_c (else 0),
  xi = clip(max(min(xi_prev, H), C), 0, 1): xi only falls on heating, only rises on cooling, and stays between
  the major branches; an anchor moves where xi moves by more than :data:`XI_EPS`;  (3)
* constitutive law (Brinson 1993, Eq. 7, with the stress-induced, oriented share of the martensite; Reuss average
  of the phases' compliances, as in Lagoudas' models):
  eps = sigma (xi / E_M + (1 - xi) / E_A) + eps_L d(sigma) xi + alpha (T - T_ref),
  d(sigma) = clip((sigma - sigma_s) / (sigma_f - sigma_s), 0, 1) the oriented share, a linear ramp between
  Brinson's critical detwinning stresses: martensite under little stress gives little strain.  (4)
* the published form (``law = 'brinson'``: Brinson 1993's own details of Eq. 4): the phases' moduli averaged
  linearly in the fraction (Voigt, Brinson's E(xi) = E_A + xi (E_M - E_A)) and the oriented share following his
  cosine kinetics of the stress-induced martensite between the critical stresses:
  eps = sigma / (E_A + xi (E_M - E_A)) + eps_L d_c(sigma) xi + alpha (T - T_ref),
  d_c(sigma) = (1 - cos(pi u)) / 2, u = clip((sigma - sigma_s) / (sigma_f - sigma_s), 0, 1).  (4b)
  Both forms have the same values; which one describes a wrist is measured (commissioning fits both and hands over
  the one that predicts a held-out recording better).

The wire's elongation is y = L eps - y_0 [mm] (L the bundle's wire length, 83 mm; y_0 the datum ``offset_mm``): the
datum puts the wire on the scale of the chain's pre-load elongation e0 (Eq. 4.17) that the SD-GPI's mirror constant
k_f sets (Eq. 4.2), so that the plant and the compensator, which inverts the SD-GPI, share one e0. eps(sigma) is
strictly increasing at fixed T and memory ((1): a larger stress lowers x_A and x_M, which raises H and C), so the
load for an elongation is one root, found against frozen memory by a safeguarded Newton iteration with the analytic
slope, then the memory is committed there (as :class:`~sma_wrist.core.hysteresis.muscle.MuscleModel` does for the
SD-GPI). The compiled kernel is :mod:`sma_wrist.core.hysteresis.phase_fraction_kernel` (same operations).

Memory per wire, ``mem`` (5,): xi, xi_h, x_h, xi_c, x_c. A wire cooled from hot is on the major cooling branch
(x_c = +inf) and its next heating on the major heating branch (x_h = -inf, xi_h = 1).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields

import numpy as np
from numpy.typing import NDArray

from sma_wrist.core.errors import ParameterError

FloatArray = NDArray[np.float64]
G = 9.81
#: the anchors of a wire on a major branch [degC]: beyond any temperature the model sees
FAR_C = 1.0e3
#: memory columns
XI, XI_H, X_H, XI_C, X_C = range(5)
#: a change of the fraction smaller than this is no reversal: the anchors stay. The load solve's tolerance moves
#: xi by ~1e-15 either way, and a branch rescaled through every such point made the replay depend on the last bit
#: of the angle (7 mrad apart after 12 s between two replays whose angles differed by 3e-16 rad)
XI_EPS = 1e-9
#: a branch starts this far [degC] past its anchor: an anchor beyond the end of its major branch (a wire that
#: transformed on heating with x_M already below M_f) makes the scaled branch a step, and which side of it the
#: rounding of the load put the wire decided whether the fraction jumped (2e-3 of xi between the numpy and the
#: compiled plant, whose torques round differently)
X_EPS = 1e-9
MEMORY_SIZE = 5
#: the constitutive details (:attr:`PhaseFractionWire.law`), their index the kernel's ``law`` column
LAWS = ('linear', 'brinson')


@dataclass(frozen=True)
class PhaseFractionWire:
    """Parameters of the phase-fraction wire (module docstring, Eqs. 1-4); temperatures at ``sigma_ref_MPa``.

    The defaults are the literature's for a 90 degC actuator wire (Flexinol-class NiTi; Brinson 1993's slopes and
    critical stresses) moved to the built-in SD-GPI's transitions at its working load: a starting point, not a
    wire; commissioning fits a wrist's own (``sma_wrist.commission.identification.fit_phase_fraction_wire``).
    """

    M_f_C: float = 40.0
    M_s_C: float = 52.0
    A_s_C: float = 56.0
    A_f_C: float = 70.0
    C_M_MPa_per_C: float = 8.0  # Brinson 1993, Table 1
    C_A_MPa_per_C: float = 13.8  # Brinson 1993, Table 1
    eps_L: float = 0.04  # recoverable (transformation) strain; actuator wires are used to 3-5 %
    E_A_GPa: float = 67.0  # Brinson 1993: D_a
    E_M_GPa: float = 26.3  # Brinson 1993: D_m
    sigma_s_MPa: float = 100.0  # detwinning starts, Brinson 1993's sigma_s^cr
    sigma_f_MPa: float = 170.0  # detwinning complete, sigma_f^cr
    alpha_per_C: float = 10e-6  # thermal expansion (NiTi 6.6-11e-6)
    T_ref_C: float = 20.0
    sigma_ref_MPa: float = 150.0  # ~0.75 kgf per 0.25 mm wire: the chain's working load
    offset_mm: float = 1.2  # elongation datum y_0 [mm]: the built-in e0 (1.98 mm) at the cold wire's mid-stroke
    T_valid: tuple[float, float] = (-10.0, 130.0)
    #: the constitutive details: 'linear' (Eq. 4: linear detwinning ramp, Reuss compliance) or 'brinson' (Eq. 4b)
    law: str = 'linear'
    name: str = field(default='phase-fraction wire', compare=False)

    def __post_init__(self) -> None:
        if self.law not in LAWS:
            raise ParameterError(f'{self.name}: law must be one of {", ".join(LAWS)}, got {self.law!r}')
        vals = [getattr(self, f.name) for f in fields(self) if f.name not in ('T_valid', 'name', 'law')]
        if not all(isinstance(v, (int, float)) and math.isfinite(v) for v in vals):
            raise ParameterError(f'{self.name}: every phase-fraction wire parameter must be a finite number')
        if not (self.M_f_C < self.M_s_C and self.A_s_C < self.A_f_C):
            raise ParameterError(
                f'{self.name}: transformation temperatures need M_f < M_s and A_s < A_f, got M_f {self.M_f_C}, '
                f'M_s {self.M_s_C}, A_s {self.A_s_C}, A_f {self.A_f_C} degC'
            )
        for k in ('C_M_MPa_per_C', 'C_A_MPa_per_C', 'E_A_GPa', 'E_M_GPa', 'eps_L'):
            if not getattr(self, k) > 0:
                raise ParameterError(f'{self.name}: {k} = {getattr(self, k)!r} must be > 0')
        if not self.eps_L < 0.1:
            raise ParameterError(f'{self.name}: eps_L = {self.eps_L} is beyond any NiTi wire (< 0.1)')
        if not 0.0 <= self.sigma_s_MPa < self.sigma_f_MPa:
            raise ParameterError(
                f'{self.name}: need 0 <= sigma_s < sigma_f, got {self.sigma_s_MPa}, {self.sigma_f_MPa} MPa'
            )
        lo, hi = (float(v) for v in self.T_valid)
        if not lo < hi:
            raise ParameterError(f'{self.name}: T_valid must be (lo, hi) with lo < hi, got {self.T_valid}')
        object.__setattr__(self, 'T_valid', (lo, hi))

    def values(self) -> dict[str, float]:
        """The numbers (no name, no validity window), for files and reports."""
        return {k: float(v) for k, v in asdict(self).items() if k not in ('T_valid', 'name', 'law')}

    def packed(self, wire_length_mm: float, wire_area_m2: float) -> FloatArray:
        """The kernel's constant row (:data:`PACKED`)."""
        per_kgf = G / (wire_area_m2 * 1e6)  # MPa per kgf of one wire
        return np.array(
            [
                self.M_f_C,
                self.M_s_C,
                self.A_s_C,
                self.A_f_C,
                self.C_M_MPa_per_C,
                self.C_A_MPa_per_C,
                self.eps_L,
                1.0 / (self.E_A_GPa * 1e3),
                1.0 / (self.E_M_GPa * 1e3),
                self.sigma_s_MPa,
                self.sigma_f_MPa,
                self.alpha_per_C,
                self.T_ref_C,
                self.sigma_ref_MPa,
                wire_length_mm,
                per_kgf,
                self.offset_mm,
                float(LAWS.index(self.law)),
            ],
            dtype=float,
        )


#: the columns of :meth:`PhaseFractionWire.packed` (compliances 1/E in 1/MPa, per_kgf in MPa per kgf)
PACKED = (
    'M_f',
    'M_s',
    'A_s',
    'A_f',
    'C_M',
    'C_A',
    'eps_L',
    'S_A',
    'S_M',
    'sig_s',
    'sig_f',
    'alpha',
    'T_ref',
    'sig_ref',
    'L_mm',
    'per_kgf',
    'offset_mm',
    'law',
)


# ----------------------------------------------------------------------------- numpy reference
def _major(x: FloatArray, lo: float, hi: float) -> tuple[FloatArray, FloatArray]:
    """(f, df/dx) of a cosine branch of Eq. 2: 1 below ``lo``, 0 above ``hi``."""
    w = hi - lo
    inside = (x > lo) & (x < hi)
    ph = np.pi * np.clip((x - lo) / w, 0.0, 1.0)
    f = np.where(x <= lo, 1.0, np.where(x >= hi, 0.0, 0.5 * (1.0 + np.cos(ph))))
    df = np.where(inside, -0.5 * np.pi / w * np.sin(ph), 0.0)
    return f, df


def fraction(wc: FloatArray, T: FloatArray, sig: FloatArray, mem: FloatArray) -> tuple[FloatArray, FloatArray]:
    """(xi, d xi / d sigma [1/MPa]) of Eq. 3 at temperatures T [degC] and stresses sig [MPa] against frozen memory
    ``mem`` (N, 5); 1-D arrays over wires."""
    M_f, M_s, A_s, A_f, C_M, C_A = wc[0], wc[1], wc[2], wc[3], wc[4], wc[5]
    x_a = T - (sig - wc[13]) / C_A
    x_m = T - (sig - wc[13]) / C_M
    xi_p, xi_h, x_h, xi_c, x_c = (mem[:, i] for i in range(5))
    fa, dfa = _major(x_a, A_s, A_f)
    fh, _ = _major(x_h, A_s, A_f)
    on_h = x_a > x_h + X_EPS
    den_h = np.maximum(fh, 1e-12)
    H = np.where(on_h, np.minimum(xi_h * fa / den_h, 1.0), 1.0)
    dH = np.where(on_h & (xi_h * fa / den_h < 1.0), -xi_h * dfa / den_h / C_A, 0.0)
    fm, dfm = _major(x_m, M_f, M_s)
    fc, _ = _major(x_c, M_f, M_s)
    on_c = x_m < x_c - X_EPS
    den_c = np.maximum(1.0 - fc, 1e-12)
    Cb = np.where(on_c, 1.0 - (1.0 - xi_c) * (1.0 - fm) / den_c, 0.0)
    dC = np.where(on_c, -(1.0 - xi_c) * dfm / den_c / C_M, 0.0)
    upper = np.minimum(xi_p, H)
    d_up = np.where(H < xi_p, dH, 0.0)
    lower = np.maximum(Cb, 0.0)
    d_lo = np.where(Cb > 0.0, dC, 0.0)
    xi = np.maximum(upper, lower)
    dxi = np.where(lower > upper, d_lo, d_up)
    out = (xi > 0.0) & (xi < 1.0)
    return np.clip(xi, 0.0, 1.0), np.where(out, dxi, 0.0)


def elongation(
    wc: FloatArray, T: FloatArray, m: FloatArray, mem: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(y [mm], dy/dm [mm/kgf], xi) of Eq. 4 at per-wire loads m [kgf] against frozen memory; over wires."""
    per_kgf = wc[15]
    sig = m * per_kgf
    xi, dxi = fraction(wc, T, sig, mem)
    S_A, S_M, eps_L, s_s, s_f = wc[7], wc[8], wc[6], wc[9], wc[10]
    u = np.clip((sig - s_s) / (s_f - s_s), 0.0, 1.0)
    inside = (sig > s_s) & (sig < s_f)
    if wc[17] == 0.0:  # Eq. 4: linear ramp, Reuss compliance (linear in xi)
        d = u
        dd = np.where(inside, 1.0 / (s_f - s_s), 0.0)
        S = S_A + xi * (S_M - S_A)
        el, d_el_sig, d_el_xi = sig * S, S, sig * (S_M - S_A)
    else:  # Eq. 4b: cosine ramp, Voigt modulus (linear in xi)
        d = 0.5 * (1.0 - np.cos(np.pi * u))
        dd = np.where(inside, 0.5 * np.pi * np.sin(np.pi * u) / (s_f - s_s), 0.0)
        E_A, E_M = 1.0 / S_A, 1.0 / S_M
        E = E_A + xi * (E_M - E_A)
        el, d_el_sig, d_el_xi = sig / E, 1.0 / E, -sig * (E_M - E_A) / E**2
    eps = el + eps_L * d * xi + wc[11] * (T - wc[12])
    deps = d_el_sig + eps_L * dd * xi + (d_el_xi + eps_L * d) * dxi
    L = wc[14]
    return L * eps - wc[16], L * deps * per_kgf, xi


def commit(wc: FloatArray, T: FloatArray, m: FloatArray, mem: FloatArray) -> FloatArray:
    """The memory after the wires reach (T, m) (Eq. 3): the new fraction, and where it moved the anchor of the branch
    the other direction starts from. Returns a new (N, 5) array."""
    sig = m * wc[15]
    xi, _ = fraction(wc, T, sig, mem)
    out = mem.copy()
    x_a = T - (sig - wc[13]) / wc[5]
    x_m = T - (sig - wc[13]) / wc[4]
    fell = xi < mem[:, XI] - XI_EPS  # transformed on heating: the next cooling branch starts here
    rose = xi > mem[:, XI] + XI_EPS
    out[:, XI_C] = np.where(fell, xi, mem[:, XI_C])
    out[:, X_C] = np.where(fell, x_m, mem[:, X_C])
    out[:, XI_H] = np.where(rose, xi, mem[:, XI_H])
    out[:, X_H] = np.where(rose, x_a, mem[:, X_H])
    out[:, XI] = xi
    return out


def cooled_memory(wc: FloatArray, T: FloatArray, m: FloatArray) -> FloatArray:
    """(N, 5) memory of wires cooled from hot to (T, m): on the major cooling branch, the next heating on the major
    heating branch."""
    T = np.atleast_1d(np.asarray(T, dtype=float))
    x_m = T - (np.broadcast_to(m, T.shape) * wc[15] - wc[13]) / wc[4]
    f, _ = _major(x_m, wc[0], wc[1])
    mem = np.empty((T.size, MEMORY_SIZE))
    mem[:, XI] = f
    mem[:, XI_H], mem[:, X_H] = 1.0, -FAR_C
    mem[:, XI_C], mem[:, X_C] = 0.0, FAR_C
    return mem


@dataclass
class FractionLoadSolution:
    """Result of :meth:`PhaseFractionMuscle.solve_load` (the fields of muscle.LoadSolution)."""

    load_kgf: FloatArray
    compliance_mm_per_kgf: FloatArray
    slack: NDArray[np.bool_]
    overload: NDArray[np.bool_]
    residual_mm: FloatArray
    memory: FloatArray  # (N, 5) committed at the solved load


class PhaseFractionMuscle:
    """The load-elongation relation of a bundle of phase-fraction wires (numpy reference of the kernel's solve)."""

    def __init__(self, wire: PhaseFractionWire, wire_length_mm: float, wire_area_m2: float, max_load_kgf: float):
        self.wire = wire
        self.wc = wire.packed(wire_length_mm, wire_area_m2)
        self.max_load_kgf = max_load_kgf

    def solve_load(
        self,
        T: FloatArray,
        y_geo_mm: FloatArray,
        mem: FloatArray,
        m_guess: FloatArray,
        tol_mm: float = 1e-7,
        max_iterations: int = 60,
    ) -> FractionLoadSolution:
        """Per-wire load at which y = y_geo against frozen memory (rtsafe: Newton from ``m_guess`` inside a bracket
        every evaluation narrows, the midpoint where a step leaves it), then the memory committed there."""
        m_max = self.max_load_kgf
        m = np.minimum(np.maximum(np.asarray(m_guess, dtype=float), 0.0), m_max)
        lo = np.zeros_like(m)
        hi = np.full_like(m, m_max)
        y, dy, _ = elongation(self.wc, T, m, mem)
        res = y - y_geo_mm
        on = np.abs(res) > tol_mm
        for _ in range(max_iterations):
            if not on.any():
                break
            pos = res > 0
            hi = np.where(on & pos, m, hi)
            lo = np.where(on & ~pos, m, lo)
            newton = m - res / dy
            done = (hi - lo) < 1e-12
            step = np.where((newton > lo) & (newton < hi), newton, 0.5 * (lo + hi))
            m = np.where(on, step, m)
            y2, dy2, _ = elongation(self.wc, T, m, mem)
            y, dy = np.where(on, y2, y), np.where(on, dy2, dy)
            res = y - y_geo_mm
            on = on & (np.abs(res) > tol_mm) & ~done
        slack = (m <= 1e-9) & (res > tol_mm)
        overload = (m >= m_max - 1e-9) & (res < -tol_mm)
        return FractionLoadSolution(m, dy, slack, overload, res, commit(self.wc, T, m, mem))


def simulate(
    wire: PhaseFractionWire, T: FloatArray, m: FloatArray, wire_length_mm: float = 83.0, area_m2: float | None = None
) -> tuple[FloatArray, FloatArray]:
    """(elongation [mm], xi) of one wire under a temperature and load history (K,) [degC, kgf], starting cooled from
    hot: the isobaric loops of a wire test."""
    area = area_m2 if area_m2 is not None else math.pi * 0.25 * 0.25e-3**2
    wc = wire.packed(wire_length_mm, area)
    T = np.asarray(T, dtype=float)
    m = np.broadcast_to(np.asarray(m, dtype=float), T.shape)
    mem = cooled_memory(wc, T[:1], m[:1])
    y = np.empty(T.shape)
    xi = np.empty(T.shape)
    for k in range(T.size):
        mem = commit(wc, T[k : k + 1], m[k : k + 1], mem)
        y[k], _, xi[k] = (v[0] for v in elongation(wc, T[k : k + 1], m[k : k + 1], mem))
    return y, xi


__all__ = [
    'PhaseFractionWire',
    'PhaseFractionMuscle',
    'FractionLoadSolution',
    'PACKED',
    'LAWS',
    'MEMORY_SIZE',
    'fraction',
    'elongation',
    'commit',
    'cooled_memory',
    'simulate',
]
