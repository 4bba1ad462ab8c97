"""The two devices commissioning talks to: a serial port (:class:`SerialDevice`, the bridge's link) and the emulated
device stepped in lockstep (:class:`SimDevice`, for ``--sim`` and tests). Both speak doc/explanation/protocol.md: the same
frames, parsed by the same :class:`sma_wrist.hw.protocol.Parser`."""

from __future__ import annotations

import contextlib
import queue
import time
from collections.abc import Iterator
from typing import Any

from sma_wrist.core.errors import SmaWristError
from sma_wrist.hw import protocol as P


class PortError(SmaWristError):
    """The port does not open (bad input: exit 2)."""


class DeviceLost(Exception):
    """The device stopped streaming or the link broke mid-procedure."""


class SerialDevice:
    """A wrist on a serial port, through :class:`sma_wrist.hw.link.SerialLink` (its reader thread and parser)."""

    def __init__(self, port: str, baud: int = 921600, open_timeout_s: float = 3.0, stall_s: float = 1.0) -> None:
        from sma_wrist.hw.link import SerialLink

        self.port = port
        self.baud = baud
        self.stall_s = stall_s
        self.open_timeout_s = open_timeout_s
        # no silent reconnects: a link that drops mid-procedure stops it (silence_s > stall_s, so it is seen here)
        self.link = SerialLink(port, baud, backoff_initial_s=0.2, backoff_max_s=1.0, silence_s=stall_s + 1.0)
        self.parser = self.link.parser
        self.parser_stats = self.parser.stats
        self._last_frame_wall = 0.0

    def open(self) -> None:
        """Connect; PortError naming the port and pyserial's reason if it does not open within the timeout."""
        self.link.start()
        t_end = time.monotonic() + self.open_timeout_s
        while time.monotonic() < t_end:
            try:
                kind, wall, x = self.link.events.get(timeout=0.05)
            except queue.Empty:
                continue
            if kind == 'connected':
                self._last_frame_wall = time.monotonic()
                return
        why = self.link.stats.last_error or 'no answer'
        self.link.stop()
        raise PortError(
            f'the port {self.port} does not open ({why}): check the port name and that the wrist '
            'controller is plugged in and powered'
        )

    def reopened(self) -> SerialDevice:
        """The same port on a new link (a closed link does not start again): the verification settles the wrist
        through it between the node graph's runs, which have the port meanwhile."""
        return SerialDevice(self.port, self.baud, self.open_timeout_s, self.stall_s)

    def send(self, u1_V: float, u2_V: float) -> None:
        self.link.send_command(u1_V, u2_V)

    def query(self) -> None:
        self.link.send(P.Query())

    def frames(self) -> list[P.Frame]:
        """The frames that arrived (waits up to 50 ms for one); DeviceLost when none came for ``stall_s``."""
        out: list[P.Frame] = []
        try:
            ev = self.link.events.get(timeout=0.05)
            while True:
                kind, wall, x = ev
                if kind == 'disconnected':
                    raise DeviceLost(f'the serial link was lost ({x})')
                if kind == 'frame':
                    out.append(x)
                ev = self.link.events.get_nowait()
        except queue.Empty:
            pass
        now = time.monotonic()
        if out:
            self._last_frame_wall = now
        elif now - self._last_frame_wall > self.stall_s:
            raise DeviceLost(f'the device stopped streaming (no valid frame for {self.stall_s:g} s)')
        return out

    def close(self) -> None:
        """TEMs off (a few times: a lost line must not leave them on until the device's watchdog), then close; safe
        to call on a link that never connected or is closed."""
        for _ in range(3):
            self.link.send_command(0.0, 0.0)
        self.link.stop()


class SimDevice:
    """The emulated device (sma_wrist/hw/emulator.py, its plant and its wiring faults) in lockstep: each
    :meth:`frames` lets ``chunk`` samples of device time pass; commands reach it as encoded ``C`` lines."""

    def __init__(self, config: Any, chunk: int = 20) -> None:
        from sma_wrist.hw.emulator import DeviceEmulator

        self.emulator = DeviceEmulator(config)
        self.parser = P.Parser()
        self.parser_stats = self.parser.stats
        self.chunk = chunk
        self.port = 'sim'
        self._seq = 0

    def open(self) -> None:
        pass

    def send(self, u1_V: float, u2_V: float) -> None:
        self._seq = (self._seq + 1) % P.SEQ_MODULUS
        self.emulator.receive(P.encode(P.Command(self._seq, int(round(u1_V * 1000.0)), int(round(u2_V * 1000.0)))))

    def query(self) -> None:
        self.emulator.receive(P.encode(P.Query()))

    def frames(self) -> list[P.Frame]:
        return self.parser.feed(self.emulator.emit(self.chunk))

    def close(self) -> None:
        self.send(0.0, 0.0)
        self.emulator.emit(1)

    @contextlib.contextmanager
    def serve(self, link: str, time_scale: float = 1.0) -> Iterator[str]:
        """The same device (its wrist as warm as it is now) served on a pseudo-terminal linked at ``link``, device
        time ``time_scale`` times wall time, or slower when the host falls behind (``host_paced``): for the node
        graph's hardware_bridge (verification). Yields the port; the device time it served is
        :attr:`device_time_s`."""
        emu = self.emulator
        emu.link = link
        emu.cfg.time_scale = time_scale
        emu.cfg.host_paced = True
        emu.start(resume=True)
        try:
            yield link
        finally:
            emu.stop()
            emu.link = None

    @property
    def device_time_s(self) -> float:
        return self.emulator.device_time_s


__all__ = ['SerialDevice', 'SimDevice', 'PortError', 'DeviceLost']
