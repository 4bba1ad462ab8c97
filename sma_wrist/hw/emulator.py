"""A device emulator on a pseudo-terminal: the wrist's microcontroller, with the simulated plant.

``sma-wrist emulate-device --port /tmp/wrist`` opens a pty, links its slave end at
``--port`` and behaves like the firmware of doc/explanation/protocol.md: boot notice and hello,
then ``$S`` samples at ``--rate-hz`` (1 kHz) of device time with 16-bit ADC quantisation
and Gaussian noise of the plant :class:`sma_wrist.core.plant.wrist.WristPlant` (the controllers' own
model), or with ``--plant`` of a registered plant that is not the model (:mod:`sma_wrist.plants`:
``phase_fraction`` a structurally different wire, ``sdgpi`` the model with a parameter spread), in the
scenario ``--scenario-file`` gives (its sensor lag and noise act on what the device reports), and with
``--params-file`` the wire, TEMs and pre-load plant_sim would simulate with those ROS params files (an
identified wire's ``wrist_params.yaml``); ``$C`` commands
take effect ``--latency-ms`` after they arrive; no command for ``--watchdog-s`` of device
time -> zero drive (flag ``FLAG_WATCHDOG``). Asked by a ``$D`` frame, every sample carries the drive applied over its
period (a firmware without the read-back: ``--no-drive-readback``). Device time runs ``--time-scale`` times
faster than wall time (the plant too), so a 126 s closed loop can take 25 s.

Fault injection (for tests and demos), from the command line as rates/periods, or from
Python with :meth:`DeviceEmulator.inject`: garbage bytes, checksum errors, cut lines,
resets, unplug (the pty's master is closed, the link removed; on replug the device
boots again on a new pty at the same link), freezes (no samples), forced ADC counts. Wiring faults of a wrist as
built (``--swap-tem-polarity N``, ``--swap-tem-channels``, ``--swap-thermocouples``, ``--reverse-angle``,
``--broken-wire N``; doc/explanation/protocol.md "Wiring"), for ``sma-wrist commission``. Effects that begin
mid-run (``--effect KIND:CHANNEL:VALUE@ONSET_S[+RAMP_S]``, :class:`Effect`: a sensor's offset, gain, lag or drift,
the TEMs weakening, a payload change, the coolant drifting, the wires' transitions drifting), for the twin
monitor (doc/howto/monitor.md); the largest drive a command asked
for is kept (``stats.max_abs_command_V``) and printed on exit. :meth:`DeviceEmulator.receive` /
:meth:`DeviceEmulator.emit` step the device in lockstep with a host that is no serial port.
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import math
import os
import signal
import threading
import time
import tty
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sma_wrist.cli_options import emulator_arguments as add_arguments
from sma_wrist.contract import PAYLOAD_RANGE_KG
from sma_wrist.core.errors import SmaWristError
from sma_wrist.hw import protocol as P
from sma_wrist.hw.calibration import Calibration, quantise

MAX_BACKLOG = 1 << 16  # bytes buffered for a host that does not read; beyond, output is dropped (UART overrun)
PACED_BACKLOG = 4096  # host_paced: beyond this many bytes unread (~0.1 s of samples) the device time waits


#: sensor effects (on muscle thermocouple T1 / T2 or the potentiometer q): offset [degC | rad], gain error [1] about
#: 25 degC / the neutral angle (as :mod:`sma_wrist.diagnose.distort`), first-order lag [s], drift [degC/h | rad/h]
SENSOR_EFFECTS = ('offset', 'gain', 'lag', 'drift')
SENSOR_CHANNELS = ('T1', 'T2', 'q')
#: plant effects (channel ``plant``), as :data:`sma_wrist.diagnose.distort.PLANT_SUBSYSTEM`: ``tem_weak`` both TEMs
#: lose this fraction of their Peltier terms, ``payload`` this mass [kg] is added, ``ambient_drift`` [degC/h],
#: ``transition_drift`` the wires transform this much hotter [degC] (reached over the ramp)
PLANT_EFFECTS = ('tem_weak', 'payload', 'ambient_drift', 'transition_drift')
EFFECT_SPEC = 'KIND:CHANNEL:VALUE@ONSET_S[+RAMP_S]'


@dataclass(frozen=True)
class Effect:
    """An effect that begins ``onset_s`` [s of device time] after the first command the device receives (the host
    starting to drive the wrist: the same time into every run) (``--effect KIND:CHANNEL:VALUE@ONSET_S[+RAMP_S]``)."""

    kind: str  # SENSOR_EFFECTS on SENSOR_CHANNELS, or PLANT_EFFECTS on 'plant'
    channel: str
    value: float
    onset_s: float
    ramp_s: float = 0.0  # transition_drift: reaches `value` this long after the onset

    @classmethod
    def parse(cls, spec: str) -> Effect:
        """``offset:T1:3@60``, ``transition_drift:plant:6@60+120``; ValueError saying what a spec looks like."""
        help_ = (
            f'--effect {spec!r}: expected {EFFECT_SPEC}, e.g. offset:T1:3@60 or transition_drift:plant:6@60+120; '
            f'KIND:CHANNEL one of {"/".join(SENSOR_EFFECTS)} on {"/".join(SENSOR_CHANNELS)}, or '
            f'{"/".join(PLANT_EFFECTS)} on plant'
        )
        try:
            head, when = spec.split('@')
            kind, channel, value = head.split(':')
            onset, _, ramp = when.partition('+')
            e = cls(kind.strip(), channel.strip(), float(value), float(onset), float(ramp) if ramp else 0.0)
        except ValueError:
            raise ValueError(help_) from None
        sensor = e.kind in SENSOR_EFFECTS and e.channel in SENSOR_CHANNELS
        plant = e.kind in PLANT_EFFECTS and e.channel == 'plant'
        if not (sensor or plant):
            raise ValueError(help_)
        if not all(math.isfinite(x) for x in (e.value, e.onset_s, e.ramp_s)) or e.onset_s < 0 or e.ramp_s < 0:
            raise ValueError(f'--effect {spec!r}: value, onset and ramp must be finite, onset and ramp >= 0')
        if e.ramp_s and e.kind != 'transition_drift':
            raise ValueError(f'--effect {spec!r}: only transition_drift takes a ramp (+RAMP_S)')
        if e.kind == 'lag' and e.value <= 0:
            raise ValueError(f'--effect {spec!r}: a lag is a time constant > 0 [s]')
        if e.kind == 'tem_weak' and not 0 <= e.value < 1:
            raise ValueError(f'--effect {spec!r}: tem_weak is the fraction the TEMs lose, in [0, 1)')
        if e.kind == 'transition_drift' and abs(e.value) > 15:
            raise ValueError(f'--effect {spec!r}: a transition drift within +-15 degC')
        return e


@dataclass
class EmulatorConfig:
    """Device behaviour. Times are device time [s] unless named wall."""

    rate_hz: float = 1000.0  # sample rate
    time_scale: float = 1.0  # device seconds per wall second
    payload_kg: float = 0.3
    noise_counts: float = 2.0  # Gaussian ADC noise, standard deviation [counts]
    latency_s: float = 0.001  # command -> drive delay
    watchdog_s: float = 0.5  # zero drive without a command for this long
    u_limit_V: float = 24.0  # driver rating; larger commands are clipped (FLAG_CLIPPED)
    seed: int = 0
    calibration: Calibration = field(default_factory=Calibration)
    device_id: str = 'sma-wrist-emulator'
    firmware: str = '1.0.0'
    # the firmware can read its drive back (doc/explanation/protocol.md, D frame): asked, every sample carries the
    # drive applied over its period. False: a firmware without it, which ignores the host's D frame
    drive_readback: bool = True
    # random faults per sample line (probabilities) and periodic events (device s, 0 = never)
    garbage_rate: float = 0.0
    checksum_error_rate: float = 0.0
    partial_rate: float = 0.0
    reset_every_s: float = 0.0
    unplug_every_s: float = 0.0
    unplug_wall_s: float = 0.5
    # the wrist behind the device: 'model' (WristPlant) or a registered plant (sma_wrist.plants.PLANTS) in the
    # scenario {perturbation: value} (sma_wrist.plants.spread.Scenario fields; a payload_kg there overrides the above)
    plant: str = 'model'
    scenario: dict[str, Any] = field(default_factory=dict)
    # its wire, TEMs, pre-load (a PlantParams; its dt is the emulator's): None = the built-in wrist
    base: Any = None
    # muscle thermocouples read by a converter chip (as a MAX31855: 0.25 degC steps, ~10 conversions a second):
    # each sample repeats the last conversion, rounded to the resolution, without the ADC's per-sample noise.
    # 0 = the thermocouples sampled through the ADC like the other channels
    thermocouple_rate_hz: float = 0.0
    thermocouple_resolution_C: float = 0.0
    # wiring faults of a wrist as built, what `sma-wrist commission` finds (doc/howto/commission.md): the host's
    # commands and the device's channels stay as doc/explanation/protocol.md says, the wires behind them do not
    tem_polarity_swapped: tuple[bool, bool] = (False, False)  # TEM i's leads swapped: its drive cools where it heated
    tem_channels_swapped: bool = False  # driver output 1 wired to TEM 2, output 2 to TEM 1
    thermocouples_swapped: bool = False  # ADC channel 1 reads muscle 2's thermocouple, channel 2 muscle 1's
    angle_reversed: bool = False  # the potentiometer's outer leads swapped: it reads 65535 - counts
    broken_wire: int = (
        0  # muscle 1 or 2 whose wire does not pull (broken, unhooked): heating it moves nothing (0: none)
    )
    # TEM i gets this fraction of its driver output's voltage (a weaker TEM, a lossy lead): unlike the scenario's
    # tem_gain_scale (both TEMs of a registered plant), one TEM alone can be off
    tem_drive_scale: tuple[float, float] = (1.0, 1.0)
    # device time waits for a host that falls behind (its line full) instead of overrunning it: a simulated device
    # serving a node graph in the same process (sma-wrist commission --sim's verification), where a busy machine
    # would otherwise drop the samples a real UART keeps streaming
    host_paced: bool = False
    # effects that begin mid-run (:class:`Effect`, ``--effect``): a sensor, the TEMs, the payload, the coolant or
    # the wires change that long after the first command, as a running wrist does
    effects: tuple[Effect, ...] = ()


@dataclass
class EmulatorStats:
    samples_sent: int = 0
    commands_received: int = 0
    bytes_dropped: int = 0
    bytes_written: int = 0  # to the line (the host can count what it must have read)
    bytes_received: int = 0  # from the line
    resets: int = 0
    unplugs: int = 0
    faults_injected: int = 0
    max_abs_command_V: float = 0.0  # the largest |drive| any command asked for (before the device's clipping)


class DeviceEmulator:
    """The emulated device. ``open()`` the pty, then ``start()`` (thread) or ``run()`` (blocking).

    Thread-safe control: :meth:`inject`, :meth:`stop`. ``sent_log`` (if enabled) keeps
    ``(wall time of ``clock`` when queued for writing, Sample)`` of every sample sent, for latency benchmarks.
    """

    def __init__(
        self,
        config: EmulatorConfig | None = None,
        link: str | None = None,
        log_sent: bool = False,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        from sma_wrist.core.plant.wrist import PlantParams, WristPlant

        self.clock = clock  # wall seconds: when samples are due (a test drives it and calls serve(), no thread)
        self.cfg = c = config or EmulatorConfig()
        if not (c.rate_hz > 0 and c.time_scale > 0):
            raise ValueError('rate_hz and time_scale must be > 0')
        self.link = link
        dt = min(1e-3, 1.0 / c.rate_hz)
        self.steps_per_sample = max(1, int(round(1.0 / (c.rate_hz * dt))))
        base = dataclasses.replace(c.base or PlantParams(), dt=1.0 / (c.rate_hz * self.steps_per_sample))
        self.sensors: Any = None  # a registered plant's scenario sensors (lag, noise) on what the device reports
        if c.plant == 'model':
            self.plant: Any = WristPlant(base, payload_kg=c.payload_kg)
        else:
            from sma_wrist.plants import make_plant
            from sma_wrist.plants.spread import Scenario, SensorBank

            sc = Scenario.from_mapping({'payload_kg': c.payload_kg, **c.scenario})
            self.plant = make_plant(c.plant, [sc], base)
            self.sensors = SensorBank([sc], 1.0 / c.rate_hz)
        if c.broken_wire not in (0, 1, 2):
            raise ValueError(f'broken_wire {c.broken_wire!r}: 0 (none), 1 or 2')
        if len(c.tem_drive_scale) != 2 or not all(0.0 < float(k) <= 2.0 for k in c.tem_drive_scale):
            raise ValueError(f'tem_drive_scale {c.tem_drive_scale!r}: two fractions in (0, 2]')
        # a broken wire: the joint is a second wrist's in which that muscle is never heated; the temperatures
        # are the first's (the TEM still heats the muscle, the wire no longer pulls)
        self._joint_plant: Any = copy.deepcopy(self.plant) if c.broken_wire else None
        # plant effects: (effect, plant, change(plant, s since the onset)); each plant (the broken wire's second wrist
        # too) changes by a closure of its own: a payload change remembers the mass that plant carried
        self._changes: list[tuple[Effect, Any, Callable[[Any, float], None]]] = []
        if any(e.kind in PLANT_EFFECTS for e in c.effects):
            if c.plant != 'model':
                raise ValueError(
                    f'plant effects (--effect {"/".join(PLANT_EFFECTS)}:plant:...) act on --plant model only'
                )
            from sma_wrist.diagnose.distort import plant_change

            for plant in (self.plant, self._joint_plant):
                if plant is not None:
                    self._changes += [
                        (e, plant, plant_change(e.kind, e.value, plant.params, e.ramp_s))
                        for e in c.effects
                        if e.kind in PLANT_EFFECTS
                    ]
        self._lagged: dict[int, float] = {}  # a lag effect's sensor reading (index in effects)
        # the effects' clock: samples since the first command arrived (the host started driving the wrist), so that
        # an onset means the same time into every run however long the host took to start; it runs on across resets
        self._effect_n: int | None = None
        self.rng = np.random.default_rng(c.seed)
        self.stats = EmulatorStats()
        self.parser = P.Parser()
        self.sent_log: list[tuple[float, P.Sample]] | None = [] if log_sent else None
        self.slave_path: str | None = None
        self._master: int | None = None
        self._slave: int | None = None
        self._out = bytearray()
        self._lock = threading.Lock()
        self._actions: deque[tuple[str, Any]] = deque()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._u = np.zeros((1, 2))  # drive in effect [V]
        self._pending: deque[tuple[float, np.ndarray]] = deque()  # (device time to apply, command)
        self._forced: dict[int, int] = {}
        self._freeze_until = 0.0  # wall
        self._corrupt = 0
        self._cut = 0
        self._boot()

    # ------------------------------------------------------------------ pty
    def open(self) -> str:
        """Open a new pty (raw, non-blocking master); link it at ``self.link``; return the slave path.

        The link replaces only an earlier symlink (a previous emulator's): a regular file or a device
        at ``--port`` is the user's, and os.replace would have deleted it (SmaWristError instead).
        """
        if self.link:
            folder = os.path.dirname(os.path.abspath(self.link))
            if not os.path.isdir(folder):
                raise SmaWristError(f'--port {self.link}: the folder {folder} does not exist')
            if os.path.lexists(self.link) and not os.path.islink(self.link):
                raise SmaWristError(
                    f'--port {self.link} exists and is not a symlink (a file, folder or device); '
                    'refusing to replace it: give a new path'
                )
        master, slave = os.openpty()
        tty.setraw(slave)
        os.set_blocking(master, False)
        self._master, self._slave = master, slave
        self.slave_path = os.ttyname(slave)
        if self.link:
            tmp = f'{self.link}.tmp{os.getpid()}'
            if os.path.lexists(tmp):
                os.unlink(tmp)
            os.symlink(self.slave_path, tmp)
            os.replace(tmp, self.link)
        return self.link or self.slave_path

    def close(self) -> None:
        """Unplug: close both pty ends (the host's reads fail) and remove the link."""
        if self.link and os.path.islink(self.link) and os.readlink(self.link) == self.slave_path:
            os.unlink(self.link)
        for fd in (self._master, self._slave):
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self._master = self._slave = None
        self._out.clear()

    # ------------------------------------------------------------------ device
    def _boot(self, reason: str = 'power') -> None:
        """(Re)boot: time and sequence restart at 0, drive off, boot notice + hello queued."""
        self._t_boot_wall = self.clock()
        self._n = 0  # samples since boot
        self._tc_next_s: float | None = None  # device time of the thermocouple chip's next conversion
        self._tc_held = np.zeros(2)
        self._last_cmd_t = -1e9
        self._u[:] = 0.0
        self._pending.clear()
        self._readback = False  # the host asks for the drive read-back again after each boot
        self.parser.reset()
        self._out += P.encode(P.Reset(reason)) + P.encode(
            P.Hello(self.cfg.device_id, self.cfg.firmware, int(round(self.cfg.rate_hz)))
        )
        self._boot_flag = True

    @property
    def device_time_s(self) -> float:
        return self._n / self.cfg.rate_hz

    def inject(self, kind: str, value: Any = None) -> None:
        """Queue a fault: ``garbage`` (n bytes), ``corrupt`` (next n lines), ``cut`` (next n lines),
        ``reset``, ``unplug`` (wall s), ``freeze`` (wall s, no output), ``force`` ((channel, counts|None)),
        ``raw`` (bytes written as they are)."""
        with self._lock:
            self._actions.append((kind, value))

    def _do_actions(self) -> None:
        with self._lock:
            actions = list(self._actions)
            self._actions.clear()
        for kind, v in actions:
            self.stats.faults_injected += 1
            if kind == 'garbage':
                self._out += bytes(self.rng.integers(0, 256, int(v or 64), dtype=np.uint8))
            elif kind == 'raw':
                self._out += bytes(v)
            elif kind == 'corrupt':
                self._corrupt += int(v or 1)
            elif kind == 'cut':
                self._cut += int(v or 1)
            elif kind == 'reset':
                self.stats.resets += 1
                self._boot('software')
            elif kind == 'freeze':
                self._freeze_until = self.clock() + float(v)
            elif kind == 'force':
                ch, counts = v
                if counts is None:
                    self._forced.pop(int(ch), None)
                else:
                    self._forced[int(ch)] = int(counts)
            elif kind == 'unplug':
                self._unplug(float(v if v is not None else self.cfg.unplug_wall_s))
            else:
                raise ValueError(f'unknown fault {kind!r}')

    def _unplug(self, wall_s: float) -> None:
        self.stats.unplugs += 1
        self.close()
        t_end = time.monotonic() + wall_s
        while not self._stop.is_set() and time.monotonic() < t_end:
            time.sleep(0.005)
        # the wrist cooled/moved meanwhile at zero drive
        lost = int(wall_s * self.cfg.time_scale * self.cfg.rate_hz)
        for plant in (self.plant, self._joint_plant):
            if plant is not None:
                plant.advance(np.zeros((1, 2)), max(1, lost * self.steps_per_sample))
        self._boot('power')
        self.open()

    def _read_commands(self) -> None:
        if self._master is None:
            return
        try:
            data = os.read(self._master, 4096)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            return
        self.receive(data)

    def receive(self, data: bytes) -> None:
        """Bytes from the host: commands take effect after the latency, a query is answered with a hello."""
        self.stats.bytes_received += len(data)
        now = self.device_time_s
        for f in self.parser.feed(data):
            if isinstance(f, P.Command):
                self.stats.commands_received += 1
                u = np.array([[f.u1_mV, f.u2_mV]], float) / 1000.0
                self.stats.max_abs_command_V = max(self.stats.max_abs_command_V, float(np.abs(u).max()))
                self._pending.append((now + self.cfg.latency_s, u))
            elif isinstance(f, P.Query):
                self._out += P.encode(P.Hello(self.cfg.device_id, self.cfg.firmware, int(round(self.cfg.rate_hz))))
            elif isinstance(f, P.DriveReadback) and self.cfg.drive_readback:
                self._readback = f.on

    def _wired(self, u: np.ndarray) -> np.ndarray:
        """The drive (1, 2) [V] each TEM gets from the driver's outputs ``u``, through the wiring faults."""
        c = self.cfg
        if c.tem_channels_swapped:
            u = u[:, ::-1]
        if any(c.tem_polarity_swapped):
            u = u * np.where(np.asarray(c.tem_polarity_swapped), -1.0, 1.0)
        if tuple(c.tem_drive_scale) != (1.0, 1.0):
            u = u * np.asarray(c.tem_drive_scale, float)
        return u

    def emit(self, n: int) -> bytes:
        """The next ``n`` samples' lines (and whatever was queued before them), at once: the device stepped in
        lockstep with a host that is no serial port (``sma-wrist commission --sim``, tests)."""
        self._do_actions()
        for _ in range(n):
            self._out += self._sample()
        out = bytes(self._out)
        self._out.clear()
        return out

    def _convert(self, t: float, T: np.ndarray) -> np.ndarray:
        """The thermocouple chip's latest conversion (2,) [degC] at device time t [s]: it samples the
        thermocouples every 1 / thermocouple_rate_hz and holds the value, rounded to its resolution."""
        c = self.cfg
        if self._tc_next_s is None or t >= self._tc_next_s:
            res = c.thermocouple_resolution_C
            self._tc_held = np.round(T / res) * res if res > 0 else np.array(T, float)
            period = 1.0 / c.thermocouple_rate_hz
            self._tc_next_s = t + period if self._tc_next_s is None else self._tc_next_s + period
        return self._tc_held

    def _sensor_effects(self, t: float, temps: np.ndarray, q: float) -> float:
        """The sensor effects begun by ``t`` [s on the effects' clock] on the muscle thermocouples (``temps[:2]``, in
        place) and the potentiometer; returns the angle read [rad]. A lag starts from the true reading at its onset."""
        from sma_wrist.diagnose.distort import GAIN_REF_C, Q_REF_RAD

        for k, e in enumerate(self.cfg.effects):
            if e.kind not in SENSOR_EFFECTS or t < e.onset_s - 1e-12:
                continue
            i = SENSOR_CHANNELS.index(e.channel)
            x = q if i == 2 else float(temps[i])
            if e.kind == 'offset':
                x += e.value
            elif e.kind == 'gain':
                ref = Q_REF_RAD if i == 2 else GAIN_REF_C
                x = ref + (1.0 + e.value) * (x - ref)
            elif e.kind == 'drift':
                x += e.value / 3600.0 * (t - e.onset_s)
            else:  # lag: y' = (x - y) / tau, exact for x held over the sample
                y = self._lagged.get(k, x)
                x = y + (1.0 - math.exp(-1.0 / (self.cfg.rate_hz * e.value))) * (x - y)
                self._lagged[k] = x
            if i == 2:
                q = x
            else:
                temps[i] = x
        return q

    def _sample(self) -> bytes:
        c = self.cfg
        self._n += 1
        t = self._n / c.rate_hz
        while self._pending and self._pending[0][0] <= t:
            self._u = self._pending.popleft()[1]
            self._last_cmd_t = t
        flags = 0
        u = self._u
        if t - self._last_cmd_t > c.watchdog_s:
            u = np.zeros((1, 2))
            flags |= P.FLAG_WATCHDOG
        if np.abs(u).max() > c.u_limit_V:
            u = np.clip(u, -c.u_limit_V, c.u_limit_V)
            flags |= P.FLAG_CLIPPED
        if self._boot_flag:
            flags |= P.FLAG_BOOT
            self._boot_flag = False
        # what the driver outputs apply over this sample's period, as the firmware reads it back (before the wiring)
        drive = (int(round(u[0, 0] * 1000.0)), int(round(u[0, 1] * 1000.0))) if self._readback else None
        u = self._wired(u)
        if self._effect_n is None and self.stats.commands_received:
            self._effect_n = 0
        if self._effect_n is not None:
            self._effect_n += 1
        # this sample's time on the effects' clock: the interval it ends begins here (-1: not driven yet)
        t0 = -1.0 if self._effect_n is None else (self._effect_n - 1) / c.rate_hz
        for e, plant, change in self._changes:
            if t0 >= e.onset_s - 1e-12:
                change(plant, t0 - e.onset_s)
        self.plant.advance(u, self.steps_per_sample)
        st = self.plant.state
        T, q, qd = self.plant.muscle_temperature_C, st.q, st.qd
        if self._joint_plant is not None:
            u_joint = u.copy()
            u_joint[:, c.broken_wire - 1] = 0.0
            self._joint_plant.advance(u_joint, self.steps_per_sample)
            q, qd = self._joint_plant.state.q, self._joint_plant.state.qd
        if self.sensors is not None:
            T, q, _ = self.sensors.measure(T, q.copy(), qd.copy())
        chip = c.thermocouple_rate_hz > 0
        if chip:
            T = self._convert(t, T[0])[None]
        th = st.thermal[0]  # (layer, face): the TEMs' exchanger faces
        temps = np.array([T[0, 0], T[0, 1], th[0, 1], th[1, 1]])
        q_read = float(q[0])
        if c.effects:
            q_read = self._sensor_effects(t0, temps, q_read)
        if c.thermocouples_swapped:
            temps[:2] = temps[1::-1]
        counts = c.calibration.to_counts(temps, q_read)
        if c.angle_reversed:
            counts[4] = P.ADC_MAX - counts[4]
        if c.noise_counts > 0:
            noise = self.rng.normal(0.0, c.noise_counts, 5)
            if chip:  # the chip's reading reaches the firmware as a number, not through the ADC
                noise[:2] = 0.0
            counts = counts + noise
        adc = list(quantise(counts))
        for ch, v in self._forced.items():
            adc[ch] = v
        s = P.Sample(
            (self._n - 1) % P.SEQ_MODULUS, int(round((self._n - 1) * 1e6 / c.rate_hz)), tuple(adc), flags, drive
        )
        line = P.encode(s)
        if self.sent_log is not None:
            self.sent_log.append((self.clock(), s))
        self.stats.samples_sent += 1
        r = self.rng.random(3) if (c.garbage_rate or c.checksum_error_rate or c.partial_rate) else None
        if self._corrupt or (r is not None and r[0] < c.checksum_error_rate):
            self._corrupt = max(0, self._corrupt - 1)
            line = line[:-5] + b'%04X\n' % ((int(line[-5:-1], 16) ^ 0x0101) & 0xFFFF)
        if self._cut or (r is not None and r[1] < c.partial_rate):
            self._cut = max(0, self._cut - 1)
            line = line[: len(line) // 2]
        if r is not None and r[2] < c.garbage_rate:
            line = bytes(self.rng.integers(0, 256, 16, dtype=np.uint8)) + line
        return line

    def _flush(self) -> None:
        if self._master is None or not self._out:
            return
        try:
            n = os.write(self._master, self._out)
            del self._out[:n]
            self.stats.bytes_written += n
        except (BlockingIOError, InterruptedError):
            pass
        except OSError:
            self._out.clear()
        if len(self._out) > MAX_BACKLOG:
            self.stats.bytes_dropped += len(self._out)
            self._out.clear()

    def step_until(self, wall_now: float) -> int:
        """Emit every sample due by ``wall_now`` (monotonic s); returns how many."""
        c = self.cfg
        due = int((wall_now - self._t_boot_wall) * c.time_scale * c.rate_hz)
        k = 0
        frozen = wall_now < self._freeze_until
        while self._n < due:
            if c.host_paced and len(self._out) > PACED_BACKLOG:
                self._t_boot_wall = wall_now - self._n / (c.rate_hz * c.time_scale)  # wait for the host
                break
            line = self._sample()
            if not frozen:
                self._out += line
            k += 1
            if c.reset_every_s and self._n % max(1, int(c.reset_every_s * c.rate_hz)) == 0:
                self.inject('reset')
                break
            if c.unplug_every_s and self._n % max(1, int(c.unplug_every_s * c.rate_hz)) == 0:
                self.inject('unplug', c.unplug_wall_s)
                break
        return k

    def serve(self, now: float) -> None:
        """One turn of the device's loop at wall time ``now``: faults, commands, every sample due, the line."""
        self._do_actions()
        self._read_commands()
        self.step_until(now)
        self._flush()

    def next_due(self) -> float:
        """Wall time [s] the next sample is due."""
        return self._t_boot_wall + (self._n + 1) / (self.cfg.rate_hz * self.cfg.time_scale)

    def run(self, duration_wall_s: float | None = None, resume: bool = False) -> None:
        """Serve until :meth:`stop` (or ``duration_wall_s``); opens the pty if not open. ``resume``: the device
        time goes on from where :meth:`emit` left it (a device stepped in lockstep, then served on a pty: the same
        wrist, warm as it was), rather than from its boot."""
        if self._master is None:
            self.open()
        self._t_boot_wall = self.clock() - (self._n / (self.cfg.rate_hz * self.cfg.time_scale) if resume else 0.0)
        t_end = None if duration_wall_s is None else self._t_boot_wall + duration_wall_s
        try:
            while not self._stop.is_set():
                now = self.clock()
                if t_end is not None and now >= t_end:
                    break
                self.serve(now)
                # next sample due; sleep at most 1 ms so commands are read promptly
                time.sleep(min(max(self.next_due() - self.clock(), 0.0), 0.001))
        finally:
            self.close()

    def start(self, resume: bool = False) -> str:
        """Open the pty and serve in a daemon thread (``resume``: see :meth:`run`); returns the port path."""
        path = self.open()
        self._stop.clear()
        self._thread = threading.Thread(
            target=self.run, kwargs={'resume': resume}, name='sma-wrist-emulator', daemon=True
        )
        self._thread.start()
        return path

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=5.0)


# --------------------------------------------------------------------------- command line
def config_from_args(a: argparse.Namespace) -> EmulatorConfig:
    """The device's configuration from the command line; ValueError naming the option for a value it cannot be."""
    try:
        offsets = tuple(float(x) for x in a.thermocouple_offsets_C.split(','))
    except ValueError:
        raise ValueError(
            f'--thermocouple-offsets-C {a.thermocouple_offsets_C!r}: 4 numbers [degC], comma separated'
        ) from None
    if len(offsets) != 4 or not all(math.isfinite(o) for o in offsets):
        raise ValueError('--thermocouple-offsets-C needs 4 finite comma-separated values')
    if not (a.rate_hz > 0 and a.time_scale > 0 and PAYLOAD_RANGE_KG[0] <= a.payload_kg <= PAYLOAD_RANGE_KG[1]):
        raise ValueError(
            '--rate-hz and --time-scale must be > 0, --payload-kg in [{:g}, {:g}]'.format(*PAYLOAD_RANGE_KG)
        )
    # a NaN or negative value here did not fail: it made a device without noise, latency or watchdog in silence
    if not (math.isfinite(a.watchdog_s) and a.watchdog_s > 0):
        raise ValueError(f'--watchdog-s {a.watchdog_s!r} must be a finite number > 0')
    tc_rate, tc_res = getattr(a, 'thermocouple_rate_hz', 0.0), getattr(a, 'thermocouple_resolution_C', 0.0)
    for flag, v in (
        ('--noise-counts', a.noise_counts),
        ('--latency-ms', a.latency_ms),
        ('--reset-every-s', a.reset_every_s),
        ('--unplug-every-s', a.unplug_every_s),
        ('--unplug-wall-s', a.unplug_wall_s),
        ('--thermocouple-rate-hz', tc_rate),
        ('--thermocouple-resolution-C', tc_res),
    ):
        if not (math.isfinite(v) and v >= 0):
            raise ValueError(f'{flag} {v!r} must be a finite number >= 0')
    if tc_rate > a.rate_hz:
        raise ValueError(f'--thermocouple-rate-hz {tc_rate:g} is above the sample rate {a.rate_hz:g} Hz')
    if tc_res > 0 and not tc_rate > 0:
        raise ValueError('--thermocouple-resolution-C models a converter chip: give --thermocouple-rate-hz too')
    for flag, v in (
        ('--garbage-rate', a.garbage_rate),
        ('--checksum-error-rate', a.checksum_error_rate),
        ('--partial-rate', a.partial_rate),
    ):
        if not 0 <= v <= 1:  # a probability per line (False for NaN)
            raise ValueError(f'{flag} {v!r} must be a probability in [0, 1]')
    # the device's sensor error: it reads `offset` too high, i.e. counts of (T + offset)
    cal = Calibration(offsets_C=tuple(-o for o in offsets))  # type: ignore[arg-type]
    plant = getattr(a, 'plant', 'model')
    from sma_wrist.plants import PLANTS

    if plant != 'model' and plant not in PLANTS:
        raise ValueError(f'--plant {plant!r}: one of model, {", ".join(sorted(PLANTS))}')
    scenario: dict[str, Any] = {}
    # a wire transforming hotter or colder, TEMs weaker or stronger than the model's: the model so perturbed
    off_model = {
        k: v
        for k, v in (
            ('transition_shift_C', getattr(a, 'transition_shift_C', None)),
            ('tem_gain_scale', getattr(a, 'tem_gain_scale', None)),
        )
        if v is not None
    }
    if off_model and plant == 'model':
        plant = 'sdgpi'
    if getattr(a, 'scenario_file', None):
        if plant == 'model':
            raise ValueError('--scenario-file perturbs a registered plant: give --plant sdgpi or phase_fraction too')
        from sma_wrist.plants.spread import Scenario

        # as plant_sim's scenario_file: axes it names (a sweep row's payload too) win; ParameterError is a ValueError
        scenario = Scenario.from_file(a.scenario_file, {'payload_kg': a.payload_kg}).to_dict()
    if off_model:
        from sma_wrist.plants.spread import Scenario

        scenario = Scenario.from_mapping({'payload_kg': a.payload_kg, **scenario, **off_model}).to_dict()
    drive_scale = (1.0, 1.0)
    if getattr(a, 'tem_drive_scale', None) is not None:
        try:
            drive_scale = tuple(float(x) for x in a.tem_drive_scale.split(','))  # type: ignore[assignment]
        except ValueError:
            drive_scale = ()  # type: ignore[assignment]
        if len(drive_scale) != 2 or not all(0.0 < k <= 2.0 for k in drive_scale):  # False for NaN
            raise ValueError(f'--tem-drive-scale {a.tem_drive_scale!r}: two fractions in (0, 2], comma separated')
    polarity = set(getattr(a, 'swap_tem_polarity', None) or ())
    broken = getattr(a, 'broken_wire', None) or 0
    if not polarity <= {1, 2} or broken not in (0, 1, 2):
        raise ValueError('--swap-tem-polarity and --broken-wire take a muscle number, 1 or 2')
    base = None
    if getattr(a, 'params_file', None):  # the wrist plant_sim would simulate with these files
        from sma_wrist import runtime

        runtime.activate()
        from sma_wrist.sweep.graph_params import plant_params

        base = plant_params(a.params_file)  # ParameterError (a ValueError) names a bad file or value
    effects = tuple(Effect.parse(spec) for spec in (getattr(a, 'effect', None) or ()))
    if plant != 'model' and any(e.kind in PLANT_EFFECTS for e in effects):
        raise ValueError(f'--effect {"/".join(PLANT_EFFECTS)}:plant:... act on --plant model only (not {plant})')
    return EmulatorConfig(
        effects=effects,
        plant=plant,
        scenario=scenario,
        base=base,
        rate_hz=a.rate_hz,
        time_scale=a.time_scale,
        payload_kg=a.payload_kg,
        noise_counts=a.noise_counts,
        latency_s=a.latency_ms / 1000.0,
        watchdog_s=a.watchdog_s,
        seed=a.seed,
        calibration=cal,
        garbage_rate=a.garbage_rate,
        checksum_error_rate=a.checksum_error_rate,
        partial_rate=a.partial_rate,
        reset_every_s=a.reset_every_s,
        unplug_every_s=a.unplug_every_s,
        unplug_wall_s=a.unplug_wall_s,
        thermocouple_rate_hz=tc_rate,
        thermocouple_resolution_C=tc_res,
        tem_polarity_swapped=(1 in polarity, 2 in polarity),
        tem_channels_swapped=bool(getattr(a, 'swap_tem_channels', False)),
        thermocouples_swapped=bool(getattr(a, 'swap_thermocouples', False)),
        angle_reversed=bool(getattr(a, 'reverse_angle', False)),
        broken_wire=broken,
        tem_drive_scale=drive_scale,
        drive_readback=not getattr(a, 'no_drive_readback', False),
    )


def run_from_args(a: argparse.Namespace) -> int:
    """Serve until SIGINT/SIGTERM or --duration; prints the port path first (flushed)."""
    try:
        cfg = config_from_args(a)
    except ValueError as e:
        print(f'error: {e}', flush=True)
        return 2
    emu = DeviceEmulator(cfg, link=a.port)
    try:
        path = emu.open()
    except SmaWristError as e:
        print(f'error: {e}', flush=True)
        return 2
    print(
        f'emulated wrist on {emu.slave_path}'
        + (f' (linked at {a.port})' if a.port else '')
        + f', {cfg.rate_hz:g} Hz, time x{cfg.time_scale:g}',
        flush=True,
    )
    print(path, flush=True)
    signal.signal(signal.SIGTERM, lambda *_: emu._stop.set())
    try:
        emu.run(a.duration)
    except KeyboardInterrupt:
        pass
    finally:
        emu.close()
    # the device's side of what the host did (commission's bring-up limits are checked against it)
    print(
        f'received {emu.stats.commands_received} commands, largest |drive| {emu.stats.max_abs_command_V:g} V',
        flush=True,
    )
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog='sma-wrist emulate-device', description=__doc__.split('\n')[0])
    add_arguments(ap)
    return run_from_args(ap.parse_args(argv))


__all__ = [
    'Effect',
    'EmulatorConfig',
    'EmulatorStats',
    'DeviceEmulator',
    'add_arguments',
    'config_from_args',
    'run_from_args',
    'main',
]

if __name__ == '__main__':
    raise SystemExit(main())
