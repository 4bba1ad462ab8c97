"""Idle-muscle pre-heat of the pid mode: cross the hysteresis gap before the reference turns.

Why (issue 14 item 2, docs/control.md "PID on the phase-fraction wrist"): a muscle that has been
lengthening (the idle one, its temperature request T_mid - |u| below the band's centre) cools
toward the cold end of its window. When the reference turns it becomes the agonist, and it must
first be heated back across its hysteresis gap to where its wire starts to contract (the reverse
transformation's start, which rises with the wire's stress, Clausius-Clapeyron) before the joint
moves at all: on the phase-fraction wrist 16 degC at ~2.3 degC/s, 7-10 s of a joint standing still
while the reference leaves. Below that temperature heating changes nothing in the wire (no
transformation starts), so the idle muscle can be warmed to just below it ahead of the turn.

The law is model-free: per muscle i (direction d_i = +1 for muscle 1, which raises q, -1 for
muscle 2) it learns T_onset,i, the measured muscle temperature [degC] at which the measured angle
last began to follow while that muscle was the agonist (u d_i > 0 with u the PID's filtered output
[degC]): when u d_i turns positive the angle q_start is noted, and the first sample with
(q - q_start) d_i > ``onset_rad`` records the measured temperature then. From ``preheat_s`` [s]
before the reference turns (its local parabola, :func:`~sma_wrist.core.control.joint_controller.time_to_turn`)
until that muscle becomes the agonist, the muscle that will drive after the turn (d_i = -sign(q_d'))
is asked for no less than T_onset,i - ``margin_C``. Before a muscle has been learnt (the first
half-cycle) or without measured temperatures nothing changes.
"""
from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

#: the direction each muscle drives the joint: muscle 1 raises q, muscle 2 lowers it
DIRECTION = np.array([1.0, -1.0])


class IdlePreheat:
    """The pre-heat floor for n wrists (the node's n = 1 and the sweep's bank run the same code)."""

    def __init__(self, n: int, preheat_s: float, margin_C: float, onset_rad: float) -> None:
        self.preheat_s, self.margin_C, self.onset_rad = preheat_s, margin_C, onset_rad
        self.T_onset = np.full((n, 2), np.nan)  # learnt contraction-onset temperatures [degC]
        self.q_start = np.full((n, 2), np.nan)  # angle at which the muscle became the agonist (nan: not watching)
        self.agonist = np.zeros((n, 2), np.bool_)
        self.on = np.zeros((n, 2), np.bool_)  # pre-heat latched until the muscle drives

    def floor(self, q: FloatArray, T_meas: FloatArray | None, u: FloatArray, time_to_turn_s: float,
              qdot_d: float) -> FloatArray:
        """(n, 2) lowest temperature request [degC] (-inf where none) after one sample: measured angles q (n,)
        [rad], measured muscle temperatures (n, 2) [degC] (None or NaN: nothing learnt), the PID's filtered
        output u (n,) [degC], the time to the reference's turn [s] (inf if it does not) and its velocity [rad/s]."""
        agonist = u[:, None] * DIRECTION > 0
        started = agonist & ~self.agonist
        self.q_start[started] = np.broadcast_to(q[:, None], agonist.shape)[started]
        self.q_start[~agonist] = np.nan
        self.agonist = agonist
        with np.errstate(invalid='ignore'):  # nan q_start: not watching
            moved = (q[:, None] - self.q_start) * DIRECTION > self.onset_rad
        if T_meas is not None:
            learn = moved & np.isfinite(T_meas)
            # the lowest onset seen: a hot antagonist raises the stress and with it the onset
            # (Clausius-Clapeyron), so a high one is not where an idle muscle may be warmed to
            self.T_onset[learn] = np.fmin(self.T_onset[learn], T_meas[learn])
        self.q_start[moved] = np.nan  # one onset per episode
        if time_to_turn_s < self.preheat_s and qdot_d != 0.0:
            self.on[:, 1 if qdot_d > 0 else 0] = True  # rising: muscle 2 drives after the turn
        self.on &= ~agonist
        return np.where(self.on & np.isfinite(self.T_onset), self.T_onset - self.margin_C, -math.inf)


__all__ = ['IdlePreheat', 'DIRECTION']
