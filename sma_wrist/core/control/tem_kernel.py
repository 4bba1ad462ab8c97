"""Compiled per-sample TEM control for one wrist (two layers), optional numba.

tem_controller runs at 100 Hz on one wrist: an observer step of the heat balance, the
linearising law and, at 10 Hz, the predictive command range. On (1, 2, 2) arrays numpy's
per-call overhead is most of the cost (~200 us a sample); these are the same equations as
scalar loops, compiled by numba when it is installed (the plant kernel's set-up, see
:mod:`sma_wrist.core.plant.kernel`), plain Python otherwise. The numpy functions of
:mod:`sma_wrist.core.thermal.heat_balance` and :mod:`sma_wrist.core.control.tem` stay the reference and
the path for N scenarios; :mod:`sma_wrist.core.control.tem` dispatches here for one wrist,
and test_tem_control checks both paths agree.
"""

from __future__ import annotations

import math

import numpy as np

from sma_wrist.core.jit import AVAILABLE, _jit, _jit_inline
from sma_wrist.core.thermal.kernel import thermal_rk4

__all__ = [
    'AVAILABLE',
    'linearising_command',
    'observer_step',
    'observer_step_rows',
    'held_command_range',
    'control_sample',
    'CONFIG_FIELDS',
    'warm_up',
]


@_jit
def observer_step(x, u, dt, th_coef):  # pragma: no cover - compiled
    """RK4 step of Eqs. 4.13-4.14 for faces x (2, 2) [degC] in place under u (2,) [V] held dt [s]."""
    s = np.empty((4, 2, 2))
    thermal_rk4(x, u, dt, th_coef, s[0], s[1], s[2], s[3])


@_jit
def observer_step_rows(x, u, dt, th_coef):  # pragma: no cover - compiled
    """:func:`observer_step` for each wrist j of x (N, 2, 2) in place under u (N, 2) held dt, with its own
    constants th_coef (N, 16) (the online estimate's rows): one call, the same numbers row by row."""
    s = np.empty((4, 2, 2))
    for j in range(x.shape[0]):
        thermal_rk4(x[j], u[j], dt, th_coef[j], s[0], s[1], s[2], s[3])


@_jit
def linearising_command(
    x, T_d, rate, th_coef, gain, h, u_min, u_max, command, face_current, no_root, saturated
):  # pragma: no cover - compiled
    """Eqs. 5.44-5.47 per layer of faces x (2, 2): the smaller root of A I^2 + B I + c = 0 per face
    (the vertex where there is none), weighted by h (2,), as a command [V] clipped to
    [u_min, u_max]. Outputs (written in place): command (2,), face_current (2, 2),
    no_root (2, 2) bool, saturated (2,) bool. Returns False on a non-finite command."""
    ipv = th_coef[0]
    coupling = th_coef[1]
    for l in range(2):
        cur = 0.0
        for f in range(2):
            o = 1 - f
            b0 = 2 + 6 * f  # K_at, K_t, K_Tinf, K_T, K_R, K_inf of this face
            a = th_coef[b0 + 4]
            b = th_coef[b0] * x[l, f] + th_coef[b0 + 1] * x[l, o]
            d = th_coef[b0 + 3] * x[l, o] - th_coef[b0 + 2] * x[l, f] + th_coef[b0 + 5]
            if f == 0 and coupling != 0.0:
                d += coupling * (x[1 - l, 0] - x[l, 0])
            c = d - gain * (T_d[l, f] - x[l, f]) - rate[l, f]
            disc = b * b - 4.0 * a * c
            sgn = 1.0 if b >= 0 else -1.0
            q = -0.5 * (b + sgn * math.sqrt(max(disc, 0.0)))
            if disc >= 0:
                root = c / q if q != 0 else 0.0
                no_root[l, f] = False
            else:
                root = -b / (2.0 * a)
                no_root[l, f] = h[f] != 0
            face_current[l, f] = root
            cur += root * h[f]
        u = -cur / (ipv * th_coef[14 + l])  # this layer's TEM: its own drive gain
        if not math.isfinite(u):
            return False
        clipped = min(max(u, u_min), u_max)
        saturated[l] = clipped != u
        command[l] = clipped
    return True


@_jit
def held_command_range(x, candidates, horizon_s, n_sub, face_min, face_max, th_coef, lo, hi):  # pragma: no cover
    """Per layer, the lowest and highest candidate command [V] that, held for horizon_s from the
    faces x (2, 2) (RK4 in n_sub steps), keeps both faces of the layer in [face_min, face_max];
    where none does, both are the candidate that leaves the window least (first on ties).
    Results in lo, hi (2,)."""
    s = np.empty((5, 2, 2))
    y = s[4]
    u = np.empty(2)
    h = horizon_s / n_sub
    best = np.full(2, np.inf)
    least = np.zeros(2)
    lo[:] = np.inf
    hi[:] = -np.inf
    top = np.empty(2)  # allocated once: two heap allocations per candidate cost more than its bounds
    bottom = np.empty(2)
    for k in range(candidates.size):
        for l in range(2):
            u[l] = candidates[k]
            for f in range(2):
                y[l, f] = x[l, f]
        for l in range(2):
            top[l] = max(y[l, 0], y[l, 1])
            bottom[l] = min(y[l, 0], y[l, 1])
        for _ in range(n_sub):
            thermal_rk4(y, u, h, th_coef, s[0], s[1], s[2], s[3])
            for l in range(2):
                top[l] = max(top[l], y[l, 0], y[l, 1])
                bottom[l] = min(bottom[l], y[l, 0], y[l, 1])
        for l in range(2):
            excess = max(top[l] - face_max, 0.0) + max(face_min - bottom[l], 0.0)
            if excess == 0.0:
                lo[l] = min(lo[l], candidates[k])
                hi[l] = max(hi[l], candidates[k])
            if excess < best[l]:
                best[l] = excess
                least[l] = candidates[k]
    for l in range(2):
        if not math.isfinite(lo[l]):
            lo[l] = least[l]
            hi[l] = least[l]


#: layout of control_sample's ``cfg`` (tem_control.TemLoop packs it once per parameter set)
CONFIG_FIELDS = (
    'gain_per_s',
    'rate_filter_s',
    'h1',
    'h2',
    'law_u_min_V',
    'law_u_max_V',
    'predictive',
    'horizon_s',
    'n_sub',
    'face_min_C',
    'face_max_C',
    'protect_above_C',
    'boost_min_V',
    'boost_max_V',
    'hold_min_V_tem1',
    'hold_min_V_tem2',
    'hold_max_V_tem1',
    'hold_max_V_tem2',
    'max_muscle_C',
)

#: control_sample's return codes; flags bits per layer
OK, BAD_STATE, BAD_TARGET, BAD_COMMAND = 0, 1, 2, 3
SATURATED, LIMITED, HOT = 1, 2, 4


@_jit
def control_sample(
    x, rate, T_d_prev, rng, command, flags, T_meas, T_d, dt_obs, dt_law, has_prev, refresh, th_coef, cfg, candidates
):  # pragma: no cover - compiled
    """:func:`control_sample_into` with its work arrays allocated here (the node's one call per sample)."""
    return control_sample_into(
        x,
        rate,
        T_d_prev,
        rng,
        command,
        flags,
        T_meas,
        T_d,
        dt_obs,
        dt_law,
        has_prev,
        refresh,
        th_coef,
        cfg,
        candidates,
        sample_scratch(),
    )


@_jit_inline
def sample_scratch():  # pragma: no cover - compiled
    """Work arrays of :func:`control_sample_into`: RK4 stages (4, 2, 2), targets (2, 2), law command (2,),
    face currents (2, 2), no-root flags (2, 2), saturation flags (2,)."""
    return (
        np.empty((4, 2, 2)),
        np.empty((2, 2)),
        np.empty(2),
        np.empty((2, 2)),
        np.empty((2, 2), np.bool_),
        np.empty(2, np.bool_),
    )


@_jit_inline
def control_sample_into(
    x,
    rate,
    T_d_prev,
    rng,
    command,
    flags,
    T_meas,
    T_d,
    dt_obs,
    dt_law,
    has_prev,
    refresh,
    th_coef,
    cfg,
    candidates,
    scratch,
):  # pragma: no cover - compiled
    """One tem_controller sample (tem_control.TemLoop.sample) in one call, state in place.

    x (2, 2) observer faces [degC]: stepped dt_obs [s] (if > 0) under ``command`` (2,) [V], the
    command in force, then its muscle faces set to T_meas (2,). rate, T_d_prev (2, 2): the law's
    filtered dT_d/dt and previous target (TemController.estimate_rate; ``has_prev`` False: rate 0),
    dt_law [s] since that target. T_d (2,) muscle targets, also used on the exchanger faces (weight 0).
    rng (2, 2): predictive command range (rows lo, hi), recomputed first if ``refresh``.
    Writes the new command into ``command`` and per-layer bits SATURATED | LIMITED | HOT into flags.
    Returns OK, or BAD_STATE / BAD_TARGET / BAD_COMMAND (non-finite) leaving ``command`` as it was.
    """
    s, Td, u, face, no_root, sat = scratch  # caller-owned: the sweep's bank allocates them once per tick, not per wrist
    if dt_obs > 0:  # observer_step on the scratch stages
        thermal_rk4(x, command, dt_obs, th_coef, s[0], s[1], s[2], s[3])
    for l in range(2):
        x[l, 0] = T_meas[l]
    for l in range(2):
        for f in range(2):
            if not math.isfinite(x[l, f]):
                return BAD_STATE
    for l in range(2):
        if not math.isfinite(T_d[l]):
            return BAD_TARGET
        Td[l, 0] = T_d[l]
        Td[l, 1] = T_d[l]
    for l in range(2):  # Eq. 5.41's dT_d/dt: filtered backward difference
        for f in range(2):
            if has_prev:
                raw = (Td[l, f] - T_d_prev[l, f]) / dt_law
                rate[l, f] = rate[l, f] + dt_law / (cfg[1] + dt_law) * (raw - rate[l, f])
            else:
                rate[l, f] = 0.0
            T_d_prev[l, f] = Td[l, f]
    h = cfg[2:4]
    if not linearising_command(x, Td, rate, th_coef, cfg[0], h, cfg[4], cfg[5], u, face, no_root, sat):
        return BAD_COMMAND
    predictive = cfg[6] != 0.0
    if predictive and refresh:
        held_command_range(x, candidates, cfg[7], int(cfg[8]), cfg[9], cfg[10], th_coef, rng[0], rng[1])
    for l in range(2):  # tem_control.protected_command; each TEM its own hold limits within the driver rating
        hold_lo, hold_hi = max(cfg[14 + l], cfg[12]), min(cfg[16 + l], cfg[13])
        if predictive:
            v = min(max(u[l], rng[0, l]), rng[1, l])
            if not (cfg[9] <= x[l, 0] <= cfg[10] and cfg[9] <= x[l, 1] <= cfg[10]):
                v = min(max(v, hold_lo), hold_hi)
        elif x[l, 0] > cfg[11] or x[l, 1] > cfg[11]:
            v = min(max(u[l], hold_lo), hold_hi)
        else:
            v = min(max(u[l], cfg[12]), cfg[13])
        bits = SATURATED if sat[l] else 0
        if v != u[l]:
            bits |= LIMITED
        if T_meas[l] > cfg[18]:  # too hot a muscle may only be cooled
            bits |= HOT
            v = min(v, 0.0)
        command[l] = v
        flags[l] = bits
    return OK


def warm_up() -> None:
    """Compile (or load from numba's cache) every kernel here on dummy data.

    A node calls this before it spins: a cold numba cache costs seconds on the first call, which
    in a running loop would look like a stalled controller to the plant's watchdog.
    """
    if not AVAILABLE:
        return
    from sma_wrist.core.thermal.heat_balance import ThermalParams
    from sma_wrist.core.thermal.kernel import thermal_constants

    coef = thermal_constants(ThermalParams())
    x, two = np.full((2, 2), 30.0), np.zeros(2)
    observer_step(x, two, 0.01, coef)
    linearising_command(
        x,
        x,
        np.zeros((2, 2)),
        coef,
        1.0,
        np.array([1.0, 0.0]),
        -1.0,
        1.0,
        two.copy(),
        np.empty((2, 2)),
        np.empty((2, 2), np.bool_),
        np.empty(2, np.bool_),
    )
    held_command_range(x, np.linspace(-1.0, 1.0, 3), 1.0, 1, 0.0, 80.0, coef, two.copy(), two.copy())
    cfg = np.zeros(len(CONFIG_FIELDS))
    cfg[[0, 2, 5, 7, 8, 10]] = 1.0
    control_sample(
        x,
        np.zeros((2, 2)),
        np.zeros((2, 2)),
        np.zeros((2, 2)),
        two.copy(),
        np.zeros(2, np.int64),
        two + 30.0,
        two + 30.0,
        0.01,
        0.01,
        True,
        True,
        coef,
        cfg,
        np.linspace(-1.0, 1.0, 3),
    )
