"""Live model monitoring of a running wrist: is it still its model, and if not, what changed since when.

:class:`Monitor` is fed the contract topics as they arrive (TEM commands, muscle temperatures, the angle, the
payload, and where the device gives them the drive it read back and the TEMs' exchanger-face temperatures). It runs
a :class:`~sma_wrist.monitor.twin.Twin` (the plant model on the TEM drive) beside the wrist, keeps the recent
samples, and every ``check_period_s`` runs the model-discrepancy diagnosis (:func:`sma_wrist.diagnose.diagnose_run`,
doc/explanation/diagnosis.md) on a rolling window of them:

* the TEM drive is the device's read-back (``/wrist/tem_drive_applied``, stamped where it took effect) where it is
  sent, else the commands, per TEM: on hardware a command takes effect after the graph's delay, which its stamp (the
  window it answers) does not say, and replayed on the commands a nominal wrist was an unexplained thermal
  discrepancy (the diagnosis' choice, :func:`sma_wrist.diagnose.data.load_run`);

* the window is ``settle_s + window_s`` long; the first ``settle_s`` only settle the replays' memory (the wires'
  hysteresis and the joint start where the wrist was, not from rest), and the thermal replay starts from the
  exchanger faces measured at the window's start (``/wrist/tem_{1,2}/face_temperature``) where they are published,
  else from the twin's heat-balance state (:attr:`sma_wrist.diagnose.data.Run.thermal_x0`): cut from the middle of
  a clean run, a window replayed from rest was an "unexplained discrepancy" in 2 of 3 checks. The twin itself
  starts from the measured faces (a wrist whose TEMs are still warm from an excitation is not at rest);
* where the twin's residuals changed inside the window (:func:`change_point`), the part after the change is
  diagnosed, from just before it when the temperatures changed (:data:`CHANGE_SETTLE_S`), with ``settle_s`` before
  it when only the angle did; while such a change is unnamed a check is due every :data:`FRESH_PERIOD_S` from
  :data:`MIN_AFTER_CHANGE_S` after it;
* where the diagnosis names nothing, a slow ambient / coolant drift is fitted to the 1 s averages of the whole
  window (:mod:`.drift`): the diagnosis' held-out split sees a drift only once it is 1.6 x the per-sample noise;
* a verdict is *raised* only when ``persist_checks`` consecutive checks agree on the subsystem with a confidence of
  at least ``min_confidence``, and cleared after as many clean checks (a single noisy window is no alarm); an
  "unexplained" one only after 90 s, unless a catalogue cause removed most of it (:data:`PARTIAL_NAME_GAIN_PCT`).

The check is split so that a node can run the costly part in a worker thread: :meth:`Monitor.window` (cheap, under
the node's lock) cuts the window, :meth:`Monitor.diagnose` (seconds of CPU) diagnoses it, :meth:`Monitor.decide`
(cheap) updates the verdict. ``sma-wrist monitor BAG`` (:mod:`.playback`) plays a bag through the same object.
See doc/explanation/monitor.md (the method) and doc/howto/monitor.md (its use).
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import math
import signal
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from sma_wrist.diagnose.data import (
    DRIVE_TOPIC,
    FACE_START_TOLERANCE_S,
    START_RANGE_C,
    TOPICS,
    DiagnoseInputError,
    Run,
    run_from_series,
    start_at_faces,
)
from sma_wrist.monitor.twin import Model, MonitorInputError, Twin, load_model

__all__ = ['MonitorConfig', 'Monitor', 'Verdict', 'MonitorInputError', 'LEVELS', 'ignore_interrupts']


def ignore_interrupts() -> None:
    """A check worker's initializer: the terminal's Ctrl-C reaches the whole process group, and the node that owns
    the worker shuts it down; a worker that took the SIGINT itself printed a KeyboardInterrupt on every Ctrl-C."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


#: DiagnosticStatus levels (diagnostic_msgs): OK 0, WARN 1, ERROR 2
LEVELS = {'OK': 0, 'WARN': 1, 'ERROR': 2}
#: a known extension (a diagnosis' extended_params.yaml) is recognised when every parameter of a named cause is one
#: of it and within this fraction of its value (or of its catalogue typical magnitude, for a value near 0)
KNOWN_TOLERANCE = 0.3
#: extra history kept beyond the window [s]: stamps jitter and the grid needs both ends
MARGIN_S = 2.0
#: the twin's residuals are averaged over blocks of this length [s] before their change point is located (the
#: 100 Hz samples' noise averaged down, the effects' seconds kept)
CP_BLOCK_S = 1.0
#: a change point needs this many blocks on either side of it
CP_MIN_SEG = 5
#: a change point counts when its likelihood ratio (:func:`change_point`) reaches this: measured on the first 210 s
#: of a pid recording with 0.1 degC / 1 mrad noise, windows without a change reached 33-89 (177 on a noise-free
#: one, at the start of the run), windows with one of the benchmark's effects in them 200-1050
CP_THRESHOLD = 150.0
#: a window with a change in its scored part is diagnosed on what follows the change once this much of it is in [s];
#: before that the check names nothing. With 20 s (the diagnosis' shortest scored part) a 2 V driver dead zone was
#: named `recalibrate_thermal` (thermal, confidence 1.0) 20 s after its onset; 35 s after it, it was unexplained
MIN_AFTER_CHANGE_S = 30.0
#: while a located change is not yet named, a check is due MIN_AFTER_CHANGE_S after it and then every this long [s]
#: (until it is named or the window holds nothing from before it), instead of every ``check_period_s``
FRESH_PERIOD_S = 5.0
#: the window diagnosed after a change starts this long before it [s] (the change is placed to a block, the onset may
#: be up to a block earlier). Not ``settle_s``: an effect the fit applies from the window's start acted over the
#: lead-in too, and the replay entered the change from a state the wrist never had. Measured 30-35 s after the
#: onset on a pid recording: with 20 s before the change a driver dead zone of 2 V and a thermocouple lag of 4 s
#: were "unexplained" (the best fit removed 62 % / 43 % of the thermal misfit), with 5 s 77 % / 73 %, starting at
#: the change they were named 35 s after the onset (2.04 V with 95 % of the misfit removed, 3.85 s)
CHANGE_SETTLE_S = 2.0
#: a check whose diagnosis is "unexplained" but whose best catalogue cause was significant and removed at least this
#: share of its channel's misfit [%] (the diagnosis' ``partial``: it names a cause only above 80 %) names that cause's
#: subsystem, raised like a named cause after ``persist_checks`` agreeing checks rather than after the unexplained
#: rule's 90 s: the straddled window that rule waits out fits no cause that well. 30-40 s after their onsets on pid
#: recordings (0.1 degC / 1 mrad): TEMs 20 % weaker, recalibrate_thermal 61-68 % (named at 80 % only 60 s after);
#: a thermocouple offset of 3 degC, temp_sensor_offsets 74-75 % (recalibrate_thermal 42 % 30 s after, not named)
PARTIAL_NAME_GAIN_PCT = 50.0
#: ... when the temperatures' residuals changed (their share of the change statistic at the split reaches this
#: fraction of CP_THRESHOLD): a change in the angle alone (a potentiometer fault, a payload, the wires) is
#: diagnosed with ``settle_s`` before it, which the mechanics replay's memory needs (from the change on, a
#: potentiometer offset, lag and a payload were "unexplained" 35 s after the onset; with settle_s named)
THERMAL_CHANGE_SHARE = 0.5
#: a TEM's command is not the twin's input while the device's read-back of that TEM's drive is at most this old [s]
#: (measurement time); older, the device has stopped reading it back (or never did) and the commands drive the twin.
#: A window replays a TEM's read-back when it covers the window to within this at both ends
READBACK_FRESH_S = 1.0
#: a live monitor's checks are falling behind the wrist (twin_monitor's WARN on ``twin_monitor: checks``) once the
#: newest sample received is more than this many check periods past the end of the window last checked: one period
#: is their rhythm and a check takes seconds, so a worker that keeps up stays within about one; a worker starved of
#: CPU takes its input in order and checks in its own time (at load 11 one made a single check in 210 s of an
#: emulated device and skipped no period)
BEHIND_PERIODS = 2.0


@dataclass
class MonitorConfig:
    """What the monitor checks against and how often (every field is a node parameter and a CLI option)."""

    window_s: float = 45.0  # scored part of the window [s]
    settle_s: float = 20.0  # lead-in that settles the replays' memory [s]
    check_period_s: float = 15.0  # time between checks [s]
    persist_checks: int = 2  # consecutive agreeing checks before a verdict is raised or cleared
    min_confidence: float = 0.5  # a discrepancy verdict at or below this confidence counts as OK
    sure_confidence: float = 0.95  # a named cause at or above this confidence is raised by one check
    candidates: tuple[str, ...] | None = None  # catalogue ids to try (None: all)
    hysteresis_file: str = ''
    thermal_file: str = ''
    params_file: str = ''  # a diagnosis' extended_params.yaml

    def check(self) -> MonitorConfig:
        """Raise MonitorInputError for values that cannot work."""
        from sma_wrist.diagnose.data import MIN_DURATION_S

        if not (
            math.isfinite(self.window_s) and self.window_s >= MIN_DURATION_S - self.settle_s and self.window_s >= 20.0
        ):
            raise MonitorInputError(
                f'window_s = {self.window_s:g} s: the diagnosis needs at least 20 s to score and '
                f'{MIN_DURATION_S:g} s in all (window_s + settle_s)'
            )
        if not (math.isfinite(self.settle_s) and self.settle_s >= 0):
            raise MonitorInputError(f'settle_s = {self.settle_s:g} s must be >= 0')
        if not (math.isfinite(self.check_period_s) and self.check_period_s > 0):
            raise MonitorInputError(f'check_period_s = {self.check_period_s:g} s must be > 0')
        if self.persist_checks < 1:
            raise MonitorInputError(f'persist_checks = {self.persist_checks} must be >= 1')
        if not 0.0 <= self.min_confidence <= 1.0:
            raise MonitorInputError(f'min_confidence = {self.min_confidence:g} must be in [0, 1]')
        if not self.min_confidence <= self.sure_confidence <= 1.0:
            raise MonitorInputError(f'sure_confidence = {self.sure_confidence:g} must be in [min_confidence, 1]')
        if self.candidates:
            from sma_wrist.diagnose import effects as fx

            unknown = [c for c in self.candidates if c not in fx.EFFECTS]
            if unknown:
                raise MonitorInputError(
                    f'unknown candidate(s) {", ".join(unknown)}; catalogue: {", ".join(fx.EFFECTS)}'
                )
        return self


@dataclass
class Verdict:
    """What the monitor says after one check (times in the recording's / node's clock [s])."""

    t_s: float  # end of the checked window
    level: str  # OK | WARN | ERROR
    cause: str | None  # catalogue id, 'unexplained', or None while OK / ERROR
    subsystem: str | None
    confidence: float
    parameters: dict[str, float] = field(default_factory=dict)
    gain_pct: float = 0.0
    summary: str = ''
    correlates: list[dict[str, Any]] = field(default_factory=list)
    #: what this check's diagnosis said, before the persistence rule (the published level may differ)
    check_cause: str | None = None
    check_subsystem: str | None = None
    check_confidence: float = 0.0
    check_cpu_s: float = 0.0
    since_s: float | None = None  # when the raised verdict was first seen (its onset as the monitor saw it)
    change_s: float | None = None  # where the twin's residuals changed inside the window, if they did [s]
    pending: bool = False  # a change too recent to diagnose: this check neither raises nor clears anything
    partial: bool = False  # the cause explains most, not all, of the misfit (PARTIAL_NAME_GAIN_PCT)
    drift_fit: bool = False  # named by the slow-drift fit (drift.py), not by the diagnosis
    #: how far this check came behind the wrist [s]: the stamp of the newest sample received when its verdict was
    #: made minus ``t_s`` (a check's own seconds; more when the check worker is starved of CPU and falls behind)
    behind_s: float | None = None

    def to_json(self) -> dict[str, Any]:
        from sma_wrist.diagnose import _plain

        return _plain(asdict(self))


def _key(v: Verdict) -> tuple[str, str | None]:
    """What must persist: the level and the subsystem (the cause may be refined from check to check)."""
    return v.level, v.subsystem


class Monitor:
    """The monitor of one wrist; feed it with :meth:`command`, :meth:`temperature`, :meth:`angle`, :meth:`payload`,
    and where the device gives them :meth:`drive` and :meth:`face`."""

    def __init__(self, config: MonitorConfig | None = None, model: Model | None = None) -> None:
        self.config = (config or MonitorConfig()).check()
        c = self.config
        self.model = model or load_model(c.hysteresis_file or None, c.thermal_file or None, c.params_file or None)
        self.twin: Twin | None = None
        self.payload_kg: float | None = None
        self._payload_pending = 0.3
        # the contract topics' samples (TOPICS keys), the read-back drive ('a1', 'a2') and the exchanger faces ('F1',
        # 'F2')
        keys = [k for k in TOPICS if k != 'payload'] + ['a1', 'a2', 'F1', 'F2']
        self._buf: dict[str, tuple[list[float], list[float]]] = {k: ([], []) for k in keys}
        self._readback_s: list[float | None] = [None, None]  # the newest read-back stamp per TEM [s]
        self._twin_start_s: float | None = None
        self._faces_started = False  # the twin's heat balance was set from the measured faces (or can no longer be)
        self.t_first: float | None = None
        self.t_last: float | None = None
        self.last_check: float | None = None
        self.history: list[Verdict] = []
        self.current: Verdict | None = None  # the raised verdict
        self._streak: list[Verdict] = []
        self._change_s: float | None = None  # the last change located in the twin's residuals [s]
        self._fresh_s: float | None = None  # a located change nothing has been raised for yet [s]
        self.change_thermal = False  # the temperatures' residuals changed there too

    # -- input ----------------------------------------------------------------------------------------------
    def payload(self, kg: float) -> None:
        """``/wrist/payload`` [kg] (latched): the twin carries it."""
        self.payload_kg = float(kg)
        if self.twin is not None:
            self.twin.set_payload(kg)

    def command(self, i: int, t_s: float, volts: float) -> None:
        """TEM ``i`` (1, 2) commanded ``volts`` [V] at ``t_s`` [s]; the twin's input unless the device reads that
        TEM's drive back (:meth:`drive`)."""
        if not math.isfinite(volts):
            return
        self._append(f'u{i}', t_s, volts)
        last = self._readback_s[i - 1]
        if last is None or t_s - last > READBACK_FRESH_S:
            self._ensure_twin(t_s).set_command(i - 1, volts)

    def drive(self, i: int, t_s: float, volts: float) -> None:
        """TEM ``i`` (1, 2) got ``volts`` [V] from ``t_s`` [s] on, as the device read it back (``DRIVE_TOPIC``:
        the drive at a window's middle, stamped at the window's start in device time, held like a command until the
        next): the twin's input and the checks' in place of that TEM's commands."""
        if not math.isfinite(volts):
            return
        self._append(f'a{i}', t_s, volts)
        last = self._readback_s[i - 1]
        self._readback_s[i - 1] = t_s if last is None else max(last, t_s)
        twin = self._ensure_twin(t_s)
        # the drive clocks the twin too: the device reads back every window, the windows the host skipped included
        # (no measurement of them), and each held only over its own
        twin.advance_to(t_s)
        twin.set_command(i - 1, volts)

    def face(self, i: int, t_s: float, celsius: float) -> None:
        """TEM ``i``'s (1, 2) exchanger face measured ``celsius`` [degC], stamped ``t_s`` [s]: the twin's heat balance
        starts there, and each check's thermal replay starts from the faces measured at its window's start."""
        if not math.isfinite(celsius):
            return
        self._append(f'F{i}', t_s, celsius)
        if not self._faces_started:
            self._start_at_faces(t_s)

    def _start_at_faces(self, t_s: float) -> None:
        """Set the twin's heat balance from the first measured faces and muscles, when they come within
        FACE_START_TOLERANCE_S of its start (later, the twin has run on and a jump would read as a change)."""
        if self.twin is None or self._twin_start_s is None:
            return
        if t_s - self._twin_start_s > FACE_START_TOLERANCE_S:
            self._faces_started = True
            return
        b = self._buf
        if not all(b[k][1] for k in ('F1', 'F2', 'T1', 'T2')):
            return
        x = np.array([[b['T1'][1][-1], b['F1'][1][-1]], [b['T2'][1][-1], b['F2'][1][-1]]])
        if np.all((x > START_RANGE_C[0]) & (x < START_RANGE_C[1])):
            self.twin.set_thermal_state(x)
        self._faces_started = True

    def temperature(self, i: int, t_s: float, celsius: float) -> None:
        """Muscle ``i`` (1, 2) measured ``celsius`` [degC], stamped ``t_s`` [s]."""
        self._append(f'T{i}', t_s, celsius)
        if not self._buf['joint'][0] and i == 1:  # no angle topic: the thermocouple's stamps clock the twin
            self.tick(t_s)

    def angle(self, t_s: float, rad: float) -> None:
        """Wrist angle [rad] stamped ``t_s`` [s]; clocks the twin."""
        self._append('joint', t_s, rad)
        self.tick(t_s)

    def tick(self, t_s: float) -> None:
        """Advance the twin to the measurement stamp ``t_s`` [s] (it keeps its heat-balance state at each)."""
        self._ensure_twin(t_s).advance_to(t_s)

    def _ensure_twin(self, t_s: float) -> Twin:
        if self.twin is None:
            self.twin = Twin(self.model, self.payload_kg if self.payload_kg is not None else self._payload_pending)
            self.twin.advance_to(t_s)
            self._twin_start_s = float(t_s)
        return self.twin

    def _append(self, key: str, t_s: float, v: float) -> None:
        t, x = self._buf[key]
        t.append(float(t_s))
        x.append(float(v))
        if self.t_first is None or t_s < self.t_first:
            self.t_first = float(t_s)
        if self.t_last is None or t_s > self.t_last:
            self.t_last = float(t_s)

    def residuals(self) -> dict[str, float]:
        """Latest measured minus twin: ``T1``, ``T2`` [degC] and ``q`` [rad] (NaN where nothing was measured)."""
        out = {'T1': float('nan'), 'T2': float('nan'), 'q': float('nan')}
        if self.twin is None:
            return out
        T = self.twin.temperatures_C
        for i in (1, 2):
            x = self._buf[f'T{i}'][1]
            if x:
                out[f'T{i}'] = x[-1] - float(T[i - 1])
        if self._buf['joint'][1]:
            out['q'] = self._buf['joint'][1][-1] - self.twin.angle_rad
        return out

    # -- checks ---------------------------------------------------------------------------------------------
    @property
    def span_s(self) -> float:
        return self.config.window_s + self.config.settle_s

    def due(self, t_s: float) -> bool:
        """A check is due at ``t_s``: a full window of data and ``check_period_s`` since the last check; while a
        located change is unnamed, from ``MIN_AFTER_CHANGE_S`` after it every ``FRESH_PERIOD_S``."""
        if self.t_first is None or t_s - self.t_first < self.span_s:
            return False
        if self.last_check is None or t_s - self.last_check >= self.config.check_period_s - 1e-9:
            return True
        c = self._fresh_s
        return (
            c is not None
            and MIN_AFTER_CHANGE_S - 1e-9 <= t_s - c <= self.span_s
            and t_s - self.last_check >= min(FRESH_PERIOD_S, self.config.check_period_s) - 1e-9
        )

    def window(self, t_s: float) -> Run | Change | str:
        """The window ending at ``t_s`` as a Run (or a message saying why it cannot be checked); trims the buffers.

        Cheap: call it where the samples arrive (under the node's lock), then :meth:`diagnose` elsewhere."""
        self.last_check = t_s
        lo = t_s - self.span_s
        self._trim(lo - MARGIN_S)
        change = self.locate_change(lo, t_s)
        if change is not None and (self.current is None or (self.current.since_s or 0.0) < change):
            self._fresh_s = change  # nothing raised since it: checked often until it is named
        if change is not None and t_s - change < MIN_AFTER_CHANGE_S:
            # too recent to diagnose; the whole window still goes along for the drift test (drift.py), which a
            # change inside it does not mislead
            whole = self._cut(lo, t_s, None)
            return Change(change, t_s - change, whole if isinstance(whole, Run) else None)
        return self._cut(lo, t_s, change)

    def _cut(self, lo: float, t_s: float, change: float | None) -> Run | str:
        """The samples of [lo, t_s] as a Run; with a ``change`` [s] only what follows it (from just before it when
        the temperatures changed, with ``settle_s`` before it when only the angle did)."""
        if change is not None:
            # the part after the change is diagnosed (a constant-parameter fit over a window with a change in it gave
            # confident wrong answers), from just before it: the fitted effect acts from the window's start
            lo = change - (CHANGE_SETTLE_S if self.change_thermal else self.config.settle_s)
        series = {}
        for k, (t, x) in self._buf.items():
            ta, xa = np.asarray(t), np.asarray(x)
            sel = (ta >= lo) & (ta <= t_s)
            if sel.sum() > 1:
                o = np.argsort(ta[sel], kind='stable')
                series[k] = (ta[sel][o], xa[sel][o])
        faces = [series.pop(f'F{i}', None) for i in (1, 2)]
        applied = 0
        for i in (1, 2):
            a = series.pop(f'a{i}', None)
            # a TEM's read-back where it covers the window (else its commands: a device without it, or it stopped)
            if a is not None and a[0][0] - lo <= READBACK_FRESH_S and t_s - a[0][-1] <= READBACK_FRESH_S:
                series[f'u{i}'] = a
                applied += 1
        if self.payload_kg is not None:
            series['payload'] = (np.array([lo]), np.array([self.payload_kg]))
        warnings: list[str] = []
        if 'u1' not in series or 'u2' not in series:
            return (
                f'no TEM commands in the last {self.span_s:g} s: the twin runs on {TOPICS["u1"]} and '
                f'{TOPICS["u2"]} (std_msgs/Float64, V) or the drive read back on {DRIVE_TOPIC}; is tem_controller '
                f'(or the bridge) running?'
            )
        try:
            run = run_from_series(series, f'window {lo:.1f}-{t_s:.1f} s', warnings)
        except DiagnoseInputError as exc:
            return str(exc)
        run.drive = 'applied' if applied == 2 else 'commanded'
        # the replay's heat balance starts from the faces measured at the window's first sample, else where the twin
        # had it there
        if not (faces[0] is not None and faces[1] is not None and not start_at_faces(run, faces)):
            if self.twin is not None:
                run.thermal_x0 = self.twin.thermal_state_at(run.t0_s)
                run.thermal_start = 'twin'
        run.settle_s = min(self.config.settle_s if change is None else change - lo, max(run.duration - 20.0, 0.0))
        if change is not None:
            run.change_s = change
        return run

    def locate_change(self, lo: float, hi: float) -> float | None:
        """Where the twin's residuals changed in [lo, hi] [s], when that is inside the scored part (after
        ``settle_s``) and significant (:data:`CP_THRESHOLD`); None otherwise. Sets :attr:`change_thermal`: the
        temperatures' residuals changed there too (:data:`THERMAL_CHANGE_SHARE`)."""
        tb, R, keys = self.residual_blocks(lo, hi)
        if R.size == 0:
            return None
        k, stat, per = change_point(R, per_channel=True)
        if stat < CP_THRESHOLD or k == 0:
            return None
        thermal = sum(float(x) for key, x in zip(keys, per) if key != 'joint') >= THERMAL_CHANGE_SHARE * CP_THRESHOLD
        t_cp = float(tb[k])
        if self._change_s is not None and 0.0 < t_cp - self._change_s < self.span_s:
            # the same change still unfolding (the loop answering a weaker TEM moved the split on by 20-25 s, and
            # the part after it was unexplained): what follows the first change is the new wrist
            t_cp = self._change_s
            self.change_thermal = self.change_thermal or thermal
        else:
            self._change_s = t_cp
            self.change_thermal = thermal
        return t_cp if t_cp - lo > self.config.settle_s else None

    def residual_blocks(self, lo: float, hi: float) -> tuple[np.ndarray, np.ndarray, list[str]]:
        """Measured minus twin over [lo, hi], averaged over blocks of ``CP_BLOCK_S``: block starts (B,) [s],
        residuals (B, C) and their channels (of T1, T2 [degC], joint [rad]: those measured throughout)."""
        none: tuple[np.ndarray, np.ndarray, list[str]] = (np.empty(0), np.empty((0, 0)), [])
        if self.twin is None:
            return none
        tt, T, q = self.twin.predictions(lo, hi)
        nb = int((hi - lo) // CP_BLOCK_S)
        if nb < 1 or tt.size < 2:
            return none
        cols, keys = [], []
        for key, pred in (('T1', T[:, 0]), ('T2', T[:, 1]), ('joint', q)):
            t, x = self._buf[key]
            ta, xa = np.asarray(t), np.asarray(x)
            sel = (ta >= lo) & (ta < lo + nb * CP_BLOCK_S)
            if sel.sum() < nb:
                continue
            ta, xa = ta[sel], xa[sel]
            r = xa - np.interp(ta, tt, pred)
            b = ((ta - lo) // CP_BLOCK_S).astype(int)
            cnt = np.bincount(b, minlength=nb)
            if (cnt == 0).any():
                continue  # a gap: that channel cannot place a change
            cols.append(np.bincount(b, weights=r, minlength=nb) / cnt)
            keys.append(key)
        if not cols:
            return none
        return lo + CP_BLOCK_S * np.arange(nb), np.stack(cols, axis=1), keys

    def _trim(self, t_min: float) -> None:
        if self.twin is not None:
            self.twin.trim(t_min)
        for t, x in self._buf.values():
            n = int(np.searchsorted(np.asarray(t), t_min)) if t else 0
            if n > 0:
                del t[:n]
                del x[:n]

    def diagnose(self, window: Run | Change | str, t_s: float) -> Verdict:
        """Diagnose one window (the costly part: seconds of CPU); returns this check's verdict, before persistence."""
        m = self.model
        return diagnose_window(window, t_s, self.config, m.hysteresis_file, m.thermal_file, m.extension, m.params_file)

    def needed(self, v: Verdict) -> int:
        """Consecutive checks that must agree before ``v`` is published: ``persist_checks`` (also for a cause that
        explains most of an unexplained misfit, :data:`PARTIAL_NAME_GAIN_PCT`, and for a drift named by the drift
        fit: one window's fit, no bootstrap over held-out segments; on 30 min of nominal inverse_adaptive through
        realistic sensors one window's slow residual fitted -14 degC/h at 7.2 standard errors, the windows 5 s
        before and 15 s after 5.1 and 0.8), one for a cause named
        with at least ``sure_confidence``; for an unexplained
        discrepancy, as many as it takes the window to hold only data after a change (a wrist that changed inside
        the window fits no constant model: the windows straddling a change are unexplained before the change
        is named)."""
        k = self.config.persist_checks
        if v.cause == 'unexplained':
            return k + int(math.ceil(self.span_s / self.config.check_period_s - 1e-9))
        if v.level == 'WARN' and v.confidence >= self.config.sure_confidence and not (v.partial or v.drift_fit):
            # a cause named with (nearly) every bootstrap resample agreeing: raised at once, so that an effect is
            # named within window_s + check_period_s of its onset (one check later, 75 s with the defaults)
            return 1
        return k

    def _persisted(self, v: Verdict) -> bool:
        """The streak ending with ``v`` is long enough to publish ``v``: :meth:`needed` checks, and for an unexplained
        discrepancy as long in time as that many checks ``check_period_s`` apart (checks come faster while a change
        is fresh, and the windows right after a change are unexplained until enough of it is in to name it)."""
        n = self.needed(v)
        if len(self._streak) < n:
            return False
        if v.cause != 'unexplained':
            return True
        return self._streak[-1].t_s - self._streak[0].t_s >= (n - 1) * self.config.check_period_s - 1e-9

    def decide(self, v: Verdict) -> Verdict:
        """Apply the persistence rule to this check's verdict; returns the published one and keeps it in history."""
        cur = self.current
        if v.pending:  # a change too recent to name: the published verdict stands, the streak waits
            out = dataclasses.replace(cur, t_s=v.t_s) if cur is not None else v
            if cur is not None:
                out.summary = f'{v.summary}; raised before it: {cur.summary}'
                out.parameters, out.correlates = dict(cur.parameters), list(cur.correlates)
                out.change_s, out.pending = v.change_s, True
            return self._keep(out)
        if _key(v) == (_key(cur) if cur is not None else ('OK', None)):
            self._streak = []
            if v.level != 'OK':
                v.since_s = cur.since_s if cur is not None else v.t_s
                self.current = v  # the same subsystem: refreshed cause, parameters, confidence
            out = v
        else:
            if self._streak and _key(self._streak[-1]) != _key(v):
                self._streak = []
            self._streak.append(v)
            if self._persisted(v):
                since = self._streak[0].t_s
                self._streak = []
                if v.level == 'OK':
                    self.current = None
                else:
                    v.since_s = since
                    self.current = v
                    self._fresh_s = None  # named
                out = v
            else:  # not (yet) persistent: the raised verdict (or OK) stands; this check's view is attached
                pending = f'{v.level} {v.cause or ""} in this check ({len(self._streak)} of {self.needed(v)} needed): '
                if cur is None:
                    out = Verdict(
                        v.t_s,
                        'OK',
                        None,
                        None,
                        v.confidence if v.level == 'OK' else 1.0 - v.confidence,
                        summary=pending + v.summary,
                    )
                else:
                    out = Verdict(
                        v.t_s,
                        cur.level,
                        cur.cause,
                        cur.subsystem,
                        cur.confidence,
                        dict(cur.parameters),
                        cur.gain_pct,
                        pending + v.summary,
                        list(cur.correlates),
                        since_s=cur.since_s,
                    )
                out.check_cause, out.check_subsystem = v.check_cause, v.check_subsystem
                out.check_confidence, out.check_cpu_s = v.check_confidence, v.check_cpu_s
        return self._keep(out)

    def _keep(self, out: Verdict) -> Verdict:
        """Keep a published verdict in the history, with how far behind the newest sample fed it came."""
        if self.t_last is not None:  # the samples fed while the check ran (a node knows of newer ones: it sets its own)
            out.behind_s = max(self.t_last - out.t_s, 0.0)
        self.history.append(out)
        return out

    def check(self, t_s: float) -> Verdict:
        """Cut, diagnose and decide in one call (what playback does; a node splits it over its worker thread)."""
        return self.decide(self.diagnose(self.window(t_s), t_s))

    # -- history --------------------------------------------------------------------------------------------
    def episodes(self) -> list[dict[str, Any]]:
        """Each raised verdict once: level, subsystem, the causes named (first first), onset_s (the first check that
        saw it), raised_s (when it was published), until_s (None: still raised)."""
        out: list[dict[str, Any]] = []
        for v in self.history:
            open_ = out[-1] if out and out[-1]['until_s'] is None else None
            if v.level == 'OK' or (open_ is not None and (open_['level'], open_['subsystem']) != _key(v)):
                if open_ is not None:
                    open_['until_s'] = v.t_s
                    open_ = None
            if v.level == 'OK':
                continue
            if open_ is None:
                out.append(
                    {
                        'level': v.level,
                        'subsystem': v.subsystem,
                        'cause': v.cause,
                        'causes': [],
                        'onset_s': v.since_s if v.since_s is not None else v.t_s,
                        'raised_s': v.t_s,
                        'until_s': None,
                        'parameters': dict(v.parameters),
                        'confidence': v.confidence,
                    }
                )
                open_ = out[-1]
            if v.cause is not None and v.cause not in open_['causes']:
                open_['causes'].append(v.cause)
            open_['parameters'], open_['confidence'] = dict(v.parameters), v.confidence
        return out


@dataclass
class Change:
    """A window whose residuals changed too recently to diagnose what follows: at ``t_s``, ``after_s`` ago [s]."""

    t_s: float
    after_s: float
    run: Run | None = None  # the whole window, for the drift test


def diagnose_window(
    window: Run | Change | str,
    t_s: float,
    config: MonitorConfig,
    hysteresis_file: str | None = None,
    thermal_file: str | None = None,
    extension: dict[str, float] | None = None,
    params_file: str | None = None,
) -> Verdict:
    """One check's verdict on a window (:meth:`Monitor.window`), before persistence; a plain function of picklable
    arguments, so that a node can run it in a worker process. ``extension``: the known model extension;
    ``params_file``: the params file whose plant model (pre-load, ``model.*`` values) the diagnosis replays."""
    v = _diagnose(window, t_s, config, hysteresis_file, thermal_file, extension, params_file)
    change = getattr(window, 'change_s', None)
    if change is not None:  # the part after a change in the window was diagnosed
        v.change_s = change
        v.summary = f'after the change at {change:.1f} s: {v.summary}'
    return v


def _diagnose(
    window: Run | Change | str,
    t_s: float,
    config: MonitorConfig,
    hysteresis_file: str | None,
    thermal_file: str | None,
    extension: dict[str, float] | None,
    params_file: str | None = None,
) -> Verdict:
    import time

    if isinstance(window, Change):
        drift = _drift_verdict(window.run, t_s, config, hysteresis_file, thermal_file, extension, params_file)
        if drift is not None:  # the whole window, the change in it too recent to diagnose
            drift.change_s = window.t_s
            return drift
        return Verdict(
            t_s,
            'OK',
            None,
            None,
            0.0,
            summary=f'the residuals changed at {window.t_s:.1f} s; named once {MIN_AFTER_CHANGE_S:g} s after it are in '
            f'({window.after_s:.1f} s so far)',
            change_s=window.t_s,
            pending=True,
        )
    if isinstance(window, str):
        return Verdict(t_s, 'ERROR', None, None, 1.0, summary=f'cannot check: {window}')
    from sma_wrist.diagnose import diagnose_run

    c0 = time.process_time()
    c = config
    try:
        res = diagnose_run(
            window,
            candidates=list(c.candidates) if c.candidates else None,
            hysteresis_file=hysteresis_file,
            thermal_file=thermal_file,
            params_file=params_file,
        )
    except DiagnoseInputError as exc:
        return Verdict(
            t_s, 'ERROR', None, None, 1.0, summary=f'cannot check: {exc}', check_cpu_s=time.process_time() - c0
        )
    if res.cause is None:  # nothing named: a slow drift the held-out split cannot see yet may be there
        drift = _drift_verdict(window, t_s, config, hysteresis_file, thermal_file, extension, params_file)
        if drift is not None:
            drift.check_cpu_s = time.process_time() - c0
            drift.summary += f'; the diagnosis: {res.summary}'
            return drift
    cpu = time.process_time() - c0
    params = {k: v['value'] for k, v in res.parameters.items()}
    if not res.discrepancy:
        return Verdict(
            t_s, 'OK', None, None, res.confidence, summary=res.summary, check_confidence=res.confidence, check_cpu_s=cpu
        )
    part = res.partial if res.cause is None else None
    if part is not None and part['gain_pct'] >= PARTIAL_NAME_GAIN_PCT and res.confidence > c.min_confidence:
        pv = {k: v['value'] for k, v in part['parameters'].items()}
        if not known(part['cause'], pv, extension or {}):
            return Verdict(
                t_s,
                'WARN',
                part['cause'],
                part['subsystem'],
                res.confidence,
                pv,
                part['gain_pct'],
                f'partly explained: {part["cause"]} ({part["subsystem"]}) removes {part["gain_pct"]:.0f} % of the '
                f'{part["channel"]} misfit, the rest is unexplained; {res.summary}',
                res.correlates,
                check_cause=part['cause'],
                check_subsystem=part['subsystem'],
                check_confidence=res.confidence,
                check_cpu_s=cpu,
                partial=True,
            )
    cause = res.cause or 'unexplained'
    seen = {
        'check_cause': cause,
        'check_subsystem': res.subsystem,
        'check_confidence': res.confidence,
        'check_cpu_s': cpu,
    }
    if res.confidence <= c.min_confidence:  # at 0.5 (the cap of an ambiguous verdict) a coin toss, no alarm
        return Verdict(
            t_s,
            'OK',
            None,
            None,
            1.0 - res.confidence,
            summary=f'not raised (confidence {res.confidence:.2f} <= {c.min_confidence:g}): {res.summary}',
            **seen,
        )
    if known(res.cause, params, extension or {}):
        return Verdict(
            t_s, 'OK', None, None, res.confidence, summary=f'the known extension of the model: {res.summary}', **seen
        )
    return Verdict(
        t_s,
        'WARN',
        cause,
        res.subsystem,
        res.confidence,
        params,
        res.gain_pct,
        res.summary,
        res.correlates if cause == 'unexplained' else [],
        **seen,
    )


def _drift_verdict(
    run: Run | None,
    t_s: float,
    config: MonitorConfig,
    hysteresis_file: str | None,
    thermal_file: str | None,
    extension: dict[str, float] | None,
    params_file: str | None = None,
) -> Verdict | None:
    """A WARN naming an ambient / coolant drift when :func:`sma_wrist.monitor.drift.ambient_drift_fit` names one in
    ``run`` (and it is not the known extension, nor left out of ``config.candidates``); None otherwise."""
    if run is None or (config.candidates and 'ambient_drift' not in config.candidates):
        return None
    from sma_wrist.diagnose import effects as fx
    from sma_wrist.diagnose import nominal_plant
    from sma_wrist.monitor.drift import ambient_drift_fit

    f = ambient_drift_fit(
        run, nominal_plant(run, hysteresis_file, thermal_file, params_file)
    )  # the plant the diagnosis replays
    if f is None or not f.named:
        return None
    params = {'ambient_drift_C_per_h': f.rate_C_per_h}
    if known('ambient_drift', params, extension or {}):
        return None
    e = fx.EFFECTS['ambient_drift']
    return Verdict(
        t_s,
        'WARN',
        e.id,
        e.subsystem,
        f.confidence,
        params,
        100.0 * f.explained,
        f.summary(),
        check_cause=e.id,
        check_subsystem=e.subsystem,
        check_confidence=f.confidence,
        change_s=getattr(run, 'change_s', None),
        drift_fit=True,
    )


def known(cause: str | None, params: dict[str, float], extension: dict[str, float]) -> bool:
    """The named cause is the extension the model was given (a diagnosis' params file), at about its values."""
    if not cause or not extension or not params or any(k not in extension for k in params):
        return False
    from sma_wrist.diagnose import effects as fx

    return all(
        abs(v - extension[k]) <= KNOWN_TOLERANCE * max(abs(extension[k]), float(fx.TYPICAL[fx.INDEX[k]]))
        for k, v in params.items()
    )


def change_point(r: np.ndarray, min_seg: int = CP_MIN_SEG, per_channel: bool = False) -> tuple:
    """Where the residuals ``r`` (B blocks, C channels) change: the split ``k`` that maximises the Gaussian
    likelihood ratio of a change in mean and variance, summed over the channels,
    ``sum_c B log s_c^2 - k log s1_c^2 - (B - k) log s2_c^2`` (s^2 the ML variance about each segment's mean).
    It is invariant to each channel's scale (degC, rad) and sees a step (offset, payload), a change of the
    residual's swing (gain, lag, a weaker TEM) and a change of its slope alike. Returns (k, statistic), and with
    ``per_channel`` each channel's share of the statistic at ``k`` (C,) as a third item."""
    r = np.asarray(r, dtype=float)
    B = r.shape[0]
    if B < 2 * min_seg:
        return (0, 0.0, np.zeros(r.shape[1] if r.ndim == 2 else 0)) if per_channel else (0, 0.0)

    def var_prefix(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        n = np.arange(1, x.shape[0] + 1)[:, None]
        s1, s2 = np.cumsum(x, axis=0), np.cumsum(x * x, axis=0)
        return np.maximum(s2 / n - (s1 / n) ** 2, 0.0), n

    floor = 1e-12 + 1e-6 * np.var(r, axis=0)  # a channel without noise must not give log(0)
    v1, n1 = var_prefix(r)  # variance of r[:k] at row k-1
    v2, n2 = var_prefix(r[::-1])
    ks = np.arange(min_seg, B - min_seg + 1)
    tot = B * np.log(v1[-1] + floor)
    stat = tot[None, :] - ks[:, None] * np.log(v1[ks - 1] + floor) - (B - ks)[:, None] * np.log(v2[B - ks - 1] + floor)
    s = stat.sum(axis=1)
    j = int(np.argmax(s))
    if per_channel:
        return int(ks[j]), float(s[j]), stat[j]
    return int(ks[j]), float(s[j])


HISTORY_FIELDS = (
    't_s',
    'level',
    'cause',
    'subsystem',
    'confidence',
    'gain_pct',
    'check_cause',
    'check_subsystem',
    'check_confidence',
    'since_s',
    'parameters',
    'change_s',
    'behind_s',
    'summary',
)


def history_text(history: Sequence[Verdict], fmt: str, episodes: list[dict[str, Any]] | None = None) -> str:
    """The verdict history as ``csv``, ``json`` or ``md`` (markdown table)."""
    rows = [v.to_json() for v in history]
    if fmt == 'json':
        return json.dumps({'verdicts': rows, 'episodes': episodes or []}, indent=1)

    def cell(r: dict[str, Any], k: str) -> str:
        x = r.get(k)
        if isinstance(x, dict):
            return '; '.join(f'{a} = {b:.4g}' for a, b in x.items())
        if isinstance(x, float):
            return f'{x:.4g}'
        return '' if x is None else str(x)

    if fmt == 'csv':
        buf = io.StringIO()
        w = csv.writer(buf)
        w.writerow(HISTORY_FIELDS)
        for r in rows:
            w.writerow([cell(r, k) for k in HISTORY_FIELDS])
        return buf.getvalue()
    if fmt == 'md':
        cols = ('t_s', 'level', 'cause', 'subsystem', 'confidence', 'parameters', 'summary')
        lines = ['# Model monitor: verdict history', '', '| ' + ' | '.join(cols) + ' |', '|' + '---|' * len(cols)]
        lines += ['| ' + ' | '.join(cell(r, k).replace('|', '/') for k in cols) + ' |' for r in rows]
        return '\n'.join(lines) + '\n'
    raise MonitorInputError(f'history format {fmt!r}: use a file ending .csv, .json or .md')


def history_format(path: str | Path) -> str:
    """csv | json | md from a file name; MonitorInputError otherwise."""
    ext = Path(path).suffix.lower().lstrip('.')
    fmt = {'csv': 'csv', 'json': 'json', 'md': 'md', 'markdown': 'md'}.get(ext)
    if fmt is None:
        raise MonitorInputError(
            f'{path}: the verdict history is written as .csv, .json or .md (got {ext or "no"} extension)'
        )
    return fmt


def write_history(path: str | Path, history: Sequence[Verdict], episodes: list[dict[str, Any]] | None = None) -> Path:
    p = Path(path)
    text = history_text(history, history_format(p), episodes)
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = p.with_name(p.name + '.tmp')
    tmp.write_text(text)
    tmp.replace(p)  # a reader never sees half a file
    return p
