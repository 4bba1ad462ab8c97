"""Steps of the measured angle that the model's replay does not make: ``sma-wrist diagnose`` names them.

A wrist whose angle jumps within a fraction of a second while its muscle temperatures move smoothly has done
something no smooth model describes: a snap of the antagonistic pair (one wire's transformation running away under
the other's pull), a wire slipping in its crimp, the chain skipping a tooth, a potentiometer's wiper lifting. The
residual then holds a large, short error that the catalogue's effects (each a smooth change of a parameter) cannot
fit, and the verdict would be "unexplained discrepancy" with nothing said about when or how large.

The rule compares the run with its own replay: a step is where the measured angle changes over :data:`WINDOW_S`
by more than :data:`RATIO` times the largest change the model's replay makes over that window anywhere in the run
(the model is driven by the same temperatures, so a fast but real motion of the wrist is fast in the replay too),
and by more than :data:`NOISE_RATIO` times the angle's noise. Measured on 26 closed-loop runs of the emulated
phase-fraction wrist, each diagnosed against its commissioned model (doc/explanation/commissioning.md): in the 23
runs without a snap the measured largest change over 0.1 s was 0.50-1.35 times the replay's (one run with a small
step of 0.043 rad: 1.79), in the three with a snap (0.19-0.28 rad) 11.2, 14.0 and 18.8 times. The size reported is
the change of the measured angle less the replay's over the window: the part of the motion the replay does not make.
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: the window over which the angle's change is taken [s]
WINDOW_S = 0.1
#: a step: the measured change over WINDOW_S beyond this many times the replay's largest one
RATIO = 2.5
#: ... and beyond this many times the angle's noise [rad / rad]
NOISE_RATIO = 10.0
#: steps closer than this [s] are one
MERGE_S = 1.0
#: the replay restarts from the measured angle this long [s] after a step's last window ends (past its bounce) ...
RESTART_AFTER_S = 0.1
#: ... at the median of the measured angle over this long [s] (one noisy reading would offset what follows)
RESTART_MEDIAN_S = 0.05


def angle_steps(
    t: np.ndarray, q: np.ndarray, q_model: np.ndarray, noise_rad: float, valid: np.ndarray | None = None
) -> list[dict[str, Any]]:
    """The steps of the measured angle ``q`` [rad] that the replay ``q_model`` [rad] (same samples, times ``t``
    [s], uniform) does not make (module docstring), largest first: ``{'t_s', 'start_s', 'end_s', 'step_rad',
    'model_max_rad'}``, the time where the window of the largest change starts, where the step's first window starts
    and its last ends (windows within :data:`MERGE_S` are one step), the change over :data:`WINDOW_S` of the measured
    angle less the replay's (the step the replay does not make) and the replay's largest change over that window in
    the whole stretch.
    ``valid`` (bool per sample, optional): samples with a measurement; a window touching one without is skipped."""
    t, q, q_model = (np.asarray(a, float) for a in (t, q, q_model))
    if t.size < 3:
        return []
    dt = float(t[1] - t[0])
    n = max(1, int(round(WINDOW_S / dt)))
    if t.size <= n:
        return []
    dq = np.abs(q[n:] - q[:-n])
    dm = np.abs(q_model[n:] - q_model[:-n])
    # the size: the change of the residual, the part of the motion the replay does not make
    dr = np.abs((q - q_model)[n:] - (q - q_model)[:-n])
    ok = np.isfinite(dq) & np.isfinite(dm)
    if valid is not None:
        gaps = np.concatenate([[0], np.cumsum(~np.asarray(valid, bool))])
        ok &= (gaps[n + 1 :] - gaps[: -n - 1]) == 0  # no sample of the window without a measurement
    if not ok.any():
        return []
    model_max = float(np.max(dm[ok]))
    limit = max(RATIO * model_max, NOISE_RATIO * noise_rad)
    hits = np.flatnonzero(ok & (dq > limit))
    steps: list[dict[str, Any]] = []
    for i in hits:
        if steps and t[i] - steps[-1]['_last'] <= MERGE_S:
            s = steps[-1]
            s['_last'] = float(t[i])
            if dr[i] > s['step_rad']:
                s['t_s'], s['step_rad'] = float(t[i]), float(dr[i])
            continue
        steps.append(
            {
                't_s': float(t[i]),
                'start_s': float(t[i]),
                'step_rad': float(dr[i]),
                'model_max_rad': model_max,
                '_last': float(t[i]),
            }
        )
    for s in steps:
        s['end_s'] = s.pop('_last') + n * dt
    return sorted(steps, key=lambda s: -s['step_rad'])


def _settled(t: np.ndarray, step: dict[str, Any]) -> tuple[int, int]:
    """(first sample, length) of the readings whose median the replay restarts from after ``step``: from
    :data:`RESTART_AFTER_S` after its last window, :data:`RESTART_MEDIAN_S` long; the restart is at the window's middle
    sample (the angle there, not a lagged one)."""
    dt = float(t[1] - t[0])
    m = max(1, int(round(RESTART_MEDIAN_S / dt)))
    return int(np.searchsorted(t, step['end_s'] + RESTART_AFTER_S - 1e-9 * dt)), m


def event_samples(t: np.ndarray, steps: list[dict[str, Any]]) -> np.ndarray:
    """Bool per sample of ``t`` [s]: inside a step, from its first window's start to where the replay restarts after
    it (:func:`restarts`): the event itself, which the summary names and no model replay is scored on."""
    t = np.asarray(t, float)
    out = np.zeros(t.size, bool)
    if t.size < 2:
        return out
    for s in steps:
        i, m = _settled(t, s)
        out[int(np.searchsorted(t, s['start_s'] - 1e-9)) : i + (m - 1) // 2 + 1] = True
    return out


def restarts(t: np.ndarray, q: np.ndarray, steps: list[dict[str, Any]]) -> tuple[list[int], list[float]]:
    """Where the replay restarts from the measured angle after each step (:func:`angle_steps` of the same times
    ``t`` [s] and angle ``q`` [rad]): (sample indices into ``t``, angles [rad]), two per step: where the angle went
    farthest in the step's direction (the reading: a sampled snap peaks between readings), then the median of the
    finite readings over :data:`RESTART_MEDIAN_S` from :data:`RESTART_AFTER_S` after the step's end, at that window's
    middle sample; a step too close to the end of the run gets none."""
    t, q = np.asarray(t, float), np.asarray(q, float)
    if t.size < 2:
        return [], []
    idx, ang = [], []
    for s in sorted(steps, key=lambda s: s['t_s']):
        i, m = _settled(t, s)
        w = q[i : i + m]
        w = w[np.isfinite(w)]
        if i + m > t.size or w.size == 0:
            continue
        # first to the farthest the angle went: the wires remember that stretch (after a snap of the emulated pair, its
        # own values replayed the 5 s after 21.6 mrad RMS off restarted at the settled angle alone, 7.2 so)
        a = max(int(np.searchsorted(t, s['start_s'] - 1e-9)) - 1, 0)
        seg = q[a : i + 1]
        ok = np.flatnonzero(np.isfinite(seg))
        if ok.size >= 2:
            far = int(ok[np.argmax(seg[ok])] if np.median(w) > seg[ok[0]] else ok[np.argmin(seg[ok])])
            if 1 <= a + far < i + (m - 1) // 2:
                idx.append(a + far)
                ang.append(float(seg[far]))
        idx.append(i + (m - 1) // 2)
        ang.append(float(np.median(w)))
    return idx, ang


def describe(steps: list[dict[str, Any]]) -> str:
    """One sentence for the diagnosis' summary ('' for none): the largest steps, when, and what may make them."""
    if not steps:
        return ''
    shown = ', '.join(f'{s["step_rad"]:.3g} rad at {s["t_s"]:.1f} s' for s in steps[:3])
    more = f' (and {len(steps) - 3} more)' if len(steps) > 3 else ''
    return (
        f'the measured angle stepped within {WINDOW_S:g} s ({shown}{more}) where the model moves at most '
        f'{steps[0]["model_max_rad"]:.3g} rad in {WINDOW_S:g} s: a snap of the pair, a wire slipping in its crimp, '
        'the chain skipping or the potentiometer, which no smooth model describes; the replay restarts from the '
        'measured angle after each step, so the verdict judges the model between them'
    )


__all__ = [
    'angle_steps',
    'describe',
    'event_samples',
    'restarts',
    'WINDOW_S',
    'RATIO',
    'NOISE_RATIO',
    'MERGE_S',
    'RESTART_AFTER_S',
    'RESTART_MEDIAN_S',
]
