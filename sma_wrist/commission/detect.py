"""The bring-up's numerical decisions, from step responses (pure: numpy only, no device, no ROS).

A short drive pulse on one TEM changes three temperatures: its exchanger face (which sits on that TEM: the face
cools while the muscle side heats, doc/explanation/model.md), the muscle under it, and nothing else (the other muscle is
on its own TEM). So with a pulse on each driver output:

* the face that moves names the TEM the output is wired to (:func:`classify_pulses`: TEM channels swapped);
* the muscle thermocouple that moves names the thermocouple that reads that TEM's muscle (thermocouples swapped);
* the sign of that muscle's change is the TEM's polarity (a positive drive must heat it);
* a face that moves while no muscle reading changes at all is a frozen thermocouple.

Heating each muscle until the joint turns gives the angle's sign (:func:`angle_direction`): muscle 1 turns the
joint to positive angles, muscle 2 to negative ones (the model's convention, ``sma_wrist.core.plant``).
Each finding is a :class:`Fault` that names its fix; :func:`found_wiring` turns the findings into the wiring
measured through the one in use (``Wiring.then`` composes them).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from sma_wrist.hw.calibration import Wiring

#: the wiring fault kinds, each corrected by a bridge parameter (``--accept-fixes`` writes it)
SOFTWARE_FIXABLE = ('tem_polarity', 'tem_channels_swapped', 'thermocouples_swapped', 'angle_reversed')


@dataclass
class Fault:
    """A finding that stops the bring-up: ``kind`` (one of :data:`SOFTWARE_FIXABLE` or a sensor / mechanics kind),
    the muscle / TEM / channel it concerns (1 or 2; None: both or the link), what was seen, and how to fix it."""

    kind: str
    channel: int | None
    message: str
    fix: str
    params: dict[str, Any] = field(default_factory=dict)  # the bridge parameters that correct it (if software can)
    fixed: bool = False  # corrected by --accept-fixes and verified

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class StepChange:
    """The change of a signal over a pulse [its unit] and the standard error of that estimate."""

    change: float
    stderr: float


def noise_level(t: np.ndarray, y: np.ndarray) -> float:
    """Standard deviation of ``y`` about its least-squares line over ``t`` (a drift is no noise) [its unit]."""
    t, y = np.asarray(t, float), np.asarray(y, float)
    if len(y) < 3:
        return 0.0
    A = np.vstack([t - t.mean(), np.ones_like(t)]).T
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    return float(np.std(y - A @ coef, ddof=2))


def step_change(
    t: np.ndarray, y: np.ndarray, t_on: float, t_off: float, baseline_s: float = 2.0, tail_s: float = 0.5
) -> StepChange:
    """How much ``y`` changed by the end of a pulse from ``t_on`` to ``t_off`` [s]: the mean over the pulse's last
    ``tail_s`` minus the baseline (the line fitted over the ``baseline_s`` before ``t_on``, extrapolated to the
    tail's mean time, so that a drift left by an earlier pulse is not taken for a response).

    ValueError if either stretch holds fewer than 3 samples."""
    t, y = np.asarray(t, float), np.asarray(y, float)
    base = (t >= t_on - baseline_s) & (t < t_on)
    tail = (t > t_off - tail_s) & (t <= t_off)
    if base.sum() < 3 or tail.sum() < 3:
        raise ValueError(
            f'too few samples around the pulse {t_on:g}..{t_off:g} s (baseline {base.sum()}, tail {tail.sum()})'
        )
    tb, yb = t[base], y[base]
    slope, icpt = np.polyfit(tb - tb.mean(), yb, 1)
    t_tail = t[tail].mean()
    expected = icpt + slope * (t_tail - tb.mean())
    sd = noise_level(tb, yb)
    # the tail's mean, the baseline's level and its slope extrapolated over (t_tail - its mean): the last dominates
    # (a 1 s baseline of 0.1 degC noise extrapolated 2 s ahead: 0.02 degC, five times the other two)
    stderr = sd * float(
        np.sqrt(1.0 / tail.sum() + 1.0 / base.sum() + (t_tail - tb.mean()) ** 2 / np.sum((tb - tb.mean()) ** 2))
    )
    return StepChange(float(y[tail].mean() - expected), stderr)


@dataclass(frozen=True)
class PulseFindings:
    """What the pulses say, in terms of the wiring in use: for muscle m (index m-1) the command that reaches its
    TEM (``tem_of_muscle``), that TEM's sign (``polarity``), the temperature reading that reads it
    (``reading_of_muscle``); and the faults. ``None`` entries: not determined (see the faults)."""

    tem_of_muscle: tuple[int | None, int | None]
    polarity: tuple[int | None, int | None]
    reading_of_muscle: tuple[int | None, int | None]
    faults: tuple[Fault, ...]

    @property
    def complete(self) -> bool:
        return None not in self.tem_of_muscle + self.polarity + self.reading_of_muscle

    def wiring(self) -> Wiring:
        """The wiring measured through the one in use (Wiring.then corrects it); requires ``complete``."""
        if not self.complete:
            raise ValueError('the pulses did not determine the wiring')
        return Wiring(self.polarity, self.tem_of_muscle, self.reading_of_muscle)  # type: ignore[arg-type]


def _dominant(changes: Sequence[float], floor: float, ratio: float) -> int | None:
    """Index of the one entry whose magnitude is above ``floor`` and ``ratio`` times every other's, or None."""
    mag = np.abs(np.asarray(changes, float))
    i = int(np.argmax(mag))
    others = np.delete(mag, i)
    if mag[i] < floor or (len(others) and mag[i] < ratio * others.max()):
        return None
    return i


def classify_pulses(
    muscle: np.ndarray,
    face: np.ndarray,
    muscle_floor_C: float,
    face_floor_C: float,
    frozen: np.ndarray | None = None,
    ratio: float = 3.0,
    face_ratio: float = 2.0,
    current: Wiring = Wiring(),
) -> PulseFindings:
    """Wiring findings from a positive pulse on each command of the wiring in use.

    ``muscle[k, j]`` [degC]: change of temperature reading j (muscle-ordered by the wiring in use) during the pulse
    on command k; ``face[k, f]``: change of TEM face f (each face sensor sits on its own TEM, which sits on muscle f).
    ``muscle_floor_C`` / ``face_floor_C``: the least change that counts as a response (a few
    standard errors above the noise, and a physical minimum); ``ratio`` / ``face_ratio``: how much larger than the
    other channel's a response must be (a face on a large heat sink moves 0.13 degC in a pulse, the other one
    within the noise: 2 rather than 3). ``frozen[j]``: reading j did not change at all over the pulses. ``current``: the
    wiring the pulses went through; a fault's ``params`` are that wiring corrected.
    """
    muscle, face = np.asarray(muscle, float), np.asarray(face, float)
    frozen = np.zeros(2, bool) if frozen is None else np.asarray(frozen, bool)
    faults: list[Fault] = []
    tem_of_muscle: list[int | None] = [None, None]
    polarity: list[int | None] = [None, None]
    reading_of_muscle: list[int | None] = [None, None]
    for k in range(2):
        f = _dominant(face[k], face_floor_C, face_ratio)
        j = _dominant(muscle[k], muscle_floor_C, ratio)
        if f is None and j is None:
            faults.append(
                Fault(
                    'tem_no_response',
                    k + 1,
                    f'TEM command {k + 1} changed neither TEM face nor '
                    f'muscle temperature (faces {_fmt(face[k])} degC, muscles {_fmt(muscle[k])} degC)',
                    f'check driver output {k + 1}, its fuse and the TEM wires on it',
                )
            )
            continue
        if f is None:  # without the face the TEM cannot be told apart from its muscle's thermocouple
            faults.append(
                Fault(
                    'face_sensor_no_response',
                    k + 1,
                    f'TEM command {k + 1} moved a muscle temperature '
                    f'({_fmt(muscle[k])} degC) but no TEM face ({_fmt(face[k])} degC)',
                    'check the TEM face thermocouples (ADC channels 3 and 4): without them a swapped TEM '
                    'channel cannot be told from swapped muscle thermocouples',
                )
            )
            continue
        if tem_of_muscle[f] is not None:
            faults.append(
                Fault(
                    'tem_wiring_unclear',
                    None,
                    f'both TEM commands moved TEM face {f + 1}',
                    'check that each driver output is wired to one TEM',
                )
            )
            continue
        tem_of_muscle[f] = k + 1
        if j is None:
            if frozen.any():
                jf = int(np.argmax(frozen))
                faults.append(
                    Fault(
                        'sensor_frozen',
                        jf + 1,
                        f'temperature reading {jf + 1} did not change at all '
                        f'while TEM {f + 1} moved its face by {face[k, f]:+.2f} degC',
                        f'check the thermocouple on ADC channel {jf + 1}, its connector and converter',
                    )
                )
            else:
                faults.append(
                    Fault(
                        'muscle_sensor_no_response',
                        f + 1,
                        f'TEM {f + 1} moved its face by '
                        f'{face[k, f]:+.2f} degC but no muscle temperature changed clearly '
                        f'({_fmt(muscle[k])} degC)',
                        f'check that TEM {f + 1} touches its muscle and that the muscle thermocouples sit on the wires',
                    )
                )
            continue
        reading_of_muscle[f] = j + 1
        # u > 0 heats the muscle (and cools the face): the muscle's sign is the TEM's polarity
        polarity[f] = 1 if muscle[k, j] > 0 else -1
    if None not in reading_of_muscle and reading_of_muscle[0] == reading_of_muscle[1]:
        faults.append(
            Fault(
                'tem_wiring_unclear',
                None,
                'both TEMs moved the same muscle thermocouple',
                'check that each muscle has its own thermocouple',
            )
        )
        reading_of_muscle = [None, None]
    complete = None not in tem_of_muscle + polarity + reading_of_muscle
    # the parameters that correct it: the wiring in use corrected by what was found (where that is all known)
    fixed = (
        current.then(Wiring(tuple(polarity), tuple(tem_of_muscle), tuple(reading_of_muscle))).params()
        if complete
        else {}
    )  # type: ignore[arg-type]

    def fix(key: str, wires: str) -> tuple[str, dict[str, Any]]:
        if key not in fixed:
            return wires, {}
        return (
            f'set {key}: {fixed[key]} (sma-wrist commission --accept-fixes writes it), or {wires}',
            {key: fixed[key]},
        )

    if tem_of_muscle == [2, 1]:
        faults.append(
            Fault(
                'tem_channels_swapped',
                None,
                'TEM command 1 moves TEM 2 (on muscle 2) and command 2 moves TEM 1: the TEM drive channels are swapped',
                *fix('calibration.tem_channel_map', 'swap the TEM drive wires between driver outputs 1 and 2'),
            )
        )
    if reading_of_muscle == [2, 1]:
        faults.append(
            Fault(
                'thermocouples_swapped',
                None,
                'heating muscle 1 moves temperature reading 2 and heating '
                'muscle 2 reading 1: the muscle thermocouples are swapped',
                *fix('calibration.thermocouple_map', 'swap the two muscle thermocouple plugs'),
            )
        )
    for m in range(2):
        if polarity[m] == -1:
            dT = muscle[tem_of_muscle[m] - 1, reading_of_muscle[m] - 1]  # type: ignore[operator]
            faults.append(
                Fault(
                    'tem_polarity',
                    m + 1,
                    f'a positive drive of TEM {m + 1} cooled muscle {m + 1} (by '
                    f'{-dT:.2f} degC): TEM {m + 1} is wired with reversed polarity',
                    *fix('calibration.tem_sign', f'swap the two leads of TEM {m + 1} at the driver'),
                )
            )
    return PulseFindings(
        tuple(tem_of_muscle),
        tuple(polarity),
        tuple(reading_of_muscle),  # type: ignore[arg-type]
        tuple(faults),
    )


@dataclass(frozen=True)
class AngleFindings:
    """The sign of the angle reading (+1 as documented, -1 reversed, None undetermined) and the faults."""

    sign: int | None
    faults: tuple[Fault, ...]


def angle_direction(
    dq: Sequence[float],
    moved: Sequence[bool],
    reached_limit: Sequence[bool],
    limit_C: float,
    peak_C: Sequence[float],
    angle_params: dict[str, float] | None = None,
) -> AngleFindings:
    """The angle's sign from heating each muscle: ``dq[m]`` [rad] the angle's change while muscle m+1 was heated,
    ``moved[m]`` whether that exceeded the motion threshold, ``reached_limit[m]`` whether the muscle got to the
    bring-up temperature limit ``limit_C`` (its peak: ``peak_C[m]``) without the joint moving.

    Heating muscle 1 must turn the joint to positive angles, muscle 2 to negative ones. Both the other way round:
    the potentiometer is reversed. A muscle at the limit and no motion: its wire does not pull. A muscle that never
    got there (weak TEMs, a wire transforming hotter) decides nothing and is no fault."""
    expected = (1, -1)
    faults: list[Fault] = []
    signs = []
    for m in range(2):
        if moved[m]:
            signs.append(int(np.sign(dq[m])) * expected[m])
        elif reached_limit[m]:
            faults.append(
                Fault(
                    'muscle_not_moving',
                    m + 1,
                    f'muscle {m + 1} reached {peak_C[m]:.1f} degC (the '
                    f'bring-up limit {limit_C:g} degC) and the joint moved only {dq[m]:+.4f} rad',
                    f"check muscle {m + 1}'s wire: broken, unhooked from the joint or its crimp slipped "
                    '(a wire transforming above the limit: raise --max-muscle-C)',
                )
            )
    if not signs:
        return AngleFindings(None, tuple(faults))
    if len(set(signs)) > 1:
        faults.append(
            Fault(
                'angle_inconsistent',
                None,
                f'heating muscle 1 and muscle 2 turned the joint the same way ({dq[0]:+.4f}, {dq[1]:+.4f} rad)',
                "check the joint, its stops and the potentiometer's coupling to it",
            )
        )
        return AngleFindings(None, tuple(faults))
    sign = signs[0]
    if sign < 0:
        faults.append(
            Fault(
                'angle_reversed',
                None,
                'heating muscle 1 turned the measured angle to negative values '
                f'({dq[0]:+.4f} rad) and muscle 2 to positive ones ({dq[1]:+.4f} rad): the potentiometer '
                'reads the angle reversed',
                'set '
                + ', '.join(f'{k}: {v:.6g}' for k, v in (angle_params or {}).items())
                + " (--accept-fixes writes them), or swap the potentiometer's two outer leads",
                dict(angle_params or {}),
            )
        )
    return AngleFindings(sign, tuple(faults))


def _fmt(v: Sequence[float]) -> str:
    return '[' + ', '.join(f'{x:+.2f}' for x in v) + ']'


__all__ = [
    'Fault',
    'StepChange',
    'PulseFindings',
    'AngleFindings',
    'SOFTWARE_FIXABLE',
    'noise_level',
    'step_change',
    'classify_pulses',
    'angle_direction',
]
