"""Safety checks of the device's readings that need their history (pure, no ROS).

A thermocouple that stops -- its converter returns its last reading, a firmware bug, a cable
that broke at a connector and left the chip's register as it was -- is not caught by the
over-temperature limit: the limit sees the frozen value while the TEM goes on heating or
cooling the wire. :class:`StuckSensor` flags a reading that has not changed at all for
``hold_s`` of device time while its TEM was driven one way harder than ``drive_V`` (the signed
drive's mean over about the last ``hold_s``: an exponential average with that time constant). A
sensor at rest repeats its value (a 0.25 degC chip does so for seconds), and so may one whose TEM
swings between heating and cooling; but a TEM driven one way that hard, beyond the drive that can
hold any temperature (identify thermal's hold limits, about +-13 V), moves a muscle by degrees.
The flag stays until the reading changes: with the TEMs off the drive no longer says anything.
"""

from __future__ import annotations

import math
from collections.abc import Sequence


class StuckSensor:
    """Per channel: True while a reading repeats for over ``hold_s`` [s] under a mean drive beyond +-``drive_V`` [V].

    Plain floats, not numpy: it runs for every sample of the device (1 kHz or more), where a few numpy calls on
    two channels cost ~8 us against ~1.5 us.
    """

    def __init__(self, channels: int, hold_s: float, drive_V: float) -> None:
        self.set_limits(hold_s, drive_V)
        self.value = [math.nan] * channels
        self.since = [0.0] * channels  # device time of the last change [s]
        self.drive_mean = [0.0] * channels  # the signed drive averaged over about the last hold_s [V]
        self.stuck = [False] * channels
        self.t: float | None = None

    def set_limits(self, hold_s: float, drive_V: float) -> None:
        """``hold_s`` 0 turns the check off."""
        if not (math.isfinite(hold_s) and hold_s >= 0 and math.isfinite(drive_V) and drive_V >= 0):
            raise ValueError(f'hold_s and drive_V must be finite and >= 0, got {hold_s!r}, {drive_V!r}')
        self.hold_s, self.drive_V = float(hold_s), float(drive_V)

    def update(self, t: float, values: Sequence[float], drive_V: Sequence[float]) -> list[bool]:
        """The flags (one per channel) after a sample at device time t [s] of ``values`` read while ``drive_V`` (one
        per channel) was applied [V]."""
        dt = 0.0 if self.t is None else max(t - self.t, 0.0)
        self.t = t
        on = self.hold_s > 0
        a = min(dt / self.hold_s, 1.0) if on else 0.0
        for i, v in enumerate(values):
            self.drive_mean[i] += a * (drive_V[i] - self.drive_mean[i])
            if v != self.value[i]:  # NaN at the start: the first reading is a change
                self.value[i], self.since[i], self.stuck[i] = v, t, False
            elif not on:
                self.stuck[i] = False
            elif t - self.since[i] > self.hold_s and abs(self.drive_mean[i]) > self.drive_V:
                self.stuck[i] = True
        return self.stuck


__all__ = ['StuckSensor']
