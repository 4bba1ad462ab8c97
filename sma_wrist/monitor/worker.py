"""The monitor's worker: the twin and the checks, away from the node that feeds them.

``twin_monitor`` only buffers the samples it receives and hands them over in batches (:class:`WorkerLink`); the
:class:`MonitorWorker` at the other end owns the :class:`~sma_wrist.monitor.Monitor`: it steps the twin over each
batch, sends back the twin's prediction at the batch's last stamp, and runs a check when one is due (in
measurement time) in a check thread of its own, so that the twin keeps up while a check runs. A check that is due
while the previous one still runs waits for it and then starts on the newest data: checks are never queued, and
the periods that passed without one are counted (``skipped``).

Where the worker runs (``twin_monitor``'s ``worker``): a process of its own, ``worker_nice`` steps of Unix niceness
below the node (on Linux the processes of one session share the CPU as a group, so a busy worker at the node's
priority took the control loop's core share; 19 leaves it what the loop does not use); a thread of the node's
process; or ``inline``, in the node's callback, every check made (offline simulation).
"""

from __future__ import annotations

import dataclasses
import math
import os
import pickle
import queue
import struct
import threading
import time
from collections.abc import Callable
from typing import Any

from sma_wrist.monitor import Monitor, MonitorConfig, Verdict, diagnose_window, ignore_interrupts

#: the node's events: (kind, muscle or TEM 1/2 (0 for the angle and payload), stamp [s], value); kinds: 'u' TEM
#: command [V], 'd' the TEM drive the device read back [V], 'T' muscle temperature [degC], 'f' TEM exchanger-face
#: temperature [degC], 'q' angle [rad], 'p' payload [kg]
Event = tuple[str, int, float, float]
#: the MonitorConfig fields a node may change while it runs (its runtime parameters)
RUNTIME_FIELDS = ('check_period_s', 'persist_checks', 'min_confidence', 'sure_confidence')


def worker_niceness(nice: int) -> int | None:
    """The Unix niceness of a worker ``nice`` steps below this process (capped at 19), None where there is none
    (Windows) or ``nice`` is 0."""
    if nice <= 0 or not hasattr(os, 'getpriority'):
        return None
    return min(os.getpriority(os.PRIO_PROCESS, 0) + int(nice), 19)


def lower_priority(pid: int, niceness: int | None) -> None:
    """Set process ``pid`` (0: this one) to ``niceness`` when that lowers its priority; where this is not permitted
    it keeps its own."""
    if niceness is None:
        return
    try:
        if os.getpriority(os.PRIO_PROCESS, pid) < niceness:
            os.setpriority(os.PRIO_PROCESS, pid, niceness)
    except OSError:  # not permitted here, or the process already ended
        pass


def start_worker(niceness: int | None = None) -> None:
    """A check worker's start-up: Ctrl-C left to the node that owns it (:func:`ignore_interrupts`), and its
    scheduling priority lowered to ``niceness`` (:func:`worker_niceness`) so that on a busy machine it takes the CPU
    the control loop leaves over rather than a share of the loop's. (The node lowers a worker process' priority as
    soon as it starts, before its imports; this makes sure of it from inside.)"""
    ignore_interrupts()
    lower_priority(0, niceness)


class MonitorWorker:
    """Owns the monitor; :meth:`handle` takes the node's messages, ``send`` gives back its answers:

    * ``('feed', seq, events, want_twin)`` -> ``('twin', seq, t_s, (T1, T2) [degC], q [rad], qd [rad/s],
      residuals {T1, T2, q}, cpu_s)`` when ``want_twin`` and the twin runs;
    * a check's result -> ``('verdict', published Verdict, episodes, skipped, cpu_s)``;

    ``cpu_s``: the CPU time of the worker's process so far [s] (of a worker process: the monitor's whole cost).
    * ``('config', {field: value})`` changes :data:`RUNTIME_FIELDS`.

    ``inline``: every due check runs in :meth:`handle` (nothing skipped); otherwise in a check thread."""

    def __init__(self, config: MonitorConfig, send: Callable[[tuple], None], inline: bool = False) -> None:
        self.monitor = Monitor(config)
        self.send = send
        self.inline = inline
        self.skipped = 0
        self._lock = threading.Lock()  # the monitor: fed here, decided in the check thread
        self._busy = False
        self._checks: queue.SimpleQueue | None = None
        if not inline:
            self._checks = queue.SimpleQueue()
            threading.Thread(target=self._check_loop, name='twin_monitor_check', daemon=True).start()

    def handle(self, msg: tuple) -> None:
        if msg[0] == 'feed':
            self._feed(*msg[1:])
        elif msg[0] == 'config':
            with self._lock:
                for k, v in msg[1].items():
                    setattr(self.monitor.config, k, v)

    def _feed(self, seq: int, events: list[Event], want_twin: bool) -> None:
        m = self.monitor
        t_last = None
        for kind, i, t, v in events:
            with self._lock:
                if kind == 'q':
                    m.angle(t, v)
                    t_last = t
                elif kind == 'T':
                    m.temperature(i, t, v)
                elif kind == 'u':
                    m.command(i, t, v)
                elif kind == 'd':
                    m.drive(i, t, v)
                elif kind == 'f':
                    m.face(i, t, v)
                else:
                    m.payload(v)
            if kind == 'q':
                self._maybe_check(t)
        if want_twin and t_last is not None:
            with self._lock:
                tw = m.twin
                if tw is None:
                    return
                T = tw.temperatures_C
                out = ('twin', seq, t_last, (float(T[0]), float(T[1])), tw.angle_rad, float(tw.plant.state.qd[0]))
                res = m.residuals()
            self.send((*out, res, time.process_time()))

    def _maybe_check(self, t: float) -> None:
        m = self.monitor
        if self._busy or not m.due(t):  # due again at every sample while the last check runs: it waits, not queued
            return
        last = m.last_check
        if last is not None:  # the periods that passed while the last check ran
            self.skipped += max(int(math.floor((t - last) / m.config.check_period_s + 1e-9)) - 1, 0)
        with self._lock:
            window = m.window(t)
        if self.inline or self._checks is None:
            self._check(window, t)
        else:
            self._busy = True
            self._checks.put((window, t))

    def _check_loop(self) -> None:
        assert self._checks is not None
        while True:
            window, t = self._checks.get()
            try:
                self._check(window, t)
            finally:
                self._busy = False

    def _check(self, window: Any, t: float) -> None:
        m = self.monitor
        try:
            mm = m.model
            raw = diagnose_window(
                window, t, m.config, mm.hysteresis_file, mm.thermal_file, mm.extension, mm.params_file
            )
        except Exception as exc:  # noqa: BLE001 - a check that failed is reported, the monitor goes on
            raw = Verdict(t, 'ERROR', None, None, 1.0, summary=f'the check failed: {type(exc).__name__}: {exc}')
        with self._lock:
            v = m.decide(raw)
            episodes = m.episodes()
        self.send(('verdict', v, episodes, self.skipped, time.process_time()))

    def run(self, get: Callable[[], tuple | None]) -> None:
        """Serve messages from ``get`` until it returns None."""
        while (msg := get()) is not None:
            self.handle(msg)


def serve(config: MonitorConfig, niceness: int | None, inbox: Any, outbox: Any) -> None:
    """A worker process' main: niced (:func:`start_worker`), it serves the node's messages from the ``inbox``
    connection and answers on ``outbox`` (blocking: its own threads wait, never the node)."""
    start_worker(niceness)
    lock = threading.Lock()  # the twin's and the checks' answers come from two threads

    def send(msg: tuple) -> None:
        with lock:
            outbox.send(msg)

    def get() -> tuple | None:
        try:
            return inbox.recv()
        except EOFError:  # the node closed its end
            return None

    MonitorWorker(config, send).run(get)


class WorkerLink:
    """The node's end: :meth:`send` never blocks, :meth:`poll` returns what the worker answered so far (never
    waits).

    To a worker process the node writes and reads the pipes itself, non-blocking, in the frames of
    :class:`multiprocessing.connection.Connection` (4-byte length, pickle), with no thread of its own: a
    :class:`multiprocessing.Queue`'s feeder thread took the interpreter lock from the control loop at every batch,
    which cost the graph a quarter of its speed on a busy machine. What the worker has not read yet waits in the
    node's memory."""

    def __init__(self, where: str, config: MonitorConfig, nice: int = 19) -> None:
        self.where = where
        self._proc: Any = None
        config = dataclasses.replace(config)  # the worker's own copy (a thread must not share the node's)
        if where == 'inline':
            self._answers: list[tuple] = []
            self._worker = MonitorWorker(config, self._answers.append, inline=True)
        elif where == 'thread':
            self._in: Any = queue.SimpleQueue()
            self._out: Any = queue.SimpleQueue()
            worker = MonitorWorker(config, self._out.put)
            threading.Thread(target=worker.run, args=(self._in.get,), name='twin_monitor_worker', daemon=True).start()
        elif where == 'process':
            import multiprocessing

            # spawn: a fork of a process running rclpy's threads may inherit a held lock
            ctx = multiprocessing.get_context('spawn')
            their_in, self._in = ctx.Pipe(duplex=False)
            self._out, their_out = ctx.Pipe(duplex=False)
            niceness = worker_niceness(int(nice))
            self._proc = ctx.Process(
                target=serve, args=(config, niceness, their_in, their_out), name='twin_monitor_worker', daemon=True
            )
            self._proc.start()
            # niced at once, not in serve(): a spawned worker first imports the monitor (about 1.2 s of CPU), which
            # at the node's priority took the graph's CPU while it started
            lower_priority(self._proc.pid, niceness)
            their_in.close()
            their_out.close()
            os.set_blocking(self._in.fileno(), False)
            os.set_blocking(self._out.fileno(), False)
            self._unsent = bytearray()
            self._unread = bytearray()
        else:
            raise ValueError(f'worker {where!r}: process, thread or inline')

    def send(self, msg: tuple) -> None:
        if self.where == 'inline':
            self._worker.handle(msg)
        elif self.where == 'closed':
            return
        elif self._proc is None:
            self._in.put(msg)
        else:
            b = pickle.dumps(msg, protocol=pickle.HIGHEST_PROTOCOL)
            self._unsent += struct.pack('!i', len(b)) + b
            try:
                n = os.write(self._in.fileno(), self._unsent)
            except BlockingIOError:  # the worker is behind: kept for the next batch
                return
            except OSError:  # the worker ended (ended() says so)
                self._unsent.clear()
                return
            del self._unsent[:n]

    def poll(self) -> list[tuple]:
        if self.where == 'inline':
            out, self._answers[:] = list(self._answers), []
            return out
        if self.where == 'closed':
            return []
        if self._proc is None:
            out = []
            while True:
                try:
                    out.append(self._out.get_nowait())
                except queue.Empty:
                    return out
        while True:
            try:
                chunk = os.read(self._out.fileno(), 1 << 16)
            except (BlockingIOError, OSError):
                break
            if not chunk:
                break
            self._unread += chunk
        out = []
        while len(self._unread) >= 4:
            (n,) = struct.unpack('!i', self._unread[:4])
            if len(self._unread) < 4 + n:
                break
            out.append(pickle.loads(self._unread[4 : 4 + n]))
            del self._unread[: 4 + n]
        return out

    def ended(self) -> int | None:
        """The worker process' exit code once it ended unasked (None while it runs; threads do not end)."""
        return None if self._proc is None or self._proc.is_alive() else self._proc.exitcode

    def close(self) -> None:
        """Stop the worker: a check still running is abandoned (its process ended, not waited for: a niced
        process on a busy machine may take seconds to be scheduled and end)."""
        if self._proc is not None:
            self._proc.terminate()
            self._in.close()
            self._out.close()
            self._proc = None
            self.where = 'closed'
        elif self.where == 'thread':
            self._in.put(None)
