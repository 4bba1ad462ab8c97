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

from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

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

    def to_physical_array(self, counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """As :meth:`to_physical` for many samples: counts (n, 5) -> (temperatures (n, 4) [degC], angles (n,) [rad])."""
        c = np.asarray(counts, dtype=float).reshape(-1, 5)
        temps = self.temperature_zero_C + self.temperature_gain_C_per_count * c[:, :4] + np.asarray(self.offsets_C)
        return temps, self.angle_offset_rad + self.angle_gain_rad_per_count * c[:, 4]

    def to_physical_fast(self, counts: tuple[int, ...]) -> tuple[tuple[float, float, float, float], float]:
        """As :meth:`to_physical` in plain Python floats (the bridge's per-sample path, ~1 us)."""
        g, z, o = self.temperature_gain_C_per_count, self.temperature_zero_C, self.offsets_C
        return (
            (z + g * counts[0] + o[0], z + g * counts[1] + o[1], z + g * counts[2] + o[2], z + g * counts[3] + o[3]),
            self.angle_offset_rad + self.angle_gain_rad_per_count * counts[4],
        )

    def to_counts(self, temps_C: np.ndarray, angle_rad: float) -> np.ndarray:
        """Un-quantised counts (float, 5) that :meth:`to_physical` maps back to the inputs."""
        t = (
            np.asarray(temps_C, float) - np.asarray(self.offsets_C) - self.temperature_zero_C
        ) / self.temperature_gain_C_per_count
        a = (angle_rad - self.angle_offset_rad) / self.angle_gain_rad_per_count
        return np.append(t, a)

    def reversed_angle(self) -> Calibration:
        """The calibration of the same joint read through a potentiometer with its outer leads swapped (it reads
        ``ADC_MAX - counts``): value = offset + gain * (ADC_MAX - counts'), i.e. the gain negated and the offset
        moved by gain * ADC_MAX. Applying it twice gives the original back."""
        return replace(
            self,
            angle_gain_rad_per_count=-self.angle_gain_rad_per_count,
            angle_offset_rad=self.angle_offset_rad + self.angle_gain_rad_per_count * ADC_MAX,
        )


#: a pair of signs / 1-based channel numbers, one per muscle
Pair = tuple[int, int]


@dataclass(frozen=True)
class Wiring:
    """Which device channel serves which muscle, and with which sign (the bridge's ``calibration.tem_sign``,
    ``calibration.tem_channel_map``, ``calibration.thermocouple_map``; doc/explanation/protocol.md "Wiring").

    The host thinks in muscles: the command u_i is for the TEM on muscle i (u > 0 heats it), temperature i is
    muscle i's. A wrist wired otherwise is corrected here rather than re-soldered:

    * ``tem_channel_map[i]``: the driver output (1 or 2, the ``C`` frame's u1 / u2) wired to muscle i+1's TEM;
    * ``tem_sign[i]``: +1, or -1 when that TEM's leads are swapped (the output's positive drive cools it);
    * ``thermocouple_map[i]``: the ADC channel (1 or 2, the ``S`` frame's adc_T1 / adc_T2) of muscle i+1's
      thermocouple.

    The TEM face channels stay as they are (each face sensor sits on its own TEM); a reversed potentiometer is
    :meth:`Calibration.reversed_angle`.
    """

    tem_sign: Pair = (1, 1)
    tem_channel_map: Pair = (1, 2)
    thermocouple_map: Pair = (1, 2)

    def problem(self) -> str | None:
        """Why these values are no wiring, or None."""
        if any(s not in (1, -1) for s in self.tem_sign) or len(self.tem_sign) != 2:
            return f'calibration.tem_sign {list(self.tem_sign)} must be two signs, each 1 or -1'
        for name, m in (('tem_channel_map', self.tem_channel_map), ('thermocouple_map', self.thermocouple_map)):
            if sorted(m) != [1, 2]:
                return f'calibration.{name} {list(m)} must be [1, 2] or [2, 1] (each channel once)'
        return None

    @property
    def identity(self) -> bool:
        return self == Wiring()

    def device_command(self, u1_V: float, u2_V: float) -> tuple[float, float]:
        """The driver outputs (u1, u2) [V] that give muscle 1's TEM ``u1_V`` and muscle 2's ``u2_V``."""
        out = [0.0, 0.0]
        out[self.tem_channel_map[0] - 1] = self.tem_sign[0] * u1_V
        out[self.tem_channel_map[1] - 1] = self.tem_sign[1] * u2_V
        return out[0], out[1]

    def muscle_drive(self, d1_V: float, d2_V: float) -> tuple[float, float]:
        """The drive [V] muscle 1's and muscle 2's TEMs got from the driver outputs ``(d1_V, d2_V)`` (the inverse of
        :meth:`device_command`: a device's read-back of its outputs in the host's terms)."""
        d = (d1_V, d2_V)
        return self.tem_sign[0] * d[self.tem_channel_map[0] - 1], self.tem_sign[1] * d[self.tem_channel_map[1] - 1]

    def channel_order(self) -> list[int]:
        """Column indices that put a sample's five counts in muscle order (``counts[:, order]``)."""
        return [self.thermocouple_map[0] - 1, self.thermocouple_map[1] - 1, 2, 3, 4]

    def muscle_counts(self, adc: tuple[int, ...]) -> tuple[int, ...]:
        """A sample's counts in protocol order with the muscle thermocouples put in muscle order."""
        if self.thermocouple_map == (1, 2):
            return adc  # the per-sample path of a wrist wired as documented: nothing to copy
        k1, k2 = self.thermocouple_map
        return (adc[k1 - 1], adc[k2 - 1], *adc[2:])

    def then(self, found: Wiring) -> Wiring:
        """This wiring corrected by ``found``, a wiring measured *through* this one (found.tem_channel_map[i]: the
        command of this wiring that reaches muscle i+1's TEM, found.tem_sign[i] its sign; found.thermocouple_map[i]:
        the temperature of this wiring that reads muscle i+1)."""
        c = tuple(self.tem_channel_map[j - 1] for j in found.tem_channel_map)
        s = tuple(self.tem_sign[j - 1] * found.tem_sign[i] for i, j in enumerate(found.tem_channel_map))
        k = tuple(self.thermocouple_map[j - 1] for j in found.thermocouple_map)
        return Wiring(s, c, k)  # type: ignore[arg-type]

    def params(self) -> dict[str, list[int]]:
        """The bridge's parameters for this wiring."""
        return {
            'calibration.tem_sign': list(self.tem_sign),
            'calibration.tem_channel_map': list(self.tem_channel_map),
            'calibration.thermocouple_map': list(self.thermocouple_map),
        }

    @classmethod
    def from_params(cls, p: Mapping[str, Any]) -> Wiring:
        """From the bridge's parameter values (lists or arrays of ints)."""
        return cls(
            *(
                tuple(int(x) for x in p[f'calibration.{k}'])  # type: ignore[arg-type]
                for k in ('tem_sign', 'tem_channel_map', 'thermocouple_map')
            )
        )


def quantise(counts: np.ndarray) -> tuple[int, int, int, int, int]:
    """Round to integer counts and clip to the ADC range 0 .. 65535 (saturation)."""
    q = np.clip(np.rint(counts), 0, ADC_MAX).astype(int)
    return tuple(int(v) for v in q)  # type: ignore[return-value]


__all__ = ['CHANNELS', 'Calibration', 'Wiring', 'quantise']
