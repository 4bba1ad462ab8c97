"""hardware_bridge: the real wrist (or its emulator) on a serial line, in place of plant_sim.

Same topics, types and units as plant_sim (msg_defs/topics.yaml): /clock,
/wrist/muscle_{1,2}/temperature, /wrist/muscle_{1,2}/stress, /wrist/joint_states,
/wrist/payload (latched); subscribes /wrist/tem_{1,2}/command; reports on /diagnostics. A device that reads its
drive back (the protocol's D frame, asked for at every hello) also gives /wrist/tem_drive_applied: the drive the
TEMs got, stamped in device time where it took effect.
The line protocol is doc/explanation/protocol.md (sma_wrist/hw/protocol.py); a reader thread
(sma_wrist/hw/link.py) parses and reconnects with exponential backoff.

Measurements: every ``1 / publish_rate_hz`` of device time the samples of that window
(1 kHz) are calibrated (``adc.*``, ``calibration.*``: counts -> degC / rad) and published:
temperatures (the muscles and the TEMs' exchanger faces) as the window mean (variance = the window's), the angle
as the least-squares line's value at the window end and its slope, low-pass filtered over ``velocity_filter_s``,
as velocity. **The stresses and the effort are estimates**, not measurements: the SD-GPI
wire-load solve at the measured temperatures and angle (sma_wrist/hw/estimate.py), taken
through a Kalman filter first whose measurement noise is each window's own spread and whose
process noise is ``stress_filter.*`` (the stiff wires multiply the sensors' noise).

Time: the device clock is the graph's clock. /clock is the device time stamp of the last
sample of each window, rebased to 0 at the first sample and kept continuous (spliced one
window after the last published time) across device resets and reconnects. Samples are ordered
by their sequence number and timed by their stamp: a late line is dropped, a stamp that repeats or
trails a little (a millisecond clock) is taken at the newest time, and a boot flag or a stamp more
than 50 ms back is a device restart (doc/explanation/protocol.md). The other
nodes run with use_sim_time as with plant_sim, so an emulator running N x faster than
wall time (--time-scale) makes the whole graph run N x faster. The bridge itself runs on
its steady clock (use_sim_time false): its timer polls every half window; a tick waits
up to ``sample_wait_s`` (wall) for the window to complete, then publishes, except the first
tick after a publication, which takes only what has arrived: while a tick waits, the
executor takes no TEM command, and the commands answering a window arrive in the next
milliseconds (doc/explanation/runtime.md, "The hardware bridge and the executor"). On the embedded
runtime, whose steady clock is virtual, that wait is what paces the graph by the device:
nothing is published before the device sent it. If the host falls a window or more behind, the older windows
are skipped (counted), the newest complete one is published; data is never queued up into latency, so a command
takes effect within a window of the one it answers.

Safety, checked every tick; any fault sends 0 V to both TEMs (the device's own watchdog
also zeroes the drive without commands) and reports ERROR on /diagnostics until it clears:

* no valid sample for ``sensor_timeout_s`` of wall time (unplugged, silent, garbage only);
* a muscle above ``max_muscle_temperature_C`` or a TEM face above
  ``max_tem_face_temperature_C`` (clears ``over_temperature_hysteresis_C`` lower);
* angle outside [``angle_min_rad``, ``angle_max_rad``];
* an ADC channel at 0 or full scale (open thermocouple, broken wiper) or a non-finite value;
* a muscle thermocouple whose reading stays exactly the same for ``stuck_sensor_s`` while its
  TEM is driven one way harder than ``stuck_sensor_drive_V`` on average (a stuck converter or sensor:
  the over-temperature limit cannot see through it); until the reading changes
  (sma_wrist/hw/safety.py). Its samples are not published.

Commands: clipped to [``u_min_V``, ``u_max_V``]; NaN/inf commands are rejected and that
TEM gets 0 V until a finite one arrives; a command older than ``command_timeout_s`` (sim
time) is replaced by 0 V. Serial faults (garbage, bad checksums, cut lines, resets,
unplug) never reach the topics: only CRC-checked, in-range, in-sequence samples do.
"""

from __future__ import annotations

import math
import queue
from collections.abc import Mapping
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.time import Time
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState, Temperature
from std_msgs.msg import Float64

from sma_wrist.contract import PAYLOAD_RANGE_KG
from sma_wrist.core.errors import SmaWristError
from sma_wrist.core.plant.wrist import PlantParams
from sma_wrist.hw import protocol as P
from sma_wrist.hw.calibration import Calibration, Wiring
from sma_wrist.hw.estimate import StressEstimator, slope
from sma_wrist.hw.link import SerialLink
from sma_wrist.hw.safety import StuckSensor
from sma_wrist.nodes.common import (
    HYSTERESIS_FILE_PARAM,
    LOG_THROTTLE_S,
    PRELOAD_PARAM,
    Param,
    WristNode,
    finite,
    main_for,
)

#: while the TEMs are off for a fault, a reminder is logged this often (wall time) [s]
FAULT_REMINDER_S = LOG_THROTTLE_S
#: how far before a window's edge [s] a sample still closes it: timestamp jitter, well under a sample period
WINDOW_EDGE_TOLERANCE_S = 1e-4
#: a sample whose stamp is further back than this [us] (without being a repeat) is from a restarted device;
#: late lines, millisecond clocks and interrupt latency stay well within it
REORDER_TOLERANCE_US = 50_000
HELLO_WAIT_S = 0.5  # after connecting, samples before the device's hello (or this long, wall) are stale
OK, WARN, ERROR = DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR


class HardwareBridge(WristNode):
    OWNS_CLOCK = True
    #: the serial link; its ``clock`` is the bridge's wall time (a test gives one that reads a pty on a clock it drives)
    LINK: type[SerialLink] = SerialLink
    PARAMS = (
        Param('port', '/dev/ttyACM0', 'serial port (or pyserial URL) of the wrist controller', runtime=False),
        Param(
            'baud_rate',
            921600,
            'serial baud rate (1 kHz samples need >= 921600; ignored by USB CDC/pty)',
            'bit/s',
            (9600, 4000000),
            runtime=False,
        ),
        Param(
            'payload_kg',
            0.3,
            'payload mass M at the lever l = 0.09 m, as mounted (published latched)',
            'kg',
            PAYLOAD_RANGE_KG,
        ),
        Param(
            'publish_rate_hz',
            100.0,
            'rate of /clock and of the measurements, in device time',
            'Hz',
            (1.0, 500.0),
            runtime=False,
        ),
        # the wire behind the stress estimate (hw/estimate.py): identify writes both into wrist_params.yaml
        HYSTERESIS_FILE_PARAM,
        PRELOAD_PARAM,
        Param(
            'sample_wait_s',
            0.05,
            'longest a tick waits for the device to complete a window (wall time)',
            's',
            (0.001, 1.0),
        ),
        Param(
            'max_backlog_windows',
            5,
            'device time jumping further than this many windows between two samples: samples lost, time spliced',
            '',
            (1, 1000),
        ),
        Param(
            'sensor_timeout_s', 0.1, 'no valid sample for this long (wall time): TEMs off, ERROR', 's', (0.005, 10.0)
        ),
        Param(
            'stuck_sensor_s',
            5.0,
            'a muscle thermocouple reading exactly the same this long (device time) while '
            'its TEM is driven harder than stuck_sensor_drive_V: a stuck sensor, TEMs off, ERROR, not published '
            '(0: off)',
            's',
            (0.0, 600.0),
        ),
        Param(
            'stuck_sensor_drive_V',
            18.0,
            'mean TEM drive (one way, over about stuck_sensor_s) beyond which an '
            'unchanged reading is a stuck sensor: beyond the drive that holds any temperature (~13 V), it moves a '
            'muscle by degrees in that time',
            'V',
            (0.0, 30.0),
        ),
        Param(
            'command_timeout_s', 0.5, 'a TEM command older than this (sim time) is replaced by 0 V', 's', (0.01, 60.0)
        ),
        Param('max_muscle_temperature_C', 90.0, 'muscle over-temperature: TEMs off above this', 'degC', (30.0, 120.0)),
        Param(
            'max_tem_face_temperature_C',
            85.0,
            'TEM exchanger-face over-temperature: TEMs off above this',
            'degC',
            (30.0, 150.0),
        ),
        Param(
            'over_temperature_hysteresis_C',
            5.0,
            'an over-temperature clears this far below its limit',
            'degC',
            (0.0, 30.0),
        ),
        Param('angle_min_rad', -0.45, 'angle below this (past the -0.35 rad stop): TEMs off', 'rad', (-3.2, 3.2)),
        Param('angle_max_rad', 1.5, 'angle above this (past the 1.40 rad stop): TEMs off', 'rad', (-3.2, 3.2)),
        Param('u_min_V', -24.0, 'most negative TEM command sent (driver rating, cooling)', 'V', (-30.0, 0.0)),
        Param('u_max_V', 24.0, 'most positive TEM command sent (driver rating, heating)', 'V', (0.0, 30.0)),
        Param('velocity_filter_s', 0.02, 'time constant of the velocity low-pass', 's', (0.0, 1.0)),
        # the stress estimate's input filter (hw/estimate.py InputFilter): how far the true values may wander
        Param(
            'stress_filter.temperature_drift_C',
            0.175,
            'muscle temperature random walk per sqrt(s) the stress '
            "estimate's Kalman filter assumes (larger: follows faster, smooths less)",
            'degC',
            (1e-4, 100.0),
        ),
        Param(
            'stress_filter.angle_drift_rad',
            0.00275,
            'joint angle random walk per sqrt(s) the stress '
            "estimate's Kalman filter assumes (larger: follows faster, smooths less)",
            'rad',
            (1e-6, 10.0),
        ),
        Param(
            'reconnect_backoff_initial_s',
            0.05,
            'first reconnect delay; doubles per failure',
            's',
            (0.001, 10.0),
            runtime=False,
        ),
        Param('reconnect_backoff_max_s', 2.0, 'longest reconnect delay', 's', (0.01, 60.0), runtime=False),
        Param(
            'silence_reconnect_s',
            1.0,
            'reopen the port after this long without a valid frame (wall)',
            's',
            (0.05, 60.0),
            runtime=False,
        ),
        Param(
            'adc.temperature_gain_C_per_count', 0.004, 'thermocouple channels: degC per ADC count', 'degC', (1e-5, 1.0)
        ),
        Param(
            'adc.temperature_zero_C', -50.0, 'thermocouple channels: temperature at count 0', 'degC', (-300.0, 300.0)
        ),
        Param('calibration.muscle_1_offset_C', 0.0, 'thermocouple offset added to muscle 1', 'degC', (-20.0, 20.0)),
        Param('calibration.muscle_2_offset_C', 0.0, 'thermocouple offset added to muscle 2', 'degC', (-20.0, 20.0)),
        Param(
            'calibration.tem_face_1_offset_C',
            0.0,
            'thermocouple offset added to TEM 1 exchanger face',
            'degC',
            (-20.0, 20.0),
        ),
        Param(
            'calibration.tem_face_2_offset_C',
            0.0,
            'thermocouple offset added to TEM 2 exchanger face',
            'degC',
            (-20.0, 20.0),
        ),
        Param('calibration.angle_gain_rad_per_count', 1e-4, 'potentiometer gain', 'rad', (-1e-2, 1e-2)),
        Param('calibration.angle_offset_rad', -3.2768, 'angle at count 0', 'rad', (-10.0, 10.0)),
        # the wiring (hw/calibration.py Wiring): a wrist wired otherwise than doc/explanation/protocol.md, corrected in software;
        # sma-wrist commission measures them and writes them into its wrist_params.yaml (doc/howto/commission.md)
        Param(
            'calibration.tem_sign',
            [1, 1],
            "per muscle, the sign of its TEM's drive: -1 where the TEM's two leads "
            'are swapped (a positive drive of its driver output cools the muscle); each 1 or -1',
        ),
        Param(
            'calibration.tem_channel_map',
            [1, 2],
            "per muscle, the driver output (the C frame's u1 = 1, u2 = 2) "
            "wired to its TEM: [1, 2] as documented, [2, 1] with the TEMs' drive wires swapped",
        ),
        Param(
            'calibration.thermocouple_map',
            [1, 2],
            "per muscle, the ADC channel (the S frame's adc_T1 = 1, "
            'adc_T2 = 2) of its thermocouple: [1, 2] as documented, [2, 1] with the thermocouples swapped',
        ),
    )

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('hardware_bridge', **kwargs)
        p = self.p
        self.cal = self._calibration(p)
        self.wiring = Wiring.from_params(p)
        self.period_s = 1.0 / p['publish_rate_hz']
        self.command_V = np.zeros(2)
        self._cmd_t: list[float | None] = [None, None]  # sim time [s] of the last good command per TEM
        self._ticks_since_pub = 1  # timer ticks since the last window went out (none went out yet)
        # the stresses are the wire model's (the device measures none): the identified wire's when given
        self.estimator = StressEstimator(
            PlantParams.from_files(p['hysteresis_file'], preload_elongation_mm=p['preload_elongation_mm']),
            payload_kg=p['payload_kg'],
            drift=self._drift(),
        )
        self.seq = P.SequenceTracker()
        self.counters = {
            'samples': 0,
            'windows': 0,
            'windows_skipped': 0,
            'resets': 0,
            'time_gaps': 0,
            'out_of_order': 0,
            'stale_discarded': 0,
            'invalid_samples': 0,
            'safe_ticks': 0,
            'rejected_samples': 0,
            'windows_withheld': 0,
        }
        # (sim t [s], temps (4,), q, usable, the drive muscle 1's and 2's TEMs got over the sample's period [V] or
        # None): a sample rejected for safety keeps time but is no measurement; its drive is still what was applied
        self._window: list[tuple[float, tuple[float, ...], float, bool, tuple[float, float] | None]] = []
        self._last_t_us: int | None = None
        self._drive_from_s: float | None = None  # device time from which the next applied drive message holds
        self._anchor: tuple[int, float] | None = None  # (device t_us, sim s) of the time base
        self._last_pub_s: float | None = None
        self._est_t_s: float | None = None  # device time of the stress estimate's last input
        self._next_pub_s = 0.0
        self._last_valid_wall: float | None = None
        self._latest: tuple[tuple[float, ...], float, bool] | None = None  # temps, q, adc at a rail
        self._hot = False
        self._stuck = StuckSensor(2, p['stuck_sensor_s'], p['stuck_sensor_drive_V'])  # muscle thermocouples
        self._sent_V = [0.0, 0.0]  # the drive last sent to the device [V]
        self._qd = 0.0
        self._device = ''
        self._await_hello_until = 0.0
        self._diag_wall = 0.0
        self._line_at_sample = (0, 0)  # the parser's (version mismatches, rejected lines + garbage) at the last sample
        self._prev_end: tuple[float, float] | None = None  # (t, q) at the end of the last published window

        self.pub_clock = self.publisher('/clock')
        self.pub_joint = self.publisher('/wrist/joint_states')
        self.pub_temp = [self.publisher(f'/wrist/muscle_{i}/temperature') for i in (1, 2)]
        self.pub_face = [self.publisher(f'/wrist/tem_{i}/face_temperature') for i in (1, 2)]
        self.pub_stress = [self.publisher(f'/wrist/muscle_{i}/stress') for i in (1, 2)]
        self.pub_payload = self.publisher('/wrist/payload')
        self.pub_drive = self.publisher('/wrist/tem_drive_applied')
        for i in (1, 2):
            self.subscription(f'/wrist/tem_{i}/command', lambda msg, i=i: self._on_command(i, msg))
        self._publish_payload()
        self.link = self.LINK(
            p['port'],
            p['baud_rate'],
            backoff_initial_s=p['reconnect_backoff_initial_s'],
            backoff_max_s=p['reconnect_backoff_max_s'],
            silence_s=p['silence_reconnect_s'],
        )
        self.wall = self.link.clock  # the time base of the link's events: every wall-time limit is read on it
        self.timer = self.create_timer(0.5 * self.period_s, self._tick)
        self.link.start()
        self.get_logger().info(
            f'hardware_bridge: port {p["port"]} at {p["baud_rate"]} bit/s, publishing at '
            f'{p["publish_rate_hz"]:g} Hz of device time, payload {p["payload_kg"]} kg'
        )

    def destroy_node(self) -> None:
        link = getattr(self, 'link', None)
        if link is not None:
            try:
                link.send_command(0.0, 0.0)
            finally:
                link.stop()
        super().destroy_node()

    # -- parameters ------------------------------------------------------------
    @staticmethod
    def _calibration(p: Mapping[str, Any]) -> Calibration:
        return Calibration(
            p['adc.temperature_gain_C_per_count'],
            p['adc.temperature_zero_C'],
            (
                p['calibration.muscle_1_offset_C'],
                p['calibration.muscle_2_offset_C'],
                p['calibration.tem_face_1_offset_C'],
                p['calibration.tem_face_2_offset_C'],
            ),
            p['calibration.angle_gain_rad_per_count'],
            p['calibration.angle_offset_rad'],
        )

    def validate(self, values: Mapping[str, Any]) -> str | None:
        problem = super().validate(values)
        if problem:
            return problem
        if not values['angle_min_rad'] < values['angle_max_rad']:
            return f'angle_min_rad {values["angle_min_rad"]} must be below angle_max_rad {values["angle_max_rad"]}'
        if values['calibration.angle_gain_rad_per_count'] == 0.0:
            return 'calibration.angle_gain_rad_per_count must not be 0'
        try:
            wiring_problem = Wiring.from_params(values).problem()
        except (TypeError, ValueError):
            wiring_problem = 'calibration.tem_sign, tem_channel_map and thermocouple_map must be lists of integers'
        if wiring_problem:
            return wiring_problem
        if not values['reconnect_backoff_initial_s'] <= values['reconnect_backoff_max_s']:
            return 'reconnect_backoff_initial_s must not exceed reconnect_backoff_max_s'
        if not isinstance(values['port'], str) or not values['port'].strip():
            return 'port must be a non-empty string'
        return None

    def apply(self, changed: Mapping[str, Any]) -> None:
        if any(k.startswith(('adc.', 'calibration.')) for k in changed):
            self.cal = self._calibration(self.p)
            self.wiring = Wiring.from_params(self.p)
        if 'payload_kg' in changed:
            self._publish_payload()
        if any(k.startswith('stress_filter.') for k in changed):
            self.estimator.filter.set_drift(self._drift())
        if any(k.startswith('stuck_sensor_') for k in changed):
            self._stuck.set_limits(self.p['stuck_sensor_s'], self.p['stuck_sensor_drive_V'])

    # -- inputs ----------------------------------------------------------------
    def _on_command(self, i: int, msg: Any) -> None:
        if not finite(msg.data):
            self.command_V[i - 1] = 0.0  # hardware: a garbled command turns that TEM off, not "keep last"
            self.reject_input(f'tem_{i}/command', f'non-finite command {msg.data!r} V: TEM {i} off')
            return
        self.command_V[i - 1] = msg.data
        self._cmd_t[i - 1] = self._last_pub_s if self._last_pub_s is not None else 0.0
        self._send()

    # -- serial events ---------------------------------------------------------
    def _resync(self) -> None:
        """Forget the time base and the open window (device reset, reconnect, time went back)."""
        self._anchor = None
        self._window.clear()
        self._drive_from_s = None
        self._last_t_us = None
        self._prev_end = None
        self.seq.restart()

    def _handle(self, ev: tuple[str, float, Any]) -> None:
        kind, wall, x = ev
        if kind == 'connected':
            self._resync()
            # bytes the device wrote before we opened the port are stale: use samples only after the
            # hello that answers the link's query (or after hello_wait_s if the device never answers)
            self._await_hello_until = wall + HELLO_WAIT_S
            self.diagnose('link', OK, f'connected to {x}')
            return
        if kind == 'disconnected':
            self._resync()
            self.diagnose('link', ERROR, f'serial link lost ({x}); reconnecting with backoff')
            return
        if isinstance(x, P.Sample):
            self._on_sample(x, wall)
        elif isinstance(x, P.Reset):
            self._device_restarted(x.reason)
        elif isinstance(x, P.Hello):
            self._await_hello_until = 0.0
            # the drive read-back (a device without it ignores the request): a hello follows every boot and connect
            self.link.send(P.DriveReadback(True))
            self._device = f'{x.device_id} {x.firmware} at {x.rate_hz} Hz'
            slow = self._slow_device(x.rate_hz)
            self.diagnose(
                'device',
                WARN if slow else OK,
                f'device {self._device}, protocol v{x.version}' + (': ' + '; '.join(slow) if slow else ''),
            )
        elif isinstance(x, P.Error):
            self.diagnose('device', WARN, f'device error {x.code}: {x.text}')

    def _slow_device(self, rate_hz: int) -> list[str]:
        """What a device sampling at ``rate_hz`` leaves unmet of this bridge's settings (empty: nothing)."""
        p = self.p
        out = []
        if rate_hz < 2.0 * p['publish_rate_hz']:  # a one-sample window has no spread and no slope
            out.append(
                f'under two samples per publish window: lower publish_rate_hz ({p["publish_rate_hz"]:g}) to '
                f'{rate_hz / 2.0:g} or less (velocity is taken between windows meanwhile)'
            )
        if 2.0 / rate_hz > p['sensor_timeout_s']:  # one late sample would turn the TEMs off
            out.append(
                f'sensor_timeout_s ({p["sensor_timeout_s"]:g} s) is under two sample periods: raise it to '
                f'{2.0 / rate_hz:g} s or more'
            )
        return out

    def why_no_data(self) -> str:
        """Why no valid sample arrives, where the bridge can tell ('' if it cannot): a port that does not open (a
        wrong port:= said only 'sensor timeout' under Humble), or a line that carries no usable sample (a device on
        another protocol version or baud rate)."""
        ls = self.link.stats
        if not self.link.connected and ls.open_failures and ls.last_error.startswith('open '):
            # no count of the tries in the text: a text that changes is logged again (their count is on /diagnostics)
            return f'the port does not open ({ls.last_error}): check port:= and that the device is plugged in'
        st = self.link.parser.stats
        seen = self._line_at_sample
        if st.version_mismatch > seen[0]:
            return (
                f'the device speaks protocol version {self.link.parser.foreign_version}, this bridge '
                f'{P.PROTOCOL_VERSION} '
                f'({st.version_mismatch - seen[0]} frames ignored): update the firmware or sma_wrist to match'
            )
        bad = st.rejected_lines + st.garbage_bytes - seen[1]
        if bad > 0:
            return (
                'bytes arrive but no valid sample (bad checksums, cut or malformed lines, garbage): check the '
                'baud rate, the port and doc/explanation/protocol.md'
            )
        return ''

    def _device_restarted(self, why: str) -> None:
        self.counters['resets'] += 1
        self._resync()
        self.link.send(P.DriveReadback(True))  # a reboot forgets it (its hello may have been lost with the reset line)
        self.diagnose('device', WARN, f'device reset ({why}); time base spliced', {'resets': self.counters['resets']})

    def _on_sample(self, s: P.Sample, wall: float) -> None:
        if wall < self._await_hello_until:
            self.counters['stale_discarded'] += 1
            return
        last_t = self._last_t_us
        if (
            last_t is not None
            and s.seq != self.seq.last
            and (s.flags & P.FLAG_BOOT or last_t - s.t_us > REORDER_TOLERANCE_US)
        ):
            # a boot sample, or device time far back: the device restarted and its reset line was lost (or its
            # clock wrapped). A late line or a coarse clock goes back a little, never this far.
            self._device_restarted(
                'no reset line; '
                + (
                    'a boot flag'
                    if s.flags & P.FLAG_BOOT
                    else f'device time went back {(last_t - s.t_us) * 1e-6:.3f} s'
                )
            )
            last_t = None
        gap = self.seq.update(s.seq)
        if last_t is not None and gap < 0:  # a repeated or late (reordered) line: its window may be gone
            self.counters['out_of_order'] += 1
            return
        if last_t is not None and s.t_us - last_t > 1e6 * self.p['max_backlog_windows'] * self.period_s:
            # device time jumped (samples lost in an overrun or a stall): splice, /clock stays continuous
            self.counters['time_gaps'] += 1
            self._resync()
            self.seq.update(s.seq)
            last_t = None
        temps, q = self.cal.to_physical_fast(self.wiring.muscle_counts(s.adc))  # muscle i's thermocouple first
        rail = min(s.adc) == 0 or max(s.adc) == P.ADC_MAX
        if not (math.isfinite(sum(temps)) and math.isfinite(q)):
            self.counters['invalid_samples'] += 1
            return
        # a newer sample whose stamp repeats or trails a little (a millisecond clock, interrupt latency) is taken
        # at the newest time: the sequence number orders samples, the stamp only times them
        t_us = s.t_us if last_t is None else max(s.t_us, last_t)
        self._last_t_us = t_us
        if self._anchor is None:
            start = 0.0 if self._last_pub_s is None else self._last_pub_s + self.period_s
            self._anchor = (t_us, start)
            self._next_pub_s = start
        t = self._anchor[1] + (t_us - self._anchor[0]) * 1e-6
        # the safety check sees every sample (_latest); a railed channel or an angle outside the safe
        # range is a faulty reading, never published as a measurement
        stuck = any(self._stuck.update(t, temps[:2], self._sent_V))
        usable = not rail and not stuck and self.p['angle_min_rad'] <= q <= self.p['angle_max_rad']
        self.counters['rejected_samples'] += not usable
        drive = None if s.drive_mV is None else self.wiring.muscle_drive(1e-3 * s.drive_mV[0], 1e-3 * s.drive_mV[1])
        self._window.append((t, temps, q, usable, drive))
        self._latest = (temps, q, rail)
        self._device_cut(s.flags)
        self._last_valid_wall = wall
        st = self.link.parser.stats
        self._line_at_sample = (st.version_mismatch, st.rejected_lines + st.garbage_bytes)
        self.counters['samples'] += 1

    def _device_cut(self, flags: int) -> None:
        """The device's own over-temperature cut (FLAG_OVERTEMP) on /diagnostics: the controllers' commands do not
        reach the TEMs while it lasts, and nothing else said so. (Its watchdog flag is set at every start, before
        the first command arrives; the bridge's own timeouts cover a host that stops commanding.)"""
        cut = bool(flags & P.FLAG_OVERTEMP)
        self.diagnose(
            'device_drive',
            WARN if cut else OK,
            'the device cut the TEM drive on its own over-temperature check' if cut else 'the device drives the TEMs',
        )

    # -- the tick ----------------------------------------------------------------
    def _window_ready(self) -> bool:
        # a sample a few microseconds early (a timer read in an interrupt) still closes the window on its grid point
        return bool(self._window) and self._window[-1][0] >= self._next_pub_s - WINDOW_EDGE_TOLERANCE_S

    def _tick(self) -> None:
        events = self.link.events
        # right after a window went out, the controllers' answer to it (the TEM commands) is on its way: a tick that
        # blocked on the device now would hold that answer in the executor's queue (rclpy runs one callback at a
        # time) until the next window is out, a window of extra loop delay. So the first tick after a publication
        # only takes what has arrived; the next one (half a window later) waits, and windows still go out as
        # they complete. (The commands carry no stamp: which window one answers cannot be told.)
        wait_s = self.p['sample_wait_s'] if self._ticks_since_pub > 0 else 0.0
        self._ticks_since_pub += 1
        deadline = self.wall() + wait_s
        # a whole window of 1 kHz samples queued behind a complete one: the device is a window or more ahead of
        # what would go out, and the controllers' answer would take effect that much later than the window it answers
        # (its stamp in a bag). Read on and publish the newest complete window (the older ones skipped, counted).
        # Letting up to 5 windows through drove a graph that started 40 ms behind a streaming device 40 ms after the
        # windows its commands answered, and a diagnosis of a nominal run found the TEMs' heat late
        # (test_hardware_bridge.py::test_a_graph_that_starts_behind_the_device_drives_it_at_the_window_it_answers)
        backlog = self.period_s * 1000.0
        while True:
            if self._window_ready():
                if events.qsize() < backlog:
                    break
                self._next_pub_s += self.period_s  # a newer window is complete in the queue: this one is skipped
                self.counters['windows_skipped'] += 1
            try:
                ev = events.get_nowait()
            except queue.Empty:
                if self._window_ready():
                    break
                remaining = deadline - self.wall()
                if remaining <= 0:
                    break
                try:
                    ev = self.link.next_event(remaining)
                except queue.Empty:
                    break
            self._handle(ev)
        if self._window_ready():
            self._publish_window()
        self._check_safety()
        self._send()
        self._report()

    def _drift(self) -> tuple[float, float, float]:
        d_T, d_q = self.p['stress_filter.temperature_drift_C'], self.p['stress_filter.angle_drift_rad']
        return d_T, d_T, d_q

    def _publish_window(self) -> None:
        t_end = self._window[-1][0]
        w = [x for x in self._window if x[0] > t_end - self.period_s + 1e-9]
        skipped = int((t_end - self._next_pub_s) / self.period_s + 1e-9)
        self._ticks_since_pub = 0
        self.counters['windows_skipped'] += max(0, skipped)
        self._publish_drive(t_end)
        self._window.clear()
        first = self._last_pub_s is None
        self._last_pub_s = t_end
        # the next edge on the fixed grid: from t_end, each window started where the last overshot, and a few
        # microseconds of timestamp jitter cost one sample per window and 5 % of the windows
        self._next_pub_s += self.period_s * (max(0, skipped) + 1)
        stamp = Time(nanoseconds=int(round(t_end * 1e9))).to_msg()
        self.pub_clock.publish(Clock(clock=stamp))  # device time goes on: the graph's clock keeps running
        w = [x for x in w if x[3]]
        if not w:
            self.counters['windows_withheld'] += 1
            self.diagnose(
                'measurement',
                ERROR,
                'every sample of the window was rejected for safety '
                '(ADC at 0 or full scale, angle outside the safe range, or a stuck thermocouple): nothing '
                'published',
                {
                    'rejected_samples': self.counters['rejected_samples'],
                    'windows_withheld': self.counters['windows_withheld'],
                },
            )
            return
        t = np.array([x[0] for x in w])
        temps = np.array([x[1] for x in w])
        qs = np.array([x[2] for x in w])
        q, qd_raw, q_var = slope(t, qs)
        if len(w) < 2 and self._prev_end is not None and t[-1] > self._prev_end[0]:  # a slow device: no slope within
            qd_raw = (q - self._prev_end[1]) / (t[-1] - self._prev_end[0])
        self._prev_end = (float(t[-1]), q)
        tau = self.p['velocity_filter_s']
        a = 1.0 if tau <= 0 or first else self.period_s / (tau + self.period_s)
        self._qd += a * (qd_raw - self._qd)
        T = temps.mean(axis=0)
        var = temps.var(axis=0) if len(w) > 1 else np.zeros(4)
        estimate = None
        if all(math.isfinite(v) for v in (*T, *var, q, self._qd)):  # a NaN would stay in the estimate's filter
            t_est, self._est_t_s = self._est_t_s, t_end  # withheld windows leave a longer step
            estimate = self.estimator.update(
                float(T[0]),
                float(T[1]),
                q,
                dt_s=self.period_s if t_est is None else t_end - t_est,
                variance=(var[0] / len(w), var[1] / len(w), q_var),
            )
        if estimate is None or not all(math.isfinite(v) for v in estimate):
            self.counters['invalid_samples'] += len(w)
            self.diagnose('estimate', ERROR, 'non-finite value in a window: not published')
            return
        s1, s2, torque = estimate
        self.diagnose('measurement', OK, 'published')
        self.counters['windows'] += 1
        for i in range(2):
            msg = Temperature(temperature=float(T[i]), variance=float(var[i]))
            msg.header.stamp = stamp
            msg.header.frame_id = f'muscle_{i + 1}'
            self.pub_temp[i].publish(msg)
            # the TEM's exchanger face (the T2 face of Eq. 4.14): the heat-balance state a diagnosis replay starts
            # from; from the same usable samples as the muscles (a sample rejected for safety is no measurement)
            face = Temperature(temperature=float(T[2 + i]), variance=float(var[2 + i]))
            face.header.stamp = stamp
            face.header.frame_id = f'tem_{i + 1}'
            self.pub_face[i].publish(face)
        for i, s in enumerate((s1, s2)):
            self.pub_stress[i].publish(Float64(data=float(s)))
        js = JointState(
            name=[self.contract.joint_name], position=[float(q)], velocity=[float(self._qd)], effort=[float(torque)]
        )
        js.header.stamp = stamp
        js.header.frame_id = self.contract.frame_id
        self.pub_joint.publish(js)

    def _publish_drive(self, t_end: float) -> None:
        """The drive the device read back, one message per window of device time up to ``t_end`` (the skipped ones
        too): the drive in force at the window's middle [V] per muscle, stamped with the window's start (the last
        window's stamp). That is the convention of a command, which drives the wrist from its stamp to the next, but
        at the device time the drive took effect rather than at the window a command answered; a bag of a graph
        whose answers reach the device late replays right with it (sma_wrist/diagnose/data.py prefers it).

        The middle, not the window's mean: the heat balance has a Joule term (K_R I^2, Eqs. 4.13-4.14), and a drive
        that changes sign inside a window averages to less than its heat (on the emulated device driven with a
        command every ~4 ms, a replay of the means read 6.6 degC too cold; of the middles 0.004 degC, 0.41 RMS)."""
        start = self._drive_from_s if self._drive_from_s is not None else t_end - self.period_s
        self._drive_from_s = t_end
        if start < 0.0:  # the first window, at time 0, has no time before it to hold from
            return
        drive = [(x[0], x[4]) for x in self._window if x[4] is not None and x[0] > start + 1e-9]
        k = 0
        for j in range(max(1, int(round((t_end - start) / self.period_s)))):
            t0 = start + j * self.period_s
            mid = t0 + 0.5 * self.period_s  # a sample holds the drive over the sample period it ends
            while k < len(drive) and drive[k][0] < mid - 1e-9:
                k += 1
            if k == len(drive):  # a device without the read-back: the commands are what a bag has
                return
            if drive[k][0] > t0 + self.period_s + 1e-9:  # no sample of this window (lost): nothing to say
                continue
            msg = JointState(name=['tem_1', 'tem_2'], effort=[float(drive[k][1][0]), float(drive[k][1][1])])
            msg.header.stamp = Time(nanoseconds=int(round(t0 * 1e9))).to_msg()
            msg.header.frame_id = self.contract.frame_id
            self.pub_drive.publish(msg)

    def diagnostics_stamp(self) -> Any:
        """Device time of the last published window, as the measurements and /clock (the steady
        clock the bridge polls on is another time base)."""
        t = getattr(self, '_last_pub_s', None)
        return Time(nanoseconds=int(round((t or 0.0) * 1e9))).to_msg()

    # -- safety ----------------------------------------------------------------
    def faults(self) -> list[str]:
        """Reasons the TEMs must be off now (empty: normal operation)."""
        p = self.p
        out = []
        now = self.wall()
        if self._last_valid_wall is None or now - self._last_valid_wall > p['sensor_timeout_s']:
            # a fixed text: the age is in the status values (a text changing every tick was one log line per tick)
            why = self.why_no_data()
            out.append(
                f'sensor timeout (no valid sample for more than {p["sensor_timeout_s"]:g} s)'
                + (f': {why}' if why else '')
            )
            return out
        assert self._latest is not None
        temps, q, rail = self._latest
        hyst = p['over_temperature_hysteresis_C'] if self._hot else 0.0
        hot_m = max(temps[:2]) > p['max_muscle_temperature_C'] - hyst
        hot_f = max(temps[2:]) > p['max_tem_face_temperature_C'] - hyst
        self._hot = bool(hot_m or hot_f)
        if hot_m:
            out.append(f'muscle over-temperature ({max(temps[:2]):.1f} degC, limit {p["max_muscle_temperature_C"]})')
        if hot_f:
            out.append(
                f'TEM face over-temperature ({max(temps[2:]):.1f} degC, limit {p["max_tem_face_temperature_C"]})'
            )
        if not p['angle_min_rad'] <= q <= p['angle_max_rad']:
            out.append(f'angle {q:.3f} rad outside [{p["angle_min_rad"]}, {p["angle_max_rad"]}]')
        if rail:
            out.append('ADC channel at 0 or full scale (open or shorted sensor)')
        for i, stuck in enumerate(self._stuck.stuck):
            if stuck:
                out.append(
                    f'muscle {i + 1} thermocouple stuck (the same reading for over {p["stuck_sensor_s"]:g} s '
                    f'while its TEM was driven one way at over {p["stuck_sensor_drive_V"]:g} V on average)'
                )
        return out

    def _check_safety(self) -> None:
        self._faults = self.faults()
        if self._faults:
            self.counters['safe_ticks'] += 1
            self.diagnose('safety', ERROR, 'TEMs off: ' + '; '.join(self._faults), self.status_values())
            # the onset and the recovery are logged by diagnose; while the fault lasts, a reminder
            self.get_logger().error(
                f'TEMs still off: {"; ".join(self._faults)} (details on /diagnostics)',
                throttle_duration_sec=FAULT_REMINDER_S,
                skip_first=True,
            )
        else:
            self.diagnose('safety', OK, 'normal operation')

    def command_to_send(self) -> tuple[float, float]:
        """The drive [V] the device gets now: 0 in a fault, stale commands 0, else clipped."""
        if getattr(self, '_faults', None) is None:
            self._faults = self.faults()
        if self._faults:
            return 0.0, 0.0
        u = self.command_V.copy()
        now = self._last_pub_s if self._last_pub_s is not None else 0.0
        for i, t in enumerate(self._cmd_t):
            if t is None or now - t > self.p['command_timeout_s']:
                u[i] = 0.0
        u = np.clip(u, self.p['u_min_V'], self.p['u_max_V'])
        return float(u[0]), float(u[1])

    def _send(self) -> None:
        if self.link.connected:
            u1, u2 = self.command_to_send()
            self.link.send_command(*self.wiring.device_command(u1, u2))  # muscle i's TEM on its driver output
            self._sent_V[:] = (u1, u2)

    def status_values(self) -> dict[str, Any]:
        st = self.link.parser.stats
        age = None if self._last_valid_wall is None else round(self.wall() - self._last_valid_wall, 3)
        return {
            **self.counters,
            'last_valid_sample_age_s': age,
            'lost_samples': self.seq.lost,
            'bad_checksum': st.bad_checksum,
            'partial_lines': st.partial_lines,
            'malformed': st.malformed,
            'garbage_bytes': st.garbage_bytes,
            'version_mismatch': st.version_mismatch,
            'connects': self.link.stats.connects,
            'open_failures': self.link.stats.open_failures,
            'device': self._device,
            'stress': 'model estimate (SD-GPI load solve at measured T and angle)',
        }

    def _report(self) -> None:
        """Line statistics on /diagnostics about once per wall second (WARN while errors accrue)."""
        now = self.wall()
        if now - self._diag_wall < 1.0:
            return
        self._diag_wall = now
        v = self.status_values()
        bad = self.link.parser.stats.rejected_lines + self.seq.lost
        prev = getattr(self, '_bad_reported', 0)
        self._bad_reported = bad
        self.diagnose(
            'line',
            WARN if bad > prev else OK,
            f'{bad - prev} line errors / lost samples in the last second' if bad > prev else 'line clean',
            v,
        )

    def _publish_payload(self) -> None:
        self.pub_payload.publish(Float64(data=float(self.p['payload_kg'])))


def main(args: list[str] | None = None) -> int:
    return main_for(HardwareBridge, args)


if __name__ == '__main__':
    raise SystemExit(main())


__all__ = ['HardwareBridge', 'main', 'SmaWristError']
