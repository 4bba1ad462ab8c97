"""Excitation for identification: after the bring-up passed, the wrist is driven so that its own sensors identify
the TEM heat balance, the wire and the joint (:mod:`sma_wrist.commission.identification`).

The drive is antagonistic, u2 = -u1 (one muscle heated while the other is cooled), so that each wire is taken
through its transformation both ways and the joint sweeps its range; sines of several periods excite the heat
balance of each TEM layer at several frequencies (the seed's Sec. 4.3.1 runs, 12 V sines of 1/128-1 Hz), and
holds at the ends and at rest leave the joint still long enough to show its payload, pre-load and friction.
The phases (:func:`schedule`) are marked in ``bring.rec.marks``; each belongs to the ``fit`` part or the
``heldout`` part, the last phase, at a period no fit phase has, which only the validation sees.

Safety is the bring-up's: every sample goes through :meth:`BringUp._check` (ADC rails, muscle and face limits,
the joint's excursion; any breach raises :class:`~sma_wrist.commission.bringup.Stop` with the TEMs turned off),
device time paces everything, and the relays' drive never exceeds the bring-up's largest (``heat_V``), the sines' the
TEM driver rating the closed loop uses next (:attr:`ExcitationLimits.sine_V`). The muscle limit
is raised from the bring-up's to the TEMs' window (the muscle is a TEM face: Table 4.9's model holds in
``window_C``, 0-80 degC), with a governor below it: a muscle within ``margin_C`` of the window's top is not
heated further, one near its bottom not cooled further, an exchanger face near the face limit not loaded with
more heat. The governor changes the drive only; what was sent is what is recorded (``rec.u``), so the
identification sees the true input.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from sma_wrist.commission.bringup import BringUp
from sma_wrist.core.thermal.heat_balance import ThermalParams

#: the phase marks' prefix in ``bring.rec.marks`` ('excite fit: ...', 'excite heldout: ...')
MARK = 'excite'
COMMAND_PERIOD_S = 0.05  # a new drive value this often [s of device time]
GOVERNOR_AVG_S = 0.1  # the governor acts on the mean of the readings over this window [s]


@dataclass(frozen=True)
class Phase:
    """One phase: a sine u1 = amplitude_V sin(2 pi t / period_s), u2 = -u1, for ``cycles``; or a hold of ``hold_V``
    on muscle 1 (-hold_V on muscle 2) for ``hold_s``, ended early once the heated muscle reaches ``until_C`` (a
    half-cycle of a relay: the wire taken through its transformation as far as the TEMs' window lets it).
    ``part``: 'fit' or 'heldout'."""

    label: str
    part: str
    amplitude_V: float = 0.0
    period_s: float = 0.0
    cycles: float = 0.0
    hold_V: float = 0.0
    hold_s: float = 0.0
    until_C: float | None = None

    @property
    def duration_s(self) -> float:
        """The longest the phase may take [s]."""
        return self.cycles * self.period_s if self.period_s > 0 else self.hold_s

    def drive(self, t: float) -> float:
        """Muscle 1's drive [V] at ``t`` [s] into the phase (muscle 2 gets the negative)."""
        if self.period_s > 0:
            return self.amplitude_V * math.sin(2.0 * math.pi * t / self.period_s)
        return self.hold_V


def schedule(
    budget_s: float = 600.0, max_V: float = 20.0, hot_C: float = 77.0, sine_V: float | None = None
) -> list[Phase]:
    """The excitation's phases, at most 516 s of device time (the relay half-cycles end early once the heated muscle
    reaches ``hot_C``: 240-320 s on the emulated wrists); a smaller ``budget_s`` shortens the sines and rests (periods
    too: their frequencies rise), below 380 s drops them and shortens the relays' caps. The relays' drive is
    ``max_V`` (the bring-up's largest drive), the sines' amplitude ``sine_V`` (None: ``max_V``).

    Fit: a relay cycle at ``max_V`` (each muscle heated towards ``hot_C`` while the other cools: both wires through
    their transformation both ways, the joint across its range and held at each end), a rest at 0 V, sines of 30 s
    and 12 s (the heat balance's faster modes, up to the drive the closed loop uses: :attr:`ExcitationLimits.sine_V`).
    Held out: a second relay cycle at 0.8 ``max_V`` (another heating rate, another path through the hysteresis)
    ending at rest.
    """
    v = max_V
    a = v if sine_V is None else sine_V
    phases = [
        Phase('relay: muscle 1 heated', 'fit', hold_V=v, hold_s=100.0, until_C=hot_C),
        Phase('relay: muscle 2 heated', 'fit', hold_V=-v, hold_s=100.0, until_C=hot_C),
        Phase('rest at 0 V', 'fit', hold_s=20.0),
        Phase('sine 30 s', 'fit', amplitude_V=a, period_s=30.0, cycles=2),
        Phase('sine 12 s', 'fit', amplitude_V=a, period_s=12.0, cycles=3),
        Phase('relay: muscle 1 heated', 'heldout', hold_V=0.8 * v, hold_s=90.0, until_C=hot_C),
        Phase('relay: muscle 2 heated', 'heldout', hold_V=-0.8 * v, hold_s=90.0, until_C=hot_C),
        Phase('rest at 0 V', 'heldout', hold_s=20.0),
    ]
    # a smaller budget shortens the sines and rests first (the relay half-cycles end on temperature: their length is
    # a cap the wrist's TEMs decide, and cutting it would leave the wire short of its transformation)
    relay = sum(p.duration_s for p in phases if p.until_C is not None)
    other = sum(p.duration_s for p in phases) - relay
    k_other = float(np.clip((budget_s - relay) / other, 0.0, 1.0))
    k_relay = min(1.0, budget_s / relay)
    phases = [
        dataclasses.replace(p, period_s=p.period_s * k, hold_s=p.hold_s * k)
        for p in phases
        for k in [k_relay if p.until_C is not None else k_other]
        if k > 0
    ]
    return phases


@dataclass(frozen=True)
class ExcitationLimits:
    """The temperatures the excitation keeps to [degC]: the TEMs' window (the muscle face is a TEM face), a governor
    ``margin_C`` inside it, and the hard stop ``stop_margin_C`` beyond its top (over it: Stop, TEMs off)."""

    window_C: tuple[float, float] = ThermalParams().window_C
    margin_C: float = 2.0
    stop_margin_C: float = 2.0
    face_margin_C: float = 5.0  # an exchanger face this close to the bring-up's face limit takes no more heat
    max_excursion_rad: float = 1.8  # the whole range between the stops (-0.35 and 1.40 rad on the model wrist)
    #: the sines' amplitude [V]: the TEM driver rating, which the closed loop drives (tem_controller's u_min_V /
    #: u_max_V, a third of its time at +-24 V on the phase-fraction wrist). A heat balance identified up to the
    #: relays' 20 V (18 V sines) predicted the loop's muscle temperatures to 2.46 / 2.85 degC RMS per TEM, fitted
    #: with sines at 24 V 2.10 / 2.84, and refitted on every phase 1.51 / 1.79 (1.97 / 2.48 with 18 V sines)
    sine_V: float = 24.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.sine_V) and 0.0 < self.sine_V <= 24.0):
            raise ValueError(f'sine_V {self.sine_V!r} must be in (0, 24] V (the TEM driver rating)')


def excite(bring: BringUp, budget_s: float = 600.0, limits: ExcitationLimits | None = None) -> dict[str, Any]:
    """Drive the excitation of :func:`schedule` through ``bring`` (after its :meth:`~BringUp.run` passed); returns
    the step's summary (JSON-ready), also kept in ``bring.steps['excite']``. Raises
    :class:`~sma_wrist.commission.bringup.Stop` on anything unsafe (the TEMs are off by then), KeyboardInterrupt and
    DeviceLost as they come (TEMs off too)."""
    if not (math.isfinite(budget_s) and budget_s > 0):
        raise ValueError(f'excitation budget {budget_s!r} s must be a finite number > 0')
    el = limits or ExcitationLimits()
    lim0 = bring.lim
    soft_hi, soft_lo = el.window_C[1] - el.margin_C, el.window_C[0] + el.margin_C
    face_hi = lim0.max_face_C - el.face_margin_C
    phases = schedule(budget_s, lim0.max_drive_V, soft_hi - 1.0, el.sine_V)
    bring.lim = dataclasses.replace(
        lim0,
        max_muscle_C=el.window_C[1] + el.stop_margin_C,
        max_excursion_rad=max(lim0.max_excursion_rad, el.max_excursion_rad),
        # the sines up to the driver rating: the drive limit raised to it for the excitation (the wiring is known)
        cool_V=max(lim0.cool_V, el.sine_V),
    )
    t_begin = bring.t
    governed = np.zeros(2)  # device seconds each muscle's drive was limited by the governor
    rows: list[dict[str, Any]] = []
    bring.step = 'excite'
    bring.progress('excite')
    try:
        for ph in phases:
            t0 = bring.mark(f'{MARK} {ph.part}: {ph.label}')
            while bring.t - t0 < ph.duration_s:
                u = ph.drive(bring.t - t0)
                want = [u, -u]
                _, adc, _ = bring.rec.arrays(bring.t - GOVERNOR_AVG_S)
                temps, _ = bring.physical(adc)
                T = temps.mean(axis=0)
                if ph.until_C is not None and T[0 if u > 0 else 1] >= ph.until_C:
                    break
                for m in (0, 1):
                    d = want[m]
                    if (T[m] > soft_hi and d > 0) or (T[m] < soft_lo and d < 0) or (T[2 + m] > face_hi and d < 0):
                        want[m] = 0.0
                        governed[m] += COMMAND_PERIOD_S
                bring.set_drive(*want)
                bring.hold(COMMAND_PERIOD_S)
            rows.append(
                {
                    'label': ph.label,
                    'part': ph.part,
                    't_start_s': round(t0, 3),
                    't_end_s': round(bring.t, 3),
                    'amplitude_V': ph.amplitude_V or abs(ph.hold_V),
                    'period_s': round(ph.period_s, 3) or None,
                }
            )
        bring.set_drive(0.0, 0.0)
        bring.step = ''  # (kept on a stop or Ctrl-C: the message names the step)
    except BaseException:
        bring.off()
        raise
    finally:
        bring.lim = lim0
    t, adc, u = bring.rec.arrays(t_begin)
    temps, q = bring.physical(adc)
    summary = {
        'device_time_s': round(float(bring.t - t_begin), 3),
        'phases': rows,
        'muscle_C': [[round(float(temps[:, m].min()), 2), round(float(temps[:, m].max()), 2)] for m in (0, 1)],
        'face_C': [[round(float(temps[:, 2 + m].min()), 2), round(float(temps[:, 2 + m].max()), 2)] for m in (0, 1)],
        'angle_rad': [round(float(q.min()), 4), round(float(q.max()), 4)],
        'max_drive_V': round(float(np.abs(u).max()), 3) if len(u) else 0.0,
        'sine_V': el.sine_V,
        'governed_s': [round(float(g), 2) for g in governed],
        'window_C': list(el.window_C),
    }
    bring.steps['excite'] = summary
    return summary


__all__ = ['excite', 'schedule', 'Phase', 'ExcitationLimits', 'MARK']
