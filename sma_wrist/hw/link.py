"""The host end of the serial line: a reader thread that parses, and reconnects with backoff.

:class:`SerialLink` opens the port with pyserial (``serial.serial_for_url``, so
``/dev/ttyACM0``, a pty path or ``loop://`` all work), feeds every byte to a
:class:`sma_wrist.hw.protocol.Parser` and puts ``(kind, wall_s, payload)`` events on a
queue the bridge drains: ``('frame', t, Frame)``, ``('connected', t, port)``,
``('disconnected', t, reason)``. Only frames the parser validated are ever queued.

Faults: a failed open, a read/write error (unplugged cable, pty closed) or no valid frame
for ``silence_s`` (a device that only sends garbage or hangs) closes the port and retries
after a delay that doubles from ``backoff_initial_s`` up to ``backoff_max_s``; it is reset
once a connection delivers a valid frame. Times here are wall seconds of ``clock`` (``time.monotonic``; a test
gives a clock it drives, and a link that reads the port when the bridge waits, through :meth:`SerialLink.next_event`).
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from sma_wrist.hw import protocol as P

Event = tuple[str, float, Any]


def open_serial(port: str, baud: int) -> Any:
    """Default opener: pyserial, 20 ms read timeout, 100 ms write timeout."""
    import serial

    return serial.serial_for_url(port, baudrate=baud, timeout=0.02, write_timeout=0.1)


@dataclass
class LinkStats:
    connects: int = 0
    disconnects: int = 0
    open_failures: int = 0
    silence_reconnects: int = 0
    write_errors: int = 0
    queue_overflows: int = 0
    bytes_in: int = 0
    commands_sent: int = 0
    backoff_s: float = 0.0
    last_error: str = ''


class SerialLink:
    """Reader thread + thread-safe writer for one serial port. ``start()``, ``events``, ``send()``, ``stop()``."""

    def __init__(
        self,
        port: str,
        baud: int = 921600,
        *,
        backoff_initial_s: float = 0.05,
        backoff_max_s: float = 2.0,
        silence_s: float = 1.0,
        queue_size: int = 100000,
        opener: Callable[[str, int], Any] = open_serial,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.port = port
        self.clock = clock  # wall seconds: the events' stamps, the silence limit, and the bridge's timeouts
        self.baud = baud
        self.backoff_initial_s = backoff_initial_s
        self.backoff_max_s = backoff_max_s
        self.silence_s = silence_s
        self.opener = opener
        self.parser = P.Parser()
        self.stats = LinkStats()
        self.events: queue.Queue[Event] = queue.Queue(queue_size)
        self._ser: Any = None
        self._wlock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._cmd_seq = 0

    @property
    def connected(self) -> bool:
        return self._ser is not None

    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name=f'serial-link {self.port}', daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        self._close('stopped', notify=False)

    def send(self, frame: P.Frame) -> bool:
        """Write one frame; False (and the link reconnects) if the port is closed or the write fails."""
        ser = self._ser
        if ser is None:
            return False
        data = P.encode(frame)
        try:
            with self._wlock:
                ser.write(data)
            return True
        except Exception as e:  # pyserial raises SerialException, SerialTimeoutException, OSError
            self.stats.write_errors += 1
            self.stats.last_error = f'write: {e}'
            return False

    def send_command(self, u1_V: float, u2_V: float) -> bool:
        """Send a drive command [V] (rounded to mV); the command sequence number is kept here."""
        self._cmd_seq = (self._cmd_seq + 1) % P.SEQ_MODULUS
        ok = self.send(P.Command(self._cmd_seq, int(round(u1_V * 1000.0)), int(round(u2_V * 1000.0))))
        if ok:
            self.stats.commands_sent += 1
        return ok

    def next_event(self, timeout_s: float) -> Event:
        """The next event, waiting up to ``timeout_s`` of the link's clock; queue.Empty if none came."""
        return self.events.get(timeout=timeout_s)

    # ------------------------------------------------------------------ reader thread
    def _put(self, ev: Event) -> None:
        try:
            self.events.put_nowait(ev)
        except queue.Full:
            self.stats.queue_overflows += 1

    def _close(self, reason: str, notify: bool = True) -> None:
        ser, self._ser = self._ser, None
        if ser is not None:
            try:
                ser.close()
            except Exception:
                pass
            if notify:
                self.stats.disconnects += 1
                self._put(('disconnected', self.clock(), reason))

    def _run(self) -> None:
        delay = self.backoff_initial_s
        while not self._stop.is_set():
            try:
                ser = self.opener(self.port, self.baud)
            except Exception as e:
                self.stats.open_failures += 1
                self.stats.last_error = f'open {self.port}: {e}'
                self.stats.backoff_s = delay
                self._stop.wait(delay)
                delay = min(delay * 2.0, self.backoff_max_s)
                continue
            self.parser.reset()
            self._ser = ser
            self.stats.connects += 1
            self._put(('connected', self.clock(), self.port))
            self.send(P.Query())  # ask who is there (the hello sent at boot may have been flushed)
            good = self._serve(ser)
            if good:
                delay = self.backoff_initial_s
            self.stats.backoff_s = delay
            self._stop.wait(delay)
            delay = min(delay * 2.0, self.backoff_max_s)

    def _serve(self, ser: Any) -> bool:
        """Read until error, silence or stop; True if at least one valid frame arrived."""
        got_any = False
        last_valid = self.clock()
        while not self._stop.is_set():
            try:
                data = ser.read(ser.in_waiting or 1)
            except Exception as e:
                self.stats.last_error = f'read: {e}'
                self._close(f'read failed: {e}')
                return got_any
            now = self.clock()
            if data:
                self.stats.bytes_in += len(data)
                for f in self.parser.feed(data):
                    got_any = True
                    last_valid = now
                    self._put(('frame', now, f))
            if now - last_valid > self.silence_s:
                self.stats.silence_reconnects += 1
                self._close(f'no valid frame for {self.silence_s:g} s')
                return got_any
        return got_any


__all__ = ['SerialLink', 'LinkStats', 'open_serial', 'Event']
