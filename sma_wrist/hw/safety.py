"""Safety checks of the device's readings that need their history (pure, no ROS).

A thermocouple that stops -- its converter returns its last reading, a firmware bug, a cable
that broke at a connector and left the chip's register as it was -- is not caught by the
over-temperature limit: the limit sees the frozen value while the TEM goes on heating or
cooling the wire. :class:`StuckSensor` flags a reading that has not changed at all for
``hold_s`` of device time while its TEM was driven one way harder than ``drive_V`` (the signed
drive's mean over about the last ``hold_s``: an exponential average with that time constant). A
sensor at rest repeats its value (a 0.25 degC chip does so for seconds), and so may one whose TEM
swings between heating and cooling; but a TEM driven one way that hard, beyond the drive that can
hold any temperature (identify thermal's hold limits, about +-13 V), moves a muscle by degrees. The flag stays until the reading changes: with the
TEMs off the drive no longer says anything.
"""
from __future__ import annotations

import numpy as np


class StuckSensor:
    """Per channel: True while a reading repeats for over ``hold_s`` [s] under a mean drive beyond +-``drive_V`` [V]."""

    def __init__(self, channels: int, hold_s: float, drive_V: float) -> None:
        self.set_limits(hold_s, drive_V)
        self.value = np.full(channels, np.nan)
        self.since = np.zeros(channels)  # device time of the last change [s]
        self.drive_mean = np.zeros(channels)  # the signed drive averaged over about the last hold_s [V]
        self.stuck = np.zeros(channels, bool)
        self.t: float | None = None

    def set_limits(self, hold_s: float, drive_V: float) -> None:
        """``hold_s`` 0 turns the check off."""
        if not (np.isfinite(hold_s) and hold_s >= 0 and np.isfinite(drive_V) and drive_V >= 0):
            raise ValueError(f'hold_s and drive_V must be finite and >= 0, got {hold_s!r}, {drive_V!r}')
        self.hold_s, self.drive_V = float(hold_s), float(drive_V)

    def update(self, t: float, values: np.ndarray, drive_V: np.ndarray) -> np.ndarray:
        """The flags (channels,) after a sample at device time t [s] of ``values`` read while ``drive_V`` (channels,)
        was applied [V]."""
        values = np.asarray(values, float)
        dt = 0.0 if self.t is None else max(t - self.t, 0.0)
        self.t = t
        changed = values != self.value
        if self.hold_s > 0:
            self.drive_mean += min(dt / self.hold_s, 1.0) * (np.asarray(drive_V, float) - self.drive_mean)
        self.since = np.where(changed, t, self.since)
        self.value = values
        if self.hold_s > 0:
            hard = (t - self.since > self.hold_s) & (np.abs(self.drive_mean) > self.drive_V)
            self.stuck = np.where(changed, False, self.stuck | hard)
        else:
            self.stuck[:] = False
        return self.stuck

    def held_s(self, t: float) -> np.ndarray:
        """How long each channel's reading has been the same at device time t [s]."""
        return t - self.since


__all__ = ['StuckSensor']
