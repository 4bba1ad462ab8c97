"""twin_monitor: tells, while the wrist runs, when it stops behaving like its model.

Subscribes the contract topics (TEM commands, muscle temperatures, joint state, payload, and where a device publishes
them the drive it read back and the TEMs' exchanger-face temperatures), runs the plant model on the TEM drive (the
read-back where it comes, else the commands) beside the wrist (:class:`sma_wrist.monitor.twin.Twin`: the built-in model, the identified
``hysteresis_file`` / ``thermal_file``, or a diagnosis' ``extended_params.yaml`` as ``params_file``) and publishes
its predictions and the residuals (measured - twin) on ``/wrist/twin/...`` (msg_defs/topics.yaml). Every
``check_period_s`` it diagnoses a rolling window of the recent data (:mod:`sma_wrist.monitor`, doc/howto/monitor.md).
The node itself only buffers the samples: the twin and the checks run in a worker process
(:mod:`sma_wrist.monitor.worker`; ``worker: thread`` for a worker thread) that it hands them to every ``BATCH_S``
of measurement time and that answers with the twin's prediction at the batch's last stamp and with each check's
verdict, so that neither holds up its subscriptions or the control loop; a check due while the last one still runs
waits for it and starts on the newest data (never queued). The verdict goes to
``/diagnostics`` (``twin_monitor: model``): OK while the wrist is its model; WARN naming the cause, subsystem,
fitted parameters, held-out gain and confidence when it is not (cause ``unexplained`` with what the residual
correlates with when the catalogue has nothing); ERROR when the data cannot be checked (what is missing); its
key/values carry the check's details, among them ``change_s`` (where the check placed a change of the residuals in
its window), ``pending`` (that change too recent to name: the published verdict stands) and ``partial`` (the cause
explains most, not all, of the misfit), as in the verdict history, which goes to ``history_file`` (.csv, .json or .md).
Both also carry ``behind_s``, how far the checks are behind the wrist (the newest sample received minus the end of the
window last checked); a separate status, ``twin_monitor: checks``, is WARN while that exceeds
:data:`sma_wrist.monitor.BEHIND_PERIODS` check periods (the worker starved of CPU: a fact about the monitor, not a
verdict on the wrist).

Optional in both launch files (``monitor:=true``) and in ``sma-wrist run --monitor``.
"""

from __future__ import annotations

from collections import OrderedDict
from typing import Any

from diagnostic_msgs.msg import DiagnosticStatus
from sensor_msgs.msg import JointState, Temperature
from std_msgs.msg import Float64, Header

from sma_wrist.core.errors import SmaWristError
from sma_wrist.monitor import BEHIND_PERIODS, MonitorConfig, MonitorInputError, Verdict, history_format, write_history
from sma_wrist.monitor.twin import load_model
from sma_wrist.monitor.worker import RUNTIME_FIELDS, WorkerLink
from sma_wrist.nodes.common import HYSTERESIS_FILE_PARAM, MUSCLE_FRAMES, Param, WristNode, finite, main_for

_LEVEL = {'OK': DiagnosticStatus.OK, 'WARN': DiagnosticStatus.WARN, 'ERROR': DiagnosticStatus.ERROR}
_DEFAULTS = MonitorConfig()
#: period of the repeated verdict on /diagnostics [s]
HEARTBEAT_S = 1.0
#: measurement time between two batches handed to the worker [s] (and the fastest twin prediction it sends back)
BATCH_S = 0.1
#: batches the node keeps the stamps of while the worker has not answered them
MAX_PENDING = 1000


class TwinMonitor(WristNode):
    PARAMS = (
        Param(
            'window_s',
            _DEFAULTS.window_s,
            'scored part of the rolling window each check diagnoses',
            's',
            (20.0, 3600.0),
            runtime=False,
        ),
        Param(
            'settle_s',
            _DEFAULTS.settle_s,
            "lead-in before the window that only settles the replays' memory (wire hysteresis, joint)",
            's',
            (0.0, 600.0),
            runtime=False,
        ),
        Param(
            'check_period_s',
            _DEFAULTS.check_period_s,
            'time between two checks (measurement time); after a located change not yet named, every 5 s from 30 s after it',
            's',
            (1.0, 3600.0),
        ),
        Param(
            'persist_checks',
            _DEFAULTS.persist_checks,
            'consecutive agreeing checks before a verdict is raised or cleared',
            'checks',
            (1, 100),
        ),
        Param(
            'min_confidence',
            _DEFAULTS.min_confidence,
            'a discrepancy found with this confidence or lower counts as OK',
            '1',
            (0.0, 1.0),
        ),
        Param(
            'sure_confidence',
            _DEFAULTS.sure_confidence,
            'a cause named with at least this confidence is raised by one check',
            '1',
            (0.0, 1.0),
        ),
        Param(
            'candidates',
            '',
            'comma-separated catalogue ids the checks try (doc/explanation/diagnosis.md; empty: all)',
            runtime=False,
        ),
        HYSTERESIS_FILE_PARAM,
        Param(
            'thermal_file',
            '',
            "TEMs' heat balance: thermal.yaml from sma-wrist identify thermal (empty: Table 4.9)",
            runtime=False,
        ),
        Param(
            'params_file',
            '',
            "a params file whose plant model (plant_sim's section, else hardware_bridge's: a commissioned "
            "wrist_params.yaml, a diagnosis' extended_params.yaml) the twin runs and the checks replay",
            runtime=False,
        ),
        Param(
            'history_file',
            '',
            'write the verdict history here after every check (.csv, .json or .md; empty: not written)',
            runtime=False,
        ),
        Param(
            'worker',
            'process',
            'where the twin and the checks run: a worker process (never holds the node up), a worker '
            'thread (no process start; shares the interpreter), or inline in the callback (holds the node up '
            'for the check: only for offline simulation, where every check must be made)',
            choices=('process', 'thread', 'inline'),
            runtime=False,
        ),
        Param(
            'worker_nice',
            19,
            "the worker process's niceness above the node's (Unix; 0: the same priority): the twin and the checks "
            'take the CPU the control loop leaves over (a check due while the last one still runs waits for it, '
            'the periods without a check counted in skipped_checks)',
            '1',
            (0, 19),
            runtime=False,
        ),
        Param(
            'payload_kg',
            0.3,
            'payload the twin carries until /wrist/payload says otherwise',
            'kg',
            (0.0, 2.0),
            runtime=False,
        ),
        Param(
            'twin_rate_hz',
            10.0,
            'rate of the twin predictions and residuals on /wrist/twin/* (0: not published)',
            'Hz',
            (0.0, 1000.0),
            runtime=False,
        ),
    )

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('twin_monitor', **kwargs)
        p = self.p
        cands = tuple(c.strip() for c in p['candidates'].split(',') if c.strip()) or None
        try:
            self.config = MonitorConfig(
                window_s=p['window_s'],
                settle_s=p['settle_s'],
                check_period_s=p['check_period_s'],
                persist_checks=p['persist_checks'],
                min_confidence=p['min_confidence'],
                sure_confidence=p['sure_confidence'],
                candidates=cands,
                hysteresis_file=p['hysteresis_file'],
                thermal_file=p['thermal_file'],
                params_file=p['params_file'],
            ).check()
            if p['history_file']:
                history_format(p['history_file'])
            # loaded here so that a file that does not load stops the node with its name; the worker loads its own
            model = load_model(p['hysteresis_file'] or None, p['thermal_file'] or None, p['params_file'] or None)
        except MonitorInputError as exc:
            raise SmaWristError(f'twin_monitor: {exc}') from None
        # the node only buffers: the twin and the checks run in the worker (sma_wrist/monitor/worker.py), which
        # it feeds a batch every BATCH_S of measurement time. No lock: the node's callbacks are in its default,
        # mutually exclusive callback group, so they run one at a time under any executor
        self._events: list[tuple[str, int, float, float]] = [('p', 0, 0.0, float(p['payload_kg']))]
        self._batch_s = min(BATCH_S, 1.0 / p['twin_rate_hz']) if p['twin_rate_hz'] > 0 else BATCH_S
        self._sent_t: float | None = None
        self._twin_t: float | None = None  # stamp of the last twin prediction asked for
        self._seq = 0
        self._stamps: OrderedDict[int, Any] = OrderedDict()  # batch -> its last joint state's stamp
        self.t_first: float | None = None
        self.t_newest: float | None = None  # stamp of the newest measurement received [s]
        self.span_s = self.config.window_s + self.config.settle_s
        self.skipped_checks = 0
        self.history: list[Verdict] = []
        self.episodes: list[dict[str, Any]] = []
        self.verdict: Verdict | None = None
        #: CPU time of the worker process so far (its last answer) [s]: the twin's and the checks' whole cost
        self.worker_cpu_s = 0.0
        self._worker_ended = False
        self._link = WorkerLink(p['worker'], self.config, int(p['worker_nice']))
        for i in (1, 2):
            self.subscription(f'/wrist/tem_{i}/command', lambda m, i=i: self._on_command(i, m))
            self.subscription(f'/wrist/muscle_{i}/temperature', lambda m, i=i: self._on_temperature(i, m))
            self.subscription(f'/wrist/tem_{i}/face_temperature', lambda m, i=i: self._on_face(i, m))
        # only a device that reads its drive back publishes it (hardware_bridge); subscribed before the joint state,
        # whose sample closes the window the drive held over (an executor takes ready subscriptions in this order)
        self.subscription('/wrist/tem_drive_applied', self._on_drive)
        self.subscription('/wrist/joint_states', self._on_joint)
        self.subscription('/wrist/payload', self._on_payload)
        self.pub = {
            name: self.publisher(name)
            for name in (
                '/wrist/twin/muscle_1/temperature',
                '/wrist/twin/muscle_2/temperature',
                '/wrist/twin/joint_states',
                '/wrist/twin/residual/muscle_1/temperature',
                '/wrist/twin/residual/muscle_2/temperature',
                '/wrist/twin/residual/angle',
            )
        }
        # a result that arrives while the wrist publishes nothing is still published, and the verdict is repeated
        # every second (diagnostic_updater's 1 Hz convention): a healthy run shows that it is being watched
        self._status: tuple[Any, str, dict[str, Any]] | None = None
        self.timer = self.create_timer(HEARTBEAT_S, self._heartbeat)
        self.get_logger().info(
            f'twin_monitor: {model.description}; a check of {p["settle_s"]:g} + '
            f'{p["window_s"]:g} s every {p["check_period_s"]:g} s in a worker {p["worker"]}'
        )

    def apply(self, changed: dict[str, Any]) -> None:
        values = {k: self.p[k] for k in RUNTIME_FIELDS}
        for k, v in values.items():
            setattr(self.config, k, v)
        self._link.send(('config', values))

    # -- input: buffered, handed to the worker every BATCH_S ----------------------------------------------------
    def _on_command(self, i: int, msg: Float64) -> None:
        if not finite(msg.data):
            self.reject_input(f'/wrist/tem_{i}/command', f'non-finite command {msg.data!r}')
            return
        self._events.append(('u', i, self.now_ns() * 1e-9, float(msg.data)))

    def _on_temperature(self, i: int, msg: Temperature) -> None:
        if not finite(msg.temperature):
            self.reject_input(f'/wrist/muscle_{i}/temperature', f'non-finite temperature {msg.temperature!r}')
            return
        t = self.stamp_s(msg)
        self._newest(t)
        self._events.append(('T', i, t, float(msg.temperature)))

    def _on_face(self, i: int, msg: Temperature) -> None:
        if finite(msg.temperature):  # a face is no safety input here: a bad sample is left out
            self._events.append(('f', i, self.stamp_s(msg), float(msg.temperature)))

    def _on_drive(self, msg: JointState) -> None:
        """The drive the device read back (effort [V] of tem_1, tem_2), held from its stamp."""
        t = self.stamp_s(msg)
        names = list(msg.name)
        for i, name in enumerate(('tem_1', 'tem_2')):
            j = names.index(name) if name in names else i
            if j < len(msg.effort) and finite(msg.effort[j]):
                self._events.append(('d', i + 1, t, float(msg.effort[j])))

    def _on_payload(self, msg: Float64) -> None:
        if finite(msg.data) and 0.0 <= msg.data <= 2.0:
            self._events.append(('p', 0, 0.0, float(msg.data)))
        else:
            self.reject_input('/wrist/payload', f'{msg.data!r} is not a payload in kg (0-2)')

    def _on_joint(self, msg: JointState) -> None:
        try:
            q = float(msg.position[list(msg.name).index(self.contract.joint_name)] if msg.name else msg.position[0])
        except (ValueError, IndexError):
            self.reject_input('/wrist/joint_states', f'no position of joint {self.contract.joint_name!r}')
            return
        if not finite(q):
            self.reject_input('/wrist/joint_states', f'non-finite angle {q!r}')
            return
        t = self.stamp_s(msg)
        self._newest(t)
        self._events.append(('q', 0, t, q))
        if self._sent_t is not None and t - self._sent_t < self._batch_s - 1e-9:
            return
        events, self._events = self._events, []
        self._sent_t = t
        self._seq += 1
        seq = self._seq
        if self.t_first is None:
            self.t_first = min(e[2] for e in events if e[0] != 'p')
        rate = self.p['twin_rate_hz']
        want_twin = rate > 0 and (self._twin_t is None or t - self._twin_t >= 1.0 / rate - 1e-9)
        if want_twin:
            self._twin_t = t
            self._stamps[seq] = msg.header.stamp
            while len(self._stamps) > MAX_PENDING:  # a worker that answers nothing: forget the oldest
                self._stamps.popitem(last=False)
        self._link.send(('feed', seq, events, want_twin))
        self.collect()

    def _newest(self, t: float) -> None:
        if self.t_newest is None or t > self.t_newest:
            self.t_newest = t

    def behind_s(self) -> float:
        """How far the checks are behind the wrist [s]: the stamp of the newest measurement received minus the end of
        the window last checked (before the first check: minus when it was due); 0 before that."""
        if self.t_newest is None:
            return 0.0
        if self.verdict is not None:
            end = self.verdict.t_s
        elif self.t_first is not None:
            end = self.t_first + self.span_s
        else:
            return 0.0
        return max(self.t_newest - end, 0.0)

    def _keeping_up(self) -> None:
        """``twin_monitor: checks``: WARN while the checks are more than BEHIND_PERIODS check periods behind the
        wrist (the worker gets too little CPU; a fact about the monitor, not about the wrist), OK again once they
        are not."""
        behind, period = self.behind_s(), self.config.check_period_s
        values = {'behind_s': f'{behind:.2f}', 'skipped_checks': self.skipped_checks}
        if behind > BEHIND_PERIODS * period:
            self.diagnose(
                'checks',
                DiagnosticStatus.WARN,
                f'the checks are more than {BEHIND_PERIODS:g} check periods ({BEHIND_PERIODS * period:g} s) behind '
                f'the wrist: the monitor worker gets too little CPU (a busy machine), its verdicts come late',
                values,
            )
        else:
            self.diagnose('checks', DiagnosticStatus.OK, 'the checks keep up with the wrist', values)

    # -- the worker's answers -----------------------------------------------------------------------------------
    def collect(self, publish: bool = True) -> None:
        """Publish what the worker answered so far: the twin's predictions and the checks' verdicts. ``publish``
        False (the node is being destroyed: under rclpy Ctrl-C has already shut the context down, and a publish
        raises): the verdicts only go into the history (and its file)."""
        for a in self._link.poll():
            if a[0] == 'twin':
                stamp = self._stamps.pop(a[1], None)
                while self._stamps and next(iter(self._stamps)) < a[1]:  # answered out of reach: never published
                    self._stamps.popitem(last=False)
                self.worker_cpu_s = a[7]
                if stamp is not None and publish:
                    self._publish_twin(stamp, *a[3:7])
            elif a[0] == 'verdict':
                self._on_verdict(*a[1:], publish=publish)

    def _on_verdict(
        self,
        v: Verdict,
        episodes: list[dict[str, Any]],
        skipped: int,
        cpu_s: float | None = None,
        publish: bool = True,
    ) -> None:
        if cpu_s is not None:
            self.worker_cpu_s = cpu_s
        if self.t_newest is not None:  # the node has seen newer samples than the worker had when it decided
            v.behind_s = max(v.behind_s or 0.0, self.t_newest - v.t_s, 0.0)
        self.verdict = v
        self.history.append(v)
        self.episodes = episodes
        self.skipped_checks = skipped
        if publish:
            self._publish_verdict(v)
        if self.p['history_file']:
            try:
                write_history(self.p['history_file'], self.history, episodes)
            except OSError as exc:
                message = f'cannot write {self.p["history_file"]}: {exc}'
                if publish:
                    self.diagnose('history', DiagnosticStatus.WARN, message)
                else:
                    self.get_logger().warning(message)

    def _publish_verdict(self, v: Verdict) -> None:
        if v.level == 'OK':
            text = 'the wrist behaves like its model'
        elif v.level == 'ERROR':
            text = v.summary
        else:
            ps = ', '.join(f'{k} = {x:.4g}' for k, x in v.parameters.items())
            text = (
                f'{v.cause} ({v.subsystem})' + (f': {ps}' if ps else '') + f'; held-out gain {v.gain_pct:.0f} %, '
                f'confidence {v.confidence:.2f}, since {v.since_s:.1f} s'
            )
            if v.partial:
                text = f'partly explained ({v.gain_pct:.0f} % of the misfit): ' + text
            if v.cause == 'unexplained' or v.partial:
                text += '; correlates: ' + ', '.join(f'{c["regressor"]} ({c["r"]:+.2f})' for c in v.correlates[:3])
        values = {
            't_s': f'{v.t_s:.2f}',
            'cause': v.cause or '',
            'subsystem': v.subsystem or '',
            'confidence': f'{v.confidence:.3f}',
            'gain_pct': f'{v.gain_pct:.1f}',
            'since_s': '' if v.since_s is None else f'{v.since_s:.2f}',
            'check': v.summary,
            'check_cpu_s': f'{v.check_cpu_s:.2f}',
            'skipped_checks': self.skipped_checks,
            'behind_s': f'{self.behind_s():.2f}',
            'change_s': '' if v.change_s is None else f'{v.change_s:.2f}',
            'pending': 'true' if v.pending else 'false',
            'partial': 'true' if v.partial else 'false',
            **{k: f'{x:.6g}' for k, x in v.parameters.items()},
        }
        self._status = (_LEVEL[v.level], text, values)
        self.diagnose('model', _LEVEL[v.level], text, values)

    def _heartbeat(self) -> None:
        """Collect the worker's answers, then repeat the current verdict on /diagnostics (OK with what is awaited
        before the first check)."""
        self.collect()
        code = self._link.ended()
        if code is not None and not self._worker_ended:
            self._worker_ended = True
            v = Verdict(
                self.verdict.t_s if self.verdict else 0.0,
                'ERROR',
                None,
                None,
                1.0,
                summary=f'the monitor worker process ended (exit code {code}): no twin and no checks; restart the node',
            )
            self._on_verdict(v, self.episodes, self.skipped_checks)
        if self._status is None:
            t0 = self.t_first
            first = 'no measurement yet' if t0 is None else f'first check at {t0 + self.span_s:.1f} s'
            level, text, values = DiagnosticStatus.OK, f'watching: {first}', {'skipped_checks': self.skipped_checks}
        else:
            level, text, values = self._status
        values = {**values, 'behind_s': f'{self.behind_s():.2f}'}  # of now, not of the verdict's arrival
        self.publish_status('model', level, text, values)
        self._keeping_up()

    def _publish_twin(
        self, stamp: Any, T: tuple[float, float], q: float, qd: float, residuals: dict[str, float]
    ) -> None:
        """The twin's prediction at ``stamp`` (the stamp of the joint state it was stepped to)."""
        for i in (0, 1):
            m = Temperature(header=Header(stamp=stamp, frame_id=MUSCLE_FRAMES[i]), temperature=T[i], variance=0.0)
            self.pub[f'/wrist/twin/muscle_{i + 1}/temperature'].publish(m)
        self.pub['/wrist/twin/joint_states'].publish(
            JointState(
                header=Header(stamp=stamp, frame_id=self.contract.frame_id),
                name=[self.contract.joint_name],
                position=[q],
                velocity=[qd],
                effort=[],
            )
        )
        for name, key in (
            ('/wrist/twin/residual/muscle_1/temperature', 'T1'),
            ('/wrist/twin/residual/muscle_2/temperature', 'T2'),
            ('/wrist/twin/residual/angle', 'q'),
        ):
            self.pub[name].publish(Float64(data=residuals[key]))

    def destroy_node(self) -> Any:
        if self._link is not None:
            self.collect(publish=False)  # the answers already in, into the history (a running check is abandoned)
            self._link.close()
            self._link = None
        return super().destroy_node()


def main(args: list[str] | None = None) -> int:
    return main_for(TwinMonitor, args)


if __name__ == '__main__':
    raise SystemExit(main())
