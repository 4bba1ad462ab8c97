"""Identification of the TEM heat balance from measured runs (seed Sec. 4.3.2, Tables 4.9-4.10).

The model is Eqs. 4.13/4.14 (:mod:`sma_wrist.core.thermal.heat_balance`): per face f (T1 = muscle face,
T2 = exchanger face, degC; input I = -input_per_volt * u, u the drive voltage [V])::

    dT_f/dt = (K_at,f T_f + K_t,f T_o) I - K_Tinf,f T_f + K_T,f T_o + K_R,f I^2 + K_inf,f

The seed fitted the Table 4.9 columns by ``lsqcurvefit`` on the RK4-simulated temperatures
of 12 V sine runs (1/128-1 Hz), starting every parameter at 1. Here:

* **Simulation error**, not equation error: the residual is simulated minus measured
  temperature along each whole run, the model driven only by the measured voltage and the
  measured initial temperatures (a free-run prediction; nothing measured later is fed back).
* **Vectorised**: for a held command the model is linear in T, dT/dt = M(I) T + b(I), so one
  RK4 step is the affine map T <- A T + c with A = 1 + h P M, c = h P b and
  P = 1 + hM/2 + (hM)^2/6 + (hM)^3/24 (:func:`sma_wrist.core.thermal.heat_balance.step` uses the same
  identity). A and c of a block of steps are built in a few array operations over (steps,
  parameter sets, runs); the recursion itself is then 2 x 2 multiply-adds per step.
* **Jacobian by complex step**: the model is a polynomial in its parameters, so simulating
  parameter j at x + i h e_j gives d(sim)/dx_j = Im(sim) / h exactly (no cancellation, h =
  1e-30). All parameters are one batch of complex simulations; the real part is the
  simulation itself.
* **Start**: the better (lower simulation error) of the base parameters (Table 4.9 or a
  previous file) and an equation-error least-squares estimate from smoothed derivatives
  (linear in the parameters when both faces are measured).
* **Parameterisation**: per face x = (K_at, K_t, loss, K_T, K_R, K_inf) with
  loss = K_Tinf - K_T = k_inf / (rho Cp) (Eq. 4.15) bounded > 0 (a face must lose heat to its
  ambient), K_T >= 0 and K_R >= 0 (conduction and Joule heating cannot change sign).
* **Identifiability**: with only the muscle face measured (a wrist bag: the exchanger face
  has no published sensor) the exchanger column stays at the base values and only the
  muscle column (Eq. 4.13) is fitted; its start state is the base model's zero-drive
  offset between the faces, and the first ``settle_s`` seconds are left out of the residual.

The command scale input_per_volt is not identifiable apart from the K's (every K multiplies
a power of I); it stays fixed (doc/explanation/model.md). What is identifiable is one TEM's scale relative to the
other's when both share the columns: ``fit_thermal(tem_gain=True)`` fits TEM 1's drive gain (``tem_gain``) from
the runs of both (each run's ``layer``), and ``rest_C`` ties each fitted face's K_inf to a measured rest state.

Error statistics (Table 4.10): e = measured - simulated on the evaluated samples, in degC and
in % of the measured range of that face in that run (the form of Eq. 4.3).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from sma_wrist.core.errors import ParameterError, SmaWristError
from sma_wrist.core.signals import first_order
from sma_wrist.core.thermal import heat_balance as th

FloatArray = NDArray[np.float64]

#: Table 4.9 row names in the order of a face's coefficient vector (FaceCoefficients fields).
FACE_KEYS = ('K_alpha_tau', 'K_tau', 'K_T_inf', 'K_T', 'K_R', 'K_inf')
#: Free parameters of one face (loss = K_T_inf - K_T replaces K_T_inf, see module docstring).
FREE_KEYS = ('K_alpha_tau', 'K_tau', 'loss', 'K_T', 'K_R', 'K_inf')
FACE_NAMES = ('T1', 'T2')  # Table 4.9 columns: muscle face (Eq. 4.13), exchanger face (Eq. 4.14)
_LOWER = np.array([-1.0, -1.0, 1e-5, 0.0, 0.0, -50.0])
_UPPER = np.array([1.0, 1.0, 5.0, 5.0, 1.0, 50.0])
_COMPLEX_STEP = 1e-30
#: bounds of a TEM's fitted drive gain relative to the other's (``fit_thermal(tem_gain=True)``)
TEM_GAIN_BOUNDS = (0.2, 5.0)
#: the TEMs' drive gains differ by more than this: a warning (a supply lead, a thermal contact)
LAYER_GAIN_TOLERANCE = 0.1
#: the temperature sensors' first-order lag [s] when fitted (--sensor-lag): its bounds, and the lags the start is
#: chosen from on the fit without a lag (from 1 s a 7.8 h real staircase's fit ran to 0 s, a local minimum, where
#: the same table read through 120-240 s was 35 % better)
SENSOR_LAG_BOUNDS_S = (0.0, 1800.0)
SENSOR_LAG_STARTS_S = (0.0, 0.3, 1.0, 3.0, 10.0, 30.0, 100.0, 300.0, 1000.0)
_BLOCK = 512  # steps per block of precomputed affine maps (bounds memory)


class ThermalIdentificationError(SmaWristError, ValueError):
    """The data cannot identify the heat balance; the message says what is needed."""


@dataclass(frozen=True)
class ThermalRecord:
    """One measured run on a uniform grid.

    ``u[k]`` [V] drives the interval [t_k, t_k+1): the model holds I = -input_per_volt u[k]
    over it and the Joule term uses ``u2[k]``, the mean of u^2 over the interval (default
    u[k]^2, a zero-order hold as the DAC does; :func:`interval_means` makes both from a log of a
    faster or continuous drive). ``T[k]`` the measured faces [T1/muscle, T2/exchanger] at t_k
    [degC]; a face that was not measured is an all-NaN column. ``valid`` (K,) masks samples left
    out of every residual and statistic (bridged gaps). ``layer``: the wrist's TEM the run measured (0: TEM 1,
    1: TEM 2), whose drive gain (``ThermalParams.tem_gain``) the model applies.
    """

    name: str
    dt: float
    u: FloatArray
    T: FloatArray
    frequency_Hz: float | None = None
    valid: FloatArray | None = None
    source: str = ''
    u2: FloatArray | None = None
    layer: int = 0

    def __post_init__(self) -> None:
        if self.layer not in (0, 1):
            raise ThermalIdentificationError(f'{self.name}: layer {self.layer!r} must be 0 (TEM 1) or 1 (TEM 2)')
        u = np.asarray(self.u, dtype=float)
        T = np.asarray(self.T, dtype=float)
        if not (math.isfinite(self.dt) and self.dt > 0):
            raise ThermalIdentificationError(f'{self.name}: sample period {self.dt!r} s must be > 0')
        if u.ndim != 1 or T.shape != (u.size, 2):
            raise ThermalIdentificationError(f'{self.name}: need u (K,) and T (K, 2); got {u.shape}, {T.shape}')
        if not np.isfinite(u).all():
            raise ThermalIdentificationError(f'{self.name}: the drive voltage must be finite at every sample')
        faces = [f for f in range(2) if np.isfinite(T[:, f]).all()]
        if MUSCLE not in faces:
            raise ThermalIdentificationError(
                f'{self.name}: the T1 (muscle face) temperature must be finite at every sample of the grid'
            )
        object.__setattr__(self, 'u', u)
        u2 = u * u if self.u2 is None else np.asarray(self.u2, dtype=float)
        if u2.shape != u.shape or not np.isfinite(u2).all() or (u2 < u * u - 1e-9 * (1 + u * u)).any():
            raise ThermalIdentificationError(
                f'{self.name}: u2 must be the finite mean square of u over each interval (>= u^2)'
            )
        object.__setattr__(self, 'u2', u2)
        object.__setattr__(self, 'T', T)
        v = np.ones(u.size, bool) if self.valid is None else np.asarray(self.valid, bool)
        object.__setattr__(self, 'valid', v)

    @property
    def n(self) -> int:
        return int(self.u.size)

    @property
    def duration_s(self) -> float:
        return (self.n - 1) * self.dt

    @property
    def faces(self) -> tuple[int, ...]:
        """Indices of the measured faces (0 = T1 always; 1 = T2 when measured)."""
        return tuple(f for f in range(2) if np.isfinite(self.T[:, f]).all())


MUSCLE, EXCHANGER = th.MUSCLE_FACE, th.EXCHANGER_FACE


# ------------------------------------------------------------------------------ parameters


def table_of(params: th.ThermalParams) -> FloatArray:
    """(2, 6) Table 4.9 layout [face, FACE_KEYS] of a ThermalParams; K_inf as the model uses it."""
    rows = []
    for f, face in enumerate((params.muscle_face, params.exchanger_face)):
        rows.append([face.K_alpha_tau, face.K_tau, face.K_T_inf, face.K_T, face.K_R, float(params.K_inf[f])])
    return np.array(rows)


def params_from_table(table: FloatArray, base: th.ThermalParams) -> th.ThermalParams:
    """ThermalParams with the (2, 6) Table 4.9 columns; everything else from ``base``.

    ambient_C is cleared: the fitted K_inf is the model's heat input (Eq. 4.15), not a shifted one.
    """
    faces = [th.FaceCoefficients(*(float(v) for v in table[f])) for f in range(2)]
    try:
        return dataclasses.replace(base, muscle_face=faces[0], exchanger_face=faces[1], ambient_C=None)
    except ParameterError as e:
        raise ThermalIdentificationError(f'identified parameters are not a valid heat balance: {e}') from None


def _free_from_table(table: FloatArray, faces: Sequence[int], rest: bool = False) -> FloatArray:
    """Free vector of ``faces`` (FREE_KEYS each; without K_inf where the rest state sets it)."""
    x = []
    for f in faces:
        k_at, k_t, k_tinf, k_tc, k_r, k_inf = table[f]
        x.extend([k_at, k_t, k_tinf - k_tc, k_tc, k_r] + ([] if rest else [k_inf]))
    return np.array(x, dtype=float)


def _table_from_free(
    x: NDArray, base_table: FloatArray, faces: Sequence[int], rest_C: tuple[float, float] | None = None
) -> NDArray:
    """(..., 2, 6) tables from free vectors x (..., n len(faces)); works for complex x. ``rest_C``: the faces'
    zero-drive rest temperatures [degC]; each fitted face's K_inf then holds it there (Eq. 4.13/4.14 at I = 0:
    K_inf = K_Tinf T_own - K_T T_other) and is not in x (n = 5, else 6)."""
    x = np.asarray(x)
    n = 5 if rest_C is not None else 6
    out = np.empty(x.shape[:-1] + (2, 6), dtype=np.result_type(x, float))
    out[...] = base_table
    for i, f in enumerate(faces):
        k_at, k_t, loss, k_tc, k_r = (x[..., n * i + j] for j in range(5))
        out[..., f, 0], out[..., f, 1], out[..., f, 2] = k_at, k_t, loss + k_tc
        out[..., f, 3], out[..., f, 4] = k_tc, k_r
        if rest_C is None:
            out[..., f, 5] = x[..., n * i + 5]
        else:
            out[..., f, 5] = (loss + k_tc) * rest_C[f] - k_tc * rest_C[1 - f]
    return out


# ------------------------------------------------------------------------------ simulation


def interval_means(
    t: FloatArray, u: FloatArray, grid: FloatArray, dt: float, hold: str = 'zoh', sub: int = 8
) -> tuple[FloatArray, FloatArray]:
    """(mean u, mean u^2) [V, V^2] over each grid interval [g_k, g_k + dt) of a logged drive (t, u).

    ``hold``: 'zoh' when the logged value was held until the next sample (a DAC command, a
    bag's commands); 'linear' when the samples are of a continuous drive (a sine generator
    logged by a DAQ): u and u^2 are each interpolated linearly between samples. Evaluated with the midpoint rule on
    ``sub`` points per interval or per source sample, whichever is finer, so the I and I^2
    terms of Eqs. 4.13/4.14 see the drive's interval averages instead of a sample half an
    interval off.
    """
    if hold not in ('zoh', 'linear'):
        raise ThermalIdentificationError(f'input hold {hold!r} is not one of zoh, linear')
    src_dt = float(np.median(np.diff(t))) if t.size > 1 else dt
    m = max(sub, int(math.ceil(dt / max(src_dt, 1e-12))) * 2)
    at = grid[:, None] + (np.arange(m) + 0.5) / m * dt
    if hold == 'zoh':
        i = np.clip(np.searchsorted(t, at + 1e-9 * dt, side='right') - 1, 0, t.size - 1)
        x = u[i]
        return x.mean(axis=1), (x * x).mean(axis=1)
    # u^2 is interpolated itself, not squared after interpolation: for a sine sampled N times a
    # period the sample mean of u^2 is exact, the square of the interpolant falls short by
    # ~(pi/N)^2/3 (3 % of the Joule heat at 1 Hz logged at 10 Hz; measured 0.35 degC)
    return np.interp(at, t, u).mean(axis=1), np.interp(at, t, u * u).mean(axis=1)


def _pad(records: Sequence[ThermalRecord]) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """u, u2 (K, R), measured T (K, R, 2) with NaN where unmeasured or padded, mask (K, R, 2)."""
    dts = {round(r.dt, 12) for r in records}
    if len(dts) != 1:
        raise ThermalIdentificationError(
            f'runs have different sample periods {sorted(dts)} s; resample them to one grid first'
        )
    K = max(r.n for r in records)
    R = len(records)
    u = np.zeros((K, R))
    u2 = np.zeros((K, R))
    T = np.full((K, R, 2), np.nan)
    for j, r in enumerate(records):
        u[: r.n, j] = r.u
        u2[: r.n, j] = r.u2
        T[: r.n, j] = r.T
        T[: r.n, j][~r.valid] = np.nan
    return u, u2, T, np.isfinite(T)


def simulate_tables(
    tables: NDArray,
    input_per_volt: float | NDArray,
    u: FloatArray,
    T0: NDArray,
    dt: float,
    u2: FloatArray | None = None,
) -> NDArray:
    """RK4 of Eqs. 4.13/4.14 for parameter tables (N, 2, 6) and runs u (K, R) [V] from T0 (N|1, R, 2).

    ``input_per_volt``: one, or per parameter set and run (broadcastable to (N, R): each run's TEM its own drive
    gain). ``u2`` (K, R) [V^2] is the interval mean of u^2 for the Joule term (default u^2).

    Returns (K, N, R, 2): row 0 is T0, row k + 1 the state after command k was held dt.
    Real or complex (complex-step differentiation) tables; exact RK4 of the held-input
    linear system (module docstring). Non-finite values propagate (runaway parameter sets).
    """
    tables = np.asarray(tables)
    ipv = np.asarray(input_per_volt)
    dtype = np.result_type(tables, T0, ipv, float)
    K, R = u.shape
    N = tables.shape[0]
    c = [tables[:, f, j][:, None] for f in range(2) for j in range(6)]  # each (N, 1)
    kat0, kt0, ktinf0, ktc0, kr0, kinf0, kat1, kt1, ktinf1, ktc1, kr1, kinf1 = c
    out = np.empty((K, N, R, 2), dtype=dtype)
    x = np.broadcast_to(np.asarray(T0, dtype=dtype), (N, R, 2))
    x0, x1 = x[..., 0].copy(), x[..., 1].copy()
    out[0, :, :, 0], out[0, :, :, 1] = x0, x1
    h = dt
    for k0 in range(0, K - 1, _BLOCK):
        k1 = min(K - 1, k0 + _BLOCK)
        cur = -ipv * u[k0:k1][:, None, :]  # (B, 1 | N, R)
        # M = [[a, b], [c, d]] and the input term e (per face) for every step of the block
        a = kat0 * cur - ktinf0
        b = kt0 * cur + ktc0
        cc = kt1 * cur + ktc1
        d = kat1 * cur - ktinf1
        i2 = cur * cur if u2 is None else ipv**2 * u2[k0:k1][:, None, :]
        e0 = kr0 * i2 + kinf0
        e1 = kr1 * i2 + kinf1
        ha, hb, hc, hd = h * a, h * b, h * cc, h * d
        # P = 1 + hM/2 + (hM)^2/6 + (hM)^3/24 by Horner: P = 1 + hM (1/2 + hM (1/6 + hM/24))
        q_a, q_b, q_c, q_d = 1 / 6 + ha / 24, hb / 24, hc / 24, 1 / 6 + hd / 24
        q_a, q_b, q_c, q_d = (
            0.5 + ha * q_a + hb * q_c,
            ha * q_b + hb * q_d,
            hc * q_a + hd * q_c,
            0.5 + hc * q_b + hd * q_d,
        )
        p_a, p_b, p_c, p_d = (
            1 + ha * q_a + hb * q_c,
            ha * q_b + hb * q_d,
            hc * q_a + hd * q_c,
            1 + hc * q_b + hd * q_d,
        )
        # A = 1 + h P M, c = h P e
        A00 = 1 + h * (p_a * a + p_b * cc)
        A01 = h * (p_a * b + p_b * d)
        A10 = h * (p_c * a + p_d * cc)
        A11 = 1 + h * (p_c * b + p_d * d)
        C0 = h * (p_a * e0 + p_b * e1)
        C1 = h * (p_c * e0 + p_d * e1)
        for i in range(k1 - k0):
            x0, x1 = A00[i] * x0 + A01[i] * x1 + C0[i], A10[i] * x0 + A11[i] * x1 + C1[i]
            out[k0 + i + 1, :, :, 0] = x0
            out[k0 + i + 1, :, :, 1] = x1
    return out


def simulate_records(
    params: th.ThermalParams,
    records: Sequence[ThermalRecord],
    base: th.ThermalParams | None = None,
    sensor_lag_s: float = 0.0,
    muscle_lag_s: float = 0.0,
) -> list[FloatArray]:
    """Free-run simulation of each record (K_r, 2) [degC] from its measured start (see :func:`start_states`), as
    sensors of first-order lag ``sensor_lag_s`` [s] read it (0: the faces themselves) and the muscle face through
    its thermocouple's lag ``muscle_lag_s`` [s] (:func:`muscle_lagged`)."""
    u, u2, _, _ = _pad(records)
    T0 = start_states(records, base or params)
    sim = simulate_tables(
        table_of(params)[None], record_input_per_volt(params, records), u, T0[None], records[0].dt, u2
    )
    sim = first_order(muscle_lagged(sim, muscle_lag_s, records[0].dt), sensor_lag_s, records[0].dt)
    return [sim[: r.n, 0, j] for j, r in enumerate(records)]


def muscle_lagged(sim: NDArray, tau: float, dt: float) -> NDArray:
    """Simulated faces (K, ..., 2) [degC] with the muscle face as its thermocouple reads it: a first-order lag of
    time constant ``tau`` [s] along axis 0 (:func:`sma_wrist.core.signals.first_order`, exact for a face linear
    between the samples dt [s] apart), starting at rest at the simulated start (a run that starts at rest starts
    with the node at the measured temperature). The exchanger face as simulated. ``tau`` <= 0 returns ``sim``.

    A model whose measured muscle temperature is its node's lagged (plant_sim's ``model.temp_lag_s``) is fitted
    through this lag: fitted to the lagged measurement directly, the node would carry the lag once more. The lag
    is linear in the samples, so the complex-step part of a complex ``sim`` is lagged alike. Linear between the
    samples, not held: plant_sim lags at its 100 Hz tick, nearly the continuous lag, while the records' grid is
    coarse (commissioning's 0.25 s, where a held face lags a smooth one by 0.10 s for 0.2 s)."""
    if not tau > 0:
        return sim
    out = sim.copy()
    out[..., MUSCLE] = first_order(sim[..., MUSCLE], tau, dt, linear=True)
    return out


def record_input_per_volt(params: th.ThermalParams, records: Sequence[ThermalRecord]) -> FloatArray:
    """(R,) input per volt of each record's TEM (input_per_volt x its ``tem_gain``) [1/V]."""
    return params.layer_input_per_volt(2)[[r.layer for r in records]]


def start_states(
    records: Sequence[ThermalRecord], base: th.ThermalParams | None, rest: FloatArray | None = None
) -> FloatArray:
    """(R, 2) initial faces: measured where measured; an unmeasured exchanger face starts at the
    measured muscle face plus the base model's zero-drive offset between the faces (``rest``: that model's
    (muscle, exchanger) rest faces [degC] where the base is another form, e.g. the Peltier form's)."""
    rest = th.rest_state(base, 1, 1)[0, 0] if rest is None else np.asarray(rest, dtype=float)
    T0 = np.empty((len(records), 2))
    for j, r in enumerate(records):
        T0[j, MUSCLE] = r.T[0, MUSCLE]
        T0[j, EXCHANGER] = r.T[0, EXCHANGER] if EXCHANGER in r.faces else r.T[0, MUSCLE] + rest[1] - rest[0]
    return T0


# ------------------------------------------------------------------------------ statistics


def error_statistics(
    measured: FloatArray, simulated: FloatArray, mask: FloatArray | None = None, span_C: float | None = None
) -> dict[str, float]:
    """Table 4.10 statistics of e = measured - simulated [degC] and in % of the measured range (Eq. 4.3).

    ``span_C`` defaults to the range of ``measured`` over the masked samples.
    """
    m = np.ones(measured.shape, bool) if mask is None else np.asarray(mask, bool)
    e = (measured - simulated)[m]
    if e.size == 0:
        raise ThermalIdentificationError('no samples to evaluate')
    span = float(np.ptp(measured[m])) if span_C is None else float(span_C)
    pct = 100.0 * e / max(span, 1e-9)
    return {
        'n': int(e.size),
        'span_C': span,
        'mean_C': float(e.mean()),
        'std_C': float(e.std()),
        'max_C': float(e.max()),
        'min_C': float(e.min()),
        'rms_C': float(np.sqrt(np.mean(e * e))),
        'max_abs_C': float(np.abs(e).max()),
        'mean_pct': float(pct.mean()),
        'std_pct': float(pct.std()),
        'max_pct': float(pct.max()),
        'min_pct': float(pct.min()),
        'rms_pct': float(np.sqrt(np.mean(pct * pct))),
        'max_abs_pct': float(np.abs(pct).max()),
    }


# ------------------------------------------------------------------------------ fitting


@dataclass
class ThermalFit:
    """Result of :func:`fit_thermal`."""

    params: th.ThermalParams
    faces: tuple[int, ...]  # fitted Table 4.9 columns (0 = T1, 1 = T2)
    start: str  # 'base' or 'equation_error'
    cost: float  # mean over run-faces of the mean squared error [degC^2]
    rms_C: float  # sqrt(cost)
    nfev: int
    wall_s: float
    message: str = ''
    converged: bool = True  # False: stopped at max_iter with the cost still falling
    at_bounds: tuple[str, ...] = ()  # free parameters the fit left on a bound, e.g. 'T1 K_R = 0 (lower bound)'
    sensor_lag_s: float = 0.0  # the temperature sensors' first-order lag [s] fitted with the heat balance (0: none)
    rest_C: tuple[float, float] | None = None  # the rest state the fitted faces' K_inf were tied to [degC]
    muscle_lag_s: float = 0.0  # the muscle thermocouple's known lag [s] the fit read the muscle face through


def _weights(mask: FloatArray) -> FloatArray:
    """Each run-face gets equal weight: 1 / sqrt(samples x run-faces), so sum(r^2) = mean MSE."""
    n = mask.sum(axis=0)  # (R, 2)
    used = n > 0
    w = np.zeros(n.shape)
    w[used] = 1.0 / np.sqrt(n[used] * used.sum())
    return w


def equation_error_table(
    records: Sequence[ThermalRecord], input_per_volt: float, masks: Sequence[FloatArray] | None = None
) -> FloatArray | None:
    """Linear least-squares Table 4.9 (2, 6) from smoothed dT/dt when both faces are measured.

    Eq. 4.13/4.14 are linear in the parameters given T and I: dT_f/dt =
    [T_f I, T_o I, -T_f, T_o, I^2, 1] . (K_at, K_t, K_Tinf, K_T, K_R, K_inf). Biased by noise
    and sensor lag (that is why it is only a start). None when a run lacks the T2 face.
    """
    from scipy.signal import savgol_filter

    rows: list[list[FloatArray]] = [[], []]
    rhs: list[list[FloatArray]] = [[], []]
    for j, r in enumerate(records):
        if EXCHANGER not in r.faces:
            return None
        w = max(5, int(round(2.0 / r.dt)) | 1)
        if r.n <= w:
            continue
        Ts = savgol_filter(r.T, w, 2, axis=0)
        dT = savgol_filter(r.T, w, 2, deriv=1, delta=r.dt, axis=0)
        # the command is held over [t_k, t_k+1): the rate at t_k sees the mean of u_{k-1}, u_k
        uc = np.r_[r.u[0], 0.5 * (r.u[1:] + r.u[:-1])]
        u2c = np.r_[r.u2[0], 0.5 * (r.u2[1:] + r.u2[:-1])]
        cur = -input_per_volt * uc
        keep = r.valid.copy() if masks is None else masks[j].copy()
        keep[:w] = keep[-w:] = False
        wt = 1.0 / math.sqrt(max(int(keep.sum()), 1))
        for f in range(2):
            o = 1 - f
            X = np.stack(
                [Ts[:, f] * cur, Ts[:, o] * cur, -Ts[:, f], Ts[:, o], input_per_volt**2 * u2c, np.ones(r.n)], axis=1
            )
            rows[f].append(wt * X[keep])
            rhs[f].append(wt * dT[keep, f])
    if not rows[0]:
        return None
    table = np.empty((2, 6))
    for f in range(2):
        X, y = np.concatenate(rows[f]), np.concatenate(rhs[f])
        scale = np.abs(X).max(axis=0) + 1e-12
        sol, *_ = np.linalg.lstsq(X / scale, y, rcond=None)
        table[f] = sol / scale
    return table


class _Problem:
    """Residuals and complex-step Jacobian of the simulation error over a set of runs."""

    def __init__(
        self,
        records: Sequence[ThermalRecord],
        base: th.ThermalParams,
        faces: tuple[int, ...],
        masks: Sequence[FloatArray] | None,
        settle_s: float,
        sensor_lag: bool = False,
        rest_C: tuple[float, float] | None = None,
        tem_gain: bool = False,
        muscle_lag_s: float = 0.0,
    ) -> None:
        self.records = records
        self.lag = sensor_lag  # x's last entry is then the sensors' lag [s]
        self.muscle_lag = muscle_lag_s  # the muscle thermocouple's known lag [s] (muscle_lagged)
        self.base = base
        self.faces = faces
        self.rest_C = rest_C
        self.n_table = (5 if rest_C is not None else 6) * len(faces)  # x[:n_table]: the table's free entries
        # x[n_table] with ``tem_gain``: TEM 1's drive gain relative to the base's (TEM 2's stays the base's)
        self.gain = tem_gain
        self.base_table = table_of(base)
        self.ipv = record_input_per_volt(base, records)  # (R,)
        self.tem1 = np.array([r.layer == 0 for r in records])
        self.dt = records[0].dt
        self.u, self.u2, self.T, mask = _pad(records)
        if masks is not None:  # training masks (K_r,) per record
            for j, (r, m) in enumerate(zip(records, masks)):
                mask[: r.n, j] &= np.asarray(m, bool)[:, None]
        for j, r in enumerate(records):
            if EXCHANGER not in r.faces:  # guessed start state of the unmeasured face: let it settle
                mask[: int(round(settle_s / r.dt)), j] = False
        mask[0] = False  # the start is measured, not predicted
        if not mask.any():
            raise ThermalIdentificationError('no training samples left (runs too short for the settle time?)')
        self.mask = mask
        self.w = _weights(mask)
        self.T0 = start_states(records, base)
        self.Tm = np.where(mask, self.T, 0.0)
        self._cache: tuple[bytes, FloatArray, FloatArray] | None = None

    def _ipv(self, x: NDArray) -> NDArray:
        """(N, R) input per volt of each run under parameter rows x (N, n) (TEM 1's runs scaled by the fitted gain)."""
        if not self.gain:
            return self.ipv[None]
        g = x[:, self.n_table, None]
        return self.ipv[None] * np.where(self.tem1[None], g, 1.0)

    def _run(self, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        key = x.tobytes()
        if self._cache is not None and self._cache[0] == key:
            return self._cache[1], self._cache[2]
        n = x.size
        xc = np.tile(x.astype(complex), (n, 1))
        xc[np.arange(n), np.arange(n)] += 1j * _COMPLEX_STEP
        m = n - 1 if self.lag else n  # the heat balance's columns; the lag's needs no heat-balance run of its own
        tables = _table_from_free(xc[:m, : self.n_table], self.base_table, self.faces, self.rest_C)
        with np.errstate(all='ignore'):
            sim = simulate_tables(tables, self._ipv(xc[:m]), self.u, self.T0[None], self.dt, self.u2)  # (K, m, R, 2)
            sim = muscle_lagged(sim, self.muscle_lag, self.dt)  # linear: the complex step's part lagged alike
            if self.lag:  # the table's columns through the lag at x's value; the lag's column: x's run, lag stepped
                stepped = first_order(sim[:, :1].real.astype(complex), xc[-1, -1], self.dt)
                sim = np.concatenate([first_order(sim, float(x[-1]), self.dt), stepped], axis=1)  # (K, n, R, 2)
            res = (sim[:, 0].real - self.Tm) * self.w  # (K, R, 2)
            jac = sim.imag / _COMPLEX_STEP * self.w[None]  # (K, n, R, 2)
        r = res[self.mask]
        J = np.moveaxis(jac, 1, -1)[self.mask]  # (M, n)
        self._cache = (key, r, J)
        return r, J

    def residuals(self, x: FloatArray) -> FloatArray:
        return self._run(x)[0]

    def jacobian(self, x: FloatArray) -> FloatArray:
        return self._run(x)[1]

    def cost(self, x: FloatArray) -> float:
        tables = _table_from_free(x[None, : self.n_table], self.base_table, self.faces, self.rest_C)
        with np.errstate(all='ignore'):
            sim = muscle_lagged(
                simulate_tables(tables, self._ipv(x[None]), self.u, self.T0[None], self.dt, self.u2),
                self.muscle_lag,
                self.dt,
            )
            if self.lag:
                sim = first_order(sim, float(x[-1]), self.dt)
            r = ((sim[:, 0] - self.Tm) * self.w)[self.mask]
        c = float(np.sum(r * r))
        return c if math.isfinite(c) else math.inf


def _levenberg_marquardt(
    prob: _Problem, x: FloatArray, lo: FloatArray, hi: FloatArray, max_iter: int
) -> tuple[FloatArray, float, int, str]:
    """Levenberg-Marquardt on the normal equations with Marquardt scaling, steps projected on the bounds.

    The residual vector is long (samples x run-faces) and the parameters few (<= 12), so the
    12 x 12 normal equations are the cheap way (scipy's trf spends most of its time in an SVD
    of the tall Jacobian). Returns (x, cost, simulations, message).
    """
    r, J = prob._run(x)
    cost = float(r @ r)
    nfev, lam = 1, 1e-3
    for _ in range(max_iter):
        g = J.T @ r
        H = J.T @ J
        d = np.maximum(np.diag(H), 1e-30)
        while True:
            try:
                step = np.linalg.solve(H + lam * np.diag(d), -g)
            except np.linalg.LinAlgError:
                step = np.linalg.lstsq(H + lam * np.diag(d), -g, rcond=None)[0]
            x_new = np.clip(x + step, lo, hi)
            c_new = prob.cost(x_new)
            nfev += 1
            if c_new < cost:
                break
            lam *= 4.0
            if lam > 1e12:
                return x, cost, nfev, 'converged (no decreasing step left)'
        done = cost - c_new <= 1e-8 * cost or np.all(np.abs(x_new - x) <= 1e-9 * (np.abs(x) + 1e-9))
        x, cost, lam = x_new, c_new, max(lam / 3.0, 1e-12)
        if done:
            return x, cost, nfev, 'converged (relative decrease below 1e-8)'
        r, J = prob._run(x)
        nfev += 1
    return x, cost, nfev, f'stopped after {max_iter} iterations'


def fit_thermal(
    records: Sequence[ThermalRecord],
    base: th.ThermalParams | None = None,
    *,
    faces: str = 'auto',
    masks: Sequence[FloatArray] | None = None,
    settle_s: float = 30.0,
    max_iter: int = 60,
    sensor_lag: bool = False,
    rest_C: tuple[float, float] | None = None,
    tem_gain: bool = False,
    muscle_lag_s: float = 0.0,
) -> ThermalFit:
    """Fit Table 4.9 columns to runs by simulation-error least squares (module docstring).

    ``faces``: 'auto' (both columns when every run measured T2, else the T1 column), 'both',
    'muscle'. ``masks``: per-run (K_r,) bool training samples (default all valid samples).
    ``sensor_lag``: fit, with the table, one first-order lag [s] through which every temperature was measured
    (a thermistor on a block, a sheathed thermocouple: the simulation is compared as that sensor reads it).
    ``rest_C``: the (muscle, exchanger) face temperatures the TEM settles at with no drive, measured [degC]; each
    fitted face's K_inf is then tied to it (Eqs. 4.13/4.14 at I = 0) instead of fitted. Runs of minutes do not
    tell a small loss to ambient from a large ambient (measured on the emulated phase-fraction wrist: the muscle
    face's loss at its bound 1e-5 /s with an implied ambient of 1078 degC, a model that holds no drive in the
    window); the rest state does. ``tem_gain``: fit TEM 1's drive gain relative to TEM 2's with the shared columns
    (the runs' ``layer`` says which TEM each measured; ``params.tem_gain`` = (base's x gain, base's)).
    ``muscle_lag_s``: the muscle thermocouple's known first-order lag [s] (the model's ``temp_lag_s``): the muscle
    face is fitted as it reads it (:func:`muscle_lagged`), the table then the node's; the exchanger face as measured.
    Raises ThermalIdentificationError when the data cannot support the fit.
    """
    t_wall = time.perf_counter()
    if not records:
        raise ThermalIdentificationError('no runs to fit')
    base = base or th.ThermalParams()
    both = all(EXCHANGER in r.faces for r in records)
    if faces == 'auto':
        fitted = (MUSCLE, EXCHANGER) if both else (MUSCLE,)
    elif faces == 'both':
        if not both:
            missing = [r.name for r in records if EXCHANGER not in r.faces]
            raise ThermalIdentificationError(
                f'--faces both needs the T2 (exchanger face) temperature in every run; missing in {", ".join(missing)}'
            )
        fitted = (MUSCLE, EXCHANGER)
    elif faces == 'muscle':
        fitted = (MUSCLE,)
    else:
        raise ThermalIdentificationError(f'faces = {faces!r} is not one of auto, both, muscle')
    for r in records:
        if float(np.ptp(r.u)) < 0.5:
            raise ThermalIdentificationError(
                f'{r.name}: the drive voltage hardly changes (range {np.ptp(r.u):.3g} V); '
                "identification needs an exciting input, e.g. the seed's 12 V sines"
            )
    if tem_gain and len({r.layer for r in records}) < 2:
        raise ThermalIdentificationError("a TEM's drive gain relative to the other's needs runs of both TEMs")
    rest = rest_C is not None
    if rest and not all(math.isfinite(t) for t in rest_C):  # type: ignore[union-attr]
        raise ThermalIdentificationError(f'rest temperatures {rest_C!r} must be finite degC')
    if not (math.isfinite(muscle_lag_s) and muscle_lag_s >= 0):
        raise ThermalIdentificationError(f'muscle thermocouple lag {muscle_lag_s!r} s must be >= 0')
    prob = _Problem(records, base, fitted, masks, settle_s, sensor_lag, rest_C, tem_gain, muscle_lag_s)
    per = 5 if rest else 6
    lo, hi = np.tile(_LOWER[:per], len(fitted)), np.tile(_UPPER[:per], len(fitted))
    extra = [1.0] if tem_gain else []  # TEM 1's gain relative to the base's, from the base's
    if tem_gain:
        lo, hi = np.r_[lo, TEM_GAIN_BOUNDS[0]], np.r_[hi, TEM_GAIN_BOUNDS[1]]
    if sensor_lag:  # the table fitted without a lag (from the starts below), read through the lag that suits it best
        plain = fit_thermal(
            records,
            base,
            faces=faces,
            masks=masks,
            settle_s=settle_s,
            max_iter=max_iter,
            rest_C=rest_C,
            tem_gain=tem_gain,
            muscle_lag_s=muscle_lag_s,
        )
        x0 = np.r_[_free_from_table(table_of(plain.params), fitted, rest), plain.params.tem_gain[0] / base.tem_gain[0]]
        x0 = x0 if tem_gain else x0[:-1]
        lags = [t for t in SENSOR_LAG_STARTS_S if SENSOR_LAG_BOUNDS_S[0] <= t <= SENSOR_LAG_BOUNDS_S[1]]
        starts = {f'no-lag fit, lag {t:g} s': np.r_[x0, t] for t in lags}
        lo, hi = np.r_[lo, SENSOR_LAG_BOUNDS_S[0]], np.r_[hi, SENSOR_LAG_BOUNDS_S[1]]
    else:
        starts = {'base': np.r_[_free_from_table(prob.base_table, fitted, rest), extra]}
        if both:
            ee = equation_error_table(records, base.input_per_volt, masks)
            if ee is not None and np.isfinite(ee).all():
                starts['equation_error'] = np.r_[_free_from_table(ee, fitted, rest), extra]
    costs = {k: prob.cost(np.clip(v, lo, hi)) for k, v in starts.items()}
    start = min(costs, key=lambda k: costs[k])
    if not math.isfinite(costs[start]):
        raise ThermalIdentificationError(
            'the simulation diverges from every start (base parameters and equation '
            'error); check the voltage unit and the sign convention (u > 0 heats T1)'
        )
    x, cost, nfev, message = _levenberg_marquardt(prob, np.clip(starts[start], lo, hi), lo, hi, max_iter)
    nfev += len(costs) + (plain.nfev if sensor_lag else 0)
    table = _table_from_free(x[None, : prob.n_table], prob.base_table, fitted, rest_C)[0].real
    params = params_from_table(table, base)
    if tem_gain:
        params = dataclasses.replace(params, tem_gain=(base.tem_gain[0] * float(x[prob.n_table]), base.tem_gain[1]))
    # a bound the data pushed a parameter onto (measured: K_R = 0 on a heating-only real Peltier) says the data do
    # not determine it, which the fit's RMS alone does not show
    names = (
        [f'{FACE_NAMES[f]} {k}' for f in fitted for k in FREE_KEYS[:per]]
        + (['TEM 1 drive gain'] if tem_gain else [])
        + (['sensor lag [s]'] if sensor_lag else [])
    )
    tol = 1e-9 * (hi - lo)
    at_bounds = tuple(
        f'{n} = {v:.4g} ({"lower" if v <= a + e else "upper"} bound)'
        for n, v, a, b, e in zip(names, x, lo, hi, tol)
        if v <= a + e or v >= b - e
    )
    return ThermalFit(
        params,
        fitted,
        start,
        cost,
        math.sqrt(cost),
        nfev,
        time.perf_counter() - t_wall,
        message,
        not message.startswith('stopped'),
        at_bounds,
        float(x[-1]) if sensor_lag else 0.0,
        rest_C,
        muscle_lag_s,
    )


# ------------------------------------------------------------------------------ validation


@dataclass
class RecordEvaluation:
    """Error statistics of one run (per measured face) under one parameter set."""

    record: str
    frequency_Hz: float | None
    mode: str  # 'in-sample', 'leave-one-out', 'time-split', 'holdout-file', 'default'
    faces: dict[str, dict[str, float]]
    simulated: FloatArray = field(repr=False)
    evaluated: FloatArray = field(repr=False)  # (K,) bool: samples in the statistics

    def as_dict(self) -> dict[str, object]:
        return {'record': self.record, 'frequency_Hz': self.frequency_Hz, 'mode': self.mode, 'faces': self.faces}


def evaluate(
    params: th.ThermalParams,
    records: Sequence[ThermalRecord],
    mode: str,
    masks: Sequence[FloatArray] | None = None,
    settle_s: float = 30.0,
    base: th.ThermalParams | None = None,
    sensor_lag_s: float = 0.0,
    muscle_lag_s: float = 0.0,
) -> list[RecordEvaluation]:
    """Free-run each record under ``params`` and return Table 4.10 statistics per measured face.

    ``masks``: per-record samples to evaluate (default all valid samples after the start,
    and after ``settle_s`` when T2 is not measured). The % is of the face's measured range
    over the whole run. ``sensor_lag_s``: the simulation as sensors of that lag read it; ``muscle_lag_s``: the muscle
    face as its thermocouple of that lag reads it (:func:`muscle_lagged`).
    """
    sims = simulate_records(params, records, base, sensor_lag_s, muscle_lag_s)
    out = []
    for j, r in enumerate(records):
        ev = r.valid.copy()
        ev[0] = False
        if EXCHANGER not in r.faces:
            ev[: int(round(settle_s / r.dt))] = False
        if masks is not None:
            ev &= np.asarray(masks[j], bool)
        if not ev.any():
            raise ThermalIdentificationError(f'{r.name}: no samples left to evaluate')
        faces = {}
        for f in r.faces:
            faces[FACE_NAMES[f]] = error_statistics(r.T[:, f], sims[j][:, f], ev, span_C=float(np.ptp(r.T[r.valid, f])))
        out.append(RecordEvaluation(r.name, r.frequency_Hz, mode, faces, sims[j], ev))
    return out


@dataclass
class ThermalIdentification:
    """Everything :func:`identify_thermal` found."""

    fit: ThermalFit
    base: th.ThermalParams
    in_sample: list[RecordEvaluation]
    holdout: list[RecordEvaluation]
    before: list[RecordEvaluation]  # the base (default) model on the same runs
    validation: str
    wall_s: float


def identify_thermal(
    records: Sequence[ThermalRecord],
    holdout: Sequence[ThermalRecord] = (),
    base: th.ThermalParams | None = None,
    *,
    faces: str = 'auto',
    validation: str = 'auto',
    train_fraction: float = 0.6,
    settle_s: float = 30.0,
    sensor_lag: bool = False,
    progress: Callable[[str], None] | None = None,
    tem_gain: bool = False,
) -> ThermalIdentification:
    """Fit on ``records`` and validate on data the fit never saw (``sensor_lag``, ``tem_gain``: :func:`fit_thermal`'s,
    in every fit; each prediction is read through the lag its fit found and drives its TEM with its fitted gain).

    ``validation``: 'leave-one-out' (each run predicted by the fit on the others; needs >= 2
    runs), 'time-split' (fit on the first ``train_fraction`` of every run, score the rest,
    simulated on from the start), 'none', or 'auto' (leave-one-out with >= 2 runs, else
    time-split). ``holdout`` runs are always predicted by the final fit on all ``records``.
    """
    t0 = time.perf_counter()
    say = progress or (lambda s: None)
    base = base or th.ThermalParams()
    if validation == 'auto':
        validation = 'leave-one-out' if len(records) >= 2 else 'time-split'
    if validation not in ('leave-one-out', 'time-split', 'none'):
        raise ThermalIdentificationError(
            f'validation {validation!r} is not one of auto, leave-one-out, time-split, none'
        )
    if validation == 'leave-one-out' and len(records) < 2:
        raise ThermalIdentificationError(
            'leave-one-out validation needs at least two runs (files, frequencies or '
            'muscles); use --validation time-split for one run'
        )
    if not 0.2 <= train_fraction <= 0.9:
        raise ThermalIdentificationError(f'train fraction {train_fraction} must be in [0.2, 0.9]')
    all_records = list(records) + list(holdout)
    if len({round(r.dt, 12) for r in all_records}) != 1:
        raise ThermalIdentificationError('all runs (and hold-out runs) must share one sample period')
    if tem_gain and validation == 'leave-one-out' and not each_tem_twice(records):
        raise ThermalIdentificationError(
            "leave-one-out validation of each TEM's drive gain needs at least two runs of each TEM (a fit without "
            "a TEM's runs cannot know its gain); use time-split validation"
        )
    say(f'fit on {len(records)} run(s)')
    final = fit_thermal(records, base, faces=faces, settle_s=settle_s, sensor_lag=sensor_lag, tem_gain=tem_gain)
    fitted_faces = 'both' if len(final.faces) == 2 else 'muscle'
    held: list[RecordEvaluation] = []
    if validation == 'leave-one-out':
        for j, r in enumerate(records):
            say(f'leave-one-out {j + 1}/{len(records)}: predicting {r.name}')
            others = [q for i, q in enumerate(records) if i != j]
            f = fit_thermal(
                others, base, faces=fitted_faces, settle_s=settle_s, sensor_lag=sensor_lag, tem_gain=tem_gain
            )
            held += evaluate(f.params, [r], 'leave-one-out', settle_s=settle_s, base=base, sensor_lag_s=f.sensor_lag_s)
    elif validation == 'time-split':
        say(f'time split: fit on the first {train_fraction:.0%} of every run')
        train = [np.arange(r.n) < int(train_fraction * r.n) for r in records]
        f = fit_thermal(
            records,
            base,
            faces=fitted_faces,
            masks=train,
            settle_s=settle_s,
            sensor_lag=sensor_lag,
            tem_gain=tem_gain,
        )
        held += evaluate(
            f.params,
            records,
            'time-split',
            masks=[~m for m in train],
            settle_s=settle_s,
            base=base,
            sensor_lag_s=f.sensor_lag_s,
        )
    lag = final.sensor_lag_s
    if holdout:
        say(f'predicting {len(holdout)} hold-out run(s)')
        held += evaluate(final.params, holdout, 'holdout-file', settle_s=settle_s, base=base, sensor_lag_s=lag)
    in_sample = evaluate(final.params, records, 'in-sample', settle_s=settle_s, base=base, sensor_lag_s=lag)
    before = evaluate(base, all_records, 'default', settle_s=settle_s, base=base)
    return ThermalIdentification(final, base, in_sample, held, before, validation, time.perf_counter() - t0)


def each_tem_twice(records: Sequence[ThermalRecord]) -> bool:
    """Whether leave-one-out can validate each TEM's drive gain: two runs or more of each TEM (a fit without a TEM's
    runs cannot know its gain)."""
    return all(sum(r.layer == m for r in records) >= 2 for m in (0, 1))


def tem_gain_warning(tem_gain: tuple[float, float], where: str) -> str | None:
    """The warning where TEM 1's and TEM 2's drive gains (``ThermalParams.tem_gain``) differ by more than
    :data:`LAYER_GAIN_TOLERANCE` (``where``: what became of the gains, in brackets), else None."""
    ratio = tem_gain[0] / tem_gain[1]
    if abs(ratio - 1.0) <= LAYER_GAIN_TOLERANCE:
        return None
    weaker = 1 if ratio < 1 else 2
    return (
        f'TEM {weaker} pumps {abs(1 - min(ratio, 1 / ratio)):.0%} less per volt than the other ({where}): '
        f'check TEM {weaker} (its supply lead, its thermal contact) if the difference is not intended'
    )


def tem_hold_limits(params: th.ThermalParams, resolution_V: float = 0.05) -> tuple[tuple[float, float], ...]:
    """Command hold limits [V] of each TEM of an identified model ((low, high) of TEM 1, TEM 2), found as
    doc/explanation/model.md found the defaults.

    :func:`sma_wrist.core.thermal.heat_balance.characterise_constant_commands` (every face in the window,
    converged after 3000 s) at each TEM's drive gain, rounded inward to whole volts: a weaker TEM holds a larger
    drive. Raises when a TEM holds less than 1 V in a direction.
    """
    out: dict[float, tuple[float, float]] = {}
    for g in sorted(set(params.tem_gain)):
        one = dataclasses.replace(params, input_per_volt=params.input_per_volt * g, tem_gain=(1.0, 1.0))
        c = th.characterise_constant_commands(one, resolution_V=resolution_V)
        hi, lo = math.floor(c.heating_max_V), math.ceil(c.cooling_max_V)
        if hi < 1 or lo > -1:
            raise ThermalIdentificationError(
                f'the identified model holds only {c.cooling_max_V:+.2f}..{c.heating_max_V:+.2f} V with every face '
                f'in {params.window_C} degC; it is not usable for the wrist (check the data and the voltage unit)'
            )
        out[g] = (float(lo), float(hi))
    return tuple(out[g] for g in params.tem_gain)


def hold_limits(params: th.ThermalParams, resolution_V: float = 0.05) -> tuple[float, float]:
    """The command hold limits [V] both TEMs hold (:func:`tem_hold_limits`: the larger low, the smaller high)."""
    per = tem_hold_limits(params, resolution_V)
    return max(lo for lo, _ in per), min(hi for _, hi in per)
