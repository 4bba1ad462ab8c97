"""Splitting a measurement into stress levels, thermal cycles and heating/cooling branches.

* Stress levels: stresses are grouped where the sorted values have no gap larger than
  max(2 MPa, 3 %); groups holding at least 5 % of the samples (and >= 20) are levels, the
  rest (load ramps between levels) is dropped and counted. A group that densely sampled
  ramps have joined (several loads in one file) is split at its modes (:func:`_modes`).
* Branches: the temperature's turning points with a dead band (a reversal counts once T has
  come back by max(2 degC, 10 % of the level's range)), so sensor noise does not cut
  branches. A branch is complete when it spans >= 80 % of the level's temperature range.
* Cycles: consecutive pairs of complete branches (heating then cooling or the reverse).
  ``cycle`` picks one (1-based), 'last' (default: the first cycles of a wire often still
  train it) or 'all' (every complete cycle in order).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from sma_wrist.identify.io import IdentifyInputError, Measurement

FloatArray = NDArray[np.float64]

MIN_LOOP_SAMPLES = 40


@dataclass
class Loop:
    """One isobaric loop (or several cycles) at one stress, ready for the model."""

    source: str
    stress_MPa: float
    T_C: FloatArray
    strain: FloatArray
    first_branch: str  # 'heating' or 'cooling': the direction the loop starts with
    n_cycles_found: int
    cycle_used: str
    dropped_ramp: int

    @property
    def init_branch(self) -> str:
        """Memory before the loop: heated from cold means it came down the cooling branch."""
        return 'cooling' if self.first_branch == 'heating' else 'heating'

    @property
    def label(self) -> str:
        return f'{self.source} @ {self.stress_MPa:.4g} MPa'


def _tol(level: float) -> float:
    """Half-width [MPa] of a stress level: max(2 MPa, 3 %)."""
    return max(2.0, 0.03 * abs(level))


def _modes(g: FloatArray, need: int) -> list[float]:
    """Stress levels [MPa] held in one gap-free group of sorted stresses (the densest values first).

    A test with several loads in one file ramps between them, and a densely sampled ramp
    leaves no gap in the sorted stresses; the holds are where the samples pile up. A mode
    counts as a new level only if it lies beyond the noise of the levels already found
    (3 half-widths, 6 robust standard deviations), so a noisy single level is one level.
    """
    lo = np.searchsorted(g, g - np.maximum(2.0, 0.03 * np.abs(g)), 'left')
    hi = np.searchsorted(g, g + np.maximum(2.0, 0.03 * np.abs(g)), 'right')
    count = hi - lo
    levels: list[float] = []
    spread: list[float] = []
    free = np.ones(g.size, bool)
    while True:
        c = np.where(free, count, 0)
        i = int(np.argmax(c))
        if c[i] < need:
            break
        lv = float(g[i])
        near = np.abs(g - lv) <= 1.5 * _tol(lv)
        lv = float(np.median(g[near]))
        sigma = 1.4826 * float(np.median(np.abs(g[near] - lv)))
        if all(abs(lv - m) > max(3.0 * _tol(m), 6.0 * sd) for m, sd in zip(levels, spread)):
            levels.append(lv)
            spread.append(sigma)
        free &= ~(np.abs(g - lv) <= max(3.0 * _tol(lv), 6.0 * sigma))
    return levels


def stress_levels(stress: FloatArray) -> tuple[list[float], NDArray[np.intp]]:
    """(levels [MPa], label per sample: level index or -1 for ramp samples)."""
    s = np.sort(stress)
    tol = np.maximum(2.0, 0.03 * np.abs(s[1:]))
    cuts = np.nonzero(np.diff(s) > tol)[0]
    groups = np.split(s, cuts + 1)
    need = max(20, int(0.05 * stress.size))
    levels = []
    for g in groups:
        if g.size < need:
            continue
        modes = _modes(g, need)
        # one level: its median as before; several (ramps joined them): each hold's median
        levels.extend([float(np.median(g))] if len(modes) <= 1 else sorted(modes))
    label = np.full(stress.size, -1, np.intp)
    for k, lv in enumerate(levels):
        label[np.abs(stress - lv) <= _tol(lv) * 1.5] = k
    return levels, label


def turning_points(T: FloatArray, band: float) -> list[int]:
    """Indices of the temperature extrema, with a dead band against noise (start and end included)."""
    pts = [0]
    hi = lo = ext = 0
    direction = 0
    for k in range(1, T.size):
        if direction == 0:  # until T has moved by the band, only track the extremes
            hi = k if T[k] > T[hi] else hi
            lo = k if T[k] < T[lo] else lo
            if T[hi] - T[lo] >= band:
                direction = 1 if hi > lo else -1
                start = lo if direction == 1 else hi
                if start != 0:
                    pts.append(start)
                ext = hi if direction == 1 else lo
        elif (T[k] - T[ext]) * direction >= 0:
            ext = k
        elif abs(T[k] - T[ext]) >= band:  # reversal confirmed
            pts.append(ext)
            direction = -direction
            ext = k
    if direction != 0 and ext != pts[-1]:
        pts.append(ext)
    if pts[-1] != T.size - 1:
        pts.append(T.size - 1)
    return pts


def loops_of(m: Measurement, cycle: str = 'last') -> list[Loop]:
    """Every stress level of a measurement as a :class:`Loop` (see the module docstring)."""
    levels, label = stress_levels(m.stress_MPa)
    if not levels:
        raise IdentifyInputError(f'{m.path}: no constant stress level with >= 20 samples; an isobaric test is needed')
    out = []
    for k, lv in enumerate(levels):
        idx = np.nonzero(label == k)[0]
        T, eps = m.T_C[idx], m.strain[idx]
        rng = float(np.ptp(T))
        if rng < 5.0:
            continue  # a load ramp or hold at constant temperature, not a thermal cycle
        band = max(2.0, 0.1 * rng)
        tp = turning_points(T, band)
        branches = []
        for a, b in zip(tp[:-1], tp[1:]):
            span = abs(T[b] - T[a])
            if span >= 0.8 * rng:
                branches.append((a, b, 'heating' if T[b] > T[a] else 'cooling'))
        cycles = [
            (branches[i], branches[i + 1])
            for i in range(len(branches) - 1)
            if branches[i][1] == branches[i + 1][0] and branches[i][2] != branches[i + 1][2]
        ]
        if not cycles:
            raise IdentifyInputError(
                f'{m.path}: at {lv:.4g} MPa no complete heating-cooling cycle (found {len(branches)} complete '
                f'branch(es) over {T.min():.4g}..{T.max():.4g} degC); a full heating and cooling branch is needed'
            )
        # non-overlapping cycles: pairs (0,1), (2,3), ... of the complete branches
        cyc = cycles[::2] if len(cycles) > 1 else cycles
        if cycle == 'all':
            a, b = cyc[0][0][0], cyc[-1][1][1]
            used = f'all ({len(cyc)})'
            first = cyc[0][0][2]
        else:
            if cycle == 'last':
                i = len(cyc) - 1
            else:
                try:
                    i = int(cycle) - 1
                except ValueError:
                    raise IdentifyInputError(f"--cycle must be a number, 'last' or 'all', got {cycle!r}") from None
                if not 0 <= i < len(cyc):
                    raise IdentifyInputError(
                        f'{m.path}: --cycle {cycle} asked, {len(cyc)} complete cycle(s) at {lv:.4g} MPa'
                    )
            a, b = cyc[i][0][0], cyc[i][1][1]
            used = str(i + 1)
            first = cyc[i][0][2]
        sl = slice(a, b + 1)
        if b + 1 - a < MIN_LOOP_SAMPLES:
            raise IdentifyInputError(
                f'{m.path}: the cycle at {lv:.4g} MPa has {b + 1 - a} samples; '
                f'>= {MIN_LOOP_SAMPLES} are needed for a fit'
            )
        out.append(Loop(m.path, lv, T[sl].copy(), eps[sl].copy(), first, len(cyc), used, int(np.sum(label == -1))))
    if not out:
        raise IdentifyInputError(f'{m.path}: no stress level with a temperature cycle (>= 5 degC swing)')
    return out
