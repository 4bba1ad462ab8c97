"""twin_monitor: tells, while the wrist runs, when it stops behaving like its model.

Subscribes the contract topics (TEM commands, muscle temperatures, joint state, payload), runs the plant model on
the measured commands beside the wrist (:class:`sma_wrist.monitor.twin.Twin`: the built-in model, the identified
``hysteresis_file`` / ``thermal_file``, or a diagnosis' ``extended_params.yaml`` as ``params_file``) and publishes
its predictions and the residuals (measured - twin) on ``/wrist/twin/...`` (msg_defs/topics.yaml). Every
``check_period_s`` it diagnoses a rolling window of the recent data (:mod:`sma_wrist.monitor`, doc/howto/monitor.md) in a
worker process (``worker: thread`` for a worker thread), so the checks never hold up its subscriptions or the
control loop; a check still running when the next is due is skipped, not queued. The verdict goes to
``/diagnostics`` (``twin_monitor: model``): OK while the wrist is its model; WARN naming the cause, subsystem,
fitted parameters, held-out gain and confidence when it is not (cause ``unexplained`` with what the residual
correlates with when the catalogue has nothing); ERROR when the data cannot be checked (what is missing). The
verdict history goes to ``history_file`` (.csv, .json or .md).

Optional in both launch files (``monitor:=true``) and in ``sma-wrist run --monitor``.
"""

from __future__ import annotations

import threading
from concurrent.futures import Executor, Future
from typing import Any

from diagnostic_msgs.msg import DiagnosticStatus
from sensor_msgs.msg import JointState, Temperature
from std_msgs.msg import Float64, Header

from sma_wrist.core.errors import SmaWristError
from sma_wrist.monitor import (
    Monitor,
    MonitorConfig,
    MonitorInputError,
    Verdict,
    diagnose_window,
    write_history,
)
from sma_wrist.nodes.common import HYSTERESIS_FILE_PARAM, MUSCLE_FRAMES, Param, WristNode, finite, main_for

_LEVEL = {'OK': DiagnosticStatus.OK, 'WARN': DiagnosticStatus.WARN, 'ERROR': DiagnosticStatus.ERROR}
_DEFAULTS = MonitorConfig()
#: period of the repeated verdict on /diagnostics [s]
HEARTBEAT_S = 1.0


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
            'check_period_s', _DEFAULTS.check_period_s, 'time between two checks (measurement time)', 's', (1.0, 3600.0)
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
            "a diagnosis' extended_params.yaml (sma-wrist diagnose --params): the twin runs that "
            'extended model, and the fitted extension is what the monitor expects',
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
            'where the checks run: a worker process (never holds the node up), a worker '
            'thread (no process start; shares the interpreter), or inline in the callback (holds the node up '
            'for the check: only for offline simulation, where every check must be made)',
            choices=('process', 'thread', 'inline'),
            runtime=False,
        ),
        Param(
            'worker_nice',
            5,
            "the check worker process's niceness above the node's (Unix; 0: the same priority): on a busy machine "
            'the checks take what the control loop leaves over (a check still running when the next is due is '
            'skipped, counted in skipped_checks)',
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
            )
            if p['history_file']:
                from sma_wrist.monitor import history_format

                history_format(p['history_file'])
            self.monitor = Monitor(self.config)
        except MonitorInputError as exc:
            raise SmaWristError(f'twin_monitor: {exc}') from None
        self.monitor.payload(p['payload_kg'])
        self._lock = threading.Lock()
        self._pool: Executor | None = None
        self._job: Future | None = None
        self._job_t = 0.0
        self.skipped_checks = 0
        self._last_pub: float | None = None
        self.verdict: Verdict | None = None
        for i in (1, 2):
            self.subscription(f'/wrist/tem_{i}/command', lambda m, i=i: self._on_command(i, m))
            self.subscription(f'/wrist/muscle_{i}/temperature', lambda m, i=i: self._on_temperature(i, m))
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
            f'twin_monitor: {self.monitor.model.description}; a check of {p["settle_s"]:g} + '
            f'{p["window_s"]:g} s every {p["check_period_s"]:g} s in a worker {p["worker"]}'
        )

    def apply(self, changed: dict[str, Any]) -> None:
        c = self.config
        c.check_period_s = self.p['check_period_s']
        c.persist_checks = self.p['persist_checks']
        c.min_confidence = self.p['min_confidence']
        c.sure_confidence = self.p['sure_confidence']

    # -- input ------------------------------------------------------------------------------------------------
    def _on_command(self, i: int, msg: Float64) -> None:
        if not finite(msg.data):
            self.reject_input(f'/wrist/tem_{i}/command', f'non-finite command {msg.data!r}')
            return
        with self._lock:
            self.monitor.command(i, self.now_ns() * 1e-9, float(msg.data))

    def _on_temperature(self, i: int, msg: Temperature) -> None:
        if not finite(msg.temperature):
            self.reject_input(f'/wrist/muscle_{i}/temperature', f'non-finite temperature {msg.temperature!r}')
            return
        with self._lock:
            self.monitor.temperature(i, self.stamp_s(msg), float(msg.temperature))

    def _on_payload(self, msg: Float64) -> None:
        if finite(msg.data) and 0.0 <= msg.data <= 2.0:
            with self._lock:
                self.monitor.payload(float(msg.data))
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
        with self._lock:
            self.monitor.angle(t, q)
            due = self.monitor.due(t)
            window = self.monitor.window(t) if due and (self._job is None or self._job.done()) else None
            if due and window is None:
                self.monitor.last_check = t
                self.skipped_checks += 1
        if window is not None:
            self._submit(window, t)
        self._collect()
        rate = self.p['twin_rate_hz']
        if rate > 0 and (self._last_pub is None or t - self._last_pub >= 1.0 / rate - 1e-9):
            self._last_pub = t
            self._publish_twin(msg.header)

    # -- checks -----------------------------------------------------------------------------------------------
    def _check_pool(self) -> Executor:
        if self._pool is None:
            if self.p['worker'] == 'process':
                import multiprocessing
                from concurrent.futures import ProcessPoolExecutor

                from sma_wrist.monitor.worker import start_worker

                # spawn: a fork of a process running rclpy's threads may inherit a held lock
                self._pool = ProcessPoolExecutor(
                    max_workers=1,
                    mp_context=multiprocessing.get_context('spawn'),
                    initializer=start_worker,
                    initargs=(int(self.p['worker_nice']),),
                )
            else:
                from concurrent.futures import ThreadPoolExecutor

                self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix='twin_monitor_check')
        return self._pool

    def _submit(self, window: Any, t: float) -> None:
        m = self.monitor.model
        self._job_t = t
        if self.p['worker'] == 'inline':
            job: Future = Future()
            try:
                job.set_result(diagnose_window(window, t, self.config, m.hysteresis_file, m.thermal_file, m.extension))
            except Exception as exc:  # noqa: BLE001 - reported by _collect like a worker's failure
                job.set_exception(exc)
            self._job = job
            return
        self._job = self._check_pool().submit(
            diagnose_window, window, t, self.config, m.hysteresis_file, m.thermal_file, m.extension
        )

    def _collect(self) -> None:
        job = self._job
        if job is None or not job.done():
            return
        self._job = None
        try:
            raw = job.result()
        except Exception as exc:  # noqa: BLE001 - a check that failed is reported, the node goes on
            raw = Verdict(
                self._job_t, 'ERROR', None, None, 1.0, summary=f'the check failed: {type(exc).__name__}: {exc}'
            )
        with self._lock:
            v = self.monitor.decide(raw)
            history = list(self.monitor.history)
            episodes = self.monitor.episodes()
        self.verdict = v
        self._publish_verdict(v)
        if self.p['history_file']:
            try:
                write_history(self.p['history_file'], history, episodes)
            except OSError as exc:
                self.diagnose('history', DiagnosticStatus.WARN, f'cannot write {self.p["history_file"]}: {exc}')

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
            if v.cause == 'unexplained':
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
            **{k: f'{x:.6g}' for k, x in v.parameters.items()},
        }
        self._status = (_LEVEL[v.level], text, values)
        self.diagnose('model', _LEVEL[v.level], text, values)

    def _heartbeat(self) -> None:
        """Collect a finished check, then repeat the current verdict on /diagnostics (OK with what is awaited
        before the first check)."""
        self._collect()
        if self._status is None:
            with self._lock:
                t0, span = self.monitor.t_first, self.monitor.span_s
            first = 'no measurement yet' if t0 is None else f'first check at {t0 + span:.1f} s'
            level, text, values = DiagnosticStatus.OK, f'watching: {first}', {'skipped_checks': self.skipped_checks}
        else:
            level, text, values = self._status
        self.publish_status('model', level, text, values)

    def _publish_twin(self, header: Any) -> None:
        tw = self.monitor.twin
        if tw is None:
            return
        T = tw.temperatures_C
        stamp = header.stamp
        for i in (0, 1):
            m = Temperature(
                header=Header(stamp=stamp, frame_id=MUSCLE_FRAMES[i]), temperature=float(T[i]), variance=0.0
            )
            self.pub[f'/wrist/twin/muscle_{i + 1}/temperature'].publish(m)
        self.pub['/wrist/twin/joint_states'].publish(
            JointState(
                header=Header(stamp=stamp, frame_id=self.contract.frame_id),
                name=[self.contract.joint_name],
                position=[tw.angle_rad],
                velocity=[float(tw.plant.state.qd[0])],
                effort=[],
            )
        )
        r = self.monitor.residuals()
        for name, key in (
            ('/wrist/twin/residual/muscle_1/temperature', 'T1'),
            ('/wrist/twin/residual/muscle_2/temperature', 'T2'),
            ('/wrist/twin/residual/angle', 'q'),
        ):
            self.pub[name].publish(Float64(data=r[key]))

    def destroy_node(self) -> Any:
        if self._pool is not None:
            # a check still running is abandoned: its worker process is ended, not waited for (seconds)
            for proc in list((getattr(self._pool, '_processes', None) or {}).values()):
                proc.terminate()
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool = None
        return super().destroy_node()


def main(args: list[str] | None = None) -> int:
    return main_for(TwinMonitor, args)


if __name__ == '__main__':
    raise SystemExit(main())
