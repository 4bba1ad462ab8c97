"""Inverse compensation in the wrist's own coordinates: bundle strain + wire stress -> temperature.

The back-stepping law asks each muscle for a force at the elongation the chain gives it
(Eq. 5.32 with Eq. 4.17); :class:`sma_wrist.core.hysteresis.inverse.InverseCompensator` works in the
SD-GPI's coordinates (elongation of the 80 mm model wire, per-wire load). The muscle model
(:mod:`sma_wrist.core.hysteresis.muscle`, Eq. 1 there) links them::

    y_bundle = (L_wire / L_model) y_SDGPI(T, m) + c_el m,     m = sigma A / g,   y_bundle = eps L_wire

so the SD-GPI target is y_SDGPI = (eps L_wire - c_el m) / (L_wire / L_model). Loads outside
the SD-GPI's calibrated range are clipped to it and reported (the inverse is undefined there).

Temperature-axis adaptation (doc/explanation/controllers.md). The inverse is
a feed-forward at the desired strain: any difference between the SD-GPI and the wire
(transition temperatures, stroke, the heat balance behind the measured temperature) goes
straight to the joint. :meth:`MuscleCompensator.track` brings the measured angle in: each
bundle's strain is measured through the chain (Eq. 4.17, measured angle); the SD-GPI, observed
at T_measured - shift, predicts it; the shift follows the prediction error along the model's
own temperature slope (a normalised gradient step, ``shift_gain_per_s``), so the memory and the
inverse work on the temperature axis that explains the wire, and the answer is shifted back,
T_d = T_inv + shift. Where the model's loop is flat (inside the hysteresis gap) its slope is ~0
and the shift holds. Each wire has its own shift: the common mode, which the angle alone
cannot see (both wires move it the same way), is seen by each wire's strain prediction.

Stroke adaptation (doc/explanation/controllers.md): a wire whose
transformation strain differs from the model's (stroke x s about the mid-stroke elongation y_mid,
the way the family's plants differ, ``plants.spread.perturbed_hysteresis``) is predicted as
y = y_mid + k (y_SDGPI(T - shift) - y_mid); k follows the same prediction error where the shift
cannot (on the loop's flat ends, where a stroke error shows whole), and the inverse is asked for
y_mid + (y_target - y_mid) / k.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sma_wrist.core import jit as _jm
from sma_wrist.core.errors import ParameterError, check_finite
from sma_wrist.core.hysteresis import kernel as _hk
from sma_wrist.core.hysteresis.inverse import InverseCompensator, _output_frozen, _residual
from sma_wrist.core.hysteresis.muscle import G, MuscleGeometry
from sma_wrist.core.hysteresis.sdgpi import SDGPIParams, initial_state, mirrored_output

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class CompensationResult:
    temperature_C: FloatArray  # desired muscle temperatures
    saturated: NDArray[np.bool_]  # target unreachable inside the temperature window
    load_clipped: NDArray[np.bool_]  # requested load outside the SD-GPI's calibrated range
    load_kgf: FloatArray  # per-wire load used (after clipping)
    sdgpi_elongation_mm: FloatArray  # target handed to the inverse


class MuscleCompensator:
    """Desired temperature of each muscle from its desired strain and wire stress (Eqs. 5.5-5.8)."""

    def __init__(
        self,
        params: SDGPIParams,
        geometry: MuscleGeometry | None = None,
        T_range_C: tuple[float, float] = (20.0, 80.0),
        method: str = 'numerical',
        shift_gain_per_s: float = 0.0,
        shift_limit_C: float = 15.0,
        window_follows_shift: bool = False,
        stroke_gain_per_s: float = 0.0,
        stroke_limits: tuple[float, float] = (0.5, 2.0),
        hold_outside_load_range: bool = False,
    ) -> None:
        self.params = params
        self.T_range_C = T_range_C
        if not (math.isfinite(shift_gain_per_s) and shift_gain_per_s >= 0):
            raise ParameterError(f'shift_gain_per_s = {shift_gain_per_s!r} must be >= 0')
        if not (math.isfinite(shift_limit_C) and shift_limit_C >= 0):
            raise ParameterError(f'shift_limit_C = {shift_limit_C!r} must be >= 0')
        self.shift_gain_per_s = float(shift_gain_per_s)
        self.shift_limit_C = float(shift_limit_C)
        if not (math.isfinite(stroke_gain_per_s) and stroke_gain_per_s >= 0):
            raise ParameterError(f'stroke_gain_per_s = {stroke_gain_per_s!r} must be >= 0')
        k_lo, k_hi = (float(x) for x in stroke_limits)
        if not (0 < k_lo <= 1 <= k_hi and math.isfinite(k_hi)):
            raise ParameterError(f'stroke_limits = {stroke_limits!r} must be (lo, hi) with 0 < lo <= 1 <= hi')
        #: rate [1/s] at which each wire's stroke ratio follows the strain prediction error (0: off)
        self.stroke_gain_per_s, self.stroke_limits = float(stroke_gain_per_s), (k_lo, k_hi)
        #: :meth:`track` holds a wrist's shifts (and strokes) while either of its wires' measured load lies
        #: outside the SD-GPI's calibrated range (:meth:`pair_in_load_range`); off by default since the shift's
        #: slope is kept <= 0: it had stood in for that fix, and it kept a measured wire from adapting at all
        #: (doc/explanation/controllers.md)
        self.hold_outside_load_range = bool(hold_outside_load_range)
        #: per wire: the wire's stroke over the model's, about y_mid_mm
        self.stroke = np.ones(2)
        #: per wire: (cold, hot) edge of the window reached since reset; the stroke adapts once both
        #: are (the memory is then wiped of its unknown starting state, which would read as a stroke error)
        self._seen = np.zeros((2, 2), np.bool_)
        # the model's mid-stroke elongation: mean of the cold (cooled) and hot (heated) major-loop ends
        # at the adaptive law's default pre-load per wire
        lo, hi = T_range_C
        cold = initial_state(params, lo, MID_LOAD_KGF, branch='cooling')
        hot = initial_state(params, hi, MID_LOAD_KGF, branch='heating')
        self.y_mid_mm = params.k_f - 0.5 * float(
            mirrored_output(params, cold, lo)[0] + mirrored_output(params, hot, hi)[0]
        )
        #: the inverse searches [lo, hi] - shift on the model's axis, so its answer on the wire's axis
        #: spans the whole window [lo, hi] (else a wire colder than the model never gets above hi - |shift|)
        self.window_follows_shift = bool(window_follows_shift)
        #: per wire: the wire's temperature minus the model's that explains its strain [degC]
        self.shift_C = np.zeros(2)  # the node's two wires; reset() sizes it to its wires
        self.geometry = geometry or MuscleGeometry()
        self.inverse = InverseCompensator(params, T_range=T_range_C, method=method)
        g = self.geometry
        # the geometry's properties as floats, read once (they are recomputed on every access)
        self._area_m2, self._wire_mm = g.wire_area_m2, float(g.wire_length_mm)
        self._c_el, self._scale = g.elastic_mm_per_kgf, g.length_scale
        self._load_range = params.load_range

    def reset(self, T0_C: ArrayLike, stress_Pa: ArrayLike, branch: str = 'cooling') -> None:
        """Start the inverse's memory at measured temperatures and stresses."""
        m = self._load(np.asarray(stress_Pa, float))[0]
        self.inverse.reset(np.asarray(T0_C, float), m, branch=branch)
        self.shift_C = np.zeros(np.shape(m))
        self.stroke = np.ones(np.shape(m))
        self._seen = np.zeros((2,) + np.shape(m), np.bool_)

    def observe(self, T_C: ArrayLike, stress_Pa: ArrayLike) -> None:
        """Advance the memory with measured temperatures and stresses (InverseCompensator.observe)."""
        sigma = np.asarray(stress_Pa, float)
        _check_finite('measured stress', sigma, 'Pa')
        # the load unclipped: observe clips it to the same range itself
        m = np.array(self._kgf(sigma))
        self.inverse.observe(np.asarray(T_C, float), m.reshape(sigma.shape) if sigma.ndim != 1 else m)

    def _kgf(self, stress_Pa: FloatArray) -> list[float] | FloatArray:
        """MuscleGeometry.load_kgf, m = sigma A / g, on the flattened stresses as Python floats: on
        the node's two wires a fraction of the numpy calls on (2,) arrays, the same IEEE operations.
        On many wires (the sweep's bank) the same expression on the flat array, element by element."""
        area = self._area_m2
        if stress_Pa.size > FLOAT_BY_FLOAT_MAX:
            return stress_Pa.ravel() * area / G
        return [s * area / G for s in stress_Pa.ravel().tolist()]

    def _load(self, stress_Pa: FloatArray) -> tuple[FloatArray, NDArray[np.bool_]]:
        """(per-wire load clipped to the SD-GPI's range, clipped flags), shaped as stress_Pa."""
        lo, hi = self._load_range
        m = self._kgf(stress_Pa)
        if stress_Pa.size > FLOAT_BY_FLOAT_MAX:  # min(max(x, lo), hi) and the range test on the array
            m_a = np.asarray(m)
            return np.minimum(np.maximum(m_a, lo), hi).reshape(stress_Pa.shape), ((m_a < lo) | (m_a > hi)).reshape(
                stress_Pa.shape
            )
        m_c, out = np.array([min(max(x, lo), hi) for x in m]), np.array([x < lo or x > hi for x in m], np.bool_)
        if stress_Pa.ndim != 1:
            m_c, out = m_c.reshape(stress_Pa.shape), out.reshape(stress_Pa.shape)
        return m_c, out

    def _target(self, eps: float, m: float) -> float:
        """SD-GPI elongation for bundle strain eps at load m: y = (eps L_wire - c_el m) / (L_wire / L_model)."""
        return (eps * self._wire_mm - self._c_el * m) / self._scale

    def __call__(self, strain: ArrayLike, stress_Pa: ArrayLike, *, commit: bool = True) -> CompensationResult:
        """Desired temperatures; ``commit`` advances the memory to them (Eq. 5.5), else :meth:`observe` does."""
        eps = np.asarray(strain, float)
        sigma = np.asarray(stress_Pa, float)
        _check_finite('desired strain', eps)
        _check_finite('desired stress', sigma, 'Pa')
        m, clipped = self._load(sigma)
        if eps.shape == m.shape and eps.size <= FLOAT_BY_FLOAT_MAX:  # the node's call: float by float (see _load)
            y = np.array([self._target(e, x) for e, x in zip(eps.ravel().tolist(), m.ravel().tolist())])
            y = y.reshape(eps.shape) if eps.ndim != 1 else y
        else:  # broadcast shapes: the same expression on arrays
            y = self._target(eps, m)  # type: ignore[arg-type]
        if self.stroke_gain_per_s:  # the model's elongation whose stroke-scaled value is the target
            c = self.y_mid_mm
            y = c + (y - c) / np.broadcast_to(self.stroke, np.shape(y))
        window = None
        if self.shift_gain_per_s and self.window_follows_shift:
            # inside the model's validity: |shift| <= shift_limit_C, the window's edges 1 degC apart at least
            lo, hi = self.T_range_C
            v_lo, v_hi = self.params.T_valid
            # float by float (see _load): numpy's per-call cost on the node's (2,) arrays tripled this call's
            if y.size > FLOAT_BY_FLOAT_MAX:  # the same on the sweep's bank of wires, as arrays
                shift_a = np.broadcast_to(self.shift_C, y.shape)
                window = (
                    np.minimum(np.maximum(lo - shift_a, v_lo), v_hi - 1.0),
                    np.minimum(np.maximum(hi - shift_a, v_lo + 1.0), v_hi),
                )
            else:
                shift = np.broadcast_to(self.shift_C, y.shape).ravel().tolist()
                window = (
                    np.array([min(max(lo - x, v_lo), v_hi - 1.0) for x in shift]).reshape(y.shape),
                    np.array([min(max(hi - x, v_lo + 1.0), v_hi) for x in shift]).reshape(y.shape),
                )
        res = self.inverse.solve(y, m, commit=commit, window=window)
        T = res.T if not self.shift_gain_per_s else self.clip_T(res.T + self.shift_C)
        return CompensationResult(T, res.saturated, clipped, m, y)

    def track(
        self,
        T_C: ArrayLike,
        stress_Pa: ArrayLike,
        strain_measured: ArrayLike,
        dt: float,
        adapt: ArrayLike | None = None,
    ) -> None:
        """:meth:`observe` on the adapted temperature axis, then one adaptation step of the shift
        (module docstring) from the bundles' strains at the measured angle (2,) over dt [s]. Without
        adaptation (``shift_gain_per_s`` 0) the same as observe. ``adapt`` (bool, shaped like the
        temperatures): where False that wire's shift and stroke hold (:func:`strain_informative`); with
        ``hold_outside_load_range`` they also hold where :meth:`pair_in_load_range` is False.

        Step: shift += gain dt (y_model - y_meas) s / (s^2 + s_0^2), s = dy_model/dT [mm/degC] of the
        loop the memory is on (central difference, heating up / cooling down), y in the SD-GPI's
        coordinates (``_target``), s_0 = SLOPE_FLOOR_MM_PER_C; clipped to +-shift_limit_C.
        A model predicting a longer wire than measured is too cold: its axis moves up.
        s is taken as min(s, 0): heating never lengthens the model's wire along its loop, but inside the
        loop the central difference spans both branches' memoryless parts (Eq. 3.22, c set at T + h, d set
        at T - h) and reads up to ~+0.001 mm/degC. Times a large prediction error (a wire that transformed
        where the model's loop is flat: 1.6 mm on a family plant) that sign drove the shift the wrong way
        at ~1 degC/s, to its limit, and the pair locked against each other (doc/explanation/
        controllers.md).

        With ``stroke_gain_per_s`` k > 0 (module docstring): the prediction is y_mid + k (y_model - y_mid),
        the shift's slope k s, and, once the wire has been within STROKE_EDGE_C of both window edges,
        k -= gain_k dt (y_pred - y_meas) d / (d^2 + d_0^2) s_0^2 / ((k s)^2 + s_0^2), d = y_model - y_mid,
        d_0 = STROKE_FLOOR_MM: a gradient step on the loop's flat ends, where the shift's is ~0;
        clipped to ``stroke_limits``."""
        T = np.asarray(T_C, float)
        self.observe(T - self.shift_C, stress_Pa)
        if self.shift_gain_per_s <= 0.0:
            return
        sigma = np.asarray(stress_Pa, float)
        m, out = self._load(sigma)  # once: the gate and the step both need it
        if self.hold_outside_load_range:
            taut = _pair_taut(out)
            if not taut.all():
                adapt = taut if adapt is None else np.asarray(adapt, bool) & taut
        if adapt is None:
            self._adapt(T, m, strain_measured, dt)
            return
        held = ~np.asarray(adapt, bool)
        shift, stroke = self.shift_C, self.stroke
        self._adapt(T, m, strain_measured, dt)
        self.shift_C = np.where(held, shift, self.shift_C)
        self.stroke = np.where(held, stroke, self.stroke)

    def pair_in_load_range(self, stress_Pa: ArrayLike) -> NDArray[np.bool_]:
        """Per wire (shaped like ``stress_Pa``, wires in pairs: (2,), (N, 2) or (2N,) flat): whether both wires
        of its wrist carry a measured load inside the SD-GPI's calibrated range (``load_range``).

        Outside it the strain at the measured angle is not the model's to explain: a slack wire's (0 Pa)
        is the chain's, not the wire's, and the model is extrapolated there (the plant clamps its
        envelopes, Eq. 4.4-4.5). On the measured Flexinol wire the pair runs below 50 MPa most of the
        time, and each wire's shift fitted there ran to its limit within seconds (doc/explanation/
        controllers.md). The partner counts too: a slack antagonist leaves the
        other wire carrying the payload alone, off the operating point the pre-load sets."""
        return _pair_taut(self._load(np.asarray(stress_Pa, float))[1])

    def _adapt(self, T: FloatArray, m: FloatArray, strain_measured: ArrayLike, dt: float) -> None:
        """The adaptation step of :meth:`track` on every wire (m: the loads clipped to the range [kgf])."""
        k_dt = self.stroke_gain_per_s * dt
        if k_dt:
            lo, hi = self.T_range_C
            self._seen |= np.stack([T <= lo + STROKE_EDGE_C, T >= hi - STROKE_EDGE_C])
        inv = self.inverse
        st = inv.state
        assert st is not None
        eps = np.asarray(strain_measured, float)
        y_meas = self._target(eps, m)  # type: ignore[arg-type]  # the same expression on arrays
        if _jm.AVAILABLE and st.T_prev.ndim == 1 and eps.shape == st.T_prev.shape:
            # the node's call at 100 Hz: ~1 ms of numpy on (3, 2) arrays -> a few us
            shift = self.shift_C.astype(float)  # a copy: the kernel writes it
            # without stroke adaptation the kernel neither reads the flags nor writes the stroke: no copies
            stroke, on = (self.stroke.astype(float), self._seen.all(axis=0)) if k_dt else (self.stroke, self._seen[0])
            _track_step(
                st.T_prev,
                st.heating,
                st.w,
                m,
                y_meas,
                shift,
                self.shift_gain_per_s * dt,
                SLOPE_STEP_C,
                SLOPE_FLOOR_MM_PER_C**2,
                self.shift_limit_C,
                stroke,
                on,
                k_dt,
                self.y_mid_mm,
                STROKE_FLOOR_MM**2,
                *self.stroke_limits,
                *inv._kernel_params,
            )
            self.shift_C, self.stroke = shift, stroke
            return
        h = SLOPE_STEP_C
        up, down = np.ones_like(st.heating), np.zeros_like(st.heating)
        y = _output_frozen(
            self.params,
            st.w,
            st.T_prev + np.array([0.0, h, -h]).reshape((3,) + (1,) * st.T_prev.ndim),
            m,
            np.stack([st.heating, up, down]),
        )
        # mm/degC of the loop the wire is on, ~0 inside the gap; never > 0 (track's docstring)
        slope = np.minimum((y[1] - y[2]) / (2.0 * h), 0.0)
        f2 = SLOPE_FLOOR_MM_PER_C**2
        err = y[0] - y_meas
        if k_dt:
            k, d = self.stroke, y[0] - self.y_mid_mm
            err, slope = self.y_mid_mm + k * d - y_meas, k * slope
            dk = k_dt * err * d / (d * d + STROKE_FLOOR_MM**2) * f2 / (slope * slope + f2)
            self.stroke = np.clip(k - np.where(self._seen.all(axis=0), dk, 0.0), *self.stroke_limits)
        step = self.shift_gain_per_s * dt * err * slope / (slope * slope + f2)
        self.shift_C = np.clip(self.shift_C + step, -self.shift_limit_C, self.shift_limit_C)

    def clip_T(self, temperature_C: FloatArray) -> FloatArray:
        """Temperatures clipped to the compensator's window [degC]."""
        lo, hi = self.T_range_C
        return np.minimum(np.maximum(temperature_C, lo), hi)


def _pair_taut(outside: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """Per wire, shaped like ``outside`` (wires in pairs): neither wire of its wrist outside the load range."""
    out = outside.reshape(-1, 2).any(axis=1)
    return np.repeat(~out, 2).reshape(outside.shape)


def strain_informative(
    q_rad: ArrayLike,
    q_prev_rad: ArrayLike,
    dt: float,
    stress_Pa: ArrayLike,
    q_stops_rad: tuple[float, float],
    slack_Pa: float = 1e6,
    still_rad_s: float = 0.05,
) -> NDArray[np.bool_]:
    """(N, 2) whether the bundles' strains at the measured angle (Eq. 4.17) say something about the wires
    (doc/explanation/controllers.md): not while the joint rests on a mechanical stop
    (measured angle q_rad (N,) at or over ``q_stops_rad``), nor while it stands still (|q - q_prev| / dt
    below ``still_rad_s``) with a wire slack (measured stress (N, 2) [Pa] below ``slack_Pa``): there the
    angle is the stop's or the other wire's, and a shift fitted to it winds up (both wires then pull
    against each other). Both wires of a wrist hold together."""
    q = np.asarray(q_rad, float)
    on_stop = (q <= q_stops_rad[0]) | (q >= q_stops_rad[1])
    still = np.abs(q - np.asarray(q_prev_rad, float)) < still_rad_s * dt
    slack = (np.asarray(stress_Pa, float) < slack_Pa).any(axis=-1)
    return np.repeat(~(on_stop | (still & slack))[..., None], 2, axis=-1)


#: temperature step of the model's loop slope in :meth:`MuscleCompensator.track` [degC]
SLOPE_STEP_C = 0.5
#: slope below which the shift adapts ever more slowly (the flat inside of the loop) [mm/degC]
SLOPE_FLOOR_MM_PER_C = 0.05
#: distance of the model's output from y_mid below which the stroke adapts ever more slowly [mm]
#: (the model's stroke is ~3.6 mm: its ends lie ~1.8 mm from y_mid)
STROKE_FLOOR_MM = 0.3
#: the stroke adapts once a wire has been this close to both edges of the window [degC]
STROKE_EDGE_C = 15.0
#: per-wire load at which y_mid is taken [kgf]: the adaptive law's default pre-load (AdaptiveParams)
MID_LOAD_KGF = 0.775


@_jm._jit
def _track_step(
    T_prev,
    heating,
    w,
    m,
    y_meas,
    shift,
    gain_dt,
    h,
    floor2,
    limit,
    stroke,
    stroke_on,
    gain_k_dt,
    y_mid,
    floor_k2,
    k_lo,
    k_hi,
    stacked,
    edges,
    r,
    wts,
    c,
    d,
    p0,
    k_f,
):  # pragma: no cover - compiled
    """Compiled adaptation step of :meth:`MuscleCompensator.track`, wire by wire, on shift (S,) and stroke (S,)
    in place: the SD-GPI output (Eqs. 3.19, 3.22, 4.1-4.5, :func:`~sma_wrist.core.hysteresis.inverse._residual`
    against the frozen memory) at T_prev in the memory's direction and at T_prev +- h heating / cooling, then
    shift += gain_dt (y - y_meas) s / (s^2 + floor2), s = min((y(+h) - y(-h)) / 2h, 0), clipped to +-limit; with
    gain_k_dt > 0 the stroke step of the method's docstring first (where stroke_on)."""
    for s in range(T_prev.shape[0]):
        coef, _ = _hk._envelopes(stacked, edges, m[s])
        T0 = T_prev[s]
        y0 = _residual(T0, np.nan, heating[s], heating[s], coef, w[s], 0.0, r, wts, c, d, p0, k_f)
        y_up = _residual(T0 + h, np.nan, True, True, coef, w[s], 0.0, r, wts, c, d, p0, k_f)
        y_down = _residual(T0 - h, np.nan, False, False, coef, w[s], 0.0, r, wts, c, d, p0, k_f)
        slope = min((y_up - y_down) / (2.0 * h), 0.0)
        err = y0 - y_meas[s]
        if gain_k_dt != 0.0:
            k = stroke[s]
            dev = y0 - y_mid
            err = y_mid + k * dev - y_meas[s]
            slope = k * slope
            if stroke_on[s]:
                k = k - gain_k_dt * err * dev / (dev * dev + floor_k2) * floor2 / (slope * slope + floor2)
                stroke[s] = min(max(k, k_lo), k_hi)
        x = shift[s] + gain_dt * err * slope / (slope * slope + floor2)
        shift[s] = min(max(x, -limit), limit)


#: arrays up to this size (the node's two wires) are converted float by float (numpy's per-call cost
#: dominates there); larger ones (the sweep's bank of wires) stay arrays: the same IEEE operations
FLOAT_BY_FLOAT_MAX = 8


def _check_finite(name: str, x: FloatArray, unit: str = '') -> None:
    """check_finite for a float array: a few float tests on the node's (2,) arrays (np.isfinite
    costs more than the rest of the conversion), check_finite's message on a bad value."""
    if x.size > FLOAT_BY_FLOAT_MAX or not all(map(math.isfinite, x.ravel().tolist())):
        check_finite(name, x, unit)


__all__ = ['MuscleCompensator', 'CompensationResult']
