"""What doc/explanation/protocol.md states about the device side, checked on the emulator.

The emulator is driven sample by sample (``_read_commands`` / ``_sample``), so everything is in
device time and deterministic; commands go in through the pty as a host writes them.
"""

from __future__ import annotations

import fcntl
import os
import re
import struct
import termios
import time
from pathlib import Path

import numpy as np
import pytest

from sma_wrist.hw import protocol as P
from sma_wrist.hw.calibration import Calibration
from sma_wrist.hw.emulator import DeviceEmulator, EmulatorConfig

DOC = (Path(__file__).resolve().parent.parent / 'doc' / 'explanation' / 'protocol.md').read_text()


class Device:
    """The emulator on a pty, stepped one sample at a time; ``send`` writes a frame as the host."""

    def __init__(self, tmp_path: Path, **cfg) -> None:
        self.emu = DeviceEmulator(EmulatorConfig(noise_counts=0.0, **cfg), link=str(tmp_path / 'wrist'))
        self.emu.open()
        self.host = os.open(self.emu.link, os.O_RDWR | os.O_NOCTTY)
        self.seq = 0
        self.unread = 0  # bytes written by the host that the emulator has not read yet

    def send(self, u1_mV: int, u2_mV: int) -> None:
        self.seq += 1
        self.write(P.Command(self.seq, u1_mV, u2_mV))

    def write(self, frame: P.Frame) -> None:
        self.unread += os.write(self.host, P.encode(frame))
        self._until_delivered()

    def _until_delivered(self, timeout_s: float = 5.0) -> None:
        """Wait until the kernel has moved the host's bytes to the emulator's side of the pty.

        A pty hands written bytes over asynchronously; on a loaded machine a frame written just
        before a sample may not be readable yet, and would take effect samples later than the
        device-time statements below say."""
        end = time.monotonic() + timeout_s
        while self._readable() < self.unread:
            if time.monotonic() > end:
                raise TimeoutError(f'{self.unread} bytes written, {self._readable()} readable after {timeout_s} s')
            time.sleep(0.0005)

    def _readable(self) -> int:
        return struct.unpack('i', fcntl.ioctl(self.emu._master, termios.FIONREAD, b'\0\0\0\0'))[0]

    def samples(self, n: int) -> list[P.Sample]:
        out = []
        for _ in range(n):
            self.emu._read_commands()
            self.unread = 0
            (s,) = P.Parser().feed(self.emu._sample())
            out.append(s)
        return out

    def close(self) -> None:
        os.close(self.host)
        self.emu.close()


@pytest.fixture
def device(tmp_path):
    made = []

    def make(**cfg) -> Device:
        made.append(Device(tmp_path, **cfg))
        return made[-1]

    yield make
    for d in made:
        d.close()


@pytest.mark.parametrize('tem', [1, 2])
def test_positive_C_voltage_heats_muscle_i(device, tem):
    d = device()
    d.send(*((8000, 0) if tem == 1 else (0, 8000)))
    T = []
    for _ in range(20):  # 2 s of device time, commands repeated within the watchdog
        T += [Calibration().to_physical(np.array(s.adc))[0][:2] for s in d.samples(100)]
        d.send(*((8000, 0) if tem == 1 else (0, 8000)))
    rise = np.array(T[-1]) - np.array(T[0])
    assert rise[tem - 1] > 1.0 and rise[tem - 1] > 3 * abs(rise[2 - tem]), rise


def test_first_sample_after_boot_has_t_us_0_seq_0_and_flags_boot_and_watchdog(device):
    d = device(rate_hz=1000.0)
    s = d.samples(3)
    assert [x.t_us for x in s] == [0, 1000, 2000] and [x.seq for x in s] == [0, 1, 2]
    assert s[0].flags == P.FLAG_BOOT | P.FLAG_WATCHDOG  # flag 1 is set before any command arrived
    assert s[1].flags == P.FLAG_WATCHDOG


def test_device_watchdog_counts_device_time(device):
    # time_scale 10: wall time runs 10x slower than device time; the watchdog still trips after
    # watchdog_s of *device* time (0.5 s = 500 samples), whatever the wall clock did meanwhile
    d = device(time_scale=10.0, watchdog_s=0.5, latency_s=0.001)
    d.send(5000, 5000)
    flags = [s.flags for s in d.samples(700)]
    on = [k for k, f in enumerate(flags) if not f & P.FLAG_WATCHDOG]
    assert on[0] == 0  # the command took effect at the first sample 1 ms after it arrived
    # driven while t - t_command <= watchdog_s (samples at 1..501 ms), zero from the first sample past it
    assert on == list(range(501))
    assert all(f & P.FLAG_WATCHDOG for f in flags[on[-1] + 1 :])


def test_flag_2_stays_set_while_a_clipped_command_is_in_force(device):
    d = device(u_limit_V=24.0)
    d.send(30000, 0)  # 30 V > the 24 V rating
    flags = [s.flags for s in d.samples(200)]
    assert all(f & P.FLAG_CLIPPED for f in flags)
    d.send(10000, 0)  # within the rating: cleared once it takes effect
    flags = [s.flags for s in d.samples(10)]
    assert not any(f & P.FLAG_CLIPPED for f in flags[1:])
    d.send(30000, 0)
    flags = [s.flags for s in d.samples(700)]  # ... and not set once the watchdog zeroed the drive
    assert flags[1] & P.FLAG_CLIPPED and flags[-1] == P.FLAG_WATCHDOG


@pytest.mark.parametrize('firmware_has_it', [True, False])
def test_asked_the_device_reads_back_the_drive_it_applied_until_it_reboots(device, firmware_has_it):
    """After a D frame every sample carries the drive of the period it ends, as applied: from the first sample at
    the command's arrival + latency, clipped to the rating, zeroed by the watchdog; a reboot forgets it. A firmware
    without the read-back ignores the D frame: its samples stay as they were."""
    d = device(u_limit_V=24.0, watchdog_s=0.1, latency_s=0.002, drive_readback=firmware_has_it)
    assert all(s.drive_mV is None for s in d.samples(5))  # not asked: the samples of protocol 1 as they were
    d.write(P.DriveReadback(True))
    d.send(30000, -5000)
    drive = [s.drive_mV for s in d.samples(150)]
    if not firmware_has_it:
        assert drive == [None] * 150
        return
    # arrival (5 ms) + 2 ms: the sample at 6 ms is still undriven, then 24 V (clipped) until the watchdog
    assert drive[0] == (0, 0) and drive[1] == (24000, -5000)
    assert drive[-1] == (0, 0) and drive.count((24000, -5000)) == 101
    d.emu.inject('reset')
    d.emu._do_actions()
    assert all(s.drive_mV is None for s in d.samples(5))


def test_minus_zero_is_not_canonical():
    parser = P.Parser()
    assert parser.feed(P.encode_unchecked('C,1,5,-0,0')) == [] and parser.stats.malformed == 1
    assert parser.feed(P.encode_unchecked('C,1,5,0,0')) == [P.Command(5, 0, 0)]
    assert P.encode(P.Command(5, 0, 0)).startswith(b'$C,1,5,0,0*')


def test_the_doc_states_each_answer_and_the_bridges_safe_angle_range():
    from sma_wrist import runtime

    runtime.activate()
    from sma_wrist.nodes.hardware_bridge import HardwareBridge

    d = {p.name: p.default for p in HardwareBridge.PARAMS}
    assert f'[{d["angle_min_rad"]:g}, {d["angle_max_rad"]:g}] rad' in DOC
    for statement in (
        'positive `u1_mV` heats muscle 1',
        'first sample after boot has `seq` 0 and `t_us` 0',
        'counts device time',
        'set from boot until the first command',
        'stays set on every sample while a clipped command is in force',
        '`-0` is not canonical',
        'a reboot forgets it',
    ):
        assert statement in DOC, statement
    assert re.search(r'\| `C` \|', DOC)
