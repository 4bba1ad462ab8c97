"""Stress-dependent generalized Prandtl-Ishlinskii (SD-GPI) hysteresis of a Nitinol wire.

Model (seed, Chapter 4), for wire temperature T [degC] and wire load m [kgf]:

* generalized play operator, Eq. 3.19::

      w_j <- max(gamma_l(T, m) - r_j, min(gamma_r(T, m) + r_j, w_j))

* tanh envelopes, Eq. 3.21: gamma_r = a0 tanh(a1 T + a2) + a3 (the "a" set),
  gamma_l = b0 tanh(b1 T + b2) + b3 (the "b" set), gamma_l <= gamma_r; the
  lower bound gamma_l - r is followed while T rises, the upper gamma_r + r while it falls;
* memoryless part, Eq. 3.22: p0 * (c0 tanh(c1 T + c2) + c3) while heating, the d set while cooling;
* density p(r) = rho exp(-tau r), Eq. 3.23, thresholds r_j = c j, j = 1..n, Eq. 3.24;
* output, Eqs. 4.1/4.6: y_m = p0 gamma(T) + sum_j p(r_j) w_j, the *mirrored* elongation;
  the elongation is y = k_f - y_m (Eq. 4.2, k_f = 6 mm);
* stress dependence, Eqs. 4.4-4.5: every a_i, b_i is a quadratic of the load m,
  a_i = s_ai0 m^2 + s_ai1 m + s_ai2, on load sections joined at knots (the seed uses two
  sections joined at 0.8 kgf; the default set of :mod:`sma_wrist.core.hysteresis.default_params`
  uses more, same algebra).

A plain GPI at one load is the special case of one section with constant quadratics
(:meth:`SDGPIParams.from_gpi`).

Units: T in degC, m in kgf (= kg of hanging mass per wire), y and y_m in mm.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sma_wrist.core.errors import ModelInputError, ParameterError, check_finite, check_range

FloatArray = NDArray[np.float64]

#: Temperatures at which the envelopes are trusted [degC]; the seed's data span 20-78 degC.
T_VALID_DEFAULT = (-10.0, 110.0)


def tanh_envelope(coeffs: ArrayLike, T: ArrayLike) -> FloatArray:
    """k0 tanh(k1 T + k2) + k3 for a coefficient array whose last axis is (k0, k1, k2, k3).

    Eq. 3.21 (a and b sets) and Eq. 3.22 (c and d sets).
    """
    k = np.asarray(coeffs, dtype=float)
    return k[..., 0] * np.tanh(k[..., 1] * T + k[..., 2]) + k[..., 3]


@dataclass(frozen=True)
class EnvelopeSections:
    """Load-dependent envelope coefficients, Eqs. 4.4-4.5, on contiguous load sections.

    ``a[k, i, :] = (s_ai0, s_ai1, s_ai2)`` on section k = [edges[k], edges[k+1]] kgf,
    so a_i(m) = s_ai0 m^2 + s_ai1 m + s_ai2; likewise ``b``.
    """

    edges_kg: FloatArray
    a: FloatArray
    b: FloatArray

    def __post_init__(self) -> None:
        edges = np.asarray(self.edges_kg, dtype=float)
        a = np.asarray(self.a, dtype=float)
        b = np.asarray(self.b, dtype=float)
        k = edges.size - 1
        if k < 1 or np.any(np.diff(edges) <= 0):
            raise ParameterError(f'load section edges must be increasing with >= 2 entries, got {edges}')
        if a.shape != (k, 4, 3) or b.shape != (k, 4, 3):
            raise ParameterError(f'a and b must have shape ({k}, 4, 3) for {k} sections, got {a.shape}, {b.shape}')
        if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b)) and np.all(np.isfinite(edges))):
            raise ParameterError('envelope coefficients must be finite')
        object.__setattr__(self, 'edges_kg', edges)
        object.__setattr__(self, 'a', a)
        object.__setattr__(self, 'b', b)

    @functools.cached_property
    def load_range(self) -> tuple[float, float]:
        """(lowest, highest) load [kgf]; cached: the compensator reads it several times a tick."""
        return float(self.edges_kg[0]), float(self.edges_kg[-1])

    def section(self, m: FloatArray) -> NDArray[np.intp]:
        """Index of the section holding each load (the upper edge belongs to the last one)."""
        return np.clip(np.searchsorted(self.edges_kg, m, side='right') - 1, 0, self.edges_kg.size - 2)

    def coefficients(self, m: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """(a_i(m), b_i(m)), each of shape m.shape + (4,), Eqs. 4.4-4.5."""
        m = np.asarray(m, dtype=float)
        k = self.section(m)
        mm = m[..., None]
        sa, sb = self.a[k], self.b[k]
        a = (sa[..., 0] * mm + sa[..., 1]) * mm + sa[..., 2]
        b = (sb[..., 0] * mm + sb[..., 1]) * mm + sb[..., 2]
        return a, b

    @functools.cached_property
    def _stacked(self) -> FloatArray:
        """(K, 3, 8): per section, the m^2, m, 1 rows of (a0..a3, b0..b3) for one-gather evaluation."""
        return np.concatenate([self.a, self.b], axis=1).transpose(0, 2, 1).copy()

    def coefficients_and_slopes(self, m: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(coefficients, slopes) of shape (N, 2, 4) for a 1-D load array: [:, 0] the a set, [:, 1] the b set.

        The same numbers as :meth:`coefficients` and :meth:`coefficient_slopes` with one
        section lookup and one gather; the load solve calls it at every iteration.
        """
        k = np.minimum(np.searchsorted(self.edges_kg, m, side='right') - 1, self.edges_kg.size - 2)
        np.maximum(k, 0, out=k)
        s = self._stacked[k]
        mm = m[:, None]
        quad, lin = s[:, 0], s[:, 1]
        coeffs = (quad * mm + lin) * mm + s[:, 2]
        slopes = 2.0 * quad * mm + lin
        return coeffs.reshape(-1, 2, 4), slopes.reshape(-1, 2, 4)

    def coefficient_slopes(self, m: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """(d a_i/dm, d b_i/dm) [1/kgf], same shapes as :meth:`coefficients`."""
        m = np.asarray(m, dtype=float)
        k = self.section(m)
        mm = m[..., None]
        sa, sb = self.a[k], self.b[k]
        return 2.0 * sa[..., 0] * mm + sa[..., 1], 2.0 * sb[..., 0] * mm + sb[..., 1]


@dataclass(frozen=True)
class SDGPIParams:
    """Parameters of the SD-GPI model (Eqs. 3.19-3.24, 4.1-4.6). See the module docstring."""

    envelopes: EnvelopeSections
    c: FloatArray  # memoryless set while heating, Eq. 3.22
    d: FloatArray  # memoryless set while cooling
    rho: float  # density scale, Eq. 3.23
    tau: float  # density decay [1/mm], Eq. 3.23
    c_thr: float  # threshold spacing c [mm], Eq. 3.24
    n: int = 15  # number of play operators (Sec. 4.1.1)
    p0: float = 1.0  # weight of the memoryless part, Eq. 4.1 (not printed in the seed)
    k_f: float = 6.0  # mirror constant [mm], Eq. 4.2
    T_valid: tuple[float, float] = T_VALID_DEFAULT
    name: str = field(default='unnamed', compare=False)

    def __post_init__(self) -> None:
        c = np.asarray(self.c, dtype=float)
        d = np.asarray(self.d, dtype=float)
        if c.shape != (4,) or d.shape != (4,):
            raise ParameterError('memoryless sets c and d must have 4 entries each (Eq. 3.22)')
        if not (
            self.n >= 1 and self.c_thr >= 0 and np.isfinite([self.rho, self.tau, self.c_thr, self.p0, self.k_f]).all()
        ):
            raise ParameterError(f'need n >= 1, c >= 0 and finite rho, tau, p0, k_f; got n={self.n}, c={self.c_thr}')
        object.__setattr__(self, 'c', c)
        object.__setattr__(self, 'd', d)

    @classmethod
    def from_gpi(
        cls,
        a: ArrayLike,
        b: ArrayLike,
        c: ArrayLike,
        d: ArrayLike,
        rho: float,
        tau: float,
        c_thr: float,
        *,
        load_kg: float = 0.0,
        **kw: object,
    ) -> SDGPIParams:
        """A fixed-load GPI (Tables 4.1-4.3 form) as a one-section SD-GPI valid at any load."""
        a = np.asarray(a, dtype=float)
        b = np.asarray(b, dtype=float)
        const = lambda v: np.stack([np.zeros(4), np.zeros(4), v], axis=-1)[None]  # noqa: E731
        env = EnvelopeSections(
            np.array([-1e6, 1e6]) if load_kg == 0.0 else np.array([load_kg - 1e6, load_kg + 1e6]), const(a), const(b)
        )
        return cls(env, np.asarray(c, float), np.asarray(d, float), float(rho), float(tau), float(c_thr), **kw)  # type: ignore[arg-type]

    @functools.cached_property
    def thresholds(self) -> FloatArray:
        """r_j = c j, j = 1..n (Eq. 3.24) [mm]. Read-only (cached: every model step reads it)."""
        r = self.c_thr * np.arange(1, self.n + 1, dtype=float)
        r.flags.writeable = False
        return r

    @functools.cached_property
    def weights(self) -> FloatArray:
        """p(r_j) = rho exp(-tau r_j) (Eq. 3.23). Read-only, cached."""
        p = self.rho * np.exp(-self.tau * self.thresholds)
        p.flags.writeable = False
        return p

    @property
    def load_range(self) -> tuple[float, float]:
        return self.envelopes.load_range


def check_inputs(params: SDGPIParams, T: ArrayLike, m: ArrayLike) -> None:
    """Raise ModelInputError for non-finite or out-of-envelope temperature or load."""
    lo, hi = params.T_valid
    check_range('wire temperature T', T, lo, hi, 'degC')
    mlo, mhi = params.load_range
    check_range('wire load m', m, mlo, mhi, 'kgf')


def play_bounds(params: SDGPIParams, T: ArrayLike, m: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """(gamma_l - r_j, gamma_r + r_j), shape broadcast(T, m).shape + (n,) (Eq. 3.19)."""
    a, b = params.envelopes.coefficients(m)
    T = np.asarray(T, dtype=float)
    r = params.thresholds
    gamma_r = tanh_envelope(a, T)
    gamma_l = tanh_envelope(b, T)
    return gamma_l[..., None] - r, gamma_r[..., None] + r


def memoryless(params: SDGPIParams, T: ArrayLike, heating: ArrayLike) -> FloatArray:
    """p0 gamma(T), Eq. 3.22: the c set while heating (dT >= 0), the d set while cooling."""
    T = np.asarray(T, dtype=float)
    return params.p0 * np.where(heating, tanh_envelope(params.c, T), tanh_envelope(params.d, T))


@dataclass
class HysteresisState:
    """Memory of N independent SD-GPI models: play states w (N, n), last direction, last T."""

    w: FloatArray
    heating: NDArray[np.bool_]
    T_prev: FloatArray

    def copy(self) -> HysteresisState:
        return HysteresisState(self.w.copy(), self.heating.copy(), self.T_prev.copy())


def initial_state(params: SDGPIParams, T0: ArrayLike, m0: ArrayLike, *, branch: str = 'cooling') -> HysteresisState:
    """Memory after a long approach to (T0, m0) along the cooling (default) or heating branch.

    'cooling' leaves every play operator on its upper bound (the wire came down from hot),
    'heating' on its lower bound.
    """
    if branch not in ('cooling', 'heating'):
        raise ModelInputError('branch', branch, "{'cooling', 'heating'}")
    T0 = np.atleast_1d(np.asarray(T0, dtype=float))
    m0 = np.broadcast_to(np.asarray(m0, dtype=float), T0.shape)
    check_inputs(params, T0, m0)
    lower, upper = play_bounds(params, T0, m0)
    w = (upper if branch == 'cooling' else lower).copy()
    return HysteresisState(w, np.full(T0.shape, branch == 'heating'), T0.copy())


def mirrored_output(params: SDGPIParams, state: HysteresisState, T: ArrayLike) -> FloatArray:
    """y_m = p0 gamma(T) + sum_j p_j w_j, Eqs. 4.1/4.6 [mm]."""
    return memoryless(params, T, state.heating) + state.w @ params.weights


def step(params: SDGPIParams, state: HysteresisState, T: ArrayLike, m: ArrayLike, *, check: bool = True) -> FloatArray:
    """Advance the memory to (T, m) and return the elongation y = k_f - y_m [mm] (Eq. 4.2).

    Updates ``state`` in place. The memoryless part keeps its last direction while T
    is constant, so repeating a sample changes nothing (rate independence).
    """
    T = np.asarray(T, dtype=float)
    m = np.asarray(m, dtype=float)
    if check:
        check_inputs(params, T, m)
    lower, upper = play_bounds(params, T, m)
    np.minimum(np.maximum(state.w, lower, out=state.w), upper, out=state.w)
    dT = T - state.T_prev
    state.heating = np.where(dT > 0, True, np.where(dT < 0, False, state.heating))
    state.T_prev = np.array(np.broadcast_to(T, state.T_prev.shape), dtype=float)
    return params.k_f - mirrored_output(params, state, T)


def simulate(
    params: SDGPIParams, T: ArrayLike, m: ArrayLike, state: HysteresisState | None = None, *, branch: str = 'cooling'
) -> FloatArray:
    """Elongation [mm] for temperature and load series T[t], m[t] (scalars broadcast).

    Series may carry trailing scenario axes: T of shape (N,) or (N, S). The initial memory
    is ``initial_state(T[0], m[0], branch)`` unless ``state`` is given (then it is updated).
    """
    T = np.asarray(T, dtype=float)
    m = np.broadcast_to(np.asarray(m, dtype=float), T.shape)
    check_finite('wire temperature T', T, 'degC')
    check_inputs(params, T, m)
    if state is None:
        state = initial_state(params, T[0].reshape(-1), m[0].reshape(-1), branch=branch)
    y = np.empty(T.shape)
    for k in range(T.shape[0]):
        y[k] = step(params, state, T[k].reshape(-1), m[k].reshape(-1), check=False).reshape(T.shape[1:])
    return y
