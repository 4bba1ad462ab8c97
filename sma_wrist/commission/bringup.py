"""Bring-up: link, sensors, TEM wiring, angle direction, with small drives and the TEMs off on anything unsafe.

Steps (each records what it found in :attr:`BringUp.steps`, whatever happens after it):

1. **link**: the device's hello (id, firmware, rate), the sample rate measured in device time (and against wall
   time on a serial port), lost samples and rejected lines, with the TEMs commanded to 0 V.
2. **sensors**: ``rest_s`` at 0 V: every channel alive (not at an ADC rail), finite, its noise (standard deviation
   about a line) in degC / rad; a muscle already above the bring-up limit stops here.
3. **tem_pulses**: a ``pulse_V`` pulse of ``pulse_s`` on each TEM command in turn, ``rest_s`` apart: which face
   and which muscle reading move, and which way (detect.classify_pulses). Wiring faults stop here; with
   ``accept_fixes`` the ones a bridge parameter corrects are applied and the pulses repeated to verify.
4. **angle**: each muscle heated at ``heat_V`` (the wiring now known to heat it) until the joint turns by
   ``move_rad``, the muscle reaches ``max_muscle_C`` or its temperature stops rising, then cooled back at
   ``cool_V``: which way the angle moves (detect.angle_direction). A reversed potentiometer stops here (or is
   corrected with ``accept_fixes``).

Every sample is checked against the bring-up limits (an ADC channel at a rail, a muscle or face over its limit,
the joint further than ``max_excursion_rad`` from where it started); the device time, not wall time, paces
everything, so a device emulated faster than real time runs the same procedure.
"""

from __future__ import annotations

import bisect
import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sma_wrist.commission import detect as D
from sma_wrist.commission.device import DeviceLost
from sma_wrist.hw import protocol as P
from sma_wrist.hw.calibration import Calibration, Wiring

HELLO_TIMEOUT_S = 3.0  # wall: the device answers a query within this
CHANNEL_NAMES = ('muscle 1 thermocouple', 'muscle 2 thermocouple', 'TEM 1 face', 'TEM 2 face', 'angle potentiometer')


@dataclass(frozen=True)
class BringUpLimits:
    """What the bring-up may do to the wrist. Voltages [V], times device [s], temperatures [degC]."""

    pulse_V: float = 6.0  # the wiring pulses: ~1.7 degC on the model wrist's muscle in 3 s
    pulse_s: float = 3.0
    rest_s: float = 2.0  # at 0 V: the sensors' noise, and between pulses
    heat_V: float = 20.0  # the angle check, once the pulses showed that a positive drive heats that muscle
    cool_V: float = 12.0  # cooling back after it (a negative drive of this size)
    max_muscle_C: float = 75.0  # the bring-up temperature limit (the bridge's own limit is 90 degC)
    max_face_C: float = 70.0
    move_rad: float = 0.01  # the joint turned: the angle check stops heating
    # heating ends when the joint turns, at the limit or when the muscle stops warming; this only ends a muscle
    # still warming slowly: TEMs at 0.6x the model's with a wire 10 degC hotter turn the joint after 63 s at 20 V
    # (a 60 s timeout stopped that healthy wrist with angle_not_determined)
    heat_timeout_s: float = 150.0
    stall_C: float = 0.3  # a muscle rising less than this over stall_window_s is as hot as heat_V makes it
    stall_window_s: float = 8.0
    cool_margin_C: float = 5.0  # cooled back to within this of where it started
    cool_timeout_s: float = 40.0
    max_excursion_rad: float = 0.3  # the joint further than this from its start: stop
    command_period_s: float = 0.02  # commands are repeated this often (the device's watchdog is 0.5 s)
    min_response_C: float = 0.15  # the least muscle temperature change a pulse must cause to count
    min_face_response_C: float = 0.05  # the same for a TEM face
    response_sigmas: float = 8.0  # ... and this many standard errors of its estimate
    face_response_sigmas: float = 4.0  # a face's: the decision between the two faces is relative (face_ratio)

    @property
    def max_drive_V(self) -> float:
        return max(self.pulse_V, self.heat_V, self.cool_V)

    def problem(self) -> str | None:
        for name in ('pulse_V', 'pulse_s', 'rest_s', 'heat_V', 'cool_V', 'max_muscle_C', 'max_face_C', 'move_rad'):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                return f'{name} {v!r} must be a finite number > 0'
        if self.max_drive_V > 24.0:
            return f'bring-up drive {self.max_drive_V:g} V is above the TEM driver rating 24 V'
        if self.max_muscle_C > 90.0:
            return f"bring-up muscle limit {self.max_muscle_C:g} degC is above the bridge's 90 degC"
        return None


class Stop(Exception):
    """A finding that ends the procedure (the TEMs go off; the fault is in the result)."""

    def __init__(self, fault: D.Fault) -> None:
        super().__init__(fault.message)
        self.fault = fault


@dataclass
class Record:
    """Every sample used: device time [s], raw counts, the drive commanded per muscle and per driver output [V]."""

    t: list[float] = field(default_factory=list)
    adc: list[tuple[int, ...]] = field(default_factory=list)
    u: list[tuple[float, float]] = field(default_factory=list)
    marks: list[tuple[float, str]] = field(default_factory=list)  # (t, label) of each phase's start

    def arrays(self, since: float = -math.inf) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(t, counts (n, 5), drive (n, 2)) of the samples from device time ``since`` on."""
        i = bisect.bisect_left(self.t, since)
        return (
            np.asarray(self.t[i:], float),
            np.asarray(self.adc[i:], float).reshape(-1, 5),
            np.asarray(self.u[i:], float).reshape(-1, 2),
        )


class BringUp:
    """One bring-up on ``device`` (SerialDevice or SimDevice) with the bridge's ``calibration`` and ``wiring``."""

    def __init__(
        self,
        device: Any,
        calibration: Calibration,
        wiring: Wiring,
        limits: BringUpLimits | None = None,
        accept_fixes: bool = False,
        progress: Callable[[str], None] | None = None,
    ) -> None:
        self.dev = device
        self.cal = calibration
        self.wiring = wiring
        self.lim = limits or BringUpLimits()
        self.accept_fixes = accept_fixes
        self.progress = progress or (lambda text: None)
        self.rec = Record()
        self.steps: dict[str, dict[str, Any]] = {}
        self.faults: list[D.Fault] = []
        self.warnings: list[str] = []
        self.hello: P.Hello | None = None
        self.max_drive_sent_V = 0.0
        self.step = ''
        self._seq = P.SequenceTracker()
        self._t0_us: int | None = None
        self._drive = (0.0, 0.0)  # per muscle [V]
        self._last_cmd_t = -math.inf
        self._wall0: float | None = None

    # ------------------------------------------------------------------ samples and drive
    @property
    def t(self) -> float:
        return self.rec.t[-1] if self.rec.t else 0.0

    def physical(self, adc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(temperatures (n, 4) [degC] in muscle order through the wiring in use, angle (n,) [rad])."""
        return self.cal.to_physical_array(np.atleast_2d(adc)[:, self.wiring.channel_order()])

    def _command(self, force: bool = False) -> None:
        if force or self.t - self._last_cmd_t >= self.lim.command_period_s:
            d = self.wiring.device_command(*self._drive)
            self.max_drive_sent_V = max(self.max_drive_sent_V, abs(d[0]), abs(d[1]))
            self.dev.send(*d)
            self._last_cmd_t = self.t

    def set_drive(self, u1_V: float, u2_V: float) -> None:
        """The drive per muscle [V] (positive heats); beyond the bring-up limit is a defect, not a request."""
        if max(abs(u1_V), abs(u2_V)) > self.lim.max_drive_V + 1e-9:
            raise AssertionError(f'drive {u1_V}, {u2_V} V beyond the bring-up limit {self.lim.max_drive_V} V')
        self._drive = (float(u1_V), float(u2_V))
        self._command(force=True)

    def _take(self, s: P.Sample) -> None:
        if self._t0_us is not None and s.flags & P.FLAG_BOOT:
            raise Stop(
                D.Fault(
                    'device_reset',
                    None,
                    f'the device restarted at {self.t:.1f} s of the procedure',
                    'check the supply (brown-out) and the firmware; then run commissioning again',
                )
            )
        if self._seq.update(s.seq) < 0:
            return  # a repeated or late line
        if self._t0_us is None:
            self._t0_us = s.t_us
        t = (s.t_us - self._t0_us) * 1e-6
        if self.rec.t and t < self.rec.t[-1]:
            return
        self.rec.t.append(t)
        self.rec.adc.append(s.adc)
        self.rec.u.append(self._drive)
        self._check(s.adc)

    def _check(self, adc: tuple[int, ...]) -> None:
        """The bring-up limits on one sample: any breach stops the procedure (the TEMs go off in run())."""
        for ch, c in enumerate(adc):
            if c in (0, P.ADC_MAX):
                raise Stop(
                    D.Fault(
                        'sensor_saturated',
                        ch + 1,
                        f'{CHANNEL_NAMES[ch]} (ADC channel {ch + 1}) reads '
                        f'{c}, the end of the ADC range, at {self.t:.2f} s',
                        f'check the {CHANNEL_NAMES[ch]}: an open or shorted sensor, its connector and its supply',
                    )
                )
        temps, q = self.cal.to_physical_fast(self.wiring.muscle_counts(adc))  # plain floats: every sample
        if not (math.isfinite(sum(temps)) and math.isfinite(q)):
            raise Stop(
                D.Fault(
                    'sensor_not_finite',
                    None,
                    'a reading is not a finite number',
                    'check the calibration parameters (adc.*, calibration.*)',
                )
            )
        if max(temps[:2]) > self.lim.max_muscle_C:
            m = 0 if temps[0] >= temps[1] else 1
            raise Stop(
                D.Fault(
                    'over_temperature',
                    m + 1,
                    f'muscle {m + 1} at {temps[m]:.1f} degC, above the bring-up limit {self.lim.max_muscle_C:g} degC',
                    'let the wrist cool down; if it was not heated, check its thermocouple',
                )
            )
        if max(temps[2:]) > self.lim.max_face_C:
            f = 0 if temps[2] >= temps[3] else 1
            raise Stop(
                D.Fault(
                    'over_temperature',
                    f + 1,
                    f'TEM {f + 1} face at {temps[2 + f]:.1f} degC, above the '
                    f'bring-up limit {self.lim.max_face_C:g} degC',
                    "check the TEM's cooling (coolant flow, heat sink)",
                )
            )
        q0 = getattr(self, '_q_start', None)
        if q0 is not None and abs(q - q0) > self.lim.max_excursion_rad:
            raise Stop(
                D.Fault(
                    'angle_excursion',
                    None,
                    f'the joint moved {q - q0:+.3f} rad from where it started, '
                    f'beyond the bring-up limit {self.lim.max_excursion_rad:g} rad',
                    'check the joint, its stops and the potentiometer',
                )
            )

    def pump(self) -> int:
        """Take the frames that arrived; repeat the drive command as needed. Returns the number of samples taken."""
        n = 0
        for f in self.dev.frames():
            if isinstance(f, P.Sample):
                if self.hello is None:
                    continue  # buffered before the port was opened, or before the device said who it is
                self._take(f)
                n += 1
            elif isinstance(f, P.Hello):
                self.hello = f
            elif isinstance(f, P.Reset) and self._t0_us is not None:
                raise Stop(
                    D.Fault(
                        'device_reset',
                        None,
                        f'the device restarted ({f.reason}) at {self.t:.1f} s',
                        'check the supply (brown-out) and the firmware; then run commissioning again',
                    )
                )
            elif isinstance(f, P.Error):
                self.warnings.append(f'device error {f.code}: {f.text}')
        self._command()
        return n

    def hold(self, duration_s: float, until: Callable[[], bool] | None = None) -> float:
        """Keep the drive for ``duration_s`` of device time (or until ``until()``); returns the device time spent."""
        t_start = self.t
        while self.t - t_start < duration_s:
            self.pump()
            if until is not None and until():
                break
        return self.t - t_start

    def mark(self, label: str) -> float:
        self.rec.marks.append((self.t, label))
        return self.t

    # ------------------------------------------------------------------ the steps
    def run(self) -> str:
        """All bring-up steps; returns 'passed', 'fault' or raises KeyboardInterrupt / DeviceLost after turning the
        TEMs off. The findings are in ``steps`` / ``faults`` in every case."""
        try:
            for name, step in (
                ('link', self.step_link),
                ('sensors', self.step_sensors),
                ('tem_pulses', self.step_pulses),
                ('angle', self.step_angle),
            ):
                self.step = name
                self.progress(name)
                step()
            self.step = ''
            return 'passed'
        except Stop as e:
            if not any(f is e.fault for f in self.faults):
                self.faults.append(e.fault)
            return 'fault'
        except DeviceLost as e:
            self.faults.append(
                D.Fault(
                    'link_lost',
                    None,
                    f'{e} during the {self.step} step',
                    "check the cable, the port and the device's supply; then run commissioning again",
                )
            )
            return 'fault'
        finally:
            self.off()

    def off(self) -> None:
        """TEMs to 0 V (and kept there: the device's watchdog also zeroes them without commands)."""
        self._drive = (0.0, 0.0)
        try:
            self.dev.send(0.0, 0.0)
        except Exception:  # a broken link: the device's watchdog zeroes the drive
            pass

    def step_link(self) -> None:
        self.dev.query()
        wall0 = time.monotonic()
        self.set_drive(0.0, 0.0)
        while self.hello is None:
            self.pump()
            if self.hello is None and time.monotonic() - wall0 > HELLO_TIMEOUT_S:
                st = self.dev.parser_stats
                seen = (
                    f'its lines are protocol version {self.dev.parser.foreign_version}, this host speaks '
                    f'{P.PROTOCOL_VERSION}'
                    if st.version_mismatch
                    else f'{st.rejected_lines} lines and {st.garbage_bytes} bytes failed their checks'
                    if st.rejected_lines or st.garbage_bytes
                    else 'nothing valid arrived'
                )
                raise Stop(
                    D.Fault(
                        'no_hello',
                        None,
                        f'the device sends no hello (H frame) in answer to a query: {seen}',
                        'check the baud rate, the port and that the firmware speaks doc/explanation/protocol.md',
                    )
                )
        self._wall0 = time.monotonic()
        self.hold(1.0)
        t, adc, _ = self.rec.arrays()
        wall = time.monotonic() - self._wall0
        rate = (len(t) - 1) / (t[-1] - t[0]) if len(t) > 1 and t[-1] > t[0] else float('nan')
        st = self.dev.parser_stats
        h = self.hello
        info = {
            'device_id': h.device_id,
            'firmware': h.firmware,
            'protocol_version': h.version,
            'rate_hz_announced': h.rate_hz,
            'rate_hz_measured': round(rate, 2),
            'samples': len(t),
            'lost_samples': self._seq.lost,
            'rejected_lines': st.rejected_lines,
            'garbage_bytes': st.garbage_bytes,
            'device_s_per_wall_s': round(t[-1] / wall, 3) if wall > 0 and len(t) and self.dev.port != 'sim' else None,
        }
        self.steps['link'] = info
        if not (math.isfinite(rate) and abs(rate - h.rate_hz) <= 0.02 * h.rate_hz):
            self.warnings.append(f'the device announces {h.rate_hz} Hz and sends {rate:.1f} Hz of device time')

    def step_sensors(self) -> None:
        t_start = self.mark('sensors at rest, 0 V')
        self.hold(self.lim.rest_s)
        t, adc, _ = self.rec.arrays(t_start)
        temps, q = self.physical(adc)
        values = np.column_stack([temps, q])
        units = ('degC',) * 4 + ('rad',)
        names = ('muscle_1', 'muscle_2', 'tem_face_1', 'tem_face_2', 'angle')
        self.steps['sensors'] = {
            n: {
                'mean': round(float(values[:, i].mean()), 4),
                'noise': float(f'{D.noise_level(t, values[:, i]):.3g}'),
                'unit': units[i],
                'adc_min': int(adc[:, i].min()),
                'adc_max': int(adc[:, i].max()),
            }
            for i, n in enumerate(names)
        }
        self.steps['sensors']['seconds'] = round(float(t[-1] - t[0]), 3)
        self._q_start = float(q.mean())
        self._T_start = temps.mean(axis=0)

    def _pulses(self, longer: float = 1.0) -> D.PulseFindings:
        """One positive pulse per TEM command of the wiring in use; the step changes and their classification.
        ``longer``: the pulses and the rests between them this many times as long (the drive as ever)."""
        lim = dataclasses.replace(self.lim, pulse_s=self.lim.pulse_s * longer, rest_s=self.lim.rest_s * longer)
        muscle, face, se_m, se_f = np.zeros((2, 2)), np.zeros((2, 2)), [], []
        t_begin = self.t
        windows = []
        for k in range(2):
            self.set_drive(0.0, 0.0)
            self.hold(lim.rest_s)
            t_on = self.mark(f'pulse {lim.pulse_V:g} V on TEM command {k + 1}')
            drive = [0.0, 0.0]
            drive[k] = lim.pulse_V
            self.set_drive(*drive)
            self.hold(lim.pulse_s)
            t_off = self.t
            self.set_drive(0.0, 0.0)
            windows.append((t_on, t_off))
        self.hold(lim.rest_s)
        t, adc, _ = self.rec.arrays(t_begin - lim.rest_s)
        temps, _ = self.physical(adc)
        for k, (t_on, t_off) in enumerate(windows):
            # the first sample at the drive's new value is one latency later; the window ends where the drive did
            for j in range(2):
                c = D.step_change(t, temps[:, j], t_on, t_off, baseline_s=0.75 * lim.rest_s)
                muscle[k, j] = c.change
                se_m.append(c.stderr)
                c = D.step_change(t, temps[:, 2 + j], t_on, t_off, baseline_s=0.75 * lim.rest_s)
                face[k, j] = c.change
                se_f.append(c.stderr)
        floor = max(lim.min_response_C, lim.response_sigmas * max(se_m))
        # an exchanger face on a large heat sink moves less (0.13 degC on the phase-fraction wrist): its own floor
        floor_f = max(lim.min_face_response_C, lim.face_response_sigmas * max(se_f))
        sel = t >= t_begin
        frozen = np.ptp(adc[sel][:, :2], axis=0) == 0 if sel.any() else np.zeros(2, bool)
        frozen = frozen[self.wiring.channel_order()[:2]]
        found = D.classify_pulses(muscle, face, floor, floor_f, frozen=frozen, current=self.wiring)
        self._pulse_table = {
            'muscle_change_C': np.round(muscle, 3).tolist(),
            'face_change_C': np.round(face, 3).tolist(),
            'response_floor_C': round(floor, 3),
            'face_response_floor_C': round(floor_f, 3),
            'frozen_readings': [bool(x) for x in frozen],
        }
        return found

    def step_pulses(self) -> None:
        found = self._pulses()
        info: dict[str, Any] = {'first': self._pulse_table, 'wiring_in_use': self.wiring.params()}
        self.steps['tem_pulses'] = info
        if found.faults and all(f.kind == 'face_sensor_no_response' for f in found.faults):
            # a weak TEM on a large heat sink moves its face by about the error of that estimate (0.074 against a
            # floor of 0.087 degC: the phase-fraction wrist, TEMs at 0.6x, 0.1 degC sensor noise): once more, twice
            # as long (a longer baseline too), before a face sensor is called dead
            self.mark('pulses again, twice as long: a TEM face answered within its noise')
            found = self._pulses(longer=2.0)
            info['longer'] = self._pulse_table
        if not found.faults:
            return
        fixable = all(f.kind in D.SOFTWARE_FIXABLE for f in found.faults) and found.complete
        if not (self.accept_fixes and fixable):
            self.faults.extend(found.faults)
            raise Stop(found.faults[0])
        self.wiring = self.wiring.then(found.wiring())
        info['wiring_corrected'] = self.wiring.params()
        self.mark('pulses again through the corrected wiring')
        again = self._pulses()
        info['verified'] = self._pulse_table
        if again.faults:
            self.faults.extend(found.faults)
            raise Stop(
                D.Fault(
                    'fix_not_verified',
                    None,
                    'the corrected wiring did not pass the pulses again: ' + again.faults[0].message,
                    again.faults[0].fix,
                )
            )
        for f in found.faults:
            f.fixed = True
            self.faults.append(f)

    def _heat(self, m: int) -> dict[str, Any]:
        """Heat muscle m (0/1) until the joint turns, the limit, a stall or the timeout; then cool it back."""
        lim = self.lim
        self.set_drive(0.0, 0.0)
        self.hold(0.5)
        t, adc, _ = self.rec.arrays(self.t - 0.5)
        temps, q = self.physical(adc)
        q0, T0 = float(q.mean()), float(temps[:, m].mean())
        t_on = self.mark(f'heat muscle {m + 1} at {lim.heat_V:g} V')
        hist: list[tuple[float, float]] = []
        why = ['timeout']
        n_avg = 20

        def done() -> bool:
            t, adc, _ = self.rec.arrays(self.t - 0.05)
            temps, q = self.physical(adc[-n_avg:])
            T, dq = float(temps[:, m].mean()), float(q.mean()) - q0
            hist.append((self.t, T))
            if abs(dq) >= lim.move_rad:
                why[0] = 'moved'
            elif T >= lim.max_muscle_C - 1.0:
                why[0] = 'limit'
            elif (
                self.t - t_on > lim.stall_window_s
                and T - next(x for tt, x in hist if tt >= self.t - lim.stall_window_s) < lim.stall_C
            ):
                why[0] = 'stalled'
            else:
                return False
            return True

        drive = [0.0, 0.0]
        drive[m] = lim.heat_V
        self.set_drive(*drive)
        self.hold(lim.heat_timeout_s, done)
        t_heat = self.t - t_on
        t, adc, _ = self.rec.arrays(self.t - 0.05)
        temps, q = self.physical(adc)
        dq, peak = float(q.mean()) - q0, float(temps[:, m].max())
        self.mark(f'cool muscle {m + 1} at {-lim.cool_V:g} V')
        drive[m] = -lim.cool_V

        def cooled() -> bool:
            t, adc, _ = self.rec.arrays(self.t - 0.05)
            return float(self.physical(adc)[0][:, m].mean()) <= T0 + lim.cool_margin_C

        self.set_drive(*drive)
        t_cool = self.hold(lim.cool_timeout_s, cooled)
        self.set_drive(0.0, 0.0)
        return {
            'start_C': round(T0, 2),
            'peak_C': round(peak, 2),
            'angle_change_rad': round(dq, 5),
            'heated_s': round(t_heat, 2),
            'ended': why[0],
            'cooled_s': round(t_cool, 2),
        }

    def step_angle(self) -> None:
        lim = self.lim
        res = [self._heat(0), self._heat(1)]
        self.hold(0.5)
        rev = self.cal.reversed_angle()
        found = D.angle_direction(
            [r['angle_change_rad'] for r in res],
            [r['ended'] == 'moved' for r in res],
            [r['ended'] == 'limit' for r in res],
            lim.max_muscle_C,
            [r['peak_C'] for r in res],
            {
                'calibration.angle_gain_rad_per_count': rev.angle_gain_rad_per_count,
                'calibration.angle_offset_rad': rev.angle_offset_rad,
            },
        )
        info: dict[str, Any] = {'muscle_1': res[0], 'muscle_2': res[1], 'angle_sign': found.sign}
        self.steps['angle'] = info
        for r, m in zip(res, (1, 2)):
            if r['ended'] in ('stalled', 'timeout'):
                self.warnings.append(
                    f'muscle {m} got to {r["peak_C"]:.1f} degC at {lim.heat_V:g} V and the joint did '
                    f"not turn {lim.move_rad:g} rad ({r['angle_change_rad']:+.4f}): the angle's "
                    'direction rests on the other muscle'
                    if found.sign is not None
                    else f'muscle {m} got to {r["peak_C"]:.1f} degC at {lim.heat_V:g} V without turning the joint'
                )
        if found.sign is None and not found.faults:
            raise Stop(
                D.Fault(
                    'angle_not_determined',
                    None,
                    'neither muscle turned the joint within the bring-up '
                    f'limits ({lim.heat_V:g} V, {lim.max_muscle_C:g} degC)',
                    'check that the wires are hooked to the joint; TEMs too weak or a wire transforming '
                    'hotter than the limits allow: raise --heat-V / --max-muscle-C',
                )
            )
        if not found.faults:
            return
        fixable = all(f.kind == 'angle_reversed' for f in found.faults)
        if not (self.accept_fixes and fixable):
            self.faults.extend(found.faults)
            raise Stop(found.faults[0])
        self.cal = rev
        info['calibration_corrected'] = {
            'calibration.angle_gain_rad_per_count': rev.angle_gain_rad_per_count,
            'calibration.angle_offset_rad': rev.angle_offset_rad,
        }
        for f in found.faults:
            f.fixed = True
            self.faults.append(f)


__all__ = ['BringUp', 'BringUpLimits', 'Record', 'Stop', 'CHANNEL_NAMES']
