"""ADC counts <-> physical units for the wrist's five channels (pure, numpy only).

The device sends raw 16-bit counts (sma_wrist/hw/protocol.py); this linear map is the
host's calibration, set by the bridge's ``adc.*`` / ``calibration.*`` parameters. The
emulator uses the same map (with its own, possibly different, numbers) to produce counts,
so a calibration error on the host shows up as an offset on the topics, as it would on
the real wrist.

Channels, in protocol order: muscle 1 thermocouple, muscle 2 thermocouple, TEM 1
exchanger face, TEM 2 exchanger face (all degC), angle potentiometer (rad).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sma_wrist.hw.protocol import ADC_MAX

CHANNELS = ('muscle_1', 'muscle_2', 'tem_face_1', 'tem_face_2', 'angle')


@dataclass(frozen=True)
class Calibration:
    """Linear channel maps: value = zero + gain * counts (+ per-thermocouple offset).

    Defaults: temperatures -50 .. +212 degC over 0 .. 65535 (4 mdegC per count),
    angle -3.2768 .. +3.2767 rad (0.1 mrad per count).
    """

    temperature_gain_C_per_count: float = 0.004
    temperature_zero_C: float = -50.0
    #: thermocouple offsets added to (muscle 1, muscle 2, TEM face 1, TEM face 2) [degC]
    offsets_C: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    angle_gain_rad_per_count: float = 1e-4
    angle_offset_rad: float = -3.2768

    def to_physical(self, counts: tuple[int, ...] | np.ndarray) -> tuple[np.ndarray, float]:
        """(4 temperatures [degC], angle [rad]) of one sample's counts."""
        c = np.asarray(counts, dtype=float)
        temps = self.temperature_zero_C + self.temperature_gain_C_per_count * c[:4] + np.asarray(self.offsets_C)
        return temps, float(self.angle_offset_rad + self.angle_gain_rad_per_count * c[4])

    def to_physical_fast(self, counts: tuple[int, ...]) -> tuple[tuple[float, float, float, float], float]:
        """As :meth:`to_physical` in plain Python floats (the bridge's per-sample path, ~1 us)."""
        g, z, o = self.temperature_gain_C_per_count, self.temperature_zero_C, self.offsets_C
        return ((z + g * counts[0] + o[0], z + g * counts[1] + o[1], z + g * counts[2] + o[2],
                 z + g * counts[3] + o[3]), self.angle_offset_rad + self.angle_gain_rad_per_count * counts[4])

    def to_counts(self, temps_C: np.ndarray, angle_rad: float) -> np.ndarray:
        """Un-quantised counts (float, 5) that :meth:`to_physical` maps back to the inputs."""
        t = (np.asarray(temps_C, float) - np.asarray(self.offsets_C) - self.temperature_zero_C) \
            / self.temperature_gain_C_per_count
        a = (angle_rad - self.angle_offset_rad) / self.angle_gain_rad_per_count
        return np.append(t, a)


def quantise(counts: np.ndarray) -> tuple[int, int, int, int, int]:
    """Round to integer counts and clip to the ADC range 0 .. 65535 (saturation)."""
    q = np.clip(np.rint(counts), 0, ADC_MAX).astype(int)
    return tuple(int(v) for v in q)  # type: ignore[return-value]


__all__ = ['CHANNELS', 'Calibration', 'quantise']
