"""The chain's pre-load elongation e0 for a given wire (Sec. 2.2.3; doc/explanation/model.md).

The chain (Eq. 4.17) stretches both bundles to e0 at q_neutral: y_1 = e0 - x, y_2 = e0 + x. e0 decides
where the pair can hold the joint: a larger e0 pulls both wires harder, so the hot muscle lifts a
heavier payload to the top of the range but both wires carry more stress. The built-in 1.98 mm was
calibrated so that +-30 deg about q_neutral is reachable quasi-statically up to ~0.7 kg in the
TEM-reachable temperature window. :func:`calibrate_preload` applies the same calibration to any SD-GPI
set: the smallest e0 with which slow antagonistic swings between the window's ends reach the whole
target range at every payload of the given range (the lightest reaches least far down, the heaviest
least far up), found by scans of the plant itself (all candidates of a scan in one batched run).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from sma_wrist.core.errors import ParameterError
from sma_wrist.core.plant.wrist import PlantParams, WristPlant
from sma_wrist.core.thermal import heat_balance as th

#: target range of Sec. 6.1: q_d = q_neutral +- 30 deg [rad]
TARGET_HALF_RANGE_RAD = math.radians(30.0)
#: payloads [kg] at whose ends :func:`calibrate_preload` asks for the whole target range (the built-in pre-load's
#: design point, doc/explanation/model.md). Not the payloads the nodes accept (sma_wrist.contract.PAYLOAD_RANGE_KG, 0-1.5 kg):
#: no pre-load reaches the range at 1.5 kg, and the smallest that reaches it at 0.7 kg still does to ~1.3 kg in the
#: controllers' 20-80 degC window (doc/explanation/model.md)
CALIBRATION_PAYLOAD_KG = (0.0, 0.7)


def reachable_window(
    thermal: th.ThermalParams, controllers_C: tuple[float, float] | None = None
) -> tuple[float, float]:
    """(coldest, hottest) muscle temperature [degC] the TEMs hold at their command limits (steady states of
    Eqs. 4.13-4.14 at each TEM's hold limits, ThermalParams.layer_hold_limits; where the TEMs differ, what both
    hold), inside ``controllers_C`` (the window the controllers may ask for)."""
    ss, _ = th.steady_state(thermal, np.stack(thermal.layer_hold_limits()))
    cold, hot = float(ss[0, :, 0].max()), float(ss[1, :, 0].min())
    if controllers_C is not None:
        cold, hot = max(cold, float(controllers_C[0])), min(hot, float(controllers_C[1]))
    return cold, hot


def swing_range(
    params: PlantParams,
    payload_kg: np.ndarray,
    T_lo_C: float,
    T_hi_C: float,
    period_s: float = 60.0,
    dt: float = 1e-2,
    cycles: float = 1.5,
) -> tuple[np.ndarray, np.ndarray]:
    """(q_min, q_max) [rad] per payload after the first half cycle of slow antagonistic temperature swings.

    Muscle temperatures prescribed (no thermal model): T_1 from T_lo_C to T_hi_C and back as a raised
    cosine of ``period_s``, T_2 in antiphase; loads and joint by the plant's step (Eqs. 4.4-4.6, 4.17-4.18).
    """
    plant = WristPlant(dataclasses.replace(params, dt=dt), payload_kg=payload_kg)
    q_min = np.full(plant.n, np.inf)
    q_max = np.full(plant.n, -np.inf)
    T = np.empty((plant.n, 2))
    for k in range(round(cycles * period_s / dt)):
        t = (k + 1) * dt
        ph = 0.5 * (1.0 - math.cos(2.0 * math.pi * t / period_s))
        T[:, 0] = T_lo_C + (T_hi_C - T_lo_C) * ph
        T[:, 1] = T_lo_C + (T_hi_C - T_lo_C) * (1.0 - ph)
        q = plant.step_mechanics(T).q
        if t > 0.5 * period_s:  # after the first half cycle: the memory no longer remembers the rest state
            np.minimum(q_min, q, out=q_min)
            np.maximum(q_max, q, out=q_max)
    return q_min, q_max


def reach_margins(
    params: PlantParams, preload_mm: np.ndarray, window_C: tuple[float, float], payload_kg: tuple[float, float]
) -> tuple[np.ndarray, np.ndarray]:
    """(down, up) [rad] per pre-load in ``preload_mm``: how far the lightest payload swings below
    q_neutral - 30 deg and the heaviest above q_neutral + 30 deg (:func:`swing_range`; >= 0: reached).

    All pre-loads in one batched plant: the chain's e0 per scenario, which the numpy path broadcasts
    (the compiled kernel takes one e0).
    A 10 s period is still quasi-static for the mechanics: within 3e-4 rad of 60 s on the built-in set
    (0.01 mm of pre-load moves the top by ~4e-3 rad).
    """
    e0 = np.asarray(preload_mm, dtype=float)
    q_n = params.joint.q_neutral_rad
    p = dataclasses.replace(params, preload_elongation_mm=np.repeat(e0, 2), engine='numpy')  # type: ignore[arg-type]
    q_min, q_max = swing_range(p, np.tile(np.asarray(payload_kg, dtype=float), e0.size), *window_C, period_s=10.0)
    return (q_n - TARGET_HALF_RANGE_RAD) - q_min[0::2], q_max[1::2] - (q_n + TARGET_HALF_RANGE_RAD)


def calibrate_preload(
    params: PlantParams,
    window_C: tuple[float, float],
    payload_kg: tuple[float, float] = CALIBRATION_PAYLOAD_KG,
    bracket_mm: tuple[float, float] = (0.5, 4.0),
    step_mm: float = 0.25,
    tolerance_mm: float = 0.01,
) -> float:
    """Pre-load elongation e0 [mm] (Eq. 4.17) for ``params.hysteresis`` in the temperature window ``window_C`` [degC].

    The smallest e0 in ``bracket_mm`` with which q_neutral +- 30 deg is reachable quasi-statically
    (:func:`reach_margins`) at both ends of ``payload_kg``: the heaviest payload must reach the top, the
    lightest the bottom. The top is not monotonic in e0 (a pair pulled too tight hardly moves), so a scan
    in ``step_mm`` finds the first e0 that reaches it and scans 5x finer below it refine to ``tolerance_mm``; raises :class:`~sma_wrist.core.errors.ParameterError`, naming what is missing, when no e0 reaches the range.
    """
    lo_C, hi_C = (float(v) for v in window_C)
    m_lo, m_hi = (float(v) for v in payload_kg)
    a, b = (float(v) for v in bracket_mm)
    if not (
        np.isfinite([lo_C, hi_C, m_lo, m_hi, a, b, step_mm, tolerance_mm]).all()
        and lo_C < hi_C
        and 0.0 <= m_lo <= m_hi <= 2.0
        and 0.0 < a < b
        and 0.0 < tolerance_mm <= step_mm
    ):
        raise ParameterError(
            'pre-load calibration needs a window lo < hi [degC], payloads 0 <= lo <= hi <= 2 kg, '
            f'a bracket 0 < lo < hi [mm] and 0 < tolerance <= step; got {window_C!r}, {payload_kg!r}, '
            f'{bracket_mm!r}, {tolerance_mm!r}, {step_mm!r}'
        )
    q_n = params.joint.q_neutral_rad
    q_low, q_high = q_n - TARGET_HALF_RANGE_RAD, q_n + TARGET_HALF_RANGE_RAD
    coarse = np.arange(a, b + 0.5 * step_mm, step_mm)
    down, up = reach_margins(params, coarse, (lo_C, hi_C), (m_lo, m_hi))
    hit = np.flatnonzero(up >= 0.0)
    if hit.size == 0:
        raise ParameterError(
            f'{params.hysteresis.name}: no pre-load of {a:g}-{b:g} mm lifts {m_hi:g} kg to '
            f'{q_high:.3f} rad with the muscles at {lo_C:.1f}-{hi_C:.1f} degC (best '
            f'{q_high + up.max():.3f} rad at {coarse[up.argmax()]:.2f} mm): a lighter payload or a '
            'hotter window is needed'
        )
    e0, down_e0 = float(coarse[hit[0]]), float(down[hit[0]])
    step = step_mm
    while hit[0] > 0 and step > tolerance_mm * 1.001:
        # e0 - step did not reach: try the points between at a 5x finer step (one batched run a pass)
        fine_step = max(step / 5.0, tolerance_mm)
        fine = e0 - step + fine_step * np.arange(1, round(step / fine_step))
        step = fine_step
        down, up = reach_margins(params, fine, (lo_C, hi_C), (m_lo, m_hi))
        ok = np.flatnonzero(up >= 0.0)
        if ok.size:
            e0, down_e0 = float(fine[ok[0]]), float(down[ok[0]])
    if down_e0 < 0.0:
        raise ParameterError(
            f'{params.hysteresis.name}: with the {e0:.2f} mm pre-load that lifts {m_hi:g} kg to '
            f'{q_high:.3f} rad, {m_lo:g} kg reaches down only to {q_low - down_e0:.3f} rad '
            f'(target {q_low:.3f}) in {lo_C:.1f}-{hi_C:.1f} degC: no pre-load reaches the whole range'
        )
    return round(e0, 3)
