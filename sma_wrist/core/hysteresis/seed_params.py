"""The seed's printed GPI/SD-GPI tables as model parameters, under named conventions.

The printed Tables 4.1-4.3 (GPI per load) and 4.5-4.6 (SD-GPI) lost something: units,
which envelope is "l" and which "r", the unprinted weight p0 of Eq. 4.1, or whether the
mirror of Eq. 4.2 is already in the numbers. This module builds :class:`~sma_wrist.core.hysteresis.sdgpi.SDGPIParams` from
the tables under each reading and measures what loop each gives for the input of Sec. 3.2,
so the choice can be argued from numbers (doc/explanation/model.md).

Conventions
-----------
``envelope``
    'literal': a set -> gamma_r, b set -> gamma_l, as Eq. 3.21 prints (and as
    :mod:`sma_wrist.core.hysteresis.sdgpi` implements). 'swapped': the a set is the ascending
    (heating, lower) envelope gamma_l and the b set gamma_r, implemented by passing the
    sets to :class:`~sma_wrist.core.hysteresis.sdgpi.SDGPIParams` in swapped roles.
``p0``
    1.0, 0.0, or 'fitted': the p0 whose loop shape (mean removed) is closest in the
    least-squares sense to the project's default loop at the same load
    (:func:`sma_wrist.core.hysteresis.default_params.default_sdgpi`), i.e. to the behaviour Sec. 3.2
    describes. p0 enters linearly, so this is a one-line regression.
``mirror``
    True: elongation y = k_f - y_m (Eq. 4.2, k_f = 6 mm); False: the tables give the
    elongation directly, y = y_m.
``load_unit``
    Unit of m in the quadratics of Table 4.5 (Eqs. 4.4-4.5): 'kg', 'g', 'hg' or 'N'.

Input (Sec. 3.2): a decaying sawtooth of 4e-3 Hz whose amplitude starts at 78 degC and
decays as exp(-1e-3 t) towards the 20 degC floor, preceded by one heating ramp from 20 degC
(the wire starts on its cooling branch), so the first rise and fall form the major loop.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sma_wrist.core.errors import ModelInputError
from sma_wrist.core.hysteresis.play import play_update
from sma_wrist.core.hysteresis.sdgpi import EnvelopeSections, SDGPIParams, memoryless, play_bounds
from sma_wrist.data import seed_tables as st

FloatArray = NDArray[np.float64]
EnvelopeConvention = Literal['literal', 'swapped']

#: Per-load scale from grams to each candidate unit of the Table 4.5 quadratics.
LOAD_UNITS: dict[str, float] = {'kg': 1e-3, 'g': 1.0, 'hg': 1e-2, 'N': 9.80665e-3}

#: Sec. 3.2 sawtooth.
SAWTOOTH_FREQ_HZ = 4e-3
SAWTOOTH_DECAY_PER_S = 1e-3
SAWTOOTH_T_MAX_C = 78.0
SAWTOOTH_T_MIN_C = 20.0

#: Criteria of an "SMA-like" loop (Sec. 3.2 described loops).
MIN_HYSTERESIS_WIDTH_C = 5.0
STROKE_RANGE_MM = (0.1, 6.0)


# ----------------------------------------------------------------------------- parameter builders


def _check_envelope(envelope: str) -> None:
    if envelope not in ('literal', 'swapped'):
        raise ModelInputError('envelope convention', envelope, "{'literal', 'swapped'}")


def gpi_params(load_g: int, *, envelope: EnvelopeConvention = 'literal', p0: float = 1.0) -> SDGPIParams:
    """A row of Tables 4.1-4.3 as a fixed-load GPI (Eqs. 3.19-3.24, 4.1), valid at any load."""
    _check_envelope(envelope)
    row = st.gpi_row(load_g)
    a, b = (row['a'], row['b']) if envelope == 'literal' else (row['b'], row['a'])
    return SDGPIParams.from_gpi(
        a,
        b,
        row['c'],
        row['d'],
        row['rho'],
        row['tau'],
        row['c_thr'],  # type: ignore[arg-type]
        p0=p0,
        name=f'Table 4.1-4.3 {load_g} g, {envelope}, p0={p0:g}',
    )


def sdgpi_section_params(
    section: int,
    *,
    envelope: EnvelopeConvention = 'literal',
    p0: float = 1.0,
    load_unit: str = 'kg',
    reversed_order: bool = False,
) -> SDGPIParams:
    """Tables 4.5-4.6, section 0 (650-800 g) or 1 (800-1050 g), as an SD-GPI (Eqs. 4.4-4.6).

    Each section has its own c, d, rho, tau, c (Table 4.6), so the seed's SD-GPI is two
    models; the section's edges are expressed in ``load_unit``. ``reversed_order`` reads
    Table 4.5's third index as the m^2 coefficient instead of the constant.
    """
    _check_envelope(envelope)
    if load_unit not in LOAD_UNITS:
        raise ModelInputError('load unit', load_unit, str(sorted(LOAD_UNITS)))
    q = st.sdgpi_quadratics(section)
    qa, qb = np.array(q['a']), np.array(q['b'])  # (4, 3): (s_i0, s_i1, s_i2)
    if reversed_order:
        qa, qb = qa[:, ::-1], qb[:, ::-1]
    if envelope == 'swapped':
        qa, qb = qb, qa
    edges = np.array(st.SDGPI_SECTIONS_G[section], dtype=float) * LOAD_UNITS[load_unit]
    t6 = {k: v[section] for k, v in st.TABLE_4_6.items()}
    cset = np.array([t6[f'c{i}'] for i in range(4)])
    dset = np.array([t6[f'd{i}'] for i in range(4)])
    return SDGPIParams(
        EnvelopeSections(edges, qa[None], qb[None]),
        cset,
        dset,
        t6['rho'],
        t6['tau'],
        t6['c'],
        p0=p0,
        name=f'Tables 4.5-4.6 section {section}, {envelope}, m in {load_unit}, p0={p0:g}',
    )


def sdgpi_section_for(load_g: float) -> int:
    """Section of Tables 4.5-4.6 holding a load [g]; 800 g belongs to the first (650-800)."""
    return 0 if load_g <= st.SDGPI_SECTIONS_G[0][1] else 1


def sdgpi_coefficients(
    load_g: float, *, load_unit: str = 'kg', reversed_order: bool = False
) -> tuple[FloatArray, FloatArray]:
    """(a_i(m), b_i(m)) from Table 4.5 at a load [g] under a unit reading (Eqs. 4.4-4.5, literal sets)."""
    p = sdgpi_section_params(sdgpi_section_for(load_g), load_unit=load_unit, reversed_order=reversed_order)
    a, b = p.envelopes.coefficients(np.array(load_g * LOAD_UNITS[load_unit]))
    return a, b


def load_unit_test(
    units: Iterable[str] = LOAD_UNITS, orders: Sequence[bool] = (False, True)
) -> list[dict[str, object]]:
    """How far Table 4.5's a_i(m), b_i(m) lie from Table 4.1's rows, per unit reading.

    Returns one dict per (unit, order): the median over loads and coefficients of
    |log10(|coef_4.5| / |coef_4.1|)| (0 = same magnitude; 1 = a factor 10 off), the fraction of
    coefficients with the same sign, and the median relative error |coef_4.5 - coef_4.1| / |coef_4.1|.
    """
    out = []
    for unit in units:
        for rev in orders:
            logs, signs, rels = [], [], []
            for load in st.GPI_LOADS_G:
                a, b = sdgpi_coefficients(load, load_unit=unit, reversed_order=rev)
                got = np.concatenate([a, b])
                want = np.array(st.TABLE_4_1[load])
                logs.append(np.abs(np.log10(np.abs(got) / np.abs(want))))
                signs.append(np.sign(got) == np.sign(want))
                rels.append(np.abs(got - want) / np.abs(want))
            out.append(
                {
                    'unit': unit,
                    'reversed_order': rev,
                    'median_log10_ratio': float(np.median(np.concatenate(logs))),
                    'same_sign_fraction': float(np.mean(np.concatenate(signs))),
                    'median_rel_error': float(np.median(np.concatenate(rels))),
                }
            )
    return out


# ----------------------------------------------------------------------------- input and simulation


def sawtooth_input(
    dt: float = 0.5, n_periods: int = 5, *, T_min: float = SAWTOOTH_T_MIN_C, T_max: float = SAWTOOTH_T_MAX_C
) -> tuple[FloatArray, FloatArray, int, int]:
    """Sec. 3.2 decaying sawtooth: (t [s], T [degC], index of the first peak, index of the first trough).

    One heating ramp T_min -> T_max (half a period), then triangles whose peak decays as
    T_min + (T_max - T_min) exp(-1e-3 t). Samples [0, i_peak] are the major heating branch,
    [i_peak, i_trough] the major cooling branch.
    """
    half = 0.5 / SAWTOOTH_FREQ_HZ
    n_half = int(round(half / dt))
    t = np.arange(0, (2 * n_periods + 1) * n_half + 1) * dt
    phase = (t / half) % 2.0  # 0..2 per period; starts rising
    tri = np.where(phase <= 1.0, phase, 2.0 - phase)
    amp = np.where(t <= half, 1.0, np.exp(-SAWTOOTH_DECAY_PER_S * (t - half)))
    T = T_min + (T_max - T_min) * tri * amp
    return t, T, n_half, 2 * n_half


def split_output(
    params: SDGPIParams, T: ArrayLike, m: float, *, branch: str = 'cooling'
) -> tuple[FloatArray, FloatArray]:
    """(sum_j p_j w_j, memoryless part with p0 = 1) along a temperature series at fixed load.

    Same recursion as :func:`sma_wrist.core.hysteresis.sdgpi.simulate` (Eqs. 3.19, 3.22, 4.1), with
    the bounds computed for all samples at once; y_m = p0 * second + first.
    """
    T = np.asarray(T, dtype=float)
    lower, upper = play_bounds(params, T, np.full(T.shape, m))
    w = (upper[0] if branch == 'cooling' else lower[0]).copy()
    W = np.empty_like(lower)
    for k in range(T.size):
        w = play_update(w, lower[k], upper[k], out=w)
        W[k] = w
    dT = np.diff(T, prepend=T[0])
    heating = np.empty(T.shape, dtype=bool)
    h = branch == 'heating'
    for k, d in enumerate(dT):  # keeps the last direction while T is constant, like hysteresis.step
        h = True if d > 0 else (False if d < 0 else h)
        heating[k] = h
    mem = memoryless(replace(params, p0=1.0), T, heating)
    return W @ params.weights, mem


def elongation(params: SDGPIParams, T: ArrayLike, m: float, *, mirror: bool = True) -> FloatArray:
    """Elongation [mm]: k_f - y_m with the mirror of Eq. 4.2, y_m without it."""
    s, g = split_output(params, T, m)
    ym = params.p0 * g + s
    return params.k_f - ym if mirror else ym


# ----------------------------------------------------------------------------- loop metrics


@dataclass(frozen=True)
class LoopMetrics:
    """Shape of a major loop (first heating and cooling branch) and the whole run's range."""

    y_min: float  # whole run [mm]
    y_max: float
    stroke_mm: float  # max - min over the major loop
    T_heat50: float  # temperature at the 50 % point of the heating branch [degC] (nan if none)
    T_cool50: float
    area: float  # |closed integral of y dT| over the major loop [mm degC]
    contracts_on_heating: bool
    sma_like: bool

    @property
    def width_C(self) -> float:
        return self.T_heat50 - self.T_cool50


def _crossing(T: FloatArray, y: FloatArray, level: float) -> float:
    """First T where y crosses level (linear interpolation); nan if it never does."""
    s = np.sign(y - level)
    idx = np.nonzero(s[:-1] * s[1:] <= 0)[0]
    if idx.size == 0:
        return float('nan')
    k = idx[0]
    if y[k + 1] == y[k]:
        return float(T[k])
    return float(T[k] + (level - y[k]) * (T[k + 1] - T[k]) / (y[k + 1] - y[k]))


def loop_metrics(T: FloatArray, y: FloatArray, i_peak: int, i_trough: int) -> LoopMetrics:
    """Metrics of the major loop T[0:i_peak] (heating), T[i_peak:i_trough] (cooling)."""
    Th, yh = T[: i_peak + 1], y[: i_peak + 1]
    Tc, yc = T[i_peak : i_trough + 1], y[i_peak : i_trough + 1]
    major = y[: i_trough + 1]
    lo, hi = float(major.min()), float(major.max())
    stroke = hi - lo
    T_h = _crossing(Th, yh, 0.5 * (yh[0] + yh[-1]))
    T_c = _crossing(Tc, yc, 0.5 * (yc[0] + yc[-1]))
    area = abs(float(np.trapezoid(yh, Th) + np.trapezoid(yc, Tc)))
    contracts = bool(yh[-1] < yh[0])
    width = T_h - T_c
    sma = bool(
        contracts
        and np.isfinite(width)
        and width > MIN_HYSTERESIS_WIDTH_C
        and STROKE_RANGE_MM[0] <= stroke <= STROKE_RANGE_MM[1]
    )
    return LoopMetrics(float(y.min()), float(y.max()), stroke, T_h, T_c, area, contracts, sma)


# ----------------------------------------------------------------------------- the survey


@dataclass(frozen=True)
class ConventionResult:
    """One (table row, convention) evaluated on the Sec. 3.2 input."""

    source: str  # 'GPI' (Tables 4.1-4.3) or 'SD-GPI' (Tables 4.5-4.6, m in kg)
    load_g: int
    envelope: str
    p0_label: str  # '1', '0' or 'fitted'
    p0: float
    mirror: bool
    metrics: LoopMetrics
    extra: dict[str, float] = field(default_factory=dict)


def _reference_loop(load_g: int, T: FloatArray) -> FloatArray:
    from sma_wrist.core.hysteresis.default_params import default_sdgpi  # the built-in set: Sec. 3.2 behaviour

    p = default_sdgpi()
    return elongation(p, T, load_g * 1e-3)


def _fit_p0(s: FloatArray, g: FloatArray, ref: FloatArray, k_f: float, mirror: bool) -> float:
    """p0 minimising ||(y - mean y) - (ref - mean ref)||, y = +-(p0 g + s) (+ k_f)."""
    sign = -1.0 if mirror else 1.0
    gc, sc, rc = g - g.mean(), s - s.mean(), ref - ref.mean()
    den = float(gc @ gc)
    return 0.0 if den == 0.0 else float(gc @ (sign * rc - sc)) / den


def evaluate_conventions(
    loads_g: Sequence[int] = st.GPI_LOADS_G,
    *,
    sources: Sequence[str] = ('GPI', 'SD-GPI'),
    envelopes: Sequence[str] = ('literal', 'swapped'),
    p0s: Sequence[float | str] = (1.0, 0.0, 'fitted'),
    mirrors: Sequence[bool] = (True, False),
    dt: float = 0.5,
) -> list[ConventionResult]:
    """Run the Sec. 3.2 sawtooth through every (source, load, convention) and measure the loop."""
    t, T, i_peak, i_trough = sawtooth_input(dt)
    out: list[ConventionResult] = []
    for source in sources:
        for load in loads_g:
            ref = _reference_loop(load, T) if 'fitted' in p0s else None
            for env in envelopes:
                if source == 'GPI':
                    p = gpi_params(load, envelope=env)  # type: ignore[arg-type]
                    m = 0.0
                else:
                    p = sdgpi_section_params(sdgpi_section_for(load), envelope=env)  # type: ignore[arg-type]
                    m = load * 1e-3
                s, g = split_output(p, T, m)
                for mirror in mirrors:
                    for p0 in p0s:
                        p0v = _fit_p0(s, g, ref, p.k_f, mirror) if p0 == 'fitted' else float(p0)  # type: ignore[arg-type]
                        ym = p0v * g + s
                        y = p.k_f - ym if mirror else ym
                        met = loop_metrics(T, y, i_peak, i_trough)
                        extra = {}
                        if ref is not None:
                            e = (y - y.mean()) - (ref - ref.mean())
                            extra['shape_rms_vs_default_mm'] = float(np.sqrt(np.mean(e**2)))
                        out.append(
                            ConventionResult(
                                source, load, env, 'fitted' if p0 == 'fitted' else f'{p0:g}', p0v, mirror, met, extra
                            )
                        )
    return out


def play_part_metrics(load_g: int, envelope: EnvelopeConvention, dt: float = 0.5) -> LoopMetrics:
    """Loop of the play part alone, k_f - sum p_j w_j (p0 = 0, mirrored), for a GPI row."""
    _, T, i_peak, i_trough = sawtooth_input(dt)
    s, _ = split_output(gpi_params(load_g, envelope=envelope), T, 0.0)
    return loop_metrics(T, 6.0 - s, i_peak, i_trough)


def envelope_order_fraction(params: SDGPIParams, m: float = 0.0, T_range: tuple[float, float] = (20.0, 78.0)) -> float:
    """Fraction of [T_min, T_max] where gamma_l <= gamma_r, the ordering Sec. 3.3 states for Eq. 3.19.

    Where it fails the play bounds cross, the clamp returns the upper bound and the operator
    has no memory: the loop closes.
    """
    T = np.linspace(*T_range, 581)
    lower, upper = play_bounds(params, T, np.full(T.shape, m))
    r = params.thresholds[0]
    return float(np.mean((lower[:, 0] + r) <= (upper[:, 0] - r)))


def sdgpi_vs_gpi(
    loads_g: Sequence[int] = st.GPI_LOADS_G, envelope: EnvelopeConvention = 'swapped', dt: float = 0.5
) -> list[dict[str, float]]:
    """Does the SD-GPI (Tables 4.5-4.6, m in kg) reproduce the GPI rows (Tables 4.1-4.3)?

    Per load: RMS difference of the mirrored elongations (p0 = 1) on the Sec. 3.2 input, in mm
    and as % of the GPI row's output range, and the median relative error of a_i, b_i.
    """
    _, T, _, _ = sawtooth_input(dt)
    rows = []
    for load in loads_g:
        y1 = elongation(gpi_params(load, envelope=envelope), T, 0.0)
        y2 = elongation(sdgpi_section_params(sdgpi_section_for(load), envelope=envelope), T, load * 1e-3)
        rms = float(np.sqrt(np.mean((y1 - y2) ** 2)))
        a, b = sdgpi_coefficients(load)
        rel = np.abs(np.concatenate([a, b]) - np.array(st.TABLE_4_1[load])) / np.abs(np.array(st.TABLE_4_1[load]))
        rows.append(
            {
                'load_g': load,
                'rms_mm': rms,
                'rms_pct_of_gpi_range': 100 * rms / max(np.ptp(y1), 1e-12),
                'median_coef_rel_err': float(np.median(rel)),
            }
        )
    return rows


def format_table(results: Sequence[ConventionResult]) -> str:
    head = (
        f'{"source":7s} {"load":>5s} {"envelope":8s} {"p0":>7s} {"mirror":6s} {"y_min":>9s} {"y_max":>9s} '
        f'{"stroke":>8s} {"T_h50":>6s} {"T_c50":>6s} {"width":>6s} {"area":>9s} {"shape_rms":>9s} SMA-like'
    )
    lines = [head]
    for r in results:
        m = r.metrics
        lines.append(
            f'{r.source:7s} {r.load_g:5d} {r.envelope:8s} {r.p0:7.3f} {str(r.mirror):6s} {m.y_min:9.3f} '
            f'{m.y_max:9.3f} {m.stroke_mm:8.3f} {m.T_heat50:6.1f} {m.T_cool50:6.1f} {m.width_C:6.1f} '
            f'{m.area:9.2f} {r.extra.get("shape_rms_vs_default_mm", float("nan")):9.3f} '
            f'{"yes" if m.sma_like else "no"}'
        )
    return '\n'.join(lines)


def main() -> None:
    print(
        'Sec. 3.2 input: decaying sawtooth 4e-3 Hz, 20 degC floor, peak 78 degC decaying exp(-1e-3 t); '
        'major loop = first heating ramp + first cooling ramp.\n'
    )
    res = evaluate_conventions()
    print(format_table(res))
    n_sma = sum(r.metrics.sma_like for r in res)
    print(f'\nSMA-like: {n_sma} of {len(res)} (row, convention) pairs')
    for r in res:
        if r.metrics.sma_like:
            print(f'  {r.source} {r.load_g} g {r.envelope} p0={r.p0:.3f} mirror={r.mirror}')
    print('\nPlay part alone (p0 = 0, mirrored), GPI rows; share of 20-78 degC where gamma_l <= gamma_r:')
    for env in ('literal', 'swapped'):
        for load in st.GPI_LOADS_G:
            m = play_part_metrics(load, env)  # type: ignore[arg-type]
            order = envelope_order_fraction(gpi_params(load, envelope=env))  # type: ignore[arg-type]
            print(
                f'  {env:8s} {load:5d} g  stroke {m.stroke_mm:7.3f} mm  T_h50 {m.T_heat50:6.1f}  '
                f'T_c50 {m.T_cool50:6.1f}  contracts {m.contracts_on_heating}  gamma_l<=gamma_r {100 * order:5.1f} %'
            )
    print('\nTable 4.5 load unit vs Table 4.1 rows:')
    for u in load_unit_test():
        print(
            f'  m in {u["unit"]:3s} order {"reversed" if u["reversed_order"] else "printed "}: median |log10 ratio| '
            f'{u["median_log10_ratio"]:.2f}, same sign {100 * u["same_sign_fraction"]:.0f} %, '
            f'median rel. error {u["median_rel_error"]:.3g}'
        )
    print('\nSD-GPI (Tables 4.5-4.6, kg, swapped, p0=1) vs GPI rows (Tables 4.1-4.3):')
    for row in sdgpi_vs_gpi():
        print(
            f'  {row["load_g"]:5d} g  RMS {row["rms_mm"]:9.3f} mm = {row["rms_pct_of_gpi_range"]:8.1f} % of GPI range; '
            f'median coef rel. error {row["median_coef_rel_err"]:.2f}'
        )


if __name__ == '__main__':
    main()
